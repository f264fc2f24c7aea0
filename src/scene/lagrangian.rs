//! Lagrangian scenes: named coordinates, A(q) and forces given as expressions, G derived exactly.
//!
//! With T = 1/2 v^T A(q) v (2.1), Lagrange's equations d/dt(dT/dv) - dT/dq = Q give (2.2) with
//! G = dT/dq - (dA/dt) v, i.e. G_k = 1/2 v^T (dA/dq_k) v - sum_j (dA_kj/dt) v_j, with
//! dA_ij/dt = sum_k dA_ij/dq_k v_k. Both terms come from one gradient of each non-constant entry
//! (one reverse sweep over its tape, [`Expr::gradient`]); a potential V(q) adds Q = -dV/dq, one
//! gradient too. The plain computation (one dual pass for dA/dt, one per q_k for dA/dq_k and
//! -dV/dq_k; [`LagrangianModel::set_plain_passes`]) stays for the tests to compare. No symbolic or
//! finite-difference derivatives.

use super::layout::Layout;
use crate::expr::Expr;
use crate::model::{Model, Segment};
use crate::scalar::{Dual, Scalar};
use nalgebra::DMatrix;

/// A mechanical system given by its kinetic energy matrix and forces as expressions.
#[derive(Clone, Debug)]
pub struct LagrangianModel {
    names: Vec<String>,
    segments: [Segment; 1],
    layout: Layout,
    /// Non-zero entries (i, j), i <= j, of the symmetric A(q).
    mass: Vec<(usize, usize, Expr)>,
    potential: Option<Expr>,
    forces: Vec<(usize, Expr)>,
    max_stack: usize,
    max_work: usize,
    /// Dual passes per direction instead of gradients (the plain computation, for tests).
    plain: bool,
}

/// Scratch of a [`LagrangianModel`] evaluation.
pub struct LagrangianWork<S: Scalar> {
    slots: Vec<S>,
    stack: Vec<S>,
    dslots: Vec<Dual<S>>,
    dstack: Vec<Dual<S>>,
    grad: Vec<S>,
    work: Vec<S>,
}

impl LagrangianModel {
    /// Build from compiled expressions. `mass` holds the upper triangle (i <= j) with constant-zero
    /// entries left out; every expression reads the slots of `layout`.
    pub fn new(
        names: Vec<String>,
        layout: Layout,
        mass: Vec<(usize, usize, Expr)>,
        potential: Option<Expr>,
        forces: Vec<(usize, Expr)>,
    ) -> Self {
        let n = names.len();
        let max_stack = mass
            .iter()
            .map(|m| m.2.max_stack())
            .chain(potential.iter().map(|e| e.max_stack()))
            .chain(forces.iter().map(|f| f.1.max_stack()))
            .max()
            .unwrap_or(1);
        let max_work = mass
            .iter()
            .map(|m| m.2.gradient_work())
            .chain(potential.iter().map(|e| e.gradient_work()))
            .max()
            .unwrap_or(0);
        LagrangianModel {
            names,
            segments: [Segment::Euclidean { q: 0, v: 0, len: n }],
            layout,
            mass,
            potential,
            forces,
            max_stack,
            max_work,
            plain: false,
        }
    }

    /// G and -dV/dq by one dual pass per direction (true) or one gradient per expression (false,
    /// the default); the tests compare the two.
    pub fn set_plain_passes(&mut self, plain: bool) {
        self.plain = plain;
    }

    fn fill<S: Scalar>(&self, slots: &mut [S], t: S, q: &[S], v: &[S]) {
        let l = &self.layout;
        slots[l.t] = t;
        slots[l.q..l.q + q.len()].copy_from_slice(q);
        slots[l.v..l.v + v.len()].copy_from_slice(v);
    }
}

impl Model for LagrangianModel {
    type Workspace<S: Scalar> = LagrangianWork<S>;

    fn workspace<S: Scalar>(&self) -> LagrangianWork<S> {
        let n = self.layout.slots;
        LagrangianWork {
            slots: vec![S::zero(); n],
            stack: Vec::with_capacity(self.max_stack),
            dslots: vec![Dual::from_re(S::zero()); n],
            dstack: Vec::with_capacity(self.max_stack),
            grad: vec![S::zero(); n],
            work: Vec::with_capacity(self.max_work),
        }
    }
    fn nq(&self) -> usize {
        self.names.len()
    }
    fn nv(&self) -> usize {
        self.names.len()
    }
    fn segments(&self) -> &[Segment] {
        &self.segments
    }
    fn q_names(&self) -> Vec<String> {
        self.names.clone()
    }
    fn v_names(&self) -> Vec<String> {
        self.names.clone()
    }

