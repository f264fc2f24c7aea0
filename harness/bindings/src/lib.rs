//! `progmo._core`: the Rust core seen from Python (private; the public API is the
//! `progmo` package). Thin glue only: every error of the core (`progmo::Error`) becomes a Python
//! exception in one place, `py_err`; every solve releases the GIL.

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use progmo::formulation::Formulation;
use progmo::model::Model;
use progmo::output::{Bounded, StopOn};
use progmo::programme::{Constraints, Level, Role};
use progmo::scene::{Scene, SceneSystem};
use progmo::solve::{Evaluator, Overrides, Solution, Trajectory};
use progmo::with_problem;
use pyo3::create_exception;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;

mod check;
mod solution;

/// (body name, world position, orientation w x y z) as Python gets it.
type BodyPoseTuple = (String, [f64; 3], [f64; 4]);
use progmo::output::SampleLayout;
use solution::PySolution;

create_exception!(
    _core,
    SceneError,
    PyValueError,
    "A scene file is invalid; the message names file, line, column and field."
);

create_exception!(
    _core,
    SettingsError,
    PyValueError,
    "A solver setting or override is invalid; the message names it (`rtol: must be > 0`)."
);

create_exception!(
    _core,
    SolveStopped,
    pyo3::exceptions::PyRuntimeError,
    "A solve stopped before t1 (`Solution.raise_if_stopped`); args[0] is the return code as one sentence, `.code` its name."
);

create_exception!(
    _core,
    ExportUnsupported,
    PyValueError,
    "The scene holds an element the simulator format cannot carry; the message names it."
);

/// The one conversion of the core's errors (`progmo::Error`, typed variants) into Python's
/// exceptions: `Scene` and `Input` -> `SceneError`, `Settings` -> `SettingsError`, an unsupported
/// `Export` -> `ExportUnsupported` (other export errors ValueError), `Output` -> OSError,
/// `Formulation` -> RuntimeError, `Argument` -> ValueError. `args[0]` is the one-line message;
/// every exception carries `kind`, `field`, `message`, `file`, `line`, `column`, `excerpt` and
/// `rows` as attributes (None where they do not apply).
pub(crate) fn py_err(e: impl Into<progmo::Error>) -> PyErr {
    use progmo::Error as E;
    let e: E = e.into();
    let text = e.to_string();
    let err = match &e {
        E::Scene(_) | E::Input { .. } => SceneError::new_err(text),
        E::Settings { .. } => SettingsError::new_err(text),
        E::Export(progmo::export::ExportError::Unsupported { .. }) => {
            ExportUnsupported::new_err(text)
        }
        E::Export(_) | E::Argument { .. } => PyValueError::new_err(text),
        E::Output(_) => pyo3::exceptions::PyOSError::new_err(text),
        E::Formulation(_) => PyRuntimeError::new_err(text),
    };
    let at = e.location();
    let excerpt = match &e {
        E::Scene(s) => s.excerpt.clone(),
        _ => String::new(),
    };
    Python::attach(|py| {
        let v = err.value(py);
        // an exception instance takes attributes; a failure here would leave only the message
        let _ = v.setattr("kind", e.kind());
        let _ = v.setattr("field", e.field());
        let _ = v.setattr("message", e.message());
        let _ = v.setattr("file", e.file());
        let _ = v.setattr("line", at.as_ref().map(|a| a.line));
        let _ = v.setattr("column", at.as_ref().map(|a| a.column));
        let _ = v.setattr("excerpt", excerpt);
        let _ = v.setattr("rows", e.rows().map(<[usize]>::to_vec));
    });
    err
}

/// A ValueError for the argument `field` (shapes, finiteness: checks of this glue's own).
pub(crate) fn argument_error(field: &str, message: impl Into<String>) -> PyErr {
    py_err(progmo::Error::argument(field, message))
}

/// A `SettingsError` for the setting `field` (a check of this glue's own, e.g. a keyword's type).
fn settings_error(field: &str, message: &str) -> PyErr {
    py_err(progmo::Error::Settings {
        field: field.into(),
        message: message.into(),
    })
}

/// Keyword arguments as the core's overrides (`progmo::solve::Overrides::from_table`: names, types
/// and ranges of the one definition); None values are left out.
fn overrides(kw: Option<&Bound<'_, PyDict>>) -> PyResult<Overrides> {
    let mut table = toml::Table::new();
    for (k, v) in kw.into_iter().flat_map(|d| d.iter()) {
        let name: String = k.extract()?;
        if v.is_none() {
            continue;
        }
        let value = if let Ok(b) = v.cast::<pyo3::types::PyBool>() {
            toml::Value::Boolean(b.is_true())
        } else if let Ok(i) = v.extract::<i64>() {
            toml::Value::Integer(i)
        } else if let Ok(x) = v.extract::<f64>() {
            toml::Value::Float(x)
        } else if let Ok(t) = v.extract::<String>() {
            toml::Value::String(t)
        } else {
            let kind = v.get_type().name()?;
            let want =
                progmo::solve::setting(&name).map_or("a setting's value", |s| s.kind.as_str());
            return Err(settings_error(
                &name,
                &format!("expected {want}, got {kind}"),
            ));
        };
        table.insert(name, value);
    }
    Overrides::from_table(&table).map_err(py_err)
}

