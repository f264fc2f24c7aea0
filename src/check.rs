//! The vocabulary of the cross-simulator check (`progmo check`, `harness/progmo/checks.py`):
//! every metric it judges, with the name its budget has in a scene's `[tolerances]`, the checks
//! that judge it, its default budget and the reason; the replay options of `[tolerances]`; the
//! simulators of `[checks] not_checked`.
//!
//! One definition, read by every door: the scene loader refuses a `[tolerances]` or
//! `[checks] not_checked` name outside it (located, with the nearest valid name), the scene schema
//! lists the same names, the binding hands the table to Python (`checks.default_budgets` and
//! `checks.budgets_for` read it), and FORMAT.md's "Default budgets" table is generated from it
//! (`tests/schema.rs` keeps the page in step).

use crate::solve::{DriftControl, DEFAULT_PROJECTION_TOL};

/// Relative tolerance of the check's reference solve: tighter than a scene's own, so that the
/// replay measures the simulator and the per-stage feed of u, not the solver's tolerance.
pub const REFERENCE_RTOL: f64 = 1e-12;
/// Absolute tolerance of the check's reference solve.
pub const REFERENCE_ATOL: f64 = 1e-14;

/// Simulators of the cross-simulator check (keys of `[checks] not_checked`).
pub const SIMULATORS: [&str; 3] = ["mujoco", "pinocchio", "drake"];
/// The checker of a scene no simulator document describes: a second formulation and the scene's
/// reference values instead of a replay.
pub const SOLVER_ONLY: &str = "solver_only";

/// When a check judges a metric.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum When {
    /// Never (the metric belongs to the other kind of check).
    Never,
    /// On every scene.
    Always,
    /// On scenes with loop closures (`[[model.closures]]`).
    Closures,
    /// On scenes with `[[actuators]]`.
    Actuators,
    /// On scenes with `[[reference]]` values.
    References,
    /// On scenes whose model is a robot file (`urdf`, `mjcf`): the simulators read that file.
    RobotFile,
}

impl When {
    /// The name the binding gives Python.
    pub fn name(self) -> &'static str {
        match self {
            When::Never => "never",
            When::Always => "always",
            When::Closures => "closures",
            When::Actuators => "actuators",
            When::References => "references",
            When::RobotFile => "robot_file",
        }
    }
}

/// How a metric's default budget is set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rule {
    /// A fixed value.
    Fixed(f64),
    /// The row residual of the reference solve: 100 x `projection_tol` with projection, else
    /// 1e4 x [`REFERENCE_RTOL`] (rows drift with the integration error).
    DriftResidual,
}

/// One judged metric.
#[derive(Clone, Copy, Debug)]
pub struct Metric {
    /// The metric's name in results, baselines and reports.
    pub name: &'static str,
    /// The name of its budget in a scene's `[tolerances]` (`programme_residual` judges
    /// `solver_residual`).
    pub table: &'static str,
    /// When a simulator check (mujoco, pinocchio) judges it.
    pub simulators: When,
    /// When the solver_only check judges it.
    pub solver_only: When,
    /// Its default budget.
    pub rule: Rule,
    /// The tolerance class (ARCHITECTURE.md: algebraic identity, integrated, cross-simulator).
    pub class: &'static str,
    /// Why the default is what it is (report and FORMAT.md).
    pub reason: &'static str,
}

