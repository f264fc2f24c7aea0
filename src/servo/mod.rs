//! Servo-constraints: a programme realized by given actuators, u = H tau (issue 17).
//!
//! The ideal realization (Do Sanh 1998, (2.7)) lets the control force act along every programme
//! gradient, u in range(B^T). Real machines push on given joints: A dv/dt - F = H tau with H the
//! n x m actuation map (here: unit columns of the actuated joints' velocities). The programme rows
//! are then *servo-constraints* (Blajer & Kolodziejczyk, Multibody Syst. Dyn. 11 (2004) 343-364):
//! - orthogonal realization: range(H) = range(B^T) (the ideal case);
//! - tangential: B A^-1 H = 0 (tau does not reach the programme at acceleration level);
//! - mixed: otherwise.
//!
//! Each row y_i = g_i(t, q, v[, dv/dt]) is differentiated along the motion until tau appears
//! (Isidori, Nonlinear Control Systems, 3rd ed. (1995), Sec. 5.1, relative degree): with the flow
//! x' = f(t, x; tau) = (v, A^-1 (F + H tau)),
//!   y_i^(k) = L_f^k g_i           free of tau for k < r_i,
//!   y_i^(r_i) = a_i(x) + b_i(x) tau,
//! with the decoupling matrix b (rows b_i, s x m). Holding tau constant in the Lie derivatives is
//! exact up to k = r_i: a derivative of tau would only enter beyond the relative degree. The
//! index-reduced system is tau = -b^-1 a, dv/dt = A^-1 (F + H tau); the hidden constraints
//! y_i = ... = y_i^(r_i - 1) = 0 are kept by projection after every step ([`ServoProjector`]). The
//! differentiation index of the DAE (A dv/dt - F = H tau, g = 0) is max_i r_i + 1 (tau itself needs
//! one more differentiation).
//!
//! Derivatives are exact: L^k g is evaluated by nesting k first-order dual numbers, each level
//! seeded with the flow, (t, q, v) + eps (1, v, a) (Euclidean coordinates only: q' = v). b comes
//! from one more dual level seeded on tau. Cost grows as 3^(k+1) model evaluations; k <= 5 here.

use crate::linalg;
use crate::model::{Model, Segment};
use crate::programme::{jet::Jet, Constraints};
use crate::scalar::{re, Dual, Scalar};
use nalgebra::DMatrix;
use num_dual::Dual64;

pub mod internal;

/// Highest relative degree searched (index 6).
pub const MAX_RELATIVE_DEGREE: usize = 5;

/// A row's derivative b_i (at the order it first appears) counts as reaching tau when its largest
/// entry exceeds this fraction of the largest such entry over all orders k <= MAX_RELATIVE_DEGREE:
/// terms that cancel analytically (tau entering two coordinates whose sum the row reads) leave
/// round-off, about 1e-16 of their size.
pub const DEGREE_TOL: f64 = 1e-8;

/// Which joint velocities the actuators drive: H = [e_dofs[0], e_dofs[1], ...] (n x m).
#[derive(Clone, Debug, PartialEq)]
pub struct Actuation {
    /// Actuator names (for messages and outputs), in file order.
    pub names: Vec<String>,
    /// The velocity index each actuator's generalized force acts on.
    pub dofs: Vec<usize>,
}

/// The realization of a programme by the actuators at a state (Blajer & Kolodziejczyk 2004).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Realization {
    /// range(H) = range(B^T): the ideal realization.
    Orthogonal,
    /// B A^-1 H = 0: tau reaches the programme only through higher derivatives.
    Tangential,
    /// Neither.
    Mixed,
}

impl Realization {
    /// Machine name.
    pub fn name(self) -> &'static str {
        match self {
            Realization::Orthogonal => "orthogonal",
            Realization::Tangential => "tangential",
            Realization::Mixed => "mixed",
        }
    }
}

/// What the analysis at a state found.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Analysis {
    /// Relative degree r_i of each programme row.
    pub degrees: Vec<usize>,
    /// Differentiation index of the servo DAE: max r_i + 1.
    pub index: usize,
    /// Realization at the state.
    pub realization: Realization,
    /// Pivot-ratio estimate of the decoupling matrix b.
    pub rcond: f64,
    /// |b_i| (largest entry) of each row at the state: the reference of the vanishing-row test
    /// along the motion ([`Servo::decoupling`]).
    pub b_norms: Vec<f64>,
}

