//! Hard cases for numerical stability. Expected behaviour of each case: `references/hard/README.md`.
//!
//! Every case either passes at a stated accuracy or stops with a specific return code keeping its
//! partial results (finite samples up to `t_end`), never a wrong success. Tolerances are in units of
//! the solver's `rtol` or of f64::EPSILON; measured numbers are printed (`--nocapture`).

// Settings are built by changing a few fields of the default, case by case.
#![allow(clippy::field_reassign_with_default)]

use nalgebra::{DMatrix, DVector};
use progmo::formulation::{Formulation, RankTolerances};
use progmo::integrate::Method;
use progmo::model::Model;
use progmo::problems::hard::{self, NanAfterLaw, WithForce};
use progmo::problems::particle::{self, ConstantSpeed};
use progmo::problems::pendulum::{self, DoublePendulum, ElbowProgramme};
use progmo::programme::Constraints;
use progmo::solve::{
    check_initial, solve, solve_into, DriftControl, Evaluator, Output, Problem, ReturnCode, Sample,
    SampleSink, Settings, Solution,
};

const EPS: f64 = f64::EPSILON;

fn max_abs(x: impl IntoIterator<Item = f64>) -> f64 {
    x.into_iter().fold(0.0, |m, y| m.max(y.abs()))
}

fn norm(x: &[f64]) -> f64 {
    x.iter().map(|y| y * y).sum::<f64>().sqrt()
}

/// Every sample finite and the last sample at t_end (partial results kept, never garbage).
fn assert_partial_results_clean(sol: &Solution) {
    let tr = &sol.trajectory;
    assert!(!tr.is_empty(), "no samples kept ({:?})", sol.code);
    for v in [&tr.t, &tr.q, &tr.v, &tr.a, &tr.u, &tr.lambda, &tr.residual] {
        assert!(v.iter().all(|x| x.is_finite()), "non-finite sample");
    }
    assert_eq!(
        *tr.t.last().unwrap(),
        sol.t_end,
        "last sample is not at t_end"
    );
}

// ---------------------------------------------------------------------------------------------
// 1a. Example 2.1 through rd = 0: the paper's D (2.19) against the orthonormal D.

/// The paper's hand-made D (2.19) in coordinates (theta, phi, r) divides by rd: the square system
/// [D A; B] a = [D F; gamma] has a condition number growing like 1/rd^2 and is non-finite at rd = 0,
/// while the orthonormal D (rank-revealing QR) gives the KKT accelerations to round-off at every
/// state; the whole solve through rd = 0 succeeds.
#[test]
fn c1a_paper_d_breaks_down_at_rd0_orthonormal_d_does_not() {
    let model = particle::Particle { m: 1.0, mu: 1.0 };
    let tol = RankTolerances::default();
    let q = [0.1, 0.0, 1.0];
    let mut errs_paper = vec![];
    eprintln!("rd        cond[DA;B] (2.19)  |a_2.19 - a_kkt|/|a|  |a_ns - a_kkt|/|a|");
    for rd in [1e-1, 1e-3, 1e-5, 1e-7, 1e-9, 1e-11, 0.0] {
        let v = [0.3, 1.1, rd];
        let cons = ConstantSpeed::new(particle::speed2(&q, &v));
        let mut ev = Evaluator::new(&model, &cons);
        ev.evaluate(Formulation::Kkt, &tol, None, 0.0, &q, &v)
            .unwrap();
        let a_kkt = ev.acc.clone();
        ev.evaluate(Formulation::NullSpace, &tol, None, 0.0, &q, &v)
            .unwrap();
        let a_ns = ev.acc.clone();
        let e_ns = norm(&sub(&a_ns, &a_kkt)) / norm(&a_kkt);
        // The paper's D (2.19).
        let (th, r) = (q[0], q[2]);
        let d = DMatrix::from_row_slice(
            2,
            3,
            &[
                1.0,
                0.0,
                -r * r * v[0] / rd,
                0.0,
                1.0,
                -r * r * th.cos().powi(2) * v[1] / rd,
            ],
        );
        let da = &d * &ev.mass;
        let df = &d * DVector::from_column_slice(&ev.force);
        let mut k = DMatrix::zeros(3, 3);
        let mut rhs = DVector::zeros(3);
        for i in 0..2 {
            for j in 0..3 {
                k[(i, j)] = da[(i, j)];
            }
            rhs[i] = df[i];
        }
        for j in 0..3 {
            k[(2, j)] = ev.jet.b[(0, j)];
        }
        rhs[2] = ev.jet.gamma[0];
        let finite = k.iter().all(|x| x.is_finite());
        let cond = if finite {
            let sv = k.clone().svd(false, false).singular_values;
            sv.max() / sv.min()
        } else {
            f64::INFINITY
        };
        let a_paper = if finite { k.lu().solve(&rhs) } else { None };
        let e_paper = match a_paper {
            Some(a) if a.iter().all(|x| x.is_finite()) => {
                norm(&sub(a.as_slice(), &a_kkt)) / norm(&a_kkt)
            }
            _ => f64::INFINITY,
        };
        eprintln!("{rd:8.1e}  {cond:16.3e}  {e_paper:20.3e}  {e_ns:18.3e}");
        assert!(e_ns < 10.0 * EPS, "orthonormal D at rd = {rd:e}: {e_ns:e}");
        if rd == 0.0 {
            assert!(!finite && e_paper.is_infinite(), "(2.19) finite at rd = 0");
        } else {
            assert!(cond > 0.1 / rd, "cond {cond:e} at rd {rd:e}");
        }
        errs_paper.push(e_paper);
    }
    // The error of (2.19) grows as rd -> 0 (round-off amplified by 1/rd^2) while the QR one does not.
    assert!(errs_paper[0] < 1e3 * EPS, "{errs_paper:?}");

    // The whole solve through rd = 0 succeeds, and near the crossing the orthonormal D still agrees
    // with KKT to round-off.
    let p = particle::example_2_1_through_rd0();
    let sol = solve(&p, &Settings::default());
    assert_eq!(sol.code, ReturnCode::Success);
    let tr = &sol.trajectory;
    let k = (1..tr.len())
        .find(|&k| tr.v_at(k - 1)[2].signum() != tr.v_at(k)[2].signum())
        .expect("rd changes sign");
    let mut ev = Evaluator::new(&p.model, &p.constraints);
    for j in [k - 1, k] {
        let (q, v) = (tr.q_at(j), tr.v_at(j));
        ev.evaluate(Formulation::Kkt, &tol, None, tr.t[j], q, v)
            .unwrap();
        let a = ev.acc.clone();
        ev.evaluate(Formulation::NullSpace, &tol, None, tr.t[j], q, v)
            .unwrap();
        let e = norm(&sub(&ev.acc, &a)) / norm(&a);
        eprintln!(
            "t = {:.4}, rd = {:+.3e}: |a_ns - a_kkt|/|a| = {e:.2e}",
            tr.t[j], v[2]
        );
        assert!(e < 10.0 * EPS);
    }
    assert!(sol.max_residual[0] <= 1e-10);
}

