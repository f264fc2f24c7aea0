//! The programmed motion as an ODE on a chart, driven by `crate::integrate`.
//!
//! State y = (delta, v): q = base (+) delta (Euclidean blocks add, quaternion blocks
//! q = base (x) Exp(delta)), so every integrator steps a flat R^(2 nv) and rotations are integrated
//! Lie-group-correctly (RKMK: d(delta)/dt = dexp^-1(delta) omega). After each accepted step the
//! chart is re-centred when needed, the state is projected onto the programme manifold (if
//! enabled), samples are emitted and residuals monitored.

use super::evaluator::{Baumgarte, Evaluator};
use super::project::Projector;
use super::{
    is_state_row, DriftControl, InitialCorrection, Output, Problem, ReturnCode, Sample, SampleSink,
    Settings, Statistics, Warning, WarningKind,
};
use crate::formulation::{FormulationError, RankTolerances};
use crate::integrate::{Accept, DenseOutput, OdeProblem, Outcome};
use crate::model::{self, Model, Segment};
use crate::programme::{Constraints, Level, Role};
use crate::scalar::Dual;
use nalgebra::DMatrix;
use num_dual::Dual64;

/// Why the run stopped, as seen from inside a step.
#[derive(Clone, Debug)]
pub(crate) enum Stop {
    Formulation(FormulationError),
    NonFinite,
    Drift {
        row: usize,
        residual: f64,
    },
    Projection {
        row: usize,
        residual: f64,
    },
    /// Strict mode: the warning of this index was raised.
    IllConditioned(usize),
    /// The sink asked to stop.
    Interrupted,
    /// At the recent step rate the span needs about this many steps (see [`StepBudget`]).
    TooManySteps(f64),
}

/// A run whose step rate says it cannot reach t1 within `max_steps` stops early instead of running
/// for minutes into the limit (a span of 1e9 s at the scene's own rate): at 10^4 accepted steps and
/// each doubling after, the steps needed are estimated from the rate since the previous checkpoint
/// (the recent rate, so an initial transient of small steps does not count against the run); the
/// run stops when they exceed [`StepBudget::FACTOR`] times `max_steps`.
struct StepBudget {
    accepted: usize,
    next: usize,
    /// Accepted steps and time at the previous checkpoint.
    since: (usize, f64),
}

impl StepBudget {
    const FIRST: usize = 10_000;
    const FACTOR: f64 = 10.0;

    fn new(t0: f64) -> Self {
        StepBudget {
            accepted: 0,
            next: Self::FIRST,
            since: (0, t0),
        }
    }

    /// Count a step accepted at `t`; the estimated total if it is beyond the budget.
    fn step(&mut self, t: f64, t1: f64, max_steps: usize) -> Option<f64> {
        self.accepted += 1;
        if self.accepted < self.next {
            return None;
        }
        let (n0, ta) = self.since;
        let rate = (self.accepted - n0) as f64 / (t - ta);
        let needed = self.accepted as f64 + rate * (t1 - t);
        self.since = (self.accepted, t);
        self.next = self.next.saturating_mul(2);
        (needed > Self::FACTOR * max_steps as f64).then_some(needed)
    }
}

pub(crate) struct MotionOde<'a, M: Model, C: Constraints> {
    problem: &'a Problem<M, C>,
    settings: &'a Settings,
    ev: Evaluator<'a, M, C, f64>,
    evd: Option<Evaluator<'a, M, C, Dual64>>,
    proj: Projector<'a, M, C>,
    sink: &'a mut dyn SampleSink,
    segments: Vec<Segment>,
    levels: Vec<Level>,
    nv: usize,
    base: Vec<f64>,
    q: Vec<f64>,
    v: Vec<f64>,
    qd: Vec<Dual64>,
    yd: Vec<Dual64>,
    dyd: Vec<Dual64>,
    ybuf: Vec<f64>,
    u: Vec<f64>,
    reac: Vec<f64>,
    res: Vec<f64>,
    rate: Vec<f64>,
    rank: RankTolerances,
    baumgarte: Option<Baumgarte>,
    has_quaternion: bool,
    out_index: usize,
    pub stats: Statistics,
    pub max_residual: Vec<f64>,
    pub max_residual_rate: Vec<f64>,
    pub t_last: f64,
    pub initial_correction: Option<InitialCorrection>,
    /// Conditioning warnings raised so far.
    pub warnings: Vec<Warning>,
    /// Smallest singular value of the t0-scaled B at t0 (s >= 2).
    sigma0: Option<f64>,
    /// With actuators: the decoupling determinant's sign at the last emitted sample (0 before).
    det_sign: f64,
    /// Largest |u| so far above round-off of its terms (the scale of the cancellation test).
    u_scale: f64,
    gram: DMatrix<f64>,
    eigv: DMatrix<f64>,
    /// The last accepted state (at `t_last`) and the time of the last sample handed to the sink.
    acc_q: Vec<f64>,
    acc_v: Vec<f64>,
    last_sample_t: f64,
    budget: StepBudget,
    /// Relative degrees and t0 decoupling row norms of a servo programme (actuators), else None.
    servo_degrees: Option<ServoDegrees>,
    /// The between-evaluations row-gradient monitor ([`DipWatch`]).
    dip: DipWatch,
}