    fn mass_matrix<S: Scalar>(&self, ws: &mut LagrangianWork<S>, q: &[S], a: &mut DMatrix<S>) {
        let l = &self.layout;
        ws.slots[l.q..l.q + q.len()].copy_from_slice(q);
        a.fill(S::zero());
        for (i, j, e) in &self.mass {
            let x = e.eval(&ws.slots, &mut ws.stack);
            a[(*i, *j)] = x;
            a[(*j, *i)] = x;
        }
    }

    fn velocity_terms<S: Scalar>(&self, ws: &mut LagrangianWork<S>, q: &[S], v: &[S], g: &mut [S]) {
        let n = q.len();
        let l = &self.layout;
        for x in g.iter_mut() {
            *x = S::zero();
        }
        if !self.plain {
            ws.slots[l.q..l.q + n].copy_from_slice(q);
            for (i, j, e) in &self.mass {
                if e.slots().is_empty() {
                    continue;
                }
                e.gradient(&ws.slots, &mut ws.work, &mut ws.grad);
                let (i, j) = (*i, *j);
                let w = if i == j { 0.5 } else { 1.0 };
                let vv = v[i] * v[j] * w;
                let mut ad = S::zero();
                for &s in e.slots() {
                    let k = s - l.q;
                    let d = ws.grad[s];
                    ad += d * v[k];
                    g[k] += d * vv;
                }
                g[i] -= ad * v[j];
                if i != j {
                    g[j] -= ad * v[i];
                }
            }
            return;
        }
        for k in 0..ws.dslots.len() {
            ws.dslots[k] = Dual::from_re(S::zero());
        }
        // -(dA/dt) v: seed q along v.
        for k in 0..n {
            ws.dslots[l.q + k] = Dual::new(q[k], v[k]);
        }
        for (i, j, e) in &self.mass {
            let ad = e.eval(&ws.dslots, &mut ws.dstack).eps;
            g[*i] -= ad * v[*j];
            if i != j {
                g[*j] -= ad * v[*i];
            }
        }
        // + 1/2 v^T (dA/dq_k) v.
        for k in 0..n {
            ws.dslots[l.q + k] = Dual::from_re(q[k]);
        }
        for k in 0..n {
            ws.dslots[l.q + k] = Dual::new(q[k], S::one());
            let mut s = S::zero();
            for (i, j, e) in &self.mass {
                if !e.uses(l.q + k) {
                    continue;
                }
                let d = e.eval(&ws.dslots, &mut ws.dstack).eps;
                let w = if i == j { 0.5 } else { 1.0 };
                s += d * v[*i] * v[*j] * w;
            }
            g[k] += s;
            ws.dslots[l.q + k] = Dual::from_re(q[k]);
        }
    }

    fn applied_forces<S: Scalar>(
        &self,
        ws: &mut LagrangianWork<S>,
        t: S,
        q: &[S],
        v: &[S],
        f: &mut [S],
    ) {
        for x in f.iter_mut() {
            *x = S::zero();
        }
        let mut slots = std::mem::take(&mut ws.slots);
        self.fill(&mut slots, t, q, v);
        for (i, e) in &self.forces {
            f[*i] += e.eval(&slots, &mut ws.stack);
        }
        ws.slots = slots;
        if let (Some(pot), false) = (&self.potential, self.plain) {
            let l = &self.layout;
            pot.gradient(&ws.slots, &mut ws.work, &mut ws.grad);
            for &s in pot.slots() {
                if s >= l.q && s < l.q + q.len() {
                    f[s - l.q] -= ws.grad[s];
                }
            }
        } else if let Some(pot) = &self.potential {
            let l = &self.layout;
            for k in 0..ws.dslots.len() {
                ws.dslots[k] = Dual::from_re(S::zero());
            }
            ws.dslots[l.t] = Dual::from_re(t);
            for k in 0..q.len() {
                ws.dslots[l.q + k] = Dual::from_re(q[k]);
            }
            for k in 0..q.len() {
                if !pot.uses(l.q + k) {
                    continue;
                }
                ws.dslots[l.q + k] = Dual::new(q[k], S::one());
                f[k] -= pot.eval(&ws.dslots, &mut ws.dstack).eps;
                ws.dslots[l.q + k] = Dual::from_re(q[k]);
            }
        }
    }
}
