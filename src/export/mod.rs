//! Export of kinematic trees ([`crate::tree::Model`]) to MJCF (MuJoCo 4.0) and URDF (Pinocchio 4.1),
//! so that the simulators replaying our control forces see exactly the same system.
//!
//! Both exporters return the document and an [`ExportReport`]: what had to be changed (MuJoCo's
//! minimum mass/inertia), forces the harness must apply itself (attractors; springs and dampers in
//! URDF), and the map from our q/v entries to the simulator's qpos/dof entries.
//!
//! Policies (facts measured in `shared/notes/simulators.md`):
//! - **Mass floor (MJCF only).** MuJoCo rejects a moving body (one with joints) whose mass or any
//!   principal moment of inertia is below `mjMINVAL` = 1e-15. Such a body gets
//!   `mass = max(mass, min_mass)` and, when its smallest principal moment is below `min_inertia`,
//!   `I + min_inertia * 1` (every principal moment rises by `min_inertia`, so the triangle
//!   inequality still holds). Default 1e-14. The change of the mass matrix is
//!   `dM = dm Jc^T Jc + Jw^T dI Jw` (Jc: CoM Jacobian, Jw: angular Jacobian, |Jw| <= 1), reported per
//!   body in [`MassChange`]. Joint-less bodies are welded and are not changed.
//! - **URDF chains.** URDF has one joint per link: a body with n joints becomes n links, the first
//!   n - 1 massless (`{body}__{joint}`), the last named after the body and carrying its inertia. A
//!   joint-less body is attached by a fixed joint `{body}__fixed`. Link frames sit at the anchor of
//!   the body's last hinge/ball joint (URDF rotates about the joint frame origin).
//! - **Ball joints in URDF.** URDF has no spherical joint. A ball joint that is the first joint of
//!   the only child of the world, with its centre at the world origin and the body unrotated, is
//!   exported as the URDF root: the harness must pass `pin.JointModelSpherical()` as root joint
//!   (see [`ExportReport::root_joint`]). Any other ball joint is [`ExportError::Unsupported`].
//! - **Free joints in URDF** become `floating` joints (Pinocchio: `JointModelFreeFlyer`); Pinocchio's
//!   linear velocity is body-frame, ours (and MuJoCo's) world-frame: see [`Conversion`].
//! - **Gravity in URDF** is not part of the format: the harness sets `model.gravity.linear` to
//!   [`ExportReport::gravity`].
//! - **Attractors** have no element in either format: they are listed in
//!   [`ExportReport::harness_forces`] with their formula.
//! - **Armature, gravity compensation, reference positions.** MJCF carries them (joint
//!   `armature`, body `gravcomp`, hinge/slide `ref`, with our meaning). URDF has none of them:
//!   armature goes to [`ExportReport::armature`] (the harness sets Pinocchio's `model.armature`),
//!   gravity compensation to a [`HarnessForce::Gravcomp`], and a reference position is folded
//!   into the joint's `<origin>` (a hinge turning by `q - ref` about its axis is the origin
//!   rotated by `-ref` about that axis followed by a turn by `q`; a slide, the origin moved by
//!   `-ref` along the axis), so the simulator coordinate is q itself.
//!
//! Parity check: `tests/python/test_export_parity.py` loads both documents of every bundled tree
//! scene in MuJoCo and Pinocchio (through the harness back-ends and the reports' q/v maps) and
//! compares M(q) and every force term with ours at random states, with a negative control.
//!
//! ```
//! use progmo::export::{mjcf, urdf, ExportOptions};
//! use progmo::tree::{BodySpec, Fields, JointSpec, Model, WORLD};
//! let b = BodySpec::point_mass("bob", WORLD, 1.0, [0.0, 0.0, -1.0])
//!     .joint(JointSpec::hinge("swing", [0.0, 1.0, 0.0]));
//! let m = Model::new(&[b], Fields { gravity: [0.0, 0.0, -9.81], attractors: vec![] }).unwrap();
//! let (xml, report) = mjcf(&m, &ExportOptions::default()).unwrap();
//! assert!(xml.contains("<joint name=\"swing\" type=\"hinge\""));
//! assert_eq!(report.mass_changes[0].body, "bob"); // point mass: inertia raised to 1e-14
//! let (_urdf, report) = urdf(&m, &ExportOptions::default()).unwrap();
//! assert_eq!(report.gravity, [0.0, 0.0, -9.81]); // the harness sets model.gravity
//! ```
//!
//! Measured on the bundled tree scenes: max |dM| <= 1.0e-14 (the inertia floor of point masses)
//! and max |dbias| <= 5e-15 in MuJoCo; <= 2e-16 / 2e-15 in Pinocchio. On a 13-dof test tree with
//! branches, anchors, a free body, springs and dampers: MuJoCo 3e-14 / 8e-14, Pinocchio 4e-15 /
//! 2e-14; MuJoCo's `qfrc_passive` equals our springs + dampers exactly, and attractor forces built
//! from MuJoCo's state by the report's formula agree to 4e-15.

