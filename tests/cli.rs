//! The `progmo` command line as a user runs it: outputs, messages and exit codes.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn progmo() -> Command {
    Command::new(env!("CARGO_BIN_EXE_progmo"))
}

fn scene(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("references/scenes/{name}.toml"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("progmo-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn solve_writes_csv_summary_and_mcap() {
    let out = tmp("solve");
    let o = progmo()
        .args(["solve", scene("double_pendulum").to_str().unwrap(), "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert!(header.starts_with("t,q:q1,q:q2,v:q1,v:q2,"), "{header}");
    assert!(header.contains("u:q1") && header.contains("residual:elbow"));
    assert_eq!(
        csv.lines().count(),
        1 + 1001,
        "samples at output_dt = 0.01 over 10 s"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["code_name"], "success");
    assert!(summary["max_residual"].as_f64().unwrap() <= 1e-10);
    assert!(summary["command_line"].as_array().unwrap().len() >= 3);
    assert!(std::fs::metadata(out.join("recording.mcap")).unwrap().len() > 1000);
}

#[test]
fn overrides_change_the_method() {
    let out = tmp("override");
    let o = progmo()
        .args([
            "solve",
            scene("heavy_top").to_str().unwrap(),
            "--integrator",
            "rk4",
            "--step",
            "0.001",
            "--formulation",
            "kkt",
            "--no-mcap",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["settings"]["formulation"], "kkt");
    assert_eq!(summary["statistics"]["integrator"]["steps"], 5000);
    assert!(!out.join("recording.mcap").exists());
}

#[test]
fn bad_scene_is_a_located_error_with_exit_2() {
    let dir = tmp("bad");
    let text = std::fs::read_to_string(scene("double_pendulum")).unwrap();
    let bad = text.replace("q2 - amp*sin(w*t)", "q2 - amp*sin(omega*t)");
    let p = write(&dir, "bad.toml", &bad);
    let line = bad.lines().position(|l| l.contains("omega*t")).unwrap() + 1;
    let o = progmo()
        .args(["solve", p.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains(&format!("bad.toml:{line}:")), "{err}");
    assert!(err.contains("unknown symbol `omega`"), "{err}");
    assert!(!err.contains("panicked"));
}

#[test]
fn inconsistent_initial_state_points_at_the_row() {
    let dir = tmp("inconsistent");
    let text = std::fs::read_to_string(scene("double_pendulum")).unwrap();
    let bad = text.replace("q = { q1 = 0.3, q2 = 0.0 }", "q = { q1 = 0.3, q2 = 0.1 }");
    let p = write(&dir, "off.toml", &bad);
    let line = bad.lines().position(|l| l.contains("q2 - amp")).unwrap() + 1;
    for cmd in ["validate", "solve"] {
        let o = progmo()
            .args([cmd, p.to_str().unwrap()])
            .arg("--help")
            .output()
            .unwrap();
        assert!(o.status.success());
        let o = progmo()
            .args([cmd, p.to_str().unwrap()])
            .current_dir(&dir)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(2), "{cmd}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(&format!("off.toml:{line}:")) && err.contains("initial state violates"),
            "{cmd}: {err}"
        );
    }
    // With assembly the state is projected and the solve succeeds.
    let fixed = bad.replace("[initial]", "[initial]\nassemble = true");
    let p = write(&dir, "assembled.toml", &fixed);
    let o = progmo()
        .args(["solve", p.to_str().unwrap(), "--no-mcap", "--out"])
        .arg(dir.join("a"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn a_programme_singular_at_t0_is_refused_like_validate_and_keeps_results() {
    let dir = tmp("singular");
    let text = std::fs::read_to_string(scene("example_3_1_free")).unwrap();
    // Angular velocity along the body z axis: the programme's gradient vanishes at t0.
    let bad = text.replace(
        "v = { ball = [0.8, 0.3, 1.2] }",
        "v = { ball = [0.0, 0.0, 1.2] }",
    );
    let p = write(&dir, "degenerate.toml", &bad);
    let o = progmo()
        .args(["validate", p.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("singular"));
    let o = progmo()
        .args(["solve", p.to_str().unwrap(), "--out"])
        .arg(dir.join("o"))
        .output()
        .unwrap();
    // Refused at the initial state: the same located diagnosis and exit code as `validate` (issue 9).
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("degenerate.toml:") && err.contains("singular at the initial state"),
        "{err}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("o/summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["code_name"], "singular_programme");
    assert_eq!(summary["code"]["rows"][0], "precession");
}

#[test]
fn help_on_every_subcommand() {
    for sub in [
        vec!["--help"],
        vec!["solve", "--help"],
        vec!["validate", "--help"],
    ] {
        let o = progmo().args(&sub).output().unwrap();
        assert!(o.status.success());
        assert!(String::from_utf8_lossy(&o.stdout).contains("Usage"));
    }
}

#[test]
fn export_writes_mjcf_urdf_and_report() {
    let dir = tmp("export");
    for (fmt, tag) in [("mjcf", "<mujoco"), ("urdf", "<robot")] {
        let out = dir.join(format!("heavy_top.{fmt}"));
        let o = progmo()
            .args([
                "export",
                scene("heavy_top").to_str().unwrap(),
                "--format",
                fmt,
                "--out",
            ])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(std::fs::read_to_string(&out).unwrap().contains(tag));
        let report: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(format!("{}.report.json", out.display())).unwrap(),
        )
        .unwrap();
        assert_eq!(report["gravity"][2], -9.81);
    }
    // A lagrangian scene cannot be exported: clear error, exit 2.
    let o = progmo()
        .args([
            "export",
            scene("slider_crank").to_str().unwrap(),
            "--format",
            "mjcf",
        ])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("lagrangian"));
}

/// Done criterion of the scenes issue: every bundled scene solves from the command line.
#[test]
fn every_bundled_scene_solves_from_the_command_line() {
    common::robot_path();
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("references/scenes");
    let out = tmp("catalog");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_none_or(|x| x != "toml") {
            continue;
        }
        let o = progmo()
            .args([
                "solve",
                p.to_str().unwrap(),
                "--no-mcap",
                "--quiet",
                "--out",
            ])
            .arg(out.join(p.file_stem().unwrap()))
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{}: {}",
            p.display(),
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(String::from_utf8_lossy(&o.stdout).contains("success"));
        n += 1;
    }
    assert!(n >= 10, "{n} scenes");
}

fn test_scene(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("tests/scenes/{name}.toml"))
}

#[test]
fn conditioning_warnings_reach_every_output_and_strict_stops() {
    // Example 3.1's programme through its degenerate point (tests/conditioning.rs has the numbers).
    let out = tmp("warn");
    let o = progmo()
        .args([
            "solve",
            test_scene("precession_degenerate").to_str().unwrap(),
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let line = String::from_utf8_lossy(&o.stdout);
    assert!(
        line.contains("1 conditioning WARNING (row_gradient at t = 2.2"),
        "{line}"
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("warning: the gradient of row `precession`"),
        "{err}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let w = &summary["warnings"][0];
    assert_eq!(w["kind"], "row_gradient");
    assert_eq!(w["rows"][0], "precession");
    assert!(w["message"].as_str().unwrap().contains("initial norm"));
    // The MCAP has the warning channel with one message.
    let bytes = std::fs::read(out.join("recording.mcap")).unwrap();
    let mut n = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == "/progmo/warning" {
            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            assert_eq!(v["kind"], "row_gradient");
            n += 1;
        }
    }
    assert_eq!(n, 1);

    // --strict: the warning stops the solve (exit 1); code, t_end and the last sample agree.
    let o = progmo()
        .args([
            "solve",
            test_scene("precession_degenerate").to_str().unwrap(),
            "--strict",
            "--out",
        ])
        .arg(out.join("strict"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("ill_conditioned") && !err.contains('{'),
        "{err}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("strict/summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["code_name"], "ill_conditioned");
    let t_end = summary["t_end"].as_f64().unwrap();
    assert_eq!(summary["code"]["t"].as_f64().unwrap(), t_end);
    let csv = std::fs::read_to_string(out.join("strict/trajectory.csv")).unwrap();
    let last: f64 = csv
        .lines()
        .last()
        .unwrap()
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert_eq!(last, t_end);
    assert!(summary["message"]
        .as_str()
        .unwrap()
        .contains("`precession`"));
}

#[test]
fn output_failures_are_exit_codes_not_panics() {
    // stdout on a full device: every subcommand that prints says so and exits 3 (issue 11).
    let dir = tmp("full");
    let s = scene("double_pendulum");
    let s = s.to_str().unwrap();
    let out = dir.join("o");
    let out = out.to_str().unwrap();
    for args in [
        vec!["validate", s],
        vec!["solve", s, "--no-mcap", "--out", out],
        vec!["export", s, "--format", "mjcf"],
    ] {
        let full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let o = progmo().args(&args).stdout(full).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(3), "{args:?}: {err}");
        assert!(
            err.contains("cannot write to standard output") && !err.contains("panicked"),
            "{args:?}: {err}"
        );
    }
    // A closed pipe ends quietly (141, as a tool killed by SIGPIPE), or 0 if all was written first.
    let cmd = format!(
        "{} validate {s} {s} {s} {s} | true; echo ${{PIPESTATUS[0]}}",
        env!("CARGO_BIN_EXE_progmo")
    );
    let o = Command::new("bash").args(["-c", &cmd]).output().unwrap();
    let status = String::from_utf8_lossy(&o.stdout).trim().to_string();
    assert!(status == "141" || status == "0", "status {status}");
    assert!(!String::from_utf8_lossy(&o.stderr).contains("panicked"));
}

#[test]
fn a_non_utf8_output_path_is_a_path_like_any_other() {
    use std::os::unix::ffi::OsStrExt;
    let dir = tmp("nonutf8");
    let out = dir.join(std::ffi::OsStr::from_bytes(b"run-\xff"));
    let o = progmo()
        .args(["solve", scene("double_pendulum").to_str().unwrap(), "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("summary.json").is_file() && out.join("recording.mcap").is_file());
}

#[test]
fn a_run_into_an_earlier_runs_folder_leaves_nothing_of_it() {
    // --no-mcap into the folder of an earlier run: its recording.mcap must not pass for this run's.
    let dir = tmp("reuse");
    let first = progmo()
        .args(["solve", scene("heavy_top").to_str().unwrap(), "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(first.status.success());
    assert!(dir.join("recording.mcap").is_file());
    let second = progmo()
        .args([
            "solve",
            scene("double_pendulum").to_str().unwrap(),
            "--no-mcap",
            "--out",
        ])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(second.status.success());
    assert!(!dir.join("recording.mcap").exists());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["scene"], "double_pendulum");
    assert!(!dir.join("summary.json.tmp").exists());
}

/// Bundled scenes are named without a path from any directory (the checkout's catalog, or the one
/// `$PROGMO_REFERENCES` points at); an unknown name lists the bundled ones; `--json` puts one JSON
/// document on stdout and the line for people on stderr.
#[test]
fn bundled_names_from_any_directory_and_json_on_stdout() {
    let dir = tmp("bundled");
    let o = progmo()
        .current_dir(&dir)
        .args([
            "solve",
            "double_pendulum",
            "--t1",
            "0.2",
            "--json",
            "--quiet",
        ])
        .env_remove("PROGMO_REFERENCES")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value =
        serde_json::from_slice(&o.stdout).expect("stdout is one JSON document");
    assert_eq!(v["code_name"], "success");
    assert_eq!(v["output"], "out/double_pendulum");
    assert!(dir.join("out/double_pendulum/summary.json").is_file());
    assert!(String::from_utf8_lossy(&o.stderr).contains("double_pendulum: success"));

    let o = progmo()
        .current_dir(&dir)
        .args(["validate", "no_such_scene"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("no_such_scene: no such scene file or bundled scene")
            && err.contains("heavy_top"),
        "{err}"
    );
    // A path is never taken for a name.
    let o = progmo()
        .current_dir(&dir)
        .args(["validate", "sub/double_pendulum.toml"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no such scene file"));

    // $PROGMO_REFERENCES names another catalog (the Python package points it at its own).
    std::fs::create_dir_all(dir.join("refs/scenes")).unwrap();
    write(
        &dir.join("refs/scenes"),
        "mine.toml",
        &std::fs::read_to_string(scene("heavy_top")).unwrap(),
    );
    let o = progmo()
        .current_dir(&dir)
        .args(["validate", "mine", "--json"])
        .env("PROGMO_REFERENCES", dir.join("refs"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v[0]["name"], "heavy_top");
    assert_eq!(v[0]["ok"], true);
}

#[test]
fn validate_reports_the_servo_realization_and_index() {
    let p = scene("two_car_chain");
    let o = progmo()
        .args(["validate", p.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains(
            "servo-constraints: tangential realization at t0, derivatives until tau appears [4], \
             index 5"
        ),
        "{out}"
    );
    let o = progmo()
        .args(["validate", "--json", p.to_str().unwrap()])
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v[0]["servo"]["index"], 5);
    assert_eq!(v[0]["servo"]["realization"], "tangential");
    // Without actuators: no servo report.
    let o = progmo()
        .args([
            "validate",
            "--json",
            scene("double_pendulum").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v[0]["servo"].is_null());
    // A rank-deficient decoupling: validate says which rows were kept and which combined.
    let o = progmo()
        .args(["validate", scene("overhead_crane").to_str().unwrap()])
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("derivatives until tau appears [4, 2], index 5")
            && out.contains("kept [\"p_z\"] at degree [2], replaced [\"p_x\"]"),
        "{out}"
    );
}

/// One name rule (`progmo.data.scene_file` in Python, `cli::scene_file` here): with
/// `$PROGMO_REFERENCES` set, a bundled scene is looked for there and nowhere else (not in the
/// checkout the binary was built from), and the error names the folder looked in.
#[test]
fn progmo_references_is_the_only_place_bundled_names_resolve() {
    let refs = tmp("references");
    std::fs::create_dir_all(refs.join("scenes")).unwrap();
    let validate = |name: &str| {
        progmo()
            .args(["validate", name])
            .env("PROGMO_REFERENCES", &refs)
            .output()
            .unwrap()
    };
    let o = validate("double_pendulum");
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("no such scene file or bundled scene")
            && err.contains(&refs.join("scenes").display().to_string())
            && err.contains("none found"),
        "{err}"
    );
    // the same name in that folder resolves there
    std::fs::copy(
        scene("double_pendulum"),
        refs.join("scenes/double_pendulum.toml"),
    )
    .unwrap();
    let o = validate("double_pendulum");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // without it, the checkout the binary runs from (found at run time, not baked in)
    let o = progmo()
        .args(["validate", "double_pendulum"])
        .env_remove("PROGMO_REFERENCES")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}
