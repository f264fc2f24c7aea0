//! JSON run summary (format: see the module docs of [`crate::output`]).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use serde::Serialize;

use super::OutputError;
use crate::solve::{
    GlobalError, InitialCorrection, ReturnCode, Settings, Solution, Statistics, Warning,
};

/// Format version written in `format_version`.
const FORMAT_VERSION: u32 = 1;

/// What a summary is made of.
#[derive(Clone, Copy, Debug)]
pub struct SummaryInput<'a> {
    /// Scene name.
    pub scene: &'a str,
    /// The solve's outcome.
    pub solution: &'a Solution,
    /// Names of the constraint rows, in solver order; when empty, those of
    /// `solution.trajectory` (which are empty after `solve_into`).
    pub row_names: &'a [String],
    /// The method used.
    pub settings: &'a Settings,
    /// Wall-clock duration of the run.
    pub wall_seconds: f64,
    /// Git revision of the code, if known.
    pub git_revision: Option<&'a str>,
    /// Command line to rerun (program first).
    pub command_line: &'a [String],
    /// With `[[actuators]]`: the servo analysis (`Scene::servo_report`), written as `servo`.
    pub servo: Option<&'a serde_json::Value>,
    /// A `urdf`/`mjcf` scene's robot file (`Scene::robot`: path, locked joints, ranges, what
    /// is not modelled and whether the scene declares it), written as `robot_file`.
    pub robot_file: Option<&'a serde_json::Value>,
}

#[derive(Serialize)]
struct Row<'a> {
    name: &'a str,
    max_residual: f64,
    max_residual_rate: f64,
}

#[derive(Serialize)]
struct WarningOut<'a> {
    #[serde(flatten)]
    warning: &'a Warning,
    message: String,
}

#[derive(Serialize)]
struct Versions<'a> {
    progmo: &'static str,
    git_revision: Option<&'a str>,
}

#[derive(Serialize)]
struct SummaryOut<'a> {
    format: &'static str,
    format_version: u32,
    scene: &'a str,
    success: bool,
    code: &'a ReturnCode,
    code_name: &'static str,
    /// The return code as one sentence (quantity, time, rows).
    message: String,
    t_end: f64,
    max_residual: f64,
    max_residual_rate: f64,
    rows: Vec<Row<'a>>,
    statistics: &'a Statistics,
    warnings: Vec<WarningOut<'a>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    global_error: Option<&'a GlobalError>,
    initial_correction: &'a Option<InitialCorrection>,
    settings: &'a Settings,
    wall_seconds: f64,
    versions: Versions<'a>,
    command_line: &'a [String],
    #[serde(skip_serializing_if = "Option::is_none")]
    servo: Option<&'a serde_json::Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    robot_file: Option<&'a serde_json::Value>,
}

/// Largest value; NaN if any is NaN; 0 for none.
fn max_nan(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m: f64, &x| {
        if x.is_nan() || m.is_nan() {
            f64::NAN
        } else {
            m.max(x.abs())
        }
    })
}

fn build<'a>(input: &SummaryInput<'a>, file: &str) -> Result<SummaryOut<'a>, OutputError> {
    let sol = input.solution;
    let names = if input.row_names.is_empty() {
        &sol.trajectory.row_names[..]
    } else {
        input.row_names
    };
    if names.len() != sol.max_residual.len() || names.len() != sol.max_residual_rate.len() {
        return Err(OutputError::invalid(
            file,
            format!(
                "{} row names for {} max residuals and {} max residual rates",
                names.len(),
                sol.max_residual.len(),
                sol.max_residual_rate.len()
            ),
        ));
    }
    let rows = names
        .iter()
        .zip(sol.max_residual.iter().zip(&sol.max_residual_rate))
        .map(|(name, (&r, &rr))| Row {
            name,
            max_residual: r,
            max_residual_rate: rr,
        })
        .collect();
    Ok(SummaryOut {
        format: "progmo.summary",
        format_version: FORMAT_VERSION,
        scene: input.scene,
        success: sol.code.is_success(),
        code: &sol.code,
        code_name: sol.code.name(),
        message: sol.code.to_string(),
        t_end: sol.t_end,
        max_residual: max_nan(&sol.max_residual),
        max_residual_rate: max_nan(&sol.max_residual_rate),
        rows,
        statistics: &sol.stats,
        warnings: sol
            .warnings
            .iter()
            .map(|w| WarningOut {
                warning: w,
                message: w.to_string(),
            })
            .collect(),
        global_error: sol.global_error.as_ref(),
        initial_correction: &sol.initial_correction,
        settings: input.settings,
        wall_seconds: input.wall_seconds,
        versions: Versions {
            progmo: env!("CARGO_PKG_VERSION"),
            git_revision: input.git_revision,
        },
        command_line: input.command_line,
        servo: input.servo,
        robot_file: input.robot_file,
    })
}

