//! Problem, method settings, solution and return codes; `solve(problem, settings)`.
//!
//! - [`Problem`]: a [`Model`], its [`Constraints`] (programme rows and system constraints), the
//!   initial state and the time span.
//! - [`Settings`]: formulation, integrator, tolerances, drift control, output rate.
//! - [`Solution`]: the trajectory (t, q, v, dv/dt, u, reactions, residuals), statistics and a
//!   [`ReturnCode`]. Whatever was computed before a failure is kept.

mod evaluator;
mod ode;
mod overrides;
mod project;
mod validate;

pub use evaluator::{Baumgarte, Evaluator};
pub use overrides::{
    setting, settings, settings_table, OverrideError, Overrides, SettingError, SettingInfo,
    UnknownName, DEFAULT_BAUMGARTE, DEFAULT_PROJECTION_ITER, DEFAULT_PROJECTION_TOL, DRIFT_NAMES,
    FORMULATION_NAMES, INTEGRATOR_NAMES,
};
pub use project::{ProjectionReport, Projector};
pub use validate::{
    in_memory_samples, validate, validate_in_memory, validate_replay_step, SettingsError,
    SettingsField, DEFAULT_MAX_SAMPLES, IN_MEMORY_LIMIT_BYTES,
};

use crate::formulation::{Formulation, RankTolerances};
use crate::integrate::{DriverOptions, Integrator, IntegratorStats, Method};
use crate::model::Model;
use crate::programme::{Constraints, Level, Role};

/// What to integrate: a system, its constraints, an initial state and a time span.
#[derive(Clone, Debug)]
pub struct Problem<M: Model, C: Constraints> {
    /// The mechanical system.
    pub model: M,
    /// Programme rows and system constraints.
    pub constraints: C,
    /// Initial time.
    pub t0: f64,
    /// Final time.
    pub t1: f64,
    /// Initial configuration (nq).
    pub q0: Vec<f64>,
    /// Initial velocity (nv).
    pub v0: Vec<f64>,
}

/// How the programme's violation is kept in check (Section 2: the programme is part of the closed
/// system, so its violation is a numerical error that can be controlled).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum DriftControl {
    /// Monitor only.
    None,
    /// After every accepted step, project positions onto g(t, q) = 0 and velocities onto the
    /// velocity-level rows, each by Newton iterations minimizing the correction in the
    /// kinetic-energy metric (A). `tol`: residual to reach; `max_iter` per level.
    Projection { tol: f64, max_iter: usize },
    /// Baumgarte stabilization of the differentiated rows.
    Baumgarte { alpha: f64, beta: f64 },
}

/// Output sampling.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Output {
    /// One sample at t0 and one after every accepted step.
    Steps,
    /// Samples at t0, t0 + dt, ... and t1, from the dense output.
    Every(f64),
}

/// The method: every field documents its default (`Settings::default()`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Settings {
    /// Formulation of the accelerations. Default: `auto`, the paper's null-space form except on
    /// trees of at least [`crate::formulation::AUTO_ARTICULATED_NV`] velocities, where the
    /// articulated-body form is faster ([`Formulation::resolve`]).
    pub formulation: Formulation,
    /// Integrator. Default: DOP853.
    pub integrator: Method,
    /// Relative local error tolerance. Default 1e-10.
    pub rtol: f64,
    /// Absolute local error tolerance. Default 1e-12.
    pub atol: f64,
    /// Largest step. Default: unlimited.
    pub max_step: f64,
    /// Force a fixed step on the adaptive methods (convergence studies). Default: None.
    pub fixed_step: Option<f64>,
    /// Maximum step attempts. Default 10_000_000.
    pub max_steps: usize,
    /// Most output samples [`validate`] lets a run write (t0 and t1 included). Default
    /// [`DEFAULT_MAX_SAMPLES`] (10^7); scene `[time] max_samples`, CLI `--max-samples`.
    #[serde(default = "default_max_samples")]
    pub max_samples: usize,
    /// Drift control. Default: projection to 1e-12 with up to 8 Newton iterations.
    pub drift: DriftControl,
    /// Rank decisions on B. Default: [`RankTolerances::default`].
    pub rank_dependent: f64,
    /// See [`RankTolerances::vanishing`]. Default 1e-12.
    pub rank_vanishing: f64,
    /// Output sampling. Default: every accepted step.
    pub output: Output,
    /// Stop with [`ReturnCode::DriftExceeded`] when a position- or velocity-level residual exceeds
    /// this after a step. Default: None (monitor only).
    pub max_drift: Option<f64>,
    /// Initial state: residuals above this make it inconsistent. Default 1e-10.
    pub consistency_tol: f64,
    /// Project an inconsistent initial state onto the constraints (and report the correction)
    /// instead of refusing it. Default false.
    pub assemble: bool,
    /// Thresholds of the conditioning monitor. Default: [`Conditioning::default`].
    pub conditioning: Conditioning,
    /// Turn a conditioning warning into a stop ([`ReturnCode::IllConditioned`]). Default false.
    pub strict: bool,
    /// A fixed-step solve (RK4, or `fixed_step`) also runs a companion solve at twice the step and
    /// reports the Richardson estimate of its global error ([`GlobalError`]); the companion costs
    /// about half of the solve again (counted in [`GlobalError::companion`]). Default true.
    #[serde(default = "default_true")]
    pub richardson: bool,
}

fn default_true() -> bool {
    true
}

