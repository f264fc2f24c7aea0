//! Body-point signals of tree scenes: the expressions' view of named sites.
//!
//! A site `tip` (a point fixed in a body) offers `tip.x`, `tip.y`, `tip.z` (world position), their
//! time derivatives `tip.x'` (velocity) and `tip.x''` (acceleration), the body orientation
//! `tip.qw`, `tip.qx`, `tip.qy`, `tip.qz` (unit quaternion, body to world) and the world angular
//! velocity `tip.wx`, `tip.wy`, `tip.wz` with derivative `tip.wx'`. Only the signals a scene uses
//! are computed, by the tree's forward kinematics over the same scalar type as everything else
//! (so their derivatives are exact).

use crate::programme::Level;
use crate::scalar::Scalar;
use crate::tree::spatial::{cross, mm, mv, quat_from_rot};
use crate::tree::{self, TreeData};
use nalgebra::{DMatrix, Matrix3, Vector3};
use std::sync::Arc;

/// What a signal measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    /// World position component (0..3) and its time derivatives (order 0, 1, 2).
    Position { axis: usize, order: u8 },
    /// Body orientation quaternion component (w, x, y, z).
    Orientation { k: usize },
    /// World angular velocity component (order 0) or angular acceleration (order 1).
    Angular { axis: usize, order: u8 },
    /// The system's angular momentum about its centre of mass, world frame (order 0), or its
    /// rate (order 1): `com.hx`, `com.hx'` only.
    Momentum { axis: usize, order: u8 },
}

impl Quantity {
    /// Level of a row that reads this signal.
    pub fn level(&self) -> Level {
        let o = match *self {
            Quantity::Position { order, .. } => order,
            Quantity::Orientation { .. } => 0,
            Quantity::Angular { order, .. } | Quantity::Momentum { order, .. } => order + 1,
        };
        match o {
            0 => Level::Position,
            1 => Level::Velocity,
            _ => Level::Acceleration,
        }
    }

    /// Parse the part of a signal name after `site.`: `x`, `y'`, `qw`, `wz'`...
    pub fn parse(component: &str) -> Option<Quantity> {
        let order = component.bytes().rev().take_while(|&b| b == b'\'').count() as u8;
        let base = component.trim_end_matches('\'');
        let axis = |c: &str| match c {
            "x" => Some(0),
            "y" => Some(1),
            "z" => Some(2),
            _ => None,
        };
        if let Some(a) = axis(base) {
            return (order <= 2).then_some(Quantity::Position { axis: a, order });
        }
        if let Some(rest) = base.strip_prefix('w') {
            if let Some(a) = axis(rest) {
                return (order <= 1).then_some(Quantity::Angular { axis: a, order });
            }
        }
        if let Some(rest) = base.strip_prefix('h') {
            if let Some(a) = axis(rest) {
                return (order <= 1).then_some(Quantity::Momentum { axis: a, order });
            }
        }
        if order == 0 {
            return match base {
                "qw" => Some(Quantity::Orientation { k: 0 }),
                "qx" => Some(Quantity::Orientation { k: 1 }),
                "qy" => Some(Quantity::Orientation { k: 2 }),
                "qz" => Some(Quantity::Orientation { k: 3 }),
                _ => None,
            };
        }
        None
    }
}

/// A named site: a point fixed in a body.
#[derive(Clone, Debug, PartialEq)]
pub struct Site {
    pub name: String,
    pub body: usize,
    pub pos: [f64; 3],
}

/// The site index of the system's centre of mass (`com.x`, `com.y'`, `com.z''`), a virtual site.
pub const COM: usize = usize::MAX;

/// The signals a scene's expressions read, in slot order.
#[derive(Clone, Debug, Default)]
pub struct Signals {
    tree: Option<Arc<tree::Model>>,
    sites: Vec<Site>,
    /// (site index, quantity) per signal slot.
    list: Vec<(usize, Quantity)>,
    /// The centre of mass c = sum_i m_i p_i / M over the rigid bodies with mass (a body with the
    /// bodies welded to it): (body, p_i its CoM in the body frame, m_i / M). c, its rates and its
    /// Jacobian are the same weighted sums of the bodies' point kinematics.
    com: Vec<(usize, [f64; 3], f64)>,
    /// Per entry of `com` (a rigid body of mass 0 with a rotational inertia has weight 0): m_i
    /// and the inertia about its CoM in the body frame, for the angular momentum about c.
    com_inertia: Vec<(f64, Matrix3<f64>)>,
}

