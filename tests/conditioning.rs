//! The conditioning monitor, early stops and programme-free scenes (issue 9).
//!
//! - A programme that passes close to its singular set warns (with the time and the rows) and, in
//!   strict mode, stops there: Example 3.1's row (3.14) on a heavy top whose (p, q) passes through
//!   zero (the gradient (-q, p, 0) collapses, seed NOTES), and the two-link arm touching its dead
//!   point (hard case 1c': B of rank 1 at t = 1.5 s).
//! - Negative controls: the same scenes with the thresholds beyond what they reach do not warn.
//! - On an early stop, the return code's time, `t_end` and the last sample are one instant.
//! - Zero programme rows: the free motion, u = 0, energy conserved (an invariant of the model).

use progmo::problems::hard;
use progmo::scene::{Scene, SceneSystem};
use progmo::solve::{solve, Output, ReturnCode, Settings, WarningKind};
use std::path::PathBuf;

fn test_scene(name: &str) -> Scene {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("tests/scenes/{name}.toml"));
    Scene::load(&p).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn precession_through_its_degenerate_point_warns() {
    let scene = test_scene("precession_degenerate");
    let sol = scene.solve(&scene.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let w = sol
        .warnings
        .iter()
        .find(|w| w.kind == WarningKind::RowGradient)
        .unwrap_or_else(|| panic!("no row_gradient warning: {:?}", sol.warnings));
    eprintln!("{w}");
    assert_eq!(w.rows, vec!["precession".to_string()]);
    assert!(w.value < 1e-3 && w.worst <= w.value);
    // p^2 + q^2 is smallest at about t = 2.26 s (output samples every 0.01 s).
    let tr = &sol.trajectory;
    let k = (0..tr.len())
        .min_by(|&i, &j| {
            let pq = |k: usize| tr.v_at(k)[0].powi(2) + tr.v_at(k)[1].powi(2);
            pq(i).total_cmp(&pq(j))
        })
        .unwrap();
    assert!(
        (w.t_worst - tr.t[k]).abs() < 0.02,
        "{} vs {}",
        w.t_worst,
        tr.t[k]
    );
    assert!(
        w.t <= w.t_worst && w.t > 2.0,
        "first {} worst {}",
        w.t,
        w.t_worst
    );
    assert!(sol.stats.min_row_gradient_ratio == w.worst);
    assert!(w.to_string().contains("`precession`"));

    // Negative control: a threshold below what the run reaches gives no warning.
    let mut s = scene.settings.clone();
    s.conditioning.row_gradient = w.worst / 10.0;
    let quiet = scene.solve(&s);
    assert!(
        !quiet
            .warnings
            .iter()
            .any(|w| w.kind == WarningKind::RowGradient),
        "{:?}",
        quiet.warnings
    );

    // Strict: the warning stops the solve there, and the stop is one instant everywhere.
    let mut s = scene.settings.clone();
    s.strict = true;
    let st = scene.solve(&s);
    let ReturnCode::IllConditioned { t, warning } = &st.code else {
        panic!("{:?}", st.code)
    };
    assert_eq!(warning.kind, WarningKind::RowGradient);
    assert_eq!(*t, st.t_end);
    assert_eq!(st.trajectory.t.last().copied(), Some(st.t_end));
    assert!((st.t_end - w.t).abs() < 0.02, "{} vs {}", st.t_end, w.t);
}

#[test]
fn dead_point_touch_warns() {
    // Hard case 1c': DOP853 succeeds on a non-smooth branch (references/hard/README.md); the monitor
    // must say that the rows became nearly dependent near tc.
    let p = hard::arm_touching_boundary();
    let tc = p.constraints.tc;
    let sol = solve(&p, &Settings::default());
    let w = sol
        .warnings
        .iter()
        .find(|w| w.kind == WarningKind::SingularValue)
        .unwrap_or_else(|| {
            panic!(
                "{:?}: no singular_value warning: {:?}",
                sol.code, sol.warnings
            )
        });
    eprintln!("{:?}: {w}", sol.code);
    assert!(
        (w.t_worst - tc).abs() < 0.05,
        "worst at {} (tc {tc})",
        w.t_worst
    );
    assert!(!w.rows.is_empty());
    let mut s = Settings::default();
    s.conditioning.singular_value = w.worst / 10.0;
    s.conditioning.row_gradient = 0.0;
    s.conditioning.u_cancellation = f64::INFINITY;
    assert!(solve(&p, &s).warnings.is_empty());
}

#[test]
fn an_early_stop_is_one_instant() {
    // The arm pulled through its workspace boundary stops with a singular programme inside a step;
    // with dense output the stop must still be reported at the last written sample.
    for output in [Output::Steps, Output::Every(0.01)] {
        let p = hard::arm_through_boundary();
        let s = Settings {
            rank_dependent: 1e-6,
            output,
            ..Default::default()
        };
        let sol = solve(&p, &s);
        assert!(!sol.code.is_success());
        let t_code = sol.code.time().expect("a stop has a time");
        eprintln!("{output:?}: {}", sol.code);
        assert_eq!(t_code, sol.t_end, "{:?}", sol.code);
        assert_eq!(sol.trajectory.t.last().copied(), Some(sol.t_end));
        let msg = sol.code.to_string();
        assert!(msg.contains("at t = ") && msg.contains("`tip_"), "{msg}");
        assert!(!msg.contains('{'), "{msg}");
    }
}

#[test]
fn a_scene_without_programme_is_the_free_motion() {
    let scene = test_scene("no_programme");
    assert!(scene.rows().is_empty());
    let sol = scene.solve(&scene.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    assert!(sol.trajectory.u.iter().all(|&u| u == 0.0));
    let SceneSystem::Tree(p) = &scene.system else {
        panic!()
    };
    let tree = p.model.tree();
    let mut data = tree.data();
    let tr = &sol.trajectory;
    let mut energy = |k: usize| {
        progmo::tree::kinetic_energy(tree, &mut data, tr.q_at(k), tr.v_at(k))
            + progmo::tree::potential_energy(tree, &mut data, tr.q_at(k))
    };
    let e0 = energy(0);
    let drift = (0..tr.len())
        .map(|k| (energy(k) - e0).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "no programme: energy {e0:.6}, drift {drift:.2e}, {} samples",
        tr.len()
    );
    // Integrated-trajectory class: DOP853 at rtol 1e-10 over 3 s of a chaotic double pendulum.
    assert!(drift < 1e-8 * e0.abs().max(1.0), "energy drift {drift:e}");
}
