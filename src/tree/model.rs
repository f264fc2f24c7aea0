//! The immutable, validated kinematic-tree model and its construction from specifications.

use super::spatial::{rot_quat, Inertia, Xform};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// Reserved name of the fixed world (the root of every tree).
pub const WORLD: &str = "world";

/// Joint type. Axes are given in the body frame (more precisely: in the frame produced by the
/// preceding joints of the same body, which for an axis not moved by them is the body frame) and are
/// normalised at construction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum JointType {
    /// Rotation by angle `q` about `axis` through the joint anchor. nq = nv = 1.
    Hinge { axis: [f64; 3] },
    /// Translation by `q` along `axis`. nq = nv = 1.
    Slide { axis: [f64; 3] },
    /// Spherical joint about the anchor: q = unit quaternion (w, x, y, z), v = angular velocity in
    /// the joint's child frame (the body frame if it is the body's last joint). nq = 4, nv = 3.
    Ball,
    /// Floating base (only joint of a child of the world): q = (x, y, z, w, qx, qy, qz) = position of
    /// the body origin in world frame and body orientation; v = (world-frame linear velocity of the
    /// body origin, body-frame angular velocity) — MuJoCo's convention. nq = 7, nv = 6.
    Free,
}

impl JointType {
    pub fn nq(&self) -> usize {
        match self {
            JointType::Hinge { .. } | JointType::Slide { .. } => 1,
            JointType::Ball => 4,
            JointType::Free => 7,
        }
    }
    pub fn nv(&self) -> usize {
        match self {
            JointType::Hinge { .. } | JointType::Slide { .. } => 1,
            JointType::Ball => 3,
            JointType::Free => 6,
        }
    }
}

/// Specification of one joint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointSpec {
    /// Unique name (also the name of its q/v entries, see [`Model::q_names`]).
    pub name: String,
    #[serde(flatten)]
    pub kind: JointType,
    /// Point the hinge axis passes through / ball centre, in the body frame (MuJoCo `pos`).
    /// Ignored by slides; must be zero for free joints.
    #[serde(default)]
    pub anchor: [f64; 3],
    /// Spring stiffness k: generalized force `-k (q - spring_ref)` (hinge and slide only).
    #[serde(default)]
    pub stiffness: f64,
    /// Spring reference position.
    #[serde(default)]
    pub spring_ref: f64,
    /// Viscous damping d: generalized force `-d v` on every dof of the joint.
    #[serde(default)]
    pub damping: f64,
    /// Armature (rotor inertia reflected on the joint, MuJoCo `armature`), >= 0: added to the
    /// diagonal of `A(q)` on every dof of the joint.
    #[serde(default)]
    pub armature: f64,
    /// Reference position (MuJoCo `ref`, hinge and slide only): the joint's displacement is
    /// `q - reference`, so `q = reference` is the pose the body's placement describes. The spring
    /// reference `spring_ref` is a value of q (absolute), as in MuJoCo.
    #[serde(default)]
    pub reference: f64,
}

impl JointSpec {
    pub fn hinge(name: &str, axis: [f64; 3]) -> Self {
        Self::new(name, JointType::Hinge { axis })
    }
    pub fn slide(name: &str, axis: [f64; 3]) -> Self {
        Self::new(name, JointType::Slide { axis })
    }
    pub fn ball(name: &str) -> Self {
        Self::new(name, JointType::Ball)
    }
    pub fn free(name: &str) -> Self {
        Self::new(name, JointType::Free)
    }
    pub fn new(name: &str, kind: JointType) -> Self {
        JointSpec {
            name: name.to_string(),
            kind,
            anchor: [0.0; 3],
            stiffness: 0.0,
            spring_ref: 0.0,
            damping: 0.0,
            armature: 0.0,
            reference: 0.0,
        }
    }
    pub fn with_anchor(mut self, anchor: [f64; 3]) -> Self {
        self.anchor = anchor;
        self
    }
    pub fn with_spring(mut self, stiffness: f64, spring_ref: f64) -> Self {
        self.stiffness = stiffness;
        self.spring_ref = spring_ref;
        self
    }
    pub fn with_damping(mut self, damping: f64) -> Self {
        self.damping = damping;
        self
    }
    pub fn with_armature(mut self, armature: f64) -> Self {
        self.armature = armature;
        self
    }
    /// MuJoCo `ref`: the joint's displacement is `q - reference`.
    pub fn with_reference(mut self, reference: f64) -> Self {
        self.reference = reference;
        self
    }
}

