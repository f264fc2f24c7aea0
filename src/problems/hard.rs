//! Hard cases for numerical stability (`tests/hard_cases.rs`, `references/hard/README.md`).
//!
//! - [`precession_to_axis`]: Example 3.1 on an axisymmetric body with a transverse damping torque,
//!   so that p^2 + q^2 -> 0 (the programme's gradient (-q, p, 0) vanishes) at a known rate.
//! - [`arm_through_boundary`]: a two-link arm whose end point is programmed along a line that
//!   leaves the workspace (dead point: the programme Jacobian loses rank at full stretch).
//! - [`nearly_redundant`]: a point mass with two rows whose gradients differ by eps.
//! - [`WithForce`] with [`JointSpringLaw`]: a stiff, damped joint spring added to any Euclidean model.
//! - [`WithForce`] with [`NanAfterLaw`]: an applied force that turns NaN after a given time.

use super::euclidean_names;
use super::pendulum::{DoublePendulum, ElbowProgramme};
use super::rigid_body::{Precession, RigidBody};
use crate::model::{Model, Segment};
use crate::programme::{Constraints, Level, Role, RowSpec};
use crate::scalar::{c, Scalar};
use crate::solve::Problem;
use nalgebra::DMatrix;

/// A rigid body with the torque -c (p, q, 0) (body frame): damps the transverse spin only.
#[derive(Clone, Debug)]
pub struct TransverseDamping {
    pub body: RigidBody,
    pub c: f64,
}

impl Model for TransverseDamping {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    fn nq(&self) -> usize {
        4
    }
    fn nv(&self) -> usize {
        3
    }
    fn segments(&self) -> &[Segment] {
        self.body.segments()
    }
    fn q_names(&self) -> Vec<String> {
        self.body.q_names()
    }
    fn v_names(&self) -> Vec<String> {
        self.body.v_names()
    }
    fn mass_matrix<S: Scalar>(&self, ws: &mut (), q: &[S], a: &mut DMatrix<S>) {
        self.body.mass_matrix(ws, q, a)
    }
    fn velocity_terms<S: Scalar>(&self, ws: &mut (), q: &[S], v: &[S], g: &mut [S]) {
        self.body.velocity_terms(ws, q, v, g)
    }
    fn applied_forces<S: Scalar>(&self, ws: &mut (), t: S, q: &[S], v: &[S], f: &mut [S]) {
        self.body.applied_forces(ws, t, q, v, f);
        f[0] -= v[0] * self.c;
        f[1] -= v[1] * self.c;
    }
}

/// Free axisymmetric body (A = B = 2, C = 1), lambda = 0.7, transverse damping c = 4.
/// Closed form ([`precession_to_axis_closed_form`]): rho = |(p, q)| = rho0 exp(-c t / A), so the
/// gradient norm |(-q, p, 0)| = rho falls below `vanishing` x rho0 at t = (A / c) ln(1 / vanishing).
pub fn precession_to_axis() -> Problem<TransverseDamping, Precession> {
    Problem {
        model: TransverseDamping {
            body: RigidBody {
                inertia: [2.0, 2.0, 1.0],
                m: 0.0,
                l: 0.0,
                g: 0.0,
            },
            c: 4.0,
        },
        constraints: Precession::new(0.7),
        t0: 0.0,
        t1: 30.0,
        q0: vec![1.0, 0.0, 0.0, 0.0],
        v0: vec![0.6, 0.8, 1.5],
    }
}

/// Closed form of [`precession_to_axis`]-type problems (A = B): omega(t) and u(t).
/// Radial: A rho' = -c rho; tangential: psi' = lambda rho - r (the programme), r constant;
/// u = (A lambda rho - C r) (-q, p, 0).
pub fn precession_to_axis_closed_form(
    m: &TransverseDamping,
    lambda: f64,
    w0: [f64; 3],
    t: f64,
) -> ([f64; 3], [f64; 3]) {
    let [a, _, cc] = m.body.inertia;
    let k = m.c / a;
    let rho0 = w0[0].hypot(w0[1]);
    let rho = rho0 * (-k * t).exp();
    let r = w0[2];
    let psi = w0[1].atan2(w0[0]) - r * t + lambda * rho0 * (1.0 - (-k * t).exp()) / k;
    let (p, q) = (rho * psi.cos(), rho * psi.sin());
    let mu = a * lambda * rho - cc * r;
    ([p, q, r], [-mu * q, mu * p, 0.0])
}

