//! Truncated Taylor series in one variable: univariate Taylor propagation for the servo's Lie
//! derivatives (issue 31; Griewank & Walther, Evaluating Derivatives, 2nd ed. (2008), Sec. 13.2,
//! Table 13.2).
//!
//! `Taylor<T, N>` holds the normalized coefficients x_k = x^(k)(0) / k!, k < N, of a function of
//! one variable. A product costs N (N + 1) / 2 multiplications and every elementary function one
//! recurrence of the same order, so derivatives to degree d cost O(d^2) per operation, against 3^d
//! for d nested first-order dual numbers. The coefficients may themselves be dual numbers
//! (`Taylor<Dual64, N>`: a derivative along the motion and one across it, as the decoupling
//! matrix's columns need).
//!
//! Recurrences (k >= 1; sums over j = 1..k unless noted):
//! - product  c_k = sum_{j=0..k} a_j b_(k-j);  quotient  w_k = (u_k - sum v_j w_(k-j)) / v_0;
//! - exp      y_k = (1/k) sum j x_j y_(k-j);
//! - sin, cos s_k = (1/k) sum j x_j c_(k-j),  c_k = -(1/k) sum j x_j s_(k-j);
//! - sqrt     r_k = (x_k - sum_{j=1..k-1} r_j r_(k-j)) / (2 r_0);
//! - x^p      y_k = (1 / (k x_0)) sum (p j - (k - j)) x_j y_(k-j)  (from x y' = p y x');
//! - f(x) with f' known as a series (ln, atan, asin, ...):  y = y_0 + integral of f'(x) x'.
//!
//! Comparisons, like num-dual's, read the value x_0 only, so code branches as it would on f64.

use num_dual::{DualNum, DualStruct, Mappable};
use num_traits::{FromPrimitive, Inv, Num, One, Signed, Zero};
use std::fmt;
use std::iter::{Product, Sum};
use std::ops::{
    Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Rem, RemAssign, Sub, SubAssign,
};

/// The coefficient types: f64 and the dual numbers over it.
pub trait Coef: DualNum<Primitive = f64> + Copy {}
impl<T: DualNum<Primitive = f64> + Copy> Coef for T {}

/// A truncated Taylor series sum_{k < len} x_k s^k, len <= N (module docs). Constants have
/// len 1, so a constant times a series costs len multiplications; the result of an operation
/// has the larger len of its operands (the truncation order of the computation). Coefficients
/// from len to N are zero.
#[derive(Clone, Copy, Debug)]
pub struct Taylor<T, const N: usize> {
    c: [T; N],
    len: usize,
}

impl<T: Coef, const N: usize> Taylor<T, N> {
    /// The constant x.
    #[inline]
    pub fn constant(x: T) -> Self {
        let mut c = [T::zero(); N];
        c[0] = x;
        Taylor { c, len: 1 }
    }

    /// The series with coefficients `x` (1 <= length <= N).
    #[inline]
    pub fn from_coefficients(x: &[T]) -> Self {
        assert!(!x.is_empty() && x.len() <= N, "1 to {N} coefficients");
        let mut c = [T::zero(); N];
        c[..x.len()].copy_from_slice(x);
        Taylor { c, len: x.len() }
    }

    /// The coefficients x_k, k < len.
    #[inline]
    pub fn coefficients(&self) -> &[T] {
        &self.c[..self.len]
    }

    /// Coefficient x_k (zero at and beyond len; k < N).
    #[inline]
    pub fn coefficient(&self, k: usize) -> T {
        self.c[k]
    }

    /// A series of length `len` from the first coefficients of `c` (the rest zero).
    #[inline]
    fn of(c: [T; N], len: usize) -> Self {
        Taylor { c, len }
    }

    /// d/ds of the series, at the same length (its top coefficient zero).
    #[inline]
    fn deriv(&self) -> Self {
        let mut c = [T::zero(); N];
        for k in 0..self.len - 1 {
            c[k] = self.c[k + 1] * (k + 1) as f64;
        }
        Self::of(c, self.len)
    }

    /// y of length `len` with y_0 = `y0` and dy/ds = `d`: y_k = d_(k-1) / k.
    #[inline]
    fn integral(d: &Self, y0: T, len: usize) -> Self {
        let mut c = [T::zero(); N];
        c[0] = y0;
        for k in 1..len {
            c[k] = d.c[k - 1] / k as f64;
        }
        Self::of(c, len)
    }

