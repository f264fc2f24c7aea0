//! The actuation map H of servo-constraints (A dv/dt - F = H tau): which generalized forces the
//! actuators can apply. It belongs to the problem (the programme and the actuators that must
//! realize it); the servo module reduces the index with it.

use crate::scalar::Scalar;

/// The actuation map H (n x m): column j is the generalized force of actuator j per unit tau_j, a
/// unit vector on one joint's velocity (`joint = ...`) or a direction over the velocities
/// (`direction = {...}`, e.g. a force acting between two joints). A direction's entries may be
/// expressions of t and the coordinates ([`MapEntry`]: a cable whose line of pull turns with the
/// motion); H is then evaluated at each state, with the scalar type of the caller, so the Lie
/// derivatives differentiate it exactly.
#[derive(Clone, Debug, PartialEq)]
pub struct Actuation {
    /// Actuator names (for messages and outputs), in file order.
    pub names: Vec<String>,
    /// The columns of H at the state the map was built at (the initial state), each of length n.
    columns: Vec<Vec<f64>>,
    /// The same with the state-dependent entries set to zero (the part [`Actuation::add_force`]
    /// does not evaluate).
    fixed: Vec<Vec<f64>>,
    /// The state-dependent entries.
    entries: Vec<MapEntry>,
    /// Orthonormal basis of range(H) at the build state (modified Gram-Schmidt), for the
    /// component of a force outside it.
    basis: Vec<Vec<f64>>,
}

/// Entry (row, col) of H as an expression over the slots [t, q_0, .., q_{nq-1}].
#[derive(Clone, Debug, PartialEq)]
pub struct MapEntry {
    /// Velocity index (row of H).
    pub row: usize,
    /// Actuator index (column of H).
    pub col: usize,
    /// The entry's expression (slot 0 is t, slot 1 + i is q_i).
    pub expr: crate::expr::Expr,
}

/// Why a set of actuation columns is not an actuation map.
#[derive(Clone, Debug, PartialEq)]
pub enum ActuationError {
    /// Column `j` is zero or a combination of the columns before it (|residual| / |column|).
    Dependent { column: usize, ratio: f64 },
}

impl Actuation {
    /// Columns below this relative residual after removing the earlier columns are dependent.
    pub const DEPENDENT: f64 = 1e-10;

    /// H from its constant columns (all of one length n, independent).
    pub fn new(names: Vec<String>, columns: Vec<Vec<f64>>) -> Result<Self, ActuationError> {
        let basis = Self::orthonormal(&columns)?;
        Ok(Actuation {
            names,
            fixed: columns.clone(),
            columns,
            entries: vec![],
            basis,
        })
    }

    /// H with state-dependent entries: `columns` hold the constant entries (the entries' slots are
    /// overwritten), checked independent at (t, q).
    pub fn with_entries(
        names: Vec<String>,
        columns: Vec<Vec<f64>>,
        entries: Vec<MapEntry>,
        t: f64,
        q: &[f64],
    ) -> Result<Self, ActuationError> {
        let mut fixed = columns;
        for e in &entries {
            fixed[e.col][e.row] = 0.0;
        }
        let mut act = Actuation {
            names,
            columns: fixed.clone(),
            fixed,
            entries,
            basis: vec![],
        };
        act.columns = act.columns_at(t, q);
        act.basis = Self::orthonormal(&act.columns)?;
        Ok(act)
    }

    /// Modified Gram-Schmidt on the columns, refusing a dependent one.
    fn orthonormal(columns: &[Vec<f64>]) -> Result<Vec<Vec<f64>>, ActuationError> {
        let mut basis: Vec<Vec<f64>> = Vec::with_capacity(columns.len());
        for (j, c) in columns.iter().enumerate() {
            let norm = c.iter().map(|x| x * x).sum::<f64>().sqrt();
            let mut r = c.clone();
            for e in &basis {
                let d: f64 = r.iter().zip(e).map(|(x, y)| x * y).sum();
                for (x, y) in r.iter_mut().zip(e) {
                    *x -= d * y;
                }
            }
            let rn = r.iter().map(|x| x * x).sum::<f64>().sqrt();
            let ratio = if norm > 0.0 { rn / norm } else { 0.0 };
            if !(ratio > Self::DEPENDENT) {
                return Err(ActuationError::Dependent { column: j, ratio });
            }
            r.iter_mut().for_each(|x| *x /= rn);
            basis.push(r);
        }
        Ok(basis)
    }

