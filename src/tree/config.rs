//! Charts of the configuration space for integrators: `q ⊕ δ` and `q1 ⊖ q0` with `δ` in velocity
//! coordinates (the exponential map of each joint). Smooth at `δ = 0` for dual numbers (series
//! branches), so exact Jacobians of a local chart are available.

use super::kinematics::ensure_vec;
use super::model::{JointKind, Model};
use crate::lie::quat_mul;
pub use crate::lie::{quat_exp, quat_log};
use crate::scalar::Scalar;
use nalgebra::DVector;

/// `out = q ⊕ δ`: hinge/slide `q + δ`; ball `quat ⊗ exp(δ)` (δ a body-frame rotation vector); free
/// `p + δ_lin` (world frame), `quat ⊗ exp(δ_ang)`. `d/dε (q ⊕ ε v)` at 0 equals [`super::qdot`].
pub fn integrate_configuration<S: Scalar>(
    model: &Model,
    q: &[S],
    delta: &[S],
    out: &mut DVector<S>,
) {
    assert!(
        q.len() == model.nq() && delta.len() == model.nv(),
        "tree: q or delta has the wrong length"
    );
    ensure_vec(out, model.nq());
    for jt in model.joints() {
        let (iq, iv) = (jt.iq, jt.iv);
        let rot = |iq: usize, iv: usize, out: &mut DVector<S>| {
            let e = quat_exp(&delta[iv..iv + 3]);
            let r = quat_mul(&[q[iq], q[iq + 1], q[iq + 2], q[iq + 3]], &e);
            for k in 0..4 {
                out[iq + k] = r[k];
            }
        };
        match jt.kind {
            JointKind::Hinge(_) | JointKind::Slide(_) => out[iq] = q[iq] + delta[iv],
            JointKind::Ball => rot(iq, iv, out),
            JointKind::Free => {
                for k in 0..3 {
                    out[iq + k] = q[iq + k] + delta[iv + k];
                }
                rot(iq + 3, iv + 3, out);
            }
        }
    }
}

/// `out = q1 ⊖ q0`, the δ with `q0 ⊕ δ = q1` (up to quaternion scale and sign).
pub fn difference_configuration<S: Scalar>(
    model: &Model,
    q0: &[S],
    q1: &[S],
    out: &mut DVector<S>,
) {
    assert!(
        q0.len() == model.nq() && q1.len() == model.nq(),
        "tree: q has the wrong length"
    );
    ensure_vec(out, model.nv());
    for jt in model.joints() {
        let (iq, iv) = (jt.iq, jt.iv);
        let rot = |iq: usize, iv: usize, out: &mut DVector<S>| {
            let conj = [q0[iq], -q0[iq + 1], -q0[iq + 2], -q0[iq + 3]];
            let r = quat_mul(&conj, &[q1[iq], q1[iq + 1], q1[iq + 2], q1[iq + 3]]);
            let l = quat_log(&r);
            for k in 0..3 {
                out[iv + k] = l[k];
            }
        };
        match jt.kind {
            JointKind::Hinge(_) | JointKind::Slide(_) => out[iv] = q1[iq] - q0[iq],
            JointKind::Ball => rot(iq, iv, out),
            JointKind::Free => {
                for k in 0..3 {
                    out[iv + k] = q1[iq + k] - q0[iq + k];
                }
                rot(iq + 3, iv + 3, out);
            }
        }
    }
}
