//! Criterion benchmarks of the solver core on the shared test problems: one right-hand side
//! (accelerations and multipliers) per formulation (chains up to n = 128 for the articulated-body
//! formulation), the shared sweep against the plain passes (`sweep/`), lagrangian scenes' right-hand
//! side (car axis, slider crank), whole solves and the servo right-hand side (`servo_rhs/`: Taylor
//! series against nested dual numbers).
//!
//! Run: `cargo bench --bench core` (one group: `cargo bench --bench core -- sweep/`, `-- lagrangian` or `-- servo_rhs`).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use progmo::formulation::{Formulation, RankTolerances};
use progmo::integrate::Method;
use progmo::model::Model;
use progmo::problems::{hard, particle, pendulum, rigid_body};
use progmo::programme::Constraints;
use progmo::scalar::{Dual, Scalar};
use progmo::scene::chain;
use progmo::solve::{
    solve, solve_into, DriftControl, Evaluator, Output, Problem, Sample, SampleSink, Settings,
};
use std::hint::black_box;

fn rhs_group<M: Model, C: Constraints>(c: &mut Criterion, name: &str, p: &Problem<M, C>) {
    rhs_group_of(c, name, p, &Formulation::ALL)
}

fn rhs_group_of<M: Model, C: Constraints>(
    c: &mut Criterion,
    name: &str,
    p: &Problem<M, C>,
    formulations: &[Formulation],
) {
    let mut g = c.benchmark_group(format!("rhs/{name}"));
    for &f in formulations {
        let mut ev = Evaluator::<M, C, f64>::new(&p.model, &p.constraints);
        let tol = RankTolerances::default();
        // Two nearby states, alternated: every evaluation is at a new q, as in a solve (nothing
        // cached from the previous call can be reused).
        let qb: Vec<f64> = p.q0.iter().map(|x| x + 1e-9).collect();
        let states = [&p.q0, &qb];
        let mut k = 0usize;
        g.bench_function(BenchmarkId::from_parameter(format!("{f:?}")), |b| {
            b.iter(|| {
                k ^= 1;
                ev.evaluate(
                    f,
                    &tol,
                    None,
                    black_box(0.1),
                    black_box(states[k]),
                    black_box(&p.v0),
                )
                .unwrap();
                black_box(ev.acc[0])
            })
        });
    }
    g.finish();
}

fn rhs(c: &mut Criterion) {
    rhs_group(c, "example_2_1", &particle::example_2_1());
    rhs_group(c, "heavy_top", &rigid_body::heavy_top());
    rhs_group(c, "double_pendulum", &pendulum::double_pendulum());
    // generated tree scenes (expression rows, a body-point signal): the sizes of issue 5's targets,
    // and of issue 15's (the articulated-body formulation against the dense ones up to n = 128)
    for n in [7, 30] {
        let scene = chain::ChainSpec::uniform(n)
            .scene()
            .expect("generated chain loads");
        progmo::with_problem!(&scene.system, p => rhs_group(c, &format!("chain_{n}"), p));
    }
    let long = [
        Formulation::NullSpace,
        Formulation::Kkt,
        Formulation::ArticulatedBody,
    ];
    for n in [64, 128] {
        let scene = chain::ChainSpec::uniform(n)
            .scene()
            .expect("generated chain loads");
        progmo::with_problem!(&scene.system, p => rhs_group_of(c, &format!("chain_{n}"), p, &long));
    }
}

/// One sweep per state (issue 15): the right-hand side with the constraint jet reading the model's
/// forward passes (`shared`) and with its own passes (`plain`, the computation before the sweep
/// was shared), on generated chains (a tip-height signal row), over f64 and over dual numbers
/// (what the implicit integrator differentiates).
fn sweep(c: &mut Criterion) {
    for n in [7, 30, 64] {
        let scene = chain::ChainSpec::uniform(n)
            .scene()
            .expect("generated chain loads");
        progmo::with_problem!(&scene.system, p => {
            sweep_group::<_, _, f64>(c, &format!("sweep/chain_{n}"), p, Formulation::NullSpace);
            sweep_group::<_, _, f64>(c, &format!("sweep/chain_{n}"), p, Formulation::ArticulatedBody);
            if n == 7 {
                sweep_group::<_, _, Dual<f64>>(c, &format!("sweep/chain_{n}/dual"), p, Formulation::NullSpace);
            }
        });
    }
}

fn sweep_group<M: Model, C: Constraints, S: Scalar>(
    c: &mut Criterion,
    name: &str,
    p: &Problem<M, C>,
    f: Formulation,
) {
    let mut g = c.benchmark_group(name);
    let tol = RankTolerances::default();
    let lift = |x: &[f64], d: f64| -> Vec<S> { x.iter().map(|&y| S::from(y + d)).collect() };
    let states = [lift(&p.q0, 0.0), lift(&p.q0, 1e-9)];
    let v = lift(&p.v0, 0.0);
    for (label, shared) in [("shared", true), ("plain", false)] {
        let mut ev = Evaluator::<M, C, S>::new(&p.model, &p.constraints);
        ev.set_shared_sweep(shared);
        let mut k = 0usize;
        g.bench_function(BenchmarkId::new(format!("{f:?}"), label), |b| {
            b.iter(|| {
                k ^= 1; // a new q at every call, as in a solve
                ev.evaluate(
                    f,
                    &tol,
                    None,
                    S::from(0.1),
                    black_box(&states[k]),
                    black_box(&v),
                )
                .unwrap();
                black_box(ev.acc[0])
            })
        });
    }
    g.finish();
}

