//! Expressions affine in chosen slots with constant coefficients, read from the bytecode.
//!
//! E = sum_k c_k x_k + F, the x_k slots of the `linear` set, F a function of the `free` slots
//! (and constants) only. A programme row of this form, such as a frame task
//! `tcp.x - x0 - r*cos(w*t)` or a weld's rotation row (a constant combination of one frame's
//! quaternion signals), has dE/dx_k = c_k whatever the state, so its B row is sum_k c_k J_k and,
//! when F is a constant, its derivatives along the motion are those of the x_k
//! ([`crate::scene::rows`] then skips the tape). The bytecode is interpreted over abstract values:
//! a constant, a function of free slots, an affine form, or anything else.

use super::compile::{Expr, Op};

/// E = sum (slot, c) of `terms` c x_slot + F (see the module's text).
#[derive(Clone, Debug, PartialEq)]
pub struct Affine {
    /// Distinct slots, ascending, each with its constant coefficient.
    pub terms: Vec<(usize, f64)>,
    /// Whether F reads a free slot (else F is a constant).
    pub reads_free: bool,
}

#[derive(Clone, Debug)]
enum Val {
    Const(f64),
    /// A function of free slots (and constants) only.
    Free,
    /// An affine form; `bool`: its offset reads free slots.
    Lin(Vec<(usize, f64)>, bool),
    Other,
}

impl Val {
    fn scaled(self, c: f64) -> Val {
        match self {
            Val::Const(x) => Val::Const(x * c),
            Val::Lin(t, f) => Val::Lin(t.into_iter().map(|(s, k)| (s, k * c)).collect(), f),
            v => v,
        }
    }

    /// A nonlinear function of this value (and of `other`, when binary).
    fn through(self, other: Option<Val>) -> Val {
        let plain = |v: &Val| matches!(v, Val::Const(_) | Val::Free);
        if plain(&self) && other.as_ref().is_none_or(plain) {
            Val::Free
        } else {
            Val::Other
        }
    }
}

fn add(a: Val, b: Val) -> Val {
    match (a, b) {
        (Val::Other, _) | (_, Val::Other) => Val::Other,
        (Val::Const(x), Val::Const(y)) => Val::Const(x + y),
        (Val::Lin(mut t, f), Val::Lin(u, g)) => {
            for (s, k) in u {
                match t.iter_mut().find(|(r, _)| *r == s) {
                    Some(e) => e.1 += k,
                    None => t.push((s, k)),
                }
            }
            Val::Lin(t, f || g)
        }
        (Val::Lin(t, f), Val::Const(_)) | (Val::Const(_), Val::Lin(t, f)) => Val::Lin(t, f),
        (Val::Lin(t, _), Val::Free) | (Val::Free, Val::Lin(t, _)) => Val::Lin(t, true),
        _ => Val::Free,
    }
}

fn mul(a: Val, b: Val) -> Val {
    match (a, b) {
        (Val::Const(x), v) | (v, Val::Const(x)) => v.scaled(x),
        (a, b) => a.through(Some(b)),
    }
}

fn div(a: Val, b: Val) -> Val {
    match (a, b) {
        (a, Val::Const(c)) => a.scaled(1.0 / c),
        (a, b) => a.through(Some(b)),
    }
}

impl Expr {
    /// `Some` when this expression is affine in the slots `linear` accepts with constant
    /// coefficients and reads no other slot than those and the ones `free` accepts (see the
    /// module's text); `None` otherwise, and whenever the bytecode's shape is not recognised
    /// (the answer errs on `None`: a product of two free functions is never mistaken for one).
    pub fn affine(
        &self,
        linear: impl Fn(usize) -> bool,
        free: impl Fn(usize) -> bool,
    ) -> Option<Affine> {
        let load = |s: u32| {
            let s = s as usize;
            if linear(s) {
                Val::Lin(vec![(s, 1.0)], false)
            } else if free(s) {
                Val::Free
            } else {
                Val::Other
            }
        };
        let mut stack: Vec<Val> = Vec::with_capacity(self.max_stack());
        let mut temps: Vec<Val> = vec![];
        for op in self.code() {
            let v = match *op {
                Op::Const(c) => Val::Const(c),
                Op::Load(s) => load(s),
                Op::Get(k) => temps.get(k as usize)?.clone(),
                Op::Tee(k) => {
                    let k = k as usize;
                    if temps.len() <= k {
                        temps.resize(k + 1, Val::Other);
                    }
                    temps[k] = stack.last()?.clone();
                    continue;
                }
                _ => {
                    let a = stack.pop()?;
                    match *op {
                        Op::Add | Op::Sub | Op::Mul | Op::Div | Op::Pow | Op::Atan2 => {
                            let (a, b) = (stack.pop()?, a);
                            match *op {
                                Op::Add => add(a, b),
                                Op::Sub => add(a, b.scaled(-1.0)),
                                Op::Mul => mul(a, b),
                                Op::Div => div(a, b),
                                _ => a.through(Some(b)),
                            }
                        }
                        Op::AddC(c) => add(a, Val::Const(c)),
                        Op::SubC(c) => add(a, Val::Const(-c)),
                        Op::RSubC(c) => add(Val::Const(c), a.scaled(-1.0)),
                        Op::MulC(c) => a.scaled(c),
                        Op::DivC(c) => a.scaled(1.0 / c),
                        Op::RDivC(c) => div(Val::Const(c), a),
                        Op::AddL(s) => add(a, load(s)),
                        Op::SubL(s) => add(a, load(s).scaled(-1.0)),
                        Op::RSubL(s) => add(load(s), a.scaled(-1.0)),
                        Op::MulL(s) => mul(a, load(s)),
                        Op::DivL(s) => div(a, load(s)),
                        Op::RDivL(s) => div(load(s), a),
                        Op::Neg => a.scaled(-1.0),
                        _ => a.through(None),
                    }
                }
            };
            stack.push(v);
        }
        match stack.pop()? {
            Val::Const(_) => Some(Affine {
                terms: vec![],
                reads_free: false,
            }),
            Val::Free => Some(Affine {
                terms: vec![],
                reads_free: true,
            }),
            Val::Lin(mut terms, reads_free) => {
                terms.sort_by_key(|t| t.0);
                Some(Affine { terms, reads_free })
            }
            Val::Other => None,
        }
    }
}
