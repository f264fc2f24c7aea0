//! Sink adapters: [`Tee`] (two sinks), [`Every`] (decimation by time), [`StopOn`] (a stop
//! request from a flag, e.g. set by a signal handler) and [`Bounded`] (an in-memory trajectory
//! with a size bound).

use std::sync::atomic::{AtomicBool, Ordering};

use super::{OutputError, OutputSink, OwnedSample};
use crate::solve::{Sample, SampleSink};

/// Feeds every sample to two sinks (nest for more).
pub struct Tee<A, B> {
    /// First sink.
    pub a: A,
    /// Second sink.
    pub b: B,
}

impl<A: SampleSink, B: SampleSink> Tee<A, B> {
    /// Feed `a` then `b`.
    pub fn new(a: A, b: B) -> Self {
        Tee { a, b }
    }
    /// The two sinks.
    pub fn into_parts(self) -> (A, B) {
        (self.a, self.b)
    }
}

impl<A: SampleSink, B: SampleSink> SampleSink for Tee<A, B> {
    fn sample(&mut self, s: &Sample<'_>) {
        self.a.sample(s);
        self.b.sample(s);
    }
    fn warning(&mut self, w: &crate::solve::Warning) {
        self.a.warning(w);
        self.b.warning(w);
    }
    fn interrupted(&self) -> bool {
        self.a.interrupted() || self.b.interrupted()
    }
}

impl<A: OutputSink, B: OutputSink> OutputSink for Tee<A, B> {
    /// Finishes both; returns the first sink's error if both fail.
    fn finish(&mut self) -> Result<(), OutputError> {
        let ra = self.a.finish();
        let rb = self.b.finish();
        ra.and(rb)
    }
}

/// Passes samples at most every `dt` of sample time: the first sample, then each sample at least
/// `dt` after the last one passed (with a relative slack of 1e-9 dt, so that samples on a grid of
/// step dt all pass). The last sample received is held and passed by [`Every::flush_last`]
/// (called by `finish` and `into_inner`) unless it was passed already.
pub struct Every<S> {
    dt: f64,
    inner: S,
    last_passed: Option<f64>,
    held: OwnedSample,
    holding: bool,
}

impl<S: SampleSink> Every<S> {
    /// Decimate to one sample per `dt` (dt <= 0 passes everything).
    pub fn new(dt: f64, inner: S) -> Self {
        Every {
            dt,
            inner,
            last_passed: None,
            held: OwnedSample::default(),
            holding: false,
        }
    }

    /// Pass the held last sample, if any.
    pub fn flush_last(&mut self) {
        if self.holding {
            self.holding = false;
            self.last_passed = Some(self.held.t);
            self.inner.sample(&self.held.as_sample());
        }
    }

    /// The wrapped sink (not flushed).
    pub fn inner(&self) -> &S {
        &self.inner
    }

    /// Pass the held last sample and return the wrapped sink.
    pub fn into_inner(mut self) -> S {
        self.flush_last();
        self.inner
    }
}

impl<S: SampleSink> SampleSink for Every<S> {
    fn sample(&mut self, s: &Sample<'_>) {
        let pass = match self.last_passed {
            None => true,
            Some(t) => s.t - t >= self.dt * (1.0 - 1e-9),
        };
        if pass {
            self.holding = false;
            self.last_passed = Some(s.t);
            self.inner.sample(s);
        } else {
            self.held.set(s);
            self.holding = true;
        }
    }
    fn warning(&mut self, w: &crate::solve::Warning) {
        self.inner.warning(w);
    }
    fn interrupted(&self) -> bool {
        self.inner.interrupted()
    }
}

impl<S: OutputSink> OutputSink for Every<S> {
    fn finish(&mut self) -> Result<(), OutputError> {
        self.flush_last();
        self.inner.finish()
    }
}

/// Forwards everything to `inner` and asks the solve to stop
/// ([`SampleSink::interrupted`]) once `flag` is set.
pub struct StopOn<'a, S> {
    inner: S,
    flag: &'a AtomicBool,
}

impl<'a, S: SampleSink> StopOn<'a, S> {
    /// Stop when `flag` becomes true.
    pub fn new(inner: S, flag: &'a AtomicBool) -> Self {
        StopOn { inner, flag }
    }
    /// The wrapped sink.
    pub fn into_inner(self) -> S {
        self.inner
    }
}

impl<S: SampleSink> SampleSink for StopOn<'_, S> {
    fn sample(&mut self, s: &Sample<'_>) {
        self.inner.sample(s);
    }
    fn warning(&mut self, w: &crate::solve::Warning) {
        self.inner.warning(w);
    }
    fn interrupted(&self) -> bool {
        self.flag.load(Ordering::Relaxed) || self.inner.interrupted()
    }
}

impl<S: OutputSink> OutputSink for StopOn<'_, S> {
    fn finish(&mut self) -> Result<(), OutputError> {
        self.inner.finish()
    }
}

