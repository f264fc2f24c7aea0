//! The scene file as written (TOML), before validation: the one source of truth of the format.
//! The JSON Schema `scene.schema.json` is generated from these types ([`super::schema`]; doc
//! comments become its descriptions) and `FORMAT.md` is checked against it (`tests/schema.rs`).

use super::schema::{self, Expression, Identifier};
use crate::solve;
use schemars::JsonSchema;
use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::fmt;
use toml::Spanned;

/// Model kinds (`model.kind`).
pub const MODEL_KINDS: [&str; 4] = ["lagrangian", "tree", "urdf", "mjcf"];
/// Keys of `[model]` only an imported (urdf or mjcf) model has (mjcf: not root_joint).
pub const URDF_ONLY: [&str; 5] = ["file", "root_joint", "frames", "locked_joints", "ignore"];
/// Root joints of a urdf model (`model.root_joint`).
pub const ROOT_JOINTS: [&str; 2] = ["fixed", "free"];
/// Keys of `[model]` only a lagrangian model has.
pub const LAGRANGIAN_ONLY: [&str; 4] = ["coordinates", "mass_matrix", "mass_diagonal", "potential"];
/// Keys of `[model]` only a tree model has.
pub const TREE_ONLY: [&str; 6] = [
    "bodies",
    "sites",
    "gravity",
    "attractors",
    "point_forces",
    "closures",
];
/// Loop-closure kinds (`kind` of a `[[model.closures]]` entry).
pub const CLOSURE_KINDS: [&str; 6] = ["point", "weld", "distance", "line", "plane", "rolling"];
/// Joint types (`type` of a joint).
pub const JOINT_TYPES: [&str; 4] = ["hinge", "slide", "ball", "free"];
/// Joint types that need an `axis`.
pub const JOINTS_WITH_AXIS: [&str; 2] = ["hinge", "slide"];
/// Simulators of the cross-simulator check (keys of `[checks] not_checked`).
pub use crate::check::SIMULATORS;

/// A number or an expression of parameters ("2*pi", "sqrt(mu/r0)").
#[derive(Clone, Debug, JsonSchema)]
#[serde(untagged)]
#[schemars(rename = "number_or_expression")]
pub enum Number {
    Value(f64),
    Expr(String),
}

/// One value, or the values of a ball joint (4 for q, 3 for v) or a free joint (7, 6).
#[derive(Clone, Debug, JsonSchema)]
#[serde(untagged)]
#[schemars(rename = "initial_value")]
pub enum Initial {
    One(Number),
    Many(Vec<Number>),
}

// By hand rather than `#[serde(untagged)]`, so that a wrong type (`q1 = true`) says what was
// expected instead of "did not match any variant".
struct NumberVisitor;

impl<'de> Visitor<'de> for NumberVisitor {
    type Value = Number;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number or an expression string")
    }
    fn visit_f64<E: de::Error>(self, x: f64) -> Result<Number, E> {
        Ok(Number::Value(x))
    }
    fn visit_i64<E: de::Error>(self, x: i64) -> Result<Number, E> {
        Ok(Number::Value(x as f64))
    }
    fn visit_u64<E: de::Error>(self, x: u64) -> Result<Number, E> {
        Ok(Number::Value(x as f64))
    }
    fn visit_str<E: de::Error>(self, s: &str) -> Result<Number, E> {
        Ok(Number::Expr(s.to_string()))
    }
}

impl<'de> Deserialize<'de> for Number {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(NumberVisitor)
    }
}

struct InitialVisitor;

