//! Progress bar over the sample time.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use super::{OutputError, OutputSink};
use crate::solve::{Sample, SampleSink};

/// Resolution of the bar (positions over [t0, t1]).
const TICKS: u64 = 1000;
/// Minimum interval between updates.
const INTERVAL: Duration = Duration::from_millis(100);

/// Wraps a sink and shows a progress bar on stderr over [t0, t1], keyed on the sample time, with
/// the message `<scene> t=<t> max|res|=<largest |residual| so far>`. Silent (no bar, no
/// bookkeeping beyond forwarding) when stderr is not a terminal or when disabled; the bar appears
/// at the first sample and is updated at most 10 times per second.
pub struct Progress<S> {
    inner: S,
    /// Show a bar: stderr is a terminal and the bar is not disabled.
    show: bool,
    bar: Option<ProgressBar>,
    scene: String,
    t0: f64,
    t1: f64,
    last_t: f64,
    max_residual: f64,
    last_update: Option<Instant>,
}

impl<S: SampleSink> Progress<S> {
    /// A bar for `scene` over [t0, t1] if stderr is a terminal.
    pub fn new(inner: S, scene: &str, t0: f64, t1: f64) -> Self {
        Progress {
            inner,
            show: std::io::stderr().is_terminal(),
            bar: None,
            scene: scene.to_string(),
            t0,
            t1,
            last_t: t0,
            max_residual: 0.0,
            last_update: None,
        }
    }

    /// Enable or disable the bar (it is never shown when stderr is not a terminal).
    pub fn enabled(mut self, enabled: bool) -> Self {
        self.show &= enabled;
        if !self.show {
            if let Some(b) = self.bar.take() {
                b.finish_and_clear();
            }
        }
        self
    }

    /// True when a bar is (to be) shown.
    pub fn is_active(&self) -> bool {
        self.show
    }

    /// Largest |residual| seen so far (tracked only while the bar is active).
    pub fn max_residual(&self) -> f64 {
        self.max_residual
    }

    /// The wrapped sink.
    pub fn inner(&self) -> &S {
        &self.inner
    }

    /// Remove the bar and return the wrapped sink.
    pub fn into_inner(mut self) -> S {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
        self.inner
    }

    fn position(&self, t: f64) -> u64 {
        let span = self.t1 - self.t0;
        let f = if span > 0.0 {
            ((t - self.t0) / span).clamp(0.0, 1.0)
        } else {
            1.0
        };
        (f * TICKS as f64).round() as u64
    }

    fn update(&mut self, t: f64) {
        if let Some(bar) = &self.bar {
            bar.set_position(self.position(t));
            bar.set_message(format!(
                "{} t={:.6} max|res|={:.3e}",
                self.scene, t, self.max_residual
            ));
        }
    }
}

impl<S: SampleSink> SampleSink for Progress<S> {
    fn warning(&mut self, w: &crate::solve::Warning) {
        self.inner.warning(w);
    }
    fn interrupted(&self) -> bool {
        self.inner.interrupted()
    }
    fn sample(&mut self, s: &Sample<'_>) {
        self.inner.sample(s);
        if !self.show {
            return;
        }
        if self.bar.is_none() {
            let bar =
                ProgressBar::with_draw_target(Some(TICKS), ProgressDrawTarget::stderr_with_hz(10));
            if let Ok(style) =
                ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {percent:>3}% {msg}")
            {
                bar.set_style(style.progress_chars("=> "));
            }
            self.bar = Some(bar);
        }
        self.last_t = s.t;
        for r in s.residual {
            // NaN sticks: a non-finite residual should show.
            let a = r.abs();
            if a.is_nan() || a > self.max_residual {
                self.max_residual = a;
            }
        }
        let now = Instant::now();
        if self
            .last_update
            .is_none_or(|last| now.duration_since(last) >= INTERVAL)
        {
            self.last_update = Some(now);
            self.update(s.t);
        }
    }
}

impl<S: OutputSink> OutputSink for Progress<S> {
    /// Finishes the wrapped sink, then leaves the bar at its final state.
    fn finish(&mut self) -> Result<(), OutputError> {
        let r = self.inner.finish();
        self.update(self.last_t);
        if let Some(bar) = self.bar.take() {
            bar.finish();
        }
        self.show = false;
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::testutil::{feed, layout};

    #[test]
    fn disabled_progress_forwards_everything() {
        let l = layout();
        let mut p = Progress::new(l.trajectory(), "scene", 0.0, 1.0).enabled(false);
        assert!(!p.is_active());
        feed(&mut p, &l, 50, 0.02);
        p.finish().unwrap();
        let mut expect = l.trajectory();
        feed(&mut expect, &l, 50, 0.02);
        assert_eq!(p.inner(), &expect);
    }

    #[test]
    fn progress_tracks_the_max_residual_when_active() {
        // Active only when stderr is a terminal; forwarding holds either way.
        let l = layout();
        let mut p = Progress::new(l.trajectory(), "scene", 0.0, 1.0);
        feed(&mut p, &l, 200, 0.005);
        if p.is_active() {
            let mut all = l.trajectory();
            feed(&mut all, &l, 200, 0.005);
            assert_eq!(
                p.max_residual(),
                all.residual.iter().fold(0.0, |m, r| r.abs().max(m))
            );
        } else {
            assert_eq!(p.max_residual(), 0.0);
        }
        p.finish().unwrap();
        assert_eq!(p.into_inner().len(), 200);
    }

    #[test]
    fn positions_cover_the_span() {
        let p = Progress::new(crate::solve::Trajectory::default(), "s", 1.0, 3.0).enabled(false);
        assert_eq!(p.position(1.0), 0);
        assert_eq!(p.position(2.0), TICKS / 2);
        assert_eq!(p.position(3.0), TICKS);
        assert_eq!(p.position(9.0), TICKS);
        assert_eq!(p.position(-9.0), 0);
    }
}
