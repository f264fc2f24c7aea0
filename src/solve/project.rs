//! Projection onto the programme manifold: the paper's promise that the programme's violation is a
//! controlled numerical error (Section 2, after (2.12)).
//!
//! Positions: minimize 1/2 dq^T A dq subject to g(t, q (+) dq) = 0 for the position rows, by Newton
//! steps on the KKT system [A, J^T; J, 0] [dq; mu] = [0; -g], J = g_q N (the position rows of B).
//! Velocities: minimize 1/2 dv^T A dv subject to the velocity-level rows (dg/dt of position rows,
//! which is linear in v, and the velocity rows f(t, q, v), possibly nonlinear) by the same Newton
//! steps with J = B. A is the kinetic-energy metric, so the correction is the smallest in energy.
//! Acceleration-level rows constrain no state and are not projected.

use super::evaluator::Evaluator;
use crate::linalg;
use crate::model::{self, Model};
use crate::programme::{Constraints, Level};
use nalgebra::DMatrix;

/// What one projection did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ProjectionReport {
    /// Newton iterations (both levels).
    pub iterations: usize,
    /// |dq| inf-norm of the total position correction (chart coordinates).
    pub dq: f64,
    /// |dv| inf-norm of the total velocity correction.
    pub dv: f64,
    /// Largest remaining |residual| and its row, after projection.
    pub residual: f64,
    /// Row index of `residual`.
    pub row: usize,
    /// Residual reached the tolerance at both levels.
    pub converged: bool,
}

/// Preallocated projection workspace.
pub struct Projector<'a, M: Model, C: Constraints> {
    ev: Evaluator<'a, M, C, f64>,
    segments: Vec<model::Segment>,
    levels: Vec<Level>,
    k: DMatrix<f64>,
    piv: Vec<usize>,
    rhs: Vec<f64>,
    qtmp: Vec<f64>,
    sel: Vec<usize>,
    nv: usize,
    model: &'a M,
    cons: &'a C,
    /// Relative degrees of a servo programme: project onto its hidden constraints instead.
    servo: Option<(Vec<usize>, Option<crate::servo::Reduction>)>,
    /// The servo passes' workspaces, kept for the solve.
    servo_work: crate::servo::WorkCache,
    /// The hidden constraints' Jacobian of the last servo projection (simplified Newton).
    servo_jac: crate::servo::KeptJacobian,
}

impl<'a, M: Model, C: Constraints> Projector<'a, M, C> {
    /// Workspace for `model` and `cons`.
    pub fn new(model: &'a M, cons: &'a C) -> Self {
        let (nv, s) = (model.nv(), cons.rows().len());
        Projector {
            ev: Evaluator::new(model, cons),
            segments: model.segments().to_vec(),
            levels: cons.rows().iter().map(|r| r.level).collect(),
            k: DMatrix::zeros(nv + s, nv + s),
            piv: vec![0; nv + s],
            rhs: vec![0.0; nv + s],
            qtmp: vec![0.0; model.nq()],
            sel: Vec::with_capacity(s),
            nv,
            model,
            cons,
            servo: None,
            servo_work: Default::default(),
            servo_jac: Default::default(),
        }
    }

    /// Project onto the hidden constraints y^(k) = 0, k < r_i, of a servo programme with these
    /// relative degrees ([`crate::servo::Servo::project`]) instead of the rows and their rates.
    pub fn set_servo(&mut self, degrees: Vec<usize>, reduction: Option<crate::servo::Reduction>) {
        self.servo = Some((degrees, reduction));
    }

    /// Residuals at (t, q, v) of the state rows: g for position rows (and dg/dt into `rate`),
    /// f for velocity rows; acceleration rows get 0.
    pub fn residuals(&mut self, t: f64, q: &[f64], v: &[f64], res: &mut [f64], rate: &mut [f64]) {
        self.ev.prepare_geometry(t, q, v);
        for i in 0..self.levels.len() {
            res[i] = match self.levels[i] {
                Level::Acceleration => 0.0,
                _ => self.ev.jet.value[i],
            };
            rate[i] = self.ev.jet.gdot[i];
        }
    }