impl<'de> Visitor<'de> for InitialVisitor {
    type Value = Initial;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a number, an expression string, or an array of them")
    }
    fn visit_f64<E: de::Error>(self, x: f64) -> Result<Initial, E> {
        Ok(Initial::One(Number::Value(x)))
    }
    fn visit_i64<E: de::Error>(self, x: i64) -> Result<Initial, E> {
        Ok(Initial::One(Number::Value(x as f64)))
    }
    fn visit_u64<E: de::Error>(self, x: u64) -> Result<Initial, E> {
        Ok(Initial::One(Number::Value(x as f64)))
    }
    fn visit_str<E: de::Error>(self, s: &str) -> Result<Initial, E> {
        Ok(Initial::One(Number::Expr(s.to_string())))
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Initial, A::Error> {
        let mut v = Vec::new();
        while let Some(n) = seq.next_element::<Number>()? {
            v.push(n);
        }
        Ok(Initial::Many(v))
    }
}

impl<'de> Deserialize<'de> for Initial {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(InitialVisitor)
    }
}

/// A mechanical system, its programme (ideal constraints whose reactions are the control forces),
/// the initial state and what to check. Reference: src/scene/FORMAT.md.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(title = "progmo scene file")]
pub struct SceneFile {
    /// Scene name, non-empty; in the catalog equal to the file stem.
    #[schemars(length(min = 1))]
    pub name: String,
    /// What the scene is.
    #[serde(default)]
    pub description: String,
    /// Why it is in the catalog: what it checks.
    #[serde(default)]
    pub purpose: String,
    /// Named constants: numbers or expressions of other parameters (and pi). Names are
    /// identifiers other than t and pi.
    #[serde(default)]
    #[schemars(with = "BTreeMap<String, Number>", transform = schema::parameter_names)]
    pub parameters: BTreeMap<String, Spanned<Number>>,
    #[schemars(with = "ModelFile")]
    pub model: Spanned<ModelFile>,
    /// System constraints: the mechanism's own constraints (e.g. loop closures). Rows in file
    /// order, before the programme.
    #[serde(default)]
    pub constraints: Vec<RowFile>,
    /// Programme rows g(t, q, v[, dv/dt]) = 0. May be empty or absent: the motion is then the
    /// (constrained) free motion, u = 0.
    #[serde(default)]
    pub programme: Vec<RowFile>,
    /// Actuators realizing the programme (tree and urdf scenes): with them the control force is
    /// u = H tau on the listed joints only and the programme rows are servo-constraints
    /// (FORMAT.md, "Actuators"); as many actuators as programme rows. Absent: the ideal
    /// realization, u in the row space of the programme Jacobian.
    #[serde(default)]
    #[schemars(with = "Vec<ActuatorFile>")]
    pub actuators: Vec<Spanned<ActuatorFile>>,
    #[schemars(with = "InitialFile")]
    pub initial: Spanned<InitialFile>,
    #[schemars(with = "TimeFile")]
    pub time: Spanned<TimeFile>,
    #[serde(default)]
    #[schemars(with = "schema::SolverTable")]
    pub solver: SolverFile,
    /// Check tolerances by name, each with a reason: the budgets of the check's metrics
    /// (programme_residual is required for catalog scenes); an unknown name is refused. The
    /// check's options (`replay_step`) live in `[checks]`.
    #[serde(default)]
    #[schemars(with = "BTreeMap<String, ToleranceFile>", transform = schema::tolerance_names)]
    pub tolerances: BTreeMap<String, Spanned<ToleranceFile>>,
    #[serde(default)]
    pub checks: ChecksFile,
    /// Reference values at given times, of an origin independent of the solver (a closed form, a
    /// published solution), each entry with its source; judged by the solver_only check's
    /// `reference_error` (FORMAT.md, "Reference values").
    #[serde(default)]
    #[schemars(with = "Vec<ReferenceFile>")]
    pub reference: Vec<Spanned<ReferenceFile>>,
    #[serde(default)]
    pub view: ViewFile,
}

/// Target kinds of `[[view.targets]]`.
pub const TARGET_KINDS: [&str; 5] = ["point", "line", "plane", "circle", "path"];

