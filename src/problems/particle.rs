//! Example 2.1: a particle of mass m in a Newtonian field whose speed is programmed constant.
//!
//! Coordinates q = (theta, phi, r) (elevation, azimuth, radius; x = r cos(theta) cos(phi),
//! y = r cos(theta) sin(phi), z = r sin(theta)). Errata applied (`../shared/seed/NOTES.md`):
//! A = m diag(r^2, r^2 cos^2 theta, 1) (2.15 with the mass), Q = (0, 0, -mu m / r^2) (2.17),
//! G re-derived (2.20). Programme (2.18): r^2 thetad^2 + r^2 cos^2(theta) phid^2 + rd^2 - C = 0.
//!
//! Independent checks: the reaction of |v|^2 = C is along the velocity, so the motion stays in its
//! initial plane (angular momentum direction fixed) and |v| = V is constant; on a circular orbit of
//! speed sqrt(mu / r) the natural motion already satisfies the programme, so u = 0 and r is
//! constant, with rd = 0 throughout (where the paper's D (2.19) divides by zero).
//!
//! A first integral (derived here, not in the paper): with alpha the angle of the velocity above the
//! local horizontal, the path obeys d(alpha)/ds = (cos(alpha) / r) (1 - mu / (r V^2)) and
//! dr/ds = sin(alpha), hence h exp(mu / (r V^2)) = const, h = |r x v| (see [`first_integral`]). So
//! the circular orbit is a saddle: faster than circular the particle escapes, slower it falls in,
//! and rd passes through 0 at most once.

use super::euclidean_names;
use crate::model::Model;
use crate::programme::{Constraints, Level, Role, RowSpec};
use crate::scalar::{c, Scalar};
use crate::solve::Problem;
use nalgebra::DMatrix;

/// The particle in spherical coordinates.
#[derive(Clone, Debug)]
pub struct Particle {
    /// Mass m.
    pub m: f64,
    /// Gravitational parameter mu = gamma M.
    pub mu: f64,
}

const NAMES: [&str; 3] = ["theta", "phi", "r"];

impl Model for Particle {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    euclidean_names!(NAMES);

    fn mass_matrix<S: Scalar>(&self, _: &mut (), q: &[S], a: &mut DMatrix<S>) {
        let (th, r) = (q[0], q[2]);
        a.fill(S::zero());
        a[(0, 0)] = r * r * self.m;
        a[(1, 1)] = r * r * th.cos().powi(2) * self.m;
        a[(2, 2)] = c(self.m);
    }

    fn velocity_terms<S: Scalar>(&self, _: &mut (), q: &[S], v: &[S], g: &mut [S]) {
        let (th, r) = (q[0], q[2]);
        let (thd, phd, rd) = (v[0], v[1], v[2]);
        let (s, co) = (th.sin(), th.cos());
        let m = self.m;
        // (2.20), second row sign corrected.
        g[0] = -(r * rd * thd * 2.0 + r * r * co * s * phd * phd) * m;
        g[1] = -(r * co * co * rd * phd - r * r * co * s * thd * phd) * (2.0 * m);
        g[2] = (r * co * co * phd * phd + r * thd * thd) * m;
    }

    fn applied_forces<S: Scalar>(&self, _: &mut (), _t: S, q: &[S], _v: &[S], f: &mut [S]) {
        // (2.17) corrected: Q_r = -mu m / r^2.
        f[0] = S::zero();
        f[1] = S::zero();
        f[2] = -(q[2] * q[2]).recip() * (self.mu * self.m);
    }
}

/// The constant-speed programme (2.18).
#[derive(Clone, Debug)]
pub struct ConstantSpeed {
    /// The programmed squared speed C.
    pub c2: f64,
    rows: [RowSpec; 1],
}

impl ConstantSpeed {
    /// |v|^2 = c2.
    pub fn new(c2: f64) -> Self {
        ConstantSpeed {
            c2,
            rows: [RowSpec::new("speed", Level::Velocity, Role::Programme)],
        }
    }
}