/// Specification of one body.
///
/// Mass properties: `mass > 0` with `inertia` (about the CoM, body frame) symmetric positive
/// semi-definite (exactly zero: a point mass at `com`), or `mass == 0` with a nonzero such inertia; each rigid body (a body with joints, or the
/// world, with what is welded to it) has principal moments satisfying the triangle inequality; or `massless = true` with `mass == 0` and zero inertia (coordinate bodies).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BodySpec {
    pub name: String,
    /// Name of the parent body, or [`WORLD`]. Parents must be specified before their children.
    pub parent: String,
    /// Position of the body frame origin in the parent frame (before the body's joints act).
    #[serde(default)]
    pub pos: [f64; 3],
    /// Orientation (w, x, y, z) of the body frame in the parent frame; normalised at construction.
    #[serde(default = "unit_quat")]
    pub quat: [f64; 4],
    #[serde(default)]
    pub mass: f64,
    /// Centre of mass in the body frame.
    #[serde(default)]
    pub com: [f64; 3],
    /// Inertia tensor about the centre of mass, body frame (row-major).
    #[serde(default)]
    pub inertia: [[f64; 3]; 3],
    #[serde(default)]
    pub massless: bool,
    /// Joints applied in sequence (parent placement, then joint 1, joint 2, ...; MuJoCo semantics).
    #[serde(default)]
    pub joints: Vec<JointSpec>,
    /// Gravity compensation (MuJoCo body `gravcomp`): a passive world-frame force
    /// `-gravcomp m g` at the CoM (1: the body feels no gravity).
    #[serde(default)]
    pub gravcomp: f64,
}

fn unit_quat() -> [f64; 4] {
    [1.0, 0.0, 0.0, 0.0]
}

impl BodySpec {
    /// A rigid body with mass, CoM and inertia about the CoM.
    pub fn new(name: &str, parent: &str, mass: f64, com: [f64; 3], inertia: [[f64; 3]; 3]) -> Self {
        BodySpec {
            name: name.to_string(),
            parent: parent.to_string(),
            pos: [0.0; 3],
            quat: unit_quat(),
            mass,
            com,
            inertia,
            massless: false,
            joints: Vec::new(),
            gravcomp: 0.0,
        }
    }
    /// A point mass at `com`.
    pub fn point_mass(name: &str, parent: &str, mass: f64, com: [f64; 3]) -> Self {
        Self::new(name, parent, mass, com, [[0.0; 3]; 3])
    }
    /// A massless body (e.g. an intermediate frame of a coordinate chain).
    pub fn massless(name: &str, parent: &str) -> Self {
        let mut b = Self::new(name, parent, 0.0, [0.0; 3], [[0.0; 3]; 3]);
        b.massless = true;
        b
    }
    pub fn at(mut self, pos: [f64; 3]) -> Self {
        self.pos = pos;
        self
    }
    pub fn rotated(mut self, quat: [f64; 4]) -> Self {
        self.quat = quat;
        self
    }
    pub fn joint(mut self, j: JointSpec) -> Self {
        self.joints.push(j);
        self
    }
    pub fn with_gravcomp(mut self, gravcomp: f64) -> Self {
        self.gravcomp = gravcomp;
        self
    }
}

/// A uniform field or central attraction acting on every body's centre of mass.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Attractor {
    /// Fixed attracting point, world frame.
    pub point: [f64; 3],
    /// Gravitational parameter mu: force `-mu m r / |r|^3` with `r = com - point`.
    pub mu: f64,
}

/// Fields applied by [`super::applied_forces`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Fields {
    /// Uniform gravity (world frame), e.g. `[0, 0, -9.81]`.
    #[serde(default)]
    pub gravity: [f64; 3],
    /// Newtonian attractions of every body's CoM to fixed points.
    #[serde(default)]
    pub attractors: Vec<Attractor>,
}

