//! Accelerations and constraint reactions from A a - F = B^T lambda, B a = gamma.
//!
//! Given the mass matrix A (nv x nv, SPD), the total natural force F = G + Q (2.2), the stacked
//! constraint Jacobian B (s x nv) and gamma, every formulation returns the acceleration a = dv/dt
//! and multipliers lambda with A a - F = B^T lambda: the total ideal reaction, whose programme rows
//! make up the control force u (2.12) and whose system rows are joint reactions.
//!
//! - [`Formulation::NullSpace`] (the paper, (2.7)-(2.10)): D = orthonormal basis of null(B) from a
//!   column-pivoted Householder QR of B^T (rank-revealing; never the paper's hand-made ratios of
//!   (2.19), which divide by velocities). The equations D A a = D F, B a = gamma are solved in the
//!   QR's orthonormal basis: with B_hat^T P = Q R, Q = [Q1 Q2], D = Q2^T and a = Q1 y1 + Q2 y2,
//!   R1^T y1 = P^T gamma_hat and (D A Q2) y2 = D F - (D A Q1) y1, where D A Q2 is the symmetric
//!   positive definite reduced inertia (Cholesky). Q^T A Q costs O(s n^2) with the reflectors;
//!   when few directions are free (m = n - s small: a robot's task rows) Q2 is formed instead and
//!   only D A Q2 and D (F - A Q1 y1) are computed (O(m n^2)). No inverse of A.
//! - [`Formulation::NullSpaceStacked`]: the same equations as the paper writes them, the square
//!   system [D A; B] a = [D F; gamma] (2.10), by LU of the stacked matrix (2/3 n^3 flops, and its
//!   rows mix the scales of A and of B).
//! - [`Formulation::Kkt`] (Lagrange multipliers): [A, -B^T; B, 0] [a; lambda] = [F; gamma].
//! - [`Formulation::RangeSpace`] (the earlier method the paper criticizes, refs [4, 5]): explicit
//!   A^-1; lambda = (B A^-1 B^T)^-1 (gamma - B A^-1 F), a = A^-1 (F + B^T lambda).
//! - [`Formulation::UdwadiaKalaba`] (Udwadia & Kalaba, Proc. R. Soc. A 439 (1992) 407-410):
//!   a = a0 + W (B W)^+ (gamma - B a0), a0 = A^-1 F, W W^T = A^-1; here W = L^-T from the Cholesky
//!   factor A = L L^T and the pseudo-inverse from a QR of (B W)^T.
//! - [`Formulation::ArticulatedBody`] (O(n s^2 + s^3) on kinematic trees, A never formed): the
//!   range-space equations with A^-1 applied by the articulated-body factorization (Featherstone,
//!   RBDA 2008, Table 7.1; `crate::tree::aba_factor`): a0 = A^-1 F, X = A^-1 B_hat^T by s unit-force
//!   solves, (B_hat X) lambda_hat = gamma_hat - B_hat a0 (Cholesky of the s x s SPD matrix),
//!   a = a0 + X lambda_hat. u = A a - F comes from an O(n) product (inverse dynamics with v = 0).
//!   On models without that factorization ([`crate::model::Model::has_mass_factor`] false:
//!   lagrangian scenes and the hand-written problems) the same equations with A^-1 from a dense
//!   Cholesky factor of A.
//! - [`Formulation::Auto`] (the default): [`Formulation::ArticulatedBody`] on models with the
//!   articulated-body factorization and at least [`AUTO_ARTICULATED_NV`] velocities, else
//!   [`Formulation::NullSpace`] ([`Formulation::resolve`]).
//!
//! Rows of B are normalized to unit length before factorizing (this changes neither null(B) nor
//! the solution), so rank decisions compare like with like. A row whose gradient vanishes or a set of
//! dependent rows is reported as [`FormulationError::RankDeficient`]; it is never papered over.

use crate::linalg::{self, Singular};
use crate::scalar::{re, Scalar};
use nalgebra::DMatrix;

/// Which equations give the accelerations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Formulation {
    /// The paper's null-space form (2.8)-(2.10) with D from a rank-revealing QR, solved in the
    /// QR's orthonormal basis (Cholesky of the reduced inertia D A D^T).
    NullSpace,
    /// The same, solved as the stacked square system [D A; B] a = [D F; gamma] by LU.
    NullSpaceStacked,
    /// Lagrange multipliers: the (n + s) KKT system.
    Kkt,
    /// Range space with an explicit inverse of A.
    RangeSpace,
    /// Udwadia-Kalaba with the Moore-Penrose pseudo-inverse.
    UdwadiaKalaba,
    /// Range space with A^-1 from the articulated-body factorization: O(n) per solve on trees.
    ArticulatedBody,
    /// [`Formulation::ArticulatedBody`] on trees of at least [`AUTO_ARTICULATED_NV`] velocities,
    /// else [`Formulation::NullSpace`] (see [`Formulation::resolve`]).
    Auto,
}

/// Smallest number of velocities at which [`Formulation::Auto`] picks the articulated-body
/// formulation on a tree. Measured (`progmo bench --only anchor`, chains with 2 programme rows,
/// README's Benchmarks): null-space is faster below, articulated-body from here on.
pub const AUTO_ARTICULATED_NV: usize = 20;

impl Formulation {
    /// All methods, for comparisons ([`Formulation::Auto`] names one of them).
    pub const ALL: [Formulation; 6] = [
        Formulation::NullSpace,
        Formulation::NullSpaceStacked,
        Formulation::Kkt,
        Formulation::RangeSpace,
        Formulation::UdwadiaKalaba,
        Formulation::ArticulatedBody,
    ];