    /// f(x) from f(x_0) = `y0` and f'(x) as a series `fp`: dy/ds = f'(x) dx/ds.
    #[inline]
    fn chain(&self, fp: &Self, y0: T) -> Self {
        Self::integral(&(self.deriv() * fp), y0, self.len)
    }

    /// x^p with y_0 = `y0` given (the recurrence of the module docs; x_0 != 0).
    fn pow_series(&self, p: f64, y0: T) -> Self {
        let x = &self.c;
        let mut y = [T::zero(); N];
        y[0] = y0;
        if self.len > 1 {
            let r = x[0].recip();
            for k in 1..self.len {
                let mut s = T::zero();
                for j in 1..=k {
                    s += x[j] * y[k - j] * (p * j as f64 - (k - j) as f64);
                }
                y[k] = s * r / k as f64;
            }
        }
        Self::of(y, self.len)
    }

    /// The value of `f` at x_0 in the value slot, the series' higher coefficients kept.
    #[inline]
    fn with_value(mut self, y0: T) -> Self {
        self.c[0] = y0;
        self
    }
}

// ---- arithmetic -------------------------------------------------------------------------------

impl<T: Coef, const N: usize> Mul<&Taylor<T, N>> for &Taylor<T, N> {
    type Output = Taylor<T, N>;
    #[inline]
    fn mul(self, o: &Taylor<T, N>) -> Taylor<T, N> {
        let (a, b) = (&self.c, &o.c);
        let mut c = [T::zero(); N];
        let len = self.len.max(o.len);
        if self.len == 1 {
            for k in 0..len {
                c[k] = a[0] * b[k];
            }
        } else if o.len == 1 {
            for k in 0..len {
                c[k] = a[k] * b[0];
            }
        } else {
            product(a, b, len, &mut c);
        }
        Taylor::of(c, len)
    }
}

/// The Cauchy product of two series of `len` coefficients, one unrolled loop per length: out of
/// line, so each multiplication site of the model's passes holds a call, not five loops (the
/// core's compile time; docs/benchmarks.md, stop 52).
#[inline(never)]
fn product<T: Coef, const N: usize>(a: &[T; N], b: &[T; N], len: usize, c: &mut [T; N]) {
    match len {
        2 => convolve::<T, N, 2>(a, b, c),
        3 => convolve::<T, N, 3>(a, b, c),
        4 => convolve::<T, N, 4>(a, b, c),
        5 => convolve::<T, N, 5>(a, b, c),
        _ => convolve::<T, N, N>(a, b, c),
    }
}

/// c_k = sum_{j=0..k} a_j b_(k-j), k < L (L a constant: the loops unroll).
#[inline(always)]
fn convolve<T: Coef, const N: usize, const L: usize>(a: &[T; N], b: &[T; N], c: &mut [T; N]) {
    for k in 0..L.min(N) {
        let mut s = a[0] * b[k];
        for j in 1..=k {
            s += a[j] * b[k - j];
        }
        c[k] = s;
    }
}

impl<T: Coef, const N: usize> Div<&Taylor<T, N>> for &Taylor<T, N> {
    type Output = Taylor<T, N>;
    #[inline]
    fn div(self, o: &Taylor<T, N>) -> Taylor<T, N> {
        let (u, v) = (&self.c, &o.c);
        let mut w = [T::zero(); N];
        let len = self.len.max(o.len);
        w[0] = u[0] / v[0];
        if len > 1 {
            let r = v[0].recip();
            for k in 1..len {
                let mut s = u[k];
                for j in 1..=k.min(o.len - 1) {
                    s -= v[j] * w[k - j];
                }
                w[k] = s * r;
            }
        }
        Taylor::of(w, len)
    }
}

impl<T: Coef, const N: usize> Add<&Taylor<T, N>> for &Taylor<T, N> {
    type Output = Taylor<T, N>;
    #[inline]
    fn add(self, o: &Taylor<T, N>) -> Taylor<T, N> {
        let mut c = self.c;
        let len = self.len.max(o.len);
        for k in 0..o.len {
            c[k] += o.c[k];
        }
        Taylor::of(c, len)
    }
}

