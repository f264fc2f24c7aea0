//! Export tests: well-formed XML (own minimal parser), numbers read back, kinematics recomputed from
//! the documents alone (MuJoCo and URDF semantics) against our forward kinematics, mass floor,
//! coordinate maps, unsupported cases, bundled scenes.

use super::*;
use crate::tree::{self, BodySpec, Fields, JointSpec, WORLD};
use nalgebra::{Matrix3, Quaternion, Rotation3, Unit, UnitQuaternion, Vector3};

// ---------- minimal XML parser (checks tag balance and attribute syntax) ----------

#[derive(Debug)]
struct El {
    name: String,
    attrs: Vec<(String, String)>,
    children: Vec<El>,
}

impl El {
    fn attr(&self, k: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(a, _)| a == k)
            .map(|(_, v)| v.as_str())
    }
    fn f(&self, k: &str) -> Vec<f64> {
        self.attr(k)
            .unwrap_or_else(|| panic!("<{}> lacks {k}", self.name))
            .split_whitespace()
            .map(|s| s.parse().expect("number"))
            .collect()
    }
    fn v3(&self, k: &str) -> Vector3<f64> {
        let v = self.f(k);
        assert_eq!(v.len(), 3, "{k}");
        Vector3::new(v[0], v[1], v[2])
    }
    fn all<'a>(&'a self, name: &str, out: &mut Vec<&'a El>) {
        if self.name == name {
            out.push(self);
        }
        for c in &self.children {
            c.all(name, out);
        }
    }
    fn find(&self, name: &str) -> Vec<&El> {
        let mut v = vec![];
        self.all(name, &mut v);
        v
    }
    fn child(&self, name: &str) -> Option<&El> {
        self.children.iter().find(|c| c.name == name)
    }
}