    /// Every value a setting may take: `Auto`, then [`Formulation::ALL`].
    pub const NAMED: [Formulation; 7] = [
        Formulation::Auto,
        Formulation::NullSpace,
        Formulation::NullSpaceStacked,
        Formulation::Kkt,
        Formulation::RangeSpace,
        Formulation::UdwadiaKalaba,
        Formulation::ArticulatedBody,
    ];

    /// The method this setting stands for on a model with `nv` velocities that has (`factored`) or
    /// lacks the articulated-body factorization: `Auto` picks [`Formulation::ArticulatedBody`] when
    /// `factored` and `nv >= AUTO_ARTICULATED_NV`, else [`Formulation::NullSpace`]; every other
    /// value is itself.
    pub fn resolve(self, nv: usize, factored: bool) -> Formulation {
        match self {
            Formulation::Auto if factored && nv >= AUTO_ARTICULATED_NV => {
                Formulation::ArticulatedBody
            }
            Formulation::Auto => Formulation::NullSpace,
            f => f,
        }
    }
}

/// A(q) as the articulated-body formulation uses it: factored once, then solves and products.
pub trait MassOperator<S: Scalar> {
    /// Factor A; a reciprocal condition estimate, or where A is not positive definite.
    fn factor(&mut self) -> Result<f64, Singular>;
    /// `x <- A^-1 x`.
    fn solve(&mut self, x: &mut [S]);
    /// `x <- A^-1 x` for `cols` right-hand sides (x column-major, `n x cols`).
    fn solve_block(&mut self, x: &mut [S], cols: usize) {
        let n = x.len() / cols.max(1);
        for col in x.chunks_mut(n.max(1)).take(cols) {
            self.solve(col);
        }
    }
    /// `out = A x`.
    fn mul(&mut self, x: &[S], out: &mut [S]);
}

/// (min / max)^2 of the diagonal of a Cholesky factor L of the leading `n x n` block: the pivot
/// ratio of L L^T, a reciprocal condition estimate (1 for n = 0).
fn cholesky_rcond<S: Scalar>(l: &DMatrix<S>, n: usize) -> f64 {
    let (mut lmin, mut lmax) = (f64::INFINITY, 0.0f64);
    for i in 0..n {
        let d = re(l[(i, i)]).abs();
        lmin = lmin.min(d);
        lmax = lmax.max(d);
    }
    if n == 0 {
        1.0
    } else {
        (lmin / lmax).powi(2)
    }
}

/// The dense A with its Cholesky factor L (the lower triangle of `l`, as `linalg::cholesky` leaves it).
struct DenseCholesky<'a, S: Scalar> {
    a: &'a DMatrix<S>,
    l: &'a DMatrix<S>,
    n: usize,
}

impl<S: Scalar> MassOperator<S> for DenseCholesky<'_, S> {
    fn factor(&mut self) -> Result<f64, Singular> {
        Ok(cholesky_rcond(self.l, self.n))
    }
    fn solve(&mut self, x: &mut [S]) {
        linalg::cholesky_solve(self.l, self.n, x);
    }
    fn mul(&mut self, x: &[S], out: &mut [S]) {
        for o in out.iter_mut() {
            *o = S::zero();
        }
        for (j, col) in self.a.column_iter().enumerate() {
            let xj = x[j];
            for (o, &y) in out.iter_mut().zip(col.iter()) {
                *o += y * xj;
            }
        }
    }
}

/// Why the accelerations could not be computed.
#[derive(Clone, Debug, PartialEq)]
pub enum FormulationError {
    /// B has numerical rank `rank` < s. `rows` lists the rows judged dependent or vanishing;
    /// `rcond` is the smallest |r_jj| of the normalized QR (or the vanishing row's norm).
    RankDeficient {
        rank: usize,
        rows: Vec<usize>,
        rcond: f64,
    },
    /// The square system (or A itself) is numerically singular.
    SingularSystem { rcond: f64 },
    /// B, gamma, A or F contain NaN or infinity.
    NonFinite,
    /// With actuators ([`crate::servo`]): the decoupling matrix d y^(r) / d tau is singular (pivot
    /// ratio `rcond`): the actuators cannot realize the programme here.
    Unrealizable { rcond: f64 },
}

impl std::fmt::Display for FormulationError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FormulationError::RankDeficient { rank, rows, rcond } => write!(
                f,
                "the programme Jacobian has rank {rank} < {}: rows {rows:?} vanish or are \
                 dependent (rcond {rcond:.2e})",
                rank + rows.len()
            ),
            FormulationError::SingularSystem { rcond } => write!(
                f,
                "the linear system for dv/dt is singular (reciprocal condition {rcond:.2e})"
            ),
            FormulationError::NonFinite => {
                f.write_str("A, G + Q, the programme Jacobian or gamma is not finite")
            }
            FormulationError::Unrealizable { rcond } => write!(
                f,
                "the actuators cannot realize the programme: the decoupling matrix is singular \
                 (pivot ratio {rcond:.2e})"
            ),
        }
    }
}

impl std::error::Error for FormulationError {}

