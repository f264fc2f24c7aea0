//! URDF -> [`BodySpec`]s. One body per link, named as the link; the joint whose child a link is
//! becomes that body's placement (`origin` xyz, rpy) and joint (`axis`, in the joint frame):
//! revolute and continuous -> hinge, prismatic -> slide, fixed -> none (welded: the link keeps
//! its own frame and its inertia stays with it; the tree adds it to the parent's composite
//! inertia exactly), floating -> free. The root link is welded to the world or gets a free joint
//! (`root_joint`). Inertials: mass, the CoM `origin` and the inertia tensor rotated by the
//! origin's rpy into the link frame. `<dynamics damping>` is modelled (a viscous damper on the
//! joint, as in the tree model). Read and not modelled, one [`Unmodelled`] record per element
//! (kinds of [`super::unmodelled::KINDS`]): `<limit>` lower/upper (with the ranges), effort and
//! velocity, `<safety_controller>`, `<dynamics friction>`, `<mimic>`, links' `<collision>`,
//! `<transmission>`. Visuals, calibration and materials are not read (no dynamics).

use super::unmodelled::{JointRange, Recorder, Unmodelled};
use crate::input::MAX_BODIES;
use crate::located::{SceneError, Source};
use crate::tree::{BodySpec, JointSpec, WORLD};
use roxmltree::Node;
use std::collections::{HashMap, HashSet, VecDeque};

/// An imported robot.
#[derive(Clone, Debug)]
pub struct Robot {
    /// Bodies, parents first (link names; a root link named `world` is the world itself).
    pub bodies: Vec<BodySpec>,
    /// Coordinate (joint) names, in body order.
    pub joints: Vec<String>,
    /// Remarks on how the file was read (e.g. MJCF gravity replaced by the scene's), one line each.
    pub notes: Vec<String>,
    /// Every element read and not modelled (closed vocabulary of kinds).
    pub unmodelled: Vec<Unmodelled>,
    /// Position limits the file states for the (unlocked) hinge and slide joints.
    pub ranges: Vec<JointRange>,
    /// Locked joints with the value of q they are welded at.
    pub locked: Vec<(String, f64)>,
    /// MJCF `<keyframe>` keys by name (none in a URDF).
    pub keyframes: Vec<super::mjcf::Keyframe>,
    /// MJCF named `<site>`s (none in a URDF).
    pub sites: Vec<super::mjcf::Site>,
    /// Where each body's mass properties are written (URDF `<inertial>`, MJCF `<inertial>` or
    /// the element they come from), as an error located there: a check of the assembled tree
    /// (the triangle inequality of a rigid body) is reported at that line of the file.
    pub body_at: Vec<(String, SceneError)>,
    /// Geoms of static bodies whose mass progmo does not compute (an MJCF mesh: MuJoCo's mesh
    /// inertia is not modelled), as errors located at the geom: the motion does not need a static
    /// body's mass; the scene's `com.` signals do, and are refused with the first of these.
    pub mass_unknown: Vec<SceneError>,
    /// URDF `<mimic>` joints: follower = multiplier x leader + offset (none in an MJCF).
    pub mimics: Vec<Mimic>,
}

/// A URDF `<mimic>`: joint `joint` follows `leader` as q = multiplier q_leader + offset.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Mimic {
    pub joint: String,
    pub leader: String,
    pub multiplier: f64,
    pub offset: f64,
    /// Whether the follower is welded by `locked_joints`.
    pub locked: bool,
    /// The `<mimic>` element, as an error located there (a check of the scene is reported at it).
    #[serde(skip)]
    pub at: SceneError,
}

/// Body `name`'s place for errors of its mass properties: `n`, field `what`.
pub(crate) fn body_at(src: &Source, n: Node, name: &str, what: &str) -> (String, SceneError) {
    (name.to_string(), err(src, n, what, ""))
}

/// How the root link is attached to the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RootJoint {
    Fixed,
    /// A free joint named `root` (6 dof).
    Free,
}

/// Name of the free joint `RootJoint::Free` adds.
pub const ROOT_JOINT_NAME: &str = "root";

type R<T> = Result<T, SceneError>;

fn err(src: &Source, n: Node, what: &str, msg: impl Into<String>) -> SceneError {
    src.error(n.range(), what, msg)
}

