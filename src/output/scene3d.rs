//! The 3D view of a tree scene in recordings (Foxglove's 3D panel): one frame per body moving with
//! q (`foxglove.FrameTransform`, world -> `<prefix>/<body>`) and geometry fixed to those frames
//! (`foxglove.SceneUpdate`, frame-locked entities, written once):
//!
//! - each body with a `shape` in the scene: that shape (box, sphere, cylinder, capsule) at its pose
//!   in the body frame;
//! - each other body with mass: a box with the body's principal axes and its inertia (the uniform box of
//!   the same mass and principal moments, sides `sqrt(6 (I_j + I_k - I_i) / m)`), at the CoM; a
//!   point mass (zero inertia) as a sphere; a massless coordinate body as a small grey sphere;
//! - each joint: an arrow along its axis at its anchor (hinge: blue, slide: green), a sphere for a
//!   ball joint;
//! - a line from each body's origin to each child's origin (the links of the mechanism).
//!
//! - the programme's declared geometric targets (`[[view.targets]]`: point, line, plane, circle,
//!   sampled path) in the world frame, entity ids `<prefix>/target/<name>`;
//! - at the end of a recording, the realized trace of every site the programme rows read: a line
//!   strip in the world frame through its positions at the recorded samples, entity id
//!   `<prefix>/trace/<site>` ([`Bodies::trace_update`]).
//!
//! Sizes of spheres and arrows scale with the mechanism (its largest body-to-body distance). The
//! solver's motion uses prefix `progmo`; `progmo debug` draws the same geometry for each simulator
//! (`mujoco`, `pinocchio`) and the solver's as a translucent ghost.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use serde_json::{json, Value};
use std::sync::Arc;

use crate::tree::{self, spatial::quat_from_rot, JointKind, TreeData};

/// World pose of one body frame.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyPose {
    /// Body name.
    pub name: String,
    /// Origin in the world frame.
    pub position: [f64; 3],
    /// Orientation body -> world, (w, x, y, z).
    pub quaternion: [f64; 4],
}

/// A body's drawn shape (scene key `shape`), in the body frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Shape {
    /// The geometry.
    pub geometry: Geometry,
    /// Centre in the body frame.
    pub position: [f64; 3],
    /// Orientation in the body frame, unit quaternion (w, x, y, z).
    pub quaternion: [f64; 4],
    /// Colour (r, g, b, a).
    pub color: [f64; 4],
}

/// Shape geometries; cylinders and capsules lie along the shape's z axis.
#[derive(Clone, Debug, PartialEq)]
pub enum Geometry {
    /// Side lengths.
    Box([f64; 3]),
    /// Radius.
    Sphere(f64),
    /// Radius and length.
    Cylinder(f64, f64),
    /// Radius and distance between the centres of the end spheres.
    Capsule(f64, f64),
}

/// A programme target drawn in the world frame (scene `[[view.targets]]`).
#[derive(Clone, Debug, PartialEq)]
pub enum Target {
    /// A point.
    Point([f64; 3]),
    /// A line through a point along a direction, drawn over `size` (None: twice the mechanism's
    /// size) centred on the point.
    Line([f64; 3], [f64; 3], Option<f64>),
    /// A plane through a point with a normal, drawn as a square of side `size`.
    Plane([f64; 3], [f64; 3], Option<f64>),
    /// A circle: centre, normal, radius.
    Circle([f64; 3], [f64; 3], f64),
    /// A path sampled over the time span.
    Path(Vec<[f64; 3]>),
}

/// A named target with its colour.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewTarget {
    /// Entity name (`<prefix>/target/<name>`).
    pub name: String,
    /// The geometry.
    pub target: Target,
    /// Colour (r, g, b, a).
    pub color: [f64; 4],
}

/// A site whose realized trace is drawn (one the programme rows read).
#[derive(Clone, Debug, PartialEq)]
pub struct TracedSite {
    /// Site name.
    pub name: String,
    /// Body index.
    pub body: usize,
    /// Position in the body frame.
    pub pos: [f64; 3],
}

/// What a scene adds to the drawing of its tree: shapes by body index, targets, traced sites.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct View {
    /// Shape of each body (by body index; empty or None: derived from mass and inertia).
    pub shapes: Vec<Option<Shape>>,
    /// Declared targets.
    pub targets: Vec<ViewTarget>,
    /// Sites the programme rows read.
    pub traced: Vec<TracedSite>,
}