fn unescape(s: &str) -> Result<String, String> {
    if s.contains('<') {
        return Err(format!("'<' in attribute value {s:?}"));
    }
    let mut out = String::new();
    let mut rest = s;
    while let Some(i) = rest.find('&') {
        out.push_str(&rest[..i]);
        let j = rest[i..].find(';').ok_or("unterminated entity")? + i;
        out.push(match &rest[i + 1..j] {
            "amp" => '&',
            "lt" => '<',
            "gt" => '>',
            "quot" => '"',
            "apos" => '\'',
            e => return Err(format!("unknown entity {e}")),
        });
        rest = &rest[j + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

fn parse_xml(xml: &str) -> Result<El, String> {
    let b = xml.as_bytes();
    let mut i = 0;
    let mut stack: Vec<El> = vec![];
    let mut root: Option<El> = None;
    let is_name = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b'-' || c == b':';
    while i < b.len() {
        if b[i] != b'<' {
            if !b[i].is_ascii_whitespace() {
                return Err(format!("text outside tags at byte {i}"));
            }
            i += 1;
            continue;
        }
        if xml[i..].starts_with("<?") {
            if !stack.is_empty() || root.is_some() || i != 0 {
                return Err("misplaced declaration".into());
            }
            i = xml[i..].find("?>").ok_or("unterminated declaration")? + i + 2;
            continue;
        }
        if xml[i..].starts_with("<!--") {
            i = xml[i..].find("-->").ok_or("unterminated comment")? + i + 3;
            continue;
        }
        if xml[i..].starts_with("</") {
            let j = xml[i..].find('>').ok_or("unterminated end tag")? + i;
            let name = xml[i + 2..j].trim();
            let el = stack.pop().ok_or(format!("unmatched </{name}>"))?;
            if el.name != name {
                return Err(format!("</{name}> closes <{}>", el.name));
            }
            i = j + 1;
            match stack.last_mut() {
                Some(p) => p.children.push(el),
                None if root.is_none() => root = Some(el),
                None => return Err("two root elements".into()),
            }
            continue;
        }
        // start tag
        i += 1;
        let s = i;
        while i < b.len() && is_name(b[i]) {
            i += 1;
        }
        if s == i {
            return Err(format!("empty tag name at byte {s}"));
        }
        let mut el = El {
            name: xml[s..i].to_string(),
            attrs: vec![],
            children: vec![],
        };
        loop {
            let ws = i;
            while i < b.len() && b[i].is_ascii_whitespace() {
                i += 1;
            }
            if i >= b.len() {
                return Err("unterminated tag".into());
            }
            if b[i] == b'>' || xml[i..].starts_with("/>") {
                break;
            }
            if ws == i {
                return Err(format!("missing space before attribute in <{}>", el.name));
            }
            let s = i;
            while i < b.len() && is_name(b[i]) {
                i += 1;
            }
            let k = xml[s..i].to_string();
            if k.is_empty() || !xml[i..].starts_with("=\"") {
                return Err(format!("bad attribute in <{}> at byte {i}", el.name));
            }
            i += 2;
            let e = xml[i..].find('"').ok_or("unterminated attribute")? + i;
            if el.attrs.iter().any(|(a, _)| *a == k) {
                return Err(format!("duplicate attribute {k}"));
            }
            el.attrs.push((k, unescape(&xml[i..e])?));
            i = e + 1;
        }
        let selfclose = b[i] == b'/';
        i += if selfclose { 2 } else { 1 };
        if selfclose {
            match stack.last_mut() {
                Some(p) => p.children.push(el),
                None if root.is_none() => root = Some(el),
                None => return Err("two root elements".into()),
            }
        } else {
            stack.push(el);
        }
    }
    if let Some(el) = stack.last() {
        return Err(format!("<{}> not closed", el.name));
    }
    root.ok_or("no root element".into())
}

#[test]
fn xml_checker_rejects_malformed() {
    assert!(parse_xml("<a><b/></a>").is_ok());
    assert!(parse_xml("<a><b></a>").is_err());
    assert!(parse_xml("<a></a><b/>").is_err());
    assert!(parse_xml("<a x=\"1\"y=\"2\"/>").is_err());
    assert!(parse_xml("<a x=\"1\" x=\"2\"/>").is_err());
    assert!(parse_xml("<a x=\"&bogus;\"/>").is_err());
    assert!(parse_xml("<a>text</a>").is_err());
    assert_eq!(
        parse_xml("<a n=\"x&amp;&quot;y\"/>").unwrap().attr("n"),
        Some("x&\"y")
    );
}

// ---------- models ----------

fn inertia(a: f64, b: f64, c: f64) -> [[f64; 3]; 3] {
    [[a, 0.0, 0.0], [0.0, b, 0.0], [0.0, 0.0, c]]
}

/// Branches, several joints per body with anchors, a rotated placement, a full inertia tensor, a
/// point mass, a massless coordinate body, a welded body, a spring and a damper, a free body, a name
/// that needs escaping, siblings whose joint names are not in byte order.
fn complex() -> tree::Model {
    let full = [[2.0, 0.1, -0.2], [0.1, 1.5, 0.05], [-0.2, 0.05, 1.8]];
    let s = 0.5f64.sqrt();
    let bodies = vec![
        BodySpec::new("base", WORLD, 3.0, [0.1, -0.2, 0.3], full)
            .at([0.2, 0.1, 0.5])
            .rotated([s, 0.0, s, 0.0])
            .joint(JointSpec::hinge("z_yaw", [0.0, 0.0, 1.0]).with_anchor([0.1, 0.0, 0.0]))
            .joint(JointSpec::slide("lift", [0.0, 0.6, 0.8]).with_spring(5.0, 0.3))
            .joint(
                JointSpec::hinge("pitch", [1.0, 1.0, 0.0])
                    .with_anchor([0.0, 0.2, -0.1])
                    .with_damping(0.7),
            ),
        BodySpec::point_mass("tip<&>", "base", 0.8, [0.3, 0.0, 0.1])
            .at([0.0, 0.0, -0.6])
            .joint(JointSpec::hinge("elbow", [0.0, 1.0, 0.0]).with_anchor([0.0, 0.1, 0.2])),
        BodySpec::new(
            "welded",
            "tip<&>",
            0.4,
            [0.0, 0.1, 0.0],
            inertia(0.1, 0.2, 0.25),
        )
        .at([0.1, 0.2, 0.3])
        .rotated([0.9, 0.1, -0.2, 0.3]),
        BodySpec::massless("gimbal", "base")
            .at([0.3, 0.0, 0.0])
            .joint(JointSpec::hinge("g1", [1.0, 0.0, 0.0]).with_anchor([0.0, 0.05, 0.0]))
            .joint(JointSpec::hinge("a_g2", [0.0, 0.0, 1.0])),
        BodySpec::new(
            "pod",
            "gimbal",
            1.2,
            [0.0, 0.0, 0.2],
            inertia(0.3, 0.3, 0.1),
        )
        .at([0.0, 0.0, 0.4])
        .joint(JointSpec::slide("extend", [0.0, 0.0, 1.0])),
        BodySpec::new(
            "drone",
            WORLD,
            2.0,
            [0.0, 0.0, 0.05],
            inertia(0.2, 0.3, 0.4),
        )
        .joint(JointSpec::free("fly").with_damping(0.1)),
    ];
    let fields = Fields {
        gravity: [0.1, -0.2, -9.81],
        attractors: vec![tree::Attractor {
            point: [1.0, 2.0, 3.0],
            mu: 4.0,
        }],
    };
    tree::Model::new(&bodies, fields).unwrap()
}

/// [`complex`] with armature (hinge, slide, free), reference positions (hinges and a slide, on
/// first and later joints of a body) and gravity compensation (full, partial, and on a body
/// whose joints' link frames sit at an anchor).
fn complex_extras() -> tree::Model {
    let m = complex();
    let mut specs: Vec<BodySpec> = vec![];
    for b in m.bodies() {
        let mut s = if b.massless {
            BodySpec::massless(&b.name, "")
        } else {
            BodySpec::new(
                &b.name,
                "",
                b.mass,
                b.com.into(),
                super::to_rows(&b.inertia),
            )
        };
        s.parent = b
            .parent
            .map_or(WORLD.to_string(), |p| m.bodies()[p].name.clone());
        s = s.at(b.pos.into()).rotated(b.quat);
        s.gravcomp = match b.name.as_str() {
            "base" => 1.0,
            "pod" => 0.4,
            "tip<&>" => -0.5,
            _ => 0.0,
        };
        for j in b.joints.clone() {
            let jt = &m.joints()[j];
            let (arm, r) = match jt.name.as_str() {
                "z_yaw" => (0.2, 0.3),
                "lift" => (0.05, -0.25),
                "pitch" => (0.0, 0.8),
                "a_g2" => (0.01, -1.1),
                "extend" => (0.3, 0.15),
                "fly" => (0.07, 0.0),
                _ => (0.0, 0.0),
            };
            s = s.joint(
                JointSpec::new(&jt.name, jt.joint_type())
                    .with_anchor(jt.anchor.into())
                    .with_spring(jt.stiffness, jt.spring_ref)
                    .with_damping(jt.damping)
                    .with_armature(arm)
                    .with_reference(r),
            );
        }
        specs.push(s);
    }
    tree::Model::new(&specs, m.fields().clone()).unwrap()
}

fn particle() -> tree::Model {
    let body = BodySpec::point_mass("p", WORLD, 2.0, [0.0; 3])
        .joint(JointSpec::hinge("phi", [0.0, 0.0, 1.0]))
        .joint(JointSpec::hinge("theta", [0.0, -1.0, 0.0]))
        .joint(JointSpec::slide("r", [1.0, 0.0, 0.0]));
    tree::Model::new(&[body], Fields::default()).unwrap()
}

fn top() -> tree::Model {
    let b = BodySpec::new("top", WORLD, 1.0, [0.0, 0.0, 0.5], inertia(1.25, 1.25, 0.5))
        .joint(JointSpec::ball("ball"))
        .joint(JointSpec::slide("stretch", [0.0, 0.0, 1.0]).with_damping(0.2));
    tree::Model::new(
        &[b],
        Fields {
            gravity: [0.0, 0.0, -9.81],
            attractors: vec![],
        },
    )
    .unwrap()
}

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

fn random_q(m: &tree::Model, rng: &mut Rng) -> Vec<f64> {
    let mut q: Vec<f64> = (0..m.nq()).map(|_| rng.next()).collect();
    tree::normalize_quaternions(m, &mut q);
    q
}

fn rot_axis(axis: Vector3<f64>, angle: f64) -> Matrix3<f64> {
    Rotation3::from_axis_angle(&Unit::new_normalize(axis), angle).into_inner()
}

fn rot_wxyz(q: &[f64]) -> Matrix3<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
        .to_rotation_matrix()
        .into_inner()
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + b.abs())
}

fn assert_close3(a: &Vector3<f64>, b: &Vector3<f64>, what: &str) {
    assert!((a - b).norm() < 1e-12, "{what}: {a:?} vs {b:?}");
}

fn assert_map_consistent(m: &tree::Model, r: &ExportReport) {
    let names: Vec<_> = r.q_map.iter().map(|c| c.name.clone()).collect();
    assert_eq!(names, m.q_names());
    let names: Vec<_> = r.v_map.iter().map(|c| c.name.clone()).collect();
    assert_eq!(names, m.v_names());
    for (map, n) in [(&r.q_map, m.nq()), (&r.v_map, m.nv())] {
        let mut s: Vec<_> = map.iter().map(|c| c.sim_index).collect();
        assert!(map.iter().enumerate().all(|(i, c)| c.index == i));
        s.sort();
        assert_eq!(s, (0..n).collect::<Vec<_>>(), "not a permutation");
        for c in map.iter() {
            let j = m.joint_id(&c.sim_joint).expect("sim joint is one of ours");
            assert!(m.joint_q_range(j).contains(&c.index) || m.joint_v_range(j).contains(&c.index));
        }
    }
}

// ---------- MJCF ----------

/// World pose of every body from the MJCF alone, MuJoCo semantics (joints of a body in sequence,
/// hinge/ball about `pos`), qpos indexed through the report's q map.
fn mjcf_poses(
    doc: &El,
    m: &tree::Model,
    r: &ExportReport,
    q: &[f64],
) -> Vec<(String, Matrix3<f64>, Vector3<f64>)> {
    let mut qpos = vec![0.0; m.nq()];
    for c in &r.q_map {
        qpos[c.sim_index] = q[c.index];
    }
    let mut out = vec![];
    let mut k = 0;
    let wb = doc.child("worldbody").unwrap();
    fn walk(
        el: &El,
        rot: Matrix3<f64>,
        pos: Vector3<f64>,
        qpos: &[f64],
        k: &mut usize,
        out: &mut Vec<(String, Matrix3<f64>, Vector3<f64>)>,
    ) {
        for b in el.children.iter().filter(|c| c.name == "body") {
            let mut p = pos + rot * b.v3("pos");
            let mut r = rot * rot_wxyz(&b.f("quat"));
            for j in b.children.iter().filter(|c| c.name == "joint") {
                let anchor = |j: &El| j.attr("pos").map(|_| j.v3("pos")).unwrap_or_default();
                // MuJoCo: hinges and slides move by qpos - ref
                let r0 = j.attr("ref").map_or(0.0, |_| j.f("ref")[0]);
                match j.attr("type").unwrap() {
                    "hinge" => {
                        let a = anchor(j);
                        let xa = p + r * a;
                        r *= rot_axis(j.v3("axis"), qpos[*k] - r0);
                        p = xa - r * a;
                        *k += 1;
                    }
                    "slide" => {
                        p += r * j.v3("axis").normalize() * (qpos[*k] - r0);
                        *k += 1;
                    }
                    "ball" => {
                        let a = anchor(j);
                        let xa = p + r * a;
                        r *= rot_wxyz(&qpos[*k..*k + 4]);
                        p = xa - r * a;
                        *k += 4;
                    }
                    "free" => {
                        p = Vector3::new(qpos[*k], qpos[*k + 1], qpos[*k + 2]);
                        r = rot_wxyz(&qpos[*k + 3..*k + 7]);
                        *k += 7;
                    }
                    t => panic!("joint type {t}"),
                }
            }
            out.push((b.attr("name").unwrap().to_string(), r, p));
            walk(b, r, p, qpos, k, out);
        }
    }
    walk(
        wb,
        Matrix3::identity(),
        Vector3::zeros(),
        &qpos,
        &mut k,
        &mut out,
    );
    assert_eq!(k, m.nq());
    out
}

fn check_mjcf(m: &tree::Model) -> ExportReport {
    let o = ExportOptions::default();
    let (xml, r) = mjcf(m, &o).unwrap();
    let doc = parse_xml(&xml).unwrap_or_else(|e| panic!("{e}\n{xml}"));
    assert_eq!(doc.name, "mujoco");
    assert_eq!(doc.child("compiler").unwrap().attr("angle"), Some("radian"));
    let opt = doc.child("option").unwrap();
    assert_eq!(opt.attr("integrator"), Some("RK4"));
    assert_eq!(opt.f("gravity"), m.fields().gravity.to_vec());
    let flag = opt.child("flag").unwrap();
    for f in ["contact", "limit", "equality", "frictionloss", "autoreset"] {
        assert_eq!(flag.attr(f), Some("disable"), "{f}");
    }
    assert_eq!(flag.attr("actuation"), None, "actuation must stay enabled");
    let spring = m.joints().iter().any(|j| j.stiffness != 0.0);
    let damper =
        m.joints().iter().any(|j| j.damping != 0.0) || m.bodies().iter().any(|b| b.gravcomp != 0.0);
    assert_eq!(flag.attr("spring") == Some("enable"), spring);
    assert_eq!(flag.attr("damper") == Some("enable"), damper);
    assert!(doc.find("actuator").is_empty());

    // bodies: placement, inertial (with the reported floor)
    let bodies = doc.find("body");
    assert_eq!(bodies.len(), m.bodies().len());
    for be in &bodies {
        let name = be.attr("name").unwrap();
        let b = &m.bodies()[m.body_id(name).expect("body name")];
        assert_eq!(be.v3("pos"), b.pos);
        assert_eq!(be.f("quat"), b.quat.to_vec());
        let gc = be.attr("gravcomp").map_or(0.0, |_| be.f("gravcomp")[0]);
        assert_eq!(gc, b.gravcomp, "{name}");
        let ine = be.child("inertial").expect("explicit inertial");
        assert_eq!(ine.v3("pos"), b.com);
        let change = r.mass_changes.iter().find(|c| c.body == name);
        let (mass, i) = match change {
            Some(c) => (c.new_mass, Matrix3::from_row_slice(&c.new_inertia.concat())),
            None => (b.mass, b.inertia),
        };
        assert_eq!(ine.f("mass"), vec![mass]);
        let got = match (ine.attr("diaginertia"), ine.attr("fullinertia")) {
            (Some(_), None) => Matrix3::from_diagonal(&ine.v3("diaginertia")),
            (None, Some(_)) => {
                let v = ine.f("fullinertia");
                Matrix3::new(v[0], v[3], v[4], v[3], v[1], v[5], v[4], v[5], v[2])
            }
            _ => panic!("exactly one of diaginertia/fullinertia"),
        };
        assert_eq!(got, i, "{name}");
        if !b.joints.is_empty() {
            assert!(
                mass > 1e-15 && i.symmetric_eigenvalues().min() > 1e-15,
                "{name}"
            );
        }
        // joints in sequence, in our order
        let je: Vec<_> = be.children.iter().filter(|c| c.name == "joint").collect();
        assert_eq!(je.len(), b.joints.len());
        for (e, j) in je.iter().zip(b.joints.clone()) {
            let jt = &m.joints()[j];
            assert_eq!(e.attr("name"), Some(jt.name.as_str()));
            assert_eq!(e.f("armature"), vec![jt.armature]);
            match jt.joint_type() {
                tree::JointType::Hinge { axis } => {
                    assert_eq!(e.attr("type"), Some("hinge"));
                    assert_eq!(e.f("axis"), axis.to_vec());
                    assert_eq!(e.v3("pos"), jt.anchor);
                }
                tree::JointType::Slide { axis } => {
                    assert_eq!(e.attr("type"), Some("slide"));
                    assert_eq!(e.f("axis"), axis.to_vec());
                }
                tree::JointType::Ball => assert_eq!(e.attr("type"), Some("ball")),
                tree::JointType::Free => assert_eq!(e.attr("type"), Some("free")),
            }
            let get = |k: &str| e.attr(k).map(|_| e.f(k)[0]).unwrap_or(0.0);
            assert_eq!(get("damping"), jt.damping);
            assert_eq!(get("stiffness"), jt.stiffness);
            assert_eq!(get("springref"), jt.spring_ref);
            assert_eq!(get("ref"), jt.reference);
        }
    }
    assert_map_consistent(m, &r);
    // kinematics from the document equal ours
    let mut rng = Rng(7);
    let mut data = m.data::<f64>();
    for _ in 0..5 {
        let q = random_q(m, &mut rng);
        for (name, rot, pos) in mjcf_poses(&doc, m, &r, &q) {
            let (r0, p0) = tree::body_pose(m, &mut data, &q, m.body_id(&name).unwrap());
            assert!((rot - r0).norm() < 1e-12, "{name} rotation");
            assert_close3(&pos, &p0, &name);
        }
    }
    r
}

#[test]
fn mjcf_complex_model() {
    let m = complex();
    let r = check_mjcf(&m);
    // floor: the point mass (zero inertia) and the massless gimbal; not the welded body
    let changed: Vec<_> = r.mass_changes.iter().map(|c| c.body.as_str()).collect();
    assert_eq!(changed, ["tip<&>", "gimbal"]);
    let g = &r.mass_changes[1];
    assert_eq!((g.old_mass, g.new_mass), (0.0, 1e-14));
    assert_eq!(g.new_inertia, inertia(1e-14, 1e-14, 1e-14));
    let t = &r.mass_changes[0];
    assert_eq!((t.old_mass, t.new_mass, t.delta_mass), (0.8, 0.8, 0.0));
    assert!(close(t.delta_inertia, 1e-14, 1e-12));
    // attractor listed for the harness, with every massive body
    match &r.harness_forces[..] {
        [HarnessForce::Attractor {
            point, mu, bodies, ..
        }] => {
            assert_eq!((*point, *mu), ([1.0, 2.0, 3.0], 4.0));
            assert_eq!(bodies.len(), 5);
        }
        f => panic!("{f:?}"),
    }
    // the report serializes
    let js = serde_json::to_string(&r).unwrap();
    let back: ExportReport = serde_json::from_str(&js).unwrap();
    assert_eq!(back, r);
    // escaped name
    assert!(mjcf(&m, &ExportOptions::default())
        .unwrap()
        .0
        .contains("name=\"tip&lt;&amp;&gt;\""));
}

/// Armature, reference positions and gravity compensation: MJCF carries them as attributes (and
/// the document's MuJoCo-semantics kinematics, qpos - ref, equal ours); URDF folds ref into the
/// joint origins (the document's kinematics equal ours with q itself as Pinocchio's coordinate),
/// lists armature for `model.armature` and gravity compensation as harness forces. Negative
/// control: the document of the same tree without ref, read at the same q, puts the links
/// elsewhere.
#[test]
fn armature_ref_gravcomp_exported() {
    let m = complex_extras();
    let r = check_mjcf(&m);
    assert!(r.armature.is_empty());
    assert!(!r
        .harness_forces
        .iter()
        .any(|f| matches!(f, HarnessForce::Gravcomp { .. })));
    let r = check_urdf(&m);
    let arm: Vec<_> = r
        .armature
        .iter()
        .map(|a| (a.joint.as_str(), a.armature, a.sim_v, a.nv))
        .collect();
    // Pinocchio order: fly, z_yaw, lift, pitch, elbow, g1, a_g2, extend
    assert_eq!(
        arm,
        [
            ("fly", 0.07, 0, 6),
            ("z_yaw", 0.2, 6, 1),
            ("lift", 0.05, 7, 1),
            ("a_g2", 0.01, 11, 1),
            ("extend", 0.3, 12, 1)
        ]
    );
    let gc: Vec<_> = r
        .harness_forces
        .iter()
        .filter_map(|f| match f {
            HarnessForce::Gravcomp {
                body,
                gravcomp,
                mass,
                ..
            } => Some((body.as_str(), *gravcomp, *mass)),
            _ => None,
        })
        .collect();
    assert_eq!(
        gc,
        [("base", 1.0, 3.0), ("tip<&>", -0.5, 0.8), ("pod", 0.4, 1.2)]
    );
    // negative control: without the fold the links are elsewhere
    let (xml0, r0) = urdf(&complex(), &ExportOptions::default()).unwrap();
    let doc0 = parse_xml(&xml0).unwrap();
    let q = random_q(&m, &mut Rng(3));
    let frames = urdf_links(&doc0, &m, &r0, &q);
    let (rot, _) = tree::body_pose(&m, &mut m.data(), &q, m.body_id("pod").unwrap());
    assert!((frames["pod"].0 - rot).norm() > 1e-2);
    // existing documents are unchanged by the new fields: no gravcomp, ref or nonzero armature
    let (xml, r) = mjcf(&complex(), &ExportOptions::default()).unwrap();
    assert!(!xml.contains("gravcomp") && !xml.contains(" ref="));
    assert!(serde_json::to_string(&r)
        .unwrap()
        .find("\"armature\"")
        .is_none());
}

#[test]
fn mjcf_particle_and_top() {
    let r = check_mjcf(&particle());
    assert_eq!(r.mass_changes.len(), 1);
    assert_eq!(r.mass_changes[0].new_inertia, inertia(1e-14, 1e-14, 1e-14));
    let r = check_mjcf(&top());
    assert!(r.mass_changes.is_empty());
    assert!(r.harness_forces.is_empty());
}

#[test]
fn mjcf_order_is_depth_first() {
    // bodies listed a, b (world), c (child of a): MuJoCo order a, c, b
    let bs = vec![
        BodySpec::point_mass("a", WORLD, 1.0, [1.0, 0.0, 0.0])
            .joint(JointSpec::hinge("ja", [0.0, 0.0, 1.0])),
        BodySpec::point_mass("b", WORLD, 1.0, [1.0, 0.0, 0.0])
            .joint(JointSpec::hinge("jb", [0.0, 0.0, 1.0])),
        BodySpec::point_mass("c", "a", 1.0, [1.0, 0.0, 0.0])
            .joint(JointSpec::hinge("jc", [0.0, 0.0, 1.0])),
    ];
    let m = tree::Model::new(&bs, Fields::default()).unwrap();
    let r = check_mjcf(&m);
    let s: Vec<_> = r.q_map.iter().map(|c| c.sim_index).collect();
    assert_eq!(s, [0, 2, 1]);
}

#[test]
fn options_are_checked() {
    let m = particle();
    for o in [
        ExportOptions {
            min_mass: 1e-16,
            ..Default::default()
        },
        ExportOptions {
            min_inertia: 0.0,
            ..Default::default()
        },
        ExportOptions {
            timestep: -1.0,
            ..Default::default()
        },
    ] {
        assert!(matches!(mjcf(&m, &o), Err(ExportError::Options(_))));
        assert!(matches!(urdf(&m, &o), Err(ExportError::Options(_))));
    }
    // a larger floor is reported as such
    let o = ExportOptions {
        min_mass: 1e-9,
        min_inertia: 1e-9,
        ..Default::default()
    };
    let (_, r) = mjcf(&m, &o).unwrap();
    assert_eq!(r.mass_changes[0].new_inertia, inertia(1e-9, 1e-9, 1e-9));
}

// ---------- URDF ----------

/// World frame of every URDF link from the document alone (URDF/Pinocchio semantics).
fn urdf_links(
    doc: &El,
    m: &tree::Model,
    r: &ExportReport,
    q: &[f64],
) -> std::collections::HashMap<String, (Matrix3<f64>, Vector3<f64>)> {
    let mut sq = vec![0.0; m.nq()];
    for c in &r.q_map {
        sq[c.sim_index] = q[c.index];
    }
    // Pinocchio joint order: sim index of the first q of each joint
    let qstart = |name: &str| {
        r.q_map
            .iter()
            .filter(|c| c.sim_joint == name)
            .map(|c| c.sim_index)
            .min()
            .unwrap()
    };
    let mut frames = std::collections::HashMap::new();
    let links = doc.find("link");
    let joints = doc.find("joint");
    let children: Vec<_> = joints
        .iter()
        .map(|j| j.child("child").unwrap().attr("link").unwrap())
        .collect();
    let roots: Vec<_> = links
        .iter()
        .map(|l| l.attr("name").unwrap())
        .filter(|n| !children.contains(n))
        .collect();
    assert_eq!(roots.len(), 1, "one root link");
    let root = roots[0];
    match &r.root_joint {
        None => {
            assert_eq!(root, "world");
            frames.insert(root.to_string(), (Matrix3::identity(), Vector3::zeros()));
        }
        Some(rj) => {
            assert_eq!(rj.python, "pin.JointModelSpherical()");
            let k = qstart(&rj.name);
            // Pinocchio quaternion (x, y, z, w)
            let rot = rot_wxyz(&[sq[k + 3], sq[k], sq[k + 1], sq[k + 2]]);
            frames.insert(root.to_string(), (rot, Vector3::zeros()));
        }
    }
    let mut changed = true;
    while changed {
        changed = false;
        for j in &joints {
            let p = j.child("parent").unwrap().attr("link").unwrap();
            let c = j.child("child").unwrap().attr("link").unwrap();
            if frames.contains_key(c) || !frames.contains_key(p) {
                continue;
            }
            let (pr, pp) = frames[p];
            let o = j.child("origin").unwrap();
            let rpy = o.f("rpy");
            let or = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]).into_inner();
            let (mut r2, mut p2) = (pr * or, pp + pr * o.v3("xyz"));
            let name = j.attr("name").unwrap();
            match j.attr("type").unwrap() {
                "revolute" => {
                    let ax = j.child("axis").unwrap().v3("xyz");
                    r2 *= rot_axis(ax, sq[qstart(name)]);
                    let l = j.child("limit").unwrap();
                    assert!(l.f("lower")[0] <= -1e9 && l.f("upper")[0] >= 1e9);
                }
                "prismatic" => {
                    let ax = j.child("axis").unwrap().v3("xyz");
                    p2 += r2 * ax.normalize() * sq[qstart(name)];
                }
                "floating" => {
                    let k = qstart(name);
                    p2 += r2 * Vector3::new(sq[k], sq[k + 1], sq[k + 2]);
                    r2 *= rot_wxyz(&[sq[k + 6], sq[k + 3], sq[k + 4], sq[k + 5]]);
                }
                "fixed" => {}
                t => panic!("joint type {t}"),
            }
            frames.insert(c.to_string(), (r2, p2));
            changed = true;
        }
    }
    assert_eq!(frames.len(), links.len(), "every link reached");
    frames
}