/// Diagnostics of one solve.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Diagnostics {
    /// Smallest |r_jj| of the QR of the row-normalized B^T (1 for orthogonal rows; 1 if s = 0).
    pub b_rcond: f64,
    /// Pivot ratio of the LU of the square system (a reciprocal condition estimate).
    pub system_rcond: f64,
    /// |D u|_inf / max(|u|, |A a|, |F|)_inf: how far u is from the row space of B (2.7), relative to
    /// the terms it is computed from (every method reports it, from the same QR).
    pub du: f64,
    /// Factorizations performed.
    pub factorizations: usize,
    /// Smallest |B_i| / row_scale_i over the rows (1 if s = 0) and the row where it occurs: how
    /// far a row's gradient collapsed against its reference (t0) norm.
    pub row_ratio: f64,
    pub row_ratio_row: usize,
    /// |A a - F| (inf-norm): the total ideal reaction, u plus system reactions (2.12).
    pub u_norm: f64,
    /// max(|A a|, |F|, |A a - F|) (inf-norms): the terms u is computed from.
    pub u_terms: f64,
    /// With actuators: the sign of the decoupling matrix's determinant (+1 or -1; 0 otherwise).
    pub det_sign: f64,
}

/// Tolerances of the rank decisions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RankTolerances {
    /// Dependent rows: smallest |r_jj| of the QR of the row-normalized B^T below this. Default 1e-10.
    pub dependent: f64,
    /// A row whose gradient norm |B_i| falls below this is vanishing. Default 1e-12 (absolute: the
    /// caller scales it by the row's norm at the initial state).
    pub vanishing: f64,
}

impl Default for RankTolerances {
    fn default() -> Self {
        RankTolerances {
            dependent: 1e-10,
            vanishing: 1e-12,
        }
    }
}

/// Preallocated workspace for all formulations.
pub struct FormulationWork<S: Scalar> {
    nv: usize,
    s: usize,
    bt: DMatrix<S>,
    beta: Vec<S>,
    perm: Vec<usize>,
    norms: Vec<S>,
    k: DMatrix<S>,
    piv: Vec<usize>,
    rhs: Vec<S>,
    tmp: Vec<S>,
    tmp2: Vec<S>,
    inv: DMatrix<S>,
    x: DMatrix<S>,
    ainv_bt: DMatrix<S>,
    /// D^T (columns 0..m) and A D^T (columns m..2m), m = nv - s: the null-space method when
    /// D A D^T is cheaper than Q^T A Q.
    dt: DMatrix<S>,
    /// F and B_hat^T (nv x (1 + s), column-major): the range-space solves as one block.
    block: Vec<S>,
}

impl<S: Scalar> FormulationWork<S> {
    /// Workspace for `nv` velocities and `s` constraint rows.
    pub fn new(nv: usize, s: usize) -> Self {
        let z = S::zero();
        FormulationWork {
            nv,
            s,
            bt: DMatrix::from_element(nv, s, z),
            beta: vec![z; s],
            perm: vec![0; s],
            norms: vec![z; s],
            k: DMatrix::from_element(nv + s, nv + s, z),
            piv: vec![0; nv + s],
            rhs: vec![z; nv + s],
            tmp: vec![z; nv + s],
            tmp2: vec![z; nv + s],
            inv: DMatrix::from_element(nv, nv, z),
            x: DMatrix::from_element(nv, s, z),
            ainv_bt: DMatrix::from_element(nv, s, z),
            dt: DMatrix::from_element(nv, 2 * nv.saturating_sub(s), z),
            block: vec![z; nv * (1 + s)],
        }
    }

    /// Solve for `acc` (nv) and `lambda` (s). `row_scale[i]` is the reference norm of row i for the
    /// vanishing test (its norm at the initial state; 1 where unknown).
    #[allow(clippy::too_many_arguments)]
    pub fn solve(
        &mut self,
        formulation: Formulation,
        a: &DMatrix<S>,
        force: &[S],
        b: &DMatrix<S>,
        gamma: &[S],
        row_scale: &[f64],
        tol: &RankTolerances,
        acc: &mut [S],
        lambda: &mut [S],
    ) -> Result<Diagnostics, FormulationError> {
        let nv = self.nv;
        let mut diag = self.factor_rows(b, gamma, row_scale, tol)?;
        match formulation.resolve(nv, false) {
            Formulation::NullSpace | Formulation::Auto => {
                self.null_space(a, force, gamma, acc, &mut diag)?
            }
            Formulation::NullSpaceStacked => {
                self.null_space_stacked(a, force, gamma, acc, &mut diag)?
            }
            Formulation::Kkt => self.kkt(a, force, b, gamma, acc, &mut diag)?,
            Formulation::RangeSpace => self.range_space(a, force, b, gamma, acc, &mut diag)?,
            Formulation::UdwadiaKalaba => {
                self.udwadia_kalaba(a, force, b, gamma, acc, &mut diag)?
            }
            Formulation::ArticulatedBody => {
                // no O(n) factorization here: A^-1 from a dense Cholesky factor
                self.load_mass(a);
                linalg::cholesky(&mut self.k, nv)
                    .map_err(|e| FormulationError::SingularSystem { rcond: e.rcond })?;
                let l = std::mem::replace(&mut self.k, DMatrix::from_element(0, 0, S::zero()));
                let mut op = DenseCholesky { a, l: &l, n: nv };
                let r = self.range_operator(&mut op, force, gamma, acc, &mut diag);
                self.k = l;
                r?
            }
        }
        // Reaction u = A a - F = B^T lambda = B_hat^T N lambda. With Q^T u = w:
        // R P^T (N lambda) = w[..s], and D u = w[s..] should vanish (2.7).
        for i in 0..nv {
            self.tmp[i] = -force[i];
        }
        for (j, col) in a.column_iter().enumerate() {
            let aj = acc[j];
            for (t, &x) in self.tmp[..nv].iter_mut().zip(col.iter()) {
                *t += x * aj;
            }
        }
        self.reaction(force, &mut diag, lambda);
        Ok(diag)
    }

