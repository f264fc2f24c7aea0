//! Time integration of y' = f(t, y), y in R^m.
//!
//! The mechanical layer (`crate::solve`) presents each solve as an [`OdeProblem`] on a chart:
//! quaternion coordinates are integrated in local exponential coordinates (RKMK), so every method
//! here only ever sees a flat R^m. After each accepted step the problem is called back
//! ([`OdeProblem::accepted`]): it records output from the dense interpolant, projects the state onto
//! the programme manifold or re-centres its chart, and may change `y` in place. The step-size
//! controller's state survives such a change (the paper's drift control must not restart the
//! integrator); only the FSAL derivative is re-evaluated.
//!
//! Methods: fixed-step classical RK4; Dormand-Prince 5(4) with 4th-order dense output
//! (Hairer, Norsett, Wanner, *Solving ODEs I*, II.5); DOP853 with 7th-order dense output (ibid.);
//! Radau IIA order 5 with simplified Newton and exact Jacobians (Hairer & Wanner, *Solving ODEs II*,
//! IV.8).
//!
//! Driver conventions (all methods):
//! - error norm: RMS of err_i / sc_i with sc from [`OdeProblem::error_scale`]`(y0, y1, atol, rtol)`;
//!   DOP853 combines its 5th- and 3rd-order estimates as HNW I, II.10 (err5^2 / sqrt(err5^2 +
//!   0.01 err3^2)); Radau5 uses RADAU5's transformed tolerances (see `radau5`);
//! - one step-size controller (`control`): PI control (HNW I, IV.2) for DOPRI5 (beta = 0.04) and
//!   DOP853 (beta = 0), Gustafsson's predictive control for Radau5, never increasing h right after
//!   a rejection;
//! - non-finite stages or error estimates, and `rhs` errors inside a trial step, reject the step and
//!   divide h by 4 (an `rhs` error is reported once h < h_min, so a stop is localized);
//! - after [`Accept::Changed`] the explicit methods re-evaluate f(t1, y) instead of reusing the FSAL
//!   stage (counted in `rhs_evals`); h and the controller memory are kept;
//! - the last step lands exactly on t1 (steps within 1% of the remaining interval are stretched);
//! - [`DriverOptions::fixed_step`] turns the adaptive methods into fixed-step ones (convergence
//!   studies); RK4 is always fixed-step;
//! - all buffers live in the [`Integrator`]; a run allocates nothing.

use nalgebra::DMatrix;

mod control;
mod erk;
mod radau5;
#[cfg(test)]
mod tests;

use erk::ErkWork;
use radau5::RadauWork;

/// Which integration method a driver uses.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Classical 4th-order Runge-Kutta with a fixed step `h` (the last step is shortened to hit the end).
    Rk4 { h: f64 },
    /// Dormand-Prince 5(4), adaptive, FSAL, 4th-order dense output.
    Dopri5,
    /// Dormand-Prince 8(5,3), adaptive, 7th-order dense output; for tight tolerances.
    Dop853,
    /// Radau IIA, order 5, 3 stages, implicit; for stiff scenes. Uses [`OdeProblem::jacobian`].
    Radau5,
}

impl Method {
    /// Classical order of the method (for convergence tests).
    pub fn order(&self) -> usize {
        match self {
            Method::Rk4 { .. } => 4,
            Method::Dopri5 => 5,
            Method::Dop853 => 8,
            Method::Radau5 => 5,
        }
    }
}

/// Options of the step driver. Every field documents its default (`Default` impl).
#[derive(Clone, Debug)]
pub struct DriverOptions {
    /// Relative tolerance of the local error. Default 1e-8.
    pub rtol: f64,
    /// Absolute tolerance of the local error. Default 1e-10.
    pub atol: f64,
    /// Initial step; `None` chooses one automatically (Hairer's initial-step heuristic). Default None.
    pub h0: Option<f64>,
    /// Largest step allowed. Default: infinity (limited by the interval).
    pub h_max: f64,
    /// The driver stops with [`Outcome::StepTooSmall`] when the step falls below
    /// `h_min_factor * max(|t|, 1) * f64::EPSILON`. Default 10.
    pub h_min_factor: f64,
    /// Maximum number of step attempts (accepted + rejected). Default 10_000_000.
    pub max_steps: usize,
    /// Force a fixed step for the adaptive methods (`Dopri5`, `Dop853`, `Radau5`): every step has
    /// length `h` except the last, shortened to land on `t1` (exactly `ceil((t1-t0)/h - 1e-9)` steps,
    /// as for [`Method::Rk4`]); the error estimate is not used and no step is rejected. Meant for
    /// convergence studies. A Radau step whose Newton iteration diverges even with a fresh
    /// Jacobian ends the run with [`Outcome::StepTooSmall`]. Ignored by `Rk4` and when not > 0.
    /// Default None.
    pub fixed_step: Option<f64>,
}

/// Default relative and absolute local error tolerances, of the driver and of
/// [`crate::solve::Settings`] alike (one default, one place).
pub const DEFAULT_RTOL: f64 = 1e-10;
pub const DEFAULT_ATOL: f64 = 1e-12;
/// Default step limit.
pub const DEFAULT_MAX_STEPS: usize = 10_000_000;