    /// Actuators on joints only: H = [e_dofs[0], e_dofs[1], ...] over n velocities.
    pub fn joints(names: Vec<String>, dofs: &[usize], n: usize) -> Result<Self, ActuationError> {
        let cols = dofs
            .iter()
            .map(|&d| {
                let mut c = vec![0.0; n];
                c[d] = 1.0;
                c
            })
            .collect();
        Self::new(names, cols)
    }

    /// Number of actuators m.
    pub fn len(&self) -> usize {
        self.columns.len()
    }

    /// True without actuators.
    pub fn is_empty(&self) -> bool {
        self.columns.is_empty()
    }

    /// Does H depend on the state (t, q)?
    pub fn is_constant(&self) -> bool {
        self.entries.is_empty()
    }

    /// Column j of H at the build state (the initial state; H itself when constant).
    pub fn column(&self, j: usize) -> &[f64] {
        &self.columns[j]
    }

    /// The columns of H at (t, q).
    pub fn columns_at(&self, t: f64, q: &[f64]) -> Vec<Vec<f64>> {
        let mut cols = self.fixed.clone();
        if !self.entries.is_empty() {
            let slots = Self::slots(t, q);
            for e in &self.entries {
                cols[e.col][e.row] = e.expr.value(&slots);
            }
        }
        cols
    }

    /// The velocity index of actuator j when its column is a constant unit vector (a joint).
    pub fn joint(&self, j: usize) -> Option<usize> {
        if self.entries.iter().any(|e| e.col == j) {
            return None;
        }
        let c = &self.columns[j];
        let nz: Vec<usize> = (0..c.len()).filter(|&i| c[i] != 0.0).collect();
        (nz.len() == 1 && c[nz[0]] == 1.0).then(|| nz[0])
    }

    fn slots<T: Scalar>(t: T, q: &[T]) -> Vec<T> {
        std::iter::once(t).chain(q.iter().copied()).collect()
    }

    /// out += H(t, q) tau (u = H tau, the actuators' generalized force).
    pub fn add_force<T: Scalar>(&self, t: T, q: &[T], tau: &[T], out: &mut [T]) {
        self.add_force_with(&mut ForceWork::default(), t, q, tau, out);
    }

    /// [`Actuation::add_force`] with the expression entries' slots and stack in `w` (kept by the
    /// caller: no allocation once they have grown to size).
    pub fn add_force_with<T: Scalar>(
        &self,
        w: &mut ForceWork<T>,
        t: T,
        q: &[T],
        tau: &[T],
        out: &mut [T],
    ) {
        for (c, &tj) in self.fixed.iter().zip(tau) {
            for (o, &h) in out.iter_mut().zip(c) {
                if h != 0.0 {
                    *o += tj * h;
                }
            }
        }
        if !self.entries.is_empty() {
            w.slots.clear();
            w.slots.push(t);
            w.slots.extend_from_slice(q);
            for e in &self.entries {
                out[e.row] += tau[e.col] * e.expr.eval(&w.slots, &mut w.stack);
            }
        }
    }

    /// |x - P x| with P the orthogonal projector onto range(H(t, q)): the size of the part of x
    /// no actuator can produce ([`Actuation::outside_part`]).
    pub fn outside(&self, t: f64, q: &[f64], x: &[f64]) -> f64 {
        let r = self.outside_part(t, q, x);
        r.iter().map(|a| a * a).sum::<f64>().sqrt()
    }

    /// x - P x with P the orthogonal projector onto range(H(t, q)): the part of x no actuator can
    /// produce (exactly the entries on unactuated joints when every column is a joint's: a unit
    /// basis vector removes its entry and leaves the others untouched).
    pub fn outside_part(&self, t: f64, q: &[f64], x: &[f64]) -> Vec<f64> {
        let owned;
        let basis = if self.entries.is_empty() {
            &self.basis
        } else {
            // dependent columns at this state: everything outside the independent ones' span
            owned = Self::orthonormal(&self.columns_at(t, q)).unwrap_or_default();
            &owned
        };
        let mut r = x.to_vec();
        for e in basis {
            let d: f64 = r.iter().zip(e).map(|(a, b)| a * b).sum();
            for (a, b) in r.iter_mut().zip(e) {
                *a -= d * b;
            }
        }
        r
    }
}

/// Buffers of [`Actuation::add_force_with`] at one scalar type: the expressions' slots (t, q)
/// and their evaluation stack.
#[derive(Clone, Debug)]
pub struct ForceWork<T> {
    slots: Vec<T>,
    stack: Vec<T>,
}

impl<T> Default for ForceWork<T> {
    fn default() -> Self {
        ForceWork {
            slots: Vec::new(),
            stack: Vec::new(),
        }
    }
}
