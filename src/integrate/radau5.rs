//! Radau IIA of order 5 (3 stages), implicit, stiffly accurate, after Hairer & Wanner,
//! *Solving ODEs II*, IV.8 and their code RADAU5:
//! - the collocation equations Z = h (A ⊗ I) F(Z) are solved by simplified Newton iterations with
//!   the exact Jacobian J = df/dy at the step start; with A^{-1} = T diag(gamma, [[alpha, -beta],
//!   [beta, alpha]]) T^{-1} the 3n x 3n system splits into a real n x n system with
//!   (gamma/h I - J) and a complex one with ((alpha + i beta)/h I - J) (IV.8, (8.15)-(8.17));
//!   the complex system is factored and solved in complex arithmetic (the crate's LU,
//!   `crate::linalg`, pivoting by modulus);
//! - Newton stopping and divergence test from the contraction rate theta (IV.8, (8.10)-(8.13));
//! - error estimate err = (I - h gamma0 J)^{-1} [gamma0 h f(y0) + sum e_i Z_i], filtered once more
//!   through (I - h gamma0 J)^{-1} after a rejected or first step (IV.8, (8.19)-(8.20));
//! - Gustafsson's predictive step-size controller (IV.8, (8.25)) and RADAU5's tolerance
//!   transformation rtol' = 0.1 rtol^(2/3), atol' = rtol' atol / rtol (the estimate is O(h^4));
//! - dense output: the collocation polynomial (cubic through y0 and the three stage values).
//!
//! Accounting: `lu_decompositions` counts factorisations of the pair (E1, E2), as RADAU5's NDEC;
//! `rejected` includes Newton failures and singular iteration matrices. f(t, y) is evaluated
//! after every accepted step (it enters the next error estimate), after the `accepted` hook, so a
//! projection costs no extra evaluation; the Jacobian and LU factors survive a projection.

// Index loops mirror the formulas.
#![allow(clippy::needless_range_loop, clippy::too_many_arguments)]

use std::ops::ControlFlow;

use nalgebra::{Complex, DMatrix, Matrix3};

use super::control::StepControl;
use super::erk::Attempt;
use super::{
    fixed_step_count, h_min, initial_step, rms, Accept, DenseOutput, DriverOptions,
    IntegratorStats, OdeProblem, Outcome,
};
use crate::linalg::{lu_factor, lu_factor_with, lu_solve, Modulus};

/// Maximum Newton iterations per step (RADAU5 default).
const NIT: usize = 7;
/// Maximum Newton iterations per step in fixed-step mode (no step reduction to fall back on).
const NIT_FIXED: usize = 50;
/// Safety factor of the step-size controller.
const SAFE: f64 = 0.9;
/// Bounds of h / h_new: FACR <= h / h_new <= FACL.
const FACL: f64 = 5.0;
const FACR: f64 = 0.125;
/// Reuse the Jacobian when the Newton contraction rate stays below THET.
const THET: f64 = 0.001;
/// Keep h (and the LU factors) when h_new / h lies in [QUOT1, QUOT2].
const QUOT1: f64 = 1.0;
const QUOT2: f64 = 1.2;

/// Constants of Radau IIA order 5 (HNW II, Table IV.5.6) and the eigen-decomposition of A^{-1}.
#[derive(Clone, Debug)]
pub(crate) struct RadauConsts {
    pub c: [f64; 3],
    #[cfg_attr(not(test), allow(dead_code))]
    pub a: [[f64; 3]; 3],
    /// Error-estimate weights e_i / gamma0 (RADAU5's dd1..dd3).
    pub dd: [f64; 3],
    /// Real eigenvalue of A^{-1}.
    pub gamma: f64,
    /// Complex eigenvalues alpha +- i beta of A^{-1}.
    pub alpha: f64,
    pub beta: f64,
    /// A^{-1} T = T [[gamma, 0, 0], [0, alpha, -beta], [0, beta, alpha]], TI = T^{-1}.
    pub t: [[f64; 3]; 3],
    pub ti: [[f64; 3]; 3],
}