/// The end point of a [`DoublePendulum`] (pivot at the origin, y up) programmed along the
/// horizontal line y = y0 at speed `speed`: x = x0 + speed t, y = y0 (two position rows, s = n).
#[derive(Clone, Debug)]
pub struct TipOnLine {
    pub l1: f64,
    pub l2: f64,
    pub x0: f64,
    pub y0: f64,
    pub speed: f64,
    rows: [RowSpec; 2],
}

impl TipOnLine {
    /// End point on y = y0, x = x0 + speed t.
    pub fn new(l1: f64, l2: f64, x0: f64, y0: f64, speed: f64) -> Self {
        TipOnLine {
            l1,
            l2,
            x0,
            y0,
            speed,
            rows: [
                RowSpec::new("tip_x", Level::Position, Role::Programme),
                RowSpec::new("tip_y", Level::Position, Role::Programme),
            ],
        }
    }

    /// Time at which the line leaves the workspace (|tip| = l1 + l2), x0 >= 0, speed > 0.
    pub fn t_boundary(&self) -> f64 {
        let r = self.l1 + self.l2;
        ((r * r - self.y0 * self.y0).sqrt() - self.x0) / self.speed
    }
}

impl Constraints for TipOnLine {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    fn rows(&self) -> &[RowSpec] {
        &self.rows
    }
    fn eval<S: Scalar>(&self, _: &mut (), t: S, q: &[S], _v: &[S], _a: &[S], out: &mut [S]) {
        let q12 = q[0] + q[1];
        out[0] = q[0].sin() * self.l1 + q12.sin() * self.l2 - (t * self.speed + self.x0);
        out[1] = -(q[0].cos() * self.l1 + q12.cos() * self.l2) - self.y0;
    }
}