mod mjcf;
mod urdf;

#[cfg(test)]
mod tests;

pub use mjcf::{mjcf, mjcf_closed};
pub use urdf::{urdf, urdf_closed, UrdfReport};

use crate::tree::{Body, Model};
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

/// Options of both exporters.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportOptions {
    /// Model / robot name.
    pub name: String,
    /// MJCF `<option timestep>`.
    pub timestep: f64,
    /// MJCF mass floor for moving bodies (must exceed MuJoCo's mjMINVAL = 1e-15).
    pub min_mass: f64,
    /// MJCF floor of the smallest principal moment of inertia of moving bodies (> 1e-15).
    pub min_inertia: f64,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            name: "progmo".into(),
            timestep: 1e-3,
            min_mass: 1e-14,
            min_inertia: 1e-14,
        }
    }
}

/// Export failure.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExportError {
    /// The model uses something the target format cannot express.
    #[error("{format}: unsupported: {what}")]
    Unsupported { format: Format, what: String },
    /// Invalid [`ExportOptions`].
    #[error("invalid export options: {0}")]
    Options(String),
    /// A generated name (e.g. `{body}__{joint}`) collides with another name.
    #[error("{format}: name collision: '{name}'")]
    NameCollision { format: Format, name: String },
}

/// Target format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Mjcf,
    Urdf,
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Format::Mjcf => "MJCF",
            Format::Urdf => "URDF",
        })
    }
}

/// What an export changed, what the harness must add, and how coordinates correspond.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExportReport {
    pub format: Format,
    /// Mass/inertia raised to the simulator's minimum (MJCF only).
    pub mass_changes: Vec<MassChange>,
    /// Forces not expressible in the format: the harness applies them from the simulator's state.
    pub harness_forces: Vec<HarnessForce>,
    /// One entry per our q index: where it lives in the simulator's qpos.
    pub q_map: Vec<CoordMap>,
    /// One entry per our v index: where it lives in the simulator's qvel / dof vector.
    pub v_map: Vec<CoordMap>,
    /// Uniform gravity (world frame). Written into MJCF; the harness must set it for URDF.
    pub gravity: [f64; 3],
    /// URDF only: root joint the harness must pass to `pin.buildModelFromUrdf(path, root_joint,
    /// root_joint_name)`, as a Python expression, with its name; `None`: no root joint.
    pub root_joint: Option<RootJoint>,
    /// Free-text notes on conventions the harness must respect.
    pub notes: Vec<String>,
    /// Loop closures of the scene and how the document carries them (see [`ClosureExport`]).
    #[serde(default)]
    pub closures: Vec<ClosureExport>,
    /// URDF only: joint armature (URDF has no element for it; Pinocchio 4.1's `buildModelFromUrdf`
    /// leaves `model.armature` at 0 and its `crba`, `rnea` and `aba` add `model.armature` to the
    /// mass matrix diagonal): the harness sets `model.armature[sim_v..sim_v + nv] = armature`.
    /// MJCF carries it as the joints' `armature`. Absent from the JSON when empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub armature: Vec<ArmatureExport>,
}