/// Scratch for computing signals.
pub struct SignalWork<S: Scalar> {
    data: Option<TreeData<S>>,
    /// Per link: the centre of mass's subtree sums ([`tree::weighted_points_jacobian`]).
    com_sub: Vec<(S, Vector3<S>)>,
}

/// Signals as Taylor jets along the motion with dv/dt = 0 at (q, v), and their velocity
/// Jacobians: what the chain-rule jet of the rows ([`super::rows`]) needs.
pub struct SignalJets<S: Scalar> {
    /// Per signal: value, d/dt, d^2/dt^2 along the motion with dv/dt = 0 (entries a signal's
    /// derivative order does not reach are zero).
    pub taylor: Vec<[S; 3]>,
    /// Row k: d(signal k^(m))/d(dv/dt) where m = 2 - (derivative order of signal k): the signal's
    /// linear or angular Jacobian (orientation: d(quat')/dv). Filled for signals flagged in `needs`.
    pub jac: DMatrix<S>,
    /// The world angular (rows 0..3) and linear (rows 3..6) Jacobian of the site read last: the
    /// signals of one site share it (a frame task reads up to seven).
    site_jac: DMatrix<S>,
    /// The centre of mass c, c' and c''_0, and its linear Jacobian (`3 x nv`): computed at the
    /// first `com` position signal of a call, read by the others.
    com: [Vector3<S>; 3],
    com_jac: DMatrix<S>,
}

impl<S: Scalar> SignalJets<S> {
    /// Storage for `n` signals and `nv` velocities.
    pub fn new(n: usize, nv: usize) -> Self {
        SignalJets {
            taylor: vec![[S::zero(); 3]; n],
            jac: DMatrix::from_element(n, nv, S::zero()),
            site_jac: DMatrix::from_element(6, nv, S::zero()),
            com: [Vector3::zeros(); 3],
            com_jac: DMatrix::from_element(3, nv, S::zero()),
        }
    }
}

impl Signals {
    /// No signals (Lagrangian scenes).
    pub fn none() -> Self {
        Signals::default()
    }

    /// Signals on `sites` of `tree`; add them with [`Signals::push`].
    pub fn new(tree: Arc<tree::Model>, sites: Vec<Site>) -> Self {
        let bodies = tree.bodies();
        let total: f64 = bodies.iter().map(|b| b.mass).sum();
        // The bodies welded to one link move as one rigid body: one entry each (mass, CoM and
        // inertia about it in the link's own body, parallel-axis theorem), so the sums over the
        // bodies below run over the moving links (a humanoid: 19 entries, not 60). Not read from
        // the tree's folded links: those hold the inertia about the link's origin, and the inertia
        // about the CoM recovered from it (ibar - m (|c|^2 1 - c c^T)) would lose digits to
        // cancellation for a CoM far from the origin; combining the parts about their own CoMs
        // does not.
        // (mass, CoM, inertia about it) of each body, in the frame of its link's own body
        type Part = (f64, Vector3<f64>, Matrix3<f64>);
        let mut owners: Vec<(usize, Vec<Part>)> = vec![];
        for (i, b) in bodies.iter().enumerate() {
            if b.mass <= 0.0 && b.inertia.iter().all(|x| *x == 0.0) {
                continue;
            }
            let (o, r, p) =
                (tree.welded_into(i)).unwrap_or((i, Matrix3::identity(), Vector3::zeros()));
            let part = (b.mass, p + r * b.com, r * b.inertia * r.transpose());
            match owners.iter_mut().find(|e| e.0 == o) {
                Some(e) => e.1.push(part),
                None => owners.push((o, vec![part])),
            }
        }
        let mut com = vec![];
        let mut com_inertia = vec![];
        for (o, parts) in owners {
            let m: f64 = parts.iter().map(|x| x.0).sum();
            let moment: Vector3<f64> = parts.iter().map(|x| x.1 * x.0).sum();
            let c = if m > 0.0 {
                moment / m
            } else {
                Vector3::zeros()
            };
            let mut inertia = Matrix3::zeros();
            for (mi, ci, ii) in parts {
                let d = ci - c;
                inertia += ii + (Matrix3::identity() * d.dot(&d) - d * d.transpose()) * mi;
            }
            com.push((o, [c.x, c.y, c.z], m / total));
            com_inertia.push((m, inertia));
        }
        Signals {
            tree: Some(tree),
            sites,
            list: vec![],
            com: if total > 0.0 { com } else { vec![] },
            com_inertia,
        }
    }

