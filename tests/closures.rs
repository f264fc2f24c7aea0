//! Loop closures of tree scenes (`[[model.closures]]`, src/scene/closures.rs): the catalog's
//! closed-loop tree scenes against independent references (closed-form kinematics, the lagrangian
//! slider crank as a second formulation), dependent closure rows set aside, located errors.

use progmo::scene::Scene;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn load(name: &str) -> Scene {
    Scene::load(root().join(format!("references/scenes/{name}.toml")))
        .unwrap_or_else(|e| panic!("{e}"))
}

fn param(s: &Scene, name: &str) -> f64 {
    s.parameters.iter().find(|p| p.0 == name).unwrap().1
}

/// Slider crank as a tree with a point closure: the planar loop's z row is set aside (its
/// gradient vanishes) and stays zero; x3 follows the closed form x3 = L1 cos(phi1) +
/// sqrt(L2^2 - L1^2 sin^2(phi1)); the motor torque and the closure reactions equal those of the
/// lagrangian slider_crank (a second formulation: other coordinates, A(q) written by hand).
#[test]
fn slider_crank_tree_matches_closed_form_and_lagrangian() {
    let s = load("slider_crank_tree");
    let (aside, _) = s
        .set_aside
        .as_ref()
        .expect("a planar loop sets a row aside");
    assert_eq!(aside.len(), 1);
    assert_eq!(aside[0].row, "pin_z");
    assert!(aside[0].reason.contains("vanishes"), "{}", aside[0].reason);
    let rows: Vec<String> = s.rows().into_iter().map(|r| r.name).collect();
    assert_eq!(rows, ["pin_x", "pin_y", "drive"]);

    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let lag = load("slider_crank");
    let lsol = lag.solve(&lag.settings);
    assert!(lsol.code.is_success(), "{:?}", lsol.code);
    let (l1, l2) = (param(&s, "L1"), param(&s, "L2"));
    let (tr, lt) = (&sol.trajectory, &lsol.trajectory);
    assert_eq!(tr.t, lt.t, "same output grid");
    let (mut dx, mut dx_control, mut du, mut dl, mut umax, mut lmax, mut z) =
        (0f64, f64::INFINITY, 0f64, 0f64, 0f64, 0f64, 0f64);
    let li = |name: &str| lt.row_names.iter().position(|n| n == name).unwrap();
    let ti = |name: &str| tr.row_names.iter().position(|n| n == name).unwrap();
    let (s_l, s_t) = (lt.row_names.len(), tr.row_names.len());
    for k in 0..tr.len() {
        let (q, v) = (tr.q_at(k), tr.v_at(k));
        let phi = q[0];
        let x3 = l1 * phi.cos() + (l2 * l2 - (l1 * phi.sin()).powi(2)).sqrt();
        dx = dx.max((q[2] - x3).abs());
        // Negative control: a rod 1 mm longer in the closed form must be told apart.
        let l2c = l2 + 1e-3;
        let x3c = l1 * phi.cos() + (l2c * l2c - (l1 * phi.sin()).powi(2)).sqrt();
        dx_control = dx_control.min((q[2] - x3c).abs());
        // u on the crank (same virtual work tau dphi1 in both coordinate sets).
        du = du.max((tr.u_at(k)[0] - lt.u_at(k)[0]).abs());
        umax = umax.max(lt.u_at(k)[0].abs());
        // Closure forces: tree rows are p_rod - p_slider, lagrangian closure_x = x3 - (...).
        let lam = &tr.lambda[k * s_t..(k + 1) * s_t];
        let llam = &lt.lambda[k * s_l..(k + 1) * s_l];
        dl = dl
            .max((lam[ti("pin_x")] + llam[li("closure_x")]).abs())
            .max((lam[ti("pin_y")] - llam[li("closure_y")]).abs());
        lmax = lmax.max(llam[li("closure_x")].abs());
        for (_, g) in s.set_aside_residuals(tr.t[k], q, v) {
            z = z.max(g.abs());
        }
    }
    // Trajectory class: both solves at rtol 1e-10 with projection to 1e-12.
    assert!(dx < 1e-10, "x3 off the closed form by {dx:e}");
    assert!(
        dx_control > 1e-4,
        "control: rod +1 mm only {dx_control:e} away"
    );
    assert!(du < 1e-9 * umax, "u differs by {du:e} (max |u| {umax:e})");
    assert!(
        dl < 1e-9 * lmax,
        "closure reactions differ by {dl:e} (max {lmax:e})"
    );
    assert!(z < 1e-15, "set-aside row pin_z drifted to {z:e}");
}