fn check_urdf(m: &tree::Model) -> ExportReport {
    let (xml, r) = urdf(m, &ExportOptions::default()).unwrap();
    let doc = parse_xml(&xml).unwrap_or_else(|e| panic!("{e}\n{xml}"));
    assert_eq!(doc.name, "robot");
    assert_map_consistent(m, &r);
    assert_eq!(r.gravity, m.fields().gravity);
    assert!(r.mass_changes.is_empty());
    // one URDF joint per joint of ours (except a root ball), plus fixed joints for joint-less bodies
    let joints = doc.find("joint");
    let njoints = m.joints().len() - r.root_joint.is_some() as usize;
    let nfixed = m.bodies().iter().filter(|b| b.joints.is_empty()).count();
    assert_eq!(joints.len(), njoints + nfixed);
    for j in &joints {
        let ty = j.attr("type").unwrap();
        assert_ne!(ty, "continuous", "Pinocchio: nq = 2");
    }
    // the link named after each body carries its inertia; CoM and orientation match our kinematics
    let mut rng = Rng(11);
    let mut data = m.data::<f64>();
    for _ in 0..5 {
        let q = random_q(m, &mut rng);
        let frames = urdf_links(&doc, m, &r, &q);
        for (bi, b) in m.bodies().iter().enumerate() {
            let le = doc
                .find("link")
                .into_iter()
                .find(|l| l.attr("name") == Some(b.name.as_str()))
                .expect("link named after the body");
            let (r0, p0) = tree::body_pose(m, &mut data, &q, bi);
            let (rl, pl) = frames[&b.name];
            assert!((rl - r0).norm() < 1e-12, "{} rotation", b.name);
            match le.child("inertial") {
                None => assert!(b.massless, "{}", b.name),
                Some(ie) => {
                    assert!(!b.massless);
                    let o = ie.child("origin").unwrap();
                    assert_eq!(o.f("rpy"), vec![0.0; 3]);
                    let com = pl + rl * o.v3("xyz");
                    assert_close3(&com, &(p0 + r0 * b.com), &b.name);
                    assert_eq!(ie.child("mass").unwrap().f("value"), vec![b.mass]);
                    let ii = ie.child("inertia").unwrap();
                    let g = |k: &str| ii.f(k)[0];
                    let i = Matrix3::new(
                        g("ixx"),
                        g("ixy"),
                        g("ixz"),
                        g("ixy"),
                        g("iyy"),
                        g("iyz"),
                        g("ixz"),
                        g("iyz"),
                        g("izz"),
                    );
                    assert_eq!(i, b.inertia, "{}", b.name);
                }
            }
        }
        // intermediate links are massless
        for l in doc.find("link") {
            let n = l.attr("name").unwrap();
            if m.body_id(n).is_none() {
                assert!(l.child("inertial").is_none(), "{n}");
            }
        }
    }
    r
}