/// Default colours: shapes (orange), targets (magenta), traces (cyan).
pub const SHAPE_COLOR: [f64; 4] = [0.85, 0.55, 0.2, 1.0];
/// Default colour of a target.
pub const TARGET_COLOR: [f64; 4] = [0.9, 0.1, 0.7, 0.8];
const TRACE_COLOR: [f64; 4] = [0.1, 0.75, 0.9, 1.0];

/// Poses and geometry of a kinematic tree (forward kinematics with its own workspace), with the
/// traces of its traced sites recorded so far.
pub struct Bodies {
    model: Arc<tree::Model>,
    view: Arc<View>,
    data: TreeData<f64>,
    poses: Vec<BodyPose>,
    traces: Vec<Vec<[f64; 3]>>,
}

impl Clone for Bodies {
    fn clone(&self) -> Self {
        Bodies::new(Arc::clone(&self.model), Arc::clone(&self.view))
    }
}

impl Bodies {
    /// For the tree of a scene and what its view adds.
    pub fn new(model: Arc<tree::Model>, view: Arc<View>) -> Self {
        let data = TreeData::new(&model);
        let poses = model
            .bodies()
            .iter()
            .map(|b| BodyPose {
                name: b.name.clone(),
                position: [0.0; 3],
                quaternion: [1.0, 0.0, 0.0, 0.0],
            })
            .collect();
        let traces = vec![vec![]; view.traced.len()];
        Bodies {
            model,
            view,
            data,
            poses,
            traces,
        }
    }