    /// [`Formulation::ArticulatedBody`] with A as an operator (`op`: the model's articulated-body
    /// factorization), A never formed: the same rank decisions, diagnostics and multipliers as
    /// [`FormulationWork::solve`], with u = A a - F from `op.mul`.
    #[allow(clippy::too_many_arguments)]
    pub fn solve_factored(
        &mut self,
        op: &mut impl MassOperator<S>,
        force: &[S],
        b: &DMatrix<S>,
        gamma: &[S],
        row_scale: &[f64],
        tol: &RankTolerances,
        acc: &mut [S],
        lambda: &mut [S],
    ) -> Result<Diagnostics, FormulationError> {
        let nv = self.nv;
        let mut diag = self.factor_rows(b, gamma, row_scale, tol)?;
        self.range_operator(op, force, gamma, acc, &mut diag)?;
        op.mul(&acc[..nv], &mut self.tmp[..nv]);
        for (t, &f) in self.tmp[..nv].iter_mut().zip(force.iter()) {
            *t -= f;
        }
        self.reaction(force, &mut diag, lambda);
        Ok(diag)
    }

    /// Normalize the rows (B_hat = N^-1 B into `bt` and `x`) and factor B_hat^T P = Q R; the
    /// vanishing and dependent rows are refused here, before any method runs.
    fn factor_rows(
        &mut self,
        b: &DMatrix<S>,
        gamma: &[S],
        row_scale: &[f64],
        tol: &RankTolerances,
    ) -> Result<Diagnostics, FormulationError> {
        let (nv, s) = (self.nv, self.s);
        let mut diag = Diagnostics {
            b_rcond: 1.0,
            system_rcond: 1.0,
            du: 0.0,
            factorizations: 0,
            row_ratio: 1.0,
            row_ratio_row: 0,
            u_norm: 0.0,
            u_terms: 0.0,
            det_sign: 0.0,
        };
        // Normalize rows: B_hat = N^-1 B, gamma_hat = N^-1 gamma. B is column-major: the squared
        // row norms accumulate column by column (each row's sum in the order j = 0..nv, as a
        // row-wise loop would), into `norms`.
        assert_eq!((b.nrows(), b.ncols()), (s, nv), "B is s x nv");
        let bs = b.as_slice();
        let norms = &mut self.norms[..s];
        norms.fill(S::zero());
        for col in bs.chunks_exact(s.max(1)).take(nv) {
            for (n2, &x) in norms.iter_mut().zip(col) {
                *n2 += x * x;
            }
        }
        for i in 0..s {
            let n = self.norms[i].sqrt();
            if !re(n).is_finite() || !re(gamma[i]).is_finite() {
                return Err(FormulationError::NonFinite);
            }
            if re(n) <= tol.vanishing * row_scale[i].max(f64::MIN_POSITIVE) || re(n) == 0.0 {
                return Err(FormulationError::RankDeficient {
                    rank: s - 1,
                    rows: vec![i],
                    rcond: re(n) / row_scale[i].max(f64::MIN_POSITIVE),
                });
            }
            let ratio = re(n) / row_scale[i].max(f64::MIN_POSITIVE);
            if ratio < diag.row_ratio {
                diag.row_ratio = ratio;
                diag.row_ratio_row = i;
            }
            self.norms[i] = n;
            let inv = n.recip();
            let (lb, lx) = (self.bt.nrows(), self.x.nrows());
            let bt = &mut self.bt.as_mut_slice()[i * lb..i * lb + nv];
            let x = &mut self.x.as_mut_slice()[i * lx..i * lx + nv];
            for j in 0..nv {
                let y = bs[j * s + i] * inv;
                bt[j] = y;
                x[j] = y;
            }
        }
        // Rank-revealing QR of B_hat^T (nv x s): B_hat^T P = Q R.
        if s > 0 {
            let rank = linalg::qr_colpiv(
                &mut self.bt,
                nv,
                s,
                &mut self.beta,
                &mut self.perm,
                tol.dependent,
            );
            diag.factorizations += 1;
            let mut rmin = f64::INFINITY;
            for j in 0..s {
                rmin = rmin.min(re(self.bt[(j, j)]).abs());
            }
            diag.b_rcond = rmin;
            if rank < s || rmin < tol.dependent {
                let rank = rank.min(s - 1);
                return Err(FormulationError::RankDeficient {
                    rank,
                    rows: self.perm[rank..s].to_vec(),
                    rcond: rmin,
                });
            }
        }
        Ok(diag)
    }

    /// From u = A a - F in `tmp[..nv]`: the diagnostics of u (2.7) and lambda from
    /// R P^T (N lambda) = (Q^T u)[..s].
    fn reaction(&mut self, force: &[S], diag: &mut Diagnostics, lambda: &mut [S]) {
        let (nv, s) = (self.nv, self.s);
        // Scale of the terms of u = A a - F, so that du measures round-off, not cancellation.
        let (mut umax, mut unorm) = (0.0f64, 0.0f64);
        for i in 0..nv {
            unorm = unorm.max(re(self.tmp[i]).abs());
            umax = umax
                .max(re(self.tmp[i]).abs())
                .max(re(force[i]).abs())
                .max(re(self.tmp[i] + force[i]).abs());
        }
        diag.u_norm = unorm;
        diag.u_terms = umax;
        linalg::qr_apply_qt(&self.bt, nv, s, &self.beta, &mut self.tmp[..nv]);
        let mut du = 0.0f64;
        for i in s..nv {
            du = du.max(re(self.tmp[i]).abs());
        }
        diag.du = du / umax.max(f64::MIN_POSITIVE);
        linalg::solve_upper(&self.bt, s, &mut self.tmp[..s]);
        for j in 0..s {
            let row = self.perm[j];
            lambda[row] = self.tmp[j] / self.norms[row];
        }
    }

