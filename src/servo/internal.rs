//! Internal (zero) dynamics of a servo programme (issue 17): what the actuators leave free.
//!
//! The hidden constraints h = (y_i^(k), k < r_i) fix sum r_i of the 2n state coordinates; the
//! remaining 2n - sum r_i move on their own along the manifold h = 0 (Isidori, Nonlinear Control
//! Systems, 3rd ed. (1995), Sec. 5.1 and 6.1: normal form and zero dynamics). A system is *flat*
//! with these outputs when that dimension is 0 (two_car_chain); otherwise the programme is
//! realizable open-loop only if the internal dynamics does not amplify errors faster than the
//! horizon allows.
//!
//! Linearization at a state: the closed-loop field x' = f_cl(t, x) = (v, A^-1 (F + H tau(t, x))),
//! tau = -b^-1 a ([`Servo::solve`]), has the exact Jacobian J = df_cl/dx (one dual pass per state
//! coordinate through the whole decoupling). With N an orthonormal basis of the tangent space
//! null(dh/dx) (dh/dx exact by duals, as [`Servo::project`] uses), the internal dynamics' matrix is
//! N^T J N (dimension 2n - sum r_i). Its eigenvalues are *frozen-time* values: exact for a
//! stationary programme at rest (J then maps the tangent space into itself), an indicator
//! otherwise (a time-varying linear system can grow with all frozen eigenvalues in the left half
//! plane); the growth actually seen is measured separately by a perturbed run
//! (`Scene::servo_report`).

use super::Servo;
use crate::linalg;
use crate::model::Model;
use crate::programme::Constraints;
use crate::scalar::Dual;
use nalgebra::DMatrix;
use num_dual::Dual64;

/// One eigenvalue (re, im) of the internal dynamics' linearization.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Eigenvalue {
    pub re: f64,
    pub im: f64,
}

/// The internal dynamics' linearization at one state.
#[derive(Clone, Debug, PartialEq)]
pub struct Linearization {
    /// Orthonormal basis of the tangent space of h = 0 (2n x d, d = 2n - sum r_i).
    pub basis: DMatrix<f64>,
    /// N^T J N (d x d).
    pub matrix: DMatrix<f64>,
    /// Its eigenvalues, largest real part first.
    pub eigenvalues: Vec<Eigenvalue>,
}

impl<M: Model, C: Constraints> Servo<'_, M, C> {
    /// dh/dx (rows: the hidden constraints in [`Servo::hidden`] order; columns: q then v), exact.
    pub fn hidden_jacobian(
        &self,
        t: f64,
        q: &[f64],
        v: &[f64],
        degrees: &[usize],
    ) -> Result<DMatrix<f64>, linalg::Singular> {
        let n = v.len();
        let mut hd: Vec<Dual64> = vec![];
        let nh = self.hidden_names(degrees).len();
        let mut jac = DMatrix::zeros(nh, 2 * n);
        for c in 0..2 * n {
            let (qd, vd) = seeded(q, v, c);
            self.hidden(Dual::from_re(t), &qd, &vd, degrees, &mut hd)?;
            for (r, x) in hd.iter().enumerate() {
                jac[(r, c)] = x.eps;
            }
        }
        Ok(jac)
    }

    /// J = d f_cl / d(q, v) of the closed-loop field f_cl = (v, A^-1 (F + H tau)), exact.
    pub fn closed_loop_jacobian(
        &self,
        t: f64,
        q: &[f64],
        v: &[f64],
        degrees: &[usize],
        b_norms: &[f64],
        rank_tol: f64,
    ) -> Result<DMatrix<f64>, linalg::Singular> {
        let n = v.len();
        let (_, m) = self.dims();
        let mut jac = DMatrix::zeros(2 * n, 2 * n);
        let mut tau = vec![Dual64::from_re(0.0); m];
        let mut acc = vec![Dual64::from_re(0.0); n];
        for c in 0..2 * n {
            let (qd, vd) = seeded(q, v, c);
            self.solve(
                Dual::from_re(t),
                &qd,
                &vd,
                degrees,
                b_norms,
                rank_tol,
                &mut tau,
                &mut acc,
            )?;
            if c >= n {
                jac[(c - n, c)] = 1.0; // dq'/dv = I
            }
            for i in 0..n {
                jac[(n + i, c)] = acc[i].eps;
            }
        }
        Ok(jac)
    }

    /// The internal dynamics' linearization at (t, q, v) (module docs). A flat programme
    /// (sum r_i = 2n) gives an empty matrix.
    pub fn internal_linearization(
        &self,
        t: f64,
        q: &[f64],
        v: &[f64],
        degrees: &[usize],
        b_norms: &[f64],
        rank_tol: f64,
    ) -> Result<Linearization, linalg::Singular> {
        let n = v.len();
        let dh = self.hidden_jacobian(t, q, v, degrees)?;
        let basis = tangent_basis(&dh, 2 * n);
        let j = self.closed_loop_jacobian(t, q, v, degrees, b_norms, rank_tol)?;
        let matrix = basis.transpose() * &j * &basis;
        let eigenvalues = eigenvalues(&matrix);
        Ok(Linearization {
            basis,
            matrix,
            eigenvalues,
        })
    }
}

