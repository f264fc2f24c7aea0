//! Pendulums: a double pendulum with a time-dependent holonomic programme, and a Cartesian pendulum
//! whose rod is a system constraint and whose motion is a complete programme (s = n).

use super::euclidean_names;
use crate::model::Model;
use crate::programme::{Constraints, Level, Role, RowSpec};
use crate::scalar::{c, Scalar};
use crate::solve::Problem;
use nalgebra::DMatrix;

/// Planar double pendulum with point masses; q1 the upper angle from the downward vertical, q2 the
/// elbow angle relative to the upper link (hinge-chain convention of MuJoCo and Pinocchio).
#[derive(Clone, Debug)]
pub struct DoublePendulum {
    pub m1: f64,
    pub m2: f64,
    pub l1: f64,
    pub l2: f64,
    pub g: f64,
}

const DP: [&str; 2] = ["q1", "q2"];

impl Model for DoublePendulum {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    euclidean_names!(DP);

    fn mass_matrix<S: Scalar>(&self, _: &mut (), q: &[S], a: &mut DMatrix<S>) {
        let (m1, m2, l1, l2) = (self.m1, self.m2, self.l1, self.l2);
        let c2 = q[1].cos();
        a[(0, 0)] = c2 * (2.0 * m2 * l1 * l2) + (m1 * l1 * l1 + m2 * (l1 * l1 + l2 * l2));
        a[(0, 1)] = c2 * (m2 * l1 * l2) + m2 * l2 * l2;
        a[(1, 0)] = a[(0, 1)];
        a[(1, 1)] = c(m2 * l2 * l2);
    }

    fn velocity_terms<S: Scalar>(&self, _: &mut (), q: &[S], v: &[S], g: &mut [S]) {
        let h = q[1].sin() * (self.m2 * self.l1 * self.l2);
        g[0] = h * (v[0] * v[1] * 2.0 + v[1] * v[1]);
        g[1] = -h * v[0] * v[0];
    }

    fn applied_forces<S: Scalar>(&self, _: &mut (), _t: S, q: &[S], _v: &[S], f: &mut [S]) {
        let s1 = q[0].sin();
        let s12 = (q[0] + q[1]).sin();
        f[0] =
            -(s1 * ((self.m1 + self.m2) * self.g * self.l1) + s12 * (self.m2 * self.g * self.l2));
        f[1] = -(s12 * (self.m2 * self.g * self.l2));
    }
}

/// Programme q2 - amplitude sin(omega t) = 0.
#[derive(Clone, Debug)]
pub struct ElbowProgramme {
    pub amplitude: f64,
    pub omega: f64,
    rows: [RowSpec; 1],
}

impl ElbowProgramme {
    /// q2(t) = amplitude sin(omega t).
    pub fn new(amplitude: f64, omega: f64) -> Self {
        ElbowProgramme {
            amplitude,
            omega,
            rows: [RowSpec::new("elbow", Level::Position, Role::Programme)],
        }
    }
}

impl Constraints for ElbowProgramme {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    fn rows(&self) -> &[RowSpec] {
        &self.rows
    }
    fn eval<S: Scalar>(&self, _: &mut (), t: S, q: &[S], _v: &[S], _a: &[S], out: &mut [S]) {
        out[0] = q[1] - (t * self.omega).sin() * self.amplitude;
    }
}

/// Double pendulum, q2(t) = 0.5 sin t, from rest at q1 = 0.3 (q2'(0) = 0.5).
pub fn double_pendulum() -> Problem<DoublePendulum, ElbowProgramme> {
    Problem {
        model: DoublePendulum {
            m1: 1.0,
            m2: 1.0,
            l1: 1.0,
            l2: 1.0,
            g: 9.81,
        },
        constraints: ElbowProgramme::new(0.5, 1.0),
        t0: 0.0,
        t1: 10.0,
        q0: vec![0.3, 0.0],
        v0: vec![0.0, 0.5],
    }
}

/// A point mass in the plane, Cartesian (x, y), gravity -g y.
#[derive(Clone, Debug)]
pub struct PlanarMass {
    pub m: f64,
    pub g: f64,
}

const XY: [&str; 2] = ["x", "y"];

impl Model for PlanarMass {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    euclidean_names!(XY);
    fn mass_matrix<S: Scalar>(&self, _: &mut (), _q: &[S], a: &mut DMatrix<S>) {
        a.fill(S::zero());
        a[(0, 0)] = c(self.m);
        a[(1, 1)] = c(self.m);
    }
    fn velocity_terms<S: Scalar>(&self, _: &mut (), _q: &[S], _v: &[S], g: &mut [S]) {
        g[0] = S::zero();
        g[1] = S::zero();
    }
    fn applied_forces<S: Scalar>(&self, _: &mut (), _t: S, _q: &[S], _v: &[S], f: &mut [S]) {
        f[0] = S::zero();
        f[1] = c(-self.m * self.g);
    }
}

/// Rod x^2 + y^2 - L^2 = 0 (system constraint) and programme x - L sin(phi(t)) = 0 with
/// phi(t) = phi0 sin(omega t): together a complete programme (s = n = 2).
#[derive(Clone, Debug)]
pub struct RodAndSwing {
    pub length: f64,
    pub phi0: f64,
    pub omega: f64,
    rows: [RowSpec; 2],
}

impl RodAndSwing {
    /// Rod of `length`, swing amplitude `phi0` at frequency `omega`.
    pub fn new(length: f64, phi0: f64, omega: f64) -> Self {
        RodAndSwing {
            length,
            phi0,
            omega,
            rows: [
                RowSpec::new("rod", Level::Position, Role::System),
                RowSpec::new("swing", Level::Position, Role::Programme),
            ],
        }
    }

    /// Closed form: phi, phid, phidd at t.
    pub fn phi(&self, t: f64) -> (f64, f64, f64) {
        let (a, w) = (self.phi0, self.omega);
        (
            a * (w * t).sin(),
            a * w * (w * t).cos(),
            -a * w * w * (w * t).sin(),
        )
    }
}

impl Constraints for RodAndSwing {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    fn rows(&self) -> &[RowSpec] {
        &self.rows
    }
    fn eval<S: Scalar>(&self, _: &mut (), t: S, q: &[S], _v: &[S], _a: &[S], out: &mut [S]) {
        let l = self.length;
        out[0] = q[0] * q[0] + q[1] * q[1] - l * l;
        let phi = (t * self.omega).sin() * self.phi0;
        out[1] = q[0] - phi.sin() * l;
    }
}

/// The Cartesian pendulum with the complete programme; starts at the bottom moving sideways.
pub fn rod_and_swing() -> Problem<PlanarMass, RodAndSwing> {
    let cons = RodAndSwing::new(1.2, 0.4, 2.0);
    let (_, phid, _) = cons.phi(0.0);
    Problem {
        model: PlanarMass { m: 0.8, g: 9.81 },
        v0: vec![cons.length * phid, 0.0],
        q0: vec![0.0, -cons.length],
        constraints: cons,
        t0: 0.0,
        t1: 5.0,
    }
}
