//! What a robot file may hold that progmo reads and does not model: a closed vocabulary of kinds
//! ([`KINDS`]), one [`Unmodelled`] record per element found (kind, element, file, line), and the
//! joint ranges the file states ([`JointRange`]).
//!
//! A scene declares the kinds it ignores, with a reason (`[model] ignore = { kind = "reason" }`,
//! checked against [`KINDS`] at load); `Scene::robot` carries every record with its declaration,
//! and the check (Python harness) reports an undeclared one as not checked. Anything of the file
//! that changes the dynamics and is neither modelled nor in this vocabulary is refused at import
//! with a located error (src/scene/FORMAT.md, "Robot files", lists every element and attribute).

use serde::Serialize;
use std::path::PathBuf;

/// The closed vocabulary: kind name and what it covers (FORMAT.md's tables use these names;
/// `tests/schema.rs` keeps them in step).
pub const KINDS: &[(&str, &str)] = &[
    (
        "joint_limit",
        "joint position limits: MJCF joint `range` (limited), URDF `<limit lower upper>` of \
         revolute and prismatic joints and `<safety_controller>`",
    ),
    (
        "effort_limit",
        "joint force limits: MJCF joint `actuatorfrcrange`, URDF `<limit effort>`",
    ),
    (
        "velocity_limit",
        "joint velocity limits: URDF `<limit velocity>`",
    ),
    (
        "frictionloss",
        "dry joint friction: MJCF joint `frictionloss`, URDF `<dynamics friction>`",
    ),
    (
        "tendon",
        "MJCF `<tendon>` elements (fixed and spatial tendons, their springs, dampers, limits)",
    ),
    ("equality", "MJCF `<equality>` constraints"),
    (
        "contact",
        "collisions: MJCF geoms of moving bodies that can collide (contype or conaffinity \
         nonzero), `<contact>` pairs and excludes; URDF `<collision>`",
    ),
    (
        "actuator",
        "actuator models: MJCF `<actuator>` elements (gains, biases, dynamics, ranges), URDF \
         `<transmission>`",
    ),
    (
        "mimic",
        "URDF `<mimic>`: a joint that follows another (modelled as a system row unless declared \
         ignored: the joints are then independent)",
    ),
    (
        "fluid",
        "fluid forces: MJCF `<option>` density, viscosity or wind nonzero",
    ),
];

/// Whether `kind` is in [`KINDS`].
pub fn is_kind(kind: &str) -> bool {
    KINDS.iter().any(|(k, _)| *k == kind)
}

/// The kind of [`KINDS`] nearest to `name` (edit distance), for "did you mean" messages.
pub fn nearest_kind(name: &str) -> &'static str {
    KINDS
        .iter()
        .map(|(k, _)| (edit_distance(name, k), *k))
        .min()
        .map(|(_, k)| k)
        .unwrap_or("joint_limit")
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// One element of a robot file that is read and not modelled.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Unmodelled {
    /// A kind of [`KINDS`].
    pub kind: &'static str,
    /// The element, e.g. `joint[elbow].frictionloss`, `tendon[t1]`, `link[hand].collision`.
    pub element: String,
    /// The robot file (absolute) and the element's line (1-based).
    pub file: PathBuf,
    pub line: usize,
}

impl Unmodelled {
    /// `file:line`.
    pub fn location(&self) -> String {
        format!("{}:{}", self.file.display(), self.line)
    }
}

/// Position limits of a hinge or slide joint as the file states them, in q's units (radians for
/// hinges: an MJCF range in degrees is converted as MuJoCo does).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct JointRange {
    pub joint: String,
    pub lower: f64,
    pub upper: f64,
}

/// Collects records while a file is read.
pub(crate) struct Recorder<'s> {
    pub src: &'s crate::located::Source,
    pub file: PathBuf,
    pub out: Vec<Unmodelled>,
}

impl<'s> Recorder<'s> {
    pub fn new(src: &'s crate::located::Source) -> Self {
        let file = std::path::absolute(&src.file).unwrap_or_else(|_| src.file.clone());
        Recorder {
            src,
            file,
            out: vec![],
        }
    }

    /// Record `element` of kind `kind` found at `node`.
    pub fn push(&mut self, kind: &'static str, element: String, node: roxmltree::Node) {
        debug_assert!(is_kind(kind), "{kind} is not in KINDS");
        let at = node.range().start;
        let (line, _) = self.src.line_col(at);
        let from = self.src.file_at(at); // an MJCF <include>d file, or the file itself
        let file = if from == self.src.file {
            self.file.clone()
        } else {
            std::path::absolute(from).unwrap_or_else(|_| from.to_path_buf())
        };
        self.out.push(Unmodelled {
            kind,
            element,
            file,
            line,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_kind_names_the_closest() {
        assert_eq!(nearest_kind("frictionlos"), "frictionloss");
        assert_eq!(nearest_kind("joint_limits"), "joint_limit");
        assert_eq!(nearest_kind("tendons"), "tendon");
        assert!(is_kind("contact") && !is_kind("contacts"));
    }
}