/// What the 3D view of recordings draws besides the mechanism (tree scenes).
#[derive(Clone, Debug, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "view")]
pub struct ViewFile {
    /// The programme's geometric targets, drawn in the world frame (`/progmo/scene`).
    #[serde(default)]
    #[schemars(with = "Vec<TargetFile>")]
    pub targets: Vec<Spanned<TargetFile>>,
}

/// A geometric target: numbers or expressions of parameters (a path's: of t too), world frame.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "target")]
pub struct TargetFile {
    /// point, line, plane, circle or path.
    #[schemars(schema_with = "schema::target_kind")]
    pub kind: Spanned<String>,
    /// Entity name in the view (default: target<index>).
    #[serde(default)]
    pub name: Option<String>,
    /// point: the point; line, plane: a point on it; circle: its centre (m).
    #[serde(default)]
    #[schemars(with = "Option<[Number; 3]>")]
    pub point: Option<Spanned<[Number; 3]>>,
    /// line: its direction.
    #[serde(default)]
    #[schemars(with = "Option<[Number; 3]>")]
    pub direction: Option<Spanned<[Number; 3]>>,
    /// plane, circle: the normal.
    #[serde(default)]
    #[schemars(with = "Option<[Number; 3]>")]
    pub normal: Option<Spanned<[Number; 3]>>,
    /// circle: the radius (m), > 0.
    #[serde(default)]
    #[schemars(with = "Option<Number>")]
    pub radius: Option<Spanned<Number>>,
    /// line: drawn length, plane: drawn side (m), > 0; default twice the mechanism's size.
    #[serde(default)]
    #[schemars(with = "Option<Number>")]
    pub size: Option<Spanned<Number>>,
    /// path: x, y, z as expressions of t and parameters, sampled over the time span.
    #[serde(default)]
    #[schemars(with = "Option<[Expression; 3]>")]
    pub path: Option<[Spanned<String>; 3]>,
    /// path: number of samples over [t0, t1], >= 2. Default 200.
    #[serde(default)]
    #[schemars(with = "Option<i64>", range(min = 2))]
    pub samples: Option<Spanned<i64>>,
    /// Colour [r, g, b, a], each in [0, 1]. Default magenta.
    #[serde(default)]
    #[schemars(with = "Option<[f64; 4]>")]
    pub color: Option<Spanned<[f64; 4]>>,
}

/// A body's drawn shape: exactly one of box, sphere, cylinder, capsule.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "shape")]
pub struct ShapeFile {
    /// A box with these side lengths (m).
    #[serde(default, rename = "box")]
    #[schemars(with = "Option<[f64; 3]>")]
    pub cuboid: Option<Spanned<[f64; 3]>>,
    /// A sphere of this radius (m).
    #[serde(default)]
    #[schemars(with = "Option<f64>")]
    pub sphere: Option<Spanned<f64>>,
    /// A cylinder [radius, length] (m) along the shape's z axis.
    #[serde(default)]
    #[schemars(with = "Option<[f64; 2]>")]
    pub cylinder: Option<Spanned<[f64; 2]>>,
    /// A capsule [radius, length between the centres of its end spheres] (m) along z.
    #[serde(default)]
    #[schemars(with = "Option<[f64; 2]>")]
    pub capsule: Option<Spanned<[f64; 2]>>,
    /// Centre in the body frame (m). Default: the body's centre of mass.
    #[serde(default)]
    pub pos: Option<[f64; 3]>,
    /// Orientation in the body frame, quaternion (w, x, y, z), normalised implicitly.
    #[serde(default)]
    #[schemars(with = "[f64; 4]", extend("default" = [1.0, 0.0, 0.0, 0.0]))]
    pub quat: Option<Spanned<[f64; 4]>>,
    /// Colour [r, g, b, a], each in [0, 1]. Default orange.
    #[serde(default)]
    #[schemars(with = "Option<[f64; 4]>")]
    pub color: Option<Spanned<[f64; 4]>>,
}

