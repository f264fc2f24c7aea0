//! Small dense factorizations, in place and allocation-free, generic over [`Scalar`].
//!
//! nalgebra's decompositions consume and allocate and need `RealField`; the right-hand side of a
//! programmed motion is evaluated millions of times, also over dual numbers (for exact Jacobians), so
//! the two factorizations it needs are written here on preallocated storage:
//! - LU with partial pivoting (Golub & Van Loan, *Matrix Computations*, Alg. 3.4.1), also over
//!   complex numbers (Radau IIA's complex iteration matrix, [`lu_factor_with`] and [`Modulus`]);
//! - Householder QR with column pivoting, rank-revealing (ibid., Alg. 5.4.1).
//!
//! Pivot choices compare real parts only, so a dual evaluation follows the same branch as the
//! `f64` one and its derivative parts are the derivatives of that branch.

use crate::scalar::{c, re, Scalar};
use nalgebra::{Complex, DMatrix};
use std::ops::{DivAssign, Mul, MulAssign, SubAssign};

/// The field operations LU needs: `f64`, the dual numbers and `Complex<f64>` have them.
pub trait Field:
    nalgebra::Scalar + Copy + Mul<Output = Self> + MulAssign + SubAssign + DivAssign
{
}
impl<T: nalgebra::Scalar + Copy + Mul<Output = T> + MulAssign + SubAssign + DivAssign> Field for T {}

/// How LU sizes and inverts a pivot of a [`Field`].
pub trait Pivot<T> {
    /// Magnitude compared to choose the pivot.
    fn size(x: T) -> f64;
    /// 1 / x.
    fn recip(x: T) -> T;
}

/// Pivots of [`Scalar`]s by the real part: a dual evaluation follows the `f64` branch.
pub struct RealPart;

impl<S: Scalar> Pivot<S> for RealPart {
    #[inline]
    fn size(x: S) -> f64 {
        re(x).abs()
    }
    #[inline]
    fn recip(x: S) -> S {
        x.recip()
    }
}

/// Pivots of complex numbers by the modulus.
pub struct Modulus;

impl Pivot<Complex<f64>> for Modulus {
    #[inline]
    fn size(x: Complex<f64>) -> f64 {
        x.norm()
    }
    #[inline]
    fn recip(x: Complex<f64>) -> Complex<f64> {
        Complex::new(1.0, 0.0) / x
    }
}

/// A pivot fell to zero (or below `tol` times the largest pivot) during a factorization.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Singular {
    /// Column at which elimination broke down.
    pub column: usize,
    /// Ratio of the smallest to the largest pivot magnitude seen (a reciprocal condition estimate).
    pub rcond: f64,
}

/// In-place LU with partial pivoting of the leading `n x n` block of `a`: P A = L U, L unit lower.
/// Returns the reciprocal pivot-ratio estimate `min|u_ii| / max|u_ii|`, or `Singular` if a pivot is
/// exactly zero or the ratio falls below `tol`.
pub fn lu_factor<S: Scalar>(
    a: &mut DMatrix<S>,
    n: usize,
    piv: &mut [usize],
    tol: f64,
) -> Result<f64, Singular> {
    lu_factor_with::<S, RealPart>(a, n, piv, tol)
}

/// [`lu_factor`] over any [`Field`], pivots chosen and inverted by `P`.
pub fn lu_factor_with<T: Field, P: Pivot<T>>(
    a: &mut DMatrix<T>,
    n: usize,
    piv: &mut [usize],
    tol: f64,
) -> Result<f64, Singular> {
    let mut umax = 0.0f64;
    let mut umin = f64::INFINITY;
    for k in 0..n {
        let mut p = k;
        let mut best = P::size(a[(k, k)]);
        for i in k + 1..n {
            let m = P::size(a[(i, k)]);
            if m > best {
                best = m;
                p = i;
            }
        }
        piv[k] = p;
        if best == 0.0 || !best.is_finite() {
            return Err(Singular {
                column: k,
                rcond: 0.0,
            });
        }
        umax = umax.max(best);
        umin = umin.min(best);
        if p != k {
            a.swap_rows(k, p);
        }
        let inv = P::recip(a[(k, k)]);
        let ld = a.nrows();
        let data = a.as_mut_slice();
        for x in &mut data[k * ld + k + 1..k * ld + n] {
            *x *= inv;
        }
        // Right-looking update, column by column (contiguous in column-major storage).
        for j in k + 1..n {
            let (colk, colj) = two_columns(data, ld, k, j);
            let akj = colj[k];
            axpy_neg(akj, &colk[k + 1..n], &mut colj[k + 1..n]);
        }
    }
    let rcond = if n == 0 { 1.0 } else { umin / umax };
    if rcond < tol {
        return Err(Singular {
            column: n.saturating_sub(1),
            rcond,
        });
    }
    Ok(rcond)
}