    /// Range space with A^-1 from `op` (module docs, [`Formulation::ArticulatedBody`]):
    /// a0 = A^-1 F, X = A^-1 B_hat^T, (B_hat X) lambda_hat = gamma_hat - B_hat a0 by Cholesky,
    /// a = a0 + X lambda_hat.
    fn range_operator(
        &mut self,
        op: &mut impl MassOperator<S>,
        force: &[S],
        gamma: &[S],
        acc: &mut [S],
        diag: &mut Diagnostics,
    ) -> Result<(), FormulationError> {
        let (nv, s) = (self.nv, self.s);
        let rcond = op
            .factor()
            .map_err(|e| FormulationError::SingularSystem { rcond: e.rcond })?;
        diag.factorizations += 1;
        diag.system_rcond = rcond;
        // a0 = A^-1 F and X = A^-1 B_hat^T (column r of `x` is B_hat_r^T) in one block
        self.block[..nv].copy_from_slice(&force[..nv]);
        for r in 0..s {
            for j in 0..nv {
                self.block[(1 + r) * nv + j] = self.x[(j, r)];
            }
        }
        op.solve_block(&mut self.block, 1 + s);
        acc[..nv].copy_from_slice(&self.block[..nv]);
        if s == 0 {
            return Ok(());
        }
        for r in 0..s {
            for j in 0..nv {
                self.ainv_bt[(j, r)] = self.block[(1 + r) * nv + j];
            }
        }
        // K = B_hat X (s x s, SPD; lower triangle) in `inv`, rhs = gamma_hat - B_hat a0
        for c in 0..s {
            for r in c..s {
                let mut k = S::zero();
                for j in 0..nv {
                    k += self.x[(j, r)] * self.ainv_bt[(j, c)];
                }
                self.inv[(r, c)] = k;
            }
            let mut ba0 = S::zero();
            for j in 0..nv {
                ba0 += self.x[(j, c)] * acc[j];
            }
            self.rhs[c] = gamma[c] / self.norms[c] - ba0;
        }
        linalg::cholesky(&mut self.inv, s)
            .map_err(|e| FormulationError::SingularSystem { rcond: e.rcond })?;
        diag.factorizations += 1;
        diag.system_rcond = rcond.min(cholesky_rcond(&self.inv, s));
        linalg::cholesky_solve(&self.inv, s, &mut self.rhs[..s]);
        for r in 0..s {
            let lr = self.rhs[r];
            for j in 0..nv {
                acc[j] += self.ainv_bt[(j, r)] * lr;
            }
        }
        Ok(())
    }

    /// (2.8)-(2.10) in the basis Q of the QR of B_hat^T (module docs): K = Q^T A Q,
    /// R1^T y1 = P^T gamma_hat, K22 y2 = (Q^T F)_2 - K21 y1 (Cholesky), a = Q y.
    fn null_space(
        &mut self,
        a: &DMatrix<S>,
        force: &[S],
        gamma: &[S],
        acc: &mut [S],
        diag: &mut Diagnostics,
    ) -> Result<(), FormulationError> {
        let (nv, s) = (self.nv, self.s);
        let m = nv - s;
        // flops: D A D^T and D (F - A a_p) against the whole Q^T A Q (two sweeps of s reflectors)
        if nv * m * (2 * nv + m) < 4 * s * nv * nv {
            return self.null_space_reduced(a, force, gamma, acc, diag);
        }
        self.null_space_whole(a, force, gamma, acc, diag)
    }

    /// [`Self::null_space`] through K = Q^T A Q.
    fn null_space_whole(
        &mut self,
        a: &DMatrix<S>,
        force: &[S],
        gamma: &[S],
        acc: &mut [S],
        diag: &mut Diagnostics,
    ) -> Result<(), FormulationError> {
        let (nv, s) = (self.nv, self.s);
        let m = nv - s;
        // K = (Q^T A) Q.
        self.load_mass(a);
        linalg::qr_apply_qt_mat(&self.bt, nv, s, &self.beta, &mut self.k, nv);
        linalg::qr_apply_q_right(&self.bt, nv, s, &self.beta, &mut self.k, nv, &mut self.tmp2);
        // y1 from the programme rows in pivot order.
        self.programme_coordinates(gamma);
        // (Q^T F)_2 - K21 y1, then the reduced inertia K22 = D A D^T by Cholesky.
        self.tmp[..nv].copy_from_slice(&force[..nv]);
        linalg::qr_apply_qt(&self.bt, nv, s, &self.beta, &mut self.tmp[..nv]);
        self.rhs[s..nv].copy_from_slice(&self.tmp[s..nv]);
        for j in 0..s {
            let yj = self.rhs[j];
            for i in s..nv {
                let kij = self.k[(i, j)];
                self.rhs[i] -= kij * yj;
            }
        }
        for j in s..nv {
            self.inv
                .column_mut(j - s)
                .rows_mut(0, m)
                .copy_from(&self.k.column(j).rows(s, m));
        }
        self.factor_reduced_inertia(m, diag)?;
        linalg::cholesky_solve(&self.inv, m, &mut self.rhs[s..nv]);
        linalg::qr_apply_q(&self.bt, nv, s, &self.beta, &mut self.rhs[..nv]);
        acc[..nv].copy_from_slice(&self.rhs[..nv]);
        Ok(())
    }

