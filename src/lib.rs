//! progmo: programmed motions of mechanical systems and the control forces that realize them.
//!
//! Method: Do Sanh, "A method of constructing programmed motions of a mechanical system",
//! Vietnam Journal of Mechanics XX (1998) 46-57. A programme g(t, q, v) = 0 is treated as a set of
//! ideal constraints; with D an orthonormal basis of the null space of B = dg/dv,
//! D A dv/dt = D (G + Q) (2.8)-(2.10) and the differentiated programme give dv/dt without inverting
//! A, and the control force is u = A dv/dt - G - Q (2.12).
//!
//! See `ARCHITECTURE.md` for the map of modules.

pub mod cli;
pub mod export;
pub mod expr;
pub mod formulation;
#[doc(hidden)]
pub mod fuzzing;
pub mod integrate;
pub mod interrupt;
pub mod linalg;
pub mod model;
pub mod output;
pub mod problems;
pub mod programme;
pub mod scalar;
pub mod scene;
pub mod solve;
pub mod tree;
