//! One scene's right-hand side (dv/dt and u) in a loop, for a profiler: no Python in the stack,
//! so `perf record` shows the core alone. Same loop as the binding's `Scene.rhs_benchmark` (two
//! nearby states alternated, each evaluation at a new q); the printed time is wall clock and only
//! a guide: speed figures come from `progmo bench` and `cargo bench`.
//!
//! Run: `cargo run --release --example rhs_profile -- SCENE.toml [ITERATIONS] [FORMULATION]`
//! (defaults 100000, auto); with `CARGO_PROFILE_RELEASE_DEBUG=true` for symbols, then
//! `perf record -g target/release/examples/rhs_profile ...`. Robot files are found through
//! `$PROGMO_ROBOT_PATH` (`python -c "from progmo import data; print(*data.robot_path(), sep=':')"`).

use progmo::formulation::Formulation;
use progmo::programme::Role;
use progmo::scene::Scene;
use progmo::solve::Evaluator;
use progmo::with_problem;

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [path, rest @ ..] = args.as_slice() else {
        return Err("usage: rhs_profile SCENE.toml [ITERATIONS] [FORMULATION]".into());
    };
    let iterations: usize = match rest.first() {
        Some(n) => n
            .parse()
            .ok()
            .filter(|&n| n > 0)
            .ok_or(format!("ITERATIONS: `{n}` is not a positive integer"))?,
        None => 100_000,
    };
    let formulation: Formulation = match rest.get(1) {
        Some(f) => f.parse().map_err(|e| format!("FORMULATION: {e}"))?,
        None => Formulation::Auto,
    };
    let scene = Scene::load(path).map_err(|e| e.to_string())?;
    let rank = scene.settings.rank();
    with_problem!(&scene.system, p => {
        let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
        ev.set_row_scale_at(p.t0, &p.q0, &p.v0);
        let mut u = vec![0.0; p.v0.len()];
        let nearby: Vec<f64> = p.q0.iter().map(|x| x + 1e-9).collect();
        let states = [&p.q0, &nearby];
        let start = std::time::Instant::now();
        for i in 0..iterations {
            ev.evaluate(formulation, &rank, None, p.t0, states[i % 2], &p.v0)
                .map_err(|e| format!("{path}: at the initial state: {e}"))?;
            ev.reaction(Role::Programme, &mut u);
            std::hint::black_box(&u);
        }
        let us = start.elapsed().as_secs_f64() / iterations as f64 * 1e6;
        println!("{}: {us:.3} us per right-hand side ({formulation:?}, {iterations} calls, wall clock)", scene.name);
    });
    Ok(())
}

fn main() {
    if let Err(e) = run() {
        eprintln!("rhs_profile: {e}");
        std::process::exit(2);
    }
}
