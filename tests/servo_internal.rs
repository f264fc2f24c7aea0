//! Internal (zero) dynamics of servo programmes (issue 17, `progmo::servo::internal`), on
//! references/scenes/passive_arm.toml: joints 1-2 driven, joint 3 passive and damped, the point P at
//! joint 3 programmed. The internal dynamics is the passive link, a pendulum hung from P:
//!   I q3'' + c q3' + m g lc cos(Q3) ... linearized at hanging (Q3 = -pi/2): I x'' + c x' + k x = 0,
//! k = m g lc, I = Iyy + m lc^2 (link 3: m = 0.5, lc = 0.2, Iyy = 0.4^2 m/12, c = 0.05, g = 9.81,
//! numbers of the scene file), roots (-c +- sqrt(c^2 - 4 I k))/(2 I); upright (Q3 = +pi/2) k = -m g lc
//! and the positive root is the growth rate. P held fixed (A = 0) makes these exact.

use progmo::integrate::Method;
use progmo::scene::Scene;
use progmo::servo::Realization;
use progmo::solve::{DriftControl, Output, Settings};
use std::path::PathBuf;

const M3: f64 = 0.5;
const LC: f64 = 0.2;
const IYY: f64 = 0.0066666666666666671;
const C: f64 = 0.05;
const G: f64 = 9.81;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn text() -> String {
    std::fs::read_to_string(root().join("references/scenes/passive_arm.toml")).unwrap()
}

fn load(text: &str) -> Scene {
    Scene::from_text(&root().join("passive_arm.toml"), text).unwrap_or_else(|e| panic!("{e}"))
}

fn param(s: &Scene, name: &str) -> f64 {
    s.parameters.iter().find(|(n, _)| n == name).unwrap().1
}

/// P held fixed (A = 0), link 3 hanging (`upright = false`) or upright, optionally displaced by
/// `dq3` at rest.
fn held(upright: bool, dq3: f64, t1: f64) -> Scene {
    let q30 = if upright {
        "pi/2 - q10 - q20"
    } else {
        "-pi/2 - q10 - q20"
    };
    let t = text()
        .replace("A = 0.1 ", "A = 0.0 ")
        .replace(
            "q30 = \"-pi/2 - q10 - q20\"",
            &format!("q30 = \"{q30} + {dq3:e}\""),
        )
        .replace("t1 = 4.0", &format!("t1 = {t1}"));
    let s = load(&t);
    assert_eq!(param(&s, "A"), 0.0);
    s
}

/// Closed-form inverse kinematics of P(t) = (x0 + A sin(w t), z0): (q1, q2, q1', q2').
fn ik(s: &Scene, t: f64) -> [f64; 4] {
    let (l, x0, z0, a, w) = (
        param(s, "l"),
        param(s, "x0"),
        param(s, "z0"),
        param(s, "A"),
        param(s, "w"),
    );
    let (x, z, xd) = (x0 + a * (w * t).sin(), z0, a * w * (w * t).cos());
    let q2 = ((x * x + z * z - 2.0 * l * l) / (2.0 * l * l)).acos();
    let q1 = z.atan2(x) - q2.sin().atan2(1.0 + q2.cos());
    let (c1, c12) = (q1.cos(), (q1 + q2).cos());
    [
        q1,
        q2,
        c12 * xd / (l * q2.sin()),
        -(c1 + c12) * xd / (l * q2.sin()),
    ]
}

/// Largest error of (q1, q2, q1', q2') against the inverse kinematics.
fn ik_error(s: &Scene, settings: &Settings) -> f64 {
    let sol = s.solve(settings);
    assert!(sol.code.is_success(), "{}", sol.code);
    let tr = &sol.trajectory;
    let mut e = 0.0f64;
    for i in 0..tr.len() {
        let r = ik(s, tr.t[i]);
        let (q, v) = (tr.q_at(i), tr.v_at(i));
        for (x, y) in [q[0], q[1], v[0], v[1]].iter().zip(r) {
            e = e.max((x - y).abs());
        }
    }
    e
}

