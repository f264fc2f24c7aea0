//! Loop closures of tree scenes (`[[model.closures]]`): system rows that close a kinematic loop.
//!
//! A closure is compiled into ordinary expression rows over two synthetic sites (`NAME__a` on
//! body a, `NAME__b` on body b; a world point is a constant), so its jet is the exact chain-rule
//! jet of [`super::rows`] through the tree's point kinematics (no second kinematics kernel):
//! - `point`: p_a - p_b = 0 (rows NAME_x, NAME_y, NAME_z, world frame);
//! - `weld`: the point rows plus the vector part of conj(F_b) (x) F_a = 0 (NAME_rx, NAME_ry,
//!   NAME_rz), F = body quaternion (x) frame quaternion, i.e. the frames' relative rotation;
//! - `distance`: |p_a - p_b| - d = 0 (NAME);
//! - `line`: e_1 . (p_a - p_b) = 0, e_2 . (p_a - p_b) = 0 (NAME_u, NAME_v), e_1, e_2 = R_b times
//!   two unit vectors perpendicular to the line's direction in body b ([`perpendiculars`]);
//! - `plane`: n . (p_a - p_b) = 0 (NAME), n = R_b times the unit normal in body b;
//! - `rolling`: body a (a disk of `radius` about `axis` in body a, or a sphere without `axis`)
//!   centred at point_a rolls without slipping on the world plane through point_b with unit
//!   normal n (`normal`): the contact height n . (c - p_b) - r_n = 0 (NAME_n, holonomic) and the
//!   contact point's velocity along e_1, e_2 (perpendicular to n, [`perpendiculars`]) zero,
//!   e_i . (c' + w x r_c) = 0 (NAME_u, NAME_v, nonholonomic); c the centre, w the body's world
//!   angular velocity, r_c the centre-to-contact vector: sphere -r n (r_n = r); disk
//!   -r k / |k|, k = n - (n . a) a, a = R_a axis, |k| = sqrt(1 - (n . a)^2) (r_n = r |k|). The
//!   normal component of the contact velocity is the height's rate, so it is not a row of its own.
//!
//! R_b is body b's rotation written from its quaternion signals (`NAME__b.qw`, ...), the identity
//! for the world, so a line or plane carried by a moving body turns with it.
//!
//! They are system rows (role system, paper 2.2: their reactions are joint forces, not control).
//! A planar loop closed by a spatial point gives a row whose gradient dg/dv vanishes, and loops
//! can repeat each other's rows: [`set_aside_dependent`] keeps the first independent rows in
//! declaration order at t0 and sets the others aside (reported, and their residual monitored).

use super::error::{SceneError, Source};
use super::file::{ClosureFile, ModelFile, RowFile};
use super::rows::ExprConstraints;
use super::signals::Site;
use crate::formulation::RankTolerances;
use crate::linalg;
use crate::model::Model;
use crate::programme::jet::Jet;
use crate::programme::Constraints;
use crate::solve::Problem;
use crate::tree;
use nalgebra::DMatrix;
use toml::Spanned;

/// What a closure holds together.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ClosureKind {
    /// Two points coincide (3 rows).
    Point,
    /// Two frames coincide (6 rows).
    Weld,
    /// Two points keep a distance (1 row).
    Distance,
    /// A point of body a stays on a line of body b (2 rows).
    Line,
    /// A point of body a stays in a plane of body b (1 row).
    Plane,
    /// A disk or a sphere of body a rolls without slipping on a world plane (3 rows: contact
    /// height, two tangential no-slip rows).
    Rolling,
}

impl ClosureKind {
    /// The scene file's name of the kind.
    pub fn name(self) -> &'static str {
        match self {
            ClosureKind::Point => "point",
            ClosureKind::Weld => "weld",
            ClosureKind::Distance => "distance",
            ClosureKind::Line => "line",
            ClosureKind::Plane => "plane",
            ClosureKind::Rolling => "rolling",
        }
    }
}

