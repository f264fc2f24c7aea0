//! Programmes and system constraints: rows g = 0 at three levels, and their exact derivatives.
//!
//! A programme (2.3) is a set of s < n rows treated as ideal constraints whose reactions are the
//! control forces. A system may also carry constraints of its own (closed loops, rolling) whose
//! reactions are joint forces. Both kinds enter the same formulation and differ only in how their
//! reactions are reported ([`Role`]).
//!
//! Each row is one of
//! - position level g(t, q) = 0 (holonomic), differentiated twice;
//! - velocity level g(t, q, v) = 0, possibly nonlinear in v (2.3), differentiated once;
//! - acceleration level h(t, q, v, dv/dt) = 0, linear in dv/dt (Example 3.1, (3.14)).
//!
//! Every row contributes one line of B dv/dt = gamma, obtained exactly by forward-mode AD
//! ([`jet`]): B = dg/dv (2.6) for velocity rows, B = g_q N(q) for position rows, B = dh/d(dv/dt)
//! for acceleration rows.

pub mod actuation;
pub mod jet;

use crate::model::Segment;
use crate::scalar::Scalar;

/// At which level a row constrains the motion.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Level {
    /// g(t, q) = 0.
    Position,
    /// g(t, q, v) = 0.
    Velocity,
    /// h(t, q, v, dv/dt) = 0, linear in dv/dt.
    Acceleration,
}

/// Whose reaction a row's multiplier is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// A row of the programme: its reaction is a control force u.
    Programme,
    /// A constraint of the system itself: its reaction is a joint force, not a control.
    System,
}

/// Description of one row.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RowSpec {
    /// Name used in outputs (`residual:<name>`).
    pub name: String,
    /// Level of the row.
    pub level: Level,
    /// Programme row or system constraint.
    pub role: Role,
}

impl RowSpec {
    /// A row description.
    pub fn new(name: &str, level: Level, role: Role) -> Self {
        RowSpec {
            name: name.to_string(),
            level,
            role,
        }
    }
}

/// The rows of a programme together with the system's own constraints.
pub trait Constraints: Send + Sync {
    /// Scratch space for evaluations over scalar type `S`.
    type Workspace<S: Scalar>: Send + 'static;

    /// Allocate a workspace for scalar type `S`.
    fn workspace<S: Scalar>(&self) -> Self::Workspace<S>;

    /// The rows, in order.
    fn rows(&self) -> &[RowSpec];

    /// Evaluate every row at (t, q, v, a) into `out` (one entry per row). Position rows must read
    /// only t and q, velocity rows only t, q and v; acceleration rows must be linear in `a`.
    fn eval<S: Scalar>(
        &self,
        ws: &mut Self::Workspace<S>,
        t: S,
        q: &[S],
        v: &[S],
        a: &[S],
        out: &mut [S],
    );

    /// B, gamma, the row values and dg/dt (the outputs of [`jet::Jet`]) in one go, for constraints
    /// that know their structure better than generic AD passes over [`Constraints::eval`] (scene
    /// rows: chain rule through their slots, [`crate::scene`]). Return `false` (the default) to let
    /// [`jet::Jet`] run the generic passes. `ws` is a workspace over `S` itself. `sweep`: the
    /// model's tree and forward passes ([`crate::model::Model::tree_sweep`]), which constraints on
    /// the same tree read instead of running their own (the same values: the passes recompute
    /// whatever is stale).
    #[allow(unused_variables, clippy::too_many_arguments)]
    fn jet<S: Scalar>(
        &self,
        ws: &mut Self::Workspace<S>,
        segments: &[Segment],
        t: S,
        q: &[S],
        v: &[S],
        out: jet::JetRows<'_, S>,
        sweep: Option<crate::tree::TreeSweep<'_, S>>,
    ) -> bool {
        false
    }

    /// The actuators that must realize the programme (servo-constraints, [`actuation`]), or
    /// `None` (the default) for the ideal realization of (2.7).
    fn actuation(&self) -> Option<&actuation::Actuation> {
        None
    }
}

/// No constraints at all (the natural system).
#[derive(Clone, Debug, Default)]
pub struct Unconstrained;

impl Constraints for Unconstrained {
    type Workspace<S: Scalar> = ();
    fn workspace<S: Scalar>(&self) -> Self::Workspace<S> {}
    fn rows(&self) -> &[RowSpec] {
        &[]
    }
    fn eval<S: Scalar>(&self, _: &mut (), _: S, _: &[S], _: &[S], _: &[S], _: &mut [S]) {}
}