/// The damped pendulum's roots (re, im), largest real part first.
fn roots(k: f64) -> [(f64, f64); 2] {
    let i = IYY + M3 * LC * LC;
    let disc = C * C - 4.0 * i * k;
    let re = -C / (2.0 * i);
    if disc < 0.0 {
        let im = (-disc).sqrt() / (2.0 * i);
        [(re, im), (re, -im)]
    } else {
        let d = disc.sqrt() / (2.0 * i);
        [(re + d, 0.0), (re - d, 0.0)]
    }
}

#[test]
fn passive_arm_is_orthogonal_of_degrees_2_2_with_a_2_dimensional_internal_dynamics() {
    let s = load(&text());
    let r = s.servo_report(&s.settings, false).expect("realizable");
    assert_eq!(r.analysis.degrees, vec![2, 2]);
    assert_eq!(r.analysis.index, 3);
    assert_eq!(r.analysis.realization, Realization::Orthogonal);
    assert_eq!(r.internal.dimension, 2);
}

#[test]
fn the_held_passive_link_has_the_damped_pendulums_eigenvalues() {
    // Algebraic class: exact Jacobians by duals, then a 2x2 Schur form: k * eps.
    for (upright, k) in [(false, M3 * G * LC), (true, -M3 * G * LC)] {
        let s = held(upright, 0.0, 2.0);
        let r = s.servo_report(&s.settings, false).expect("realizable");
        let e = &r.internal.eigenvalues_t0;
        let want = roots(k);
        eprintln!("upright {upright}: eigenvalues {e:?}, closed form {want:?}");
        assert_eq!(e.len(), 2);
        for (x, (re, im)) in e.iter().zip(want) {
            assert!(
                (x.re - re).abs() < 1e-12 * re.abs().max(1.0)
                    && (x.im - im).abs() < 1e-12 * im.abs().max(1.0),
                "{x:?} vs ({re}, {im})"
            );
        }
    }
}

#[test]
fn the_held_passive_link_swings_as_the_linear_damped_oscillator() {
    // Independent of the eigenvalue code: x = q3 - q3_hang from x(0) = d, x'(0) = 0 against
    // x(t) = d e^(-s t) (cos(wd t) + s/wd sin(wd t)), s = c/(2I), wd = sqrt(k/I - s^2). The
    // pendulum's cubic term leaves d^3/6 relative to d (1.7e-9 at d = 1e-4); the solver's rtol 1e-10.
    let d = 1e-4;
    let s = held(false, d, 4.0);
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{}", sol.code);
    let i = IYY + M3 * LC * LC;
    let (sg, wd) = (
        C / (2.0 * i),
        (M3 * G * LC / i - (C / (2.0 * i)).powi(2)).sqrt(),
    );
    let hang = -std::f64::consts::FRAC_PI_2 - param(&s, "q10") - param(&s, "q20");
    let tr = &sol.trajectory;
    let mut e = 0.0f64;
    for k in 0..tr.len() {
        let t = tr.t[k];
        let lin = d * (-sg * t).exp() * ((wd * t).cos() + sg / wd * (wd * t).sin());
        e = e.max((tr.q_at(k)[2] - hang - lin).abs());
        // P stays put: q1, q2 at rest.
        assert!((tr.q_at(k)[0] - param(&s, "q10")).abs() < 1e-10);
    }
    eprintln!("held passive link vs linear oscillator: max |error| {e:.2e} (d = {d:e})");
    assert!(e < 1e-3 * d, "error {e:.2e} against amplitude {d:e}");
}