/// A loop closure as loaded (bodies resolved, `body_b = None`: the world).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Closure {
    pub name: String,
    pub kind: ClosureKind,
    pub body_a: String,
    pub point_a: [f64; 3],
    /// Frame a's orientation in body a (w, x, y, z), normalised.
    pub quat_a: [f64; 4],
    /// None: the world.
    pub body_b: Option<String>,
    pub point_b: [f64; 3],
    pub quat_b: [f64; 4],
    /// `distance` only.
    pub distance: Option<f64>,
    /// `line` (direction) and `plane` (normal): unit vector in body b's frame (world frame for the
    /// world); `rolling`: the disk's axis in body a's frame (None: a sphere).
    pub axis: Option<[f64; 3]>,
    /// `rolling` only: the disk's or sphere's radius (m).
    pub radius: Option<f64>,
    /// `rolling` only: the plane's unit normal (world frame).
    pub normal: Option<[f64; 3]>,
}

/// A closure row set aside as dependent at t0, with why.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SetAside {
    /// Row name.
    pub row: String,
    /// Why it was set aside (one sentence).
    pub reason: String,
}

pub(super) fn site_name(closure: &str, side: char) -> String {
    format!("{closure}__{side}")
}

fn num(x: f64) -> String {
    format!("({x:e})")
}

fn normalised(q: [f64; 4]) -> Option<[f64; 4]> {
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    (n.is_finite() && n > 0.0).then(|| q.map(|x| x / n))
}

/// The closures and their rows, each with the field it is reported under.
pub(super) type ClosureRows = (Vec<Closure>, Vec<(RowFile, String)>);

/// Validate the closures of `m`, adding their synthetic sites to `sites`. Returns the closures and
/// their rows (name and expression, spanned at the closure) in declaration order, with the field
/// each row is reported under.
pub(super) fn load(
    src: &Source,
    m: &ModelFile,
    tree: &tree::Model,
    joint_names: &[&str],
    sites: &mut Vec<Site>,
) -> Result<ClosureRows, SceneError> {
    let mut closures = vec![];
    let mut rows = vec![];
    for (ci, c) in m.closures.iter().enumerate() {
        let field = format!("model.closures[{ci}]");
        let cx = ClosureCx {
            src,
            c,
            cf: c.get_ref(),
            field: &field,
        };
        let closure = cx.closure(tree, joint_names, sites, &closures)?;
        for (name, expr) in closure.rows() {
            let row = RowFile {
                name: Spanned::new(c.span(), name),
                expr: Spanned::new(c.span(), expr),
            };
            rows.push((row, field.clone()));
        }
        closures.push(closure);
    }
    Ok((closures, rows))
}

/// One `[[model.closures]]` table being validated; its errors point at the table.
struct ClosureCx<'a> {
    src: &'a Source,
    c: &'a Spanned<ClosureFile>,
    cf: &'a ClosureFile,
    /// `model.closures[i]`.
    field: &'a str,
}

