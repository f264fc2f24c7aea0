//! Files stay where they belong (src/input.rs, FORMAT.md "Files a scene reads"): a scene's model
//! file resolves inside its folder, its package or `$PROGMO_ALLOW_ROOTS`; only regular files are
//! read, within a size bound; no error quotes a file that is not text or not the expected format.
//! Each refusal has its positive control (the same file where it is allowed loads). The bad-scene
//! corpus (`tests/bad_scenes/files_*.toml`) holds the escapes with their located errors; the
//! canary across every door (CLI, Python, check, debug, sweep): tests/python/test_input_files.py.

use std::path::{Path, PathBuf};
use std::process::Command;

const CANARY: &str = "PROGMO-CANARY-7f3a91c2e4";

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("progmo-input-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn robot() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/robots/two_link.urdf")
}

fn scene(dir: &Path, file: &str) -> PathBuf {
    let p = dir.join("scene.toml");
    std::fs::write(
        &p,
        format!("name = \"t\"\n[model]\nkind = \"urdf\"\nfile = \"{file}\"\n[initial]\n[time]\nt1 = 1.0\n"),
    )
    .unwrap();
    p
}

/// `progmo validate SCENE` with the robot path and allowed roots given (and the canary in the
/// environment): exit code and stdout + stderr.
fn validate(scene: &Path, robot_path: &str, allow: &str) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_progmo"))
        .arg("validate")
        .arg(scene)
        .env("PROGMO_ROBOT_PATH", robot_path)
        .env_remove("ROS_PACKAGE_PATH")
        .env("PROGMO_ALLOW_ROOTS", allow)
        .env("PROGMO_CANARY", CANARY)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!text.contains(CANARY), "the canary leaked:\n{text}");
    (out.status.code().unwrap_or(-1), text)
}

#[test]
fn a_file_outside_loads_only_from_an_allowed_root() {
    let base = tmp("allow");
    let (sc, outside) = (base.join("scenes"), base.join("robots"));
    std::fs::create_dir_all(&sc).unwrap();
    std::fs::create_dir_all(&outside).unwrap();
    std::fs::copy(robot(), outside.join("r.urdf")).unwrap();
    for file in [
        outside.join("r.urdf").display().to_string(),
        "../robots/r.urdf".to_string(),
    ] {
        let s = scene(&sc, &file);
        let (code, text) = validate(&s, "", "");
        assert_eq!(code, 2, "{text}");
        assert!(
            text.contains("scene.toml:4:8: error: model.file:")
                && text.contains("outside the folder")
                && text.contains("PROGMO_ALLOW_ROOTS"),
            "{text}"
        );
        let (code, text) = validate(&s, "", &outside.display().to_string());
        assert_eq!(code, 0, "allowed root: {text}");
    }
    // a symlink in the folder to the file outside: refused, allowed with the root
    std::os::unix::fs::symlink(outside.join("r.urdf"), sc.join("link.urdf")).unwrap();
    let s = scene(&sc, "link.urdf");
    let (code, text) = validate(&s, "", "");
    assert!(code == 2 && text.contains("resolves to"), "{text}");
    assert_eq!(validate(&s, "", &outside.display().to_string()).0, 0);
    // inside the folder: loads without any option
    std::fs::copy(robot(), sc.join("r.urdf")).unwrap();
    assert_eq!(validate(&scene(&sc, "r.urdf"), "", "").0, 0);
    std::fs::remove_dir_all(&base).unwrap();
}

#[test]
fn a_package_path_stays_inside_its_package() {
    let base = tmp("pkg");
    let (share, sc) = (base.join("share"), base.join("scenes"));
    std::fs::create_dir_all(share.join("pkg/urdf")).unwrap();
    std::fs::create_dir_all(share.join("other")).unwrap();
    std::fs::create_dir_all(&sc).unwrap();
    std::fs::copy(robot(), share.join("pkg/urdf/r.urdf")).unwrap();
    std::fs::copy(robot(), share.join("other/r.urdf")).unwrap();
    std::fs::write(base.join("canary.txt"), CANARY).unwrap();
    std::os::unix::fs::symlink(share.join("other/r.urdf"), share.join("pkg/urdf/link.urdf"))
        .unwrap();
    let rp = share.display().to_string();
    let ok = |f: &str| validate(&scene(&sc, f), &rp, "");
    assert_eq!(ok("package://pkg/urdf/r.urdf").0, 0);
    assert_eq!(ok("package://pkg/urdf/../urdf/r.urdf").0, 0);
    for (file, phrase) in [
        ("package://../canary.txt", "not `.` or `..`"),
        (
            "package://pkg/../other/r.urdf",
            "leaves the folder of package `pkg`",
        ),
        (
            "package://pkg/../../canary.txt",
            "leaves the folder of package `pkg`",
        ),
        (
            "package://pkg/urdf/link.urdf",
            "outside the folder of package `pkg`",
        ),
    ] {
        let (code, text) = ok(file);
        assert!(
            code == 2 && text.contains("model.file") && text.contains(phrase),
            "{file}: {text}"
        );
    }
    // a folder of $PROGMO_ALLOW_ROOTS admits the symlinked file
    let allow = share.join("other").display().to_string();
    assert_eq!(
        validate(&scene(&sc, "package://pkg/urdf/link.urdf"), &rp, &allow).0,
        0
    );
    std::fs::remove_dir_all(&base).unwrap();
}

