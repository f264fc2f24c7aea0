//! Programme rows and system constraints of a scene, as compiled expressions.
//!
//! A row's level is the highest level among the symbols it reads (q: position, v: velocity,
//! dv/dt: acceleration; body-point signals by their derivative order). Acceleration rows are
//! checked to be linear in dv/dt when the scene is loaded.
//!
//! The jet of the rows (B, gamma; [`crate::programme::jet`]) goes through the slots by the chain
//! rule instead of nv AD passes over the whole evaluation (which would re-run the tree's forward
//! kinematics per direction). Along the motion through (t, q, v) with dv/dt = 0 every slot has a
//! Taylor jet: t (t, 1, 0); q (q, N v, (dN/dt) v); v (v, 0); dv/dt 0; signals from one set of
//! forward passes ([`Signals::jets`]). A row of level L (differentiated m = 2, 1, 0 times for
//! position, velocity, acceleration) then has
//! - gamma_i = -d^m E_i/dt^m along that motion: one `Dual2`, `Dual` or plain pass over the
//!   expressions of that level;
//! - B_i = d(d^m E_i/dt^m)/d(dv/dt) = sum over the slots s of level L that E_i reads of
//!   dE_i/ds * J_s, with J_s = N(q) rows for q, unit rows for v and dv/dt, the tree's point
//!   Jacobian rows for signals; one gradient of E_i (a reverse sweep over its tape,
//!   [`Expr::gradient`]) gives every dE_i/ds (the plain computation, one `Dual` pass per slot, stays
//!   for the tests: [`ExprConstraints::set_plain_passes`]).
//!
//! A row affine in signals with constant coefficients, E = sum_k c_k s_k + F(t) (a frame task
//! such as `tcp.x - x_d(t)`, a weld's point and rotation rows; [`Expr::affine`]), skips the
//! tape where it can (issue 31, fast rows for frames): B_i = sum c_k J_k over the signals of its
//! level, no gradient; and when F is a constant (no t), value and derivatives are the signals'
//! jets combined, value = sum c_k s_k + F, d^m E/dt^m = sum c_k d^m s_k/dt^m, no pass over the
//! expression at all. Within round-off of the tape's result (the same products, summed in
//! another order).

use super::layout::Layout;
use super::signals::{SignalJets, SignalWork, Signals};
use crate::expr::Expr;
use crate::model::{lie, Segment};
use crate::programme::jet::JetRows;
use crate::programme::{Constraints, Level, RowSpec};
use crate::scalar::{Dual, Dual2, Scalar};
use nalgebra::DMatrix;

/// Rows as expressions over the scene's slots.
#[derive(Clone, Debug)]
pub struct ExprConstraints {
    specs: Vec<RowSpec>,
    exprs: Vec<Expr>,
    layout: Layout,
    signals: Signals,
    max_stack: usize,
    /// Slots that enter B (read by a row of the slot's own level), each with those rows.
    seeds: Vec<(usize, Vec<usize>)>,
    /// The same by row: rows that have such slots, each with them.
    row_seeds: Vec<(usize, Vec<usize>)>,
    max_work: usize,
    /// B by one dual pass per slot (the plain computation, for tests) instead of gradients.
    plain: bool,
    /// Signals whose Jacobian row enters B.
    signal_needs: Vec<bool>,
    /// Rows per level: position, velocity, acceleration.
    by_level: [Vec<usize>; 3],
    /// Rows affine in signals (see the module's text), by row.
    fast: Vec<Option<FastRow>>,
    /// The rows per level whose value and derivatives need a pass over their expression when
    /// fast rows are on (all but the fast rows without t).
    tape_by_level: [Vec<usize>; 3],
    /// `[[actuators]]`: the programme is realized by these (servo-constraints), else ideally.
    actuation: Option<crate::servo::Actuation>,
}

/// A row E = sum_k c_k s_k + F of signals s_k ([`Expr::affine`]).
#[derive(Clone, Debug)]
struct FastRow {
    /// (signal, c_k) of every term.
    terms: Vec<(usize, f64)>,
    /// (signal, c_k) of the terms of the row's own level: B_i = sum c_k J_k.
    b_terms: Vec<(usize, f64)>,
    /// F when it is a constant (the row reads no t): the row needs no pass over its expression.
    offset: Option<f64>,
}

impl FastRow {
    fn new(e: &Expr, level: Level, layout: &Layout, signals: &Signals) -> Option<FastRow> {
        let a = e.affine(|s| s >= layout.signals, |s| s == layout.t)?;
        if a.terms.is_empty() {
            return None;
        }
        let terms: Vec<(usize, f64)> = (a.terms.iter())
            .map(|&(s, c)| (s - layout.signals, c))
            .collect();
        let b_terms = (terms.iter())
            .filter(|&&(k, _)| signals.quantity(k).level() == level)
            .copied()
            .collect();
        // F = E at every signal 0 (the form is affine); t unread
        let offset = Some(e.value(&vec![0.0; e.min_slots()])).filter(|f| f.is_finite());
        Some(FastRow {
            terms,
            b_terms,
            offset: offset.filter(|_| !a.reads_free),
        })
    }
}

