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
    assert!(notes.contains("<option gravity> not read"), "{notes}");
    // damping and armature (from the default class) and the slide's spring are modelled
    let tree = p.model.tree();
    for j in tree.joints() {
        assert_eq!((j.damping, j.armature), (0.1, 0.01), "{}", j.name);
    }
    assert_eq!(tree.joints()[2].stiffness, 3.0);
    // what is not modelled: one record per element, located, undeclared
    let r = s.robot.as_ref().expect("an mjcf scene has a robot file");
    let got: Vec<(&str, &str, bool)> = r
        .unmodelled
        .iter()
        .map(|u| (u.kind.as_str(), u.element.as_str(), u.declared.is_none()))
        .collect();
    assert_eq!(
        got,
        [
            ("equality", "equality.joint[0]", true),
            ("joint_limit", "joint[shoulder].range", true),
            ("frictionloss", "joint[elbow].frictionloss", true),
        ]
    );
    let file = std::path::absolute(robots().join("two_link.xml")).unwrap();
    assert_eq!(r.unmodelled[1].location, format!("{}:9", file.display()));
    assert_eq!(r.path, file);
    assert_eq!(r.ranges.len(), 1);
    assert_eq!((r.ranges[0].lower, r.ranges[0].upper), (-1.0, 1.0)); // radians here
}