    /// (2.8)-(2.10) with D^T = Q[:, s..] formed (few free directions, m = nv - s small): the
    /// particular solution a_p = Q (y1, 0) of B_hat a = gamma_hat (R1^T y1 = P^T gamma_hat),
    /// (D A D^T) y2 = D (F - A a_p) by Cholesky, a = a_p + D^T y2. The same solution as
    /// [`Self::null_space`] (K21 y1 = D A a_p), without forming Q^T A Q.
    fn null_space_reduced(
        &mut self,
        a: &DMatrix<S>,
        force: &[S],
        gamma: &[S],
        acc: &mut [S],
        diag: &mut Diagnostics,
    ) -> Result<(), FormulationError> {
        let (nv, s) = (self.nv, self.s);
        let m = nv - s;
        let z = S::zero();
        self.programme_coordinates(gamma);
        self.rhs[s..nv].fill(z);
        linalg::qr_apply_q(&self.bt, nv, s, &self.beta, &mut self.rhs[..nv]);
        acc[..nv].copy_from_slice(&self.rhs[..nv]);
        if m == 0 {
            return self.factor_reduced_inertia(0, diag);
        }
        // Over column slices (dt is nv x 2m: D^T, then A D^T), each sum in the order of the
        // index loops it replaces: the same operations, bit for bit.
        debug_assert_eq!(self.dt.nrows(), nv);
        let (dt, tmp) = (self.dt.as_mut_slice(), &mut self.tmp[..nv]);
        let (d_t, ad_t) = dt.split_at_mut(m * nv);
        // D^T: Q applied to the unit vectors e_s.. e_nv-1; then A D^T.
        for (j, dj) in d_t.chunks_exact_mut(nv).enumerate() {
            dj.fill(z);
            dj[s + j] = S::one();
            linalg::qr_apply_q(&self.bt, nv, s, &self.beta, dj);
        }
        let columns = || a.as_slice().chunks_exact(a.nrows()).take(nv);
        for (dj, out) in d_t.chunks_exact(nv).zip(ad_t.chunks_exact_mut(nv)) {
            out.fill(z);
            for (col, &d) in columns().zip(dj) {
                for (o, &x) in out.iter_mut().zip(col) {
                    *o += x * d;
                }
            }
        }
        // r = F - A a_p, rhs2 = D r; K22 = D (A D^T), lower triangle.
        tmp.copy_from_slice(&force[..nv]);
        for (col, &ak) in columns().zip(acc.iter()) {
            for (t, &x) in tmp.iter_mut().zip(col) {
                *t -= x * ak;
            }
        }
        let dot = |x: &[S], y: &[S]| {
            let mut r = z;
            for (&p, &q) in x.iter().zip(y) {
                r += p * q;
            }
            r
        };
        for (j, dj) in d_t.chunks_exact(nv).enumerate() {
            self.rhs[j] = dot(dj, tmp);
            for (c, adc) in ad_t.chunks_exact(nv).enumerate().take(j + 1) {
                self.inv[(j, c)] = dot(dj, adc);
            }
        }
        self.factor_reduced_inertia(m, diag)?;
        linalg::cholesky_solve(&self.inv, m, &mut self.rhs[..m]);
        for (dj, &y) in self
            .dt
            .as_slice()
            .chunks_exact(nv)
            .take(m)
            .zip(&self.rhs[..m])
        {
            for (x, &d) in acc[..nv].iter_mut().zip(dj) {
                *x += d * y;
            }
        }
        Ok(())
    }

    /// y1 of R1^T y1 = P^T gamma_hat into `rhs[..s]`: the coordinates of a along Q1 that the
    /// programme rows fix.
    fn programme_coordinates(&mut self, gamma: &[S]) {
        let s = self.s;
        for j in 0..s {
            let row = self.perm[j];
            self.rhs[j] = gamma[row] / self.norms[row];
        }
        linalg::solve_upper_t(&self.bt, s, &mut self.rhs[..s]);
    }

    /// Cholesky of the reduced inertia D A D^T (the leading `m x m` block of `inv`) and its
    /// pivot ratio as the system's reciprocal condition.
    fn factor_reduced_inertia(
        &mut self,
        m: usize,
        diag: &mut Diagnostics,
    ) -> Result<(), FormulationError> {
        linalg::cholesky(&mut self.inv, m)
            .map_err(|e| FormulationError::SingularSystem { rcond: e.rcond })?;
        diag.factorizations += 1;
        diag.system_rcond = cholesky_rcond(&self.inv, m);
        Ok(())
    }

    /// (2.10) as written: [B_hat; D A] a = [gamma_hat; D F], D = rows s..nv of Q^T, by LU.
    fn null_space_stacked(
        &mut self,
        a: &DMatrix<S>,
        force: &[S],
        gamma: &[S],
        acc: &mut [S],
        diag: &mut Diagnostics,
    ) -> Result<(), FormulationError> {
        let (nv, s) = (self.nv, self.s);
        for i in 0..nv {
            for j in 0..nv {
                self.k[(i, j)] = a[(i, j)];
            }
            self.rhs[i] = force[i];
        }
        // Q^T [A | F]: rows s.. are D A and D F.
        linalg::qr_apply_qt_mat(&self.bt, nv, s, &self.beta, &mut self.k, nv);
        linalg::qr_apply_qt(&self.bt, nv, s, &self.beta, &mut self.rhs[..nv]);
        // Rows 0..s: the normalized programme B_hat a = gamma_hat, in pivot order.
        for j in 0..s {
            let row = self.perm[j];
            for col in 0..nv {
                self.k[(j, col)] = self.bt_row_entry(row, col);
            }
            self.rhs[j] = gamma[row] / self.norms[row];
        }
        self.lu_solve_k(nv, acc, diag)
    }