/// `n`'s attribute parsed as k numbers (`default` when absent).
fn numbers<const K: usize>(
    src: &Source,
    n: Node,
    attr: &str,
    default: Option<[f64; K]>,
) -> R<[f64; K]> {
    let what = format!("<{}>.{attr}", n.tag_name().name());
    let Some(text) = n.attribute(attr) else {
        return default.ok_or_else(|| err(src, n, &what, format!("missing attribute `{attr}`")));
    };
    let vals: Vec<f64> = text
        .split_whitespace()
        .map(|s| s.parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| err(src, n, &what, format!("`{text}` is not a list of numbers")))?;
    let out: [f64; K] = vals
        .try_into()
        .map_err(|_| err(src, n, &what, format!("`{text}`: expected {K} numbers")))?;
    if out.iter().any(|x| !x.is_finite()) {
        return Err(err(src, n, &what, format!("`{text}` is not finite")));
    }
    Ok(out)
}

fn child<'a, 'i>(n: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    n.children().find(|c| c.is_element() && c.has_tag_name(tag))
}

/// Quaternion (w, x, y, z) of URDF roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll).
pub fn rpy_quat([r, p, y]: [f64; 3]) -> [f64; 4] {
    let (sr, cr) = (r / 2.0).sin_cos();
    let (sp, cp) = (p / 2.0).sin_cos();
    let (sy, cy) = (y / 2.0).sin_cos();
    [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]
}

fn rpy_matrix(rpy: [f64; 3]) -> nalgebra::Matrix3<f64> {
    let [w, x, y, z] = rpy_quat(rpy);
    nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z))
        .to_rotation_matrix()
        .into_inner()
}

/// `<origin xyz rpy>` of `n` (identity when absent).
fn origin(src: &Source, n: Node) -> R<([f64; 3], [f64; 3])> {
    match child(n, "origin") {
        None => Ok(([0.0; 3], [0.0; 3])),
        Some(o) => Ok((
            numbers(src, o, "xyz", Some([0.0; 3]))?,
            numbers(src, o, "rpy", Some([0.0; 3]))?,
        )),
    }
}

/// Where link `name`'s mass properties are written: its `<inertia>`, else `<inertial>`, else the link.
fn link_at(src: &Source, link: Node, name: &str) -> (String, SceneError) {
    let inertial = child(link, "inertial");
    match inertial.and_then(|i| child(i, "inertia")) {
        Some(n) => body_at(src, n, name, &format!("link[{name}].inertial.inertia")),
        None => match inertial {
            Some(i) => body_at(src, i, name, &format!("link[{name}].inertial")),
            None => body_at(src, link, name, &format!("link[{name}]")),
        },
    }
}

/// The body of a link: massless without `<inertial>` or with mass 0 and zero inertia. A link with
/// mass needs a positive semi-definite inertia; round-off negative eigenvalues are clipped to zero
/// (a note in `notes` names the link).
fn link_body(
    src: &Source,
    link: Node,
    name: &str,
    parent: &str,
    notes: &mut Vec<String>,
) -> R<BodySpec> {
    let Some(inertial) = child(link, "inertial") else {
        return Ok(BodySpec::massless(name, parent));
    };
    let what = format!("link[{name}].inertial");
    let mass_node = child(inertial, "mass")
        .ok_or_else(|| err(src, inertial, &what, "an <inertial> needs a <mass value>"))?;
    let [mass] = numbers::<1>(src, mass_node, "value", None)?;
    let inertia_node = child(inertial, "inertia");
    let i = match inertia_node {
        None => [0.0; 6],
        Some(n) => {
            let mut v = [0.0; 6];
            for (k, a) in ["ixx", "iyy", "izz", "ixy", "ixz", "iyz"]
                .iter()
                .enumerate()
            {
                v[k] = numbers::<1>(src, n, a, Some([0.0]))?[0];
            }
            v
        }
    };
    if i == [0.0; 6] && mass == 0.0 {
        return Ok(BodySpec::massless(name, parent));
    }
    // mass 0 with an inertia: the spatial inertia is still semi-definite (bolt's feet); whether the
    // motion is determined is A's rank check
    if mass < 0.0 || !mass.is_finite() {
        return Err(err(
            src,
            mass_node,
            &format!("{what}.mass"),
            format!("mass must be positive, or 0 (a massless link, or one with inertia only), got {mass}"),
        ));
    }
    let at = inertia_node.unwrap_or(inertial);
    let local = nalgebra::Matrix3::new(i[0], i[3], i[4], i[3], i[1], i[5], i[4], i[5], i[2]);
    let local =
        semi_definite(&local, mass).map_err(|m| err(src, at, &format!("{what}.inertia"), m))?;
    if let Some(lo) = local.1 {
        notes.push(format!(
            "link `{name}`: inertia eigenvalue {lo:e} (round-off) clipped to zero"
        ));
    }
    let (com, rpy) = origin(src, inertial)?;
    // Inertia about the CoM in the link frame: R I R^T with R the inertial origin's rotation.
    let r = rpy_matrix(rpy);
    let inertia = super::rotate_inertia(&r, &local.0);
    Ok(BodySpec::new(name, parent, mass, com, inertia))
}

