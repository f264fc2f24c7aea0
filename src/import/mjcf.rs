//! MJCF (MuJoCo XML) -> [`BodySpec`]s. One body per `<body>` of `<worldbody>`, named as the
//! body; `pos` and the orientation (`quat`, `axisangle`, `euler`, `xyaxes` or `zaxis`, with
//! `<compiler angle eulerseq>`: degrees and `xyz` by default, MuJoCo's XML reference "Frame
//! orientations") place it in its parent; its joints act in sequence after that placement, as in
//! MuJoCo and in [`crate::tree`]: hinge (axis through `pos`), slide, ball (centre `pos`), free.
//! Joint attributes may come from `<default>` classes (`class`, a body's `childclass`, nested
//! defaults inherit). Mass properties from an explicit `<inertial>` (`pos`, orientation, `mass`,
//! `diaginertia` or `fullinertia`) or, as MuJoCo's compiler does, from the primitive geoms
//! ([`super::geom_inertia`]) and mesh geoms ([`super::mesh`], files under `meshdir`), then
//! `boundmass`/`boundinertia`.
//! Modelled with MuJoCo's meaning: joint `damping`, `armature`, `springdamper` (hinge and slide,
//! [`spring_dampers`]), `stiffness` with `springref`
//! (hinge and slide), `ref` (hinge and slide; `ref` and `springref` of hinges in degrees under
//! `<compiler angle="degree">`, as MuJoCo converts them) and body `gravcomp`. Read and not
//! modelled, one [`Unmodelled`] record per element (kinds of [`super::unmodelled::KINDS`]): joint
//! limits (with their ranges), `actuatorfrcrange`, `frictionloss`, tendons, equality constraints,
//! colliding geoms and `<contact>` pairs/excludes, actuators, fluid options. Refused (located
//! errors): springs on ball and free joints, and what changes the stated model
//! (see [`compiler`]). Cameras, lights, sensors, textures and materials are not read (no
//! dynamics); of the assets only meshes are.
//! `<include>`s are expanded first, as MuJoCo does ([`super::include`]); `<frame>` and
//! `<replicate>` are resolved while walking the bodies ([`child_bodies`]); an `<attach>`ed
//! model's file is imported on its own and its subtree grafted ([`Walk::attach`]).

use super::geom_inertia::{self as gi, GeomMass, MassProps, Shape};
use super::mesh::{self, MeshInertia, MeshMass};
use super::unmodelled::{JointRange, Recorder, Unmodelled};
use super::urdf::Robot;
use crate::located::{SceneError, Source};
use crate::tree::{BodySpec, JointSpec, WORLD};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use roxmltree::Node;
use std::cell::RefCell;
use std::collections::{HashMap, HashSet};
use std::path::Path;

type R<T> = Result<T, SceneError>;

fn err(src: &Source, n: Node, what: &str, msg: impl Into<String>) -> SceneError {
    src.error(n.range(), what, msg)
}

fn elements<'a, 'i>(n: Node<'a, 'i>) -> impl Iterator<Item = Node<'a, 'i>> {
    n.children().filter(|c| c.is_element())
}

/// A list of numbers (any count), `None` when `text` is absent.
fn parse_list(src: &Source, n: Node, what: &str, attr: &str, text: &str) -> R<Vec<f64>> {
    let vals: Vec<f64> = text
        .split_whitespace()
        .map(|s| s.parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            err(
                src,
                n,
                what,
                format!("`{attr}=\"{text}\"` is not a list of numbers"),
            )
        })?;
    if vals.iter().any(|x| !x.is_finite()) {
        return Err(err(
            src,
            n,
            what,
            format!("`{attr}=\"{text}\"` is not finite"),
        ));
    }
    Ok(vals)
}

fn fixed<const K: usize>(src: &Source, n: Node, what: &str, attr: &str, text: &str) -> R<[f64; K]> {
    parse_list(src, n, what, attr, text)?
        .try_into()
        .map_err(|_| {
            err(
                src,
                n,
                what,
                format!("`{attr}=\"{text}\"`: expected {K} numbers"),
            )
        })
}

/// `n`'s attribute as K numbers (`default` when absent).
fn attr_k<const K: usize>(
    src: &Source,
    n: Node,
    what: &str,
    attr: &str,
    default: [f64; K],
) -> R<[f64; K]> {
    match n.attribute(attr) {
        None => Ok(default),
        Some(t) => fixed(src, n, what, attr, t),
    }
}

/// `<compiler>` settings that change how numbers are read.
struct Compiler {
    /// Angles of euler/axisangle (and ranges) in degrees (MuJoCo's default).
    degrees: bool,
    /// Euler sequence: lower case axes rotate with the frame, upper case are fixed.
    eulerseq: [u8; 3],
    /// `inertiafromgeom`: "auto" (default), "true" or "false".
    from_geom: String,
    /// `boundmass`, `boundinertia`: lower bounds of every body's mass and principal moments.
    boundmass: f64,
    boundinertia: f64,
    /// `inertiagrouprange`: the geom groups that count for inertia (MuJoCo's default 0 5).
    groups: [f64; 2],
    /// `settotalmass` (> 0: every body's mass and inertia scaled to this total; 0: off).
    totalmass: f64,
    /// `meshdir` (else `assetdir`): the folder of mesh files, relative to the main file's.
    meshdir: String,
    /// `strippath`: mesh file names reduced to their last component.
    strippath: bool,
    /// `fitaabb`: a primitive geom naming a mesh is fitted to its bounding box (refused), not
    /// to its equivalent inertia box.
    fitaabb: bool,
}

fn compiler(src: &Source, root: Node) -> R<Compiler> {
    let mut c = Compiler {
        degrees: true,
        eulerseq: *b"xyz",
        from_geom: "auto".into(),
        boundmass: 0.0,
        boundinertia: 0.0,
        groups: [0.0, 5.0],
        totalmass: 0.0,
        meshdir: String::new(),
        strippath: false,
        fitaabb: false,
    };
    for n in elements(root).filter(|n| n.has_tag_name("compiler")) {
        if let Some(a) = n.attribute("angle") {
            c.degrees = match a {
                "degree" => true,
                "radian" => false,
                _ => {
                    return Err(err(
                        src,
                        n,
                        "compiler.angle",
                        format!("`{a}`: expected degree or radian"),
                    ))
                }
            };
        }
        if let Some(s) = n.attribute("eulerseq") {
            let b = s.as_bytes();
            if b.len() != 3 || !b.iter().all(|c| b"xyzXYZ".contains(c)) {
                return Err(err(
                    src,
                    n,
                    "compiler.eulerseq",
                    format!("`{s}`: expected three of x, y, z, X, Y, Z"),
                ));
            }
            c.eulerseq = [b[0], b[1], b[2]];
        }
        if let Some(s) = n.attribute("inertiafromgeom") {
            if !["auto", "true", "false"].contains(&s) {
                return Err(err(
                    src,
                    n,
                    "compiler.inertiafromgeom",
                    format!("`{s}`: expected auto, true or false"),
                ));
            }
            c.from_geom = s.into();
        }
        bounds(src, n, &mut c)?;
        if let Some(d) = n.attribute("meshdir").or(n.attribute("assetdir")) {
            c.meshdir = d.into();
        }
        c.strippath = n
            .attribute("strippath")
            .map_or(c.strippath, |v| v == "true");
        c.fitaabb = n.attribute("fitaabb").map_or(c.fitaabb, |v| v == "true");
        if n.attribute("balanceinertia") == Some("true") {
            return Err(err(src, n, "compiler.balanceinertia", "`balanceinertia=\"true\"` (MuJoCo would change the stated inertias) is not supported"));
        }
        if n.attribute("coordinate").is_some_and(|v| v != "local") {
            return Err(err(
                src,
                n,
                "compiler.coordinate",
                "only local coordinates are supported",
            ));
        }
    }
    Ok(c)
}

/// `boundmass`, `boundinertia` (>= 0), `inertiagrouprange`, `settotalmass` (a total mass the
/// bodies are scaled to when > 0, [`scale_total_mass`]).
fn bounds(src: &Source, n: Node, c: &mut Compiler) -> R<()> {
    for a in ["boundmass", "boundinertia"] {
        if let Some(t) = n.attribute(a) {
            let v = fixed::<1>(src, n, &format!("compiler.{a}"), a, t)?[0];
            if v < 0.0 {
                return Err(err(
                    src,
                    n,
                    &format!("compiler.{a}"),
                    format!("`{a}` must be >= 0, got {v}"),
                ));
            }
            *(if a == "boundmass" {
                &mut c.boundmass
            } else {
                &mut c.boundinertia
            }) = v;
        }
    }
    if let Some(t) = n.attribute("inertiagrouprange") {
        c.groups = fixed::<2>(src, n, "compiler.inertiagrouprange", "inertiagrouprange", t)?;
    }
    if let Some(t) = n.attribute("settotalmass") {
        let v = fixed::<1>(src, n, "compiler.settotalmass", "settotalmass", t)?[0];
        c.totalmass = v.max(0.0); // MuJoCo: only a positive value rescales
    }
    Ok(())
}

/// `<compiler settotalmass="M">`, M > 0, as MuJoCo's compiler applies it after every body's mass
/// properties are known (geoms, `<inertial>`, bounds): each body's mass and inertia times
/// M / (the sum of the bodies' masses), the centres of mass unchanged.
fn scale_total_mass(src: &Source, root: Node, bodies: &mut [BodySpec], total: f64) -> R<()> {
    let sum: f64 = bodies.iter().map(|b| b.mass).sum();
    if !(sum > 0.0) {
        return Err(err(
            src,
            root,
            "compiler.settotalmass",
            format!("settotalmass=\"{total}\" on bodies without mass: nothing to scale"),
        ));
    }
    let k = total / sum;
    for b in bodies {
        b.mass *= k;
        for row in &mut b.inertia {
            for x in row {
                *x *= k;
            }
        }
    }
    Ok(())
}

/// The attributes that place a site (or a geom) in its body.
const PLACEMENT: [&str; 7] = [
    "pos",
    "quat",
    "axisangle",
    "euler",
    "xyaxes",
    "zaxis",
    "fromto",
];

/// A named `<site>`: a frame fixed in its body (the world for a `<worldbody>` site), which a scene
/// uses as a signal source ([`crate::scene`] adds it when its rows name it). `problem`: why it
/// cannot be one (a placement from `fromto` or from a default class), said only when it is used.
#[derive(Clone, Debug)]
pub struct Site {
    pub name: String,
    pub parent: String,
    pub pos: [f64; 3],
    pub quat: [f64; 4],
    pub problem: Option<SceneError>,
}

/// A `<key>` of the file's `<keyframe>`: per joint (MuJoCo's qpos order, locked ones too) its
/// position values (qpos: radians, quaternions w first, whatever `<compiler angle>` says) and its
/// velocity values (qvel: a free joint's world linear then body angular velocity, a ball's body
/// angular velocity: progmo's v).
#[derive(Clone, Debug, PartialEq)]
pub struct Keyframe {
    pub name: String,
    /// The file and line of the `<key>` (errors about it are located there).
    pub file: std::path::PathBuf,
    pub line: usize,
    pub joints: Vec<(String, Vec<f64>, Vec<f64>)>,
}