    /// Body names, in the order of [`Bodies::poses`].
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.poses.iter().map(|p| p.name.as_str())
    }

    /// World poses of every body at configuration q.
    pub fn poses(&mut self, q: &[f64]) -> &[BodyPose] {
        tree::forward_kinematics(&self.model, &mut self.data, q);
        for (b, pose) in self.poses.iter_mut().enumerate() {
            let (r, p) = tree::body_pose(&self.model, &mut self.data, q, b);
            pose.position = [p[0], p[1], p[2]];
            pose.quaternion = quat_from_rot(&r);
        }
        &self.poses
    }

    /// World poses of every body at q, also appending the traced sites' positions to their traces.
    pub fn record(&mut self, q: &[f64]) -> &[BodyPose] {
        self.poses(q);
        for (s, trace) in self.view.traced.iter().zip(&mut self.traces) {
            let b = &self.poses[s.body];
            let [w, x, y, z] = b.quaternion;
            let r =
                nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
            let p = Vector3::from(b.position) + r * Vector3::from(s.pos);
            trace.push([p[0], p[1], p[2]]);
        }
        &self.poses
    }

    /// The `foxglove.SceneUpdate` of the traces recorded so far ([`Bodies::record`]): one world-frame
    /// line strip `<prefix>/trace/<site>` per traced site; None if no site is traced or nothing
    /// was recorded.
    pub fn trace_update(&self, prefix: &str) -> Option<Value> {
        if self.traces.iter().all(|t| t.is_empty()) {
            return None;
        }
        let entities: Vec<Value> = self
            .view
            .traced
            .iter()
            .zip(&self.traces)
            .map(|(s, pts)| {
                let line = polyline(0, pts, 0.004 * self.extent(), TRACE_COLOR);
                world_entity(
                    &format!("{prefix}/trace/{}", s.name),
                    "trace",
                    vec![line],
                    vec![],
                )
            })
            .collect();
        Some(json!({"deletions": [], "entities": entities}))
    }

    /// Size of the drawing for defaults: the largest body distance of the last poses, at least 0.1.
    fn extent(&self) -> f64 {
        let mut d: f64 = 0.0;
        for a in &self.poses {
            for b in &self.poses {
                let e = Vector3::from(a.position) - Vector3::from(b.position);
                d = d.max(e.norm());
            }
        }
        d.max(0.1)
    }

    /// Entities of the declared targets (world frame).
    fn targets(&self, prefix: &str, scale: f64) -> Vec<Value> {
        let thick = 0.006 * scale;
        self.view
            .targets
            .iter()
            .map(|vt| {
                let c = vt.color;
                let id = format!("{prefix}/target/{}", vt.name);
                let (lines, cubes, spheres) = match &vt.target {
                    Target::Point(p) => (vec![], vec![], vec![sphere(*p, 0.06 * scale, c)]),
                    Target::Line(p, d, size) => {
                        let u = Vector3::from(*d).normalize() * 0.5 * size.unwrap_or(2.0 * scale);
                        let (a, b) = (Vector3::from(*p) - u, Vector3::from(*p) + u);
                        let pts = [[a[0], a[1], a[2]], [b[0], b[1], b[2]]];
                        (vec![polyline(0, &pts, thick, c)], vec![], vec![])
                    }
                    Target::Plane(p, n, size) => {
                        let side = size.unwrap_or(2.0 * scale);
                        let q = quat_z_to(&Vector3::from(*n).normalize());
                        let cube = json!({"pose": pose(*p, q),
                            "size": {"x": side, "y": side, "z": 0.002 * scale}, "color": color(c)});
                        (vec![], vec![cube], vec![])
                    }
                    Target::Circle(center, n, r) => {
                        let n = Vector3::from(*n).normalize();
                        let [w, x, y, z] = quat_z_to(&n);
                        let rot = nalgebra::UnitQuaternion::from_quaternion(
                            nalgebra::Quaternion::new(w, x, y, z),
                        );
                        let pts: Vec<[f64; 3]> = (0..64)
                            .map(|k| {
                                let a = 2.0 * std::f64::consts::PI * k as f64 / 64.0;
                                let p = Vector3::from(*center)
                                    + rot * Vector3::new(r * a.cos(), r * a.sin(), 0.0);
                                [p[0], p[1], p[2]]
                            })
                            .collect();
                        (vec![polyline(1, &pts, thick, c)], vec![], vec![])
                    }
                    Target::Path(pts) => (vec![polyline(0, pts, thick, c)], vec![], vec![]),
                };
                let mut e = world_entity(&id, "target", lines, cubes);
                e["spheres"] = Value::Array(spheres);
                e
            })
            .collect()
    }

    /// Largest distance between body origins at configuration q (the scale of the drawing), at
    /// least 0.1.
    fn scale(&mut self, q: &[f64]) -> f64 {
        self.poses(q);
        self.extent()
    }

    /// The `foxglove.SceneUpdate` message drawing the mechanism on frames `<prefix>/<body>`, sized
    /// at configuration q; `alpha` < 1 draws a ghost (the solver's motion beside a simulator's);
    /// `targets`: also the declared targets (world frame, once per recording).
    pub fn scene_update(&mut self, q: &[f64], prefix: &str, alpha: f64, targets: bool) -> Value {
        let scale = self.scale(q);
        let small = 0.04 * scale;
        let model = Arc::clone(&self.model);
        let mut entities = vec![];
        for (bi, b) in model.bodies().iter().enumerate() {
            let mut cubes = vec![];
            let mut spheres = vec![];
            let mut arrows = vec![];
            let mut cylinders = vec![];
            let mut lines = vec![];
            if let Some(Some(sh)) = self.view.shapes.get(bi) {
                let c = [sh.color[0], sh.color[1], sh.color[2], sh.color[3] * alpha];
                let (p, q) = (sh.position, sh.quaternion);
                match sh.geometry {
                    Geometry::Box(d) => cubes.push(json!({"pose": pose(p, q),
                        "size": {"x": d[0], "y": d[1], "z": d[2]}, "color": color(c)})),
                    Geometry::Sphere(r) => spheres.push(sphere(p, 2.0 * r, c)),
                    Geometry::Cylinder(r, l) => cylinders.push(cylinder(p, q, r, l, c)),
                    Geometry::Capsule(r, l) => {
                        cylinders.push(cylinder(p, q, r, l, c));
                        let rot = nalgebra::UnitQuaternion::from_quaternion(
                            nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]),
                        );
                        for end in [-0.5 * l, 0.5 * l] {
                            let e = Vector3::from(p) + rot * Vector3::new(0.0, 0.0, end);
                            spheres.push(sphere([e[0], e[1], e[2]], 2.0 * r, c));
                        }
                    }
                }
            } else if b.massless {
                spheres.push(sphere([0.0; 3], 0.5 * small, [0.6, 0.6, 0.6, alpha]));
            } else if let Some((size, rot)) = inertia_box(b.mass, &b.inertia) {
                cubes.push(json!({
                    "pose": pose([b.com[0], b.com[1], b.com[2]], quat_from_rot(&rot)),
                    "size": {"x": size[0], "y": size[1], "z": size[2]},
                    "color": color([0.85, 0.55, 0.2, alpha]),
                }));
            } else {
                spheres.push(sphere(
                    [b.com[0], b.com[1], b.com[2]],
                    small,
                    [0.85, 0.55, 0.2, alpha],
                ));
            }
            for j in &model.joints()[b.joints.clone()] {
                let a = [j.anchor[0], j.anchor[1], j.anchor[2]];
                match j.kind {
                    JointKind::Hinge(u) => {
                        arrows.push(arrow(a, &u, 3.0 * small, [0.2, 0.4, 0.9, alpha]))
                    }
                    JointKind::Slide(u) => {
                        arrows.push(arrow(a, &u, 3.0 * small, [0.2, 0.7, 0.3, alpha]))
                    }
                    JointKind::Ball => spheres.push(sphere(a, 0.7 * small, [0.2, 0.4, 0.9, alpha])),
                    JointKind::Free => {}
                }
            }
            // links to the children: from this body's origin to each child's placement
            for child in model.bodies().iter().filter(|c| c.parent == Some(bi)) {
                lines.push(json!({
                    "type": 0, "pose": pose([0.0; 3], [1.0, 0.0, 0.0, 0.0]), "thickness": 0.25 * small,
                    "scale_invariant": false,
                    "points": [{"x": 0.0, "y": 0.0, "z": 0.0},
                               {"x": child.pos[0], "y": child.pos[1], "z": child.pos[2]}],
                    "color": color([0.3, 0.3, 0.3, alpha]), "colors": [], "indices": [],
                }));
            }
            entities.push(json!({
                "timestamp": {"sec": 0, "nsec": 0},
                "frame_id": format!("{prefix}/{}", b.name),
                "id": format!("{prefix}/{}", b.name),
                "lifetime": {"sec": 0, "nsec": 0},
                "frame_locked": true,
                "metadata": [{"key": "body", "value": b.name}],
                "arrows": arrows, "cubes": cubes, "spheres": spheres, "cylinders": cylinders,
                "lines": lines, "triangles": [], "texts": [], "models": [],
            }));
        }
        if targets {
            entities.extend(self.targets(prefix, scale));
        }
        json!({"deletions": [], "entities": entities})
    }
}

