//! Charts of the configuration space for integrators: `q ⊕ δ` and `q1 ⊖ q0` with `δ` in velocity
//! coordinates (the exponential map of each joint). Smooth at `δ = 0` for dual numbers (series
//! branches), so exact Jacobians of a local chart are available.

use super::kinematics::ensure_vec;
use super::model::{JointKind, Model};
use super::spatial::quat_mul;
use crate::scalar::{c, Scalar};
use nalgebra::DVector;

/// `exp((0, δ/2))`: quaternion (w, x, y, z) of the rotation by the rotation vector `δ`.
pub fn quat_exp<S: Scalar>(d: &[S]) -> [S; 4] {
    let x2 = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) * c::<S>(0.25);
    let (w, s) = if x2.re() < 1e-4 {
        // cos x and sin(x)/x as series in x², truncation error < 1e-20
        let cw =
            c::<S>(1.0) - x2 * (c::<S>(0.5) - x2 * (c::<S>(1.0 / 24.0) - x2 * c::<S>(1.0 / 720.0)));
        let sc = c::<S>(1.0)
            - x2 * (c::<S>(1.0 / 6.0) - x2 * (c::<S>(1.0 / 120.0) - x2 * c::<S>(1.0 / 5040.0)));
        (cw, sc)
    } else {
        let x = x2.sqrt();
        (x.cos(), x.sin() / x)
    };
    let h = s * c::<S>(0.5);
    [w, d[0] * h, d[1] * h, d[2] * h]
}

/// Rotation vector `δ` with `exp(δ) = q / |q|`, taking the shorter way (`w >= 0`); `q` need not be
/// unit.
pub fn quat_log<S: Scalar>(q: &[S; 4]) -> [S; 3] {
    let sign = if q[0].re() < 0.0 {
        c::<S>(-1.0)
    } else {
        c::<S>(1.0)
    };
    let (w, u) = (q[0] * sign, [q[1] * sign, q[2] * sign, q[3] * sign]);
    let s2 = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
    let f = if w.re() > 0.0 && (s2 / (w * w)).re() < 1e-4 {
        // 2 atan(t)/(t w) with t = s/w as a series in t², truncation error < 1e-20
        let t2 = s2 / (w * w);
        let at = c::<S>(1.0)
            - t2 * (c::<S>(1.0 / 3.0)
                - t2 * (c::<S>(0.2) - t2 * (c::<S>(1.0 / 7.0) - t2 * c::<S>(1.0 / 9.0))));
        at * c::<S>(2.0) / w
    } else {
        let s = s2.sqrt();
        s.atan2(w) * c::<S>(2.0) / s
    };
    [u[0] * f, u[1] * f, u[2] * f]
}

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
