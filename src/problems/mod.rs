//! The library of test problems shared by tests, benchmarks and the harness.
//!
//! Each problem is a model, its constraints, a consistent initial state and, where one exists, an
//! independent reference (closed form or invariant) with its provenance in the doc comment.
//! - [`hard`]: hard cases for numerical stability (singular programmes, stiff springs, ...).
//! - [`particle`]: Example 2.1 of the paper (particle in a Newtonian field at constant speed).
//! - [`rigid_body`]: Example 3.1 (generalized precession of a rigid body), free and heavy top.
//! - [`pendulum`]: a double pendulum with a time-dependent holonomic programme, and a Cartesian
//!   pendulum whose rod is a system constraint and whose motion is a complete programme.

pub mod hard;
pub mod particle;
pub mod pendulum;
pub mod rigid_body;

/// Implements `Model::{nq, nv, segments, q_names, v_names}` for a fixed set of Euclidean coordinates.
macro_rules! euclidean_names {
    ($names:expr) => {
        fn nq(&self) -> usize {
            $names.len()
        }
        fn nv(&self) -> usize {
            $names.len()
        }
        fn segments(&self) -> &[$crate::model::Segment] {
            const SEG: [$crate::model::Segment; 1] = [$crate::model::Segment::Euclidean {
                q: 0,
                v: 0,
                len: $names.len(),
            }];
            &SEG
        }
        fn q_names(&self) -> Vec<String> {
            $names.iter().map(|s| s.to_string()).collect()
        }
        fn v_names(&self) -> Vec<String> {
            $names.iter().map(|s| s.to_string()).collect()
        }
    };
}
pub(crate) use euclidean_names;
