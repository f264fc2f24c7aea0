//! `progmo solve` refuses unbounded or meaningless runs before integrating (exit 2, the flag or the
//! scene key named), through the same `progmo::solve::validate` as the scene loader and the binding.
//! Every run here has a deadline: a refusal must come in seconds, not after a runaway.

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn scene(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join(format!("references/scenes/{name}.toml"))
        .display()
        .to_string()
}

/// Run `progmo solve` with `args`; kill it after `limit` (a failure) and return (code, stderr).
fn solve(args: &[&str], limit: Duration) -> (i32, String) {
    static RUN: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let k = RUN.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let out = std::env::temp_dir().join(format!("progmo-cli-bounds-{}-{k}", std::process::id()));
    let mut child = Command::new(env!("CARGO_BIN_EXE_progmo"))
        .arg("solve")
        .args(args)
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
            let _ = std::fs::remove_dir_all(&out);
            return (status.code().unwrap_or(-1), err);
        }
        if start.elapsed() > limit {
            child.kill().unwrap();
            child.wait().unwrap();
            let _ = std::fs::remove_dir_all(&out);
            panic!("progmo solve {args:?} still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

const QUICK: Duration = Duration::from_secs(20);

#[test]
fn an_infinite_t1_flag_is_refused() {
    let (code, err) = solve(&[&scene("double_pendulum"), "--t1", "inf"], QUICK);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.starts_with("progmo solve: error: --t1 inf: must be a finite number"),
        "{err}"
    );
}

#[test]
fn output_spacings_that_never_end_are_refused() {
    for dt in ["1e-300", "5e-324"] {
        let (code, err) = solve(&[&scene("double_pendulum"), "--output-dt", dt], QUICK);
        assert_eq!(code, 2, "{dt}: {err}");
        assert!(err.contains("--output-dt"), "{err}");
        assert!(err.contains("cannot advance time"), "{err}");
    }
    // A long span at the scene's own spacing (0.01 s): too many samples, named by the scene key.
    let (code, err) = solve(&[&scene("double_pendulum"), "--t1", "1e9"], QUICK);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("time.output_dt"), "{err}");
    assert!(err.contains("more than max_samples = 10000000"), "{err}");
}

#[test]
fn an_rk4_step_that_cannot_advance_time_is_refused() {
    let (code, err) = solve(
        &[
            &scene("double_pendulum"),
            "--integrator",
            "rk4",
            "--step",
            "1e-300",
            "--t1",
            "1",
        ],
        QUICK,
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--step 1e-300: "), "{err}");
    assert!(err.contains("cannot advance time"), "{err}");
}

#[test]
fn max_samples_is_the_boundary() {
    // double_pendulum: output_dt = 0.01 over 10 s writes 1001 samples.
    let (code, err) = solve(&[&scene("double_pendulum"), "--max-samples", "1000"], QUICK);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("more than max_samples = 1000"), "{err}");
    let (code, err) = solve(
        &[&scene("double_pendulum"), "--max-samples", "1001"],
        Duration::from_secs(120),
    );
    assert_eq!(code, 0, "{err}");
}

#[test]
fn a_huge_span_without_output_dt_stops_in_seconds() {
    // Every step is a sample without output_dt, so max_samples does not bound the run up front;
    // at the scene's step rate [0, 1e9] needs ~7e9 steps, and the run stops early saying so
    // (it used to run 9.4e6 steps into max_steps: 565 s and 7 GB of CSV and MCAP).
    let dir =
        std::env::temp_dir().join(format!("progmo-cli-bounds-{}-runaway", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(scene("double_pendulum"))
        .unwrap()
        .replace("t1 = 10.0\noutput_dt = 0.01\n", "t1 = 1e9\n");
    assert!(!text.contains("output_dt"));
    let path = dir.join("runaway.toml");
    std::fs::write(&path, text).unwrap();
    let start = Instant::now();
    let (code, err) = solve(&[path.to_str().unwrap()], QUICK);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("(too_many_steps)"), "{err}");
    assert!(err.contains("more than max_steps = 10000000"), "{err}");
    assert!(
        start.elapsed() < Duration::from_secs(10),
        "{:?}",
        start.elapsed()
    );
    std::fs::remove_dir_all(&dir).ok();
}