fn whole_solves(c: &mut Criterion) {
    let mut g = c.benchmark_group("solve");
    g.sample_size(10);
    let s = Settings::default();
    let p = particle::example_2_1();
    g.bench_function("example_2_1/dop853/projection", |b| {
        b.iter(|| black_box(solve(&p, &s)))
    });
    let p = rigid_body::heavy_top();
    g.bench_function("heavy_top/dop853/projection", |b| {
        b.iter(|| black_box(solve(&p, &s)))
    });
    let p = pendulum::double_pendulum();
    g.bench_function("double_pendulum/dop853/projection", |b| {
        b.iter(|| black_box(solve(&p, &s)))
    });
    g.finish();
}

/// Drops every sample: the solve's own work only.
struct Discard;
impl SampleSink for Discard {
    fn sample(&mut self, _: &Sample<'_>) {}
}

/// Cost of drift control over 10^4 periods (issue target: projection within 15 % of no projection;
/// residuals are checked by tests/hard_cases.rs case 6).
fn drift(c: &mut Criterion) {
    let mut g = c.benchmark_group("drift/ten_thousand_periods");
    g.sample_size(10);
    let p = hard::ten_thousand_periods();
    for (name, d) in [
        (
            "projection",
            DriftControl::Projection {
                tol: 1e-12,
                max_iter: 8,
            },
        ),
        ("none", DriftControl::None),
    ] {
        let s = Settings {
            rtol: 1e-8,
            atol: 1e-10,
            drift: d,
            ..Settings::default()
        };
        g.bench_function(name, |b| {
            b.iter(|| black_box(solve_into(&p, &s, &mut Discard).t_end))
        });
    }
    g.finish();
}

/// Lagrangian scenes (expression A, forces, rows): one RHS at the scene's own formulation, and the
/// car axis solved with DOP853 at rtol = atol = 1e-10 (8.4 digits; the bench's testset part).
fn lagrangian(c: &mut Criterion) {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("references");
    let scenes = [
        ("caraxis", root.join("testset/caraxis.toml")),
        ("slider_crank", root.join("scenes/slider_crank.toml")),
    ];
    let mut g = c.benchmark_group("rhs_lagrangian");
    for (name, path) in &scenes {
        let scene = progmo::scene::Scene::load(path).expect("bundled scene loads");
        let f = scene.settings.formulation;
        progmo::with_problem!(&scene.system, p => {
            let mut ev = Evaluator::new(&p.model, &p.constraints);
            let tol = RankTolerances::default();
            let qb: Vec<f64> = p.q0.iter().map(|x| x + 1e-9).collect();
            let states = [&p.q0, &qb];
            let mut k = 0usize;
            g.bench_function(*name, |b| {
                b.iter(|| {
                    k ^= 1;
                    ev.evaluate(f, &tol, None, black_box(0.1), black_box(states[k]), black_box(&p.v0))
                        .unwrap();
                    black_box(ev.acc[0])
                })
            });
        });
    }
    g.finish();
    let mut g = c.benchmark_group("solve_lagrangian");
    g.sample_size(10);
    let scene = progmo::scene::Scene::load(&scenes[0].1).expect("car axis loads");
    progmo::with_problem!(&scene.system, p => {
        let s = Settings {
            rtol: 1e-10,
            atol: 1e-10,
            integrator: Method::Dop853,
            output: Output::Every(p.t1 - p.t0),
            ..scene.settings.clone()
        };
        g.bench_function("caraxis/dop853/1e-10", |b| {
            b.iter(|| black_box(solve_into(p, &s, &mut Discard).t_end))
        });
    });
    g.finish();
}

/// The servo right-hand side (tau by the decoupling, then dv/dt = A^-1 (F + H tau)) of the bundled
/// servo scenes at t0, its Lie derivatives by univariate Taylor series (`series`, the default) and
/// by nested dual numbers (`nested`): the A/B of the series in one binary.
fn servo(c: &mut Criterion) {
    use progmo::scene::{Scene, SceneSystem};
    use progmo::servo::{Servo, WorkCache};
    let mut g = c.benchmark_group("servo_rhs");
    for name in [
        "two_car_chain",
        "thruster_cars",
        "overhead_crane",
        "passive_arm",
    ] {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join(format!("references/scenes/{name}.toml"));
        let text = std::fs::read_to_string(&path).expect("a bundled scene");
        let scene = Scene::from_text(&path, &text).expect("it loads");
        let an = scene
            .servo_analysis()
            .expect("actuated")
            .expect("realizable");
        let SceneSystem::Tree(p) = &scene.system else {
            panic!("{name}: a tree scene")
        };
        let act = p.constraints.actuation().expect("actuators");
        let (s, m) = (an.degrees.len(), act.len());
        for (label, series) in [("series", true), ("nested", false)] {
            let work = WorkCache::default();
            let servo = Servo::new(&p.model, &p.constraints, act)
                .reduced(an.reduction.as_ref())
                .cached(&work)
                .taylor(series);
            let (mut tau, mut acc) = (vec![0.0; s.max(m)], vec![0.0; p.q0.len()]);
            g.bench_function(BenchmarkId::new(label, name), |b| {
                b.iter(|| {
                    servo
                        .solve(
                            p.t0,
                            &p.q0,
                            &p.v0,
                            &an.degrees,
                            &an.b_norms,
                            1e-12,
                            &mut tau,
                            &mut acc,
                        )
                        .expect("realizable at t0");
                    black_box(acc[0])
                })
            });
        }
    }
    g.finish();
}

criterion_group!(benches, rhs, sweep, lagrangian, whole_solves, drift, servo);
criterion_main!(benches);