/// Inverse kinematics of the arm for a tip (x, y) and tip velocity (xd, yd), elbow angle q2 > 0.
pub fn arm_ik(l1: f64, l2: f64, x: f64, y: f64, xd: f64, yd: f64) -> ([f64; 2], [f64; 2]) {
    let d2 = x * x + y * y;
    let c2 = (d2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
    let q2 = c2.clamp(-1.0, 1.0).acos();
    // Tip direction from the downward vertical: angle atan2(x, -y).
    let beta = x.atan2(-y);
    let gamma = (l2 * q2.sin()).atan2(l1 + l2 * q2.cos());
    let q1 = beta - gamma;
    // J [q1', q2'] = [xd, yd].
    let (c1, s1, c12, s12) = (q1.cos(), q1.sin(), (q1 + q2).cos(), (q1 + q2).sin());
    let j = [
        [l1 * c1 + l2 * c12, l2 * c12],
        [l1 * s1 + l2 * s12, l2 * s12],
    ];
    let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
    let w1 = (xd * j[1][1] - j[0][1] * yd) / det;
    let w2 = (j[0][0] * yd - j[1][0] * xd) / det;
    ([q1, q2], [w1, w2])
}

/// Unit links, unit masses, gravity; the tip moves along y = -1.2 from x = 0 at speed 0.4 and
/// reaches the workspace boundary (full stretch, q2 = 0) at t = 1.6 / 0.4 = 4 s; beyond it the
/// programme has no solution. t1 = 6.
pub fn arm_through_boundary() -> Problem<DoublePendulum, TipOnLine> {
    let cons = TipOnLine::new(1.0, 1.0, 0.0, -1.2, 0.4);
    let (q0, v0) = arm_ik(1.0, 1.0, cons.x0, cons.y0, cons.speed, 0.0);
    Problem {
        model: DoublePendulum {
            m1: 1.0,
            m2: 1.0,
            l1: 1.0,
            l2: 1.0,
            g: 9.81,
        },
        constraints: cons,
        t0: 0.0,
        t1: 6.0,
        q0: q0.to_vec(),
        v0: v0.to_vec(),
    }
}

/// A point mass m in space (x, y, z), gravity -g z.
#[derive(Clone, Debug)]
pub struct PointMass3 {
    pub m: f64,
    pub g: f64,
}

const XYZ: [&str; 3] = ["x", "y", "z"];

impl Model for PointMass3 {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    euclidean_names!(XYZ);
    fn mass_matrix<S: Scalar>(&self, _: &mut (), _q: &[S], a: &mut DMatrix<S>) {
        a.fill(S::zero());
        for k in 0..3 {
            a[(k, k)] = c(self.m);
        }
    }
    fn velocity_terms<S: Scalar>(&self, _: &mut (), _q: &[S], _v: &[S], g: &mut [S]) {
        g.fill(S::zero());
    }
    fn applied_forces<S: Scalar>(&self, _: &mut (), _t: S, _q: &[S], _v: &[S], f: &mut [S]) {
        f[0] = S::zero();
        f[1] = S::zero();
        f[2] = c(-self.m * self.g);
    }
}

/// Rows g1 = x - a sin(w t), g2 = x + eps z - a sin(w t): gradients (1, 0, 0) and (1, 0, eps).
/// Together they force z = 0 (g2 - g1 = eps z), so u = (-m a w^2 sin(w t), 0, m g) exactly while the
/// multipliers grow like m g / eps.
#[derive(Clone, Debug)]
pub struct NearlyRedundant {
    pub eps: f64,
    pub a: f64,
    pub w: f64,
    rows: [RowSpec; 2],
}

impl NearlyRedundant {
    /// The two rows with gradient difference `eps`.
    pub fn new(eps: f64, a: f64, w: f64) -> Self {
        NearlyRedundant {
            eps,
            a,
            w,
            rows: [
                RowSpec::new("x_law", Level::Position, Role::Programme),
                RowSpec::new("x_law_tilted", Level::Position, Role::Programme),
            ],
        }
    }
}

impl Constraints for NearlyRedundant {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    fn rows(&self) -> &[RowSpec] {
        &self.rows
    }
    fn eval<S: Scalar>(&self, _: &mut (), t: S, q: &[S], _v: &[S], _a: &[S], out: &mut [S]) {
        let law = (t * self.w).sin() * self.a;
        out[0] = q[0] - law;
        out[1] = q[0] + q[2] * self.eps - law;
    }
}

/// [`NearlyRedundant`] on a unit mass, a = 0.5, w = 2, drifting in y at 0.3; t1 = 5.
pub fn nearly_redundant(eps: f64) -> Problem<PointMass3, NearlyRedundant> {
    let cons = NearlyRedundant::new(eps, 0.5, 2.0);
    Problem {
        model: PointMass3 { m: 1.0, g: 9.81 },
        v0: vec![cons.a * cons.w, 0.3, 0.0],
        q0: vec![0.0, 0.0, 0.0],
        constraints: cons,
        t0: 0.0,
        t1: 5.0,
    }
}

/// A force law added to a model's applied forces Q (generic over the scalar, like the models).
pub trait ForceLaw: Send + Sync {
    /// Add this law's generalized forces at (t, q, v) to `f`.
    fn add<S: Scalar>(&self, t: S, q: &[S], v: &[S], f: &mut [S]);
}

/// A model with an extra force law; everything else is the inner model's.
#[derive(Clone, Debug)]
pub struct WithForce<M, L> {
    pub inner: M,
    pub law: L,
}

impl<M: Model, L: ForceLaw> Model for WithForce<M, L> {
    type Workspace<S: Scalar> = M::Workspace<S>;
    fn workspace<S: Scalar>(&self) -> M::Workspace<S> {
        self.inner.workspace()
    }
    fn nq(&self) -> usize {
        self.inner.nq()
    }
    fn nv(&self) -> usize {
        self.inner.nv()
    }
    fn segments(&self) -> &[Segment] {
        self.inner.segments()
    }
    fn q_names(&self) -> Vec<String> {
        self.inner.q_names()
    }
    fn v_names(&self) -> Vec<String> {
        self.inner.v_names()
    }
    fn mass_matrix<S: Scalar>(&self, ws: &mut M::Workspace<S>, q: &[S], a: &mut DMatrix<S>) {
        self.inner.mass_matrix(ws, q, a)
    }
    fn velocity_terms<S: Scalar>(&self, ws: &mut M::Workspace<S>, q: &[S], v: &[S], g: &mut [S]) {
        self.inner.velocity_terms(ws, q, v, g)
    }
    fn applied_forces<S: Scalar>(
        &self,
        ws: &mut M::Workspace<S>,
        t: S,
        q: &[S],
        v: &[S],
        f: &mut [S],
    ) {
        self.inner.applied_forces(ws, t, q, v, f);
        self.law.add(t, q, v, f);
    }
    fn has_mass_factor(&self) -> bool {
        self.inner.has_mass_factor()
    }
    fn mass_factor<S: Scalar>(
        &self,
        ws: &mut M::Workspace<S>,
        q: &[S],
    ) -> Result<f64, crate::linalg::Singular> {
        self.inner.mass_factor(ws, q)
    }
    fn mass_solve<S: Scalar>(&self, ws: &mut M::Workspace<S>, x: &mut [S]) {
        self.inner.mass_solve(ws, x)
    }
    fn mass_mul<S: Scalar>(&self, ws: &mut M::Workspace<S>, x: &[S], out: &mut [S]) {
        self.inner.mass_mul(ws, x, out)
    }
}

/// The joint torque -k q_j - c v_j (a stiff, damped spring at rest at 0) on a Euclidean joint.
#[derive(Clone, Debug)]
pub struct JointSpringLaw {
    pub joint: usize,
    pub k: f64,
    pub c: f64,
}

impl ForceLaw for JointSpringLaw {
    fn add<S: Scalar>(&self, _t: S, q: &[S], v: &[S], f: &mut [S]) {
        let j = self.joint;
        f[j] -= q[j] * self.k + v[j] * self.c;
    }
}

/// A model with a stiff, damped joint spring.
pub type JointSpring<M> = WithForce<M, JointSpringLaw>;

/// Double pendulum (unit links and masses) whose shoulder has a spring k = 1e6 N m/rad with damping
/// c = 2e4 N m s/rad (overdamped: modes near -k/c = -50 /s and -c/A11 ~ -4e3 /s), elbow programmed
/// q2 = 0.5 sin(2 t); t1 = 2 s. The fast mode makes DOP853 stability-limited.
pub fn stiff_shoulder() -> Problem<JointSpring<DoublePendulum>, ElbowProgramme> {
    Problem {
        model: WithForce {
            inner: DoublePendulum {
                m1: 1.0,
                m2: 1.0,
                l1: 1.0,
                l2: 1.0,
                g: 9.81,
            },
            law: JointSpringLaw {
                joint: 0,
                k: 1e6,
                c: 2e4,
            },
        },
        constraints: ElbowProgramme::new(0.5, 2.0),
        t0: 0.0,
        t1: 2.0,
        q0: vec![0.0, 0.0],
        v0: vec![0.0, 1.0],
    }
}

/// Makes the first applied force NaN for t > `t_nan` (return-code tests).
#[derive(Clone, Debug)]
pub struct NanAfterLaw {
    pub t_nan: f64,
}

impl ForceLaw for NanAfterLaw {
    fn add<S: Scalar>(&self, t: S, _q: &[S], _v: &[S], f: &mut [S]) {
        if t.re() > self.t_nan {
            f[0] = c(f64::NAN);
        }
    }
}

/// A model whose applied forces are NaN for t > `law.t_nan`.
pub type NanAfter<M> = WithForce<M, NanAfterLaw>;

/// The arm's tip programmed along a fixed ray from the pivot at angle `alpha` from the downward
/// vertical, radius rho(t) = (l1 + l2) - delta (t - tc)^2: it touches the workspace boundary (full
/// stretch, q2 = 0, B of rank 1) at t = tc with zero radial velocity and comes back. The programme has
/// smooth solutions through tc (the elbow flips sign, q2 ~ (t - tc)) and non-smooth ones (it bounces):
/// the continuation past the dead point is not unique.
#[derive(Clone, Debug)]
pub struct TipOnRay {
    pub l1: f64,
    pub l2: f64,
    pub alpha: f64,
    pub delta: f64,
    pub tc: f64,
    rows: [RowSpec; 2],
}

impl TipOnRay {
    /// Ray at `alpha`, touching full stretch at `tc`.
    pub fn new(l1: f64, l2: f64, alpha: f64, delta: f64, tc: f64) -> Self {
        TipOnRay {
            l1,
            l2,
            alpha,
            delta,
            tc,
            rows: [
                RowSpec::new("tip_x", Level::Position, Role::Programme),
                RowSpec::new("tip_y", Level::Position, Role::Programme),
            ],
        }
    }

    /// rho and rho' at t.
    pub fn rho(&self, t: f64) -> (f64, f64) {
        let s = t - self.tc;
        (
            self.l1 + self.l2 - self.delta * s * s,
            -2.0 * self.delta * s,
        )
    }
}

impl Constraints for TipOnRay {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) {}
    fn rows(&self) -> &[RowSpec] {
        &self.rows
    }
    fn eval<S: Scalar>(&self, _: &mut (), t: S, q: &[S], _v: &[S], _a: &[S], out: &mut [S]) {
        let q12 = q[0] + q[1];
        let s = t - self.tc;
        let rho = -(s * s) * self.delta + (self.l1 + self.l2);
        out[0] = q[0].sin() * self.l1 + q12.sin() * self.l2 - rho * self.alpha.sin();
        out[1] = -(q[0].cos() * self.l1 + q12.cos() * self.l2) + rho * self.alpha.cos();
    }
}

