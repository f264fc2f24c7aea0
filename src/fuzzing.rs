//! Bodies of the fuzz targets (`fuzz/`, cargo-fuzz on nightly) and of the stable property test
//! (`tests/fuzz_props.rs`): one function per target, so both exercise the same code.
//!
//! Each takes arbitrary bytes and must return without panicking; the invariants it checks are
//! asserted (an assertion failure is a crash the fuzzer reports).

use crate::expr::{Expr, SymbolTable};
use crate::scene::{Scene, SceneError, SceneSystem};
use num_dual::{Dual2_64, Dual64};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Scene text -> load. A load error must be located inside the text and render without panicking;
/// a loaded scene's settings must pass [`crate::solve::validate`].
pub fn scene(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match Scene::from_text(Path::new("fuzz.toml"), text) {
        Ok(scene) => {
            let span = scene.span();
            if let Err(e) = crate::solve::validate(span, &scene.settings) {
                panic!("a loaded scene fails validation: {e}");
            }
        }
        Err(e) => {
            let lines = text.lines().count().max(1);
            assert!(e.line <= lines + 1, "line {} of {lines}", e.line);
            let _ = e.to_string();
        }
    }
}

/// Expression text -> compile -> evaluate over f64, first- and second-order dual numbers.
pub fn expr(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let mut table: SymbolTable = ["t", "x", "y", "x'", "tip.x", "r''"].into_iter().collect();
    table.define("m", 1.5);
    table.define("L", 0.25);
    let e = match Expr::compile(text, &table) {
        Ok(e) => e,
        Err(err) => {
            let _ = err.render("fuzz.toml", 1, 1);
            return;
        }
    };
    let _ = (e.slots(), e.time_order(), e.constant(), e.max_stack());
    for x in [[0.3, -1.25, 2.0, 0.7, -0.4, 1e-3], [0.0; 6]] {
        let _: f64 = e.value(&x);
        let _: Dual64 = e.value(&x.map(|s| Dual64::new(s, 1.0)));
        let _: Dual2_64 = e.value(&x.map(|s| Dual2_64::new(s, 1.0, 0.0)));
    }
}

/// URDF bytes -> the scene loader (`model.kind = "urdf"`): see [`robot`].
pub fn urdf(data: &[u8]) {
    robot(data, "urdf");
}

/// MJCF bytes -> the scene loader (`model.kind = "mjcf"`): see [`robot`].
pub fn mjcf(data: &[u8]) {
    robot(data, "mjcf");
}

/// This thread's folder for the robot file the fuzzed scene names (the loader reads files, so the
/// bytes go through the same door as a user's: [`crate::input::read`], [`crate::input::text`]).
fn fuzz_dir() -> PathBuf {
    thread_local! {
        static DIR: PathBuf = {
            static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
            let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            // memory-backed where there is one: rewriting a file on disk costs milliseconds
            let shm = Path::new("/dev/shm");
            let tmp = if shm.is_dir() { shm.to_path_buf() } else { std::env::temp_dir() };
            let d = tmp.join(format!("progmo-fuzz-{}-{k}", std::process::id()));
            std::fs::create_dir_all(&d).expect("a temporary folder");
            d
        };
    }
    DIR.with(|d| d.clone())
}

/// The scene that names the fuzzed robot file: no rows, so any robot the importer accepts loads.
fn robot_scene(kind: &str, file: &str) -> String {
    format!(
        "name = \"fuzz\"\n[model]\nkind = \"{kind}\"\nfile = \"{file}\"\ngravity = [0.0, 0.0, -9.81]\n[initial]\n[time]\nt1 = 1.0\n"
    )
}

/// A message with its digits removed (the part that does not depend on a position).
fn without_digits(s: &str) -> String {
    s.chars().filter(|c| !c.is_ascii_digit()).collect()
}

/// The messages of a robot file that is not XML (not text, or text that does not begin with
/// `<`), digits removed: obtained from the loader itself for one input of each kind.
fn not_xml_messages(kind: &str) -> &'static [String] {
    static URDF: OnceLock<Vec<String>> = OnceLock::new();
    static MJCF: OnceLock<Vec<String>> = OnceLock::new();
    let cell = if kind == "urdf" { &URDF } else { &MJCF };
    cell.get_or_init(|| {
        let inputs: [&[u8]; 4] = [b"\xff", b"\x00", b"\xff\xfe<", b"x"];
        inputs
            .iter()
            .map(|b| match load_robot(b, kind) {
                (Err(e), path) if e.file == path => without_digits(&e.message),
                _ => panic!("a non-XML robot file must be refused in it"),
            })
            .collect()
    })
}

/// Write `data` as this thread's robot file and load the scene naming it.
fn load_robot(data: &[u8], kind: &str) -> (Result<Scene, SceneError>, PathBuf) {
    let dir = fuzz_dir();
    let name = format!("robot.{kind}");
    let path = dir.join(&name);
    std::fs::write(&path, data).expect("write the robot file");
    let scene = Scene::from_text(&dir.join("scene.toml"), &robot_scene(kind, &name));
    (scene, path)
}

/// Robot file bytes -> the scene loader, the same door as a user's file (read with its size
/// limit, checked as text, imported, built into the tree model). Properties: no panic; a loaded
/// scene's settings validate and its model evaluates at q0; an error in the robot file is located
/// (line within the file, column >= 1, at most one quoted line); the error of a file that is not
/// XML (not text, or not beginning with `<`) quotes none of its bytes: no excerpt, and its message
/// is, up to the digits of its position, one of the loader's messages for such files.
pub fn robot(data: &[u8], kind: &str) {
    let templates = not_xml_messages(kind);
    let (scene, path) = load_robot(data, kind);
    match scene {
        Ok(scene) => {
            if let Err(e) = crate::solve::validate(scene.span(), &scene.settings) {
                panic!("a loaded scene fails validation: {e}");
            }
            if let SceneSystem::Tree(p) = &scene.system {
                use crate::model::Model;
                let n = p.model.nv();
                let mut ws = p.model.workspace::<f64>();
                let mut a = nalgebra::DMatrix::zeros(n, n);
                p.model.mass_matrix(&mut ws, &p.q0, &mut a);
                let mut g = vec![0.0; n];
                p.model.velocity_terms(&mut ws, &p.q0, &p.v0, &mut g);
            }
        }
        Err(e) => {
            let shown = e.to_string();
            if e.file != path {
                // the scene's own error (e.g. a joint named like a parameter): located in it
                assert!(e.line >= 1, "unlocated scene error: {shown}");
                return;
            }
            assert!(e.line >= 1 && e.column >= 1, "unlocated: {shown}");
            let text = std::str::from_utf8(data).ok();
            let lines = String::from_utf8_lossy(data).lines().count().max(1);
            assert!(e.line <= lines + 1, "line {} of {lines}: {shown}", e.line);
            assert!(
                e.excerpt.lines().count() <= 2
                    && e.excerpt
                        .lines()
                        .all(|l| l.chars().count() <= crate::input::QUOTE_WIDTH + 8),
                "more than one line quoted: {shown}"
            );
            let xml = text
                .is_some_and(|t| crate::input::quotable(t) && crate::input::xml_start(t).is_none());
            if !xml {
                assert!(e.excerpt.is_empty(), "a non-XML file quoted: {shown}");
                assert!(
                    templates.contains(&without_digits(&e.message)),
                    "a non-XML file's message is not one of the loader's: {shown}"
                );
            }
        }
    }
}
