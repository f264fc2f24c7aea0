//! The scalar type every model, programme and right-hand side is generic over.
//!
//! `f64` for ordinary evaluation; `num_dual` forward-mode dual numbers (`Dual64`, `Dual2_64`,
//! nested `Dual<S>`) when exact derivatives are needed: programme Jacobians B = dg/dv, the
//! second-derivative terms of holonomic rows, and the Jacobian of the whole right-hand side for
//! implicit integrators. No finite differences anywhere.
//!
//! Only `DualNum` (not nalgebra's `RealField`) is a supertrait, so `x.sin()` is unambiguous in
//! generic code; our own linear algebra (`crate::linalg`) works on `nalgebra::DMatrix<S>`.

pub use num_dual::{Dual, Dual2, DualNum, DualStruct};

/// A real number or a forward-mode dual number over `f64`.
pub trait Scalar: DualNum<Primitive = f64> + Copy + Send + Sync + nalgebra::Scalar + BitEq {}
impl<T: DualNum<Primitive = f64> + Copy + Send + Sync + nalgebra::Scalar + BitEq> Scalar for T {}

/// Equality of every part, bit for bit (`==` on dual numbers compares real parts only): the test
/// by which a cached computation is reused ([`crate::tree::forward_kinematics`]).
pub trait BitEq {
    fn bit_eq(&self, other: &Self) -> bool;
}

impl BitEq for f64 {
    #[inline(always)]
    fn bit_eq(&self, other: &Self) -> bool {
        self.to_bits() == other.to_bits()
    }
}

impl<T: BitEq> BitEq for Dual<T> {
    #[inline(always)]
    fn bit_eq(&self, other: &Self) -> bool {
        self.re.bit_eq(&other.re) && self.eps.bit_eq(&other.eps)
    }
}

impl<T: BitEq> BitEq for Dual2<T> {
    #[inline(always)]
    fn bit_eq(&self, other: &Self) -> bool {
        self.re.bit_eq(&other.re) && self.v1.bit_eq(&other.v1) && self.v2.bit_eq(&other.v2)
    }
}

/// Lift a constant into any scalar type.
#[inline(always)]
pub fn c<S: Scalar>(x: f64) -> S {
    S::from(x)
}

/// The real (value) part of any scalar.
#[inline(always)]
pub fn re<S: Scalar>(x: S) -> f64 {
    x.re()
}