/// Solve A x = b in place with the factors from [`lu_factor`] (or [`lu_factor_with`]).
pub fn lu_solve<T: Field>(a: &DMatrix<T>, n: usize, piv: &[usize], b: &mut [T]) {
    for k in 0..n {
        b.swap(k, piv[k]);
    }
    let ld = a.nrows();
    let data = a.as_slice();
    // L (unit lower) then U, column-oriented.
    for j in 0..n {
        let bj = b[j];
        axpy_neg(bj, &data[j * ld + j + 1..j * ld + n], &mut b[j + 1..n]);
    }
    for j in (0..n).rev() {
        b[j] /= data[j * ld + j];
        let bj = b[j];
        axpy_neg(bj, &data[j * ld..j * ld + j], &mut b[..j]);
    }
}

/// Columns k < j of a column-major slice with leading dimension `ld`: (column k, column j).
#[inline]
fn two_columns<S>(data: &mut [S], ld: usize, k: usize, j: usize) -> (&[S], &mut [S]) {
    debug_assert!(k < j);
    let (left, right) = data.split_at_mut(j * ld);
    (&left[k * ld..(k + 1) * ld], &mut right[..ld])
}

/// y <- y - alpha x.
#[inline]
fn axpy_neg<T: Field>(alpha: T, x: &[T], y: &mut [T]) {
    for (yi, &xi) in y.iter_mut().zip(x) {
        *yi -= alpha * xi;
    }
}

/// x . y
#[inline]
fn dot<S: Scalar>(x: &[S], y: &[S]) -> S {
    let mut s = S::zero();
    for (&a, &b) in x.iter().zip(y) {
        s += a * b;
    }
    s
}

/// Householder QR with column pivoting of the leading `m x k` block of `a` (m >= k):
/// A P = Q R. On return the upper triangle holds R, the part below the diagonal the Householder
/// vectors (with implicit leading 1), `beta[j]` their scalings (H_j = I - beta_j w_j w_j^T), and
/// `perm[j]` the original column now in position j. Returns the numerical rank: the number of
/// leading |r_jj| above `tol * |r_00|`. Column norms are recomputed at each step (k is small: the
/// number of programme rows), so there is no downdating error.
pub fn qr_colpiv<S: Scalar>(
    a: &mut DMatrix<S>,
    m: usize,
    k: usize,
    beta: &mut [S],
    perm: &mut [usize],
    tol: f64,
) -> usize {
    for (j, p) in perm.iter_mut().enumerate().take(k) {
        *p = j;
    }
    let mut rank = k;
    let mut r00 = 0.0f64;
    // column-major storage: column c is d[c * nr..(c + 1) * nr] (slices, not (i, j) indexing)
    let nr = a.nrows();
    let d = a.as_mut_slice();
    for j in 0..k {
        // Pivot: the remaining column of largest norm (real parts).
        let mut best = -1.0;
        let mut p = j;
        for col in j..k {
            let s: f64 = d[col * nr + j..col * nr + m]
                .iter()
                .map(|&x| re(x) * re(x))
                .sum();
            if s > best {
                best = s;
                p = col;
            }
        }
        if p != j {
            let (left, right) = d.split_at_mut(p * nr);
            left[j * nr..(j + 1) * nr].swap_with_slice(&mut right[..nr]);
            perm.swap(j, p);
        }
        let (left, right) = d.split_at_mut((j + 1) * nr);
        let cj = &mut left[j * nr..];
        // Householder vector for column j, rows j..m.
        let mut sigma = S::zero();
        for &x in &cj[j + 1..m] {
            sigma += x * x;
        }
        let x0 = cj[j];
        let norm_re = (re(x0) * re(x0) + re(sigma)).sqrt();
        if j == 0 {
            r00 = norm_re;
        }
        if rank == k && (norm_re == 0.0 || norm_re <= tol * r00) {
            rank = j;
        }
        if norm_re == 0.0 {
            beta[j] = S::zero();
            continue;
        }
        let norm = (x0 * x0 + sigma).sqrt();
        // v0 = x0 - alpha, alpha = -sign(x0) * norm: no cancellation.
        let alpha = if re(x0) >= 0.0 { -norm } else { norm };
        let v0 = x0 - alpha;
        // Scale w = v / v0 so that w_0 = 1; beta = -v0 / alpha.
        let inv_v0 = v0.recip();
        for x in &mut cj[j + 1..m] {
            *x *= inv_v0;
        }
        beta[j] = -v0 / alpha;
        cj[j] = alpha;
        // Apply H_j to the remaining columns.
        let w = &cj[j + 1..m];
        for cc in right.chunks_exact_mut(nr).take(k - j - 1) {
            let mut s = cc[j];
            for (&wi, &x) in w.iter().zip(&cc[j + 1..m]) {
                s += wi * x;
            }
            s *= beta[j];
            cc[j] -= s;
            for (&wi, x) in w.iter().zip(&mut cc[j + 1..m]) {
                *x -= s * wi;
            }
        }
    }
    rank
}