/// Side lengths and principal axes (columns of the rotation) of the uniform box with this mass
/// and inertia about the CoM; None for a point mass (zero inertia).
fn inertia_box(mass: f64, inertia: &Matrix3<f64>) -> Option<([f64; 3], Matrix3<f64>)> {
    if !(mass > 0.0) || inertia.norm() == 0.0 {
        return None;
    }
    let eig = SymmetricEigen::new(*inertia);
    let i = eig.eigenvalues;
    let side = |a: usize, b: usize, c: usize| (6.0 * (i[b] + i[c] - i[a]) / mass).max(0.0).sqrt();
    let mut size = [side(0, 1, 2), side(1, 2, 0), side(2, 0, 1)];
    let thin = 0.05 * size.iter().cloned().fold(0.0, f64::max);
    for s in &mut size {
        *s = s.max(thin); // a rod or a plate keeps a visible thickness
    }
    let mut rot = eig.eigenvectors;
    if rot.determinant() < 0.0 {
        rot.set_column(2, &(-rot.column(2)));
    }
    Some((size, rot))
}

/// An entity fixed in the world frame.
fn world_entity(id: &str, what: &str, lines: Vec<Value>, cubes: Vec<Value>) -> Value {
    json!({
        "timestamp": {"sec": 0, "nsec": 0}, "frame_id": "world", "id": id,
        "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": true,
        "metadata": [{"key": what, "value": id}],
        "arrows": [], "cubes": cubes, "spheres": [], "cylinders": [], "lines": lines,
        "triangles": [], "texts": [], "models": [],
    })
}

/// A line primitive through world points: kind 0 strip, 1 loop.
fn polyline(kind: u8, pts: &[[f64; 3]], thickness: f64, c: [f64; 4]) -> Value {
    let points: Vec<Value> = pts
        .iter()
        .map(|p| json!({"x": p[0], "y": p[1], "z": p[2]}))
        .collect();
    json!({"type": kind, "pose": pose([0.0; 3], [1.0, 0.0, 0.0, 0.0]), "thickness": thickness,
           "scale_invariant": false, "points": points, "color": color(c), "colors": [],
           "indices": []})
}

