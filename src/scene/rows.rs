//! Programme rows and system constraints of a scene, as compiled expressions.
//!
//! A row's level is the highest level among the symbols it reads (q: position, v: velocity,
//! dv/dt: acceleration; body-point signals by their derivative order). Acceleration rows are
//! checked to be linear in dv/dt when the scene is loaded.

use super::layout::Layout;
use super::signals::{SignalWork, Signals};
use crate::expr::Expr;
use crate::programme::{Constraints, RowSpec};
use crate::scalar::Scalar;

/// Rows as expressions over the scene's slots.
#[derive(Clone, Debug)]
pub struct ExprConstraints {
    specs: Vec<RowSpec>,
    exprs: Vec<Expr>,
    layout: Layout,
    signals: Signals,
    max_stack: usize,
}

/// Scratch of an [`ExprConstraints`] evaluation.
pub struct RowsWork<S: Scalar> {
    slots: Vec<S>,
    stack: Vec<S>,
    signals: SignalWork<S>,
}

impl ExprConstraints {
    /// Rows with their specs (name, level, role) and expressions.
    pub fn new(specs: Vec<RowSpec>, exprs: Vec<Expr>, layout: Layout, signals: Signals) -> Self {
        let max_stack = exprs.iter().map(|e| e.max_stack()).max().unwrap_or(1);
        ExprConstraints {
            specs,
            exprs,
            layout,
            signals,
            max_stack,
        }
    }

    /// The expressions, in row order.
    pub fn exprs(&self) -> &[Expr] {
        &self.exprs
    }
}

impl Constraints for ExprConstraints {
    type Workspace<S: Scalar> = RowsWork<S>;

    fn workspace<S: Scalar>(&self) -> RowsWork<S> {
        RowsWork {
            slots: vec![S::zero(); self.layout.slots + self.signals.len()],
            stack: Vec::with_capacity(self.max_stack),
            signals: self.signals.work(),
        }
    }

    fn rows(&self) -> &[RowSpec] {
        &self.specs
    }

    fn eval<S: Scalar>(
        &self,
        ws: &mut RowsWork<S>,
        t: S,
        q: &[S],
        v: &[S],
        a: &[S],
        out: &mut [S],
    ) {
        let l = &self.layout;
        ws.slots[l.t] = t;
        ws.slots[l.q..l.q + l.nq].copy_from_slice(q);
        ws.slots[l.v..l.v + l.nv].copy_from_slice(v);
        ws.slots[l.a..l.a + l.nv].copy_from_slice(a);
        self.signals
            .fill(&mut ws.signals, q, v, a, &mut ws.slots[l.signals..]);
        for (o, e) in out.iter_mut().zip(&self.exprs) {
            *o = e.eval(&ws.slots, &mut ws.stack);
        }
    }
}
