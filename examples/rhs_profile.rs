//! One scene's right-hand side (dv/dt and u) in a loop, for a profiler: no Python in the stack,
//! so `perf record` shows the core alone. Same loop as the binding's `Scene.rhs_benchmark` (two
//! nearby states alternated, each evaluation at a new q); the printed time is wall clock and only
//! a guide: speed figures come from `progmo bench` and `cargo bench`.
//!
//! With `--split` (last argument) a second line splits the call into its parts, each timed
//! alone over the same loop: A (`mass_matrix`), F = G + Q (`natural_forces`), the rows' jet (B, gamma: `prepare_geometry`
//! minus A) and the formulation (dv/dt, lambda and the diagnostics: the whole call minus
//! `prepare`). On a tree A and F alone each run the kinematics that `prepare` shares, so their sum
//! can exceed the prepared part: the split says where to look, not what a pass costs to the
//! nanosecond.
//!
//! Run: `cargo run --release --example rhs_profile -- SCENE.toml [ITERATIONS] [FORMULATION] [--split]`
//! (defaults 100000, auto); with `CARGO_PROFILE_RELEASE_DEBUG=true` for symbols, then
//! `perf record -g target/release/examples/rhs_profile ...`. Robot files are found through
//! `$PROGMO_ROBOT_PATH` (`python -c "from progmo import data; print(*data.robot_path(), sep=':')"`).

use progmo::formulation::Formulation;
use progmo::model::Model;
use progmo::programme::Role;
use progmo::scene::Scene;
use progmo::solve::Evaluator;
use progmo::with_problem;

fn run() -> Result<(), String> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let split = args.last().is_some_and(|a| a == "--split");
    if split {
        args.pop();
    }
    let [path, rest @ ..] = args.as_slice() else {
        return Err("usage: rhs_profile SCENE.toml [ITERATIONS] [FORMULATION] [--split]".into());
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
        if !split {
            return Ok(());
        }
        // The split (module text): each part alone over the same loop.
        let per_call = |f: &mut dyn FnMut(usize)| {
            let start = std::time::Instant::now();
            for i in 0..iterations {
                f(i);
            }
            start.elapsed().as_secs_f64() / iterations as f64 * 1e6
        };
        let prepared = per_call(&mut |i| {
            ev.prepare(p.t0, states[i % 2], &p.v0);
            std::hint::black_box(&ev.jet.gamma);
        });
        let geometry = per_call(&mut |i| {
            ev.prepare_geometry(p.t0, states[i % 2], &p.v0);
            std::hint::black_box(&ev.jet.gamma);
        });
        let mut mass = ev.mass.clone();
        let mass_us = per_call(&mut |i| {
            p.model.mass_matrix(ev.model_workspace(), states[i % 2], &mut mass);
            std::hint::black_box(&mass);
        });
        let (mut force, mut qf) = (vec![0.0; p.v0.len()], vec![0.0; p.v0.len()]);
        let force_us = per_call(&mut |i| {
            p.model.natural_forces(ev.model_workspace(), p.t0, states[i % 2], &p.v0, &mut force, &mut qf);
            std::hint::black_box(&force);
        });
        println!(
            "  split: A {mass_us:.3} us, F {force_us:.3} us, jet {:.3} us, formulation {:.3} us \
             (A + F + jet prepared together: {prepared:.3} us)",
            geometry - mass_us,
            us - prepared
        );
    });
    Ok(())
}

fn main() {
    if let Err(e) = run() {
        eprintln!("rhs_profile: {e}");
        std::process::exit(2);
    }
}