impl Default for DriverOptions {
    fn default() -> Self {
        DriverOptions {
            rtol: DEFAULT_RTOL,
            atol: DEFAULT_ATOL,
            h0: None,
            h_max: f64::INFINITY,
            h_min_factor: 10.0,
            max_steps: DEFAULT_MAX_STEPS,
            fixed_step: None,
        }
    }
}

/// What the problem did to `y` after an accepted step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Accept {
    /// `y` untouched: an FSAL derivative stays valid.
    Unchanged,
    /// `y` was modified (projection, chart re-centring): f(t, y) must be re-evaluated.
    Changed,
}

/// The interpolant of the last accepted step, valid on [t0, t1] of that step.
pub trait DenseOutput {
    /// Evaluate y(t) for t in [t0, t1] of the step just accepted.
    fn eval(&self, t: f64, out: &mut [f64]);
}

/// An initial-value problem y' = f(t, y) as the integrators see it.
pub trait OdeProblem {
    /// Why the problem could not go on (singular programme Jacobian, drift beyond tolerance, ...).
    type Error;

    /// Dimension m of y.
    fn dim(&self) -> usize;

    /// f(t, y) into `dy`. Must not allocate. An error inside a trial step of an adaptive method
    /// rejects the step and shrinks it (like non-finite values); the run stops with
    /// [`Outcome::Problem`] only when the step cannot shrink further (or the method has a fixed
    /// step), so the stop is localized at the point where f fails.
    fn rhs(&mut self, t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), Self::Error>;

    /// Exact Jacobian df/dy at (t, y) into `jac` (m x m). Needed by implicit methods only.
    fn jacobian(&mut self, t: f64, y: &[f64], jac: &mut DMatrix<f64>) -> Result<(), Self::Error>;

    /// Scale of each component in the error norm, sc_i = atol + rtol * max(|y0_i|, |y1_i|) by default.
    /// A problem on a chart overrides this to use the magnitudes of its true state.
    fn error_scale(&self, y0: &[f64], y1: &[f64], atol: f64, rtol: f64, out: &mut [f64]) {
        for i in 0..out.len() {
            out[i] = atol + rtol * y0[i].abs().max(y1[i].abs());
        }
    }

    /// Whether `accepted` of the step from t0 to t1 will evaluate the dense output. The explicit
    /// methods skip its extra stages (DOP853: 3 per step) and, when the problem may change `y`,
    /// defer the FSAL stage until after `accepted` when it will not. A problem that answers false
    /// must not call `DenseOutput::eval` for that step (it would read NaN).
    fn needs_dense(&self, _t0: f64, _t1: f64) -> bool {
        true
    }

    /// Called after every accepted step from t0 to t1 with the new value `y`. `dense` interpolates
    /// the step. The problem may change `y` (return [`Accept::Changed`]) or stop the run (`Err`).
    fn accepted(
        &mut self,
        t0: f64,
        t1: f64,
        y: &mut [f64],
        dense: &dyn DenseOutput,
    ) -> Result<Accept, Self::Error>;
}

/// Counters of one integration run (snapshot-tested).
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct IntegratorStats {
    /// Accepted steps.
    pub steps: usize,
    /// Rejected step attempts (error test failed, Newton failed, non-finite values).
    pub rejected: usize,
    /// Evaluations of f.
    pub rhs_evals: usize,
    /// Evaluations of the Jacobian df/dy.
    pub jacobian_evals: usize,
    /// LU decompositions of iteration matrices (implicit methods).
    pub lu_decompositions: usize,
    /// Newton iterations (implicit methods).
    pub newton_iterations: usize,
}

/// How an integration run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome<E> {
    /// Reached the final time.
    Finished,
    /// The step size fell below the minimum at time `t`.
    StepTooSmall { t: f64, h: f64 },
    /// `max_steps` attempts were used up at time `t`.
    MaxSteps { t: f64 },
    /// Non-finite values that shrinking the step could not cure, at time `t`.
    NonFinite { t: f64 },
    /// The problem stopped the run (from `rhs`, `jacobian` or `accepted`) at time `t`
    /// (the last accepted time). `rhs` errors inside a trial step first shrink the step (see
    /// [`OdeProblem::rhs`]).
    Problem { t: f64, error: E },
}

/// An integrator with its preallocated workspace for a given dimension.
pub struct Integrator {
    method: Method,
    options: DriverOptions,
    dim: usize,
    erk: ErkWork,
    radau: RadauWork,
}

impl Integrator {
    /// Allocate the workspace for problems of dimension `dim`.
    pub fn new(method: Method, options: DriverOptions, dim: usize) -> Self {
        let (erk, radau) = match method {
            Method::Radau5 => (ErkWork::new(0), RadauWork::new(dim)),
            _ => (ErkWork::new(dim), RadauWork::new(0)),
        };
        Integrator {
            method,
            options,
            dim,
            erk,
            radau,
        }
    }

    /// The method this integrator runs.
    pub fn method(&self) -> Method {
        self.method
    }