impl ClosureCx<'_> {
    fn err(&self, key: &str, msg: String) -> SceneError {
        self.src
            .error(self.c.span(), &format!("{}.{key}", self.field), msg)
    }

    /// The closure, checked against `tree` and the closures before it (`earlier`), its synthetic
    /// sites added to `sites`.
    fn closure(
        &self,
        tree: &tree::Model,
        joint_names: &[&str],
        sites: &mut Vec<Site>,
        earlier: &[Closure],
    ) -> Result<Closure, SceneError> {
        let (cf, err) = (self.cf, |key: &str, msg: String| self.err(key, msg));
        if !super::load::is_identifier(&cf.name) {
            return Err(err("name", "a closure name must be an identifier".into()));
        }
        if earlier.iter().any(|x: &Closure| x.name == cf.name) {
            return Err(err(
                "name",
                format!("closure name `{}` is used twice", cf.name),
            ));
        }
        let kind = self.kind()?;
        let (body_a, body_b) = self.bodies(tree)?;
        let finite = cf.point_a.iter().chain(&cf.point_b).all(|x| x.is_finite());
        if !finite {
            return Err(err("point_a", "closure points must be finite".into()));
        }
        let (quat_a, quat_b) = self.quats(kind)?;
        let distance = self.distance(kind)?;
        let axis = self.axis(kind)?;
        let (radius, normal) = self.rolling(kind, body_b)?;
        self.add_sites(body_a, body_b, joint_names, sites)?;
        Ok(Closure {
            name: cf.name.clone(),
            kind,
            body_a: cf.body_a.clone(),
            point_a: cf.point_a,
            quat_a,
            body_b: body_b.map(|_| cf.body_b.clone()),
            point_b: cf.point_b,
            quat_b,
            distance,
            axis,
            radius,
            normal,
        })
    }

    /// `kind`, one of the closure kinds.
    fn kind(&self) -> Result<ClosureKind, SceneError> {
        let cf = self.cf;
        Ok(match cf.kind.get_ref().as_str() {
            "point" => ClosureKind::Point,
            "weld" => ClosureKind::Weld,
            "distance" => ClosureKind::Distance,
            "line" => ClosureKind::Line,
            "plane" => ClosureKind::Plane,
            "rolling" => ClosureKind::Rolling,
            other => {
                return Err(self.src.error(
                    cf.kind.span(),
                    &format!("{}.kind", self.field),
                    format!(
                        "unknown closure kind `{other}`: expected `point`, `weld`, `distance`, \
                         `line`, `plane` or `rolling`"
                    ),
                ))
            }
        })
    }

    /// Bodies a and b (None: the world), two different ones of the tree.
    fn bodies(&self, tree: &tree::Model) -> Result<(usize, Option<usize>), SceneError> {
        let (cf, err) = (self.cf, |key: &str, msg: String| self.err(key, msg));
        let body_a = tree
            .body_id(&cf.body_a)
            .ok_or_else(|| err("body_a", format!("unknown body `{}`", cf.body_a)))?;
        let body_b = if cf.body_b == "world" {
            None
        } else {
            Some(
                tree.body_id(&cf.body_b)
                    .ok_or_else(|| err("body_b", format!("unknown body `{}`", cf.body_b)))?,
            )
        };
        if body_b == Some(body_a) {
            return Err(err(
                "body_b",
                format!(
                    "a closure joins two different bodies, not `{}` to itself",
                    cf.body_a
                ),
            ));
        }
        Ok((body_a, body_b))
    }

    /// The frames' orientations, normalised (`weld` only; the identity otherwise).
    fn quats(&self, kind: ClosureKind) -> Result<([f64; 4], [f64; 4]), SceneError> {
        let (cf, err) = (self.cf, |key: &str, msg: String| self.err(key, msg));
        if kind != ClosureKind::Weld && (cf.quat_a.is_some() || cf.quat_b.is_some()) {
            return Err(err(
                "quat_a",
                "quat_a/quat_b orient the frames of a `weld` closure only".into(),
            ));
        }
        let quat = |q: Option<[f64; 4]>, key: &str| {
            normalised(q.unwrap_or([1.0, 0.0, 0.0, 0.0]))
                .ok_or_else(|| err(key, "a quaternion must be finite and nonzero".into()))
        };
        let quat_a = quat(cf.quat_a, "quat_a")?;
        let quat_b = quat(cf.quat_b, "quat_b")?;
        Ok((quat_a, quat_b))
    }

    /// `distance`: positive, for `distance` closures only.
    fn distance(&self, kind: ClosureKind) -> Result<Option<f64>, SceneError> {
        let err = |key: &str, msg: String| self.err(key, msg);
        let distance = match (kind, self.cf.distance) {
            (ClosureKind::Distance, Some(d)) if d.is_finite() && d > 0.0 => Some(d),
            (ClosureKind::Distance, Some(d)) => {
                return Err(err(
                    "distance",
                    format!("the distance must be > 0, not {d}"),
                ))
            }
            (ClosureKind::Distance, None) => {
                return Err(err(
                    "distance",
                    "a `distance` closure needs `distance`".into(),
                ))
            }
            (_, Some(_)) => {
                return Err(err(
                    "distance",
                    "`distance` belongs to `distance` closures".into(),
                ))
            }
            (_, None) => None,
        };
        Ok(distance)
    }

    /// `a` normalised, finite and nonzero.
    fn unit(&self, a: [f64; 3], key: &str) -> Result<[f64; 3], SceneError> {
        let n = a.iter().map(|x| x * x).sum::<f64>().sqrt();
        if n.is_finite() && n > 0.0 {
            Ok(a.map(|x| x / n))
        } else {
            Err(self.err(
                key,
                format!("the {key} must be finite and nonzero, not {a:?}"),
            ))
        }
    }

    /// `axis`: a unit vector, needed by `line` and `plane`, optional for `rolling` (a disk).
    fn axis(&self, kind: ClosureKind) -> Result<Option<[f64; 3]>, SceneError> {
        let err = |key: &str, msg: String| self.err(key, msg);
        let axis = match (kind, self.cf.axis) {
            (ClosureKind::Line | ClosureKind::Plane | ClosureKind::Rolling, Some(a)) => {
                Some(self.unit(a, "axis")?)
            }
            (ClosureKind::Rolling, None) => None,
            (ClosureKind::Line | ClosureKind::Plane, None) => {
                return Err(err(
                    "axis",
                    format!(
                        "a `{}` closure needs `axis` (the line's direction or the plane's \
                         normal, in body_b's frame)",
                        kind.name()
                    ),
                ))
            }
            (_, Some(_)) => {
                return Err(err(
                    "axis",
                    "`axis` belongs to `line`, `plane` and `rolling` closures".into(),
                ))
            }
            (_, None) => None,
        };
        Ok(axis)
    }

    /// `radius` and `normal` of a `rolling` closure (on a world plane); no other kind takes them.
    fn rolling(
        &self,
        kind: ClosureKind,
        body_b: Option<usize>,
    ) -> Result<(Option<f64>, Option<[f64; 3]>), SceneError> {
        let (cf, err) = (self.cf, |key: &str, msg: String| self.err(key, msg));
        let (radius, normal) = if kind == ClosureKind::Rolling {
            if body_b.is_some() {
                return Err(err(
                    "body_b",
                    "a `rolling` closure rolls on a world plane: body_b must be `world`".into(),
                ));
            }
            let r = match cf.radius {
                Some(r) if r.is_finite() && r > 0.0 => r,
                Some(r) => return Err(err("radius", format!("the radius must be > 0, not {r}"))),
                None => return Err(err("radius", "a `rolling` closure needs `radius`".into())),
            };
            (
                Some(r),
                Some(self.unit(cf.normal.unwrap_or([0.0, 0.0, 1.0]), "normal")?),
            )
        } else {
            for (key, given) in [
                ("radius", cf.radius.is_some()),
                ("normal", cf.normal.is_some()),
            ] {
                if given {
                    return Err(err(key, format!("`{key}` belongs to `rolling` closures")));
                }
            }
            (None, None)
        };
        Ok((radius, normal))
    }

    /// The synthetic sites `NAME__a` (and `NAME__b` unless body b is the world), names not taken.
    fn add_sites(
        &self,
        body_a: usize,
        body_b: Option<usize>,
        joint_names: &[&str],
        sites: &mut Vec<Site>,
    ) -> Result<(), SceneError> {
        let cf = self.cf;
        for (side, body, point) in [('a', Some(body_a), cf.point_a), ('b', body_b, cf.point_b)] {
            let Some(body) = body else { continue };
            let name = site_name(&cf.name, side);
            if sites.iter().any(|s| s.name == name) || joint_names.contains(&name.as_str()) {
                return Err(self.err(
                    "name",
                    format!(
                        "closure `{}` needs the site name `{name}`, already taken",
                        cf.name
                    ),
                ));
            }
            sites.push(Site {
                name,
                body,
                pos: point,
            });
        }
        Ok(())
    }
}

