//! Minimal spatial (6D) algebra, generic over [`Scalar`] (no `RealField` needed).
//!
//! Notation follows Featherstone, *Rigid Body Dynamics Algorithms* (2008), ch. 2:
//! a motion vector is `(angular, linear)` = (ω, v_O) with v_O the velocity of the body point at the
//! frame origin O; a force vector is `(moment about O, force)`. A transform `^B X_A` is stored as
//! `(E, r)` (Featherstone Table 2.5): `E` rotates A coordinates into B coordinates and
//! `r` is the position of B's origin in A coordinates.

use crate::scalar::{c, Scalar};
use nalgebra::{Matrix3, Vector3};

/// Skew-symmetric matrix `[a]x` with `[a]x b = a x b`.
#[inline]
pub fn skew<S: Scalar>(a: &Vector3<S>) -> Matrix3<S> {
    let z = c::<S>(0.0);
    Matrix3::new(z, -a[2], a[1], a[2], z, -a[0], -a[1], a[0], z)
}

/// Cross product `a x b`.
#[inline]
pub fn cross<S: Scalar>(a: &Vector3<S>, b: &Vector3<S>) -> Vector3<S> {
    Vector3::new(
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    )
}

/// `a x` for a 3 x 3 `a`. The products with nalgebra's `*` scale every term by alpha = 1 and the
/// sum by beta = 1 (its gemv: y = alpha a_k x_k + beta y), free on f64 but full multiplications on
/// dual numbers (a fifth of the servo right-hand side's time went there). The sums here run over
/// k = 0, 1, 2 as nalgebra's do: the same bits on f64.
#[inline(always)]
pub fn mv<S: Scalar>(a: &Matrix3<S>, x: &Vector3<S>) -> Vector3<S> {
    Vector3::new(
        a[(0, 0)] * x[0] + a[(0, 1)] * x[1] + a[(0, 2)] * x[2],
        a[(1, 0)] * x[0] + a[(1, 1)] * x[1] + a[(1, 2)] * x[2],
        a[(2, 0)] * x[0] + a[(2, 1)] * x[1] + a[(2, 2)] * x[2],
    )
}

/// `a^T x` for a 3 x 3 `a` (as [`mv`] on the transpose).
#[inline(always)]
pub fn mtv<S: Scalar>(a: &Matrix3<S>, x: &Vector3<S>) -> Vector3<S> {
    Vector3::new(
        a[(0, 0)] * x[0] + a[(1, 0)] * x[1] + a[(2, 0)] * x[2],
        a[(0, 1)] * x[0] + a[(1, 1)] * x[1] + a[(2, 1)] * x[2],
        a[(0, 2)] * x[0] + a[(1, 2)] * x[1] + a[(2, 2)] * x[2],
    )
}

/// `a b` for 3 x 3 matrices, column by column as [`mv`].
#[inline(always)]
pub fn mm<S: Scalar>(a: &Matrix3<S>, b: &Matrix3<S>) -> Matrix3<S> {
    let c0 = mv(a, &b.column(0).into_owned());
    let c1 = mv(a, &b.column(1).into_owned());
    let c2 = mv(a, &b.column(2).into_owned());
    Matrix3::from_columns(&[c0, c1, c2])
}

/// Lift an `f64` vector into `S`.
#[inline]
pub fn lift3<S: Scalar>(a: &Vector3<f64>) -> Vector3<S> {
    Vector3::new(c(a[0]), c(a[1]), c(a[2]))
}

/// Lift an `f64` matrix into `S`.
#[inline]
pub fn lift33<S: Scalar>(a: &Matrix3<f64>) -> Matrix3<S> {
    a.map(|x| c::<S>(x))
}

/// Rotation about the unit axis `u` by angle `theta` (Rodrigues):
/// `R = 1 + sin(theta) [u]x + (1 - cos(theta)) [u]x^2`. Maps rotated-frame to original-frame coordinates.
pub fn rot_axis_angle<S: Scalar>(u: &Vector3<f64>, theta: S) -> Matrix3<S> {
    let k = skew(&lift3::<S>(u));
    let k2 = mm(&k, &k);
    Matrix3::identity() + k * theta.sin() + k2 * (c::<S>(1.0) - theta.cos())
}

/// Rotation matrix of the quaternion `(w, x, y, z)`, normalised implicitly:
/// `R = 1 + 2/|q|^2 (w [u]x + [u]x^2)` with `u = (x, y, z)`; exact for any nonzero `q` and smooth,
/// so derivatives along `q` are those of `q/|q|` (as MuJoCo, which normalises quaternions).
/// Maps the rotated (child) frame's coordinates to the reference (parent) frame's.
pub fn rot_quat<S: Scalar>(w: S, x: S, y: S, z: S) -> Matrix3<S> {
    let n2 = w * w + x * x + y * y + z * z;
    let s = c::<S>(2.0) / n2;
    let k = skew(&Vector3::new(x, y, z));
    Matrix3::identity() + (k * w + mm(&k, &k)) * s
}

