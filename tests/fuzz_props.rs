//! Stable, bounded version of the fuzz targets (`fuzz/`, nightly): mutated scene files, generated
//! expressions and mutated robot files (URDF, MJCF, through the scene loader) go through the same
//! bodies (`progmo::fuzzing`), which must not panic and assert their properties.
//! A few thousand cases, a few seconds in release; the long coverage-guided runs are `fuzz/run.sh`.

use crate::common;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

/// The seed scenes: catalog, test-only scenes and the bad-input set.
fn seeds() -> Vec<Vec<u8>> {
    let mut out = vec![];
    for dir in ["references/scenes", "tests/scenes", "tests/bad_scenes"] {
        let files = common::toml_files(dir);
        out.extend(files.iter().map(|p| std::fs::read(p).unwrap()));
    }
    out
}

/// Fragments worth splicing into scene text: numbers at the edges, structure, names.
const TOKENS: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "1e308",
    "1e-300",
    "5e-324",
    "0",
    "-1",
    "0.0",
    "[",
    "]",
    "[[",
    "]]",
    "{",
    "}",
    "\"",
    "=",
    "\n",
    ".",
    "'",
    "''",
    "(",
    ")",
    "^",
    "*",
    "+",
    "-",
    "/",
    "t",
    "pi",
    "sin(",
    "atan2(",
    "tip.x",
    "q1",
    "world",
    "\u{200b}",
    "\u{202e}",
    "\r",
    "\0",
    "[time]\n",
    "[solver]\n",
    "integrator = \"rk4\"\nstep = 1e-300\n",
    "output_dt = 1e-300\n",
    "max_samples = 2\n",
    "[[model.bodies]]\n",
    "[[model.sites]]\nname = \"s\"\nbody = \"link\"\n",
    "parent = \"world\"\n",
];

/// Fragments worth splicing into robot files: XML syntax, the formats' tags and attributes,
/// numbers at the edges, bytes that are not text.
const XML_TOKENS: &[&str] = &[
    "<",
    ">",
    "/>",
    "</",
    "\"",
    "'",
    "=",
    "<!--",
    "-->",
    "<![CDATA[",
    "]]>",
    "<!DOCTYPE r [<!ENTITY e \"x\">]>",
    "&e;",
    "&amp;",
    "&#0;",
    "&#x10FFFF;",
    "<?xml version=\"1.0\"?>",
    "\u{feff}",
    "\0",
    "\r",
    "\n",
    " ",
    "nan",
    "inf",
    "-1",
    "0",
    "1e308",
    "5e-324",
    "0 0 0",
    "1 0 0 0",
    "0 0 0 0",
    "\u{202e}",
    "\u{e9}",
    "<link name=\"l\"/>",
    "<joint name=\"j\" type=\"revolute\"><parent link=\"l\"/><child link=\"c\"/></joint>",
    "<inertial><mass value=\"1\"/><inertia ixx=\"1\" iyy=\"1\" izz=\"1\"/></inertial>",
    "<origin xyz=\"0 0 1\" rpy=\"0 1e308 0\"/>",
    "<axis xyz=\"0 0 0\"/>",
    "<limit lower=\"1\" upper=\"-1\"/>",
    "<dynamics damping=\"-1\" friction=\"nan\"/>",
    "<mimic joint=\"j\"/>",
    "<collision/>",
    "<body name=\"b\">",
    "</body>",
    "<body>",
    "<joint name=\"j\"/>",
    "<freejoint name=\"f\"/>",
    "<inertial pos=\"0 0 0\" mass=\"1\" diaginertia=\"1 1 1\"/>",
    "fullinertia=\"1 1 1 0 0 0\"",
    "euler=\"90 0 0\"",
    "axisangle=\"0 0 0 1\"",
    "xyaxes=\"1 0 0 1 0 0\"",
    "zaxis=\"0 0 -1\"",
    "quat=\"0 0 0 0\"",
    "<default class=\"a\"><joint damping=\"1\"/></default>",
    "class=\"a\"",
    "childclass=\"nope\"",
    "<compiler angle=\"radian\" eulerseq=\"ZYX\"/>",
    "type=\"ball\"",
    "type=\"slide\"",
    "stiffness=\"1\"",
    "range=\"-1 1\"",
    "gravcomp=\"1\"",
    "<geom/>",
    "<tendon><fixed/></tendon>",
    "<include file=\"x\"/>",
];