/// Armature of one joint the harness must set on the simulator model (URDF only).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArmatureExport {
    pub joint: String,
    pub armature: f64,
    /// First simulator dof of the joint and its dof count.
    pub sim_v: usize,
    pub nv: usize,
}

/// MuJoCo equality softness of exported closures (measured in `MUJOCO_CLOSURES.md`): solref
/// timeconst = this many steps of `<option timestep>` (dampratio 1); the harness keeps the ratio
/// when it replays at another step.
pub const MUJOCO_SOLREF_STEPS: f64 = 4.0;
/// Deepest indentation (levels) of a written document: nesting goes on, the indentation stops
/// growing, so a chain of n bodies writes O(n) bytes, not O(n^2).
pub const MAX_INDENT: usize = 32;

/// MuJoCo equality solimp of exported closures (near-rigid; the measured best).
pub const MUJOCO_SOLIMP: [f64; 3] = [0.9999, 0.9999, 0.001];

/// A loop closure (`[[model.closures]]`) as the exported document carries it, and the report's
/// entry. MJCF: sites `site_a`/`site_b` (body frames as ours) joined by `<equality>` `connect`
/// (point) or `weld` (weld), softness [`MUJOCO_SOLREF_STEPS`], [`MUJOCO_SOLIMP`]; a distance is
/// refused (MuJoCo's fixed-length tendon equality is not exact: `MUJOCO_CLOSURES.md`), and so are
/// a point on a line or in a plane (no such equality in MuJoCo, no such constraint model in
/// Pinocchio 4.1). URDF has no closures: each
/// body-side site is a massless link on a fixed joint (a Pinocchio frame), and the harness builds
/// `pin.RigidConstraintModel`s (CONTACT_3D / CONTACT_6D) between the frames; a world side
/// (`body_b = None`) is the world point `point_b` / orientation `quat_b`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClosureExport {
    pub name: String,
    /// `point`, `weld`, `distance`, `line` or `plane`.
    pub kind: String,
    pub body_a: String,
    /// Body-frame point and frame orientation (w, x, y, z) of side a.
    pub point_a: [f64; 3],
    pub quat_a: [f64; 4],
    /// None: the world.
    pub body_b: Option<String>,
    pub point_b: [f64; 3],
    pub quat_b: [f64; 4],
    pub distance: Option<f64>,
    /// `line` direction / `plane` normal, unit, in body_b's frame (world: world frame).
    #[serde(default)]
    pub axis: Option<[f64; 3]>,
    /// Site (MJCF) / frame (URDF link) names of the two sides; `site_b` is absent from a URDF
    /// without a world link.
    pub site_a: String,
    pub site_b: String,
    /// The scene's rows of this closure, in order (world-frame x, y, z [, rx, ry, rz]; one row
    /// for a distance); `set_aside` lists those the solver set aside as dependent at t0.
    pub rows: Vec<String>,
    pub set_aside: Vec<String>,
}

/// Root joint required by a URDF export.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RootJoint {
    /// Python expression, e.g. `pin.JointModelSpherical()`.
    pub python: String,
    /// Name to give it (our joint name).
    pub name: String,
}

/// A body whose mass properties were raised (MJCF mass floor).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MassChange {
    pub body: String,
    pub old_mass: f64,
    pub new_mass: f64,
    /// Inertia about the CoM, body frame.
    pub old_inertia: [[f64; 3]; 3],
    pub new_inertia: [[f64; 3]; 3],
    /// `new_mass - old_mass`.
    pub delta_mass: f64,
    /// Largest eigenvalue of `new_inertia - old_inertia`.
    pub delta_inertia: f64,
}

