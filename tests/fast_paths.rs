//! Fast paths of one evaluation, each against the straightforward computation it replaces.
//!
//! 1. The chain-rule jet of scene rows (`ExprConstraints::jet`: one `Dual2`/`Dual` pass per level
//!    and one `Dual` pass per slot entering B, signals from one set of tree passes) against the
//!    generic AD passes over the whole evaluation (`Jet::compute_generic`: nv `Dual` passes through
//!    the tree's forward kinematics): two independent ways to the same B, gamma, values and dg/dt.
//!
//! Scenes: every bundled scene, the generated chains, and tests/scenes/all_signals.toml (every slot
//! kind at every level: hinge, ball and free joints, quasi-velocities, accelerations, body-point
//! positions, velocities, accelerations, orientation, angular velocity and acceleration).
//! 2. `Model::natural_forces` of tree scenes (one inverse-dynamics sweep for G and gravity) against
//!    `velocity_terms + applied_forces` (two sweeps), and the cached forward kinematics against a
//!    fresh workspace per call.
//! 3. Lagrangian scenes: G (dA/dt and dA/dq_k of the mass entries) and -dV/dq from one gradient
//!    per expression (a reverse sweep over its tape) against one dual pass per direction, and B of
//!    the rows from one gradient per row against one dual pass per slot; over f64 and duals. Scenes:
//!    the car axis, both slider cranks and an inline double pendulum with a potential.
//!
//! States: the initial state and random states around it (quaternions renormalized). Tolerance:
//! round-off class, 1e3 eps relative to the largest entry of the compared quantity.

mod common;

use progmo::model::Model;
use progmo::problems::chain::ChainSpec;
use progmo::programme::jet::Jet;
use progmo::programme::Constraints;
use progmo::scalar::Dual;
use progmo::scene::{Scene, SceneSystem};
use progmo::with_problem;
use std::path::PathBuf;

const TOL: f64 = 1e3 * f64::EPSILON;

/// Small deterministic generator (xorshift), uniform in [-1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

