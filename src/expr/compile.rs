//! Constant folding, bytecode generation and the evaluator.

use super::error::{ExprError, ExprErrorKind as K};
use super::parser::{parse, BinOp, Func, Kind, Node};
use super::{time_order, SymbolTable};
use crate::scalar::Scalar;
use std::collections::HashMap;
use std::fmt;

/// One instruction of the stack machine. `C` suffix: constant right operand, `L`: slot right
/// operand, `R` prefix: operands swapped (`RSubC(c)`: c - top).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Op {
    Const(f64),
    Load(u32),
    Add,
    Sub,
    Mul,
    Div,
    /// Symbolic exponent: `powd`.
    Pow,
    AddC(f64),
    SubC(f64),
    RSubC(f64),
    MulC(f64),
    DivC(f64),
    RDivC(f64),
    AddL(u32),
    SubL(u32),
    RSubL(u32),
    MulL(u32),
    DivL(u32),
    RDivL(u32),
    Neg,
    Square,
    Powi(i32),
    Powf(f64),
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Atan2,
    Exp,
    Ln,
    Sqrt,
    Abs,
    Sinh,
    Cosh,
    Tanh,
    /// Store the top in temporary k (a repeated subexpression, `cse.rs`); the top stays.
    Tee(u32),
    /// Push temporary k.
    Get(u32),
}

/// A compiled expression: immutable, `Send + Sync`, cheap to evaluate over any [`Scalar`].
#[derive(Debug, Clone, PartialEq)]
pub struct Expr {
    code: Vec<Op>,
    max_stack: usize,
    /// Temporaries of repeated subexpressions, kept at the bottom of the stack.
    temps: usize,
    /// The code as a tape for [`Expr::gradient`] (`tape.rs`), and its result's index.
    tape: Vec<super::tape::Step>,
    tape_out: u32,
    /// Sorted, distinct slots read.
    slots: Vec<usize>,
    time_order: u8,
    source: String,
    /// Normalized infix text (before folding, so `pi` stays `pi`).
    text: String,
}

/// Result of folding a subtree: a constant or a tree with at least one symbol.
enum F {
    C(f64),
    N(Node),
}

fn apply1(f: Func, x: f64) -> f64 {
    match f {
        Func::Sin => x.sin(),
        Func::Cos => x.cos(),
        Func::Tan => x.tan(),
        Func::Asin => x.asin(),
        Func::Acos => x.acos(),
        Func::Atan => x.atan(),
        Func::Exp => x.exp(),
        Func::Log => x.ln(),
        Func::Sqrt => x.sqrt(),
        Func::Abs => x.abs(),
        Func::Sinh => x.sinh(),
        Func::Cosh => x.cosh(),
        Func::Tanh => x.tanh(),
        Func::Atan2 => f64::NAN,
    }
}

/// Evaluate `a op b` exactly as the f64 evaluator does.
fn apply2(op: BinOp, a: f64, b: f64) -> f64 {
    match op {
        BinOp::Add => a + b,
        BinOp::Sub => a - b,
        BinOp::Mul => a * b,
        BinOp::Div => a / b,
        BinOp::Pow => match pow_kind(b) {
            PowKind::One => a,
            PowKind::Square => a * a,
            PowKind::Sqrt => a.sqrt(),
            PowKind::Int(n) => a.powi(n),
            PowKind::Real => a.powf(b),
        },
    }
}

enum PowKind {
    One,
    Square,
    Sqrt,
    Int(i32),
    Real,
}

fn pow_kind(b: f64) -> PowKind {
    if b == 1.0 {
        PowKind::One
    } else if b == 2.0 {
        PowKind::Square
    } else if b == 0.5 {
        PowKind::Sqrt
    } else if b.fract() == 0.0 && b.abs() <= 1024.0 {
        PowKind::Int(b as i32)
    } else {
        PowKind::Real
    }
}

