//! Exact first and second derivatives of constraint rows by forward-mode AD (no finite differences).
//!
//! At a state (t, q, v) with dq/dt = N(q) v, every row i yields one line of B a = gamma:
//! - velocity row f(t, q, v): B_i = df/dv, gamma_i = -(f_t + f_q N v) (the programme (2.3)
//!   differentiated once);
//! - position row g(t, q): B_i = g_q N, and with the line q(s) = q + s N v the second derivative
//!   d^2 g/dt^2 = g_tt + 2 g_tq N v + (N v)^T g_qq (N v) + g_q (dN/dt) v + g_q N a, so
//!   gamma_i = -(d^2/ds^2 g(t + s, q + s N v) + g_q (dN/dt) v); one `Dual2` pass along the line gives
//!   the first term and dg/dt = g_t + g_q N v on the way;
//! - acceleration row h(t, q, v, a) = B_i a + h(t, q, v, 0): B_i = dh/da, gamma_i = -h(t, q, v, 0).
//!
//! Passes are over `Dual<S>` and `Dual2<S>`, so the whole computation can itself be run over a dual
//! `S` (Jacobians of the right-hand side for implicit integrators).

use super::{Constraints, Level};
use crate::model::{lie, Segment};
use crate::scalar::{Dual, Dual2, Scalar};
use nalgebra::DMatrix;

/// Where [`Constraints::jet`] writes: the public outputs of a [`Jet`].
pub struct JetRows<'a, S: Scalar> {
    /// B, `s x nv`.
    pub b: &'a mut DMatrix<S>,
    /// gamma, so that B a = gamma.
    pub gamma: &'a mut [S],
    /// Row values: g (position), f (velocity), h(t, q, v, 0) (acceleration).
    pub value: &'a mut [S],
    /// dg/dt for position rows; zero for other rows.
    pub gdot: &'a mut [S],
}

/// Derivatives of all rows at one state; preallocated, reused at every evaluation.
pub struct Jet<C: Constraints, S: Scalar> {
    ws0: C::Workspace<S>,
    /// The generic passes' workspaces, made by their first use: constraints with their own
    /// [`Constraints::jet`] never need them (a tree's workspace over `Dual2<S>` is large).
    ws1: Option<C::Workspace<Dual<S>>>,
    ws2: Option<C::Workspace<Dual2<S>>>,
    q1: Vec<Dual<S>>,
    v1: Vec<Dual<S>>,
    a1: Vec<Dual<S>>,
    out1: Vec<Dual<S>>,
    q2: Vec<Dual2<S>>,
    v2: Vec<Dual2<S>>,
    a2: Vec<Dual2<S>>,
    out2: Vec<Dual2<S>>,
    qd: Vec<S>,
    dir: Vec<S>,
    levels: Vec<Level>,
    has: [bool; 3],
    has_quaternion: bool,
    nv: usize,
    /// B, `s x nv`.
    pub b: DMatrix<S>,
    /// gamma, so that B a = gamma.
    pub gamma: Vec<S>,
    /// Row values: g (position), f (velocity), h(t, q, v, 0) (acceleration).
    pub value: Vec<S>,
    /// dg/dt for position rows; zero for other rows.
    pub gdot: Vec<S>,
}

impl<C: Constraints, S: Scalar> Jet<C, S> {
    /// Workspace for `constraints` on a configuration space with `nq` coordinates and `nv` velocities.
    pub fn new(constraints: &C, segments: &[Segment], nq: usize, nv: usize) -> Self {
        let s = constraints.rows().len();
        let levels: Vec<Level> = constraints.rows().iter().map(|r| r.level).collect();
        let has = [
            levels.contains(&Level::Position),
            levels.contains(&Level::Velocity),
            levels.contains(&Level::Acceleration),
        ];
        Jet {
            ws0: constraints.workspace(),
            ws1: None,
            ws2: None,
            q1: vec![Dual::from_re(S::zero()); nq],
            v1: vec![Dual::from_re(S::zero()); nv],
            a1: vec![Dual::from_re(S::zero()); nv],
            out1: vec![Dual::from_re(S::zero()); s],
            q2: vec![Dual2::from_re(S::zero()); nq],
            v2: vec![Dual2::from_re(S::zero()); nv],
            a2: vec![Dual2::from_re(S::zero()); nv],
            out2: vec![Dual2::from_re(S::zero()); s],
            qd: vec![S::zero(); nq],
            dir: vec![S::zero(); nq],
            levels,
            has,
            has_quaternion: segments
                .iter()
                .any(|g| matches!(g, Segment::Quaternion { .. })),
            nv,
            b: DMatrix::from_element(s, nv, S::zero()),
            gamma: vec![S::zero(); s],
            value: vec![S::zero(); s],
            gdot: vec![S::zero(); s],
        }
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.levels.len()
    }