/// Why the actuators cannot realize the programme.
#[derive(Clone, Debug, PartialEq)]
pub enum Unrealizable {
    /// No actuator reaches these rows within [`MAX_RELATIVE_DEGREE`] derivatives.
    NotReached { rows: Vec<usize> },
    /// The decoupling matrix b is singular (pivot ratio `rcond`).
    Singular { rcond: f64 },
    /// The model's mass matrix is singular, or a value is not finite.
    Model,
}

/// The model, its rows and the actuation, as the Lie derivatives need them.
pub struct Servo<'a, M: Model, C: Constraints> {
    model: &'a M,
    cons: &'a C,
    act: &'a Actuation,
    has_acc_rows: bool,
}

type LieFn<M, C, T> =
    fn(&Servo<'_, M, C>, T, &[T], &[T], &[T], &mut [T]) -> Result<(), linalg::Singular>;

impl<'a, M: Model, C: Constraints> Servo<'a, M, C> {
    /// For a model with Euclidean coordinates only (checked by the scene loader).
    pub fn new(model: &'a M, cons: &'a C, act: &'a Actuation) -> Self {
        debug_assert!(model
            .segments()
            .iter()
            .all(|s| matches!(s, Segment::Euclidean { .. })));
        Servo {
            model,
            cons,
            act,
            has_acc_rows: cons
                .rows()
                .iter()
                .any(|r| r.level == crate::programme::Level::Acceleration),
        }
    }

    /// Number of rows s and actuators m.
    pub fn dims(&self) -> (usize, usize) {
        (self.cons.rows().len(), self.act.dofs.len())
    }

    /// dv/dt = A^-1 (F + H tau) (2.2 with u = H tau).
    pub fn accel<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        out: &mut [T],
    ) -> Result<(), linalg::Singular> {
        let n = self.model.nv();
        let mut ws = self.model.workspace::<T>();
        let mut a = DMatrix::from_element(n, n, T::zero());
        self.model.mass_matrix(&mut ws, q, &mut a);
        let mut scratch = vec![T::zero(); n];
        self.model
            .natural_forces(&mut ws, t, q, v, out, &mut scratch);
        for (j, &d) in self.act.dofs.iter().enumerate() {
            out[d] += tau[j];
        }
        linalg::cholesky(&mut a, n)?;
        linalg::cholesky_solve(&a, n, out);
        Ok(())
    }

    /// The rows at (t, q, v) with dv/dt from tau (k = 0).
    fn rows_at<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        out: &mut [T],
    ) -> Result<(), linalg::Singular> {
        let mut acc = vec![T::zero(); v.len()];
        if self.has_acc_rows {
            self.accel(t, q, v, tau, &mut acc)?;
        }
        let mut ws = self.cons.workspace::<T>();
        self.cons.eval(&mut ws, t, q, v, &acc, out);
        Ok(())
    }

    /// One Lie derivative: d/dt of `inner` along (1, v, a) at constant tau, by one dual level.
    fn step<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        out: &mut [T],
        inner: LieFn<M, C, Dual<T>>,
    ) -> Result<(), linalg::Singular> {
        let n = v.len();
        let mut a = vec![T::zero(); n];
        self.accel(t, q, v, tau, &mut a)?;
        let td = Dual::new(t, T::one());
        let qd: Vec<Dual<T>> = (0..n).map(|i| Dual::new(q[i], v[i])).collect();
        let vd: Vec<Dual<T>> = (0..n).map(|i| Dual::new(v[i], a[i])).collect();
        let taud: Vec<Dual<T>> = tau.iter().map(|&x| Dual::from_re(x)).collect();
        let mut o = vec![Dual::from_re(T::zero()); out.len()];
        inner(self, td, &qd, &vd, &taud, &mut o)?;
        for (x, d) in out.iter_mut().zip(&o) {
            *x = d.eps;
        }
        Ok(())
    }

    /// y^(k) = L^k g of every row at (t, q, v) with constant tau, k <= [`MAX_RELATIVE_DEGREE`].
    pub fn lie<T: Scalar>(
        &self,
        k: usize,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        out: &mut [T],
    ) -> Result<(), linalg::Singular> {
        match k {
            0 => lie0(self, t, q, v, tau, out),
            1 => lie1(self, t, q, v, tau, out),
            2 => lie2(self, t, q, v, tau, out),
            3 => lie3(self, t, q, v, tau, out),
            4 => lie4(self, t, q, v, tau, out),
            5 => lie5(self, t, q, v, tau, out),
            _ => panic!("relative degree {k} beyond MAX_RELATIVE_DEGREE (checked by the caller)"),
        }
    }

    /// y^(k) and d y^(k) / d tau at (t, q, v, tau): value into `val`, s x m derivative into `db`.
    #[allow(clippy::too_many_arguments)]
    pub fn lie_tau<T: Scalar>(
        &self,
        k: usize,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        val: &mut [T],
        db: &mut DMatrix<T>,
    ) -> Result<(), linalg::Singular> {
        let (s, m) = self.dims();
        let n = v.len();
        let td = Dual::from_re(t);
        let qd: Vec<Dual<T>> = q.iter().map(|&x| Dual::from_re(x)).collect();
        let vd: Vec<Dual<T>> = v.iter().map(|&x| Dual::from_re(x)).collect();
        let mut o = vec![Dual::from_re(T::zero()); s];
        debug_assert_eq!(qd.len(), n);
        for j in 0..m {
            let taud: Vec<Dual<T>> = (0..m)
                .map(|l| Dual::new(tau[l], if l == j { T::one() } else { T::zero() }))
                .collect();
            self.lie(k, td, &qd, &vd, &taud, &mut o)?;
            for i in 0..s {
                db[(i, j)] = o[i].eps;
                val[i] = o[i].re;
            }
        }
        Ok(())
    }

    /// Relative degrees, index, realization and the decoupling matrix's conditioning at a state.
    pub fn analyse(
        &self,
        t: f64,
        q: &[f64],
        v: &[f64],
        rank_tol: f64,
    ) -> Result<Analysis, Unrealizable> {
        let (s, m) = self.dims();
        let tau = vec![0.0; m];
        let mut val = vec![0.0; s];
        let mut bk = vec![DMatrix::zeros(s, m); MAX_RELATIVE_DEGREE + 1];
        for (k, b) in bk.iter_mut().enumerate() {
            self.lie_tau(k, t, q, v, &tau, &mut val, b)
                .map_err(|_| Unrealizable::Model)?;
        }
        let norm = |b: &DMatrix<f64>, i: usize| (0..m).map(|j| b[(i, j)].abs()).fold(0.0, f64::max);
        let mut degrees = vec![0; s];
        let mut missing = vec![];
        for i in 0..s {
            let big = bk.iter().map(|b| norm(b, i)).fold(0.0, f64::max);
            if !big.is_finite() {
                return Err(Unrealizable::Model);
            }
            match (0..=MAX_RELATIVE_DEGREE)
                .find(|&k| big > 0.0 && norm(&bk[k], i) > DEGREE_TOL * big)
            {
                Some(k) => degrees[i] = k,
                None => missing.push(i),
            }
        }
        if !missing.is_empty() {
            return Err(Unrealizable::NotReached { rows: missing });
        }
        let b_norms: Vec<f64> = (0..s).map(|i| norm(&bk[degrees[i]], i)).collect();
        let rcond = self
            .decoupling(t, q, v, &degrees, &b_norms, rank_tol)
            .map(|d| d.rcond)
            .map_err(|e| Unrealizable::Singular { rcond: e.rcond })?;
        let index = degrees.iter().copied().max().unwrap_or(0) + 1;
        Ok(Analysis {
            degrees,
            index,
            realization: self.realization(t, q, v),
            rcond,
            b_norms,
        })
    }

    /// tau = -b^-1 a at (t, q, v) for the given relative degrees. A row of b whose largest entry
    /// falls below `rank_tol` times its reference `b_norms` (its t0 value), or an LU pivot ratio
    /// below `rank_tol`, is singular.
    pub fn decoupling<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        degrees: &[usize],
        b_norms: &[f64],
        rank_tol: f64,
    ) -> Result<Decoupled<T>, linalg::Singular> {
        let (s, m) = self.dims();
        debug_assert_eq!(s, m);
        let zero = vec![T::zero(); m];
        let mut b = DMatrix::from_element(s, m, T::zero());
        let mut rhs = vec![T::zero(); s];
        let mut val = vec![T::zero(); s];
        let mut db = DMatrix::from_element(s, m, T::zero());
        let mut ks: Vec<usize> = degrees.to_vec();
        ks.sort_unstable();
        ks.dedup();
        for &k in &ks {
            self.lie_tau(k, t, q, v, &zero, &mut val, &mut db)?;
            for i in (0..s).filter(|&i| degrees[i] == k) {
                rhs[i] = -val[i];
                for j in 0..m {
                    b[(i, j)] = db[(i, j)];
                }
            }
        }
        let (mut ratio, mut row) = (1.0f64, 0);
        for i in 0..s {
            let r = (0..m).map(|j| re(b[(i, j)]).abs()).fold(0.0, f64::max)
                / b_norms[i].max(f64::MIN_POSITIVE);
            if r < ratio || r.is_nan() {
                (ratio, row) = (r, i);
            }
        }
        if !(ratio >= rank_tol) {
            return Err(linalg::Singular {
                column: row,
                rcond: ratio,
            });
        }
        let mut piv = vec![0; s];
        let rcond = linalg::lu_factor(&mut b, s, &mut piv, rank_tol)?;
        linalg::lu_solve(&b, s, &piv, &mut rhs);
        Ok(Decoupled {
            tau: rhs,
            rcond,
            row_ratio: ratio,
            row,
        })
    }

    /// tau and dv/dt = A^-1 (F + H tau) of the index-reduced system at (t, q, v).
    #[allow(clippy::too_many_arguments)]
    pub fn solve<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        degrees: &[usize],
        b_norms: &[f64],
        rank_tol: f64,
        tau: &mut [T],
        acc: &mut [T],
    ) -> Result<Decoupled<T>, linalg::Singular> {
        let d = self.decoupling(t, q, v, degrees, b_norms, rank_tol)?;
        tau.copy_from_slice(&d.tau);
        self.accel(t, q, v, tau, acc)?;
        Ok(d)
    }

    /// Realization at (t, q, v): B = dg/dv of the programme rows against H (module docs).
    pub fn realization(&self, t: f64, q: &[f64], v: &[f64]) -> Realization {
        let (s, m) = self.dims();
        let n = v.len();
        let mut jet = Jet::<C, f64>::new(self.cons, self.model.segments(), q.len(), n);
        jet.compute(self.cons, self.model.segments(), t, q, v);
        let b = &jet.b;
        let bnorm = b.iter().fold(0.0f64, |x, y| x.max(y.abs()));
        // range(B^T) within range(H): B vanishes on the unactuated velocities; with s = m and both
        // of full rank the ranges are then equal.
        let unactuated = (0..n).filter(|j| !self.act.dofs.contains(j));
        let off = unactuated
            .flat_map(|j| (0..s).map(move |i| b[(i, j)].abs()))
            .fold(0.0f64, f64::max);
        if s == m && off <= 1e-12 * bnorm {
            return Realization::Orthogonal;
        }
        // B A^-1 H = 0: the columns A^-1 e_d of the actuated dofs.
        let mut ws = self.model.workspace::<f64>();
        let mut a = DMatrix::zeros(n, n);
        self.model.mass_matrix(&mut ws, q, &mut a);
        if linalg::cholesky(&mut a, n).is_err() {
            return Realization::Mixed;
        }
        let mut worst = 0.0f64;
        let mut scale = 0.0f64;
        for &d in &self.act.dofs {
            let mut col = vec![0.0; n];
            col[d] = 1.0;
            linalg::cholesky_solve(&a, n, &mut col);
            for i in 0..s {
                let x: f64 = (0..n).map(|j| b[(i, j)] * col[j]).sum();
                let terms: f64 = (0..n).map(|j| (b[(i, j)] * col[j]).abs()).sum();
                worst = worst.max(x.abs());
                scale = scale.max(terms);
            }
        }
        if worst <= 1e-12 * scale.max(f64::MIN_POSITIVE) {
            Realization::Tangential
        } else {
            Realization::Mixed
        }
    }

    /// The hidden constraints y_i^(k), k < r_i (row-major: row by row, k ascending), at tau = 0
    /// (they do not depend on tau).
    pub fn hidden<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        degrees: &[usize],
        out: &mut Vec<T>,
    ) -> Result<(), linalg::Singular> {
        let (s, m) = self.dims();
        let zero = vec![T::zero(); m];
        let kmax = degrees.iter().copied().max().unwrap_or(0);
        let mut by_k = vec![vec![T::zero(); s]; kmax];
        for (k, row) in by_k.iter_mut().enumerate() {
            self.lie(k, t, q, v, &zero, row)?;
        }
        out.clear();
        for i in 0..s {
            for row in by_k.iter().take(degrees[i]) {
                out.push(row[i]);
            }
        }
        Ok(())
    }

    /// Names of the hidden constraints, in the order of [`Servo::hidden`]: `row`, `row'`, ...,
    /// then `row (d^k/dt^k)` beyond the second derivative.
    pub fn hidden_names(&self, degrees: &[usize]) -> Vec<(usize, String)> {
        let mut out = vec![];
        for (i, r) in self.cons.rows().iter().enumerate() {
            for k in 0..degrees[i] {
                out.push((i, format!("{} (d^{k}/dt^{k}, hidden constraint)", r.name)));
            }
        }
        out
    }

    /// Project (q, v) onto the hidden constraints: Gauss-Newton steps of the least (Euclidean)
    /// correction, dx = -J^T (J J^T)^-1 h with J = dh/d(q, v) exact (one dual pass per coordinate).
    /// Returns (iterations, |dq|, |dv|, residual, index of the worst hidden constraint, converged).
    pub fn project(
        &self,
        t: f64,
        q: &mut [f64],
        v: &mut [f64],
        degrees: &[usize],
        tol: f64,
        max_iter: usize,
    ) -> ProjectOutcome {
        let n = v.len();
        let mut h = vec![];
        let mut hd: Vec<Dual64> = vec![];
        let mut out = ProjectOutcome::default();
        let (q0, v0) = (q.to_vec(), v.to_vec());
        for it in 0..=max_iter {
            if self.hidden(t, q, v, degrees, &mut h).is_err() {
                out.residual = f64::NAN;
                return out;
            }
            let (worst, at) = h.iter().enumerate().fold((0.0f64, 0), |w, (k, x)| {
                if x.abs() > w.0 || x.is_nan() {
                    (x.abs(), k)
                } else {
                    w
                }
            });
            out.residual = worst;
            out.row = at;
            if worst <= tol {
                out.converged = true;
                break;
            }
            if it == max_iter || worst.is_nan() {
                break;
            }
            let nh = h.len();
            let mut jac = DMatrix::zeros(nh, 2 * n);
            for c in 0..2 * n {
                let qd: Vec<Dual64> = (0..n)
                    .map(|i| Dual::new(q[i], if c == i { 1.0 } else { 0.0 }))
                    .collect();
                let vd: Vec<Dual64> = (0..n)
                    .map(|i| Dual::new(v[i], if c == n + i { 1.0 } else { 0.0 }))
                    .collect();
                if self
                    .hidden(Dual::from_re(t), &qd, &vd, degrees, &mut hd)
                    .is_err()
                {
                    out.residual = f64::NAN;
                    return out;
                }
                for (r, x) in hd.iter().enumerate() {
                    jac[(r, c)] = x.eps;
                }
            }
            let mut jjt = &jac * jac.transpose();
            if linalg::cholesky(&mut jjt, nh).is_err() {
                break;
            }
            let mut mu = h.clone();
            linalg::cholesky_solve(&jjt, nh, &mut mu);
            for c in 0..2 * n {
                let d: f64 = (0..nh).map(|r| jac[(r, c)] * mu[r]).sum();
                if c < n {
                    q[c] -= d;
                } else {
                    v[c - n] -= d;
                }
            }
            out.iterations += 1;
        }
        out.dq = q
            .iter()
            .zip(&q0)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        out.dv = v
            .iter()
            .zip(&v0)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        out
    }
}