/// y <- Q^T y for the leading `m` entries of a vector, with the reflectors of [`qr_colpiv`].
pub fn qr_apply_qt<S: Scalar>(qr: &DMatrix<S>, m: usize, k: usize, beta: &[S], y: &mut [S]) {
    for j in 0..k {
        reflect(qr, m, j, beta[j], y);
    }
}

/// y <- H_j y = y - beta_j w_j (w_j . y), w_j = (1, column j of `qr` below the diagonal).
#[inline]
fn reflect<S: Scalar>(qr: &DMatrix<S>, m: usize, j: usize, beta: S, y: &mut [S]) {
    if beta == S::zero() {
        return;
    }
    let ld = qr.nrows();
    let w = &qr.as_slice()[j * ld + j + 1..j * ld + m];
    let (head, tail) = y[j..m].split_at_mut(1);
    let mut s = head[0];
    for (&wi, &yi) in w.iter().zip(tail.iter()) {
        s += wi * yi;
    }
    s *= beta;
    head[0] -= s;
    for (&wi, yi) in w.iter().zip(tail.iter_mut()) {
        *yi -= s * wi;
    }
}

/// y <- Q y (the inverse of [`qr_apply_qt`]).
pub fn qr_apply_q<S: Scalar>(qr: &DMatrix<S>, m: usize, k: usize, beta: &[S], y: &mut [S]) {
    for j in (0..k).rev() {
        reflect(qr, m, j, beta[j], y);
    }
}

/// The first `ncols` columns of M <- Q^T M, for an `m`-row matrix M (reflectors of [`qr_colpiv`]).
pub fn qr_apply_qt_mat<S: Scalar>(
    qr: &DMatrix<S>,
    m: usize,
    k: usize,
    beta: &[S],
    mat: &mut DMatrix<S>,
    ncols: usize,
) {
    let (ldq, ldm) = (qr.nrows(), mat.nrows());
    let q = qr.as_slice();
    let md = mat.as_mut_slice();
    for j in 0..k {
        if beta[j] == S::zero() {
            continue;
        }
        let w = &q[j * ldq + j + 1..j * ldq + m];
        for col in 0..ncols {
            let c = &mut md[col * ldm..col * ldm + m];
            let s = (c[j] + dot(w, &c[j + 1..m])) * beta[j];
            c[j] -= s;
            axpy_neg(s, w, &mut c[j + 1..m]);
        }
    }
}

/// The first `nrows` rows of M <- M Q, for a matrix M with `m` columns (reflectors of
/// [`qr_colpiv`]); `v` is scratch of length `nrows`.
pub fn qr_apply_q_right<S: Scalar>(
    qr: &DMatrix<S>,
    m: usize,
    k: usize,
    beta: &[S],
    mat: &mut DMatrix<S>,
    nrows: usize,
    v: &mut [S],
) {
    let (ldq, ldm) = (qr.nrows(), mat.nrows());
    let q = qr.as_slice();
    let md = mat.as_mut_slice();
    let v = &mut v[..nrows];
    // M Q = M H_0 H_1 ... H_{k-1}; M H_j = M - beta_j (M w_j) w_j^T.
    for j in 0..k {
        if beta[j] == S::zero() {
            continue;
        }
        let w = &q[j * ldq..j * ldq + m];
        v.copy_from_slice(&md[j * ldm..j * ldm + nrows]);
        for i in j + 1..m {
            let wi = w[i];
            for (vr, &x) in v.iter_mut().zip(&md[i * ldm..i * ldm + nrows]) {
                *vr += wi * x;
            }
        }
        for x in v.iter_mut() {
            *x *= beta[j];
        }
        axpy_neg(S::one(), v, &mut md[j * ldm..j * ldm + nrows]);
        for i in j + 1..m {
            axpy_neg(w[i], v, &mut md[i * ldm..i * ldm + nrows]);
        }
    }
}

