//! One validation of a time span and [`Settings`] before integrating, shared by every door (scene
//! loader, CLI flags, Python binding): finite positive numbers, steps that advance time, and work
//! bounded by [`Settings::max_samples`] and [`Settings::max_steps`].

use super::{DriftControl, Output, Settings};
use crate::integrate::Method;
use std::fmt;

/// Default of [`Settings::max_samples`]: 10^7 output samples (about 1 GB of CSV for a 10-dof
/// scene).
pub const DEFAULT_MAX_SAMPLES: usize = 10_000_000;

/// The setting an error is about. Each door names it its own way ([`SettingsField::key`] in a
/// scene file, `--` and [`SettingsField::name`] on the command line, the name in Python).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SettingsField {
    T0,
    T1,
    OutputDt,
    MaxSamples,
    Step,
    FixedStep,
    Rtol,
    Atol,
    MaxStep,
    MaxSteps,
    ProjectionTol,
    BaumgarteAlpha,
    BaumgarteBeta,
    MaxDrift,
    ConsistencyTol,
    RankDependent,
    RankVanishing,
    /// The check's replay step (`progmo check/debug --step`, the scene's `replay_step` budget):
    /// its reference solve samples every half step.
    ReplayStep,
}

impl SettingsField {
    /// Plain name (`output_dt`): the setting's name at every door ([`super::settings`]), a Python
    /// keyword argument, `--output-dt` on the command line.
    pub fn name(self) -> &'static str {
        use SettingsField::*;
        match self {
            T0 => "t0",
            T1 => "t1",
            OutputDt => "output_dt",
            MaxSamples => "max_samples",
            Step => "step",
            FixedStep => "fixed_step",
            Rtol => "rtol",
            Atol => "atol",
            MaxStep => "max_step",
            MaxSteps => "max_steps",
            ProjectionTol => "projection_tol",
            BaumgarteAlpha => "baumgarte_alpha",
            BaumgarteBeta => "baumgarte_beta",
            MaxDrift => "max_drift",
            ConsistencyTol => "consistency_tol",
            RankDependent => "rank_dependent",
            RankVanishing => "rank_vanishing",
            ReplayStep => "replay_step",
        }
    }

    /// Key in a scene file (`time.output_dt`: the table of [`super::setting`]); settings the file
    /// cannot set have a `settings.` key.
    pub fn key(self) -> String {
        let name = self.name();
        match (self, super::setting(name)) {
            (SettingsField::T0, _) => "time.t0".into(),
            (SettingsField::ReplayStep, _) => "checks.replay_step".into(),
            (_, Some(s)) => format!("{}.{name}", s.table),
            _ => format!("settings.{name}"),
        }
    }
}

/// A span or setting that would make the solve meaningless or unbounded.
#[derive(Clone, Debug, PartialEq)]
pub struct SettingsError {
    /// Which setting.
    pub field: SettingsField,
    /// Its value (as f64; counts are converted).
    pub value: f64,
    /// What is wrong, without the field's name.
    pub message: String,
}

impl fmt::Display for SettingsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.field.key(), self.message)
    }
}

impl std::error::Error for SettingsError {}

fn err(field: SettingsField, value: f64, message: impl Into<String>) -> SettingsError {
    SettingsError {
        field,
        value,
        message: message.into(),
    }
}

fn positive(field: SettingsField, x: f64) -> Result<(), SettingsError> {
    if x > 0.0 && x.is_finite() {
        Ok(())
    } else {
        Err(err(field, x, format!("must be positive, got {x:?}")))
    }
}

fn finite(field: SettingsField, x: f64) -> Result<(), SettingsError> {
    if x.is_finite() {
        Ok(())
    } else {
        Err(err(field, x, format!("must be a finite number, got {x:?}")))
    }
}

/// Bound of a trajectory kept in memory (the Python API's `Scene.solve`, the check's reference
/// solves): 1 GiB of samples (`values_per_sample` doubles each; numpy's copy doubles it at the
/// peak). `progmo solve` streams its samples to files and is bounded by `max_samples` alone.
pub const IN_MEMORY_LIMIT_BYTES: usize = 1 << 30;

/// Samples of `values_per_sample` doubles that fit in [`IN_MEMORY_LIMIT_BYTES`].
pub fn in_memory_samples(values_per_sample: usize) -> usize {
    IN_MEMORY_LIMIT_BYTES / (8 * values_per_sample.max(1))
}