    /// Entry (row, col) of B_hat (kept in `x` by `solve`, since the QR overwrites `bt`).
    fn bt_row_entry(&self, row: usize, col: usize) -> S {
        self.x[(col, row)]
    }

    fn lu_solve_k(
        &mut self,
        n: usize,
        out: &mut [S],
        diag: &mut Diagnostics,
    ) -> Result<(), FormulationError> {
        let rcond = linalg::lu_factor(&mut self.k, n, &mut self.piv, 0.0)
            .map_err(|e: Singular| FormulationError::SingularSystem { rcond: e.rcond })?;
        diag.factorizations += 1;
        diag.system_rcond = rcond;
        linalg::lu_solve(&self.k, n, &self.piv, &mut self.rhs[..n]);
        out[..self.nv].copy_from_slice(&self.rhs[..self.nv]);
        Ok(())
    }

    /// [A, -B_hat^T; B_hat, 0] [a; N lambda] = [F; gamma_hat].
    fn kkt(
        &mut self,
        a: &DMatrix<S>,
        force: &[S],
        b: &DMatrix<S>,
        gamma: &[S],
        acc: &mut [S],
        diag: &mut Diagnostics,
    ) -> Result<(), FormulationError> {
        let (nv, s) = (self.nv, self.s);
        let n = nv + s;
        for i in 0..n {
            for j in 0..n {
                self.k[(i, j)] = S::zero();
            }
        }
        for i in 0..nv {
            for j in 0..nv {
                self.k[(i, j)] = a[(i, j)];
            }
            self.rhs[i] = force[i];
        }
        for r in 0..s {
            let inv = self.norms[r].recip();
            for j in 0..nv {
                let bij = b[(r, j)] * inv;
                self.k[(nv + r, j)] = bij;
                self.k[(j, nv + r)] = -bij;
            }
            self.rhs[nv + r] = gamma[r] * inv;
        }
        self.lu_solve_k(n, acc, diag)
    }

    /// Explicit inverse: lambda = (B A^-1 B^T)^-1 (gamma - B A^-1 F), a = A^-1 (F + B^T lambda).
    fn range_space(
        &mut self,
        a: &DMatrix<S>,
        force: &[S],
        b: &DMatrix<S>,
        gamma: &[S],
        acc: &mut [S],
        diag: &mut Diagnostics,
    ) -> Result<(), FormulationError> {
        let (nv, s) = (self.nv, self.s);
        self.load_mass(a);
        let rcond = linalg::lu_factor(&mut self.k, nv, &mut self.piv, 0.0)
            .map_err(|e| FormulationError::SingularSystem { rcond: e.rcond })?;
        diag.factorizations += 1;
        linalg::lu_inverse(&self.k, nv, &self.piv, &mut self.inv, &mut self.tmp[..nv]);
        // a0 = A^-1 F
        for i in 0..nv {
            let mut x = S::zero();
            for j in 0..nv {
                x += self.inv[(i, j)] * force[j];
            }
            acc[i] = x;
        }
        if s == 0 {
            diag.system_rcond = rcond;
            return Ok(());
        }
        // X = A^-1 B_hat^T (nv x s); S = B_hat X (s x s) into k; r = gamma_hat - B_hat a0.
        for r in 0..s {
            let inv_n = self.norms[r].recip();
            for i in 0..nv {
                let mut x = S::zero();
                for j in 0..nv {
                    x += self.inv[(i, j)] * b[(r, j)];
                }
                self.x[(i, r)] = x * inv_n;
            }
        }
        for r in 0..s {
            let inv_n = self.norms[r].recip();
            for c2 in 0..s {
                let mut x = S::zero();
                for j in 0..nv {
                    x += b[(r, j)] * self.x[(j, c2)];
                }
                self.k[(r, c2)] = x * inv_n;
            }
            let mut ba0 = S::zero();
            for j in 0..nv {
                ba0 += b[(r, j)] * acc[j];
            }
            self.rhs[r] = (gamma[r] - ba0) * inv_n;
        }
        let rc = linalg::lu_factor(&mut self.k, s, &mut self.piv, 0.0)
            .map_err(|e| FormulationError::SingularSystem { rcond: e.rcond })?;
        diag.factorizations += 1;
        diag.system_rcond = rcond.min(rc);
        linalg::lu_solve(&self.k, s, &self.piv, &mut self.rhs[..s]);
        for i in 0..nv {
            let mut x = S::zero();
            for r in 0..s {
                x += self.x[(i, r)] * self.rhs[r];
            }
            acc[i] += x;
        }
        Ok(())
    }