/// Construction error; the message names the offending body/joint.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    #[error("body '{body}': {msg}")]
    Body { body: String, msg: String },
    #[error("joint '{joint}' of body '{body}': {msg}")]
    Joint {
        body: String,
        joint: String,
        msg: String,
    },
    #[error("fields: {0}")]
    Fields(String),
}

/// Joint type after validation (unit axes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum JointKind {
    Hinge(Vector3<f64>),
    Slide(Vector3<f64>),
    Ball,
    Free,
}

/// A validated joint.
#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    pub body: usize,
    pub(crate) kind: JointKind,
    pub anchor: Vector3<f64>,
    pub stiffness: f64,
    pub spring_ref: f64,
    pub damping: f64,
    /// Added to `A(q)`'s diagonal on each dof of the joint.
    pub armature: f64,
    /// Hinge/slide: the displacement is `q - reference` (MuJoCo `ref`); 0 for ball/free.
    pub reference: f64,
    /// First index in q.
    pub iq: usize,
    /// First index in v.
    pub iv: usize,
    pub nq: usize,
    pub nv: usize,
}

impl Joint {
    /// The joint type with its normalised axis.
    pub fn joint_type(&self) -> JointType {
        let a = |u: &Vector3<f64>| [u[0], u[1], u[2]];
        match &self.kind {
            JointKind::Hinge(u) => JointType::Hinge { axis: a(u) },
            JointKind::Slide(u) => JointType::Slide { axis: a(u) },
            JointKind::Ball => JointType::Ball,
            JointKind::Free => JointType::Free,
        }
    }
}

/// A validated body.
#[derive(Clone, Debug)]
pub struct Body {
    pub name: String,
    /// Parent body index, `None` for the world.
    pub parent: Option<usize>,
    /// Placement in the parent frame (before joints): position and rotation (body -> parent).
    pub pos: Vector3<f64>,
    pub rot: Matrix3<f64>,
    /// Normalised placement quaternion (w, x, y, z).
    pub quat: [f64; 4],
    pub mass: f64,
    pub com: Vector3<f64>,
    pub inertia: Matrix3<f64>,
    pub massless: bool,
    /// Gravity compensation: passive force `-gravcomp m g` at the CoM.
    pub gravcomp: f64,
    /// Indices of this body's joints (consecutive, in order of application).
    pub joints: Range<usize>,
}

/// Internal link: one per joint, or one fixed link for a body without joints. The links of a body
/// form a chain of massless frames; the last one is the body frame and carries the body inertia.
#[derive(Clone, Debug)]
pub(crate) struct Link {
    pub parent: Option<usize>,
    /// `^pre X_parent`: fixed transform from the parent link frame to this link's pre-joint frame.
    pub place: Xform<f64>,
    pub joint: Option<usize>,
    pub inertia: Option<Inertia<f64>>,
}

/// Immutable kinematic tree (bodies, joints, fields). Build with [`Model::new`].
#[derive(Clone, Debug)]
pub struct Model {
    pub(crate) bodies: Vec<Body>,
    pub(crate) joints: Vec<Joint>,
    pub(crate) links: Vec<Link>,
    /// Link index of each body's frame: its last link, or for a welded body (no joints, parent not
    /// the world) the link of its nearest moving ancestor, into which it is folded.
    pub(crate) body_link: Vec<usize>,
    /// Per body folded into an ancestor's link: its fixed placement there, `x_link = R x_body + p`
    /// as (R, p).
    pub(crate) body_offset: Vec<Option<(Matrix3<f64>, Vector3<f64>)>>,
    /// Per dof: the previous dof on its path to the root (Featherstone's lambda over dofs), so the
    /// CRBA walks ancestors without touching links.
    pub(crate) dof_parent: Vec<Option<usize>>,
    /// Per dof: its link.
    pub(crate) dof_link: Vec<usize>,
    pub(crate) fields: Fields,
    nq: usize,
    nv: usize,
    q_names: Vec<String>,
    v_names: Vec<String>,
}

fn finite(x: &[f64]) -> bool {
    x.iter().all(|v| v.is_finite())
}

fn berr(b: &str, m: String) -> ModelError {
    ModelError::Body {
        body: b.to_string(),
        msg: m,
    }
}

