//! Scenes: a system, its programme and what to check, described in a TOML file.
//!
//! [`Scene::load`] parses and validates a file (format: `FORMAT.md` beside this file; JSON Schema:
//! `scene.schema.json`) into a [`Problem`] over one of two kinds of model — model only what the
//! scene needs:
//! - `lagrangian`: named coordinates, A(q) and forces (or a potential) as expressions
//!   ([`lagrangian::LagrangianModel`]);
//! - `tree`: bodies and joints ([`tree_model::TreeSceneModel`], CRBA/RNEA of `crate::tree`).
//!
//! Every error names the file, line, column and field ([`SceneError`]).

mod actuators;
pub mod chain;
pub mod closures;
mod error;
mod export;
pub mod file;
pub mod lagrangian;
pub mod layout;
mod load;
mod reference;
pub mod rows;
pub mod schema;
mod servo_report;
pub mod signals;
pub mod tree_model;
mod view;

pub use error::{SceneError, Source};
pub use reference::ReferenceValue;
pub use servo_report::{ServoReport, LINEARIZATION_SAMPLES, PERTURBATION};

use crate::solve::{self, Problem, SampleSink, Settings, Solution};
use lagrangian::LagrangianModel;
use rows::ExprConstraints;
use std::path::{Path, PathBuf};
use tree_model::TreeSceneModel;

/// A check tolerance of the scene, with the reason for its value.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Tolerance {
    pub name: String,
    pub value: f64,
    pub reason: String,
}

/// The problem of a scene, by model kind.
#[derive(Clone, Debug)]
pub enum SceneSystem {
    /// A Lagrangian model.
    Lagrangian(Problem<LagrangianModel, ExprConstraints>),
    /// A kinematic tree.
    Tree(Problem<TreeSceneModel, ExprConstraints>),
}

/// Run `$body` with `$p` bound to the scene's `Problem`, whatever its model kind.
#[macro_export]
macro_rules! with_problem {
    ($system:expr, $p:ident => $body:expr) => {
        match $system {
            $crate::scene::SceneSystem::Lagrangian($p) => $body,
            $crate::scene::SceneSystem::Tree($p) => $body,
        }
    };
}

/// A loaded, validated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Scene name (unique in a catalog).
    pub name: String,
    /// What it is.
    pub description: String,
    /// Why it is in the catalog.
    pub purpose: String,
    /// The file it came from.
    pub path: PathBuf,
    /// Parameters after evaluation, in file order.
    pub parameters: Vec<(String, f64)>,
    /// The problem.
    pub system: SceneSystem,
    /// Solver settings of the scene (defaults where the file is silent).
    pub settings: Settings,
    /// Check tolerances with their reasons.
    pub tolerances: Vec<Tolerance>,
    /// `[checks] replay_step`: the check's fixed replay step with its reason (else a convergence
    /// check picks it).
    pub replay_step: Option<Tolerance>,
    /// `[checks] not_checked`: (simulator, reason) pairs the check expects not to run.
    pub expected_not_checked: Vec<(String, String)>,
    /// `[[reference]]`: values of independent origin at given times, one per quantity.
    pub references: Vec<ReferenceValue>,
    /// The file's text, for locating later errors.
    pub source: Source,
    /// Byte span of each row's expression in the file (row order of the constraints).
    pub row_spans: Vec<std::ops::Range<usize>>,
    /// Loop closures of a tree scene (`[[model.closures]]`), for the exporters.
    pub closures: Vec<closures::Closure>,
    /// Closure rows set aside as dependent at t0 (with why), and those rows, for monitoring.
    pub set_aside: Option<(Vec<closures::SetAside>, ExprConstraints)>,
    /// What 3D views draw besides the mechanism: body shapes, targets, traced sites.
    pub view: std::sync::Arc<crate::output::View>,
    /// Remarks on how an imported robot file was read (e.g. MJCF gravity replaced by the
    /// scene's), one line each; shown by `progmo solve` (stderr) and `progmo validate`.
    pub import_notes: Vec<String>,
    /// The robot file of a `urdf` or `mjcf` scene and what it holds that is not modelled (None
    /// for other models).
    pub robot: Option<RobotFile>,
}

