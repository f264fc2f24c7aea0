//! Robot description files -> the tree model's body specifications ([`crate::tree::BodySpec`]),
//! the same structure a tree scene builds from `[[model.bodies]]`.
//!
//! - [`urdf`]: URDF (ROS) files: links, inertials, revolute / continuous / prismatic / fixed /
//!   floating joints; visuals, collisions and meshes are not read.
//! - [`resolve`]: where `package://PKG/...` paths are found (`$PROGMO_ROBOT_PATH`, then
//!   `$ROS_PACKAGE_PATH`).
//!
//! Errors are [`SceneError`](crate::scene::SceneError)s located in the description file (file,
//! line, column, element).

pub mod urdf;

use std::path::{Path, PathBuf};

/// Environment variable: search path (`:`-separated directories) for `package://PKG/rest`: the
/// first `DIR/PKG/rest` that exists. The Python package fills it (when unset) with the
/// `share` directory of an installed `example-robot-data`.
pub const ROBOT_PATH_VAR: &str = "PROGMO_ROBOT_PATH";

/// The file a model's `file` names: `package://PKG/rest` through [`ROBOT_PATH_VAR`] (then
/// `ROS_PACKAGE_PATH`), otherwise a path relative to the scene file's directory.
pub fn resolve(file: &str, scene_dir: &Path) -> Result<PathBuf, String> {
    if let Some(rest) = file.strip_prefix("package://") {
        let mut roots = vec![];
        for var in [ROBOT_PATH_VAR, "ROS_PACKAGE_PATH"] {
            if let Ok(v) = std::env::var(var) {
                roots.extend(v.split(':').filter(|s| !s.is_empty()).map(PathBuf::from));
            }
        }
        for r in &roots {
            let p = r.join(rest);
            if p.is_file() {
                return Ok(p);
            }
        }
        let pkg = rest.split('/').next().unwrap_or(rest);
        return Err(format!(
            "`{file}` not found: package `{pkg}` is looked up in ${ROBOT_PATH_VAR} and \
             $ROS_PACKAGE_PATH ({}); for example-robot-data, `pip install example-robot-data` \
             (the Python `progmo` then finds it) or set {ROBOT_PATH_VAR} to its `share` directory",
            if roots.is_empty() {
                "both unset".to_string()
            } else {
                format!("searched {}", roots.len())
            }
        ));
    }
    let p = scene_dir.join(file);
    if p.is_file() {
        Ok(p)
    } else {
        Err(format!(
            "`{}` not found (relative to the scene file)",
            p.display()
        ))
    }
}