/// Solve R x = b (R the leading `k x k` upper triangle of `qr`) in place.
pub fn solve_upper<S: Scalar>(qr: &DMatrix<S>, k: usize, b: &mut [S]) {
    let (ld, r) = (qr.nrows(), qr.as_slice());
    for i in (0..k).rev() {
        let mut s = b[i];
        for j in i + 1..k {
            s -= r[j * ld + i] * b[j];
        }
        b[i] = s / r[i * ld + i];
    }
}

/// Solve R^T x = b (R the leading `k x k` upper triangle of `qr`) in place.
pub fn solve_upper_t<S: Scalar>(qr: &DMatrix<S>, k: usize, b: &mut [S]) {
    let (ld, r) = (qr.nrows(), qr.as_slice());
    for i in 0..k {
        let col = &r[i * ld..i * ld + i];
        let mut s = b[i];
        for (&rj, &bj) in col.iter().zip(&b[..i]) {
            s -= rj * bj;
        }
        b[i] = s / r[i * ld + i];
    }
}

/// In-place Cholesky A = L L^T of the leading `n x n` block (lower triangle overwritten by L;
/// right-looking, column by column; the upper triangle is not touched).
pub fn cholesky<S: Scalar>(a: &mut DMatrix<S>, n: usize) -> Result<(), Singular> {
    let ld = a.nrows();
    let data = a.as_mut_slice();
    for j in 0..n {
        let d = data[j * ld + j];
        if re(d) <= 0.0 || !re(d).is_finite() {
            return Err(Singular {
                column: j,
                rcond: 0.0,
            });
        }
        let l = d.sqrt();
        data[j * ld + j] = l;
        let inv = l.recip();
        for x in &mut data[j * ld + j + 1..j * ld + n] {
            *x *= inv;
        }
        for k in j + 1..n {
            let (colj, colk) = two_columns(data, ld, j, k);
            let akj = colj[k];
            axpy_neg(akj, &colj[k..n], &mut colk[k..n]);
        }
    }
    Ok(())
}

/// Solve L L^T x = b in place, L the lower triangle of the leading `n x n` block of `l`
/// (as left by [`cholesky`]).
pub fn cholesky_solve<S: Scalar>(l: &DMatrix<S>, n: usize, b: &mut [S]) {
    lower_solve(l, n, b);
    lower_t_solve(l, n, b);
}

/// Solve L y = b in place (L the lower triangle of the leading `n x n` block), column-oriented.
pub fn lower_solve<S: Scalar>(l: &DMatrix<S>, n: usize, b: &mut [S]) {
    let ld = l.nrows();
    let data = l.as_slice();
    for j in 0..n {
        b[j] /= data[j * ld + j];
        let bj = b[j];
        axpy_neg(bj, &data[j * ld + j + 1..j * ld + n], &mut b[j + 1..n]);
    }
}

/// Solve L^T x = b in place (L as in [`lower_solve`]).
pub fn lower_t_solve<S: Scalar>(l: &DMatrix<S>, n: usize, b: &mut [S]) {
    let ld = l.nrows();
    let data = l.as_slice();
    for j in (0..n).rev() {
        let col = &data[j * ld + j + 1..j * ld + n];
        b[j] = (b[j] - dot(col, &b[j + 1..n])) / data[j * ld + j];
    }
}

/// Explicit inverse of an LU-factored matrix into `inv` (column by column); `col` is scratch of length n.
pub fn lu_inverse<S: Scalar>(
    lu: &DMatrix<S>,
    n: usize,
    piv: &[usize],
    inv: &mut DMatrix<S>,
    col: &mut [S],
) {
    for j in 0..n {
        for (i, x) in col.iter_mut().enumerate().take(n) {
            *x = if i == j { c(1.0) } else { S::zero() };
        }
        lu_solve(lu, n, piv, &mut col[..n]);
        for i in 0..n {
            inv[(i, j)] = col[i];
        }
    }
}