fn scenes() -> Vec<Scene> {
    common::robot_path();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut out: Vec<Scene> = std::fs::read_dir(root.join("references/scenes"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .map(|p| Scene::load(&p).unwrap_or_else(|e| panic!("{e}")))
        .collect();
    out.push(
        Scene::load(root.join("tests/scenes/all_signals.toml")).unwrap_or_else(|e| panic!("{e}")),
    );
    for name in ["caraxis.toml", "crank_rigid.toml"] {
        out.push(
            Scene::load(root.join("references/testset").join(name))
                .unwrap_or_else(|e| panic!("{e}")),
        );
    }
    for n in [2, 3, 7] {
        out.push(ChainSpec::uniform(n).scene().unwrap());
    }
    out
}

/// A double pendulum as a lagrangian scene: full mass matrix in q, a potential, one programme row.
const PENDULUM: &str = r#"
name = "lagrangian_pendulum"
description = "double pendulum, lagrangian form"
purpose = "tests/fast_paths.rs: mass entries in q and a potential"
[parameters]
m1 = 1.3
m2 = 0.7
l1 = 0.9
l2 = 0.6
g = 9.81
[model]
kind = "lagrangian"
coordinates = ["a", "b"]
mass_matrix = [
  ["(m1 + m2)*l1^2",       "m2*l1*l2*cos(a - b)"],
  ["m2*l1*l2*cos(a - b)",  "m2*l2^2"],
]
potential = "-(m1 + m2)*g*l1*cos(a) - m2*g*l2*cos(b)"
[[programme]]
name = "sum"
expr = "a + b - 0.5*sin(2*t)"
[initial]
q = { a = 0.3, b = -0.3 }
v = { a = 0.6, b = 0.4 }
[time]
t1 = 1.0
"#;

fn lagrangian_scenes() -> Vec<Scene> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut out: Vec<Scene> = [
        "references/testset/caraxis.toml",
        "references/testset/crank_rigid.toml",
        "references/scenes/slider_crank.toml",
    ]
    .iter()
    .map(|p| Scene::load(root.join(p)).unwrap_or_else(|e| panic!("{e}")))
    .collect();
    out.push(
        Scene::from_text(&root.join("lagrangian_pendulum.toml"), PENDULUM)
            .unwrap_or_else(|e| panic!("{e}")),
    );
    out
}

fn max_abs(x: impl IntoIterator<Item = f64>) -> f64 {
    x.into_iter().fold(0.0, |m, y| m.max(y.abs()))
}

/// Largest difference relative to the largest entry (floored at 1).
fn rel(a: &[f64], b: &[f64]) -> f64 {
    let scale = max_abs(a.iter().copied()).max(1.0);
    max_abs(a.iter().zip(b).map(|(x, y)| x - y)) / scale
}

/// States: the initial one, then random perturbations (quaternion blocks renormalized by the
/// model's own retraction: perturb through delta on the chart).
fn states<M: Model>(
    m: &M,
    q0: &[f64],
    v0: &[f64],
    count: usize,
    seed: u64,
) -> Vec<(f64, Vec<f64>, Vec<f64>)> {
    let mut rng = Rng(seed);
    let mut out = vec![(0.1, q0.to_vec(), v0.to_vec())];
    for _ in 0..count {
        let delta: Vec<f64> = (0..m.nv()).map(|_| 0.3 * rng.next()).collect();
        let mut q = vec![0.0; m.nq()];
        progmo::model::retract(m.segments(), q0, &delta, &mut q);
        let v: Vec<f64> = v0.iter().map(|x| x + rng.next()).collect();
        out.push((rng.next(), q, v));
    }
    out
}

#[test]
fn chain_rule_jet_matches_the_generic_ad_passes_on_every_scene() {
    let mut compared = 0;
    for scene in scenes() {
        with_problem!(&scene.system, p => {
            let (m, c) = (&p.model, &p.constraints);
            let mut fast = Jet::<_, f64>::new(c, m.segments(), m.nq(), m.nv());
            let mut slow = Jet::<_, f64>::new(c, m.segments(), m.nq(), m.nv());
            for (t, q, v) in states(m, &p.q0, &p.v0, 20, 0x9e3779b97f4a7c15) {
                fast.compute(c, m.segments(), t, &q, &v);
                slow.compute_generic(c, m.segments(), t, &q, &v);
                let what = [
                    ("B", rel(slow.b.as_slice(), fast.b.as_slice())),
                    ("gamma", rel(&slow.gamma, &fast.gamma)),
                    ("value", rel(&slow.value, &fast.value)),
                    ("gdot", rel(&slow.gdot, &fast.gdot)),
                ];
                for (name, err) in what {
                    assert!(err <= TOL, "{}: {name} differs by {err:.2e} at t = {t}, q = {q:?}, v = {v:?}", scene.name);
                }
                compared += 1;
            }
            assert!(!c.rows().is_empty(), "{}: no rows", scene.name);
        });
    }
    assert!(compared >= 14 * 21, "compared {compared} states");
}

/// The same over dual numbers (what the implicit integrator differentiates): value and derivative
/// parts agree.
#[test]
fn chain_rule_jet_matches_the_generic_ad_passes_over_dual_numbers() {
    type D = Dual<f64>;
    for scene in scenes() {
        with_problem!(&scene.system, p => {
            let (m, c) = (&p.model, &p.constraints);
            let mut fast = Jet::<_, D>::new(c, m.segments(), m.nq(), m.nv());
            let mut slow = Jet::<_, D>::new(c, m.segments(), m.nq(), m.nv());
            let mut rng = Rng(17);
            for (t, q, v) in states(m, &p.q0, &p.v0, 4, 99) {
                // seed a random direction in (t, q, v) (q only along Euclidean-safe directions:
                // the jets are compared as functions, quaternion norm does not matter here)
                let td = D::new(t, rng.next());
                let qd: Vec<D> = q.iter().map(|&x| D::new(x, rng.next())).collect();
                let vd: Vec<D> = v.iter().map(|&x| D::new(x, rng.next())).collect();
                fast.compute(c, m.segments(), td, &qd, &vd);
                slow.compute_generic(c, m.segments(), td, &qd, &vd);
                let parts = |x: &[D]| -> (Vec<f64>, Vec<f64>) { (x.iter().map(|d| d.re).collect(), x.iter().map(|d| d.eps).collect()) };
                for (name, a, b) in [
                    ("B", slow.b.as_slice(), fast.b.as_slice()),
                    ("gamma", &slow.gamma[..], &fast.gamma[..]),
                ] {
                    let (ar, ae) = parts(a);
                    let (br, be) = parts(b);
                    let err = rel(&ar, &br).max(rel(&ae, &be));
                    assert!(err <= 1e4 * f64::EPSILON, "{}: {name} (dual) differs by {err:.2e}", scene.name);
                }
            }
        });
    }
}

/// Negative control: the comparison sees a wrong Jacobian (a perturbed B entry, a dropped
/// Jacobian term) — the tolerance is not so loose that anything passes.
#[test]
fn the_comparison_detects_a_wrong_jet() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let scene = Scene::load(root.join("tests/scenes/all_signals.toml")).unwrap();
    with_problem!(&scene.system, p => {
        let (m, c) = (&p.model, &p.constraints);
        let mut fast = Jet::<_, f64>::new(c, m.segments(), m.nq(), m.nv());
        let mut slow = Jet::<_, f64>::new(c, m.segments(), m.nq(), m.nv());
        fast.compute(c, m.segments(), 0.2, &p.q0, &p.v0);
        slow.compute_generic(c, m.segments(), 0.2, &p.q0, &p.v0);
        assert!(rel(slow.b.as_slice(), fast.b.as_slice()) <= TOL);
        fast.b[(0, 3)] *= 1.0 + 1e-9;
        assert!(rel(slow.b.as_slice(), fast.b.as_slice()) > TOL);
        // every row has a nonzero B row and gamma (the scene exercises every term)
        for i in 0..c.rows().len() {
            assert!(max_abs(slow.b.row(i).iter().copied()) > 1e-3, "row {i} has no Jacobian");
            assert!(slow.gamma[i].abs() > 1e-6, "row {i} has no gamma");
        }
    });
}

