//! `[[actuators]]` -> the scene's [`crate::servo::Actuation`] (u = H tau): each actuator a column
//! of H, a joint's unit column or a `direction` over the velocities (numbers or expressions of the
//! parameters, t and the coordinates), located errors at the actuator's joint, direction or table.

use super::error::{SceneError, Source};
use super::file::{ActuatorFile, Number, SceneFile};
use super::load::{and_list, is_identifier};
use super::rows::ExprConstraints;
use crate::check;
use crate::expr::{self, Expr, SymbolTable};
use crate::model::Model;
use crate::servo::{Actuation, ActuationError, MapEntry};
use crate::solve::Problem;
use std::ops::Range;
use toml::Spanned;

type R<T> = Result<T, SceneError>;

/// `[[actuators]]`: the joints whose generalized forces realize the programme (servo-constraints,
/// [`crate::servo`]). Hinge and slide joints of a model with Euclidean coordinates only, each once,
/// as many as programme rows, no system constraints.
pub(super) fn load<M: Model>(
    src: &Source,
    file: &SceneFile,
    params: &[(String, f64)],
    p: &mut Problem<M, ExprConstraints>,
    has_closures: bool,
) -> R<()> {
    if file.actuators.is_empty() {
        return Ok(());
    }
    let cx = Actuators {
        src,
        file,
        v_names: p.model.v_names(),
        q_names: p.model.q_names(),
    };
    cx.supported(has_closures)?;
    let (state_table, slots0) = cx.direction_symbols(params, p.t0, &p.q0);
    let mut columns = Columns::default();
    for i in 0..file.actuators.len() {
        let (col, default_name) = cx.column(i, &state_table, &slots0, &mut columns)?;
        let name = cx.name(i, default_name, &columns.names)?;
        columns.names.push(name);
        columns.columns.push(col);
    }
    cx.square(columns.columns.len())?;
    let act = cx.actuation(columns, p.t0, &p.q0)?;
    p.constraints.set_actuation(act);
    Ok(())
}

/// What the actuators' pieces share: the scene and the model's velocity names.
struct Actuators<'a> {
    src: &'a Source,
    file: &'a SceneFile,
    v_names: Vec<String>,
    q_names: Vec<String>,
}

/// The actuators read so far: H's columns, its state-dependent entries, names, actuated joints.
#[derive(Default)]
struct Columns {
    entries: Vec<MapEntry>,
    names: Vec<String>,
    columns: Vec<Vec<f64>>,
    joints: Vec<usize>,
}