fn jerr(b: &str, j: &str, m: String) -> ModelError {
    ModelError::Joint {
        body: b.to_string(),
        joint: j.to_string(),
        msg: m,
    }
}

/// Gravity and attractors must be finite.
fn check_fields(fields: &Fields) -> Result<(), ModelError> {
    if !finite(&fields.gravity) {
        return Err(ModelError::Fields("gravity is not finite".into()));
    }
    for a in &fields.attractors {
        if !finite(&a.point) || !a.mu.is_finite() {
            return Err(ModelError::Fields(
                "attractor point or mu is not finite".into(),
            ));
        }
    }
    Ok(())
}

/// A body's placement: normalised quaternion (w, x, y, z), rotation (body -> parent), position.
type Placement = ([f64; 4], Matrix3<f64>, Vector3<f64>);

/// A body's placement, checked.
fn placement(name: &str, s: &BodySpec) -> Result<Placement, ModelError> {
    if !finite(&s.pos) || !finite(&s.quat) {
        return Err(berr(name, "placement is not finite".into()));
    }
    let qn = s.quat.iter().map(|x| x * x).sum::<f64>().sqrt();
    if qn < 1e-9 {
        return Err(berr(name, "placement quaternion is zero".into()));
    }
    let quat = [
        s.quat[0] / qn,
        s.quat[1] / qn,
        s.quat[2] / qn,
        s.quat[3] / qn,
    ];
    let rot = rot_quat(quat[0], quat[1], quat[2], quat[3]);
    let pos = Vector3::from(s.pos);
    Ok((quat, rot, pos))
}

/// A body's mass properties: the inertia about the CoM and the CoM, checked.
fn mass_properties(name: &str, s: &BodySpec) -> Result<(Matrix3<f64>, Vector3<f64>), ModelError> {
    let inertia = Matrix3::from_row_slice(&s.inertia.concat());
    let com = Vector3::from(s.com);
    if !s.mass.is_finite() || !finite(&s.com) || !finite(inertia.as_slice()) {
        return Err(berr(name, "mass properties are not finite".into()));
    }
    if s.massless {
        if s.mass != 0.0 || inertia.iter().any(|x| *x != 0.0) {
            return Err(berr(
                name,
                "flagged massless but mass or inertia is nonzero".into(),
            ));
        }
    } else {
        // mass 0 with a rotational inertia is a semi-definite body too (bolt's feet)
        if s.mass < 0.0 || (s.mass == 0.0 && inertia.iter().all(|x| *x == 0.0)) {
            return Err(berr(
                name,
                format!(
                    "mass must be positive, or 0 with a nonzero inertia, got {} (set massless = true for a massless body)",
                    s.mass
                ),
            ));
        }
        check_inertia(&inertia, s.mass).map_err(|m| berr(name, m))?;
    }
    Ok((inertia, com))
}

/// The validated kind of joint `k` of body `s` (`parent`: its parent body, `None` for the world).
fn joint_kind(
    name: &str,
    s: &BodySpec,
    parent: Option<usize>,
    k: usize,
    js: &JointSpec,
) -> Result<JointKind, ModelError> {
    let jn = js.name.as_str();
    if !finite(&js.anchor)
        || !js.stiffness.is_finite()
        || !js.spring_ref.is_finite()
        || !js.damping.is_finite()
        || !js.armature.is_finite()
        || !js.reference.is_finite()
    {
        return Err(jerr(name, jn, "parameters are not finite".into()));
    }
    if js.stiffness < 0.0 || js.damping < 0.0 || js.armature < 0.0 {
        return Err(jerr(
            name,
            jn,
            "stiffness, damping and armature must be >= 0".into(),
        ));
    }
    let unit = |a: &[f64; 3]| -> Result<Vector3<f64>, ModelError> {
        let u = Vector3::from(*a);
        let n = u.norm();
        if !n.is_finite() || n < 1e-12 {
            return Err(jerr(name, jn, format!("axis {a:?} is zero or not finite")));
        }
        Ok(u / n)
    };
    let kind = match &js.kind {
        JointType::Hinge { axis } => JointKind::Hinge(unit(axis)?),
        JointType::Slide { axis } => JointKind::Slide(unit(axis)?),
        JointType::Ball => JointKind::Ball,
        JointType::Free => {
            if parent.is_some() || s.joints.len() != 1 || k != 0 {
                return Err(jerr(
                    name,
                    jn,
                    "a free joint must be the only joint of a child of the world".into(),
                ));
            }
            if js.anchor != [0.0; 3] {
                return Err(jerr(name, jn, "a free joint has no anchor".into()));
            }
            JointKind::Free
        }
    };
    if js.stiffness != 0.0 && matches!(kind, JointKind::Ball | JointKind::Free) {
        return Err(jerr(
            name,
            jn,
            "springs are supported on hinge and slide joints only".into(),
        ));
    }
    if js.reference != 0.0 && matches!(kind, JointKind::Ball | JointKind::Free) {
        return Err(jerr(
            name,
            jn,
            "a reference position (ref) is supported on hinge and slide joints only".into(),
        ));
    }
    Ok(kind)
}

