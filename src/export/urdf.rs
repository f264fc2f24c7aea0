//! URDF writer (for Pinocchio 4.1).

use super::{
    attractor_forces, check_options, children, esc, gravcomp_forces, num, nums, ArmatureExport,
    ClosureExport, Conversion, CoordMap, ExportError, ExportOptions, ExportReport, Format,
    HarnessForce, RootJoint,
};
use crate::tree::{JointType, Model};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use std::collections::{HashMap, HashSet};
use std::fmt::Write;

/// Same report type for both formats.
pub type UrdfReport = ExportReport;

/// Joint limits written on revolute/prismatic joints: wide open. `continuous` is not used because
/// Pinocchio maps it to `JointModelRevoluteUnbounded` (nq = 2: cos, sin).
const OPEN: f64 = 1e10;

type ChildJoints = HashMap<String, Vec<(String, String, Option<usize>)>>;

/// Depth-first joint order from link `l` (reached by our joint `j`), child joints by name.
/// Iterative: a chain of thousands of links must not exhaust the stack.
fn dfs(l: String, j: Option<usize>, map: &mut ChildJoints, order: &mut Vec<usize>) {
    let mut stack = vec![(l, j)];
    while let Some((l, j)) = stack.pop() {
        order.extend(j);
        let mut cj = map.remove(&l).unwrap_or_default();
        cj.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
        stack.extend(cj.into_iter().rev().map(|(_, c, cj)| (c, cj)));
    }
}

/// Fixed-axis roll, pitch, yaw of `r` (URDF: `R = Rz(yaw) Ry(pitch) Rx(roll)`).
pub(crate) fn rpy(r: &Matrix3<f64>) -> [f64; 3] {
    let c = (r[(0, 0)] * r[(0, 0)] + r[(1, 0)] * r[(1, 0)]).sqrt();
    let pitch = (-r[(2, 0)]).atan2(c);
    if c > 1e-9 {
        [
            r[(2, 1)].atan2(r[(2, 2)]),
            pitch,
            r[(1, 0)].atan2(r[(0, 0)]),
        ]
    } else {
        // gimbal lock: roll = 0, yaw from the upper-left block
        [0.0, pitch, (-r[(0, 1)]).atan2(r[(1, 1)])]
    }
}

/// URDF document for Pinocchio and its [`ExportReport`] (see the module doc for the policies:
/// chains of massless links, ball joints, free joints, gravity).
///
/// Pinocchio numbers the joints depth-first from the root link, the child joints of a link in
/// byte order of their names (urdfdom keeps joints in a name-sorted map); fixed joints add no
/// coordinates. The maps in the report follow that order and reorder quaternions to Pinocchio's
/// (x, y, z, w). Springs, dampers and gravity compensation are not part of URDF dynamics: they
/// are listed as [`HarnessForce`]s; armature in [`ExportReport::armature`]; reference positions
/// are folded into the joint origins.
pub fn urdf(tree: &Model, options: &ExportOptions) -> Result<(String, UrdfReport), ExportError> {
    urdf_closed(tree, &[], options)
}