/// How the cross-simulator check treats the scene.
#[derive(Clone, Debug, Default, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "checks")]
pub struct ChecksFile {
    /// Simulators the scene is declared not to be checked in (mujoco, pinocchio, drake), each with the
    /// reason: an expected not_checked does not fail a run (an unexpected one does).
    #[serde(default)]
    #[schemars(with = "BTreeMap<String, String>", transform = schema::simulator_names)]
    pub not_checked: BTreeMap<String, Spanned<String>>,
    /// Fixed RK4 step of the open-loop replay (s), with the reason for it; absent: a
    /// convergence check picks the step (halving until the residual stops improving 16x).
    #[serde(default)]
    #[schemars(with = "Option<ToleranceFile>")]
    pub replay_step: Option<Spanned<ToleranceFile>>,
}

/// One row of a full mass matrix as written: expressions with their places.
pub type SpannedRow = Spanned<Vec<Spanned<String>>>;

/// The mechanical system: kind = lagrangian (coordinates and A(q) as expressions) or tree
/// (bodies and joints).
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = schema::model_kind_rules)]
#[schemars(rename = "model")]
pub struct ModelFile {
    /// Model kind.
    #[schemars(schema_with = "schema::model_kind")]
    pub kind: Spanned<String>,
    // lagrangian
    /// lagrangian: names of the generalized coordinates q (identifiers, not t, pi or a
    /// parameter; unique).
    #[serde(default)]
    #[schemars(with = "Vec<Identifier>", length(min = 1), extend("uniqueItems" = true))]
    pub coordinates: Vec<Spanned<String>>,
    /// lagrangian: the full symmetric n x n A(q), rows of expressions of q and parameters.
    /// Exactly one of mass_matrix and mass_diagonal.
    #[serde(default)]
    #[schemars(with = "Option<Vec<Vec<Expression>>>")]
    pub mass_matrix: Option<Spanned<Vec<SpannedRow>>>,
    /// lagrangian: the diagonal of A(q), n expressions of q and parameters.
    #[serde(default)]
    #[schemars(with = "Option<Vec<Expression>>")]
    pub mass_diagonal: Option<Spanned<Vec<Spanned<String>>>>,
    /// lagrangian: potential energy V(t, q); adds Q = -dV/dq.
    #[serde(default)]
    #[schemars(with = "Option<Expression>")]
    pub potential: Option<Spanned<String>>,
    /// Generalized forces by coordinate name (lagrangian: a coordinate; tree: a velocity
    /// coordinate), expressions of t, q and v.
    #[serde(default)]
    #[schemars(with = "BTreeMap<String, Expression>")]
    pub forces: BTreeMap<String, Spanned<String>>,
    // tree
    /// tree: uniform gravity vector (world frame), m/s^2. Default [0, 0, 0].
    #[serde(default)]
    pub gravity: Option<[f64; 3]>,
    /// tree: bodies in any order; each names its parent (world by default).
    #[serde(default)]
    #[schemars(with = "Vec<BodyFile>", length(min = 1))]
    pub bodies: Vec<Spanned<BodyFile>>,
    /// tree: named points fixed in bodies; their signals (tip.x, tip.x', tip.x'', tip.qw,
    /// tip.wx, tip.wx') may appear in rows.
    #[serde(default)]
    #[schemars(with = "Vec<SiteFile>")]
    pub sites: Vec<Spanned<SiteFile>>,
    /// tree: Newtonian attractors acting on every body's mass (potential -mu m / r).
    #[serde(default)]
    #[schemars(with = "Vec<AttractorFile>")]
    pub attractors: Vec<Spanned<AttractorFile>>,
    /// tree: forces applied at points of bodies (world-frame components as expressions of t, q,
    /// v).
    #[serde(default)]
    #[schemars(with = "Vec<PointForceFile>")]
    pub point_forces: Vec<Spanned<PointForceFile>>,
    // urdf, mjcf
    /// urdf, mjcf: the robot description file (URDF or MuJoCo MJCF), relative to the scene file
    /// or `package://PKG/path` (found through $PROGMO_ROBOT_PATH; the Python package adds
    /// example-robot-data's).
    #[serde(default)]
    #[schemars(with = "Option<String>")]
    pub file: Option<Spanned<String>>,
    /// urdf: how the root link is attached to the world: fixed (default) or free (a 6-dof joint
    /// named root).
    #[serde(default)]
    #[schemars(schema_with = "schema::root_joint")]
    pub root_joint: Option<Spanned<String>>,
    /// urdf, mjcf: joints welded at the file's pose (q = 0; an MJCF joint's `ref`), e.g. a
    /// gripper's fingers, by name.
    #[serde(default)]
    #[schemars(with = "Vec<String>")]
    pub locked_joints: Vec<Spanned<String>>,
    /// urdf, mjcf: the kinds of elements of the file that the scene knowingly leaves unmodelled,
    /// each with its reason (non-empty), e.g. { frictionloss = "...", joint_limit = "..." }.
    /// Kinds: joint_limit, effort_limit, velocity_limit, frictionloss, tendon, equality, contact,
    /// actuator, mimic, fluid (FORMAT.md, "Robot files"); each declared kind must occur in the
    /// file. Elements of an undeclared kind are reported by the check as not checked.
    #[serde(default)]
    #[schemars(schema_with = "schema::ignore_kinds")]
    pub ignore: BTreeMap<String, Spanned<String>>,
    /// urdf, mjcf: extra frames fixed in links (bodies); like every link, each is a signal
    /// source (name.x, name.qw, ...).
    #[serde(default)]
    #[schemars(with = "Vec<FrameFile>")]
    pub frames: Vec<Spanned<FrameFile>>,
    /// tree: loop closures between bodies (system rows: point 3, weld 6, distance 1, line 2,
    /// plane 1).
    #[serde(default)]
    #[schemars(with = "Vec<ClosureFile>")]
    pub closures: Vec<Spanned<ClosureFile>>,
}