/// A cylinder of radius r and length l along z of the pose (p, q).
fn cylinder(p: [f64; 3], q: [f64; 4], r: f64, l: f64, c: [f64; 4]) -> Value {
    json!({"pose": pose(p, q), "size": {"x": 2.0 * r, "y": 2.0 * r, "z": l},
           "bottom_scale": 1.0, "top_scale": 1.0, "color": color(c)})
}

/// The rotation (w, x, y, z) taking +z to the unit vector n.
fn quat_z_to(n: &Vector3<f64>) -> [f64; 4] {
    let r = nalgebra::UnitQuaternion::rotation_between(&Vector3::z(), n).unwrap_or_else(|| {
        nalgebra::UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    });
    [r.w, r.i, r.j, r.k]
}

fn color(c: [f64; 4]) -> Value {
    json!({"r": c[0], "g": c[1], "b": c[2], "a": c[3]})
}

fn pose(p: [f64; 3], wxyz: [f64; 4]) -> Value {
    json!({"position": {"x": p[0], "y": p[1], "z": p[2]},
           "orientation": {"x": wxyz[1], "y": wxyz[2], "z": wxyz[3], "w": wxyz[0]}})
}

fn sphere(p: [f64; 3], d: f64, c: [f64; 4]) -> Value {
    json!({"pose": pose(p, [1.0, 0.0, 0.0, 0.0]), "size": {"x": d, "y": d, "z": d}, "color": color(c)})
}

/// An arrow (Foxglove draws it along +x of its pose) from `at` along the unit vector `u`.
fn arrow(at: [f64; 3], u: &Vector3<f64>, length: f64, c: [f64; 4]) -> Value {
    let x = Vector3::x();
    let axis = x.cross(u);
    let q = if axis.norm() < 1e-12 {
        if u[0] >= 0.0 {
            [1.0, 0.0, 0.0, 0.0]
        } else {
            [0.0, 0.0, 0.0, 1.0]
        }
    } else {
        let angle = x.dot(u).clamp(-1.0, 1.0).acos();
        let a = axis.normalize() * (0.5 * angle).sin();
        [(0.5 * angle).cos(), a[0], a[1], a[2]]
    };
    json!({"pose": pose(at, q), "shaft_length": 0.7 * length, "shaft_diameter": 0.08 * length,
           "head_length": 0.3 * length, "head_diameter": 0.2 * length, "color": color(c)})
}