impl<T: Coef, const N: usize> Sub<&Taylor<T, N>> for &Taylor<T, N> {
    type Output = Taylor<T, N>;
    #[inline]
    fn sub(self, o: &Taylor<T, N>) -> Taylor<T, N> {
        let mut c = self.c;
        let len = self.len.max(o.len);
        for k in 0..o.len {
            c[k] -= o.c[k];
        }
        Taylor::of(c, len)
    }
}

impl<T: Coef, const N: usize> Rem<&Taylor<T, N>> for &Taylor<T, N> {
    type Output = Taylor<T, N>;
    /// x - n y with n = trunc(x_0 / y_0) held constant (f64's remainder, its derivatives).
    fn rem(self, o: &Taylor<T, N>) -> Taylor<T, N> {
        let n = (self.c[0].re() / o.c[0].re()).trunc();
        (*self - *o * n).with_value(self.c[0] % o.c[0])
    }
}

macro_rules! forward_binop {
    ($trt:ident, $mth:ident) => {
        impl<T: Coef, const N: usize> $trt for Taylor<T, N> {
            type Output = Self;
            #[inline]
            fn $mth(self, o: Self) -> Self {
                $trt::$mth(&self, &o)
            }
        }
        impl<T: Coef, const N: usize> $trt<&Taylor<T, N>> for Taylor<T, N> {
            type Output = Self;
            #[inline]
            fn $mth(self, o: &Self) -> Self {
                $trt::$mth(&self, o)
            }
        }
        impl<T: Coef, const N: usize> $trt<Taylor<T, N>> for &Taylor<T, N> {
            type Output = Taylor<T, N>;
            #[inline]
            fn $mth(self, o: Taylor<T, N>) -> Taylor<T, N> {
                $trt::$mth(self, &o)
            }
        }
    };
}
forward_binop!(Add, add);
forward_binop!(Sub, sub);
forward_binop!(Mul, mul);
forward_binop!(Div, div);
forward_binop!(Rem, rem);

macro_rules! assign_op {
    ($trt:ident, $mth:ident, $op:ident, $opm:ident) => {
        impl<T: Coef, const N: usize> $trt for Taylor<T, N> {
            #[inline]
            fn $mth(&mut self, o: Self) {
                *self = $op::$opm(&*self, &o);
            }
        }
    };
}
assign_op!(AddAssign, add_assign, Add, add);
assign_op!(SubAssign, sub_assign, Sub, sub);
assign_op!(MulAssign, mul_assign, Mul, mul);
assign_op!(DivAssign, div_assign, Div, div);
assign_op!(RemAssign, rem_assign, Rem, rem);

// with the primitive f64: a constant
impl<T: Coef, const N: usize> Add<f64> for Taylor<T, N> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: f64) -> Self {
        self.c[0] += o;
        self
    }
}
impl<T: Coef, const N: usize> Sub<f64> for Taylor<T, N> {
    type Output = Self;
    #[inline]
    fn sub(mut self, o: f64) -> Self {
        self.c[0] -= o;
        self
    }
}
impl<T: Coef, const N: usize> Mul<f64> for Taylor<T, N> {
    type Output = Self;
    #[inline]
    fn mul(mut self, o: f64) -> Self {
        self.c[..self.len].iter_mut().for_each(|x| *x *= o);
        self
    }
}
impl<T: Coef, const N: usize> Div<f64> for Taylor<T, N> {
    type Output = Self;
    #[inline]
    fn div(mut self, o: f64) -> Self {
        self.c[..self.len].iter_mut().for_each(|x| *x /= o);
        self
    }
}
impl<T: Coef, const N: usize> Rem<f64> for Taylor<T, N> {
    type Output = Self;
    /// x - n y with n = trunc(x_0 / y) held constant: only the value changes.
    #[inline]
    fn rem(mut self, o: f64) -> Self {
        self.c[0] %= o;
        self
    }
}
macro_rules! assign_f64 {
    ($trt:ident, $mth:ident, $op:ident, $opm:ident) => {
        impl<T: Coef, const N: usize> $trt<f64> for Taylor<T, N> {
            #[inline]
            fn $mth(&mut self, o: f64) {
                *self = $op::$opm(*self, o);
            }
        }
    };
}
assign_f64!(AddAssign, add_assign, Add, add);
assign_f64!(SubAssign, sub_assign, Sub, sub);
assign_f64!(MulAssign, mul_assign, Mul, mul);
assign_f64!(DivAssign, div_assign, Div, div);
assign_f64!(RemAssign, rem_assign, Rem, rem);

