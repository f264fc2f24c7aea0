//! MJCF import (`model.kind = "mjcf"`, src/import/mjcf.rs): a small robot loads, names its
//! coordinates as the file does and reports what it does not model; the scene keys an mjcf model
//! refuses; each bad robot file (`tests/robots/mjcf/bad_*.xml`, header
//! `<!-- expect: LINE:COL FIELD "phrase" -->`) fails with an error located in the MJCF file.
//! Parity with MuJoCo's own reading of MJCF files: tests/python/test_robot_files_mujoco.py.

use progmo::scene::{Scene, SceneSystem};
use std::path::{Path, PathBuf};

fn robots() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/robots/mjcf")
}

fn scene_text(xml: &Path, extra: &str) -> String {
    format!(
        "name = \"t\"\n[model]\nkind = \"mjcf\"\nfile = \"{}\"\ngravity = [0.0, 0.0, -9.81]\n{extra}\n[initial]\n[time]\nt1 = 1.0\n",
        xml.display()
    )
}

fn load(text: &str) -> Result<Scene, progmo::scene::SceneError> {
    Scene::from_text(&robots().join("scene.toml"), text)
}

#[test]
fn a_small_robot_loads_with_notes_and_body_signals() {
    let rows = "[[programme]]\nname = \"h\"\nexpr = \"tool.z + lower.qw - tool.z - lower.qw\"\n";
    let s =
        load(&scene_text(&robots().join("two_link.xml"), rows)).unwrap_or_else(|e| panic!("{e}"));
    let SceneSystem::Tree(p) = &s.system else {
        panic!("a tree system")
    };
    use progmo::model::Model;
    assert_eq!(p.model.q_names(), ["shoulder", "elbow", "slide"]);
    let notes = s.import_notes.join("\n");
    for phrase in [
        "limits not enforced (the programme decides the motion): shoulder",
        "damping ignored: shoulder, elbow, slide", // from the default class
        "armature ignored (MuJoCo adds it to the mass matrix): shoulder, elbow, slide",
        "friction loss ignored: elbow",
        "stiffness (springs) ignored: slide",
        "<equality> not modelled",
        "<option gravity> not read",
    ] {
        assert!(notes.contains(phrase), "{phrase}\n{notes}");
    }
}

#[test]
fn locked_joints_root_joint_and_a_missing_file() {
    let s = load(&scene_text(
        &robots().join("two_link.xml"),
        "locked_joints = [\"slide\"]",
    ))
    .unwrap();
    let SceneSystem::Tree(p) = &s.system else {
        panic!()
    };
    use progmo::model::Model;
    assert_eq!(p.model.q_names(), ["shoulder", "elbow"]);
    let Err(e) = load(&scene_text(
        &robots().join("two_link.xml"),
        "locked_joints = [\"nope\"]",
    )) else {
        panic!("unknown joint")
    };
    assert_eq!(
        (e.line, e.field.as_str()),
        (6, "model.locked_joints"),
        "{e}"
    );
    let Err(e) = load(&scene_text(
        &robots().join("two_link.xml"),
        "root_joint = \"free\"",
    )) else {
        panic!("root_joint")
    };
    assert_eq!((e.line, e.field.as_str()), (6, "model.root_joint"), "{e}");
    assert!(e.message.contains("<freejoint/>"), "{e}");
    let Err(e) = load(&scene_text(&robots().join("no_such.xml"), "")) else {
        panic!("missing")
    };
    assert_eq!((e.line, e.field.as_str()), (4, "model.file"), "{e}");
}

#[test]
fn every_bad_mjcf_fails_where_its_header_says() {
    let mut files: Vec<PathBuf> = std::fs::read_dir(robots())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with("bad_"))
        .collect();
    files.sort();
    assert!(files.len() >= 13);
    let mut failures = vec![];
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        let head = text.lines().next().unwrap();
        let spec = head
            .trim_start_matches("<!-- expect: ")
            .trim_end_matches(" -->");
        let (pos, rest) = spec.split_once(' ').unwrap();
        let (field, phrase) = rest.split_once(' ').unwrap();
        let phrase = phrase.trim_matches('"');
        let (l, c) = pos.split_once(':').unwrap();
        let (l, c): (usize, usize) = (l.parse().unwrap(), c.parse().unwrap());
        match std::panic::catch_unwind(|| load(&scene_text(f, ""))) {
            Err(_) => failures.push(format!("{}: panicked", f.display())),
            Ok(Ok(_)) => failures.push(format!("{}: loaded", f.display())),
            Ok(Err(e)) => {
                println!("{e}\n");
                if e.file != *f
                    || e.line != l
                    || e.column != c
                    || e.field != field
                    || !e.message.contains(phrase)
                {
                    failures.push(format!(
                        "{}: got {}:{} `{}` {}",
                        f.display(),
                        e.line,
                        e.column,
                        e.field,
                        e.message
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}