impl Constraints for ConstantSpeed {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    fn rows(&self) -> &[RowSpec] {
        &self.rows
    }
    fn eval<S: Scalar>(&self, _: &mut (), _t: S, q: &[S], v: &[S], _a: &[S], out: &mut [S]) {
        let (th, r) = (q[0], q[2]);
        let co = th.cos();
        out[0] = r * r * v[0] * v[0] + r * r * co * co * v[1] * v[1] + v[2] * v[2] - self.c2;
    }
}

/// Squared speed of a state.
pub fn speed2(q: &[f64], v: &[f64]) -> f64 {
    let (th, r) = (q[0], q[2]);
    r * r * v[0] * v[0] + r * r * th.cos().powi(2) * v[1] * v[1] + v[2] * v[2]
}

/// Cartesian position and velocity of a state.
pub fn cartesian(q: &[f64], v: &[f64]) -> ([f64; 3], [f64; 3]) {
    let (th, ph, r) = (q[0], q[1], q[2]);
    let (st, ct, sp, cp) = (th.sin(), th.cos(), ph.sin(), ph.cos());
    let p = [r * ct * cp, r * ct * sp, r * st];
    let (thd, phd, rd) = (v[0], v[1], v[2]);
    let vel = [
        rd * ct * cp - r * st * thd * cp - r * ct * sp * phd,
        rd * ct * sp - r * st * thd * sp + r * ct * cp * phd,
        rd * st + r * ct * thd,
    ];
    (p, vel)
}

/// Example 2.1 from a given initial state; the programmed speed is the initial speed.
pub fn problem(
    m: f64,
    mu: f64,
    q0: [f64; 3],
    v0: [f64; 3],
    t1: f64,
) -> Problem<Particle, ConstantSpeed> {
    let c2 = speed2(&q0, &v0);
    Problem {
        model: Particle { m, mu },
        constraints: ConstantSpeed::new(c2),
        t0: 0.0,
        t1,
        q0: q0.to_vec(),
        v0: v0.to_vec(),
    }
}

/// An inclined orbit, faster than circular, starting at rd = 0 (where the paper's D (2.19) is
/// singular); the particle then spirals out.
pub fn example_2_1() -> Problem<Particle, ConstantSpeed> {
    // mu = 1, r = 1: circular speed 1; here speed 1.13 with a tilted velocity.
    problem(1.0, 1.0, [0.1, 0.0, 1.0], [0.3, 1.1, 0.0], 20.0)
}

/// Starts inward, faster than circular: rd passes through 0 (at r ~ 0.74), then the particle
/// escapes.
pub fn example_2_1_through_rd0() -> Problem<Particle, ConstantSpeed> {
    problem(1.0, 1.0, [0.1, 0.0, 1.0], [0.3, 1.1, -0.4], 10.0)
}

/// The first integral h exp(mu / (r V^2)) of the constant-speed programme (module docs), per unit
/// mass, at a state.
pub fn first_integral(mu: f64, q: &[f64], v: &[f64]) -> f64 {
    let (p, vel) = cartesian(q, v);
    let h = [
        p[1] * vel[2] - p[2] * vel[1],
        p[2] * vel[0] - p[0] * vel[2],
        p[0] * vel[1] - p[1] * vel[0],
    ];
    let h = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
    h * (mu / (q[2] * speed2(q, v))).exp()
}

/// A circular orbit: the natural motion satisfies the programme, u = 0 exactly, rd = 0 throughout.
pub fn circular_orbit() -> Problem<Particle, ConstantSpeed> {
    let (mu, r): (f64, f64) = (2.0, 1.5);
    let w = (mu / r).sqrt() / r;
    problem(0.7, mu, [0.0, 0.0, r], [0.0, w, 0.0], 10.0)
}
