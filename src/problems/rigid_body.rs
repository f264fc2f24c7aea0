//! Example 3.1: a rigid body whose angular velocity performs a generalized precession.
//!
//! Configuration: a unit quaternion (w, x, y, z) (instead of the paper's Euler angles, which are
//! singular at sin(theta) = 0); velocities: body-frame angular velocity (p, q, r), the paper's
//! quasi-velocities. Equations of the natural system (3.15) with the errata (Q_q in the second row):
//! A pd + (C - B) q r = Q_p, B qd + (A - C) r p = Q_q, C rd + (B - A) p q = Q_r, i.e.
//! A0 = diag(A, B, C) and G0 = -((C - B) q r, (A - C) r p, (B - A) p q).
//! Programme (3.14), acceleration level:
//! h = p qd - q pd + r (p^2 + q^2) - lambda (p^2 + q^2)^(3/2) = 0, with dh/d(omegad) = (-q, p, 0), so
//! u = mu (-q, p, 0) and u_r = 0; it degenerates at p = q = 0.
//!
//! Heavy top: a fixed point at the body origin, centre of mass at (0, 0, l) in the body frame,
//! gravity (0, 0, -g) in the world frame; A, B, C are the principal moments about the fixed point;
//! Q = c x (R^T m g_world) (body-frame gravity torque).
//!
//! Independent checks: u . omega = 0 (the control does no work), so T (free body) or T + V (heavy
//! top) is conserved. For an axisymmetric free body (A = B) there is a closed form: r is constant,
//! rho = |(p, q)| is constant and (p, q) turns at the rate lambda rho - r, with
//! u = (A lambda rho - C r) (-q, p, 0) (derived from (3.19) and (3.14)).

use crate::model::{lie, Model, Segment};
use crate::programme::{Constraints, Level, Role, RowSpec};
use crate::scalar::Scalar;
use crate::solve::Problem;
use nalgebra::DMatrix;

/// A rigid body about a fixed point (or its centre of mass when `m l g = 0`).
#[derive(Clone, Debug)]
pub struct RigidBody {
    /// Principal moments A, B, C about the fixed point.
    pub inertia: [f64; 3],
    /// Mass (used by gravity only).
    pub m: f64,
    /// Distance of the centre of mass from the fixed point along the body z axis.
    pub l: f64,
    /// Gravitational acceleration (world -z).
    pub g: f64,
}

const SEG: [Segment; 1] = [Segment::Quaternion { q: 0, v: 0 }];

impl Model for RigidBody {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    fn nq(&self) -> usize {
        4
    }
    fn nv(&self) -> usize {
        3
    }
    fn segments(&self) -> &[Segment] {
        &SEG
    }
    fn q_names(&self) -> Vec<String> {
        ["qw", "qx", "qy", "qz"]
            .iter()
            .map(|s| s.to_string())
            .collect()
    }
    fn v_names(&self) -> Vec<String> {
        ["p", "q", "r"].iter().map(|s| s.to_string()).collect()
    }
    fn mass_matrix<S: Scalar>(&self, _: &mut (), _q: &[S], a: &mut DMatrix<S>) {
        a.fill(S::zero());
        for k in 0..3 {
            a[(k, k)] = S::from(self.inertia[k]);
        }
    }
    fn velocity_terms<S: Scalar>(&self, _: &mut (), _q: &[S], w: &[S], g: &mut [S]) {
        let [a, b, c] = self.inertia;
        g[0] = -(w[1] * w[2] * (c - b));
        g[1] = -(w[2] * w[0] * (a - c));
        g[2] = -(w[0] * w[1] * (b - a));
    }
    fn applied_forces<S: Scalar>(&self, _: &mut (), _t: S, q: &[S], _w: &[S], f: &mut [S]) {
        let gw = [S::zero(), S::zero(), S::from(-self.m * self.g)];
        let gb = lie::rotate_inv(q, &gw);
        let cm = [S::zero(), S::zero(), S::from(self.l)];
        let tau = lie::cross(&cm, &gb);
        f[..3].copy_from_slice(&tau);
    }
}

/// The generalized-precession programme (3.14).
#[derive(Clone, Debug)]
pub struct Precession {
    /// The constant lambda of (3.14).
    pub lambda: f64,
    rows: [RowSpec; 1],
}