fn sub(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}

// ---------------------------------------------------------------------------------------------
// 1b. Example 3.1 with p^2 + q^2 -> 0.

/// Transverse damping drives rho = |(p, q)| = rho0 exp(-c t / A) to 0; the programme's gradient
/// (-q, p, 0) has norm rho, so the solver must stop with `SingularProgramme` naming "precession" when
/// rho < vanishing x rho0, i.e. at t* = (A / c) ln(1 / vanishing) (13.816 s by default, 6.908 s with
/// vanishing = 1e-6) -- localized to 1e-2 s (default: rho ~ atol there) and 1e-6 s -- keeping a
/// trajectory that matches the closed form up to there.
#[test]
fn c1b_precession_stops_where_gradient_vanishes() {
    let p = hard::precession_to_axis();
    let a = p.model.body.inertia[0];
    for vanishing in [1e-12, 1e-6] {
        let mut s = Settings::default();
        s.rank_vanishing = vanishing;
        let t_star = a / p.model.c * (1.0 / vanishing).ln();
        let sol = solve(&p, &s);
        let tr = &sol.trajectory;
        let n = tr.len();
        eprintln!(
            "vanishing {vanishing:e}: {:?}, t_end {:.6}, t* {t_star:.6}, last step {:.3e}, samples {n}",
            sol.code,
            sol.t_end,
            sol.t_end - tr.t[n - 2]
        );
        match &sol.code {
            ReturnCode::SingularProgramme { t, rows, rcond } => {
                assert_eq!(rows, &vec!["precession".to_string()]);
                assert_eq!(*t, sol.t_end);
                assert!(*rcond <= vanishing, "rcond {rcond:e}");
                // Localized: steps that reach past t* are rejected and shrunk until they cannot.
                // The threshold is crossed where the computed rho (accurate to ~ atol + rtol rho)
                // crosses vanishing x rho0.
                let tol_t = if vanishing < 1e-9 { 1e-2 } else { 1e-6 };
                assert!((*t - t_star).abs() < tol_t, "t {t} vs t* {t_star}");
            }
            other => panic!("expected SingularProgramme, got {other:?}"),
        }
        assert_partial_results_clean(&sol);
        // Partial results are right: omega and u against the closed form (absolute, rho0 = 1).
        let w0 = [p.v0[0], p.v0[1], p.v0[2]];
        let (mut ew, mut eu) = (0.0f64, 0.0f64);
        for k in 0..n {
            let (w, u) =
                hard::precession_to_axis_closed_form(&p.model, p.constraints.lambda, w0, tr.t[k]);
            ew = ew.max(max_abs(sub(tr.v_at(k), &w)));
            eu = eu.max(max_abs(sub(tr.u_at(k), &u)));
        }
        eprintln!("  closed-form error: omega {ew:.2e}, u {eu:.2e}");
        assert!(ew < 1e3 * s.rtol && eu < 1e3 * s.rtol);
    }
}

