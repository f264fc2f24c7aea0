//! Fast paths of one evaluation, each against the straightforward computation it replaces.
//!
//! 1. The chain-rule jet of scene rows (`ExprConstraints::jet`: one `Dual2`/`Dual` pass per level
//!    and one `Dual` pass per slot entering B, signals from one set of tree passes) against the
//!    generic AD passes over the whole evaluation (`Jet::compute_generic`: nv `Dual` passes through
//!    the tree's forward kinematics): two independent ways to the same B, gamma, values and dg/dt.
//!
//! Scenes: every bundled scene, the generated chains, tests/scenes/all_signals.toml (every slot
//! kind at every level: hinge, ball and free joints, quasi-velocities, accelerations, body-point
//! positions, velocities, accelerations, orientation, angular velocity and acceleration) and
//! tests/scenes/affine_signals.toml (rows affine in signals at every level, with and without t).
//! 2. `Model::natural_forces` of tree scenes (one inverse-dynamics sweep for G and gravity) against
//!    `velocity_terms + applied_forces` (two sweeps), and the cached forward kinematics against a
//!    fresh workspace per call.
//! 3. One sweep per state (issue 15): the right-hand side whose constraint jet reads the model's
//!    forward passes (`Evaluator` default, `Model::tree_sweep`) against everything recomputed in
//!    fresh workspaces (A, F, the jet by its own passes, dv/dt and lambda of an evaluator with the
//!    sweep not shared), bit for bit, over f64 and dual numbers, on every scene and on random
//!    chains; and the pass counts that show the sweep is shared (one position and one velocity
//!    pass per state).
//! 5. Rows affine in signals (frame tasks, welds: `ExprConstraints` fast rows, B from the
//!    signals' Jacobian rows, and without t no pass over the expression) against the expression
//!    route of the same rows (`set_plain_passes`), on every scene.
//! 4. Lagrangian scenes: G (dA/dt and dA/dq_k of the mass entries) and -dV/dq from one gradient
//!    per expression (a reverse sweep over its tape) against one dual pass per direction, and B of
//!    the rows from one gradient per row against one dual pass per slot; over f64 and duals. Scenes:
//!    the car axis, both slider cranks and an inline double pendulum with a potential.
//!
//! States: the initial state and random states around it (quaternions renormalized). Tolerance:
//! round-off class, 1e3 eps relative to the largest entry of the compared quantity; the shared
//! sweep: none (the same operations on the same inputs).

use crate::common;

use progmo::formulation::{Formulation, RankTolerances};
use progmo::model::Model;
use progmo::programme::jet::Jet;
use progmo::programme::Constraints;
use progmo::scalar::{BitEq, Dual, Scalar};
use progmo::scene::chain::ChainSpec;
use progmo::scene::{Scene, SceneSystem};
use progmo::solve::{Evaluator, Problem};
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
    for name in ["all_signals.toml", "affine_signals.toml"] {
        out.push(
            Scene::load(root.join("tests/scenes").join(name)).unwrap_or_else(|e| panic!("{e}")),
        );
    }
    for name in ["caraxis.toml", "crank_rigid.toml"] {
        out.push(
            Scene::load(root.join("references/testset").join(name))
                .unwrap_or_else(|e| panic!("{e}")),
        );
    }
    for n in [2, 3, 7] {
        out.push(ChainSpec::uniform(n).scene().unwrap());
    }
    // joint armature, damping, springs and reference positions, body gravity compensation: an
    // MJCF robot with all of them (tests/robots/mjcf/dynamics.xml) and dressed random chains
    out.push(
        Scene::from_text(
            &root.join("tests/robots/mjcf/fast_paths_dynamics.toml"),
            DYNAMICS_MJCF,
        )
        .unwrap_or_else(|e| panic!("{e}")),
    );
    out.extend(dressed_chains(3, 0x9e37_79b9));
    out
}

/// An MJCF robot with armature, damping, springs, `ref` and gravcomp; its row holds at q0 = ref.
const DYNAMICS_MJCF: &str = r#"
name = "dynamics_mjcf"
[model]
kind = "mjcf"
file = "dynamics.xml"
gravity = [0.0, 0.0, -9.81]
[[programme]]
name = "lift"
expr = "shoulder - 0.5235987755982988 - 0.1*(1 - cos(t))"
[initial]
v = { elbow = 0.3, slide = -0.2 }
[time]
t1 = 1.0
"#;

