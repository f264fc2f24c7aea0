//! URDF import (`model.kind = "urdf"`, src/import): a small robot with every supported joint type
//! loads, reports what it ignores, exposes links and frames as signals and agrees with the same
//! robot written by hand as a tree scene; each bad robot file (`tests/robots/bad_*.urdf`, header
//! `<!-- expect: LINE:COL FIELD "phrase" -->`) fails with an error located in the URDF file.
//! Parity with Pinocchio's own URDF reader: tests/python/test_urdf_import.py.

use progmo::scene::{Scene, SceneSystem};
use std::path::{Path, PathBuf};

fn robots() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/robots")
}

fn scene_text(urdf: &Path, extra: &str, rows: &str) -> String {
    format!(
        "name = \"t\"\n[model]\nkind = \"urdf\"\nfile = \"{}\"\ngravity = [0.0, 0.0, -9.81]\n{extra}\n{rows}\n[initial]\n[time]\nt1 = 1.0\n",
        urdf.display()
    )
}

fn load(text: &str) -> Result<Scene, progmo::scene::SceneError> {
    Scene::from_text(&robots().join("scene.toml"), text)
}

#[test]
fn a_small_robot_loads_with_notes_and_link_signals() {
    let frames = "[[model.frames]]\nname = \"tip\"\nparent = \"tool\"\npos = [0.0, 0.0, 0.1]\nquat = [0.0, 1.0, 0.0, 0.0]\n";
    let rows = "[[programme]]\nname = \"h\"\nexpr = \"tip.z + lower.qw - tip.z - lower.qw\"\n";
    let s = load(&scene_text(&robots().join("two_link.urdf"), frames, rows))
        .unwrap_or_else(|e| panic!("{e}"));
    let SceneSystem::Tree(p) = &s.system else {
        panic!("a tree system")
    };
    use progmo::model::Model;
    assert_eq!(p.model.q_names(), ["shoulder", "elbow", "slide"]);
    assert!(s.import_notes.is_empty(), "{:?}", s.import_notes);
    let r = s.robot.as_ref().expect("a urdf scene has a robot file");
    let got: Vec<(&str, &str)> = r
        .unmodelled
        .iter()
        .map(|u| (u.kind.as_str(), u.element.as_str()))
        .collect();
    assert_eq!(
        got,
        [
            ("joint_limit", "joint[shoulder].limit"),
            ("effort_limit", "joint[shoulder].limit.effort"),
            ("velocity_limit", "joint[shoulder].limit.velocity"),
        ]
    );
    // the <mimic> is modelled: a system row slide = elbow (multiplier 1, offset 0)
    let mimic: Vec<_> = s
        .rows()
        .into_iter()
        .filter(|r| r.name == "mimic_slide")
        .collect();
    assert_eq!(mimic.len(), 1);
    assert_eq!(mimic[0].role, progmo::programme::Role::System);
    assert_eq!(
        (r.mimics[0].joint.as_str(), r.mimics[0].leader.as_str()),
        ("slide", "elbow")
    );
    assert_eq!((r.mimics[0].multiplier, r.mimics[0].offset), (1.0, 0.0));
    assert_eq!(r.kind, "urdf");
    assert!(r.path.is_absolute() && r.path.ends_with("tests/robots/two_link.urdf"));
    // a link name that is not a signal source is refused in a row (located in the scene)
    let bad = "[[programme]]\nname = \"h\"\nexpr = \"nolink.z\"\n";
    let Err(e) = load(&scene_text(&robots().join("two_link.urdf"), "", bad)) else {
        panic!("unknown frame")
    };
    assert_eq!(e.file, robots().join("scene.toml"));
    assert_eq!(e.line, 9, "{e}");
}

#[test]
fn locked_joints_are_welded_and_unknown_ones_refused() {
    // the slide follows the elbow (<mimic>): welded alone only with the coupling declared ignored
    let Err(e) = load(&scene_text(
        &robots().join("two_link.urdf"),
        "locked_joints = [\"slide\"]",
        "",
    )) else {
        panic!("a follower locked alone")
    };
    assert_eq!(
        (e.line, e.field.as_str()),
        (38, "joint[slide].mimic"),
        "{e}"
    );
    let s = load(&scene_text(
        &robots().join("two_link.urdf"),
        "locked_joints = [\"slide\"]\nignore = { mimic = \"the slide is welded alone\" }",
        "",
    ))
    .unwrap();
    let SceneSystem::Tree(p) = &s.system else {
        panic!()
    };
    use progmo::model::Model;
    assert_eq!(p.model.q_names(), ["shoulder", "elbow"]);
    let Err(e) = load(&scene_text(
        &robots().join("two_link.urdf"),
        "locked_joints = [\"nope\"]",
        "",
    )) else {
        panic!("unknown joint")
    };
    assert_eq!(
        (e.line, e.field.as_str()),
        (6, "model.locked_joints"),
        "{e}"
    );
    assert!(e.message.contains("`nope`"), "{e}");
}

