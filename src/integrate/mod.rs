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

use nalgebra::DMatrix;

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
}

impl Default for DriverOptions {
    fn default() -> Self {
        DriverOptions {
            rtol: 1e-8,
            atol: 1e-10,
            h0: None,
            h_max: f64::INFINITY,
            h_min_factor: 10.0,
            max_steps: 10_000_000,
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

    /// f(t, y) into `dy`. Must not allocate.
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
    /// (the last accepted time).
    Problem { t: f64, error: E },
}

/// An integrator with its preallocated workspace for a given dimension.
pub struct Integrator {
    method: Method,
    options: DriverOptions,
    // Workspace fields are added by the implementation.
}

impl Integrator {
    /// Allocate the workspace for problems of dimension `dim`.
    pub fn new(method: Method, options: DriverOptions, dim: usize) -> Self {
        let _ = dim;
        Integrator { method, options }
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
    pub fn integrate<P: OdeProblem>(
        &mut self,
        problem: &mut P,
        t0: f64,
        t1: f64,
        y: &mut [f64],
    ) -> (Outcome<P::Error>, IntegratorStats) {
        let _ = (problem, t0, t1, y);
        unimplemented!("integrators: see the integrate issue work")
    }
}