/// A constant, or the error naming the subexpression `start..end` that overflowed.
fn checked(v: f64, start: usize, end: usize, src: &str) -> Result<F, ExprError> {
    if v.is_finite() {
        Ok(F::C(v))
    } else {
        let text: String = src
            .chars()
            .skip(start.saturating_sub(1))
            .take(end.saturating_sub(start))
            .collect();
        Err(ExprError::new(K::NonFinite { value: v }, start, &text, src))
    }
}

fn fold(mut n: Node, src: &str) -> Result<F, ExprError> {
    // The left spine of a chain (`a + b + c`) is folded iteratively, innermost first.
    let mut spine = vec![];
    loop {
        match std::mem::replace(&mut n.kind, Kind::Num(0.0)) {
            Kind::Bin(op, a, b) => {
                spine.push((op, *b, n.start, n.end, n.height));
                n = *a;
            }
            k => {
                n.kind = k;
                break;
            }
        }
    }
    let mut acc = fold_one(n, src)?;
    for (op, b, start, end, height) in spine.into_iter().rev() {
        acc = match (acc, fold(b, src)?) {
            (F::C(x), F::C(y)) => checked(apply2(op, x, y), start, end, src)?,
            (a, b) => F::N(Node {
                kind: Kind::Bin(op, Box::new(unfold(a)), Box::new(unfold(b))),
                start,
                end,
                height,
            }),
        };
    }
    Ok(acc)
}

fn fold_one(mut n: Node, src: &str) -> Result<F, ExprError> {
    let (start, end, height) = (n.start, n.end, n.height);
    let check = |v: f64| checked(v, start, end, src);
    let rebuild = move |kind| {
        F::N(Node {
            kind,
            start,
            end,
            height,
        })
    };
    Ok(match std::mem::replace(&mut n.kind, Kind::Num(0.0)) {
        Kind::Num(v) => F::C(v),
        Kind::Named(_, v) => return check(v),
        k @ Kind::Sym(..) => rebuild(k),
        Kind::Neg(a) => match fold(*a, src)? {
            F::C(v) => F::C(-v),
            F::N(a) => rebuild(Kind::Neg(Box::new(a))),
        },
        Kind::Bin(op, a, b) => match (fold(*a, src)?, fold(*b, src)?) {
            (F::C(x), F::C(y)) => return check(apply2(op, x, y)),
            (a, b) => rebuild(Kind::Bin(op, Box::new(unfold(a)), Box::new(unfold(b)))),
        },
        Kind::Call(f, args) => {
            let args = args
                .into_iter()
                .map(|a| fold(a, src))
                .collect::<Result<Vec<_>, _>>()?;
            match (f, args.as_slice()) {
                (Func::Atan2, [F::C(y), F::C(x)]) => return check(y.atan2(*x)),
                (_, [F::C(x)]) => return check(apply1(f, *x)),
                _ => rebuild(Kind::Call(f, args.into_iter().map(unfold).collect())),
            }
        }
    })
}

fn unfold(f: F) -> Node {
    match f {
        F::C(v) => Node {
            kind: Kind::Num(v),
            start: 0,
            end: 0,
            height: 1,
        },
        F::N(n) => n,
    }
}

#[derive(Clone, Copy)]
enum Leaf {
    C(f64),
    L(u32),
}

fn leaf(n: &Node) -> Option<Leaf> {
    match n.kind {
        Kind::Num(v) => Some(Leaf::C(v)),
        Kind::Sym(s, _) => Some(Leaf::L(s as u32)),
        _ => None,
    }
}

/// `top op leaf`, or `leaf op top` when `swapped`, as one instruction (`op` is not `^`).
fn fused(op: BinOp, leaf: Leaf, swapped: bool) -> Op {
    use Leaf::{C, L};
    match (op, leaf, swapped) {
        (BinOp::Add, C(c), _) => Op::AddC(c),
        (BinOp::Add, L(s), _) => Op::AddL(s),
        (BinOp::Mul, C(c), _) => Op::MulC(c),
        (BinOp::Mul, L(s), _) => Op::MulL(s),
        (BinOp::Sub, C(c), false) => Op::SubC(c),
        (BinOp::Sub, C(c), true) => Op::RSubC(c),
        (BinOp::Sub, L(s), false) => Op::SubL(s),
        (BinOp::Sub, L(s), true) => Op::RSubL(s),
        (BinOp::Div | BinOp::Pow, C(c), false) => Op::DivC(c),
        (BinOp::Div | BinOp::Pow, C(c), true) => Op::RDivC(c),
        (BinOp::Div | BinOp::Pow, L(s), false) => Op::DivL(s),
        (BinOp::Div | BinOp::Pow, L(s), true) => Op::RDivL(s),
    }
}