/// Eigen-decomposition of the symmetric n x n block of `a` by cyclic Jacobi rotations (Golub & Van
/// Loan, Matrix Computations, 4th ed., Alg. 8.5.3), in place: on return the diagonal of `a` holds
/// the eigenvalues and the columns of `v` the eigenvectors. Allocates nothing; f64 only (it serves
/// diagnostics, not derivatives). Returns the index of the smallest eigenvalue.
pub fn sym_eigen(a: &mut DMatrix<f64>, n: usize, v: &mut DMatrix<f64>) -> usize {
    for i in 0..n {
        for j in 0..n {
            v[(i, j)] = if i == j { 1.0 } else { 0.0 };
        }
    }
    for _sweep in 0..50 {
        let mut off = 0.0;
        let mut diag = 0.0;
        for i in 0..n {
            diag += a[(i, i)] * a[(i, i)];
            for j in i + 1..n {
                off += a[(i, j)] * a[(i, j)];
            }
        }
        if off <= f64::EPSILON * f64::EPSILON * diag || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[(p, q)];
                if apq == 0.0 {
                    continue;
                }
                // Rotation that zeroes a[p][q]: tan(2 theta) = 2 a_pq / (a_qq - a_pp).
                let tau = (a[(q, q)] - a[(p, p)]) / (2.0 * apq);
                let t = tau.signum() / (tau.abs() + (1.0 + tau * tau).sqrt());
                let t = if tau == 0.0 { 1.0 } else { t };
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[(k, p)], a[(k, q)]);
                    a[(k, p)] = c * akp - s * akq;
                    a[(k, q)] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[(p, k)], a[(q, k)]);
                    a[(p, k)] = c * apk - s * aqk;
                    a[(q, k)] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[(k, p)], v[(k, q)]);
                    v[(k, p)] = c * vkp - s * vkq;
                    v[(k, q)] = s * vkp + c * vkq;
                }
            }
        }
    }
    (0..n)
        .min_by(|&i, &j| a[(i, i)].total_cmp(&a[(j, j)]))
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_matrix(m: usize, k: usize, seed: u64) -> DMatrix<f64> {
        let mut s = seed;
        DMatrix::from_fn(m, k, |_, _| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        })
    }

    #[test]
    fn lu_solves_against_nalgebra() {
        let n = 7;
        let a0 = test_matrix(n, n, 3);
        let b0: Vec<f64> = (0..n).map(|i| i as f64 - 2.0).collect();
        let mut a = a0.clone();
        let mut piv = vec![0; n];
        lu_factor(&mut a, n, &mut piv, 0.0).unwrap();
        let mut x = b0.clone();
        lu_solve(&a, n, &piv, &mut x);
        let r = &a0 * nalgebra::DVector::from_vec(x) - nalgebra::DVector::from_vec(b0);
        assert!(r.amax() < 50.0 * f64::EPSILON, "residual {}", r.amax());
    }

    /// The same LU over complex numbers (Radau IIA's E2), pivoting by modulus: a matrix whose
    /// first column has its largest real part and its largest modulus in different rows.
    #[test]
    fn lu_solves_complex_systems_pivoting_by_modulus() {
        let n = 6;
        let (re, im) = (test_matrix(n, n, 5), test_matrix(n, n, 9));
        let mut a0 = DMatrix::from_fn(n, n, |i, j| Complex::new(re[(i, j)], im[(i, j)]));
        a0[(0, 0)] = Complex::new(0.6, 0.0);
        a0[(1, 0)] = Complex::new(0.1, 2.0);
        let b0: Vec<Complex<f64>> = (0..n).map(|i| Complex::new(i as f64, 1.0)).collect();
        let mut a = a0.clone();
        let mut piv = vec![0; n];
        lu_factor_with::<_, Modulus>(&mut a, n, &mut piv, 0.0).unwrap();
        assert_eq!(piv[0], 1, "pivot of largest modulus");
        let mut x = b0.clone();
        lu_solve(&a, n, &piv, &mut x);
        let r = &a0 * nalgebra::DVector::from_vec(x) - nalgebra::DVector::from_vec(b0);
        let worst = r.iter().map(|z| z.norm()).fold(0.0, f64::max);
        assert!(worst < 50.0 * f64::EPSILON, "residual {worst}");
        let mut singular = DMatrix::from_element(2, 2, Complex::new(1.0, 1.0));
        assert!(lu_factor_with::<_, Modulus>(&mut singular, 2, &mut piv, 0.0).is_err());
    }

    #[test]
    fn lu_reports_singular() {
        let mut a = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 4.0]);
        let mut piv = vec![0; 2];
        assert!(lu_factor(&mut a, 2, &mut piv, 1e-12).is_err());
    }

    #[test]
    fn qr_reconstructs_and_gives_null_space() {
        let (m, k) = (6, 3);
        let a0 = test_matrix(m, k, 11);
        let mut a = a0.clone();
        let mut beta = vec![0.0; k];
        let mut perm = vec![0; k];
        let rank = qr_colpiv(&mut a, m, k, &mut beta, &mut perm, 1e-12);
        assert_eq!(rank, k);
        // Q^T A P = R: apply Q^T to the permuted columns of A0.
        let mut ap = DMatrix::zeros(m, k);
        for j in 0..k {
            ap.set_column(j, &a0.column(perm[j]));
        }
        qr_apply_qt_mat(&a, m, k, &beta, &mut ap, k);
        for i in 0..m {
            for j in 0..k {
                let expect = if i <= j { a[(i, j)] } else { 0.0 };
                assert!((ap[(i, j)] - expect).abs() < 20.0 * f64::EPSILON);
            }
        }
        // The last m - k columns of Q are orthogonal to range(A0).
        for l in k..m {
            let mut e = vec![0.0; m];
            e[l] = 1.0;
            qr_apply_q(&a, m, k, &beta, &mut e);
            let d = a0.transpose() * nalgebra::DVector::from_vec(e);
            assert!(d.amax() < 20.0 * f64::EPSILON);
        }
    }

    #[test]
    fn qr_reveals_rank() {
        let (m, k) = (5, 3);
        let mut a0 = test_matrix(m, k, 5);
        let c0 = a0.column(0).clone_owned();
        let c1 = a0.column(1).clone_owned();
        a0.set_column(2, &(c0 * 2.0 - c1));
        let mut a = a0.clone();
        let mut beta = vec![0.0; k];
        let mut perm = vec![0; k];
        assert_eq!(qr_colpiv(&mut a, m, k, &mut beta, &mut perm, 1e-10), 2);
    }

    #[test]
    fn cholesky_and_inverse() {
        let n = 5;
        let b = test_matrix(n, n, 7);
        let a0 = &b * b.transpose() + DMatrix::identity(n, n);
        let mut l = a0.clone();
        cholesky(&mut l, n).unwrap();
        let lo = l.lower_triangle();
        assert!((&lo * lo.transpose() - &a0).amax() < 50.0 * f64::EPSILON);
        let mut lu = a0.clone();
        let mut piv = vec![0; n];
        lu_factor(&mut lu, n, &mut piv, 0.0).unwrap();
        let mut inv = DMatrix::zeros(n, n);
        let mut col = vec![0.0; n];
        lu_inverse(&lu, n, &piv, &mut inv, &mut col);
        assert!((&inv * &a0 - DMatrix::identity(n, n)).amax() < 1e-13);
    }

    #[test]
    fn jacobi_eigen_against_nalgebra() {
        let n = 5;
        let b = test_matrix(n, n, 13);
        let a0 = &b * b.transpose();
        let mut a = a0.clone();
        let mut v = DMatrix::zeros(n, n);
        let k = sym_eigen(&mut a, n, &mut v);
        let mut ours: Vec<f64> = (0..n).map(|i| a[(i, i)]).collect();
        let mut theirs: Vec<f64> = a0.clone().symmetric_eigenvalues().iter().cloned().collect();
        assert_eq!(
            ours.iter().cloned().fold(f64::INFINITY, f64::min),
            a[(k, k)]
        );
        ours.sort_by(f64::total_cmp);
        theirs.sort_by(f64::total_cmp);
        for (x, y) in ours.iter().zip(&theirs) {
            assert!(
                (x - y).abs() < 100.0 * f64::EPSILON * theirs[n - 1],
                "{x} vs {y}"
            );
        }
        // A v_k = lambda_k v_k
        let vk = v.column(k).clone_owned();
        let r = &a0 * &vk - vk * a[(k, k)];
        assert!(r.amax() < 100.0 * f64::EPSILON * theirs[n - 1]);
    }
}