#[test]
fn only_regular_text_files_are_read_and_never_quoted() {
    let d = tmp("kinds");
    std::fs::create_dir_all(d.join("dir.urdf")).unwrap();
    let fifo = std::ffi::CString::new(d.join("fifo.urdf").to_str().unwrap()).unwrap();
    // SAFETY: mkfifo on a NUL-terminated path
    assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o600) }, 0);
    std::fs::write(d.join("plain.urdf"), format!("{CANARY}\n<robot/>\n")).unwrap();
    std::fs::write(d.join("nul.urdf"), format!("<robot>A=1\0{CANARY}</robot>")).unwrap();
    let bad = [b"<robot>\xff".as_slice(), CANARY.as_bytes(), b"</robot>"].concat();
    std::fs::write(d.join("bad.urdf"), bad).unwrap();
    // an XML file quoted in a window of the offending line: the canary 400 characters before it
    let long = format!("<robot name=\"{CANARY}{}\"><link></robot>", "x".repeat(400));
    std::fs::write(d.join("long.urdf"), long).unwrap();
    for (file, phrase) in [
        ("dir.urdf", "it is a directory, not a regular file"),
        ("fifo.urdf", "it is a FIFO (named pipe), not a regular file"),
        (
            "plain.urdf",
            "plain.urdf:1:1: error: xml: not an XML document",
        ),
        (
            "nul.urdf",
            "nul.urdf:1:11: error: xml: the robot file is not text",
        ),
        (
            "bad.urdf",
            "not valid UTF-8 (an invalid byte at line 1, column 8)",
        ),
        ("long.urdf", "not well-formed XML"),
    ] {
        let (code, text) = validate(&scene(&d, file), "", "");
        assert!(code == 2 && text.contains(phrase), "{file}: {text}");
        // a directory or FIFO exists: never "not found" (issue 29)
        assert!(!text.contains("not found"), "{file}: {text}");
        // an excerpt (indented) shows at most 120 characters and two `…`
        let quoted = text.lines().filter(|l| l.starts_with("    "));
        assert!(quoted.clone().all(|l| l.chars().count() <= 126), "{text}");
    }
    // /proc/self/environ where /proc is allowed: a regular file, not text (NUL-separated)
    let (code, text) = validate(&scene(&d, "/proc/self/environ"), "", "/proc");
    assert!(code == 2 && text.contains("is not text"), "{text}");
    // the scene file itself: a FIFO, a device, a folder, too large
    let cases: [(PathBuf, &str); 3] = [
        (d.join("fifo.urdf"), "it is a FIFO (named pipe)"),
        ("/dev/zero".into(), "it is a character device"),
        (d.join("dir.urdf"), "it is a directory"),
    ];
    for (p, phrase) in cases {
        let (code, text) = validate(&p, "", "");
        assert!(
            code == 2 && text.contains(phrase),
            "{}: {text}",
            p.display()
        );
    }
    let big = d.join("big.toml");
    let f = std::fs::File::create(&big).unwrap();
    f.set_len(progmo::input::SCENE_LIMIT + 1).unwrap();
    let (code, text) = validate(&big, "", "");
    assert!(code == 2 && text.contains("larger than 4 MiB"), "{text}");
    // a text that does not begin as a scene is refused without quoting
    std::fs::write(d.join("canary.toml"), format!("\n{CANARY}\n")).unwrap();
    let (code, text) = validate(&d.join("canary.toml"), "", "");
    assert!(
        code == 2 && text.contains("canary.toml:2:1: error: not a TOML scene"),
        "{text}"
    );
    std::fs::remove_dir_all(&d).unwrap();
}