/// Watches each row gradient B_i(t) between accepted states, where the per-evaluation test cannot
/// see it: a row whose gradient passes through (near) zero inside a step has both end values, and
/// every stage value, well above the threshold (issue 28: fixed-step RK4 through Example 3.1's
/// p = q = 0). Over a step B_i is nearly linear in t, so the chord B_i(t0) + s (B_i(t1) - B_i(t0))
/// reveals a passage by its closest approach to 0 (at s* = -B0 . d / |d|^2, d = B1 - B0) however
/// large |B0| and |B1| are; only then is the minimum of |B_i| located on the step's interpolant.
struct DipWatch {
    /// Off for servo programmes (their decoupling rows are watched by det b's sign) and without rows.
    on: bool,
    /// B at the current step's start (row-major s x nv) and whether it is known.
    b0: Vec<f64>,
    b0_valid: bool,
    /// B of every evaluation since the last accepted step: times and row-major matrices.
    rec_t: Vec<f64>,
    rec_b: Vec<f64>,
    /// The step (t0) for which `needs_dense` asked for the interpolant because of a candidate.
    asked: std::cell::Cell<Option<f64>>,
}

impl DipWatch {
    /// Most evaluations remembered within one step (rejected trials included); beyond, the oldest
    /// half is dropped (the accepted trial's evaluations are the latest).
    const MAX_RECORDS: usize = 64;
    /// The chord's closest approach is a candidate below this many times the threshold (margin for
    /// the curvature of B over a step, h^2 |B''| / 8).
    const MARGIN: f64 = 10.0;
    /// Evaluations of B on the interpolant to locate one minimum.
    const MAX_ITER: usize = 12;

    fn record(&mut self, t: f64, b: &DMatrix<f64>) {
        if !self.on {
            return;
        }
        let per = b.len();
        if self.rec_t.len() >= Self::MAX_RECORDS {
            let half = Self::MAX_RECORDS / 2;
            self.rec_t.drain(..half);
            self.rec_b.drain(..half * per);
        }
        self.rec_t.push(t);
        let (s, nv) = b.shape();
        for i in 0..s {
            for k in 0..nv {
                self.rec_b.push(b[(i, k)]);
            }
        }
    }

    /// The latest recorded B at time t (within `tol`), if any.
    fn latest_at(&self, t: f64, tol: f64) -> Option<&[f64]> {
        let per = self.b0.len();
        let k = self.rec_t.iter().rposition(|&x| (x - t).abs() <= tol)?;
        Some(&self.rec_b[k * per..(k + 1) * per])
    }

    /// B at the step's start: an evaluation at t0 after the last accepted step (the exact state,
    /// after any projection) if there was one, else the end of the previous step.
    fn start(&self, t0: f64) -> Option<&[f64]> {
        let per = self.b0.len();
        match self.rec_t.iter().position(|&x| x == t0) {
            Some(k) => Some(&self.rec_b[k * per..(k + 1) * per]),
            None => self.b0_valid.then_some(&self.b0[..]),
        }
    }

    /// End of an accepted step: B at t1 becomes the next step's start; the records are cleared.
    fn step_done(&mut self, t1: f64, tol: f64) {
        if !self.on {
            return;
        }
        let per = self.b0.len();
        let end = self.rec_t.iter().rposition(|&x| (x - t1).abs() <= tol);
        self.b0_valid = end.is_some();
        if let Some(k) = end {
            self.b0.copy_from_slice(&self.rec_b[k * per..(k + 1) * per]);
        }
        self.rec_t.clear();
        self.rec_b.clear();
    }
}

/// The chord from `a` to `b`: its parameter of closest approach to 0 and that distance, when the
/// closest approach lies strictly inside (0, 1).
fn chord_min(a: &[f64], b: &[f64]) -> Option<(f64, f64)> {
    let (mut ad, mut dd) = (0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        ad += x * (y - x);
        dd += (y - x) * (y - x);
    }
    if !(dd > 0.0) {
        return None;
    }
    let s = -ad / dd;
    if !(s > 0.0 && s < 1.0) {
        return None;
    }
    let m = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x + s * (y - x)).powi(2))
        .sum::<f64>()
        .sqrt();
    Some((s, m))
}

/// The servo-constraints' structure at t0: relative degrees, row norms of B, reduction.
type ServoDegrees = (Vec<usize>, Vec<f64>, Option<crate::servo::Reduction>);

/// The initial state of a run while [`MotionOde::new`] checks and assembles it.
struct InitialState<'a, M: Model, C: Constraints> {
    segments: Vec<Segment>,
    q: Vec<f64>,
    v: Vec<f64>,
    levels: Vec<Level>,
    proj: Projector<'a, M, C>,
    /// Residuals and rates of the rows.
    res: Vec<f64>,
    rate: Vec<f64>,
    initial_correction: Option<InitialCorrection>,
    servo_degrees: Option<ServoDegrees>,
}

