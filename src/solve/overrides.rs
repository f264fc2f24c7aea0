//! One vocabulary for the method: the names of formulations, integrators and drift controls, their
//! defaults, and how overrides apply to [`Settings`]. The scene loader (`[solver]`, `[time]`), the
//! `progmo solve` flags and the Python binding's keyword arguments all go through
//! [`Settings::apply`]; nothing else parses these names. Values are then checked, with the time
//! span, by [`super::validate`].

use super::{DriftControl, Output, Settings};
use crate::formulation::Formulation;
use crate::integrate::Method;
use clap::builder::PossibleValuesParser;
use schemars::JsonSchema;
use std::fmt;
use std::str::FromStr;

/// Projection defaults: residual to reach and Newton iterations per level.
pub const DEFAULT_PROJECTION_TOL: f64 = 1e-12;
pub const DEFAULT_PROJECTION_ITER: usize = 8;
/// Baumgarte defaults (alpha, beta), 1/s.
pub const DEFAULT_BAUMGARTE: (f64, f64) = (1.0, 1.0);

/// Names of the formulations, in [`Formulation::NAMED`] order (`auto` first: the default).
pub const FORMULATION_NAMES: [&str; 7] = [
    "auto",
    "null_space",
    "null_space_stacked",
    "kkt",
    "range_space",
    "udwadia_kalaba",
    "articulated_body",
];
/// Names of the integrators (`rk4` needs a step).
pub const INTEGRATOR_NAMES: [&str; 4] = ["dop853", "dopri5", "radau5", "rk4"];
/// Names of the drift controls.
pub const DRIFT_NAMES: [&str; 3] = ["projection", "baumgarte", "none"];

/// A name outside the vocabulary.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnknownName {
    /// What was named (`formulation`, `integrator`, `drift`).
    pub what: &'static str,
    pub value: String,
    pub expected: &'static [&'static str],
}

impl fmt::Display for UnknownName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "unknown {} `{}`: expected one of {}",
            self.what,
            self.value,
            self.expected.join(", ")
        )
    }
}

impl std::error::Error for UnknownName {}

impl Formulation {
    /// The name every door uses (`null_space`, ...).
    pub fn name(self) -> &'static str {
        let i = Formulation::NAMED
            .iter()
            .position(|&f| f == self)
            .expect("NAMED lists every formulation");
        FORMULATION_NAMES[i]
    }
}

impl FromStr for Formulation {
    type Err = UnknownName;
    fn from_str(s: &str) -> Result<Self, UnknownName> {
        FORMULATION_NAMES
            .iter()
            .position(|&n| n == s)
            .map(|i| Formulation::NAMED[i])
            .ok_or_else(|| UnknownName {
                what: "formulation",
                value: s.to_string(),
                expected: &FORMULATION_NAMES,
            })
    }
}

impl fmt::Display for Formulation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Method {
    /// The name every door uses (`dop853`, ...; the step of `rk4` is a separate setting).
    pub fn name(&self) -> &'static str {
        match self {
            Method::Dop853 => "dop853",
            Method::Dopri5 => "dopri5",
            Method::Radau5 => "radau5",
            Method::Rk4 { .. } => "rk4",
        }
    }

    /// The method of a name; `rk4` takes `step` (None: [`OverrideError::StepRequired`]).
    pub fn from_name(name: &str, step: Option<f64>) -> Result<Method, OverrideError> {
        Ok(match name {
            "dop853" => Method::Dop853,
            "dopri5" => Method::Dopri5,
            "radau5" => Method::Radau5,
            "rk4" => Method::Rk4 {
                h: step.ok_or(OverrideError::StepRequired)?,
            },
            other => {
                return Err(OverrideError::UnknownName(UnknownName {
                    what: "integrator",
                    value: other.to_string(),
                    expected: &INTEGRATOR_NAMES,
                }))
            }
        })
    }
}

impl DriftControl {
    /// The name every door uses (`projection`, `baumgarte`, `none`).
    pub fn name(&self) -> &'static str {
        match self {
            DriftControl::Projection { .. } => "projection",
            DriftControl::Baumgarte { .. } => "baumgarte",
            DriftControl::None => "none",
        }
    }
}