impl Closure {
    /// Number of rows.
    pub fn n_rows(&self) -> usize {
        match self.kind {
            ClosureKind::Point => 3,
            ClosureKind::Weld => 6,
            ClosureKind::Distance | ClosureKind::Plane => 1,
            ClosureKind::Line => 2,
            ClosureKind::Rolling => 3,
        }
    }

    /// The rows as (name, expression) over the synthetic sites' signals.
    pub fn rows(&self) -> Vec<(String, String)> {
        let a = site_name(&self.name, 'a');
        let b = site_name(&self.name, 'b');
        let pa = ["x", "y", "z"].map(|c| format!("{a}.{c}"));
        let pb: [String; 3] = match self.body_b {
            Some(_) => ["x", "y", "z"].map(|c| format!("{b}.{c}")),
            None => self.point_b.map(num),
        };
        let d: Vec<String> = (0..3).map(|k| format!("{} - {}", pa[k], pb[k])).collect();
        let n = &self.name;
        // A vector fixed in body b, in the world frame: R_b c (the world: c itself).
        let world = |c: [f64; 3]| -> [String; 3] {
            match self.body_b {
                Some(_) => rotate(&["qw", "qx", "qy", "qz"].map(|k| format!("{b}.{k}")), c),
                None => c.map(num),
            }
        };
        let dot = |e: [String; 3]| -> String {
            (0..3)
                .map(|k| format!("({})*({})", e[k], d[k]))
                .collect::<Vec<_>>()
                .join(" + ")
        };
        let axis = self.axis.unwrap_or([0.0, 0.0, 1.0]);
        match self.kind {
            ClosureKind::Rolling => self.rolling_rows(&a),
            ClosureKind::Plane => vec![(n.clone(), dot(world(axis)))],
            ClosureKind::Line => {
                let (e1, e2) = perpendiculars(axis);
                vec![
                    (format!("{n}_u"), dot(world(e1))),
                    (format!("{n}_v"), dot(world(e2))),
                ]
            }
            ClosureKind::Distance => vec![(
                n.clone(),
                format!(
                    "sqrt(({})^2 + ({})^2 + ({})^2) - {}",
                    d[0],
                    d[1],
                    d[2],
                    num(self.distance.unwrap_or(0.0))
                ),
            )],
            ClosureKind::Point | ClosureKind::Weld => {
                let mut rows: Vec<(String, String)> = ["x", "y", "z"]
                    .iter()
                    .zip(d)
                    .map(|(c, e)| (format!("{n}_{c}"), e))
                    .collect();
                if self.kind == ClosureKind::Weld {
                    // Frame quaternions F = body (x) frame, then conj(F_b) (x) F_a.
                    let body_q = |s: &str| ["qw", "qx", "qy", "qz"].map(|c| format!("{s}.{c}"));
                    let fa = qmul(&body_q(&a), &self.quat_a.map(num));
                    let fb = match self.body_b {
                        Some(_) => qmul(&body_q(&b), &self.quat_b.map(num)),
                        None => self.quat_b.map(num),
                    };
                    let conj_b = [
                        fb[0].clone(),
                        format!("(-({}))", fb[1]),
                        format!("(-({}))", fb[2]),
                        format!("(-({}))", fb[3]),
                    ];
                    let rel = qmul(&conj_b, &fa);
                    for (k, c) in ["rx", "ry", "rz"].iter().enumerate() {
                        rows.push((format!("{n}_{c}"), rel[k + 1].clone()));
                    }
                }
                rows
            }
        }
    }
}