impl<T: Coef, const N: usize> Neg for Taylor<T, N> {
    type Output = Self;
    #[inline]
    fn neg(mut self) -> Self {
        self.c[..self.len].iter_mut().for_each(|x| *x = -*x);
        self
    }
}
impl<T: Coef, const N: usize> Neg for &Taylor<T, N> {
    type Output = Taylor<T, N>;
    #[inline]
    fn neg(self) -> Taylor<T, N> {
        -*self
    }
}

impl<T: Coef, const N: usize> Inv for Taylor<T, N> {
    type Output = Self;
    #[inline]
    fn inv(self) -> Self {
        self.recip()
    }
}

impl<T: Coef, const N: usize> Zero for Taylor<T, N> {
    #[inline]
    fn zero() -> Self {
        Self::constant(T::zero())
    }
    /// The value only, as num-dual's types.
    #[inline]
    fn is_zero(&self) -> bool {
        self.c[0].is_zero()
    }
}
impl<T: Coef, const N: usize> One for Taylor<T, N> {
    #[inline]
    fn one() -> Self {
        Self::constant(T::one())
    }
}

impl<T: Coef, const N: usize> Num for Taylor<T, N> {
    type FromStrRadixErr = <f64 as Num>::FromStrRadixErr;
    fn from_str_radix(s: &str, radix: u32) -> Result<Self, <f64 as Num>::FromStrRadixErr> {
        f64::from_str_radix(s, radix).map(Self::from)
    }
}

impl<T: Coef, const N: usize> Signed for Taylor<T, N> {
    fn abs(&self) -> Self {
        if self.is_negative() {
            -*self
        } else {
            *self
        }
    }
    fn abs_sub(&self, other: &Self) -> Self {
        if self.c[0].re() > other.c[0].re() {
            self - other
        } else {
            Self::zero()
        }
    }
    fn signum(&self) -> Self {
        Self::constant(self.c[0].signum())
    }
    fn is_positive(&self) -> bool {
        self.c[0].is_positive()
    }
    fn is_negative(&self) -> bool {
        self.c[0].is_negative()
    }
}

impl<T: Coef, const N: usize> From<f64> for Taylor<T, N> {
    #[inline]
    fn from(x: f64) -> Self {
        Self::constant(T::from(x))
    }
}

impl<T: Coef, const N: usize> FromPrimitive for Taylor<T, N> {
    fn from_i64(n: i64) -> Option<Self> {
        f64::from_i64(n).map(Self::from)
    }
    fn from_u64(n: u64) -> Option<Self> {
        f64::from_u64(n).map(Self::from)
    }
    fn from_f64(x: f64) -> Option<Self> {
        Some(Self::from(x))
    }
}

impl<T: Coef, const N: usize> Sum for Taylor<T, N> {
    fn sum<I: Iterator<Item = Self>>(it: I) -> Self {
        it.fold(Self::zero(), |a, x| a + x)
    }
}
impl<'a, T: Coef, const N: usize> Sum<&'a Taylor<T, N>> for Taylor<T, N> {
    fn sum<I: Iterator<Item = &'a Self>>(it: I) -> Self {
        it.fold(Self::zero(), |a, x| a + x)
    }
}
impl<T: Coef, const N: usize> Product for Taylor<T, N> {
    fn product<I: Iterator<Item = Self>>(it: I) -> Self {
        it.fold(Self::one(), |a, x| a * x)
    }
}
impl<'a, T: Coef, const N: usize> Product<&'a Taylor<T, N>> for Taylor<T, N> {
    fn product<I: Iterator<Item = &'a Self>>(it: I) -> Self {
        it.fold(Self::one(), |a, x| a * x)
    }
}

