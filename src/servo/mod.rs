//! Servo-constraints: a programme realized by given actuators, u = H tau (issue 17).
//!
//! The ideal realization (Do Sanh 1998, (2.7)) lets the control force act along every programme
//! gradient, u in range(B^T). Real machines push on given joints: A dv/dt - F = H tau with H the
//! n x m actuation map (constant: unit columns of actuated joints, or fixed directions over the
//! velocities, [`Actuation`]). The programme rows
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
//! Derivatives are exact, by one of two routes (tested against each other to 1e-12 on every
//! bundled servo scene):
//! - nested duals: L^k g by nesting k first-order dual numbers, each level seeded with the flow,
//!   (t, q, v) + eps (1, v, a) (Euclidean coordinates only: q' = v); cost 3^k per operation;
//! - univariate Taylor propagation ([`Servo::series`], [`crate::taylor`]): the motion's Taylor
//!   series to degree k from k passes of a = A^-1 (F + H tau) on truncated series, then one
//!   evaluation of the rows on it; O(k^2) per operation, and every lower order comes free.
//!
//! Orders from [`TAYLOR_FROM`] = 3 take the series over f64 and Dual64 (the right-hand side and
//! its tau columns; degree-4 rows: 8-10 % less CPU per solve); below that order, and over the
//! Jacobians' nested duals, the nested route (cheaper at low order: a series carries its full
//! capacity's coefficients; and each scalar type of the series compiles the model once more).
//! b comes from one more dual level seeded on tau, over either. k <= 5 here.
//!
//! The direct route: a row whose relative degree is its level's (2 for a position row, 1 for a
//! velocity row, 0 for an acceleration row; the orthogonal and mixed realizations) reads
//! y^(r) = B a - gamma (B, gamma of the programme's jet, jet.rs) with a = A^-1 (F + H tau) (2.2), so
//!   a_i = (B A^-1 F - gamma)_i,   b_i = (B A^-1 H)_i:
//! one jet and one Cholesky factorization, no dual level for the flow nor for tau. The
//! combinations z_r of a [`Reduction`] whose rows all sit at their level's degree (the cranes) are
//! built from the same quantities; only their own derivatives z^(k) nest dual numbers. For those
//! (and rows of a higher degree) the decoupling takes d y^(k) / d tau from L^(k-1) seeded along
//! A^-1 h_j (tau reaches L^k only through a): one pass of L^k and m of L^(k-1), not m of L^k.

use crate::linalg;
use crate::model::{Model, Segment};
use crate::programme::{
    actuation::ForceWork,
    jet::{Jet, JetRows},
    Constraints,
};
use crate::scalar::{re, Dual, Scalar};
use crate::taylor::Taylor;
use nalgebra::DMatrix;
use num_dual::Dual64;
use num_traits::Zero;
use std::any::{Any, TypeId};
use std::collections::HashMap;

pub mod internal;

/// Highest relative degree searched (index 6).
pub const MAX_RELATIVE_DEGREE: usize = 5;

/// Highest relative degree of the rows a [`Reduction`] combines (the nesting of dual numbers grows
/// with both this and [`MAX_REDUCED_DEGREE`]; the cranes need 2).
pub const MAX_ELIMINATED_DEGREE: usize = 2;

/// Highest number of further derivatives of a combination z_r before tau appears in it.
pub const MAX_REDUCED_DEGREE: usize = 3;

/// A row whose largest b_k (k <= [`MAX_RELATIVE_DEGREE`]) is below this fraction of the largest
/// over all rows counts as not reached: its entries are round-off.
pub const ROUNDOFF: f64 = 1e-12;

/// A row's derivative b_i (at the order it first appears) counts as reaching tau when its largest
/// entry exceeds this fraction of the largest such entry over all orders k <= MAX_RELATIVE_DEGREE:
/// terms that cancel analytically (tau entering two coordinates whose sum the row reads) leave
/// round-off, about 1e-16 of their size.
pub const DEGREE_TOL: f64 = 1e-8;

pub use crate::programme::actuation::{Actuation, ActuationError, MapEntry};

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
    /// Set when the rows' decoupling matrix was rank-deficient (e.g. an overhead crane: only the
    /// hoist reaches the load's acceleration): `degrees` are then those of the effective rows
    /// (the kept rows and the combinations z_r in the eliminated rows' slots).
    pub reduction: Option<Reduction>,
    /// Derivatives of each programme row until tau appears (with a reduction: r_r + the degree
    /// of z_r for an eliminated row); the index is their maximum + 1.
    pub differentiations: Vec<usize>,
}

/// One step of the structure algorithm (Silverman, IEEE Trans. Autom. Control 14 (1969) 270-276;
/// Isidori 1995, Sec. 5.4): when the decoupling matrix b (rows at their relative degrees r_i) has
/// rank rho < s, rows I (rho of them, pivot columns J of b) keep their degree and every other row r
/// is replaced by the tau-free combination
///   z_r = y_r^(r_r) - c_r^T y_I^(r_I),   c_r^T = b[r, J] b[I, J]^-1,
/// differentiated further until tau appears. Then y_r^(r_r) = c_r^T y_I^(r_I) + z_r = 0 holds
/// once the kept rows are solved and z_r, z_r', ... are kept at zero: the hidden constraints are
/// y_i^(k), k < r_i, of every row plus z_r^(k) below z_r's degree.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Reduction {
    /// Rows I that keep their relative degree.
    pub kept: Vec<usize>,
    /// Pivot columns J (actuators) of b[I, J].
    pub cols: Vec<usize>,
    /// Rows replaced by their combinations z_r.
    pub eliminated: Vec<usize>,
    /// Relative degree r_i of every original row (the level where b lost rank).
    pub row_degrees: Vec<usize>,
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
    /// The structure algorithm's step when b was rank-deficient at t0 ([`Reduction`]).
    red: Option<&'a Reduction>,
    /// Nested dual numbers for every row (no direct route): the reference the direct route is
    /// tested against ([`Servo::nested_only`]).
    nested_only: bool,
    /// Lie derivatives by univariate Taylor propagation ([`Servo::series`]); off: nested duals.
    taylor: bool,
    /// Every row is g(t, q) (position level): the series' top velocity coefficient goes unread.
    position_rows: bool,
    /// Workspaces kept by the caller between evaluations ([`WorkCache`]).
    work: Option<&'a WorkCache>,
}

/// Workspaces of the servo's passes, one set per pass and scalar type (each nested dual level has
/// its own), made at first use and reused by every later evaluation: the owner (the evaluator,
/// the projector) keeps it for the whole solve, so a right-hand side allocates nothing (model and
/// row workspaces, the passes' seed vectors and matrices, the actuators' expression stacks;
/// `tests/no_alloc.rs` counts it on every bundled servo scene).
#[derive(Default)]
pub struct WorkCache(std::cell::RefCell<HashMap<TypeId, Box<dyn Any + Send>>>);

impl WorkCache {
    /// Run `f` on the cached `W` (made by `make` when absent, or while another call holds it).
    fn with<W: Any + Send, R>(&self, make: impl FnOnce() -> W, f: impl FnOnce(&mut W) -> R) -> R {
        // the box leaves the map while in use (a nested call of the same type makes its own)
        // and goes back as it is: no allocation, no copy of W
        let found = self.0.borrow_mut().remove(&TypeId::of::<W>());
        let mut w: Box<W> = match found.map(|b| b.downcast::<W>()) {
            Some(Ok(b)) => b,
            _ => Box::new(make()),
        };
        let r = f(&mut w);
        self.0.borrow_mut().insert(TypeId::of::<W>(), w);
        r
    }
}

/// What [`Servo::accel`] and [`Servo::flow_tau`] need at one scalar type.
struct AccelWork<W, T> {
    ws: W,
    a: DMatrix<T>,
    scratch: Vec<T>,
    force: ForceWork<T>,
}