impl Actuators<'_> {
    /// Where an actuator's messages point: its joint, else its direction, else its table.
    fn at(&self, i: usize) -> (Range<usize>, String) {
        let a = &self.file.actuators[i];
        match (&a.get_ref().joint, &a.get_ref().direction) {
            (Some(j), _) => (j.span(), format!("actuators[{i}].joint")),
            (None, Some(d)) => (d.span(), format!("actuators[{i}].direction")),
            (None, None) => (a.span(), format!("actuators[{i}]")),
        }
    }

    /// No system constraints or closures; hinge and slide joints only.
    fn supported(&self, has_closures: bool) -> R<()> {
        let src = self.src;
        if has_closures || !self.file.constraints.is_empty() {
            let (span, field) = self.at(0);
            return Err(src.error(
                span,
                &field,
                "actuators with system constraints or loop closures are not supported yet: their \
                 reactions would join tau in the index reduction",
            ));
        }
        // a ball or free joint's angular velocity (`j.wx`) is no coordinate's rate
        if let Some(j) = self.v_names.iter().find(|n| !self.q_names.contains(n)) {
            let joint = j.rsplit_once('.').map_or(j.as_str(), |(joint, _)| joint);
            let (span, field) = self.at(0);
            return Err(src.error(
                span,
                &field,
                format!(
                    "actuators need a model of hinge and slide joints only; joint `{joint}` is a ball \
                     or free joint (its quaternion coordinates are not supported by the servo solver yet)"
                ),
            ));
        }
        Ok(())
    }

    /// The symbols a direction's entries may read, and their values at the initial state.
    fn direction_symbols(
        &self,
        params: &[(String, f64)],
        t0: f64,
        q0: &[f64],
    ) -> (SymbolTable, Vec<f64>) {
        let mut consts = SymbolTable::new();
        for (name, x) in params {
            consts.define(name.clone(), *x);
        }
        // A direction's entries may read t and the coordinates (hinge and slide joints only here,
        // so the coordinates are the velocities' names): slots [t, q_0, ..].
        let mut state_table = consts.clone();
        state_table.insert("t");
        for name in &self.v_names {
            state_table.insert(name.clone());
        }
        let slots0: Vec<f64> = std::iter::once(t0).chain(q0.iter().copied()).collect();
        (state_table, slots0)
    }

    /// Actuator `i`'s column of H at the initial state, and its default name (its joint's).
    fn column(
        &self,
        i: usize,
        state_table: &SymbolTable,
        slots0: &[f64],
        acc: &mut Columns,
    ) -> R<(Vec<f64>, Option<String>)> {
        let (span, field) = self.at(i);
        let a: &ActuatorFile = self.file.actuators[i].get_ref();
        let mut col = vec![0.0; self.v_names.len()];
        let default_name = match (&a.joint, &a.direction) {
            (Some(_), Some(_)) | (None, None) => {
                return Err(self.src.error(
                    span,
                    &field,
                    "an actuator has either `joint` (a hinge or slide joint) or `direction` (a \
                     generalized force over the velocities), exactly one of the two",
                ));
            }
            (Some(joint), None) => {
                let joint = joint.get_ref();
                let d = self.joint(joint, span, &field, &acc.joints)?;
                acc.joints.push(d);
                col[d] = 1.0;
                Some(joint.clone())
            }
            (None, Some(dir)) => {
                for (key, x) in dir.get_ref() {
                    let (d, value) =
                        self.entry(i, key, x, state_table, slots0, &mut acc.entries)?;
                    col[d] = value;
                }
                None
            }
        };
        Ok((col, default_name))
    }

    /// The velocity index of an actuated joint, known and not actuated before.
    fn joint(&self, joint: &str, span: Range<usize>, field: &str, joints: &[usize]) -> R<usize> {
        let v_names = &self.v_names;
        let Some(d) = v_names.iter().position(|n| n == joint) else {
            return Err(self.src.error(
                span,
                field,
                format!(
                    "unknown joint `{joint}`: the actuated joints are among {}",
                    and_list(&v_names.iter().map(String::as_str).collect::<Vec<_>>())
                ),
            ));
        };
        if joints.contains(&d) {
            return Err(self
                .src
                .error(span, field, format!("joint `{joint}` is actuated twice")));
        }
        Ok(d)
    }

    /// One entry `key = x` of actuator `i`'s direction: its velocity index and its value at the
    /// initial state (an expression reading the state also joins `entries`).
    fn entry(
        &self,
        i: usize,
        key: &str,
        x: &Spanned<Number>,
        state_table: &SymbolTable,
        slots0: &[f64],
        entries: &mut Vec<MapEntry>,
    ) -> R<(usize, f64)> {
        let (src, v_names) = (self.src, &self.v_names);
        let f = format!("actuators[{i}].direction.{key}");
        let Some(d) = v_names.iter().position(|n| n == key) else {
            return Err(src.error(
                x.span(),
                &f,
                format!(
                    "`{key}` is not a velocity{}: the direction's entries are among {}",
                    check::did_you_mean(key, v_names.iter().map(String::as_str)),
                    and_list(&v_names.iter().map(String::as_str).collect::<Vec<_>>())
                ),
            ));
        };
        let value = match x.get_ref() {
            Number::Value(v) => *v,
            // an expression of the parameters, t and the coordinates (H(t, q))
            Number::Expr(text) => {
                if let Ok(names) = expr::referenced_names(text) {
                    if let Some(bad) = names.iter().find(|n| n.ends_with('\'')) {
                        return Err(src.error(
                            x.span(),
                            &f,
                            format!(
                                "`{bad}` is a velocity or acceleration: a direction may read the \
                                 parameters, t and the coordinates (H(t, q))"
                            ),
                        ));
                    }
                }
                let e = Expr::compile(text, state_table)
                    .map_err(|e| src.expr_error(x.span(), &f, &e))?;
                let at0 = e.value::<f64>(slots0);
                if !at0.is_finite() {
                    return Err(src.error(x.span(), &f, format!("is {at0} at the initial state")));
                }
                if !e.slots().is_empty() {
                    entries.push(MapEntry {
                        row: d,
                        col: i,
                        expr: e,
                    });
                }
                at0
            }
        };
        if !value.is_finite() {
            return Err(src.error(x.span(), &f, format!("is {value}")));
        }
        Ok((d, value))
    }

    /// Actuator `i`'s name: its own (an identifier, once), else its joint's.
    fn name(&self, i: usize, default_name: Option<String>, names: &[String]) -> R<String> {
        let a = self.file.actuators[i].get_ref();
        match (&a.name, default_name) {
            (Some(nm), _) => {
                if !is_identifier(nm.get_ref()) {
                    return Err(self.src.error(
                        nm.span(),
                        &format!("actuators[{i}].name"),
                        "an actuator name must be an identifier",
                    ));
                }
                if names.contains(nm.get_ref()) {
                    return Err(self.src.error(
                        nm.span(),
                        &format!("actuators[{i}].name"),
                        format!("actuator name `{}` is used twice", nm.get_ref()),
                    ));
                }
                Ok(nm.get_ref().clone())
            }
            (None, Some(joint)) => Ok(joint),
            (None, None) => {
                let (span, field) = self.at(i);
                Err(self.src.error(
                    span,
                    &field,
                    "an actuator with a `direction` needs a `name` (an identifier)",
                ))
            }
        }
    }

    /// As many actuators as programme rows (a square decoupling matrix).
    fn square(&self, m: usize) -> R<()> {
        let (s, n) = (self.file.programme.len(), self.v_names.len());
        if m != s {
            let (span, field) = self.at(m.min(s).min(m - 1));
            return Err(self.src.error(
                span,
                &field,
                format!(
                    "{m} actuator(s) for {s} programme row(s) ({n} degrees of freedom): the servo \
                     solver needs as many actuators as programme rows (a square decoupling matrix)"
                ),
            ));
        }
        Ok(())
    }

    /// H from its columns (and its state-dependent entries), with independent columns at t0.
    fn actuation(&self, c: Columns, t0: f64, q0: &[f64]) -> R<Actuation> {
        let names = c.names;
        let built = if c.entries.is_empty() {
            Actuation::new(names.clone(), c.columns)
        } else {
            Actuation::with_entries(names.clone(), c.columns, c.entries, t0, q0)
        };
        built.map_err(|e| match e {
            ActuationError::Dependent { column, ratio } => {
                let (span, field) = self.at(column);
                self.src.error(
                    span,
                    &field,
                    format!(
                        "actuator `{}` is zero or a combination of the actuators before it at the \
                         initial state (its part outside theirs is {ratio:.1e} of its length): H \
                         needs independent columns",
                        names[column]
                    ),
                )
            }
        })
    }
}