/// A force the harness must apply itself.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum HarnessForce {
    /// Newtonian attraction of every listed body's CoM to `point`: world-frame force
    /// `-mu m r / |r|^3`, `r = com_world - point`, applied at the CoM.
    Attractor {
        point: [f64; 3],
        mu: f64,
        /// Bodies with their (original, unfloored) masses.
        bodies: Vec<(String, f64)>,
        formula: String,
    },
    /// Gravity compensation of a body (URDF only; MJCF carries it as the body's `gravcomp`):
    /// world-frame force `-gravcomp m g` at the body's CoM (`g` the report's gravity, `m` the
    /// body's unfloored mass), applied like an attractor's force.
    Gravcomp {
        body: String,
        gravcomp: f64,
        mass: f64,
        formula: String,
    },
    /// Joint spring `-k (q - spring_ref)` on the simulator coordinate `sim_q` (URDF only).
    Spring {
        joint: String,
        stiffness: f64,
        spring_ref: f64,
        sim_q: usize,
        sim_v: usize,
    },
    /// Joint damper `-d v` on each simulator dof `sim_v..sim_v + nv` (URDF only). For a free
    /// joint our linear damping acts on the world-frame velocity.
    Damper {
        joint: String,
        damping: f64,
        sim_v: usize,
        nv: usize,
    },
    /// A scene force given as world-frame components (expressions) at a body point. At every
    /// stage the harness evaluates it from the simulator's state (`Scene.expression_forces`, entry
    /// `index`) and applies it through the simulator's own point-force input (MuJoCo
    /// `xfrc_applied`, Pinocchio's external forces), so the simulator maps it to its dofs.
    PointForce {
        index: usize,
        body: String,
        /// Body-frame point (m).
        point: [f64; 3],
        force: [String; 3],
    },
    /// A scene generalized force on our velocity coordinate `v_name` (expression). The harness
    /// evaluates it (`Scene.expression_forces`) and maps it to the simulator's dofs.
    CoordinateForce { v_name: String, expr: String },
    /// The generalized reaction B_s^T lambda_s of system rows the document leaves out because no
    /// simulator holds them (`Scene::export_supplying`), computed by progmo: the harness takes
    /// lambda_s of these rows from the solver's reference at each stage time and applies the
    /// force on our velocity coordinates, like u (open loop). The rows' residual on the replay is
    /// then a measurement, not a constraint of the simulator.
    SuppliedReaction {
        /// The rows (scene row names, role system).
        rows: Vec<String>,
        /// Why no simulator holds them (one clause per closure or group of rows).
        reason: String,
    },
}

/// Correspondence of one of our q or v entries with a simulator entry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CoordMap {
    /// Our index.
    pub index: usize,
    /// Our name (`Model::q_names` / `v_names`).
    pub name: String,
    /// Index in the simulator's qpos (q map) or dof vector (v map).
    pub sim_index: usize,
    /// Simulator joint name.
    pub sim_joint: String,
    pub conversion: Conversion,
}

/// How a simulator entry relates to ours.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Conversion {
    /// Same value.
    Same,
    /// Component of a free joint's linear velocity: the three simulator entries are `R^T v`, with
    /// `v` our three (world-frame) entries and `R` the body orientation from our quaternion
    /// (Pinocchio's `JointModelFreeFlyer` uses the local frame). Forces transform the same way.
    /// With `v_sim = P(q) v`: `M = P^T M_sim P`, `bias = P^T (bias_sim + M_sim (dP/dt) v)`,
    /// `(dP/dt) v = -w x (R^T v_lin)` (w: body angular velocity).
    BodyFrame,
}

/// Escape a string for an XML attribute value.
pub(crate) fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&apos;"),
            _ => o.push(c),
        }
    }
    o
}

/// Shortest round-trip decimal representation (Rust `Debug`), e.g. `1.0`, `1e-14`.
pub(crate) fn num(x: f64) -> String {
    format!("{x:?}")
}