struct Gen {
    code: Vec<Op>,
    depth: usize,
    max: usize,
    /// Repeated subtrees (cse.rs) and the temporary each class got when first computed.
    repeated: super::cse::Repeated,
    temps: HashMap<usize, u32>,
}

impl Gen {
    /// The temporary holding `n`'s value, if an equal subtree was computed before.
    fn stored(&self, n: &Node) -> Option<u32> {
        self.repeated
            .get(&(n as *const Node))
            .and_then(|c| self.temps.get(c))
            .copied()
    }

    /// After `n` was computed: keep its value if it is needed again.
    fn remember(&mut self, n: &Node) {
        if let Some(&c) = self.repeated.get(&(n as *const Node)) {
            if !self.temps.contains_key(&c) {
                let k = self.temps.len() as u32;
                self.temps.insert(c, k);
                self.code.push(Op::Tee(k));
            }
        }
    }

    fn push(&mut self, op: Op) {
        self.code.push(op);
        self.depth += 1;
        self.max = self.max.max(self.depth);
    }

    /// Emit an op that pops `pops` values and pushes one.
    fn reduce(&mut self, op: Op, pops: usize) {
        self.code.push(op);
        self.depth -= pops - 1;
    }

    fn emit(&mut self, n: &Node) {
        if let Some(k) = self.stored(n) {
            return self.push(Op::Get(k));
        }
        // A binary node whose left operand is not a leaf emits that operand first: walk the left
        // spine iteratively (a long chain would recurse once per term), then finish each level.
        // The walk stops at a stored operand (read back, not recomputed).
        let mut spine = vec![];
        let mut cur = n;
        while let Kind::Bin(_, a, _) = &cur.kind {
            if leaf(a).is_some() || self.stored(a).is_some() {
                break;
            }
            spine.push(cur);
            cur = a;
        }
        if spine.is_empty() {
            self.emit_one(n);
            return self.remember(n);
        }
        self.emit(cur);
        for node in spine.into_iter().rev() {
            let Kind::Bin(op, _, b) = &node.kind else {
                continue;
            };
            match (op, &b.kind, leaf(b)) {
                (BinOp::Pow, Kind::Num(e), _) => self.pow_const(*e),
                (BinOp::Pow, ..) => {
                    self.emit(b);
                    self.reduce(Op::Pow, 2);
                }
                (_, _, Some(r)) => self.reduce(fused(*op, r, false), 1),
                (_, _, None) => {
                    self.emit(b);
                    self.reduce(binary(*op), 2);
                }
            }
            self.remember(node);
        }
    }

    fn pow_const(&mut self, e: f64) {
        match pow_kind(e) {
            PowKind::One => {}
            PowKind::Square => self.reduce(Op::Square, 1),
            PowKind::Sqrt => self.reduce(Op::Sqrt, 1),
            PowKind::Int(i) => self.reduce(Op::Powi(i), 1),
            PowKind::Real => self.reduce(Op::Powf(e), 1),
        }
    }