/// A tensor with eigenvalues `>= -INERTIA_RTOL * max(largest, mass * 1 m^2)` with its negative
/// eigenvalues set to zero, and the smallest eigenvalue when it was clipped. The floor
/// `1e-12 * mass * 1 m^2` is the moment at a radius of gyration of 1 um, below any geometry a
/// URDF states (iCub writes `ixx="-5.42101e-20"` for a point mass of 0.526 kg).
type Clipped = (nalgebra::Matrix3<f64>, Option<f64>);

fn semi_definite(i: &nalgebra::Matrix3<f64>, mass: f64) -> Result<Clipped, String> {
    if i.iter().all(|x| *x == 0.0) {
        return Ok((*i, None));
    }
    let e = i.symmetric_eigen();
    let (lo, hi) = (e.eigenvalues.min(), e.eigenvalues.max());
    let tol = crate::tree::INERTIA_RTOL * hi.max(mass);
    if lo < -tol {
        return Err(format!(
            "the inertia tensor of a link with mass must be positive semi-definite: eigenvalue {lo:e} (largest {hi:e}; the round-off allowed is {tol:e})"
        ));
    }
    if lo >= 0.0 {
        return Ok((*i, None));
    }
    let d = nalgebra::Matrix3::from_diagonal(&e.eigenvalues.map(|x| x.max(0.0)));
    let m = e.eigenvectors * d * e.eigenvectors.transpose();
    Ok((0.5 * (m + m.transpose()), Some(lo)))
}

/// The kinematic loop above link `start` (every link on the way up has a parent joint), located
/// at a joint of the loop and naming its links in order.
fn loop_error(
    src: &Source,
    parent_joint: &HashMap<&str, Node>,
    start: &str,
    root: Option<&str>,
) -> SceneError {
    let parent_of = |l: &str| {
        child(parent_joint[l], "parent")
            .and_then(|n| n.attribute("link"))
            .unwrap_or("")
            .to_string()
    };
    // walk up until a link repeats: that link lies on the loop
    let mut on_path = HashSet::new();
    let mut l = start.to_string();
    while on_path.insert(l.clone()) {
        l = parent_of(&l);
    }
    let mut cycle = vec![l.clone()];
    let mut k = parent_of(&l);
    while k != l {
        cycle.push(k.clone());
        k = parent_of(&k);
    }
    cycle.reverse(); // parents first
    let names = cycle
        .iter()
        .map(|c| format!("`{c}`"))
        .collect::<Vec<_>>()
        .join(" -> ");
    let j = parent_joint[l.as_str()];
    let unreached = match root {
        Some(r) => format!(" (not reached from the root link `{r}`)"),
        None => " (every link has a parent: no root)".to_string(),
    };
    err(
        src,
        j,
        &format!("joint[{}]", j.attribute("name").unwrap_or("")),
        format!(
            "links {names} -> `{}` form a kinematic loop, which URDF trees cannot express{unreached}",
            cycle[0]
        ),
    )
}