/// Every metric the check judges, in the order budgets are listed.
pub const METRICS: [Metric; 13] = [
    Metric {
        name: "solver_residual",
        table: "programme_residual",
        simulators: When::Always,
        solver_only: When::Always,
        rule: Rule::DriftResidual,
        class: "integrated",
        reason: "projection holds every state row to `projection_tol` after each step (x100 for \
                 samples between steps and acceleration rows solved to round-off); without \
                 projection the rows drift with the integration error of the reference solve \
                 (rtol 1e-12; 1e4 x rtol)",
    },
    Metric {
        name: "parity_mass",
        table: "parity_mass",
        simulators: When::Always,
        solver_only: When::Never,
        rule: Rule::Fixed(1e-11),
        class: "algebraic identity",
        reason: "the exported mass matrix against our A, relative to max|A|: round-off (catalog \
                 <= 2e-15) plus MuJoCo's 1e-14 inertia floor",
    },
    Metric {
        name: "parity_bias",
        table: "parity_bias",
        simulators: When::Always,
        solver_only: When::Never,
        rule: Rule::Fixed(1e-11),
        class: "algebraic identity",
        reason: "every non-control force the simulator applies against our G + Q, relative to \
                 max|G + Q|: round-off (catalog <= 3e-15)",
    },
    Metric {
        name: "instant_u",
        table: "instant_u",
        simulators: When::Always,
        solver_only: When::Never,
        rule: Rule::Fixed(1e-9),
        class: "algebraic, through a constraint solve",
        reason: "u from the simulator's own constrained/inverse dynamics against ours, relative \
                 to max|u| (to max|G + Q| without a programme); catalog <= 2e-14, room for the \
                 condition of B. With loop closures the simulator's inverse-dynamics force is \
                 split over its own closure Jacobian and our programme rows (least squares), \
                 u = B_p^T lambda_p",
    },
    Metric {
        name: "replay_residual",
        table: "replay_residual",
        simulators: When::Always,
        solver_only: When::Never,
        rule: Rule::Fixed(1e-6),
        class: "cross-simulator",
        reason: "programme rows on the open-loop replay at the convergence-checked RK4 step \
                 (catalog 5e-14 .. 6e-9); an unstable programme is replayed in segments and may \
                 need its own budget",
    },
    Metric {
        name: "replay_deviation",
        table: "replay_deviation",
        simulators: When::Always,
        solver_only: When::Never,
        rule: Rule::Fixed(1e-6),
        class: "cross-simulator",
        reason: "max |dq|, |dv| of the replay from the solver (catalog 4e-13 .. 2e-9); an \
                 unstable programme is replayed in segments and may need its own budget",
    },
    Metric {
        name: "parity_closure",
        table: "parity_closure",
        simulators: When::Closures,
        solver_only: When::Never,
        rule: Rule::Fixed(1e-11),
        class: "algebraic identity",
        reason: "the simulator's closure Jacobian (MuJoCo efc_J of the equalities, Pinocchio \
                 getConstraintsJacobian) against our closure rows (set-aside rows excluded), both \
                 ways, as the largest relative distance of a row from the other's row space \
                 (free of frame, sign and row scaling; catalog <= 2e-15; a closure point 1 mm \
                 off: 1.1e-4 .. 1e-3). Gates the replay like parity_mass and parity_bias",
    },
    Metric {
        name: "reaction_closure",
        table: "reaction_closure",
        simulators: When::Closures,
        solver_only: When::Never,
        rule: Rule::Fixed(1e-9),
        class: "algebraic, through a constraint solve",
        reason: "the closures' generalized reaction J^T f from the simulator's own multipliers \
                 under the solver's u (Pinocchio constraintDynamics contact forces, MuJoCo \
                 efc_force of the equalities) against ours B_c^T lambda_c, relative to its max \
                 (Pinocchio catalog <= 1e-15; MuJoCo's soft equalities give about \
                 1 - solimp = 1e-4 and need a scene budget)",
    },
    Metric {
        name: "replay_unactuated",
        table: "replay_unactuated",
        simulators: When::Actuators,
        solver_only: When::Never,
        rule: Rule::Fixed(1e-14),
        class: "algebraic identity",
        reason: "the part of the replayed force outside range(H), relative to max|u|: u = H tau \
                 has exact zeros on joints no actuator drives (catalog 0; along a direction: \
                 round-off of the projection, ~1e-16; 1e-6 N added on two_car_chain's spring \
                 joint: 1.8e-6, tests/python/test_servo.py)",
    },
    Metric {
        name: "inverse_dynamics",
        table: "inverse_dynamics",
        simulators: When::RobotFile,
        solver_only: When::Never,
        rule: Rule::Fixed(1e-10),
        class: "algebraic identity",
        reason: "u from the simulator's inverse dynamics of the user's robot file itself (MuJoCo \
                 mj_inverse: M with armature, bias, minus passive forces; Pinocchio rnea with its \
                 armature, minus the file's passive forces) at the solver's (t, q, v, dv/dt) along \
                 the trajectory, against the solver's u, relative to max|u| (catalog <= 2e-14; \
                 mjcf_arm before progmo modelled joint damping: 3.5e-2, worst joint yaw); gates \
                 the replay like parity_mass and parity_bias",
    },
    Metric {
        name: "formulation_deviation",
        table: "formulation_deviation",
        simulators: When::Never,
        solver_only: When::Always,
        rule: Rule::Fixed(1e-8),
        class: "integrated",
        reason: "max |dq|, |dv| between two formulations solved at rtol 1e-12: both carry the \
                 integration error (about 1e4 x rtol for non-stiff scenes) and the conditioning \
                 of B",
    },
    Metric {
        name: "formulation_force_deviation",
        table: "formulation_force_deviation",
        simulators: When::Never,
        solver_only: When::Always,
        rule: Rule::Fixed(1e-8),
        class: "integrated",
        reason: "u and the system reactions of two formulations, relative to their largest \
                 value: the state difference propagated through A, G and the multipliers",
    },
    Metric {
        name: "reference_error",
        table: "reference_error",
        simulators: When::Never,
        solver_only: When::References,
        rule: Rule::Fixed(1e-8),
        class: "integrated",
        reason: "the reference solve (rtol 1e-12) against values of independent origin, \
                 max |x - x_ref| / max(1, |x_ref|): the global error of a tight solve; published \
                 values need the scene's own budget (their digits)",
    },
];

/// Options of the check that are not budgets, in the scene's `[checks]` table: (name, meaning).
pub const OPTIONS: [(&str, &str); 1] = [(
    "replay_step",
    "fixed RK4 step of the open-loop replay (s); else a convergence check picks it",
)];

