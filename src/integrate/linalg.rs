//! In-place dense LU with partial pivoting on preallocated storage (no allocation per call), for
//! the real and complex iteration matrices of Radau IIA.

// Index loops mirror the formulas.
#![allow(clippy::needless_range_loop, clippy::too_many_arguments)]

use nalgebra::{ComplexField, DMatrix};

/// Factor `a` = P L U in place (Doolittle, row partial pivoting); `piv[k]` is the row swapped
/// with row k at elimination step k. Returns false if a zero (or non-finite) pivot appears.
pub(crate) fn lu_factor<T>(a: &mut DMatrix<T>, piv: &mut [usize]) -> bool
where
    T: ComplexField<RealField = f64> + Copy,
{
    let n = a.nrows();
    let m = a.as_mut_slice(); // column-major: (i, j) at i + j n
    for k in 0..n {
        let mut p = k;
        let mut best = m[k + k * n].modulus();
        for i in k + 1..n {
            let v = m[i + k * n].modulus();
            if v > best {
                best = v;
                p = i;
            }
        }
        piv[k] = p;
        if best == 0.0 || !best.is_finite() {
            return false;
        }
        if p != k {
            for j in 0..n {
                m.swap(k + j * n, p + j * n);
            }
        }
        let inv = T::one() / m[k + k * n];
        for i in k + 1..n {
            m[i + k * n] *= inv;
        }
        for j in k + 1..n {
            let akj = m[k + j * n];
            if akj != T::zero() {
                for i in k + 1..n {
                    let lik = m[i + k * n];
                    m[i + j * n] -= lik * akj;
                }
            }
        }
    }
    true
}

/// Solve A x = b in place with the factors of [`lu_factor`].
pub(crate) fn lu_solve<T>(a: &DMatrix<T>, piv: &[usize], b: &mut [T])
where
    T: ComplexField<RealField = f64> + Copy,
{
    let n = a.nrows();
    let m = a.as_slice();
    for k in 0..n {
        if piv[k] != k {
            b.swap(k, piv[k]);
        }
    }
    // L y = b (unit lower), column oriented.
    for k in 0..n {
        let bk = b[k];
        if bk != T::zero() {
            for i in k + 1..n {
                b[i] -= m[i + k * n] * bk;
            }
        }
    }
    // U x = y.
    for k in (0..n).rev() {
        b[k] /= m[k + k * n];
        let bk = b[k];
        if bk != T::zero() {
            for i in 0..k {
                b[i] -= m[i + k * n] * bk;
            }
        }
    }
}