impl<M: Model, C: Constraints> InitialState<'_, M, C> {
    /// The largest residual of a state row at (t0, q, v) and its row (position rows: residual or
    /// rate; a NaN wins).
    fn worst(&mut self, t0: f64) -> (f64, usize) {
        let (levels, res, rate) = (&self.levels, &mut self.res, &mut self.rate);
        self.proj.residuals(t0, &self.q, &self.v, res, rate);
        let mut w = (0.0f64, 0usize);
        for i in 0..levels.len() {
            if !is_state_row(levels[i]) {
                continue;
            }
            let r = if levels[i] == Level::Position {
                res[i].abs().max(rate[i].abs())
            } else {
                res[i].abs()
            };
            if r > w.0 || r.is_nan() {
                w = (r, i);
            }
        }
        w
    }

    /// Consistency of the rows (2.5): refuse an inconsistent state, or assemble it when the
    /// settings ask for it.
    fn assemble_rows(
        &mut self,
        t0: f64,
        names: &[String],
        settings: &Settings,
    ) -> Result<(), ReturnCode> {
        let (r0, i0) = self.worst(t0);
        if r0 > settings.consistency_tol || r0.is_nan() {
            if !settings.assemble {
                return Err(ReturnCode::InconsistentInitialState {
                    row: names[i0].clone(),
                    residual: r0,
                });
            }
            let rep = self.proj.project(
                t0,
                &mut self.q,
                &mut self.v,
                settings.consistency_tol * 1e-3,
                50,
            );
            let (r1, i1) = self.worst(t0);
            if r1 > settings.consistency_tol || r1.is_nan() {
                return Err(ReturnCode::InconsistentInitialState {
                    row: format!("{} (assembly failed)", names[i1]),
                    residual: r1,
                });
            }
            self.initial_correction = Some(InitialCorrection {
                position: rep.dq,
                velocity: rep.dv,
            });
        }
        Ok(())
    }

    /// The hidden constraints of a servo programme (y^(k), k < r) must hold at t0 too.
    fn assemble_hidden(
        &mut self,
        problem: &Problem<M, C>,
        settings: &Settings,
    ) -> Result<(), ReturnCode> {
        let (m, c, t0) = (&problem.model, &problem.constraints, problem.t0);
        if let (Some((d, _, r)), Some(act)) = (&self.servo_degrees, c.actuation()) {
            let servo = crate::servo::Servo::new(m, c, act).reduced(r.as_ref());
            let hidden_worst = |q: &[f64], v: &[f64]| -> (f64, usize) {
                let mut h = vec![];
                if servo.hidden(t0, q, v, d, &mut h).is_err() {
                    return (f64::NAN, 0);
                }
                h.iter().enumerate().fold((0.0f64, 0), |w, (k, x)| {
                    if x.abs() > w.0 || x.is_nan() {
                        (x.abs(), k)
                    } else {
                        w
                    }
                })
            };
            let names = servo.hidden_names(d);
            let (r0, k0) = hidden_worst(&self.q, &self.v);
            if r0 > settings.consistency_tol || r0.is_nan() {
                if !settings.assemble {
                    return Err(ReturnCode::InconsistentInitialState {
                        row: names[k0].1.clone(),
                        residual: r0,
                    });
                }
                let rep = self.proj.project(
                    t0,
                    &mut self.q,
                    &mut self.v,
                    settings.consistency_tol * 1e-3,
                    50,
                );
                let (r1, k1) = hidden_worst(&self.q, &self.v);
                if r1 > settings.consistency_tol || r1.is_nan() {
                    return Err(ReturnCode::InconsistentInitialState {
                        row: format!("{} (assembly failed)", names[k1].1),
                        residual: r1,
                    });
                }
                self.initial_correction = Some(InitialCorrection {
                    position: rep.dq,
                    velocity: rep.dv,
                });
            }
        }
        Ok(())
    }
}

impl<'a, M: Model, C: Constraints> MotionOde<'a, M, C> {
    /// Check and (optionally) assemble the initial state, emit the first sample.
    pub fn new(
        problem: &'a Problem<M, C>,
        settings: &'a Settings,
        sink: &'a mut dyn SampleSink,
    ) -> Result<Self, ReturnCode> {
        let t0 = problem.t0;
        let init = Self::initial_state(problem, settings)?;
        let mut me = Self::from_initial(problem, settings, sink, init);
        me.acc_q = me.q.clone();
        me.acc_v = me.v.clone();
        let (q0, v0) = (me.q.clone(), me.v.clone());
        if let Err(stop) = me.emit(t0, &q0, &v0) {
            return Err(me.code_of(stop, t0));
        }
        me.dip.step_done(t0, 0.0);
        me.monitor(t0).map_err(|stop| me.code_of(stop, t0))?;
        Ok(me)
    }