    /// Level of each row.
    pub fn levels(&self) -> &[Level] {
        &self.levels
    }

    /// Compute B, gamma, the row values and dg/dt at (t, q, v): the constraints' own
    /// [`Constraints::jet`] when they have one, else [`Jet::compute_generic`]. Allocates nothing
    /// (the generic passes' workspaces once, at their first use).
    pub fn compute(&mut self, c: &C, segments: &[Segment], t: S, q: &[S], v: &[S]) {
        self.compute_with(c, segments, t, q, v, None)
    }

    /// [`Jet::compute`] reading the model's forward passes where the constraints can
    /// ([`crate::model::Model::tree_sweep`]): the same values, one sweep fewer.
    pub fn compute_with(
        &mut self,
        c: &C,
        segments: &[Segment],
        t: S,
        q: &[S],
        v: &[S],
        sweep: Option<crate::tree::TreeSweep<'_, S>>,
    ) {
        let out = JetRows {
            b: &mut self.b,
            gamma: &mut self.gamma,
            value: &mut self.value,
            gdot: &mut self.gdot,
        };
        if !c.jet(&mut self.ws0, segments, t, q, v, out, sweep) {
            self.compute_generic(c, segments, t, q, v);
        }
    }

    /// The generic passes over [`Constraints::eval`] (nv `Dual` passes per level and one `Dual2`
    /// pass); also the independent reference the specialised jets are tested against.
    pub fn compute_generic(&mut self, c: &C, segments: &[Segment], t: S, q: &[S], v: &[S]) {
        self.ws1.get_or_insert_with(|| c.workspace());
        self.ws2.get_or_insert_with(|| c.workspace());
        crate::model::qdot(segments, q, v, &mut self.qd);
        for x in self.gdot.iter_mut() {
            *x = S::zero();
        }
        for (x, &y) in self.v1.iter_mut().zip(v) {
            *x = Dual::from_re(y);
        }
        for x in self.a1.iter_mut() {
            *x = Dual::from_re(S::zero());
        }
        let t1 = Dual::from_re(t);

        if self.has[0] {
            self.position_rows(c, segments, t, t1, q, v);
            // g_q (dN/dt) v, nonzero only on quaternion blocks: d/ds [1/2 (q + s qd) (x) (0, w)].
            if self.has_quaternion {
                self.position_rate_term(c, segments, t1, q, v);
            }
        }

        if self.has[1] || self.has[2] {
            for k in 0..q.len() {
                self.q1[k] = Dual::from_re(q[k]);
            }
        }
        if self.has[1] {
            self.velocity_rows(c, t, t1, q, v);
        }
        if self.has[2] {
            self.acceleration_rows(c, t1);
        }
    }

    /// One `Dual` pass of the constraints at (t1, q1, v1, a1) into `out1`.
    fn eval1(&mut self, c: &C, t1: Dual<S>) {
        c.eval(
            self.ws1.as_mut().expect("made by compute_generic"),
            t1,
            &self.q1,
            &self.v1,
            &self.a1,
            &mut self.out1,
        );
    }