impl RadauConsts {
    pub(crate) fn new() -> Self {
        let s6 = 6.0f64.sqrt();
        let c = [(4.0 - s6) / 10.0, (4.0 + s6) / 10.0, 1.0];
        let a = [
            [
                (88.0 - 7.0 * s6) / 360.0,
                (296.0 - 169.0 * s6) / 1800.0,
                (-2.0 + 3.0 * s6) / 225.0,
            ],
            [
                (296.0 + 169.0 * s6) / 1800.0,
                (88.0 + 7.0 * s6) / 360.0,
                (-2.0 - 3.0 * s6) / 225.0,
            ],
            [(16.0 - s6) / 36.0, (16.0 + s6) / 36.0, 1.0 / 9.0],
        ];
        let dd = [
            -(13.0 + 7.0 * s6) / 3.0,
            (-13.0 + 7.0 * s6) / 3.0,
            -1.0 / 3.0,
        ];
        // Eigenvalues of A (HNW II, IV.8): real u and complex a +- i b; A^{-1} has their inverses.
        let (c81, c9) = (81.0f64.cbrt(), 9.0f64.cbrt());
        let u = (6.0 + c81 - c9) / 30.0;
        let ar = (12.0 - c81 + c9) / 60.0;
        let ai = (c81 + c9) * 3.0f64.sqrt() / 60.0;
        let cno = ar * ar + ai * ai;
        let gamma = 1.0 / u;
        let (alpha, beta) = (ar / cno, ai / cno);
        let am = Matrix3::from_fn(|i, j| a[i][j]);
        let ainv = am.try_inverse().expect("Radau IIA matrix is invertible");
        // Null vector of (A^{-1} - lambda I) as the (bilinear) cross product of two of its rows.
        let null_vec = |lam: Complex<f64>| -> [Complex<f64>; 3] {
            let m = |i: usize, j: usize| {
                Complex::new(ainv[(i, j)], 0.0) - if i == j { lam } else { Complex::new(0.0, 0.0) }
            };
            let (r0, r1) = ([m(0, 0), m(0, 1), m(0, 2)], [m(1, 0), m(1, 1), m(1, 2)]);
            [
                r0[1] * r1[2] - r0[2] * r1[1],
                r0[2] * r1[0] - r0[0] * r1[2],
                r0[0] * r1[1] - r0[1] * r1[0],
            ]
        };
        let v1 = null_vec(Complex::new(gamma, 0.0));
        let vc = null_vec(Complex::new(alpha, beta));
        // Normalise as RADAU5 does: the complex eigenvector gets v[2] = i, the real one v[2] ... any.
        let sc = Complex::new(0.0, 1.0) / vc[2];
        let vc = [vc[0] * sc, vc[1] * sc, vc[2] * sc];
        // With A^{-1} v = (alpha + i beta) v: columns (v1, Im v, Re v) give the real block form.
        let tm = Matrix3::from_fn(|i, j| match j {
            0 => v1[i].re / v1[2].re,
            1 => vc[i].im,
            _ => vc[i].re,
        });
        let tim = tm.try_inverse().expect("eigenvector matrix is invertible");
        let t = [
            [tm[(0, 0)], tm[(0, 1)], tm[(0, 2)]],
            [tm[(1, 0)], tm[(1, 1)], tm[(1, 2)]],
            [tm[(2, 0)], tm[(2, 1)], tm[(2, 2)]],
        ];
        let ti = [
            [tim[(0, 0)], tim[(0, 1)], tim[(0, 2)]],
            [tim[(1, 0)], tim[(1, 1)], tim[(1, 2)]],
            [tim[(2, 0)], tim[(2, 1)], tim[(2, 2)]],
        ];
        RadauConsts {
            c,
            a,
            dd,
            gamma,
            alpha,
            beta,
            t,
            ti,
        }
    }
}

/// The collocation polynomial of the last step, in RADAU5's form with s = (t - t1)/h in [-1, 0]:
/// y(s) = c0 + s (c1 + (s - c2 + 1) (c2' + (s - c1 + 1) c3)).
pub(crate) struct RadauDense<'a> {
    t1: f64,
    h: f64,
    n: usize,
    cm: [f64; 2],
    cont: &'a [f64],
}