/// The decoupling solved ([`Servo::decoupling`]).
#[derive(Clone, Debug)]
pub struct Decoupled<T> {
    /// tau = -b^-1 a.
    pub tau: Vec<T>,
    /// LU pivot ratio of b.
    pub rcond: f64,
    /// Smallest |b_i| / reference over the rows, and its row.
    pub row_ratio: f64,
    pub row: usize,
}

/// What [`Servo::project`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ProjectOutcome {
    pub iterations: usize,
    pub dq: f64,
    pub dv: f64,
    pub residual: f64,
    /// Index into [`Servo::hidden`] of the largest remaining residual.
    pub row: usize,
    pub converged: bool,
}

fn lie0<M: Model, C: Constraints, T: Scalar>(
    x: &Servo<'_, M, C>,
    t: T,
    q: &[T],
    v: &[T],
    tau: &[T],
    out: &mut [T],
) -> Result<(), linalg::Singular> {
    x.rows_at(t, q, v, tau, out)
}

// L^k g = d/dt (L^(k-1) g): each level adds one dual number (finite nesting: Rust cannot recurse
// over types at run time).
macro_rules! lie_level {
    ($name:ident, $inner:ident) => {
        fn $name<M: Model, C: Constraints, T: Scalar>(
            x: &Servo<'_, M, C>,
            t: T,
            q: &[T],
            v: &[T],
            tau: &[T],
            out: &mut [T],
        ) -> Result<(), linalg::Singular> {
            x.step(t, q, v, tau, out, $inner::<M, C, Dual<T>>)
        }
    };
}
lie_level!(lie1, lie0);
lie_level!(lie2, lie1);
lie_level!(lie3, lie2);
lie_level!(lie4, lie3);
lie_level!(lie5, lie4);

/// The real parts of a slice (messages and tests).
pub fn real<T: Scalar>(x: &[T]) -> Vec<f64> {
    x.iter().map(|&y| re(y)).collect()
}