/// Unit quaternion `(w, x, y, z)` with `w >= 0` of a rotation matrix (Shepperd's method: the
/// largest of the four squared components is taken through a square root, the others by division).
pub fn quat_from_rot<S: Scalar>(r: &Matrix3<S>) -> [S; 4] {
    let one = c::<S>(1.0);
    let quarter = c::<S>(0.25);
    let tr = r[(0, 0)] + r[(1, 1)] + r[(2, 2)];
    let cand = [tr.re(), r[(0, 0)].re(), r[(1, 1)].re(), r[(2, 2)].re()];
    let mut k = 0;
    for i in 1..4 {
        if cand[i] > cand[k] {
            k = i;
        }
    }
    let mut q = match k {
        0 => {
            let s = (one + tr).sqrt() * c::<S>(2.0); // s = 4w
            [
                quarter * s,
                (r[(2, 1)] - r[(1, 2)]) / s,
                (r[(0, 2)] - r[(2, 0)]) / s,
                (r[(1, 0)] - r[(0, 1)]) / s,
            ]
        }
        1 => {
            let s = (one + r[(0, 0)] - r[(1, 1)] - r[(2, 2)]).sqrt() * c::<S>(2.0); // 4x
            [
                (r[(2, 1)] - r[(1, 2)]) / s,
                quarter * s,
                (r[(0, 1)] + r[(1, 0)]) / s,
                (r[(0, 2)] + r[(2, 0)]) / s,
            ]
        }
        2 => {
            let s = (one + r[(1, 1)] - r[(0, 0)] - r[(2, 2)]).sqrt() * c::<S>(2.0); // 4y
            [
                (r[(0, 2)] - r[(2, 0)]) / s,
                (r[(0, 1)] + r[(1, 0)]) / s,
                quarter * s,
                (r[(1, 2)] + r[(2, 1)]) / s,
            ]
        }
        _ => {
            let s = (one + r[(2, 2)] - r[(0, 0)] - r[(1, 1)]).sqrt() * c::<S>(2.0); // 4z
            [
                (r[(1, 0)] - r[(0, 1)]) / s,
                (r[(0, 2)] + r[(2, 0)]) / s,
                (r[(1, 2)] + r[(2, 1)]) / s,
                quarter * s,
            ]
        }
    };
    if q[0].re() < 0.0 {
        for x in q.iter_mut() {
            *x = -*x;
        }
    }
    q
}

/// Spatial motion vector (ω, v_O) (Featherstone ch. 2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion<S: Scalar> {
    pub ang: Vector3<S>,
    pub lin: Vector3<S>,
}

/// Spatial force vector (n_O, f) (Featherstone ch. 2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Force<S: Scalar> {
    pub ang: Vector3<S>,
    pub lin: Vector3<S>,
}

impl<S: Scalar> Motion<S> {
    pub fn zero() -> Self {
        Motion {
            ang: Vector3::zeros(),
            lin: Vector3::zeros(),
        }
    }
    pub fn new(ang: Vector3<S>, lin: Vector3<S>) -> Self {
        Motion { ang, lin }
    }
    pub fn add(&self, o: &Motion<S>) -> Motion<S> {
        Motion {
            ang: self.ang + o.ang,
            lin: self.lin + o.lin,
        }
    }
    pub fn scale(&self, s: S) -> Motion<S> {
        Motion {
            ang: self.ang * s,
            lin: self.lin * s,
        }
    }
    /// Motion cross product `self x m` (Featherstone ch. 2, `crm`).
    pub fn cross_motion(&self, m: &Motion<S>) -> Motion<S> {
        Motion {
            ang: cross(&self.ang, &m.ang),
            lin: cross(&self.ang, &m.lin) + cross(&self.lin, &m.ang),
        }
    }
    /// Force cross product `self x* f` (Featherstone ch. 2, `crf`).
    pub fn cross_force(&self, f: &Force<S>) -> Force<S> {
        Force {
            ang: cross(&self.ang, &f.ang) + cross(&self.lin, &f.lin),
            lin: cross(&self.ang, &f.lin),
        }
    }
    /// Scalar product `m . f` (power).
    pub fn dot(&self, f: &Force<S>) -> S {
        self.ang.dot(&f.ang) + self.lin.dot(&f.lin)
    }
}

impl<S: Scalar> Force<S> {
    pub fn zero() -> Self {
        Force {
            ang: Vector3::zeros(),
            lin: Vector3::zeros(),
        }
    }
    pub fn add(&self, o: &Force<S>) -> Force<S> {
        Force {
            ang: self.ang + o.ang,
            lin: self.lin + o.lin,
        }
    }
}

/// Plücker transform `^B X_A` stored as `(E, r)` (Featherstone Table 2.5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Xform<S: Scalar> {
    /// Rotation from A coordinates to B coordinates.
    pub e: Matrix3<S>,
    /// Origin of B in A coordinates.
    pub r: Vector3<S>,
}