/// A trajectory kept in memory, bounded to `limit` samples: at the bound it asks the solve to stop
/// ([`SampleSink::interrupted`]) and [`Bounded::full`] says so (the caller then reports the bound,
/// keeping the samples taken). The in-memory doors size it with
/// [`crate::solve::in_memory_samples`].
pub struct Bounded {
    inner: crate::solve::Trajectory,
    limit: usize,
}

impl Bounded {
    /// At most `limit` samples.
    pub fn new(inner: crate::solve::Trajectory, limit: usize) -> Self {
        Bounded { inner, limit }
    }
    /// The bound was reached.
    pub fn full(&self) -> bool {
        self.inner.len() >= self.limit
    }
    /// The bound.
    pub fn limit(&self) -> usize {
        self.limit
    }
    /// The samples taken.
    pub fn into_inner(self) -> crate::solve::Trajectory {
        self.inner
    }
}

impl SampleSink for Bounded {
    fn sample(&mut self, s: &Sample<'_>) {
        if !self.full() {
            SampleSink::sample(&mut self.inner, s);
        }
    }
    fn interrupted(&self) -> bool {
        self.full()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::testutil::{feed, layout};
    use crate::solve::Trajectory;

    #[test]
    fn tee_feeds_both() {
        let l = layout();
        let mut tee = Tee::new(l.trajectory(), l.trajectory());
        feed(&mut tee, &l, 5, 0.1);
        tee.finish().unwrap();
        let (a, b) = tee.into_parts();
        assert_eq!(a.len(), 5);
        assert_eq!(a, b);
    }

    /// A solve with a sample per step into a bound of 5 samples stops there, interrupted, with
    /// the 5 samples kept; a bound above the solve's samples leaves it whole (negative control).
    #[test]
    fn bounded_stops_the_solve_at_its_bound() {
        use crate::solve::{solve, solve_into, Output, ReturnCode, Settings};
        let p = crate::problems::pendulum::double_pendulum();
        let s = Settings {
            output: Output::Steps,
            ..Settings::default()
        };
        let mut b = Bounded::new(Trajectory::named_for(&p), 5);
        let sol = solve_into(&p, &s, &mut b);
        assert!(
            matches!(sol.code, ReturnCode::Interrupted { .. }),
            "{:?}",
            sol.code
        );
        assert!(b.full());
        let kept = b.into_inner();
        assert_eq!(kept.len(), 5);
        let whole = solve(&p, &s).trajectory;
        assert_eq!(kept.t[..], whole.t[..5]);
        let mut b = Bounded::new(Trajectory::named_for(&p), whole.len() + 1);
        assert!(solve_into(&p, &s, &mut b).code.is_success());
        assert!(!b.full());
        assert_eq!(b.into_inner().t, whole.t);
    }

    fn times(dt: f64, step: f64, n: usize) -> Vec<f64> {
        let l = layout();
        let mut e = Every::new(dt, l.trajectory());
        feed(&mut e, &l, n, step);
        e.finish().unwrap();
        let t = e.inner().t.clone();
        // Finishing again, or into_inner, passes nothing more.
        e.finish().unwrap();
        assert_eq!(e.into_inner().t, t);
        t
    }

    #[test]
    fn every_decimates_and_keeps_first_and_last() {
        // Steps of 0.1 over [0, 2.0]; dt = 0.25 -> 0, 0.3, 0.6, 0.9, 1.2, 1.5, 1.8, then last 2.0.
        let t = times(0.25, 0.1, 21);
        let expect: Vec<f64> = [0, 3, 6, 9, 12, 15, 18, 20]
            .iter()
            .map(|&k| k as f64 * 0.1)
            .collect();
        assert_eq!(t, expect);
        // Samples on the grid all pass despite rounding (k * 0.1 vs multiples of 0.1).
        assert_eq!(times(0.1, 0.1, 11).len(), 11);
        // The last one passes once only when it was passed already.
        assert_eq!(times(0.2, 0.1, 11).len(), 6);
        // A single sample.
        assert_eq!(times(1.0, 0.1, 1), vec![0.0]);
        // Nothing.
        assert!(times(1.0, 0.1, 0).is_empty());
    }

    #[test]
    fn every_holds_full_sample_values() {
        let l = layout();
        let mut all = l.trajectory();
        feed(&mut all, &l, 10, 0.1);
        let mut e = Every::new(100.0, Trajectory::default());
        e.inner.q_names = l.q_names.clone();
        e.inner.v_names = l.v_names.clone();
        e.inner.row_names = l.row_names.clone();
        feed(&mut e, &l, 10, 0.1);
        let got = e.into_inner();
        assert_eq!(got.len(), 2);
        assert_eq!(got.q_at(1), all.q_at(9));
        assert_eq!(got.residual_at(1), all.residual_at(9));
        assert_eq!(got.reactions_at(1), all.reactions_at(9));
    }
}