/// Read a URDF document (`src` is the file and its text).
/// The xacro macro language (ROS) is not URDF: its first element or `${...}` / `$(...)` attribute
/// is refused with the command that expands the file.
fn refuse_xacro(src: &Source, robot: Node) -> R<()> {
    const XACRO: &str = "http://www.ros.org/wiki/xacro";
    let expand = "a xacro file, not URDF: expand it first (`xacro FILE.urdf.xacro > FILE.urdf`, ROS's xacro) and name the .urdf";
    for n in robot.descendants().filter(|n| n.is_element()) {
        if n.tag_name().namespace() == Some(XACRO) {
            let tag = format!("xacro:{}", n.tag_name().name());
            return Err(err(src, n, &tag, format!("<{tag}>: {expand}")));
        }
        if let Some(a) = n
            .attributes()
            .find(|a| a.value().contains("${") || a.value().contains("$("))
        {
            let (tag, name) = (n.tag_name().name(), a.name());
            return Err(err(
                src,
                n,
                &format!("{tag}.{name}"),
                format!("`{name}=\"{}\"` is a xacro expression: {expand}", a.value()),
            ));
        }
    }
    Ok(())
}

pub fn import(src: &Source, root_joint: RootJoint, locked: &[String]) -> R<Robot> {
    let doc = super::parse_xml(src)?;
    let robot = doc.root_element();
    if !robot.has_tag_name("robot") {
        return Err(err(
            src,
            robot,
            "robot",
            "the root element of a URDF file must be <robot>",
        ));
    }
    refuse_xacro(src, robot)?;
    let (links, link_order) = read_links(src, robot)?;
    let graph = read_joints(src, robot, &links)?;
    let root = find_root(src, robot, &links, &link_order, &graph.parent_joint)?;
    let mut w = Walk {
        notes: vec![],
        src,
        locked,
        used_locked: vec![false; locked.len()],
        bodies: vec![],
        joints: vec![],
        rec: Recorder::new(src),
        ranges: vec![],
        locked_values: vec![],
        body_at: vec![],
        mimics: vec![],
    };
    record_collisions(&mut w.rec, &links, &link_order);
    for t in robot.children().filter(|c| c.has_tag_name("transmission")) {
        let name = t.attribute("name").unwrap_or("");
        w.rec.push("actuator", format!("transmission[{name}]"), t);
    }
    // The root: a link named `world` without inertia is the world frame itself.
    let root_is_world = root == WORLD && child(links[root], "inertial").is_none();
    if !root_is_world {
        let mut b = link_body(src, links[root], root, WORLD, &mut w.notes)?;
        w.body_at.push(link_at(src, links[root], root));
        if root_joint == RootJoint::Free {
            b = b.joint(JointSpec::free(ROOT_JOINT_NAME));
            w.joints.push(ROOT_JOINT_NAME.to_string());
        }
        w.bodies.push(b);
    } else if root_joint == RootJoint::Free {
        return Err(err(
            src,
            links[root],
            "link[world]",
            "root_joint = \"free\" needs a root link other than `world`",
        ));
    }
    let mut queue: VecDeque<&str> = VecDeque::from([root]);
    let mut seen = 1usize;
    let mut reached: HashSet<&str> = HashSet::from([root]);
    while let Some(p) = queue.pop_front() {
        for j in graph.children.get(p).map(|v| v.as_slice()).unwrap_or(&[]) {
            let c = child(*j, "child")
                .and_then(|n| n.attribute("link"))
                .unwrap_or("");
            let parent = if p == root && root_is_world { WORLD } else { p };
            w.add_joint(*j, links[c], c, parent)?;
            seen += 1;
            reached.insert(c);
            queue.push_back(c);
        }
    }
    if seen < links.len() {
        // one parent each and one root: the links not reached form a loop (with what hangs on it)
        let start = link_order
            .iter()
            .copied()
            .find(|l| !reached.contains(l))
            .unwrap_or(root);
        return Err(loop_error(src, &graph.parent_joint, start, Some(root)));
    }
    if let Some(k) = w.used_locked.iter().position(|u| !u) {
        return Err(src.error(
            0..0,
            "locked_joints",
            format!("locked joint `{}` is not a joint of this file", locked[k]),
        ));
    }
    Ok(Robot {
        bodies: w.bodies,
        joints: w.joints,
        notes: w.notes,
        unmodelled: w.rec.out,
        ranges: w.ranges,
        locked: w.locked_values,
        keyframes: vec![],
        sites: vec![],
        body_at: w.body_at,
        mass_unknown: vec![],
        mimics: w.mimics,
    })
}

