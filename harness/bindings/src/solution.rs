//! `progmo.Solution`: the outcome of `Scene.solve`, with the samples as read-only numpy arrays and
//! the writers of `progmo solve` (CSV, MCAP, summary.json) replaying the same samples.

use crate::{json_to_py, matrix};
use numpy::PyArray1;
use progmo::output::{
    replay, write_summary_to_path, Bodies, CsvSink, McapSink, SampleLayout, Staged, SummaryInput,
};
use progmo::scene::Scene;
use progmo::solve::{Settings, Solution};
use pyo3::prelude::*;
use pyo3::types::PyList;
use std::path::PathBuf;

/// The outcome of a solve: arrays (n samples), the return code, statistics and warnings.
#[pyclass(name = "Solution", module = "progmo._core", frozen)]
pub struct PySolution {
    scene: String,
    sol: Solution,
    settings: Settings,
    layout: SampleLayout,
    /// The mechanism for the MCAP's 3D view (tree scenes).
    bodies: Option<Bodies>,
    wall_seconds: f64,
    /// The solved scene when it has `[[actuators]]`: its servo analysis goes into the summary.
    servo_scene: Option<Scene>,
    /// The scene's robot file (`Scene::robot`) for summary.json.
    robot_file: Option<serde_json::Value>,
    /// (name, array) of every sampled quantity, built once, read-only.
    arrays: Vec<(&'static str, Py<PyAny>)>,
    stats: Py<PyAny>,
    settings_py: Py<PyAny>,
    code: Py<PyAny>,
    warnings: Py<PyAny>,
}

fn frozen(a: Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
    a.getattr("flags")?.setattr("writeable", false)?;
    Ok(a.unbind())
}

impl PySolution {
    /// The solution of `scene` (its end time as solved); a servo scene is kept for the summary's
    /// servo analysis.
    pub fn new(
        py: Python<'_>,
        scene: Scene,
        sol: Solution,
        settings: Settings,
        layout: SampleLayout,
        wall_seconds: f64,
    ) -> PyResult<Self> {
        use progmo::programme::Constraints;
        let bodies = scene.bodies();
        let actuated = matches!(&scene.system,
            progmo::scene::SceneSystem::Tree(p) if p.constraints.actuation().is_some());
        let name = scene.name.clone();
        let robot_file = scene
            .robot
            .as_ref()
            .and_then(|r| serde_json::to_value(r).ok());
        let servo_scene = actuated.then_some(scene);
        let tr = &sol.trajectory;
        let (nq, nv, s) = (tr.q_names.len(), tr.v_names.len(), tr.row_names.len());
        let arrays = vec![
            (
                "t",
                frozen(PyArray1::from_vec(py, tr.t.clone()).into_any())?,
            ),
            ("q", frozen(matrix(py, &tr.q, nq)?.into_any())?),
            ("v", frozen(matrix(py, &tr.v, nv)?.into_any())?),
            ("a", frozen(matrix(py, &tr.a, nv)?.into_any())?),
            ("u", frozen(matrix(py, &tr.u, nv)?.into_any())?),
            (
                "reactions",
                frozen(matrix(py, &tr.reactions, nv)?.into_any())?,
            ),
            ("lambda_", frozen(matrix(py, &tr.lambda, s)?.into_any())?),
            (
                "residuals",
                frozen(matrix(py, &tr.residual, s)?.into_any())?,
            ),
            (
                "residual_rates",
                frozen(matrix(py, &tr.residual_rate, s)?.into_any())?,
            ),
            (
                "max_residuals",
                frozen(PyArray1::from_vec(py, sol.max_residual.clone()).into_any())?,
            ),
            (
                "max_residual_rates",
                frozen(PyArray1::from_vec(py, sol.max_residual_rate.clone()).into_any())?,
            ),
        ];
        let warnings = PyList::empty(py);
        for w in &sol.warnings {
            let wd = json_to_py(py, w)?;
            wd.set_item("message", w.to_string())?;
            warnings.append(wd)?;
        }
        Ok(PySolution {
            stats: json_to_py(py, &sol.stats)?.unbind(),
            settings_py: json_to_py(py, &settings)?.unbind(),
            code: json_to_py(py, &sol.code)?.unbind(),
            warnings: warnings.into_any().unbind(),
            scene: name,
            sol,
            settings,
            layout,
            bodies,
            wall_seconds,
            servo_scene,
            robot_file,
            arrays,
        })
    }

