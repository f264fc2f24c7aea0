//! Helpers shared by the integration tests (`mod common;`).

use std::path::PathBuf;

/// The `*.toml` files of a folder of the repository (e.g. `references/scenes`), sorted.
#[allow(dead_code)] // not every test file walks a folder
pub fn toml_files(dir: &str) -> Vec<PathBuf> {
    if dir.starts_with("references") {
        robot_path();
    }
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(dir);
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    v.sort();
    v
}

/// The robot scenes of the catalog (`model.kind = "urdf"`) read example-robot-data's URDFs through
/// `$PROGMO_ROBOT_PATH`; when it is unset, point it at the copy harness/setup.sh installs into
/// `.venv` (the Python package does the same for its own doors: `progmo.data.robot_path`).
pub fn robot_path() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("PROGMO_ROBOT_PATH").is_some() {
            return;
        }
        let lib = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(".venv/lib");
        let share = std::fs::read_dir(&lib)
            .into_iter()
            .flatten()
            .map(|e| e.unwrap().path().join("site-packages/cmeel.prefix/share"))
            .find(|p| p.join("example-robot-data").is_dir())
            .unwrap_or_else(|| {
                panic!("the robot scenes need example-robot-data: run `bash harness/setup.sh` (installs it into .venv) or set PROGMO_ROBOT_PATH")
            });
        // Set once, before any scene is loaded by this test process (and inherited by the CLI
        // processes it starts).
        std::env::set_var("PROGMO_ROBOT_PATH", share);
    });
}