/// Unit links and masses, gravity; ray at alpha = 0.6, delta = 0.1, full stretch at tc = 1.5 s;
/// t1 = 3 s.
pub fn arm_touching_boundary() -> Problem<DoublePendulum, TipOnRay> {
    let cons = TipOnRay::new(1.0, 1.0, 0.6, 0.1, 1.5);
    let (rho, rhod) = cons.rho(0.0);
    let (sa, ca) = cons.alpha.sin_cos();
    let (q0, v0) = arm_ik(1.0, 1.0, rho * sa, -rho * ca, rhod * sa, -rhod * ca);
    Problem {
        model: DoublePendulum {
            m1: 1.0,
            m2: 1.0,
            l1: 1.0,
            l2: 1.0,
            g: 9.81,
        },
        constraints: cons,
        t0: 0.0,
        t1: 3.0,
        q0: q0.to_vec(),
        v0: v0.to_vec(),
    }
}

/// Double pendulum with the elbow programmed at period 0.01 s (q2 = 0.2 sin(200 pi t)) for 100 s =
/// 10^4 periods: the long-horizon drift case (tests/hard_cases.rs case 6, benches/core.rs `drift`).
pub fn ten_thousand_periods() -> Problem<DoublePendulum, ElbowProgramme> {
    let mut p = crate::problems::pendulum::double_pendulum();
    let w = 200.0 * std::f64::consts::PI;
    p.constraints = ElbowProgramme::new(0.2, w);
    p.q0 = vec![0.3, 0.0];
    p.v0 = vec![0.0, 0.2 * w];
    p.t1 = 100.0;
    p
}