/// Thresholds of the conditioning monitor: how close the programme may come to singular, relative
/// to the initial state, before the solve warns. Row gradients and u are checked at every evaluation
/// of the right-hand side (the formulation computes both anyway), row gradients also between the
/// evaluations (a dip inside a step, located on the step's interpolant: `ode::DipWatch`), the
/// singular value at every output sample (every accepted step with the default output). Near a point where (2.6) loses rank, the reduced equations (2.8)-(2.10)
/// and u (2.12) lose about log10(1 / ratio) digits (seed notes: Example 3.1 at p = q = 0).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Conditioning {
    /// A row's gradient norm |dg_i/dv| below this fraction of its value at t0. Default 1e-3 (three
    /// digits lost to the row's collapse).
    pub row_gradient: f64,
    /// Smallest singular value of B with each row scaled by its t0 norm, below this fraction of its
    /// t0 value (s >= 2: rows becoming dependent). Default 1e-3.
    pub singular_value: f64,
    /// max(|A dv/dt|, |G + Q|) / max over the run so far of |A dv/dt - G - Q| above this: u (2.12)
    /// is computed from terms this much larger than its own scale, so it carries that many fewer
    /// digits. Measured against u's running maximum, so a zero crossing of u is no warning; a
    /// programme whose u stays at round-off level (a natural motion) is not tested. Default 1e8
    /// (half of double precision).
    pub u_cancellation: f64,
}

impl Default for Conditioning {
    fn default() -> Self {
        Conditioning {
            row_gradient: 1e-3,
            singular_value: 1e-3,
            u_cancellation: 1e8,
        }
    }
}

/// What a conditioning warning measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WarningKind {
    /// A row's gradient norm relative to t0 ([`Conditioning::row_gradient`]).
    RowGradient,
    /// The smallest singular value of the t0-scaled B relative to t0 ([`Conditioning::singular_value`]).
    SingularValue,
    /// Cancellation in u = A dv/dt - G - Q ([`Conditioning::u_cancellation`]).
    UCancellation,
    /// A fixed-step solve's Richardson estimate of its global error beyond its budget
    /// ([`GlobalError`]); `value` and `worst` are the scaled estimate, `threshold` the budget.
    GlobalError,
}

impl WarningKind {
    /// Machine name (`row_gradient`, ...).
    pub fn name(self) -> &'static str {
        match self {
            WarningKind::RowGradient => "row_gradient",
            WarningKind::SingularValue => "singular_value",
            WarningKind::UCancellation => "u_cancellation",
            WarningKind::GlobalError => "global_error",
        }
    }
}

/// The programme came close to singular: first crossing of a threshold and the worst value seen.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Warning {
    pub kind: WarningKind,
    /// Time of the first sample beyond the threshold.
    pub t: f64,
    /// Rows concerned (for u_cancellation: the programme and system rows with a reaction).
    pub rows: Vec<String>,
    /// Value at `t`.
    pub value: f64,
    /// Worst value over the run, and its time.
    pub worst: f64,
    pub t_worst: f64,
    /// The threshold crossed.
    pub threshold: f64,
    /// row_gradient of a fixed-step solve with its Richardson companion ([`GlobalError`]): the
    /// estimated relative error of the velocities (max over components / max |v|) over the samples
    /// before `t` and after `t_worst`: what the passage cost, measured (None: not measured).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_before: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_after: Option<f64>,
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let rows = quoted(&self.rows);
        match self.kind {
            WarningKind::RowGradient if self.worst == 0.0 => write!(
                f,
                "the gradient of row {rows} passed through zero before t = {:.6} (first seen at \
                 t = {:.6}, threshold {:.0e}): the programme is singular there, dv/dt and u have a \
                 pole",
                self.t_worst, self.t, self.threshold
            ),
            WarningKind::RowGradient if self.error_after.is_some() => write!(
                f,
                "the gradient of row {rows} fell to {:.2e} of its initial norm at t = {:.6} \
                 (threshold {:.0e}; worst {:.2e} at t = {:.6}); the Richardson companion puts the \
                 velocities' relative error at {:.1e} before and {:.1e} after it: {}",
                self.value,
                self.t,
                self.threshold,
                self.worst,
                self.t_worst,
                self.error_before.unwrap_or(f64::NAN),
                self.error_after.unwrap_or(f64::NAN),
                digits_kept(self.error_before, self.error_after)
            ),
            WarningKind::RowGradient => write!(
                f,
                "the gradient of row {rows} fell to {:.2e} of its initial norm at t = {:.6} \
                 (threshold {:.0e}; worst {:.2e} at t = {:.6}): {} of dv/dt and u are lost there",
                self.value,
                self.t,
                self.threshold,
                self.worst,
                self.t_worst,
                digits_lost(self.worst)
            ),
            WarningKind::SingularValue => write!(
                f,
                "rows {rows} came close to dependent at t = {:.6}: the smallest singular value of \
                 the row-scaled programme Jacobian fell to {:.2e} of its initial value (threshold \
                 {:.0e}; worst {:.2e} at t = {:.6})",
                self.t, self.value, self.threshold, self.worst, self.t_worst
            ),
            WarningKind::GlobalError => write!(
                f,
                "the fixed-step solve's estimated global error (Richardson, companion at twice the \
                 step) reaches {:.2e} times its budget atol + rtol |x| at t = {:.6} (budget {}): \
                 the trajectory is less accurate than the tolerances ask; use a smaller step or \
                 an adaptive integrator",
                self.worst, self.t_worst, self.threshold
            ),
            WarningKind::UCancellation => write!(
                f,
                "the forces that the reaction of rows {rows} is computed from grew to {:.2e} times \
                 its scale at t = {:.6} (threshold {:.0e}; worst {:.2e} at t = {:.6}): u carries \
                 about {:.0} fewer digits there",
                self.value, self.t, self.threshold, self.worst, self.t_worst,
                self.worst.log10()
            ),
        }
    }
}