pub(crate) fn nums(x: &[f64]) -> String {
    x.iter().map(|v| num(*v)).collect::<Vec<_>>().join(" ")
}

fn check_options(o: &ExportOptions) -> Result<(), ExportError> {
    let bad = |m: &str| Err(ExportError::Options(m.into()));
    if !(o.timestep.is_finite() && o.timestep > 0.0) {
        return bad("timestep must be positive");
    }
    // mjMINVAL = 1e-15: MuJoCo rejects values below it.
    if !(o.min_mass.is_finite() && o.min_mass > 1e-15) {
        return bad("min_mass must exceed 1e-15 (MuJoCo mjMINVAL)");
    }
    if !(o.min_inertia.is_finite() && o.min_inertia > 1e-15) {
        return bad("min_inertia must exceed 1e-15 (MuJoCo mjMINVAL)");
    }
    Ok(())
}

fn to_rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [
        [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
        [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
        [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
    ]
}

/// Mass floor of one body (see the module policy). Returns the mass, the inertia and the change.
pub(crate) fn floored(body: &Body, o: &ExportOptions) -> (f64, Matrix3<f64>, Option<MassChange>) {
    let moving = !body.joints.is_empty();
    let mut mass = body.mass;
    let mut inertia = body.inertia;
    if moving {
        if mass < o.min_mass {
            mass = o.min_mass;
        }
        let lo = inertia.symmetric_eigenvalues().min();
        if lo < o.min_inertia {
            inertia += Matrix3::identity() * o.min_inertia;
        }
    }
    let change = (mass != body.mass || inertia != body.inertia).then(|| MassChange {
        body: body.name.clone(),
        old_mass: body.mass,
        new_mass: mass,
        old_inertia: to_rows(&body.inertia),
        new_inertia: to_rows(&inertia),
        delta_mass: mass - body.mass,
        delta_inertia: (inertia - body.inertia).symmetric_eigenvalues().max(),
    });
    (mass, inertia, change)
}

/// Attractors as harness forces (no MJCF/URDF element exists for them).
pub(crate) fn attractor_forces(tree: &Model) -> Vec<HarnessForce> {
    let bodies: Vec<(String, f64)> = tree
        .bodies()
        .iter()
        .filter(|b| b.mass > 0.0)
        .map(|b| (b.name.clone(), b.mass))
        .collect();
    tree.fields()
        .attractors
        .iter()
        .map(|a| HarnessForce::Attractor {
            point: a.point,
            mu: a.mu,
            bodies: bodies.clone(),
            formula:
                "world-frame force f = -mu m r / |r|^3 at each body's CoM, r = com_world - point \
                      (com_world from the simulator's own state: MuJoCo d.xipos, Pinocchio \
                      data.oMi * com); generalized force J_com^T f"
                    .into(),
        })
        .collect()
}

/// Gravity compensation as harness forces (URDF has no element for it).
pub(crate) fn gravcomp_forces(tree: &Model) -> Vec<HarnessForce> {
    tree.bodies()
        .iter()
        .filter(|b| b.gravcomp != 0.0 && !b.massless)
        .map(|b| HarnessForce::Gravcomp {
            body: b.name.clone(),
            gravcomp: b.gravcomp,
            mass: b.mass,
            formula: "world-frame force f = -gravcomp m g at the body's CoM (g: the report's \
                      gravity; com_world from the simulator's state: MuJoCo d.xipos, Pinocchio \
                      data.oMi * com); generalized force J_com^T f"
                .into(),
        })
        .collect()
}

/// Children of each body (and of the world, index `n`) in our body order.
pub(crate) fn children(tree: &Model) -> Vec<Vec<usize>> {
    let n = tree.bodies().len();
    let mut ch = vec![Vec::new(); n + 1];
    for (i, b) in tree.bodies().iter().enumerate() {
        ch[b.parent.unwrap_or(n)].push(i);
    }
    ch
}
