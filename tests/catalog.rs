//! The catalog (`references/scenes/`): every scene says what it checks, and the catalog scenes
//! reproduce what their `purpose` claims (exact solutions, invariants). The scene format's schema
//! and its agreement with the loader and FORMAT.md: `tests/schema.rs`.

use crate::common;

use progmo::scene::Scene;
use std::path::PathBuf;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn catalog() -> Vec<PathBuf> {
    common::toml_files("references/scenes")
}

// ---------------------------------------------------------------------------------------------
// What the new catalog scenes claim.

fn load(name: &str) -> Scene {
    Scene::load(root().join(format!("references/scenes/{name}.toml")))
        .unwrap_or_else(|e| panic!("{e}"))
}

fn param(s: &Scene, name: &str) -> f64 {
    s.parameters.iter().find(|p| p.0 == name).unwrap().1
}

#[test]
fn every_catalog_scene_says_what_it_checks() {
    for f in catalog() {
        let s = Scene::load(&f).unwrap_or_else(|e| panic!("{e}"));
        assert!(!s.description.trim().is_empty(), "{}: description", s.name);
        assert!(!s.purpose.trim().is_empty(), "{}: purpose", s.name);
        assert_eq!(
            Some(s.name.as_str()),
            f.file_stem().and_then(|x| x.to_str()),
            "scene name = file name"
        );
        let t = s.tolerances.iter().find(|t| t.name == "programme_residual");
        assert!(t.is_some_and(|t| !t.reason.trim().is_empty()), "{}", s.name);
    }
}

/// Knife edge (Chaplygin sleigh with prescribed heading): theta = omega t, forward speed
/// v = V + b omega^2 t, lateral force F = m v omega, steering torque tau = b m v omega, and the
/// contact point on the closed-form spiral of the scene's purpose.
#[test]
fn knife_edge_matches_the_closed_form() {
    let s = load("knife_edge");
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let (v0, w, m, b) = (
        param(&s, "V"),
        param(&s, "omega"),
        param(&s, "m"),
        param(&s, "b"),
    );
    let tr = &sol.trajectory;
    let mut worst: f64 = 0.0;
    for k in 0..tr.len() {
        let t = tr.t[k];
        let (q, v, u) = (tr.q_at(k), tr.v_at(k), tr.u_at(k));
        let (c, sn) = ((w * t).cos(), (w * t).sin());
        let speed = v0 + b * w * w * t;
        let x = v0 * sn / w + b * (w * t * sn + c - 1.0);
        let y = v0 * (1.0 - c) / w + b * (sn - w * t * c);
        let f = m * speed * w;
        worst = worst
            .max((q[0] - x).abs())
            .max((q[1] - y).abs())
            .max((q[2] - w * t).abs())
            .max((v[0].hypot(v[1]) - speed).abs())
            .max((u[0] + f * sn).abs())
            .max((u[1] - f * c).abs())
            .max((u[2] - b * f).abs());
    }
    assert!(worst < 1e-7, "knife edge off the closed form by {worst:e}");
}

/// Appell-Hamel: fixed horizontal direction, s(t) = s0 - g a t / (1 + a^2), z' = a s.
#[test]
fn appell_hamel_matches_the_closed_form() {
    let s = load("appell_hamel");
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let (a, vx0, vy0) = (param(&s, "a"), param(&s, "vx0"), param(&s, "vy0"));
    let (s0, g) = (vx0.hypot(vy0), 9.81);
    let tr = &sol.trajectory;
    let mut worst: f64 = 0.0;
    for k in 0..tr.len() {
        let t = tr.t[k];
        let v = tr.v_at(k);
        let sh = s0 - g * a * t / (1.0 + a * a);
        worst = worst
            .max((v[0].hypot(v[1]) - sh).abs())
            .max((v[0] * vy0 - v[1] * vx0).abs())
            .max((v[2] - a * sh).abs());
    }
    assert!(
        worst < 1e-8,
        "Appell-Hamel off the closed form by {worst:e}"
    );
}

/// Slider crank: phi1 = Omega t, the loop stays closed, and the slider position follows from the
/// closure, x3 = L1 cos(phi1) + sqrt(L2^2 - L1^2 sin^2(phi1)).
#[test]
fn slider_crank_follows_its_kinematics() {
    let s = load("slider_crank");
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let (l1, l2, om) = (param(&s, "L1"), param(&s, "L2"), param(&s, "Omega"));
    let tr = &sol.trajectory;
    let mut worst: f64 = 0.0;
    for k in 0..tr.len() {
        let q = tr.q_at(k);
        let p1 = om * tr.t[k];
        let x3 = l1 * p1.cos() + (l2 * l2 - (l1 * p1.sin()).powi(2)).sqrt();
        worst = worst.max((q[0] - p1).abs()).max((q[2] - x3).abs());
    }
    assert!(worst < 1e-9, "slider crank kinematics off by {worst:e}");
    assert_eq!(tr.t.last().copied(), Some(0.1));
    // Power balance: the closure reactions do no work, so the drive's control force alone
    // changes the kinetic energy: u . v = dT/dt = v^T A a + 1/2 v^T (dA/dt) v.
    let (m2, m3, j1, j2) = (
        param(&s, "M2"),
        param(&s, "M3"),
        param(&s, "J1"),
        param(&s, "J2"),
    );
    let c = 0.5 * l1 * l2 * m2;
    let (mut worst, mut scale): (f64, f64) = (0.0, 0.0);
    for k in 0..tr.len() {
        let (q, v, a, u) = (tr.q_at(k), tr.v_at(k), tr.a_at(k), tr.u_at(k));
        let d = q[0] - q[1];
        let am = [
            [j1 + m2 * l1 * l1, c * d.cos(), 0.0],
            [c * d.cos(), j2, 0.0],
            [0.0, 0.0, m3],
        ];
        let mut va = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                va += v[i] * am[i][j] * a[j];
            }
        }
        let adot12 = -c * d.sin() * (v[0] - v[1]);
        let dt = va + adot12 * v[0] * v[1];
        let power: f64 = u.iter().zip(v).map(|(x, y)| x * y).sum();
        let reaction_power: f64 = tr.reactions_at(k).iter().zip(v).map(|(x, y)| x * y).sum();
        worst = worst.max((power - dt).abs()).max(reaction_power.abs());
        scale = scale.max(dt.abs());
    }
    assert!(scale > 1.0, "the drive does work");
    assert!(
        worst < 1e-8 * scale,
        "power balance off by {worst:e} (scale {scale:e})"
    );
}

/// Planar arm: the tip stays on its line and moves at speed V; the self-motion is free.
#[test]
fn planar_arm_tip_moves_along_its_line() {
    let s = load("planar_arm_line");
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let (l, v0, z0) = (param(&s, "l"), param(&s, "V"), param(&s, "z0"));
    let tr = &sol.trajectory;
    let tip = |q: &[f64]| {
        let (mut x, mut z, mut a) = (0.0, 0.0, 0.0);
        for qi in q {
            a += qi;
            x += l * f64::cos(a);
            z += l * f64::sin(a);
        }
        (x, z)
    };
    let x0 = tip(tr.q_at(0)).0;
    let mut worst: f64 = 0.0;
    for k in 0..tr.len() {
        let (x, z) = tip(tr.q_at(k));
        worst = worst.max((z - z0).abs()).max((x - x0 - v0 * tr.t[k]).abs());
    }
    assert!(worst < 1e-9, "tip off its line by {worst:e}");
}