    fn array(&self, py: Python<'_>, name: &str) -> Py<PyAny> {
        let (_, a) = self
            .arrays
            .iter()
            .find(|(n, _)| *n == name)
            .expect("every array is built in new()");
        a.clone_ref(py)
    }
}

#[pymethods]
impl PySolution {
    /// Name of the scene solved.
    #[getter]
    fn scene(&self) -> &str {
        &self.scene
    }
    /// True when the solve reached t1.
    #[getter]
    fn success(&self) -> bool {
        self.sol.code.is_success()
    }
    /// The return code's name: "success", "step_too_small", "singular_programme", ...
    #[getter]
    fn code(&self) -> &'static str {
        self.sol.code.name()
    }
    /// The return code with its fields (time, rows, values) as a dict.
    #[getter]
    fn code_details(&self, py: Python<'_>) -> Py<PyAny> {
        self.code.clone_ref(py)
    }
    /// The return code as one sentence.
    #[getter]
    fn message(&self) -> String {
        self.sol.code.to_string()
    }
    /// Last time reached (on an early stop, the time of the code and of the last sample).
    #[getter]
    fn t_end(&self) -> f64 {
        self.sol.t_end
    }
    /// Conditioning warnings (dicts with kind, t, rows, value, threshold, message).
    #[getter]
    fn warnings(&self, py: Python<'_>) -> Py<PyAny> {
        self.warnings.clone_ref(py)
    }
    /// Counters: steps, rejected steps, right-hand sides, projections, ...
    #[getter]
    fn stats(&self, py: Python<'_>) -> Py<PyAny> {
        self.stats.clone_ref(py)
    }
    /// The settings the solve used (after overrides).
    #[getter]
    fn settings(&self, py: Python<'_>) -> Py<PyAny> {
        self.settings_py.clone_ref(py)
    }
    /// Wall-clock seconds of the solve.
    #[getter]
    fn wall_seconds(&self) -> f64 {
        self.wall_seconds
    }
    #[getter]
    fn q_names(&self) -> Vec<String> {
        self.layout.q_names.clone()
    }
    #[getter]
    fn v_names(&self) -> Vec<String> {
        self.layout.v_names.clone()
    }
    #[getter]
    fn row_names(&self) -> Vec<String> {
        self.layout.row_names.clone()
    }
    /// Sample times, shape (n,).
    #[getter]
    fn t(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "t")
    }
    /// Configurations, (n, nq).
    #[getter]
    fn q(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "q")
    }
    /// Velocities, (n, nv).
    #[getter]
    fn v(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "v")
    }
    /// Accelerations dv/dt, (n, nv).
    #[getter]
    fn a(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "a")
    }
    /// Control forces of the programme rows (paper eq. 2.12), (n, nv).
    #[getter]
    fn u(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "u")
    }
    /// Reactions of the system's own constraints, (n, nv).
    #[getter]
    fn reactions(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "reactions")
    }
    /// Multipliers, (n, s).
    #[getter]
    fn lambda_(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "lambda_")
    }
    /// Residual of every row, (n, s): g (position), f (velocity), h (acceleration rows).
    /// The actuators' forces tau (samples x m, in the order of `[[actuators]]`; u = H(t, q) tau),
    /// or None without actuators.
    #[getter]
    fn tau<'py>(&self, py: Python<'py>) -> PyResult<Option<Py<PyAny>>> {
        let tr = &self.sol.trajectory;
        let m = tr.actuator_names.len();
        if m == 0 {
            return Ok(None);
        }
        let flat: Vec<f64> = (0..tr.t.len())
            .flat_map(|k| tr.tau_at(k).to_vec())
            .collect();
        Ok(Some(frozen(matrix(py, &flat, m)?.into_any())?))
    }

    #[getter]
    fn residuals(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "residuals")
    }
    /// dg/dt of position rows (0 for the others), (n, s).
    #[getter]
    fn residual_rates(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "residual_rates")
    }
    /// Largest |residual| of each row over every accepted step, (s,).
    #[getter]
    fn max_residuals(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "max_residuals")
    }
    /// Largest |dg/dt| of each position row over every accepted step, (s,).
    #[getter]
    fn max_residual_rates(&self, py: Python<'_>) -> Py<PyAny> {
        self.array(py, "max_residual_rates")
    }

    /// Write the samples as `progmo solve`'s trajectory.csv (format: src/output/csv_sink.rs),
    /// whole or under `<path>.partial` (OSError naming it, e.g. on a full device); a path holding
    /// something other than a regular file (a device) is refused.
    fn write_csv(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| {
            let mut sink = Staged::create(&path, |p| CsvSink::create(p, &self.layout))?;
            replay(&self.sol.trajectory, &self.sol.warnings, &mut sink)
        })
        .map_err(crate::py_err)
    }
    /// Write the samples as `progmo solve`'s recording.mcap (Foxglove; src/output/mcap_sink.rs),
    /// whole or under `<path>.partial`, as `write_csv`.
    fn write_mcap(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| {
            let mut sink = Staged::create(&path, |p| {
                let m = McapSink::create(p, &self.layout)?;
                Ok(match &self.bodies {
                    Some(b) => m.with_bodies(b.clone()),
                    None => m,
                })
            })?;
            replay(&self.sol.trajectory, &self.sol.warnings, &mut sink)
        })
        .map_err(crate::py_err)
    }
    /// Write `progmo solve`'s summary.json (return code, statistics, settings, max residuals),
    /// whole or not at all (through `<path>.tmp`; a device at `path` is refused, never replaced).
    /// Servo scenes: with the servo analysis and the internal dynamics along the motion (two more
    /// solves, as `progmo solve` does).
    fn write_summary(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let command_line = vec!["progmo.Scene.solve (Python)".to_string()];
        let servo = self.servo_scene.as_ref().and_then(|scene| {
            py.detach(|| scene.servo_report(&self.settings, true))
                .and_then(|r| serde_json::to_value(r).ok())
        });
        let input = SummaryInput {
            scene: &self.scene,
            solution: &self.sol,
            row_names: &self.layout.row_names,
            settings: &self.settings,
            wall_seconds: self.wall_seconds,
            git_revision: (!progmo::GIT_REVISION.is_empty()).then_some(progmo::GIT_REVISION),
            command_line: &command_line,
            servo: servo.as_ref(),
            robot_file: self.robot_file.as_ref(),
        };
        write_summary_to_path(path, &input).map_err(crate::py_err)
    }

    /// Raise `SolveStopped` (the return code as one sentence; `.code` its name) unless the solve
    /// reached t1. Returns the solution, so `scene.solve().raise_if_stopped()` chains.
    fn raise_if_stopped(slf: Bound<'_, Self>) -> PyResult<Bound<'_, Self>> {
        let me = slf.get();
        if me.sol.code.is_success() {
            return Ok(slf);
        }
        let err = crate::SolveStopped::new_err(me.sol.code.to_string());
        let value = err.value(slf.py());
        value.setattr("code", me.sol.code.name())?;
        value.setattr("solution", slf.clone())?;
        Err(err)
    }

    fn __len__(&self) -> usize {
        self.sol.trajectory.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "<progmo Solution of {:?}: {}, {} samples, t = {} .. {}>",
            self.scene,
            self.sol.code.name(),
            self.sol.trajectory.len(),
            self.sol.trajectory.t.first().copied().unwrap_or(f64::NAN),
            self.sol.t_end
        )
    }
}
