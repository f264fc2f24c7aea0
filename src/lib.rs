//! progmo: programmed motions of mechanical systems and the control forces that realize them.
//!
//! Method: Do Sanh, "A method of constructing programmed motions of a mechanical system",
//! Vietnam Journal of Mechanics XX (1998) 46-57. A programme g(t, q, v) = 0 is treated as a set of
//! ideal constraints; with D an orthonormal basis of the null space of B = dg/dv,
//! D A dv/dt = D (G + Q) (2.8)-(2.10) and the differentiated programme give dv/dt without inverting
//! A, and the control force is u = A dv/dt - G - Q (2.12).
//!
//! Use on its own (`progmo = { path = "..." }`): load a scene file, solve it, read the motion and
//! the control forces (this example runs as a doctest):
//!
//! ```
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! # std::env::set_current_dir(env!("CARGO_MANIFEST_DIR"))?;
//! let scene = progmo::scene::Scene::load("references/scenes/double_pendulum.toml")?;
//! let sol = scene.solve(&scene.settings);
//! assert!(sol.code.is_success());
//! println!("u at t1: {:?}", sol.trajectory.u_at(sol.trajectory.len() - 1));
//! # Ok(())
//! # }
//! ```
//!
//! Failures of the entry points convert into one [`Error`] (typed variants, structured fields).
//!
//! See `ARCHITECTURE.md` for the map of modules.

/// Git revision of this build (empty outside a checkout): provenance of summaries and reports.
pub const GIT_REVISION: &str = env!("PROGMO_GIT_REVISION");

pub mod check;
pub mod cli;
pub mod error;
pub mod export;
pub mod expr;
pub mod formulation;
#[doc(hidden)]
pub mod fuzzing;
pub mod import;
pub mod input;
pub mod integrate;
pub mod interrupt;
pub mod lie;
pub mod linalg;
pub mod located;
pub mod model;
pub mod output;
pub mod problems;
pub mod programme;
pub mod scalar;
pub mod scene;
pub mod servo;
pub mod solve;
pub mod taylor;
pub mod tree;

pub use error::{Error, Result};