/// The named `<key>`s of the `<keyframe>` elements, as MuJoCo's compiler reads them: a qpos
/// shorter than the model's is completed with qpos0, a qvel with zeros; a longer one is refused.
/// `time`, `act`, `ctrl`, `mpos` and `mquat` are not read (no actuators, no mocap bodies).
fn keyframes(src: &Source, root: Node, layout: &[(String, Vec<f64>)]) -> R<Vec<Keyframe>> {
    let nq: usize = layout.iter().map(|(_, q0)| q0.len()).sum();
    let nv: usize = layout
        .iter()
        .map(|(_, q0)| q0.len() - usize::from(q0.len() >= 4))
        .sum();
    let mut out = vec![];
    for key in elements(root)
        .filter(|n| n.has_tag_name("keyframe"))
        .flat_map(elements)
        .filter(|n| n.has_tag_name("key"))
    {
        let Some(name) = key.attribute("name") else {
            continue; // an unnamed key cannot be chosen by name
        };
        let what = format!("keyframe[{name}]");
        let read = |attr: &str, n: usize| -> R<Vec<f64>> {
            let vals = match key.attribute(attr) {
                Some(t) => parse_list(src, key, &format!("{what}.{attr}"), attr, t)?,
                None => vec![],
            };
            if vals.len() > n {
                return Err(err(
                    src,
                    key,
                    &format!("{what}.{attr}"),
                    format!("{} values for a model with {attr} of size {n}", vals.len()),
                ));
            }
            Ok(vals)
        };
        let (qpos, qvel) = (read("qpos", nq)?, read("qvel", nv)?);
        let (mut iq, mut iv, mut joints) = (0, 0, vec![]);
        for (j, q0) in layout {
            let dv = q0.len() - usize::from(q0.len() >= 4);
            let q: Vec<f64> = (0..q0.len())
                .map(|k| qpos.get(iq + k).copied().unwrap_or(q0[k]))
                .collect();
            let v: Vec<f64> = (0..dv)
                .map(|k| qvel.get(iv + k).copied().unwrap_or(0.0))
                .collect();
            (iq, iv) = (iq + q0.len(), iv + dv);
            joints.push((j.clone(), q, v));
        }
        let at = key.range().start;
        out.push(Keyframe {
            name: name.to_string(),
            file: src.file_at(at).to_path_buf(),
            line: src.line_col(at).0,
            joints,
        });
    }
    Ok(out)
}

/// The file's keys followed by the `<attach>`ed models' (MuJoCo's order): an attached key gives
/// its model's joints their values there, every other joint its qpos0 and zero velocity, as MuJoCo
/// compiles it. A name used twice is refused at the second key.
fn attached_keyframes(
    src: &Source,
    root: Node,
    mut own: Vec<Keyframe>,
    attached: Vec<Keyframe>,
    layout: &[(String, Vec<f64>)],
) -> R<Vec<Keyframe>> {
    for mut k in attached {
        if let Some(first) = own.iter().find(|o| o.name == k.name) {
            // located at the file's own key of that name, if it is one (else the whole file)
            let node = elements(root)
                .filter(|n| n.has_tag_name("keyframe"))
                .flat_map(elements)
                .find(|n| n.has_tag_name("key") && n.attribute("name") == Some(&k.name));
            let what = format!("keyframe[{}]", k.name);
            return Err(match node {
                Some(n) => err(src, n, &what, format!("keyframe `{}` of an <attach>ed model ({}:{}) has the name of the key at {}:{}: give the <attach> a prefix", k.name, k.file.display(), k.line, first.file.display(), first.line)),
                None => src.error(0..0, &what, format!("keyframe `{}` of an <attach>ed model ({}:{}) has the name of another attached key ({}:{})", k.name, k.file.display(), k.line, first.file.display(), first.line)),
            });
        }
        let given: HashMap<String, (Vec<f64>, Vec<f64>)> =
            k.joints.drain(..).map(|(j, q, v)| (j, (q, v))).collect();
        k.joints = layout
            .iter()
            .map(|(j, q0)| {
                let (q, v) = given.get(j).cloned().unwrap_or_else(|| {
                    (q0.clone(), vec![0.0; q0.len() - usize::from(q0.len() >= 4)])
                });
                (j.clone(), q, v)
            })
            .collect();
        own.push(k);
    }
    Ok(own)
}

/// The `springdamper`s of the file's joints applied ([`spring_dampers`]); refused in an
/// `<attach>`ed file (its stiffness would need the whole model's mass matrix).
fn apply_spring_dampers(
    src: &Source,
    root: Node,
    locked: &[String],
    depth: usize,
    sd: &[(String, [f64; 2])],
    bodies: &mut [BodySpec],
) -> R<()> {
    if sd.is_empty() {
        return Ok(());
    }
    if depth > 0 {
        let j = &sd[0].0;
        return Err(src.error(0..0, &format!("joint[{j}].springdamper"), format!("joint `{j}` of an <attach>ed model has `springdamper`: its stiffness depends on the whole model's mass matrix, which is not computed for attached models; give stiffness and damping")));
    }
    // MuJoCo's qpos0 mass matrix is the file's, every joint free to move
    let full = if locked.is_empty() {
        bodies.to_vec()
    } else {
        import(src, &[])?.bodies
    };
    spring_dampers(src, root, &full, sd, bodies)
}

/// `springdamper="timeconst dampratio"` as MuJoCo's compiler applies it to a hinge or slide:
/// with m = 1 / (A(qpos0)^-1)_ii, the joint's effective mass in the file's model at qpos0
/// (MuJoCo's `dof_invweight0`, armature included), stiffness m / (timeconst^2 dampratio^2) and
/// damping 2 m / timeconst replace the stated ones (a mass-spring-damper of that time constant
/// and damping ratio). `full` is the file's model with no joint locked.
fn spring_dampers(
    src: &Source,
    root: Node,
    full: &[BodySpec],
    joints: &[(String, [f64; 2])],
    bodies: &mut [BodySpec],
) -> R<()> {
    use crate::tree;
    let at = |m: String| err(src, root, "joint.springdamper", m);
    let model = tree::Model::new(full, tree::Fields::default())
        .map_err(|e| at(format!("the model at qpos0 (for springdamper): {e}")))?;
    let q = tree::neutral(&model);
    let mut data = tree::TreeData::<f64>::new(&model);
    let n = model.nv();
    let mut a = nalgebra::DMatrix::zeros(n, n);
    tree::mass_matrix(&model, &mut data, q.as_slice(), &mut a);
    let Some(chol) = a.cholesky() else {
        return Err(at(
            "the mass matrix at qpos0 is singular: springdamper needs each joint's effective mass"
                .into(),
        ));
    };
    let inv = chol.inverse();
    for (name, [tc, dr]) in joints {
        let j = model.joint_id(name).expect("a joint of the file");
        let i = model.joint_v_range(j).start;
        let m = 1.0 / inv[(i, i)];
        for js in bodies.iter_mut().flat_map(|b| b.joints.iter_mut()) {
            if &js.name == name {
                js.stiffness = m / (tc * tc * dr * dr);
                js.damping = 2.0 * m / tc;
            }
        }
    }
    Ok(())
}

fn quat_of(u: UnitQuaternion<f64>) -> [f64; 4] {
    [u.w, u.i, u.j, u.k]
}

fn unit(src: &Source, n: Node, what: &str, v: [f64; 3], name: &str) -> R<Vector3<f64>> {
    let v = Vector3::from(v);
    let norm = v.norm();
    if norm < 1e-12 {
        return Err(err(src, n, what, format!("`{name}` is zero")));
    }
    Ok(v / norm)
}

/// The orientation of an element with a spatial frame (MuJoCo's "frame orientations": at most one
/// of quat, axisangle, euler, xyaxes, zaxis); (w, x, y, z), identity when none is given.
fn orientation(src: &Source, c: &Compiler, n: Node, what: &str) -> R<[f64; 4]> {
    let given: Vec<&str> = ["quat", "axisangle", "euler", "xyaxes", "zaxis"]
        .into_iter()
        .filter(|a| n.attribute(*a).is_some())
        .collect();
    let angle = |a: f64| if c.degrees { a.to_radians() } else { a };
    let q = match given.as_slice() {
        [] => return Ok([1.0, 0.0, 0.0, 0.0]),
        [_, _, ..] => {
            return Err(err(
                src,
                n,
                what,
                format!("more than one orientation given ({})", given.join(", ")),
            ))
        }
        ["quat"] => {
            let q = attr_k::<4>(src, n, what, "quat", [1.0, 0.0, 0.0, 0.0])?;
            let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm < 1e-12 {
                return Err(err(src, n, what, "`quat` is zero"));
            }
            return Ok(q.map(|x| x / norm));
        }
        ["axisangle"] => {
            let [x, y, z, a] = attr_k::<4>(src, n, what, "axisangle", [0.0; 4])?;
            let axis = unit(src, n, what, [x, y, z], "axisangle")?;
            UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_unchecked(axis), angle(a))
        }
        ["euler"] => {
            let e = attr_k::<3>(src, n, what, "euler", [0.0; 3])?;
            let mut q = UnitQuaternion::identity();
            for (k, &s) in c.eulerseq.iter().enumerate() {
                let axis = match s.to_ascii_lowercase() {
                    b'x' => Vector3::x_axis(),
                    b'y' => Vector3::y_axis(),
                    _ => Vector3::z_axis(),
                };
                let r = UnitQuaternion::from_axis_angle(&axis, angle(e[k]));
                // lower case: about the moving frame's axis (post-multiply); upper case: fixed
                q = if s.is_ascii_lowercase() { q * r } else { r * q };
            }
            q
        }
        ["xyaxes"] => {
            let v = attr_k::<6>(src, n, what, "xyaxes", [0.0; 6])?;
            let x = unit(src, n, what, [v[0], v[1], v[2]], "xyaxes")?;
            let y = Vector3::new(v[3], v[4], v[5]);
            let y = unit(src, n, what, (y - x * x.dot(&y)).into(), "xyaxes")?;
            let m = Matrix3::from_columns(&[x, y, x.cross(&y)]);
            UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(m))
        }
        _ => {
            let z = unit(
                src,
                n,
                what,
                attr_k::<3>(src, n, what, "zaxis", [0.0; 3])?,
                "zaxis",
            )?;
            UnitQuaternion::rotation_between(&Vector3::z(), &z).unwrap_or_else(|| {
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
            })
        }
    };
    Ok(quat_of(q))
}

/// `<default>` classes: class -> (parent class, its `<joint>` element, its `<geom>` element).
struct Defaults<'a, 'i> {
    classes: HashMap<String, DefaultClass<'a, 'i>>,
}

