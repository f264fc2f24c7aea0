//! The `rolling` closure (`src/scene/closures.rs`): a disk or a sphere rolling without slipping on
//! a plane, against closed forms of independent origin, with negative controls; its located
//! errors; and the export route that supplies the reactions of rows no simulator holds.
//!
//! Steady circular rolling of a disk (scene `rolling_disk`), derived here by Newton-Euler about
//! the centre G. The disk (radius a, mass m, moments A transverse, C axial about G) leans by theta
//! towards the axis of the circle of radius R its contact point P traces, precessing at Omega:
//! e_3 up, n_c the horizontal unit vector from P towards the axis, e_1 = e_3 x (-n_c) the direction
//! of travel, symmetry axis k = -sin(theta) e_3 + cos(theta) n_c, PG = a (cos(theta) e_3 +
//! sin(theta) n_c), the centre on the circle rho = R - a sin(theta).
//! - No slip, v_P = v_G + w x GP = 0 with w = Omega e_3 + s k and v_G = Omega rho e_1:
//!   (Omega rho + a Omega sin(theta) - a s) e_1 = 0, so s = Omega R / a.
//! - Linear momentum: F = m g e_3 + m Omega^2 rho n_c (the contact force).
//! - Angular momentum about G, H = A Omega (e_3 + sin(theta) k) + C (s - Omega sin(theta)) k,
//!   dk/dt = Omega e_3 x k = -Omega cos(theta) e_1, equals GP x F = a m (Omega^2 rho cos(theta) -
//!   g sin(theta)) e_1, so
//!   Omega^2 = m a g sin(theta) / (cos(theta) ((A - C) sin(theta) + C R / a + m a rho)),
//!   for a thin uniform disk (A = m a^2/4, C = m a^2/2) the textbook relation
//!   Omega^2 = 4 g tan(theta) / (6 R - 5 a sin(theta)) (e.g. Greenwood, Principles of Dynamics,
//!   the rolling disk; Goldstein's rolling coin).
//!
//! A uniform sphere rolling down a plane inclined by alpha: its centre accelerates at
//! (5/7) g sin(alpha) down the slope (m x'' = m g sin(alpha) - f, (2/5) m r^2 x'' / r = f r).

use progmo::export::{ExportOptions, Format, HarnessForce};
use progmo::scene::Scene;
use progmo::solve::Settings;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn disk_text() -> String {
    std::fs::read_to_string(root().join("references/scenes/rolling_disk.toml")).unwrap()
}

fn param(s: &Scene, name: &str) -> f64 {
    s.parameters.iter().find(|p| p.0 == name).unwrap().1
}

fn tight(s: &Scene) -> Settings {
    let mut st = s.settings.clone();
    st.rtol = 1e-11;
    st.atol = 1e-13;
    st
}

/// R(q) e_x for a unit quaternion (w, x, y, z): the disk's axis in the world.
fn body_x(q: &[f64]) -> [f64; 3] {
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    [
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y + w * z),
        2.0 * (x * z - w * y),
    ]
}

