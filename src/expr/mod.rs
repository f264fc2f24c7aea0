//! Expressions of scene files: parsed once, compiled to bytecode, evaluated over any [`crate::scalar::Scalar`].
