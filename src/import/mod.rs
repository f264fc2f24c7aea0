//! Robot description files -> the tree model's body specifications ([`crate::tree::BodySpec`]),
//! the same structure a tree scene builds from `[[model.bodies]]`.
//!
//! - [`urdf`]: URDF (ROS) files: links, inertials, revolute / continuous / prismatic / fixed /
//!   floating joints, joint damping; visuals and meshes are not read.
//! - [`mjcf`]: MuJoCo MJCF files: bodies, inertials (explicit or from primitive geoms, as MuJoCo
//!   computes them: `geom_inertia`), hinge / slide / ball / free joints
//!   with damping, armature, springs and `ref`, body `gravcomp`, joint defaults, mesh geoms
//!   weighed as MuJoCo weighs them ([`mesh`]); `<include>`d files are expanded first ([`include`]).
//! - [`unmodelled`]: what either file holds that is read and not modelled (limits, friction,
//!   tendons, contacts, actuators, ...): a closed vocabulary of kinds, one record per element.
//! - [`resolve`]: where `package://PKG/...` paths are found (`$PROGMO_ROBOT_PATH`, then
//!   `$ROS_PACKAGE_PATH`) and the folders a scene may read ([`crate::input`]).
//!
//! Errors are [`SceneError`](crate::located::SceneError)s located in the description file (file,
//! line, column, element).

mod geom_inertia;
mod hull;
pub mod include;
mod mesh;
pub mod mjcf;
pub mod unmodelled;
pub mod urdf;

use nalgebra::Matrix3;
use std::path::{Path, PathBuf};

pub use crate::input::ROBOT_PATH_VAR;

/// The file a model's `file` names: `package://PKG/rest` through [`ROBOT_PATH_VAR`] (then
/// `ROS_PACKAGE_PATH`), otherwise a path relative to the scene file's directory; refused outside
/// the folders a scene may read ([`crate::input::resolve`]).
pub fn resolve(file: &str, scene_dir: &Path) -> Result<PathBuf, String> {
    crate::input::resolve(file, scene_dir)
}

/// Why a robot file's joint name cannot name a coordinate in rows, or None. Any name works,
/// written in backquotes when it is not an identifier (`` `joint_8.0`' ``, see [`crate::expr`]),
/// but for a backquote, an apostrophe (it would read as a time derivative), a line break, and `t`
/// and `pi` (time and the constant).
pub(crate) fn unusable_name(name: &str) -> Option<&'static str> {
    if name.trim().is_empty() {
        Some("is blank: a joint's name names its coordinate in rows")
    } else if name.contains(['`', '\'', '\n', '\r']) {
        Some("holds a backquote, an apostrophe or a line break: it cannot be written in rows (the apostrophe marks a time derivative)")
    } else if name == "t" || name == "pi" {
        Some("is reserved in rows (`t` is time, `pi` the constant)")
    } else {
        None
    }
}

/// Test support: example-robot-data's `share` folder inside this checkout's `.venv` (what
/// harness/setup.sh installs), for tests run without `$PROGMO_ROBOT_PATH`.
#[doc(hidden)]
pub fn checkout_robot_path() -> Option<std::path::PathBuf> {
    let lib = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/lib");
    std::fs::read_dir(lib)
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("site-packages/cmeel.prefix/share"))
        .find(|p| p.join("example-robot-data").is_dir())
}

/// Test support: set `$PROGMO_ROBOT_PATH` to [`checkout_robot_path`] when it is unset (once per
/// process, before any scene is loaded; inherited by the processes the test starts).
#[doc(hidden)]
pub fn ensure_robot_path_for_tests() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        if std::env::var_os("PROGMO_ROBOT_PATH").is_some() {
            return;
        }
        let share = checkout_robot_path().unwrap_or_else(|| {
            panic!("the robot scenes need example-robot-data: run `bash harness/setup.sh` (installs it into .venv) or set PROGMO_ROBOT_PATH")
        });
        std::env::set_var("PROGMO_ROBOT_PATH", share);
    });
}

/// An inertia tensor given in a rotated frame, in the body frame: R I R^T, made exactly
/// symmetric (the product is symmetric only up to round-off, and the tree model and the
/// exporters read the upper triangle).
pub(crate) fn rotate_inertia(r: &Matrix3<f64>, local: &Matrix3<f64>) -> [[f64; 3]; 3] {
    let m = r * local * r.transpose();
    [0, 1, 2].map(|a| [0, 1, 2].map(|b| 0.5 * (m[(a, b)] + m[(b, a)])))
}

fn options_limit() -> usize {
    3 * crate::input::MAX_XML_ELEMENTS + 16
}

/// Parse a robot description file as XML; a malformed document is a located error (the parser's
/// row and column turned into a byte offset of `src`).
pub(crate) fn parse_xml(
    src: &crate::located::Source,
) -> Result<roxmltree::Document<'_>, crate::located::SceneError> {
    // a file that does not begin as XML is not one: located, never quoted (it may be anything)
    if let Some((line, column)) = crate::input::xml_start(&src.text) {
        return Err(crate::located::SceneError {
            file: src.file.clone(),
            line,
            column,
            field: "xml".into(),
            message: format!(
                "not an XML document: it does not begin with `<` (line {line}, column {column})"
            ),
            excerpt: String::new(),
        });
    }
    // bounded before the parser allocates: located, never quoted (the file did not parse)
    let unquoted = |offset: usize, message: String| {
        let (line, column) = src.line_col(offset);
        crate::located::SceneError {
            file: src.file.clone(),
            line,
            column,
            field: "xml".into(),
            message,
            excerpt: String::new(),
        }
    };
    crate::input::xml_limits(&src.text).map_err(|(at, m)| unquoted(at, m))?;
    let options = roxmltree::ParsingOptions {
        // a backstop: text nodes lie between tags, so at most about twice the elements
        nodes_limit: options_limit() as u32,
        ..Default::default()
    };
    roxmltree::Document::parse_with_options(&src.text, options).map_err(|e| {
        if let roxmltree::Error::NodesLimitReached = e {
            return unquoted(
                0,
                format!(
                    "more than {} XML nodes (elements, text, comments): the limit for a robot file",
                    options_limit()
                ),
            );
        }
        // roxmltree counts rows by '\n' and columns in characters: back to a byte offset (the
        // start of that character; a multi-byte character or a CR before it moves no byte)
        let p = e.pos();
        let text = &src.text;
        let line_start: usize = text
            .split_inclusive('\n')
            .take((p.row as usize).saturating_sub(1))
            .map(str::len)
            .sum();
        let offset = text[line_start..]
            .char_indices()
            .nth((p.col as usize).saturating_sub(1))
            .map_or(text.len(), |(i, _)| line_start + i);
        let end = text[offset..]
            .chars()
            .next()
            .map_or(offset, |c| offset + c.len_utf8());
        src.error(offset..end, "xml", format!("not well-formed XML: {e}"))
    })
}