#[derive(Clone, Debug)]
enum Edit {
    Delete(usize, usize),
    Insert(usize, usize),
    Byte(usize, u8),
    Duplicate(usize, usize),
}

fn edit(tokens: usize) -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), 1usize..40).prop_map(|(a, n)| Edit::Delete(a, n)),
        (any::<usize>(), 0..tokens).prop_map(|(a, k)| Edit::Insert(a, k)),
        (any::<usize>(), any::<u8>()).prop_map(|(a, b)| Edit::Byte(a, b)),
        (any::<usize>(), 1usize..200).prop_map(|(a, n)| Edit::Duplicate(a, n)),
    ]
}

fn apply(mut text: Vec<u8>, edits: &[Edit], tokens: &[&str]) -> Vec<u8> {
    for e in edits {
        let len = text.len().max(1);
        match *e {
            Edit::Delete(a, n) => {
                let a = a % len;
                let b = (a + n).min(text.len());
                if a < b {
                    text.drain(a..b);
                }
            }
            Edit::Insert(a, k) => {
                let a = (a % len).min(text.len());
                text.splice(a..a, tokens[k].bytes());
            }
            Edit::Byte(a, b) => {
                if !text.is_empty() {
                    text[a % len] = b;
                }
            }
            Edit::Duplicate(a, n) => {
                let a = (a % len).min(text.len());
                let b = (a + n).min(text.len());
                let piece = text[a..b].to_vec();
                text.splice(b..b, piece);
            }
        }
    }
    text
}

#[test]
fn mutated_scenes_load_or_fail_cleanly() {
    let seeds = seeds();
    let mut runner = TestRunner::new(Config {
        cases: 3000,
        failure_persistence: None,
        ..Config::default()
    });
    let strategy = (
        0..seeds.len(),
        prop::collection::vec(edit(TOKENS.len()), 1..6),
    );
    runner
        .run(&strategy, |(k, edits)| {
            progmo::fuzzing::scene(&apply(seeds[k].clone(), &edits, TOKENS));
            Ok(())
        })
        .unwrap();
}

/// Expressions from a small grammar (so most compile), plus raw strings.
fn expression() -> impl Strategy<Value = String> {
    let leaf = prop_oneof![
        Just("x".to_string()),
        Just("y".to_string()),
        Just("t".to_string()),
        Just("x'".to_string()),
        Just("tip.x".to_string()),
        Just("m".to_string()),
        Just("pi".to_string()),
        prop_oneof![
            Just(0.0),
            Just(-0.0),
            Just(1e308),
            Just(1e-308),
            Just(2.0),
            -10.0..10.0f64
        ]
        .prop_map(|v| format!("{v:e}")),
    ];
    leaf.prop_recursive(6, 64, 4, |inner| {
        prop_oneof![
            (inner.clone(), "[-+*/^]", inner.clone()).prop_map(|(a, o, b)| format!("{a} {o} {b}")),
            (
                "(sin|cos|tan|asin|acos|atan|exp|log|sqrt|abs|sinh|cosh|tanh)",
                inner.clone()
            )
                .prop_map(|(f, a)| format!("{f}({a})")),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| format!("atan2({a}, {b})")),
            inner.clone().prop_map(|a| format!("-({a})")),
            inner.prop_map(|a| format!("({a})")),
        ]
    })
}

#[test]
fn generated_expressions_compile_and_evaluate_or_fail_cleanly() {
    let mut runner = TestRunner::new(Config {
        cases: 3000,
        failure_persistence: None,
        ..Config::default()
    });
    let strategy = prop_oneof![
        3 => expression(),
        1 => ".{0,40}",
    ];
    runner
        .run(&strategy, |text| {
            progmo::fuzzing::expr(text.as_bytes());
            Ok(())
        })
        .unwrap();
}