/// (parent class, its `<joint>`, `<geom>`, `<site>` and `<mesh>` defaults)
type DefaultClass<'a, 'i> = (
    Option<String>,
    Option<Node<'a, 'i>>,
    Option<Node<'a, 'i>>,
    Option<Node<'a, 'i>>,
    Option<Node<'a, 'i>>,
);

const MAIN: &str = "main";

impl<'a, 'i> Defaults<'a, 'i> {
    fn read(src: &Source, root: Node<'a, 'i>) -> R<Self> {
        let mut d = Defaults {
            classes: HashMap::new(),
        };
        for n in elements(root).filter(|n| n.has_tag_name("default")) {
            d.add(src, n, None)?;
        }
        Ok(d)
    }

    fn add(&mut self, src: &Source, n: Node<'a, 'i>, parent: Option<&str>) -> R<()> {
        let name = n
            .attribute("class")
            .unwrap_or(if parent.is_none() { MAIN } else { "" });
        if name.is_empty() {
            return Err(err(src, n, "default", "a nested <default> needs a class"));
        }
        if self.classes.contains_key(name) {
            return Err(err(
                src,
                n,
                &format!("default[{name}]"),
                format!("default class `{name}` is defined twice"),
            ));
        }
        let joint = elements(n).find(|c| c.has_tag_name("joint"));
        let geom = elements(n).find(|c| c.has_tag_name("geom"));
        let site = elements(n).find(|c| c.has_tag_name("site"));
        let mesh = elements(n).find(|c| c.has_tag_name("mesh"));
        self.classes.insert(
            name.to_string(),
            (parent.map(String::from), joint, geom, site, mesh),
        );
        for c in elements(n).filter(|c| c.has_tag_name("default")) {
            self.add(src, c, Some(name))?;
        }
        Ok(())
    }

    /// Attribute `attr` of joint `j` in class `class`: the element's own, else the class chain's.
    fn joint_attr(&self, j: Node<'a, 'i>, class: &str, attr: &str) -> Option<&'a str> {
        self.attr(j, class, attr, |d| d.1)
    }

    /// The same for a geom.
    fn geom_attr(&self, g: Node<'a, 'i>, class: &str, attr: &str) -> Option<&'a str> {
        self.attr(g, class, attr, |d| d.2)
    }

    /// The same for a `<mesh>` asset.
    fn mesh_attr(&self, m: Node<'a, 'i>, class: &str, attr: &str) -> Option<&'a str> {
        self.attr(m, class, attr, |d| d.4)
    }

    /// The placement attribute a `<site>` default of the class chain gives, if any.
    fn site_placement(&self, class: &str) -> Option<(&'a str, Node<'a, 'i>)> {
        let mut c = self.classes.get(class);
        while let Some(d) = c {
            if let Some(s) = d.3 {
                if let Some(a) = PLACEMENT.iter().find(|a| s.attribute(**a).is_some()) {
                    return Some((a, s));
                }
            }
            c = d.0.as_ref().and_then(|p| self.classes.get(p));
        }
        None
    }

    /// Geom `g` of class `class` and the `<geom>` defaults of the class chain, nearest first.
    fn geom_chain(&self, g: Node<'a, 'i>, class: &str) -> Vec<Node<'a, 'i>> {
        let mut out = vec![g];
        let mut c = self.classes.get(class);
        while let Some(d) = c {
            out.extend(d.2);
            c = d.0.as_ref().and_then(|p| self.classes.get(p));
        }
        out
    }

    fn attr(
        &self,
        e: Node<'a, 'i>,
        class: &str,
        attr: &str,
        pick: impl Fn(&DefaultClass<'a, 'i>) -> Option<Node<'a, 'i>>,
    ) -> Option<&'a str> {
        if let Some(v) = e.attribute(attr) {
            return Some(v);
        }
        let mut c = Some(class.to_string());
        while let Some(name) = c {
            let d = self.classes.get(&name)?;
            if let Some(v) = pick(d).and_then(|n| n.attribute(attr)) {
                return Some(v);
            }
            c = d.0.clone();
        }
        None
    }
}

/// An `<inertial>` element's mass properties in the body frame (`pos`, orientation, `mass`,
/// `diaginertia` or `fullinertia`).
fn explicit_inertial(src: &Source, c: &Compiler, n: Node, what: &str) -> R<MassProps> {
    let mass = match n.attribute("mass") {
        None => return Err(err(src, n, what, "an <inertial> needs `mass`")),
        Some(t) => fixed::<1>(src, n, &format!("{what}.mass"), "mass", t)?[0],
    };
    let pos = match n.attribute("pos") {
        None => return Err(err(src, n, what, "an <inertial> needs `pos`")),
        Some(t) => fixed::<3>(src, n, &format!("{what}.pos"), "pos", t)?,
    };
    let inertia = match (n.attribute("diaginertia"), n.attribute("fullinertia")) {
        (Some(t), None) => {
            let d = fixed::<3>(src, n, &format!("{what}.diaginertia"), "diaginertia", t)?;
            let r = rotation(orientation(src, c, n, what)?).to_rotation_matrix();
            let i = super::rotate_inertia(r.matrix(), &Matrix3::from_diagonal(&Vector3::from(d)));
            Matrix3::from(i) // symmetric: rows or columns alike
        }
        (None, Some(t)) => {
            let i = fixed::<6>(src, n, &format!("{what}.fullinertia"), "fullinertia", t)?;
            if orientation(src, c, n, what)? != [1.0, 0.0, 0.0, 0.0] {
                return Err(err(
                    src,
                    n,
                    what,
                    "fullinertia with an orientation: MuJoCo refuses it",
                ));
            }
            Matrix3::new(i[0], i[3], i[4], i[3], i[1], i[5], i[4], i[5], i[2])
        }
        (Some(_), Some(_)) => {
            return Err(err(src, n, what, "both diaginertia and fullinertia given"))
        }
        (None, None) => {
            return Err(err(
                src,
                n,
                what,
                "an <inertial> needs `diaginertia` or `fullinertia`",
            ))
        }
    };
    Ok(MassProps {
        mass,
        com: Vector3::from(pos),
        inertia,
    })
}

fn rotation(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// MuJoCo's `mjuu_z2quat`: the rotation taking z to `v` about z x v (about x when parallel).
fn z2quat(v: Vector3<f64>) -> UnitQuaternion<f64> {
    let v = v.normalize();
    let axis = Vector3::z().cross(&v);
    let s = axis.norm();
    let axis = if s < 1e-10 { Vector3::x() } else { axis / s };
    UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_unchecked(axis), s.atan2(v.z))
}

/// `props` checked and made a body: none or zero mass and inertia is a massless body; otherwise
/// the mass must be positive and the inertia positive definite (errors located at `n`).
fn body_spec(
    src: &Source,
    n: Node,
    what: &str,
    (name, parent): (&str, &str),
    props: Option<MassProps>,
) -> R<BodySpec> {
    let Some(p) = props else {
        return Ok(BodySpec::massless(name, parent));
    };
    if p.mass == 0.0 && p.inertia.iter().all(|x| *x == 0.0) {
        return Ok(BodySpec::massless(name, parent));
    }
    if p.mass <= 0.0 {
        return Err(err(
            src,
            n,
            &format!("{what}.mass"),
            format!(
                "mass must be positive (or 0 with zero inertia: a massless body), got {}",
                p.mass
            ),
        ));
    }
    if p.inertia.cholesky().is_none() {
        return Err(err(
            src,
            n,
            &format!("{what}.inertia"),
            "the inertia tensor of a body with mass must be positive definite",
        ));
    }
    let inertia = [0, 1, 2].map(|a| [0, 1, 2].map(|b| p.inertia[(a, b)]));
    Ok(BodySpec::new(name, parent, p.mass, p.com.into(), inertia))
}

/// Read an MJCF document (`src` is the file and its text); `locked` joints are welded at the
/// file's pose (q = their `ref`, the value reported in [`Robot::locked`]).
pub fn import(src: &Source, locked: &[String]) -> R<Robot> {
    import_at(src, locked, 0)
}

/// Most nested `<attach>`ed models (an attach cycle would nest without end).
const MAX_ATTACH_DEPTH: usize = 8;

/// [`import`] of a file `depth` `<attach>`es deep.
fn import_at(src: &Source, locked: &[String], depth: usize) -> R<Robot> {
    // `<include>`s expanded first: one composed document, errors located in the file they are in
    let expanded = super::include::expand(src)?;
    let src = expanded.as_ref().unwrap_or(src);
    let doc = super::parse_xml(src)?;
    let root = doc.root_element();
    if !root.has_tag_name("mujoco") {
        return Err(err(
            src,
            root,
            "mujoco",
            "the root element of an MJCF file must be <mujoco>",
        ));
    }
    let c = compiler(src, root)?;
    let defaults = Defaults::read(src, root)?;
    let meshes = Meshes::read(src, &c, &defaults, root)?;
    let mut notes = vec![];
    let mut rec = Recorder::new(src);
    read_top_level(src, root, &mut notes, &mut rec)?;
    let worldbodies: Vec<Node> = elements(root)
        .filter(|n| n.has_tag_name("worldbody"))
        .collect();
    let mut w = Walk {
        src,
        c: &c,
        defaults: &defaults,
        locked,
        used_locked: vec![false; locked.len()],
        rec,
        ranges: vec![],
        locked_values: vec![],
        bodies: vec![],
        body_at: vec![],
        joints: vec![],
        names: HashMap::new(),
        joint_set: HashSet::new(),
        moving: HashSet::new(),
        layout: vec![],
        pose: ([0.0; 3], [1.0, 0.0, 0.0, 0.0]),
        body_name: String::new(),
        sites: vec![],
        mass_unknown: vec![],
        meshes: &meshes,
        spring_dampers: vec![],
        suffix: String::new(),
        attached_keys: vec![],
        models: models(src, root)?,
        depth,
    };
    // depth-first, parents first: (element, parent body name, inherited childclass)
    let mut stack = top_bodies(src, &c, &worldbodies)?;
    while let Some((b, parent, class, frame, suffix)) = stack.pop() {
        w.suffix = suffix;
        if b.has_tag_name("attach") {
            w.attach(b, &parent, frame)?;
            continue;
        }
        let (name, class) = w.body(b, &parent, &class, frame)?;
        let mut children = vec![];
        let at = (&name[..], &class[..], &w.suffix[..]);
        child_bodies(src, &c, b, at, IDENTITY, false, &mut children)?;
        stack.extend(children.into_iter().rev());
    }
    w.suffix.clear();
    for wb in &worldbodies {
        w.sites(*wb, WORLD, MAIN)?;
    }
    if worldbodies.is_empty() || w.bodies.is_empty() {
        return Err(err(src, root, "worldbody", "no <body> in <worldbody>"));
    }
    if c.totalmass > 0.0 {
        scale_total_mass(src, root, &mut w.bodies, c.totalmass)?;
    }
    if let Some(k) = w.used_locked.iter().position(|u| !u) {
        return Err(src.error(
            0..0,
            "locked_joints",
            format!("locked joint `{}` is not a joint of this file", locked[k]),
        ));
    }
    apply_spring_dampers(src, root, locked, depth, &w.spring_dampers, &mut w.bodies)?;
    let unmodelled: Vec<Unmodelled> = w.rec.out;
    Ok(Robot {
        bodies: w.bodies,
        joints: w.joints,
        notes,
        unmodelled,
        ranges: w.ranges,
        locked: w.locked_values,
        keyframes: attached_keyframes(
            src,
            root,
            keyframes(src, root, &w.layout)?,
            w.attached_keys,
            &w.layout,
        )?,
        sites: w.sites,
        body_at: w.body_at,
        mass_unknown: w.mass_unknown,
        mimics: vec![],
    })
}