/// Schema of `foxglove.SceneUpdate` messages as written here (the fields Foxglove reads).
pub fn scene_update_schema() -> Value {
    json!({
        "title": "foxglove.SceneUpdate",
        "description": "An update to the entities displayed in a 3D scene",
        "type": "object",
        "properties": {
            "deletions": {"type": "array"},
            "entities": {"type": "array", "items": {"type": "object", "properties": {
                "timestamp": {"type": "object"}, "frame_id": {"type": "string"},
                "id": {"type": "string"}, "lifetime": {"type": "object"},
                "frame_locked": {"type": "boolean"}, "metadata": {"type": "array"},
                "arrows": {"type": "array"}, "cubes": {"type": "array"},
                "spheres": {"type": "array"}, "cylinders": {"type": "array"},
                "lines": {"type": "array"}, "triangles": {"type": "array"},
                "texts": {"type": "array"}, "models": {"type": "array"}}}}
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inertia_box_reproduces_a_uniform_box() {
        // uniform box 0.1 x 0.2 x 0.6, m = 2: I = m/12 (b^2 + c^2, ...)
        let (m, a, b, c) = (2.0, 0.1, 0.2, 0.6);
        let i = Matrix3::from_diagonal(&Vector3::new(
            m / 12.0 * (b * b + c * c),
            m / 12.0 * (a * a + c * c),
            m / 12.0 * (a * a + b * b),
        ));
        let (size, rot) = inertia_box(m, &i).unwrap();
        let mut got: Vec<(f64, f64)> = (0..3)
            .map(|k| {
                let axis = rot.column(k).iamax();
                (axis as f64, size[k])
            })
            .collect();
        got.sort_by(|x, y| x.0.partial_cmp(&y.0).unwrap());
        for (k, want) in [a, b, c].iter().enumerate() {
            assert!((got[k].1 - want).abs() < 1e-12, "{got:?}");
        }
        assert!((rot.determinant() - 1.0).abs() < 1e-12);
        assert!(inertia_box(1.0, &Matrix3::zeros()).is_none());
    }

    fn points(v: &Value) -> Vec<Vector3<f64>> {
        v["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| {
                Vector3::new(
                    p["x"].as_f64().unwrap(),
                    p["y"].as_f64().unwrap(),
                    p["z"].as_f64().unwrap(),
                )
            })
            .collect()
    }

    /// A one-body tree welded to the world (a point mass at the origin) with the given view.
    fn bodies(view: View) -> Bodies {
        let spec = tree::BodySpec::new("b", tree::WORLD, 1.0, [0.0; 3], [[0.0; 3]; 3]);
        let model = tree::Model::new(&[spec], tree::Fields::default()).unwrap();
        Bodies::new(Arc::new(model), Arc::new(view))
    }

    #[test]
    fn targets_are_drawn_where_declared() {
        let (c, n, r) = ([1.0, 2.0, 3.0], [0.0, 0.6, 0.8], 0.5);
        let view = View {
            targets: vec![
                ViewTarget {
                    name: "circle".into(),
                    target: Target::Circle(c, n, r),
                    color: TARGET_COLOR,
                },
                ViewTarget {
                    name: "plane".into(),
                    target: Target::Plane(c, n, Some(2.0)),
                    color: TARGET_COLOR,
                },
                ViewTarget {
                    name: "line".into(),
                    target: Target::Line(c, [0.0, 0.0, 2.0], Some(4.0)),
                    color: TARGET_COLOR,
                },
            ],
            ..View::default()
        };
        let mut b = bodies(view);
        let u = b.scene_update(&[], "p", 1.0, true);
        let ents = u["entities"].as_array().unwrap();
        let find = |id: &str| ents.iter().find(|e| e["id"] == id).unwrap().clone();
        // circle: every point at distance r from the centre, in the plane normal to n
        let circle = points(&find("p/target/circle")["lines"][0]);
        assert_eq!(circle.len(), 64);
        for p in &circle {
            let d = p - Vector3::from(c);
            assert!((d.norm() - r).abs() < 1e-12 && d.dot(&Vector3::from(n)).abs() < 1e-12);
        }
        // plane: the thin side of the cube along the normal
        let cube = &find("p/target/plane")["cubes"][0];
        let o = &cube["pose"]["orientation"];
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            o["w"].as_f64().unwrap(),
            o["x"].as_f64().unwrap(),
            o["y"].as_f64().unwrap(),
            o["z"].as_f64().unwrap(),
        ));
        assert!((q * Vector3::z() - Vector3::from(n)).norm() < 1e-12);
        assert_eq!(cube["size"]["x"], 2.0);
        // line: centred on the point, `size` long, along the (normalised) direction
        let line = points(&find("p/target/line")["lines"][0]);
        assert!((line[0] - Vector3::new(1.0, 2.0, 1.0)).norm() < 1e-12);
        assert!((line[1] - Vector3::new(1.0, 2.0, 5.0)).norm() < 1e-12);
        // without targets (a simulator's scene in `progmo debug`) none is drawn
        let u = b.scene_update(&[], "p", 1.0, false);
        assert!(u["entities"]
            .as_array()
            .unwrap()
            .iter()
            .all(|e| e["frame_id"] == "p/b"));
    }

    #[test]
    fn traces_follow_the_sites_and_are_absent_without_samples() {
        let view = View {
            traced: vec![TracedSite {
                name: "s".into(),
                body: 0,
                pos: [0.0, 0.0, 1.0],
            }],
            ..View::default()
        };
        let mut b = bodies(view);
        assert!(b.trace_update("p").is_none());
        b.record(&[]);
        let u = b.trace_update("p").unwrap();
        let e = &u["entities"][0];
        assert_eq!(e["id"], "p/trace/s");
        assert_eq!(e["frame_id"], "world");
        assert_eq!(points(&e["lines"][0]), vec![Vector3::new(0.0, 0.0, 1.0)]);
    }

    #[test]
    fn arrows_point_along_their_axis() {
        for u in [
            Vector3::x(),
            -Vector3::x(),
            Vector3::y(),
            Vector3::new(0.0, 0.6, 0.8),
        ] {
            let a = arrow([0.0; 3], &u, 1.0, [0.0; 4]);
            let o = &a["pose"]["orientation"];
            let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                o["w"].as_f64().unwrap(),
                o["x"].as_f64().unwrap(),
                o["y"].as_f64().unwrap(),
                o["z"].as_f64().unwrap(),
            ));
            assert!((q * Vector3::x() - u).norm() < 1e-12, "{u:?}");
        }
    }
}
