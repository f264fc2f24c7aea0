//! Result writers: streaming CSV, MCAP recordings, JSON run summaries, and sink adapters
//! (tee, decimation, progress bar).
//!
//! Every writer implements [`SampleSink`] (so it can be handed to
//! [`solve_into`](crate::solve::solve_into)) and [`OutputSink`], whose `finish` flushes and returns
//! the first error met. `sample` never panics on I/O errors: the first error is kept, later samples
//! are dropped, and `finish` reports it. Dropping a writer without `finish` still flushes on a
//! best-effort basis but loses the error.
//!
//! ```no_run
//! # use progmo::output::*;
//! # use progmo::solve::{solve_into, Settings};
//! let problem = progmo::problems::rigid_body::heavy_top();
//! let layout = SampleLayout::from_problem(&problem);
//! let csv = CsvSink::create("top.csv", &layout).unwrap();
//! let rec = McapSink::create("top.mcap", &layout).unwrap();
//! let mut sink = Progress::new(Tee::new(Every::new(0.01, csv), rec), "top", problem.t0, problem.t1);
//! let solution = solve_into(&problem, &Settings::default(), &mut sink);
//! sink.finish().unwrap();
//! ```
//!
//! # Files of a run (`progmo solve`)
//!
//! A result file exists under its real name only when it is whole: [`RunFiles`] writes
//! `trajectory.csv` and `recording.mcap` as `<name>.partial` ([`Staged`]) and renames each when its
//! writer finishes without error; `summary.json` is written last, through `summary.json.tmp`
//! ([`write_summary_to_path`]), and named `summary.json.partial` when a data file stayed
//! `.partial`. A `.partial` file is an incomplete write (a full device: the
//! command's last line names it and the exit code is 3; or a killed process). A destination
//! holding something other than a regular file (a device, a FIFO, a directory) is refused, never
//! replaced ([`writable_destination`]). A refused solve (bad settings) clears the earlier run's
//! files from its folder as a started one does. A solve that stops
//! early or is interrupted (Ctrl-C, SIGTERM: [`StopOn`] and [`crate::interrupt`]; code
//! `interrupted`, exit 130) is not an incomplete write: its files are finished, valid up to the
//! stop, and the summary's `code` says why it ended. [`remove_previous_run`] clears every one of
//! these names ([`RUN_FILES`]) before a run into an existing folder.
//!
//! # Column names
//!
//! All formats use the names of [`SampleLayout`]: `q_names` for q, `v_names` for v, dv/dt, u and the
//! reactions, `row_names` (programme rows and system constraints, in the solver's order) for
//! lambda and the residuals.
//!
//! # CSV format ([`CsvSink`], [`read_csv`])
//!
//! RFC 4180 CSV, `,` separator, `\n` line ends, UTF-8. Fields are quoted only when needed (a name
//! containing `,`, `"` or a line break). The first line is the header; then one line per sample,
//! in the order received. Columns, in this order:
//!
//! | column                    | count | meaning                                                      |
//! |---------------------------|-------|--------------------------------------------------------------|
//! | `t`                       | 1     | time                                                         |
//! | `q:<q name>`              | nq    | configuration                                                |
//! | `v:<v name>`              | nv    | velocity                                                     |
//! | `a:<v name>`              | nv    | acceleration dv/dt                                           |
//! | `u:<v name>`              | nv    | control force of the programme rows (2.12)                   |
//! | `reaction:<v name>`       | nv    | reactions of system constraints; only if `SampleLayout::reactions` |
//! | `lambda:<row name>`       | s     | multipliers                                                  |
//! | `residual:<row name>`     | s     | residual of the row (g, f or h by level)                     |
//! | `residual_rate:<row name>`| s     | dg/dt of position rows, 0 for other rows                     |
//!
//! A column name is split at its first `:` into group and name, so names may contain `:`.
//! Numbers are written with Rust's `{:e}` formatting: the shortest decimal that reads back to the
//! same `f64` bit for bit, in exponent form (`1.25e0`, `-3e-17`, `-0e0`); non-finite values are
//! written `NaN`, `inf`, `-inf`. Python's `float()`, numpy and pandas read all of these.
//!
//! [`read_csv`] accepts exactly this layout (groups in this order, each possibly empty; `a:`, `u:`
//! and `reaction:` must name the `v:` coordinates, `residual:` and `residual_rate:` the `lambda:`
//! rows). Missing `reaction:` or `residual_rate:` columns read as zeros. Errors give the line and
//! column (1-based) of the bad field.
//!
//! # MCAP format ([`McapSink`])
//!
//! An MCAP file (uncompressed chunks with message indexes and a summary section written by
//! `finish`), header profile `""`, library `progmo <version>`. Every channel has message encoding
//! `json` and a schema of encoding `jsonschema`. Log time and publish time are the sample time in
//! nanoseconds, `round(t * 1e9)` as u64 (negative or non-finite t give 0; the exact `t` is also in
//! each message). Sequence numbers count from 0 per channel. Numbers are JSON numbers (shortest
//! round-trip form); non-finite values are written as `null`. Each object below maps names to
//! numbers, keys in [`SampleLayout`] order.
//!
//! | topic               | schema name         | message                                             |
//! |---------------------|---------------------|-----------------------------------------------------|
//! | `/progmo/state`     | `progmo.State`      | `{"t", "q": {q name: ..}, "v": {v name: ..}, "a": {v name: ..}}` |
//! | `/progmo/control`   | `progmo.Control`    | `{"t", "u": {v name: ..}, "lambda": {row name: ..}}` |
//! | `/progmo/residual`  | `progmo.Residual`   | `{"t", "residual": {row name: ..}, "residual_rate": {row name: ..}}` |
//! | `/progmo/reaction`  | `progmo.Reaction`   | `{"t", "reaction": {v name: ..}}`; only if `SampleLayout::reactions` |
//! | `/progmo/tf` (tree scenes) | `foxglove.FrameTransform` | world -> `progmo/<body>` per body per sample ([`McapSink::with_bodies`], [`McapSink::frame_transform`]) |
//! | `/progmo/scene` (tree scenes) | `foxglove.SceneUpdate` | at the first sample: the mechanism's geometry on the body frames (bodies' `shape` or inertia boxes, joint axes, links) and the scene's `[[view.targets]]` in the world frame ([`Bodies::scene_update`]); at the last sample: the realized trace of each site the programme rows read, entity `progmo/trace/<site>` ([`Bodies::trace_update`]) |
//! | `/progmo/warning`   | `progmo.Warning`    | `{"t", "kind", "rows": [row names], "value", "threshold", "message"}`: one per conditioning warning, at its first crossing; only when there is one |
//!
//! One message per sample on each of the first three (four) channels. In Foxglove, plot e.g.
//! `/progmo/state.q.theta` or `/progmo/residual.residual.speed`. Further channels can be added
//! with [`McapSink::add_json_channel`].
//!
//! # JSON summary ([`write_summary`])
//!
//! One JSON object (pretty-printed, trailing newline). Non-finite numbers are written as `null`.
//! Fields:
//!
//! - `format`: `"progmo.summary"`; `format_version`: `1` (bumped on incompatible changes; fields
//!   may be added without a bump).
//! - `scene`: scene name given by the caller.
//! - `success`: `true` iff the code is `success`.
//! - `code`: the [`ReturnCode`](crate::solve::ReturnCode) as an object: `"code"` holds its machine
//!   name (as in `code_name`), the other keys its fields, e.g.
//!   `{"code": "drift_exceeded", "t": 1.5, "row": "speed", "residual": 2e-6}`. Per code:
//!   `success` {}; `step_too_small` {`t`, `h`}; `singular_programme` {`t`, `rows` (array of row
//!   names), `rcond`}; `singular_system` {`t`, `rcond`}; `drift_exceeded` {`t`, `row`,
//!   `residual`}; `non_finite` {`t`}; `max_steps` {`t`}; `inconsistent_initial_state` {`row`,
//!   `residual`}; `projection_failed` {`t`, `row`, `residual`}; `ill_conditioned` {`t`,
//!   `warning` (as in `warnings`)}; `interrupted` {`t`} (Ctrl-C or SIGTERM, or a sink's stop
//!   request); `too_many_steps` {`t`, `needed` (estimated steps for the span), `max_steps`}.
//! - `code_name`: the machine name, one of the codes above.
//! - `message`: the code as one sentence naming the quantity, the time and the rows.
//! - `t_end`: last time reached. On an early stop it is the code's `t` and the time of the last
//!   CSV/MCAP sample (the last accepted state the solve stands behind).
//! - `warnings`: array of conditioning warnings ([`Warning`](crate::solve::Warning); thresholds
//!   [`Conditioning`](crate::solve::Conditioning)), each `{"kind": "row_gradient" |
//!   "singular_value" | "u_cancellation" | "global_error", "t" (first crossing), "rows", "value",
//!   "worst", "t_worst", "threshold", "message"}`; empty when the programme stayed well
//!   conditioned. A `row_gradient` of a fixed-step solve with its Richardson companion also has
//!   `error_before` and `error_after`: the companion's estimate of the velocities' relative error
//!   (max |dv| / max |v| per sample) over the samples before `t` and after `t_worst`.
//!   `global_error`: the fixed-step estimate below is over its budget (`value`, `worst`: `scaled`;
//!   `threshold`: `budget`; `rows` empty).
//! - `global_error` (fixed-step solves only: `rk4`, or `fixed_step`, unless `--richardson=false`):
//!   the Richardson estimate of the global error ([`GlobalError`](crate::solve::GlobalError)):
//!   a companion solve at twice the step, compared at the output samples both runs have:
//!   `{"method": "richardson", "step", "companion_step", "order" (p), "estimate" (max over
//!   samples and q, v components of |y_2h - y_h| / (2^p - 1)), "scaled" (the same divided by
//!   atol + rtol |y_h| per component), "t_worst", "component" (name of the q or v entry),
//!   "budget" (1: `scaled` above it warns, and with `strict` the code is `ill_conditioned`),
//!   "samples" (compared), "companion_code", "companion_t_end", "companion" (its integrator
//!   counters: its cost, about half the solve's)}`. Absent for adaptive solves.
//! - `max_residual`: largest |residual| over all rows and accepted steps (0 when there is no row).
//! - `max_residual_rate`: largest |dg/dt| over all position rows and accepted steps.
//! - `rows`: array, one object per constraint row in solver order:
//!   `{"name", "max_residual", "max_residual_rate"}`.
//! - `statistics`: the [`Statistics`](crate::solve::Statistics) as serialized by serde (fields
//!   `integrator` {`steps`, `rejected`, `rhs_evals`, `jacobian_evals`, `lu_decompositions`,
//!   `newton_iterations`}, `factorizations`, `projections`,
//!   `projection_iterations`, `max_position_correction`, `max_velocity_correction`, `max_du`,
//!   `min_b_rcond`, `min_row_gradient_ratio`, `min_singular_value_ratio`, `max_u_cancellation`).
//! - `initial_correction`: `null`, or `{"position", "velocity"}` when the initial state was
//!   assembled.
//! - `settings`: the [`Settings`](crate::solve::Settings) as serialized by serde, e.g. the
//!   default: `{"formulation": "auto", "integrator": "dop853", "rtol": 1e-10,
//!   "atol": 1e-12, "max_step": null, "max_steps": 10000000, "drift": {"kind": "projection",
//!   "tol": 1e-12, "max_iter": 8}, "rank_dependent": 1e-10, "rank_vanishing": 1e-12,
//!   "output": "steps", "max_drift": null, "consistency_tol": 1e-10, "assemble": false,
//!   "conditioning": {"row_gradient": 0.001, "singular_value": 0.001, "u_cancellation": 1e8},
//!   "strict": false, "richardson": true}`
//!   (`max_step: null` is the unlimited default; `output` is `"steps"` or `{"every": dt}`).
//! - `wall_seconds`: wall-clock duration of the run, as measured by the caller.
//! - `versions`: `{"progmo": crate version, "git_revision": string or null}`.
//! - `command_line`: array of strings, the arguments to rerun (program first).
//! - `servo` (only for scenes with `[[actuators]]` whose programme is realizable at t0;
//!   written by `progmo solve` and by Python's `Solution.write_summary`): the
//!   `crate::scene::ServoReport`: `degrees`, `index`, `realization`, `rcond`, `b_norms` at t0 and
//!   `internal` {`dimension` (2n - sum r_i), `eigenvalues_t0` [{`re`, `im`}], `along` (null, or
//!   {`samples`, `max_real`, `t_max_real`, `eigenvalues_at_max`, `min_max_real`}), `growth` (null,
//!   or {`initial_separation`, `final_separation`, `max_separation`, `rate`, `t_end`}),
//!   `stability` (`"stable"`, `"unstable"`, `"marginal"` or null), `horizon` (s, or null)}.
//! - `robot_file` (only for `urdf` and `mjcf` scenes; written by `progmo solve` and by Python's
//!   `Solution.write_summary`): the `crate::scene::RobotFile`: `kind` (`"urdf"`/`"mjcf"`),
//!   `path` (absolute), `locked` [[joint, q value]], `ranges` [{`joint`, `lower`, `upper`}] (q's
//!   units), `unmodelled` [{`kind` (the closed vocabulary `crate::import::unmodelled::KINDS`),
//!   `element`, `location` ("file:line"), `declared` (the scene's reason from `[model] ignore`, or
//!   null: undeclared)}]. `progmo validate` prints the same entries (and `--json` gives this object
//!   as `robot_file`, with the import `notes`).