#[test]
fn urdf_complex_model() {
    let m = complex();
    let r = check_urdf(&m);
    assert!(r.root_joint.is_none());
    // Pinocchio order: depth-first, child joints by name: world: fly < z_yaw; base: elbow < g1.
    let order: Vec<&str> = {
        let mut v: Vec<_> = r.v_map.iter().collect();
        v.sort_by_key(|c| c.sim_index);
        v.dedup_by_key(|c| c.sim_joint.clone());
        v.iter()
            .map(|c| m.joints()[m.joint_id(&c.sim_joint).unwrap()].name.as_str())
            .collect()
    };
    assert_eq!(
        order,
        ["fly", "z_yaw", "lift", "pitch", "elbow", "g1", "a_g2", "extend"]
    );
    // free joint: quaternion reordered, linear velocity in the body frame
    let fly = m.joint_id("fly").unwrap();
    let qs: Vec<_> = m.joint_q_range(fly).map(|i| r.q_map[i].sim_index).collect();
    assert_eq!(qs, [0, 1, 2, 6, 3, 4, 5]);
    let conv: Vec<_> = m
        .joint_v_range(fly)
        .map(|i| r.v_map[i].conversion)
        .collect();
    assert_eq!(conv[..3], [Conversion::BodyFrame; 3]);
    assert_eq!(conv[3..], [Conversion::Same; 3]);
    // springs and dampers are harness forces in URDF
    let kinds: Vec<_> = r
        .harness_forces
        .iter()
        .map(|f| match f {
            HarnessForce::Attractor { .. } => "attractor".to_string(),
            HarnessForce::Gravcomp { body, .. } => format!("gravcomp {body}"),
            HarnessForce::Spring { joint, sim_q, .. } => format!("spring {joint} {sim_q}"),
            HarnessForce::Damper {
                joint, sim_v, nv, ..
            } => format!("damper {joint} {sim_v} {nv}"),
            HarnessForce::PointForce { body, .. } => format!("point force {body}"),
            HarnessForce::CoordinateForce { v_name, .. } => format!("coordinate force {v_name}"),
            HarnessForce::SuppliedReaction { rows, .. } => format!("supplied {rows:?}"),
        })
        .collect();
    assert_eq!(
        kinds,
        [
            "attractor",
            "damper fly 0 6",
            "spring lift 8",
            "damper pitch 8 1"
        ]
    );
}