/// [`urdf`] with the sites of loop closures (see [`ClosureExport`]): each site is a massless link
/// `site` on a fixed joint `{site}__fixed` (a frame in Pinocchio; no coordinates), placed in its
/// body's link frame; the harness closes the loops with Pinocchio constraint models.
pub fn urdf_closed(
    tree: &Model,
    closures: &[ClosureExport],
    options: &ExportOptions,
) -> Result<(String, UrdfReport), ExportError> {
    check_options(options)?;
    let bodies = tree.bodies();
    let joints = tree.joints();
    let mut u = Urdf {
        tree,
        root_ball: root_ball(tree)?,
        link_names: HashSet::new(),
        joint_names: HashSet::new(),
    };
    // Names: links and joints must be unique.
    if u.root_ball.is_none() {
        u.link_names.insert("world".to_string());
    }

    // Elements in our body order (URDF elements are unordered).
    let mut links = String::new();
    let mut ujoints = String::new();
    // URDF child joints per link name: (joint name, child link, Some(our joint) or None if fixed)
    let mut child_joints: ChildJoints = HashMap::new();
    let mut harness_forces = attractor_forces(tree);
    harness_forces.extend(gravcomp_forces(tree));
    let mut armature = vec![];
    for b in 0..bodies.len() {
        u.write_links(b, &mut links)?;
        u.write_joints(b, &mut ujoints, &mut child_joints)?;
    }

    // Pinocchio's joint order: DFS from the root link, child joints sorted by name.
    let root_link = match u.root_ball {
        Some(j) => u.link_of(joints[j].body, 0),
        None => "world".to_string(),
    };
    let mut order: Vec<usize> = u.root_ball.into_iter().collect();
    dfs(root_link, None, &mut child_joints, &mut order);
    let (qmap, vmap) = coord_maps(tree, &order, &mut harness_forces, &mut armature);

    let mut x = String::new();
    let _ = writeln!(x, "<?xml version=\"1.0\"?>");
    let _ = writeln!(x, "<robot name=\"{}\">", esc(&options.name));
    if u.root_ball.is_none() {
        let _ = writeln!(x, "  <link name=\"world\"/>");
    }
    x.push_str(&links);
    x.push_str(&ujoints);
    u.write_sites(&mut x, closures)?;
    let _ = writeln!(x, "</robot>");

    let (notes, root_joint) = notes_and_root_joint(tree, u.root_ball);
    let report = ExportReport {
        format: Format::Urdf,
        mass_changes: vec![],
        harness_forces,
        q_map: qmap
            .into_iter()
            .map(|m| m.expect("every joint is mapped"))
            .collect(),
        v_map: vmap
            .into_iter()
            .map(|m| m.expect("every joint is mapped"))
            .collect(),
        gravity: tree.fields().gravity,
        root_joint,
        notes,
        closures: closures.to_vec(),
        armature,
    };
    Ok((x, report))
}

fn unsupported(what: String) -> ExportError {
    ExportError::Unsupported {
        format: Format::Urdf,
        what,
    }
}

fn collide(name: &str) -> ExportError {
    ExportError::NameCollision {
        format: Format::Urdf,
        name: name.to_string(),
    }
}

/// The ball joint exported as the URDF root, if any.
///
/// Ball joints: only as the root joint (first joint of the only child of the world, centred at
/// the world origin, body unrotated) since Pinocchio places a root joint at the identity.
fn root_ball(tree: &Model) -> Result<Option<usize>, ExportError> {
    let bodies = tree.bodies();
    let n = bodies.len();
    let ch = children(tree);
    let mut root_ball: Option<usize> = None;
    for (j, jt) in tree.joints().iter().enumerate() {
        if jt.joint_type() != JointType::Ball {
            continue;
        }
        let b = &bodies[jt.body];
        let first = b.joints.start == j;
        let only = b.parent.is_none() && ch[n].len() == 1;
        let centre = b.pos + b.rot * jt.anchor;
        let unrotated =
            (b.quat[0] - 1.0).abs() <= 1e-15 && b.quat[1..].iter().all(|c| c.abs() <= 1e-15);
        if first && only && centre.norm() <= 1e-15 && unrotated {
            root_ball = Some(j);
        } else {
            return Err(unsupported(format!(
                "ball joint '{}' of body '{}': URDF has no spherical joint; only a ball joint \
                 that is the first joint of the only child of the world, centred at the origin \
                 (pos + R anchor = 0) with an unrotated body, can be exported (as Pinocchio root \
                 joint JointModelSpherical)",
                jt.name, b.name
            )));
        }
    }
    Ok(root_ball)
}

/// What the writers of one URDF document share: the tree, its root ball joint and the names
/// given so far (links and joints must be unique).
struct Urdf<'t> {
    tree: &'t Model,
    root_ball: Option<usize>,
    link_names: HashSet<String>,
    joint_names: HashSet<String>,
}