    fn emit_one(&mut self, n: &Node) {
        match &n.kind {
            Kind::Num(v) => self.push(Op::Const(*v)),
            Kind::Named(_, v) => self.push(Op::Const(*v)),
            Kind::Sym(s, _) => self.push(Op::Load(*s as u32)),
            Kind::Neg(a) => {
                self.emit(a);
                self.reduce(Op::Neg, 1);
            }
            Kind::Bin(BinOp::Pow, a, b) => {
                self.emit(a);
                match &b.kind {
                    Kind::Num(e) => self.pow_const(*e),
                    _ => {
                        self.emit(b);
                        self.reduce(Op::Pow, 2);
                    }
                }
            }
            Kind::Bin(op, a, b) => {
                // A constant operand, else a slot operand, is fused into the instruction.
                let (a, b, leaf, swapped) = match (leaf(a), leaf(b)) {
                    (_, Some(r @ Leaf::C(_))) => (a, b, Some(r), false),
                    (Some(l @ Leaf::C(_)), _) => (b, a, Some(l), true),
                    (_, Some(r)) => (a, b, Some(r), false),
                    (Some(l), None) => (b, a, Some(l), true),
                    (None, None) => (a, b, None, false),
                };
                self.emit(a);
                match leaf {
                    Some(l) => self.reduce(fused(*op, l, swapped), 1),
                    None => {
                        self.emit(b);
                        self.reduce(binary(*op), 2);
                    }
                }
            }
            Kind::Call(f, args) => {
                for a in args {
                    self.emit(a);
                }
                let o = match f {
                    Func::Sin => Op::Sin,
                    Func::Cos => Op::Cos,
                    Func::Tan => Op::Tan,
                    Func::Asin => Op::Asin,
                    Func::Acos => Op::Acos,
                    Func::Atan => Op::Atan,
                    Func::Atan2 => Op::Atan2,
                    Func::Exp => Op::Exp,
                    Func::Log => Op::Ln,
                    Func::Sqrt => Op::Sqrt,
                    Func::Abs => Op::Abs,
                    Func::Sinh => Op::Sinh,
                    Func::Cosh => Op::Cosh,
                    Func::Tanh => Op::Tanh,
                };
                self.reduce(o, args.len());
            }
        }
    }
}

fn binary(op: BinOp) -> Op {
    match op {
        BinOp::Add => Op::Add,
        BinOp::Sub => Op::Sub,
        BinOp::Mul => Op::Mul,
        BinOp::Div => Op::Div,
        BinOp::Pow => Op::Pow,
    }
}

/// Slots in order of appearance (an explicit stack: no recursion per level).
fn collect_slots(n: &Node, out: &mut Vec<usize>, order: &mut u8) {
    let mut stack = vec![n];
    while let Some(n) = stack.pop() {
        match &n.kind {
            Kind::Sym(s, name) => {
                out.push(*s);
                *order = (*order).max(time_order(name));
            }
            Kind::Num(_) | Kind::Named(..) => {}
            Kind::Neg(a) => stack.push(a),
            Kind::Bin(_, a, b) => {
                stack.push(b);
                stack.push(a);
            }
            Kind::Call(_, args) => stack.extend(args.iter().rev()),
        }
    }
}

/// `atan2` whose derivative part stays finite on the y axis (`x = 0`), where num-dual's
/// `atan(y/x)` form divides by zero. The value part is `f64::atan2` exactly.
#[inline]
pub(super) fn atan2<S: Scalar>(y: S, x: S) -> S {
    if S::NDERIV == 0 {
        return y.atan2(x);
    }
    let (yr, xr) = (y.re(), x.re());
    let d = if xr.abs() >= yr.abs() {
        (y / x).atan()
    } else {
        -(x / y).atan()
    };
    // Replace the value part (off by multiples of pi/2) and keep all derivative parts.
    d - S::from(d.re()) + S::from(yr.atan2(xr))
}

/// `x^y` for a symbolic exponent. Over f64 the same `powi`/`powf` choice as for a constant
/// exponent; over duals `powd` = `exp(y ln x)`, with a negative base and an integer-valued
/// exponent handled as `±(-x)^y` (num-dual cannot tell whether `y` carries derivatives).
#[inline]
pub(super) fn pow<S: Scalar>(x: S, y: S) -> S {
    let yr = y.re();
    if S::NDERIV == 0 {
        match pow_kind(yr) {
            PowKind::One => x,
            PowKind::Square => x * x,
            PowKind::Sqrt => x.sqrt(),
            PowKind::Int(n) => x.powi(n),
            PowKind::Real => x.powf(yr),
        }
    } else if x.re() < 0.0 && yr.fract() == 0.0 {
        let p = (-x).powd(y);
        if yr % 2.0 == 0.0 {
            p
        } else {
            -p
        }
    } else {
        x.powd(y)
    }
}

