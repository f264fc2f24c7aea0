//! The bytecode as a tape (each instruction's operands named by the instruction that produced
//! them) and one reverse sweep over it: the value and the gradient in every slot the expression
//! reads, for one forward pass and one backward pass, instead of one dual pass per slot. Values are
//! those of [`super::Expr::eval`] bit for bit (the same operations in the same order); the
//! gradient equals the dual passes' derivative parts to round-off.

use super::compile::{abs, atan2, pow, powf, Op};
use crate::scalar::Scalar;

/// One instruction: `a` and `b` are the tape indices of its operands (the deeper one is `a`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Step {
    op: Op,
    a: u32,
    b: u32,
}

/// The tape of `code` and the index of its result. `Tee`/`Get` only rename a value: no step.
pub(crate) fn build(code: &[Op]) -> (Vec<Step>, u32) {
    let mut tape: Vec<Step> = Vec::with_capacity(code.len());
    let mut stack: Vec<u32> = vec![];
    let mut temps: Vec<u32> = vec![];
    for &op in code {
        let (a, b) = match op {
            Op::Tee(k) => {
                let top = *stack.last().expect("Tee on an empty stack");
                let k = k as usize;
                if temps.len() <= k {
                    temps.resize(k + 1, 0);
                }
                temps[k] = top;
                continue;
            }
            Op::Get(k) => {
                stack.push(temps[k as usize]);
                continue;
            }
            Op::Const(_) | Op::Load(_) => (0, 0),
            Op::Add | Op::Sub | Op::Mul | Op::Div | Op::Pow | Op::Atan2 => {
                let b = stack.pop().expect("operand");
                (stack.pop().expect("operand"), b)
            }
            _ => (stack.pop().expect("operand"), 0),
        };
        stack.push(tape.len() as u32);
        tape.push(Step { op, a, b });
    }
    let out = stack.pop().expect("a result");
    (tape, out)
}

/// Forward pass into `vals` (one per step), then the reverse pass: `grad[s]` = d value / d slot s
/// for the slots `reads` (other entries untouched). Returns the value. `work` is scratch
/// (capacity 2 tape length: no allocation).
pub(crate) fn gradient<S: Scalar>(
    tape: &[Step],
    out: u32,
    reads: &[usize],
    slots: &[S],
    work: &mut Vec<S>,
    grad: &mut [S],
) -> S {
    let n = tape.len();
    work.clear();
    work.resize(2 * n, S::zero());
    let (vals, adj) = work.split_at_mut(n);
    for (i, st) in tape.iter().enumerate() {
        let (x, y) = (vals[st.a as usize], vals[st.b as usize]);
        vals[i] = value(st.op, x, y, slots);
    }
    for &s in reads {
        grad[s] = S::zero();
    }
    let out = out as usize;
    adj[out] = S::one();
    for i in (0..=out).rev() {
        adjoint(tape[i], i, vals, slots, adj, grad);
    }
    vals[out]
}

/// The value of one step with operands `x`, `y` (forward pass).
#[inline]
fn value<S: Scalar>(op: Op, x: S, y: S, slots: &[S]) -> S {
    match op {
        Op::Const(c) => S::from(c),
        Op::Load(s) => slots[s as usize],
        Op::Add => x + y,
        Op::Sub => x - y,
        Op::Mul => x * y,
        Op::Div => x / y,
        Op::Pow => pow(x, y),
        Op::AddC(c) => {
            let mut v = x;
            v += c;
            v
        }
        Op::SubC(c) => {
            let mut v = x;
            v -= c;
            v
        }
        Op::RSubC(c) => S::from(c) - x,
        Op::MulC(c) => {
            let mut v = x;
            v *= c;
            v
        }
        Op::DivC(c) => {
            let mut v = x;
            v /= c;
            v
        }
        Op::RDivC(c) => S::from(c) / x,
        Op::AddL(s) => {
            let mut v = x;
            v += slots[s as usize];
            v
        }
        Op::SubL(s) => {
            let mut v = x;
            v -= slots[s as usize];
            v
        }
        Op::RSubL(s) => slots[s as usize] - x,
        Op::MulL(s) => {
            let mut v = x;
            v *= slots[s as usize];
            v
        }
        Op::DivL(s) => {
            let mut v = x;
            v /= slots[s as usize];
            v
        }
        Op::RDivL(s) => slots[s as usize] / x,
        Op::Neg => -x,
        Op::Square => x * x,
        Op::Powi(k) => x.powi(k),
        Op::Powf(p) => powf(x, p),
        Op::Sin => x.sin(),
        Op::Cos => x.cos(),
        Op::Tan => x.tan(),
        Op::Asin => x.asin(),
        Op::Acos => x.acos(),
        Op::Atan => x.atan(),
        Op::Atan2 => atan2(x, y),
        Op::Exp => x.exp(),
        Op::Ln => x.ln(),
        Op::Sqrt => x.sqrt(),
        Op::Abs => abs(x),
        Op::Sinh => x.sinh(),
        Op::Cosh => x.cosh(),
        Op::Tanh => x.tanh(),
        Op::Tee(_) | Op::Get(_) => unreachable!("no tape step"),
    }
}

