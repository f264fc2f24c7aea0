//! `[[reference]]`: values of the motion at given times whose origin is independent of the solver
//! (a closed form, a published solution). Each value is a number or an expression of the
//! parameters and `t` (bound to the entry's time), evaluated at load; the check compares them with
//! the solver's samples (`reference_error`, harness/progmo/checks.py).

use super::error::{SceneError, Source};
use super::file::{Number, SceneFile};
use crate::expr::{Expr, SymbolTable};
use std::collections::BTreeMap;
use toml::Spanned;

/// Values by name as written.
type Values = BTreeMap<String, Spanned<Number>>;

/// One reference value.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceValue {
    /// Time (s).
    pub t: f64,
    /// `q`, `v` or `u`.
    pub quantity: &'static str,
    /// Coordinate (q) or velocity (v, u) name.
    pub name: String,
    /// Index into q or v.
    pub index: usize,
    /// The expected value.
    pub value: f64,
    /// Where it comes from (the entry's `source`).
    pub source: String,
    /// Where it is written (`reference[2].q.x3`).
    pub field: String,
}

/// Evaluate every entry of the file's `[[reference]]` array.
pub(super) fn references(
    src: &Source,
    file: &SceneFile,
    params: &[(String, f64)],
    q_names: &[String],
    v_names: &[String],
    (t0, t1): (f64, f64),
) -> Result<Vec<ReferenceValue>, SceneError> {
    let mut consts = SymbolTable::new();
    for (n, x) in params {
        consts.define(n.clone(), *x);
    }
    let mut with_t = consts.clone();
    with_t.insert("t");
    let mut out = vec![];
    for (i, entry) in file.reference.iter().enumerate() {
        let e = entry.get_ref();
        let here = format!("reference[{i}]");
        let t = match e.t.get_ref() {
            Number::Value(x) => *x,
            Number::Expr(text) => Expr::compile(text, &consts)
                .map(|x| x.value::<f64>(&[]))
                .map_err(|err| src.expr_error(e.t.span(), &format!("{here}.t"), &err))?,
        };
        if !(t0..=t1).contains(&t) {
            return Err(src.error(
                e.t.span(),
                &format!("{here}.t"),
                format!("t = {t} lies outside the scene's span [{t0}, {t1}]"),
            ));
        }
        if e.source.trim().is_empty() {
            return Err(src.error(
                entry.span(),
                &here,
                "a reference needs its `source` (where the values come from)",
            ));
        }
        let groups: [(&'static str, &Values, &[String]); 3] = [
            ("q", &e.q, q_names),
            ("v", &e.v, v_names),
            ("u", &e.u, v_names),
        ];
        if groups.iter().all(|(_, m, _)| m.is_empty()) {
            return Err(src.error(
                entry.span(),
                &here,
                "a reference needs at least one value (q, v or u)",
            ));
        }
        for (quantity, map, names) in groups {
            for (key, n) in map {
                let field = format!("{here}.{quantity}.{key}");
                let Some(index) = names.iter().position(|x| x == key) else {
                    return Err(src.error(
                        n.span(),
                        &field,
                        format!(
                            "`{key}` is not a {} name{} (have: {})",
                            if quantity == "q" {
                                "coordinate"
                            } else {
                                "velocity"
                            },
                            crate::check::did_you_mean(key, names.iter().map(String::as_str)),
                            names.join(", ")
                        ),
                    ));
                };
                let value = match n.get_ref() {
                    Number::Value(x) => *x,
                    Number::Expr(text) => Expr::compile(text, &with_t)
                        .map(|x| x.value::<f64>(&[t]))
                        .map_err(|err| src.expr_error(n.span(), &field, &err))?,
                };
                if !value.is_finite() {
                    return Err(src.error(n.span(), &field, format!("evaluates to {value}")));
                }
                out.push(ReferenceValue {
                    t,
                    quantity,
                    name: key.clone(),
                    index,
                    value,
                    source: e.source.clone(),
                    field,
                });
            }
        }
    }
    Ok(out)
}