/// The `<link>` elements by name, and their names in file order.
type Links<'a, 'i> = (HashMap<&'a str, Node<'a, 'i>>, Vec<&'a str>);

/// The links of `robot`: named, at most [`MAX_BODIES`], each defined once.
fn read_links<'a, 'i>(src: &Source, robot: Node<'a, 'i>) -> R<Links<'a, 'i>> {
    let mut links: HashMap<&str, Node> = HashMap::new();
    let mut link_order = vec![];
    for l in robot.children().filter(|c| c.has_tag_name("link")) {
        let name = l
            .attribute("name")
            .ok_or_else(|| err(src, l, "link", "a <link> needs a name"))?;
        if link_order.len() == MAX_BODIES {
            return Err(err(
                src,
                l,
                &format!("link[{name}]"),
                format!("more than {MAX_BODIES} links (the limit of bodies of a model)"),
            ));
        }
        if links.insert(name, l).is_some() {
            return Err(err(
                src,
                l,
                &format!("link[{name}]"),
                format!("link `{name}` is defined twice"),
            ));
        }
        link_order.push(name);
    }
    Ok((links, link_order))
}

/// The joints as edges of the link tree.
struct JointGraph<'a, 'i> {
    /// The joint of each child link.
    parent_joint: HashMap<&'a str, Node<'a, 'i>>,
    /// The joints of each parent link, in file order.
    children: HashMap<&'a str, Vec<Node<'a, 'i>>>,
}

/// The joints of `robot`: named once each, between known links, one parent per link.
fn read_joints<'a, 'i>(
    src: &Source,
    robot: Node<'a, 'i>,
    links: &HashMap<&'a str, Node<'a, 'i>>,
) -> R<JointGraph<'a, 'i>> {
    // joint of each child link
    let mut parent_joint: HashMap<&str, Node> = HashMap::new();
    let mut children: HashMap<&str, Vec<Node>> = HashMap::new();
    let mut joint_names: HashSet<&str> = HashSet::new();
    for j in robot.children().filter(|c| c.has_tag_name("joint")) {
        let name = j
            .attribute("name")
            .ok_or_else(|| err(src, j, "joint", "a <joint> needs a name"))?;
        let what = format!("joint[{name}]");
        if !joint_names.insert(name) {
            return Err(err(
                src,
                j,
                &what,
                format!("joint `{name}` is defined twice"),
            ));
        }
        let link_of = |tag: &str| -> R<&str> {
            let n =
                child(j, tag).ok_or_else(|| err(src, j, &what, format!("missing <{tag} link>")))?;
            let l = n
                .attribute("link")
                .ok_or_else(|| err(src, n, &format!("{what}.{tag}"), "missing attribute `link`"))?;
            if !links.contains_key(l) {
                return Err(err(
                    src,
                    n,
                    &format!("{what}.{tag}"),
                    format!("unknown link `{l}`"),
                ));
            }
            Ok(l)
        };
        let (p, c) = (link_of("parent")?, link_of("child")?);
        if p == c {
            return Err(err(
                src,
                j,
                &what,
                format!("link `{c}` is both the parent and the child of joint `{name}`: a kinematic loop, which URDF trees cannot express"),
            ));
        }
        if let Some(first) = parent_joint.get(c) {
            return Err(err(
                src,
                j,
                &what,
                format!(
                    "link `{c}` has two parents (joints `{}` and `{name}`): a kinematic loop, which URDF trees cannot express",
                    first.attribute("name").unwrap_or("")
                ),
            ));
        }
        parent_joint.insert(c, j);
        children.entry(p).or_default().push(j);
    }
    Ok(JointGraph {
        parent_joint,
        children,
    })
}

/// The one link without a parent joint.
fn find_root<'a>(
    src: &Source,
    robot: Node,
    links: &HashMap<&'a str, Node>,
    link_order: &[&'a str],
    parent_joint: &HashMap<&str, Node>,
) -> R<&'a str> {
    let roots: Vec<&str> = link_order
        .iter()
        .copied()
        .filter(|l| !parent_joint.contains_key(l))
        .collect();
    match roots.as_slice() {
        [r] => Ok(*r),
        [] => Err(err(
            src,
            robot,
            "robot",
            if links.is_empty() {
                "no <link>".to_string()
            } else {
                return Err(loop_error(src, parent_joint, link_order[0], None));
            },
        )),
        many => Err(err(
            src,
            links[many[1]],
            &format!("link[{}]", many[1]),
            format!(
                "several root links ({}): a URDF describes one tree",
                many.join(", ")
            ),
        )),
    }
}