/// Every modelled attribute read with MuJoCo's meaning (degrees for a hinge's ref and springref),
/// every unmodelled kind an MJCF file can hold recorded once per element, and the scene's
/// declarations: checked against the closed vocabulary (an unknown kind names the nearest), a
/// reason required, a kind absent from the file refused.
#[test]
fn dynamics_attributes_and_unmodelled_elements() {
    let f = robots().join("dynamics.xml");
    let s = load(&scene_text(&f, "")).unwrap_or_else(|e| panic!("{e}"));
    let SceneSystem::Tree(p) = &s.system else {
        panic!()
    };
    let tree = p.model.tree();
    let deg = std::f64::consts::PI / 180.0;
    let j: Vec<_> = tree
        .joints()
        .iter()
        .map(|j| {
            (
                j.damping,
                j.armature,
                j.stiffness,
                j.spring_ref,
                j.reference,
            )
        })
        .collect();
    assert_eq!(
        j,
        [
            (0.1, 0.05, 2.0, 10.0 * deg, 30.0 * deg),
            (0.1, 0.0, 0.0, 0.0, 0.0),
            (0.3, 0.2, 0.0, 0.0, 0.1),
        ]
    );
    let gc: Vec<_> = tree.bodies().iter().map(|b| b.gravcomp).collect();
    assert_eq!(gc, [1.0, 0.25, 0.0]);
    // q0 defaults to MuJoCo's qpos0: the refs
    use progmo::model::Model;
    assert_eq!(p.q0, [30.0 * deg, 0.0, 0.1]);
    let r = s.robot.as_ref().unwrap();
    let kinds: Vec<(&str, &str)> = r
        .unmodelled
        .iter()
        .map(|u| (u.kind.as_str(), u.element.as_str()))
        .collect();
    assert_eq!(
        kinds,
        [
            ("fluid", "option.density"),
            ("contact", "contact.exclude[0]"),
            ("tendon", "tendon.fixed[coupling]"),
            ("actuator", "actuator.motor[m1]"),
            ("joint_limit", "joint[shoulder].range"),
            ("contact", "body[lower].geom[bumper]"),
            ("effort_limit", "joint[elbow].actuatorfrcrange"),
            ("frictionloss", "joint[elbow].frictionloss"),
        ]
    );
    assert_eq!(
        (
            r.ranges[0].joint.as_str(),
            r.ranges[0].lower,
            r.ranges[0].upper
        ),
        ("shoulder", -90.0 * deg, 90.0 * deg)
    );
    assert!(r.undeclared().count() == kinds.len());
    let _ = p.model.nv();
    // declarations
    let all = "ignore = { fluid = \"a\", contact = \"b\", tendon = \"c\", actuator = \"d\", \
               joint_limit = \"e\", effort_limit = \"f\", frictionloss = \"g\" }";
    let s = load(&scene_text(&f, all)).unwrap_or_else(|e| panic!("{e}"));
    let r = s.robot.as_ref().unwrap();
    assert_eq!(r.undeclared().count(), 0);
    assert_eq!(r.unmodelled[7].declared.as_deref(), Some("g"));
    // negative controls: frictionloss undeclared stays listed; an unknown kind, an empty reason
    // and a kind the file lacks are refused where they are written
    let s = load(&scene_text(&f, &all.replace(", frictionloss = \"g\"", ""))).unwrap();
    let und: Vec<_> = s
        .robot
        .as_ref()
        .unwrap()
        .undeclared()
        .map(|u| u.element.clone())
        .collect();
    assert_eq!(und, ["joint[elbow].frictionloss"]);
    for (extra, phrase) in [
        (
            "ignore = { frictionlos = \"x\" }",
            "unknown kind `frictionlos`: did you mean `frictionloss`?",
        ),
        ("ignore = { frictionloss = \"  \" }", "needs a reason"),
        (
            "ignore = { mimic = \"x\" }",
            "has no element of kind `mimic`",
        ),
    ] {
        let Err(e) = load(&scene_text(&f, extra)) else {
            panic!("{extra} accepted")
        };
        assert_eq!(e.line, 6, "{e}");
        assert!(e.field.starts_with("model.ignore."), "{e}");
        assert!(e.message.contains(phrase), "{e}");
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

/// Bodies, XML nesting and XML size are bounded before anything is allocated for them: each limit
/// is a located error naming it (never quoting the file), and a file just inside loads. A chain
/// nested 50k deep used to cost 4.8 GB in the export.
#[test]
fn bodies_nesting_and_elements_are_bounded() {
    let dir = std::env::temp_dir().join(format!("progmo-mjcf-limit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let body = |k: usize| {
        format!("<body name=\"b{k}\"><inertial pos=\"0 0 0\" mass=\"1\" diaginertia=\"1 1 1\"/>")
    };
    let load_xml = |xml: String| {
        std::fs::write(dir.join("m.xml"), xml).unwrap();
        Scene::from_text(&dir.join("scene.toml"), &scene_text(&dir.join("m.xml"), ""))
    };
    // nested: <mujoco><worldbody> and then one body per line
    let nested = |n: usize| {
        let mut x = String::from("<mujoco>\n<worldbody>\n");
        for k in 0..n {
            x += &body(k);
            x += if k == 0 {
                "<freejoint name=\"root\"/>\n"
            } else {
                "\n"
            };
        }
        x += &"</body>".repeat(n);
        x + "\n</worldbody>\n</mujoco>\n"
    };
    let depth = progmo::input::MAX_XML_DEPTH;
    // <mujoco> and <worldbody> are 2 levels: body k is at depth k + 3
    let Err(e) = load_xml(nested(depth - 1)) else {
        panic!("too deep")
    };
    assert_eq!(
        (e.line, e.column, e.field.as_str()),
        (depth + 1, 1, "xml"),
        "{e}"
    );
    assert!(e.message.contains("nested more than 1024 deep"), "{e}");
    assert!(e.excerpt.is_empty(), "{e}");
    let s = load_xml(nested(depth - 2)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.v_names().len(), 6);
    // flat: bodies side by side
    let flat = |n: usize| {
        let mut x = String::from("<mujoco>\n<worldbody>\n");
        for k in 0..n {
            x += &body(k);
            x += if k == 0 {
                "<freejoint name=\"root\"/>"
            } else {
                ""
            };
            x += "</body>\n";
        }
        x + "</worldbody>\n</mujoco>\n"
    };
    let max = progmo::input::MAX_BODIES;
    let Err(e) = load_xml(flat(max + 1)) else {
        panic!("too many bodies")
    };
    assert_eq!(
        (e.line, e.column, e.field.as_str()),
        (max + 3, 1, "body"),
        "{e}"
    );
    assert!(e.message.contains("more than 4096 bodies"), "{e}");
    load_xml(flat(max)).unwrap_or_else(|e| panic!("{e}"));
    // elements: a comment of tags does not count, the elements after it do
    let n = progmo::input::MAX_XML_ELEMENTS;
    let xml = format!(
        "<mujoco>\n<!-- {} -->\n{}\n<worldbody/>\n</mujoco>\n",
        "<a/>".repeat(n),
        "<custom/>".repeat(n - 1)
    );
    let Err(e) = load_xml(xml) else {
        panic!("too many elements")
    };
    assert_eq!((e.line, e.field.as_str()), (4, "xml"), "{e}");
    assert!(e.message.contains("more than 200000 XML elements"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Mass properties from geoms (MuJoCo's compiler; parity with MuJoCo itself in
/// tests/python/test_mjcf_geom_inertia.py): closed forms of two spheres (2/5 m r^2 each, parallel
/// axes to the mass-weighted centre), a rotated box (m/12 (b^2 + c^2) with full edges) and a capsule
/// along a `fromto` (centre at the midpoint, axial moment m_cyl r^2/2 + 2/5 m_sph r^2).
#[test]
fn inertia_from_geoms_closed_forms() {
    let s = load(&scene_text(&robots().join("geoms.xml"), "")).unwrap_or_else(|e| panic!("{e}"));
    let SceneSystem::Tree(p) = &s.system else {
        panic!("a tree system")
    };
    let tree = p.model.tree();
    let close = |a: f64, b: f64| assert!((a - b).abs() <= 1e-14 * b.abs(), "{a} vs {b}");
    let [d, brick, rod] = [0, 1, 2].map(|k| &tree.bodies()[k]);
    close(d.mass, 4.0);
    close(d.com.x, 0.25);
    let sphere = 0.4 * 0.01;
    close(d.inertia[(0, 0)], 4.0 * sphere);
    // 1 (0.75)^2 + 3 (0.25)^2 = 0.75 about y and z
    close(d.inertia[(1, 1)], 4.0 * sphere + 0.75);
    let m = 500.0 * 0.2 * 0.4 * 0.6;
    close(brick.mass, m);
    // turned 90 degrees about z: the 0.4 edge along x, the 0.2 edge along y
    close(
        brick.inertia[(0, 0)],
        m / 12.0 * (0.2f64.powi(2) + 0.6f64.powi(2)),
    );
    close(
        brick.inertia[(1, 1)],
        m / 12.0 * (0.4f64.powi(2) + 0.6f64.powi(2)),
    );
    close(
        brick.inertia[(2, 2)],
        m / 12.0 * (0.4f64.powi(2) + 0.2f64.powi(2)),
    );
    close(rod.com.z, -0.2);
    let (r, h) = (0.05, 0.4);
    let ms = 2.0 * 4.0 * r / (4.0 * r + 3.0 * h);
    close(
        rod.inertia[(2, 2)],
        (2.0 - ms) * r * r / 2.0 + 0.4 * ms * r * r,
    );
}

/// `[initial] keyframe`: the key's qpos and qvel start the motion (q entries replace them); an
/// unknown key, a keyframe of a model without one, a locked joint off its weld and a qpos longer
/// than the model's are refused where they are written.
#[test]
fn a_keyframe_starts_the_motion() {
    let xml = robots().join("two_link.xml");
    let start = |init: &str, extra: &str| {
        let text = scene_text(&xml, extra).replace("[initial]\n", &format!("[initial]\n{init}\n"));
        load(&text)
    };
    let q0v0 = |s: Scene| {
        let SceneSystem::Tree(p) = s.system else {
            panic!("a tree system")
        };
        (p.q0.as_slice().to_vec(), p.v0.as_slice().to_vec())
    };
    let (q, v) = q0v0(start("keyframe = \"home\"", "").unwrap_or_else(|e| panic!("{e}")));
    assert_eq!((q, v), (vec![0.3, -0.2, 0.05], vec![0.1, 0.0, 0.0]));
    let (q, _) = q0v0(start("keyframe = \"home\"\nq = { elbow = 0.5 }", "").unwrap());
    assert_eq!(q, vec![0.3, 0.5, 0.05]);
    // a key without qpos is MuJoCo's qpos0 (here: every ref 0)
    let (q, v) = q0v0(start("keyframe = \"rest\"", "").unwrap());
    assert_eq!((q, v), (vec![0.0; 3], vec![0.0; 3]));
    let e = start("keyframe = \"hom\"", "")
        .map(|_| ())
        .expect_err("refused");
    assert!(
        e.field == "initial.keyframe" && e.message.contains("did you mean `home`"),
        "{e}"
    );
    let e = start("keyframe = \"home\"", "locked_joints = [\"slide\"]")
        .map(|_| ())
        .expect_err("refused");
    assert!(e.message.contains("locked joint `slide` at 0.05"), "{e}");
    let urdf = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/robots/two_link.urdf");
    let text = scene_text(&urdf, "")
        .replace("kind = \"mjcf\"", "kind = \"urdf\"")
        .replace("[initial]\n", "[initial]\nkeyframe = \"home\"\n");
    let e = Scene::from_text(&urdf.with_file_name("scene.toml"), &text)
        .map(|_| ())
        .expect_err("refused");
    assert!(
        e.message.contains("read from an `mjcf` model's file"),
        "{e}"
    );
    // a qpos longer than the model's: located at the key, in the MJCF file
    let dir = std::env::temp_dir().join(format!("progmo-keyframe-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let long = dir.join("long.xml");
    let text = std::fs::read_to_string(&xml).unwrap();
    std::fs::write(
        &long,
        text.replace("qpos=\"0.3 -0.2 0.05\"", "qpos=\"0.3 -0.2 0.05 1\""),
    )
    .unwrap();
    let e = Scene::from_text(&dir.join("s.toml"), &scene_text(&long, ""))
        .map(|_| ())
        .expect_err("refused");
    assert!(
        e.file == long && e.field == "keyframe[home].qpos" && e.message.contains("4 values"),
        "{e}"
    );
}

/// A static body's mesh geom (robosuite's arm bases) whose mesh cannot be weighed (here: its file
/// is missing): its mass does not enter the motion, so the file imports; a scene naming `com.`
/// needs every body's mass and is refused at the <mesh>, naming the file. (Meshes that load are
/// weighed as MuJoCo does: tests/python/test_robot_files_mujoco.py.)
#[test]
fn a_static_bodys_mesh_mass_is_needed_only_by_centre_of_mass_signals() {
    let xml = robots().join("static_mesh.xml");
    let s = load(&scene_text(&xml, "")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.q_names(), ["yaw", "pitch"]);
    let row = "[[programme]]\nname = \"h\"\nexpr = \"com.z - 0.1\"\n";
    let e = load(&scene_text(&xml, row)).expect_err("com. needs the base's mass");
    let text = e.to_string();
    assert!(text.contains("static_mesh.xml:4"), "{text}");
    assert!(text.contains("plate.stl` not found"), "{text}");
    assert_eq!(e.field, "asset.mesh[plate]");
    // the arm's own signals need no mass of the base
    let row = "[[programme]]\nname = \"h\"\nexpr = \"arm.x - 0.2\"\n";
    load(&scene_text(&xml, row)).unwrap_or_else(|e| panic!("{e}"));
}