/// A frame fixed in a link of an imported robot.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "frame")]
pub struct FrameFile {
    /// Frame name (an identifier, not a link or joint name): prefix of its signals.
    #[schemars(with = "Identifier")]
    pub name: String,
    /// The link it is fixed in.
    pub parent: String,
    /// Origin in the link frame (m).
    #[serde(default)]
    pub pos: [f64; 3],
    /// Orientation in the link frame (w, x, y, z), normalised implicitly.
    #[serde(default = "unit_quat")]
    pub quat: [f64; 4],
}

fn unit_quat() -> [f64; 4] {
    [1.0, 0.0, 0.0, 0.0]
}

/// A loop closure: a point (or frame) of body a held on a point (or frame) of body b (or the
/// world). Its rows are system constraints named after it.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "closure")]
pub struct ClosureFile {
    /// Closure name (an identifier): prefix of its row names (name_x, name_y, name_z; weld also
    /// name_rx, name_ry, name_rz; distance: name).
    #[schemars(with = "Identifier")]
    pub name: String,
    /// point: point_a = point_b (3 rows); weld: frame a = frame b (6 rows); distance: |point_a -
    /// point_b| = distance (1 row); line: point_a on the line of body_b through point_b along
    /// `axis` (2 rows); plane: point_a in the plane of body_b through point_b normal to `axis`
    /// (1 row); rolling: a disk (`axis`) or sphere of body_a centred at point_a rolls without
    /// slipping on the world plane through point_b normal to `normal` (3 rows).
    #[schemars(schema_with = "schema::closure_kind")]
    pub kind: Spanned<String>,
    /// First body.
    pub body_a: String,
    /// Point of body_a, its body frame (m).
    #[serde(default)]
    pub point_a: [f64; 3],
    /// weld: orientation of frame a in body_a, quaternion (w, x, y, z).
    #[serde(default)]
    #[schemars(with = "[f64; 4]", extend("default" = [1.0, 0.0, 0.0, 0.0]))]
    pub quat_a: Option<[f64; 4]>,
    /// Second body, or world.
    #[serde(default = "world")]
    pub body_b: String,
    /// Point of body_b (world: world coordinates) (m).
    #[serde(default)]
    pub point_b: [f64; 3],
    /// weld: orientation of frame b in body_b, quaternion (w, x, y, z).
    #[serde(default)]
    #[schemars(with = "[f64; 4]", extend("default" = [1.0, 0.0, 0.0, 0.0]))]
    pub quat_b: Option<[f64; 4]>,
    /// distance: the fixed distance (m), > 0; required for distance, refused otherwise.
    #[serde(default)]
    #[schemars(with = "Option<f64>", extend("exclusiveMinimum" = 0.0))]
    pub distance: Option<f64>,
    /// line: the line's direction; plane: the plane's normal; in body_b's frame (world: world
    /// frame), nonzero, normalised implicitly. Required for line and plane; rolling: the disk's
    /// axis in body_a's frame (absent: a sphere); refused otherwise.
    #[serde(default)]
    pub axis: Option<[f64; 3]>,
    /// rolling: the disk's or sphere's radius (m), > 0; required for rolling, refused otherwise.
    #[serde(default)]
    #[schemars(with = "Option<f64>", extend("exclusiveMinimum" = 0.0))]
    pub radius: Option<f64>,
    /// rolling: the plane's normal, world frame, nonzero, normalised implicitly (default
    /// [0, 0, 1]); refused otherwise.
    #[serde(default)]
    #[schemars(with = "[f64; 3]", extend("default" = [0.0, 0.0, 1.0]))]
    pub normal: Option<[f64; 3]>,
}