/// Extra CPU of projection over [`ten_thousand_periods`]: the runs with projection (tol 1e-12) and
/// without (DOP853, rtol 1e-8, atol 1e-10, outputs discarded) alternate `rounds` times and the
/// minimum wall time of each is kept (the run least disturbed by other load on a shared machine).
/// Used by `examples/drift_cost.rs` and `progmo bench --only drift`.
pub fn measure_drift_cost(rounds: usize) -> DriftCost {
    use crate::solve::{solve_into, DriftControl, Sample, SampleSink, Settings};
    struct Discard;
    impl SampleSink for Discard {
        fn sample(&mut self, _: &Sample<'_>) {}
    }
    let p = ten_thousand_periods();
    let settings = |d| Settings {
        rtol: 1e-8,
        atol: 1e-10,
        drift: d,
        ..Settings::default()
    };
    let on = settings(DriftControl::Projection {
        tol: 1e-12,
        max_iter: 8,
    });
    let off = settings(DriftControl::None);
    let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let mut out = DriftCost {
        rounds: rounds.max(1),
        projection_s: f64::INFINITY,
        none_s: f64::INFINITY,
        residual_projection: 0.0,
        residual_none: 0.0,
        steps: 0,
    };
    for _ in 0..out.rounds {
        let t = std::time::Instant::now();
        let a = solve_into(&p, &on, &mut Discard);
        out.projection_s = out.projection_s.min(t.elapsed().as_secs_f64());
        let t = std::time::Instant::now();
        let b = solve_into(&p, &off, &mut Discard);
        out.none_s = out.none_s.min(t.elapsed().as_secs_f64());
        out.residual_projection = max(&a.max_residual);
        out.residual_none = max(&b.max_residual);
        out.steps = a.stats.integrator.steps;
    }
    out
}

/// Result of [`measure_drift_cost`].
#[derive(Clone, Debug, PartialEq)]
pub struct DriftCost {
    /// Alternating rounds measured.
    pub rounds: usize,
    /// Minimum wall time with projection (s).
    pub projection_s: f64,
    /// Minimum wall time without drift control (s).
    pub none_s: f64,
    /// Largest programme residual over the run with projection.
    pub residual_projection: f64,
    /// The same without drift control.
    pub residual_none: f64,
    /// Accepted steps of the run with projection.
    pub steps: usize,
}