/// Equality and order of the values x_0 (the branch a f64 computation would take).
impl<T: Coef, const N: usize> PartialEq for Taylor<T, N> {
    fn eq(&self, o: &Self) -> bool {
        self.c[0] == o.c[0]
    }
}
impl<T: Coef, const N: usize> PartialEq<f64> for Taylor<T, N> {
    fn eq(&self, o: &f64) -> bool {
        self.c[0].re() == *o
    }
}
impl<T: Coef, const N: usize> PartialOrd for Taylor<T, N> {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        self.c[0].partial_cmp(&o.c[0])
    }
}
impl<T: Coef, const N: usize> PartialOrd<f64> for Taylor<T, N> {
    fn partial_cmp(&self, o: &f64) -> Option<std::cmp::Ordering> {
        self.c[0].re().partial_cmp(o)
    }
}

impl<T: Coef, const N: usize> fmt::Display for Taylor<T, N> {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{}", self.c[0])?;
        for (k, x) in self.coefficients().iter().enumerate().skip(1) {
            write!(f, " + ({x}) s^{k}")?;
        }
        Ok(())
    }
}

impl<T: Coef, const N: usize> DualStruct for Taylor<T, N> {
    type Real = f64;
    type Inner = T;
    #[inline]
    fn re(&self) -> f64 {
        self.c[0].re()
    }
    #[inline]
    fn from_inner(inner: &T) -> Self {
        Self::constant(*inner)
    }
}

impl<T: Coef, const N: usize> Mappable<Self> for Taylor<T, N> {
    type Output<O> = O;
    #[inline]
    fn map_dual<G: Fn(Self) -> O, O>(self, g: G) -> O {
        g(self)
    }
}

impl<T: Coef + Send + Sync, const N: usize> crate::scalar::BitEq for Taylor<T, N>
where
    T: crate::scalar::BitEq,
{
    #[inline(always)]
    fn bit_eq(&self, other: &Self) -> bool {
        self.len == other.len && self.c.iter().zip(&other.c).all(|(a, b)| a.bit_eq(b))
    }
}

// ---- elementary functions ---------------------------------------------------------------------

impl<T: Coef, const N: usize> DualNum for Taylor<T, N> {
    type Primitive = f64;
    const NDERIV: usize = T::NDERIV + N - 1;
    type InnerDual = T;

    #[inline]
    fn from_re(re: T) -> Self {
        Self::constant(re)
    }

    #[inline]
    fn scale(mut self, factor: &T) -> Self {
        self.c[..self.len].iter_mut().for_each(|x| *x *= *factor);
        self
    }

    fn recip(&self) -> Self {
        Self::one() / *self
    }

    fn powi(&self, n: i32) -> Self {
        match n {
            0 => Self::one(),
            n if n < 0 => self.powi(-n).recip(),
            _ => {
                // binary powers: exact at x_0 = 0 too
                let (mut base, mut e, mut acc) = (*self, n as u32, Self::one());
                while e > 0 {
                    if e & 1 == 1 {
                        acc *= base;
                    }
                    e >>= 1;
                    if e > 0 {
                        base = base * base;
                    }
                }
                acc
            }
        }
    }

    fn powf(&self, p: f64) -> Self {
        if p == 0.0 {
            Self::one()
        } else if p == 1.0 {
            *self
        } else if p.fract() == 0.0 && p.abs() <= 64.0 {
            self.powi(p as i32)
        } else {
            self.pow_series(p, self.c[0].powf(p))
        }
    }

    fn sqrt(&self) -> Self {
        let x = &self.c;
        let mut r = [T::zero(); N];
        r[0] = x[0].sqrt();
        let h = (r[0] * 2.0).recip();
        for k in 1..self.len {
            let mut s = x[k];
            for j in 1..k {
                s -= r[j] * r[k - j];
            }
            r[k] = s * h;
        }
        Self::of(r, self.len)
    }

    fn cbrt(&self) -> Self {
        self.pow_series(1.0 / 3.0, self.c[0].cbrt())
    }

    fn exp(&self) -> Self {
        let x = &self.c;
        let mut y = [T::zero(); N];
        y[0] = x[0].exp();
        for k in 1..self.len {
            let mut s = T::zero();
            for j in 1..=k {
                s += x[j] * y[k - j] * j as f64;
            }
            y[k] = s / k as f64;
        }
        Self::of(y, self.len)
    }

    fn exp2(&self) -> Self {
        (*self * std::f64::consts::LN_2)
            .exp()
            .with_value(self.c[0].exp2())
    }