#[test]
fn urdf_particle_chain() {
    let m = particle();
    let (xml, _) = urdf(&m, &ExportOptions::default()).unwrap();
    assert!(xml.contains("<link name=\"p__phi\">") && xml.contains("<link name=\"p__theta\">"));
    let r = check_urdf(&m);
    let s: Vec<_> = r.q_map.iter().map(|c| c.sim_index).collect();
    assert_eq!(s, [0, 1, 2]);
}

#[test]
fn urdf_ball_at_root() {
    let m = top();
    let r = check_urdf(&m);
    let rj = r.root_joint.as_ref().unwrap();
    assert_eq!(rj.name, "ball");
    // ours (w, x, y, z) -> Pinocchio (x, y, z, w)
    let s: Vec<_> = r.q_map.iter().map(|c| c.sim_index).collect();
    assert_eq!(s, [3, 0, 1, 2, 4]);
}

#[test]
fn urdf_unsupported_ball_joints() {
    let offset = BodySpec::new("top", WORLD, 1.0, [0.0; 3], inertia(1.0, 1.0, 1.0))
        .at([0.0, 0.0, 1.0])
        .joint(JointSpec::ball("ball"));
    let nested = vec![
        BodySpec::new("a", WORLD, 1.0, [0.0; 3], inertia(1.0, 1.0, 1.0))
            .joint(JointSpec::hinge("h", [0.0, 0.0, 1.0])),
        BodySpec::new("b", "a", 1.0, [0.0; 3], inertia(1.0, 1.0, 1.0))
            .joint(JointSpec::ball("shoulder")),
    ];
    let two_roots = vec![
        BodySpec::new("a", WORLD, 1.0, [0.0; 3], inertia(1.0, 1.0, 1.0))
            .joint(JointSpec::ball("ball")),
        BodySpec::new("b", WORLD, 1.0, [0.0; 3], inertia(1.0, 1.0, 1.0))
            .joint(JointSpec::hinge("h", [0.0, 0.0, 1.0])),
    ];
    for (specs, joint) in [
        (vec![offset], "ball"),
        (nested, "shoulder"),
        (two_roots, "ball"),
    ] {
        let m = tree::Model::new(&specs, Fields::default()).unwrap();
        match urdf(&m, &ExportOptions::default()) {
            Err(e @ ExportError::Unsupported { .. }) => {
                let s = e.to_string();
                assert!(
                    s.contains(&format!("'{joint}'")) && s.contains("spherical"),
                    "{s}"
                );
            }
            x => panic!("expected Unsupported, got {x:?}"),
        }
        // MJCF has ball joints
        check_mjcf(&m);
    }
}

