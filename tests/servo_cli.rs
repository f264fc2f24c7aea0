//! The servo analysis at the two doors that report it (issue 17): `progmo validate` (text and
//! `--json`) and `progmo solve`'s summary.json (`servo`), on passive_arm (internal dynamics of
//! dimension 2, stable) and two_car_chain (flat: dimension 0).

use std::path::PathBuf;
use std::process::Command;

fn progmo() -> Command {
    Command::new(env!("CARGO_BIN_EXE_progmo"))
}

fn scene(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("references/scenes/{name}.toml"))
}

#[test]
fn validate_reports_the_internal_dynamics() {
    let o = progmo()
        .args(["validate", scene("passive_arm").to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains(
            "servo-constraints: orthogonal realization at t0, derivatives until tau appears [2, 2], \
             index 3"
        ),
        "{out}"
    );
    // -c/(2I) = -0.05/(2 * 0.02667) = -0.9375 (tests/servo_internal.rs: the closed form).
    assert!(
        out.contains("internal dynamics: dimension 2, frozen-time eigenvalues at t0: -0.9375 + "),
        "{out}"
    );
    let o = progmo()
        .args(["validate", "--json", scene("passive_arm").to_str().unwrap()])
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let i = &v[0]["servo"]["internal"];
    assert_eq!(i["dimension"], 2);
    assert_eq!(i["eigenvalues_t0"].as_array().unwrap().len(), 2);
    assert!(i["along"].is_null(), "validate does not solve");
    let o = progmo()
        .args(["validate", scene("two_car_chain").to_str().unwrap()])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("internal dynamics: none (dimension 0"),
        "{out}"
    );
}

#[test]
fn the_summary_holds_the_servo_analysis_along_the_motion() {
    let out = std::env::temp_dir().join(format!("progmo-servo-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let o = progmo()
        .args([
            "solve",
            scene("passive_arm").to_str().unwrap(),
            "--no-mcap",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let servo = &s["servo"];
    assert_eq!(servo["realization"], "orthogonal");
    assert_eq!(servo["index"], 3);
    let i = &servo["internal"];
    assert_eq!(i["dimension"], 2);
    assert_eq!(i["stability"], "stable");
    assert!(i["horizon"].is_null());
    assert_eq!(i["along"]["samples"], 41);
    assert!(i["along"]["max_real"].as_f64().unwrap() < 0.0);
    assert!(i["growth"]["rate"].as_f64().unwrap() < 0.0);
    // Without actuators: no `servo` key.
    let o = progmo()
        .args([
            "solve",
            scene("double_pendulum").to_str().unwrap(),
            "--no-mcap",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success());
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert!(s.get("servo").is_none());
    let _ = std::fs::remove_dir_all(&out);
}

/// A programme the actuators cannot realize at t0 is bad input at both doors: `validate` and
/// `solve` refuse it with exit 2 (solve said 1, as for a solve that failed on the way).
#[test]
fn an_unrealizable_programme_exits_2_in_solve_as_in_validate() {
    // tests/servo.rs: a third car, uncoupled; pushing car 1 never moves it
    let t = std::fs::read_to_string(scene("two_car_chain"))
        .unwrap()
        .replace(
            "[[model.sites]]",
            "[[model.bodies]]\nname = \"car3\"\nmass = 1.0\njoints = [{ name = \"x3\", type = \"slide\", axis = [1.0, 0.0, 0.0] }]\n\n[[model.sites]]",
        )
        .replace("expr = \"c2.x - A*sin(w*t)\"", "expr = \"x3 - A*sin(w*t)\"")
        .replace("q = { x1 = 0.0, d = 0.0 }", "q = { x1 = 0.0, d = 0.0, x3 = 0.0 }")
        .replace("d = \"m2*A*w^3/k\" }", "d = \"m2*A*w^3/k\", x3 = \"A*w\" }");
    let dir = std::env::temp_dir().join(format!("progmo-servo-exit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("unreached.toml");
    std::fs::write(&path, t).unwrap();
    let o = progmo()
        .args(["validate", path.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = progmo()
        .args(["solve", path.to_str().unwrap(), "--quiet", "--out"])
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("do not reach"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