#[test]
fn passive_arm_follows_the_inverse_kinematics_and_the_ideal_realization() {
    // Integrated-trajectory class, in units of the scene's rtol (1e-10).
    let s = load(&text());
    let e = ik_error(&s, &s.settings);
    eprintln!("passive_arm vs inverse kinematics: {e:.2e}");
    assert!(e < 20.0 * s.settings.rtol, "{e:.2e}");
    // Second formulation of the passive link: the realization is orthogonal (B has no q3 column),
    // so the ideal realization (null-space equations, no actuators) gives the same motion and u.
    let t = text();
    let start = t.find("[[actuators]]").unwrap();
    let end = t.find("# On the hidden constraints").unwrap();
    let mut ideal = t.clone();
    ideal.replace_range(start..end, "");
    let si = load(&ideal);
    assert!(si.servo_analysis().is_none());
    let (a, b) = (s.solve(&s.settings), si.solve(&si.settings));
    assert!(b.code.is_success(), "{}", b.code);
    let (ta, tb) = (&a.trajectory, &b.trajectory);
    assert_eq!(ta.len(), tb.len());
    let (mut eq, mut eu, mut umax) = (0.0f64, 0.0f64, 0.0f64);
    for k in 0..ta.len() {
        for j in 0..3 {
            eq = eq.max((ta.q_at(k)[j] - tb.q_at(k)[j]).abs());
            eu = eu.max((ta.u_at(k)[j] - tb.u_at(k)[j]).abs());
            umax = umax.max(tb.u_at(k)[j].abs());
        }
        assert_eq!(
            ta.u_at(k)[2],
            0.0,
            "u = H tau is exactly 0 on the passive joint"
        );
    }
    eprintln!("servo vs ideal realization: q {eq:.2e}, u {eu:.2e} (max |u| {umax:.2})");
    assert!(eq < 20.0 * s.settings.rtol, "q {eq:.2e}");
    assert!(eu < 20.0 * s.settings.rtol * umax, "u {eu:.2e}");
}

#[test]
fn passive_arm_converges_at_rk4_order_without_projection() {
    // Without projection the index-reduced ODE's own error shows in q1, q2 (the programme is not
    // pinned to the state: 4 hidden constraints on 6 coordinates): RK4 order 4 within 0.3.
    let s = load(&text());
    let hs = [0.04, 0.02, 0.01];
    let errs: Vec<f64> = hs
        .iter()
        .map(|&h| {
            let settings = Settings {
                integrator: Method::Rk4 { h },
                drift: DriftControl::None,
                output: Output::Every(0.2),
                ..s.settings.clone()
            };
            ik_error(&s, &settings)
        })
        .collect();
    eprintln!("passive_arm rk4 without projection, h = {hs:?}: errors {errs:?}");
    for k in 1..hs.len() {
        let order = (errs[k - 1] / errs[k]).log2();
        assert!(
            (order - 4.0).abs() < 0.3,
            "errors {errs:?}: order {order:.2}"
        );
    }
}

#[test]
fn passive_arm_internal_dynamics_is_stable_along_the_motion_and_errors_decay() {
    let s = load(&text());
    let r = s.servo_report(&s.settings, true).expect("realizable");
    let i = &r.internal;
    let along = i.along.as_ref().expect("sampled");
    let g = i.growth.as_ref().expect("perturbed run");
    eprintln!("passive_arm internal dynamics: {along:?}\n growth {g:?}");
    assert_eq!(i.stability, Some("stable"));
    assert!(i.horizon.is_none());
    assert!(along.max_real < 0.0);
    // The perturbed run's separation decays (damping c/(2I) = 0.94/s at hanging).
    assert!(
        g.rate < 0.0 && g.final_separation < g.initial_separation,
        "{g:?}"
    );
}

#[test]
fn the_upright_passive_link_is_unstable_with_its_growth_rate_and_horizon() {
    // Unstable variant (P held, link 3 balanced upright: non-minimum-phase zero dynamics). The
    // frozen eigenvalue is the closed-form positive root; the perturbed run's mean rate over 1.5 s
    // includes ln(c)/T of the initial direction's share c in the unstable mode, hence 15 %.
    let s = held(true, 0.0, 1.5);
    let r = s.servo_report(&s.settings, true).expect("realizable");
    let i = &r.internal;
    let lam = roots(-M3 * G * LC)[0].0;
    let along = i.along.as_ref().expect("sampled");
    let g = i.growth.as_ref().expect("perturbed run");
    let horizon = i.horizon.expect("unstable: horizon stated");
    eprintln!(
        "upright: max real {:.6} (closed form {lam:.6}), growth seen {:.4}/s \
         (separation {:.2e} -> {:.2e} over {} s), horizon {horizon:.3} s",
        along.max_real, g.rate, g.initial_separation, g.final_separation, g.t_end
    );
    assert_eq!(i.stability, Some("unstable"));
    assert!(
        (along.max_real - lam).abs() < 1e-9 * lam,
        "{}",
        along.max_real
    );
    assert!((g.rate - lam).abs() < 0.15 * lam, "{g:?}");
    assert!((horizon - (1.0 / s.settings.rtol).ln() / lam).abs() < 1e-9 * horizon);
}