    /// The checked initial state: dimensions and finiteness of (q0, v0), q0 normalized, the
    /// servo-constraints' structure at t0, consistency (2.5) of the rows and of the hidden
    /// constraints, assembled when the settings ask for it.
    fn initial_state(
        problem: &'a Problem<M, C>,
        settings: &'a Settings,
    ) -> Result<InitialState<'a, M, C>, ReturnCode> {
        let m = &problem.model;
        let c = &problem.constraints;
        let (nq, nv, s) = (m.nq(), m.nv(), c.rows().len());
        if problem.q0.len() != nq || problem.v0.len() != nv {
            return Err(ReturnCode::InconsistentInitialState {
                row: format!(
                    "dimensions: q0 has {} entries (model nq = {nq}), v0 has {} (nv = {nv})",
                    problem.q0.len(),
                    problem.v0.len()
                ),
                residual: f64::NAN,
            });
        }
        if !problem.q0.iter().chain(&problem.v0).all(|x| x.is_finite()) {
            return Err(ReturnCode::NonFinite { t: problem.t0 });
        }
        let segments = m.segments().to_vec();
        let mut q = problem.q0.clone();
        model::normalize(&segments, &mut q);
        let v = problem.v0.clone();
        let levels: Vec<Level> = c.rows().iter().map(|r| r.level).collect();
        let names: Vec<String> = c.rows().iter().map(|r| r.name.clone()).collect();
        let mut proj = Projector::new(m, c);
        let t0 = problem.t0;
        // Servo-constraints: relative degrees at t0 (the index-reduced system's structure).
        let servo_degrees = match c.actuation() {
            None => None,
            Some(act) => {
                let servo = crate::servo::Servo::new(m, c, act);
                match servo.analyse(t0, &q, &v, settings.rank_dependent) {
                    Ok(an) => Some((an.degrees, an.b_norms, an.reduction)),
                    Err(e) => return Err(super::unrealizable(c, act, t0, e)),
                }
            }
        };
        if let Some((d, _, r)) = &servo_degrees {
            proj.set_servo(d.clone(), r.clone());
        }
        let mut init = InitialState {
            segments,
            q,
            v,
            levels,
            proj,
            // Consistency of the initial state (2.5).
            res: vec![0.0; s],
            rate: vec![0.0; s],
            initial_correction: None,
            servo_degrees,
        };
        init.assemble_rows(t0, &names, settings)?;
        init.assemble_hidden(problem, settings)?;
        Ok(init)
    }

    /// The ODE at the checked initial state, with its evaluator and empty monitors.
    fn from_initial(
        problem: &'a Problem<M, C>,
        settings: &'a Settings,
        sink: &'a mut dyn SampleSink,
        init: InitialState<'a, M, C>,
    ) -> Self {
        let m = &problem.model;
        let c = &problem.constraints;
        let (nq, nv, s) = (m.nq(), m.nv(), c.rows().len());
        let t0 = problem.t0;
        let InitialState {
            segments,
            q,
            v,
            levels,
            proj,
            res,
            rate,
            initial_correction,
            servo_degrees,
        } = init;
        let mut ev = Evaluator::new(m, c);
        if let Some((d, b, r)) = &servo_degrees {
            ev.set_servo(d.clone(), b.clone(), r.clone());
        }
        // Reference row norms for the vanishing-row test.
        ev.set_row_scale_at(t0, &q, &v);
        let baumgarte = match settings.drift {
            DriftControl::Baumgarte { alpha, beta } => Some(Baumgarte { alpha, beta }),
            _ => None,
        };
        MotionOde {
            problem,
            settings,
            ev,
            evd: None,
            proj,
            sink,
            has_quaternion: segments
                .iter()
                .any(|g| matches!(g, Segment::Quaternion { .. })),
            segments,
            levels,
            nv,
            base: q.clone(),
            q,
            v,
            qd: vec![Dual::from_re(0.0); nq],
            yd: vec![Dual::from_re(0.0); 2 * nv],
            dyd: vec![Dual::from_re(0.0); 2 * nv],
            ybuf: vec![0.0; 2 * nv],
            u: vec![0.0; nv],
            reac: vec![0.0; nv],
            res,
            rate,
            rank: settings.rank(),
            baumgarte,
            out_index: 0,
            stats: Statistics::new(),
            max_residual: vec![0.0; s],
            max_residual_rate: vec![0.0; s],
            t_last: t0,
            initial_correction,
            warnings: vec![],
            sigma0: None,
            det_sign: 0.0,
            u_scale: 0.0,
            gram: DMatrix::zeros(s, s),
            eigv: DMatrix::zeros(s, s),
            acc_q: vec![],
            acc_v: vec![],
            last_sample_t: f64::NEG_INFINITY,
            budget: StepBudget::new(t0),
            dip: DipWatch {
                on: s > 0 && c.actuation().is_none(),
                b0: vec![0.0; s * nv],
                b0_valid: false,
                rec_t: vec![],
                rec_b: vec![],
                asked: std::cell::Cell::new(None),
            },
            servo_degrees,
        }
    }

    /// y(t0) = (0, v0).
    pub fn initial_y(&self) -> Vec<f64> {
        let mut y = vec![0.0; 2 * self.nv];
        y[self.nv..].copy_from_slice(&self.v);
        y
    }

    fn eval_f64(&mut self, t: f64, q: &[f64], v: &[f64]) -> Result<(), Stop> {
        if !q.iter().chain(v).all(|x| x.is_finite()) {
            return Err(Stop::NonFinite);
        }
        self.ev
            .evaluate(
                self.settings.formulation,
                &self.rank,
                self.baumgarte,
                t,
                q,
                v,
            )
            .map_err(Stop::Formulation)?;
        self.dip.record(t, &self.ev.jet.b);
        let d = self.ev.diag;
        self.stats.factorizations += d.factorizations;
        self.stats.max_du = self.stats.max_du.max(d.du);
        self.stats.min_b_rcond = self.stats.min_b_rcond.min(d.b_rcond);
        // Conditioning monitor, part 1 (every evaluation: free from the formulation's own work).
        let c = self.settings.conditioning;
        self.stats.min_row_gradient_ratio = self.stats.min_row_gradient_ratio.min(d.row_ratio);
        // u's scale: the largest |u| seen that is not round-off of its terms (a programme that is
        // a natural motion has u = 0 to round-off and nothing to lose).
        if d.u_norm > 1e-12 * d.u_terms {
            self.u_scale = self.u_scale.max(d.u_norm);
        }
        let cancellation = if self.u_scale > 0.0 {
            d.u_terms / self.u_scale
        } else {
            0.0
        };
        self.stats.max_u_cancellation = self.stats.max_u_cancellation.max(cancellation);
        if d.row_ratio < c.row_gradient {
            let k = self.raise(
                WarningKind::RowGradient,
                vec![d.row_ratio_row],
                t,
                d.row_ratio,
                c.row_gradient,
            );
            self.strict_stop(k)?;
        }
        if cancellation > c.u_cancellation {
            let s = self.levels.len();
            let rows = (0..s).filter(|&i| self.ev.lambda[i] != 0.0).collect();
            let k = self.raise(
                WarningKind::UCancellation,
                rows,
                t,
                cancellation,
                c.u_cancellation,
            );
            self.strict_stop(k)?;
        }
        Ok(())
    }

    /// In strict mode a newly raised warning stops the solve.
    fn strict_stop(&self, raised: Option<usize>) -> Result<(), Stop> {
        match raised {
            Some(k) if self.settings.strict => Err(Stop::IllConditioned(k)),
            _ => Ok(()),
        }
    }

    /// Evaluate at (t, q, v) and hand the sample to the sink.
    fn emit(&mut self, t: f64, q: &[f64], v: &[f64]) -> Result<(), Stop> {
        self.eval_f64(t, q, v)?;
        self.ev.reaction(Role::Programme, &mut self.u);
        self.ev.reaction(Role::System, &mut self.reac);
        let s = self.levels.len();
        // Acceleration rows: evaluate h(t, q, v, dv/dt) directly as an independent check.
        let mut hbuf = std::mem::take(&mut self.res);
        {
            let mut ws = self.problem.constraints.workspace::<f64>();
            if self.levels.contains(&Level::Acceleration) {
                self.problem
                    .constraints
                    .eval(&mut ws, t, q, v, &self.ev.acc, &mut hbuf);
            }
        }
        for i in 0..s {
            match self.levels[i] {
                Level::Acceleration => {}
                _ => hbuf[i] = self.ev.jet.value[i],
            }
            self.rate[i] = self.ev.jet.gdot[i];
        }
        self.sink.sample(&Sample {
            t,
            q,
            v,
            a: &self.ev.acc,
            u: &self.u,
            reactions: &self.reac,
            lambda: &self.ev.lambda,
            residual: &hbuf,
            residual_rate: &self.rate,
        });
        // Every emitted sample counts towards the reported maxima (step ends are also monitored).
        for i in 0..s {
            self.max_residual[i] = self.max_residual[i].max(hbuf[i].abs());
            self.max_residual_rate[i] = self.max_residual_rate[i].max(self.rate[i].abs());
        }
        self.res = hbuf;
        self.out_index += 1;
        self.last_sample_t = t;
        self.decoupling_sign(t)?;
        self.conditioning(t)
    }

    /// With actuators: det b changing sign between two samples means the decoupling matrix passed
    /// through singular between them (tau has a pole there), however narrow the region where the
    /// per-evaluation row test would see it: a row_gradient warning with value 0.
    fn decoupling_sign(&mut self, t: f64) -> Result<(), Stop> {
        let sign = self.ev.diag.det_sign;
        if sign == 0.0 {
            return Ok(());
        }
        let before = std::mem::replace(&mut self.det_sign, sign);
        if before != 0.0 && before != sign {
            let rows = (0..self.levels.len()).collect();
            let threshold = self.settings.conditioning.row_gradient;
            let k = self.raise(WarningKind::RowGradient, rows, t, 0.0, threshold);
            self.strict_stop(k)?;
        }
        Ok(())
    }

    /// Conditioning monitor, part 2 (every output sample): the smallest singular value of
    /// diag(1/|B_i(t0)|) B against its t0 value, i.e. rows becoming dependent (s >= 2).
    fn conditioning(&mut self, t: f64) -> Result<(), Stop> {
        let s = self.levels.len();
        if s < 2 {
            return Ok(());
        }
        let nv = self.nv;
        let b = &self.ev.jet.b;
        let scale = &self.ev.row_scale;
        for i in 0..s {
            for j in 0..=i {
                let g = (0..nv).map(|k| b[(i, k)] * b[(j, k)]).sum::<f64>()
                    / (scale[i] * scale[j]).max(f64::MIN_POSITIVE);
                self.gram[(i, j)] = g;
                self.gram[(j, i)] = g;
            }
        }
        let k = crate::linalg::sym_eigen(&mut self.gram, s, &mut self.eigv);
        let sigma = self.gram[(k, k)].max(0.0).sqrt();
        let sigma0 = *self.sigma0.get_or_insert(sigma);
        let ratio = if sigma0 > 0.0 { sigma / sigma0 } else { 1.0 };
        self.stats.min_singular_value_ratio = self.stats.min_singular_value_ratio.min(ratio);
        let threshold = self.settings.conditioning.singular_value;
        if ratio < threshold {
            let big = (0..s).map(|i| self.eigv[(i, k)].abs()).fold(0.0, f64::max);
            let rows = (0..s)
                .filter(|&i| self.eigv[(i, k)].abs() >= 0.3 * big)
                .collect();
            let raised = self.raise(WarningKind::SingularValue, rows, t, ratio, threshold);
            self.strict_stop(raised)?;
        }
        Ok(())
    }

    /// Rows whose gradient's chord over the step [t0, t1] passes closer to 0 than
    /// [`DipWatch::MARGIN`] times the threshold (relative to the row's t0 norm), with B at t1 from
    /// the latest evaluation there (the last stage, or the state itself once evaluated).
    fn dip_rows(&self, t0: f64, t1: f64) -> Vec<usize> {
        let w = &self.dip;
        if !w.on {
            return vec![];
        }
        let tol = 1e-9 * (t1 - t0).abs();
        let (Some(b0), Some(b1)) = (w.start(t0), w.latest_at(t1, tol)) else {
            return vec![];
        };
        let nv = self.nv;
        let limit = DipWatch::MARGIN * self.settings.conditioning.row_gradient;
        let scale = &self.ev.row_scale;
        (0..self.levels.len())
            .filter(|&i| {
                let r = i * nv..(i + 1) * nv;
                chord_min(&b0[r.clone()], &b1[r])
                    .is_some_and(|(_, m)| m < limit * scale[i].max(f64::MIN_POSITIVE))
            })
            .collect()
    }

    /// The minimum of |B_i| / |B_i(t0)| over the step on the interpolant `dense` (None: only the
    /// chord is known): chords between bracketing points, each new point where the chord comes
    /// closest to 0, keeping the half where d|B_i|^2/dt changes sign (B_m . d > 0: the minimum lies
    /// before t_m). Exact in one evaluation when B_i is linear in t. Returns (ratio, time).
    fn locate_dip(
        &mut self,
        i: usize,
        t0: f64,
        t1: f64,
        dense: Option<&dyn DenseOutput>,
    ) -> Option<(f64, f64)> {
        let nv = self.nv;
        let tol = 1e-9 * (t1 - t0).abs();
        let r = i * nv..(i + 1) * nv;
        let mut a = self.dip.start(t0)?[r.clone()].to_vec();
        let mut b = self.dip.latest_at(t1, tol)?[r].to_vec();
        let scale = self.ev.row_scale[i].max(f64::MIN_POSITIVE);
        let norm = |x: &[f64]| x.iter().map(|v| v * v).sum::<f64>().sqrt();
        let (mut ta, mut tb) = (t0, t1);
        let (s, m) = chord_min(&a, &b)?;
        let mut best = (norm(&a).min(norm(&b)) / scale, t0 + s * (t1 - t0));
        let Some(dense) = dense else {
            return Some((m / scale, best.1));
        };
        let mut bm = vec![0.0; nv];
        for _ in 0..DipWatch::MAX_ITER {
            let Some((s, _)) = chord_min(&a, &b) else {
                break;
            };
            let tm = ta + s * (tb - ta);
            if !(tm > ta && tm < tb) {
                break;
            }
            let mut yb = std::mem::take(&mut self.ybuf);
            dense.eval(tm, &mut yb);
            self.chart_to_q(&yb);
            let q = std::mem::take(&mut self.q);
            self.ev.prepare(tm, &q, &yb[nv..]);
            self.q = q;
            self.ybuf = yb;
            for k in 0..nv {
                bm[k] = self.ev.jet.b[(i, k)];
            }
            let ratio = norm(&bm) / scale;
            if !ratio.is_finite() {
                break;
            }
            let improved = ratio < best.0;
            if improved {
                best = (ratio, tm);
            }
            let ahead: f64 = (0..nv).map(|k| bm[k] * (b[k] - a[k])).sum();
            if ahead > 0.0 {
                b.copy_from_slice(&bm);
                tb = tm;
            } else {
                a.copy_from_slice(&bm);
                ta = tm;
            }
            if !improved || tb - ta <= 1e-12 * (t1 - t0) {
                break;
            }
        }
        Some(best)
    }

    /// The between-evaluations row test of the step [t0, t1] ([`DipWatch`]): a row whose gradient
    /// dips below the threshold inside the step raises row_gradient at the located minimum.
    fn watch_step(
        &mut self,
        t0: f64,
        t1: f64,
        dense: &dyn DenseOutput,
        has_dense: bool,
    ) -> Result<(), Stop> {
        let rows = self.dip_rows(t0, t1);
        let threshold = self.settings.conditioning.row_gradient;
        for i in rows {
            let Some((ratio, tm)) = self.locate_dip(i, t0, t1, has_dense.then_some(dense)) else {
                continue;
            };
            self.stats.min_row_gradient_ratio = self.stats.min_row_gradient_ratio.min(ratio);
            if ratio < threshold {
                let k = self.raise(WarningKind::RowGradient, vec![i], tm, ratio, threshold);
                self.strict_stop(k)?;
            }
        }
        Ok(())
    }

    /// Record a threshold crossing; returns the index of its warning (new or updated). In strict mode
    /// every crossing is an error, so the integrator's step shrinking localizes the first one.
    fn raise(
        &mut self,
        kind: WarningKind,
        rows: Vec<usize>,
        t: f64,
        value: f64,
        threshold: f64,
    ) -> Option<usize> {
        let names: Vec<String> = rows
            .iter()
            .map(|&i| self.problem.constraints.rows()[i].name.clone())
            .collect();
        let worse = |a: f64, b: f64| match kind {
            WarningKind::UCancellation | WarningKind::GlobalError => a > b,
            _ => a < b,
        };
        if let Some(k) = self
            .warnings
            .iter()
            .position(|w| w.kind == kind && w.rows == names)
        {
            let w = &mut self.warnings[k];
            if worse(value, w.worst) {
                w.worst = value;
                w.t_worst = t;
            }
            return Some(k);
        }
        let w = Warning {
            kind,
            t,
            rows: names,
            value,
            worst: value,
            t_worst: t,
            threshold,
            error_before: None,
            error_after: None,
        };
        self.sink.warning(&w);
        self.warnings.push(w);
        Some(self.warnings.len() - 1)
    }

    /// Residuals of the state rows at the current (q, v); stop on drift beyond `max_drift`.
    fn monitor(&mut self, t: f64) -> Result<(), Stop> {
        let (q, v) = (std::mem::take(&mut self.q), std::mem::take(&mut self.v));
        self.proj
            .residuals(t, &q, &v, &mut self.res, &mut self.rate);
        self.q = q;
        self.v = v;
        for i in 0..self.levels.len() {
            if !is_state_row(self.levels[i]) {
                continue;
            }
            let r = self.res[i].abs();
            let rr = self.rate[i].abs();
            if r.is_nan() || rr.is_nan() {
                return Err(Stop::NonFinite);
            }
            self.max_residual[i] = self.max_residual[i].max(r);
            self.max_residual_rate[i] = self.max_residual_rate[i].max(rr);
            if let Some(lim) = self.settings.max_drift {
                if r.max(rr) > lim {
                    return Err(Stop::Drift {
                        row: i,
                        residual: r.max(rr),
                    });
                }
            }
        }
        Ok(())
    }

    fn code_of(&self, stop: Stop, t: f64) -> ReturnCode {
        let names = |rows: &[usize]| -> Vec<String> {
            rows.iter()
                .map(|&i| self.problem.constraints.rows()[i].name.clone())
                .collect()
        };
        match stop {
            Stop::Formulation(FormulationError::RankDeficient { rows, rcond, .. }) => {
                ReturnCode::SingularProgramme {
                    t,
                    rows: names(&rows),
                    rcond,
                }
            }
            Stop::Formulation(FormulationError::SingularSystem { rcond }) => {
                ReturnCode::SingularSystem { t, rcond }
            }
            Stop::Formulation(FormulationError::NonFinite) => ReturnCode::NonFinite { t },
            Stop::Formulation(FormulationError::Unrealizable { rcond }) => {
                let c = &self.problem.constraints;
                ReturnCode::UnrealizableProgramme {
                    t,
                    rows: c.rows().iter().map(|r| r.name.clone()).collect(),
                    actuators: c.actuation().map(|a| a.names.clone()).unwrap_or_default(),
                    reached: true,
                    rcond,
                }
            }
            Stop::NonFinite => ReturnCode::NonFinite { t },
            Stop::Drift { row, residual } => ReturnCode::DriftExceeded {
                t,
                row: names(&[row])[0].clone(),
                residual,
            },
            Stop::Projection { row, residual } => ReturnCode::ProjectionFailed {
                t,
                row: names(&[row])[0].clone(),
                residual,
            },
            Stop::IllConditioned(k) => ReturnCode::IllConditioned {
                t,
                warning: Box::new(self.warnings[k].clone()),
            },
            Stop::Interrupted => ReturnCode::Interrupted { t },
            Stop::TooManySteps(needed) => ReturnCode::TooManySteps {
                t,
                needed,
                max_steps: self.settings.max_steps,
            },
        }
    }

    /// Map the integrator's outcome to a return code. On an early stop the last accepted state
    /// is written as the final sample (if it was not), and the code, `t_last` and that sample
    /// name one instant: the last state the solve stands behind.
    pub fn finish(&mut self, outcome: Outcome<Stop>) -> ReturnCode {
        let code = match outcome {
            Outcome::Finished => return ReturnCode::Success,
            Outcome::StepTooSmall { t, h } => ReturnCode::StepTooSmall { t, h },
            Outcome::MaxSteps { t } => ReturnCode::MaxSteps { t },
            Outcome::NonFinite { t } => ReturnCode::NonFinite { t },
            Outcome::Problem { t, error } => self.code_of(error, t),
        };
        if self.last_sample_t < self.t_last {
            let (q, v) = (self.acc_q.clone(), self.acc_v.clone());
            // A failure here leaves the previous sample as the last one.
            let _ = self.emit(self.t_last, &q, &v);
        }
        self.t_last = self.last_sample_t;
        code.at(self.t_last)
    }

    /// q = base (+) delta into `self.q`.
    fn chart_to_q(&mut self, y: &[f64]) {
        model::retract(&self.segments, &self.base, &y[..self.nv], &mut self.q);
    }
}