    /// The sites.
    pub fn sites(&self) -> &[Site] {
        &self.sites
    }

    /// Resolve a name `site.component`; returns its quantity if it names a signal. The site is
    /// all before the last `.` (a robot file's link name may hold dots: `` `link_8.0`.x ``).
    /// `com.x`, `com.y'`, `com.z''` are the system's centre of mass, `com.hx`, `com.hx'` its
    /// angular momentum about it (world frame), unless a site is named `com`.
    pub fn resolve(&self, name: &str) -> Option<(usize, Quantity)> {
        let (site, comp) = name.rsplit_once('.')?;
        let Some(i) = self.sites.iter().position(|s| s.name == site) else {
            return match Quantity::parse(comp) {
                Some(q @ (Quantity::Position { .. } | Quantity::Momentum { .. }))
                    if site == "com" && !self.com.is_empty() =>
                {
                    Some((COM, q))
                }
                _ => None,
            };
        };
        Quantity::parse(comp)
            .filter(|q| !matches!(q, Quantity::Momentum { .. }))
            .map(|q| (i, q))
    }

    /// Add a signal; returns its index among the signals.
    pub fn push(&mut self, site: usize, q: Quantity) -> usize {
        self.list.push((site, q));
        self.list.len() - 1
    }

    /// Quantity of signal `k`.
    pub fn quantity(&self, k: usize) -> Quantity {
        self.list[k].1
    }

