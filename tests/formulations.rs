//! Instantaneous checks of the right-hand side: the four formulations against each other, the
//! ideality of u (2.7), exact constraint derivatives against closed forms, rank detection.
//!
//! Tolerance class: algebraic identities, in multiples of machine epsilon times the problem scale.

use progmo::formulation::{Formulation, FormulationError, RankTolerances};
use progmo::model::Model;
use progmo::problems::{particle, pendulum, rigid_body};
use progmo::programme::{Constraints, Role};
use progmo::solve::{Evaluator, Problem};

const EPS: f64 = f64::EPSILON;

/// Deterministic pseudo-random numbers in [-1, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        2.0 * ((self.0 >> 11) as f64 / (1u64 << 53) as f64) - 1.0
    }
}

fn accelerations<M: Model, C: Constraints>(
    p: &Problem<M, C>,
    f: Formulation,
    t: f64,
    q: &[f64],
    v: &[f64],
) -> (Vec<f64>, Vec<f64>, f64) {
    let mut ev = Evaluator::<M, C, f64>::new(&p.model, &p.constraints);
    ev.evaluate(f, &RankTolerances::default(), None, t, q, v)
        .expect("regular state");
    (ev.acc.clone(), ev.lambda.clone(), ev.diag.du)
}

fn max_abs(x: &[f64]) -> f64 {
    x.iter().fold(0.0, |m, y| m.max(y.abs()))
}

/// All formulations give the same dv/dt and lambda on well-conditioned states.
fn check_agreement<M: Model, C: Constraints>(
    p: &Problem<M, C>,
    states: &[(f64, Vec<f64>, Vec<f64>)],
) {
    for (t, q, v) in states {
        let (a0, l0, du) = accelerations(p, Formulation::NullSpace, *t, q, v);
        let scale_a = max_abs(&a0).max(1.0);
        let scale_l = max_abs(&l0).max(1.0);
        // (2.7): D u = 0, relative to |u|.
        assert!(du < 100.0 * EPS, "D u = {du:e}");
        for f in Formulation::ALL {
            let (a, l, _) = accelerations(p, f, *t, q, v);
            for k in 0..a.len() {
                assert!(
                    (a[k] - a0[k]).abs() < 1e3 * EPS * scale_a,
                    "{f:?} acc[{k}] {} vs {}",
                    a[k],
                    a0[k]
                );
            }
            for k in 0..l.len() {
                assert!(
                    (l[k] - l0[k]).abs() < 1e3 * EPS * scale_l,
                    "{f:?} lambda[{k}] {} vs {}",
                    l[k],
                    l0[k]
                );
            }
        }
    }
}

#[test]
fn formulations_agree_on_example_2_1() {
    let p = particle::example_2_1();
    let mut rng = Lcg(1);
    let states: Vec<_> = (0..20)
        .map(|_| {
            let q = vec![0.5 * rng.next(), 3.0 * rng.next(), 1.5 + rng.next()];
            let v = vec![rng.next(), rng.next(), rng.next()];
            (rng.next(), q, v)
        })
        .collect();
    check_agreement(&p, &states);
}

#[test]
fn formulations_agree_on_example_3_1_heavy_top() {
    let p = rigid_body::heavy_top();
    let mut rng = Lcg(2);
    let states: Vec<_> = (0..20)
        .map(|_| {
            let mut q: Vec<f64> = (0..4).map(|_| rng.next()).collect();
            let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            q.iter_mut().for_each(|x| *x /= n);
            let v = vec![rng.next(), rng.next(), 5.0 * rng.next()];
            (0.0, q, v)
        })
        .collect();
    check_agreement(&p, &states);
}

#[test]
fn formulations_agree_with_system_constraints_and_complete_programme() {
    let p = pendulum::rod_and_swing();
    let mut rng = Lcg(3);
    let states: Vec<_> = (0..20)
        .map(|_| {
            let th = rng.next();
            let q = vec![1.2 * th.sin(), -1.2 * th.cos()];
            let v = vec![rng.next(), rng.next()];
            (rng.next(), q, v)
        })
        .collect();
    check_agreement(&p, &states);
    let d = pendulum::double_pendulum();
    let states: Vec<_> = (0..20)
        .map(|_| {
            (
                2.0 * rng.next(),
                vec![rng.next(), rng.next()],
                vec![rng.next(), rng.next()],
            )
        })
        .collect();
    check_agreement(&d, &states);
}