mod csv_sink;
#[cfg(test)]
mod e2e;
mod error;
mod mcap_sink;
mod progress;
mod scene3d;
mod sinks;
mod staged;
mod summary;

pub use csv_sink::{read_csv, read_csv_from, CsvSink};
pub use error::OutputError;
pub use mcap_sink::recording_schemas;
pub use mcap_sink::{McapChannel, McapSink, FRAME_TRANSFORM_SCHEMA, FRAME_TRANSFORM_TOPIC};
pub use progress::Progress;
pub use scene3d::{
    scene_update_schema, Bodies, BodyPose, Geometry, Shape, Target, TracedSite, View, ViewTarget,
    SHAPE_COLOR, TARGET_COLOR,
};
pub use sinks::{Bounded, Every, StopOn, Tee};
pub use staged::{
    remove_previous_run, with_suffix, writable_destination, RunFiles, Staged, PARTIAL_SUFFIX,
    RUN_FILES,
};
pub use summary::{summary_json, write_summary, write_summary_to_path, SummaryInput};

use crate::model::Model;
use crate::programme::{Constraints, Role, RowSpec};
use crate::solve::{Problem, SampleSink, Trajectory};

/// A sink whose output must be completed: `finish` flushes everything (and for wrappers, finishes
/// the wrapped sinks) and returns the first error met since creation.
pub trait OutputSink: SampleSink {
    /// Flush and complete the output. Calling it again is harmless.
    fn finish(&mut self) -> Result<(), OutputError>;
}