pub(crate) fn json_to_py<'py>(
    py: Python<'py>,
    v: &impl serde::Serialize,
) -> PyResult<Bound<'py, PyAny>> {
    let s = serde_json::to_string(v).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    py.import("json")?.call_method1("loads", (s,))
}

pub(crate) fn matrix<'py>(
    py: Python<'py>,
    flat: &[f64],
    cols: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rows = flat.len().checked_div(cols).unwrap_or(0);
    let a = Array2::from_shape_vec((rows, cols), flat.to_vec())
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

/// A loaded scene.
#[pyclass(name = "Scene", module = "progmo._core", frozen)]
struct PyScene {
    scene: Scene,
}

fn level_name(l: Level) -> &'static str {
    match l {
        Level::Position => "position",
        Level::Velocity => "velocity",
        Level::Acceleration => "acceleration",
    }
}

impl PyScene {
    /// One state from Python: finite, with the scene's nq and nv entries (ValueError otherwise).
    fn state(
        &self,
        t: f64,
        q: &PyReadonlyArray1<'_, f64>,
        v: &PyReadonlyArray1<'_, f64>,
    ) -> PyResult<(Vec<f64>, Vec<f64>)> {
        let (q, v) = (q.as_slice()?.to_vec(), v.as_slice()?.to_vec());
        finite("t", [&t])?;
        finite("q", &q)?;
        finite("v", &v)?;
        let (nq, nv) = (self.scene.q_names().len(), self.scene.v_names().len());
        if q.len() != nq || v.len() != nv {
            return Err(argument_error("q", format!("needs {nq} entries, v {nv}")));
        }
        Ok((q, v))
    }
}

#[pymethods]
impl PyScene {
    /// Load and validate a scene file; raises SceneError with a located message.
    #[new]
    fn new(path: PathBuf) -> PyResult<Self> {
        Scene::load(&path)
            .map(|scene| PyScene { scene })
            .map_err(py_err)
    }