/// The control force of the constant-speed programme is tangential (NOTES.md, Example 2.1):
/// u = 2 lambda A v / m, i.e. in Cartesian terms f = 2 lambda xdot.
#[test]
fn example_2_1_control_force_is_along_the_velocity() {
    let p = particle::example_2_1();
    let (q, v) = (vec![0.2, 0.4, 1.3], vec![0.3, -0.7, 0.0]); // rd = 0: the paper's D is singular
    let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
    ev.evaluate(
        Formulation::NullSpace,
        &RankTolerances::default(),
        None,
        0.0,
        &q,
        &v,
    )
    .unwrap();
    let mut u = vec![0.0; 3];
    ev.reaction(Role::Programme, &mut u);
    let m = p.model.m;
    let (th, r) = (q[0], q[2]);
    let av = [
        m * r * r * v[0],
        m * r * r * th.cos().powi(2) * v[1],
        m * v[2],
    ];
    let k = 2.0 * ev.lambda[0] / m;
    for j in 0..3 {
        assert!((u[j] - k * av[j]).abs() < 100.0 * EPS * max_abs(&u).max(1.0));
    }
    // B = dg/dv = 2 (r^2 thd, r^2 cos^2 th phd, rd) exactly (AD, no finite differences).
    let b = [
        2.0 * r * r * v[0],
        2.0 * r * r * th.cos().powi(2) * v[1],
        2.0 * v[2],
    ];
    for j in 0..3 {
        assert!((ev.jet.b[(0, j)] - b[j]).abs() < 10.0 * EPS);
    }
}

/// Holonomic row q2 - A sin(w t): B = (0, 1), gamma = -A w^2 sin(w t) exactly.
#[test]
fn holonomic_row_second_derivative_is_exact() {
    let p = pendulum::double_pendulum();
    let (amp, w) = (p.constraints.amplitude, p.constraints.omega);
    let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
    let t = 0.7;
    ev.prepare(t, &[0.1, 0.2], &[0.3, 0.4]);
    assert_eq!(ev.jet.b[(0, 0)], 0.0);
    assert_eq!(ev.jet.b[(0, 1)], 1.0);
    assert!((ev.jet.gamma[0] + amp * w * w * (w * t).sin()).abs() < 10.0 * EPS);
    assert!((ev.jet.gdot[0] - (0.4 - amp * w * (w * t).cos())).abs() < 10.0 * EPS);
}

/// The complete programme of the Cartesian pendulum at its closed-form state: dv/dt, the control
/// force of the programme row and the rod reaction all match the closed form.
#[test]
fn complete_programme_matches_closed_form() {
    let p = pendulum::rod_and_swing();
    let c = &p.constraints;
    let (m, g, l) = (p.model.m, p.model.g, c.length);
    for &t in &[0.0, 0.3, 1.1, 2.5] {
        let (ph, phd, phdd) = c.phi(t);
        let q = [l * ph.sin(), -l * ph.cos()];
        let v = [l * ph.cos() * phd, l * ph.sin() * phd];
        let a = [
            l * (ph.cos() * phdd - ph.sin() * phd * phd),
            l * (ph.sin() * phdd + ph.cos() * phd * phd),
        ];
        // m a = (0, -m g) + lr (2x, 2y) + mu (1, 0)
        let lr = m * (a[1] + g) / (2.0 * q[1]);
        let mu = m * a[0] - 2.0 * q[0] * lr;
        for f in Formulation::ALL {
            let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
            ev.evaluate(f, &RankTolerances::default(), None, t, &q, &v)
                .unwrap();
            let mut u = vec![0.0; 2];
            let mut rod = vec![0.0; 2];
            ev.reaction(Role::Programme, &mut u);
            ev.reaction(Role::System, &mut rod);
            let tol = 1e3 * EPS * (m * g);
            assert!(
                (ev.acc[0] - a[0]).abs() < tol && (ev.acc[1] - a[1]).abs() < tol,
                "{f:?}"
            );
            assert!(
                (u[0] - mu).abs() < tol && u[1].abs() < tol,
                "{f:?} u {u:?} vs {mu}"
            );
            assert!((rod[0] - 2.0 * lr * q[0]).abs() < tol, "{f:?}");
            assert!((rod[1] - 2.0 * lr * q[1]).abs() < tol, "{f:?}");
        }
    }
}