/// Digits lost to a row gradient at `ratio` of its initial norm (seed notes, Example 3.1: the
/// reduced equations lose log10(1 / ratio)), as words; float64 carries 16 at most.
fn digits_lost(ratio: f64) -> String {
    let d = -ratio.log10();
    if !(d < 15.5) {
        "all digits (float64 carries about 16)".into()
    } else {
        format!("about {d:.0} digits")
    }
}

/// What a passage cost, from the relative errors before and after it, as words.
fn digits_kept(before: Option<f64>, after: Option<f64>) -> String {
    let after = after.unwrap_or(f64::NAN);
    let kept = -after.log10();
    let lost = (after / before.unwrap_or(f64::NAN)).log10();
    if !(kept >= 0.5) {
        "no digit of the motion after it is right".into()
    } else if lost >= 0.5 {
        format!("about {lost:.0} digits lost there, {kept:.0} left")
    } else {
        format!("no digit lost there, about {kept:.0} left")
    }
}

/// Names as "`a`, `b`" for messages.
pub fn quoted(names: &[String]) -> String {
    if names.is_empty() {
        return "(none)".into();
    }
    names
        .iter()
        .map(|n| format!("`{n}`"))
        .collect::<Vec<_>>()
        .join(", ")
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            formulation: Formulation::Auto,
            integrator: Method::Dop853,
            rtol: crate::integrate::DEFAULT_RTOL,
            atol: crate::integrate::DEFAULT_ATOL,
            max_step: f64::INFINITY,
            fixed_step: None,
            max_steps: crate::integrate::DEFAULT_MAX_STEPS,
            max_samples: DEFAULT_MAX_SAMPLES,
            drift: DriftControl::Projection {
                tol: DEFAULT_PROJECTION_TOL,
                max_iter: DEFAULT_PROJECTION_ITER,
            },
            rank_dependent: 1e-10,
            rank_vanishing: 1e-12,
            output: Output::Steps,
            max_drift: None,
            consistency_tol: 1e-10,
            assemble: false,
            conditioning: Conditioning::default(),
            strict: false,
            richardson: true,
        }
    }
}

fn default_max_samples() -> usize {
    DEFAULT_MAX_SAMPLES
}

impl Settings {
    /// The step driver's options these settings give (the one mapping; the driver's other fields
    /// keep their defaults).
    pub fn driver_options(&self) -> DriverOptions {
        DriverOptions {
            rtol: self.rtol,
            atol: self.atol,
            h_max: self.max_step,
            fixed_step: self.fixed_step,
            max_steps: self.max_steps,
            ..Default::default()
        }
    }

    /// The rank tolerances of B these settings give (every caller of a formulation uses these).
    pub fn rank(&self) -> RankTolerances {
        RankTolerances {
            dependent: self.rank_dependent,
            vanishing: self.rank_vanishing,
        }
    }
}

/// How a solve ended. Nightly jobs branch on this, not on messages.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "code")]
pub enum ReturnCode {
    /// Reached t1.
    Success,
    /// The step size fell below the minimum.
    StepTooSmall { t: f64, h: f64 },
    /// The constraint Jacobian B lost rank: `rows` are dependent or vanishing; `rcond` estimates the
    /// reciprocal condition of the row-normalized B.
    SingularProgramme {
        t: f64,
        rows: Vec<String>,
        rcond: f64,
    },
    /// The square system of the formulation (or A) is numerically singular.
    SingularSystem { t: f64, rcond: f64 },
    /// A residual exceeded `Settings::max_drift`.
    DriftExceeded { t: f64, row: String, residual: f64 },
    /// Non-finite values in the state or the right-hand side.
    NonFinite { t: f64 },
    /// `max_steps` used up.
    MaxSteps { t: f64 },
    /// The initial state violates a row beyond `consistency_tol` (and was not, or could not be,
    /// assembled).
    InconsistentInitialState { row: String, residual: f64 },
    /// Projection onto the constraints did not converge after a step.
    ProjectionFailed { t: f64, row: String, residual: f64 },
    /// With [`Settings::strict`]: a conditioning warning stopped the solve.
    IllConditioned { t: f64, warning: Box<Warning> },
    /// The sink asked to stop ([`SampleSink::interrupted`]: Ctrl-C or SIGTERM in `progmo solve`).
    Interrupted { t: f64 },
    /// With actuators (servo-constraints, [`crate::servo`]): the actuators cannot realize the
    /// programme rows `rows`: no actuator reaches them within the highest relative degree searched
    /// (`reached` false), or the decoupling matrix d y^(r) / d tau is singular (pivot ratio `rcond`).
    UnrealizableProgramme {
        t: f64,
        rows: Vec<String>,
        actuators: Vec<String>,
        reached: bool,
        rcond: f64,
    },
    /// At the recent step rate the span needs about `needed` steps, over 10 times `max_steps`:
    /// stopped early rather than after minutes of steps into the limit.
    TooManySteps {
        t: f64,
        needed: f64,
        max_steps: usize,
    },
}

