//! One vocabulary for the method: the names of formulations, integrators and drift controls, their
//! defaults, and how overrides apply to [`Settings`]. The scene loader (`[solver]`, `[time]`), the
//! `progmo solve` flags and the Python binding's keyword arguments all go through
//! [`Settings::apply`]; nothing else parses these names. Values are then checked, with the time
//! span, by [`super::validate`].

use super::{DriftControl, Output, Settings};
use crate::formulation::Formulation;
use crate::integrate::Method;
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

/// Changes to a [`Settings`], as a scene file, the command line or a Python call give them. `None`
/// keeps the current value. Names are those of the scene file's `[solver]` and `[time]` keys.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Overrides {
    pub formulation: Option<String>,
    pub integrator: Option<String>,
    /// Fixed step of `rk4`.
    pub step: Option<f64>,
    pub rtol: Option<f64>,
    pub atol: Option<f64>,
    pub max_step: Option<f64>,
    pub drift: Option<String>,
    pub projection_tol: Option<f64>,
    pub baumgarte_alpha: Option<f64>,
    pub baumgarte_beta: Option<f64>,
    pub max_drift: Option<f64>,
    /// Output spacing (`Output::Every`).
    pub output_dt: Option<f64>,
    pub max_samples: Option<usize>,
    pub strict: Option<bool>,
    pub assemble: Option<bool>,
    /// [`Settings::richardson`] (the global error estimate of a fixed-step solve).
    pub richardson: Option<bool>,
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
        s.h_max = o.max_step.unwrap_or(s.h_max);
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
}
