//! Monitors that watch between evaluations, and the global error of fixed-step solves (issue 28).
//!
//! - Fixed-step RK4 through Example 3.1's degenerate point (tests/scenes/precession_degenerate:
//!   (p, q) passes through 0, the row gradient (-q, p, 0) collapses) steps over the dip with every
//!   stage well above the threshold; the monitor finds it inside the step, at the time a tight
//!   adaptive solve puts it, warns, reports what the passage cost as the Richardson companion
//!   measures it (checked against the real error, from a tight adaptive solve), and `strict` stops
//!   before it keeping the samples.
//! - A fixed-step solve carries a Richardson global error estimate, checked against the real error
//!   of heavy_top (a tight adaptive solve as reference); negative control: the estimate of h
//!   does not match the error of 2h.

use progmo::integrate::Method;
use progmo::scene::Scene;
use progmo::solve::{ReturnCode, Settings, Solution, WarningKind};
use std::path::PathBuf;

fn scene(path: &str) -> Scene {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(path);
    Scene::load(&p).unwrap_or_else(|e| panic!("{e}"))
}

fn rk4(scene: &Scene, h: f64) -> Settings {
    Settings {
        integrator: Method::Rk4 { h },
        ..scene.settings.clone()
    }
}

fn tight(scene: &Scene) -> Solution {
    let s = Settings {
        rtol: 1e-13,
        atol: 1e-15,
        ..scene.settings.clone()
    };
    let sol = scene.solve(&s);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    sol
}

/// Largest relative error of the velocities (max |dv| / max |v_ref| per sample) of `a` against
/// `reference` over the samples both have in [from, to].
fn v_error(a: &Solution, reference: &Solution, from: f64, to: f64) -> f64 {
    let (ta, tr) = (&a.trajectory, &reference.trajectory);
    let mut e = 0.0f64;
    let mut k = 0;
    for i in 0..ta.len() {
        let t = ta.t[i];
        if t < from || t > to {
            continue;
        }
        while k < tr.len() && tr.t[k] < t - 1e-9 {
            k += 1;
        }
        if k >= tr.len() || (tr.t[k] - t).abs() > 1e-9 {
            continue;
        }
        let (va, vr) = (ta.v_at(i), tr.v_at(k));
        let scale = vr.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let d = va
            .iter()
            .zip(vr)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        e = e.max(d / scale);
    }
    e
}

#[test]
fn fixed_step_rk4_through_the_precession_degeneracy_warns() {
    let sc = scene("tests/scenes/precession_degenerate.toml");
    let reference = tight(&sc);
    // The dip's time from the tight solve (its per-evaluation monitor sees it: small steps there).
    let t_dip = reference
        .warnings
        .iter()
        .find(|w| w.kind == WarningKind::RowGradient)
        .expect("the tight solve warns")
        .t_worst;
    assert!((t_dip - 2.26).abs() < 0.01, "{t_dip}");
    let threshold = sc.settings.conditioning.row_gradient;
    for h in [0.01, 0.005, 0.002] {
        let s = rk4(&sc, h);
        let sol = sc.solve(&s);
        assert!(sol.code.is_success(), "h = {h}: {:?}", sol.code);
        let w = sol
            .warnings
            .iter()
            .find(|w| w.kind == WarningKind::RowGradient)
            .unwrap_or_else(|| panic!("h = {h}: no row_gradient warning: {:?}", sol.warnings));
        eprintln!("h = {h}: {w}");
        assert_eq!(w.rows, vec!["precession".to_string()]);
        assert!(w.worst < threshold, "{}", w.worst);
        // Located inside the step containing the dip (within a step of the tight solve's time).
        assert!(
            (w.t_worst - t_dip).abs() <= h,
            "h = {h}: {} vs {t_dip}",
            w.t_worst
        );
        // What the passage cost: the companion's estimate against the real error after it.
        let after = v_error(&sol, &reference, t_dip + 0.01, f64::INFINITY);
        let before = v_error(&sol, &reference, 0.0, t_dip - 0.01);
        let est = w
            .error_after
            .expect("the companion measured the error after the dip");
        eprintln!("h = {h}: error before {before:.2e} after {after:.2e}, estimated {est:.2e}");
        assert!(
            after > 1e-2,
            "h = {h}: the passage was stepped over ({after:.2e})"
        );
        assert!(
            (est.log10() - after.log10()).abs() <= 2.0,
            "h = {h}: estimated {est:.2e}, real {after:.2e}"
        );
        assert!(
            w.to_string().contains("digit"),
            "the message states the loss: {w}"
        );
        let g = sol.global_error.as_ref().expect("fixed step: global error");
        assert!(g.scaled > g.budget, "{g:?}");
        assert!(sol
            .warnings
            .iter()
            .any(|w| w.kind == WarningKind::GlobalError));

        // Strict: stops at the step before the dip, keeping the samples up to there.
        let st = sc.solve(&Settings {
            strict: true,
            ..s.clone()
        });
        let ReturnCode::IllConditioned { t, warning } = &st.code else {
            panic!("h = {h}: {:?}", st.code)
        };
        assert_eq!(warning.kind, WarningKind::RowGradient);
        assert_eq!(*t, st.t_end);
        assert!(
            st.t_end <= w.t_worst && st.t_end > w.t_worst - 0.02,
            "{}",
            st.t_end
        );
        assert_eq!(st.trajectory.t.last().copied(), Some(st.t_end));
        // The kept samples are the run's own before the dip (the monitor changes no state).
        assert_eq!(v_error(&st, &reference, 0.0, t_dip - 0.01), before);

        // Negative control: a threshold below the located depth gives no row_gradient warning.
        let mut quiet = s.clone();
        quiet.conditioning.row_gradient = w.worst / 10.0;
        let q = sc.solve(&quiet);
        assert!(
            !q.warnings
                .iter()
                .any(|w| w.kind == WarningKind::RowGradient),
            "{:?}",
            q.warnings
        );
    }
}