/// Example 3.1 closed form for an axisymmetric body: u = (A lambda rho - C r)(-q, p, 0).
#[test]
fn example_3_1_control_torque_matches_closed_form() {
    let p = rigid_body::symmetric_body();
    let (w, u_ref) =
        rigid_body::symmetric_closed_form(&p.model, p.constraints.lambda, [0.6, 0.8, 1.5], 0.0);
    let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
    ev.evaluate(
        Formulation::NullSpace,
        &RankTolerances::default(),
        None,
        0.0,
        &p.q0,
        &w,
    )
    .unwrap();
    let mut u = vec![0.0; 3];
    ev.reaction(Role::Programme, &mut u);
    for j in 0..3 {
        assert!((u[j] - u_ref[j]).abs() < 100.0 * EPS, "{u:?} vs {u_ref:?}");
    }
}

/// p = q = 0: the programme's gradient vanishes; every formulation reports it, none returns numbers.
#[test]
fn vanishing_programme_gradient_is_reported() {
    let p = rigid_body::degenerate_start();
    for f in Formulation::ALL {
        let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
        let r = ev.evaluate(f, &RankTolerances::default(), None, 0.0, &p.q0, &p.v0);
        match r {
            Err(FormulationError::RankDeficient { rows, .. }) => assert_eq!(rows, vec![0]),
            other => panic!("{f:?}: expected rank deficiency, got {other:?}"),
        }
    }
}

/// Two copies of the same row: dependent rows are reported by name order (the later pivot).
#[test]
fn dependent_rows_are_reported() {
    use progmo::programme::{Level, RowSpec};
    use progmo::scalar::Scalar;
    struct Twice([RowSpec; 2]);
    impl Constraints for Twice {
        type Workspace<S: Scalar> = ();
        fn workspace<S: Scalar>(&self) {}
        fn rows(&self) -> &[RowSpec] {
            &self.0
        }
        fn eval<S: Scalar>(&self, _: &mut (), _t: S, q: &[S], _v: &[S], _a: &[S], out: &mut [S]) {
            out[0] = q[1] - 0.1;
            out[1] = q[1] * 2.0 - 0.2;
        }
    }
    let d = pendulum::double_pendulum();
    let cons = Twice([
        RowSpec::new("a", Level::Position, Role::Programme),
        RowSpec::new("b", Level::Position, Role::Programme),
    ]);
    let mut ev = Evaluator::<_, _, f64>::new(&d.model, &cons);
    let r = ev.evaluate(
        Formulation::NullSpace,
        &RankTolerances::default(),
        None,
        0.0,
        &[0.1, 0.1],
        &[0.0, 0.0],
    );
    assert!(
        matches!(r, Err(FormulationError::RankDeficient { rank: 1, .. })),
        "{r:?}"
    );
}

/// Baumgarte: with the stabilized right-hand side, df/dt = -alpha f for a velocity row, and
/// d2g/dt2 = -2 alpha dg/dt - beta^2 g for a position row (checked through B a - gamma).
#[test]
fn baumgarte_terms_enter_as_written() {
    use progmo::solve::Baumgarte;
    let bg = Baumgarte {
        alpha: 3.0,
        beta: 2.0,
    };
    let p = particle::example_2_1();
    let (q, v) = (vec![0.2, 0.4, 1.3], vec![0.3, -0.7, 0.2]); // off the programme: f != 0
    let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
    ev.prepare(0.0, &q, &v);
    let (f, gamma0, b) = (ev.jet.value[0], ev.jet.gamma[0], ev.jet.b.clone());
    ev.evaluate(
        Formulation::NullSpace,
        &RankTolerances::default(),
        Some(bg),
        0.0,
        &q,
        &v,
    )
    .unwrap();
    let fdot = (0..3).map(|j| b[(0, j)] * ev.acc[j]).sum::<f64>() - gamma0;
    assert!(
        (fdot + bg.alpha * f).abs() < 1e-13,
        "{fdot} vs {}",
        -bg.alpha * f
    );

    let d = pendulum::double_pendulum();
    let (t, q, v) = (0.4, vec![0.1, 0.3], vec![0.2, 0.1]);
    let mut ev = Evaluator::<_, _, f64>::new(&d.model, &d.constraints);
    ev.prepare(t, &q, &v);
    let (g, gd, gamma0) = (ev.jet.value[0], ev.jet.gdot[0], ev.jet.gamma[0]);
    ev.evaluate(
        Formulation::NullSpace,
        &RankTolerances::default(),
        Some(bg),
        t,
        &q,
        &v,
    )
    .unwrap();
    let gdd = ev.acc[1] - gamma0;
    let want = -2.0 * bg.alpha * gd - bg.beta * bg.beta * g;
    assert!((gdd - want).abs() < 1e-13, "{gdd} vs {want}");
}

use crate::common;