    #[getter]
    fn name(&self) -> String {
        self.scene.name.clone()
    }
    #[getter]
    fn description(&self) -> String {
        self.scene.description.clone()
    }
    #[getter]
    fn purpose(&self) -> String {
        self.scene.purpose.clone()
    }
    #[getter]
    fn path(&self) -> String {
        self.scene.path.display().to_string()
    }
    /// "tree" or "lagrangian".
    #[getter]
    fn kind(&self) -> &'static str {
        match self.scene.system {
            SceneSystem::Tree(_) => "tree",
            SceneSystem::Lagrangian(_) => "lagrangian",
        }
    }
    #[getter]
    fn q_names(&self) -> Vec<String> {
        self.scene.q_names()
    }
    #[getter]
    fn v_names(&self) -> Vec<String> {
        self.scene.v_names()
    }
    /// Rows as dicts {name, level, role}.
    #[getter]
    fn rows<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let list = PyList::empty(py);
        for r in self.scene.rows() {
            let d = PyDict::new(py);
            d.set_item("name", &r.name)?;
            d.set_item("level", level_name(r.level))?;
            d.set_item(
                "role",
                if r.role == Role::Programme {
                    "programme"
                } else {
                    "system"
                },
            )?;
            list.append(d)?;
        }
        Ok(list)
    }
    /// Tolerances {name: (value, reason)}.
    #[getter]
    fn tolerances<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for t in &self.scene.tolerances {
            d.set_item(&t.name, (t.value, &t.reason))?;
        }
        Ok(d)
    }
    #[getter]
    fn parameters(&self) -> Vec<(String, f64)> {
        self.scene.parameters.clone()
    }
    #[getter]
    fn t0(&self) -> f64 {
        self.scene.span().0
    }
    #[getter]
    fn t1(&self) -> f64 {
        self.scene.span().1
    }
    #[getter]
    fn q0<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let q = with_problem!(&self.scene.system, p => p.q0.clone());
        PyArray1::from_vec(py, q)
    }
    #[getter]
    fn v0<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let v = with_problem!(&self.scene.system, p => p.v0.clone());
        PyArray1::from_vec(py, v)
    }
    /// The scene's solver settings as a dict.
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.scene.settings)
    }

    /// Check the check's replay step `h` over the span up to `t1` (default the scene's) with the
    /// scene's settings (`progmo::solve::validate_replay_step`): SettingsError naming
    /// `replay_step`, never the `output_dt = h/2` its reference solve uses.
    #[pyo3(signature = (h, *, t1=None))]
    fn check_replay_step(&self, h: f64, t1: Option<f64>) -> PyResult<()> {
        let (t0, own) = self.scene.span();
        progmo::solve::validate_replay_step((t0, t1.unwrap_or(own)), h, &self.scene.settings)
            .map_err(py_err)
    }

    /// Solve (the GIL is released meanwhile). Keyword arguments are the settings of the core's one
    /// definition (`progmo::solve::Overrides`; `SETTINGS` lists them with their tables, types,
    /// ranges and documentation: the scene file's keys and `progmo solve`'s flags of the same
    /// names); None leaves a setting at the scene's value. An unknown name, a wrong type or a value
    /// out of range, then the span and settings together (`progmo::solve::validate`), raise
    /// SettingsError naming the argument (`.field`). Returns a `Solution` (partial on an early
    /// stop: see its `code` / `raise_if_stopped`).
    #[pyo3(signature = (**settings))]
    fn solve<'py>(
        &self,
        py: Python<'py>,
        settings: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<PySolution> {
        let o = overrides(settings)?;
        let s = self.scene.settings.apply(&o).map_err(py_err)?;
        let t1 = o.t1;
        let mut scene = self.scene.clone();
        if let Some(t1) = t1 {
            with_problem!(&mut scene.system, p => p.t1 = t1);
        }
        let traj = with_problem!(&scene.system, p => Trajectory::named_for(p));
        let width = traj.values_per_sample();
        progmo::solve::validate(scene.span(), &s)
            .and_then(|()| progmo::solve::validate_in_memory(scene.span(), &s, width))
            .map_err(py_err)?;
        let layout = with_problem!(&scene.system, p => SampleLayout::from_problem(p));
        let started = std::time::Instant::now();
        // Ctrl-C / SIGTERM stop the solve after the step in progress (as in `progmo solve`); the
        // signal then goes to Python's own handler (KeyboardInterrupt carrying `.solution`, the
        // samples up to the stop), once the solution is built.
        // Without output_dt (a sample per step) the bound stops the solve (validate_in_memory).
        let (sol, caught, full): (Solution, Option<i32>, Option<usize>) = py.detach(|| {
            let guard = progmo::interrupt::Guard::install();
            let limit = progmo::solve::in_memory_samples(width);
            let mut sink = StopOn::new(Bounded::new(traj, limit), guard.flag());
            let mut sol = scene.solve_into(&s, &mut sink);
            let kept = sink.into_inner();
            let full = kept.full().then_some(limit);
            sol.trajectory = kept.into_inner();
            (sol, guard.release(), full)
        });
        let wall = started.elapsed().as_secs_f64();
        let t_end = sol.t_end;
        let sol = PySolution::new(py, scene, sol, s, layout, wall)?;
        if let (Some(limit), None) = (full, caught) {
            let e = settings_error(
                "output_dt",
                &format!(
                    "without output_dt every step is a sample: {limit} samples of {width} values \
                     reached the in-memory limit of {} GiB at t = {t_end:?}; set output_dt, shorten \
                     t1, or stream to files with `progmo solve` (the samples so far are in \
                     .solution)",
                    progmo::solve::IN_MEMORY_LIMIT_BYTES >> 30
                ),
            );
            e.value(py).setattr("solution", Py::new(py, sol)?)?;
            return Err(e);
        }
        if let Some(sig) = caught {
            progmo::interrupt::raise(sig);
            if let Err(e) = py.check_signals() {
                let partial = Py::new(py, sol)?;
                e.value(py).setattr("solution", partial)?;
                return Err(e);
            }
        }
        Ok(sol)
    }

    /// Residuals of every row along a trajectory (n samples): position rows g(t, q), velocity
    /// rows f(t, q, v), acceleration rows h(t, q, v, a) (needs `a`; NaN without it). Shape (n, s).
    #[pyo3(signature = (t, q, v, a=None))]
    fn residuals<'py>(
        &self,
        py: Python<'py>,
        t: PyReadonlyArray1<'py, f64>,
        q: PyReadonlyArray2<'py, f64>,
        v: PyReadonlyArray2<'py, f64>,
        a: Option<PyReadonlyArray2<'py, f64>>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let (t, q, v) = (
            t.as_array().to_owned(),
            q.as_array().to_owned(),
            v.as_array().to_owned(),
        );
        let a = a.map(|a| a.as_array().to_owned());
        finite("t", t.iter())?;
        finite("q", q.iter())?;
        finite("v", v.iter())?;
        if let Some(a) = &a {
            finite("a", a.iter())?;
        }
        let n = t.len();
        let (nq, nv) = (self.scene.q_names().len(), self.scene.v_names().len());
        if q.shape() != [n, nq]
            || v.shape() != [n, nv]
            || a.as_ref().is_some_and(|a| a.shape() != [n, nv])
        {
            return Err(argument_error(
                "q",
                format!("shapes: t ({n},), q must be ({n}, {nq}), v and a ({n}, {nv})"),
            ));
        }
        let out = py.detach(|| {
            with_problem!(&self.scene.system, p => {
                let rows = p.constraints.rows();
                let s = rows.len();
                let mut ws = p.constraints.workspace::<f64>();
                let mut res = vec![0.0; n * s];
                let zero = vec![0.0; nv];
                let mut buf = vec![0.0; s];
                for k in 0..n {
                    let qk: Vec<f64> = q.row(k).to_vec();
                    let vk: Vec<f64> = v.row(k).to_vec();
                    let ak: Vec<f64> = a.as_ref().map(|a| a.row(k).to_vec()).unwrap_or_else(|| zero.clone());
                    p.constraints.eval(&mut ws, t[k], &qk, &vk, &ak, &mut buf);
                    for i in 0..s {
                        res[k * s + i] = if rows[i].level == Level::Acceleration && a.is_none() { f64::NAN } else { buf[i] };
                    }
                }
                (res, s)
            })
        });
        matrix(py, &out.0, out.1)
    }

    /// Mass matrix A, velocity terms G and applied forces Q (A dv/dt - G = Q, paper eq. 2.2) and
    /// the constraint Jacobian B with gamma (B dv/dt = gamma) at one state.
    fn dynamics<'py>(
        &self,
        py: Python<'py>,
        t: f64,
        q: PyReadonlyArray1<'py, f64>,
        v: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (q, v) = self.state(t, &q, &v)?;
        let nv = v.len();
        let d = PyDict::new(py);
        with_problem!(&self.scene.system, p => {
            let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
            ev.prepare(t, &q, &v);
            let mut ws = p.model.workspace::<f64>();
            let mut g = vec![0.0; nv];
            let mut f = vec![0.0; nv];
            p.model.velocity_terms(&mut ws, &q, &v, &mut g);
            p.model.applied_forces(&mut ws, t, &q, &v, &mut f);
            let a: Vec<f64> = (0..nv).flat_map(|i| (0..nv).map(move |j| (i, j))).map(|(i, j)| ev.mass[(i, j)]).collect();
            let s = ev.jet.gamma.len();
            let b: Vec<f64> = (0..s).flat_map(|i| (0..nv).map(move |j| (i, j))).map(|(i, j)| ev.jet.b[(i, j)]).collect();
            d.set_item("mass", matrix(py, &a, nv)?)?;
            d.set_item("velocity_terms", PyArray1::from_vec(py, g))?;
            d.set_item("applied_forces", PyArray1::from_vec(py, f))?;
            d.set_item("B", matrix(py, &b, nv)?)?;
            d.set_item("gamma", PyArray1::from_vec(py, ev.jet.gamma.clone()))?;
        });
        Ok(d)
    }

    /// One right-hand side at (t, q, v) with `formulation` (no drift control): dv/dt ("a"), the
    /// control force u of the programme rows (2.12), the system rows' reactions and the multipliers.
    /// Rank decisions as the solver makes them (reference row norms at t0). For benchmarks and checks.
    fn accelerations<'py>(
        &self,
        py: Python<'py>,
        t: f64,
        q: PyReadonlyArray1<'py, f64>,
        v: PyReadonlyArray1<'py, f64>,
        formulation: &str,
    ) -> PyResult<Bound<'py, PyDict>> {
        let f = parse_formulation(formulation)?;
        let (q, v) = self.state(t, &q, &v)?;
        let nv = v.len();
        let rank = self.scene.settings.rank();
        let d = PyDict::new(py);
        with_problem!(&self.scene.system, p => {
            let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
            // the solver's reference row norms: at the scene's initial state
            ev.set_row_scale_at(p.t0, &p.q0, &p.v0);
            ev.evaluate(f, &rank, None, t, &q, &v)
                .map_err(py_err)?;
            let mut u = vec![0.0; nv];
            let mut r = vec![0.0; nv];
            ev.reaction(Role::Programme, &mut u);
            ev.reaction(Role::System, &mut r);
            d.set_item("a", PyArray1::from_vec(py, ev.acc.clone()))?;
            d.set_item("u", PyArray1::from_vec(py, u))?;
            d.set_item("reactions", PyArray1::from_vec(py, r))?;
            d.set_item("lambda", PyArray1::from_vec(py, ev.lambda.clone()))?;
        });
        Ok(d)
    }

    /// Seconds (wall clock, GIL released) per right-hand side: `iterations` evaluations of dv/dt
    /// and u (`accelerations` without the Python conversions) at (t0, q0, v0), or at (t, q, v) when
    /// given. Each call recomputes A, G + Q, the constraint jet and solves with `formulation`.
    #[pyo3(signature = (iterations, formulation, t=None, q=None, v=None))]
    fn rhs_benchmark<'py>(
        &self,
        py: Python<'py>,
        iterations: usize,
        formulation: &str,
        t: Option<f64>,
        q: Option<PyReadonlyArray1<'py, f64>>,
        v: Option<PyReadonlyArray1<'py, f64>>,
    ) -> PyResult<f64> {
        let f = parse_formulation(formulation)?;
        let t = t.unwrap_or(self.scene.span().0);
        let q = match q {
            Some(q) => q.as_slice()?.to_vec(),
            None => with_problem!(&self.scene.system, p => p.q0.clone()),
        };
        let v = match v {
            Some(v) => v.as_slice()?.to_vec(),
            None => with_problem!(&self.scene.system, p => p.v0.clone()),
        };
        finite("t", [&t])?;
        finite("q", &q)?;
        finite("v", &v)?;
        let (nq, nv) = (self.scene.q_names().len(), self.scene.v_names().len());
        if q.len() != nq || v.len() != nv || iterations == 0 {
            return Err(argument_error(
                "q",
                format!("needs {nq} entries, v {nv}, iterations > 0"),
            ));
        }
        let rank = self.scene.settings.rank();
        let out: Result<f64, progmo::formulation::FormulationError> = py.detach(|| {
            with_problem!(&self.scene.system, p => {
                let mut ev = Evaluator::<_, _, f64>::new(&p.model, &p.constraints);
                // the solver's reference row norms: at the scene's initial state
                ev.set_row_scale_at(p.t0, &p.q0, &p.v0);
                let mut u = vec![0.0; nv];
                // two nearby states, alternated: every evaluation is at a new q, as in a solve
                let qb: Vec<f64> = q.iter().map(|x| x + 1e-9).collect();
                let states = [&q, &qb];
                let start = std::time::Instant::now();
                for i in 0..iterations {
                    ev.evaluate(f, &rank, None, t, states[i % 2], &v)?;
                    ev.reaction(Role::Programme, &mut u);
                    std::hint::black_box(&u);
                }
                Ok(start.elapsed().as_secs_f64() / iterations as f64)
            })
        });
        out.map_err(py_err)
    }

    /// The located error the solver's refusal of the initial state gives (the same message and
    /// exit code 2 as `progmo solve`): raises SceneError, returns None when the state is usable.
    fn check_initial(&self) -> PyResult<()> {
        self.scene
            .check_initial(&self.scene.settings)
            .map(|_| ())
            .map_err(py_err)
    }

    /// `[[actuators]]` of the scene: (name, index into v) of each actuator, the index None for an
    /// actuator along a `direction`; empty for the ideal realization (u in the row space of the
    /// programme Jacobian).
    #[getter]
    fn actuators(&self) -> Vec<(String, Option<usize>)> {
        self.actuation()
            .map(|a| {
                (0..a.len())
                    .map(|j| (a.names[j].clone(), a.joint(j)))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// The actuation map H (n x m; u = H tau) at the initial state (H itself when constant), or
    /// None without actuators.
    #[getter]
    fn actuation_map<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.actuation().map(|a| {
            let n = self.scene.v_names().len();
            Array2::from_shape_fn((n, a.len()), |(i, j)| a.column(j)[i]).into_pyarray(py)
        })
    }

    /// Does the actuation map depend on the state (a `direction` written as expressions of t and
    /// the coordinates)? False without actuators.
    #[getter]
    fn actuation_varies(&self) -> bool {
        self.actuation().is_some_and(|a| !a.is_constant())
    }

    /// H(t, q) (n x m), or None without actuators.
    fn actuation_map_at<'py>(
        &self,
        py: Python<'py>,
        t: f64,
        q: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        let q = q.as_slice()?.to_vec();
        finite("t", [&t])?;
        finite("q", &q)?;
        let nq = self.scene.q_names().len();
        if q.len() != nq {
            return Err(argument_error("q", format!("needs {nq} entries")));
        }
        Ok(self.actuation().map(|a| {
            let n = self.scene.v_names().len();
            let cols = a.columns_at(t, &q);
            Array2::from_shape_fn((n, a.len()), |(i, j)| cols[j][i]).into_pyarray(py)
        }))
    }

    /// The part of each force u_k no actuator can produce, u_k - P u_k with P the orthogonal
    /// projector onto range(H(t_k, q_k)) (`servo::Actuation::outside_part`: exactly the entries on
    /// unactuated joints for joint actuators). Shapes t (K,), q (K, nq), u (K, n) -> (K, n); None
    /// without actuators.
    fn unactuated_part<'py>(
        &self,
        py: Python<'py>,
        t: PyReadonlyArray1<'py, f64>,
        q: PyReadonlyArray2<'py, f64>,
        u: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        let Some(act) = self.actuation() else {
            return Ok(None);
        };
        let (t, q, u) = (
            t.as_array().to_owned(),
            q.as_array().to_owned(),
            u.as_array().to_owned(),
        );
        finite("t", t.iter())?;
        finite("q", q.iter())?;
        finite("u", u.iter())?;
        let k = t.len();
        let (nq, nv) = (self.scene.q_names().len(), self.scene.v_names().len());
        if q.shape() != [k, nq] || u.shape() != [k, nv] {
            return Err(argument_error(
                "q",
                format!("shapes: t ({k},), q must be ({k}, {nq}), u ({k}, {nv})"),
            ));
        }
        let out = py.detach(|| {
            let mut out = Array2::<f64>::zeros((k, nv));
            for i in 0..k {
                let qi: Vec<f64> = q.row(i).to_vec();
                let ui: Vec<f64> = u.row(i).to_vec();
                let r = act.outside_part(t[i], &qi, &ui);
                out.row_mut(i).assign(&numpy::ndarray::ArrayView1::from(&r));
            }
            out
        });
        Ok(Some(out.into_pyarray(py)))
    }

    /// The robot file of a `urdf`/`mjcf` scene as a dict {kind: "urdf" | "mjcf", path: the
    /// resolved absolute path, locked_joints: [(joint, q value it is welded at)], mimics: [{joint,
    /// leader, multiplier, offset}] (the URDF `<mimic>`s modelled as system rows)}; None for
    /// other models.
    #[getter]
    fn robot_file<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(r) = &self.scene.robot else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("kind", &r.kind)?;
        d.set_item("path", r.path.display().to_string())?;
        d.set_item("locked_joints", r.locked.clone())?;
        let mimics = PyList::empty(py);
        for m in &r.mimics {
            let e = PyDict::new(py);
            e.set_item("joint", &m.joint)?;
            e.set_item("leader", &m.leader)?;
            e.set_item("multiplier", m.multiplier)?;
            e.set_item("offset", m.offset)?;
            mimics.append(e)?;
        }
        d.set_item("mimics", mimics)?;
        Ok(Some(d))
    }

    /// What the robot file holds that is not modelled, one dict per element in file order:
    /// {kind (closed vocabulary), element, location "file:line", declared: the scene's reason
    /// (`[model] ignore`) or None}; [] for other models.
    #[getter]
    fn unmodelled<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for u in self.scene.robot.iter().flat_map(|r| &r.unmodelled) {
            let d = PyDict::new(py);
            d.set_item("kind", &u.kind)?;
            d.set_item("element", &u.element)?;
            d.set_item("location", &u.location)?;
            d.set_item("declared", &u.declared)?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// Position limits the robot file states for the modelled hinge and slide joints: {joint
    /// (its q name): (lower, upper)} in q's units (radians, metres); {} for other models.
    #[getter]
    fn joint_ranges(&self) -> std::collections::BTreeMap<String, (f64, f64)> {
        self.scene
            .robot
            .iter()
            .flat_map(|r| &r.ranges)
            .map(|j| (j.joint.clone(), (j.lower, j.upper)))
            .collect()
    }

    /// The vocabulary of unmodelled kinds: [(kind, what it covers)].
    #[staticmethod]
    fn unmodelled_kinds() -> Vec<(&'static str, &'static str)> {
        progmo::import::unmodelled::KINDS.to_vec()
    }

    /// `[checks] not_checked` of the scene: {simulator: reason}.
    #[getter]
    fn expected_not_checked(&self) -> Vec<(String, String)> {
        self.scene.expected_not_checked.clone()
    }

    /// `[checks] replay_step` as (value, reason); None: a convergence check picks the step.
    #[getter]
    fn replay_step(&self) -> Option<(f64, String)> {
        self.scene
            .replay_step
            .as_ref()
            .map(|t| (t.value, t.reason.clone()))
    }

    /// `[[reference]]` of the scene, one dict per value: t, quantity ("q", "v" or "u"), name, index
    /// (into q or v), value, source, field (where it is written).
    #[getter]
    fn references<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for r in &self.scene.references {
            let d = PyDict::new(py);
            d.set_item("t", r.t)?;
            d.set_item("quantity", r.quantity)?;
            d.set_item("name", &r.name)?;
            d.set_item("index", r.index)?;
            d.set_item("value", r.value)?;
            d.set_item("source", &r.source)?;
            d.set_item("field", &r.field)?;
            out.append(d)?;
        }
        Ok(out)
    }

    /// The scene's expression forces at (t, q, v) as a simulator applies them: a dict with
    /// "generalized" (nv, the coordinate forces) and "points": one (body, world point (3),
    /// world force (3)) per point force, in the order of the export report's `point_force` entries.
    fn expression_forces<'py>(
        &self,
        py: Python<'py>,
        t: f64,
        q: PyReadonlyArray1<'py, f64>,
        v: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (q, v) = self.state(t, &q, &v)?;
        let nv = v.len();
        let d = PyDict::new(py);
        let points = PyList::empty(py);
        match &self.scene.system {
            SceneSystem::Tree(p) => {
                let (gen, pts) = p.model.expression_forces(t, &q, &v);
                let bodies = p.model.tree().bodies();
                for (b, pw, fw) in pts {
                    points.append((bodies[b].name.clone(), pw.to_vec(), fw.to_vec()))?;
                }
                d.set_item("generalized", PyArray1::from_vec(py, gen))?;
            }
            SceneSystem::Lagrangian(_) => {
                d.set_item("generalized", PyArray1::from_vec(py, vec![0.0; nv]))?;
            }
        }
        d.set_item("points", points)?;
        Ok(d)
    }

    /// Export a tree scene's model: `format` "mjcf" or "urdf". Returns (document, report dict) —
    /// the report lists mass floors applied, forces the harness must apply itself (attractors;
    /// springs/dampers in URDF), gravity, the root joint to pass to Pinocchio, and q/v maps.
    /// `supply_reactions`: system rows no simulator holds are left out and listed as a
    /// `supplied_reaction` harness force (`Scene::export_supplying`) instead of refused.
    #[pyo3(signature = (format, *, timestep=1e-3, supply_reactions=false))]
    fn export<'py>(
        &self,
        py: Python<'py>,
        format: &str,
        timestep: f64,
        supply_reactions: bool,
    ) -> PyResult<(String, Bound<'py, PyAny>)> {
        let options = progmo::export::ExportOptions {
            name: self.scene.name.clone(),
            timestep,
            ..Default::default()
        };
        let format = match format {
            "mjcf" => progmo::export::Format::Mjcf,
            "urdf" => progmo::export::Format::Urdf,
            other => {
                return Err(argument_error(
                    "format",
                    format!("unknown export format {other:?} (mjcf, urdf)"),
                ))
            }
        };
        let exported = if supply_reactions {
            self.scene.export_supplying(format, &options)
        } else {
            self.scene.export(format, &options)
        };
        let (doc, report) = exported.map_err(py_err)?;
        Ok((doc, json_to_py(py, &report)?))
    }

    /// World pose of every body at configuration q: [(name, position[3], quaternion wxyz[4])]
    /// (empty for a lagrangian scene).
    fn body_poses(&self, q: PyReadonlyArray1<'_, f64>) -> PyResult<Vec<BodyPoseTuple>> {
        let q = q.as_slice()?.to_vec();
        finite("q", &q)?;
        if q.len() != self.scene.q_names().len() {
            return Err(argument_error(
                "q",
                format!("needs {} entries", self.scene.q_names().len()),
            ));
        }
        Ok(match self.scene.bodies() {
            Some(mut b) => b
                .poses(&q)
                .iter()
                .map(|p| (p.name.clone(), p.position, p.quaternion))
                .collect(),
            None => vec![],
        })
    }

    /// The `foxglove.SceneUpdate` drawing the mechanism on frames `<prefix>/<body>` (sized at q;
    /// alpha < 1: a ghost; targets: also the declared view targets); None for a lagrangian scene.
    #[pyo3(signature = (q, prefix, alpha=1.0, targets=true))]
    fn scene_update<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray1<'py, f64>,
        prefix: &str,
        alpha: f64,
        targets: bool,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        let q = q.as_slice()?.to_vec();
        finite("q", &q)?;
        match self.scene.bodies() {
            Some(mut b) if q.len() == self.scene.q_names().len() => Ok(Some(json_to_py(
                py,
                &b.scene_update(&q, prefix, alpha, targets),
            )?)),
            Some(_) => Err(argument_error("q", "has the wrong length")),
            None => Ok(None),
        }
    }

    /// The `foxglove.SceneUpdate` of the traces of the programme's sites through the
    /// configurations (rows of `q`, non-finite rows skipped), entities `<prefix>/trace/<site>`;
    /// None for a lagrangian scene or when no site is traced.
    fn scene_trace<'py>(
        &self,
        py: Python<'py>,
        q: PyReadonlyArray2<'py, f64>,
        prefix: &str,
    ) -> PyResult<Option<Bound<'py, PyAny>>> {
        let q = q.as_array();
        if q.ncols() != self.scene.q_names().len() {
            return Err(argument_error("q", "has the wrong number of columns"));
        }
        let Some(mut b) = self.scene.bodies() else {
            return Ok(None);
        };
        for row in q.rows() {
            let row: Vec<f64> = row.to_vec();
            if row.iter().all(|x| x.is_finite()) {
                b.record(&row);
            }
        }
        b.trace_update(prefix)
            .map(|u| json_to_py(py, &u))
            .transpose()
    }

    /// The JSON schemas of recordings by schema name (the ones `progmo solve` writes), for this
    /// scene's names: progmo.State, progmo.Control, progmo.Residual, progmo.Reaction,
    /// foxglove.FrameTransform, foxglove.SceneUpdate.
    fn recording_schemas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let layout = with_problem!(&self.scene.system, p => SampleLayout::from_problem(p));
        let d = PyDict::new(py);
        for (name, schema) in progmo::output::recording_schemas(&layout) {
            d.set_item(name, json_to_py(py, &schema)?)?;
        }
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!(
            "<progmo Scene {:?} ({}) from {}>",
            self.scene.name,
            self.kind(),
            self.scene.path.display()
        )
    }
}