impl<'a, M: Model, C: Constraints> OdeProblem for MotionOde<'a, M, C> {
    type Error = Stop;

    fn dim(&self) -> usize {
        2 * self.nv
    }

    fn rhs(&mut self, t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), Stop> {
        let nv = self.nv;
        self.chart_to_q(y);
        let q = std::mem::take(&mut self.q);
        let r = self.eval_f64(t, &q, &y[nv..]);
        self.q = q;
        r?;
        model::chart_rate(&self.segments, &y[..nv], &y[nv..], &mut dy[..nv]);
        dy[nv..].copy_from_slice(&self.ev.acc);
        Ok(())
    }

    fn jacobian(&mut self, t: f64, y: &[f64], jac: &mut DMatrix<f64>) -> Result<(), Stop> {
        let nv = self.nv;
        if self.evd.is_none() {
            let mut e = Evaluator::new(&self.problem.model, &self.problem.constraints);
            e.row_scale = self.ev.row_scale.clone();
            if let Some((d, b, r)) = &self.servo_degrees {
                e.set_servo(d.clone(), b.clone(), r.clone());
            }
            self.evd = Some(e);
        }
        let evd = self.evd.as_mut().expect("created above");
        for j in 0..2 * nv {
            for k in 0..2 * nv {
                self.yd[k] = Dual::new(y[k], if k == j { 1.0 } else { 0.0 });
            }
            model::retract(&self.segments, &self.base, &self.yd[..nv], &mut self.qd);
            evd.evaluate(
                self.settings.formulation,
                &self.rank,
                self.baumgarte,
                Dual::from_re(t),
                &self.qd,
                &self.yd[nv..],
            )
            .map_err(Stop::Formulation)?;
            model::chart_rate(
                &self.segments,
                &self.yd[..nv],
                &self.yd[nv..],
                &mut self.dyd[..nv],
            );
            self.dyd[nv..].copy_from_slice(&evd.acc);
            for i in 0..2 * nv {
                jac[(i, j)] = self.dyd[i].eps;
            }
        }
        Ok(())
    }

