//! `progmo::check` seen from Python: the check's vocabulary (metrics, their scene-table names,
//! default budgets with reasons, replay options, simulators), read by `progmo.checks` instead of a
//! copy of its own.

use progmo::check::{self, METRICS};
use progmo::solve::{DriftControl, DEFAULT_BAUMGARTE, DEFAULT_PROJECTION_ITER};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// Every metric the check judges, in the order budgets are listed: dicts with name, table (its
/// budget's name in `[tolerances]`), simulators and solver_only (when those checks judge it:
/// "always", "closures", "actuators", "references" or "never"), class and reason.
#[pyfunction]
fn check_metrics<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
    let out = PyList::empty(py);
    for m in &METRICS {
        let d = PyDict::new(py);
        d.set_item("name", m.name)?;
        d.set_item("table", m.table)?;
        d.set_item("simulators", m.simulators.name())?;
        d.set_item("solver_only", m.solver_only.name())?;
        d.set_item("class", m.class)?;
        d.set_item("reason", m.reason)?;
        out.append(d)?;
    }
    Ok(out)
}

/// The default budget of every metric with its reason, under a drift control given as
/// `Scene.settings["drift"]` gives it ({"kind": "projection", "tol": ...}, {"kind": "none"}, ...).
#[pyfunction]
fn default_budgets<'py>(
    py: Python<'py>,
    drift: &Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyDict>> {
    let num = |key: &str, default: f64| -> PyResult<f64> {
        match drift.get_item(key)? {
            Some(x) => Ok(x.extract::<f64>()?),
            None => Ok(default),
        }
    };
    let kind: String = match drift.get_item("kind")? {
        Some(k) => k.extract::<String>()?,
        None => "none".into(),
    };
    let drift = match kind.as_str() {
        "projection" => DriftControl::Projection {
            tol: match drift.get_item("tol")? {
                Some(x) => x.extract::<f64>()?,
                None => return Err(crate::argument_error("drift", "projection needs `tol`")),
            },
            max_iter: match drift.get_item("max_iter")? {
                Some(x) => x.extract::<usize>()?,
                None => DEFAULT_PROJECTION_ITER,
            },
        },
        "baumgarte" => DriftControl::Baumgarte {
            alpha: num("alpha", DEFAULT_BAUMGARTE.0)?,
            beta: num("beta", DEFAULT_BAUMGARTE.1)?,
        },
        "none" => DriftControl::None,
        other => {
            return Err(crate::argument_error(
                "drift",
                format!(
                    "unknown kind `{other}`{}",
                    check::did_you_mean(other, progmo::solve::DRIFT_NAMES.iter().copied())
                ),
            ))
        }
    };
    let out = PyDict::new(py);
    for m in &METRICS {
        out.set_item(m.name, m.default_budget(&drift))?;
    }
    Ok(out)
}

/// Every name a scene's `[tolerances]` may hold (the loader refuses any other).
#[pyfunction]
fn tolerance_keys() -> Vec<String> {
    check::tolerance_keys()
}

/// The nearest of `candidates` to a misspelt `name` (the rule of every "did you mean"), or None.
#[pyfunction]
fn nearest(name: &str, candidates: Vec<String>) -> Option<String> {
    check::nearest(name, candidates.iter().map(String::as_str))
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("REFERENCE_RTOL", check::REFERENCE_RTOL)?;
    m.add("REFERENCE_ATOL", check::REFERENCE_ATOL)?;
    m.add("SIMULATORS", check::SIMULATORS.to_vec())?;
    m.add("SOLVER_ONLY", check::SOLVER_ONLY)?;
    m.add(
        "CHECK_OPTIONS",
        check::OPTIONS.iter().map(|(n, _)| *n).collect::<Vec<_>>(),
    )?;
    // The settings of the one definition (progmo::solve::Overrides) and the numeric [solver] ones,
    // which a sweep may vary.
    let settings = progmo::solve::settings();
    m.add("SETTINGS", crate::json_to_py(m.py(), &settings.to_vec())?)?;
    m.add(
        "SOLVER_NUMBERS",
        settings
            .iter()
            .filter(|s| s.table == "solver" && s.kind == "number")
            .map(|s| s.name.as_str())
            .collect::<Vec<_>>(),
    )?;
    m.add_function(wrap_pyfunction!(check_metrics, m)?)?;
    m.add_function(wrap_pyfunction!(default_budgets, m)?)?;
    m.add_function(wrap_pyfunction!(tolerance_keys, m)?)?;
    m.add_function(wrap_pyfunction!(nearest, m)?)?;
    Ok(())
}