fn parse_formulation(f: &str) -> PyResult<Formulation> {
    f.parse().map_err(|e: progmo::solve::UnknownName| py_err(e))
}

/// Arrays from Python must be finite: a NaN state would only come back as NaN results.
fn finite<'a>(name: &str, x: impl IntoIterator<Item = &'a f64>) -> PyResult<()> {
    match x.into_iter().enumerate().find(|(_, v)| !v.is_finite()) {
        None => Ok(()),
        Some((i, v)) => Err(argument_error(
            name,
            format!("entry {i} is {v:?}; inputs must be finite"),
        )),
    }
}

/// Scene text of a generated n-link planar chain (`progmo::scene::chain`): the one generator
/// shared by the Rust benchmarks, the tests and `progmo bench`.
#[pyfunction]
#[pyo3(signature = (n, *, masses=None, length=0.25, q0=None, name=None, t1=2.0))]
fn chain_toml(
    n: usize,
    masses: Option<Vec<f64>>,
    length: f64,
    q0: Option<f64>,
    name: Option<String>,
    t1: f64,
) -> PyResult<String> {
    let spec = progmo::scene::chain::ChainSpec {
        n,
        masses,
        length,
        q0,
        name,
        t1,
    };
    spec.check()
        .map_err(|e| py_err(progmo::Error::argument("chain_toml", e)))?;
    Ok(spec.toml())
}