impl OutputSink for Trajectory {
    fn finish(&mut self) -> Result<(), OutputError> {
        Ok(())
    }
}

/// Write a solved trajectory (and its warnings, each before the first sample at or after its time)
/// into `sink`, as the solver would have streamed it: the outputs of a solve kept in memory (the
/// Python `Solution.write_csv` / `write_mcap`) come from the same writers as `progmo solve`'s.
pub fn replay(
    traj: &Trajectory,
    warnings: &[crate::solve::Warning],
    sink: &mut dyn OutputSink,
) -> Result<(), OutputError> {
    let mut pending = warnings.iter().peekable();
    for k in 0..traj.len() {
        let s = traj.sample(k);
        while let Some(w) = pending.next_if(|w| w.t <= s.t) {
            sink.warning(w);
        }
        sink.sample(&s);
    }
    pending.for_each(|w| sink.warning(w));
    sink.finish()
}

/// Names of the sampled quantities, and whether reactions are written.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SampleLayout {
    /// Names of q.
    pub q_names: Vec<String>,
    /// Names of v (also of dv/dt, u and reactions).
    pub v_names: Vec<String>,
    /// Names of the constraint rows (lambda, residuals).
    pub row_names: Vec<String>,
    /// Write the reactions of system constraints.
    pub reactions: bool,
}