/// Largest deviation of a solve of `text` from the steady motion of the closed form (centre,
/// axis, centre velocity, contact force relative to m g), and the worst of each part.
fn steady_deviation(text: &str) -> (f64, [f64; 4]) {
    let s =
        Scene::from_text(Path::new("rolling_disk.toml"), text).unwrap_or_else(|e| panic!("{e}"));
    let (a, m, g, theta, r) = (
        param(&s, "a"),
        param(&s, "m"),
        param(&s, "g"),
        param(&s, "theta"),
        param(&s, "R"),
    );
    // moments of a thin uniform disk, computed here (the scene's inertia repeats them)
    let (ia, ic) = (m * a * a / 4.0, m * a * a / 2.0);
    let rho = r - a * theta.sin();
    let omega = (m * a * g * theta.sin()
        / (theta.cos() * ((ia - ic) * theta.sin() + ic * r / a + m * a * rho)))
        .sqrt();
    let textbook = (4.0 * g * theta.tan() / (6.0 * r - 5.0 * a * theta.sin())).sqrt();
    assert!(
        (omega - textbook).abs() < 1e-14 * omega,
        "{omega} vs {textbook}"
    );
    let sol = s.solve(&tight(&s));
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let tr = &sol.trajectory;
    let mut parts = [0.0f64; 4];
    for k in 0..tr.len() {
        let t = tr.t[k];
        let (q, v, f) = (tr.q_at(k), tr.v_at(k), tr.reactions_at(k));
        let (c, sn) = ((omega * t).cos(), (omega * t).sin());
        let centre = [rho * c, rho * sn, a * theta.cos()];
        let vel = [-omega * rho * sn, omega * rho * c, 0.0];
        // axis: outward and up, (cos(theta) e_rad + sin(theta) e_3)
        let axis = [theta.cos() * c, theta.cos() * sn, theta.sin()];
        let force = [
            -m * omega * omega * rho * c,
            -m * omega * omega * rho * sn,
            m * g,
        ];
        let ax = body_x(&q[3..7]);
        for i in 0..3 {
            parts[0] = parts[0].max((q[i] - centre[i]).abs());
            parts[1] = parts[1].max((ax[i] - axis[i]).abs());
            parts[2] = parts[2].max((v[i] - vel[i]).abs());
            parts[3] = parts[3].max((f[i] - force[i]).abs() / (m * g));
        }
    }
    eprintln!(
        "steady motion: centre, axis, velocity, force/(m g) off by {:.1e} {:.1e} {:.1e} {:.1e}",
        parts[0], parts[1], parts[2], parts[3]
    );
    (parts.iter().cloned().fold(0.0, f64::max), parts)
}

#[test]
fn rolling_disk_keeps_its_steady_circular_motion() {
    let (worst, parts) = steady_deviation(&disk_text());
    assert!(
        worst < 1e-8,
        "rolling disk off its steady motion: centre {:.1e}, axis {:.1e}, velocity {:.1e}, contact \
         force {:.1e}",
        parts[0],
        parts[1],
        parts[2],
        parts[3]
    );
}

/// Negative control: 1 % more precession than the steady motion needs (the initial state still
/// rolls without slipping) and the disk leaves the closed form.
#[test]
fn a_wrong_precession_rate_leaves_the_steady_motion() {
    let text = disk_text();
    let line = text
        .lines()
        .find(|l| l.starts_with("Omega = "))
        .expect("the Omega parameter");
    let expr = line.split('"').nth(1).unwrap();
    let wrong = text.replace(line, &format!("Omega = \"1.01*{expr}\""));
    let (worst, _) = steady_deviation(&wrong);
    assert!(
        worst > 1e-4,
        "a 1 % wrong precession stayed within {worst:e}"
    );
}

fn sphere_text(alpha: f64) -> String {
    format!(
        r#"
name = "sphere_incline"
[model]
kind = "tree"
gravity = [0.0, 0.0, -9.81]
[[model.bodies]]
name = "ball"
mass = 1.5
inertia = [0.024, 0.024, 0.024]
joints = [{{ name = "ball", type = "free" }}]
[[model.closures]]
name = "roll"
kind = "rolling"
body_a = "ball"
radius = 0.2
point_b = [0.0, 0.0, -1.0]
normal = [{sa}, 0.0, {ca}]
[initial]
q = {{ ball = [{x0}, 0.0, {z0}, 1.0, 0.0, 0.0, 0.0] }}
[time]
t1 = 2.0
output_dt = 0.1
"#,
        sa = alpha.sin(),
        ca = alpha.cos(),
        // the centre at distance r from the plane n . (x - p_b) = 0 along the normal
        x0 = 0.2 * alpha.sin(),
        z0 = -1.0 + 0.2 * alpha.cos(),
    )
}