    /// a = a0 + L^-T (B L^-T)^+ (gamma - B a0), A = L L^T.
    fn udwadia_kalaba(
        &mut self,
        a: &DMatrix<S>,
        force: &[S],
        b: &DMatrix<S>,
        gamma: &[S],
        acc: &mut [S],
        diag: &mut Diagnostics,
    ) -> Result<(), FormulationError> {
        let (nv, s) = (self.nv, self.s);
        self.load_mass(a);
        linalg::cholesky(&mut self.k, nv)
            .map_err(|e| FormulationError::SingularSystem { rcond: e.rcond })?;
        diag.factorizations += 1;
        // a0 = L^-T L^-1 F
        acc[..nv].copy_from_slice(&force[..nv]);
        linalg::cholesky_solve(&self.k, nv, acc);
        if s == 0 {
            return Ok(());
        }
        // X = L^-1 B_hat^T (nv x s) = (B_hat W)^T, factored in place in `x`.
        for r in 0..s {
            let inv_n = self.norms[r].recip();
            for j in 0..nv {
                self.tmp2[j] = b[(r, j)] * inv_n;
            }
            let mut col = std::mem::take(&mut self.tmp2);
            linalg::lower_solve(&self.k, nv, &mut col[..nv]);
            for j in 0..nv {
                self.x[(j, r)] = col[j];
            }
            self.tmp2 = col;
        }
        let mut beta = std::mem::take(&mut self.rhs);
        let mut perm = std::mem::take(&mut self.piv);
        let rank = linalg::qr_colpiv(&mut self.x, nv, s, &mut beta[..s], &mut perm[..s], 0.0);
        diag.factorizations += 1;
        let ok = rank == s;
        // residual r = gamma_hat - B_hat a0, permuted: z = R^-T P^T r, y = Q [z; 0].
        for j in 0..s {
            let row = perm[j];
            let inv_n = self.norms[row].recip();
            let mut ba0 = S::zero();
            for c2 in 0..nv {
                ba0 += b[(row, c2)] * acc[c2];
            }
            self.tmp2[j] = (gamma[row] - ba0) * inv_n;
        }
        if ok {
            linalg::solve_upper_t(&self.x, s, &mut self.tmp2[..s]);
            for j in s..nv {
                self.tmp2[j] = S::zero();
            }
            linalg::qr_apply_q(&self.x, nv, s, &beta[..s], &mut self.tmp2[..nv]);
            // a = a0 + L^-T y
            let mut y = std::mem::take(&mut self.tmp2);
            linalg::lower_t_solve(&self.k, nv, &mut y[..nv]);
            for j in 0..nv {
                acc[j] += y[j];
            }
            self.tmp2 = y;
        }
        self.rhs = beta;
        self.piv = perm;
        if !ok {
            return Err(FormulationError::SingularSystem { rcond: 0.0 });
        }
        diag.system_rcond = 1.0;
        Ok(())
    }

    /// The leading nv x nv block of k <- A.
    fn load_mass(&mut self, a: &DMatrix<S>) {
        let nv = self.nv;
        for j in 0..nv {
            self.k.column_mut(j).rows_mut(0, nv).copy_from(&a.column(j));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One of the methods, run on a workspace whose rows are factored.
    type Method<'a> = &'a dyn Fn(&mut FormulationWork<f64>, &mut Diagnostics, &mut [f64]);

    /// xorshift64* in [-1, 1).
    fn rand(state: &mut u64) -> f64 {
        *state ^= *state >> 12;
        *state ^= *state << 25;
        *state ^= *state >> 27;
        let x = state.wrapping_mul(0x2545F4914F6CDD1D);
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }

    /// The null-space method with D^T formed (few free directions) and with K = Q^T A Q give the
    /// same dv/dt, as does the KKT system, for every split of nv = 7 into s rows and m = nv - s
    /// free directions (m = 0: the rows alone fix dv/dt). Negative control: a row of B changed
    /// by 1e-6 moves dv/dt beyond the tolerance.
    #[test]
    fn reduced_null_space_matches_the_whole_q_and_kkt() {
        let nv = 7;
        let mut seed = 0x5eed_0fd7_u64;
        let tol = RankTolerances::default();
        for s in 1..=nv {
            let g = DMatrix::from_fn(nv, nv, |_, _| rand(&mut seed));
            let a = &g * g.transpose() + DMatrix::identity(nv, nv);
            let b = DMatrix::from_fn(s, nv, |_, _| rand(&mut seed));
            let force: Vec<f64> = (0..nv).map(|_| 3.0 * rand(&mut seed)).collect();
            let gamma: Vec<f64> = (0..s).map(|_| rand(&mut seed)).collect();
            let scale = vec![1.0; s];
            let solve = |f: Method, b: &DMatrix<f64>| {
                let mut w = FormulationWork::<f64>::new(nv, s);
                let mut diag = w.factor_rows(b, &gamma, &scale, &tol).unwrap();
                let mut acc = vec![0.0; nv];
                f(&mut w, &mut diag, &mut acc);
                (acc, diag)
            };
            let (reduced, dr) = solve(
                &|w, d, acc| w.null_space_reduced(&a, &force, &gamma, acc, d).unwrap(),
                &b,
            );
            let (whole, dw) = solve(
                &|w, d, acc| {
                    // the Q^T A Q branch, whatever the flop count picks
                    w.null_space_whole(&a, &force, &gamma, acc, d).unwrap()
                },
                &b,
            );
            let (kkt, _) = solve(
                &|w, d, acc| w.kkt(&a, &force, &b, &gamma, acc, d).unwrap(),
                &b,
            );
            let big = reduced.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            for k in 0..nv {
                assert!(
                    (reduced[k] - whole[k]).abs() <= 1e3 * f64::EPSILON * big,
                    "s = {s}: {k}"
                );
                assert!(
                    (reduced[k] - kkt[k]).abs() <= 1e3 * f64::EPSILON * big,
                    "s = {s}: {k}"
                );
            }
            assert_eq!(dr.factorizations, dw.factorizations);
            assert!((dr.system_rcond - dw.system_rcond).abs() <= 1e-8 * dw.system_rcond);
            let mut moved = b.clone();
            moved[(0, 0)] += 1e-6;
            let (off, _) = solve(
                &|w, d, acc| w.null_space_reduced(&a, &force, &gamma, acc, d).unwrap(),
                &moved,
            );
            let diff = (0..nv).fold(0.0f64, |m, k| m.max((off[k] - reduced[k]).abs()));
            assert!(
                diff > 1e6 * f64::EPSILON * big,
                "s = {s}: a moved row went unnoticed"
            );
        }
    }
}