impl DenseOutput for RadauDense<'_> {
    fn eval(&self, t: f64, out: &mut [f64]) {
        let n = self.n;
        let s = (t - self.t1) / self.h;
        let [c1m1, c2m1] = self.cm;
        for i in 0..n {
            out[i] = self.cont[i]
                + s * (self.cont[n + i]
                    + (s - c2m1) * (self.cont[2 * n + i] + (s - c1m1) * self.cont[3 * n + i]));
        }
    }
}

/// Workspace of Radau5.
pub(crate) struct RadauWork {
    n: usize,
    k: RadauConsts,
    /// Stage increments Z_i = Y_i - y0 (3 n), transformed W = T^{-1} Z (3 n), f at stages (3 n).
    z: Vec<f64>,
    w: Vec<f64>,
    fz: Vec<f64>,
    /// Collocation polynomial coefficients (4 n).
    cont: Vec<f64>,
    f0: Vec<f64>,
    scal: Vec<f64>,
    ytmp: Vec<f64>,
    ebuf: Vec<f64>,
    ecorr: Vec<f64>,
    cbuf: Vec<Complex<f64>>,
    jac: DMatrix<f64>,
    e1: DMatrix<f64>,
    e2: DMatrix<Complex<f64>>,
    piv1: Vec<usize>,
    piv2: Vec<usize>,
}

enum Newton {
    Converged(usize),
    /// Failed (diverging or too slow): retry with h * factor.
    Fail(f64),
    NonFinite,
}

/// The settings of one run of [`RadauWork::run`], fixed at its start.
struct RadauSettings {
    t0: f64,
    t1: f64,
    /// Transformed tolerances (RADAU5).
    rtol: f64,
    atol: f64,
    /// Newton stopping tolerance.
    fnewt: f64,
    fixed: Option<f64>,
    adaptive: bool,
    nfixed: Option<usize>,
}

impl RadauSettings {
    fn new(opts: &DriverOptions, t0: f64, t1: f64) -> Self {
        // RADAU5's tolerance transformation (the error estimate is of order 3).
        let (rtol, atol) = if opts.rtol > 0.0 {
            let r = 0.1 * opts.rtol.powf(2.0 / 3.0);
            (r, r * opts.atol / opts.rtol)
        } else {
            (0.0, opts.atol)
        };
        // Newton stopping tolerance (RADAU5's default), kept finite for rtol -> 0.
        let rtol_f = rtol.max(10.0 * f64::EPSILON);
        let fnewt = (10.0 * f64::EPSILON / rtol_f).max(0.03f64.min(rtol_f.sqrt()));
        let fixed = opts.fixed_step.filter(|h| *h > 0.0);
        RadauSettings {
            t0,
            t1,
            rtol,
            atol,
            fnewt,
            fixed,
            adaptive: fixed.is_none(),
            nfixed: fixed.map(|h| fixed_step_count(t0, t1, h)),
        }
    }
}

/// The state [`RadauWork::run`] carries from one attempted step to the next.
struct RadauState {
    t: f64,
    /// Proposed size of the next step.
    h: f64,
    /// Steps taken in fixed-step mode.
    ifixed: usize,
    need_jac: bool,
    /// The Jacobian was evaluated at the current point.
    caljac: bool,
    /// Step size of the current LU factors (NaN: none).
    h_lu: f64,
    first: bool,
    reject: bool,
    faccon: f64,
    theta: f64,
    /// Size of the last accepted step.
    hold: f64,
    ctl: StepControl,
}

impl RadauWork {
    pub(crate) fn new(n: usize) -> Self {
        RadauWork {
            n,
            k: RadauConsts::new(),
            z: vec![0.0; 3 * n],
            w: vec![0.0; 3 * n],
            fz: vec![0.0; 3 * n],
            cont: vec![0.0; 4 * n],
            f0: vec![0.0; n],
            scal: vec![0.0; n],
            ytmp: vec![0.0; n],
            ebuf: vec![0.0; n],
            ecorr: vec![0.0; n],
            cbuf: vec![Complex::new(0.0, 0.0); n],
            jac: DMatrix::zeros(n, n),
            e1: DMatrix::zeros(n, n),
            e2: DMatrix::zeros(n, n),
            piv1: vec![0; n],
            piv2: vec![0; n],
        }
    }