// ---------------------------------------------------------------------------------------------
// 1c. A two-link arm whose end point is programmed out of the workspace.

/// The tip moves along y = -1.2 at 0.4 m/s and reaches full stretch (q2 = 0, programme Jacobian of
/// rank 1) at t* = 4 s; the joint rates grow like 1/sqrt(t* - t) and past t* the programme has no
/// solution. Default settings: the step collapses first, `StepTooSmall` at t* (to 1e-6; measured
/// 4 + 8e-13) with `stats.min_b_rcond` < 1e-6 showing why; with `rank_dependent = 1e-6`:
/// `SingularProgramme` naming a tip row within 1e-9 before t*. Finite samples kept up to t_end, all
/// on the programme (residual <= 1e-10).
#[test]
fn c1c_arm_stops_at_the_workspace_boundary() {
    let p = hard::arm_through_boundary();
    let t_star = p.constraints.t_boundary();
    let s = Settings::default();
    let sol = solve(&p, &s);
    let tr = &sol.trajectory;
    let n = tr.len();
    eprintln!(
        "arm: {:?}, t_end {:.9}, t* {t_star}, q2 at end {:.3e}, |v| at end {:.3e}, min rcond(B) {:.2e}, steps {}",
        sol.code,
        sol.t_end,
        tr.q_at(n - 1)[1],
        norm(tr.v_at(n - 1)),
        sol.stats.min_b_rcond,
        sol.stats.integrator.steps
    );
    assert!(!sol.code.is_success());
    assert!(
        matches!(
            sol.code,
            ReturnCode::SingularProgramme { .. }
                | ReturnCode::SingularSystem { .. }
                | ReturnCode::StepTooSmall { .. }
                | ReturnCode::ProjectionFailed { .. }
        ),
        "{:?}",
        sol.code
    );
    assert_partial_results_clean(&sol);
    assert!(
        sol.t_end <= t_star + 1e-6 && sol.t_end > t_star - 1e-3,
        "t_end {}",
        sol.t_end
    );
    // What was kept is on the programme.
    assert!(max_abs(tr.residual.iter().copied()) <= 1e-10);
    // The cause is visible in the statistics: B had lost rank to ~1e-7.
    assert!(sol.stats.min_b_rcond < 1e-6, "{:e}", sol.stats.min_b_rcond);
    // A coarser rank tolerance names the rank loss instead, just before t*.
    let mut s = Settings::default();
    s.rank_dependent = 1e-6;
    let sol = solve(&p, &s);
    eprintln!(
        "arm, dependent 1e-6: {:?}, t_end {:.12}",
        sol.code, sol.t_end
    );
    match &sol.code {
        ReturnCode::SingularProgramme { t, rows, rcond } => {
            assert!(*t <= t_star && t_star - *t < 1e-9, "t {t}");
            assert!(rows.len() == 1 && rows[0].starts_with("tip_"), "{rows:?}");
            assert!(*rcond < 1e-6);
        }
        other => panic!("expected SingularProgramme, got {other:?}"),
    }
    assert_partial_results_clean(&sol);
}