impl Closure {
    /// The rows of a `rolling` closure (module doc) over the centre site `a`'s signals.
    fn rolling_rows(&self, a: &str) -> Vec<(String, String)> {
        let n = self.normal.unwrap_or([0.0, 0.0, 1.0]);
        let r = self.radius.unwrap_or(0.0);
        let c = ["x", "y", "z"].map(|k| format!("{a}.{k}"));
        let (e1, e2) = perpendiculars(n);
        // centre-to-contact vector r_c and the contact's height above the centre r_n
        let (rc, rn): ([String; 3], String) = match self.axis {
            None => (n.map(|x| num(-r * x)), num(r)),
            Some(axis) => {
                let aw = rotate(&["qw", "qx", "qy", "qz"].map(|k| format!("{a}.{k}")), axis);
                let s = (0..3)
                    .map(|k| format!("{}*({})", num(n[k]), aw[k]))
                    .collect::<Vec<_>>()
                    .join(" + ");
                let norm = format!("sqrt(1 - ({s})^2)");
                let rc = [0, 1, 2]
                    .map(|k| format!("{}*({} - ({s})*({}))/{norm}", num(-r), num(n[k]), aw[k]));
                (rc, format!("{}*{norm}", num(r)))
            }
        };
        let height = (0..3)
            .map(|k| format!("{}*({} - {})", num(n[k]), c[k], num(self.point_b[k])))
            .collect::<Vec<_>>()
            .join(" + ");
        let w = ["wx", "wy", "wz"].map(|k| format!("{a}.{k}"));
        // contact velocity c' + w x r_c
        let vc = [0, 1, 2].map(|i| {
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            format!(
                "{}' + ({})*({}) - ({})*({})",
                c[i], w[j], rc[k], w[k], rc[j]
            )
        });
        let along = |e: [f64; 3]| {
            (0..3)
                .filter(|&k| e[k] != 0.0)
                .map(|k| format!("{}*({})", num(e[k]), vc[k]))
                .collect::<Vec<_>>()
                .join(" + ")
        };
        let name = &self.name;
        vec![
            (format!("{name}_n"), format!("{height} - {rn}")),
            (format!("{name}_u"), along(e1)),
            (format!("{name}_v"), along(e2)),
        ]
    }
}