/// Scratch of an [`ExprConstraints`] evaluation.
pub struct RowsWork<S: Scalar> {
    slots: Vec<S>,
    stack: Vec<S>,
    signals: SignalWork<S>,
    slots1: Vec<Dual<S>>,
    stack1: Vec<Dual<S>>,
    slots2: Vec<Dual2<S>>,
    stack2: Vec<Dual2<S>>,
    jets: SignalJets<S>,
    grad: Vec<S>,
    work: Vec<S>,
    qd: Vec<S>,
    qdd: Vec<S>,
}

fn level_index(l: Level) -> usize {
    match l {
        Level::Position => 0,
        Level::Velocity => 1,
        Level::Acceleration => 2,
    }
}

impl ExprConstraints {
    /// Rows with their specs (name, level, role) and expressions.
    pub fn new(specs: Vec<RowSpec>, exprs: Vec<Expr>, layout: Layout, signals: Signals) -> Self {
        let max_stack = exprs.iter().map(|e| e.max_stack()).max().unwrap_or(1);
        let mut by_level: [Vec<usize>; 3] = Default::default();
        for (i, sp) in specs.iter().enumerate() {
            by_level[level_index(sp.level)].push(i);
        }
        // The level of a slot (t enters no B row).
        let slot_level = |slot: usize| -> Option<Level> {
            if slot == layout.t {
                None
            } else if slot >= layout.signals {
                Some(signals.quantity(slot - layout.signals).level())
            } else {
                layout.level(slot)
            }
        };
        let fast: Vec<Option<FastRow>> = (specs.iter().zip(&exprs))
            .map(|(sp, e)| FastRow::new(e, sp.level, &layout, &signals))
            .collect();
        let mut tape_by_level = by_level.clone();
        for rows in tape_by_level.iter_mut() {
            rows.retain(|&i| fast[i].as_ref().is_none_or(|f| f.offset.is_none()));
        }
        let mut seeds: Vec<(usize, Vec<usize>)> = vec![];
        let mut signal_needs = vec![false; signals.len()];
        let mut row_seeds: Vec<(usize, Vec<usize>)> = vec![];
        for (i, (sp, e)) in specs.iter().zip(&exprs).enumerate() {
            for &slot in e.slots() {
                if slot_level(slot) != Some(sp.level) {
                    continue;
                }
                match row_seeds.last_mut() {
                    _ if fast[i].is_some() => {}
                    Some((r, slots)) if *r == i => slots.push(slot),
                    _ => row_seeds.push((i, vec![slot])),
                }
                if slot >= layout.signals {
                    signal_needs[slot - layout.signals] = true;
                }
                match seeds.iter_mut().find(|(s, _)| *s == slot) {
                    Some((_, rows)) => rows.push(i),
                    None => seeds.push((slot, vec![i])),
                }
            }
        }
        let max_work = exprs.iter().map(|e| e.gradient_work()).max().unwrap_or(0);
        ExprConstraints {
            specs,
            exprs,
            layout,
            signals,
            max_stack,
            seeds,
            row_seeds,
            max_work,
            plain: false,
            signal_needs,
            by_level,
            fast,
            tape_by_level,
            actuation: None,
        }
    }

    /// How many rows are affine in signals (B without the tape), and how many of them need no
    /// pass over their expression at all (no t): what the tests and the profile count.
    pub fn fast_rows(&self) -> (usize, usize) {
        let f = self.fast.iter().flatten();
        (f.clone().count(), f.filter(|r| r.offset.is_some()).count())
    }

    /// B by one dual pass per slot (true) or one gradient per row (false, the default); the tests
    /// compare the two.
    pub fn set_plain_passes(&mut self, plain: bool) {
        self.plain = plain;
    }

    /// Realize the programme by these actuators ([`crate::servo`]).
    pub fn set_actuation(&mut self, actuation: crate::servo::Actuation) {
        self.actuation = Some(actuation);
    }

    /// Two row sets from this one: the rows `keep` and the rows `other` (each in the given order).
    pub fn split(&self, keep: &[usize], other: &[usize]) -> (Self, Self) {
        let part = |ix: &[usize]| {
            ExprConstraints::new(
                ix.iter().map(|&i| self.specs[i].clone()).collect(),
                ix.iter().map(|&i| self.exprs[i].clone()).collect(),
                self.layout.clone(),
                self.signals.clone(),
            )
        };
        let mut kept = part(keep);
        kept.actuation = self.actuation.clone();
        (kept, part(other))
    }