/// Check that a solve kept in memory fits [`IN_MEMORY_LIMIT_BYTES`] before integrating: with
/// `output_dt` the number of samples is known and is refused naming `output_dt`; without it
/// (a sample per accepted step) the sink stops the solve at the bound
/// ([`crate::output::Bounded`]).
pub fn validate_in_memory(
    span: (f64, f64),
    s: &Settings,
    values_per_sample: usize,
) -> Result<(), SettingsError> {
    if let Output::Every(dt) = s.output {
        let n = intervals(span, dt) + 1.0;
        let fit = in_memory_samples(values_per_sample);
        if n > fit as f64 {
            return Err(err(
                SettingsField::OutputDt,
                dt,
                format!(
                    "{dt:?} gives {n:.3e} samples of {values_per_sample} values over [{:?}, {:?}]: \
                     {:.2} GiB in memory, over the limit of {} GiB ({fit} samples); raise output_dt, \
                     shorten t1, or stream to files with `progmo solve`",
                    span.0,
                    span.1,
                    n * 8.0 * values_per_sample as f64 / (1u64 << 30) as f64,
                    IN_MEMORY_LIMIT_BYTES >> 30
                ),
            ));
        }
    }
    Ok(())
}

/// A step `h` must move time at both ends of the span (`t + h > t` in floating point).
fn advances(field: SettingsField, (t0, t1): (f64, f64), h: f64) -> Result<(), SettingsError> {
    for t in [t0, t1] {
        if t + h == t {
            return Err(err(
                field,
                h,
                format!("{h:?} cannot advance time: t + {h:?} == t at t = {t:?}"),
            ));
        }
    }
    Ok(())
}

/// Number of intervals of width `h` in the span, rounded up (saturating).
fn intervals((t0, t1): (f64, f64), h: f64) -> f64 {
    ((t1 - t0) / h).ceil()
}

/// Check the check's replay step `h` over `span`: its reference solve samples every h / 2
/// ([`validate`] with that spacing), so a step that cannot advance time or gives more than
/// `max_samples` samples is refused naming the step ([`SettingsField::ReplayStep`]), not the
/// spacing derived from it.
pub fn validate_replay_step(span: (f64, f64), h: f64, s: &Settings) -> Result<(), SettingsError> {
    use SettingsField::*;
    positive(ReplayStep, h)?;
    advances(ReplayStep, span, h)?;
    let sampled = Settings {
        output: Output::Every(h / 2.0),
        ..s.clone()
    };
    validate(span, &sampled).map_err(|e| match e.field {
        OutputDt => err(
            ReplayStep,
            h,
            format!(
                "{h:?}: its reference solve samples every h/2 = {:?}: {}",
                h / 2.0,
                e.message
            ),
        ),
        _ => e,
    })
}

