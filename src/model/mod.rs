//! The mechanical system: configuration space, mass matrix, velocity terms and applied forces.
//!
//! Equations of motion of the natural (uncontrolled) system, paper eq. (2.2) and, in
//! quasi-velocities, (3.4):
//!
//! ```text
//!     A(q) dv/dt - G(q, v) = Q(t, q, v)
//! ```
//!
//! v are generalized velocities (v = dq/dt) on Euclidean coordinates and body-frame angular
//! velocities (quasi-velocities, Section 3) on unit-quaternion coordinates; A is then the paper's
//! A0 (3.5) and G already contains the -A (dC*/dt) omega term of (3.4) (see the errata in
//! `../shared/seed/NOTES.md`). Implementors are immutable; scratch space lives in a
//! [`Model::Workspace`] so evaluation allocates nothing.

pub use crate::lie;

use crate::scalar::Scalar;
use nalgebra::DMatrix;

/// A block of the configuration vector and its velocity block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Segment {
    /// `len` Euclidean coordinates q[q..q+len] with velocities v[v..v+len] = dq/dt.
    Euclidean { q: usize, v: usize, len: usize },
    /// A unit quaternion (w, x, y, z) in q[q..q+4] whose body-frame angular velocity is v[v..v+3]:
    /// dq/dt = 1/2 q (x) (0, omega).
    Quaternion { q: usize, v: usize },
}

/// A mechanical system as the solver sees it.
pub trait Model: Send + Sync {
    /// Scratch space for evaluations over scalar type `S`.
    type Workspace<S: Scalar>: Send + 'static;

    /// Allocate a workspace for scalar type `S`.
    fn workspace<S: Scalar>(&self) -> Self::Workspace<S>;

    /// Number of configuration coordinates.
    fn nq(&self) -> usize;

    /// Number of velocities (degrees of freedom).
    fn nv(&self) -> usize;

    /// The configuration space as blocks, covering q and v in order.
    fn segments(&self) -> &[Segment];

    /// Names of the configuration coordinates (`nq` of them).
    fn q_names(&self) -> Vec<String>;

    /// Names of the velocities (`nv` of them); forces u and reactions use the same names.
    fn v_names(&self) -> Vec<String>;

    /// The mass matrix A(q) (2.1), `nv x nv`, symmetric positive definite.
    fn mass_matrix<S: Scalar>(&self, ws: &mut Self::Workspace<S>, q: &[S], a: &mut DMatrix<S>);

    /// The velocity terms G(q, v) of (2.2), with the sign convention A dv/dt - G = Q.
    fn velocity_terms<S: Scalar>(&self, ws: &mut Self::Workspace<S>, q: &[S], v: &[S], g: &mut [S]);

    /// The applied generalized forces Q(t, q, v) of (2.2) (fields, springs, dampers, given forces).
    fn applied_forces<S: Scalar>(
        &self,
        ws: &mut Self::Workspace<S>,
        t: S,
        q: &[S],
        v: &[S],
        f: &mut [S],
    );

    /// F = G + Q (2.2), the total natural force the formulations take. The default sums
    /// [`Model::velocity_terms`] and [`Model::applied_forces`] (`scratch` has nv entries); models
    /// that get both from one pass (one inverse-dynamics sweep for Coriolis and gravity) override it.
    fn natural_forces<S: Scalar>(
        &self,
        ws: &mut Self::Workspace<S>,
        t: S,
        q: &[S],
        v: &[S],
        f: &mut [S],
        scratch: &mut [S],
    ) {
        self.velocity_terms(ws, q, v, f);
        self.applied_forces(ws, t, q, v, scratch);
        for (x, &y) in f.iter_mut().zip(scratch.iter()) {
            *x += y;
        }
    }

