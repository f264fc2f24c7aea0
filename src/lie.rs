//! Unit quaternions (w, x, y, z) and the exponential chart of SO(3), generic over the scalar.
//!
//! Conventions: q (x) p is the Hamilton product; a body-frame angular velocity omega gives
//! dq/dt = 1/2 q (x) (0, omega); q(t) = q0 (x) Exp(delta) with Exp(delta) = (cos |delta|/2,
//! sin(|delta|/2) delta/|delta|). Then omega = J_r(delta) d(delta)/dt, and the RKMK chart equation is
//! d(delta)/dt = J_r^-1(delta) omega with
//! J_r^-1 = I + 1/2 [delta]x + (1/|delta|^2 - (1 + cos|delta|) / (2 |delta| sin|delta|)) [delta]x^2
//! (Iserles, Munthe-Kaas, Norsett, Zanna, *Lie-group methods*, Acta Numerica 2000, sec. 4).
//! Near delta = 0 the coefficients are taken from their Taylor series so dual parts stay finite.

use crate::scalar::{c, re, Scalar};

/// Hamilton product a (x) b.
pub fn quat_mul<S: Scalar>(a: &[S; 4], b: &[S; 4]) -> [S; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// dq/dt = 1/2 q (x) (0, omega) for a body-frame angular velocity omega.
pub fn quat_rate<S: Scalar>(q: &[S], w: &[S]) -> [S; 4] {
    let h = c::<S>(0.5);
    [
        -(q[1] * w[0] + q[2] * w[1] + q[3] * w[2]) * h,
        (q[0] * w[0] + q[2] * w[2] - q[3] * w[1]) * h,
        (q[0] * w[1] - q[1] * w[2] + q[3] * w[0]) * h,
        (q[0] * w[2] + q[1] * w[1] - q[2] * w[0]) * h,
    ]
}

/// Exp(delta) as a unit quaternion: the rotation by the rotation vector delta. The series branch
/// reaches |delta| = 0.02 so that dual parts (whose direct formula cancels like 1/|delta|^2) stay
/// accurate to about 1e-12 just above it; its truncation error is below 1e-20.
pub fn quat_exp<S: Scalar>(d: &[S]) -> [S; 4] {
    let x2 = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) * c::<S>(0.25);
    let (w, s) = if re(x2) < 1e-4 {
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
    let sign = if re(q[0]) < 0.0 {
        c::<S>(-1.0)
    } else {
        c::<S>(1.0)
    };
    let (w, u) = (q[0] * sign, [q[1] * sign, q[2] * sign, q[3] * sign]);
    let s2 = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
    let f = if re(w) > 0.0 && re(s2 / (w * w)) < 1e-4 {
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

/// d(delta)/dt = J_r^-1(delta) omega.
pub fn dexp_inv<S: Scalar>(d: &[S], w: &[S]) -> [S; 3] {
    let th2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    let k = if re(th2) < 1e-6 {
        // 1/th^2 - (1 + cos th)/(2 th sin th) = 1/12 + th^2/720 + th^4/30240 + ...
        c::<S>(1.0 / 12.0) + th2 / 720.0 + th2 * th2 / 30240.0
    } else {
        let th = th2.sqrt();
        th2.recip() - (c::<S>(1.0) + th.cos()) / (th * th.sin() * 2.0)
    };
    let dxw = cross(d, w);
    let dxdxw = cross(d, &dxw);
    [
        w[0] + dxw[0] * 0.5 + dxdxw[0] * k,
        w[1] + dxw[1] * 0.5 + dxdxw[1] * k,
        w[2] + dxw[2] * 0.5 + dxdxw[2] * k,
    ]
}

/// Cross product a x b.
pub fn cross<S: Scalar>(a: &[S], b: &[S]) -> [S; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// R^T x for the rotation R of unit quaternion q: a world vector expressed in the body frame.
pub fn rotate_inv<S: Scalar>(q: &[S], x: &[S; 3]) -> [S; 3] {
    let conj = [q[0], -q[1], -q[2], -q[3]];
    rotate(&conj, x)
}

/// R x for the rotation R of unit quaternion q: a body vector expressed in the world frame.
pub fn rotate<S: Scalar>(q: &[S], x: &[S; 3]) -> [S; 3] {
    let qv = [q[1], q[2], q[3]];
    // x + 2 w (v x x) + 2 v x (v x x)
    let t = cross(&qv, x);
    let t2 = [t[0] * 2.0, t[1] * 2.0, t[2] * 2.0];
    let u = cross(&qv, &t2);
    [
        x[0] + q[0] * t2[0] + u[0],
        x[1] + q[0] * t2[1] + u[1],
        x[2] + q[0] * t2[2] + u[2],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_dual::Dual64;

    #[test]
    fn exp_is_unit_and_matches_rotation() {
        let d = [0.3, -0.2, 0.5];
        let e = quat_exp(&d);
        let n: f64 = e.iter().map(|x| x * x).sum();
        assert!((n - 1.0).abs() < 4.0 * f64::EPSILON);
        // Rotation about delta leaves delta fixed.
        let r = rotate(&e, &d);
        for k in 0..3 {
            assert!((r[k] - d[k]).abs() < 8.0 * f64::EPSILON);
        }
    }

    #[test]
    fn dexp_inv_inverts_the_derivative_of_exp() {
        // d/ds Exp(delta + s x) = 1/2 Exp(delta) (x) (0, J_r x)  =>  J_r^-1 J_r x = x.
        for d in [[0.3, -0.2, 0.5], [1e-5, 2e-5, -1e-5], [2.0, 0.5, -1.0]] {
            let x = [0.7, 0.1, -0.4];
            let dd: [Dual64; 3] = std::array::from_fn(|k| Dual64::new(d[k], x[k]));
            let e = quat_exp(&dd);
            let q: [f64; 4] = std::array::from_fn(|k| e[k].re);
            let qd: [f64; 4] = std::array::from_fn(|k| e[k].eps);
            // omega = 2 q^* (x) dq/dt
            let conj = [q[0], -q[1], -q[2], -q[3]];
            let om = quat_mul(&conj, &qd);
            let w = [2.0 * om[1], 2.0 * om[2], 2.0 * om[3]];
            let back = dexp_inv(&d, &w);
            for k in 0..3 {
                assert!((back[k] - x[k]).abs() < 1e-13, "{d:?}: {back:?}");
            }
        }
    }
}
