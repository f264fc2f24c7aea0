//! What `progmo solve` leaves behind when it does not end normally (issue 11, "outputs never
//! lie"): Ctrl-C / SIGTERM finish the files as partial (exit 130), a file that cannot be written
//! is the last line and exit 3 and never appears under its real name, non-UTF-8 paths are kept.
#![cfg(unix)]

use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const PROGMO: &str = env!("CARGO_BIN_EXE_progmo");

fn scene(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join(format!("references/scenes/{name}.toml"))
        .display()
        .to_string()
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("progmo-outputs-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn partial_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".partial") || n.ends_with(".tmp"))
        .collect()
}

/// A long solve (t1 = 1000 at output_dt = 1e-3: about 20 s), stopped by `sig` once it is writing.
fn interrupted_by(sig: libc::c_int, name: &str) {
    let out = tmp(name);
    let mut cmd = Command::new(PROGMO);
    cmd.args(["solve", &scene("double_pendulum")])
        .args(["--t1", "1000", "--output-dt", "1e-3", "--quiet", "--out"])
        .arg(&out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    // A shell may start us with SIGINT ignored (a background job), which progmo respects.
    // SAFETY: signal(2) is async-signal-safe.
    unsafe {
        cmd.pre_exec(|| {
            libc::signal(libc::SIGINT, libc::SIG_DFL);
            libc::signal(libc::SIGTERM, libc::SIG_DFL);
            Ok(())
        });
    }
    let mut child = cmd.spawn().unwrap();
    let partial = out.join("trajectory.csv.partial");
    let start = Instant::now();
    while std::fs::metadata(&partial).map_or(0, |m| m.len()) < 1_000_000 {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the solve never wrote"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "ended before the signal"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    // SAFETY: a signal to our own child.
    assert_eq!(unsafe { libc::kill(child.id() as libc::pid_t, sig) }, 0);
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{err}");
    assert!(err.contains("(interrupted)"), "{err}");
    assert!(String::from_utf8_lossy(&o.stdout).contains("double_pendulum: interrupted, t = 0"));

    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["code_name"], "interrupted");
    assert_eq!(summary["success"], false);
    let t_end = summary["t_end"].as_f64().unwrap();
    assert_eq!(summary["code"]["t"].as_f64(), Some(t_end));
    assert!(t_end > 0.0 && t_end < 1000.0, "{t_end}");
    // The CSV parses to the stop, the MCAP is finished (summary section) and holds the same samples.
    let traj = progmo::output::read_csv(out.join("trajectory.csv")).unwrap();
    assert!(traj.len() > 1000);
    assert_eq!(traj.t.last().copied(), Some(t_end));
    let bytes = std::fs::read(out.join("recording.mcap")).unwrap();
    let stats = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a summary section")
        .stats
        .unwrap();
    // one message per sample on each sample channel, one frame per body per sample, the geometry once
    let mut per_topic = std::collections::BTreeMap::<String, usize>::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        *per_topic
            .entry(m.unwrap().channel.topic.clone())
            .or_default() += 1;
    }
    for topic in ["/progmo/state", "/progmo/control", "/progmo/residual"] {
        assert_eq!(per_topic[topic], traj.len(), "{topic}");
    }
    assert_eq!(per_topic["/progmo/tf"], 2 * traj.len()); // two bodies
    assert_eq!(per_topic["/progmo/scene"], 1);
    assert_eq!(
        stats.message_count,
        per_topic.values().sum::<usize>() as u64
    );
    assert!(partial_files(&out).is_empty(), "{:?}", partial_files(&out));
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn sigint_finishes_the_files_as_partial_and_exits_130() {
    interrupted_by(libc::SIGINT, "sigint");
}

#[test]
fn sigterm_finishes_the_files_as_partial_and_exits_130() {
    interrupted_by(libc::SIGTERM, "sigterm");
}

#[test]
fn a_file_that_cannot_be_written_is_the_last_line_and_never_has_its_real_name() {
    // A 64 KiB file size limit (works as root, unlike permissions), SIGXFSZ at its default (the
    // binary ignores it itself: killed by it, the run would leave no word): the CSV and the MCAP
    // fail mid-run with EFBIG; the summary (2 KB) is still written, named summary.json.partial
    // beside them (a summary.json saying success would vouch for files that are not whole). One
    // stream keeps the order.
    let out = tmp("fsize");
    let o = Command::new("bash")
        .args([
            "-c",
            "trap - XFSZ; ulimit -f 64; exec \"$@\" 2>&1",
            "bash",
            PROGMO,
            "solve",
            &scene("double_pendulum"),
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(3), "{text}");
    let last = text.lines().last().unwrap();
    assert!(
        last.starts_with("progmo solve: error: cannot write the results: ")
            && last.contains("recording.mcap.partial"),
        "{text}"
    );
    assert!(
        text.contains("trajectory.csv.partial: ") && text.contains("File too large"),
        "{text}"
    );
    assert!(!text.contains("panicked"), "{text}");
    // Nothing truncated under a real name; the partial files say what they are.
    assert!(!out.join("trajectory.csv").exists() && !out.join("recording.mcap").exists());
    assert!(out.join("trajectory.csv.partial").is_file());
    assert!(!out.join("summary.json").exists());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json.partial")).unwrap())
            .unwrap();
    assert_eq!(summary["code_name"], "success");

    // The next run into the folder clears the partial files of this one.
    let o = Command::new(PROGMO)
        .args(["solve", &scene("heavy_top"), "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(partial_files(&out).is_empty(), "{:?}", partial_files(&out));
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn an_output_folder_that_cannot_be_made_is_exit_3() {
    let o = Command::new(PROGMO)
        .args(["solve", &scene("double_pendulum"), "--out", "/dev/full/run"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(err.contains("cannot create /dev/full/run"), "{err}");
}

#[test]
fn export_keeps_a_non_utf8_output_path() {
    use std::os::unix::ffi::OsStrExt;
    let dir = tmp("export-nonutf8");
    let out = dir.join(std::ffi::OsStr::from_bytes(b"model-\xff.xml"));
    let o = Command::new(PROGMO)
        .args([
            "export",
            &scene("double_pendulum"),
            "--format",
            "mjcf",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.is_file());
    let report = dir.join(std::ffi::OsStr::from_bytes(b"model-\xff.xml.report.json"));
    assert!(report.is_file(), "{:?}", std::fs::read_dir(&dir).unwrap());
    std::fs::remove_dir_all(&dir).ok();
}