/// The robot file of a `urdf`/`mjcf` scene ([`crate::import`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RobotFile {
    /// `urdf` or `mjcf`.
    pub kind: String,
    /// The file, resolved (package:// through the robot path) and absolute.
    pub path: PathBuf,
    /// `model.locked_joints` with the value of q each is welded at (URDF 0, MJCF the joint's
    /// `ref`).
    pub locked: Vec<(String, f64)>,
    /// Position limits the file states for the modelled hinge and slide joints (q's units).
    pub ranges: Vec<crate::import::unmodelled::JointRange>,
    /// Every element read and not modelled, in file order, with the scene's declaration.
    pub unmodelled: Vec<UnmodelledEntry>,
    /// The MJCF file's named keyframes (`[initial] keyframe`); empty for a URDF.
    #[serde(skip)]
    pub keyframes: Vec<crate::import::mjcf::Keyframe>,
    /// Where each body's mass properties are written in the file ([`crate::import::urdf::Robot::body_at`]).
    #[serde(skip)]
    pub body_at: Vec<(String, crate::located::SceneError)>,
    /// The URDF's `<mimic>` couplings of moving joints, each a system row `mimic_JOINT` (none
    /// when the scene declares `mimic` ignored: the joints are then independent).
    pub mimics: Vec<crate::import::urdf::Mimic>,
}

/// One element of the robot file that is not modelled, and whether the scene declares its kind
/// ignorable (`[model] ignore`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct UnmodelledEntry {
    /// A kind of [`crate::import::unmodelled::KINDS`].
    pub kind: String,
    /// The element, e.g. `joint[elbow].frictionloss`.
    pub element: String,
    /// `file:line` (the file absolute).
    pub location: String,
    /// The scene's reason for ignoring this kind, or None (undeclared).
    pub declared: Option<String>,
}

impl RobotFile {
    /// The entries whose kind the scene does not declare.
    pub fn undeclared(&self) -> impl Iterator<Item = &UnmodelledEntry> {
        self.unmodelled.iter().filter(|u| u.declared.is_none())
    }
}

impl Scene {
    /// Load and validate a scene file, read through [`crate::input`]: a regular file of at most
    /// [`crate::input::SCENE_LIMIT`] bytes, UTF-8 text (otherwise refused at line and column,
    /// without quoting it).
    pub fn load(path: impl AsRef<Path>) -> Result<Scene, SceneError> {
        let path = path.as_ref();
        let bytes = crate::input::read(path, crate::input::SCENE_LIMIT)
            .map_err(|e| error::io_error(path, e))?;
        let text = crate::input::text(bytes).map_err(|e| error::not_text(path, e))?;
        Scene::from_text(path, &text)
    }

    /// Load from text (`path` names the file in messages; files the scene names are found from
    /// its folder). A text whose first line is neither a table header nor `key = value` is not a
    /// scene: refused at that line, which is not quoted.
    pub fn from_text(path: &Path, text: &str) -> Result<Scene, SceneError> {
        if let Some(line) = crate::input::toml_start(text) {
            return Err(SceneError {
                file: path.to_path_buf(),
                line,
                column: 1,
                field: String::new(),
                message: format!(
                    "not a TOML scene: line {line} is neither a `[table]` header nor a `key = value`"
                ),
                excerpt: String::new(),
            });
        }
        load::load(Source::new(path.to_path_buf(), text.to_string()))
    }

    /// The mechanism's body frames and geometry for 3D views of recordings (tree scenes; None for
    /// a lagrangian scene, which has no bodies).
    pub fn bodies(&self) -> Option<crate::output::Bodies> {
        match &self.system {
            SceneSystem::Tree(p) => Some(crate::output::Bodies::new(
                std::sync::Arc::clone(p.model.tree()),
                std::sync::Arc::clone(&self.view),
            )),
            SceneSystem::Lagrangian(_) => None,
        }
    }

    /// Names of q.
    pub fn q_names(&self) -> Vec<String> {
        use crate::model::Model;
        with_problem!(&self.system, p => p.model.q_names())
    }

    /// Names of v (and of u).
    pub fn v_names(&self) -> Vec<String> {
        use crate::model::Model;
        with_problem!(&self.system, p => p.model.v_names())
    }

    /// Constraint rows (system constraints and programme).
    pub fn rows(&self) -> Vec<crate::programme::RowSpec> {
        use crate::programme::Constraints;
        with_problem!(&self.system, p => p.constraints.rows().to_vec())
    }

    /// Time span.
    pub fn span(&self) -> (f64, f64) {
        with_problem!(&self.system, p => (p.t0, p.t1))
    }

    /// Solve with `settings`, keeping the trajectory in memory.
    pub fn solve(&self, settings: &Settings) -> Solution {
        with_problem!(&self.system, p => solve::solve(p, settings))
    }

    /// Solve with `settings`, streaming samples into `sink`.
    pub fn solve_into(&self, settings: &Settings, sink: &mut dyn SampleSink) -> Solution {
        with_problem!(&self.system, p => solve::solve_into(p, settings, sink))
    }