impl std::fmt::Display for ReturnCode {
    /// One sentence naming the quantity, the time and the rows.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReturnCode::Success => write!(f, "reached the end of the time span"),
            ReturnCode::StepTooSmall { t, h } => write!(
                f,
                "the step size fell to {h:.3e} at t = {t:.6}, below what the integrator can resolve"
            ),
            ReturnCode::SingularProgramme { t, rows, rcond } => write!(
                f,
                "the programme Jacobian dg/dv lost rank at t = {t:.6}: row(s) {} vanished or became \
                 dependent (reciprocal condition {rcond:.2e} of the row-normalized Jacobian)",
                quoted(rows)
            ),
            ReturnCode::SingularSystem { t, rcond } => write!(
                f,
                "the linear system for dv/dt became singular at t = {t:.6} (reciprocal condition \
                 {rcond:.2e})"
            ),
            ReturnCode::DriftExceeded { t, row, residual } => write!(
                f,
                "the residual of row `{row}` reached {residual:.3e} at t = {t:.6}, beyond max_drift"
            ),
            ReturnCode::NonFinite { t } => write!(
                f,
                "the state or dv/dt became non-finite (NaN or infinite) at t = {t:.6}"
            ),
            ReturnCode::MaxSteps { t } => {
                write!(f, "the step limit (max_steps) was used up at t = {t:.6}")
            }
            ReturnCode::InconsistentInitialState { row, residual } => write!(
                f,
                "the initial state violates row `{row}` by {residual:.3e} (beyond consistency_tol); \
                 set `assemble = true` in [initial] to project it"
            ),
            ReturnCode::ProjectionFailed { t, row, residual } => write!(
                f,
                "projection onto the programme did not converge at t = {t:.6}: row `{row}` kept a \
                 residual of {residual:.3e}"
            ),
            ReturnCode::IllConditioned { warning, .. } => {
                write!(f, "strict mode stopped the solve: {warning}")
            }
            ReturnCode::Interrupted { t } => write!(
                f,
                "the solve was interrupted at t = {t:.6} (Ctrl-C or a termination signal)"
            ),
            ReturnCode::UnrealizableProgramme {
                t,
                rows,
                actuators,
                reached: false,
                ..
            } => write!(
                f,
                "the actuators {} do not reach programme row(s) {} at t = {t:.6}: tau appears in \
                 none of their first {} time derivatives beyond round-off (a state where the \
                 actuators' effect on the rows vanishes to every order, e.g. a crane's rope \
                 hanging still, has no relative degree: start the motion off it)",
                quoted(actuators),
                quoted(rows),
                crate::servo::MAX_RELATIVE_DEGREE + 1
            ),
            ReturnCode::UnrealizableProgramme {
                t,
                rows,
                actuators,
                rcond,
                ..
            } => write!(
                f,
                "the actuators {} cannot realize programme row(s) {} at t = {t:.6}: the decoupling \
                 matrix d y^(r)/d tau is singular (pivot ratio {rcond:.2e})",
                quoted(actuators),
                quoted(rows)
            ),
            ReturnCode::TooManySteps {
                t,
                needed,
                max_steps,
            } => write!(
                f,
                "at its step rate up to t = {t:.6} the time span needs about {needed:.1e} steps, \
                 far more than max_steps = {max_steps}: stopped early (shorten t1)"
            ),
        }
    }
}

impl ReturnCode {
    /// True for [`ReturnCode::Success`].
    pub fn is_success(&self) -> bool {
        matches!(self, ReturnCode::Success)
    }

    /// Short machine name (`success`, `singular_programme`, ...).
    pub fn name(&self) -> &'static str {
        match self {
            ReturnCode::Success => "success",
            ReturnCode::StepTooSmall { .. } => "step_too_small",
            ReturnCode::SingularProgramme { .. } => "singular_programme",
            ReturnCode::SingularSystem { .. } => "singular_system",
            ReturnCode::DriftExceeded { .. } => "drift_exceeded",
            ReturnCode::NonFinite { .. } => "non_finite",
            ReturnCode::MaxSteps { .. } => "max_steps",
            ReturnCode::InconsistentInitialState { .. } => "inconsistent_initial_state",
            ReturnCode::ProjectionFailed { .. } => "projection_failed",
            ReturnCode::IllConditioned { .. } => "ill_conditioned",
            ReturnCode::Interrupted { .. } => "interrupted",
            ReturnCode::TooManySteps { .. } => "too_many_steps",
            ReturnCode::UnrealizableProgramme { .. } => "unrealizable_programme",
        }
    }

    /// The time the code refers to (None for success and an inconsistent initial state).
    pub fn time(&self) -> Option<f64> {
        self.clone().time_mut().copied()
    }

    /// The same code at time `t_new` (no change for codes without a time).
    pub(crate) fn at(mut self, t_new: f64) -> Self {
        if let Some(t) = self.time_mut() {
            *t = t_new;
        }
        self
    }

    fn time_mut(&mut self) -> Option<&mut f64> {
        match self {
            ReturnCode::Success | ReturnCode::InconsistentInitialState { .. } => None,
            ReturnCode::StepTooSmall { t, .. }
            | ReturnCode::SingularProgramme { t, .. }
            | ReturnCode::SingularSystem { t, .. }
            | ReturnCode::DriftExceeded { t, .. }
            | ReturnCode::NonFinite { t }
            | ReturnCode::MaxSteps { t }
            | ReturnCode::ProjectionFailed { t, .. }
            | ReturnCode::IllConditioned { t, .. }
            | ReturnCode::Interrupted { t }
            | ReturnCode::TooManySteps { t, .. }
            | ReturnCode::UnrealizableProgramme { t, .. } => Some(t),
        }
    }
}