/// Check a time span and settings before integrating. Refuses non-finite spans, t1 <= t0,
/// non-finite or non-positive step sizes and tolerances, steps and output spacings that cannot
/// advance time, more output samples than [`Settings::max_samples`], and fixed-step runs of more
/// steps than [`Settings::max_steps`].
pub fn validate(span: (f64, f64), s: &Settings) -> Result<(), SettingsError> {
    use SettingsField::*;
    let (t0, t1) = span;
    finite(T0, t0)?;
    if !t1.is_finite() {
        return Err(err(T1, t1, format!("must be a finite number, got {t1:?}")));
    }
    if t1.partial_cmp(&t0) != Some(std::cmp::Ordering::Greater) {
        return Err(err(
            T1,
            t1,
            format!("t1 = {t1:?} must be after t0 = {t0:?}"),
        ));
    }
    if s.max_samples < 2 {
        return Err(err(
            MaxSamples,
            s.max_samples as f64,
            format!("must be at least 2 (t0 and t1), got {}", s.max_samples),
        ));
    }
    if s.max_steps == 0 {
        return Err(err(MaxSteps, 0.0, "must be at least 1"));
    }
    if let Output::Every(dt) = s.output {
        positive(OutputDt, dt)?;
        advances(OutputDt, span, dt)?;
        let n = intervals(span, dt) + 1.0;
        if n > s.max_samples as f64 {
            return Err(err(
                OutputDt,
                dt,
                format!(
                    "{dt:?} gives {n:.3e} samples over [{t0:?}, {t1:?}], more than max_samples = {} \
                     (raise max_samples or the spacing)",
                    s.max_samples
                ),
            ));
        }
    }
    let fixed = |field: SettingsField, h: f64| -> Result<(), SettingsError> {
        positive(field, h)?;
        advances(field, span, h)?;
        let n = intervals(span, h);
        if n > s.max_steps as f64 {
            return Err(err(
                field,
                h,
                format!(
                    "{h:?} needs {n:.3e} steps over [{t0:?}, {t1:?}], more than max_steps = {}",
                    s.max_steps
                ),
            ));
        }
        Ok(())
    };
    if let Method::Rk4 { h } = s.integrator {
        fixed(Step, h)?;
    }
    if let Some(h) = s.fixed_step {
        fixed(FixedStep, h)?;
    }
    positive(Rtol, s.rtol)?;
    positive(Atol, s.atol)?;
    if s.max_step.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Err(err(
            MaxStep,
            s.max_step,
            format!("must be positive, got {:?}", s.max_step),
        ));
    }
    match s.drift {
        DriftControl::Projection { tol, .. } => positive(ProjectionTol, tol)?,
        DriftControl::Baumgarte { alpha, beta } => {
            finite(BaumgarteAlpha, alpha)?;
            finite(BaumgarteBeta, beta)?;
        }
        DriftControl::None => {}
    }
    if let Some(x) = s.max_drift {
        positive(MaxDrift, x)?;
    }
    positive(ConsistencyTol, s.consistency_tol)?;
    positive(RankDependent, s.rank_dependent)?;
    positive(RankVanishing, s.rank_vanishing)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(span: (f64, f64), s: &Settings) -> Option<SettingsField> {
        validate(span, s).err().map(|e| e.field)
    }

    /// `progmo check --step 1e-300` named `output_dt` (the spacing the check derives from it).
    #[test]
    fn a_replay_step_is_named_as_itself() {
        let d = Settings::default();
        for h in [1e-300, 0.0, -1.0, f64::NAN, 1e-12] {
            let e = validate_replay_step((0.0, 1.0), h, &d).expect_err("refused");
            assert_eq!(e.field, SettingsField::ReplayStep, "{h}: {e}");
            assert_eq!(e.field.name(), "replay_step");
        }
        assert_eq!(validate_replay_step((0.0, 1.0), 1e-3, &d), Ok(()));
    }

    #[test]
    fn defaults_over_a_normal_span_pass() {
        assert_eq!(validate((0.0, 10.0), &Settings::default()), Ok(()));
    }

    #[test]
    fn each_bad_value_is_named() {
        use SettingsField::*;
        let d = Settings::default();
        let every = |dt| Settings {
            output: Output::Every(dt),
            ..d.clone()
        };
        let rk4 = |h| Settings {
            integrator: Method::Rk4 { h },
            ..d.clone()
        };
        assert_eq!(field((0.0, f64::INFINITY), &d), Some(T1));
        assert_eq!(field((0.0, f64::NAN), &d), Some(T1));
        assert_eq!(field((1.0, 1.0), &d), Some(T1));
        assert_eq!(field((f64::NAN, 1.0), &d), Some(T0));
        assert_eq!(field((0.0, 1.0), &every(1e-300)), Some(OutputDt));
        assert_eq!(field((0.0, 1.0), &every(f64::NAN)), Some(OutputDt));
        assert_eq!(field((0.0, 1e9), &every(1e-3)), Some(OutputDt));
        assert_eq!(field((0.0, 1.0), &rk4(1e-300)), Some(Step));
        for h in [f64::NAN, 0.0, -1.0, f64::INFINITY] {
            assert_eq!(field((0.0, 1.0), &rk4(h)), Some(Step), "step {h}");
        }
        let baumgarte = Settings {
            drift: DriftControl::Baumgarte {
                alpha: f64::NAN,
                beta: 1.0,
            },
            ..d.clone()
        };
        assert_eq!(field((0.0, 1.0), &baumgarte), Some(BaumgarteAlpha));
        let rtol = Settings {
            rtol: 0.0,
            ..d.clone()
        };
        assert_eq!(field((0.0, 1.0), &rtol), Some(Rtol));
    }

    #[test]
    fn the_sample_limit_is_exact_and_overridable() {
        // [0, 1] at 0.25: samples 0, 0.25, 0.5, 0.75, 1.
        let s = |max_samples| Settings {
            output: Output::Every(0.25),
            max_samples,
            ..Settings::default()
        };
        assert_eq!(validate((0.0, 1.0), &s(5)), Ok(()));
        assert_eq!(field((0.0, 1.0), &s(4)), Some(SettingsField::OutputDt));
        assert_eq!(
            validate(
                (0.0, 1e9),
                &Settings {
                    output: Output::Every(1e-3),
                    max_samples: 2_000_000_000_000,
                    ..Settings::default()
                }
            ),
            Ok(())
        );
    }

    #[test]
    fn messages_name_the_field_and_the_value() {
        let e = validate((0.0, f64::INFINITY), &Settings::default()).unwrap_err();
        assert_eq!(e.to_string(), "time.t1: must be a finite number, got inf");
        assert_eq!(e.field.name(), "t1");
    }
}