/// `x^p` for a constant real p. num-dual's `powf` forms x^(p-3) x^3 and so yields NaN at x = 0,
/// even in the value; there, for p > 1, the value and first derivatives are exactly 0 (the second
/// derivatives too when p >= 2; for 1 < p < 2 they are infinite and are returned as 0).
#[inline]
pub(super) fn powf<S: Scalar>(x: S, p: f64) -> S {
    if S::NDERIV > 0 && x.re() == 0.0 && p > 1.0 {
        x * 0.0
    } else {
        x.powf(p)
    }
}

#[inline]
pub(super) fn abs<S: Scalar>(x: S) -> S {
    if x.re() < 0.0 {
        -x
    } else {
        x
    }
}

impl Expr {
    /// Parse `source`, resolve names against `symbols`, fold constants and compile to bytecode.
    pub fn compile(source: &str, symbols: &SymbolTable) -> Result<Expr, ExprError> {
        Self::compile_with(source, symbols, true)
    }

    /// `compile`, with or without storing repeated subexpressions (`cse.rs`; the tests compare).
    pub(crate) fn compile_with(
        source: &str,
        symbols: &SymbolTable,
        cse: bool,
    ) -> Result<Expr, ExprError> {
        let (tree, _) = parse(source, Some(symbols))?;
        let text = tree.to_string();
        let mut slots = Vec::new();
        let mut order = 0;
        collect_slots(&tree, &mut slots, &mut order);
        slots.sort_unstable();
        slots.dedup();
        let folded = unfold(fold(tree, source)?);
        let mut g = Gen {
            code: Vec::new(),
            depth: 0,
            max: 0,
            repeated: if cse {
                super::cse::repeated(&folded)
            } else {
                Default::default()
            },
            temps: HashMap::new(),
        };
        g.emit(&folded);
        debug_assert_eq!(g.depth, 1);
        let temps = g.temps.len();
        let (tape, tape_out) = super::tape::build(&g.code);
        Ok(Expr {
            tape,
            tape_out,
            code: g.code,
            max_stack: g.max + temps,
            temps,
            slots,
            time_order: order,
            source: source.to_string(),
            text,
        })
    }

    /// Stack capacity `eval` needs to run without allocating.
    pub fn max_stack(&self) -> usize {
        self.max_stack
    }

    /// A stack with enough capacity for [`Expr::eval`].
    pub fn new_stack<S: Scalar>(&self) -> Vec<S> {
        Vec::with_capacity(self.max_stack)
    }

    /// The distinct slots this expression reads, ascending.
    pub fn slots(&self) -> &[usize] {
        &self.slots
    }

    /// Whether the expression reads `slot`.
    pub fn uses(&self, slot: usize) -> bool {
        self.slots.binary_search(&slot).is_ok()
    }

    /// Minimum length of the slot array passed to `eval`.
    pub fn min_slots(&self) -> usize {
        self.slots.last().map_or(0, |s| s + 1)
    }

    /// Highest number of apostrophes on a symbol read: 0 position, 1 velocity (`r'`),
    /// 2 acceleration (`r''`) level.
    pub fn time_order(&self) -> u8 {
        self.time_order
    }

    /// `Some(value)` when the expression reads no symbols.
    pub fn constant(&self) -> Option<f64> {
        match self.code.as_slice() {
            [Op::Const(v)] => Some(*v),
            _ => None,
        }
    }

    /// The source the expression was compiled from.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Number of bytecode instructions.
    pub fn len(&self) -> usize {
        self.code.len()
    }

    /// Always false: an expression has at least one instruction.
    pub fn is_empty(&self) -> bool {
        self.code.is_empty()
    }