/// The tip touches full stretch at tc = 1.5 s with zero radial velocity and comes back: smooth
/// solutions exist through the dead point (the elbow flips) but the continuation is not unique, and
/// the normalized rcond of B only dips to ~1e-6 between samples, above the default `dependent`
/// tolerance 1e-10. KNOWN LIMITATION (measured, asserted so that a change is noticed): with default
/// settings DOP853 returns `Success` on the *bouncing* branch (q2 stays > 0, a control spike
/// max|u| ~ 1e5 against ~10 elsewhere) and Radau5 `StepTooSmall` just before tc; the rank loss is
/// visible only in `stats.min_b_rcond` (< 2e-5). With `rank_dependent = 1e-5` both integrators stop
/// with `SingularProgramme` before tc, partial results clean.
#[test]
fn c1c_arm_touching_the_boundary_known_limitation() {
    let p = hard::arm_touching_boundary();
    let tc = p.constraints.tc;
    for dependent in [1e-10, 1e-5] {
        for m in [Method::Dop853, Method::Radau5] {
            let mut s = Settings::default();
            s.integrator = m;
            s.rank_dependent = dependent;
            let sol = solve(&p, &s);
            let tr = &sol.trajectory;
            let n = tr.len();
            let umax = max_abs(tr.u.iter().copied());
            eprintln!(
                "arm touching, dependent {dependent:e}, {m:?}: {:?}, t_end {:.9}, steps {}, \
                 min rcond(B) {:.2e}, q2 at end {:.3e}, max|u| {umax:.2e}, max residual {:.2e}",
                sol.code,
                sol.t_end,
                sol.stats.integrator.steps,
                sol.stats.min_b_rcond,
                tr.q_at(n - 1)[1],
                max_abs(sol.max_residual.iter().copied()),
            );
            eprintln!(
                "  max projection corrections: dq {:.2e}, dv {:.2e}",
                sol.stats.max_position_correction, sol.stats.max_velocity_correction
            );
            if std::env::var("HARD_VERBOSE").is_ok() {
                for k in 0..n {
                    if (tr.t[k] - tc).abs() < 0.05 {
                        eprintln!(
                            "    t {:.9} q2 {:+.3e} q2' {:+.3e} u {:+.3e} {:+.3e}",
                            tr.t[k],
                            tr.q_at(k)[1],
                            tr.v_at(k)[1],
                            tr.u_at(k)[0],
                            tr.u_at(k)[1]
                        );
                    }
                }
            }
            assert_partial_results_clean(&sol);
            assert!(max_abs(sol.max_residual.iter().copied()) <= 1e-10);
            assert!(sol.stats.min_b_rcond < 2e-5, "rank loss not recorded");
            match (&sol.code, dependent < 1e-9, m) {
                (ReturnCode::Success, true, Method::Dop853) => {
                    // The bouncing branch: q2 > 0 after tc, with a control spike.
                    assert!(tr.q_at(n - 1)[1] > 0.5 && umax > 1e4);
                }
                (ReturnCode::StepTooSmall { t, .. }, true, Method::Radau5) => {
                    assert!(*t < tc && tc - *t < 1e-3)
                }
                (ReturnCode::SingularProgramme { t, rows, .. }, false, _) => {
                    assert!(*t < tc && tc - *t < 1e-3 && rows[0].starts_with("tip_"));
                }
                (other, ..) => panic!("dependent {dependent:e} {m:?}: {other:?}"),
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// 2. Nearly redundant rows.

/// Rows with gradients (1, 0, 0) and (1, 0, eps): above the `dependent` tolerance (1e-10 on the
/// row-normalized QR) the solve succeeds and u = (-m a w^2 sin(w t), 0, m g) to an accuracy
/// ~ EPS / eps (multipliers ~ m g / eps); below it, `SingularProgramme` at t0 naming the second row.
#[test]
fn c2_nearly_redundant_rows() {
    for eps in [1e-6, 1e-9, 1e-12] {
        let p = hard::nearly_redundant(eps);
        let mut s = Settings::default();
        s.output = Output::Every(0.25);
        let sol = solve(&p, &s);
        let (m, g) = (p.model.m, p.model.g);
        let c = &p.constraints;
        let u_error = |o: &Solution| {
            let tr = &o.trajectory;
            let mut e = 0.0f64;
            for k in 0..tr.len() {
                let t = tr.t[k];
                let u = [-m * c.a * c.w * c.w * (c.w * t).sin(), 0.0, m * g];
                e = e.max(max_abs(sub(tr.u_at(k), &u)) / (m * g));
            }
            e
        };
        if eps < s.rank_dependent {
            eprintln!("eps {eps:e}: {:?}", sol.code);
            match &sol.code {
                ReturnCode::SingularProgramme { t, rows, rcond } => {
                    assert_eq!(*t, 0.0);
                    assert_eq!(rows, &vec!["x_law_tilted".to_string()]);
                    assert!(*rcond < s.rank_dependent);
                }
                other => panic!("eps {eps:e}: expected SingularProgramme, got {other:?}"),
            }
            continue;
        }
        assert_eq!(sol.code, ReturnCode::Success, "eps {eps:e}");
        let tr = &sol.trajectory;
        let eu = u_error(&sol);
        let mut ez = 0.0f64;
        let mut lam = 0.0f64;
        for k in 0..tr.len() {
            ez = ez.max(tr.q_at(k)[2].abs());
            lam = lam.max(max_abs(tr.lambda_at(k).iter().copied()));
        }
        eprintln!(
            "eps {eps:e}: NullSpace success, |u - closed form|/(m g) {eu:.2e}, max|z| {ez:.2e}, \
             max|lambda| {lam:.2e}, min rcond(B) {:.2e}",
            sol.stats.min_b_rcond
        );
        // The other formulations square the conditioning (cond ~ 1/eps^2): they either report
        // SingularSystem or are accurate only to ~ EPS / eps^2.
        for f in [
            Formulation::Kkt,
            Formulation::RangeSpace,
            Formulation::UdwadiaKalaba,
        ] {
            s.formulation = f;
            let o = solve(&p, &s);
            let e = u_error(&o);
            eprintln!(
                "  {f:?}: {}, |u - closed form|/(m g) {e:.2e}",
                o.code.name()
            );
            match o.code {
                ReturnCode::Success => assert!(e < 1e3 * s.rtol + 1e3 * EPS / (eps * eps)),
                ReturnCode::SingularSystem { .. } => {}
                ref other => panic!("{f:?}: {other:?}"),
            }
        }
        assert!(lam > 0.5 * m * g / eps, "multipliers should be ~ m g / eps");
        let bound = 1e3 * s.rtol + 1e3 * EPS / eps;
        assert!(eu < bound, "eps {eps:e}: {eu:e} > {bound:e}");
        // z is fixed only through g2 - g1 = eps z, projected to 1e-12: |z| <= ~1e-12 / eps.
        assert!(ez <= 2e-12 / eps, "z drifted {ez:e}");
    }
}

// ---------------------------------------------------------------------------------------------
// 3. Stiff scene.

fn final_state<M: Model, C: Constraints>(p: &Problem<M, C>, s: &Settings) -> (Vec<f64>, Solution) {
    let sol = solve(p, s);
    assert_eq!(
        sol.code,
        ReturnCode::Success,
        "{:?} {:?}",
        s.integrator,
        sol.code
    );
    let tr = &sol.trajectory;
    let k = tr.len() - 1;
    let mut x = tr.q_at(k).to_vec();
    x.extend_from_slice(tr.v_at(k));
    (x, sol)
}

/// Double pendulum with a shoulder spring k = 1e6, damping 2e4 (fast mode ~ -4e3 /s), elbow
/// programmed. At equal final-state error (<= 1e-6 against Radau5 at rtol 1e-12), Radau5 costs fewer
/// RHS-equivalents (RHS evaluations + 2 nv per AD Jacobian, each counted twice) than DOP853, whose
/// step is limited by stability.
#[test]
fn c3_stiff_spring_radau5_beats_dop853_in_cost() {
    let p = hard::stiff_shoulder();
    let nv = p.model.nv();
    let mut s = Settings::default();
    s.integrator = Method::Radau5;
    s.rtol = 1e-12;
    s.atol = 1e-14;
    let (reference, _) = final_state(&p, &s);
    let target = 1e-6;
    let mut best = vec![];
    for m in [Method::Dop853, Method::Radau5] {
        let mut found = None;
        for rtol in [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9] {
            let mut s = Settings::default();
            s.integrator = m;
            s.rtol = rtol;
            s.atol = rtol * 1e-2;
            let (x, sol) = final_state(&p, &s);
            let err = max_abs(sub(&x, &reference));
            let st = &sol.stats.integrator;
            let cost = st.rhs_evals + 2 * 2 * (2 * nv) * st.jacobian_evals;
            eprintln!(
                "{m:?} rtol {rtol:e}: error {err:.2e}, steps {}, rejected {}, rhs {}, jac {}, lu {}, \
                 RHS-equivalents {cost}",
                st.steps, st.rejected, st.rhs_evals, st.jacobian_evals, st.lu_decompositions
            );
            if err <= target {
                found = Some((rtol, err, cost));
                break;
            }
        }
        best.push(found.unwrap_or_else(|| panic!("{m:?} never reached {target:e}")));
    }
    eprintln!(
        "cheapest at error <= {target:e}: DOP853 {:?}, Radau5 {:?}",
        best[0], best[1]
    );
    assert!(best[1].2 < best[0].2, "Radau5 not cheaper: {best:?}");
}

// ---------------------------------------------------------------------------------------------
// 4. Chaotic long horizon.

fn pendulum_energy(m: &DoublePendulum, q: &[f64], v: &[f64]) -> f64 {
    let mut a = DMatrix::zeros(2, 2);
    m.mass_matrix(&mut (), q, &mut a);
    let t = 0.5
        * (v[0] * (a[(0, 0)] * v[0] + a[(0, 1)] * v[1])
            + v[1] * (a[(1, 0)] * v[0] + a[(1, 1)] * v[1]));
    let pot = -(m.m1 + m.m2) * m.g * m.l1 * q[0].cos() - m.m2 * m.g * m.l2 * (q[0] + q[1]).cos();
    t + pot
}

/// Largest |E(t) - E(0) - W(t)| over the samples, W = integral of u . v (composite Simpson on the
/// uniform samples), relative to the energy scale.
fn energy_balance(m: &DoublePendulum, sol: &Solution, scale: f64) -> f64 {
    let tr = &sol.trajectory;
    let power: Vec<f64> = (0..tr.len())
        .map(|k| tr.u_at(k).iter().zip(tr.v_at(k)).map(|(a, b)| a * b).sum())
        .collect();
    let e0 = pendulum_energy(m, tr.q_at(0), tr.v_at(0));
    let mut w = 0.0;
    let mut worst = 0.0f64;
    let mut k = 0;
    while k + 2 < tr.len() {
        let h = tr.t[k + 2] - tr.t[k];
        w += h / 6.0 * (power[k] + 4.0 * power[k + 1] + power[k + 2]);
        k += 2;
        let e = pendulum_energy(m, tr.q_at(k), tr.v_at(k));
        worst = worst.max((e - e0 - w).abs());
    }
    worst / scale
}

/// Double pendulum started near the inverted position, elbow programmed q2 = sin(2 t), 200 s. Runs at rtol 1e-8
/// and 1e-10 diverge pointwise (chaos: differences reach O(1)) while both keep the programme residual
/// <= 1e-10 and the energy balance E(t) - E(0) = work of u to <= 1e-6 of the energy scale.
#[test]
fn c4_chaotic_long_horizon_keeps_invariants() {
    let mut p = pendulum::double_pendulum();
    p.constraints = ElbowProgramme::new(1.0, 2.0);
    p.q0 = vec![3.0, 0.0];
    p.v0 = vec![0.0, 2.0];
    p.t1 = 200.0;
    let scale = (p.model.m1 + p.model.m2) * p.model.g * (p.model.l1 + p.model.l2);
    let mut runs = vec![];
    for rtol in [1e-8, 1e-10] {
        let mut s = Settings::default();
        s.rtol = rtol;
        s.atol = rtol * 1e-2;
        s.output = Output::Every(0.01);
        let sol = solve(&p, &s);
        assert_eq!(sol.code, ReturnCode::Success);
        let bal = energy_balance(&p.model, &sol, scale);
        eprintln!(
            "rtol {rtol:e}: steps {}, residual {:.2e} (rate {:.2e}), energy balance {bal:.2e} of m g l",
            sol.stats.integrator.steps, sol.max_residual[0], sol.max_residual_rate[0]
        );
        assert!(sol.max_residual[0] <= 1e-10 && sol.max_residual_rate[0] <= 1e-10);
        assert!(bal < 1e-6, "energy balance {bal:e}");
        runs.push(sol);
    }
    let (a, b) = (&runs[0].trajectory, &runs[1].trajectory);
    assert_eq!(a.len(), b.len());
    let diff: Vec<f64> = (0..a.len())
        .map(|k| {
            (a.q_at(k)[0] - b.q_at(k)[0])
                .abs()
                .max((a.v_at(k)[0] - b.v_at(k)[0]).abs())
        })
        .collect();
    let t_sep = (0..a.len()).find(|&k| diff[k] > 1e-3).map(|k| a.t[k]);
    let late = max_abs(diff[diff.len() / 2..].iter().copied());
    eprintln!("pointwise difference > 1e-3 from t = {t_sep:?}; max difference over [100, 200] s: {late:.2}");
    assert!(late > 0.1, "runs did not diverge: {late:e}");
}

// ---------------------------------------------------------------------------------------------
// 5. Ill-conditioned masses.

/// Double pendulum with m2/m1 from 1e-8 to 1e8, elbow programmed: all four formulations succeed with
/// finite results; the null-space D u stays at round-off (max Diagnostics::du <= 1e3 EPS). The
/// disagreement of dv/dt and u between formulations is printed, not asserted beyond sanity.
#[test]
fn c5_ill_conditioned_masses_all_formulations() {
    eprintln!("m2/m1     formulation     max|a - a_kkt|/max|a|  max|u - u_kkt|/max|u|  max du");
    for ratio in [1e-8, 1e-4, 1.0, 1e4, 1e8] {
        let mut p = pendulum::double_pendulum();
        p.model.m2 = ratio;
        p.t1 = 2.0;
        let mut sols = vec![];
        for f in Formulation::ALL {
            let mut s = Settings::default();
            s.formulation = f;
            s.output = Output::Every(0.1);
            let sol = solve(&p, &s);
            assert_eq!(sol.code, ReturnCode::Success, "{ratio:e} {f:?}");
            assert_partial_results_clean(&sol);
            sols.push(sol);
        }
        let ik = Formulation::ALL
            .iter()
            .position(|f| *f == Formulation::Kkt)
            .unwrap();
        let kkt = &sols[ik].trajectory;
        let amax = max_abs(kkt.a.iter().copied());
        let umax = max_abs(kkt.u.iter().copied());
        for (f, sol) in Formulation::ALL.iter().zip(&sols) {
            let tr = &sol.trajectory;
            assert_eq!(tr.len(), kkt.len());
            let da = max_abs(sub(&tr.a, &kkt.a)) / amax;
            let du = max_abs(sub(&tr.u, &kkt.u)) / umax;
            eprintln!(
                "{ratio:8.0e}  {:14}  {da:22.2e}  {du:22.2e}  {:.2e}",
                format!("{f:?}"),
                sol.stats.max_du
            );
            assert!(da < 1e-2 && du < 1e-2, "sanity: {f:?} at {ratio:e}");
        }
        assert!(
            sols[0].stats.max_du <= 1e3 * EPS,
            "null-space du {:e}",
            sols[0].stats.max_du
        );
    }
}

// ---------------------------------------------------------------------------------------------
// 6. 10^4 periods with an O(1) memory sink.

/// Keeps maxima only: memory does not grow with the number of samples.
struct MaxSink {
    samples: usize,
    max_residual: Vec<f64>,
    max_rate: Vec<f64>,
    max_u: f64,
    t_last: f64,
}

impl SampleSink for MaxSink {
    fn sample(&mut self, s: &Sample<'_>) {
        self.samples += 1;
        for (m, r) in self.max_residual.iter_mut().zip(s.residual) {
            *m = m.max(r.abs());
        }
        for (m, r) in self.max_rate.iter_mut().zip(s.residual_rate) {
            *m = m.max(r.abs());
        }
        self.max_u = self.max_u.max(max_abs(s.u.iter().copied()));
        self.t_last = s.t;
    }
}

/// Double pendulum with the elbow programmed at period 0.01 s (q2 = 0.2 sin(200 pi t)) for 100 s =
/// 10^4 periods: with projection the residual (and its rate) stays <= 1e-12 over every accepted
/// step; without projection it grows well past that (negative control). The sink sees every sample
/// (one per accepted step plus t0) and stores O(1).
#[test]
fn c6_ten_thousand_periods_residual_and_constant_memory() {
    let p = hard::ten_thousand_periods();
    let mut s = Settings::default();
    s.rtol = 1e-8;
    s.atol = 1e-10;
    let mut results = vec![];
    for drift in [
        DriftControl::Projection {
            tol: 1e-12,
            max_iter: 8,
        },
        DriftControl::None,
    ] {
        s.drift = drift;
        let mut sink = MaxSink {
            samples: 0,
            max_residual: vec![0.0; 1],
            max_rate: vec![0.0; 1],
            max_u: 0.0,
            t_last: 0.0,
        };
        let sol = solve_into(&p, &s, &mut sink);
        assert_eq!(sol.code, ReturnCode::Success);
        assert!(sol.trajectory.is_empty());
        assert_eq!(
            sink.samples,
            sol.stats.integrator.steps + 1,
            "every sample delivered"
        );
        assert_eq!(sink.max_residual.capacity(), 1, "sink memory grew");
        assert_eq!(sink.t_last, p.t1);
        eprintln!(
            "{drift:?}: steps {}, samples {}, max residual {:.2e} (sink {:.2e}), rate {:.2e}, max|u| {:.2e}",
            sol.stats.integrator.steps,
            sink.samples,
            sol.max_residual[0],
            sink.max_residual[0],
            sol.max_residual_rate[0],
            sink.max_u
        );
        results.push(sol);
    }
    assert!(results[0].max_residual[0] <= 1e-12 && results[0].max_residual_rate[0] <= 1e-12);
    assert!(
        results[1].max_residual[0].max(results[1].max_residual_rate[0]) > 1e2 * 1e-12,
        "negative control did not drift"
    );
}

// ---------------------------------------------------------------------------------------------
// 7. Inconsistent initial states.

/// Off by 1e-3 and by 1.0: refused with `InconsistentInitialState` naming the row; with
/// `assemble = true` the state is corrected to residual <= consistency_tol (correction reported),
/// or, when no consistent state is near (tip target beyond reach), refused with
/// "<row> (assembly failed)". Never a wrong success.
#[test]
fn c7_inconsistent_initial_states() {
    let base = Settings::default();
    let mut asm = Settings::default();
    asm.assemble = true;
    // Velocity level: Example 2.1 with the programmed speed off.
    for off in [1e-3, 1.0] {
        let mut p = particle::example_2_1();
        let c2 = particle::speed2(&p.q0, &p.v0);
        p.constraints = ConstantSpeed::new(c2 - off);
        match check_initial(&p, &base) {
            Err(ReturnCode::InconsistentInitialState { row, residual }) => {
                assert_eq!(row, "speed");
                assert!((residual - off).abs() < 1e-12);
            }
            other => panic!("{other:?}"),
        }
        let (tr, corr) = check_initial(&p, &asm).expect("assembled");
        let corr = corr.expect("correction reported");
        let r = tr.residual_at(0)[0].abs();
        eprintln!("speed off by {off:e}: assembled, correction {corr:?}, residual after {r:.1e}");
        assert!(r <= asm.consistency_tol && corr.velocity > 0.0);
        assert!(
            (particle::speed2(tr.q_at(0), tr.v_at(0)) - (c2 - off)).abs() <= asm.consistency_tol
        );
    }
    // Position level: the arm's tip target moved by `dx`, `dy`.
    for (dx, dy, reachable) in [(1e-3, 0.0, true), (1.0, 0.0, true), (0.0, -1.0, false)] {
        let mut p = hard::arm_through_boundary();
        p.t1 = 1.0;
        p.constraints.x0 += dx;
        p.constraints.y0 += dy;
        let row = if dx != 0.0 { "tip_x" } else { "tip_y" };
        match check_initial(&p, &base) {
            Err(ReturnCode::InconsistentInitialState { row: r, .. }) => assert_eq!(r, row),
            other => panic!("{other:?}"),
        }
        let sol_asm = check_initial(&p, &asm);
        match (&sol_asm, reachable) {
            (Ok((tr, corr)), true) => {
                let corr = corr.as_ref().expect("correction");
                let r = max_abs(tr.residual_at(0).iter().copied());
                eprintln!(
                    "tip off by ({dx}, {dy}): assembled, correction {corr:?}, residual {r:.1e}"
                );
                assert!(r <= asm.consistency_tol && corr.position > 0.5 * dx.abs());
            }
            (Err(ReturnCode::InconsistentInitialState { row, residual }), false) => {
                eprintln!("tip off by ({dx}, {dy}): refused: {row}, residual {residual:.3}");
                assert!(row.ends_with("(assembly failed)"), "{row}");
            }
            other => panic!("tip off by ({dx}, {dy}): {other:?}"),
        }
        // solve() agrees with check_initial.
        let sol = solve(&p, &asm);
        assert!(sol.code.is_success() || !reachable, "{:?}", sol.code);
        if !reachable {
            assert!(matches!(
                sol.code,
                ReturnCode::InconsistentInitialState { .. }
            ));
            assert!(sol.trajectory.is_empty());
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Return codes without a test elsewhere.

/// `MaxSteps` after max_steps attempts, keeping the samples of the accepted steps.
#[test]
fn rc_max_steps_keeps_partial_results() {
    let p = pendulum::double_pendulum();
    let mut s = Settings::default();
    s.max_steps = 20;
    let sol = solve(&p, &s);
    eprintln!("{:?}, samples {}", sol.code, sol.trajectory.len());
    match sol.code {
        ReturnCode::MaxSteps { t } => assert!(t > 0.0 && t < p.t1 && t == sol.t_end),
        ref other => panic!("{other:?}"),
    }
    assert_partial_results_clean(&sol);
    assert_eq!(sol.trajectory.len(), sol.stats.integrator.steps + 1);
}

/// An absurd tolerance (rtol = 1e-30, atol = 1e-300): the step falls below the minimum at once;
/// `StepTooSmall` at (or near) t0 with the initial sample kept.
#[test]
fn rc_step_too_small_with_absurd_tolerance() {
    let p = pendulum::double_pendulum();
    let mut s = Settings::default();
    s.rtol = 1e-30;
    s.atol = 1e-300;
    let sol = solve(&p, &s);
    eprintln!("{:?}, samples {}", sol.code, sol.trajectory.len());
    assert!(
        matches!(sol.code, ReturnCode::StepTooSmall { .. }),
        "{:?}",
        sol.code
    );
    assert_partial_results_clean(&sol);
}

/// A force that turns NaN after t = 1: failing steps are shrunk until they cannot, then `NonFinite`
/// at t in (1 - 1e-9, 1], keeping finite samples up to there.
#[test]
fn rc_non_finite_force_keeps_partial_results() {
    let base = pendulum::double_pendulum();
    let p = Problem {
        model: WithForce {
            inner: base.model.clone(),
            law: NanAfterLaw { t_nan: 1.0 },
        },
        constraints: base.constraints.clone(),
        t0: base.t0,
        t1: base.t1,
        q0: base.q0.clone(),
        v0: base.v0.clone(),
    };
    let sol = solve(&p, &Settings::default());
    eprintln!(
        "{:?}, t_end {}, samples {}",
        sol.code,
        sol.t_end,
        sol.trajectory.len()
    );
    match sol.code {
        ReturnCode::NonFinite { t } => assert!(t <= 1.0 && t > 1.0 - 1e-9, "t {t}"),
        ref other => panic!("{other:?}"),
    }
    assert_partial_results_clean(&sol);
    assert!(sol.t_end <= 1.0);
}

/// Projection allowed no Newton iteration (max_iter = 0) on a coarse run: the first step's residual
/// is beyond 1e3 x tol, so `ProjectionFailed` naming the row at the first step, samples kept.
#[test]
fn rc_projection_failed_keeps_partial_results() {
    let p = pendulum::double_pendulum();
    let mut s = Settings::default();
    s.rtol = 1e-4;
    s.atol = 1e-6;
    s.drift = DriftControl::Projection {
        tol: 1e-14,
        max_iter: 0,
    };
    let sol = solve(&p, &s);
    eprintln!("{:?}, samples {}", sol.code, sol.trajectory.len());
    match &sol.code {
        ReturnCode::ProjectionFailed { t, row, residual } => {
            assert_eq!(row, "elbow");
            assert!(*residual > 1e-11 && *t > 0.0 && *t == sol.t_end);
        }
        other => panic!("{other:?}"),
    }
    assert!(!sol.trajectory.is_empty());
}

/// m2 = 0 makes A singular: the null-space and KKT forms need no inverse of A and succeed; the range
/// space and Udwadia-Kalaba forms stop with `SingularSystem` at t0.
#[test]
fn rc_singular_system_only_where_a_is_inverted() {
    let mut p = pendulum::double_pendulum();
    p.model.m2 = 0.0;
    p.t1 = 1.0;
    for f in Formulation::ALL {
        let mut s = Settings::default();
        s.formulation = f;
        let sol = solve(&p, &s);
        eprintln!("m2 = 0, {f:?}: {:?}", sol.code);
        match f {
            Formulation::NullSpace | Formulation::NullSpaceStacked | Formulation::Kkt => {
                assert_eq!(sol.code, ReturnCode::Success);
                assert_partial_results_clean(&sol);
            }
            _ => assert!(
                matches!(sol.code, ReturnCode::SingularSystem { t, .. } if t == 0.0),
                "{:?}",
                sol.code
            ),
        }
    }
}