/// The dof tree: within a joint, dof k follows dof k-1; the first dof of a joint follows the
/// last dof of the nearest ancestor link that has a joint. Returns (dof_parent, dof_link).
fn dof_tree(links: &[Link], joints: &[Joint], nv: usize) -> (Vec<Option<usize>>, Vec<usize>) {
    let mut dof_parent = vec![None; nv];
    let mut dof_link = vec![0; nv];
    let mut last_dof: Vec<Option<usize>> = vec![None; links.len()];
    for (i, link) in links.iter().enumerate() {
        let inherited = link.parent.and_then(|p| last_dof[p]);
        last_dof[i] = inherited;
        if let Some(j) = link.joint {
            let jt: &Joint = &joints[j];
            let mut prev = inherited;
            for k in 0..jt.nv {
                dof_parent[jt.iv + k] = prev;
                dof_link[jt.iv + k] = i;
                prev = Some(jt.iv + k);
            }
            last_dof[i] = prev;
        }
    }
    (dof_parent, dof_link)
}

/// A [`Model`] under construction: the bodies, joints and links so far.
#[derive(Default)]
struct ModelBuilder {
    bodies: Vec<Body>,
    joints: Vec<Joint>,
    links: Vec<Link>,
    body_link: Vec<usize>,
    nq: usize,
    nv: usize,
    q_names: Vec<String>,
    v_names: Vec<String>,
}

impl ModelBuilder {
    /// Validate a body (its parent listed before it) and add it with its joints and links.
    fn add_body(&mut self, s: &BodySpec) -> Result<(), ModelError> {
        let name = s.name.as_str();
        if name.is_empty() || name == WORLD {
            return Err(berr(
                name,
                format!("invalid body name (empty or '{WORLD}')"),
            ));
        }
        if self.bodies.iter().any(|b| b.name == name) {
            return Err(berr(name, "duplicate body name".into()));
        }
        let parent = if s.parent == WORLD {
            None
        } else {
            match self.bodies.iter().position(|b| b.name == s.parent) {
                Some(p) => Some(p),
                None => {
                    return Err(berr(
                        name,
                        format!(
                            "unknown parent '{}' (parents must be defined before their children)",
                            s.parent
                        ),
                    ))
                }
            }
        };
        // placement
        let (quat, rot, pos) = placement(name, s)?;
        // mass properties
        let (inertia, com) = mass_properties(name, s)?;
        if !s.gravcomp.is_finite() {
            return Err(berr(name, "gravcomp is not finite".into()));
        }
        // joints
        let j0 = self.joints.len();
        let b = self.bodies.len();
        for (k, js) in s.joints.iter().enumerate() {
            self.add_joint(name, s, parent, b, k, js)?;
        }
        let body = Body {
            name: name.to_string(),
            parent,
            pos,
            rot,
            quat,
            mass: s.mass,
            com,
            inertia,
            massless: s.massless,
            gravcomp: s.gravcomp,
            joints: j0..self.joints.len(),
        };
        // links
        self.add_links(s, &body);
        self.bodies.push(body);
        Ok(())
    }