    /// Form and factor E1 = gamma/h I - J and E2 = (alpha + i beta)/h I - J.
    fn decompose(&mut self, h: f64) -> bool {
        let n = self.n;
        let fac1 = self.k.gamma / h;
        let e2d = Complex::new(self.k.alpha / h, self.k.beta / h);
        for j in 0..n {
            for i in 0..n {
                let jij = self.jac[(i, j)];
                self.e1[(i, j)] = -jij;
                self.e2[(i, j)] = Complex::new(-jij, 0.0);
            }
            self.e1[(j, j)] += fac1;
            self.e2[(j, j)] += e2d;
        }
        lu_factor(&mut self.e1, n, &mut self.piv1, 0.0).is_ok()
            && lu_factor_with::<_, Modulus>(&mut self.e2, n, &mut self.piv2, 0.0).is_ok()
    }

    /// Simplified Newton iteration for the stage increments of a step of size h from (t, y).
    #[allow(clippy::too_many_arguments)]
    fn newton<P: OdeProblem>(
        &mut self,
        problem: &mut P,
        t: f64,
        y: &[f64],
        h: f64,
        fnewt: f64,
        adaptive: bool,
        faccon: &mut f64,
        theta: &mut f64,
        stats: &mut IntegratorStats,
    ) -> Result<Newton, P::Error> {
        let n = self.n;
        let kc = &self.k;
        let (fac1, alphn, betan) = (kc.gamma / h, kc.alpha / h, kc.beta / h);
        let (c, ti, tt) = (kc.c, kc.ti, kc.t);
        *faccon = faccon.max(f64::EPSILON).powf(0.8);
        *theta = THET;
        let (mut dynold, mut thqold) = (0.0f64, 0.0f64);
        let mut newt = 0usize;
        let nit = if adaptive { NIT } else { NIT_FIXED };
        loop {
            if newt >= nit {
                return Ok(Newton::Fail(0.5));
            }
            for s in 0..3 {
                for i in 0..n {
                    self.ytmp[i] = y[i] + self.z[s * n + i];
                }
                stats.rhs_evals += 1;
                problem.rhs(t + c[s] * h, &self.ytmp, &mut self.fz[s * n..(s + 1) * n])?;
            }
            if !self.fz.iter().all(|v| v.is_finite()) {
                return Ok(Newton::NonFinite);
            }
            // Right-hand sides of the transformed system -(1/h) Lambda W + (T^{-1} ⊗ I) F.
            for i in 0..n {
                let f = [self.fz[i], self.fz[n + i], self.fz[2 * n + i]];
                let w = [self.w[i], self.w[n + i], self.w[2 * n + i]];
                let g = |r: usize| ti[r][0] * f[0] + ti[r][1] * f[1] + ti[r][2] * f[2];
                self.z[i] = g(0) - fac1 * w[0];
                self.z[n + i] = g(1) - alphn * w[1] + betan * w[2];
                self.z[2 * n + i] = g(2) - alphn * w[2] - betan * w[1];
            }
            lu_solve(&self.e1, n, &self.piv1, &mut self.z[..n]);
            for i in 0..n {
                self.cbuf[i] = Complex::new(self.z[n + i], self.z[2 * n + i]);
            }
            lu_solve(&self.e2, n, &self.piv2, &mut self.cbuf);
            for i in 0..n {
                self.z[n + i] = self.cbuf[i].re;
                self.z[2 * n + i] = self.cbuf[i].im;
            }
            stats.newton_iterations += 1;
            newt += 1;
            let mut sum = 0.0;
            for i in 0..n {
                let sc = self.scal[i];
                sum += (self.z[i] / sc).powi(2)
                    + (self.z[n + i] / sc).powi(2)
                    + (self.z[2 * n + i] / sc).powi(2);
            }
            let dyno = (sum / (3 * n).max(1) as f64).sqrt();
            if !dyno.is_finite() {
                return Ok(Newton::NonFinite);
            }
            if newt > 1 && newt < nit {
                let thq = dyno / dynold;
                *theta = if newt == 2 {
                    thq
                } else {
                    (thq * thqold).sqrt()
                };
                thqold = thq;
                if *theta < 0.99 {
                    *faccon = *theta / (1.0 - *theta);
                    let dyth = *faccon * dyno * theta.powi((nit - 1 - newt) as i32) / fnewt;
                    if dyth >= 1.0 && adaptive {
                        // Predicted not to converge in time: retry with a smaller step (8.13).
                        let qnewt = dyth.clamp(1e-4, 20.0);
                        return Ok(Newton::Fail(
                            0.8 * qnewt.powf(-1.0 / (4.0 + (nit - 1 - newt) as f64)),
                        ));
                    }
                } else {
                    return Ok(Newton::Fail(0.5));
                }
            }
            dynold = dyno.max(f64::EPSILON);
            for i in 0..n {
                self.w[i] += self.z[i];
                self.w[n + i] += self.z[n + i];
                self.w[2 * n + i] += self.z[2 * n + i];
                let w = [self.w[i], self.w[n + i], self.w[2 * n + i]];
                for r in 0..3 {
                    self.z[r * n + i] = tt[r][0] * w[0] + tt[r][1] * w[1] + tt[r][2] * w[2];
                }
            }
            if *faccon * dyno <= fnewt {
                return Ok(Newton::Converged(newt));
            }
        }
    }