impl SampleLayout {
    /// Names of q, v and of the rows; `reactions` is true iff some row is a system constraint.
    pub fn new(q_names: Vec<String>, v_names: Vec<String>, rows: &[RowSpec]) -> Self {
        SampleLayout {
            q_names,
            v_names,
            row_names: rows.iter().map(|r| r.name.clone()).collect(),
            reactions: rows.iter().any(|r| r.role == Role::System),
        }
    }

    /// Names from a problem; `reactions` is true iff it has system-constraint rows.
    pub fn from_problem<M: Model, C: Constraints>(problem: &Problem<M, C>) -> Self {
        Self::new(
            problem.model.q_names(),
            problem.model.v_names(),
            problem.constraints.rows(),
        )
    }

    /// Names of a trajectory; `reactions` is true iff some reaction is non-zero.
    pub fn from_trajectory(traj: &Trajectory) -> Self {
        SampleLayout {
            q_names: traj.q_names.clone(),
            v_names: traj.v_names.clone(),
            row_names: traj.row_names.clone(),
            reactions: traj.reactions.iter().any(|&r| r != 0.0),
        }
    }

    /// Set whether reactions are written.
    pub fn with_reactions(mut self, reactions: bool) -> Self {
        self.reactions = reactions;
        self
    }

    /// An empty trajectory with these names.
    pub fn trajectory(&self) -> Trajectory {
        Trajectory {
            q_names: self.q_names.clone(),
            v_names: self.v_names.clone(),
            row_names: self.row_names.clone(),
            ..Default::default()
        }
    }