/// Random chains whose joints carry armature, damping and springs and whose bodies carry
/// gravity compensation (from -0.5 to 1.5).
fn dressed_chains(count: usize, seed: u64) -> Vec<Scene> {
    let mut rng = Rng(seed);
    (0..count)
        .map(|i| {
            let n = 3 + ((rng.next() + 1.0) * 3.49) as usize;
            let spec = ChainSpec {
                masses: Some((0..n).map(|_| 0.3 + 0.25 * rng.next()).collect()),
                q0: Some(0.3 * rng.next()),
                name: Some(format!("dressed_{i}")),
                ..ChainSpec::uniform(n)
            };
            let mut text = String::new();
            for line in spec.toml().lines() {
                if line.starts_with("joints = ") {
                    let extra = format!(
                        ", armature = {:?}, damping = {:?}, stiffness = {:?}, spring_ref = {:?} }}]",
                        0.05 * (1.0 + rng.next()),
                        0.1 * (1.0 + rng.next()),
                        2.0 * (1.0 + rng.next()),
                        0.5 * rng.next()
                    );
                    text.push_str(&line.replacen(" }]", &extra, 1));
                } else if line.starts_with("mass = ") {
                    text.push_str(&format!("{line}\ngravcomp = {:?}", 0.5 + rng.next()));
                } else {
                    text.push_str(line);
                }
                text.push('\n');
            }
            let scene = Scene::from_text(std::path::Path::new(&format!("dressed_{i}.toml")), &text)
                .unwrap_or_else(|e| panic!("{e}"));
            let SceneSystem::Tree(p) = &scene.system else {
                panic!("a tree scene")
            };
            let tree = p.model.tree();
            assert!(tree.joints().iter().all(|j| j.armature > 0.0 && j.stiffness > 0.0));
            assert!(tree.bodies().iter().all(|b| b.gravcomp != 0.0));
            scene
        })
        .collect()
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

/// Random chains: 3 to 12 links, random masses, length and initial bend.
fn random_chains(count: usize, seed: u64) -> Vec<Scene> {
    let mut rng = Rng(seed);
    (0..count)
        .map(|_| {
            let n = 3 + ((rng.next() + 1.0) * 4.99) as usize;
            let spec = ChainSpec {
                masses: Some((0..n).map(|_| 0.3 + 0.25 * rng.next()).collect()),
                length: 0.25 + 0.15 * rng.next(),
                q0: Some(0.3 * rng.next()),
                ..ChainSpec::uniform(n)
            };
            spec.scene().unwrap()
        })
        .collect()
}

/// First index where the bits differ (every dual part), if any.
fn differ<S: BitEq>(a: &[S], b: &[S]) -> Option<usize> {
    assert_eq!(a.len(), b.len());
    (0..a.len()).find(|&i| !a[i].bit_eq(&b[i]))
}

/// The sequence of states the shared-sweep tests walk: each random state, then a new q with the
/// same v (the velocity pass must not be reused on new positions), then a new v with the same q
/// (the position pass is, the velocity pass is not).
fn walk(states: &[(f64, Vec<f64>, Vec<f64>)]) -> Vec<(f64, Vec<f64>, Vec<f64>)> {
    let mut out = vec![];
    for w in states.windows(2) {
        let ((t0, q0, v0), (t1, q1, v1)) = (&w[0], &w[1]);
        out.push((*t0, q0.clone(), v0.clone()));
        out.push((*t1, q1.clone(), v0.clone()));
        out.push((*t1, q1.clone(), v1.clone()));
    }
    out
}

/// Everything the shared sweep touches, from the evaluator that shares it, against fresh
/// workspaces that recompute every pass; returns the number of states compared.
fn compare_shared_sweep<M: Model, C: Constraints, S: Scalar>(
    name: &str,
    p: &Problem<M, C>,
    states: &[(S, Vec<S>, Vec<S>)],
) -> usize {
    let (m, c) = (&p.model, &p.constraints);
    let (nv, tol) = (m.nv(), RankTolerances::default());
    let mut compared = 0;
    for f in [Formulation::NullSpace, Formulation::ArticulatedBody] {
        // one evaluator for the whole walk: its caches see every change of q and v
        let mut shared = Evaluator::<M, C, S>::new(m, c);
        for (t, q, v) in states {
            let (t, q, v) = (*t, &q[..], &v[..]);
            let r = shared.evaluate(f, &tol, None, t, q, v);
            let mut plain = Evaluator::<M, C, S>::new(m, c);
            plain.set_shared_sweep(false);
            let r0 = plain.evaluate(f, &tol, None, t, q, v);
            assert_eq!(r.is_ok(), r0.is_ok(), "{name} {f:?}: {r:?} vs {r0:?}");
            if r.is_err() {
                continue;
            }
            let mut fresh_jet = Jet::<C, S>::new(c, m.segments(), m.nq(), m.nv());
            fresh_jet.compute(c, m.segments(), t, q, v);
            let (mut force, mut scratch) = (vec![S::zero(); nv], vec![S::zero(); nv]);
            m.natural_forces(&mut m.workspace(), t, q, v, &mut force, &mut scratch);
            let mut checks = vec![
                ("F", differ(&shared.force, &force)),
                ("B", differ(shared.jet.b.as_slice(), fresh_jet.b.as_slice())),
                ("gamma", differ(&shared.jet.gamma, &fresh_jet.gamma)),
                ("value", differ(&shared.jet.value, &fresh_jet.value)),
                ("gdot", differ(&shared.jet.gdot, &fresh_jet.gdot)),
                ("dv/dt", differ(&shared.acc, &plain.acc)),
                ("lambda", differ(&shared.lambda, &plain.lambda)),
            ];
            if f == Formulation::NullSpace {
                let mut a = nalgebra::DMatrix::from_element(nv, nv, S::zero());
                m.mass_matrix(&mut m.workspace(), q, &mut a);
                checks.push(("A", differ(shared.mass.as_slice(), a.as_slice())));
            }
            for (what, d) in checks {
                assert!(
                    d.is_none(),
                    "{name} {f:?}: {what} differs at entry {d:?}, t = {}",
                    t.re()
                );
            }
            compared += 1;
        }
    }
    compared
}

#[test]
fn shared_sweep_equals_the_plain_computation_bit_for_bit() {
    let mut compared = 0;
    let mut all = scenes();
    all.extend(random_chains(6, 0x2545f4914f6cdd1d));
    all.extend(dressed_chains(3, 0x7f4a_7c15));
    for scene in all {
        with_problem!(&scene.system, p => {
            let states = walk(&states(&p.model, &p.q0, &p.v0, 6, 11));
            compared += compare_shared_sweep(&scene.name, p, &states);
        });
    }
    assert!(compared >= 20 * 2 * 18, "compared {compared} states");
}

/// Over dual numbers (the implicit integrator's Jacobians): the passes are reused only when every
/// dual part is unchanged; the walk also changes only the derivative parts of q and v (the real
/// parts, which `==` compares, stay the same).
#[test]
fn shared_sweep_equals_the_plain_computation_over_dual_numbers() {
    type D = Dual<f64>;
    let mut compared = 0;
    let mut all = scenes();
    all.extend(random_chains(3, 0x51a3));
    for scene in all {
        with_problem!(&scene.system, p => {
            let mut rng = Rng(5);
            let mut seeded = vec![];
            for (t, q, v) in walk(&states(&p.model, &p.q0, &p.v0, 3, 23)) {
                for _ in 0..2 {
                    let td = D::new(t, rng.next());
                    let qd: Vec<D> = q.iter().map(|&x| D::new(x, rng.next())).collect();
                    let vd: Vec<D> = v.iter().map(|&x| D::new(x, rng.next())).collect();
                    seeded.push((td, qd, vd));
                }
            }
            compared += compare_shared_sweep(&scene.name, p, &seeded);
        });
    }
    assert!(compared >= 20 * 2 * 12, "compared {compared} states");
}

/// The sweep is shared: per new state one position pass and one velocity pass on the model's
/// workspace, which the forces and the constraint jet reuse; without sharing the jet's passes are
/// its own (the model's velocity pass is never reused). Over f64 and dual numbers.
#[test]
fn one_position_and_one_velocity_pass_per_state() {
    fn count<S: Scalar>(shared: bool, lift: impl Fn(f64, f64) -> S) -> progmo::tree::SweepPasses {
        let scene = ChainSpec::uniform(7).scene().unwrap();
        with_problem!(&scene.system, p => {
            let mut ev = Evaluator::<_, _, S>::new(&p.model, &p.constraints);
            ev.set_shared_sweep(shared);
            let tol = RankTolerances::default();
            for k in 0..5 {
                let d = 1e-3 * k as f64;
                let q: Vec<S> = p.q0.iter().map(|&x| lift(x + d, d)).collect();
                let v: Vec<S> = p.v0.iter().map(|&x| lift(x + d, 1.0)).collect();
                ev.evaluate(Formulation::NullSpace, &tol, None, lift(0.1, 0.0), &q, &v).unwrap();
            }
            p.model.tree_sweep(ev.model_workspace()).unwrap().data.passes()
        })
    }
    let f = |x: f64, _| x;
    let d = |x: f64, e: f64| Dual::new(x, e);
    for (kind, on, off) in [
        ("f64", count::<f64>(true, f), count::<f64>(false, f)),
        (
            "dual",
            count::<Dual<f64>>(true, d),
            count::<Dual<f64>>(false, d),
        ),
    ] {
        // positions: the mass matrix; reused by the forces and the jet (2 per state)
        assert_eq!(
            (on.positions, on.positions_reused),
            (5, 10),
            "{kind}: {on:?}"
        );
        assert_eq!(
            (on.velocities, on.velocities_reused),
            (5, 5),
            "{kind}: {on:?}"
        );
        assert_eq!(
            (off.positions, off.positions_reused),
            (5, 5),
            "{kind}: {off:?}"
        );
        assert_eq!(
            (off.velocities, off.velocities_reused),
            (5, 0),
            "{kind}: {off:?}"
        );
    }
}

/// The reuse test compares every dual part: a q differing only in its derivative part reruns the
/// position pass (with `==`, which compares real parts, it would not).
#[test]
fn a_change_in_a_dual_part_alone_reruns_the_passes() {
    let scene = ChainSpec::uniform(3).scene().unwrap();
    with_problem!(&scene.system, p => {
        let tree = p.model.tree_sweep(&mut p.model.workspace::<f64>()).unwrap().model.clone();
        let mut data = tree.data::<Dual<f64>>();
        let q1: Vec<Dual<f64>> = p.q0.iter().map(|&x| Dual::new(x, 1.0)).collect();
        let q2: Vec<Dual<f64>> = p.q0.iter().map(|&x| Dual::new(x, 2.0)).collect();
        assert!(q1[0] == q2[0], "== compares real parts");
        progmo::tree::forward_kinematics(&tree, &mut data, &q1);
        progmo::tree::forward_kinematics(&tree, &mut data, &q1);
        progmo::tree::forward_kinematics(&tree, &mut data, &q2);
        let n = data.passes();
        assert_eq!((n.positions, n.positions_reused), (2, 1), "{n:?}");
    });
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

/// Fast rows (B = sum c_k J_k; value and derivatives from the signals' jets when the row reads no
/// t) against the expression route of the same rows, on every scene at random states, over f64
/// and dual numbers; the rows that take the fast route are counted where the scene says which
/// (the Panda's six frame-task rows, four without t; the humanoid's 12 weld rows and six
/// centre-of-mass and level rows, all affine, two with t; the test
/// scene's four affine rows at three levels, three without t, and its product row not).
#[test]
fn fast_rows_equal_the_expression_route() {
    type D = Dual<f64>;
    let mut counted = std::collections::BTreeMap::new();
    for scene in scenes() {
        with_problem!(&scene.system, p => {
            let (m, fast) = (&p.model, &p.constraints);
            counted.insert(scene.name.clone(), fast.fast_rows());
            let mut plain = fast.clone();
            plain.set_plain_passes(true);
            let (nq, nv) = (m.nq(), m.nv());
            let mut jf = Jet::<_, f64>::new(fast, m.segments(), nq, nv);
            let mut jp = Jet::<_, f64>::new(&plain, m.segments(), nq, nv);
            let mut jfd = Jet::<_, D>::new(fast, m.segments(), nq, nv);
            let mut jpd = Jet::<_, D>::new(&plain, m.segments(), nq, nv);
            let mut rng = Rng(0xfa57);
            for (t, q, v) in states(m, &p.q0, &p.v0, 4, 17) {
                jf.compute(fast, m.segments(), t, &q, &v);
                jp.compute(&plain, m.segments(), t, &q, &v);
                let td = D::new(t, rng.next());
                let qd: Vec<D> = q.iter().map(|&x| D::new(x, rng.next())).collect();
                let vd: Vec<D> = v.iter().map(|&x| D::new(x, rng.next())).collect();
                jfd.compute(fast, m.segments(), td, &qd, &vd);
                jpd.compute(&plain, m.segments(), td, &qd, &vd);
                let re = |x: &[D]| x.iter().map(|d| d.re).collect::<Vec<_>>();
                let eps = |x: &[D]| x.iter().map(|d| d.eps).collect::<Vec<_>>();
                for (what, a, b) in [
                    ("B", jp.b.as_slice().to_vec(), jf.b.as_slice().to_vec()),
                    ("gamma", jp.gamma.to_vec(), jf.gamma.to_vec()),
                    ("value", jp.value.to_vec(), jf.value.to_vec()),
                    ("gdot", jp.gdot.to_vec(), jf.gdot.to_vec()),
                    ("B (dual)", eps(jpd.b.as_slice()), eps(jfd.b.as_slice())),
                    ("gamma (dual)", eps(&jpd.gamma), eps(&jfd.gamma)),
                    ("gamma (dual, re)", re(&jpd.gamma), re(&jfd.gamma)),
                    ("value (dual)", eps(&jpd.value), eps(&jfd.value)),
                ] {
                    let err = rel(&a, &b);
                    assert!(err <= TOL, "{}: {what} differs by {err:.2e}", scene.name);
                }
            }
        });
    }
    for (name, want) in [
        ("panda_circle", (6, 4)),
        ("talos_com_shift", (18, 16)),
        ("affine_signals", (4, 3)),
        ("all_signals", (0, 0)),
    ] {
        assert_eq!(counted.get(name), Some(&want), "{name}: {counted:?}");
    }
}