    fn exp_m1(&self) -> Self {
        self.exp().with_value(self.c[0].exp_m1())
    }

    fn ln(&self) -> Self {
        self.chain(&self.recip(), self.c[0].ln())
    }

    fn log(&self, base: f64) -> Self {
        (self.ln() / base.ln()).with_value(self.c[0].log(base))
    }

    fn log2(&self) -> Self {
        (self.ln() / std::f64::consts::LN_2).with_value(self.c[0].log2())
    }

    fn log10(&self) -> Self {
        (self.ln() / std::f64::consts::LN_10).with_value(self.c[0].log10())
    }

    fn ln_1p(&self) -> Self {
        self.chain(&(*self + 1.0).recip(), self.c[0].ln_1p())
    }

    fn sin(&self) -> Self {
        self.sin_cos().0
    }

    fn cos(&self) -> Self {
        self.sin_cos().1
    }

    fn tan(&self) -> Self {
        let (s, c) = self.sin_cos();
        (s / c).with_value(self.c[0].tan())
    }

    fn sin_cos(&self) -> (Self, Self) {
        let x = &self.c;
        let (mut s, mut c) = ([T::zero(); N], [T::zero(); N]);
        (s[0], c[0]) = x[0].sin_cos();
        for k in 1..self.len {
            let (mut a, mut b) = (T::zero(), T::zero());
            for j in 1..=k {
                let jx = x[j] * j as f64;
                a += jx * c[k - j];
                b += jx * s[k - j];
            }
            s[k] = a / k as f64;
            c[k] = -b / k as f64;
        }
        (Self::of(s, self.len), Self::of(c, self.len))
    }

    fn asin(&self) -> Self {
        let r = (-(*self * *self) + 1.0).sqrt();
        self.chain(&r.recip(), self.c[0].asin())
    }

    fn acos(&self) -> Self {
        let r = (-(*self * *self) + 1.0).sqrt();
        self.chain(&(-r.recip()), self.c[0].acos())
    }

    fn atan(&self) -> Self {
        self.chain(&(*self * *self + 1.0).recip(), self.c[0].atan())
    }

    /// atan2(y = self, x = other): d theta = (x dy - y dx) / (x^2 + y^2).
    fn atan2(&self, x: Self) -> Self {
        let y = *self;
        let p = x * y.deriv() - y * x.deriv();
        let d = x * x + y * y;
        Self::integral(&(p / d), self.c[0].atan2(x.c[0]), self.len.max(x.len))
    }

    fn sinh(&self) -> Self {
        let (e, ei) = (self.exp(), (-*self).exp());
        ((e - ei) * 0.5).with_value(self.c[0].sinh())
    }

    fn cosh(&self) -> Self {
        let (e, ei) = (self.exp(), (-*self).exp());
        ((e + ei) * 0.5).with_value(self.c[0].cosh())
    }

    fn tanh(&self) -> Self {
        (self.sinh() / self.cosh()).with_value(self.c[0].tanh())
    }

    fn asinh(&self) -> Self {
        let r = (*self * *self + 1.0).sqrt();
        self.chain(&r.recip(), self.c[0].asinh())
    }

    fn acosh(&self) -> Self {
        let r = (*self * *self - 1.0).sqrt();
        self.chain(&r.recip(), self.c[0].acosh())
    }

    fn atanh(&self) -> Self {
        self.chain(&(-(*self * *self) + 1.0).recip(), self.c[0].atanh())
    }

    /// sin x / x (x_0 != 0; the value at x_0 = 0 from the coefficient type).
    fn sph_j0(&self) -> Self {
        (self.sin() / *self).with_value(self.c[0].sph_j0())
    }

    /// (sin x / x - cos x) / x (x_0 != 0).
    fn sph_j1(&self) -> Self {
        let (s, c) = self.sin_cos();
        ((s / *self - c) / *self).with_value(self.c[0].sph_j1())
    }

    /// ((3 / x^2 - 1) sin x - 3 cos x / x) / x (x_0 != 0).
    fn sph_j2(&self) -> Self {
        let (s, c) = self.sin_cos();
        let x2 = *self * *self;
        let three = Self::from(3.0);
        (((three / x2 - 1.0) * s - three * c / *self) / *self).with_value(self.c[0].sph_j2())
    }
}

#[cfg(test)]
mod tests;
