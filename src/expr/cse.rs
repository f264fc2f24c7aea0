//! Common subexpressions of one folded expression, found by value numbering: every node gets the
//! number of its (kind, operands' numbers) class, so two subtrees share a number exactly when they
//! are the same expression. A class evaluated at least twice whose work exceeds what storing and
//! reading it back costs is computed once: the code generator stores its first value (`Op::Tee`) and reads it back at
//! its other places (`Op::Get`). The values are those of the plain code, bit for bit (the same
//! operations on the same operands), for f64 and for the dual numbers alike.
//!
//! Iterative throughout: a chain of 10,000 terms must not recurse once per term.

use super::parser::{BinOp, Func, Kind, Node};
use std::collections::HashMap;

#[derive(Clone, PartialEq, Eq, Hash)]
enum Key {
    Num(u64),
    Sym(usize),
    Neg(usize),
    Bin(BinOp, usize, usize),
    Call(Func, Vec<usize>),
}

/// Node address -> class number, for the nodes whose class repeats (candidates to store).
pub(super) type Repeated = HashMap<*const Node, usize>;

/// The repeated non-trivial subtrees of `root`.
pub(super) fn repeated(root: &Node) -> Repeated {
    // Post-order without recursion: (node, children done).
    let mut order: Vec<&Node> = vec![];
    let mut stack: Vec<(&Node, bool)> = vec![(root, false)];
    while let Some((n, done)) = stack.pop() {
        if done {
            order.push(n);
            continue;
        }
        stack.push((n, true));
        match &n.kind {
            Kind::Neg(a) => stack.push((a, false)),
            Kind::Bin(_, a, b) => {
                stack.push((b, false));
                stack.push((a, false));
            }
            Kind::Call(_, args) => stack.extend(args.iter().rev().map(|a| (a, false))),
            Kind::Num(_) | Kind::Named(..) | Kind::Sym(..) => {}
        }
    }
    let mut classes: HashMap<Key, usize> = HashMap::new();
    let mut number: HashMap<*const Node, usize> = HashMap::with_capacity(order.len());
    // per class: occurrences, and the work of one evaluation (weighted instructions)
    let mut count: Vec<usize> = vec![];
    let mut work: Vec<u32> = vec![];
    let num = |n: &Node, number: &HashMap<*const Node, usize>| number[&(n as *const Node)];
    for n in &order {
        let (key, w) = match &n.kind {
            Kind::Num(v) | Kind::Named(_, v) => (Key::Num(v.to_bits()), 0),
            Kind::Sym(s, _) => (Key::Sym(*s), 0),
            Kind::Neg(a) => {
                let a = num(a, &number);
                (Key::Neg(a), work[a] + 1)
            }
            Kind::Bin(op, a, b) => {
                let (a, b) = (num(a, &number), num(b, &number));
                let own = if matches!(op, BinOp::Div | BinOp::Pow) {
                    4
                } else {
                    1
                };
                (Key::Bin(*op, a, b), work[a] + work[b] + own)
            }
            Kind::Call(f, args) => {
                let args: Vec<usize> = args.iter().map(|a| num(a, &number)).collect();
                let w = args.iter().map(|&a| work[a]).sum::<u32>() + 8;
                (Key::Call(*f, args), w)
            }
        };
        let next = classes.len();
        let c = *classes.entry(key).or_insert(next);
        if c == count.len() {
            count.push(0);
            work.push(w.min(1 << 20));
        }
        count[c] += 1;
        number.insert(*n as *const Node, c);
    }
    // Occurrences that are evaluated: parents first, a later occurrence of a stored class is read
    // back, so nothing inside it is evaluated again.
    let stored = |c: usize| count[c] >= 2 && work[c] >= MIN_WORK;
    let mut evaluated: Vec<usize> = vec![0; count.len()];
    let mut seen: Vec<bool> = vec![false; count.len()];
    let mut stack: Vec<&Node> = vec![root];
    while let Some(n) = stack.pop() {
        let c = number[&(n as *const Node)];
        evaluated[c] += 1;
        if stored(c) && std::mem::replace(&mut seen[c], true) {
            continue;
        }
        match &n.kind {
            Kind::Neg(a) => stack.push(a),
            Kind::Bin(_, a, b) => {
                stack.push(b);
                stack.push(a);
            }
            Kind::Call(_, args) => stack.extend(args.iter().rev()),
            Kind::Num(_) | Kind::Named(..) | Kind::Sym(..) => {}
        }
    }
    order
        .iter()
        .map(|n| (*n as *const Node, number[&(*n as *const Node)]))
        .filter(|&(_, c)| stored(c) && evaluated[c] >= 2)
        .collect()
}

/// Least work (an add or multiply counts 1, a divide or power 4, a function 8) worth storing: a
/// store and a read cost about two instructions of the stack machine.
const MIN_WORK: u32 = 3;