/// The overridable settings: the one definition every door reads. A scene file gives them as keys
/// of the table each names (`[solver]`, `[time]`, `[initial]`), `progmo solve` as flags
/// (`--max-step`), the Python binding as keyword arguments (`Scene.solve(max_step=...)`), a sweep
/// as `vary.solver.<name>` (the numeric `[solver]` ones). `None` keeps the current value. Ranges are
/// the schema's (`exclusiveMinimum`, `minimum`: [`settings`] reads them; [`Overrides::from_table`]
/// and [`Overrides::check`] enforce them); a new setting is a field here and its effect in
/// [`Settings::apply`].
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, JsonSchema, clap::Args,
)]
#[serde(deny_unknown_fields)]
pub struct Overrides {
    /// How the accelerations are computed: `auto` (`null_space`, except on tree models with at
    /// least `progmo::formulation::AUTO_ARTICULATED_NV` velocities, the crossover `progmo bench
    /// --only anchor` measures: `articulated_body`), `null_space` (the paper: orthonormal basis D of
    /// null(B), D A v' = D (G + Q), solved in that basis with a Cholesky factorization of the reduced
    /// inertia), `null_space_stacked` (the same equations as the stacked square system (2.10), by
    /// LU), `kkt` (Lagrange multipliers), `range_space` (the earlier method the paper criticises),
    /// `udwadia_kalaba`, `articulated_body` (range space with A^-1 applied by the articulated-body
    /// factorization of a tree: O(n) per row, A never formed; on lagrangian models A^-1 from a dense
    /// Cholesky factor).
    #[arg(long, value_parser = PossibleValuesParser::new(FORMULATION_NAMES))]
    #[schemars(extend("enum" = FORMULATION_NAMES, "default" = "auto", "x-table" = "solver"))]
    pub formulation: Option<String>,
    /// Integrator: `dop853`, `dopri5` (adaptive explicit), `radau5` (implicit), `rk4` (fixed
    /// step; needs `step`).
    #[arg(long, value_parser = PossibleValuesParser::new(INTEGRATOR_NAMES))]
    #[schemars(extend("enum" = INTEGRATOR_NAMES, "default" = "dop853", "x-table" = "solver"))]
    pub integrator: Option<String>,
    /// Fixed step of `rk4` (s); required with it, ignored by the others.
    #[arg(long)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "x-table" = "solver"))]
    pub step: Option<f64>,
    /// Relative local error tolerance.
    #[arg(long)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "default" = 1e-10, "x-table" = "solver"))]
    pub rtol: Option<f64>,
    /// Absolute local error tolerance.
    #[arg(long)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "default" = 1e-12, "x-table" = "solver"))]
    pub atol: Option<f64>,
    /// Largest step (s). Default unlimited.
    #[arg(long)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "x-table" = "solver"))]
    pub max_step: Option<f64>,
    /// Drift control: `projection` (after every accepted step, Newton projection of q onto the
    /// position rows and of v onto the velocity rows, in the kinetic-energy metric), `baumgarte`,
    /// `none` (monitor only).
    #[arg(long, value_parser = PossibleValuesParser::new(DRIFT_NAMES))]
    #[schemars(extend("enum" = DRIFT_NAMES, "default" = "projection", "x-table" = "solver"))]
    pub drift: Option<String>,
    /// Residual the projection reaches (up to 8 Newton iterations per level).
    #[arg(long)]
    #[schemars(extend(
        "exclusiveMinimum" = 0.0,
        "default" = DEFAULT_PROJECTION_TOL,
        "x-table" = "solver"
    ))]
    pub projection_tol: Option<f64>,
    /// Baumgarte alpha (with `drift = "baumgarte"`).
    #[arg(long)]
    #[schemars(extend("default" = DEFAULT_BAUMGARTE.0, "x-table" = "solver"))]
    pub baumgarte_alpha: Option<f64>,
    /// Baumgarte beta.
    #[arg(long)]
    #[schemars(extend("default" = DEFAULT_BAUMGARTE.1, "x-table" = "solver"))]
    pub baumgarte_beta: Option<f64>,
    /// Stop with `drift_exceeded` when a position- or velocity-level residual exceeds this after a
    /// step. Default: monitor only.
    #[arg(long)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "x-table" = "solver"))]
    pub max_drift: Option<f64>,
    /// Stop at the first conditioning warning (return code `ill_conditioned`) instead of
    /// reporting it and going on.
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true", value_name = "BOOL")]
    #[schemars(extend("default" = false, "x-table" = "solver"))]
    pub strict: Option<bool>,
    /// With a fixed step (`rk4`): the companion solve at twice the step whose Richardson estimate
    /// of the global error summary.json reports as `global_error` (about half the solve again).
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true", value_name = "BOOL")]
    #[schemars(extend("default" = true, "x-table" = "solver"))]
    pub richardson: Option<bool>,
    /// Most step attempts; a run whose step rate says it cannot reach t1 within them stops early
    /// with `too_many_steps`.
    #[arg(long)]
    #[schemars(extend("minimum" = 1, "default" = crate::integrate::DEFAULT_MAX_STEPS, "x-table" = "solver"))]
    pub max_steps: Option<usize>,
    /// End time (s), > t0.
    #[arg(long)]
    #[schemars(extend("x-table" = "time"))]
    pub t1: Option<f64>,
    /// Output sample spacing (s); absent: one sample per accepted step.
    #[arg(long)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "x-table" = "time"))]
    pub output_dt: Option<f64>,
    /// Most output samples a run may write, t0 and t1 included (a longer span or a finer
    /// output_dt is refused before integrating).
    #[arg(long)]
    #[schemars(extend("minimum" = 2, "default" = super::DEFAULT_MAX_SAMPLES, "x-table" = "time"))]
    pub max_samples: Option<usize>,
    /// Project an inconsistent initial state onto the constraints instead of refusing it.
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "true", value_name = "BOOL")]
    #[schemars(extend("default" = false, "x-table" = "initial"))]
    pub assemble: Option<bool>,
}