/// Four-bar: the rocker angle over the run against Freudenstein's closed form (written here
/// independently of the scene's triangle construction of its initial state), branch chosen at
/// t0; the other assembly branch is the negative control.
#[test]
fn four_bar_follows_freudenstein() {
    let s = load("four_bar");
    let aside = &s.set_aside.as_ref().expect("planar loop").0;
    assert_eq!(
        aside.iter().map(|a| a.row.as_str()).collect::<Vec<_>>(),
        ["joint_b_z"]
    );
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let (a, b, c, d) = (
        param(&s, "a"),
        param(&s, "b"),
        param(&s, "c"),
        param(&s, "d"),
    );
    let (k1, k2, k3) = (
        d / a,
        d / c,
        (a * a - b * b + c * c + d * d) / (2.0 * a * c),
    );
    // K1 cos th4 - K2 cos th2 + K3 = cos(th2 - th4): tan(th4/2) roots of A x^2 + B x + C = 0.
    let th4 = |th2: f64, sign: f64| {
        let aa = th2.cos() - k1 - k2 * th2.cos() + k3;
        let bb = -2.0 * th2.sin();
        let cc = k1 - (k2 + 1.0) * th2.cos() + k3;
        2.0 * ((-bb + sign * (bb * bb - 4.0 * aa * cc).sqrt()) / (2.0 * aa)).atan()
    };
    let wrap = |x: f64| {
        (x + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
    };
    let tr = &sol.trajectory;
    let q0 = tr.q_at(0);
    let sign = if wrap(th4(q0[0], 1.0) - q0[2]).abs() < wrap(th4(q0[0], -1.0) - q0[2]).abs() {
        1.0
    } else {
        -1.0
    };
    let (mut err, mut other) = (0f64, f64::INFINITY);
    for k in 0..tr.len() {
        let q = tr.q_at(k);
        err = err.max(wrap(q[2] - th4(q[0], sign)).abs());
        other = other.min(wrap(q[2] - th4(q[0], -sign)).abs());
        assert!((q[0] - param(&s, "th20") - param(&s, "Omega") * tr.t[k]).abs() < 1e-10);
    }
    assert!(err < 1e-10, "rocker off Freudenstein by {err:e}");
    assert!(
        other > 1e-2,
        "control: the crossed branch is only {other:e} away"
    );
}

fn scene_error(text: &str) -> String {
    match Scene::from_text(Path::new("bad.toml"), text) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

const BASE: &str = r#"
name = "bad"
[model]
kind = "tree"
[[model.bodies]]
name = "l1"
mass = 1.0
com = [0.5, 0.0, 0.0]
inertia = [0.01, 0.1, 0.1]
joints = [{ name = "q1", type = "hinge", axis = [0.0, 0.0, 1.0] }]
[[model.bodies]]
name = "l2"
parent = "l1"
pos = [1.0, 0.0, 0.0]
mass = 1.0
com = [0.5, 0.0, 0.0]
inertia = [0.01, 0.1, 0.1]
joints = [{ name = "q2", type = "hinge", axis = [0.0, 0.0, 1.0] }]
[initial]
[time]
t1 = 1.0
"#;

/// Bad closures: located errors naming the field.
#[test]
fn bad_closures_are_located() {
    let cases = [
        (
            "[[model.closures]]\nname = \"c\"\nkind = \"pointy\"\nbody_a = \"l2\"\n",
            "model.closures[0].kind: unknown closure kind `pointy`",
        ),
        (
            "[[model.closures]]\nname = \"c\"\nkind = \"point\"\nbody_a = \"l9\"\n",
            "model.closures[0].body_a: unknown body `l9`",
        ),
        (
            "[[model.closures]]\nname = \"c\"\nkind = \"distance\"\nbody_a = \"l2\"\n",
            "model.closures[0].distance: a `distance` closure needs `distance`",
        ),
        (
            "[[model.closures]]\nname = \"c\"\nkind = \"point\"\nbody_a = \"l2\"\nbody_b = \"l2\"\n",
            "model.closures[0].body_b: a closure joins two different bodies",
        ),
        (
            "[[model.closures]]\nname = \"c\"\nkind = \"line\"\nbody_a = \"l2\"\n",
            "model.closures[0].axis: a `line` closure needs `axis`",
        ),
        (
            "[[model.closures]]\nname = \"c\"\nkind = \"plane\"\nbody_a = \"l2\"\naxis = [0.0, 0.0, 0.0]\n",
            "model.closures[0].axis: the axis must be finite and nonzero",
        ),
        (
            "[[model.closures]]\nname = \"c\"\nkind = \"point\"\nbody_a = \"l2\"\naxis = [1.0, 0.0, 0.0]\n",
            "model.closures[0].axis: `axis` belongs to `line`, `plane` and `rolling` closures",
        ),
        // Tip of the straightened chain held 1 m away from where it is: not assembled.
        (
            "[[model.closures]]\nname = \"c\"\nkind = \"point\"\nbody_a = \"l2\"\npoint_a = [1.0, 0.0, 0.0]\npoint_b = [1.0, 0.0, 0.0]\n",
            "bad.toml:",
        ),
    ];
    for (extra, want) in cases {
        let e = scene_error(&format!("{BASE}{extra}"));
        assert!(e.contains(want), "{e}\nwanted: {want}");
        assert!(e.starts_with("bad.toml:2") || e.contains(":2"), "{e}");
    }
}

/// A weld and a distance closure load and give the expected rows; the distance closure holds
/// along the free motion (u = 0) by the closed-form forward kinematics of the two-link chain: its
/// tip (cos q1 + cos(q1 + q2), sin q1 + sin(q1 + q2)) stays 1 m from (2, 1). A weld of link 2 to
/// the world at q = 0 keeps 2 rows: w_x vanishes there and the out-of-plane rows are set aside.
#[test]
fn distance_and_weld_closures_hold() {
    let dist = format!(
        "{BASE}[[model.closures]]\nname = \"rope\"\nkind = \"distance\"\nbody_a = \"l2\"\n\
         point_a = [1.0, 0.0, 0.0]\npoint_b = [2.0, 1.0, 0.0]\ndistance = 1.0\n"
    )
    // Rate of the row at q = 0: (0, -1) . (-(2 v1 + v2) ... ) = -2 v1 - v2 = 0.
    .replace("[initial]", "[initial]\nv = { q1 = 1.0, q2 = -2.0 }");
    let s = Scene::from_text(Path::new("dist.toml"), &dist).unwrap_or_else(|e| panic!("{e}"));
    let rows: Vec<String> = s.rows().into_iter().map(|r| r.name).collect();
    assert_eq!(rows, ["rope"]);
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let tr = &sol.trajectory;
    let (mut err, mut moved) = (0f64, 0f64);
    for k in 0..tr.len() {
        let q = tr.q_at(k);
        let x = q[0].cos() + (q[0] + q[1]).cos();
        let y = q[0].sin() + (q[0] + q[1]).sin();
        err = err.max(((x - 2.0).hypot(y - 1.0) - 1.0).abs());
        moved = moved.max(q[0].abs());
    }
    assert!(err < 1e-10, "tip off its circle by {err:e}");
    assert!(moved > 0.1, "the chain must move (control): {moved}");
    let weld = format!(
        "{BASE}[[model.closures]]\nname = \"w\"\nkind = \"weld\"\nbody_a = \"l2\"\n\
         point_a = [0.0, 0.0, 0.0]\npoint_b = [1.0, 0.0, 0.0]\n"
    );
    let s = Scene::from_text(Path::new("weld.toml"), &weld).unwrap_or_else(|e| panic!("{e}"));
    let rows: Vec<String> = s.rows().into_iter().map(|r| r.name).collect();
    assert_eq!(rows, ["w_y", "w_rz"]);
    let aside: Vec<&str> = s
        .set_aside
        .as_ref()
        .unwrap()
        .0
        .iter()
        .map(|a| a.row.as_str())
        .collect();
    assert_eq!(aside, ["w_x", "w_z", "w_rx", "w_ry"]);
}

/// A weld between two bodies: the relative quaternion conj(F_b) (x) F_a is the identity when the
/// frames coincide, also for frames rotated in their bodies (regression: the conjugate negated only
/// the first term of F_b's product expansion, so the rz row read 2.9 at an assembled state). Link 2
/// welded to a body `l3` hinged on the world at (1, 0): at q = 0 the frames are the same world
/// frame, rotated by 0.3 rad about z and 0.5 rad about x.
#[test]
fn weld_between_bodies_holds_at_the_assembled_state() {
    let (c3, s3) = ((0.15f64).cos(), (0.15f64).sin());
    let (c5, s5) = ((0.25f64).cos(), (0.25f64).sin());
    // quat = Rz(0.3) (x) Rx(0.5)
    let q = [c3 * c5, c3 * s5, s3 * s5, s3 * c5];
    let weld = format!(
        "{BASE}[[model.bodies]]\nname = \"l3\"\npos = [1.0, 0.0, 0.0]\nmass = 1.0\n\
         com = [0.5, 0.0, 0.0]\ninertia = [0.01, 0.1, 0.1]\n\
         joints = [{{ name = \"q3\", type = \"hinge\", axis = [0.0, 0.0, 1.0] }}]\n\
         [[model.closures]]\nname = \"w\"\nkind = \"weld\"\nbody_a = \"l2\"\nbody_b = \"l3\"\n\
         point_a = [0.2, 0.1, 0.0]\npoint_b = [0.2, 0.1, 0.0]\nquat_a = {q:?}\nquat_b = {q:?}\n"
    );
    let s = Scene::from_text(Path::new("weld2.toml"), &weld).unwrap_or_else(|e| panic!("{e}"));
    let rows: Vec<String> = s.rows().into_iter().map(|r| r.name).collect();
    assert!(!rows.is_empty());
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let tr = &sol.trajectory;
    let mut worst = 0f64;
    for k in 0..tr.len() {
        let q = tr.q_at(k);
        // welded: l2 and l3 move as one body, so q1 + q2 = q3 and l2's origin stays at (1, 0)
        worst = worst.max((q[0] + q[1] - q[2]).abs()).max(q[0].abs());
    }
    assert!(worst < 1e-9, "weld broken by {worst:e}");
}

/// Freudenstein's output angle of a four-bar with input link a at the origin, coupler b, output
/// link c at (d, 0): K1 cos th4 - K2 cos th2 + K3 = cos(th2 - th4), tan(th4/2) the roots of
/// A x^2 + B x + C = 0 (`sign` picks the branch).
fn freudenstein(a: f64, b: f64, c: f64, d: f64, th2: f64, sign: f64) -> f64 {
    let (k1, k2, k3) = (
        d / a,
        d / c,
        (a * a - b * b + c * c + d * d) / (2.0 * a * c),
    );
    let aa = th2.cos() - k1 - k2 * th2.cos() + k3;
    let bb = -2.0 * th2.sin();
    let cc = k1 - (k2 + 1.0) * th2.cos() + k3;
    2.0 * ((-bb + sign * (bb * bb - 4.0 * aa * cc).sqrt()) / (2.0 * aa)).atan()
}

fn wrap(x: f64) -> f64 {
    use std::f64::consts::PI;
    (x + PI).rem_euclid(2.0 * PI) - PI
}

/// Watt II six-bar: both rockers over the run against Freudenstein twice (loop 1: crank -> th4;
/// loop 2, ground O4 -> O6 rotated onto the x axis: th4 + beta -> th6), branches chosen at t0;
/// the crossed branch of loop 2 is the negative control. Two planar loops: both z rows set aside.
#[test]
fn watt_six_bar_follows_freudenstein_twice() {
    let s = load("watt_six_bar");
    let aside: Vec<&str> = s
        .set_aside
        .as_ref()
        .unwrap()
        .0
        .iter()
        .map(|a| a.row.as_str())
        .collect();
    assert_eq!(aside, ["joint_b_z", "joint_d_z"]);
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let p = |n: &str| param(&s, n);
    let (gx, gy) = (p("gx"), p("gy"));
    let (gamma, d2) = (gy.atan2(gx), gx.hypot(gy));
    let th4 = |th2: f64, sg: f64| freudenstein(p("a"), p("b"), p("c"), p("d"), th2, sg);
    let th6 = |th4: f64, sg: f64| {
        gamma + freudenstein(p("a2"), p("b2"), p("c2"), d2, th4 + p("beta") - gamma, sg)
    };
    let tr = &sol.trajectory;
    let q0 = tr.q_at(0);
    let pick = |f: &dyn Fn(f64) -> f64, x: f64| {
        if wrap(f(1.0) - x).abs() < wrap(f(-1.0) - x).abs() {
            1.0
        } else {
            -1.0
        }
    };
    let s1 = pick(&|sg| th4(q0[0], sg), q0[2]);
    let s2 = pick(&|sg| th6(q0[2], sg), q0[4]);
    let (mut e4, mut e6, mut other) = (0f64, 0f64, f64::INFINITY);
    for k in 0..tr.len() {
        let q = tr.q_at(k);
        let t4 = th4(q[0], s1);
        e4 = e4.max(wrap(q[2] - t4).abs());
        e6 = e6.max(wrap(q[4] - th6(t4, s2)).abs());
        other = other.min(wrap(q[4] - th6(t4, -s2)).abs());
    }
    assert!(
        e4 < 1e-10 && e6 < 1e-10,
        "rockers off Freudenstein by {e4:e}, {e6:e}"
    );
    assert!(
        other > 1e-2,
        "control: the crossed branch is only {other:e} away"
    );
}

/// Spatial RSSR: the rocker angle over the run against its closed form (|B - A| = b with
/// B = O4 + c (cos psi, 0, -sin psi), A = a (cos th2, sin th2, 0): A cos psi + B sin psi = C),
/// branch chosen at t0, the other branch as negative control. All three closure rows are kept
/// (a spatial loop), and the coupler's free spin (ga) moves under the dynamics alone.
#[test]
fn rssr_rocker_follows_its_closed_form() {
    let s = load("rssr");
    assert!(s.set_aside.as_ref().is_none_or(|a| a.0.is_empty()));
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let p = |n: &str| param(&s, n);
    let (a, b, c, px, h) = (p("a"), p("b"), p("c"), p("p"), p("h"));
    let psi = |th: f64, sign: f64| {
        let (dx, dy) = (px - a * th.cos(), -a * th.sin());
        let (aa, bb) = (2.0 * c * dx, -2.0 * c * h);
        let cc = b * b - (dx * dx + dy * dy + h * h) - c * c;
        bb.atan2(aa) + sign * (cc / aa.hypot(bb)).acos()
    };
    let tr = &sol.trajectory;
    let q0 = tr.q_at(0);
    let sign = if wrap(psi(q0[0], 1.0) - q0[4]).abs() < wrap(psi(q0[0], -1.0) - q0[4]).abs() {
        1.0
    } else {
        -1.0
    };
    let (mut err, mut other, mut spin) = (0f64, f64::INFINITY, 0f64);
    for k in 0..tr.len() {
        let q = tr.q_at(k);
        err = err.max(wrap(q[4] - psi(q[0], sign)).abs());
        other = other.min(wrap(q[4] - psi(q[0], -sign)).abs());
        spin = spin.max((q[3] - q0[3]).abs());
    }
    assert!(err < 1e-10, "rocker off its closed form by {err:e}");
    assert!(
        other > 1e-2,
        "control: the other branch is only {other:e} away"
    );
    assert!(spin > 1e-3, "the coupler's spin must move: {spin:e}");
}

/// A slider crank whose rod end runs on a line of the world (`line` closure, no slider body):
/// the out-of-plane row (offset along e_1 = z) is set aside, the in-plane row kept, and the rod
/// end follows the closed form x = L1 cos(phi) + sqrt(L2^2 - L1^2 sin^2(phi)) with the rod at
/// the absolute angle -asin(L1 sin(phi) / L2). Negative control: a rod 1 mm longer in the closed
/// form is told apart.
#[test]
fn line_closure_slider_crank_matches_closed_form() {
    let (l1, l2, omega) = (0.3f64, 0.8f64, 4.0f64);
    let text = format!(
        r#"name = "line_crank"
[model]
kind = "tree"
gravity = [0.0, -9.81, 0.0]
[[model.bodies]]
name = "crank"
mass = 1.0
com = [{h1}, 0.0, 0.0]
inertia = [0.001, 0.01, 0.01]
joints = [{{ name = "q1", type = "hinge", axis = [0.0, 0.0, 1.0] }}]
[[model.bodies]]
name = "rod"
parent = "crank"
pos = [{l1}, 0.0, 0.0]
mass = 0.5
com = [{h2}, 0.0, 0.0]
inertia = [0.001, 0.03, 0.03]
joints = [{{ name = "q2", type = "hinge", axis = [0.0, 0.0, 1.0] }}]
[[model.closures]]
name = "guide"
kind = "line"
body_a = "rod"
point_a = [{l2}, 0.0, 0.0]
axis = [2.0, 0.0, 0.0]
[[programme]]
name = "drive"
expr = "q1 - {omega}*t"
[initial]
q = {{ q1 = 0.0, q2 = 0.0 }}
v = {{ q1 = {omega}, q2 = {w2} }}
[time]
t1 = 2.0
output_dt = 0.01
"#,
        h1 = l1 / 2.0,
        h2 = l2 / 2.0,
        w2 = -omega * (1.0 + l1 / l2),
    );
    let s = Scene::from_text(Path::new("line_crank.toml"), &text).unwrap_or_else(|e| panic!("{e}"));
    let rows: Vec<String> = s.rows().into_iter().map(|r| r.name).collect();
    assert_eq!(rows, ["guide_v", "drive"]);
    let aside = &s
        .set_aside
        .as_ref()
        .expect("a planar loop sets a row aside")
        .0;
    assert_eq!(aside.len(), 1);
    assert_eq!(aside[0].row, "guide_u");
    assert!(aside[0].reason.contains("vanishes"), "{}", aside[0].reason);
    let sol = s.solve(&s.settings);
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let tr = &sol.trajectory;
    let (mut dx, mut dth, mut control) = (0f64, 0f64, f64::INFINITY);
    for k in 0..tr.len() {
        let q = tr.q_at(k);
        let phi = q[0];
        let th = q[0] + q[1];
        let x = l1 * phi.cos() + l2 * th.cos();
        let x_cf = l1 * phi.cos() + (l2 * l2 - (l1 * phi.sin()).powi(2)).sqrt();
        dx = dx.max((x - x_cf).abs());
        dth = dth.max((th + (l1 * phi.sin() / l2).asin()).abs());
        let l2c = l2 + 1e-3;
        let x_c = l1 * phi.cos() + (l2c * l2c - (l1 * phi.sin()).powi(2)).sqrt();
        control = control.min((x - x_c).abs());
    }
    // Integrated trajectory class: the projection holds the row to ~1e-12, the closed form is the
    // same manifold, so a few 1e-10 at most.
    assert!(
        dx < 1e-9 && dth < 1e-9,
        "off the closed form: x {dx:e}, angle {dth:e}"
    );
    assert!(
        control > 5e-4,
        "negative control not told apart: {control:e}"
    );
    assert!(
        tr.q_at(tr.len() - 1)[0] > 7.9,
        "the crank turned: {}",
        tr.q_at(tr.len() - 1)[0]
    );
}

/// A bead on two world slides held in the plane of a turntable (`plane` closure on a moving
/// body, normal e_x of the table) or, the same manifold, on the table's line along e_y (`line`):
/// with the table driven at a constant rate Omega and no gravity, the bead's distance r from the
/// axis obeys r'' = Omega^2 r (a bead on a rotating rod), r = r0 cosh(Omega t) for r0' = 0; it
/// sits at (-r sin(psi), r cos(psi)). Negative control: the closed form with Omega 1 % off.
#[test]
fn plane_and_line_closures_on_a_turning_body_match_the_rotating_rod() {
    let (omega, r0) = (1.5f64, 0.1f64);
    for (kind, axis, kept, aside) in [
        ("plane", "[1.0, 0.0, 0.0]", "slot", None),
        ("line", "[0.0, 1.0, 0.0]", "slot_v", Some("slot_u")),
    ] {
        let text = format!(
            r#"name = "turntable"
[model]
kind = "tree"
gravity = [0.0, 0.0, -9.81]
[[model.bodies]]
name = "table"
mass = 2.0
inertia = [0.05, 0.05, 0.1]
joints = [{{ name = "psi", type = "hinge", axis = [0.0, 0.0, 1.0] }}]
[[model.bodies]]
name = "bead"
mass = 0.2
inertia = [1e-4, 1e-4, 1e-4]
joints = [{{ name = "x", type = "slide", axis = [1.0, 0.0, 0.0] }}, {{ name = "y", type = "slide", axis = [0.0, 1.0, 0.0] }}]
[[model.closures]]
name = "slot"
kind = "{kind}"
body_a = "bead"
body_b = "table"
axis = {axis}
[[programme]]
name = "drive"
expr = "psi - {omega}*t"
[initial]
q = {{ psi = 0.0, x = 0.0, y = {r0} }}
v = {{ psi = {omega}, x = {vx}, y = 0.0 }}
[time]
t1 = 1.5
output_dt = 0.01
"#,
            vx = -r0 * omega,
        );
        let s = Scene::from_text(Path::new("turntable.toml"), &text)
            .unwrap_or_else(|e| panic!("{kind}: {e}"));
        let rows: Vec<String> = s.rows().into_iter().map(|r| r.name).collect();
        assert_eq!(rows, [kept, "drive"], "{kind}");
        let set: Vec<String> = s
            .set_aside
            .as_ref()
            .map(|a| a.0.iter().map(|r| r.row.clone()).collect())
            .unwrap_or_default();
        assert_eq!(
            set,
            aside.into_iter().map(String::from).collect::<Vec<_>>(),
            "{kind}"
        );
        let sol = s.solve(&s.settings);
        assert!(sol.code.is_success(), "{kind}: {:?}", sol.code);
        let tr = &sol.trajectory;
        let (mut err, mut control) = (0f64, 0f64);
        for k in 0..tr.len() {
            let (t, q) = (tr.t[k], tr.q_at(k));
            let psi = q[0];
            let r = r0 * (omega * t).cosh();
            err = err
                .max((q[1] + r * psi.sin()).abs())
                .max((q[2] - r * psi.cos()).abs());
            let rc = r0 * (1.01 * omega * t).cosh();
            control = control.max(
                (q[1] + rc * psi.sin())
                    .abs()
                    .max((q[2] - rc * psi.cos()).abs()),
            );
        }
        // Integrated trajectory class: rtol 1e-10 (the default) over 1.5 s of exponential growth.
        assert!(
            err < 1e-8,
            "{kind}: off the rotating-rod solution by {err:e}"
        );
        assert!(
            control > 1e-3,
            "{kind}: negative control not told apart: {control:e}"
        );
    }
}
