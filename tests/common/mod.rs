//! Helpers shared by the integration tests (`crate::common`, declared in tests/integration.rs).

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
    progmo::import::ensure_robot_path_for_tests();
}
