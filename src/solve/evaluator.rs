//! One evaluation of the programmed-motion right-hand side at (t, q, v): dv/dt and multipliers.

use crate::formulation::{
    Diagnostics, Formulation, FormulationError, FormulationWork, MassOperator, RankTolerances,
};
use crate::linalg::Singular;
use crate::model::Model;
use crate::programme::jet::Jet;
use crate::programme::{Constraints, Level, Role};
use crate::scalar::{re, Scalar};
use nalgebra::DMatrix;

/// Baumgarte stabilization gains: velocity rows get d f/dt = -alpha f, position rows
/// d^2 g/dt^2 = -2 alpha dg/dt - beta^2 g (Baumgarte, CMAME 1 (1972) 1-16).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Baumgarte {
    /// Damping gain alpha (1/s).
    pub alpha: f64,
    /// Stiffness gain beta (1/s).
    pub beta: f64,
}

/// Preallocated state of the right-hand side for scalar type `S`.
pub struct Evaluator<'a, M: Model, C: Constraints, S: Scalar> {
    model: &'a M,
    cons: &'a C,
    mws: M::Workspace<S>,
    /// Derivatives of the constraint rows at the last evaluated state.
    pub jet: Jet<C, S>,
    fw: FormulationWork<S>,
    /// Mass matrix A(q) at the last [`Evaluator::prepare`], [`Evaluator::prepare_geometry`] or
    /// evaluation with a dense formulation (the articulated-body formulation on a tree never forms
    /// it, and leaves it as it was).
    pub mass: DMatrix<S>,
    /// F = G + Q at the last state.
    pub force: Vec<S>,
    qf: Vec<S>,
    /// dv/dt at the last state.
    pub acc: Vec<S>,
    /// Multipliers: A dv/dt - F = B^T lambda.
    pub lambda: Vec<S>,
    /// Diagnostics of the last solve.
    pub diag: Diagnostics,
    /// Reference norm of each row of B (its norm at the initial state) for the vanishing test.
    pub row_scale: Vec<f64>,
    /// With actuators: the rows' relative degrees found at t0 ([`crate::servo::Servo::analyse`]);
    /// dv/dt then comes from the index-reduced servo system and `lambda` holds tau.
    servo_degrees: Option<Vec<usize>>,
    /// With actuators: each decoupling row's norm at t0 (reference of the vanishing-row test).
    servo_b_norms: Vec<f64>,
    /// The servo passes' workspaces, kept for the solve.
    servo_work: crate::servo::WorkCache,
    /// The structure algorithm's step, when the decoupling matrix was rank-deficient at t0.
    servo_reduction: Option<crate::servo::Reduction>,
    /// With actuators: u = H(t, q) tau at the last state.
    servo_u: Vec<S>,
    /// Buffers of u = H(t, q) tau (the actuators' expression entries).
    servo_force: crate::programme::actuation::ForceWork<S>,
    /// The constraint jet reads the model's forward passes ([`Model::tree_sweep`]); off, it runs
    /// its own (the plain computation the tests and the bench compare with).
    share_sweep: bool,
}

impl<'a, M: Model, C: Constraints, S: Scalar> Evaluator<'a, M, C, S> {
    /// Allocate everything for `model` and `cons`.
    pub fn new(model: &'a M, cons: &'a C) -> Self {
        let (nq, nv, s) = (model.nq(), model.nv(), cons.rows().len());
        let z = S::zero();
        Evaluator {
            model,
            cons,
            mws: model.workspace(),
            jet: Jet::new(cons, model.segments(), nq, nv),
            fw: FormulationWork::new(nv, s),
            mass: DMatrix::from_element(nv, nv, z),
            force: vec![z; nv],
            qf: vec![z; nv],
            acc: vec![z; nv],
            lambda: vec![z; s],
            diag: Diagnostics::default(),
            row_scale: vec![1.0; s],
            servo_degrees: None,
            servo_b_norms: vec![],
            servo_work: Default::default(),
            servo_reduction: None,
            servo_u: vec![z; nv],
            servo_force: Default::default(),
            share_sweep: true,
        }
    }