/// Counters of a solve (snapshot-tested).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Statistics {
    /// Integrator counters (steps, rejected, RHS and Jacobian evaluations, LU, Newton).
    pub integrator: IntegratorStats,
    /// Factorizations inside right-hand-side evaluations (QR of B^T, LU of the square system).
    pub factorizations: usize,
    /// Post-step projections performed (steps where a correction was applied).
    pub projections: usize,
    /// Newton iterations of all projections.
    pub projection_iterations: usize,
    /// Largest position correction |dq| (in the chart, inf-norm).
    pub max_position_correction: f64,
    /// Largest velocity correction |dv| (inf-norm).
    pub max_velocity_correction: f64,
    /// Largest relative |D u| / |u| seen: how far u left the row space of B (2.7).
    pub max_du: f64,
    /// Smallest reciprocal condition estimate of the row-normalized B seen.
    pub min_b_rcond: f64,
    /// Smallest |dg_i/dv| / |dg_i/dv (t0)| over rows and right-hand-side evaluations (1 without rows).
    pub min_row_gradient_ratio: f64,
    /// Smallest singular value of the t0-row-scaled B relative to t0, over output samples (1 if s < 2).
    pub min_singular_value_ratio: f64,
    /// Largest cancellation ratio of u (see [`Conditioning::u_cancellation`]); 0 if never tested.
    pub max_u_cancellation: f64,
}

impl Statistics {
    /// Counters before a solve (ratios at their neutral values).
    pub fn new() -> Self {
        Statistics {
            min_b_rcond: 1.0,
            min_row_gradient_ratio: 1.0,
            min_singular_value_ratio: 1.0,
            ..Default::default()
        }
    }
}

/// Correction applied to the initial state when it was assembled.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct InitialCorrection {
    /// |dq| (inf-norm, chart coordinates).
    pub position: f64,
    /// |dv| (inf-norm).
    pub velocity: f64,
}

/// The sampled motion, one row per sample, flattened.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    /// Names of q.
    pub q_names: Vec<String>,
    /// Names of v (also of dv/dt, u, reactions).
    pub v_names: Vec<String>,
    /// Names of the constraint rows.
    pub row_names: Vec<String>,
    /// Names of the actuators (`[[actuators]]`; empty without): a servo solve's multipliers are
    /// their forces tau, the first `actuator_names.len()` of each sample's lambda ([`Self::tau_at`]).
    pub actuator_names: Vec<String>,
    /// Sample times.
    pub t: Vec<f64>,
    /// Configurations, nq per sample.
    pub q: Vec<f64>,
    /// Velocities, nv per sample.
    pub v: Vec<f64>,
    /// Accelerations dv/dt, nv per sample.
    pub a: Vec<f64>,
    /// Control forces u of the programme rows (2.12), nv per sample.
    pub u: Vec<f64>,
    /// Reactions of the system's own constraints, nv per sample.
    pub reactions: Vec<f64>,
    /// Multipliers lambda, s per sample.
    pub lambda: Vec<f64>,
    /// Residual of each row, s per sample: g (position), f (velocity), h (acceleration).
    pub residual: Vec<f64>,
    /// dg/dt of position rows (0 for other rows), s per sample.
    pub residual_rate: Vec<f64>,
}

impl Trajectory {
    /// Doubles per sample: t, q, and v, dv/dt, u, reactions (nv each), lambda, residual, dg/dt
    /// (s each).
    pub fn values_per_sample(&self) -> usize {
        1 + self.q_names.len() + 4 * self.v_names.len() + 3 * self.row_names.len()
    }

    /// An empty trajectory with the names of `problem`'s q, v and rows.
    pub fn named_for<M: Model, C: Constraints>(problem: &Problem<M, C>) -> Self {
        Trajectory {
            q_names: problem.model.q_names(),
            v_names: problem.model.v_names(),
            row_names: problem
                .constraints
                .rows()
                .iter()
                .map(|r| r.name.clone())
                .collect(),
            actuator_names: problem
                .constraints
                .actuation()
                .map(|a| a.names.clone())
                .unwrap_or_default(),
            ..Default::default()
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }
    /// True when there is no sample.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
    fn nq(&self) -> usize {
        self.q_names.len()
    }
    fn nv(&self) -> usize {
        self.v_names.len()
    }
    fn s(&self) -> usize {
        self.row_names.len()
    }
    /// q of sample k.
    pub fn q_at(&self, k: usize) -> &[f64] {
        &self.q[k * self.nq()..(k + 1) * self.nq()]
    }
    /// v of sample k.
    pub fn v_at(&self, k: usize) -> &[f64] {
        &self.v[k * self.nv()..(k + 1) * self.nv()]
    }
    /// dv/dt of sample k.
    pub fn a_at(&self, k: usize) -> &[f64] {
        &self.a[k * self.nv()..(k + 1) * self.nv()]
    }
    /// u of sample k.
    pub fn u_at(&self, k: usize) -> &[f64] {
        &self.u[k * self.nv()..(k + 1) * self.nv()]
    }
    /// System reactions of sample k.
    pub fn reactions_at(&self, k: usize) -> &[f64] {
        &self.reactions[k * self.nv()..(k + 1) * self.nv()]
    }
    /// Multipliers of sample k.
    pub fn lambda_at(&self, k: usize) -> &[f64] {
        &self.lambda[k * self.s()..(k + 1) * self.s()]
    }
    /// The actuators' forces tau of sample k (u = H(t, q) tau; empty without actuators): the
    /// servo solve keeps them as the leading multipliers.
    pub fn tau_at(&self, k: usize) -> &[f64] {
        &self.lambda_at(k)[..self.actuator_names.len()]
    }
    /// Residuals of sample k.
    pub fn residual_at(&self, k: usize) -> &[f64] {
        &self.residual[k * self.s()..(k + 1) * self.s()]
    }
    /// Sample k as the solver emitted it.
    pub fn sample(&self, k: usize) -> Sample<'_> {
        let s = self.s();
        Sample {
            t: self.t[k],
            q: self.q_at(k),
            v: self.v_at(k),
            a: self.a_at(k),
            u: self.u_at(k),
            reactions: self.reactions_at(k),
            lambda: self.lambda_at(k),
            residual: self.residual_at(k),
            residual_rate: &self.residual_rate[k * s..(k + 1) * s],
        }
    }
    /// Largest |residual| of row i over the samples.
    pub fn max_residual(&self, i: usize) -> f64 {
        (0..self.len())
            .map(|k| self.residual_at(k)[i].abs())
            .fold(0.0, f64::max)
    }
}