    /// An error located at a row's expression (e.g. a row violated at the initial state).
    pub fn row_error(&self, row: &str, message: impl Into<String>) -> SceneError {
        let rows = self.rows();
        match rows.iter().position(|r| r.name == row) {
            Some(i) => self
                .source
                .error(self.row_spans[i].clone(), &format!("row {row}"), message),
            None => self.source.general("", message),
        }
    }

    /// The initial state as the solver will start from it, or the located error every door reports
    /// (exit 2) when the solver refuses it: a row violated at t0, a singular programme at t0, ...
    /// `progmo solve`, `validate`, `check` and `debug` all go through here.
    pub fn check_initial(
        &self,
        settings: &Settings,
    ) -> Result<
        (
            crate::solve::Trajectory,
            Option<crate::solve::InitialCorrection>,
        ),
        SceneError,
    > {
        let r = with_problem!(&self.system, p => solve::check_initial(p, settings));
        r.map_err(|code| self.initial_error(&code, settings))
    }

    /// The located error for a return code that stopped a solve at its initial state.
    pub fn initial_error(&self, code: &solve::ReturnCode, settings: &Settings) -> SceneError {
        use solve::ReturnCode as R;
        match code {
            R::InconsistentInitialState { row, residual } => {
                let name = row.split(' ').next().unwrap_or(row);
                // A servo programme's hidden constraint: `row (d^k/dt^k, hidden constraint)`.
                let what = match row.find("(d^") {
                    Some(i) => format!(
                        "the derivative {} of this row (a hidden constraint of the servo \
                         programme: it must vanish for the actuators to hold the row)",
                        row[i + 1..].split(',').next().unwrap_or("")
                    ),
                    None => "this row".to_string(),
                };
                let how = if row.ends_with("(assembly failed)") {
                    "assembling the initial state (`assemble = true`) did not bring this row within"
                        .to_string()
                } else {
                    "set `assemble = true` in [initial] to project the state onto the rows, or make \
                     it consistent by hand; tolerance"
                        .to_string()
                };
                self.row_error(
                    name,
                    format!(
                        "the initial state violates {what} by {residual:.3e} ({how} {:.1e})",
                        settings.consistency_tol
                    ),
                )
            }
            R::SingularProgramme { rows, rcond, .. } => {
                let first = rows.first().cloned().unwrap_or_default();
                self.row_error(
                    &first,
                    format!(
                        "the programme Jacobian dg/dv is singular at the initial state: rows {} \
                         vanish or are dependent (rcond {rcond:.1e})",
                        solve::quoted(rows)
                    ),
                )
            }
            R::UnrealizableProgramme { rows, .. } => {
                let first = rows.first().cloned().unwrap_or_default();
                self.row_error(&first, format!("{code}"))
            }
            code => self.source.general(
                "initial",
                format!("the initial state cannot be used: {code}"),
            ),
        }
    }

    /// Residuals of the closure rows set aside at t0 (none: empty) at (t, q, v): they hold along
    /// the motion when they were truly dependent, so callers monitor them.
    pub fn set_aside_residuals(&self, t: f64, q: &[f64], v: &[f64]) -> Vec<(String, f64)> {
        use crate::programme::Constraints;
        let Some((_, rows)) = &self.set_aside else {
            return vec![];
        };
        let mut ws = rows.workspace::<f64>();
        let mut g = vec![0.0; rows.rows().len()];
        let zero = vec![0.0; v.len()];
        rows.eval(&mut ws, t, q, v, &zero, &mut g);
        rows.rows().iter().map(|r| r.name.clone()).zip(g).collect()
    }

    /// With `[[actuators]]`: the servo analysis at the initial state (relative degrees, index,
    /// realization), or the return code of a programme the actuators cannot realize there. None
    /// without actuators (the ideal realization).
    pub fn servo_analysis(&self) -> Option<Result<crate::servo::Analysis, solve::ReturnCode>> {
        use crate::programme::Constraints;
        let SceneSystem::Tree(p) = &self.system else {
            return None;
        };
        let act = p.constraints.actuation()?;
        let servo = crate::servo::Servo::new(&p.model, &p.constraints, act);
        Some(
            servo
                .analyse(p.t0, &p.q0, &p.v0, self.settings.rank_dependent)
                .map_err(|e| solve::unrealizable(&p.constraints, act, p.t0, e)),
        )
    }

    /// A tolerance by name.
    pub fn tolerance(&self, name: &str) -> Option<f64> {
        self.tolerances
            .iter()
            .find(|t| t.name == name)
            .map(|t| t.value)
    }
}