    /// One sweep per state (the default): the mass matrix, the forces and the constraint jet share
    /// the model's forward kinematics and velocities. `false`: the jet runs its own passes (same
    /// values; for the tests and the bench that compare the two).
    pub fn set_shared_sweep(&mut self, on: bool) {
        self.share_sweep = on;
    }

    /// The model's workspace (the tests read its pass counts through [`Model::tree_sweep`]).
    pub fn model_workspace(&mut self) -> &mut M::Workspace<S> {
        &mut self.mws
    }

    /// The constraint jet at (t, q, v), after the model's passes at the same state.
    fn compute_jet(&mut self, t: S, q: &[S], v: &[S]) {
        let model = self.model;
        let sweep = if self.share_sweep {
            model.tree_sweep(&mut self.mws)
        } else {
            None
        };
        self.jet
            .compute_with(self.cons, model.segments(), t, q, v, sweep);
    }

    /// Solve the servo system with these relative degrees and t0 decoupling row norms
    /// ([`crate::servo::Analysis`]; the constraints carry actuators).
    pub fn set_servo(
        &mut self,
        degrees: Vec<usize>,
        b_norms: Vec<f64>,
        reduction: Option<crate::servo::Reduction>,
    ) {
        self.servo_degrees = Some(degrees);
        self.servo_reduction = reduction;
        self.servo_b_norms = b_norms;
    }

    /// Take the reference row norms of the vanishing-row test (|B_i| at (t, q, v)); a solve takes
    /// them at its initial state, and so must every caller that wants the solver's rank decisions.
    pub fn set_row_scale_at(&mut self, t: S, q: &[S], v: &[S]) {
        self.prepare(t, q, v);
        for i in 0..self.row_scale.len() {
            let n2 = (0..self.jet.b.ncols())
                .map(|j| re(self.jet.b[(i, j)]) * re(self.jet.b[(i, j)]))
                .sum::<f64>();
            self.row_scale[i] = n2.sqrt();
        }
    }

    /// A and the constraint jet at (t, q, v): what projection needs (no forces).
    pub fn prepare_geometry(&mut self, t: S, q: &[S], v: &[S]) {
        self.model.mass_matrix(&mut self.mws, q, &mut self.mass);
        self.compute_jet(t, q, v);
    }

    /// A, F = G + Q and the constraint jet at (t, q, v), without solving.
    pub fn prepare(&mut self, t: S, q: &[S], v: &[S]) {
        self.model.mass_matrix(&mut self.mws, q, &mut self.mass);
        self.model
            .natural_forces(&mut self.mws, t, q, v, &mut self.force, &mut self.qf);
        self.compute_jet(t, q, v);
    }

    /// Solve for dv/dt and the multipliers at (t, q, v). Allocates nothing unless it fails.
    /// `formulation` is resolved by [`Formulation::resolve`] (`auto`: by nv and the model).
    pub fn evaluate(
        &mut self,
        formulation: Formulation,
        tol: &RankTolerances,
        baumgarte: Option<Baumgarte>,
        t: S,
        q: &[S],
        v: &[S],
    ) -> Result<(), FormulationError> {
        let cons = self.cons;
        if let (Some(act), Some(deg)) = (cons.actuation(), self.servo_degrees.take()) {
            // the servo system (actuators) solves its own equations on the prepared state
            // (the degrees lent out and put back: no copy per call)
            self.prepare(t, q, v);
            let r = self.evaluate_servo(act, &deg, tol, t, q, v);
            self.servo_degrees = Some(deg);
            return r;
        }
        let factored = self.model.has_mass_factor();
        let formulation = formulation.resolve(self.model.nv(), factored);
        // the articulated-body formulation on a tree: A is never formed
        let factored = factored && formulation == Formulation::ArticulatedBody;
        if factored {
            self.model
                .natural_forces(&mut self.mws, t, q, v, &mut self.force, &mut self.qf);
            self.compute_jet(t, q, v);
        } else {
            self.prepare(t, q, v);
        }
        if let Some(bg) = baumgarte {
            for i in 0..self.jet.rows() {
                let level = self.jet.levels()[i];
                match level {
                    Level::Velocity => self.jet.gamma[i] -= self.jet.value[i] * bg.alpha,
                    Level::Position => {
                        self.jet.gamma[i] -= self.jet.gdot[i] * (2.0 * bg.alpha)
                            + self.jet.value[i] * (bg.beta * bg.beta)
                    }
                    Level::Acceleration => {}
                }
            }
        }
        self.diag = if factored {
            let mut op = ModelMass {
                model: self.model,
                ws: &mut self.mws,
                q,
            };
            self.fw.solve_factored(
                &mut op,
                &self.force,
                &self.jet.b,
                &self.jet.gamma,
                &self.row_scale,
                tol,
                &mut self.acc,
                &mut self.lambda,
            )?
        } else {
            self.fw.solve(
                formulation,
                &self.mass,
                &self.force,
                &self.jet.b,
                &self.jet.gamma,
                &self.row_scale,
                tol,
                &mut self.acc,
                &mut self.lambda,
            )?
        };
        Ok(())
    }