/// The top-level elements besides `<worldbody>`: refused ones, the gravity note, and the records
/// of fluid options, equalities, tendons, actuators and contact pairs/excludes.
fn read_top_level(src: &Source, root: Node, notes: &mut Vec<String>, rec: &mut Recorder) -> R<()> {
    for n in elements(root) {
        let tag = n.tag_name().name();
        match tag {
            "replicate" | "frame" | "attach" => {
                return Err(err(
                    src,
                    n,
                    tag,
                    format!(
                    "<{tag}> is not supported here (a <frame> or <replicate> belongs in <worldbody> or a <body>)"
                ),
                ))
            }
            "deformable" => {
                return Err(err(
                    src,
                    n,
                    tag,
                    "<deformable> (flexes, skins) is not supported: progmo models rigid bodies",
                ))
            }
            "option" => {
                if n.attribute("gravity").is_some() {
                    notes.push(
                        "<option gravity> not read: gravity comes from the scene's model.gravity"
                            .to_string(),
                    );
                }
                for a in ["density", "viscosity", "wind"] {
                    if n.attribute(a)
                        .is_some_and(|v| v.split_whitespace().any(|x| x.parse::<f64>() != Ok(0.0)))
                    {
                        rec.push("fluid", format!("option.{a}"), n);
                    }
                }
            }
            "equality" | "tendon" | "actuator" => {
                let kind = if tag == "tendon" {
                    "tendon"
                } else if tag == "equality" {
                    "equality"
                } else {
                    "actuator"
                };
                for (k, e) in elements(n)
                    .filter(|e| !e.has_tag_name("default"))
                    .enumerate()
                {
                    let name = e.attribute("name").map_or(format!("{k}"), String::from);
                    rec.push(kind, format!("{tag}.{}[{name}]", e.tag_name().name()), e);
                }
            }
            "contact" => {
                for (k, e) in elements(n).enumerate() {
                    let name = e.attribute("name").map_or(format!("{k}"), String::from);
                    rec.push(
                        "contact",
                        format!("contact.{}[{name}]", e.tag_name().name()),
                        e,
                    );
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// A body still to read: (element, parent body name, inherited childclass, the pose of the
/// `<frame>`s and `<replicate>` copies around it in the parent body's frame, the suffix the
/// `<replicate>`s around it add to the names in its subtree).
type Pending<'a, 'i> = (Node<'a, 'i>, String, String, Pose, String);

/// A placement: position and quaternion (w, x, y, z) in the enclosing frame.
type Pose = ([f64; 3], [f64; 4]);

const IDENTITY: Pose = ([0.0; 3], [1.0, 0.0, 0.0, 0.0]);

/// `outer` after `inner`: the pose `inner` (given in `outer`'s frame) in `outer`'s parent frame.
fn compose(outer: Pose, inner: Pose) -> Pose {
    let r = rotation(outer.1);
    let p = Vector3::from(outer.0) + r * Vector3::from(inner.0);
    (p.into(), quat_of(r * rotation(inner.1)))
}

/// The bodies of the `<worldbody>` elements as a stack (the first on top).
fn top_bodies<'a, 'i>(
    src: &Source,
    c: &Compiler,
    worldbodies: &[Node<'a, 'i>],
) -> R<Vec<Pending<'a, 'i>>> {
    let mut all = vec![];
    for w in worldbodies {
        child_bodies(src, c, *w, (WORLD, MAIN, ""), IDENTITY, true, &mut all)?;
    }
    all.reverse();
    Ok(all)
}

/// The child bodies of `parent` in document order, those inside `<frame>` elements (nested too)
/// with the frames' composed pose and childclass, and those inside `<replicate>` elements once per
/// copy ([`replicas`]), as MuJoCo's compiler resolves them (its sites: `Walk::sites_in`). A geom,
/// joint or inertial in a body's frame or replicate is refused (its pose would change the body's
/// mass properties or joints); in the worldbody its static geometry is not read. An `<attach>`
/// is queued like a body ([`Walk::attach`]).
fn child_bodies<'a, 'i>(
    src: &Source,
    c: &Compiler,
    parent: Node<'a, 'i>,
    (name, class, suffix): (&str, &str, &str),
    frame: Pose,
    in_world: bool,
    out: &mut Vec<Pending<'a, 'i>>,
) -> R<()> {
    for e in elements(parent) {
        let tag = e.tag_name().name();
        match tag {
            "body" => out.push((e, name.to_string(), class.to_string(), frame, suffix.into())),
            "frame" | "replicate" => {
                let held = ["geom", "joint", "freejoint", "inertial"];
                if let Some(x) =
                    elements(e).find(|x| !in_world && held.contains(&x.tag_name().name()))
                {
                    let t = x.tag_name().name();
                    let what = format!("{tag}[{}].{t}", e.attribute("name").unwrap_or(""));
                    return Err(err(src, x, &what, format!("a <{t}> inside a <{tag}> of a body is not supported (bodies, sites, frames and replicates are read there): move it into the body, composing the pose")));
                }
                let fclass = e.attribute("childclass").unwrap_or(class);
                for (pose, sfx) in replicas(src, c, e, suffix)? {
                    let at = (name, fclass, &sfx[..]);
                    child_bodies(src, c, e, at, compose(frame, pose), in_world, out)?;
                }
            }
            "attach" => out.push((e, name.to_string(), class.to_string(), frame, suffix.into())),
            _ => {}
        }
    }
    Ok(())
}

/// The file of an `<asset>` `<model>` (element `m`, what `mwhat`), imported `depth` attaches deep.
fn attached_file(
    src: &Source,
    m: Node,
    mwhat: &str,
    file: &str,
    depth: usize,
) -> R<(Robot, std::path::PathBuf)> {
    let at = |msg: String| err(src, m, mwhat, msg);
    let dir = src.file.parent().unwrap_or(Path::new("."));
    let path = crate::input::resolve(file, dir).map_err(at)?;
    let bytes = crate::input::read(&path, crate::input::ROBOT_LIMIT)
        .map_err(|x| at(format!("cannot read `{}`: {x}", path.display())))?;
    let text = crate::input::text(bytes)
        .map_err(|x| at(format!("`{}`: {}", path.display(), x.message)))?;
    Ok((
        import_at(&Source::new(path.clone(), text), &[], depth)?,
        path,
    ))
}

/// The `<asset>` `<model name file>` elements by name.
fn models<'a, 'i>(src: &Source, root: Node<'a, 'i>) -> R<HashMap<String, Node<'a, 'i>>> {
    let mut out = HashMap::new();
    for m in elements(root)
        .filter(|n| n.has_tag_name("asset"))
        .flat_map(elements)
        .filter(|n| n.has_tag_name("model"))
    {
        let Some(name) = m.attribute("name") else {
            return Err(err(src, m, "asset.model", "a <model> needs `name`"));
        };
        if out.insert(name.to_string(), m).is_some() {
            return Err(err(
                src,
                m,
                &format!("asset.model[{name}]"),
                format!("model `{name}` is defined twice"),
            ));
        }
    }
    Ok(out)
}

/// The copies a `<frame>` (one, its pose) or a `<replicate count sep offset orientation>` makes:
/// copy k placed at T^k, T the offset and rotation, its names suffixed by `sep` and k before the
/// suffix of the replicates around it (MuJoCo: the innermost index first).
fn replicas(src: &Source, c: &Compiler, e: Node, suffix: &str) -> R<Vec<(Pose, String)>> {
    let tag = e.tag_name().name();
    let what = format!("{tag}[{}]", e.attribute("name").unwrap_or(""));
    let pos = attr_k::<3>(src, e, &format!("{what}.pos"), "pos", [0.0; 3])?;
    let quat = orientation(src, c, e, &what)?;
    if tag == "frame" {
        return Ok(vec![((pos, quat), suffix.to_string())]);
    }
    let count = match e.attribute("count").map(|t| t.trim().parse::<usize>()) {
        Some(Ok(n)) if (1..=crate::input::MAX_BODIES).contains(&n) => n,
        _ => {
            return Err(err(
                src,
                e,
                &format!("{what}.count"),
                format!(
                    "a <replicate> needs `count`, a whole number from 1 to {}",
                    crate::input::MAX_BODIES
                ),
            ))
        }
    };
    let offset = attr_k::<3>(src, e, &format!("{what}.offset"), "offset", [0.0; 3])?;
    let sep = e.attribute("sep").unwrap_or("");
    let step = (offset, quat);
    let mut at = (pos, [1.0, 0.0, 0.0, 0.0]);
    let mut out = Vec::with_capacity(count);
    for k in 0..count {
        out.push((at, format!("{sep}{k}{suffix}")));
        at = compose(at, step);
    }
    Ok(out)
}

/// What the depth-first walk over the bodies builds, and what it checks names against.
struct Walk<'s, 'd, 'a, 'i> {
    src: &'s Source,
    c: &'d Compiler,
    defaults: &'d Defaults<'a, 'i>,
    locked: &'d [String],
    used_locked: Vec<bool>,
    rec: Recorder<'s>,
    ranges: Vec<JointRange>,
    locked_values: Vec<(String, f64)>,
    bodies: Vec<BodySpec>,
    /// Where each body's mass properties come from ([`super::urdf::Robot::body_at`]).
    body_at: Vec<(String, SceneError)>,
    joints: Vec<String>,
    names: HashMap<String, Node<'a, 'i>>,
    joint_set: HashSet<String>,
    /// Bodies with joints, or on one that has (MuJoCo's non-static bodies).
    moving: HashSet<String>,
    /// Every joint in MuJoCo's qpos order (locked ones too) with its qpos0 (MuJoCo's default pose:
    /// `ref`, the identity quaternion, a free body's pos and quat): a keyframe's layout.
    layout: Vec<(String, Vec<f64>)>,
    /// The pose of the body whose joints are being read (qpos0 of a free joint) and its name
    /// (an unnamed free joint's name: `BODY_free`, as Pinocchio names it).
    pose: ([f64; 3], [f64; 4]),
    body_name: String,
    /// The named `<site>`s, in file order.
    sites: Vec<Site>,
    /// Static bodies' geoms whose mass progmo does not compute ([`super::urdf::Robot::mass_unknown`]).
    mass_unknown: Vec<SceneError>,
    /// The `<asset>` meshes, weighed at first use.
    meshes: &'d Meshes<'d, 'a, 'i>,
    /// Joints with `springdamper` (time constant, damping ratio), in file order.
    spring_dampers: Vec<(String, [f64; 2])>,
    /// The suffix the `<replicate>`s around the current body add to its subtree's names.
    suffix: String,
    /// The `<attach>`ed models' named keys, renamed, with the values of the attached joints only
    /// (completed over the whole model by [`attached_keyframes`]).
    attached_keys: Vec<Keyframe>,
    /// The `<asset>` `<model>`s (name -> element) an `<attach>` may name.
    models: HashMap<String, Node<'a, 'i>>,
    /// How many `<attach>`es deep this file is read.
    depth: usize,
}

impl<'a, 'i> Walk<'_, '_, 'a, 'i> {
    /// Body `b` on `parent` with the inherited childclass `class`: its placement, mass properties,
    /// gravcomp, colliding geoms and joints; returns its name and its childclass.
    fn body(
        &mut self,
        b: Node<'a, 'i>,
        parent: &str,
        class: &str,
        frame: Pose,
    ) -> R<(String, String)> {
        let src = self.src;
        let k = self.bodies.len();
        if k == crate::input::MAX_BODIES {
            return Err(err(
                src,
                b,
                "body",
                format!(
                    "more than {} bodies (the limit of bodies of a model)",
                    crate::input::MAX_BODIES
                ),
            ));
        }
        let name = b
            .attribute("name")
            .map(|n| format!("{n}{}", self.suffix))
            .unwrap_or_else(|| format!("body{k}"));
        let what = format!("body[{name}]");
        if name == WORLD {
            return Err(err(src, b, &what, "a body cannot be named `world`"));
        }
        if self.names.insert(name.clone(), b).is_some() {
            return Err(err(
                src,
                b,
                &what,
                format!("body `{name}` is defined twice"),
            ));
        }
        if b.attribute("mocap") == Some("true") {
            return Err(err(src, b, &what, "mocap bodies are not supported"));
        }
        let class = b.attribute("childclass").unwrap_or(class).to_string();
        if !self.defaults.classes.contains_key(&class) && class != MAIN {
            return Err(err(
                src,
                b,
                &format!("{what}.childclass"),
                format!("unknown default class `{class}`"),
            ));
        }
        let pos = attr_k::<3>(src, b, &format!("{what}.pos"), "pos", [0.0; 3])?;
        let quat = orientation(src, self.c, b, &what)?;
        let (pos, quat) = compose(frame, (pos, quat)); // the <frame>s around it
        let moving = self.moving.contains(parent)
            || elements(b).any(|e| e.has_tag_name("joint") || e.has_tag_name("freejoint"));
        if moving {
            self.moving.insert(name.clone());
        }
        let mut spec = self
            .mass_props(b, (&name, parent), &class, (pos, moving))?
            .at(pos)
            .rotated(quat);
        if let Some(t) = b.attribute("gravcomp") {
            spec = spec
                .with_gravcomp(fixed::<1>(src, b, &format!("{what}.gravcomp"), "gravcomp", t)?[0]);
        }
        self.record_geoms(b, &what, &class);
        self.sites(b, &name, &class)?;
        self.pose = (pos, quat);
        self.body_name.clone_from(&name);
        for e in elements(b) {
            let tag = e.tag_name().name();
            if tag != "joint" && tag != "freejoint" {
                continue;
            }
            if let Some(js) = self.joint(e, &what, &class, parent)? {
                spec = spec.joint(js);
            }
        }
        self.bodies.push(spec);
        Ok((name, class))
    }

    /// `<attach model body prefix>` (MuJoCo): the subtree of body `body` of the `<asset>` `<model>`'s
    /// file, read as that file says (its own compiler settings, defaults and mesh folder), its
    /// names prefixed (and suffixed by the replicates around the attach point), its root placed at
    /// the attach point (`frame`: the frames and replicates around it) in body `parent`. The
    /// attached file's records (limits, actuators, ...), sites and named keys come along (a key
    /// renamed as a body is, holding the attached joints' values: [`attached_keyframes`]).
    fn attach(&mut self, e: Node<'a, 'i>, parent: &str, frame: Pose) -> R<()> {
        let src = self.src;
        let what = format!("attach[{}]", e.attribute("model").unwrap_or(""));
        let need = |a: &str| {
            e.attribute(a)
                .ok_or_else(|| err(src, e, &what, format!("an <attach> needs `{a}`")))
        };
        let (model, body) = (need("model")?, need("body")?);
        let prefix = e.attribute("prefix").unwrap_or("");
        let (child, path) = self.attached_model(e, &what, model)?;
        if let Some(x) = child.mass_unknown.first() {
            return Err(x.clone());
        }
        let suffix = self.suffix.clone();
        let rename = |n: &str| format!("{prefix}{n}{suffix}");
        let mut inside: HashSet<&str> = HashSet::new();
        for b in &child.bodies {
            let root = b.name == body;
            if !(root || inside.contains(b.parent.as_str())) {
                continue;
            }
            inside.insert(&b.name);
            let mut spec = b.clone();
            spec.name = rename(&b.name);
            spec.parent = if root {
                parent.to_string()
            } else {
                rename(&b.parent)
            };
            if root {
                (spec.pos, spec.quat) = compose(frame, (b.pos, b.quat));
            }
            if self.names.insert(spec.name.clone(), e).is_some() {
                return Err(err(
                    src,
                    e,
                    &what,
                    format!("body `{}` is defined twice", spec.name),
                ));
            }
            let parent_moving = self.moving.contains(&spec.parent);
            if parent_moving || !spec.joints.is_empty() {
                self.moving.insert(spec.name.clone());
            }
            spec.joints = self.attached_joints(
                e,
                &what,
                spec.joints,
                (&spec.parent, spec.pos, spec.quat),
                &rename,
            )?;
            self.bodies.push(spec);
        }
        if inside.is_empty() {
            return Err(err(
                src,
                e,
                &format!("{what}.body"),
                format!("no body `{body}` in `{}`", path.display()),
            ));
        }
        let joint_in = |j: &str| self.joint_set.contains(&rename(j));
        self.ranges.extend(
            child
                .ranges
                .into_iter()
                .filter(|r| joint_in(&r.joint))
                .map(|mut r| {
                    r.joint = rename(&r.joint);
                    r
                }),
        );
        self.rec.out.extend(child.unmodelled);
        for mut site in child
            .sites
            .into_iter()
            .filter(|x| inside.contains(x.parent.as_str()))
        {
            (site.name, site.parent) = (rename(&site.name), rename(&site.parent));
            self.sites.push(site);
        }
        for (name, at) in child
            .body_at
            .into_iter()
            .filter(|x| inside.contains(x.0.as_str()))
        {
            self.body_at.push((rename(&name), at));
        }
        for mut key in child.keyframes {
            key.name = rename(&key.name);
            key.joints = key
                .joints
                .into_iter()
                .filter(|(j, _, _)| self.joint_set.contains(&rename(j)))
                .map(|(j, q, v)| (rename(&j), q, v))
                .collect();
            self.attached_keys.push(key);
        }
        Ok(())
    }

    /// The file of the `<asset>` `<model>` named `model` that attach element `e` names, imported.
    fn attached_model(
        &self,
        e: Node<'a, 'i>,
        what: &str,
        model: &str,
    ) -> R<(Robot, std::path::PathBuf)> {
        let src = self.src;
        let Some(&m) = self.models.get(model) else {
            return Err(err(
                src,
                e,
                &format!("{what}.model"),
                format!("no <model> named `{model}` in <asset>"),
            ));
        };
        let mwhat = format!("asset.model[{model}]");
        let Some(file) = m.attribute("file") else {
            return Err(err(src, m, &mwhat, "a <model> needs `file`"));
        };
        if self.depth >= MAX_ATTACH_DEPTH {
            return Err(err(src, e, what, format!("more than {MAX_ATTACH_DEPTH} nested <attach>ed models (does a model attach itself?)")));
        }
        attached_file(src, m, &mwhat, file, self.depth + 1)
    }

    /// The joints of an attached body, renamed: recorded in the layout and joint lists as the
    /// file's own joints are (a locked one welded at its reference).
    fn attached_joints(
        &mut self,
        e: Node<'a, 'i>,
        what: &str,
        joints: Vec<JointSpec>,
        (parent, pos, quat): (&str, [f64; 3], [f64; 4]),
        rename: &dyn Fn(&str) -> String,
    ) -> R<Vec<JointSpec>> {
        let mut kept = vec![];
        for mut js in joints {
            js.name = rename(&js.name);
            let qpos0 = match js.kind {
                crate::tree::JointType::Free if parent != WORLD => {
                    return Err(err(self.src, e, what, format!("joint `{}` is free: a free joint belongs to a top-level body (attach it in <worldbody>)", js.name)));
                }
                crate::tree::JointType::Free => [&pos[..], &quat[..]].concat(),
                crate::tree::JointType::Ball => vec![1.0, 0.0, 0.0, 0.0],
                _ => vec![js.reference],
            };
            if !self.joint_set.insert(js.name.clone()) {
                return Err(err(
                    self.src,
                    e,
                    what,
                    format!("joint `{}` is defined twice", js.name),
                ));
            }
            self.layout.push((js.name.clone(), qpos0));
            if let Some(k) = self.locked.iter().position(|l| *l == js.name) {
                self.used_locked[k] = true;
                self.locked_values.push((js.name.clone(), js.reference));
                continue;
            }
            self.joints.push(js.name.clone());
            kept.push(js);
        }
        Ok(kept)
    }

    /// The named `<site>`s of body (or worldbody) `b`, whose childclass is `class`.
    fn sites(&mut self, b: Node<'a, 'i>, parent: &str, class: &str) -> R<()> {
        self.sites_in(b, parent, class, IDENTITY)
    }

    /// The named `<site>`s among `b`'s children, those in `<frame>`s (nested too) with the frames'
    /// composed pose and childclass; `frame`: the pose of the frames around `b` in the body.
    fn sites_in(&mut self, b: Node<'a, 'i>, parent: &str, class: &str, frame: Pose) -> R<()> {
        let src = self.src;
        for f in elements(b).filter(|e| e.has_tag_name("frame") || e.has_tag_name("replicate")) {
            let fclass = f.attribute("childclass").unwrap_or(class).to_string();
            let outer = std::mem::take(&mut self.suffix);
            for (pose, sfx) in replicas(src, self.c, f, &outer)? {
                self.suffix = sfx;
                self.sites_in(f, parent, &fclass, compose(frame, pose))?;
            }
            self.suffix = outer;
        }
        for e in elements(b).filter(|e| e.has_tag_name("site")) {
            let Some(name) = e.attribute("name").map(|n| format!("{n}{}", self.suffix)) else {
                continue; // an unnamed site cannot be named in a row
            };
            let name = &name[..];
            let what = format!("site[{name}]");
            let sclass = e.attribute("class").unwrap_or(class);
            let problem = if e.attribute("fromto").is_some() {
                Some(err(src, e, &format!("{what}.fromto"), "a site placed by `fromto` is not read as a frame: give it pos and an orientation"))
            } else {
                self.defaults.site_placement(sclass).map(|(a, d)| {
                    let msg = format!("site `{name}` takes `{a}` from its default class `{sclass}` (line {}), which is not read for sites: write it on the site", src.line_col(d.range().start).0);
                    err(src, e, &format!("{what}.class"), msg)
                })
            };
            let pos = attr_k::<3>(src, e, &format!("{what}.pos"), "pos", [0.0; 3])?;
            let quat = orientation(src, self.c, e, &what)?;
            let (pos, quat) = compose(frame, (pos, quat));
            self.sites.push(Site {
                name: name.to_string(),
                parent: parent.to_string(),
                pos,
                quat,
                problem,
            });
        }
        Ok(())
    }

    /// Body `b`'s mass properties as MuJoCo's compiler makes them: from its geoms when
    /// `inertiafromgeom` is true, or auto and it has no `<inertial>` (an `<inertial>` is kept
    /// when no geom has mass), else from its `<inertial>`; then `boundmass` / `boundinertia`.
    fn mass_props(
        &mut self,
        b: Node<'a, 'i>,
        (name, parent): (&str, &str),
        class: &str,
        (pos, moving): ([f64; 3], bool),
    ) -> R<BodySpec> {
        let (src, c) = (self.src, self.c);
        let what = format!("body[{name}]");
        let inertial = elements(b).find(|e| e.has_tag_name("inertial"));
        let iwhat = format!("{what}.inertial");
        let mut props = inertial
            .map(|n| explicit_inertial(src, c, n, &iwhat))
            .transpose()?;
        let mut at = inertial.map_or((b, &what), |n| (n, &iwhat));
        if c.from_geom == "true" || (c.from_geom == "auto" && inertial.is_none()) {
            let mut parts = vec![];
            for (k, g) in elements(b).filter(|e| e.has_tag_name("geom")).enumerate() {
                let gclass = g.attribute("class").unwrap_or(class);
                let gname = g
                    .attribute("name")
                    .map_or(format!("{k}"), |n| format!("{n}{}", self.suffix));
                let gwhat = format!("{what}.geom[{gname}]");
                if !self.defaults.classes.contains_key(gclass) && gclass != MAIN {
                    return Err(err(
                        src,
                        g,
                        &format!("{gwhat}.class"),
                        format!("unknown default class `{gclass}`"),
                    ));
                }
                let chain = self.defaults.geom_chain(g, gclass);
                let a = GeomAttrs {
                    src,
                    chain,
                    what: gwhat,
                };
                parts.extend(geom_mass(self.meshes, &a, moving, &mut self.mass_unknown)?);
            }
            if let Some(p) = gi::combine(&parts) {
                props = Some(p);
                at = (b, &what);
            }
        }
        if c.boundmass > 0.0 || c.boundinertia > 0.0 {
            // MuJoCo: a body without an inertial frame gets its own `pos` as the centre of mass
            let p = props.unwrap_or(MassProps {
                mass: 0.0,
                com: Vector3::from(pos),
                inertia: Matrix3::zeros(),
            });
            props = Some(gi::bound(p, c.boundmass, c.boundinertia));
        }
        self.body_at
            .push(super::urdf::body_at(src, at.0, name, at.1));
        body_spec(src, at.0, at.1, (name, parent), props)
    }

    /// One `contact` record per geom of body `b` that collides (`contype` or `conaffinity` not 0).
    fn record_geoms(&mut self, b: Node<'a, 'i>, what: &str, class: &str) {
        for (gi, g) in elements(b).filter(|e| e.has_tag_name("geom")).enumerate() {
            let gclass = g.attribute("class").unwrap_or(class);
            let collides = ["contype", "conaffinity"].iter().any(|a| {
                self.defaults
                    .geom_attr(g, gclass, a)
                    .is_none_or(|v| v.trim().parse::<i64>() != Ok(0)) // MuJoCo's default: 1
            });
            if collides {
                let gname = g
                    .attribute("name")
                    .map_or(format!("{gi}"), |n| format!("{n}{}", self.suffix));
                self.rec.push("contact", format!("{what}.geom[{gname}]"), g);
            }
        }
    }

    /// Joint element `e` (`<joint>` or `<freejoint>`) of the body `what` on `parent`: its tree
    /// joint, or `None` when it is locked (welded at its `ref`).
    fn joint(
        &mut self,
        e: Node<'a, 'i>,
        what: &str,
        class: &str,
        parent: &str,
    ) -> R<Option<JointSpec>> {
        let src = self.src;
        let tag = e.tag_name().name();
        let jclass = e.attribute("class").unwrap_or(class);
        if !self.defaults.classes.contains_key(jclass) && jclass != MAIN {
            return Err(err(
                src,
                e,
                &format!("{what}.joint.class"),
                format!("unknown default class `{jclass}`"),
            ));
        }
        let free = tag == "freejoint"
            || (tag == "joint" && self.defaults.joint_attr(e, jclass, "type") == Some("free"));
        let unnamed_free = format!("{}_free", self.body_name);
        let suffixed = e.attribute("name").map(|n| format!("{n}{}", self.suffix));
        let jname = match &suffixed {
            Some(n) => n.as_str(),
            None if free => unnamed_free.as_str(), // the body's coordinates: BODY_free.x, ...
            None => {
                return Err(err(
                    src,
                    e,
                    &format!("{what}.{tag}"),
                    "a joint needs a name: it names a coordinate",
                ))
            }
        };
        let jwhat = format!("joint[{jname}]");
        if let Some(why) = super::unusable_name(jname) {
            return Err(err(src, e, &jwhat, format!("joint name `{jname}` {why}")));
        }
        if !self.joint_set.insert(jname.to_string()) {
            return Err(err(
                src,
                e,
                &jwhat,
                format!("joint `{jname}` is defined twice"),
            ));
        }
        let a = JointAttrs {
            src,
            e,
            freejoint: tag == "freejoint",
            class: jclass,
            defaults: self.defaults,
            what: jwhat,
        };
        let kind = if a.freejoint {
            "free"
        } else {
            a.get("type").unwrap_or("hinge")
        };
        let js = a.spec(jname, kind, parent)?;
        let (js, reference, springdamper) = a.dynamics(self.c, js, kind)?;
        if let Some(sd) = springdamper {
            self.spring_dampers.push((jname.to_string(), sd));
        }
        let qpos0 = match kind {
            "free" => [&self.pose.0[..], &self.pose.1[..]].concat(),
            "ball" => vec![1.0, 0.0, 0.0, 0.0],
            _ => vec![reference],
        };
        self.layout.push((jname.to_string(), qpos0));
        let is_locked = self.locked.iter().position(|l| l == jname);
        if let Some(k) = is_locked {
            self.used_locked[k] = true;
            self.locked_values.push((jname.to_string(), reference));
            return Ok(None); // welded: its limits, friction and forces act on no coordinate
        }
        self.record_joint(&a, jname, kind)?;
        self.joints.push(jname.to_string());
        Ok(Some(js))
    }

    /// The records of a joint's limits (with its range), actuator force range and frictionloss.
    fn record_joint(&mut self, a: &JointAttrs, jname: &str, kind: &str) -> R<()> {
        let (src, e, jwhat) = (self.src, a.e, &a.what);
        let hinge = kind == "hinge";
        let limited = match a.get("limited") {
            Some("true") => true,
            Some("false") => false,
            _ => a.get("range").is_some(), // autolimits (MuJoCo's default)
        };
        if limited && kind != "free" {
            self.rec.push("joint_limit", format!("{jwhat}.range"), e);
            if hinge || kind == "slide" {
                let r = match a.get("range") {
                    None => [0.0, 0.0],
                    Some(t) => fixed::<2>(src, e, &format!("{jwhat}.range"), "range", t)?,
                };
                self.ranges.push(JointRange {
                    joint: jname.to_string(),
                    lower: joint_angle(self.c, kind, r[0]),
                    upper: joint_angle(self.c, kind, r[1]),
                });
            }
        }
        let frc_limited = match a.get("actuatorfrclimited") {
            Some("true") => true,
            Some("false") => false,
            _ => a.get("actuatorfrcrange").is_some(),
        };
        if frc_limited {
            self.rec
                .push("effort_limit", format!("{jwhat}.actuatorfrcrange"), e);
        }
        if a.nonzero("frictionloss") {
            self.rec
                .push("frictionloss", format!("{jwhat}.frictionloss"), e);
        }
        Ok(())
    }
}

/// An angle of a joint of type `kind`: a hinge's in the compiler's unit, converted to radians.
fn joint_angle(c: &Compiler, kind: &str, x: f64) -> f64 {
    if kind == "hinge" && c.degrees {
        x.to_radians()
    } else {
        x
    }
}

/// A joint element's attributes: its own, else (for a `<joint>`) its default class chain's.
struct JointAttrs<'d, 'a, 'i> {
    src: &'d Source,
    e: Node<'a, 'i>,
    /// A `<freejoint>` takes no defaults.
    freejoint: bool,
    class: &'d str,
    defaults: &'d Defaults<'a, 'i>,
    /// `joint[name]`, the element named in errors and records.
    what: String,
}

impl<'a> JointAttrs<'_, 'a, '_> {
    fn get(&self, a: &str) -> Option<&'a str> {
        if self.freejoint {
            self.e.attribute(a)
        } else {
            self.defaults.joint_attr(self.e, self.class, a)
        }
    }

    fn nonzero(&self, a: &str) -> bool {
        self.get(a)
            .is_some_and(|v| v.split_whitespace().any(|x| x.parse::<f64>() != Ok(0.0)))
    }

    fn num3(&self, a: &str, d: [f64; 3]) -> R<[f64; 3]> {
        match self.get(a) {
            None => Ok(d),
            Some(t) => fixed::<3>(self.src, self.e, &format!("{}.{a}", self.what), a, t),
        }
    }

    /// One number (`default` when absent).
    fn scalar(&self, a: &str, default: f64) -> R<f64> {
        match self.get(a) {
            None => Ok(default),
            Some(t) => Ok(fixed::<1>(self.src, self.e, &format!("{}.{a}", self.what), a, t)?[0]),
        }
    }

    /// The tree joint of type `kind` named `jname` (its axis and anchor), on body parent `parent`.
    fn spec(&self, jname: &str, kind: &str, parent: &str) -> R<JointSpec> {
        let (src, e, jwhat) = (self.src, self.e, &self.what);
        let anchor = self.num3("pos", [0.0; 3])?;
        let axis = || -> R<[f64; 3]> {
            Ok(unit(
                src,
                e,
                &format!("{jwhat}.axis"),
                self.num3("axis", [0.0, 0.0, 1.0])?,
                "axis",
            )?
            .into())
        };
        Ok(match kind {
            "hinge" => JointSpec::hinge(jname, axis()?).with_anchor(anchor),
            "slide" => JointSpec::slide(jname, axis()?),
            "ball" => JointSpec::ball(jname).with_anchor(anchor),
            "free" if parent != WORLD => {
                return Err(err(
                    src,
                    e,
                    jwhat,
                    "a free joint belongs to a top-level body (a child of <worldbody>), as MuJoCo requires",
                ))
            }
            "free" => JointSpec::free(jname),
            other => {
                return Err(err(
                    src,
                    e,
                    &format!("{jwhat}.type"),
                    format!("unknown joint type `{other}`: expected hinge, slide, ball or free"),
                ))
            }
        })
    }

    /// `js` with its damping, armature, spring and reference (angles of hinges in the compiler's
    /// unit), and the reference.
    /// `springdamper` (time constant, damping ratio) unless "0 0" (then both must be positive):
    /// its stiffness and damping replace the stated ones ([`spring_dampers`]).
    fn dynamics(
        &self,
        c: &Compiler,
        js: JointSpec,
        kind: &str,
    ) -> R<(JointSpec, f64, Option<[f64; 2]>)> {
        let (src, e, jwhat) = (self.src, self.e, &self.what);
        let hinge = kind == "hinge";
        let angle = |x: f64| joint_angle(c, kind, x);
        let sd = match self.get("springdamper") {
            Some(t) => fixed::<2>(src, e, &format!("{jwhat}.springdamper"), "springdamper", t)?,
            None => [0.0; 2],
        };
        // MuJoCo: "0 0" is none; any other pair must be positive
        let springdamper = (sd != [0.0; 2]).then_some(sd);
        if springdamper.is_some() && !(sd[0] > 0.0 && sd[1] > 0.0) {
            return Err(err(src, e, &format!("{jwhat}.springdamper"), format!("springdamper values must be positive (time constant, damping ratio), got {} {} (MuJoCo refuses them too)", sd[0], sd[1])));
        }
        if springdamper.is_some() && !(hinge || kind == "slide") {
            return Err(err(src, e, &format!("{jwhat}.springdamper"), format!("a spring on a {kind} joint is not supported (springs on hinge and slide joints only)")));
        }
        let damping = self.scalar("damping", 0.0)?;
        let armature = self.scalar("armature", 0.0)?;
        let stiffness = self.scalar("stiffness", 0.0)?;
        let (reference, springref) = if hinge || kind == "slide" {
            (
                angle(self.scalar("ref", 0.0)?),
                angle(self.scalar("springref", 0.0)?),
            )
        } else {
            (0.0, 0.0) // MuJoCo reads ref and springref of hinges and slides only
        };
        if stiffness != 0.0 && !(hinge || kind == "slide") {
            return Err(err(src, e, &format!("{jwhat}.stiffness"), format!("a spring on a {kind} joint is not supported (springs on hinge and slide joints only)")));
        }
        for (a, v) in [
            ("damping", damping),
            ("armature", armature),
            ("stiffness", stiffness),
        ] {
            if v < 0.0 {
                return Err(err(
                    src,
                    e,
                    &format!("{jwhat}.{a}"),
                    format!("`{a}` must be >= 0, got {v}"),
                ));
            }
        }
        let js = js
            .with_damping(damping)
            .with_armature(armature)
            .with_spring(stiffness, springref)
            .with_reference(reference);
        Ok((js, reference, springdamper))
    }
}

/// A geom element's attributes: its own, else its default class chain's (`chain[0]` is the
/// element, then its class and the class's parents).
struct GeomAttrs<'s, 'a, 'i> {
    src: &'s Source,
    chain: Vec<Node<'a, 'i>>,
    what: String,
}

impl<'a, 'i> GeomAttrs<'_, 'a, 'i> {
    /// The attribute and the element that states it.
    fn get(&self, a: &str) -> Option<(Node<'a, 'i>, &'a str)> {
        self.chain
            .iter()
            .find_map(|n| n.attribute(a).map(|v| (*n, v)))
    }

    fn num<const K: usize>(&self, a: &str, default: [f64; K]) -> R<[f64; K]> {
        match self.get(a) {
            None => Ok(default),
            Some((n, t)) => fixed(self.src, n, &format!("{}.{a}", self.what), a, t),
        }
    }

    /// `size`, number by number: MuJoCo fills the class's size and the element overwrites the
    /// numbers it gives (`size="0.5"` over a default `0.1 0.2 0.3` is 0.5 0.2 0.3).
    fn size(&self) -> R<[f64; 3]> {
        let mut out = [None; 3];
        for n in &self.chain {
            if let Some(t) = n.attribute("size") {
                let v = parse_list(self.src, *n, &format!("{}.size", self.what), "size", t)?;
                for (k, x) in v.into_iter().take(3).enumerate() {
                    out[k] = out[k].or(Some(x));
                }
            }
        }
        Ok(out.map(|x| x.unwrap_or(0.0)))
    }

    /// The orientation of the first element of the chain that gives one.
    fn orientation(&self, c: &Compiler) -> R<UnitQuaternion<f64>> {
        let given = ["quat", "axisangle", "euler", "xyaxes", "zaxis"];
        match self
            .chain
            .iter()
            .find(|n| given.iter().any(|a| n.attribute(*a).is_some()))
        {
            None => Ok(UnitQuaternion::identity()),
            Some(n) => Ok(rotation(orientation(self.src, c, *n, &self.what)?)),
        }
    }

    /// The geom's frame in the body and its size: `pos` and orientation, or `fromto` (centre at
    /// the midpoint, z along from - to as MuJoCo's `mjuu_z2quat`, half-length |from - to| / 2 as
    /// size[1] of a capsule or cylinder, size[2] of a box or ellipsoid whose size[1] = size[0]).
    fn frame(
        &self,
        c: &Compiler,
        shape: Shape,
    ) -> R<(Vector3<f64>, UnitQuaternion<f64>, [f64; 3])> {
        let mut size = self.size()?;
        let pos = Vector3::from(self.num::<3>("pos", [0.0; 3])?);
        let Some((n, _)) = self.get("fromto") else {
            return Ok((pos, self.orientation(c)?, size));
        };
        let w = format!("{}.fromto", self.what);
        if shape == Shape::Sphere {
            return Err(err(
                self.src,
                n,
                &w,
                "fromto requires a capsule, cylinder, box or ellipsoid",
            ));
        }
        if pos != Vector3::zeros() {
            return Err(err(
                self.src,
                self.chain[0],
                &w,
                "both pos and fromto given",
            ));
        }
        let f = self.num::<6>("fromto", [0.0; 6])?;
        let v = Vector3::new(f[0] - f[3], f[1] - f[4], f[2] - f[5]);
        let half = v.norm() / 2.0;
        if half < gi::MJ_EPS {
            return Err(err(self.src, n, &w, "the fromto points coincide"));
        }
        if matches!(shape, Shape::Box | Shape::Ellipsoid) {
            size = [size[0], size[0], half];
        } else {
            size[1] = half;
        }
        let mid = Vector3::new(f[0] + f[3], f[1] + f[4], f[2] + f[5]) / 2.0;
        Ok((mid, z2quat(v), size))
    }

    /// The geom's mass for volume `vol` (the area for a shell): `mass` when given (0 when the
    /// volume is not above mjEPS), else `density` (1000) times the volume.
    fn mass(&self, vol: f64) -> R<f64> {
        let (attr, value) = match self.get("mass") {
            Some(_) => ("mass", self.num::<1>("mass", [0.0])?[0]),
            None => ("density", self.num::<1>("density", [1000.0])?[0]),
        };
        if value < 0.0 {
            let n = self.get(attr).map_or(self.chain[0], |x| x.0);
            return Err(err(
                self.src,
                n,
                &format!("{}.{attr}", self.what),
                format!("`{attr}` must be >= 0, got {value}"),
            ));
        }
        Ok(match attr {
            "mass" if vol > gi::MJ_EPS => value,
            "mass" => 0.0,
            _ => value * vol,
        })
    }

    /// A geom type without a closed form: a plane adds nothing (refused in a moving body, as
    /// MuJoCo does); an sdf or height field only with `mass="0"` or `density="0"`; a mesh geom
    /// reaches here only without its `mesh`.
    fn no_shape(&self, kind: &str, moving: bool) -> R<()> {
        let (src, g, what) = (self.src, self.chain[0], &self.what);
        match kind {
            "plane" if moving => Err(err(
                src,
                g,
                what,
                "a plane geom in a body that moves: MuJoCo allows planes only in static bodies",
            )),
            "plane" => Ok(()),
            "mesh" => Err(err(
                src,
                g,
                what,
                "a mesh geom needs `mesh` (the name of an <asset> <mesh>)",
            )),
            "sdf" | "hfield" => {
                let zero = |a| {
                    self.get(a)
                        .is_some_and(|(_, v)| v.trim().parse::<f64>() == Ok(0.0))
                };
                if zero("mass") || (self.get("mass").is_none() && zero("density")) {
                    return Ok(());
                }
                let asset = self
                    .get(if kind == "hfield" { "hfield" } else { "sdf" })
                    .map_or("?", |x| x.1);
                let msg = if moving {
                    format!("the inertia of {kind} geom (`{asset}`) is not supported (give the body an <inertial>, or the geom mass=\"0\")")
                } else {
                    format!("the mass of {kind} geom (`{asset}`) of a static body is not computed (MuJoCo's {kind} inertia is not modelled); the motion does not need it, `com.` signals do: give the body an <inertial>, or the geom mass=\"0\"")
                };
                Err(err(src, g, what, msg))
            }
            other => Err(err(
                src,
                g,
                &format!("{what}.type"),
                format!("unknown geom type `{other}`"),
            )),
        }
    }
}

/// One geom's share of its body's mass properties (`None` for a geom outside
/// `inertiagrouprange` or without volume). A mesh geom is weighed as MuJoCo does ([`mesh`]); a
/// primitive geom naming a mesh is fitted to it first. A geom of a static body whose mass progmo
/// cannot compute (an sdf or height field, a mesh it cannot weigh) does not enter the motion: it
/// is left out and its error kept in `unknown` (raised only if the scene needs every body's mass:
/// `com.` signals).
fn geom_mass(
    meshes: &Meshes,
    a: &GeomAttrs,
    moving: bool,
    unknown: &mut Vec<SceneError>,
) -> R<Option<GeomMass>> {
    let (src, c) = (meshes.src, meshes.c);
    let group = a.num::<1>("group", [0.0])?[0];
    if group < c.groups[0] || group > c.groups[1] {
        return Ok(None);
    }
    let kind = a.get("type").map_or("sphere", |x| x.1);
    let shell = a.get("shellinertia").is_some_and(|x| x.1 == "true");
    let zero = |attr| {
        a.get(attr)
            .is_some_and(|(_, v)| v.trim().parse::<f64>() == Ok(0.0))
    };
    if kind == "mesh" && (zero("mass") || (a.get("mass").is_none() && zero("density"))) {
        return Ok(None); // a visual-only mesh: no mass, its file not needed
    }
    let fitted = match a.get("mesh") {
        Some((n, name)) if kind == "mesh" || Shape::parse(kind).is_some() => {
            if kind == "mesh" && shell {
                return Err(err(src, a.chain[0], &format!("{}.shellinertia", a.what), "a mesh geom is weighed as its asset says: give the <mesh> inertia=\"shell\" instead"));
            }
            match meshes.weigh(n, name, &a.what) {
                Ok(m) => Some(m),
                Err(e) if !moving => {
                    unknown.push(e);
                    return Ok(None);
                }
                Err(e) => return Err(e),
            }
        }
        _ => None,
    };
    if let (Some(m), "mesh") = (&fitted, kind) {
        return mesh_geom(a, c, m).map(Some);
    }
    let Some(shape) = Shape::parse(kind) else {
        match a.no_shape(kind, moving) {
            Err(e) if !moving => unknown.push(e),
            r => r?,
        }
        return Ok(None);
    };
    let (pos, rot, size) = match &fitted {
        None => a.frame(c, shape)?,
        Some(m) => fit(a, c, shape, m)?,
    };
    if let Some(k) = (0..shape.sizes()).find(|&k| !(size[k] > 0.0)) {
        return Err(err(
            src,
            a.chain[0],
            &format!("{}.size", a.what),
            format!(
                "size {k} of a {kind} geom must be positive, got {}",
                size[k]
            ),
        ));
    }
    let mass = a.mass(gi::volume(shape, size, shell))?;
    let principal = if mass > 0.0 {
        gi::principal(shape, size, mass, shell)
    } else {
        [0.0; 3]
    };
    Ok(Some(GeomMass {
        mass,
        pos,
        rot,
        principal,
    }))
}

/// The geom's `pos` and orientation (a mesh geom, or one fitted to a mesh, takes no `fromto`).
fn placement(a: &GeomAttrs, c: &Compiler) -> R<(Vector3<f64>, UnitQuaternion<f64>)> {
    if let Some((n, _)) = a.get("fromto") {
        return Err(err(
            a.src,
            n,
            &format!("{}.fromto", a.what),
            "`fromto` on a geom placed by its mesh is not supported (give pos and an orientation)",
        ));
    }
    Ok((
        Vector3::from(a.num::<3>("pos", [0.0; 3])?),
        a.orientation(c)?,
    ))
}

/// A mesh geom: its frame moved to the mesh's centre of mass and principal axes, its mass
/// density times the mesh's volume (or `mass`), its inertia the equivalent box's.
fn mesh_geom(a: &GeomAttrs, c: &Compiler, m: &MeshMass) -> R<GeomMass> {
    let (pos, rot) = placement(a, c)?;
    let mass = a.mass(m.measure)?;
    Ok(GeomMass {
        mass,
        pos: pos + rot * m.com,
        rot: rot * m.rot,
        principal: m.principal(mass),
    })
}

/// A primitive geom fitted to a mesh (`mjCMesh::FitGeom` with `fitaabb="false"`): sizes from the
/// mesh's equivalent inertia box b (sphere (b0 + b1 + b2)/3; capsule r = (b0 + b1)/2 and half
/// length b2 - r/2; cylinder r = (b0 + b1)/2, b2; box and ellipsoid b), times `fitscale`; placed at
/// the mesh's centre of mass along its principal axes.
fn fit(
    a: &GeomAttrs,
    c: &Compiler,
    shape: Shape,
    m: &MeshMass,
) -> R<(Vector3<f64>, UnitQuaternion<f64>, [f64; 3])> {
    if c.fitaabb {
        return Err(err(a.src, a.chain[0], &a.what, "a geom fitted to a mesh's bounding box (`<compiler fitaabb=\"true\">`) is not supported: give the geom type=\"mesh\" or its own size"));
    }
    let (pos, rot) = placement(a, c)?;
    let b = m.boxsz;
    let r = (b[0] + b[1]) / 2.0;
    let size = match shape {
        Shape::Sphere => [(b[0] + b[1] + b[2]) / 3.0, 0.0, 0.0],
        Shape::Capsule => [r, (b[2] - r / 2.0).max(0.0), 0.0],
        Shape::Cylinder => [r, b[2], 0.0],
        Shape::Ellipsoid | Shape::Box => b,
    };
    let scale = a.num::<1>("fitscale", [1.0])?[0];
    Ok((pos + rot * m.com, rot * m.rot, size.map(|x| x * scale)))
}

/// The `<asset>` meshes by name, each weighed at its first use ([`mesh`]).
struct Meshes<'d, 'a, 'i> {
    src: &'d Source,
    c: &'d Compiler,
    defaults: &'d Defaults<'a, 'i>,
    decl: HashMap<String, Node<'a, 'i>>,
    done: RefCell<HashMap<String, MeshMass>>,
}