/// A rigid body of a tree model.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "body")]
pub struct BodyFile {
    /// Body name (unique).
    pub name: String,
    /// Parent body name, or world (bodies may be listed in any order).
    #[serde(default = "world")]
    pub parent: String,
    /// Frame origin in the parent's frame (m).
    #[serde(default)]
    #[schemars(with = "[f64; 3]", extend("default" = [0.0, 0.0, 0.0]))]
    pub pos: Option<Spanned<[f64; 3]>>,
    /// Frame orientation in the parent's frame, quaternion (w, x, y, z), normalised implicitly.
    #[serde(default)]
    #[schemars(with = "[f64; 4]", extend("default" = [1.0, 0.0, 0.0, 0.0]))]
    pub quat: Option<Spanned<[f64; 4]>>,
    /// Mass (kg), >= 0; 0 with no inertia makes a massless link.
    #[schemars(with = "f64", range(min = 0.0))]
    pub mass: Spanned<f64>,
    /// Centre of mass in the body frame (m).
    #[serde(default)]
    pub com: [f64; 3],
    /// Inertia about the centre of mass in the body frame (kg m^2): principal [ixx, iyy, izz] or
    /// full [ixx, iyy, izz, ixy, ixz, iyz]; positive definite, or absent/zero for a point mass.
    #[serde(default)]
    #[schemars(with = "Option<Vec<f64>>", transform = schema::inertia_lengths)]
    pub inertia: Option<Spanned<Vec<f64>>>,
    /// Joints acting in sequence between parent and body (none: welded).
    #[serde(default)]
    #[schemars(with = "Vec<JointFile>")]
    pub joints: Vec<Spanned<JointFile>>,
    /// Gravity compensation (MuJoCo's body `gravcomp`): a force -gravcomp m g at the centre of
    /// mass (1: the body feels no gravity; 0: none).
    #[serde(default)]
    pub gravcomp: f64,
    /// Shape drawn in 3D views; absent: a box with the body's mass and inertia.
    #[serde(default)]
    #[schemars(with = "Option<ShapeFile>")]
    pub shape: Option<Spanned<ShapeFile>>,
}

fn world() -> String {
    "world".to_string()
}