    /// The Radau5 step driver.
    pub(crate) fn run<P: OdeProblem>(
        &mut self,
        opts: &DriverOptions,
        problem: &mut P,
        t0: f64,
        t1: f64,
        y: &mut [f64],
        stats: &mut IntegratorStats,
    ) -> Outcome<P::Error> {
        let set = RadauSettings::new(opts, t0, t1);
        let t = t0;
        stats.rhs_evals += 1;
        if let Err(error) = problem.rhs(t, y, &mut self.f0) {
            return Outcome::Problem { t, error };
        }
        if !self.f0.iter().all(|v| v.is_finite()) {
            return Outcome::NonFinite { t };
        }
        let h = match self.first_step(opts, &set, problem, y, stats) {
            Ok(h) => h,
            Err(error) => return Outcome::Problem { t, error },
        };
        let mut st = RadauState {
            t,
            h,
            ifixed: 0,
            need_jac: true,
            caljac: false,
            h_lu: f64::NAN,
            first: true,
            reject: false,
            faccon: 1.0,
            theta: THET,
            hold: h,
            // Gustafsson's predictive controller (HNW II, IV.8, (8.25)); err = O(h^4).
            ctl: StepControl::predictive(0.25, SAFE, FACR, FACL),
        };
        loop {
            if let ControlFlow::Break(Some(outcome)) =
                self.attempt(opts, &set, &mut st, problem, y, stats)
            {
                return outcome;
            }
        }
    }

    /// The first step size: the fixed one, the user's h0 or the estimate of `initial_step`.
    fn first_step<P: OdeProblem>(
        &mut self,
        opts: &DriverOptions,
        set: &RadauSettings,
        problem: &mut P,
        y: &[f64],
        stats: &mut IntegratorStats,
    ) -> Result<f64, P::Error> {
        Ok(match (set.fixed, opts.h0) {
            (Some(h), _) => h,
            (None, Some(h0)) => h0.min(opts.h_max),
            (None, None) => initial_step(
                problem,
                set.t0,
                y,
                &self.f0,
                3,
                set.atol,
                set.rtol,
                opts.h_max,
                set.t1 - set.t0,
                &mut self.scal,
                &mut self.ytmp,
                &mut self.ebuf,
                stats,
            )?,
        })
    }