/// One output sample, handed to a [`SampleSink`].
pub struct Sample<'a> {
    pub t: f64,
    pub q: &'a [f64],
    pub v: &'a [f64],
    pub a: &'a [f64],
    pub u: &'a [f64],
    pub reactions: &'a [f64],
    pub lambda: &'a [f64],
    pub residual: &'a [f64],
    pub residual_rate: &'a [f64],
}

/// Where samples go: kept in memory ([`Trajectory`]) or streamed (CSV, MCAP) so memory does not grow
/// with the number of steps.
pub trait SampleSink {
    /// Take one sample.
    fn sample(&mut self, s: &Sample<'_>);
    /// A conditioning warning was raised (once per warning, at its first crossing). Default:
    /// ignored (it is in [`Solution::warnings`] anyway).
    fn warning(&mut self, _w: &Warning) {}
    /// Polled after every accepted step: true stops the solve there with
    /// [`ReturnCode::Interrupted`] (the step's samples are written first). Default: never.
    fn interrupted(&self) -> bool {
        false
    }
}

impl SampleSink for Trajectory {
    fn sample(&mut self, s: &Sample<'_>) {
        self.t.push(s.t);
        self.q.extend_from_slice(s.q);
        self.v.extend_from_slice(s.v);
        self.a.extend_from_slice(s.a);
        self.u.extend_from_slice(s.u);
        self.reactions.extend_from_slice(s.reactions);
        self.lambda.extend_from_slice(s.lambda);
        self.residual.extend_from_slice(s.residual);
        self.residual_rate.extend_from_slice(s.residual_rate);
    }
}

/// The outcome of a solve.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// How it ended.
    pub code: ReturnCode,
    /// The samples taken until then.
    pub trajectory: Trajectory,
    /// Counters.
    pub stats: Statistics,
    /// Largest |residual| of each row over every accepted step and every output sample.
    pub max_residual: Vec<f64>,
    /// Largest |dg/dt| of each position row over every accepted step (0 for other rows).
    pub max_residual_rate: Vec<f64>,
    /// Correction applied to the initial state, if it was assembled.
    pub initial_correction: Option<InitialCorrection>,
    /// Conditioning warnings (see [`Conditioning`]), in the order first raised.
    pub warnings: Vec<Warning>,
    /// Last time reached: on an early stop the time of the last output sample and of the code.
    pub t_end: f64,
    /// Fixed-step solves (with [`Settings::richardson`]): the estimate of the global error.
    pub global_error: Option<GlobalError>,
}

/// A fixed-step solve's a-posteriori global error estimate (Richardson extrapolation, HNW I, II.4):
/// a companion solve with twice the step h gives, at the output samples both runs share,
/// err(y_h) ~ (y_2h - y_h) / (2^p - 1) for a method of order p. Judged per component of (q, v)
/// against the solve's own tolerances: `scaled` = max |y_2h - y_h| / ((2^p - 1)(atol + rtol |y_h|))
/// over samples and components, with budget 1 (the accuracy an adaptive solve is asked for per
/// step, here asked of the whole trajectory). Beyond the budget: a `global_error` warning (and
/// with `strict`, the code `ill_conditioned`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct GlobalError {
    /// `"richardson"`.
    pub method: &'static str,
    /// The solve's step h and the companion's step 2h.
    pub step: f64,
    pub companion_step: f64,
    /// Order p of the method.
    pub order: usize,
    /// Largest estimated absolute error max |y_2h - y_h| / (2^p - 1) over samples and components.
    pub estimate: f64,
    /// Largest scaled estimate (see the type's docs) and where it occurs.
    pub scaled: f64,
    pub t_worst: f64,
    pub component: String,
    /// The budget of `scaled` (1).
    pub budget: f64,
    /// Output samples compared (those the two runs share, up to the earlier end).
    pub samples: usize,
    /// The companion's return code name, last time and integrator counters (its cost).
    pub companion_code: &'static str,
    pub companion_t_end: f64,
    pub companion: IntegratorStats,
}

/// Solve and keep all samples in memory.
pub fn solve<M: Model, C: Constraints>(problem: &Problem<M, C>, settings: &Settings) -> Solution {
    let mut traj = Trajectory::named_for(problem);
    let mut out = solve_into(problem, settings, &mut traj);
    out.trajectory = traj;
    out
}