    fn error_scale(&self, y0: &[f64], y1: &[f64], atol: f64, rtol: f64, out: &mut [f64]) {
        let nv = self.nv;
        for seg in &self.segments {
            match *seg {
                Segment::Euclidean { q: iq, v: iv, len } => {
                    for k in 0..len {
                        let a = (self.base[iq + k] + y0[iv + k]).abs();
                        let b = (self.base[iq + k] + y1[iv + k]).abs();
                        out[iv + k] = atol + rtol * a.max(b);
                    }
                }
                Segment::Quaternion { v: iv, .. } => {
                    for k in 0..3 {
                        out[iv + k] = atol + rtol;
                    }
                }
            }
        }
        for i in nv..2 * nv {
            out[i] = atol + rtol * y0[i].abs().max(y1[i].abs());
        }
    }

    /// Only interior output times read the dense output (`Output::Every`, the same test as in
    /// `accepted`); with output at step ends or at t1 only, the integrator skips it.
    fn needs_dense(&self, t0: f64, t1: f64) -> bool {
        // A row gradient whose chord dips inside the step: its minimum is located on the interpolant.
        if !self.dip_rows(t0, t1).is_empty() {
            self.dip.asked.set(Some(t0));
            return true;
        }
        let Output::Every(dt) = self.settings.output else {
            return false;
        };
        let (ts, te) = (self.problem.t0, self.problem.t1);
        let mut k = self.out_index;
        loop {
            let tk = ts + k as f64 * dt;
            if tk >= t1 - 1e-12 * t1.abs().max(1.0) || tk > te {
                return false;
            }
            if tk > t0 {
                return true;
            }
            k += 1;
        }
    }

