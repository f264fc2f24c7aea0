//! The right-hand side allocates nothing (issue requirement; Pinocchio's "hot paths must not
//! allocate"): a counting global allocator around repeated evaluations of every formulation, on a
//! Euclidean, a quaternion, an expression-based tree scene and a system with system constraints.
//! A module of the integration binary: the allocator serves every test, each counting on its
//! own thread's counter.

use progmo::formulation::{Formulation, RankTolerances};
use progmo::model::Model;
use progmo::problems::{particle, pendulum, rigid_body};
use progmo::programme::Constraints;
use progmo::solve::{Evaluator, Problem};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    // Per thread, so that tests running in parallel do not see each other's allocations.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn count() -> usize {
    ALLOCATIONS.with(|c| c.get())
}

fn bump() {
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        bump();
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        bump();
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations_per_evaluation<M: Model, C: Constraints>(p: &Problem<M, C>) -> usize {
    let mut worst = 0;
    for f in Formulation::ALL {
        let mut ev = Evaluator::<M, C, f64>::new(&p.model, &p.constraints);
        let tol = RankTolerances::default();
        ev.evaluate(f, &tol, None, p.t0, &p.q0, &p.v0).unwrap(); // warm-up
        let before = count();
        for k in 0..10 {
            ev.evaluate(f, &tol, None, p.t0 + 0.01 * k as f64, &p.q0, &p.v0)
                .unwrap();
        }
        let n = count() - before;
        if n > 0 {
            eprintln!("{f:?}: {n} allocations in 10 evaluations");
        }
        worst = worst.max(n);
    }
    worst
}

#[test]
fn right_hand_side_does_not_allocate() {
    assert_eq!(allocations_per_evaluation(&particle::example_2_1()), 0);
    assert_eq!(allocations_per_evaluation(&rigid_body::heavy_top()), 0);
    assert_eq!(allocations_per_evaluation(&pendulum::rod_and_swing()), 0);
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("references/scenes");
    // chain_8: the articulated-body factorization on a tree of hinges; heavy_top: on a ball joint
    // slider_crank: a lagrangian model (gradients of the mass entries and of the rows)
    for name in [
        "heavy_top",
        "double_pendulum",
        "example_2_1",
        "chain_8",
        "slider_crank",
    ] {
        let scene = progmo::scene::Scene::load(dir.join(format!("{name}.toml"))).unwrap();
        let n = progmo::with_problem!(&scene.system, p => allocations_per_evaluation(p));
        assert_eq!(n, 0, "{name}");
    }
}

/// Over dual numbers too (the Radau Jacobian evaluates the right-hand side over Dual64): the
/// articulated-body formulation on a tree allocates nothing.
#[test]
fn articulated_body_over_duals_does_not_allocate() {
    type D = progmo::scalar::Dual<f64>;
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("references/scenes");
    let scene = progmo::scene::Scene::load(dir.join("chain_8.toml")).unwrap();
    let n = progmo::with_problem!(&scene.system, p => {
        let mut ev = Evaluator::<_, _, D>::new(&p.model, &p.constraints);
        let q: Vec<D> = p.q0.iter().map(|&x| D::new(x, 1.0)).collect();
        let v: Vec<D> = p.v0.iter().map(|&x| D::from_re(x)).collect();
        let tol = RankTolerances::default();
        let f = Formulation::ArticulatedBody;
        ev.evaluate(f, &tol, None, D::from_re(p.t0), &q, &v).unwrap();
        let before = count();
        for k in 0..10 {
            ev.evaluate(f, &tol, None, D::from_re(p.t0 + 0.01 * k as f64), &q, &v)
                .unwrap();
        }
        count() - before
    });
    assert_eq!(n, 0);
}

#[test]
fn the_counter_counts() {
    // Negative control: an allocating call is seen.
    let before = count();
    let v = std::hint::black_box(vec![1u8; 100]);
    assert!(count() > before);
    drop(v);
}

/// The servo right-hand side (issue 31 item 2: u = H tau from the decoupling of the
/// index-reduced system, its Lie derivatives over nested duals) allocates nothing once its
/// workspaces exist: every bundled scene with `[[actuators]]` (found by reading the scene files).
#[test]
fn servo_right_hand_side_does_not_allocate() {
    let dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("references/scenes");
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter(|p| {
            let text = std::fs::read_to_string(p).unwrap();
            text.lines().any(|l| l.trim() == "[[actuators]]")
        })
        .collect();
    paths.sort();
    let mut servo = vec![];
    for path in paths {
        let scene = progmo::scene::Scene::load(&path).unwrap();
        let n = progmo::with_problem!(&scene.system, p => (|| {
            let act = p.constraints.actuation()?;
            let an = progmo::servo::Servo::new(&p.model, &p.constraints, act)
                .analyse(p.t0, &p.q0, &p.v0, 1e-10)
                .unwrap();
            let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
            ev.set_servo(an.degrees.clone(), an.b_norms.clone(), an.reduction.clone());
            let tol = RankTolerances::default();
            let f = Formulation::Auto;
            ev.evaluate(f, &tol, None, p.t0, &p.q0, &p.v0).unwrap(); // warm-up
            // ten states near the initial one (made before counting)
            let vs: Vec<Vec<f64>> = (0..10)
                .map(|k| p.v0.iter().map(|x| x + 1e-3 * k as f64).collect())
                .collect();
            let before = count();
            for (k, v) in vs.iter().enumerate() {
                ev.evaluate(f, &tol, None, p.t0 + 0.01 * k as f64, &p.q0, v).unwrap();
            }
            Some(count() - before)
        })());
        if let Some(n) = n {
            servo.push(path.file_stem().unwrap().to_string_lossy().into_owned());
            assert_eq!(
                n,
                0,
                "{}: {n} allocations in 10 evaluations",
                servo.last().unwrap()
            );
        }
    }
    // the scenes with actuators were found (the test judged something)
    assert!(servo.len() >= 6, "servo scenes found: {servo:?}");
}