    /// Check the lengths of a sample against the names.
    pub(crate) fn check(&self, s: &crate::solve::Sample<'_>) -> Result<(), String> {
        let nv = self.v_names.len();
        let ns = self.row_names.len();
        let checks: [(&str, usize, usize); 8] = [
            ("q", s.q.len(), self.q_names.len()),
            ("v", s.v.len(), nv),
            ("a", s.a.len(), nv),
            ("u", s.u.len(), nv),
            ("lambda", s.lambda.len(), ns),
            ("residual", s.residual.len(), ns),
            ("residual_rate", s.residual_rate.len(), ns),
            (
                "reactions",
                s.reactions.len(),
                if self.reactions {
                    nv
                } else {
                    s.reactions.len()
                },
            ),
        ];
        for (what, got, want) in checks {
            if got != want {
                return Err(format!(
                    "sample at t = {:e}: {what} has {got} values, the layout names {want}",
                    s.t
                ));
            }
        }
        Ok(())
    }
}

/// A sample with owned storage (kept by [`Every`] for the last sample).
#[derive(Clone, Debug, Default)]
pub(crate) struct OwnedSample {
    t: f64,
    q: Vec<f64>,
    v: Vec<f64>,
    a: Vec<f64>,
    u: Vec<f64>,
    reactions: Vec<f64>,
    lambda: Vec<f64>,
    residual: Vec<f64>,
    residual_rate: Vec<f64>,
}

impl OwnedSample {
    pub(crate) fn set(&mut self, s: &crate::solve::Sample<'_>) {
        fn copy(dst: &mut Vec<f64>, src: &[f64]) {
            dst.clear();
            dst.extend_from_slice(src);
        }
        self.t = s.t;
        copy(&mut self.q, s.q);
        copy(&mut self.v, s.v);
        copy(&mut self.a, s.a);
        copy(&mut self.u, s.u);
        copy(&mut self.reactions, s.reactions);
        copy(&mut self.lambda, s.lambda);
        copy(&mut self.residual, s.residual);
        copy(&mut self.residual_rate, s.residual_rate);
    }

    pub(crate) fn as_sample(&self) -> crate::solve::Sample<'_> {
        crate::solve::Sample {
            t: self.t,
            q: &self.q,
            v: &self.v,
            a: &self.a,
            u: &self.u,
            reactions: &self.reactions,
            lambda: &self.lambda,
            residual: &self.residual,
            residual_rate: &self.residual_rate,
        }
    }
}

#[cfg(test)]
pub(crate) mod testutil {
    use super::SampleLayout;
    use crate::solve::{Sample, SampleSink};

    /// A layout with awkward names (a comma, a quote, a colon) and reactions.
    pub fn layout() -> SampleLayout {
        SampleLayout {
            q_names: vec!["x".into(), "th,eta".into()],
            v_names: vec!["vx".into(), "w\"z".into()],
            row_names: vec!["speed".into(), "pos:1".into(), "sys".into()],
            reactions: true,
        }
    }

    /// Feed `n` samples with values that exercise full precision, at times `k * dt`.
    pub fn feed(sink: &mut dyn SampleSink, layout: &SampleLayout, n: usize, dt: f64) {
        for k in 0..n {
            let o = sample_values(layout, k);
            let t = k as f64 * dt;
            sink.sample(&Sample {
                t,
                q: &o[0],
                v: &o[1],
                a: &o[2],
                u: &o[3],
                reactions: &o[4],
                lambda: &o[5],
                residual: &o[6],
                residual_rate: &o[7],
            });
        }
    }

    /// Values of sample k: q, v, a, u, reactions, lambda, residual, residual_rate.
    pub fn sample_values(layout: &SampleLayout, k: usize) -> [Vec<f64>; 8] {
        let nq = layout.q_names.len();
        let nv = layout.v_names.len();
        let ns = layout.row_names.len();
        let f = |g: usize, i: usize| -> f64 {
            let x = (k * 31 + g * 7 + i + 1) as f64;
            match (g + i + k) % 5 {
                0 => 1.0 / 3.0 * x,
                1 => -x.sqrt() * 1e-300,
                2 => x.sin() * 1e17,
                3 => -0.0,
                _ => std::f64::consts::PI / x,
            }
        };
        let v = |g: usize, n: usize| (0..n).map(|i| f(g, i)).collect::<Vec<_>>();
        [
            v(0, nq),
            v(1, nv),
            v(2, nv),
            v(3, nv),
            v(4, nv),
            v(5, ns),
            v(6, ns),
            v(7, ns),
        ]
    }
}