/// max |x - y| / max(max |y|, 1).
fn rel_diff(x: &[f64], y: &[f64]) -> f64 {
    let d = x
        .iter()
        .zip(y)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    d / max_abs(y).max(1.0)
}

/// cond(A) at (t, q, v) (2-norm, from the symmetric eigenvalues).
fn cond_a<M: Model, C: Constraints>(p: &Problem<M, C>, t: f64, q: &[f64], v: &[f64]) -> f64 {
    let mut ev = Evaluator::<M, C, f64>::new(&p.model, &p.constraints);
    ev.prepare(t, q, v);
    let e = ev.mass.clone().symmetric_eigenvalues();
    e.max() / e.min()
}

/// The articulated-body formulation (A^-1 by the tree's factorization, A never formed) against the
/// null-space and KKT forms at (t, q, v): dv/dt and lambda to 100 eps cond(A) relative (algebraic
/// class: a range-space method loses eps cond(A)); returns the largest relative difference.
fn articulated_vs_dense<M: Model, C: Constraints>(
    p: &Problem<M, C>,
    t: f64,
    q: &[f64],
    v: &[f64],
    what: &str,
) -> f64 {
    assert!(
        p.model.has_mass_factor(),
        "{what}: a tree model has the factorization"
    );
    let (a, l, du) = accelerations(p, Formulation::ArticulatedBody, t, q, v);
    let tol = 100.0 * EPS * cond_a(p, t, q, v);
    assert!(du < tol.max(100.0 * EPS), "{what}: D u = {du:e}");
    let mut worst = 0.0f64;
    for f in [Formulation::NullSpace, Formulation::Kkt] {
        let (a0, l0, _) = accelerations(p, f, t, q, v);
        let (ea, el) = (rel_diff(&a, &a0), rel_diff(&l, &l0));
        assert!(
            ea <= tol && el <= tol,
            "{what} vs {f:?}: dv/dt {ea:.1e}, lambda {el:.1e} > {tol:.1e}"
        );
        worst = worst.max(ea).max(el);
    }
    worst
}

/// Deterministic states near (q0, v0): the initial state and small perturbations.
fn near_states(q0: &[f64], v0: &[f64], t0: f64, rng: &mut Lcg) -> Vec<(f64, Vec<f64>, Vec<f64>)> {
    let mut out = vec![(t0, q0.to_vec(), v0.to_vec())];
    for _ in 0..3 {
        let q = q0.iter().map(|x| x + 0.01 * rng.next()).collect();
        let v = v0.iter().map(|x| x + 0.3 * rng.next()).collect();
        out.push((t0 + 0.1 * rng.next().abs(), q, v));
    }
    out
}

/// Every tree scene of the catalog and of tests/scenes (robots, closures, ball and free joints,
/// point forces): articulated-body agrees with the dense formulations.
#[test]
fn articulated_body_agrees_on_every_tree_scene() {
    use progmo::scene::{Scene, SceneSystem};
    let mut rng = Lcg(15);
    let mut seen = vec![];
    for path in common::toml_files("references/scenes")
        .into_iter()
        .chain(common::toml_files("tests/scenes"))
    {
        let scene = Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let SceneSystem::Tree(p) = &scene.system else {
            continue;
        };
        let mut worst = 0.0f64;
        for (t, q, v) in near_states(&p.q0, &p.v0, p.t0, &mut rng) {
            let mut q = q;
            progmo::model::normalize(p.model.segments(), &mut q);
            worst = worst.max(articulated_vs_dense(p, t, &q, &v, &scene.name));
        }
        eprintln!(
            "{:24} nv {:3}: max relative difference {worst:.1e}",
            scene.name,
            p.v0.len()
        );
        seen.push(scene.name.clone());
    }
    // the catalog's trees are all here (a loader change that hid them would pass vacuously)
    for name in [
        "chain_8",
        "heavy_top",
        "four_bar",
        "panda_circle",
        "xarm7_elbow_height",
    ] {
        assert!(
            seen.iter().any(|s| s == name),
            "{name} not checked: {seen:?}"
        );
    }
}