/// R(q) c for a quaternion q = (w, x, y, z) given as expression text and a constant c: the rows of
/// the rotation matrix (body -> world) of a unit quaternion, terms with c_j = 0 left out.
fn rotate(q: &[String; 4], c: [f64; 3]) -> [String; 3] {
    let [w, x, y, z] = q.clone().map(|e| format!("({e})"));
    let r = [
        [
            format!("1 - 2*({y}^2 + {z}^2)"),
            format!("2*({x}*{y} - {w}*{z})"),
            format!("2*({x}*{z} + {w}*{y})"),
        ],
        [
            format!("2*({x}*{y} + {w}*{z})"),
            format!("1 - 2*({x}^2 + {z}^2)"),
            format!("2*({y}*{z} - {w}*{x})"),
        ],
        [
            format!("2*({x}*{z} - {w}*{y})"),
            format!("2*({y}*{z} + {w}*{x})"),
            format!("1 - 2*({x}^2 + {y}^2)"),
        ],
    ];
    [0, 1, 2].map(|i| {
        let terms: Vec<String> = (0..3)
            .filter(|&j| c[j] != 0.0)
            .map(|j| format!("({})*{}", r[i][j], num(c[j])))
            .collect();
        if terms.is_empty() {
            "0".into()
        } else {
            terms.join(" + ")
        }
    })
}

/// Two unit vectors completing the unit vector `a` to a right-handed orthonormal basis (e_1, e_2,
/// a): e_1 = a x e_k normalised, with e_k the coordinate axis least aligned with a, e_2 = a x e_1.
pub fn perpendiculars(a: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let cross = |u: [f64; 3], v: [f64; 3]| {
        [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ]
    };
    let k = (0..3)
        .min_by(|&i, &j| a[i].abs().total_cmp(&a[j].abs()))
        .unwrap_or(0);
    let mut ek = [0.0; 3];
    ek[k] = 1.0;
    let e1 = cross(a, ek);
    let n = e1.iter().map(|x| x * x).sum::<f64>().sqrt();
    let e1 = e1.map(|x| x / n);
    (e1, cross(a, e1))
}