impl<'d, 'a, 'i> Meshes<'d, 'a, 'i> {
    fn read(
        src: &'d Source,
        c: &'d Compiler,
        defaults: &'d Defaults<'a, 'i>,
        root: Node<'a, 'i>,
    ) -> R<Self> {
        let mut decl = HashMap::new();
        for m in elements(root)
            .filter(|n| n.has_tag_name("asset"))
            .flat_map(elements)
            .filter(|n| n.has_tag_name("mesh"))
        {
            // MuJoCo names a mesh without `name` after its file, without folder and extension
            let stem = m
                .attribute("file")
                .and_then(|f| Path::new(f).file_stem())
                .and_then(|s| s.to_str());
            let Some(name) = m.attribute("name").or(stem) else {
                return Err(err(src, m, "asset.mesh", "a <mesh> needs `name` or `file`"));
            };
            if decl.insert(name.to_string(), m).is_some() {
                return Err(err(
                    src,
                    m,
                    &format!("asset.mesh[{name}]"),
                    format!("mesh `{name}` is defined twice"),
                ));
            }
        }
        Ok(Meshes {
            src,
            c,
            defaults,
            decl,
            done: RefCell::new(HashMap::new()),
        })
    }

    /// The mass properties of mesh `name`, which geom `what` (element `at`) names.
    fn weigh(&self, at: Node, name: &str, what: &str) -> R<MeshMass> {
        if let Some(m) = self.done.borrow().get(name) {
            return Ok(m.clone());
        }
        let Some(&n) = self.decl.get(name) else {
            return Err(err(
                self.src,
                at,
                &format!("{what}.mesh"),
                format!("no <mesh> named `{name}` in <asset>"),
            ));
        };
        let m = self.compute(n, name)?;
        self.done.borrow_mut().insert(name.into(), m.clone());
        Ok(m)
    }