    /// The kinematic tree and the workspace's forward passes, lent to constraints on the same tree
    /// (body-point signals) so that one sweep per state serves the mass matrix, the forces and the
    /// constraint jet. `None` (the default) for models that are not trees. The passes are valid
    /// only where their cache says so ([`crate::tree::forward_kinematics`] checks q itself).
    fn tree_sweep<'w, S: Scalar>(
        &'w self,
        _ws: &'w mut Self::Workspace<S>,
    ) -> Option<crate::tree::TreeSweep<'w, S>> {
        None
    }

    /// Whether [`Model::mass_factor`], [`Model::mass_solve`] and [`Model::mass_mul`] work in O(n)
    /// without forming A (kinematic trees: the articulated-body factorization). Default false: the
    /// articulated-body formulation then factors the dense A (Cholesky) instead, and `auto` never
    /// picks it.
    fn has_mass_factor(&self) -> bool {
        false
    }

    /// Factor A(q) for [`Model::mass_solve`] and [`Model::mass_mul`]; returns a reciprocal condition
    /// estimate (pivot ratio) or the pivot at which A is not positive definite. Called only when
    /// [`Model::has_mass_factor`] is true.
    fn mass_factor<S: Scalar>(
        &self,
        _ws: &mut Self::Workspace<S>,
        _q: &[S],
    ) -> Result<f64, crate::linalg::Singular> {
        unreachable!("mass_factor on a model without has_mass_factor")
    }

    /// `x <- A(q)^-1 x` with the last [`Model::mass_factor`].
    fn mass_solve<S: Scalar>(&self, _ws: &mut Self::Workspace<S>, _x: &mut [S]) {
        unreachable!("mass_solve on a model without has_mass_factor")
    }

    /// `x <- A(q)^-1 x` for `cols` right-hand sides (x column-major, `nv x cols`).
    fn mass_solve_block<S: Scalar>(&self, ws: &mut Self::Workspace<S>, x: &mut [S], cols: usize) {
        let n = x.len() / cols.max(1);
        for col in x.chunks_mut(n.max(1)).take(cols) {
            self.mass_solve(ws, col);
        }
    }

    /// `out = A(q) x` at the q of the last [`Model::mass_factor`].
    fn mass_mul<S: Scalar>(&self, _ws: &mut Self::Workspace<S>, _x: &[S], _out: &mut [S]) {
        unreachable!("mass_mul on a model without has_mass_factor")
    }
}

/// dq/dt = N(q) v for the given segments.
pub fn qdot<S: Scalar>(segments: &[Segment], q: &[S], v: &[S], out: &mut [S]) {
    for seg in segments {
        match *seg {
            Segment::Euclidean { q: iq, v: iv, len } => {
                out[iq..iq + len].copy_from_slice(&v[iv..iv + len]);
            }
            Segment::Quaternion { q: iq, v: iv } => {
                let d = lie::quat_rate(&q[iq..iq + 4], &v[iv..iv + 3]);
                out[iq..iq + 4].copy_from_slice(&d);
            }
        }
    }
}

/// q = base (+) delta: Euclidean blocks add, quaternion blocks right-multiply by Exp(delta)
/// (body-frame increment, consistent with body-frame angular velocity).
pub fn retract<S: Scalar>(segments: &[Segment], base: &[f64], delta: &[S], out: &mut [S]) {
    for seg in segments {
        match *seg {
            Segment::Euclidean { q: iq, v: iv, len } => {
                for k in 0..len {
                    out[iq + k] = delta[iv + k] + base[iq + k];
                }
            }
            Segment::Quaternion { q: iq, v: iv } => {
                let e = lie::quat_exp(&delta[iv..iv + 3]);
                let b: [S; 4] = std::array::from_fn(|k| S::from(base[iq + k]));
                out[iq..iq + 4].copy_from_slice(&lie::quat_mul(&b, &e));
            }
        }
    }
}

/// Time derivative of the chart coordinates delta given the velocity v at base (+) delta:
/// Euclidean blocks d(delta)/dt = v, quaternion blocks d(delta)/dt = dexp^-1(delta) omega (RKMK).
pub fn chart_rate<S: Scalar>(segments: &[Segment], delta: &[S], v: &[S], out: &mut [S]) {
    for seg in segments {
        match *seg {
            Segment::Euclidean { v: iv, len, .. } => {
                out[iv..iv + len].copy_from_slice(&v[iv..iv + len]);
            }
            Segment::Quaternion { v: iv, .. } => {
                let r = lie::dexp_inv(&delta[iv..iv + 3], &v[iv..iv + 3]);
                out[iv..iv + 3].copy_from_slice(&r);
            }
        }
    }
}

/// Renormalize the quaternion blocks of q.
pub fn normalize(segments: &[Segment], q: &mut [f64]) {
    for seg in segments {
        if let Segment::Quaternion { q: iq, .. } = *seg {
            let n = q[iq..iq + 4].iter().map(|x| x * x).sum::<f64>().sqrt();
            for x in &mut q[iq..iq + 4] {
                *x /= n;
            }
        }
    }
}

/// Largest chart coordinate magnitude on quaternion blocks (rotation angle since the chart centre).
pub fn chart_angle(segments: &[Segment], delta: &[f64]) -> f64 {
    let mut m: f64 = 0.0;
    for seg in segments {
        if let Segment::Quaternion { v: iv, .. } = *seg {
            let a = delta[iv..iv + 3].iter().map(|x| x * x).sum::<f64>().sqrt();
            m = m.max(a);
        }
    }
    m
}