impl<S: Scalar> Xform<S> {
    pub fn identity() -> Self {
        Xform {
            e: Matrix3::identity(),
            r: Vector3::zeros(),
        }
    }
    /// From a pose of frame B in frame A: `x_A = R x_B + p`, i.e. `E = R^T`, `r = p`.
    pub fn from_pose(rot: Matrix3<S>, pos: Vector3<S>) -> Self {
        Xform {
            e: rot.transpose(),
            r: pos,
        }
    }
    pub fn lift(x: &Xform<f64>) -> Self {
        Xform {
            e: lift33(&x.e),
            r: lift3(&x.r),
        }
    }
    /// `^B X_A m` = `(E ω, E (v - r x ω))`.
    pub fn apply_motion(&self, m: &Motion<S>) -> Motion<S> {
        Motion {
            ang: mv(&self.e, &m.ang),
            lin: mv(&self.e, &(m.lin - cross(&self.r, &m.ang))),
        }
    }
    /// `^A X_B m` (inverse) = `(E^T ω, E^T v + r x E^T ω)`.
    pub fn inv_apply_motion(&self, m: &Motion<S>) -> Motion<S> {
        let w = mtv(&self.e, &m.ang);
        Motion {
            lin: mtv(&self.e, &m.lin) + cross(&self.r, &w),
            ang: w,
        }
    }
    /// `(^B X_A)^T f = ^A X_B^* f` (force from B to A) = `(E^T n + r x E^T f, E^T f)`.
    pub fn transpose_force(&self, f: &Force<S>) -> Force<S> {
        let lin = mtv(&self.e, &f.lin);
        Force {
            ang: mtv(&self.e, &f.ang) + cross(&self.r, &lin),
            lin,
        }
    }
    /// Composition `^C X_A = self * other` with `self = ^C X_B`, `other = ^B X_A`.
    pub fn compose(&self, other: &Xform<S>) -> Xform<S> {
        Xform {
            e: mm(&self.e, &other.e),
            r: other.r + mtv(&other.e, &self.r),
        }
    }
}

/// Rigid-body spatial inertia about a frame origin: mass `m`, first moment `h = m c`, rotational
/// inertia `ibar` about the origin (Featherstone ch. 2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inertia<S: Scalar> {
    pub m: S,
    pub h: Vector3<S>,
    pub ibar: Matrix3<S>,
}

impl<S: Scalar> Inertia<S> {
    pub fn zero() -> Self {
        Inertia {
            m: c(0.0),
            h: Vector3::zeros(),
            ibar: Matrix3::zeros(),
        }
    }
    /// From mass, centre of mass and inertia about the centre of mass (Featherstone ch. 2):
    /// `ibar = I_c + m [c]x [c]x^T`.
    pub fn from_com(m: S, com: Vector3<S>, ic: Matrix3<S>) -> Self {
        let cx = skew(&com);
        Inertia {
            m,
            h: com * m,
            ibar: ic - cx * cx * m,
        }
    }
    pub fn lift(i: &Inertia<f64>) -> Self {
        Inertia {
            m: c(i.m),
            h: lift3(&i.h),
            ibar: lift33(&i.ibar),
        }
    }
    pub fn add(&self, o: &Inertia<S>) -> Inertia<S> {
        Inertia {
            m: self.m + o.m,
            h: self.h + o.h,
            ibar: self.ibar + o.ibar,
        }
    }
    /// `I m` = `(ibar ω + h x v, m v - h x ω)`.
    pub fn mul_motion(&self, v: &Motion<S>) -> Force<S> {
        Force {
            ang: self.ibar * v.ang + cross(&self.h, &v.lin),
            lin: v.lin * self.m - cross(&self.h, &v.ang),
        }
    }
    /// Express an inertia given in B coordinates in A coordinates: `X^T I X` with `X = ^B X_A`
    /// (Featherstone Table 2.5, written with the parallel-axis theorem, no division by `m`).
    ///
    /// ibar_A = E^T ibar E - m [r]x[r]x - [r]x[h']x - [h']x[r]x with h' = E^T h, and with
    /// [a]x[b]x = b a^T - (a . b) 1 the last three terms are
    /// (m |r|^2 + 2 r . h') 1 - m r r^T - r h'^T - h' r^T; both parts symmetric, one triangle
    /// computed.
    pub fn transform_to_parent(&self, x: &Xform<S>) -> Inertia<S> {
        let (e, r, m) = (&x.e, &x.r, self.m);
        let hp = e.tr_mul(&self.h);
        let t = e.tr_mul(&self.ibar);
        let diag = r.dot(r) * m + r.dot(&hp) * c::<S>(2.0);
        let mut ibar = Matrix3::zeros();
        for i in 0..3 {
            for j in i..3 {
                let rot = t[(i, 0)] * e[(0, j)] + t[(i, 1)] * e[(1, j)] + t[(i, 2)] * e[(2, j)];
                let mut v = rot - r[i] * r[j] * m - r[i] * hp[j] - hp[i] * r[j];
                if i == j {
                    v += diag;
                }
                ibar[(i, j)] = v;
                ibar[(j, i)] = v;
            }
        }
        Inertia {
            m,
            h: hp + r * m,
            ibar,
        }
    }
}