    /// Project (q, v) in place. Returns what was done; never panics on singular systems (it stops
    /// iterating and reports `converged = false`).
    #[allow(clippy::too_many_lines)] // over 100 lines before the lint: to split, not to grow
    pub fn project(
        &mut self,
        t: f64,
        q: &mut [f64],
        v: &mut [f64],
        tol: f64,
        max_iter: usize,
    ) -> ProjectionReport {
        if let (Some(act), Some((deg, red))) = (self.cons.actuation(), &self.servo) {
            let servo = crate::servo::Servo::new(self.model, self.cons, act)
                .reduced(red.as_ref())
                .cached(&self.servo_work);
            let out = servo.project_with(t, q, v, deg, tol, max_iter, &mut self.servo_jac);
            let row = servo.hidden_names(deg).get(out.row).map_or(0, |(i, _)| *i);
            return ProjectionReport {
                iterations: out.iterations,
                dq: out.dq,
                dv: out.dv,
                residual: out.residual,
                row,
                converged: out.converged,
            };
        }
        let mut rep = ProjectionReport {
            converged: true,
            ..Default::default()
        };
        let nv = self.nv;
        // A and the jet are re-evaluated only after q or v changed.
        let mut stale = true;
        // Positions.
        self.sel.clear();
        self.sel
            .extend((0..self.levels.len()).filter(|&i| self.levels[i] == Level::Position));
        if !self.sel.is_empty() {
            let mut done = false;
            for _ in 0..=max_iter {
                if stale {
                    self.ev.prepare_geometry(t, q, v);
                    stale = false;
                }
                let r = self.worst(|ev, i| ev.jet.value[i]);
                if r.0 <= tol {
                    done = true;
                    break;
                }
                if rep.iterations >= max_iter {
                    break;
                }
                rep.iterations += 1;
                for (k, &i) in self.sel.iter().enumerate() {
                    self.rhs[nv + k] = -self.ev.jet.value[i];
                }
                if !self.kkt_solve() {
                    break;
                }
                let step = &self.rhs[..nv];
                rep.dq = rep.dq.max(step.iter().fold(0.0, |m, x| m.max(x.abs())));
                self.qtmp.copy_from_slice(q);
                model::retract(&self.segments, &self.qtmp, step, q);
                model::normalize(&self.segments, q);
                stale = true;
            }
            if !done {
                rep.converged = false;
            }
        }
        // Velocities: dg/dt of position rows and f of velocity rows.
        self.sel.clear();
        self.sel
            .extend((0..self.levels.len()).filter(|&i| self.levels[i] != Level::Acceleration));
        if !self.sel.is_empty() {
            let mut done = false;
            let mut it = 0;
            for _ in 0..=max_iter {
                if stale {
                    self.ev.prepare_geometry(t, q, v);
                    stale = false;
                }
                let r = self.worst(|ev, i| rate_or_value(ev, i));
                if r.0 <= tol {
                    done = true;
                    break;
                }
                if it >= max_iter {
                    break;
                }
                it += 1;
                for (k, &i) in self.sel.iter().enumerate() {
                    self.rhs[nv + k] = -rate_or_value(&self.ev, i);
                }
                if !self.kkt_solve() {
                    break;
                }
                for j in 0..nv {
                    v[j] += self.rhs[j];
                    rep.dv = rep.dv.max(self.rhs[j].abs());
                }
                stale = true;
            }
            rep.iterations += it;
            if !done {
                rep.converged = false;
            }
        }
        // Final residuals of all state rows.
        if stale {
            self.ev.prepare_geometry(t, q, v);
        }
        self.sel.clear();
        self.sel
            .extend((0..self.levels.len()).filter(|&i| self.levels[i] != Level::Acceleration));
        let a = self.worst(|ev, i| ev.jet.value[i]);
        let b = self.worst(|ev, i| rate_or_value(ev, i));
        let (r, row) = if a.0 >= b.0 { a } else { b };
        rep.residual = r;
        rep.row = row;
        rep
    }

    fn worst(&self, f: impl Fn(&Evaluator<'a, M, C, f64>, usize) -> f64) -> (f64, usize) {
        let mut w = (0.0, 0);
        for &i in &self.sel {
            let r = f(&self.ev, i).abs();
            if r > w.0 || r.is_nan() {
                w = (r, i);
            }
        }
        w
    }

    /// Solve [A, J^T; J, 0] [d; mu] = [0; rhs_J] with J = rows `sel` of B; d lands in rhs[..nv].
    fn kkt_solve(&mut self) -> bool {
        let nv = self.nv;
        let p = self.sel.len();
        let n = nv + p;
        for i in 0..n {
            for j in 0..n {
                self.k[(i, j)] = 0.0;
            }
        }
        for i in 0..nv {
            for j in 0..nv {
                self.k[(i, j)] = self.ev.mass[(i, j)];
            }
            self.rhs[i] = 0.0;
        }
        for (r, &i) in self.sel.iter().enumerate() {
            for j in 0..nv {
                let b = self.ev.jet.b[(i, j)];
                self.k[(nv + r, j)] = b;
                self.k[(j, nv + r)] = b;
            }
        }
        if linalg::lu_factor(&mut self.k, n, &mut self.piv, 1e-14).is_err() {
            return false;
        }
        linalg::lu_solve(&self.k, n, &self.piv, &mut self.rhs[..n]);
        self.rhs[..n].iter().all(|x| x.is_finite())
    }
}

fn rate_or_value<M: Model, C: Constraints>(ev: &Evaluator<'_, M, C, f64>, i: usize) -> f64 {
    match ev.jet.levels()[i] {
        Level::Position => ev.jet.gdot[i],
        _ => ev.jet.value[i],
    }
}
