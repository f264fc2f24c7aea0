//! The bundled scene catalog (`references/scenes/`): every scene loads, solves and meets its own
//! programme-residual tolerance; tree and Lagrangian descriptions agree with the Rust problems.

use crate::common;

use progmo::scene::Scene;
use std::path::PathBuf;

fn catalog() -> Vec<PathBuf> {
    common::toml_files("references/scenes")
}

#[test]
fn every_bundled_scene_solves_within_its_tolerance() {
    let files = catalog();
    assert!(files.len() >= 4, "catalog has {} scenes", files.len());
    for f in files {
        let scene = Scene::load(&f).unwrap_or_else(|e| panic!("{e}"));
        let sol = scene.solve(&scene.settings);
        assert!(sol.code.is_success(), "{}: {:?}", scene.name, sol.code);
        let tol = scene
            .tolerance("programme_residual")
            .unwrap_or_else(|| panic!("{}: no programme_residual tolerance", scene.name));
        let worst = sol.max_residual.iter().cloned().fold(0.0, f64::max);
        assert!(worst <= tol, "{}: residual {worst:e} > {tol:e}", scene.name);
        // No bundled scene comes near a programme singularity (conditioning monitor, issue 9).
        assert!(
            sol.warnings.is_empty(),
            "{}: unexpected conditioning warnings: {:?}",
            scene.name,
            sol.warnings
        );
        eprintln!(
            "{}: ok, residual {worst:.1e}, {} steps",
            scene.name, sol.stats.integrator.steps
        );
    }
}

fn load(name: &str) -> Scene {
    let p =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("references/scenes/{name}.toml"));
    Scene::load(&p).unwrap_or_else(|e| panic!("{e}"))
}

/// A second formulation of the same system: the tree scene (CRBA/RNEA, attractor field, joints
/// composed in one body) against the hand-derived Lagrangian of `problems::particle` (coordinate
/// order (phi, theta, r) there (theta, phi, r)). Agreement in units of the solver tolerance.
#[test]
fn example_2_1_tree_scene_matches_the_hand_derived_model() {
    use progmo::problems::particle;
    use progmo::solve::{solve, Output};
    let scene = load("example_2_1");
    let mut s = scene.settings.clone();
    s.output = Output::Every(0.5);
    let a = scene.solve(&s);
    let b = solve(&particle::example_2_1(), &s);
    assert_eq!(a.trajectory.len(), b.trajectory.len());
    let mut worst: f64 = 0.0;
    for k in 0..a.trajectory.len() {
        let (qa, qb) = (a.trajectory.q_at(k), b.trajectory.q_at(k));
        let (ua, ub) = (a.trajectory.u_at(k), b.trajectory.u_at(k));
        for (i, j) in [(0, 1), (1, 0), (2, 2)] {
            worst = worst.max((qa[i] - qb[j]).abs()).max((ua[i] - ub[j]).abs());
        }
    }
    assert!(worst < 1e3 * s.rtol, "tree vs hand-derived: {worst:e}");
}

/// The heavy-top scene (ball joint, CoM offset, uniform gravity) against `problems::rigid_body`
/// (Euler's equations about the fixed point with the gravity torque written by hand).
#[test]
fn heavy_top_tree_scene_matches_the_hand_derived_model() {
    use progmo::problems::rigid_body;
    use progmo::solve::{solve, Output};
    let scene = load("heavy_top");
    let mut s = scene.settings.clone();
    s.output = Output::Every(0.25);
    let a = scene.solve(&s);
    let b = solve(&rigid_body::heavy_top(), &s);
    let worst = a
        .trajectory
        .v
        .iter()
        .zip(&b.trajectory.v)
        .chain(a.trajectory.u.iter().zip(&b.trajectory.u))
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(
        worst < 1e3 * s.rtol * 8.0,
        "tree vs hand-derived: {worst:e}"
    );
}