    /// The driver options.
    pub fn options(&self) -> &DriverOptions {
        &self.options
    }

    /// Integrate from `t0` to `t1` (t1 > t0), `y` holding y(t0) on entry and the last accepted value
    /// on exit, whatever the outcome.
    ///
    /// `t1 == t0` returns [`Outcome::Finished`] at once; backward integration (`t1 < t0`) is not
    /// supported and returns [`Outcome::StepTooSmall`] with `h = t1 - t0` without touching `y`, as
    /// does `Rk4 { h }` with `h` not positive and finite.
    ///
    /// # Panics
    /// If `y.len() != problem.dim()`.
    pub fn integrate<P: OdeProblem>(
        &mut self,
        problem: &mut P,
        t0: f64,
        t1: f64,
        y: &mut [f64],
    ) -> (Outcome<P::Error>, IntegratorStats) {
        let n = problem.dim();
        assert_eq!(y.len(), n, "integrate: y.len() != problem.dim()");
        let mut stats = IntegratorStats::default();
        if t1 == t0 {
            return (Outcome::Finished, stats);
        }
        if t1 < t0 || t1.is_nan() || t0.is_nan() {
            return (Outcome::StepTooSmall { t: t0, h: t1 - t0 }, stats);
        }
        if n != self.dim {
            // One reallocation for a problem of another dimension.
            *self = Integrator::new(self.method, self.options.clone(), n);
        }
        let outcome = match self.method {
            Method::Radau5 => self
                .radau
                .run(&self.options, problem, t0, t1, y, &mut stats),
            Method::Rk4 { h } => self.erk.run(
                erk::Kind::Rk4,
                Some(h),
                &self.options,
                problem,
                t0,
                t1,
                y,
                &mut stats,
            ),
            Method::Dopri5 => self.erk.run(
                erk::Kind::Dopri5,
                self.options.fixed_step,
                &self.options,
                problem,
                t0,
                t1,
                y,
                &mut stats,
            ),
            Method::Dop853 => self.erk.run(
                erk::Kind::Dop853,
                self.options.fixed_step,
                &self.options,
                problem,
                t0,
                t1,
                y,
                &mut stats,
            ),
        };
        (outcome, stats)
    }
}

/// Smallest step allowed at time `t` (see [`DriverOptions::h_min_factor`]).
pub(crate) fn h_min(opts: &DriverOptions, t: f64) -> f64 {
    opts.h_min_factor * t.abs().max(1.0) * f64::EPSILON
}

/// Number of steps of a fixed-step run: `ceil((t1 - t0)/h - 1e-9)`, at least 1.
pub(crate) fn fixed_step_count(t0: f64, t1: f64, h: f64) -> usize {
    (((t1 - t0) / h - 1e-9).ceil() as usize).max(1)
}

/// RMS norm sqrt(1/m sum (v_i / sc_i)^2).
pub(crate) fn rms(v: &[f64], sc: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let s: f64 = v.iter().zip(sc).map(|(a, b)| (a / b) * (a / b)).sum();
    (s / v.len() as f64).sqrt()
}

/// Hairer's initial step heuristic (HNW I, II.4, algorithm after (4.13)): with d0 = ||y0||,
/// d1 = ||f0||, h0 = 0.01 d0/d1 (1e-6 if either is below 1e-5), one explicit Euler step
/// gives d2 = ||f(t0 + h0, y0 + h0 f0) - f0|| / h0 and h1 = (0.01 / max(d1, d2))^(1/(p+1));
/// the result is min(100 h0, h1, h_max). `f0` is given; one more f evaluation is counted.
#[allow(clippy::too_many_arguments)]
pub(crate) fn initial_step<P: OdeProblem>(
    problem: &mut P,
    t0: f64,
    y0: &[f64],
    f0: &[f64],
    p: usize,
    atol: f64,
    rtol: f64,
    h_max: f64,
    span: f64,
    sc: &mut [f64],
    y1: &mut [f64],
    f1: &mut [f64],
    stats: &mut IntegratorStats,
) -> Result<f64, P::Error> {
    problem.error_scale(y0, y0, atol, rtol, sc);
    let d0 = rms(y0, sc);
    let d1 = rms(f0, sc);
    let mut h = if d0 < 1e-5 || d1 < 1e-5 || !(d0 / d1).is_finite() {
        1e-6
    } else {
        0.01 * d0 / d1
    };
    h = h.min(h_max).min(span);
    for i in 0..y0.len() {
        y1[i] = y0[i] + h * f0[i];
    }
    stats.rhs_evals += 1;
    problem.rhs(t0 + h, y1, f1)?;
    for i in 0..y0.len() {
        y1[i] = f1[i] - f0[i];
    }
    let d2 = rms(y1, sc) / h;
    let dmax = d1.max(d2);
    let h1 = if dmax <= 1e-15 || !dmax.is_finite() {
        (h * 1e-3).max(1e-6)
    } else {
        (0.01 / dmax).powf(1.0 / (p as f64 + 1.0))
    };
    Ok((100.0 * h).min(h1).min(h_max).min(span))
}