impl Urdf<'_> {
    /// Effective anchor of a joint: hinge/ball rotate about it, slides/free have none.
    fn anchor(&self, j: usize) -> Vector3<f64> {
        let joints = self.tree.joints();
        match joints[j].joint_type() {
            JointType::Hinge { .. } | JointType::Ball => joints[j].anchor,
            _ => Vector3::zeros(),
        }
    }

    /// Link frame of a body = body frame translated by the anchor of its last joint.
    fn off(&self, b: usize) -> Vector3<f64> {
        let r = self.tree.bodies()[b].joints.clone();
        if r.is_empty() {
            Vector3::zeros()
        } else {
            self.anchor(r.end - 1)
        }
    }

    /// Name of link `k` of body `b`: the body's name for its last link.
    fn link_of(&self, b: usize, k: usize) -> String {
        let body = &self.tree.bodies()[b];
        if body.joints.is_empty() || k + 1 == body.joints.len() {
            body.name.clone()
        } else {
            format!(
                "{}__{}",
                body.name,
                self.tree.joints()[body.joints.start + k].name
            )
        }
    }

    /// The links of body `b`: one per joint (at least one), the last with the body's inertia.
    fn write_links(&mut self, b: usize, links: &mut String) -> Result<(), ExportError> {
        let body = &self.tree.bodies()[b];
        let nlinks = body.joints.len().max(1);
        for k in 0..nlinks {
            let lname = self.link_of(b, k);
            if !self.link_names.insert(lname.clone()) {
                return Err(collide(&lname));
            }
            let _ = write!(links, "  <link name=\"{}\">", esc(&lname));
            if k + 1 == nlinks && !body.massless {
                let i = &body.inertia;
                let c = body.com - self.off(b);
                let _ = write!(
                    links,
                    "\n    <inertial>\n      <origin xyz=\"{}\" rpy=\"0 0 0\"/>\n      \
                     <mass value=\"{}\"/>\n      <inertia ixx=\"{}\" ixy=\"{}\" ixz=\"{}\" \
                     iyy=\"{}\" iyz=\"{}\" izz=\"{}\"/>\n    </inertial>\n  ",
                    nums(c.as_slice()),
                    num(body.mass),
                    num(i[(0, 0)]),
                    num(i[(0, 1)]),
                    num(i[(0, 2)]),
                    num(i[(1, 1)]),
                    num(i[(1, 2)]),
                    num(i[(2, 2)])
                );
            }
            let _ = writeln!(links, "</link>");
        }
        Ok(())
    }

    /// The joints of body `b` (a fixed one if it has none), each entered in `child_joints`.
    fn write_joints(
        &mut self,
        b: usize,
        ujoints: &mut String,
        child_joints: &mut ChildJoints,
    ) -> Result<(), ExportError> {
        let body = &self.tree.bodies()[b];
        let joints = self.tree.joints();
        let nj = body.joints.len();
        let nlinks = nj.max(1);
        let parent_link = match body.parent {
            None => "world".to_string(),
            Some(p) => self.tree.bodies()[p].name.clone(),
        };
        for k in 0..nlinks {
            let j = body.joints.start + k;
            if Some(j) == self.root_ball {
                continue; // the root joint, passed by the harness
            }
            let plink = if k == 0 {
                parent_link.clone()
            } else {
                self.link_of(b, k - 1)
            };
            let clink = self.link_of(b, k);
            let (xyz, rot) = self.joint_origin(b, k);
            let jname = if nj == 0 {
                format!("{}__fixed", body.name)
            } else {
                joints[j].name.clone()
            };
            if !self.joint_names.insert(jname.clone()) {
                return Err(collide(&jname));
            }
            let (ty, extra) = if nj == 0 {
                ("fixed", String::new())
            } else {
                joint_type(&joints[j])
            };
            let _ = writeln!(
                ujoints,
                "  <joint name=\"{}\" type=\"{ty}\">\n    <parent link=\"{}\"/>\n    \
                 <child link=\"{}\"/>\n    <origin xyz=\"{}\" rpy=\"{}\"/>{extra}\n  </joint>",
                esc(&jname),
                esc(&plink),
                esc(&clink),
                nums(xyz.as_slice()),
                nums(&rpy(&rot))
            );
            child_joints
                .entry(plink)
                .or_default()
                .push((jname, clink, (nj > 0).then_some(j)));
        }
        Ok(())
    }

    /// The `<origin>` of the joint of link `k` of body `b`, the reference position folded in.
    fn joint_origin(&self, b: usize, k: usize) -> (Vector3<f64>, Matrix3<f64>) {
        let body = &self.tree.bodies()[b];
        let joints = self.tree.joints();
        let nj = body.joints.len();
        let j = body.joints.start + k;
        let parent_off = match body.parent {
            None => Vector3::zeros(),
            Some(p) => self.off(p),
        };
        // origin = T(-off_parent) P T(a_0) for the first joint, T(a_k - a_{k-1}) after.
        let (mut xyz, mut rot) = if nj == 0 {
            (body.pos - parent_off, body.rot)
        } else if k == 0 {
            if joints[j].joint_type() == JointType::Free {
                // q of a free joint is the world pose of the body: identity placement
                (-parent_off, Matrix3::identity())
            } else {
                (body.pos + body.rot * self.anchor(j) - parent_off, body.rot)
            }
        } else {
            (self.anchor(j) - self.anchor(j - 1), Matrix3::identity())
        };
        // reference position: J(q - ref) = J(-ref) J(q) (same axis), J(-ref) into the origin
        if nj > 0 && joints[j].reference != 0.0 {
            let r = joints[j].reference;
            match joints[j].joint_type() {
                JointType::Hinge { axis } => {
                    let u = nalgebra::Unit::new_normalize(Vector3::from(axis));
                    rot *= nalgebra::Rotation3::from_axis_angle(&u, -r).into_inner();
                }
                JointType::Slide { axis } => xyz -= rot * Vector3::from(axis) * r,
                _ => unreachable!("the model refuses ref on ball and free joints"),
            }
        }
        (xyz, rot)
    }

    /// Closure sites: massless links on fixed joints, in the link frame of their body.
    fn write_sites(
        &mut self,
        x: &mut String,
        closures: &[ClosureExport],
    ) -> Result<(), ExportError> {
        for c in closures {
            let sides = [
                (&c.site_a, Some(&c.body_a), c.point_a, c.quat_a),
                (&c.site_b, c.body_b.as_ref(), c.point_b, c.quat_b),
            ];
            for (site, body, point, quat) in sides {
                let (parent, xyz) = match body {
                    Some(name) => {
                        let b = self.tree.body_id(name).ok_or_else(|| {
                            unsupported(format!("closure body '{name}' is not in the tree"))
                        })?;
                        (name.clone(), Vector3::from(point) - self.off(b))
                    }
                    None if self.root_ball.is_none() => ("world".to_string(), Vector3::from(point)),
                    None => continue, // no world link: the harness takes the report's point
                };
                if !self.link_names.insert(site.clone()) {
                    return Err(collide(site));
                }
                let jname = format!("{site}__fixed");
                if !self.joint_names.insert(jname.clone()) {
                    return Err(collide(&jname));
                }
                let r = UnitQuaternion::from_quaternion(Quaternion::new(
                    quat[0], quat[1], quat[2], quat[3],
                ))
                .to_rotation_matrix()
                .into_inner();
                let _ = writeln!(
                    x,
                    "  <link name=\"{}\"/>\n  <joint name=\"{}\" type=\"fixed\">\n    \
                     <parent link=\"{}\"/>\n    <child link=\"{}\"/>\n    \
                     <origin xyz=\"{}\" rpy=\"{}\"/>\n  </joint>",
                    esc(site),
                    esc(&jname),
                    esc(&parent),
                    esc(site),
                    nums(xyz.as_slice()),
                    nums(&rpy(&r))
                );
            }
        }
        Ok(())
    }
}