    /// Number of signal slots.
    pub fn len(&self) -> usize {
        self.list.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// Allocate scratch.
    pub fn work<S: Scalar>(&self) -> SignalWork<S> {
        SignalWork {
            data: self.tree.as_ref().map(|t| t.data::<S>()),
            com_sub: Vec::with_capacity(self.tree.as_ref().map_or(0, |t| t.links.len())),
        }
    }

    /// Highest derivative order any signal needs (0 positions/orientations, 1 velocities, 2).
    fn max_order(&self) -> u8 {
        self.list
            .iter()
            .map(|&(_, q)| match q {
                Quantity::Position { order, .. } => order,
                Quantity::Orientation { .. } => 0,
                Quantity::Angular { order, .. } | Quantity::Momentum { order, .. } => order + 1,
            })
            .max()
            .unwrap_or(0)
    }

    /// Compute all signals at (q, v, a) into `out`: the tree's forward passes run once, up to the
    /// order the signals need.
    pub fn fill<S: Scalar>(&self, w: &mut SignalWork<S>, q: &[S], v: &[S], a: &[S], out: &mut [S]) {
        let (Some(tree), Some(data)) = (&self.tree, &mut w.data) else {
            return;
        };
        if self.list.is_empty() {
            return;
        }
        let order = self.max_order();
        tree::forward_kinematics(tree, data, q);
        if order >= 1 {
            tree::forward_velocity(tree, data, v);
        }
        if order >= 2 {
            tree::forward_acceleration(tree, data, a, &Vector3::zeros());
        }
        for (k, &(si, quantity)) in self.list.iter().enumerate() {
            if si == COM {
                if let Quantity::Momentum { axis, order } = quantity {
                    let (h, dh) = self.momentum(tree, data);
                    out[k] = if order == 0 { h[axis] } else { dh[axis] };
                    continue;
                }
                let Quantity::Position { axis, order } = quantity else {
                    unreachable!("the centre of mass has positions and momenta only")
                };
                let mut c = S::zero();
                for (b, p, w) in &self.com {
                    let pk = tree::point_kinematics(tree, data, *b, &lift(p));
                    let x = match order {
                        0 => pk.pos[axis],
                        1 => pk.vel[axis],
                        _ => pk.acc[axis],
                    };
                    c += x * S::from(*w);
                }
                out[k] = c;
                continue;
            }
            let site = &self.sites[si];
            let p = lift(&site.pos);
            let (rot, origin) = tree::body_frame(tree, data, site.body);
            out[k] = match quantity {
                Quantity::Position { axis, order: 0 } => (origin + mv(&rot, &p))[axis],
                Quantity::Orientation { k } => quat_from_rot(&rot)[k],
                _ => {
                    let pk = tree::point_kinematics(tree, data, site.body, &p);
                    match quantity {
                        Quantity::Position { axis, order: 1 } => pk.vel[axis],
                        Quantity::Position { axis, .. } => pk.acc[axis],
                        Quantity::Angular { axis, order: 0 } => pk.omega[axis],
                        Quantity::Angular { axis, .. } => pk.alpha[axis],
                        Quantity::Orientation { .. } => unreachable!(),
                        Quantity::Momentum { .. } => unreachable!("the centre of mass's only"),
                    }
                }
            };
        }
    }

    /// Taylor jets of all signals along the motion with dv/dt = 0 at (q, v), and the Jacobian rows
    /// of the signals flagged in `needs` (see [`SignalJets`]). One set of forward passes: those of
    /// `sweep` (the model's workspace) when it is over this tree, whose position and velocity
    /// passes are then already done at (q, v) by the mass matrix and the forces and are reused bit
    /// for bit ([`tree::forward_kinematics`] recomputes them otherwise); only the acceleration pass
    /// (dv/dt = 0, no gravity) runs here, over the model's accelerations, which the forces have
    /// consumed.
    ///
    /// Position p: (p, p', p''_0), row J_p; velocity p': (p', p''_0), row J_p; acceleration p'':
    /// p''_0, row J_p. Angular velocity w: (w, w'_0), row J_w; w': w'_0, row J_w. Orientation
    /// quat (body -> world): quat' = 1/2 (0, w) (x) quat, quat''_0 = 1/2 [(0, w'_0) (x) quat +
    /// (0, w) (x) quat'], row 1/2 (0, J_w) (x) quat.
    pub fn jets<S: Scalar>(
        &self,
        w: &mut SignalWork<S>,
        sweep: Option<tree::TreeSweep<'_, S>>,
        q: &[S],
        v: &[S],
        needs: &[bool],
        out: &mut SignalJets<S>,
    ) {
        let SignalWork { data: own, com_sub } = w;
        let (Some(tree), Some(own)) = (&self.tree, own) else {
            return;
        };
        if self.list.is_empty() {
            return;
        }
        let data = match sweep {
            Some(s) if std::ptr::eq(s.model, &**tree) => s.data,
            _ => own,
        };
        tree::forward_kinematics(tree, data, q);
        tree::forward_velocity(tree, data, v);
        tree::forward_bias_acceleration(tree, data);
        let z = S::zero();
        // (site, its kinematics, whether site_jac holds its Jacobian) of the site read last
        let mut last: Option<(usize, tree::PointKinematics<S>, bool)> = None;
        // the centre of mass's position signals share one computation (`com_jets`)
        let com_position = |(&(si, q), &need): (&(usize, Quantity), &bool)| {
            si == COM && matches!(q, Quantity::Position { .. }) && need
        };
        let mut com_done = false;
        for (k, &(si, quantity)) in self.list.iter().enumerate() {
            if si == COM {
                if !com_done && matches!(quantity, Quantity::Position { .. }) {
                    let jac = self.list.iter().zip(needs).any(com_position);
                    self.com_jets(tree, data, jac, com_sub, out);
                    com_done = true;
                }
                self.com_jet(tree, data, quantity, needs[k], k, out);
                continue;
            }
            let site = &self.sites[si];
            let (pk, has_jac) = match last {
                Some((s, pk, j)) if s == si => (pk, j),
                _ => {
                    let pk = tree::point_kinematics(tree, data, site.body, &lift(&site.pos));
                    (pk, false)
                }
            };
            last = Some((si, pk, has_jac));
            let (quat, dquat) = if let Quantity::Orientation { .. } = quantity {
                let qb = quat_from_rot(&pk.rot);
                let d = omega_times(&pk.omega, &qb);
                (qb, d)
            } else {
                ([z; 4], [z; 4])
            };
            out.taylor[k] = match quantity {
                Quantity::Position { axis, order: 0 } => [pk.pos[axis], pk.vel[axis], pk.acc[axis]],
                Quantity::Position { axis, order: 1 } => [pk.vel[axis], pk.acc[axis], z],
                Quantity::Position { axis, .. } => [pk.acc[axis], z, z],
                Quantity::Angular { axis, order: 0 } => [pk.omega[axis], pk.alpha[axis], z],
                Quantity::Angular { axis, .. } => [pk.alpha[axis], z, z],
                Quantity::Momentum { .. } => unreachable!("the centre of mass's only"),
                Quantity::Orientation { k: c } => {
                    let a = omega_times(&pk.alpha, &quat);
                    let b = omega_times(&pk.omega, &dquat);
                    [quat[c], dquat[c], a[c] + b[c]]
                }
            };
            if !needs[k] {
                continue;
            }
            if !has_jac {
                let jac = &mut out.site_jac;
                jac.fill(z);
                tree::for_each_point_column(tree, data, site.body, &pk.pos, |j, wc, lin| {
                    for r in 0..3 {
                        jac[(r, j)] = wc[r];
                        jac[(r + 3, j)] = lin[r];
                    }
                });
                last = Some((si, pk, true));
            }
            let jac = &out.site_jac;
            let mut row = out.jac.row_mut(k);
            for j in 0..jac.ncols() {
                let wc = Vector3::new(jac[(0, j)], jac[(1, j)], jac[(2, j)]);
                row[j] = match quantity {
                    Quantity::Position { axis, .. } => jac[(3 + axis, j)],
                    Quantity::Angular { axis, .. } => wc[axis],
                    Quantity::Orientation { k: c } => omega_times(&wc, &quat)[c],
                    Quantity::Momentum { .. } => unreachable!("the centre of mass's only"),
                };
            }
        }
    }
}

impl Signals {
    /// Signal `k`, a centre-of-mass component, into `out` ([`Signals::jets`]): a position
    /// component from `out.com` and `out.com_jac` ([`Signals::com_jets`]), a momentum component
    /// from [`Signals::momentum_jet`].
    fn com_jet<S: Scalar>(
        &self,
        tree: &tree::Model,
        data: &tree::TreeData<S>,
        quantity: Quantity,
        need: bool,
        k: usize,
        out: &mut SignalJets<S>,
    ) {
        if let Quantity::Momentum { axis, order } = quantity {
            return self.momentum_jet(tree, data, (axis, order), need, k, out);
        }
        let Quantity::Position { axis, order } = quantity else {
            unreachable!("the centre of mass has positions and momenta only")
        };
        let z = S::zero();
        let mut jet = [z; 3];
        for (m, j) in jet.iter_mut().enumerate().take(3 - order as usize) {
            *j = out.com[m + order as usize][axis];
        }
        out.taylor[k] = jet;
        if need {
            for j in 0..out.jac.ncols() {
                out.jac[(k, j)] = out.com_jac[(axis, j)];
            }
        }
    }