/// A joint.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = schema::joint_axis_rule)]
#[schemars(rename = "joint")]
pub struct JointFile {
    /// Joint name: the coordinate name of hinge/slide joints; prefix j. of ball (j.qw..j.qz,
    /// j.wx..j.wz) and free joints (j.x, j.y, j.z, j.qw.., j.vx.., j.wx..).
    pub name: String,
    /// Joint type.
    #[serde(rename = "type")]
    #[schemars(schema_with = "schema::joint_type")]
    pub kind: Spanned<String>,
    /// hinge/slide: axis in the frame of the preceding joints (required for them).
    #[serde(default)]
    #[schemars(with = "Option<[f64; 3]>")]
    pub axis: Option<Spanned<[f64; 3]>>,
    /// Point on the joint axis / centre of a ball joint, same frame (m). Not for free joints.
    #[serde(default)]
    pub anchor: [f64; 3],
    /// Spring stiffness (N/m or N m/rad), >= 0.
    #[serde(default)]
    #[schemars(range(min = 0.0))]
    pub stiffness: f64,
    /// Spring rest position.
    #[serde(default)]
    pub spring_ref: f64,
    /// Viscous damping (N s/m or N m s/rad), >= 0.
    #[serde(default)]
    #[schemars(range(min = 0.0))]
    pub damping: f64,
    /// Armature (kg m^2 or kg), >= 0: rotor inertia reflected on the joint, added to the mass
    /// matrix's diagonal on each of its dofs (MuJoCo's `armature`).
    #[serde(default)]
    #[schemars(range(min = 0.0))]
    pub armature: f64,
}

/// A point fixed in a body.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "site")]
pub struct SiteFile {
    /// Site name (an identifier, unique, not a joint name): prefix of its signals.
    #[schemars(with = "Identifier")]
    pub name: String,
    /// The body it is fixed in.
    pub body: String,
    /// Position in the body frame (m).
    #[serde(default)]
    pub pos: [f64; 3],
}

/// A Newtonian attractor: each body's mass m feels -mu m r / |r|^3 toward `point`.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "attractor")]
pub struct AttractorFile {
    /// Attracting centre, world frame (m).
    #[serde(default)]
    pub point: [f64; 3],
    /// Gravitational parameter (m^3/s^2).
    pub mu: f64,
}

/// A force applied at a body point.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "point_force")]
pub struct PointForceFile {
    /// Body the force acts on.
    pub body: String,
    /// Point of application in the body frame (m).
    #[serde(default)]
    pub point: [f64; 3],
    /// World-frame force components (N), expressions of t, q, v.
    #[schemars(with = "[Expression; 3]")]
    pub force: [Spanned<String>; 3],
}

/// One row; its level (position, velocity, acceleration) is that of the highest-level symbol
/// it reads.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "row")]
pub struct RowFile {
    /// Row name (an identifier, unique among all rows).
    #[schemars(with = "Identifier")]
    pub name: Spanned<String>,
    /// The row's left-hand side: the row is expr = 0.
    #[schemars(with = "Expression")]
    pub expr: Spanned<String>,
}

/// One actuator: a generalized force on one hinge or slide joint (`joint`), or along a direction
/// over the velocities (`direction`, e.g. a force between two joints, possibly turning with the
/// coordinates); exactly one of the two.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "actuator")]
pub struct ActuatorFile {
    /// The actuated joint: a hinge or slide joint of the model (its velocity's name).
    #[serde(default)]
    #[schemars(with = "Option<Identifier>")]
    pub joint: Option<Spanned<String>>,
    /// The generalized force per unit tau by velocity name (numbers, or expressions of the
    /// parameters, t and the coordinates: H(t, q)); velocities not listed get 0. Needs `name`.
    #[serde(default)]
    #[schemars(with = "Option<BTreeMap<String, Number>>")]
    pub direction: Option<Spanned<BTreeMap<String, Spanned<Number>>>>,
    /// Name in messages and outputs (an identifier, unique among actuators); default: the joint's.
    #[serde(default)]
    #[schemars(with = "Option<Identifier>")]
    pub name: Option<Spanned<String>>,
}