/// Solve, streaming samples into `sink`; the returned solution's trajectory is empty. A fixed-step
/// solve with [`Settings::richardson`] then runs its companion ([`GlobalError`]).
pub fn solve_into<M: Model, C: Constraints>(
    problem: &Problem<M, C>,
    settings: &Settings,
    sink: &mut dyn SampleSink,
) -> Solution {
    let Some(h) = fixed_step_of(settings).filter(|_| settings.richardson) else {
        return solve_core(problem, settings, sink);
    };
    let width = problem.model.nq() + problem.model.nv();
    let span = (problem.t1 - problem.t0).max(0.0);
    let per = match settings.output {
        Output::Every(dt) if dt > 0.0 => dt.min(h),
        _ => h,
    };
    let expected = (span / per).min(1e15) as usize + 2;
    let stride = (expected.saturating_mul(width + 1))
        .div_ceil(RICHARDSON_MAX_NUMBERS)
        .max(1);
    let mut rec = Recording {
        inner: sink,
        rec: Recorded {
            stride,
            seen: 0,
            width,
            t: vec![],
            x: vec![],
        },
    };
    let mut sol = solve_core(problem, settings, &mut rec);
    let Recording { inner, rec } = rec;
    richardson(problem, settings, inner, &rec, &mut sol);
    sol
}

fn solve_core<M: Model, C: Constraints>(
    problem: &Problem<M, C>,
    settings: &Settings,
    sink: &mut dyn SampleSink,
) -> Solution {
    let s = problem.constraints.rows().len();
    let mut sol = Solution {
        code: ReturnCode::Success,
        trajectory: Trajectory::default(),
        stats: Statistics::new(),
        max_residual: vec![0.0; s],
        max_residual_rate: vec![0.0; s],
        initial_correction: None,
        warnings: vec![],
        t_end: problem.t0,
        global_error: None,
    };
    let mut ode = match ode::MotionOde::new(problem, settings, sink) {
        Ok(o) => o,
        Err(code) => {
            sol.code = code;
            return sol;
        }
    };
    sol.initial_correction = ode.initial_correction.clone();
    let nv = problem.model.nv();
    let mut integrator = Integrator::new(settings.integrator, settings.driver_options(), 2 * nv);
    let mut y = ode.initial_y();
    let (outcome, istats) = integrator.integrate(&mut ode, problem.t0, problem.t1, &mut y);
    sol.code = ode.finish(outcome);
    sol.warnings = ode.warnings.clone();
    sol.stats = ode.stats.clone();
    sol.stats.integrator = istats;
    sol.max_residual = ode.max_residual.clone();
    sol.max_residual_rate = ode.max_residual_rate.clone();
    sol.t_end = ode.t_last;
    sol
}

/// The step of a fixed-step solve, if the settings make one.
fn fixed_step_of(settings: &Settings) -> Option<f64> {
    match settings.integrator {
        Method::Rk4 { h } => Some(h),
        _ => settings.fixed_step.filter(|h| *h > 0.0),
    }
    .filter(|h| h.is_finite() && *h > 0.0)
}

/// Most numbers the Richardson recorder keeps (t, q, v per sample); beyond, it keeps every k-th
/// sample.
const RICHARDSON_MAX_NUMBERS: usize = 10_000_000;

/// (t, q, v) of the samples a fixed-step solve emitted (every `stride`-th), for the companion.
struct Recorded {
    stride: usize,
    seen: usize,
    width: usize,
    t: Vec<f64>,
    x: Vec<f64>,
}

/// Passes samples on to the caller's sink and records them.
struct Recording<'a> {
    inner: &'a mut dyn SampleSink,
    rec: Recorded,
}

impl SampleSink for Recording<'_> {
    fn sample(&mut self, s: &Sample<'_>) {
        self.inner.sample(s);
        let r = &mut self.rec;
        if r.seen % r.stride == 0 {
            r.t.push(s.t);
            r.x.extend_from_slice(s.q);
            r.x.extend_from_slice(s.v);
        }
        r.seen += 1;
    }
    fn warning(&mut self, w: &Warning) {
        self.inner.warning(w)
    }
    fn interrupted(&self) -> bool {
        self.inner.interrupted()
    }
}

/// Compares the companion's samples with the recorded ones at shared times.
struct Comparing<'a> {
    inner: &'a dyn SampleSink,
    rec: &'a Recorded,
    next: usize,
    tol: f64,
    atol: f64,
    rtol: f64,
    denominator: f64,
    samples: usize,
    estimate: f64,
    scaled: f64,
    t_worst: f64,
    component: usize,
    buf: Vec<f64>,
    /// Per compared sample: t and the estimated relative error of v (max |dv| / max |v|).
    v_error: Vec<(f64, f64)>,
}

impl SampleSink for Comparing<'_> {
    fn sample(&mut self, s: &Sample<'_>) {
        let r = self.rec;
        while self.next < r.t.len() && r.t[self.next] < s.t - self.tol {
            self.next += 1;
        }
        if self.next >= r.t.len() || (r.t[self.next] - s.t).abs() > self.tol {
            return;
        }
        let x = &r.x[self.next * r.width..(self.next + 1) * r.width];
        self.buf.clear();
        self.buf.extend_from_slice(s.q);
        self.buf.extend_from_slice(s.v);
        for (j, (a, b)) in x.iter().zip(&self.buf).enumerate() {
            let e = (b - a).abs() / self.denominator;
            let sc = e / (self.atol + self.rtol * a.abs());
            self.estimate = self.estimate.max(e);
            if sc > self.scaled || sc.is_nan() {
                self.scaled = sc;
                self.t_worst = s.t;
                self.component = j;
            }
        }
        let nq = s.q.len();
        let (mut dv, mut vmax) = (0.0f64, 0.0f64);
        for (a, b) in x[nq..].iter().zip(s.v) {
            dv = dv.max((b - a).abs() / self.denominator);
            vmax = vmax.max(a.abs());
        }
        self.v_error.push((s.t, dv / vmax.max(f64::MIN_POSITIVE)));
        self.samples += 1;
    }
    fn interrupted(&self) -> bool {
        self.inner.interrupted()
    }
}