    /// c = sum_i m_i p_i / M, c' and c''_0 (the same sums of the bodies' point kinematics) into
    /// `out.com`, and when `jac` its linear Jacobian into `out.com_jac`, by subtree sums
    /// ([`tree::weighted_points_jacobian`]): once per call, for every `com` position signal.
    fn com_jets<S: Scalar>(
        &self,
        tree: &tree::Model,
        data: &tree::TreeData<S>,
        jac: bool,
        sub: &mut Vec<(S, Vector3<S>)>,
        out: &mut SignalJets<S>,
    ) {
        out.com = [Vector3::zeros(); 3];
        for (b, p, w) in &self.com {
            let w = S::from(*w);
            let pk = tree::point_kinematics(tree, data, *b, &lift(p));
            out.com[0] += pk.pos * w;
            out.com[1] += pk.vel * w;
            out.com[2] += pk.acc * w;
        }
        if jac {
            let points = (self.com.iter()).map(|(b, p, w)| (*b, lift(p), S::from(*w)));
            tree::weighted_points_jacobian(tree, data, points, sub, &mut out.com_jac);
        }
    }
}

impl Signals {
    /// The centre of mass c from the position pass in `data`.
    fn com_point<S: Scalar>(&self, tree: &tree::Model, data: &TreeData<S>) -> Vector3<S> {
        let mut c = Vector3::zeros();
        for (b, p, w) in &self.com {
            c += tree::point_kinematics(tree, data, *b, &lift(p)).pos * S::from(*w);
        }
        c
    }

