//! The check's vocabulary (`progmo::check`): unique names, the residual budget's drift rule, the
//! metrics each check judges, and the nearest-name rule the loader's suggestions use. The loader's
//! refusals of names outside it are in `tests/bad_scenes` (names_tolerance_*, names_not_checked_*).

use progmo::check::{
    did_you_mean, metric, metrics_for, nearest, tolerance_keys, When, METRICS, SIMULATORS,
    SOLVER_ONLY,
};
use progmo::solve::DriftControl;

#[test]
fn names_are_unique_and_every_metric_is_judged_somewhere() {
    let keys = tolerance_keys();
    let mut sorted = keys.clone();
    sorted.sort();
    sorted.dedup();
    assert_eq!(
        sorted.len(),
        keys.len(),
        "a [tolerances] name twice: {keys:?}"
    );
    for m in &METRICS {
        assert!(
            m.simulators != When::Never || m.solver_only != When::Never,
            "{}",
            m.name
        );
        assert!(!m.reason.is_empty() && !m.class.is_empty(), "{}", m.name);
    }
}

#[test]
fn the_residual_budget_follows_the_drift_control() {
    let m = metric("solver_residual").unwrap();
    let p = DriftControl::Projection {
        tol: 1e-11,
        max_iter: 8,
    };
    let (v, why) = m.default_budget(&p);
    assert_eq!(v, 100.0 * 1e-11);
    assert!(
        why.starts_with("default (integrated): 100 x projection_tol (1e-11)"),
        "{why}"
    );
    let (v, why) = m.default_budget(&DriftControl::None);
    assert_eq!(v, 1e-8);
    assert!(
        why.contains("drift control none") && why.contains("(rtol 1e-12)"),
        "{why}"
    );
    let (v, why) = metric("parity_mass").unwrap().default_budget(&p);
    assert_eq!(v, 1e-11);
    assert!(why.starts_with("default (algebraic identity): "), "{why}");
}

#[test]
fn a_misspelt_name_finds_its_metric_and_a_far_one_none() {
    let keys = tolerance_keys();
    let near = |n: &str| nearest(n, keys.iter().map(|s| s.as_str()));
    assert_eq!(near("replay_residul").as_deref(), Some("replay_residual"));
    assert_eq!(
        near("programe_residual").as_deref(),
        Some("programme_residual")
    );
    assert_eq!(
        near("parity_bias_pinochio").as_deref(),
        Some("parity_bias_pinocchio")
    );
    assert_eq!(near("tolerance"), None);
    assert_eq!(
        did_you_mean("mujocco", SIMULATORS.iter().copied()),
        " (did you mean `mujoco`?)"
    );
    assert_eq!(did_you_mean("gazebo", SIMULATORS.iter().copied()), "");
}

#[test]
fn each_check_judges_its_metrics() {
    let names = |v: Vec<&progmo::check::Metric>| v.iter().map(|m| m.name).collect::<Vec<_>>();
    let base = [
        "solver_residual",
        "parity_mass",
        "parity_bias",
        "instant_u",
        "replay_residual",
        "replay_deviation",
    ];
    assert_eq!(
        names(metrics_for("mujoco", false, false, true, false)),
        base
    );
    let mut all = base.to_vec();
    all.extend([
        "parity_closure",
        "reaction_closure",
        "replay_unactuated",
        "inverse_dynamics",
    ]);
    assert_eq!(
        names(metrics_for("pinocchio", true, true, false, true)),
        all
    );
    assert_eq!(
        names(metrics_for(SOLVER_ONLY, true, true, false, true)),
        [
            "solver_residual",
            "formulation_deviation",
            "formulation_force_deviation"
        ]
    );
    assert_eq!(
        names(metrics_for(SOLVER_ONLY, false, false, true, false)).last(),
        Some(&"reference_error")
    );
}