/// One `contact` record per `<collision>` of every link.
fn record_collisions(rec: &mut Recorder, links: &HashMap<&str, Node>, link_order: &[&str]) {
    for l in link_order {
        let collisions: Vec<Node> = links[l]
            .children()
            .filter(|c| c.has_tag_name("collision"))
            .collect();
        for (k, c) in collisions.iter().enumerate() {
            let element = match (collisions.len(), c.attribute("name")) {
                (_, Some(n)) => format!("link[{l}].collision[{n}]"),
                (1, None) => format!("link[{l}].collision"),
                (_, None) => format!("link[{l}].collision[{k}]"),
            };
            rec.push("contact", element, *c);
        }
    }
}

/// What the walk down the tree builds: bodies, coordinates, records, ranges and locked joints.
struct Walk<'s, 'l> {
    src: &'s Source,
    locked: &'l [String],
    used_locked: Vec<bool>,
    bodies: Vec<BodySpec>,
    joints: Vec<String>,
    rec: Recorder<'s>,
    ranges: Vec<JointRange>,
    locked_values: Vec<(String, f64)>,
    notes: Vec<String>,
    body_at: Vec<(String, SceneError)>,
    mimics: Vec<Mimic>,
}

impl Walk<'_, '_> {
    /// The body of link `c` (element `link`) placed by its joint `j` on `parent`.
    fn add_joint(&mut self, j: Node, link: Node, c: &str, parent: &str) -> R<()> {
        let src = self.src;
        let name = j.attribute("name").unwrap_or("");
        let what = format!("joint[{name}]");
        let (xyz, rpy) = origin(src, j)?;
        let mut b = link_body(src, link, c, parent, &mut self.notes)?
            .at(xyz)
            .rotated(rpy_quat(rpy));
        self.body_at.push(link_at(src, link, c));
        let kind = j
            .attribute("type")
            .ok_or_else(|| err(src, j, &what, "missing attribute `type`"))?;
        let is_locked = match self.locked.iter().position(|l| l == name) {
            Some(k) => {
                self.used_locked[k] = true;
                self.locked_values.push((name.to_string(), 0.0));
                true
            }
            None => false,
        };
        let specs = joint_spec(src, j, name, &what, kind)?;
        if let Some(m) = child(j, "mimic") {
            self.mimic(m, name, &what, kind, is_locked)?;
        }
        if !is_locked {
            let mut damping = None;
            for s in specs {
                let jname = s.name.clone();
                // a planar joint's three: the records and damping of its element once
                let s = match damping {
                    None => self.coordinate(j, name, &what, kind, s)?,
                    Some(d) => s.with_damping(d),
                };
                damping = Some(s.damping);
                b = b.joint(s);
                self.joints.push(jname);
            }
        }
        self.bodies.push(b);
        Ok(())
    }

    /// The joint of an unlocked coordinate: its name checked, its `<dynamics damping>`, and the
    /// records of what is read and not modelled (limits, safety controller, friction).
    fn coordinate(
        &mut self,
        j: Node,
        name: &str,
        what: &str,
        kind: &str,
        s: JointSpec,
    ) -> R<JointSpec> {
        let src = self.src;
        if let Some(why) = super::unusable_name(name) {
            return Err(err(src, j, what, format!("joint name `{name}` {why}")));
        }
        let mut s = s;
        if let Some(l) = child(j, "limit") {
            self.limit(l, name, what, kind)?;
        }
        if let Some(sc) = child(j, "safety_controller") {
            self.rec
                .push("joint_limit", format!("{what}.safety_controller"), sc);
        }
        if let Some(d) = child(j, "dynamics") {
            let [damping] = numbers::<1>(src, d, "damping", Some([0.0]))?;
            let [friction] = numbers::<1>(src, d, "friction", Some([0.0]))?;
            if damping < 0.0 {
                return Err(err(
                    src,
                    d,
                    &format!("{what}.dynamics.damping"),
                    format!("damping must be >= 0, got {damping}"),
                ));
            }
            s = s.with_damping(damping);
            if friction != 0.0 {
                self.rec
                    .push("frictionloss", format!("{what}.dynamics.friction"), d);
            }
        }
        Ok(s)
    }