/// Random chains (masses 0.05 ... 1, lengths 0.1 ... 0.5, bends, velocities) of 2 ... 64 links.
#[test]
fn articulated_body_agrees_on_random_chains() {
    use progmo::scene::chain::ChainSpec;
    let mut rng = Lcg(1515);
    for n in [2, 3, 5, 9, 17, 33, 64] {
        let spec = ChainSpec {
            masses: Some((0..n).map(|_| 0.525 + 0.475 * rng.next()).collect()),
            length: 0.3 + 0.2 * rng.next(),
            q0: Some(0.1 * rng.next()),
            ..ChainSpec::uniform(n)
        };
        let scene = spec.scene().unwrap();
        progmo::with_problem!(&scene.system, p => {
            let v: Vec<f64> = (0..n).map(|_| rng.next()).collect();
            let w = articulated_vs_dense(p, 0.3, &p.q0, &v, &format!("chain_{n}"));
            eprintln!("random chain n = {n:3}: max relative difference {w:.1e}");
        });
    }
}

/// `auto` is null-space, bit for bit, below AUTO_ARTICULATED_NV velocities and articulated-body
/// from there on (trees); on models without the factorization it is always null-space.
#[test]
fn auto_resolves_by_size_and_model() {
    use progmo::formulation::AUTO_ARTICULATED_NV;
    use progmo::scene::chain::ChainSpec;
    for n in [AUTO_ARTICULATED_NV - 1, AUTO_ARTICULATED_NV] {
        let scene = ChainSpec::uniform(n).scene().unwrap();
        progmo::with_problem!(&scene.system, p => {
            let v: Vec<f64> = (0..n).map(|k| 0.1 * k as f64).collect();
            let (a, l, _) = accelerations(p, Formulation::Auto, 0.2, &p.q0, &v);
            let want = if n < AUTO_ARTICULATED_NV {
                Formulation::NullSpace
            } else {
                Formulation::ArticulatedBody
            };
            let (a0, l0, _) = accelerations(p, want, 0.2, &p.q0, &v);
            assert_eq!((a, l), (a0, l0), "n = {n}: auto is {want:?}");
            assert_eq!(Formulation::Auto.resolve(n, true), want);
        });
    }
    assert_eq!(
        Formulation::Auto.resolve(10 * AUTO_ARTICULATED_NV, false),
        Formulation::NullSpace
    );
    let p = particle::example_2_1();
    let (a, _, _) = accelerations(
        &p,
        Formulation::Auto,
        0.0,
        &[0.2, 0.4, 1.3],
        &[0.3, -0.7, 0.2],
    );
    let (a0, _, _) = accelerations(
        &p,
        Formulation::NullSpace,
        0.0,
        &[0.2, 0.4, 1.3],
        &[0.3, -0.7, 0.2],
    );
    assert_eq!(a, a0);
}

/// Over dual numbers (the Radau Jacobian and the jets): the derivative of dv/dt along a direction
/// in (q, v) agrees between articulated-body and null-space on a chain.
#[test]
fn articulated_body_derivatives_agree_over_duals() {
    use progmo::scene::chain::ChainSpec;
    type Dual64 = progmo::scalar::Dual<f64>;
    let n = 12;
    let scene = ChainSpec::uniform(n).scene().unwrap();
    progmo::with_problem!(&scene.system, p => {
        let mut rng = Lcg(7);
        let dir: Vec<f64> = (0..2 * n).map(|_| rng.next()).collect();
        let q: Vec<Dual64> = (0..n).map(|k| Dual64::new(p.q0[k], dir[k])).collect();
        let v: Vec<Dual64> = (0..n).map(|k| Dual64::new(0.2 * rng.next(), dir[n + k])).collect();
        let t = Dual64::from_re(0.3);
        let mut out = vec![];
        for f in [Formulation::ArticulatedBody, Formulation::NullSpace] {
            let mut ev = Evaluator::<_, _, Dual64>::new(&p.model, &p.constraints);
            ev.evaluate(f, &RankTolerances::default(), None, t, &q, &v).unwrap();
            out.push(ev.acc.clone());
        }
        let (re0, re1): (Vec<f64>, Vec<f64>) = (out[0].iter().map(|x| x.re).collect(), out[1].iter().map(|x| x.re).collect());
        let (d0, d1): (Vec<f64>, Vec<f64>) = (out[0].iter().map(|x| x.eps).collect(), out[1].iter().map(|x| x.eps).collect());
        let qf: Vec<f64> = q.iter().map(|x| x.re).collect();
        let vf: Vec<f64> = v.iter().map(|x| x.re).collect();
        let tol = 100.0 * EPS * cond_a(p, 0.3, &qf, &vf);
        assert!(rel_diff(&re0, &re1) <= tol, "values {:.1e}", rel_diff(&re0, &re1));
        assert!(rel_diff(&d0, &d1) <= tol, "derivatives {:.1e}", rel_diff(&d0, &d1));
        assert!(max_abs(&d1) > 1e-3, "the direction moves dv/dt");
    });
}
