//! Where each symbol of a scene's expressions lives in the slot array.
//!
//! Slots: `t`; the configuration coordinates q; the velocities v; the accelerations dv/dt; then
//! body-point signals of tree scenes. Expression names: a coordinate `x` and its derivatives
//! `x'`, `x''` where the velocity is the derivative of a coordinate; otherwise (angular velocities
//! of ball and free joints, which are quasi-velocities) the velocity's own name `b.wx` and its
//! derivative `b.wx'`.

use crate::expr::SymbolTable;
use crate::programme::Level;

/// Slot offsets of a scene.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    pub t: usize,
    pub q: usize,
    pub v: usize,
    pub a: usize,
    pub signals: usize,
    pub slots: usize,
    pub nq: usize,
    pub nv: usize,
}

impl Layout {
    /// Insert t, q, v and a names into `symbols` (which must be empty) and return the layout.
    pub fn build(symbols: &mut SymbolTable, q_names: &[String], v_names: &[String]) -> Layout {
        assert!(symbols.is_empty(), "layout symbols first");
        let t = symbols.insert("t");
        let q = symbols.len();
        for n in q_names {
            symbols.insert(n.clone());
        }
        let v = symbols.len();
        for n in v_names {
            symbols.insert(velocity_symbol(n, q_names));
        }
        let a = symbols.len();
        for n in v_names {
            symbols.insert(format!("{}'", velocity_symbol(n, q_names)));
        }
        let signals = symbols.len();
        Layout {
            t,
            q,
            v,
            a,
            signals,
            slots: signals,
            nq: q_names.len(),
            nv: v_names.len(),
        }
    }

    /// Level of a slot: t and q are position level, v velocity, a acceleration. Signals are
    /// classified by the caller.
    pub fn level(&self, slot: usize) -> Option<Level> {
        if slot < self.v {
            Some(Level::Position)
        } else if slot < self.a {
            Some(Level::Velocity)
        } else if slot < self.signals {
            Some(Level::Acceleration)
        } else {
            None
        }
    }
}

/// The expression name of a velocity: `x'` when it is the rate of coordinate `x`, else its own name.
pub fn velocity_symbol(v_name: &str, q_names: &[String]) -> String {
    if q_names.iter().any(|q| q == v_name) {
        format!("{v_name}'")
    } else {
        v_name.to_string()
    }
}