/// Projection cost over 10^4 periods (`progmo::problems::hard::measure_drift_cost`): dict with
/// rounds, projection_s, none_s (minimum wall times), residual_projection, residual_none, steps.
/// Releases the GIL.
#[pyfunction]
#[pyo3(signature = (rounds=5))]
fn drift_cost<'py>(py: Python<'py>, rounds: usize) -> PyResult<Bound<'py, PyDict>> {
    let r = py.detach(|| progmo::problems::hard::measure_drift_cost(rounds));
    let d = PyDict::new(py);
    d.set_item("rounds", r.rounds)?;
    d.set_item("projection_s", r.projection_s)?;
    d.set_item("none_s", r.none_s)?;
    d.set_item("residual_projection", r.residual_projection)?;
    d.set_item("residual_none", r.residual_none)?;
    d.set_item("steps", r.steps)?;
    Ok(d)
}

/// The `progmo` command line (`progmo::cli::run`): `argv[0]` is the program name. Returns the
/// exit code. The Python package's `progmo` command calls it for solve, validate and export.
#[pyfunction]
fn cli(py: Python<'_>, argv: Vec<std::ffi::OsString>) -> u8 {
    py.detach(|| progmo::cli::run(argv))
}

/// The file `name` names when written in a file of `folder` (a sweep file's `scene`), under the
/// path rule of scene files (`progmo::input::resolve`): its canonical path, or SceneError saying
/// which rule refused it.
#[pyfunction]
fn resolve_file(name: &str, folder: PathBuf) -> PyResult<String> {
    progmo::input::resolve(name, &folder)
        .map(|p| p.display().to_string())
        .map_err(|m| py_err(progmo::Error::input(m)))
}