    fn accepted(
        &mut self,
        t0: f64,
        t1: f64,
        y: &mut [f64],
        dense: &dyn DenseOutput,
    ) -> Result<Accept, Stop> {
        let nv = self.nv;
        let (ts, te) = (self.problem.t0, self.problem.t1);
        // Row gradients between the evaluations (before any output: a strict stop keeps t0 as the
        // last state). The interpolant is there when `needs_dense` asked for it (Radau: always).
        let has_dense = self.dip.asked.take() == Some(t0)
            || matches!(self.settings.integrator, crate::integrate::Method::Radau5);
        self.watch_step(t0, t1, dense, has_dense)?;
        // Interior output times from the dense output (before any projection of the step end).
        if let Output::Every(dt) = self.settings.output {
            loop {
                let tk = ts + self.out_index as f64 * dt;
                if tk >= t1 - 1e-12 * t1.abs().max(1.0) || tk > te {
                    break;
                }
                if tk <= t0 {
                    self.out_index += 1;
                    continue;
                }
                let mut yb = std::mem::take(&mut self.ybuf);
                dense.eval(tk, &mut yb);
                self.chart_to_q(&yb);
                let mut q = std::mem::take(&mut self.q);
                // The interpolant is not on the manifold: with projection on, samples are projected
                // like step ends, so every output sample meets the programme to the same tolerance.
                if let DriftControl::Projection { tol, max_iter } = self.settings.drift {
                    self.proj.project(tk, &mut q, &mut yb[nv..], tol, max_iter);
                }
                let r = self.emit(tk, &q, &yb[nv..]);
                self.q = q;
                self.ybuf = yb;
                r?;
            }
        }
        // The new state, re-centred and projected.
        self.chart_to_q(y);
        self.v.copy_from_slice(&y[nv..]);
        let mut changed = false;
        if let DriftControl::Projection { tol, max_iter } = self.settings.drift {
            let (mut q, mut v) = (std::mem::take(&mut self.q), std::mem::take(&mut self.v));
            let rep = self.proj.project(t1, &mut q, &mut v, tol, max_iter);
            self.q = q;
            self.v = v;
            if rep.iterations > 0 {
                changed = true;
                self.stats.projections += 1;
                self.stats.projection_iterations += rep.iterations;
                self.stats.max_position_correction = self.stats.max_position_correction.max(rep.dq);
                self.stats.max_velocity_correction = self.stats.max_velocity_correction.max(rep.dv);
            }
            if !rep.converged && !(rep.residual <= 1e3 * tol) {
                self.t_last = t1;
                self.acc_q.copy_from_slice(&self.q);
                self.acc_v.copy_from_slice(&self.v);
                return Err(Stop::Projection {
                    row: rep.row,
                    residual: rep.residual,
                });
            }
        }
        if changed || (self.has_quaternion && model::chart_angle(&self.segments, &y[..nv]) > 0.5) {
            model::normalize(&self.segments, &mut self.q);
            self.base.copy_from_slice(&self.q);
            for x in &mut y[..nv] {
                *x = 0.0;
            }
            y[nv..].copy_from_slice(&self.v);
            changed = true;
        }
        self.t_last = t1;
        self.acc_q.copy_from_slice(&self.q);
        self.acc_v.copy_from_slice(&self.v);
        self.monitor(t1)?;
        let at_output = match self.settings.output {
            Output::Steps => true,
            Output::Every(dt) => {
                let tk = ts + self.out_index as f64 * dt;
                (tk - t1).abs() <= 1e-12 * t1.abs().max(1.0) || t1 >= te
            }
        };
        if at_output {
            let (q, v) = (self.q.clone(), self.v.clone());
            self.emit(t1, &q, &v)?;
        }
        self.dip.step_done(t1, 1e-9 * (t1 - t0));
        // A stop request, or a step rate that cannot reach te, ends the run at this step (unless
        // it completed the span).
        if t1 < te {
            if self.sink.interrupted() {
                return Err(Stop::Interrupted);
            }
            if let Some(n) = self.budget.step(t1, te, self.settings.max_steps) {
                return Err(Stop::TooManySteps(n));
            }
        }
        Ok(if changed {
            Accept::Changed
        } else {
            Accept::Unchanged
        })
    }
}