    /// Joint `name`'s `<mimic joint multiplier offset>` (defaults 1 and 0) on a one-coordinate
    /// joint (revolute, continuous, prismatic); on a fixed joint it couples nothing and is skipped.
    fn mimic(&mut self, m: Node, name: &str, what: &str, kind: &str, locked: bool) -> R<()> {
        let src = self.src;
        let field = format!("{what}.mimic");
        let Some(leader) = m.attribute("joint") else {
            return Err(err(
                src,
                m,
                &field,
                "a <mimic> needs `joint`, the joint it follows",
            ));
        };
        if kind == "fixed" {
            return Ok(()); // no coordinate to couple (talos' gripper files): nothing follows
        }
        if !matches!(kind, "revolute" | "continuous" | "prismatic") {
            return Err(err(src, m, &field, format!("a `{kind}` joint cannot follow another (<mimic> couples one-coordinate joints)")));
        }
        let [multiplier] = numbers::<1>(src, m, "multiplier", Some([1.0]))?;
        let [offset] = numbers::<1>(src, m, "offset", Some([0.0]))?;
        // recorded too: a scene that declares `mimic` ignored keeps the joints independent
        self.rec.push("mimic", field.clone(), m);
        self.mimics.push(Mimic {
            joint: name.to_string(),
            leader: leader.to_string(),
            multiplier,
            offset,
            locked,
            at: err(src, m, &field, ""),
        });
        Ok(())
    }

    /// A joint's `<limit>`: the range of a revolute or prismatic joint, effort and velocity.
    fn limit(&mut self, l: Node, name: &str, what: &str, kind: &str) -> R<()> {
        let src = self.src;
        let bounded = kind == "revolute" || kind == "prismatic";
        if bounded && (l.attribute("lower").is_some() || l.attribute("upper").is_some()) {
            let [lower] = numbers::<1>(src, l, "lower", Some([0.0]))?;
            let [upper] = numbers::<1>(src, l, "upper", Some([0.0]))?;
            self.rec.push("joint_limit", format!("{what}.limit"), l);
            self.ranges.push(JointRange {
                joint: name.to_string(),
                lower,
                upper,
            });
        }
        if l.attribute("effort").is_some() {
            self.rec
                .push("effort_limit", format!("{what}.limit.effort"), l);
        }
        if l.attribute("velocity").is_some() {
            self.rec
                .push("velocity_limit", format!("{what}.limit.velocity"), l);
        }
        Ok(())
    }
}

/// The tree joints of URDF joint `j` of type `kind` (none: fixed). A `planar` joint moves in
/// the plane normal to its axis: slides along e1 and e2, then a hinge about the axis n, named
/// `NAME_TX`, `NAME_TY`, `NAME_RZ` as MuJoCo's URDF compiler names them, with (e1, e2, n) its
/// frame: the rotation taking z to n by the shortest arc (MuJoCo's `mju_quatZ2Vec`; n = -z:
/// half a turn about x), applied to x and y.
fn joint_spec(src: &Source, j: Node, name: &str, what: &str, kind: &str) -> R<Vec<JointSpec>> {
    let axis = || -> R<[f64; 3]> {
        let a = match child(j, "axis") {
            None => [1.0, 0.0, 0.0], // the URDF default
            Some(n) => numbers(src, n, "xyz", Some([1.0, 0.0, 0.0]))?,
        };
        if a.iter().map(|x| x * x).sum::<f64>() < 1e-24 {
            return Err(err(src, j, &format!("{what}.axis"), "the axis is zero"));
        }
        Ok(a)
    };
    Ok(match kind {
        "revolute" | "continuous" => vec![JointSpec::hinge(name, axis()?)],
        "prismatic" => vec![JointSpec::slide(name, axis()?)],
        "floating" => vec![JointSpec::free(name)],
        "fixed" => vec![],
        "planar" => {
            for part in ["_TX", "_TY", "_RZ"] {
                if let Some(why) = super::unusable_name(&format!("{name}{part}")) {
                    return Err(err(src, j, what, format!("joint name `{name}{part}` {why}")));
                }
            }
            let [e1, e2, n] = planar_frame(axis()?);
            vec![
                JointSpec::slide(&format!("{name}_TX"), e1),
                JointSpec::slide(&format!("{name}_TY"), e2),
                JointSpec::hinge(&format!("{name}_RZ"), n),
            ]
        }
        other => {
            return Err(err(
                src,
                j,
                &format!("{what}.type"),
                format!("unknown joint type `{other}`: expected revolute, continuous, prismatic, planar, fixed or floating"),
            ))
        }
    })
}