/// (q, v) as dual numbers with coordinate c (q first, then v) seeded.
fn seeded(q: &[f64], v: &[f64], c: usize) -> (Vec<Dual64>, Vec<Dual64>) {
    let n = v.len();
    let qd = (0..q.len())
        .map(|i| Dual::new(q[i], if c == i { 1.0 } else { 0.0 }))
        .collect();
    let vd = (0..n)
        .map(|i| Dual::new(v[i], if c == n + i { 1.0 } else { 0.0 }))
        .collect();
    (qd, vd)
}

/// Orthonormal basis of null(dh) (dim - rows columns, dh of full row rank): the eigenvectors of
/// dh^T dh (symmetric, dim x dim) with the smallest eigenvalues.
pub fn tangent_basis(dh: &DMatrix<f64>, dim: usize) -> DMatrix<f64> {
    let d = dim - dh.nrows().min(dim);
    if d == 0 {
        return DMatrix::zeros(dim, 0);
    }
    let gram = dh.transpose() * dh;
    let eig = nalgebra::SymmetricEigen::new(gram);
    let mut order: Vec<usize> = (0..dim).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    DMatrix::from_fn(dim, d, |i, k| eig.eigenvectors[(i, order[k])])
}

/// Eigenvalues of a real square matrix (real Schur form), largest real part first.
pub fn eigenvalues(m: &DMatrix<f64>) -> Vec<Eigenvalue> {
    if m.nrows() == 0 {
        return vec![];
    }
    let mut out: Vec<Eigenvalue> = m
        .clone()
        .complex_eigenvalues()
        .iter()
        .map(|z| Eigenvalue { re: z.re, im: z.im })
        .collect();
    out.sort_by(|a, b| b.re.total_cmp(&a.re).then(b.im.total_cmp(&a.im)));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigenvalues_of_a_damped_oscillator_are_its_roots() {
        // x'' + 2 zeta w x' + w^2 x = 0: roots -zeta w +- i w sqrt(1 - zeta^2).
        let (w, zeta) = (3.0f64, 0.2f64);
        let m = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -w * w, -2.0 * zeta * w]);
        let e = eigenvalues(&m);
        let wd = w * (1.0 - zeta * zeta).sqrt();
        assert!((e[0].re + zeta * w).abs() < 1e-12 && (e[0].im - wd).abs() < 1e-12);
        assert!((e[1].re + zeta * w).abs() < 1e-12 && (e[1].im + wd).abs() < 1e-12);
    }

    #[test]
    fn the_tangent_basis_is_orthonormal_and_annihilated() {
        let dh = DMatrix::from_row_slice(2, 4, &[1.0, 2.0, 0.0, -1.0, 0.0, 1.0, 1.0, 3.0]);
        let n = tangent_basis(&dh, 4);
        assert_eq!(n.shape(), (4, 2));
        assert!((&dh * &n).amax() < 1e-13);
        assert!((n.transpose() * &n - DMatrix::identity(2, 2)).amax() < 1e-13);
    }
}