/// The initial state; it must satisfy every row (and the position rows' first derivatives)
/// unless assemble = true.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "initial")]
pub struct InitialFile {
    /// Initial configuration by coordinate or joint name (ball: 4 quaternion values, free: 7).
    /// tree: missing ones take the neutral configuration; lagrangian: every coordinate is
    /// required.
    #[serde(default)]
    #[schemars(with = "BTreeMap<String, Initial>")]
    pub q: BTreeMap<String, Spanned<Initial>>,
    /// Initial velocities by coordinate or joint name (ball: 3, free: 6); missing ones are 0.
    #[serde(default)]
    #[schemars(with = "BTreeMap<String, Initial>")]
    pub v: BTreeMap<String, Spanned<Initial>>,
    /// An `mjcf` model's `<keyframe>` key (by name) the state starts from; `q` and `v` entries
    /// given here replace its values.
    #[serde(default)]
    #[schemars(with = "Option<String>")]
    pub keyframe: Option<Spanned<String>>,
    /// Project an inconsistent initial state onto the constraints instead of refusing it.
    #[serde(default)]
    pub assemble: bool,
}

/// Time span and output.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "time")]
pub struct TimeFile {
    /// Start time (s). Default 0.
    #[serde(default)]
    #[schemars(with = "Option<f64>", extend("default" = 0.0))]
    pub t0: Option<Spanned<f64>>,
    /// End time (s), > t0.
    #[schemars(with = "f64")]
    pub t1: Spanned<f64>,
    /// Output sample spacing (s); absent: one sample per accepted step.
    #[serde(default)]
    #[schemars(with = "Option<f64>", extend("exclusiveMinimum" = 0.0))]
    pub output_dt: Option<Spanned<f64>>,
    /// Most output samples a run may write, t0 and t1 included (a longer span or a finer
    /// output_dt is refused before integrating).
    #[serde(default)]
    #[schemars(
        with = "Option<i64>",
        range(min = 2),
        extend("default" = solve::DEFAULT_MAX_SAMPLES)
    )]
    pub max_samples: Option<Spanned<i64>>,
}

/// `[solver]`: settings of [`crate::solve::Overrides`] whose table is `solver`, by name (the loader
/// reads them through [`crate::solve::Overrides::from_table`]; the schema lists them from the same
/// definition, [`schema::SolverTable`]).
pub type SolverFile = BTreeMap<String, Spanned<toml::Value>>;

/// A check tolerance with its reason.
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "tolerance")]
pub struct ToleranceFile {
    /// The tolerance.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub value: f64,
    /// One line: why this value.
    #[schemars(length(min = 1), regex(pattern = r"\S"))]
    pub reason: String,
}

/// Reference values of the motion at one time (`[[reference]]`).
#[derive(Clone, Debug, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "reference")]
pub struct ReferenceFile {
    /// The time (s): a number or an expression of parameters, inside the scene's span.
    #[schemars(with = "Number")]
    pub t: Spanned<Number>,
    /// Where the values come from (a closed form, a publication): required, one line or more.
    #[schemars(length(min = 1), regex(pattern = r"\S"))]
    pub source: String,
    /// Coordinates: name -> number or expression of parameters and `t`.
    #[serde(default)]
    #[schemars(with = "BTreeMap<String, Number>")]
    pub q: BTreeMap<String, Spanned<Number>>,
    /// Velocities (by velocity name, e.g. `phi1` for phi1'): numbers or expressions of parameters and `t`.
    #[serde(default)]
    #[schemars(with = "BTreeMap<String, Number>")]
    pub v: BTreeMap<String, Spanned<Number>>,
    /// Control forces u (by velocity name): numbers or expressions of parameters and `t`.
    #[serde(default)]
    #[schemars(with = "BTreeMap<String, Number>")]
    pub u: BTreeMap<String, Spanned<Number>>,
}