    /// Evaluate with `slots` filled in symbol-table order. `stack` is scratch space; no
    /// allocation happens when its capacity is at least [`Expr::max_stack`].
    ///
    /// Panics if `slots.len() < self.min_slots()`.
    pub fn eval<S: Scalar>(&self, slots: &[S], stack: &mut Vec<S>) -> S {
        stack.clear();
        // Temporaries first: stack[k] is temporary k; the machine's values go above them.
        stack.resize(self.temps, S::from(0.0));
        // Top of stack lives in `acc`; `stack` holds the values below it (plus one dummy).
        let mut acc = S::from(0.0);
        macro_rules! pop {
            () => {
                match stack.pop() {
                    Some(v) => v,
                    None => unreachable!("bytecode stack underflow"),
                }
            };
        }
        for op in &self.code {
            match *op {
                Op::Const(c) => {
                    stack.push(acc);
                    acc = S::from(c);
                }
                Op::Load(s) => {
                    stack.push(acc);
                    acc = slots[s as usize];
                }
                Op::Add => acc = pop!() + acc,
                Op::Sub => acc = pop!() - acc,
                Op::Mul => acc = pop!() * acc,
                Op::Div => acc = pop!() / acc,
                Op::Pow => acc = pow(pop!(), acc),
                Op::AddC(c) => acc += c,
                Op::SubC(c) => acc -= c,
                Op::RSubC(c) => acc = S::from(c) - acc,
                Op::MulC(c) => acc *= c,
                Op::DivC(c) => acc /= c,
                Op::RDivC(c) => acc = S::from(c) / acc,
                Op::AddL(s) => acc += slots[s as usize],
                Op::SubL(s) => acc -= slots[s as usize],
                Op::RSubL(s) => acc = slots[s as usize] - acc,
                Op::MulL(s) => acc *= slots[s as usize],
                Op::DivL(s) => acc /= slots[s as usize],
                Op::RDivL(s) => acc = slots[s as usize] / acc,
                Op::Neg => acc = -acc,
                Op::Square => acc = acc * acc,
                Op::Powi(n) => acc = acc.powi(n),
                Op::Powf(p) => acc = powf(acc, p),
                Op::Sin => acc = acc.sin(),
                Op::Cos => acc = acc.cos(),
                Op::Tan => acc = acc.tan(),
                Op::Asin => acc = acc.asin(),
                Op::Acos => acc = acc.acos(),
                Op::Atan => acc = acc.atan(),
                Op::Atan2 => acc = atan2(pop!(), acc),
                Op::Exp => acc = acc.exp(),
                Op::Ln => acc = acc.ln(),
                Op::Sqrt => acc = acc.sqrt(),
                Op::Abs => acc = abs(acc),
                Op::Sinh => acc = acc.sinh(),
                Op::Cosh => acc = acc.cosh(),
                Op::Tanh => acc = acc.tanh(),
                Op::Tee(k) => stack[k as usize] = acc,
                Op::Get(k) => {
                    let x = stack[k as usize];
                    stack.push(acc);
                    acc = x;
                }
            }
        }
        acc
    }

    /// The value, and in `grad[s]` its derivative in slot s for every slot it reads (other entries
    /// untouched), by one reverse sweep (`tape.rs`) instead of one dual pass per slot. `work` is
    /// scratch; no allocation when its capacity is at least [`Expr::gradient_work`].
    pub fn gradient<S: Scalar>(&self, slots: &[S], work: &mut Vec<S>, grad: &mut [S]) -> S {
        super::tape::gradient(&self.tape, self.tape_out, &self.slots, slots, work, grad)
    }

    /// Scratch capacity [`Expr::gradient`] needs to run without allocating.
    pub fn gradient_work(&self) -> usize {
        2 * self.tape.len()
    }

    /// Convenience evaluation that allocates its own stack (not for hot loops).
    pub fn value<S: Scalar>(&self, slots: &[S]) -> S {
        let mut stack = self.new_stack();
        self.eval(slots, &mut stack)
    }

    /// The bytecode (read by [`Expr::affine`] and the tests).
    pub(crate) fn code(&self) -> &[Op] {
        &self.code
    }
}

/// Normalized infix text with minimal parentheses; compiling it again gives the same expression.
impl fmt::Display for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}