/// Version of the core.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // numpy's C API now: fetched lazily, it would be imported by the first array made, and a
    // Ctrl-C pending then (one that ended a solve) failed that import with a panic.
    let _ = PyArray1::<f64>::zeros(m.py(), 0, false);
    m.add_class::<PyScene>()?;
    m.add_class::<PySolution>()?;
    m.add("SettingsError", m.py().get_type::<SettingsError>())?;
    m.add("SolveStopped", m.py().get_type::<SolveStopped>())?;
    m.add("SceneError", m.py().get_type::<SceneError>())?;
    m.add("ExportUnsupported", m.py().get_type::<ExportUnsupported>())?;
    // The method vocabulary of the core (progmo::solve): one list for every door.
    m.add("FORMULATIONS", progmo::solve::FORMULATION_NAMES.to_vec())?;
    m.add("INTEGRATORS", progmo::solve::INTEGRATOR_NAMES.to_vec())?;
    m.add("DRIFTS", progmo::solve::DRIFT_NAMES.to_vec())?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(cli, m)?)?;
    m.add_function(wrap_pyfunction!(chain_toml, m)?)?;
    m.add_function(wrap_pyfunction!(drift_cost, m)?)?;
    // The check's vocabulary (progmo::check): metrics, budgets, options.
    check::register(m)?;
    m.add_function(wrap_pyfunction!(resolve_file, m)?)?;
    Ok(())
}

impl PyScene {
    /// The scene's actuation map (tree scenes with `[[actuators]]`).
    fn actuation(&self) -> Option<&progmo::servo::Actuation> {
        use progmo::programme::Constraints;
        match &self.scene.system {
            SceneSystem::Tree(p) => p.constraints.actuation(),
            SceneSystem::Lagrangian(_) => None,
        }
    }
}