    fn compute(&self, n: Node<'a, 'i>, name: &str) -> R<MeshMass> {
        let src = self.src;
        let what = format!("asset.mesh[{name}]");
        let class = n.attribute("class").unwrap_or(MAIN);
        if !self.defaults.classes.contains_key(class) && class != MAIN {
            return Err(err(
                src,
                n,
                &format!("{what}.class"),
                format!("unknown default class `{class}`"),
            ));
        }
        let attr = |a: &str| self.defaults.mesh_attr(n, class, a);
        let num3 = |a: &str, d: [f64; 3]| match attr(a) {
            None => Ok(d),
            Some(t) => fixed::<3>(src, n, &format!("{what}.{a}"), a, t),
        };
        let (scale, refpos) = (num3("scale", [1.0; 3])?, num3("refpos", [0.0; 3])?);
        let refquat = match attr("refquat") {
            None => [1.0, 0.0, 0.0, 0.0],
            Some(t) => fixed::<4>(src, n, &format!("{what}.refquat"), "refquat", t)?,
        };
        let kind = MeshInertia::parse(attr("inertia").unwrap_or("legacy"))
            .map_err(|e| err(src, n, &format!("{what}.inertia"), e))?;
        if n.has_children() && elements(n).any(|e| e.has_tag_name("plugin"))
            || attr("plugin").is_some()
        {
            return Err(err(
                src,
                n,
                &what,
                "a mesh made by a plugin (an SDF) is not supported",
            ));
        }
        let at = |e: String| err(src, n, &what, e);
        let list = |a: &str| {
            n.attribute(a)
                .map(|t| parse_list(src, n, &format!("{what}.{a}"), a, t))
                .transpose()
        };
        let mut m = match (n.attribute("file"), list("vertex")?) {
            (Some(_), Some(_)) => {
                return Err(at(
                    "both `file` and `vertex` given (MuJoCo: repeated vertex specification)".into(),
                ))
            }
            (Some(f), None) => self.load(f, scale).map_err(at)?,
            (None, Some(v)) => mesh::inline(&v, list("face")?.as_deref(), scale).map_err(at)?,
            (None, None) => return Err(at("a <mesh> needs `file` or `vertex`".into())),
        };
        let hull_weighed = kind == MeshInertia::Convex || m.face.is_empty();
        if let Some(v) = attr("maxhullvert").filter(|v| hull_weighed && v.trim() != "-1") {
            return Err(err(src, n, &format!("{what}.maxhullvert"), format!("`maxhullvert=\"{v}\"` stops MuJoCo's hull early, and this mesh is weighed by its hull: that partial hull is not reproduced (drop the attribute, or give the body an <inertial>)")));
        }
        let norm = refquat.iter().map(|x| x * x).sum::<f64>().sqrt();
        mesh::transform(&mut m, refpos, refquat.map(|x| x / norm), scale);
        mesh::mass(&m, kind).map_err(|e| at(format!("mesh `{name}`: {e}")))
    }