/// Hamilton product of quaternions (w, x, y, z) written as expression text.
fn qmul(p: &[String; 4], q: &[String; 4]) -> [String; 4] {
    let m = |i: usize, j: usize| format!("({})*({})", p[i], q[j]);
    [
        format!("{} - {} - {} - {}", m(0, 0), m(1, 1), m(2, 2), m(3, 3)),
        format!("{} + {} + {} - {}", m(0, 1), m(1, 0), m(2, 3), m(3, 2)),
        format!("{} - {} + {} + {}", m(0, 2), m(1, 3), m(2, 0), m(3, 1)),
        format!("{} + {} - {} + {}", m(0, 3), m(1, 2), m(2, 1), m(3, 0)),
    ]
}

/// Rows of `candidates` (closure rows) dependent at (t0, q0, v0) on the rows before them, in
/// declaration order: a row is kept when adding its normalised gradient dg/dv to the rows kept
/// so far raises the numerical rank (column-pivoted QR of [`linalg::qr_colpiv`] with the solver's
/// `dependent` tolerance); a row whose gradient vanishes (below `vanishing` of the largest) is
/// set aside too. Rows outside `candidates` are always kept. Returns (row index, reason).
pub(super) fn set_aside_dependent<M: Model>(
    p: &Problem<M, ExprConstraints>,
    candidates: std::ops::Range<usize>,
    tol: &RankTolerances,
) -> Vec<(usize, String)> {
    let c = &p.constraints;
    let s = c.rows().len();
    let (nq, nv) = (p.model.nq(), p.model.nv());
    let segments = p.model.segments();
    let mut jet = Jet::new(c, segments, nq, nv);
    jet.compute(c, segments, p.t0, &p.q0, &p.v0);
    let norms: Vec<f64> = (0..s).map(|i| jet.b.row(i).norm()).collect();
    let scale = norms.iter().cloned().fold(0.0, f64::max);
    let mut kept: Vec<usize> = vec![];
    let mut out = vec![];
    for i in 0..s {
        if !candidates.contains(&i) {
            kept.push(i);
            continue;
        }
        if norms[i] <= tol.vanishing * scale || norms[i] == 0.0 {
            out.push((
                i,
                format!(
                    "its gradient dg/dv vanishes at t0 (|dg/dv| = {:.1e}): the loop keeps it by \
                     itself (e.g. a planar loop closed by a spatial point)",
                    norms[i]
                ),
            ));
            continue;
        }
        // B_hat^T of the kept rows plus row i (nv x k), normalised rows.
        let k = kept.len() + 1;
        if k > nv {
            out.push((
                i,
                "the rows before it already fill every degree of freedom".into(),
            ));
            continue;
        }
        let mut bt = DMatrix::<f64>::zeros(nv, k);
        for (col, &r) in kept.iter().chain(std::iter::once(&i)).enumerate() {
            let inv = 1.0 / norms[r].max(f64::MIN_POSITIVE);
            for j in 0..nv {
                bt[(j, col)] = jet.b[(r, j)] * inv;
            }
        }
        let mut beta = vec![0.0; k];
        let mut perm = vec![0; k];
        let rank = linalg::qr_colpiv(&mut bt, nv, k, &mut beta, &mut perm, tol.dependent);
        let rmin = (0..k)
            .map(|j| bt[(j, j)].abs())
            .fold(f64::INFINITY, f64::min);
        if rank < k || rmin < tol.dependent {
            out.push((
                i,
                format!(
                    "it depends on the rows before it at t0 (smallest |R_jj| of the normalised \
                     gradients {rmin:.1e} < {:.0e})",
                    tol.dependent
                ),
            ));
        } else {
            kept.push(i);
        }
    }
    out
}