/// What [`Servo::direct`] needs at one scalar type: the model's and the rows' workspaces and
/// the jet's outputs.
struct DirectWork<W, R, T> {
    model: W,
    rows: R,
    b: DMatrix<T>,
    gamma: Vec<T>,
    value: Vec<T>,
    gdot: Vec<T>,
    a: DMatrix<T>,
    x: Vec<T>,
    scratch: Vec<T>,
    e: Vec<T>,
    force: ForceWork<T>,
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
            red: None,
            nested_only: false,
            taylor: true,
            position_rows: cons
                .rows()
                .iter()
                .all(|r| r.level == crate::programme::Level::Position),
            work: None,
        }
    }

    /// The same servo keeping its workspaces in `work` between calls ([`WorkCache`]).
    pub fn cached(mut self, work: &'a WorkCache) -> Self {
        self.work = Some(work);
        self
    }

    /// Run `f` on a `W` from the cache when there is one (made by `make` otherwise): each pass
    /// keeps its buffers in its own type, so a right-hand side allocates nothing.
    fn with_work<W: Any + Send, R>(
        &self,
        make: impl FnOnce() -> W,
        f: impl FnOnce(&mut W) -> R,
    ) -> R {
        match self.work {
            Some(w) => w.with(make, f),
            None => f(&mut make()),
        }
    }

    /// Run `f` on the model's workspace, the n x n matrix and a scratch vector at scalar type T
    /// (from the cache when there is one).
    fn with_accel_work<T: Scalar, R>(
        &self,
        f: impl FnOnce(&mut AccelWork<M::Workspace<T>, T>) -> R,
    ) -> R {
        let n = self.model.nv();
        let make = || AccelWork {
            ws: self.model.workspace::<T>(),
            a: DMatrix::from_element(n, n, T::zero()),
            scratch: vec![T::zero(); n],
            force: ForceWork::default(),
        };
        self.with_work(make, f)
    }

    /// The same servo with every derivative taken by nested dual numbers (module docs: the
    /// direct route switched off); the independent route the direct one is checked against.
    pub fn nested_only(mut self, on: bool) -> Self {
        self.nested_only = on;
        self.taylor = !on;
        self
    }

    /// The same servo taking L^k g and L^k z by univariate Taylor propagation (`on`, the default:
    /// [`Servo::series`]) or by k nested dual numbers (the reference it is tested against).
    pub fn taylor(mut self, on: bool) -> Self {
        self.taylor = on;
        self
    }

    /// The degree at which tau reaches row i directly, through a (y^(r) = B a - gamma): 2 for a
    /// position row, 1 for a velocity row, 0 for an acceleration row.
    fn level_degree(&self, i: usize) -> usize {
        match self.cons.rows()[i].level {
            crate::programme::Level::Position => 2,
            crate::programme::Level::Velocity => 1,
            crate::programme::Level::Acceleration => 0,
        }
    }

    /// Does row i (of relative degree `k`) take the direct route?
    fn is_direct(&self, i: usize, k: usize) -> bool {
        !self.nested_only && k == self.level_degree(i)
    }

    /// Rows that take the direct route at the given (effective) degrees: the rows that are not
    /// combinations z_r and sit at their level's degree.
    pub fn direct_rows(&self, degrees: &[usize]) -> Vec<usize> {
        (0..degrees.len())
            .filter(|&i| !self.is_z(i) && self.is_direct(i, degrees[i]))
            .collect()
    }

    /// A^-1 h_j into `x`: the acceleration actuator j gives per unit tau_j (2.2), with `chol` the
    /// Cholesky factor of A and `e` scratch of length m.
    #[allow(clippy::too_many_arguments)]
    fn force_direction<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        j: usize,
        chol: &DMatrix<T>,
        e: &mut [T],
        force: &mut ForceWork<T>,
        x: &mut [T],
    ) {
        e.iter_mut()
            .enumerate()
            .for_each(|(l, y)| *y = if l == j { T::one() } else { T::zero() });
        x.iter_mut().for_each(|y| *y = T::zero());
        self.act.add_force_with(force, t, q, e, x);
        linalg::cholesky_solve(chol, x.len(), x);
    }

    /// y^(r) at tau = 0 (`val`) and b = d y^(r) / d tau (`db`, s x m; only the columns `cols` when
    /// given) of every row at its level's degree r, by the direct route (module docs):
    /// y^(r) = B a - gamma, a = A^-1 (F + H tau), so val = B A^-1 F - gamma and db = B A^-1 H.
    /// Entries of rows at other degrees are meaningless.
    fn direct<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        cols: Option<&[usize]>,
        val: &mut [T],
        db: &mut DMatrix<T>,
    ) -> Result<(), linalg::Singular> {
        let (s, m) = self.dims();
        let n = v.len();
        let segments = self.model.segments();
        let make = || DirectWork {
            model: self.model.workspace::<T>(),
            rows: self.cons.workspace::<T>(),
            b: DMatrix::from_element(s, n, T::zero()),
            gamma: vec![T::zero(); s],
            value: vec![T::zero(); s],
            gdot: vec![T::zero(); s],
            a: DMatrix::from_element(n, n, T::zero()),
            x: vec![T::zero(); n],
            scratch: vec![T::zero(); n],
            e: vec![T::zero(); m],
            force: ForceWork::default(),
        };
        let body = |w: &mut DirectWork<M::Workspace<T>, C::Workspace<T>, T>| {
            let DirectWork {
                model: ws,
                rows,
                b,
                gamma,
                value,
                gdot,
                a,
                x,
                scratch,
                e,
                force,
            } = w;
            // A and F first: the rows' jet then reads the model's forward passes (one sweep).
            self.model.mass_matrix(ws, q, a);
            x.iter_mut().for_each(|y| *y = T::zero());
            self.model.natural_forces(ws, t, q, v, x, scratch);
            let out = JetRows {
                b,
                gamma,
                value,
                gdot,
            };
            let sweep = self.model.tree_sweep(ws);
            if !self.cons.jet(rows, segments, t, q, v, out, sweep) {
                let mut jet = Jet::<C, T>::new(self.cons, segments, q.len(), n);
                jet.compute_generic(self.cons, segments, t, q, v);
                b.copy_from(&jet.b);
                gamma.copy_from_slice(&jet.gamma);
            }
            linalg::cholesky(a, n)?;
            linalg::cholesky_solve(a, n, x);
            let bx = |x: &[T], i: usize| (0..n).fold(T::zero(), |acc, k| acc + b[(i, k)] * x[k]);
            for (i, y) in val.iter_mut().enumerate().take(s) {
                *y = bx(x, i) - gamma[i];
            }
            for j in (0..m).filter(|j| cols.is_none_or(|c| c.contains(j))) {
                self.force_direction(t, q, j, a, e, force, x);
                for i in 0..s {
                    db[(i, j)] = bx(x, i);
                }
            }
            Ok(())
        };
        self.with_work(make, body)
    }

    /// The same servo with the rows of a [`Reduction`] (from [`Analysis::reduction`]): the
    /// eliminated rows' slots then hold their tau-free combinations z_r.
    pub fn reduced(mut self, red: Option<&'a Reduction>) -> Self {
        self.red = red;
        self
    }

    /// Is effective row i a combination z_i of the reduction?
    fn is_z(&self, i: usize) -> bool {
        self.red.is_some_and(|r| r.eliminated.contains(&i))
    }

    /// Relative degree of original row i (the level where tau first reaches it).
    fn row_degree(&self, degrees: &[usize], i: usize) -> usize {
        self.red.map_or(degrees[i], |r| r.row_degrees[i])
    }

    /// Number of rows s and actuators m.
    pub fn dims(&self) -> (usize, usize) {
        (self.cons.rows().len(), self.act.len())
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
        self.with_accel_work(|w: &mut AccelWork<M::Workspace<T>, T>| {
            self.model.mass_matrix(&mut w.ws, q, &mut w.a);
            self.model
                .natural_forces(&mut w.ws, t, q, v, out, &mut w.scratch);
            self.act.add_force_with(&mut w.force, t, q, tau, out);
            linalg::cholesky(&mut w.a, n)?;
            linalg::cholesky_solve(&w.a, n, out);
            Ok(())
        })
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
        /// The rows' workspace and dv/dt at one scalar type ([`WorkCache`]).
        struct RowsWork<R, T>(R, Vec<T>);
        let make = || RowsWork(self.cons.workspace::<T>(), vec![T::zero(); v.len()]);
        self.with_work(make, |w: &mut RowsWork<C::Workspace<T>, T>| {
            fit(&mut w.1, v.len(), T::zero());
            if self.has_acc_rows {
                self.accel(t, q, v, tau, &mut w.1)?;
            }
            self.cons.eval(&mut w.0, t, q, v, &w.1, out);
            Ok(())
        })
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
        self.with_work(StepWork::<T>::default, |w: &mut StepWork<T>| {
            fit(&mut w.a, n, T::zero());
            self.accel(t, q, v, tau, &mut w.a)?;
            let td = Dual::new(t, T::one());
            seed(&mut w.qd, q, v);
            seed(&mut w.vd, v, &w.a);
            lift(&mut w.taud, tau);
            fit(&mut w.o, out.len(), Dual::from_re(T::zero()));
            inner(self, td, &w.qd, &w.vd, &w.taud, &mut w.o)?;
            for (x, d) in out.iter_mut().zip(&w.o) {
                *x = d.eps;
            }
            Ok(())
        })
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
        if self.taylor && k >= TAYLOR_FROM {
            let mut top = |j, i, y| {
                if j == k {
                    out[i] = y;
                }
            };
            if let Some(r) = self.series_at(false, k, t, q, v, tau, &mut top) {
                return r;
            }
        }
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
        self.tau_columns(t, q, v, tau, val, db, |td, qd, vd, taud, o| {
            self.lie(k, td, qd, vd, taud, o)
        })
    }

    /// d y^(k) / d tau for every k <= [`MAX_RELATIVE_DEGREE`] (`z` false) or d z^(k) / d tau for
    /// every k <= [`MAX_REDUCED_DEGREE`] (`z` true) into `bk` (s x m each, one per order): the same
    /// numbers as [`Servo::lie_tau`] / [`Servo::z_tau`] order by order, from one tau-seeded pass
    /// per actuator of the highest order (its nested levels hold the lower ones).
    pub fn tau_upto<T: Scalar>(
        &self,
        z: bool,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        bk: &mut [DMatrix<T>],
    ) -> Result<(), linalg::Singular> {
        let (s, m) = self.dims();
        let top = if z {
            MAX_REDUCED_DEGREE
        } else {
            MAX_RELATIVE_DEGREE
        };
        assert_eq!(bk.len(), top + 1, "one matrix per order");
        let td = Dual::from_re(t);
        let qd: Vec<Dual<T>> = q.iter().map(|&x| Dual::from_re(x)).collect();
        let vd: Vec<Dual<T>> = v.iter().map(|&x| Dual::from_re(x)).collect();
        let mut outs = vec![vec![Dual::from_re(T::zero()); s]; top + 1];
        for j in 0..m {
            let taud: Vec<Dual<T>> = (0..m)
                .map(|l| Dual::new(tau[l], if l == j { T::one() } else { T::zero() }))
                .collect();
            if z {
                zupto3(self, td, &qd, &vd, &taud, &mut outs)?;
            } else {
                upto5(self, td, &qd, &vd, &taud, &mut outs)?;
            }
            for (b, o) in bk.iter_mut().zip(&outs) {
                for i in 0..s {
                    b[(i, j)] = o[i].eps;
                }
            }
        }
        Ok(())
    }

    /// [`Servo::lie_tau`] of the combinations z_r of the reduction (k <= [`MAX_REDUCED_DEGREE`]);
    /// the other slots of `val` and `db` are zero.
    #[allow(clippy::too_many_arguments)]
    pub fn z_tau<T: Scalar>(
        &self,
        k: usize,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        val: &mut [T],
        db: &mut DMatrix<T>,
    ) -> Result<(), linalg::Singular> {
        self.tau_columns(t, q, v, tau, val, db, |td, qd, vd, taud, o| {
            self.zlie(k, td, qd, vd, taud, o)
        })
    }

    /// Value and tau-derivative of `f` (one dual pass per actuator seeded on tau_j).
    #[allow(clippy::too_many_arguments)]
    fn tau_columns<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        val: &mut [T],
        db: &mut DMatrix<T>,
        mut f: impl FnMut(
            Dual<T>,
            &[Dual<T>],
            &[Dual<T>],
            &[Dual<T>],
            &mut [Dual<T>],
        ) -> Result<(), linalg::Singular>,
    ) -> Result<(), linalg::Singular> {
        let (s, m) = self.dims();
        let td = Dual::from_re(t);
        self.with_work(StepWork::<T>::default, |w: &mut StepWork<T>| {
            lift(&mut w.qd, q);
            lift(&mut w.vd, v);
            fit(&mut w.o, s, Dual::from_re(T::zero()));
            for j in 0..m {
                lift(&mut w.taud, tau);
                w.taud[j].eps = T::one();
                f(td, &w.qd, &w.vd, &w.taud, &mut w.o)?;
                for i in 0..s {
                    db[(i, j)] = w.o[i].eps;
                    val[i] = w.o[i].re;
                }
            }
            Ok(())
        })
    }

    /// [`Servo::lie_tau`] (`z` false) or [`Servo::z_tau`] (`z` true) for the rows whose degree is
    /// k >= 1, by the flow: L^(k-1) of such a row is free of tau, and tau enters
    /// L^k = d/dt L^(k-1) only through the acceleration a = A^-1 (F + H tau) (2.2), so
    ///   y^(k) = d/ds L^(k-1) (t + s, q + s v, v + s a),   d y^(k) / d tau_j = d/ds L^(k-1) (t, q, v + s A^-1 h_j):
    /// one pass of the k-th derivative and m passes of the (k-1)-th instead of m passes of the
    /// k-th. Rows of other degrees get meaningless entries; k = 0 (and [`Servo::nested_only`])
    /// take the tau-seeded passes.
    #[allow(clippy::too_many_arguments)]
    fn flow_tau<T: Scalar>(
        &self,
        z: bool,
        k: usize,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        val: &mut [T],
        db: &mut DMatrix<T>,
    ) -> Result<(), linalg::Singular> {
        if k == 0 || self.nested_only {
            return if z {
                self.z_tau(k, t, q, v, tau, val, db)
            } else {
                self.lie_tau(k, t, q, v, tau, val, db)
            };
        }
        let derivative = |k, t, q: &[T], v: &[T], tau: &[T], out: &mut [T]| {
            if z {
                self.zlie(k, t, q, v, tau, out)
            } else {
                self.lie(k, t, q, v, tau, out)
            }
        };
        derivative(k, t, q, v, tau, val)?;
        let (s, m) = self.dims();
        let n = v.len();
        /// [`Servo::flow_tau`]'s buffers at one scalar type: the Cholesky factor of A, A^-1 h_j.
        struct FlowWork<T: Scalar> {
            chol: DMatrix<T>,
            e: Vec<T>,
            x: Vec<T>,
            force: ForceWork<T>,
            step: StepWork<T>,
        }
        let make = || FlowWork {
            chol: DMatrix::from_element(n, n, T::zero()),
            e: vec![T::zero(); m],
            x: vec![T::zero(); n],
            force: ForceWork::default(),
            step: StepWork::default(),
        };
        self.with_work(make, |fw: &mut FlowWork<T>| {
            self.with_accel_work(|w: &mut AccelWork<M::Workspace<T>, T>| {
                self.model.mass_matrix(&mut w.ws, q, &mut w.a);
                linalg::cholesky(&mut w.a, n)?;
                fw.chol.copy_from(&w.a);
                Ok::<(), linalg::Singular>(())
            })?;
            let td = Dual::from_re(t);
            let w = &mut fw.step;
            lift(&mut w.qd, q);
            lift(&mut w.taud, tau);
            fit(&mut w.o, s, Dual::from_re(T::zero()));
            for j in 0..m {
                self.force_direction(t, q, j, &fw.chol, &mut fw.e, &mut fw.force, &mut fw.x);
                seed(&mut w.vd, v, &fw.x);
                if z {
                    self.zlie(k - 1, td, &w.qd, &w.vd, &w.taud, &mut w.o)?;
                } else {
                    self.lie(k - 1, td, &w.qd, &w.vd, &w.taud, &mut w.o)?;
                }
                for i in 0..s {
                    db[(i, j)] = w.o[i].eps;
                }
            }
            Ok(())
        })
    }

    /// L^k z of the reduction's combinations at constant tau, k <= [`MAX_REDUCED_DEGREE`].
    pub fn zlie<T: Scalar>(
        &self,
        k: usize,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        out: &mut [T],
    ) -> Result<(), linalg::Singular> {
        if self.taylor && k >= TAYLOR_FROM && self.z_direct() {
            let mut top = |j, i, y| {
                if j == k {
                    out[i] = y;
                }
            };
            if let Some(r) = self.series_at(true, k, t, q, v, tau, &mut top) {
                return r;
            }
        }
        match k {
            0 => zlie0(self, t, q, v, tau, out),
            1 => zlie1(self, t, q, v, tau, out),
            2 => zlie2(self, t, q, v, tau, out),
            3 => zlie3(self, t, q, v, tau, out),
            _ => panic!("reduced degree {k} beyond MAX_REDUCED_DEGREE (checked by the caller)"),
        }
    }

    /// [`Servo::series`] when T is f64 or Dual64 (the right-hand side's values and its tau
    /// columns), None otherwise: each scalar type the series run over instantiates the model, the
    /// rows and the factorizations once more (compile time: docs/benchmarks.md, stop 50), and the
    /// Jacobians' nested duals gain little from them. T is matched at run time (no
    /// specialization in Rust); values cross as the concrete type, unchanged.
    #[allow(clippy::too_many_arguments)]
    fn series_at<T: Scalar>(
        &self,
        z: bool,
        k: usize,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        emit: &mut dyn FnMut(usize, usize, T),
    ) -> Option<Result<(), linalg::Singular>> {
        if TypeId::of::<T>() == TypeId::of::<f64>() {
            Some(self.series_as::<T, f64>(z, k, t, q, v, tau, emit))
        } else if TypeId::of::<T>() == TypeId::of::<Dual64>() {
            Some(self.series_as::<T, Dual64>(z, k, t, q, v, tau, emit))
        } else {
            None
        }
    }

    /// [`Servo::series`] at U for T = U (buffers of U kept per type in the cache).
    #[allow(clippy::too_many_arguments)]
    fn series_as<T: Scalar, U: Scalar>(
        &self,
        z: bool,
        k: usize,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        emit: &mut dyn FnMut(usize, usize, T),
    ) -> Result<(), linalg::Singular> {
        /// q, v, tau as U.
        struct AsWork<U>(Vec<U>, Vec<U>, Vec<U>);
        let make = || AsWork::<U>(Vec::new(), Vec::new(), Vec::new());
        self.with_work(make, |w: &mut AsWork<U>| {
            for (to, from) in [(&mut w.0, q), (&mut w.1, v), (&mut w.2, tau)] {
                to.clear();
                to.extend(from.iter().map(same::<T, U>));
            }
            let mut back = |j, i, y: U| emit(j, i, same::<U, T>(&y));
            self.series(z, k, same::<T, U>(&t), &w.0, &w.1, &w.2, &mut back)
        })
    }

    /// y^(j) = L^j g (`z` false) or z^(j) = L^j z (`z` true) of every row for j <= k at constant
    /// tau, by univariate Taylor propagation (Griewank & Walther 2008, Sec. 13.2; [`Taylor`]):
    /// along the motion q(s) = sum q_j s^j, v(s) = sum v_j s^j the flow q' = v, v' = a gives
    ///   q_(j+1) = v_j / (j + 1),   v_(j+1) = a_j / (j + 1),
    /// with a_j the top coefficient of a = A^-1 (F + H tau) (2.2) evaluated on the series known to
    /// degree j; k such passes (degrees 0 .. k-1), then one evaluation of the rows on the series to
    /// degree k yields y_j = y^(j) / j!. A product on a series of degree d costs (d+1)(d+2)/2
    /// multiplications, against 3^d for d nested duals. `emit(j, i, y)` receives y_i^(j). For z_r
    /// the reduction's rows must all take the direct route ([`Servo::z_direct`]; otherwise z_r's
    /// own tau-seeded passes would nest dual numbers over the series).
    #[allow(clippy::too_many_arguments)]
    pub fn series<T: Scalar>(
        &self,
        z: bool,
        k: usize,
        t: T,
        q: &[T],
        v: &[T],
        tau: &[T],
        emit: &mut dyn FnMut(usize, usize, T),
    ) -> Result<(), linalg::Singular> {
        assert!(
            k <= if z {
                MAX_REDUCED_DEGREE
            } else {
                MAX_RELATIVE_DEGREE
            },
            "degree {k} beyond the servo's maximum (checked by the caller)"
        );
        assert!(
            !z || self.z_direct(),
            "z_r by series: the direct route's rows only"
        );
        let n = v.len();
        let make = || SeriesWork {
            q: vec![[T::zero(); SERIES]; n],
            v: vec![[T::zero(); SERIES]; n],
            a: vec![T::zero(); n],
        };
        self.with_work(make, |w: &mut SeriesWork<T>| {
            fit(&mut w.q, n, [T::zero(); SERIES]);
            fit(&mut w.v, n, [T::zero(); SERIES]);
            fit(&mut w.a, n, T::zero());
            for i in 0..n {
                w.q[i][0] = q[i];
                w.v[i][0] = v[i];
                w.q[i][1] = v[i];
            }
            // rows g(t, q) (position level only) read q to degree k, which needs a_0 .. a_(k-2):
            // the pass giving a_(k-1) (v_k) is skipped and v_k set to zero
            let top = if !z && self.position_rows {
                k.saturating_sub(1)
            } else {
                k
            };
            if top > 0 {
                // degree 0: a_0 = dv/dt at the state
                self.accel(t, q, v, tau, &mut w.a)?;
                for i in 0..n {
                    w.v[i][1] = w.a[i];
                    w.q[i][2] = w.a[i] / 2.0;
                }
            }
            // passes on the series to degrees 1 .. top-1, then the rows on the series to degree k
            for d in 1..top {
                self.series_pass(d + 1, t, tau, w)?;
            }
            if top < k {
                w.v.iter_mut().for_each(|c| c[k] = T::zero());
            }
            self.series_rows(z, k + 1, t, tau, w, emit)
        })
    }

    /// One pass of [`Servo::series`]: a on the series known to degree len-1, whose top
    /// coefficient a_(len-1) gives v_len = a_(len-1) / len and q_(len+1) = v_len / (len + 1).
    fn series_pass<T: Scalar>(
        &self,
        len: usize,
        t: T,
        tau: &[T],
        w: &mut SeriesWork<T>,
    ) -> Result<(), linalg::Singular> {
        self.with_work(PassWork::<T>::default, |p: &mut PassWork<T>| {
            p.load(len, t, tau, w);
            self.accel(p.t, &p.q, &p.v, &p.tau, &mut p.out)?;
            for (i, a) in p.out.iter().enumerate() {
                let vn = a.coefficient(len - 1) / len as f64;
                w.v[i][len] = vn;
                if len + 1 < SERIES {
                    w.q[i][len + 1] = vn / (len + 1) as f64;
                }
            }
            Ok(())
        })
    }

    /// The rows (or the combinations z_r, all of the direct route) on the series to degree
    /// len-1: y^(j) = j! y_j.
    fn series_rows<T: Scalar>(
        &self,
        z: bool,
        len: usize,
        t: T,
        tau: &[T],
        w: &mut SeriesWork<T>,
        emit: &mut dyn FnMut(usize, usize, T),
    ) -> Result<(), linalg::Singular> {
        let s = self.dims().0;
        self.with_work(PassWork::<T>::default, |p: &mut PassWork<T>| {
            p.load(len, t, tau, w);
            fit(&mut p.out, s, Taylor::zero());
            if z {
                self.zrows_direct(p.t, &p.q, &p.v, &mut p.out)?;
            } else {
                self.rows_at(p.t, &p.q, &p.v, &p.tau, &mut p.out)?;
            }
            for (i, y) in p.out.iter().enumerate() {
                let mut fact = 1.0;
                for j in 0..len {
                    if j > 1 {
                        fact *= j as f64;
                    }
                    emit(j, i, y.coefficient(j) * fact);
                }
            }
            Ok(())
        })
    }

    /// The combinations z_r = y_r^(r_r) - c_r^T y_I^(r_I), c_r^T = b[r, J] b[I, J]^-1, at
    /// (t, q, v) into the eliminated rows' slots of `out` (the others are set to zero). Free of
    /// tau by construction (its terms cancel), so evaluated at tau = 0.
    fn zrows<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        out: &mut [T],
    ) -> Result<(), linalg::Singular> {
        if self.z_direct() {
            return self.zrows_direct(t, q, v, out);
        }
        let red = self.red.expect("zrows needs a reduction");
        let (s, m) = self.dims();
        self.with_work(ZrowsWork::make(s, m, red), |w: &mut ZrowsWork<T>| {
            w.ks.clear();
            w.ks.extend_from_slice(&red.row_degrees);
            w.ks.sort_unstable();
            w.ks.dedup();
            for ki in 0..w.ks.len() {
                let k = w.ks[ki];
                self.tau_columns(
                    t,
                    q,
                    v,
                    &w.zero,
                    &mut w.vk,
                    &mut w.bk,
                    |td, qd, vd, taud, o| match k {
                        0 => lie0(self, td, qd, vd, taud, o),
                        1 => lie1(self, td, qd, vd, taud, o),
                        2 => lie2(self, td, qd, vd, taud, o),
                        _ => panic!("eliminated degree {k} beyond MAX_ELIMINATED_DEGREE"),
                    },
                )?;
                for i in (0..s).filter(|&i| red.row_degrees[i] == k) {
                    w.val[i] = w.vk[i];
                    for j in 0..m {
                        w.b[(i, j)] = w.bk[(i, j)];
                    }
                }
            }
            w.combine(red, out)
        })
    }

    /// Do all rows of the reduction take the direct route (the cranes)? Then z_r needs one jet
    /// and one factorization ([`Servo::zrows_direct`]) and no dual level for tau.
    fn z_direct(&self) -> bool {
        self.red.is_some_and(|red| {
            (0..red.row_degrees.len()).all(|i| self.is_direct(i, red.row_degrees[i]))
        })
    }

    /// [`Servo::zrows`] when [`Servo::z_direct`]: y^(r) and b from the direct route (its pivot
    /// columns J only).
    fn zrows_direct<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        out: &mut [T],
    ) -> Result<(), linalg::Singular> {
        let red = self.red.expect("zrows needs a reduction");
        let (s, m) = self.dims();
        self.with_work(ZrowsWork::make(s, m, red), |w: &mut ZrowsWork<T>| {
            self.direct(t, q, v, Some(&red.cols), &mut w.val, &mut w.b)?;
            w.combine(red, out)
        })
    }

    /// Relative degrees, index, realization and the decoupling matrix's conditioning at a state.
    /// A rank-deficient decoupling matrix gets one step of the structure algorithm
    /// ([`Reduction`]); the analysis then describes the effective rows.
    pub fn analyse(
        &self,
        t: f64,
        q: &[f64],
        v: &[f64],
        rank_tol: f64,
    ) -> Result<Analysis, Unrealizable> {
        if self.work.is_none() {
            // passes over up to six nested dual levels, m per order: one workspace per type
            let work = WorkCache::default();
            return Servo {
                work: Some(&work),
                ..*self
            }
            .analyse(t, q, v, rank_tol);
        }
        let (s, m) = self.dims();
        let tau = vec![0.0; m];
        let mut bk = vec![DMatrix::zeros(s, m); MAX_RELATIVE_DEGREE + 1];
        self.tau_upto(false, t, q, v, &tau, &mut bk)
            .map_err(|_| Unrealizable::Model)?;
        let degrees = first_degrees(&bk, s, m)?;
        let b_norms: Vec<f64> = (0..s).map(|i| row_norm(&bk[degrees[i]], i)).collect();
        let index = degrees.iter().copied().max().unwrap_or(0) + 1;
        let analysis =
            |degrees: Vec<usize>, b_norms, rcond, reduction, differentiations| Analysis {
                degrees,
                index,
                realization: self.realization(t, q, v),
                rcond,
                b_norms,
                reduction,
                differentiations,
            };
        let err = match self.decoupling(t, q, v, &degrees, &b_norms, rank_tol) {
            Ok(d) => return Ok(analysis(degrees.clone(), b_norms, d.rcond, None, degrees)),
            Err(e) => Unrealizable::Singular { rcond: e.rcond },
        };
        // Rank-deficient b: one step of the structure algorithm, if the rows allow it.
        let b = DMatrix::from_fn(s, m, |i, j| bk[degrees[i]][(i, j)]);
        let Some(red) = reduce(&b, &degrees, rank_tol) else {
            return Err(err);
        };
        let servo = Servo {
            red: Some(&red),
            ..*self
        };
        let mut zk = vec![DMatrix::zeros(s, m); MAX_REDUCED_DEGREE + 1];
        servo
            .tau_upto(true, t, q, v, &tau, &mut zk)
            .map_err(|_| Unrealizable::Model)?;
        let mut eff = degrees.clone();
        let mut norms = b_norms;
        let mut missing = vec![];
        for &r in &red.eliminated {
            let big = zk.iter().map(|b| row_norm(b, r)).fold(0.0, f64::max);
            match (0..=MAX_REDUCED_DEGREE)
                .find(|&k| big > 0.0 && row_norm(&zk[k], r) > DEGREE_TOL * big)
            {
                Some(k) => (eff[r], norms[r]) = (k, row_norm(&zk[k], r)),
                None => missing.push(r),
            }
        }
        if !missing.is_empty() {
            return Err(Unrealizable::NotReached { rows: missing });
        }
        let d = servo
            .decoupling(t, q, v, &eff, &norms, rank_tol)
            .map_err(|e| Unrealizable::Singular { rcond: e.rcond })?;
        let diffs: Vec<usize> = (0..s)
            .map(|i| {
                degrees[i]
                    + if red.eliminated.contains(&i) {
                        eff[i]
                    } else {
                        0
                    }
            })
            .collect();
        let mut an = analysis(eff, norms, d.rcond, Some(red), diffs);
        an.index = an.differentiations.iter().copied().max().unwrap_or(0) + 1;
        Ok(an)
    }

    /// tau = -b^-1 a at (t, q, v) for the given (effective) relative degrees. A row of b whose
    /// largest entry falls below `rank_tol` times its reference `b_norms` (its t0 value), or an LU
    /// pivot ratio below `rank_tol`, is singular.
    #[allow(clippy::too_many_arguments)]
    pub fn decoupling<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        degrees: &[usize],
        b_norms: &[f64],
        rank_tol: f64,
    ) -> Result<Decoupled<T>, linalg::Singular> {
        let mut tau = vec![T::zero(); self.dims().1];
        let c = self.decouple(t, q, v, degrees, b_norms, rank_tol, &mut tau)?;
        Ok(Decoupled {
            tau,
            rcond: c.rcond,
            row_ratio: c.row_ratio,
            row: c.row,
            det_sign: c.det_sign,
        })
    }

    /// [`Servo::decoupling`] with tau into `tau` (length m), allocating nothing when cached.
    #[allow(clippy::too_many_arguments)]
    fn decouple<T: Scalar>(
        &self,
        t: T,
        q: &[T],
        v: &[T],
        degrees: &[usize],
        b_norms: &[f64],
        rank_tol: f64,
        tau: &mut [T],
    ) -> Result<Conditioning, linalg::Singular> {
        let (s, m) = self.dims();
        debug_assert_eq!(s, m);
        /// [`Servo::decouple`]'s buffers at one scalar type.
        struct DecoupleWork<T> {
            zero: Vec<T>,
            b: DMatrix<T>,
            val: Vec<T>,
            db: DMatrix<T>,
            direct: Vec<usize>,
            ks: Vec<usize>,
            piv: Vec<usize>,
        }
        let make = || DecoupleWork {
            zero: vec![T::zero(); m],
            b: DMatrix::from_element(s, m, T::zero()),
            val: vec![T::zero(); s],
            db: DMatrix::from_element(s, m, T::zero()),
            direct: Vec::with_capacity(s),
            ks: Vec::with_capacity(s),
            piv: vec![0; s],
        };
        self.with_work(make, |w: &mut DecoupleWork<T>| {
            let DecoupleWork {
                zero,
                b,
                val,
                db,
                direct,
                ks,
                piv,
            } = w;
            let rhs = tau;
            rhs.iter_mut().for_each(|x| *x = T::zero());
            b.fill(T::zero());
            direct.clear();
            direct.extend((0..s).filter(|&i| !self.is_z(i) && self.is_direct(i, degrees[i])));
            if !direct.is_empty() {
                self.direct(t, q, v, None, val, db)?;
                for &i in direct.iter() {
                    rhs[i] = -val[i];
                    for j in 0..m {
                        b[(i, j)] = db[(i, j)];
                    }
                }
            }
            for z in [false, true] {
                ks.clear();
                ks.extend(
                    (0..s)
                        .filter(|&i| self.is_z(i) == z && !direct.contains(&i))
                        .map(|i| degrees[i]),
                );
                ks.sort_unstable();
                ks.dedup();
                for &k in ks.iter() {
                    self.flow_tau(z, k, t, q, v, zero, val, db)?;
                    for i in (0..s)
                        .filter(|&i| degrees[i] == k && self.is_z(i) == z && !direct.contains(&i))
                    {
                        rhs[i] = -val[i];
                        for j in 0..m {
                            b[(i, j)] = db[(i, j)];
                        }
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
            let rcond = linalg::lu_factor(b, s, piv, rank_tol)?;
            // sign of det b = prod u_kk times the parity of the row swaps
            let det_sign = (0..s).fold(1.0, |sg, k| {
                let swap = if piv[k] != k { -1.0 } else { 1.0 };
                sg * swap * re(b[(k, k)]).signum()
            });
            linalg::lu_solve(b, s, piv, rhs);
            Ok(Conditioning {
                rcond,
                row_ratio: ratio,
                row,
                det_sign,
            })
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
    ) -> Result<Conditioning, linalg::Singular> {
        let d = self.decouple(
            t,
            q,
            v,
            degrees,
            b_norms,
            rank_tol,
            &mut tau[..self.dims().1],
        )?;
        self.accel(t, q, v, &tau[..self.dims().1], acc)?;
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
        // range(B^T) within range(H): every row's gradient is a force the actuators produce (on
        // joint actuators: B vanishes on the unactuated velocities); with s = m and both of full
        // rank the ranges are then equal.
        let off = (0..s)
            .map(|i| {
                self.act
                    .outside(t, q, &b.row(i).iter().copied().collect::<Vec<_>>())
            })
            .fold(0.0f64, f64::max);
        if s == m && off <= 1e-12 * bnorm {
            return Realization::Orthogonal;
        }
        // B A^-1 H = 0: the columns A^-1 h_j.
        let mut ws = self.model.workspace::<f64>();
        let mut a = DMatrix::zeros(n, n);
        self.model.mass_matrix(&mut ws, q, &mut a);
        if linalg::cholesky(&mut a, n).is_err() {
            return Realization::Mixed;
        }
        let mut worst = 0.0f64;
        let mut scale = 0.0f64;
        for mut col in self.act.columns_at(t, q) {
            linalg::cholesky_solve(&a, n, &mut col);
            // Against |B_i| |A^-1 h_j|, not the products' sizes: A^-1 h_j may be round-off exactly
            // where B_i reads it (a force reaching the row's coordinates only through others).
            let cn = col.iter().map(|x| x * x).sum::<f64>().sqrt();
            for i in 0..s {
                let x: f64 = (0..n).map(|j| b[(i, j)] * col[j]).sum();
                let bn = (0..n).map(|j| b[(i, j)] * b[(i, j)]).sum::<f64>().sqrt();
                worst = worst.max(x.abs());
                scale = scale.max(bn * cn);
            }
        }
        if worst <= 1e-12 * scale.max(f64::MIN_POSITIVE) {
            Realization::Tangential
        } else {
            Realization::Mixed
        }
    }

    /// The hidden constraints y_i^(k), k < r_i (row-major: row by row, k ascending; with a
    /// reduction an eliminated row's z_r^(k), k below its degree, follow its own), at tau = 0
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
        let kmax = (0..s)
            .map(|i| self.row_degree(degrees, i))
            .max()
            .unwrap_or(0);
        let mut by_k = vec![vec![T::zero(); s]; kmax];
        // every order from one series where it runs, else order by order
        let one = (self.taylor && kmax > TAYLOR_FROM)
            .then(|| {
                let mut put = |j: usize, i: usize, y| by_k[j][i] = y;
                self.series_at(false, kmax - 1, t, q, v, &zero, &mut put)
            })
            .flatten();
        match one {
            Some(r) => r?,
            None => {
                for (k, row) in by_k.iter_mut().enumerate() {
                    self.lie(k, t, q, v, &zero, row)?;
                }
            }
        }
        let zmax = (0..s)
            .filter(|&i| self.is_z(i))
            .map(|i| degrees[i])
            .max()
            .unwrap_or(0);
        let mut zk = vec![vec![T::zero(); s]; zmax];
        let one = (self.taylor && zmax > TAYLOR_FROM && self.z_direct())
            .then(|| {
                let mut put = |j: usize, i: usize, y| zk[j][i] = y;
                self.series_at(true, zmax - 1, t, q, v, &zero, &mut put)
            })
            .flatten();
        match one {
            Some(r) => r?,
            None => {
                for (k, row) in zk.iter_mut().enumerate() {
                    self.zlie(k, t, q, v, &zero, row)?;
                }
            }
        }
        out.clear();
        for i in 0..s {
            for row in by_k.iter().take(self.row_degree(degrees, i)) {
                out.push(row[i]);
            }
            if self.is_z(i) {
                for row in zk.iter().take(degrees[i]) {
                    out.push(row[i]);
                }
            }
        }
        Ok(())
    }

    /// Names of the hidden constraints, in the order of [`Servo::hidden`].
    pub fn hidden_names(&self, degrees: &[usize]) -> Vec<(usize, String)> {
        let mut out = vec![];
        for (i, r) in self.cons.rows().iter().enumerate() {
            let ri = self.row_degree(degrees, i);
            for k in 0..ri {
                out.push((i, format!("{} (d^{k}/dt^{k}, hidden constraint)", r.name)));
            }
            if self.is_z(i) {
                for k in 0..degrees[i] {
                    out.push((
                        i,
                        format!(
                            "{} (d^{k}/dt^{k} of z = d^{ri}/dt^{ri} less the kept rows' share, \
                             hidden constraint)",
                            r.name
                        ),
                    ));
                }
            }
        }
        out
    }

    /// Project (q, v) onto the hidden constraints: Gauss-Newton steps of the least (Euclidean)
    /// correction, dx = -J^T (J J^T)^-1 h with J = dh/d(q, v) exact (one dual pass per coordinate)
    /// at the first iterate, kept while a step shrinks the residual tenfold (simplified Newton,
    /// [`Servo::project_with`]). Returns (iterations, |dq|, |dv|, residual, index of the worst
    /// hidden constraint, converged).
    pub fn project(
        &self,
        t: f64,
        q: &mut [f64],
        v: &mut [f64],
        degrees: &[usize],
        tol: f64,
        max_iter: usize,
    ) -> ProjectOutcome {
        self.project_with(
            t,
            q,
            v,
            degrees,
            tol,
            max_iter,
            &mut KeptJacobian::default(),
        )
    }

    /// [`Servo::project`] starting from the Jacobian `kept` from an earlier projection (simplified
    /// Newton, Hairer, Lubich & Wanner, Geometric Numerical Integration, Sec. IV.4): the
    /// corrections then lie in the rows of that Jacobian, and a step that does not shrink the
    /// residual tenfold takes a fresh one (kept for the next call). The projected state meets the
    /// hidden constraints to `tol` either way; the 2n dual passes of a fresh Jacobian are the
    /// projection's cost.
    #[allow(clippy::too_many_arguments)]
    pub fn project_with(
        &self,
        t: f64,
        q: &mut [f64],
        v: &mut [f64],
        degrees: &[usize],
        tol: f64,
        max_iter: usize,
        kept: &mut KeptJacobian,
    ) -> ProjectOutcome {
        let n = v.len();
        let mut h = vec![];
        let mut out = ProjectOutcome::default();
        let (q0, v0) = (q.to_vec(), v.to_vec());
        let mut last = f64::INFINITY;
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
            if !kept.valid || kept.jac.shape() != (nh, 2 * n) || worst > 0.1 * last {
                match self.fresh_jacobian(t, q, v, degrees, kept) {
                    Ok(()) => {}
                    Err(Some(())) => break,
                    Err(None) => {
                        out.residual = f64::NAN;
                        return out;
                    }
                }
            }
            last = worst;
            let mut mu = h.clone();
            linalg::cholesky_solve(&kept.jjt, nh, &mut mu);
            for c in 0..2 * n {
                let d: f64 = (0..nh).map(|r| kept.jac[(r, c)] * mu[r]).sum();
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

    /// J = dh/d(q, v) of the hidden constraints at (t, q, v) (one dual pass per coordinate) and
    /// the Cholesky factor of J J^T into `kept`. Err(None): a hidden constraint could not be
    /// evaluated; Err(Some(())): J J^T is singular.
    fn fresh_jacobian(
        &self,
        t: f64,
        q: &[f64],
        v: &[f64],
        degrees: &[usize],
        kept: &mut KeptJacobian,
    ) -> Result<(), Option<()>> {
        let n = v.len();
        kept.valid = false;
        let mut hd: Vec<Dual64> = vec![];
        let mut jac = DMatrix::zeros(0, 2 * n);
        for c in 0..2 * n {
            let qd: Vec<Dual64> = (0..n)
                .map(|i| Dual::new(q[i], if c == i { 1.0 } else { 0.0 }))
                .collect();
            let vd: Vec<Dual64> = (0..n)
                .map(|i| Dual::new(v[i], if c == n + i { 1.0 } else { 0.0 }))
                .collect();
            self.hidden(Dual::from_re(t), &qd, &vd, degrees, &mut hd)
                .map_err(|_| None)?;
            if c == 0 {
                jac = DMatrix::zeros(hd.len(), 2 * n);
            }
            for (r, x) in hd.iter().enumerate() {
                jac[(r, c)] = x.eps;
            }
        }
        let nh = jac.nrows();
        let mut jjt = &jac * jac.transpose();
        linalg::cholesky(&mut jjt, nh).map_err(|_| Some(()))?;
        kept.jac = jac;
        kept.jjt = jjt;
        kept.valid = true;
        kept.fresh += 1;
        Ok(())
    }
}

/// The Jacobian of the hidden constraints and the Cholesky factor of J J^T, kept between
/// projections by their owner ([`Servo::project_with`]).
#[derive(Clone, Debug)]
pub struct KeptJacobian {
    jac: DMatrix<f64>,
    jjt: DMatrix<f64>,
    valid: bool,
    /// Fresh Jacobians computed into it so far.
    pub fresh: usize,
}

impl Default for KeptJacobian {
    fn default() -> Self {
        KeptJacobian {
            jac: DMatrix::zeros(0, 0),
            jjt: DMatrix::zeros(0, 0),
            valid: false,
            fresh: 0,
        }
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
    /// Sign of det b (+1 or -1): a change between two states means b passed through singular
    /// between them, however narrow the region where it is small.
    pub det_sign: f64,
}

/// How the decoupling matrix was conditioned where [`Servo::solve`] solved it (the fields of
/// [`Decoupled`] without tau).
#[derive(Clone, Copy, Debug)]
pub struct Conditioning {
    /// LU pivot ratio of b.
    pub rcond: f64,
    /// Smallest |b_i| / reference over the rows, and its row.
    pub row_ratio: f64,
    pub row: usize,
    /// Sign of det b (+1 or -1).
    pub det_sign: f64,
}

/// Buffers of [`Servo::step`] (and of the tau-seeded passes) at one scalar type.
struct StepWork<T: Scalar> {
    a: Vec<T>,
    qd: Vec<Dual<T>>,
    vd: Vec<Dual<T>>,
    taud: Vec<Dual<T>>,
    o: Vec<Dual<T>>,
}

impl<T: Scalar> Default for StepWork<T> {
    fn default() -> Self {
        StepWork {
            a: Vec::new(),
            qd: Vec::new(),
            vd: Vec::new(),
            taud: Vec::new(),
            o: Vec::new(),
        }
    }
}

impl<T: Scalar> ZrowsWork<T> {
    fn make(s: usize, m: usize, red: &Reduction) -> impl FnOnce() -> Self {
        let rho = red.kept.len();
        move || ZrowsWork {
            zero: vec![T::zero(); m],
            val: vec![T::zero(); s],
            b: DMatrix::from_element(s, m, T::zero()),
            vk: vec![T::zero(); s],
            bk: DMatrix::from_element(s, m, T::zero()),
            ks: Vec::with_capacity(s),
            bij: DMatrix::from_element(rho, rho, T::zero()),
            piv: vec![0; rho],
            c: vec![T::zero(); rho],
        }
    }

    /// z_r = y_r^(r_r) - c_r^T y_I^(r_I) from the values `val` and the decoupling rows `b`:
    /// b[I, J]^T c_r = b[r, J]^T.
    fn combine(&mut self, red: &Reduction, out: &mut [T]) -> Result<(), linalg::Singular> {
        let rho = red.kept.len();
        for a in 0..rho {
            for (cc, &i) in red.kept.iter().enumerate() {
                self.bij[(a, cc)] = self.b[(i, red.cols[a])];
            }
        }
        linalg::lu_factor(&mut self.bij, rho, &mut self.piv, 0.0)?;
        for x in out.iter_mut() {
            *x = T::zero();
        }
        for &r in &red.eliminated {
            for (a, x) in self.c.iter_mut().enumerate() {
                *x = self.b[(r, red.cols[a])];
            }
            linalg::lu_solve(&self.bij, rho, &self.piv, &mut self.c);
            let mut z = self.val[r];
            for (a, &i) in red.kept.iter().enumerate() {
                z -= self.c[a] * self.val[i];
            }
            out[r] = z;
        }
        Ok(())
    }
}

/// The lowest order taken by [`Servo::series`]; below it nested duals are cheaper (a series of
/// degree d carries the full capacity's coefficients; docs/benchmarks.md, stop 50).
pub const TAYLOR_FROM: usize = 3;

/// Coefficients kept by [`Servo::series`]: q_j, v_j for j <= [`MAX_RELATIVE_DEGREE`].
const SERIES: usize = MAX_RELATIVE_DEGREE + 1;

/// The motion's Taylor coefficients at one scalar type ([`Servo::series`]).
struct SeriesWork<T> {
    q: Vec<[T; SERIES]>,
    v: Vec<[T; SERIES]>,
    a: Vec<T>,
}

/// The series type of [`Servo::series`] over T (each pass sets its length).
type Series<T> = Taylor<T, SERIES>;

/// One pass's series of t, q, v, tau and its outputs ([`Servo::series_pass`]).
struct PassWork<T: Scalar> {
    t: Series<T>,
    q: Vec<Series<T>>,
    v: Vec<Series<T>>,
    tau: Vec<Series<T>>,
    out: Vec<Series<T>>,
}

impl<T: Scalar> Default for PassWork<T> {
    fn default() -> Self {
        PassWork {
            t: Taylor::zero(),
            q: Vec::new(),
            v: Vec::new(),
            tau: Vec::new(),
            out: Vec::new(),
        }
    }
}

impl<T: Scalar> PassWork<T> {
    /// t + s, the series q, v to degree len-1 and tau constant.
    fn load(&mut self, len: usize, t: T, tau: &[T], w: &SeriesWork<T>) {
        // t + s at the pass's length (an expression of t alone must carry every coefficient)
        let mut tc = [T::zero(); SERIES];
        tc[0] = t;
        tc[1] = T::one();
        self.t = Taylor::from_coefficients(&tc[..len]);
        self.q.clear();
        self.q
            .extend(w.q.iter().map(|c| Taylor::from_coefficients(&c[..len])));
        self.v.clear();
        self.v
            .extend(w.v.iter().map(|c| Taylor::from_coefficients(&c[..len])));
        self.tau.clear();
        self.tau.extend(tau.iter().map(|&x| Taylor::constant(x)));
        fit(&mut self.out, w.v.len(), Taylor::zero());
    }
}

/// [`Servo::zrows`]'s buffers at one scalar type.
struct ZrowsWork<T> {
    zero: Vec<T>,
    val: Vec<T>,
    b: DMatrix<T>,
    vk: Vec<T>,
    bk: DMatrix<T>,
    ks: Vec<usize>,
    bij: DMatrix<T>,
    piv: Vec<usize>,
    c: Vec<T>,
}

/// x as U where the caller has checked that T is U ([`Servo::series_at`]).
fn same<T: 'static + Copy, U: 'static + Copy>(x: &T) -> U {
    *(x as &dyn Any)
        .downcast_ref::<U>()
        .expect("the caller matched the types")
}

/// `x` resized to `n` (its capacity kept: no allocation once it has held `n`).
fn fit<X: Copy>(x: &mut Vec<X>, n: usize, zero: X) {
    x.clear();
    x.resize(n, zero);
}

/// `out[i] = x[i] + eps dx[i]` (a dual seeded along dx).
fn seed<T: Scalar>(out: &mut Vec<Dual<T>>, x: &[T], dx: &[T]) {
    out.clear();
    out.extend(x.iter().zip(dx).map(|(&a, &b)| Dual::new(a, b)));
}

/// `out[i] = x[i]` as duals with zero derivative.
fn lift<T: Scalar>(out: &mut Vec<Dual<T>>, x: &[T]) {
    out.clear();
    out.extend(x.iter().map(|&a| Dual::from_re(a)));
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

/// L^j g for every j <= k (k + 1 = `outs.len()`) from one evaluation of L^k: the nested level j
/// holds L^(k-1-j) and its derivative ([`Servo::lie_tau_upto`]).
fn upto0<M: Model, C: Constraints, T: Scalar>(
    x: &Servo<'_, M, C>,
    t: T,
    q: &[T],
    v: &[T],
    tau: &[T],
    outs: &mut [Vec<T>],
) -> Result<(), linalg::Singular> {
    x.rows_at(t, q, v, tau, &mut outs[0])
}

macro_rules! upto_level {
    ($name:ident, $inner:ident, $k:expr) => {
        fn $name<M: Model, C: Constraints, T: Scalar>(
            x: &Servo<'_, M, C>,
            t: T,
            q: &[T],
            v: &[T],
            tau: &[T],
            outs: &mut [Vec<T>],
        ) -> Result<(), linalg::Singular> {
            let (n, s) = (v.len(), outs[0].len());
            let mut a = vec![T::zero(); n];
            x.accel(t, q, v, tau, &mut a)?;
            let td = Dual::new(t, T::one());
            let qd: Vec<Dual<T>> = (0..n).map(|i| Dual::new(q[i], v[i])).collect();
            let vd: Vec<Dual<T>> = (0..n).map(|i| Dual::new(v[i], a[i])).collect();
            let taud: Vec<Dual<T>> = tau.iter().map(|&y| Dual::from_re(y)).collect();
            let mut inner = vec![vec![Dual::from_re(T::zero()); s]; $k];
            $inner::<M, C, Dual<T>>(x, td, &qd, &vd, &taud, &mut inner)?;
            for j in 0..$k {
                for i in 0..s {
                    outs[j][i] = inner[j][i].re;
                }
            }
            for i in 0..s {
                outs[$k][i] = inner[$k - 1][i].eps;
            }
            Ok(())
        }
    };
}
// the chains end at MAX_RELATIVE_DEGREE = 5 and MAX_REDUCED_DEGREE = 3
const _: () = assert!(MAX_RELATIVE_DEGREE == 5 && MAX_REDUCED_DEGREE == 3);
upto_level!(upto1, upto0, 1);
upto_level!(upto2, upto1, 2);
upto_level!(upto3, upto2, 3);
upto_level!(upto4, upto3, 4);
upto_level!(upto5, upto4, 5);

fn zupto0<M: Model, C: Constraints, T: Scalar>(
    x: &Servo<'_, M, C>,
    t: T,
    q: &[T],
    v: &[T],
    _tau: &[T],
    outs: &mut [Vec<T>],
) -> Result<(), linalg::Singular> {
    x.zrows(t, q, v, &mut outs[0])
}
upto_level!(zupto1, zupto0, 1);
upto_level!(zupto2, zupto1, 2);
upto_level!(zupto3, zupto2, 3);

fn zlie0<M: Model, C: Constraints, T: Scalar>(
    x: &Servo<'_, M, C>,
    t: T,
    q: &[T],
    v: &[T],
    _tau: &[T],
    out: &mut [T],
) -> Result<(), linalg::Singular> {
    x.zrows(t, q, v, out)
}
lie_level!(zlie1, zlie0);
lie_level!(zlie2, zlie1);
lie_level!(zlie3, zlie2);

/// |b_i|: the largest entry of row i.
fn row_norm(b: &DMatrix<f64>, i: usize) -> f64 {
    (0..b.ncols()).map(|j| b[(i, j)].abs()).fold(0.0, f64::max)
}

/// The relative degree of each row: the first order k whose b_k row exceeds [`DEGREE_TOL`] of the
/// row's largest over all orders.
fn first_degrees(bk: &[DMatrix<f64>], s: usize, _m: usize) -> Result<Vec<usize>, Unrealizable> {
    let mut degrees = vec![0; s];
    let mut missing = vec![];
    let bigs: Vec<f64> = (0..s)
        .map(|i| bk.iter().map(|b| row_norm(b, i)).fold(0.0, f64::max))
        .collect();
    let all = bigs.iter().copied().fold(0.0, f64::max);
    for (i, d) in degrees.iter_mut().enumerate() {
        let big = bigs[i];
        if !big.is_finite() {
            return Err(Unrealizable::Model);
        }
        // A row whose every b_k is round-off next to the other rows' is not reached at this state
        // (e.g. a crane's rope hanging still: its tau gradient vanishes to all orders there).
        if !(big > ROUNDOFF * all) {
            missing.push(i);
            continue;
        }
        match (0..bk.len()).find(|&k| row_norm(&bk[k], i) > DEGREE_TOL * big) {
            Some(k) => *d = k,
            None => missing.push(i),
        }
    }
    if missing.is_empty() {
        Ok(degrees)
    } else {
        Err(Unrealizable::NotReached { rows: missing })
    }
}

/// The structure algorithm's step for a rank-deficient square b ([`Reduction`]): pivots of a
/// Gaussian elimination with complete pivoting above `rank_tol` of the first give rows I and
/// columns J. None when b is not square, has full rank or rank zero, or a row to combine has a
/// degree beyond [`MAX_ELIMINATED_DEGREE`].
fn reduce(b: &DMatrix<f64>, degrees: &[usize], rank_tol: f64) -> Option<Reduction> {
    let (s, m) = b.shape();
    if s != m || degrees.iter().any(|&d| d > MAX_ELIMINATED_DEGREE) {
        return None;
    }
    let mut w = b.clone();
    let (mut rows, mut cols) = (vec![], vec![]);
    let mut first = 0.0;
    loop {
        let mut best = (0.0f64, 0, 0);
        for i in (0..s).filter(|i| !rows.contains(i)) {
            for j in (0..m).filter(|j| !cols.contains(j)) {
                if w[(i, j)].abs() > best.0 {
                    best = (w[(i, j)].abs(), i, j);
                }
            }
        }
        let (p, pi, pj) = best;
        if rows.is_empty() {
            first = p;
        }
        if !(p > rank_tol * first) || rows.len() == s {
            break;
        }
        for i in (0..s).filter(|i| !rows.contains(i) && *i != pi) {
            let f = w[(i, pj)] / w[(pi, pj)];
            for j in 0..m {
                w[(i, j)] -= f * w[(pi, j)];
            }
        }
        rows.push(pi);
        cols.push(pj);
    }
    if rows.is_empty() || rows.len() == s {
        return None;
    }
    let eliminated = (0..s).filter(|i| !rows.contains(i)).collect();
    Some(Reduction {
        kept: rows,
        cols,
        eliminated,
        row_degrees: degrees.to_vec(),
    })
}

/// The real parts of a slice (messages and tests).
pub fn real<T: Scalar>(x: &[T]) -> Vec<f64> {
    x.iter().map(|&y| re(y)).collect()
}