/// Robot files of one format: the tests' good and bad files and the catalog's.
fn robot_seeds(kind: &str) -> Vec<Vec<u8>> {
    let (dirs, ext): (&[&str], &str) = if kind == "urdf" {
        (&["tests/robots", "tests/bad_scenes/files"], "urdf")
    } else {
        (&["tests/robots/mjcf", "references/scenes/robots"], "xml")
    };
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files: Vec<_> = dirs
        .iter()
        .flat_map(|d| std::fs::read_dir(root.join(d)).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == ext))
        .collect();
    files.sort();
    assert!(files.len() >= 8, "{kind} seeds: {files:?}");
    files.iter().map(|p| std::fs::read(p).unwrap()).collect()
}

/// Mutated robot files through the scene loader (`progmo::fuzzing::robot`): no panic, every error
/// located in the file, none quoting a file that is not XML.
fn mutated_robots(kind: &str) {
    let seeds = robot_seeds(kind);
    let mut runner = TestRunner::new(Config {
        cases: 1500,
        failure_persistence: None,
        ..Config::default()
    });
    let strategy = (
        0..seeds.len(),
        prop::collection::vec(edit(XML_TOKENS.len()), 1..6),
    );
    runner
        .run(&strategy, |(k, edits)| {
            progmo::fuzzing::robot(&apply(seeds[k].clone(), &edits, XML_TOKENS), kind);
            Ok(())
        })
        .unwrap();
}

#[test]
fn mutated_urdf_files_load_or_fail_located() {
    mutated_robots("urdf");
}

#[test]
fn mutated_mjcf_files_load_or_fail_located() {
    mutated_robots("mjcf");
}

/// Load `text` as the robot file of a scene (through the fuzz body's door) and return the error.
fn robot_error(text: &str, kind: &str) -> progmo::scene::SceneError {
    let dir = std::env::temp_dir().join(format!("progmo-fuzz-found-{}-{kind}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = format!("robot.{kind}");
    std::fs::write(dir.join(&file), text).unwrap();
    let scene = format!(
        "name = \"t\"\n[model]\nkind = \"{kind}\"\nfile = \"{file}\"\n[initial]\n[time]\nt1 = 1.0\n"
    );
    let Err(e) = progmo::scene::Scene::from_text(&dir.join("scene.toml"), &scene) else {
        panic!("a malformed robot file loaded")
    };
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(e.file.ends_with(&file), "{e}");
    e
}

/// Found by the bounded pass above (before the first fuzzer run): a malformed XML file with a
/// multi-byte character before the error on its line panicked (roxmltree's column counts
/// characters; it was added to the line's byte offset and sliced the text inside the character).
/// The error is now at roxmltree's line and column, on CRLF lines too.
#[test]
fn malformed_xml_after_a_multibyte_character_is_located() {
    for kind in ["urdf", "mjcf"] {
        let root = if kind == "urdf" { "robot" } else { "mujoco" };
        // the crashing inputs, shrunk by proptest: a BOM where an attribute value's quote belongs
        let e = robot_error(
            &format!("<{root}>\n  <link name=\u{feff}\"a\">\n</{root}>\n"),
            kind,
        );
        assert_eq!((e.line, e.column), (2, 14), "{e}");
        assert!(e.excerpt.contains('^'), "{e}");
        let e = robot_error(
            &format!("<!-- é -->\r\n<{root}>\r\n<é a=é/>\r\n</{root}>\r\n"),
            kind,
        );
        assert_eq!((e.line, e.column), (3, 6), "{e}");
        progmo::fuzzing::robot(
            format!("<!-- \u{feff} -->\n<{root}>\n  <link name=\u{feff}\"a\">\n  </{root}>\n")
                .as_bytes(),
            kind,
        );
    }
}