/// What [`settings`] says of one overridable setting (from [`Overrides`]' schema).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SettingInfo {
    /// Its name at every door (`max_step`; the flag is `--max-step`).
    pub name: String,
    /// The scene file's table that holds it (`solver`, `time`, `initial`).
    pub table: String,
    /// `number`, `integer`, `string` or `boolean`.
    pub kind: String,
    /// The field's documentation.
    pub description: String,
    /// A number must be above this (`exclusiveMinimum`) ...
    pub above: Option<f64>,
    /// ... or at least this (`minimum`).
    pub at_least: Option<f64>,
    /// The names a string setting accepts.
    pub choices: Vec<String>,
    /// The default, where it is a value (JSON).
    pub default: Option<serde_json::Value>,
}

/// Every overridable setting, by name: read from [`Overrides`]' JSON Schema, so the
/// names, tables, ranges and descriptions are those of the fields.
pub fn settings() -> &'static [SettingInfo] {
    static LIST: std::sync::OnceLock<Vec<SettingInfo>> = std::sync::OnceLock::new();
    LIST.get_or_init(|| {
        let schema = schemars::SchemaGenerator::default()
            .into_root_schema_for::<Overrides>()
            .to_value();
        let props = schema["properties"]
            .as_object()
            .expect("Overrides is a struct");
        props
            .iter()
            .map(|(name, p)| {
                let kind = match &p["type"] {
                    serde_json::Value::Array(t) => t.iter().find(|t| *t != "null").cloned(),
                    t => Some(t.clone()),
                };
                let text = |k: &str| p[k].as_str().unwrap_or_default().to_string();
                SettingInfo {
                    name: name.clone(),
                    table: text("x-table"),
                    kind: kind
                        .and_then(|k| k.as_str().map(str::to_string))
                        .unwrap_or_default(),
                    description: text("description").replace('\n', " "),
                    above: p["exclusiveMinimum"].as_f64(),
                    at_least: p["minimum"].as_f64(),
                    choices: p["enum"]
                        .as_array()
                        .map(|a| {
                            a.iter()
                                .filter_map(|x| x.as_str().map(str::to_string))
                                .collect()
                        })
                        .unwrap_or_default(),
                    default: p.get("default").filter(|d| !d.is_null()).cloned(),
                }
            })
            .collect()
    })
}

/// The setting of a name.
pub fn setting(name: &str) -> Option<&'static SettingInfo> {
    settings().iter().find(|s| s.name == name)
}