    /// Position rows: B_i = g_q N, the value, dg/dt and the second derivative along the line
    /// (t + s, q + s N v) into gamma.
    fn position_rows(&mut self, c: &C, segments: &[Segment], t: S, t1: Dual<S>, q: &[S], v: &[S]) {
        // B_i = g_q N e_j: seed q along N(q) e_j.
        for j in 0..self.nv {
            direction(segments, q, j, &mut self.dir);
            for k in 0..q.len() {
                self.q1[k] = Dual::new(q[k], self.dir[k]);
            }
            self.eval1(c, t1);
            for i in 0..self.levels.len() {
                if self.levels[i] == Level::Position {
                    self.b[(i, j)] = self.out1[i].eps;
                }
            }
        }
        // Second derivative along the line (t + s, q + s N v).
        for k in 0..q.len() {
            self.q2[k] = Dual2::new(q[k], self.qd[k], S::zero());
        }
        for (x, &y) in self.v2.iter_mut().zip(v) {
            *x = Dual2::from_re(y);
        }
        for x in self.a2.iter_mut() {
            *x = Dual2::from_re(S::zero());
        }
        let t2 = Dual2::new(t, S::one(), S::zero());
        c.eval(
            self.ws2.as_mut().expect("made by compute_generic"),
            t2,
            &self.q2,
            &self.v2,
            &self.a2,
            &mut self.out2,
        );
        for i in 0..self.levels.len() {
            if self.levels[i] == Level::Position {
                self.value[i] = self.out2[i].re;
                self.gdot[i] = self.out2[i].v1;
                self.gamma[i] = -self.out2[i].v2;
            }
        }
    }

    /// Position rows: gamma_i -= g_q (dN/dt) v (quaternion blocks only).
    fn position_rate_term(&mut self, c: &C, segments: &[Segment], t1: Dual<S>, q: &[S], v: &[S]) {
        for x in self.dir.iter_mut() {
            *x = S::zero();
        }
        for seg in segments {
            if let Segment::Quaternion { q: iq, v: iv } = *seg {
                let r = lie::quat_rate(&self.qd[iq..iq + 4], &v[iv..iv + 3]);
                self.dir[iq..iq + 4].copy_from_slice(&r);
            }
        }
        for k in 0..q.len() {
            self.q1[k] = Dual::new(q[k], self.dir[k]);
        }
        self.eval1(c, t1);
        for i in 0..self.levels.len() {
            if self.levels[i] == Level::Position {
                self.gamma[i] -= self.out1[i].eps;
            }
        }
    }

    /// Velocity rows: B_i = df/dv, the value and gamma_i = -(f_t + f_q N v); q1 is left at q.
    fn velocity_rows(&mut self, c: &C, t: S, t1: Dual<S>, q: &[S], v: &[S]) {
        // B_i = df/dv_j.
        for j in 0..self.nv {
            self.v1[j] = Dual::new(v[j], S::one());
            self.eval1(c, t1);
            self.v1[j] = Dual::from_re(v[j]);
            for i in 0..self.levels.len() {
                if self.levels[i] == Level::Velocity {
                    self.b[(i, j)] = self.out1[i].eps;
                }
            }
        }
        // f_t + f_q N v.
        for k in 0..q.len() {
            self.q1[k] = Dual::new(q[k], self.qd[k]);
        }
        self.eval1(c, Dual::new(t, S::one()));
        for i in 0..self.levels.len() {
            if self.levels[i] == Level::Velocity {
                self.value[i] = self.out1[i].re;
                self.gamma[i] = -self.out1[i].eps;
            }
        }
        for k in 0..q.len() {
            self.q1[k] = Dual::from_re(q[k]);
        }
    }

    /// Acceleration rows, h linear in a: B_i = dh/da_j, gamma_i = -h(t, q, v, 0).
    fn acceleration_rows(&mut self, c: &C, t1: Dual<S>) {
        for j in 0..self.nv {
            self.a1[j] = Dual::new(S::zero(), S::one());
            self.eval1(c, t1);
            self.a1[j] = Dual::from_re(S::zero());
            for i in 0..self.levels.len() {
                if self.levels[i] == Level::Acceleration {
                    self.b[(i, j)] = self.out1[i].eps;
                    self.value[i] = self.out1[i].re;
                    self.gamma[i] = -self.out1[i].re;
                }
            }
        }
    }
}

/// The tangent direction N(q) e_j in coordinate space.
fn direction<S: Scalar>(segments: &[Segment], q: &[S], j: usize, out: &mut [S]) {
    for x in out.iter_mut() {
        *x = S::zero();
    }
    for seg in segments {
        match *seg {
            Segment::Euclidean { q: iq, v: iv, len } => {
                if j >= iv && j < iv + len {
                    out[iq + j - iv] = S::one();
                }
            }
            Segment::Quaternion { q: iq, v: iv } => {
                if j >= iv && j < iv + 3 {
                    let mut e = [S::zero(); 3];
                    e[j - iv] = S::one();
                    let r = lie::quat_rate(&q[iq..iq + 4], &e);
                    out[iq..iq + 4].copy_from_slice(&r);
                }
            }
        }
    }
}