    /// One attempted step from `st.t`, accepted or rejected.
    fn attempt<P: OdeProblem>(
        &mut self,
        opts: &DriverOptions,
        set: &RadauSettings,
        st: &mut RadauState,
        problem: &mut P,
        y: &mut [f64],
        stats: &mut IntegratorStats,
    ) -> Attempt<P::Error> {
        let (t, t1) = (st.t, set.t1);
        if stats.steps + stats.rejected >= opts.max_steps {
            return ControlFlow::Break(Some(Outcome::MaxSteps { t }));
        }
        let (hs, last) = match (set.fixed, set.nfixed) {
            (Some(hf), Some(nf)) => {
                if st.ifixed + 1 >= nf {
                    (t1 - t, true)
                } else {
                    (hf, false)
                }
            }
            _ => {
                if st.h < h_min(opts, t) {
                    return ControlFlow::Break(Some(Outcome::StepTooSmall { t, h: st.h }));
                }
                if t + 1.01 * st.h >= t1 {
                    (t1 - t, true)
                } else {
                    (st.h, false)
                }
            }
        };
        self.iteration_matrices(opts, set, st, problem, hs, y, stats)?;
        problem.error_scale(y, y, set.atol, set.rtol, &mut self.scal);
        self.starting_values(st, hs);
        let newt = self.solve_stages(opts, set, st, problem, hs, y, stats)?;
        let mut hnew = hs;
        if set.adaptive {
            hnew = self.control_error(opts, set, st, problem, hs, newt, y, stats)?;
        }
        self.accept(set, st, problem, hs, hnew, last, y, stats)
    }

    /// The Jacobian when needed, and the factors of E1, E2 when h changed; a singular iteration
    /// matrix rejects the step.
    fn iteration_matrices<P: OdeProblem>(
        &mut self,
        opts: &DriverOptions,
        set: &RadauSettings,
        st: &mut RadauState,
        problem: &mut P,
        hs: f64,
        y: &[f64],
        stats: &mut IntegratorStats,
    ) -> Attempt<P::Error> {
        let t = st.t;
        if st.need_jac {
            stats.jacobian_evals += 1;
            if let Err(error) = problem.jacobian(t, y, &mut self.jac) {
                return ControlFlow::Break(Some(Outcome::Problem { t, error }));
            }
            st.need_jac = false;
            st.caljac = true;
            st.h_lu = f64::NAN;
        }
        if hs != st.h_lu {
            stats.lu_decompositions += 1;
            if !self.decompose(hs) {
                // Singular (or non-finite) iteration matrix: halve the step.
                stats.rejected += 1;
                st.h_lu = f64::NAN;
                if !set.adaptive {
                    return ControlFlow::Break(Some(Outcome::StepTooSmall { t, h: hs }));
                }
                if !self.jac.iter().all(|v| v.is_finite()) {
                    st.h = hs * 0.25;
                    if st.h < h_min(opts, t) {
                        return ControlFlow::Break(Some(Outcome::NonFinite { t }));
                    }
                    st.need_jac = !st.caljac;
                } else {
                    st.h = hs * 0.5;
                }
                st.reject = true;
                return ControlFlow::Break(None);
            }
            st.h_lu = hs;
        }
        ControlFlow::Continue(())
    }

    /// Starting values: zero on the first step, else the extrapolated collocation polynomial.
    fn starting_values(&mut self, st: &RadauState, hs: f64) {
        let n = self.n;
        let kc = &self.k;
        let [c1, c2, _] = kc.c;
        let (c1m1, c2m1) = (c1 - 1.0, c2 - 1.0);
        if st.first {
            self.z.fill(0.0);
            self.w.fill(0.0);
        } else {
            let c3q = hs / st.hold;
            for i in 0..n {
                let (ak1, ak2, ak3) =
                    (self.cont[n + i], self.cont[2 * n + i], self.cont[3 * n + i]);
                let mut zz = [0.0; 3];
                for (s, zs) in zz.iter_mut().enumerate() {
                    let q = kc.c[s] * c3q;
                    *zs = q * (ak1 + (q - c2m1) * (ak2 + (q - c1m1) * ak3));
                    self.z[s * n + i] = *zs;
                }
                for r in 0..3 {
                    self.w[r * n + i] =
                        kc.ti[r][0] * zz[0] + kc.ti[r][1] * zz[1] + kc.ti[r][2] * zz[2];
                }
            }
        }
    }