/// A uniform sphere (I = 2/5 m r^2) from rest on a plane inclined by alpha (normal (sin, 0, cos)):
/// the centre moves down the slope (cos(alpha), 0, -sin(alpha)) by (5/14) g sin(alpha) t^2 and
/// never turns about the normal.
#[test]
fn a_sphere_rolls_down_an_incline_at_five_sevenths_g_sin_alpha() {
    let alpha: f64 = 0.4;
    let s = Scene::from_text(Path::new("sphere.toml"), &sphere_text(alpha))
        .unwrap_or_else(|e| panic!("{e}"));
    let sol = s.solve(&tight(&s));
    assert!(sol.code.is_success(), "{:?}", sol.code);
    let tr = &sol.trajectory;
    let g = 9.81;
    let mut worst: f64 = 0.0;
    for k in 0..tr.len() {
        let t = tr.t[k];
        let d = 5.0 / 14.0 * g * alpha.sin() * t * t;
        let q = tr.q_at(k);
        let x = 0.2 * alpha.sin() + d * alpha.cos();
        let z = -1.0 + 0.2 * alpha.cos() - d * alpha.sin();
        worst = worst
            .max((q[0] - x).abs())
            .max(q[1].abs())
            .max((q[2] - z).abs());
    }
    eprintln!("sphere on the incline: off (5/7) g sin(alpha) by {worst:.1e}");
    assert!(worst < 1e-9, "sphere off (5/7) g sin(alpha) by {worst:e}");
    // negative control: sliding without friction would be g sin(alpha), 7/5 as fast
    let t = tr.t[tr.len() - 1];
    let slide = g * alpha.sin() * t * t / 2.0;
    assert!((tr.q_at(tr.len() - 1)[0] - (0.2 * alpha.sin() + slide * alpha.cos())).abs() > 0.1);
}

fn refused(text: &str) -> String {
    match Scene::from_text(Path::new("bad.toml"), text) {
        Ok(_) => panic!("accepted"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn rolling_closures_refuse_bad_fields_with_a_location() {
    let base = sphere_text(0.0);
    let e = refused(&base.replace("radius = 0.2\n", ""));
    assert!(
        e.contains("model.closures[0].radius") && e.contains("needs `radius`"),
        "{e}"
    );
    let e = refused(&base.replace("radius = 0.2", "radius = -0.2"));
    assert!(
        e.contains("model.closures[0].radius") && e.contains("> 0"),
        "{e}"
    );
    let zero = base
        .lines()
        .map(|l| {
            if l.starts_with("normal") {
                "normal = [0.0, 0.0, 0.0]".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let e = refused(&zero);
    assert!(
        e.contains("model.closures[0].normal") && e.contains("nonzero"),
        "{e}"
    );
    let e = refused(&base.replace("kind = \"rolling\"", "kind = \"point\""));
    assert!(
        e.contains("model.closures[0].radius") && e.contains("belongs to `rolling`"),
        "{e}"
    );
    let two = base.replace(
        "[[model.closures]]",
        "[[model.bodies]]\nname = \"floor\"\nmass = 1.0\ninertia = [1.0, 1.0, 1.0]\n[[model.closures]]",
    )
    .replace("radius = 0.2", "radius = 0.2\nbody_b = \"floor\"");
    let e = refused(&two);
    assert!(
        e.contains("model.closures[0].body_b") && e.contains("world"),
        "{e}"
    );
}

/// The one export door refuses the rolling rows (no simulator holds them); the supplying route
/// leaves them out (no closure in the report) and lists them, with the reason, as the one supplied
/// reaction.
#[test]
fn the_export_supplies_the_rolling_rows() {
    let s = Scene::from_text(Path::new("rolling_disk.toml"), &disk_text()).unwrap();
    let o = ExportOptions::default();
    // MJCF refuses it; a URDF carries the closure's site, and the Pinocchio back-end refuses it
    assert!(s.export(Format::Mjcf, &o).is_err());
    for format in [Format::Mjcf, Format::Urdf] {
        let (_, report) = s.export_supplying(format, &o).unwrap();
        assert!(
            report.closures.is_empty(),
            "{format}: {:?}",
            report.closures
        );
        let supplied: Vec<_> = report
            .harness_forces
            .iter()
            .filter_map(|f| match f {
                HarnessForce::SuppliedReaction { rows, reason } => Some((rows.clone(), reason)),
                _ => None,
            })
            .collect();
        assert_eq!(supplied.len(), 1);
        assert_eq!(supplied[0].0, ["roll_n", "roll_u", "roll_v"]);
        assert!(
            supplied[0].1.contains("rolling closure `roll`"),
            "{}",
            supplied[0].1
        );
    }
    // without such rows the two routes are one
    let four_bar = Scene::load(root().join("references/scenes/four_bar.toml")).unwrap();
    assert_eq!(
        four_bar.export(Format::Mjcf, &o).unwrap(),
        four_bar.export_supplying(Format::Mjcf, &o).unwrap()
    );
}