#[test]
fn urdf_name_collision() {
    let bs = vec![
        BodySpec::point_mass("a", WORLD, 1.0, [1.0, 0.0, 0.0])
            .joint(JointSpec::hinge("x", [0.0, 0.0, 1.0]))
            .joint(JointSpec::hinge("y", [0.0, 1.0, 0.0])),
        BodySpec::point_mass("a__x", WORLD, 1.0, [1.0, 0.0, 0.0])
            .joint(JointSpec::hinge("z", [0.0, 0.0, 1.0])),
    ];
    let m = tree::Model::new(&bs, Fields::default()).unwrap();
    assert_eq!(
        urdf(&m, &ExportOptions::default()).unwrap_err(),
        ExportError::NameCollision {
            format: Format::Urdf,
            name: "a__x".into()
        }
    );
}

#[test]
fn rpy_round_trip() {
    let mut rng = Rng(3);
    let mut cases: Vec<Matrix3<f64>> = (0..50)
        .map(|_| rot_wxyz(&[rng.next(), rng.next(), rng.next(), rng.next()]))
        .collect();
    cases.push(rot_axis(Vector3::y(), std::f64::consts::FRAC_PI_2));
    cases.push(rot_axis(Vector3::y(), -std::f64::consts::FRAC_PI_2) * rot_axis(Vector3::z(), 0.3));
    for r in cases {
        let a = urdf::rpy(&r);
        let back = Rotation3::from_euler_angles(a[0], a[1], a[2]).into_inner();
        assert!((back - r).norm() < 1e-14, "{r}");
    }
}

