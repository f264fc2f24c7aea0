//! Body-point signals of tree scenes (positions, velocities, accelerations of named sites); empty
//! for Lagrangian scenes.

use crate::scalar::Scalar;

/// The signals a scene's expressions read, computed before each evaluation.
#[derive(Clone, Debug, Default)]
pub struct Signals {
    count: usize,
}

/// Scratch for computing signals.
pub struct SignalWork<S: Scalar> {
    _s: std::marker::PhantomData<S>,
}

impl Signals {
    /// No signals.
    pub fn none() -> Self {
        Signals { count: 0 }
    }
    /// Number of signal slots.
    pub fn len(&self) -> usize {
        self.count
    }
    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
    /// Allocate scratch.
    pub fn work<S: Scalar>(&self) -> SignalWork<S> {
        SignalWork {
            _s: std::marker::PhantomData,
        }
    }
    /// Compute all signals at (q, v, a) into `out`.
    pub fn fill<S: Scalar>(&self, _w: &mut SignalWork<S>, _q: &[S], _v: &[S], _a: &[S], _out: &mut [S]) {}
}