    /// The expressions, in row order.
    pub fn exprs(&self) -> &[Expr] {
        &self.exprs
    }
}

impl Constraints for ExprConstraints {
    type Workspace<S: Scalar> = RowsWork<S>;

    fn actuation(&self) -> Option<&crate::programme::actuation::Actuation> {
        self.actuation.as_ref()
    }

    fn workspace<S: Scalar>(&self) -> RowsWork<S> {
        let n = self.layout.slots + self.signals.len();
        RowsWork {
            slots: vec![S::zero(); n],
            stack: Vec::with_capacity(self.max_stack),
            signals: self.signals.work(),
            slots1: vec![Dual::from_re(S::zero()); n],
            stack1: Vec::with_capacity(self.max_stack),
            slots2: vec![Dual2::from_re(S::zero()); n],
            stack2: Vec::with_capacity(self.max_stack),
            jets: SignalJets::new(self.signals.len(), self.layout.nv),
            grad: vec![S::zero(); n],
            work: Vec::with_capacity(self.max_work),
            qd: vec![S::zero(); self.layout.nq],
            qdd: vec![S::zero(); self.layout.nq],
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

    fn jet<S: Scalar>(
        &self,
        ws: &mut RowsWork<S>,
        segments: &[Segment],
        t: S,
        q: &[S],
        v: &[S],
        out: JetRows<'_, S>,
        sweep: Option<crate::tree::TreeSweep<'_, S>>,
    ) -> bool {
        let l = &self.layout;
        let z = S::zero();
        // q along the motion with dv/dt = 0: q' = N v; q'' = (dN/dt) v = 1/2 q' (x) (0, v) on
        // quaternion blocks, 0 elsewhere.
        crate::model::qdot(segments, q, v, &mut ws.qd);
        ws.qdd.fill(z);
        for seg in segments {
            if let Segment::Quaternion { q: iq, v: iv } = *seg {
                let r = lie::quat_rate(&ws.qd[iq..iq + 4], &v[iv..iv + 3]);
                ws.qdd[iq..iq + 4].copy_from_slice(&r);
            }
        }
        self.signals.jets(
            &mut ws.signals,
            sweep,
            q,
            v,
            &self.signal_needs,
            &mut ws.jets,
        );
        // Values at dv/dt = 0.
        ws.slots[l.t] = t;
        ws.slots[l.q..l.q + l.nq].copy_from_slice(q);
        ws.slots[l.v..l.v + l.nv].copy_from_slice(v);
        ws.slots[l.a..l.a + l.nv].fill(z);
        for (k, j) in ws.jets.taylor.iter().enumerate() {
            ws.slots[l.signals + k] = j[0];
        }
        out.gdot.fill(z);
        // gamma and values, level by level; rows affine in signals without t from the jets
        let levels = if self.plain {
            &self.by_level
        } else {
            self.direct_rows(ws, out.value, out.gdot, out.gamma);
            &self.tape_by_level
        };
        if !levels[0].is_empty() {
            for (x, &y) in ws.slots2.iter_mut().zip(&ws.slots) {
                *x = Dual2::from_re(y);
            }
            ws.slots2[l.t] = Dual2::new(t, S::one(), z);
            for k in 0..l.nq {
                ws.slots2[l.q + k] = Dual2::new(q[k], ws.qd[k], ws.qdd[k]);
            }
            for (k, j) in ws.jets.taylor.iter().enumerate() {
                ws.slots2[l.signals + k] = Dual2::new(j[0], j[1], j[2]);
            }
            for &i in &levels[0] {
                let g = self.exprs[i].eval(&ws.slots2, &mut ws.stack2);
                out.value[i] = g.re;
                out.gdot[i] = g.v1;
                out.gamma[i] = -g.v2;
            }
        }
        if !levels[1].is_empty() {
            for (x, &y) in ws.slots1.iter_mut().zip(&ws.slots) {
                *x = Dual::from_re(y);
            }
            ws.slots1[l.t] = Dual::new(t, S::one());
            for k in 0..l.nq {
                ws.slots1[l.q + k] = Dual::new(q[k], ws.qd[k]);
            }
            for (k, j) in ws.jets.taylor.iter().enumerate() {
                ws.slots1[l.signals + k] = Dual::new(j[0], j[1]);
            }
            for &i in &levels[1] {
                let f = self.exprs[i].eval(&ws.slots1, &mut ws.stack1);
                out.value[i] = f.re;
                out.gamma[i] = -f.eps;
            }
        }
        for &i in &levels[2] {
            let h = self.exprs[i].eval(&ws.slots, &mut ws.stack);
            out.value[i] = h;
            out.gamma[i] = -h;
        }
        self.fill_b(ws, segments, q, out.b);
        true
    }
}

impl ExprConstraints {
    /// B (the module's text): one gradient per row, or one Dual pass per slot in plain mode; the
    /// rows affine in signals as sum c_k J_k.
    fn fill_b<S: Scalar>(
        &self,
        ws: &mut RowsWork<S>,
        segments: &[Segment],
        q: &[S],
        b: &mut DMatrix<S>,
    ) {
        let (l, z) = (&self.layout, S::zero());
        b.fill(z);
        if !self.plain {
            for (i, slots) in &self.row_seeds {
                let i = *i;
                self.exprs[i].gradient(&ws.slots, &mut ws.work, &mut ws.grad);
                for &slot in slots {
                    let d = ws.grad[slot];
                    add_slot(l, segments, q, &ws.jets, slot, d, b, i);
                }
            }
            for (i, f) in self.fast.iter().enumerate() {
                for &(k, c) in f.iter().flat_map(|f| &f.b_terms) {
                    let c = S::from(c);
                    for j in 0..l.nv {
                        b[(i, j)] += c * ws.jets.jac[(k, j)];
                    }
                }
            }
            return;
        }
        for x in ws.slots1.iter_mut().zip(&ws.slots) {
            *x.0 = Dual::from_re(*x.1);
        }
        for (slot, rows) in &self.seeds {
            let slot = *slot;
            ws.slots1[slot].eps = S::one();
            for &i in rows {
                let d = self.exprs[i].eval(&ws.slots1, &mut ws.stack1).eps;
                add_slot(l, segments, q, &ws.jets, slot, d, b, i);
            }
            ws.slots1[slot].eps = z;
        }
    }

    /// Value, dE/dt and gamma of the rows affine in signals without t, from the signals' jets:
    /// d^m E/dt^m = sum c_k d^m s_k/dt^m, gamma = -d^m E/dt^m with m = 2, 1, 0 for position,
    /// velocity and acceleration rows (the module's text).
    fn direct_rows<S: Scalar>(
        &self,
        ws: &RowsWork<S>,
        value: &mut [S],
        gdot: &mut [S],
        gamma: &mut [S],
    ) {
        for (i, f) in self.fast.iter().enumerate() {
            let Some((f, offset)) = f.as_ref().and_then(|f| Some((f, f.offset?))) else {
                continue;
            };
            let mut d = [S::zero(); 3];
            for &(k, c) in &f.terms {
                let (j, c) = (&ws.jets.taylor[k], S::from(c));
                for m in 0..3 {
                    d[m] += j[m] * c;
                }
            }
            value[i] = d[0] + S::from(offset);
            match self.specs[i].level {
                Level::Position => {
                    gdot[i] = d[1];
                    gamma[i] = -d[2];
                }
                Level::Velocity => gamma[i] = -d[1],
                Level::Acceleration => gamma[i] = -value[i],
            }
        }
    }
}

/// b[i, :] += d * J_slot: a signal's Jacobian row, a unit row (v, dv/dt) or a row of N(q).
#[allow(clippy::too_many_arguments)]
fn add_slot<S: Scalar>(
    l: &Layout,
    segments: &[Segment],
    q: &[S],
    jets: &SignalJets<S>,
    slot: usize,
    d: S,
    b: &mut DMatrix<S>,
    i: usize,
) {
    if slot >= l.signals {
        let k = slot - l.signals;
        for j in 0..l.nv {
            b[(i, j)] += d * jets.jac[(k, j)];
        }
    } else if slot >= l.a {
        b[(i, slot - l.a)] += d;
    } else if slot >= l.v {
        b[(i, slot - l.v)] += d;
    } else {
        add_n_row(segments, q, slot - l.q, d, b, i);
    }
}

/// b[i, :] += d * (row k of N(q)), N the map v -> dq/dt of [`crate::model::qdot`].
fn add_n_row<S: Scalar>(
    segments: &[Segment],
    q: &[S],
    k: usize,
    d: S,
    b: &mut DMatrix<S>,
    i: usize,
) {
    for seg in segments {
        match *seg {
            Segment::Euclidean { q: iq, v: iv, len } if k >= iq && k < iq + len => {
                b[(i, iv + k - iq)] += d;
            }
            Segment::Quaternion { q: iq, v: iv } if k >= iq && k < iq + 4 => {
                for j in 0..3 {
                    let mut e = [S::zero(); 3];
                    e[j] = S::one();
                    b[(i, iv + j)] += d * lie::quat_rate(&q[iq..iq + 4], &e)[k - iq];
                }
            }
            _ => {}
        }
    }
}