/// G + Q from one sweep equals the two separate sweeps; a workspace reused across states (forward
/// kinematics cached while q is unchanged) gives what a fresh workspace gives.
#[test]
fn natural_forces_and_cached_kinematics_match_the_plain_computation() {
    let mut compared = 0;
    for scene in scenes() {
        with_problem!(&scene.system, p => {
            let m = &p.model;
            let nv = m.nv();
            let mut ws = m.workspace::<f64>();
            for (t, q, v) in states(m, &p.q0, &p.v0, 10, 7) {
                for _repeat in 0..2 {
                    let (mut f, mut scratch) = (vec![0.0; nv], vec![0.0; nv]);
                    m.natural_forces(&mut ws, t, &q, &v, &mut f, &mut scratch);
                    let mut a = nalgebra::DMatrix::zeros(nv, nv);
                    m.mass_matrix(&mut ws, &q, &mut a);
                    let mut fresh = m.workspace::<f64>();
                    let (mut g, mut qf) = (vec![0.0; nv], vec![0.0; nv]);
                    m.velocity_terms(&mut fresh, &q, &v, &mut g);
                    m.applied_forces(&mut fresh, t, &q, &v, &mut qf);
                    let sum: Vec<f64> = g.iter().zip(&qf).map(|(x, y)| x + y).collect();
                    let mut a2 = nalgebra::DMatrix::zeros(nv, nv);
                    m.mass_matrix(&mut m.workspace::<f64>(), &q, &mut a2);
                    let ef = rel(&sum, &f);
                    let ea = rel(a2.as_slice(), a.as_slice());
                    assert!(ef <= TOL && ea <= TOL, "{}: G + Q differs by {ef:.2e}, A by {ea:.2e}", scene.name);
                    compared += 1;
                }
            }
        });
    }
    assert!(compared > 100);
}