/// URDF type of a moving joint and what follows its `<origin>` (axis and wide-open limits).
fn joint_type(jt: &crate::tree::Joint) -> (&'static str, String) {
    let lim = format!(
        "\n    <limit lower=\"{}\" upper=\"{}\" effort=\"{}\" velocity=\"{}\"/>",
        num(-OPEN),
        num(OPEN),
        num(OPEN),
        num(OPEN)
    );
    match jt.joint_type() {
        JointType::Hinge { axis } => (
            "revolute",
            format!("\n    <axis xyz=\"{}\"/>{lim}", nums(&axis)),
        ),
        JointType::Slide { axis } => (
            "prismatic",
            format!("\n    <axis xyz=\"{}\"/>{lim}", nums(&axis)),
        ),
        JointType::Free => ("floating", String::new()),
        JointType::Ball => unreachable!("checked above"),
    }
}

/// Our q and v entries -> Pinocchio's, joints in Pinocchio's `order`; the springs and dampers
/// (harness forces) and armature of those joints at their simulator offsets.
fn coord_maps(
    tree: &Model,
    order: &[usize],
    harness_forces: &mut Vec<HarnessForce>,
    armature: &mut Vec<ArmatureExport>,
) -> (Vec<Option<CoordMap>>, Vec<Option<CoordMap>>) {
    let joints = tree.joints();
    let mut qmap: Vec<Option<CoordMap>> = vec![None; tree.nq()];
    let mut vmap: Vec<Option<CoordMap>> = vec![None; tree.nv()];
    let (mut sq, mut sv) = (0usize, 0usize);
    for &j in order {
        let jt = &joints[j];
        // (our offset, simulator offset, conversion) per q and v entry
        let (qperm, vconv): (Vec<usize>, Vec<Conversion>) = match jt.joint_type() {
            JointType::Hinge { .. } | JointType::Slide { .. } => (vec![0], vec![Conversion::Same]),
            // ours (w, x, y, z) -> Pinocchio (x, y, z, w)
            JointType::Ball => (vec![3, 0, 1, 2], vec![Conversion::Same; 3]),
            // ours (x, y, z, w, qx, qy, qz) -> Pinocchio (x, y, z, qx, qy, qz, w); linear velocity
            // world-frame (ours) vs local (JointModelFreeFlyer)
            JointType::Free => (
                vec![0, 1, 2, 6, 3, 4, 5],
                [[Conversion::BodyFrame; 3], [Conversion::Same; 3]].concat(),
            ),
        };
        for (k, &s) in qperm.iter().enumerate() {
            qmap[jt.iq + k] = Some(CoordMap {
                index: jt.iq + k,
                name: tree.q_names()[jt.iq + k].clone(),
                sim_index: sq + s,
                sim_joint: jt.name.clone(),
                conversion: Conversion::Same,
            });
        }
        for (k, c) in vconv.iter().enumerate() {
            vmap[jt.iv + k] = Some(CoordMap {
                index: jt.iv + k,
                name: tree.v_names()[jt.iv + k].clone(),
                sim_index: sv + k,
                sim_joint: jt.name.clone(),
                conversion: *c,
            });
        }
        if jt.stiffness != 0.0 {
            harness_forces.push(HarnessForce::Spring {
                joint: jt.name.clone(),
                stiffness: jt.stiffness,
                spring_ref: jt.spring_ref,
                sim_q: sq,
                sim_v: sv,
            });
        }
        if jt.armature != 0.0 {
            armature.push(ArmatureExport {
                joint: jt.name.clone(),
                armature: jt.armature,
                sim_v: sv,
                nv: jt.nv,
            });
        }
        if jt.damping != 0.0 {
            harness_forces.push(HarnessForce::Damper {
                joint: jt.name.clone(),
                damping: jt.damping,
                sim_v: sv,
                nv: jt.nv,
            });
        }
        sq += jt.nq;
        sv += jt.nv;
    }
    (qmap, vmap)
}

/// The report's notes and the root joint the harness passes (the root ball joint, if any).
fn notes_and_root_joint(
    tree: &Model,
    root_ball: Option<usize>,
) -> (Vec<String>, Option<RootJoint>) {
    let mut notes = vec![
        "gravity is not part of URDF: set model.gravity.linear = report.gravity".to_string(),
        "quaternions in Pinocchio qpos are (x, y, z, w); the q map reorders them".to_string(),
        "massless intermediate links {body}__{joint} carry the joints of multi-joint bodies"
            .to_string(),
    ];
    if tree
        .joints()
        .iter()
        .any(|j| j.joint_type() == JointType::Free)
    {
        notes.push(
            "free joint: Pinocchio's linear velocity/force are body-frame (R^T v_world)".into(),
        );
    }
    let root_joint = root_ball.map(|j| {
        notes.push(
            "load with pin.buildModelFromUrdf(path, root_joint.python, root_joint.name)".into(),
        );
        RootJoint {
            python: "pin.JointModelSpherical()".into(),
            name: tree.joints()[j].name.clone(),
        }
    });
    (notes, root_joint)
}