    /// The Newton iteration of the stage values, going on with its iteration count; a failed
    /// iteration rejects the step.
    fn solve_stages<P: OdeProblem>(
        &mut self,
        opts: &DriverOptions,
        set: &RadauSettings,
        st: &mut RadauState,
        problem: &mut P,
        hs: f64,
        y: &[f64],
        stats: &mut IntegratorStats,
    ) -> Attempt<P::Error, usize> {
        let (t, adaptive) = (st.t, set.adaptive);
        match self.newton(
            problem,
            t,
            y,
            hs,
            set.fnewt,
            adaptive,
            &mut st.faccon,
            &mut st.theta,
            stats,
        ) {
            // A failed evaluation at a collocation stage: reject and shrink (see erk.rs).
            Err(error) => {
                stats.rejected += 1;
                st.reject = true;
                st.h = hs * 0.25;
                if !adaptive || st.h < h_min(opts, t) {
                    return ControlFlow::Break(Some(Outcome::Problem { t, error }));
                }
                ControlFlow::Break(None)
            }
            Ok(Newton::Converged(it)) => ControlFlow::Continue(it),
            Ok(Newton::Fail(fac)) => {
                stats.rejected += 1;
                st.reject = true;
                if !adaptive {
                    if st.caljac {
                        return ControlFlow::Break(Some(Outcome::StepTooSmall { t, h: hs }));
                    }
                    st.need_jac = true;
                    return ControlFlow::Break(None);
                }
                st.h = hs * fac;
                st.need_jac = !st.caljac;
                ControlFlow::Break(None)
            }
            Ok(Newton::NonFinite) => {
                stats.rejected += 1;
                if !adaptive {
                    return ControlFlow::Break(Some(Outcome::NonFinite { t }));
                }
                st.reject = true;
                st.h = hs * 0.25;
                if st.h < h_min(opts, t) {
                    return ControlFlow::Break(Some(Outcome::NonFinite { t }));
                }
                ControlFlow::Break(None)
            }
        }
    }

    /// The error test of an adaptive step, going on with the proposed next step size; a failed
    /// test rejects the step.
    fn control_error<P: OdeProblem>(
        &mut self,
        opts: &DriverOptions,
        set: &RadauSettings,
        st: &mut RadauState,
        problem: &mut P,
        hs: f64,
        newt: usize,
        y: &[f64],
        stats: &mut IntegratorStats,
    ) -> Attempt<P::Error, f64> {
        let t = st.t;
        let refine = st.first || st.reject;
        let err = match self.estimate(problem, t, y, hs, set.atol, set.rtol, refine, stats) {
            Ok(e) => e,
            Err(error) => {
                stats.rejected += 1;
                st.reject = true;
                st.h = hs * 0.25;
                if st.h < h_min(opts, t) {
                    return ControlFlow::Break(Some(Outcome::Problem { t, error }));
                }
                return ControlFlow::Break(None);
            }
        };
        if !err.is_finite() {
            stats.rejected += 1;
            st.reject = true;
            st.h = hs * 0.25;
            if st.h < h_min(opts, t) {
                return ControlFlow::Break(Some(Outcome::NonFinite { t }));
            }
            return ControlFlow::Break(None);
        }
        // Safety factor decreasing with the Newton iterations.
        let fac = SAFE.min(SAFE * (1 + 2 * NIT) as f64 / (newt + 2 * NIT) as f64);
        if err >= 1.0 {
            stats.rejected += 1;
            st.h = if st.first {
                hs * 0.1
            } else {
                hs / st.ctl.rejected(err, fac)
            };
            st.reject = true;
            st.need_jac = !st.caljac;
            return ControlFlow::Break(None);
        }
        ControlFlow::Continue(st.ctl.accepted(err, hs, fac, opts.h_max, st.reject))
    }