/// The summary as a JSON value.
pub fn summary_json(input: &SummaryInput<'_>) -> Result<serde_json::Value, OutputError> {
    let out = build(input, "<summary>")?;
    serde_json::to_value(&out).map_err(|e| OutputError::Json {
        file: "<summary>".into(),
        what: "serialize summary".into(),
        source: e,
    })
}

fn write_named<W: Write>(
    mut w: W,
    input: &SummaryInput<'_>,
    file: &str,
) -> Result<(), OutputError> {
    let out = build(input, file)?;
    serde_json::to_writer_pretty(&mut w, &out).map_err(|e| {
        if e.is_io() {
            OutputError::io(file, "write summary", e.into())
        } else {
            OutputError::Json {
                file: file.into(),
                what: "serialize summary".into(),
                source: e,
            }
        }
    })?;
    w.write_all(b"\n")
        .and_then(|_| w.flush())
        .map_err(|e| OutputError::io(file, "write summary", e))
}

/// Write the summary to `w` (pretty-printed, trailing newline) and flush.
pub fn write_summary<W: Write>(w: W, input: &SummaryInput<'_>) -> Result<(), OutputError> {
    write_named(w, input, "<summary>")
}

/// Write the summary to the file at `path`, whole or not at all: it is written under
/// `<path>.tmp` and renamed when complete (a full device leaves no truncated summary.json).
pub fn write_summary_to_path(
    path: impl AsRef<Path>,
    input: &SummaryInput<'_>,
) -> Result<(), OutputError> {
    let path = path.as_ref();
    let name = path.display().to_string();
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    // Never beside or over a device (`/dev/null` would be replaced by the rename).
    super::staged::writable_destination(path)?;
    super::staged::writable_destination(&tmp)?;
    let r = File::create(&tmp)
        .map_err(|e| OutputError::io(&name, "create", e))
        .and_then(|f| write_named(BufWriter::new(f), input, &name))
        .and_then(|()| super::staged::writable_destination(path))
        .and_then(|()| {
            std::fs::rename(&tmp, path).map_err(|e| OutputError::io(&name, "rename", e))
        });
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::Trajectory;

    fn solution() -> Solution {
        let mut stats = Statistics {
            factorizations: 42,
            min_b_rcond: 0.25,
            ..Default::default()
        };
        stats.integrator.steps = 17;
        Solution {
            code: ReturnCode::DriftExceeded {
                t: 1.5,
                row: "speed".into(),
                residual: 2e-6,
            },
            trajectory: Trajectory::default(),
            stats,
            max_residual: vec![1e-13, 2e-6],
            max_residual_rate: vec![0.0, f64::NAN],
            initial_correction: Some(InitialCorrection {
                position: 1e-9,
                velocity: 0.0,
            }),
            warnings: vec![],
            t_end: 1.5,
            global_error: None,
        }
    }

    #[test]
    fn summary_fields() {
        let sol = solution();
        let names = vec!["energy".to_string(), "speed".to_string()];
        let settings = Settings::default();
        let cmd = vec!["progmo".to_string(), "run".into(), "top".into()];
        let input = SummaryInput {
            scene: "top",
            solution: &sol,
            row_names: &names,
            settings: &settings,
            wall_seconds: 0.5,
            git_revision: Some("abc123"),
            command_line: &cmd,
            servo: None,
            robot_file: None,
        };
        let mut buf = Vec::new();
        write_summary(&mut buf, &input).unwrap();
        assert_eq!(buf.last(), Some(&b'\n'));
        let v: serde_json::Value = serde_json::from_slice(&buf).unwrap();
        assert_eq!(v, summary_json(&input).unwrap());
        assert_eq!(v["format"], "progmo.summary");
        assert_eq!(v["format_version"], 1);
        assert_eq!(v["scene"], "top");
        assert_eq!(v["success"], false);
        assert_eq!(v["code_name"], "drift_exceeded");
        assert_eq!(v["code"]["code"], "drift_exceeded");
        assert_eq!(v["code"]["row"], "speed");
        assert_eq!(v["code"]["t"], 1.5);
        assert_eq!(v["code"]["residual"], 2e-6);
        assert_eq!(v["t_end"], 1.5);
        assert_eq!(v["max_residual"], 2e-6);
        assert!(v["max_residual_rate"].is_null());
        assert_eq!(v["rows"][0]["name"], "energy");
        assert_eq!(v["rows"][0]["max_residual"], 1e-13);
        assert_eq!(v["rows"][1]["name"], "speed");
        assert!(v["rows"][1]["max_residual_rate"].is_null());
        assert_eq!(v["statistics"]["factorizations"], 42);
        assert_eq!(v["statistics"]["integrator"]["steps"], 17);
        assert_eq!(v["initial_correction"]["position"], 1e-9);
        assert_eq!(v["settings"]["rtol"], 1e-10);
        assert!(v["settings"]["max_step"].is_null());
        assert_eq!(v["wall_seconds"], 0.5);
        assert_eq!(v["versions"]["progmo"], env!("CARGO_PKG_VERSION"));
        assert_eq!(v["versions"]["git_revision"], "abc123");
        assert_eq!(
            v["command_line"],
            serde_json::json!(["progmo", "run", "top"])
        );
    }

    #[test]
    fn success_and_row_name_fallback() {
        let mut sol = solution();
        sol.code = ReturnCode::Success;
        sol.trajectory.row_names = vec!["a".into(), "b".into()];
        sol.initial_correction = None;
        let settings = Settings::default();
        let input = SummaryInput {
            scene: "s",
            solution: &sol,
            row_names: &[],
            settings: &settings,
            wall_seconds: 0.0,
            git_revision: None,
            command_line: &[],
            servo: None,
            robot_file: None,
        };
        let v = summary_json(&input).unwrap();
        assert_eq!(v["success"], true);
        assert_eq!(v["code"], serde_json::json!({"code": "success"}));
        assert_eq!(v["rows"][1]["name"], "b");
        assert!(v["initial_correction"].is_null());
        assert!(v["versions"]["git_revision"].is_null());

        let mut short = sol.clone();
        short.trajectory.row_names.pop();
        let input = SummaryInput {
            solution: &short,
            ..input
        };
        assert!(matches!(
            summary_json(&input),
            Err(OutputError::Invalid { .. })
        ));
    }

    #[test]
    fn file_summary() {
        let sol = solution();
        let names = vec!["energy".to_string(), "speed".to_string()];
        let settings = Settings::default();
        let path = std::env::temp_dir().join(format!("progmo-summary-{}.json", std::process::id()));
        let input = SummaryInput {
            scene: "top",
            solution: &sol,
            row_names: &names,
            settings: &settings,
            wall_seconds: 0.5,
            git_revision: None,
            command_line: &[],
            servo: None,
            robot_file: None,
        };
        write_summary_to_path(&path, &input).unwrap();
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(v["scene"], "top");
        let bad = write_summary_to_path("/nonexistent-dir/x.json", &input).unwrap_err();
        assert!(bad
            .to_string()
            .starts_with("/nonexistent-dir/x.json: create"));
    }
}