    /// The angular momentum about the centre of mass, world frame, from the passes in `data`,
    /// and its rate, in one sweep over the bodies:
    /// h = sum_i [R I_i R^T w_i + m_i (p_i - c) x v_i],
    /// h' = sum_i [R I_i R^T alpha_i + w_i x R I_i R^T w_i + m_i (p_i - c) x a_i] (the terms
    /// m_i (v_i - c') x v_i sum to -c' x M c' = 0; h' reads the acceleration pass).
    fn momentum<S: Scalar>(
        &self,
        tree: &tree::Model,
        data: &TreeData<S>,
    ) -> (Vector3<S>, Vector3<S>) {
        let c = self.com_point(tree, data);
        let (mut h, mut dh) = (Vector3::zeros(), Vector3::zeros());
        for ((b, p, _), (m, inertia)) in self.com.iter().zip(&self.com_inertia) {
            let pk = tree::point_kinematics(tree, data, *b, &lift(p));
            let iw = mm(&mm(&pk.rot, &inertia.map(S::from)), &pk.rot.transpose());
            let (r, m) = (pk.pos - c, S::from(*m));
            let iw_w = iw * pk.omega;
            h += iw_w + cross(&r, &pk.vel) * m;
            dh += iw * pk.alpha + cross(&pk.omega, &iw_w) + cross(&r, &pk.acc) * m;
        }
        (h, dh)
    }

    /// Signal `k`, a component of the angular momentum about c, into `out` ([`Signals::jets`]):
    /// h: (h, h'_0), h': h'_0 (passes with dv/dt = 0); its Jacobian row is the centroidal momentum
    /// matrix's angular row, sum_i [R I_i R^T J_w,i + m_i (p_i - c) x J_v,i] (d h' / d(dv/dt)).
    fn momentum_jet<S: Scalar>(
        &self,
        tree: &tree::Model,
        data: &TreeData<S>,
        (axis, order): (usize, u8),
        need: bool,
        k: usize,
        out: &mut SignalJets<S>,
    ) {
        let z = S::zero();
        let (h, dh) = self.momentum(tree, data);
        out.taylor[k] = if order == 0 {
            [h[axis], dh[axis], z]
        } else {
            [dh[axis], z, z]
        };
        if !need {
            return;
        }
        let c = self.com_point(tree, data);
        let mut row = out.jac.row_mut(k);
        row.fill(z);
        for ((b, p, _), (m, inertia)) in self.com.iter().zip(&self.com_inertia) {
            let pk = tree::point_kinematics(tree, data, *b, &lift(p));
            let iw = mm(&mm(&pk.rot, &inertia.map(S::from)), &pk.rot.transpose());
            let r = pk.pos - c;
            let m = S::from(*m);
            tree::for_each_point_column(tree, data, *b, &pk.pos, |j, wc, lin| {
                row[j] += (iw * wc + cross(&r, &lin) * m)[axis];
            });
        }
    }
}

/// 1/2 (0, w) (x) quat: the rate of a body -> world quaternion under world angular velocity w.
fn omega_times<S: Scalar>(w: &Vector3<S>, q: &[S; 4]) -> [S; 4] {
    let h = S::from(0.5);
    [
        -(w[0] * q[1] + w[1] * q[2] + w[2] * q[3]) * h,
        (w[0] * q[0] + w[1] * q[3] - w[2] * q[2]) * h,
        (w[1] * q[0] + w[2] * q[1] - w[0] * q[3]) * h,
        (w[2] * q[0] + w[0] * q[2] - w[1] * q[1]) * h,
    ]
}

fn lift<S: Scalar>(p: &[f64; 3]) -> Vector3<S> {
    Vector3::new(S::from(p[0]), S::from(p[1]), S::from(p[2]))
}