    /// Validate joint `k` of body `s` (index `b`) and add it with the names of its coordinates.
    fn add_joint(
        &mut self,
        name: &str,
        s: &BodySpec,
        parent: Option<usize>,
        b: usize,
        k: usize,
        js: &JointSpec,
    ) -> Result<(), ModelError> {
        let jn = js.name.as_str();
        if jn.is_empty() {
            return Err(jerr(name, jn, "empty joint name".into()));
        }
        if self.joints.iter().any(|j| j.name == jn) {
            return Err(jerr(name, jn, "duplicate joint name".into()));
        }
        let kind = joint_kind(name, s, parent, k, js)?;
        let (jnq, jnv) = (js.kind.nq(), js.kind.nv());
        let (q_names, v_names) = (&mut self.q_names, &mut self.v_names);
        match kind {
            JointKind::Hinge(_) | JointKind::Slide(_) => {
                q_names.push(jn.to_string());
                v_names.push(jn.to_string());
            }
            JointKind::Ball => {
                for e in ["qw", "qx", "qy", "qz"] {
                    q_names.push(format!("{jn}.{e}"));
                }
                for e in ["wx", "wy", "wz"] {
                    v_names.push(format!("{jn}.{e}"));
                }
            }
            JointKind::Free => {
                for e in ["x", "y", "z", "qw", "qx", "qy", "qz"] {
                    q_names.push(format!("{jn}.{e}"));
                }
                for e in ["vx", "vy", "vz", "wx", "wy", "wz"] {
                    v_names.push(format!("{jn}.{e}"));
                }
            }
        }
        self.joints.push(Joint {
            name: jn.to_string(),
            body: b,
            kind,
            anchor: Vector3::from(js.anchor),
            stiffness: js.stiffness,
            spring_ref: js.spring_ref,
            damping: js.damping,
            armature: js.armature,
            reference: js.reference,
            iq: self.nq,
            iv: self.nv,
            nq: jnq,
            nv: jnv,
        });
        self.nq += jnq;
        self.nv += jnv;
        Ok(())
    }

    /// The links of body `s` (validated as `body`): one per joint (the first placed, the last
    /// carrying the inertia), or one fixed link.
    fn add_links(&mut self, s: &BodySpec, body: &Body) {
        let (rot, pos, com, inertia) = (body.rot, body.pos, body.com, body.inertia);
        let j0 = body.joints.start;
        let links = &mut self.links;
        let parent_link = body.parent.map(|p| self.body_link[p]);
        let place = if matches!(s.joints.first().map(|j| &j.kind), Some(JointType::Free)) {
            Xform::identity() // q of the free joint is the world pose
        } else {
            Xform::from_pose(rot, pos)
        };
        let inertia6 = if s.massless {
            None
        } else {
            Some(Inertia::from_com(s.mass, com, inertia))
        };
        let nj = s.joints.len();
        if nj == 0 {
            links.push(Link {
                parent: parent_link,
                place,
                joint: None,
                inertia: inertia6,
            });
        } else {
            for k in 0..nj {
                let par = if k == 0 {
                    parent_link
                } else {
                    Some(links.len() - 1)
                };
                links.push(Link {
                    parent: par,
                    place: if k == 0 { place } else { Xform::identity() },
                    joint: Some(j0 + k),
                    inertia: if k + 1 == nj { inertia6 } else { None },
                });
            }
        }
        self.body_link.push(links.len() - 1);
    }
}

impl Model {
    /// Validate and build. Bodies must be listed parents first; names of bodies and joints must be
    /// unique and not [`WORLD`].
    pub fn new(specs: &[BodySpec], fields: Fields) -> Result<Model, ModelError> {
        check_fields(&fields)?;
        let mut m = ModelBuilder {
            bodies: Vec::with_capacity(specs.len()),
            body_link: Vec::with_capacity(specs.len()),
            ..ModelBuilder::default()
        };
        for s in specs {
            m.add_body(s)?;
        }
        check_rigid_bodies(&m.bodies, &m.links, &m.body_link)?;
        let folded = fold_welded(&m.links, &m.body_link);
        let (dof_parent, dof_link) = dof_tree(&folded.links, &m.joints, m.nv);
        Ok(Model {
            bodies: m.bodies,
            joints: m.joints,
            links: folded.links,
            body_link: folded.body_link,
            body_offset: folded.body_offset,
            dof_parent,
            dof_link,
            fields,
            nq: m.nq,
            nv: m.nv,
            q_names: m.q_names,
            v_names: m.v_names,
        })
    }