#[test]
fn fixed_step_solves_estimate_their_global_error() {
    let sc = scene("references/scenes/heavy_top.toml");
    let reference = tight(&sc);
    let mut real = vec![];
    let mut est = vec![];
    for h in [0.01, 0.005] {
        let sol = sc.solve(&rk4(&sc, h));
        assert!(sol.code.is_success(), "{:?}", sol.code);
        let g = sol
            .global_error
            .clone()
            .expect("a fixed-step solve has one");
        assert_eq!((g.order, g.step, g.companion_step), (4, h, 2.0 * h));
        assert_eq!(g.companion_code, "success");
        assert_eq!(g.samples, sol.trajectory.len());
        // The companion's cost is reported: about half of the solve's evaluations.
        let ratio = g.companion.rhs_evals as f64 / sol.stats.integrator.rhs_evals as f64;
        assert!((0.4..0.6).contains(&ratio), "{ratio}");
        // Absolute error of (q, v) against the tight solve, the quantity `estimate` estimates.
        let (ta, tr) = (&sol.trajectory, &reference.trajectory);
        let mut e = 0.0f64;
        let mut k = 0;
        for i in 0..ta.len() {
            while tr.t[k] < ta.t[i] - 1e-9 {
                k += 1;
            }
            assert!((tr.t[k] - ta.t[i]).abs() < 1e-9);
            for (x, y) in ta
                .q_at(i)
                .iter()
                .chain(ta.v_at(i))
                .zip(tr.q_at(k).iter().chain(tr.v_at(k)))
            {
                e = e.max((x - y).abs());
            }
        }
        eprintln!(
            "h = {h}: real {e:.3e}, estimated {:.3e}, scaled {:.2e}",
            g.estimate, g.scaled
        );
        real.push(e);
        est.push(g.estimate);
        // At the default rtol 1e-10 these steps are far less accurate than asked: warned.
        assert!(g.scaled > g.budget);
        let w = sol
            .warnings
            .iter()
            .find(|w| w.kind == WarningKind::GlobalError)
            .expect("over budget: warned");
        assert_eq!(w.worst, g.scaled);
        assert!(w.to_string().contains("global error"), "{w}");
    }
    for k in 0..2 {
        let r = est[k] / real[k];
        assert!((0.5..2.0).contains(&r), "estimate / real = {r}");
    }
    // Negative control: h's estimate does not pass for 2h's error (RK4: 16 times larger).
    let r = est[1] / real[0];
    assert!(!(0.5..2.0).contains(&r), "{r}");

    // Within budget with the budget's own tolerances loose enough: no warning.
    let loose = Settings {
        rtol: 1e-3,
        atol: 1e-3,
        ..rk4(&sc, 0.01)
    };
    let sol = sc.solve(&loose);
    let g = sol.global_error.as_ref().unwrap();
    assert!(g.scaled <= g.budget, "{g:?}");
    assert!(sol.warnings.is_empty(), "{:?}", sol.warnings);

    // Strict: over budget is the code ill_conditioned, results kept.
    let st = sc.solve(&Settings {
        strict: true,
        ..rk4(&sc, 0.01)
    });
    let ReturnCode::IllConditioned { warning, .. } = &st.code else {
        panic!("{:?}", st.code)
    };
    assert_eq!(warning.kind, WarningKind::GlobalError);
    assert_eq!(st.t_end, 5.0);

    // Opt-out: no companion, no estimate.
    let off = sc.solve(&Settings {
        richardson: false,
        ..rk4(&sc, 0.01)
    });
    assert!(off.global_error.is_none() && off.warnings.is_empty());
    // Adaptive solves have none.
    assert!(sc.solve(&sc.settings).global_error.is_none());
}