/// The Markdown table of the settings of a scene file's `table` (FORMAT.md's, generated: `PROGMO_BLESS=1
/// cargo test --release --test integration schema::`): key, type and range, default, meaning.
pub fn settings_table(table: &str) -> String {
    let mut out = String::from("| key | type | default | meaning |\n|---|---|---|---|\n");
    for s in settings().iter().filter(|s| s.table == table) {
        let kind = match (s.kind.as_str(), s.above, s.at_least) {
            ("number", Some(m), _) => format!("number > {m}"),
            ("number", _, _) => "finite number".to_string(),
            ("integer", _, Some(m)) => format!("integer ≥ {m}"),
            (k, _, _) => k.to_string(),
        };
        let default = match &s.default {
            Some(d) => format!("`{d}`"),
            None => "—".to_string(),
        };
        out += &format!(
            "| `{}` | {kind} | {default} | {} |\n",
            s.name, s.description
        );
    }
    out
}

/// A setting refused by its name, type or range: `name` is the setting (`rtol`), `message` what is
/// wrong without it. Each door locates it its own way (the scene file's key, the flag, the
/// keyword argument).
#[derive(Clone, Debug, PartialEq)]
pub struct SettingError {
    pub name: String,
    pub message: String,
}

impl fmt::Display for SettingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.name, self.message)
    }
}

impl std::error::Error for SettingError {}

impl Overrides {
    /// The overrides of a table of named values (a scene file's keys, a Python call's keyword
    /// arguments): every name must be a setting, every value of its type and range.
    pub fn from_table(values: &toml::Table) -> Result<Overrides, SettingError> {
        for (name, value) in values {
            let Some(info) = setting(name) else {
                let names = settings().iter().map(|s| s.name.as_str());
                return Err(SettingError {
                    name: name.clone(),
                    message: format!(
                        "unknown setting `{name}`{}: expected one of {}",
                        crate::located::did_you_mean(name, names.clone()),
                        names.collect::<Vec<_>>().join(", ")
                    ),
                });
            };
            check_range(info, value)?;
            let one = toml::Table::from_iter([(name.clone(), value.clone())]);
            if let Err(e) = toml::Value::Table(one).try_into::<Overrides>() {
                return Err(SettingError {
                    name: name.clone(),
                    message: format!("expected {}: {}", info.kind, e.message().trim()),
                });
            }
        }
        toml::Value::Table(values.clone())
            .try_into()
            .map_err(|e: toml::de::Error| SettingError {
                name: String::new(),
                message: e.message().trim().to_string(),
            })
    }

    /// The given values as a table (names of [`settings`]; `None` left out).
    pub fn to_table(&self) -> toml::Table {
        match toml::Value::try_from(self) {
            Ok(toml::Value::Table(t)) => t,
            _ => unreachable!("Overrides serializes to a table"),
        }
    }

    /// Every given value within its setting's range (the command line's typed flags: their type is
    /// clap's).
    pub fn check(&self) -> Result<(), SettingError> {
        for (name, value) in &self.to_table() {
            let info = setting(name).expect("a field of Overrides is a setting");
            check_range(info, value)?;
        }
        Ok(())
    }

    /// Whether the value of `name` is given.
    pub fn has(&self, name: &str) -> bool {
        self.to_table().contains_key(name)
    }
}

/// A number finite and within the setting's schema range.
fn check_range(info: &SettingInfo, value: &toml::Value) -> Result<(), SettingError> {
    let x = match value {
        toml::Value::Float(x) => *x,
        toml::Value::Integer(i) => *i as f64,
        _ => return Ok(()),
    };
    let bad = |message: String| {
        Err(SettingError {
            name: info.name.clone(),
            message,
        })
    };
    match (info.above, info.at_least) {
        (Some(0.0), _) if !(x > 0.0) || !x.is_finite() => bad(format!("must be positive, got {x}")),
        _ if !x.is_finite() => bad(format!("must be a finite number, got {x}")),
        (Some(m), _) if !(x > m) => bad(format!("must be above {m}, got {x}")),
        (_, Some(m)) if !(x >= m) => bad(format!("must be at least {m}, got {x}")),
        _ => Ok(()),
    }
}

/// An override that does not name a method of the vocabulary.
#[derive(Clone, Debug, PartialEq)]
pub enum OverrideError {
    /// A formulation, integrator or drift control outside the vocabulary.
    UnknownName(UnknownName),
    /// `rk4` without a step.
    StepRequired,
}

impl OverrideError {
    /// The override it is about (`formulation`, `integrator`, `drift`, `step`).
    pub fn field(&self) -> &'static str {
        match self {
            OverrideError::UnknownName(u) => u.what,
            OverrideError::StepRequired => "step",
        }
    }
}