    /// Number of configuration coordinates.
    pub fn nq(&self) -> usize {
        self.nq
    }
    /// Number of velocity coordinates (degrees of freedom).
    pub fn nv(&self) -> usize {
        self.nv
    }
    pub fn bodies(&self) -> &[Body] {
        &self.bodies
    }
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }
    pub fn fields(&self) -> &Fields {
        &self.fields
    }
    /// Index of a body by name.
    pub fn body_id(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }
    /// Index of a joint by name.
    pub fn joint_id(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }
    /// Range of joint `j`'s entries in q.
    pub fn joint_q_range(&self, j: usize) -> Range<usize> {
        let jt = &self.joints[j];
        jt.iq..jt.iq + jt.nq
    }
    /// Range of joint `j`'s entries in v.
    pub fn joint_v_range(&self, j: usize) -> Range<usize> {
        let jt = &self.joints[j];
        jt.iv..jt.iv + jt.nv
    }
    /// Names of the q entries: hinge/slide `name`; ball `name.qw, name.qx, name.qy, name.qz`;
    /// free `name.x, name.y, name.z, name.qw, name.qx, name.qy, name.qz`.
    pub fn q_names(&self) -> &[String] {
        &self.q_names
    }
    /// Names of the v entries: hinge/slide `name`; ball `name.wx, name.wy, name.wz` (body frame);
    /// free `name.vx, name.vy, name.vz` (world) then `name.wx, name.wy, name.wz` (body frame).
    pub fn v_names(&self) -> &[String] {
        &self.v_names
    }
    /// A workspace for this model over the scalar type `S`.
    pub fn data<S: crate::scalar::Scalar>(&self) -> super::TreeData<S> {
        super::TreeData::new(self)
    }
    /// The body whose link carries welded body `b` (its nearest ancestor with joints, or the first
    /// world-welded body of its chain) and b's placement in that body, `x_owner = R x_b + p` as
    /// (owner, R, p); `None` for a body that is its link's own.
    pub fn welded_into(&self, b: usize) -> Option<(usize, Matrix3<f64>, Vector3<f64>)> {
        let (r, p) = self.body_offset[b]?;
        let link = self.body_link[b];
        let owner = (0..self.bodies.len())
            .find(|&o| self.body_link[o] == link && self.body_offset[o].is_none())
            .expect("every link has its own body");
        Some((owner, r, p))
    }
    /// Whether any joint is a ball or free joint (q is then not a plain vector space chart).
    pub fn has_quaternions(&self) -> bool {
        self.joints
            .iter()
            .any(|j| matches!(j.kind, JointKind::Ball | JointKind::Free))
    }
}

/// The links after [`fold_welded`].
struct Folded {
    links: Vec<Link>,
    body_link: Vec<usize>,
    body_offset: Vec<Option<(Matrix3<f64>, Vector3<f64>)>>,
}

/// Fold every fixed link below a moving link into that link: its inertia joins the link's
/// (`X^T I X`, Featherstone Table 2.5, exact: a welded body moves with it) and its children hang
/// from the link with the placements composed. The passes (CRBA, RNEA, ABA, kinematics) then run
/// over the moving links only, as Pinocchio merges fixed joints into frames; a welded body is read
/// through its placement in the link. Fixed links on the world (no moving ancestor) stay.
fn fold_welded(links: &[Link], body_link: &[usize]) -> Folded {
    // per old link: its new link and ^old X_new (None: the link itself)
    let mut to: Vec<(usize, Option<Xform<f64>>)> = Vec::with_capacity(links.len());
    let mut out: Vec<Link> = Vec::with_capacity(links.len());
    for link in links {
        let parent = link.parent.map(|p| to[p]);
        match (link.joint, parent) {
            (None, Some((tp, xp))) => {
                let x = match xp {
                    Some(xp) => link.place.compose(&xp),
                    None => link.place,
                };
                if let Some(inr) = &link.inertia {
                    let moved = inr.transform_to_parent(&x);
                    let target = &mut out[tp].inertia;
                    *target = Some(target.map_or(moved, |t| t.add(&moved)));
                }
                to.push((tp, Some(x)));
            }
            _ => {
                let (parent, place) = match parent {
                    Some((tp, Some(xp))) => (Some(tp), link.place.compose(&xp)),
                    Some((tp, None)) => (Some(tp), link.place),
                    None => (None, link.place),
                };
                to.push((out.len(), None));
                out.push(Link {
                    parent,
                    place,
                    joint: link.joint,
                    inertia: link.inertia,
                });
            }
        }
    }
    Folded {
        links: out,
        body_link: body_link.iter().map(|&l| to[l].0).collect(),
        body_offset: body_link
            .iter()
            .map(|&l| to[l].1.map(|x| (x.e.transpose(), x.r)))
            .collect(),
    }
}