    /// dv/dt and tau (into `lambda`) of the index-reduced servo system at the prepared state.
    fn evaluate_servo(
        &mut self,
        act: &crate::servo::Actuation,
        degrees: &[usize],
        tol: &RankTolerances,
        t: S,
        q: &[S],
        v: &[S],
    ) -> Result<(), FormulationError> {
        let servo = crate::servo::Servo::new(self.model, self.cons, act)
            .reduced(self.servo_reduction.as_ref())
            .cached(&self.servo_work);
        let dec = servo
            .solve(
                t,
                q,
                v,
                degrees,
                &self.servo_b_norms,
                tol.dependent,
                &mut self.lambda,
                &mut self.acc,
            )
            .map_err(|e| FormulationError::Unrealizable { rcond: e.rcond })?;
        if !self
            .acc
            .iter()
            .chain(&self.lambda)
            .all(|x| re(*x).is_finite())
        {
            return Err(FormulationError::NonFinite);
        }
        self.servo_u.iter_mut().for_each(|x| *x = S::zero());
        act.add_force_with(
            &mut self.servo_force,
            t,
            q,
            &self.lambda[..act.len()],
            &mut self.servo_u,
        );
        let u_norm = self.lambda.iter().fold(0.0f64, |m, x| m.max(re(*x).abs()));
        let f_norm = self.force.iter().fold(0.0f64, |m, x| m.max(re(*x).abs()));
        self.diag = Diagnostics {
            b_rcond: 1.0,
            system_rcond: dec.rcond,
            du: 0.0,
            factorizations: 1,
            // The decoupling row's collapse feeds the conditioning monitor's row-gradient test.
            row_ratio: dec.row_ratio,
            row_ratio_row: dec.row,
            u_norm,
            u_terms: u_norm.max(f_norm),
            det_sign: dec.det_sign,
        };
        Ok(())
    }

    /// Reaction of the rows with role `role`: sum over those rows of B_i^T lambda_i (2.12).
    pub fn reaction(&self, role: Role, out: &mut [S]) {
        for x in out.iter_mut() {
            *x = S::zero();
        }
        if self.cons.actuation().is_some() && self.servo_degrees.is_some() {
            // u = H(t, q) tau (the actuators' generalized forces, kept by the last evaluation);
            // no system rows with actuators.
            if role == Role::Programme {
                out.copy_from_slice(&self.servo_u);
            }
            return;
        }
        for (i, spec) in self.cons.rows().iter().enumerate() {
            if spec.role == role {
                for j in 0..out.len() {
                    out[j] += self.jet.b[(i, j)] * self.lambda[i];
                }
            }
        }
    }
}

/// A model's articulated-body factorization at q as the formulation's [`MassOperator`].
struct ModelMass<'m, 'w, 'q, M: Model, S: Scalar> {
    model: &'m M,
    ws: &'w mut M::Workspace<S>,
    q: &'q [S],
}

impl<M: Model, S: Scalar> MassOperator<S> for ModelMass<'_, '_, '_, M, S> {
    fn factor(&mut self) -> Result<f64, Singular> {
        self.model.mass_factor(self.ws, self.q)
    }
    fn solve(&mut self, x: &mut [S]) {
        self.model.mass_solve(self.ws, x)
    }
    fn solve_block(&mut self, x: &mut [S], cols: usize) {
        self.model.mass_solve_block(self.ws, x, cols)
    }
    fn mul(&mut self, x: &[S], out: &mut [S]) {
        self.model.mass_mul(self.ws, x, out)
    }
}