/// The frame (e1, e2, n) of a planar joint with axis `a` (nonzero): R x, R y and n = a / |a|,
/// R the shortest rotation taking z to n (half a turn about x when n = -z).
fn planar_frame(a: [f64; 3]) -> [[f64; 3]; 3] {
    use nalgebra::{Rotation3, Unit, Vector3};
    let n = Vector3::from(a).normalize();
    let cross = Vector3::z().cross(&n);
    let sin = cross.norm();
    let r = if sin < 1e-15 {
        if n.z < 0.0 {
            Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        } else {
            Rotation3::identity()
        }
    } else {
        Rotation3::from_axis_angle(&Unit::new_unchecked(cross / sin), sin.atan2(n.z))
    };
    let (e1, e2) = (r * Vector3::x(), r * Vector3::y());
    [[e1.x, e1.y, e1.z], [e2.x, e2.y, e2.z], [n.x, n.y, n.z]]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A planar joint's frame: (e1, e2, n) orthonormal and right-handed with n the axis; the
    /// slide axes MuJoCo 4.0's URDF compiler gives (its jnt_axis, measured): axis x -> e1 = -z,
    /// e2 = y; axis -z -> e1 = x, e2 = -y; axis (0, -1, 1) -> x, (0, 1, 1)/√2; axis z -> x, y.
    #[test]
    fn planar_frame_is_mujocos() {
        let close = |a: [f64; 3], b: [f64; 3]| {
            let d = (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f64::max);
            assert!(d < 1e-15, "{a:?} vs {b:?}");
        };
        let [e1, e2, n] = planar_frame([2.0, 0.0, 0.0]);
        close(e1, [0.0, 0.0, -1.0]);
        close(e2, [0.0, 1.0, 0.0]);
        close(n, [1.0, 0.0, 0.0]);
        let [e1, e2, _] = planar_frame([0.0, 0.0, -1.0]);
        close(e1, [1.0, 0.0, 0.0]);
        close(e2, [0.0, -1.0, 0.0]);
        let [e1, e2, _] = planar_frame([0.0, 0.0, 3.0]);
        close(e1, [1.0, 0.0, 0.0]);
        close(e2, [0.0, 1.0, 0.0]);
        let [e1, e2, n] = planar_frame([0.0, -1.0, 1.0]);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        close(e1, [1.0, 0.0, 0.0]);
        close(e2, [0.0, h, h]);
        let v = |a: [f64; 3]| nalgebra::Vector3::from(a);
        close(v(e1).cross(&v(e2)).into(), n);
        assert!((v(e1).dot(&v(n))).abs() < 1e-15 && (v(e2).dot(&v(n))).abs() < 1e-15);
    }

    /// rpy_quat against the product of the three axis rotations (URDF: fixed axes x, y, z).
    #[test]
    fn rpy_is_z_y_x() {
        use nalgebra::{Rotation3, Vector3};
        let (r, p, y) = (0.3, -1.1, 2.5);
        let m = Rotation3::from_axis_angle(&Vector3::z_axis(), y)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), p)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), r);
        let d = (rpy_matrix([r, p, y]) - m.into_inner()).abs().max();
        assert!(d < 4.0 * f64::EPSILON, "{d}");
        // negative control: the reversed order differs
        let wrong = Rotation3::from_axis_angle(&Vector3::x_axis(), r)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), p)
            * Rotation3::from_axis_angle(&Vector3::z_axis(), y);
        assert!((rpy_matrix([r, p, y]) - wrong.into_inner()).abs().max() > 0.1);
    }
}