/// Tolerance of the inertia checks: moments within `INERTIA_RTOL * max(largest moment, mass * 1
/// m^2)` of zero are round-off (a symmetric eigen-solver errs by a few eps of the norm; the mass
/// term, a radius of gyration of 1 um, covers files that write 1e-20 for a point mass's zero).
pub const INERTIA_RTOL: f64 = 1e-12;

/// Inertia about the CoM: symmetric positive semi-definite (zero moments, e.g. a point mass or a
/// thin rod, are accepted; negative eigenvalues within [`INERTIA_RTOL`] are round-off).
fn check_inertia(i: &Matrix3<f64>, mass: f64) -> Result<(), String> {
    if i.iter().all(|x| *x == 0.0) {
        return Ok(());
    }
    let scale = i.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let tol = INERTIA_RTOL * scale;
    if (i - i.transpose()).iter().any(|x| x.abs() > tol) {
        return Err("inertia is not symmetric".into());
    }
    let e = i.symmetric_eigenvalues();
    let (lo, hi) = (e.min(), e.max());
    if lo < -INERTIA_RTOL * hi.max(mass) {
        return Err(format!(
            "inertia is not positive definite nor semi-definite (smallest eigenvalue {lo:e}, largest {hi:e})"
        ));
    }
    Ok(())
}

/// The principal moments of every rigid body (a body with joints, or the world, with the bodies
/// welded to it: a welded link is part of its parent's rigid body, its own inertia need not be
/// physical) satisfy the triangle inequality (A + B >= C for every permutation).
fn check_rigid_bodies(
    bodies: &[Body],
    links: &[Link],
    body_link: &[usize],
) -> Result<(), ModelError> {
    let mut comp: Vec<Inertia<f64>> = body_link
        .iter()
        .map(|&l| links[l].inertia.unwrap_or_else(Inertia::zero))
        .collect();
    let mut world = Inertia::zero();
    for b in (0..bodies.len()).rev() {
        if !bodies[b].joints.is_empty() {
            continue;
        }
        let moved = comp[b].transform_to_parent(&links[body_link[b]].place);
        match bodies[b].parent {
            Some(p) => comp[p] = comp[p].add(&moved),
            None => world = world.add(&moved),
        }
    }
    let first_welded = bodies
        .iter()
        .position(|b| b.parent.is_none() && b.joints.is_empty());
    let moving = (0..bodies.len()).filter(|&b| !bodies[b].joints.is_empty());
    for (b, c) in moving
        .map(|b| (b, comp[b]))
        .chain(first_welded.map(|b| (b, world)))
    {
        triangle(&c).map_err(|m| berr(&bodies[b].name, m))?;
    }
    Ok(())
}

/// The triangle inequality on the principal moments about the CoM of `c` (massless: none).
fn triangle(c: &Inertia<f64>) -> Result<(), String> {
    if c.m <= 0.0 {
        return Ok(());
    }
    let cx = super::spatial::skew(&(c.h / c.m));
    let ic = c.ibar + cx * cx * c.m;
    let e = (0.5 * (ic + ic.transpose())).symmetric_eigenvalues();
    let (a, b, cc) = (e[0], e[1], e[2]);
    let tol = INERTIA_RTOL * e.amax().max(c.m);
    if a + b < cc - tol || b + cc < a - tol || a + cc < b - tol {
        return Err(format!(
            "principal moments ({a}, {b}, {cc}) of the rigid body (with the bodies welded to it) violate the triangle inequality"
        ));
    }
    Ok(())
}