/// G, Q and B of lagrangian scenes: gradients (the default) against one dual pass per direction.
#[test]
fn lagrangian_gradients_match_the_dual_passes() {
    type D = Dual<f64>;
    let mut nontrivial_g = 0;
    for scene in lagrangian_scenes() {
        let SceneSystem::Lagrangian(p) = &scene.system else {
            panic!("{}: not lagrangian", scene.name);
        };
        let fast = &p.model;
        let mut plain = p.model.clone();
        plain.set_plain_passes(true);
        let fc = &p.constraints;
        let mut pc = p.constraints.clone();
        pc.set_plain_passes(true);
        let nv = fast.nv();
        let (mut wf, mut wp) = (fast.workspace::<f64>(), plain.workspace::<f64>());
        let (mut wfd, mut wpd) = (fast.workspace::<D>(), plain.workspace::<D>());
        let mut jf = Jet::<_, f64>::new(fc, fast.segments(), nv, nv);
        let mut jp = Jet::<_, f64>::new(&pc, fast.segments(), nv, nv);
        let mut jfd = Jet::<_, D>::new(fc, fast.segments(), nv, nv);
        let mut jpd = Jet::<_, D>::new(&pc, fast.segments(), nv, nv);
        let mut rng = Rng(5);
        for (t, q, v) in states(fast, &p.q0, &p.v0, 20, 3) {
            let (mut g1, mut g2) = (vec![0.0; nv], vec![0.0; nv]);
            fast.velocity_terms(&mut wf, &q, &v, &mut g1);
            plain.velocity_terms(&mut wp, &q, &v, &mut g2);
            let (mut f1, mut f2) = (vec![0.0; nv], vec![0.0; nv]);
            fast.applied_forces(&mut wf, t, &q, &v, &mut f1);
            plain.applied_forces(&mut wp, t, &q, &v, &mut f2);
            jf.compute(fc, fast.segments(), t, &q, &v);
            jp.compute(&pc, fast.segments(), t, &q, &v);
            for (what, a, b) in [
                ("G", &g2[..], &g1[..]),
                ("Q", &f2[..], &f1[..]),
                ("B", jp.b.as_slice(), jf.b.as_slice()),
                ("gamma", &jp.gamma[..], &jf.gamma[..]),
            ] {
                let err = rel(a, b);
                assert!(
                    err <= TOL,
                    "{}: {what} differs by {err:.2e} at q = {q:?}",
                    scene.name
                );
            }
            if max_abs(g2.iter().copied()) > 1e-3 {
                nontrivial_g += 1;
            }
            // over duals (the implicit integrator's Jacobian): value and derivative parts
            let td = D::new(t, rng.next());
            let qd: Vec<D> = q.iter().map(|&x| D::new(x, rng.next())).collect();
            let vd: Vec<D> = v.iter().map(|&x| D::new(x, rng.next())).collect();
            let (mut g1, mut g2) = (vec![D::from(0.0); nv], vec![D::from(0.0); nv]);
            fast.velocity_terms(&mut wfd, &qd, &vd, &mut g1);
            plain.velocity_terms(&mut wpd, &qd, &vd, &mut g2);
            let (mut f1, mut f2) = (vec![D::from(0.0); nv], vec![D::from(0.0); nv]);
            fast.applied_forces(&mut wfd, td, &qd, &vd, &mut f1);
            plain.applied_forces(&mut wpd, td, &qd, &vd, &mut f2);
            jfd.compute(fc, fast.segments(), td, &qd, &vd);
            jpd.compute(&pc, fast.segments(), td, &qd, &vd);
            let parts = |x: &[D]| -> (Vec<f64>, Vec<f64>) {
                (
                    x.iter().map(|d| d.re).collect(),
                    x.iter().map(|d| d.eps).collect(),
                )
            };
            for (what, a, b) in [
                ("G", &g2[..], &g1[..]),
                ("Q", &f2[..], &f1[..]),
                ("B", jpd.b.as_slice(), jfd.b.as_slice()),
            ] {
                let ((ar, ae), (br, be)) = (parts(a), parts(b));
                let err = rel(&ar, &br).max(rel(&ae, &be));
                assert!(
                    err <= TOL,
                    "{}: {what} (dual) differs by {err:.2e}",
                    scene.name
                );
            }
        }
    }
    // the mass entries of the cranks and the pendulum depend on q: G is not zero there
    assert!(nontrivial_g >= 3 * 20, "G nonzero at {nontrivial_g} states");
}