impl Precession {
    /// Programme with constant `lambda`.
    pub fn new(lambda: f64) -> Self {
        Precession {
            lambda,
            rows: [RowSpec::new(
                "precession",
                Level::Acceleration,
                Role::Programme,
            )],
        }
    }
}

impl Constraints for Precession {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    fn rows(&self) -> &[RowSpec] {
        &self.rows
    }
    fn eval<S: Scalar>(&self, _: &mut (), _t: S, _q: &[S], w: &[S], a: &[S], out: &mut [S]) {
        let (p, q, r) = (w[0], w[1], w[2]);
        let rho2 = p * p + q * q;
        // rho2^(3/2) is C1 with zero gradient at rho2 = 0, but forward AD of rho2 * sqrt(rho2) (or
        // num-dual's powf) gives 0 * inf = NaN there: take the exact value 0 at that point.
        let rho3 = if rho2.re() == 0.0 {
            rho2
        } else {
            rho2 * rho2.sqrt()
        };
        out[0] = p * a[1] - q * a[0] + r * rho2 - rho3 * self.lambda;
    }
}

/// Kinetic plus potential energy of a state.
pub fn energy(body: &RigidBody, q: &[f64], w: &[f64]) -> f64 {
    let t: f64 = (0..3).map(|k| 0.5 * body.inertia[k] * w[k] * w[k]).sum();
    let c = lie::rotate(q, &[0.0, 0.0, body.l]);
    t + body.m * body.g * c[2]
}

/// A free asymmetric body.
pub fn free_body() -> Problem<RigidBody, Precession> {
    Problem {
        model: RigidBody {
            inertia: [1.0, 2.0, 3.0],
            m: 0.0,
            l: 0.0,
            g: 0.0,
        },
        constraints: Precession::new(0.5),
        t0: 0.0,
        t1: 10.0,
        q0: vec![1.0, 0.0, 0.0, 0.0],
        v0: vec![0.8, 0.3, 1.2],
    }
}

/// An axisymmetric free body (A = B), with the closed form of the module docs.
pub fn symmetric_body() -> Problem<RigidBody, Precession> {
    Problem {
        model: RigidBody {
            inertia: [2.0, 2.0, 1.0],
            m: 0.0,
            l: 0.0,
            g: 0.0,
        },
        constraints: Precession::new(0.7),
        t0: 0.0,
        t1: 10.0,
        q0: vec![1.0, 0.0, 0.0, 0.0],
        v0: vec![0.6, 0.8, 1.5],
    }
}

/// Closed form for [`symmetric_body`]-type problems: omega(t) and u(t).
pub fn symmetric_closed_form(
    body: &RigidBody,
    lambda: f64,
    w0: [f64; 3],
    t: f64,
) -> ([f64; 3], [f64; 3]) {
    let rho = (w0[0] * w0[0] + w0[1] * w0[1]).sqrt();
    let psi0 = w0[1].atan2(w0[0]);
    let r = w0[2];
    let rate = lambda * rho - r;
    let psi = psi0 + rate * t;
    let (p, q) = (rho * psi.cos(), rho * psi.sin());
    let mu = body.inertia[0] * lambda * rho - body.inertia[2] * r;
    ([p, q, r], [-mu * q, mu * p, 0.0])
}

/// A heavy top: tilted, spinning, with gravity torque depending on the orientation.
pub fn heavy_top() -> Problem<RigidBody, Precession> {
    let tilt: f64 = 0.3;
    Problem {
        model: RigidBody {
            inertia: [1.5, 1.5, 0.5],
            m: 1.0,
            l: 0.5,
            g: 9.81,
        },
        constraints: Precession::new(0.2),
        t0: 0.0,
        t1: 5.0,
        q0: vec![(tilt / 2.0).cos(), (tilt / 2.0).sin(), 0.0, 0.0],
        v0: vec![0.5, 0.4, 8.0],
    }
}

/// Angular velocity along the body z axis: the programme's gradient (-q, p, 0) vanishes.
pub fn degenerate_start() -> Problem<RigidBody, Precession> {
    let mut p = free_body();
    p.v0 = vec![0.0, 0.0, 1.0];
    p
}