/// The companion solve at twice the step and the estimate it gives ([`GlobalError`]).
fn richardson<M: Model, C: Constraints>(
    problem: &Problem<M, C>,
    settings: &Settings,
    sink: &mut dyn SampleSink,
    rec: &Recorded,
    sol: &mut Solution,
) {
    let Some(h) = fixed_step_of(settings) else {
        return;
    };
    if sink.interrupted() {
        return;
    }
    let mut s2 = settings.clone();
    match &mut s2.integrator {
        Method::Rk4 { h: h2 } => *h2 = 2.0 * h,
        _ => s2.fixed_step = Some(2.0 * h),
    }
    // The companion judges the solve; its own stops and warnings are not the solve's.
    s2.strict = false;
    let p = settings.integrator.order();
    let mut cmp = Comparing {
        inner: sink,
        rec,
        next: 0,
        tol: 1e-9 * h,
        atol: settings.atol,
        rtol: settings.rtol,
        denominator: 2f64.powi(p as i32) - 1.0,
        samples: 0,
        estimate: 0.0,
        scaled: 0.0,
        t_worst: problem.t0,
        component: 0,
        buf: vec![],
        v_error: vec![],
    };
    let mut ode = match ode::MotionOde::new(problem, &s2, &mut cmp) {
        Ok(o) => o,
        Err(_) => return,
    };
    let nv = problem.model.nv();
    let mut integrator = Integrator::new(s2.integrator, s2.driver_options(), 2 * nv);
    let mut y = ode.initial_y();
    let (outcome, istats) = integrator.integrate(&mut ode, problem.t0, problem.t1, &mut y);
    let code = ode.finish(outcome);
    let t_end = ode.t_last;
    drop(ode);
    let names: Vec<String> = problem
        .model
        .q_names()
        .into_iter()
        .chain(problem.model.v_names())
        .collect();
    let g = GlobalError {
        method: "richardson",
        step: h,
        companion_step: 2.0 * h,
        order: p,
        estimate: cmp.estimate,
        scaled: cmp.scaled,
        t_worst: cmp.t_worst,
        component: names.get(cmp.component).cloned().unwrap_or_default(),
        budget: 1.0,
        samples: cmp.samples,
        companion_code: code.name(),
        companion_t_end: t_end,
        companion: istats,
    };
    // What each row-gradient passage cost: the velocities' estimated error before and after it.
    for w in sol.warnings.iter_mut() {
        if w.kind != WarningKind::RowGradient {
            continue;
        }
        let max_over = |keep: &dyn Fn(f64) -> bool| {
            cmp.v_error
                .iter()
                .filter(|(t, _)| keep(*t))
                .map(|x| x.1)
                .reduce(f64::max)
        };
        let (t_first, t_worst) = (w.t, w.t_worst);
        w.error_before = max_over(&|t| t < t_first);
        w.error_after = max_over(&|t| t > t_worst);
    }
    if !(g.scaled <= g.budget) {
        let w = Warning {
            kind: WarningKind::GlobalError,
            t: g.t_worst,
            rows: vec![],
            value: g.scaled,
            worst: g.scaled,
            t_worst: g.t_worst,
            threshold: g.budget,
            error_before: None,
            error_after: None,
        };
        sink.warning(&w);
        if settings.strict && sol.code.is_success() {
            sol.code = ReturnCode::IllConditioned {
                t: sol.t_end,
                warning: Box::new(w.clone()),
            };
        }
        sol.warnings.push(w);
    }
    sol.global_error = Some(g);
}

/// The state at t0 as the solver will start from it: consistency checked (and assembled if the
/// settings ask for it), the right-hand side evaluated once. Returns the first sample (residuals,
/// u, ...) and any initial correction, or the return code that would stop the solve at t0.
pub fn check_initial<M: Model, C: Constraints>(
    problem: &Problem<M, C>,
    settings: &Settings,
) -> Result<(Trajectory, Option<InitialCorrection>), ReturnCode> {
    let mut traj = Trajectory::named_for(problem);
    let corr = {
        let ode = ode::MotionOde::new(problem, settings, &mut traj)?;
        ode.initial_correction.clone()
    };
    Ok((traj, corr))
}

/// The return code of a programme the actuators cannot realize at time t.
pub fn unrealizable<C: Constraints>(
    c: &C,
    act: &crate::servo::Actuation,
    t: f64,
    e: crate::servo::Unrealizable,
) -> ReturnCode {
    use crate::servo::Unrealizable as U;
    let all: Vec<String> = c.rows().iter().map(|r| r.name.clone()).collect();
    let (rows, reached, rcond) = match e {
        U::NotReached { rows } => (rows.iter().map(|&i| all[i].clone()).collect(), false, 0.0),
        U::Singular { rcond } => (all, true, rcond),
        U::Model => return ReturnCode::NonFinite { t },
    };
    ReturnCode::UnrealizableProgramme {
        t,
        rows,
        actuators: act.names.clone(),
        reached,
        rcond,
    }
}

/// Is row i one whose residual the state itself must satisfy (position or velocity level)?
pub(crate) fn is_state_row(level: Level) -> bool {
    matches!(level, Level::Position | Level::Velocity)
}

/// Names of the rows of a role.
pub fn rows_of_role<C: Constraints>(c: &C, role: Role) -> Vec<String> {
    c.rows()
        .iter()
        .filter(|r| r.role == role)
        .map(|r| r.name.clone())
        .collect()
}