/// Entries of `[tolerances]` the check no longer reads, refused with the reason: (name, why).
pub const RETIRED: [(&str, &str); 2] = [
    (
        "replay_horizon",
        "the segmented replay covers the whole span (segments restart from the solver's state; \
         their length follows from the dynamics' growth measured in the simulator); remove the \
         entry",
    ),
    (
        "replay_step",
        "it is an option of the check, not a budget: move it to the `[checks]` table \
         (`[checks] replay_step = { value = ..., reason = \"...\" }`)",
    ),
];

/// The metric of this name.
pub fn metric(name: &str) -> Option<&'static Metric> {
    METRICS.iter().find(|m| m.name == name)
}

/// The metrics a check judges, in [`METRICS`] order: `checker` is a simulator or
/// [`SOLVER_ONLY`]; the scene's loop closures, actuators and reference values add theirs.
pub fn metrics_for(
    checker: &str,
    closures: bool,
    actuators: bool,
    references: bool,
    robot_file: bool,
) -> Vec<&'static Metric> {
    let judged = |w: When| match w {
        When::Never => false,
        When::Always => true,
        When::Closures => closures,
        When::Actuators => actuators,
        When::References => references,
        When::RobotFile => robot_file,
    };
    METRICS
        .iter()
        .filter(|m| {
            if checker == SOLVER_ONLY {
                judged(m.solver_only)
            } else {
                judged(m.simulators)
            }
        })
        .collect()
}

impl Metric {
    /// The `[tolerances]` names of its budget: the table name, and per checker that judges it
    /// `<table>_<checker>` (which takes precedence in that checker).
    pub fn table_keys(&self) -> Vec<String> {
        let mut keys = vec![self.table.to_string()];
        if self.simulators != When::Never {
            keys.extend(SIMULATORS.iter().map(|s| format!("{}_{s}", self.table)));
        }
        if self.solver_only != When::Never {
            keys.push(format!("{}_{SOLVER_ONLY}", self.table));
        }
        keys
    }

    /// The default budget under the scene's drift control, with its reason (marked `default`).
    pub fn default_budget(&self, drift: &DriftControl) -> (f64, String) {
        match (self.rule, drift) {
            (Rule::Fixed(v), _) => (v, format!("default ({}): {}", self.class, self.reason)),
            (Rule::DriftResidual, DriftControl::Projection { tol, .. }) => (
                100.0 * tol,
                format!(
                    "default ({}): 100 x projection_tol ({}): the projection holds every state \
                     row to projection_tol after each step; x100 for samples between steps and \
                     acceleration rows solved to round-off",
                    self.class,
                    fmt_g(*tol)
                ),
            ),
            (Rule::DriftResidual, other) => (
                1e4 * REFERENCE_RTOL,
                format!(
                    "default ({}): drift control {}: rows drift with the integration error of \
                     the reference solve (rtol {}); 1e4 x rtol",
                    self.class,
                    other.name(),
                    fmt_g(REFERENCE_RTOL)
                ),
            ),
        }
    }
}

/// Every name a scene's `[tolerances]` may hold: the budgets' [`Metric::table_keys`].
pub fn tolerance_keys() -> Vec<String> {
    METRICS.iter().flat_map(|m| m.table_keys()).collect()
}

pub use crate::located::{did_you_mean, nearest};

/// A number as Python's `{:g}` would print the catalog's values (1e-10, 0.5).
fn fmt_g(x: f64) -> String {
    if x != 0.0 && (x.abs() < 1e-4 || x.abs() >= 1e6) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// FORMAT.md's "Default budgets" table (markdown), generated from [`METRICS`].
pub fn default_budget_table() -> String {
    let mut s = String::from("| metric | default | why |\n|--------|---------|-----|\n");
    for m in &METRICS {
        let mut notes = vec![];
        if m.table != m.name {
            notes.push(format!("budget `{}`", m.table));
        }
        match (m.simulators, m.solver_only) {
            (When::Closures, _) => notes.push("scenes with `[[model.closures]]`".into()),
            (When::Actuators, _) => notes.push("scenes with `[[actuators]]`".into()),
            (When::RobotFile, _) => notes.push("`urdf` and `mjcf` scenes".into()),
            (When::Never, When::References) => {
                notes.push("solver_only, scenes with `[[reference]]`".into())
            }
            (When::Never, _) => notes.push("solver_only".into()),
            _ => {}
        }
        let name = if notes.is_empty() {
            format!("`{}`", m.name)
        } else {
            format!("`{}` ({})", m.name, notes.join("; "))
        };
        let default = match m.rule {
            Rule::Fixed(v) => fmt_g(v),
            Rule::DriftResidual => format!(
                "100 × `projection_tol` with `drift = \"projection\"` ({} by default); else {}",
                fmt_g(100.0 * DEFAULT_PROJECTION_TOL),
                fmt_g(1e4 * REFERENCE_RTOL)
            ),
        };
        let why = format!("{}: {}", m.class, m.reason).replace('|', "\\|");
        s.push_str(&format!("| {name} | {default} | {why} |\n"));
    }
    s
}