impl fmt::Display for OverrideError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OverrideError::UnknownName(u) => u.fmt(f),
            OverrideError::StepRequired => f.write_str("the rk4 integrator needs a fixed step"),
        }
    }
}

impl std::error::Error for OverrideError {}

impl Settings {
    /// These settings with `o` applied. A new drift control keeps the current gains or tolerance
    /// where it has them (else the defaults); a `step` alone changes the step of a current `rk4`.
    /// Values are not range-checked here: [`super::validate`] does that with the time span.
    pub fn apply(&self, o: &Overrides) -> Result<Settings, OverrideError> {
        let mut s = self.clone();
        if let Some(f) = &o.formulation {
            s.formulation = f.parse().map_err(OverrideError::UnknownName)?;
        }
        let current_step = match s.integrator {
            Method::Rk4 { h } => Some(h),
            _ => None,
        };
        if let Some(name) = &o.integrator {
            s.integrator = Method::from_name(name, o.step.or(current_step))?;
        } else if let (Some(h), Some(_)) = (o.step, current_step) {
            s.integrator = Method::Rk4 { h };
        }
        s.rtol = o.rtol.unwrap_or(s.rtol);
        s.atol = o.atol.unwrap_or(s.atol);
        s.max_step = o.max_step.unwrap_or(s.max_step);
        let (tol, max_iter) = match s.drift {
            DriftControl::Projection { tol, max_iter } => (tol, max_iter),
            _ => (DEFAULT_PROJECTION_TOL, DEFAULT_PROJECTION_ITER),
        };
        let (alpha, beta) = match s.drift {
            DriftControl::Baumgarte { alpha, beta } => (alpha, beta),
            _ => DEFAULT_BAUMGARTE,
        };
        let name = o.drift.as_deref().unwrap_or(s.drift.name());
        s.drift = match name {
            "projection" => DriftControl::Projection {
                tol: o.projection_tol.unwrap_or(tol),
                max_iter,
            },
            "baumgarte" => DriftControl::Baumgarte {
                alpha: o.baumgarte_alpha.unwrap_or(alpha),
                beta: o.baumgarte_beta.unwrap_or(beta),
            },
            "none" => DriftControl::None,
            other => {
                return Err(OverrideError::UnknownName(UnknownName {
                    what: "drift",
                    value: other.to_string(),
                    expected: &DRIFT_NAMES,
                }))
            }
        };
        if o.max_drift.is_some() {
            s.max_drift = o.max_drift;
        }
        if let Some(dt) = o.output_dt {
            s.output = Output::Every(dt);
        }
        s.max_samples = o.max_samples.unwrap_or(s.max_samples);
        s.max_steps = o.max_steps.unwrap_or(s.max_steps);
        s.strict = o.strict.unwrap_or(s.strict);
        s.assemble = o.assemble.unwrap_or(s.assemble);
        s.richardson = o.richardson.unwrap_or(s.richardson);
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_round_trips() {
        assert_eq!(Formulation::NAMED.len(), FORMULATION_NAMES.len());
        for f in Formulation::NAMED {
            assert_eq!(f.name().parse::<Formulation>(), Ok(f));
            // serde spells them the same way (summary.json, the binding's settings dict)
            assert_eq!(serde_json::to_value(f).unwrap(), f.name());
        }
        for n in INTEGRATOR_NAMES {
            assert_eq!(Method::from_name(n, Some(0.1)).unwrap().name(), n);
        }
        for n in DRIFT_NAMES {
            let o = Overrides {
                drift: Some(n.into()),
                ..Default::default()
            };
            assert_eq!(Settings::default().apply(&o).unwrap().drift.name(), n);
        }
        let e = "nullspace".parse::<Formulation>().unwrap_err();
        assert!(e
            .to_string()
            .contains("expected one of auto, null_space, null_space_stacked"));
    }

    #[test]
    fn overrides_apply_in_one_place() {
        let base = Settings::default();
        assert_eq!(base.apply(&Overrides::default()).unwrap(), base);
        let o = Overrides {
            formulation: Some("kkt".into()),
            integrator: Some("rk4".into()),
            step: Some(1e-3),
            rtol: Some(1e-8),
            projection_tol: Some(1e-11),
            output_dt: Some(0.01),
            strict: Some(true),
            ..Default::default()
        };
        let s = base.apply(&o).unwrap();
        assert_eq!(s.formulation, Formulation::Kkt);
        assert_eq!(s.integrator, Method::Rk4 { h: 1e-3 });
        assert_eq!(s.rtol, 1e-8);
        assert_eq!(
            s.drift,
            DriftControl::Projection {
                tol: 1e-11,
                max_iter: DEFAULT_PROJECTION_ITER
            }
        );
        assert_eq!(s.output, Output::Every(0.01));
        assert!(s.strict);
        // a step alone changes a current rk4; rk4 without any step is refused
        let t = s
            .apply(&Overrides {
                step: Some(2e-3),
                ..Default::default()
            })
            .unwrap();
        assert_eq!(t.integrator, Method::Rk4 { h: 2e-3 });
        let rk = Overrides {
            integrator: Some("rk4".into()),
            ..Default::default()
        };
        assert_eq!(base.apply(&rk), Err(OverrideError::StepRequired));
        // switching drift keeps what the current one has, defaults otherwise
        let b = base
            .apply(&Overrides {
                drift: Some("baumgarte".into()),
                baumgarte_alpha: Some(3.0),
                ..Default::default()
            })
            .unwrap();
        assert_eq!(
            b.drift,
            DriftControl::Baumgarte {
                alpha: 3.0,
                beta: DEFAULT_BAUMGARTE.1
            }
        );
        let bad = Overrides {
            drift: Some("stabilize".into()),
            ..Default::default()
        };
        assert_eq!(base.apply(&bad).unwrap_err().field(), "drift");
    }

    #[test]
    fn settings_come_from_the_one_definition() {
        let names: Vec<&str> = settings().iter().map(|s| s.name.as_str()).collect();
        assert!(names.windows(2).all(|w| w[0] < w[1]), "{names:?}");
        assert!(
            names.contains(&"max_step") && names.contains(&"t1"),
            "{names:?}"
        );
        for s in settings() {
            assert!(
                ["solver", "time", "initial"].contains(&s.table.as_str()),
                "{s:?}"
            );
            assert!(!s.description.is_empty(), "{s:?}");
        }
        let rtol = setting("rtol").unwrap();
        assert_eq!((rtol.kind.as_str(), rtol.above), ("number", Some(0.0)));
        assert_eq!(setting("max_samples").unwrap().at_least, Some(2.0));
        assert_eq!(setting("drift").unwrap().choices, DRIFT_NAMES);
        assert_eq!(setting("assemble").unwrap().table, "initial");
        // a name-keyed lookup refuses what is not a field (negative control)
        assert!(setting("h_max").is_none());
    }

    #[test]
    fn tables_of_values_are_checked_by_name_type_and_range() {
        let t = |s: &str| s.parse::<toml::Table>().unwrap();
        let o = Overrides::from_table(&t("rtol = 1e-8\nmax_samples = 10\nstrict = true")).unwrap();
        assert_eq!(
            (o.rtol, o.max_samples, o.strict),
            (Some(1e-8), Some(10), Some(true))
        );
        // integers are numbers
        assert_eq!(
            Overrides::from_table(&t("atol = 1")).unwrap().atol,
            Some(1.0)
        );
        let e = Overrides::from_table(&t("rtl = 1e-8")).unwrap_err();
        assert_eq!(e.name, "rtl");
        assert!(e.message.contains("did you mean `rtol`"), "{e}");
        let e = Overrides::from_table(&t("rtol = \"tight\"")).unwrap_err();
        assert!(e.message.starts_with("expected number"), "{e}");
        for (text, want) in [
            ("rtol = -1.0", "must be positive, got -1"),
            ("max_step = inf", "must be positive, got inf"),
            ("baumgarte_alpha = nan", "must be a finite number, got NaN"),
            ("max_samples = 1", "must be at least 2"),
        ] {
            let e = Overrides::from_table(&t(text)).unwrap_err();
            assert!(e.message.contains(want), "{text}: {e}");
        }
        // the typed door (clap) is range-checked the same way
        let o = Overrides {
            projection_tol: Some(0.0),
            ..Default::default()
        };
        assert_eq!(o.check().unwrap_err().name, "projection_tol");
        // to_table leaves out what is not given
        let given = Overrides {
            step: Some(0.1),
            ..Default::default()
        };
        assert_eq!(given.to_table().len(), 1);
        assert!(given.has("step") && !given.has("rtol"));
    }
}