    /// The mesh file `file` (in `meshdir`, relative to the main file's folder, under the path
    /// rule of [`crate::input::resolve`]) by its extension: `.stl`, `.obj` or `.msh`.
    fn load(&self, file: &str, scale: [f64; 3]) -> Result<mesh::Mesh, String> {
        let file = if self.c.strippath {
            Path::new(file)
                .file_name()
                .and_then(|s| s.to_str())
                .unwrap_or(file)
        } else {
            file
        };
        let rel = Path::new(&self.c.meshdir).join(file);
        let rel = rel.to_string_lossy();
        let dir = self.src.file.parent().unwrap_or(Path::new("."));
        let path = crate::input::resolve(&rel, dir)?;
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        if !["stl", "obj", "msh"].contains(&ext.as_str()) {
            return Err(format!("`{rel}`: a mesh file is .stl, .obj or .msh"));
        }
        let bytes = crate::input::read(&path, crate::input::ROBOT_LIMIT)
            .map_err(|e| format!("cannot read `{}`: {e}", path.display()))?;
        let out = match ext.as_str() {
            "stl" => mesh::stl(&bytes, scale),
            "msh" => mesh::msh(&bytes, scale),
            _ => match String::from_utf8(bytes) {
                Ok(t) => mesh::obj(&t, scale),
                Err(_) => Err("an OBJ file is text; this one is not UTF-8".into()),
            },
        };
        out.map_err(|e| format!("`{}`: {e}", path.display()))
    }
}