// ---------- bundled scenes ----------

fn scene_trees() -> Vec<(String, std::sync::Arc<tree::Model>)> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("references/scenes");
    let mut out = vec![];
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    crate::import::ensure_robot_path_for_tests();
    for p in paths {
        let s = crate::scene::Scene::load(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        if let crate::scene::SceneSystem::Tree(pr) = &s.system {
            out.push((s.name.clone(), pr.model.tree().clone()));
        }
    }
    out
}

#[test]
fn bundled_tree_scenes_export() {
    let trees = scene_trees();
    assert!(trees.len() >= 3, "bundled tree scenes: {}", trees.len());
    for (name, t) in &trees {
        let r = check_mjcf(t);
        assert_eq!(r.format, Format::Mjcf, "{name}");
        let r = check_urdf(t);
        assert_eq!(r.format, Format::Urdf, "{name}");
    }
}

/// Loop closures reach the documents (sites + equality in MJCF, site frames in URDF) and the
/// report lists them with their rows; expression system rows are still refused, naming them.
#[test]
fn closures_are_exported_and_other_system_rows_refused() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("references/scenes");
    let s = crate::scene::Scene::load(dir.join("slider_crank_tree.toml")).unwrap();
    let o = ExportOptions::default();
    let (x, r) = s.export(Format::Mjcf, &o).unwrap();
    assert!(
        x.contains("<site name=\"pin__a\" pos=\"0.3 0.0 0.0\""),
        "{x}"
    );
    assert!(
        x.contains("<connect name=\"pin\" site1=\"pin__a\" site2=\"pin__b\" solref=\"0.004 1\"")
    );
    assert!(x.contains("equality=\"enable\""));
    assert_eq!(r.closures.len(), 1);
    assert_eq!(r.closures[0].rows, ["pin_x", "pin_y", "pin_z"]);
    assert_eq!(r.closures[0].set_aside, ["pin_z"]);
    let (u, r) = s.export(Format::Urdf, &o).unwrap();
    assert!(u.contains("<link name=\"pin__a\"/>") && u.contains("<link name=\"pin__b\"/>"));
    assert_eq!(r.q_map.len(), 3); // site frames add no coordinates
                                  // the four-bar's crank row as a system constraint instead: refused, naming it
    let text = std::fs::read_to_string(dir.join("four_bar.toml"))
        .unwrap()
        .replace("[[programme]]", "[[constraints]]");
    let s = crate::scene::Scene::from_text(&dir.join("four_bar.toml"), &text).unwrap();
    match s.export(Format::Mjcf, &o) {
        Err(ExportError::Unsupported { what, .. }) => {
            assert!(
                what.contains("`crank`") && !what.contains("joint_b"),
                "{what}"
            )
        }
        other => panic!("{other:?}"),
    }
}