/// One step `st` (tape index `i`) of the reverse pass: its adjoint `adj[i]` passed on to its
/// operands' adjoints and to the gradient of the slots it reads.
#[inline]
fn adjoint<S: Scalar>(st: Step, i: usize, vals: &[S], slots: &[S], adj: &mut [S], grad: &mut [S]) {
    let d = adj[i];
    let (a, b) = (st.a as usize, st.b as usize);
    let (x, y, z) = (vals[a], vals[b], vals[i]);
    match st.op {
        Op::Const(_) => {}
        Op::Load(s) => grad[s as usize] += d,
        Op::Add => {
            adj[a] += d;
            adj[b] += d;
        }
        Op::Sub => {
            adj[a] += d;
            adj[b] -= d;
        }
        Op::Mul => {
            adj[a] += d * y;
            adj[b] += d * x;
        }
        Op::Div => {
            adj[a] += d / y;
            adj[b] -= d * z / y;
        }
        Op::Pow => {
            adj[a] += d * y * z / x;
            adj[b] += d * z * abs(x).ln();
        }
        Op::AddC(_) | Op::SubC(_) => adj[a] += d,
        Op::RSubC(_) | Op::Neg => adj[a] -= d,
        Op::MulC(c) => adj[a] += d * c,
        Op::DivC(c) => adj[a] += d / c,
        Op::RDivC(_) => adj[a] -= d * z / x,
        Op::AddL(s) => {
            adj[a] += d;
            grad[s as usize] += d;
        }
        Op::SubL(s) => {
            adj[a] += d;
            grad[s as usize] -= d;
        }
        Op::RSubL(s) => {
            adj[a] -= d;
            grad[s as usize] += d;
        }
        Op::MulL(s) => {
            adj[a] += d * slots[s as usize];
            grad[s as usize] += d * x;
        }
        Op::DivL(s) => {
            let w = slots[s as usize];
            adj[a] += d / w;
            grad[s as usize] -= d * z / w;
        }
        Op::RDivL(s) => {
            adj[a] -= d * z / x;
            grad[s as usize] += d / x;
        }
        Op::Square => adj[a] += d * x * 2.0,
        Op::Powi(k) => {
            if k != 0 {
                adj[a] += d * x.powi(k - 1) * k as f64
            }
        }
        // num-dual's powf is NaN at 0; there, for p > 1, the derivative is 0 (as `powf`).
        Op::Powf(p) => {
            if !(x.re() == 0.0 && p > 1.0) {
                adj[a] += d * x.powf(p - 1.0) * p
            }
        }
        Op::Sin => adj[a] += d * x.cos(),
        Op::Cos => adj[a] -= d * x.sin(),
        Op::Tan => adj[a] += d * (z * z + 1.0),
        Op::Asin => adj[a] += d / (-(x * x) + 1.0).sqrt(),
        Op::Acos => adj[a] -= d / (-(x * x) + 1.0).sqrt(),
        Op::Atan => adj[a] += d / (x * x + 1.0),
        Op::Atan2 => {
            let r2 = x * x + y * y;
            adj[a] += d * y / r2;
            adj[b] -= d * x / r2;
        }
        Op::Exp => adj[a] += d * z,
        Op::Ln => adj[a] += d / x,
        Op::Sqrt => adj[a] += d / (z * 2.0),
        Op::Abs => {
            if x.re() < 0.0 {
                adj[a] -= d
            } else {
                adj[a] += d
            }
        }
        Op::Sinh => adj[a] += d * x.cosh(),
        Op::Cosh => adj[a] += d * x.sinh(),
        Op::Tanh => adj[a] += d * (-(z * z) + 1.0),
        Op::Tee(_) | Op::Get(_) => unreachable!("no tape step"),
    }
}