#[test]
fn a_missing_robot_file_is_located_in_the_scene() {
    let Err(e) = load(&scene_text(&robots().join("no_such.urdf"), "", "")) else {
        panic!("missing")
    };
    assert_eq!((e.line, e.field.as_str()), (4, "model.file"), "{e}");
    assert!(e.message.contains("not found"), "{e}");
    let text = "name = \"t\"\n[model]\nkind = \"urdf\"\nfile = \"package://nopkg/x.urdf\"\n[initial]\n[time]\nt1 = 1.0\n";
    let Err(e) = load(text) else {
        panic!("missing package")
    };
    assert!(e.message.contains("PROGMO_ROBOT_PATH"), "{e}");
}

#[test]
fn every_bad_robot_fails_where_its_header_says() {
    let mut files: Vec<PathBuf> = std::fs::read_dir(robots())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with("bad_"))
        .collect();
    files.sort();
    assert!(files.len() >= 7);
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
        match std::panic::catch_unwind(|| load(&scene_text(f, "", ""))) {
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

/// `<dynamics damping>` is modelled (a viscous damper on the joint); friction, limits, the safety
/// controller, collisions and transmissions are recorded one per element, with the file's line,
/// and a scene declares the kinds it ignores. Negative control: without the declaration of
/// `frictionloss` the friction stays undeclared.
#[test]
fn dynamics_damping_is_modelled_and_the_rest_recorded() {
    let f = robots().join("dynamics.urdf");
    let s = load(&scene_text(&f, "", "")).unwrap_or_else(|e| panic!("{e}"));
    let SceneSystem::Tree(p) = &s.system else {
        panic!()
    };
    assert_eq!(p.model.tree().joints()[0].damping, 0.7);
    let r = s.robot.as_ref().unwrap();
    let got: Vec<(&str, &str, usize)> = r
        .unmodelled
        .iter()
        .map(|u| {
            let line = u.location.rsplit(':').next().unwrap().parse().unwrap();
            (u.kind.as_str(), u.element.as_str(), line)
        })
        .collect();
    assert_eq!(
        got,
        [
            ("contact", "link[arm].collision", 8),
            ("actuator", "transmission[t_pivot]", 17),
            ("joint_limit", "joint[pivot].limit", 13),
            ("effort_limit", "joint[pivot].limit.effort", 13),
            ("velocity_limit", "joint[pivot].limit.velocity", 13),
            ("joint_limit", "joint[pivot].safety_controller", 14),
            ("frictionloss", "joint[pivot].dynamics.friction", 15),
        ]
    );
    assert_eq!(
        (
            r.ranges[0].joint.as_str(),
            r.ranges[0].lower,
            r.ranges[0].upper
        ),
        ("pivot", -1.5, 2.0)
    );
    let decl = "ignore = { contact = \"c\", actuator = \"a\", joint_limit = \"l\", \
                effort_limit = \"e\", velocity_limit = \"v\" }";
    let s = load(&scene_text(&f, decl, "")).unwrap_or_else(|e| panic!("{e}"));
    let und: Vec<_> = s
        .robot
        .as_ref()
        .unwrap()
        .undeclared()
        .map(|u| u.kind.as_str())
        .collect();
    assert_eq!(und, ["frictionloss"]);
}

/// A locked joint used in a row is named as locked (and where), not "unknown symbol (did you
/// mean ...)"; a frame named like a joint is refused where it is written; a link named like a
/// joint (ANYmal's `LF_HAA`) is no site, and a row using its signals is told why.
#[test]
fn locked_joints_and_name_clashes_are_explained_where_they_are_used() {
    let urdf = robots().join("two_link.urdf");
    let row = |e: &str| format!("[[programme]]\nname = \"h\"\nexpr = \"{e}\"\n");
    let Err(e) = load(&scene_text(
        &urdf,
        "locked_joints = [\"slide\"]\nignore = { mimic = \"slide locked alone\" }",
        &row("slide - sin(t)"),
    )) else {
        panic!("a locked joint in a row")
    };
    assert_eq!((e.line, e.field.as_str()), (10, "programme[0].expr"), "{e}");
    assert!(
        e.message.contains(
            "`slide` is a locked joint, welded at q = 0 by model.locked_joints[0] (line 6)"
        ),
        "{e}"
    );
    let frame = "[[model.frames]]\nname = \"elbow\"\nparent = \"tool\"\n";
    let Err(e) = load(&scene_text(&urdf, frame, "")) else {
        panic!("a frame named like a joint")
    };
    assert_eq!(
        (e.line, e.field.as_str()),
        (6, "model.frames[0].name"),
        "{e}"
    );
    assert!(e.message.contains("also a joint name"), "{e}");
    // a link named like a joint
    let dir = std::env::temp_dir().join(format!("progmo-urdf-clash-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(&urdf)
        .unwrap()
        .replace("\"lower\"", "\"elbow\"");
    std::fs::write(dir.join("clash.urdf"), text).unwrap();
    let sc = |rows: &str| {
        Scene::from_text(
            &dir.join("scene.toml"),
            &scene_text(&dir.join("clash.urdf"), "", rows),
        )
    };
    let Err(e) = sc(&row("elbow.z - sin(t)")) else {
        panic!("the signal of a link named like a joint")
    };
    assert!(
        e.message
            .contains("link `elbow` has the name of a joint, so it is not a site"),
        "{e}"
    );
    sc(&row("elbow")).unwrap_or_else(|e| panic!("{e}"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A file over the limit of bodies is refused at the first link past it; a chain at the limit
/// loads, in linear time (the joints were looked up in a list: 100k links took over 20 s).
#[test]
fn links_are_bounded_and_read_in_linear_time() {
    let dir = std::env::temp_dir().join(format!("progmo-urdf-limit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let chain = |n: usize| {
        let mut x = String::from("<robot name=\"chain\">\n");
        for k in 0..n {
            x += &format!("<link name=\"l{k}\"><inertial><mass value=\"1\"/><inertia ixx=\"1\" iyy=\"1\" izz=\"1\"/></inertial></link>\n");
        }
        for k in 1..n {
            // fixed joints: the limit of bodies, not of coordinates
            x += &format!("<joint name=\"j{k}\" type=\"fixed\"><parent link=\"l{}\"/><child link=\"l{k}\"/></joint>\n", k - 1);
        }
        x + "</robot>\n"
    };
    let max = progmo::input::MAX_BODIES;
    let sc = |n: usize| {
        std::fs::write(dir.join("chain.urdf"), chain(n)).unwrap();
        Scene::from_text(
            &dir.join("scene.toml"),
            &scene_text(&dir.join("chain.urdf"), "root_joint = \"free\"", ""),
        )
    };
    let Err(e) = sc(max + 1) else {
        panic!("over the limit")
    };
    assert_eq!((e.line, e.column), (max + 2, 1), "{e}");
    assert_eq!(e.field, format!("link[l{max}]"));
    assert!(e.message.contains("more than 4096 links"), "{e}");
    let started = std::time::Instant::now();
    let s = sc(max).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.q_names().len(), 7);
    assert!(
        started.elapsed().as_secs_f64() < 20.0,
        "{:?}",
        started.elapsed()
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A two-link arm on the world whose second link `b` has the given `<inertial>` body; `j1` turns
/// `a`, `j2` turns `b`. The file is written beside the test robots (unique per `tag`).
fn arm(tag: &str, inertial_b: &str) -> PathBuf {
    let text = format!(
        r#"<robot name="arm">
  <link name="a">
    <inertial><origin xyz="0.5 0 0"/><mass value="1"/><inertia ixx="0.01" iyy="0.1" izz="0.1"/></inertial>
  </link>
  <link name="b">
    {inertial_b}
  </link>
  <joint name="j1" type="revolute"><parent link="world_anchor"/><child link="a"/><axis xyz="0 0 1"/></joint>
  <link name="world_anchor"/>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/><origin xyz="1 0 0"/><axis xyz="0 1 0"/></joint>
</robot>
"#
    );
    let dir = std::env::temp_dir().join(format!("progmo_urdf_inertia_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join(format!("{tag}.urdf"));
    std::fs::write(&f, text).unwrap();
    f
}

/// The minimal scene of robot file `f`, loaded from a scene file beside it.
fn load_beside(f: &Path) -> Result<Scene, progmo::scene::SceneError> {
    Scene::from_text(&f.with_file_name("scene.toml"), &scene_text(f, "", ""))
}

/// The mass matrix of a loaded tree scene at its initial configuration.
fn mass_matrix(s: &Scene) -> nalgebra::DMatrix<f64> {
    use progmo::model::Model;
    let SceneSystem::Tree(p) = &s.system else {
        panic!("a tree system")
    };
    let n = p.model.nv();
    let mut a = nalgebra::DMatrix::zeros(n, n);
    p.model
        .mass_matrix(&mut p.model.workspace::<f64>(), &p.q0, &mut a);
    a
}

/// Point masses (zero inertia, as Talos, iCub and Baxter write them) and a thin rod with an exact
/// zero moment import without a note; A stays positive definite (the link's mass moves with j2
/// away from its axis).
#[test]
fn semi_definite_inertias_import() {
    for (tag, inertial) in [
        (
            "point",
            r#"<inertial><origin xyz="0 0 0.3"/><mass value="2"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>"#,
        ),
        (
            "bare",
            r#"<inertial><origin xyz="0 0 0.3"/><mass value="2"/></inertial>"#,
        ),
        (
            "rod",
            r#"<inertial><origin xyz="0 0 0.3"/><mass value="2"/><inertia ixx="0.00012" iyy="0.00012" izz="0"/></inertial>"#,
        ),
    ] {
        let s = load_beside(&arm(tag, inertial)).unwrap_or_else(|e| panic!("{tag}: {e}"));
        assert!(s.import_notes.is_empty(), "{tag}: {:?}", s.import_notes);
        let a = mass_matrix(&s);
        // j2 row: the point mass 2 kg at 0.3 m from the j2 axis (plus the rod's 0.00012)
        let want = 2.0 * 0.09 + if tag == "rod" { 0.00012 } else { 0.0 };
        assert!((a[(1, 1)] - want).abs() < 1e-12, "{tag}: {a}");
    }
    // mass 0 with an inertia (bolt's feet): a rotor, its moment about the j2 axis is A's j2 entry
    let rotor = r#"<inertial><origin xyz="0 0 0.3"/><mass value="0"/><inertia ixx="0.01" iyy="0.02" izz="0.01"/></inertial>"#;
    let s = load_beside(&arm("rotor", rotor)).unwrap_or_else(|e| panic!("rotor: {e}"));
    let a = mass_matrix(&s);
    assert!((a[(1, 1)] - 0.02).abs() < 1e-15, "rotor: {a}");
}

/// ANYmal's `ixx = ixy = ... = 1e-6` (rank one: eigenvalues 3e-6, about -2e-22 and 0) on a link
/// welded to a moving one loads: the round-off eigenvalue is clipped with a note naming the link,
/// and the triangle inequality holds for the rigid body they form. The same tensor on a link that
/// moves by itself is no rigid body's: refused, naming it.
#[test]
fn round_off_eigenvalues_are_clipped_with_a_note() {
    let ones = r#"<inertial><mass value="0.001"/><inertia ixx="1e-6" ixy="1e-6" ixz="1e-6" iyy="1e-6" iyz="1e-6" izz="1e-6"/></inertial>"#;
    let b = r#"<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/></inertial>"#;
    let f = arm("ones", b);
    let text = std::fs::read_to_string(&f).unwrap().replace(
        "</robot>",
        &format!("<link name=\"flange\">{ones}</link><joint name=\"weld\" type=\"fixed\"><parent link=\"b\"/><child link=\"flange\"/></joint></robot>"),
    );
    std::fs::write(&f, text).unwrap();
    let s = load_beside(&f).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(s.import_notes.len(), 1, "{:?}", s.import_notes);
    let n = &s.import_notes[0];
    assert!(n.starts_with("link `flange`: inertia eigenvalue -"), "{n}");
    assert!(n.ends_with("(round-off) clipped to zero"), "{n}");
    let f = arm("ones_b", ones);
    let e = match load_beside(&f) {
        Err(e) => e,
        Ok(_) => panic!("a moving rank-one inertia"),
    };
    assert!(
        e.message.contains("'b'") && e.message.contains("triangle inequality"),
        "{e}"
    );
    // located at the link's <inertia> in the robot file, not at the scene's [model]
    assert_eq!((e.file.as_path(), e.line), (f.as_path(), 6), "{e}");
    assert_eq!(e.field, "link[b].inertial.inertia", "{e}");
}

/// A truly negative eigenvalue (-1e-3) is refused, located at the `<inertia>` element.
#[test]
fn a_negative_eigenvalue_is_refused_at_its_element() {
    let inertial = r#"<inertial><mass value="1"/>
    <inertia ixx="0.1" iyy="0.1" izz="-1e-3"/></inertial>"#;
    let f = arm("negative", inertial);
    let Err(e) = load_beside(&f) else {
        panic!("a negative moment")
    };
    assert_eq!(e.file, f);
    assert_eq!((e.line, e.column), (7, 5), "{e}");
    assert_eq!(e.field, "link[b].inertial.inertia");
    assert!(
        e.message
            .contains("positive semi-definite: eigenvalue -1e-3"),
        "{e}"
    );
}

/// A massless link at the end of the chain leaves A singular: the load names its joint.
#[test]
fn a_singular_mass_matrix_names_the_massless_joint() {
    let f = arm("massless", "");
    let Err(e) = load_beside(&f) else {
        panic!("j2 moves no mass")
    };
    assert_eq!(e.field, "model", "{e}");
    assert!(
        e.message.contains("singular") && e.message.contains("rank 1 of 2"),
        "{e}"
    );
    assert!(e.message.contains("the rows of `j2` are zero"), "{e}");
}