    /// An accepted step: the new y and collocation polynomial, the `accepted` hook, f at the new
    /// point and the next step size.
    fn accept<P: OdeProblem>(
        &mut self,
        set: &RadauSettings,
        st: &mut RadauState,
        problem: &mut P,
        hs: f64,
        hnew: f64,
        last: bool,
        y: &mut [f64],
        stats: &mut IntegratorStats,
    ) -> Attempt<P::Error> {
        let n = self.n;
        let [c1, c2, _] = self.k.c;
        let (c1m1, c2m1, c1mc2) = (c1 - 1.0, c2 - 1.0, c1 - c2);
        // Accepted: new y and collocation polynomial.
        st.first = false;
        for i in 0..n {
            let (z1, z2, z3) = (self.z[i], self.z[n + i], self.z[2 * n + i]);
            y[i] += z3;
            let cont1 = (z2 - z3) / c2m1;
            let ak = (z1 - z2) / c1mc2;
            let acont3 = (ak - z1 / c1) / c2;
            let cont2 = (ak - cont1) / c1m1;
            self.cont[i] = y[i];
            self.cont[n + i] = cont1;
            self.cont[2 * n + i] = cont2;
            self.cont[3 * n + i] = cont2 - acont3;
        }
        st.hold = hs;
        let tnew = if last {
            set.t1
        } else if let Some(hf) = set.fixed {
            set.t0 + (st.ifixed + 1) as f64 * hf
        } else {
            st.t + hs
        };
        stats.steps += 1;
        st.ifixed += 1;
        let dense = RadauDense {
            t1: tnew,
            h: hs,
            n,
            cm: [c1m1, c2m1],
            cont: &self.cont,
        };
        let acc = problem.accepted(st.t, tnew, y, &dense);
        st.t = tnew;
        let t = tnew;
        match acc {
            Err(error) => return ControlFlow::Break(Some(Outcome::Problem { t, error })),
            Ok(Accept::Unchanged) | Ok(Accept::Changed) => {}
        }
        if last {
            return ControlFlow::Break(Some(Outcome::Finished));
        }
        // f(t, y) at the new point (always needed: not FSAL), after a possible projection.
        stats.rhs_evals += 1;
        if let Err(error) = problem.rhs(t, y, &mut self.f0) {
            return ControlFlow::Break(Some(Outcome::Problem { t, error }));
        }
        st.caljac = false;
        if !set.adaptive {
            return ControlFlow::Continue(());
        }
        st.reject = false;
        let qt = hnew / hs;
        if st.theta <= THET && (QUOT1..=QUOT2).contains(&qt) {
            // Keep h, the Jacobian and the LU factors.
            st.h = hs;
        } else {
            st.h = hnew;
            st.need_jac = st.theta > THET;
        }
        ControlFlow::Continue(())
    }

    /// Error estimate (HNW II, IV.8, (8.19)-(8.20)): err = (gamma/h I - J)^{-1} (f0 + sum dd_i Z_i / h);
    /// after a first or rejected step with err >= 1 it is filtered once more through f(t, y0 + err).
    #[allow(clippy::too_many_arguments)]
    fn estimate<P: OdeProblem>(
        &mut self,
        problem: &mut P,
        t: f64,
        y: &[f64],
        h: f64,
        atol: f64,
        rtol: f64,
        refine: bool,
        stats: &mut IntegratorStats,
    ) -> Result<f64, P::Error> {
        let n = self.n;
        let dd = self.k.dd;
        for i in 0..n {
            self.ytmp[i] = y[i] + self.z[2 * n + i];
        }
        problem.error_scale(y, &self.ytmp, atol, rtol, &mut self.scal);
        for i in 0..n {
            self.ebuf[i] =
                (dd[0] * self.z[i] + dd[1] * self.z[n + i] + dd[2] * self.z[2 * n + i]) / h;
            self.ecorr[i] = self.ebuf[i] + self.f0[i];
        }
        lu_solve(&self.e1, n, &self.piv1, &mut self.ecorr);
        let mut err = rms(&self.ecorr, &self.scal).max(1e-10);
        if err >= 1.0 && refine && err.is_finite() {
            for i in 0..n {
                self.ytmp[i] = y[i] + self.ecorr[i];
            }
            stats.rhs_evals += 1;
            problem.rhs(t, &self.ytmp, &mut self.fz[..n])?;
            for i in 0..n {
                self.ecorr[i] = self.fz[i] + self.ebuf[i];
            }
            lu_solve(&self.e1, n, &self.piv1, &mut self.ecorr);
            err = rms(&self.ecorr, &self.scal).max(1e-10);
        }
        Ok(err)
    }
}
