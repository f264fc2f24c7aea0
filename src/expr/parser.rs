//! Recursive-descent parser producing a resolved syntax tree.

use super::error::{closest, ExprError, ExprErrorKind as K};
use super::lexer::{lex, Tok, Token};
use super::SymbolTable;
use std::fmt;

/// Limits (FORMAT.md, "Limits"): nesting of parentheses, unary signs, powers and calls, and the
/// height of the tree (a flat sum or product of up to 10,000 terms).
pub(crate) const MAX_DEPTH: usize = 200;
pub(crate) const MAX_HEIGHT: usize = 10_000;

/// Built-in functions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Func {
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Atan2,
    Exp,
    Log,
    Sqrt,
    Abs,
    Sinh,
    Cosh,
    Tanh,
}

impl Func {
    pub const ALL: [Func; 14] = [
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Asin,
        Func::Acos,
        Func::Atan,
        Func::Atan2,
        Func::Exp,
        Func::Log,
        Func::Sqrt,
        Func::Abs,
        Func::Sinh,
        Func::Cosh,
        Func::Tanh,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Asin => "asin",
            Func::Acos => "acos",
            Func::Atan => "atan",
            Func::Atan2 => "atan2",
            Func::Exp => "exp",
            Func::Log => "log",
            Func::Sqrt => "sqrt",
            Func::Abs => "abs",
            Func::Sinh => "sinh",
            Func::Cosh => "cosh",
            Func::Tanh => "tanh",
        }
    }

    pub fn arity(self) -> usize {
        if self == Func::Atan2 {
            2
        } else {
            1
        }
    }

    pub fn from_name(name: &str) -> Option<Func> {
        Func::ALL.into_iter().find(|f| f.name() == name)
    }
}

/// Common spellings from other languages.
fn alias(name: &str) -> Option<&'static str> {
    Some(match name {
        "ln" => "log",
        "arcsin" => "asin",
        "arccos" => "acos",
        "arctan" => "atan",
        "arctan2" => "atan2",
        "fabs" => "abs",
        _ => return None,
    })
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Pow,
}

impl BinOp {
    fn symbol(self) -> &'static str {
        match self {
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::Pow => "^",
        }
    }
}

#[derive(Debug, Clone)]
pub(crate) enum Kind {
    Num(f64),
    /// `pi` or a constant defined in the symbol table: folded, printed by name.
    Named(String, f64),
    /// Slot (usize::MAX when only collecting names) and name as written.
    Sym(usize, String),
    Neg(Box<Node>),
    Bin(BinOp, Box<Node>, Box<Node>),
    Call(Func, Vec<Node>),
}

#[derive(Debug, Clone)]
pub(crate) struct Node {
    pub kind: Kind,
    /// 1-based char columns: first char, one past the last char.
    pub start: usize,
    pub end: usize,
    pub height: usize,
}

/// Dropped iteratively: a chain of 10,000 terms would otherwise recurse once per level.
impl Drop for Node {
    fn drop(&mut self) {
        let mut stack = vec![];
        take_children(&mut self.kind, &mut stack);
        while let Some(mut n) = stack.pop() {
            take_children(&mut n.kind, &mut stack);
        }
    }
}

fn take_children(k: &mut Kind, out: &mut Vec<Node>) {
    match k {
        Kind::Neg(a) => out.push(std::mem::replace(&mut **a, Node::empty())),
        Kind::Bin(_, a, b) => {
            out.push(std::mem::replace(&mut **a, Node::empty()));
            out.push(std::mem::replace(&mut **b, Node::empty()));
        }
        Kind::Call(_, args) => out.append(args),
        Kind::Num(_) | Kind::Named(..) | Kind::Sym(..) => {}
    }
}

struct Parser<'a> {
    toks: Vec<Token>,
    pos: usize,
    src: &'a str,
    symbols: Option<&'a SymbolTable>,
    names: Vec<String>,
    depth: usize,
}

/// Parse and resolve. With `symbols == None` every name is accepted and collected instead.
pub(crate) fn parse(
    src: &str,
    symbols: Option<&SymbolTable>,
) -> Result<(Node, Vec<String>), ExprError> {
    let toks = lex(src)?;
    if toks.len() == 1 {
        return Err(ExprError::new(K::Empty, 1, "", src));
    }
    let mut p = Parser {
        toks,
        pos: 0,
        src,
        symbols,
        names: Vec::new(),
        depth: 0,
    };
    let node = p.expr()?;
    let t = p.peek().clone();
    match t.tok {
        Tok::Eof => Ok((node, p.names)),
        Tok::RParen => Err(p.err_at(K::UnmatchedClose, &t)),
        _ => Err(p.err_at(
            K::Trailing {
                found: t.text.clone(),
            },
            &t,
        )),
    }
}

fn found(t: &Token) -> String {
    if t.tok == Tok::Eof {
        "end of input".to_string()
    } else {
        format!("`{}`", t.text)
    }
}

impl<'a> Parser<'a> {
    fn peek(&self) -> &Token {
        &self.toks[self.pos.min(self.toks.len() - 1)]
    }

    fn next(&mut self) -> Token {
        let t = self.peek().clone();
        if self.pos < self.toks.len() - 1 {
            self.pos += 1;
        }
        t
    }

    fn err_at(&self, kind: K, t: &Token) -> ExprError {
        ExprError::new(kind, t.col, &t.text, self.src)
    }

    fn make(&self, kind: Kind, start: usize, end: usize, tok: &Token) -> Result<Node, ExprError> {
        let height = 1 + match &kind {
            Kind::Num(_) | Kind::Named(..) | Kind::Sym(..) => 0,
            Kind::Neg(a) => a.height,
            Kind::Bin(_, a, b) => a.height.max(b.height),
            Kind::Call(_, args) => args.iter().map(|a| a.height).max().unwrap_or(0),
        };
        if height > MAX_HEIGHT {
            return Err(self.err_at(K::TooDeep { limit: MAX_HEIGHT }, tok));
        }
        Ok(Node {
            kind,
            start,
            end,
            height,
        })
    }

    /// expr = term { ("+" | "-") term }
    fn expr(&mut self) -> Result<Node, ExprError> {
        let mut lhs = self.term()?;
        loop {
            let op = match self.peek().tok {
                Tok::Plus => BinOp::Add,
                Tok::Minus => BinOp::Sub,
                _ => return Ok(lhs),
            };
            let t = self.next();
            let rhs = self.term()?;
            let (s, e) = (lhs.start, rhs.end);
            lhs = self.make(Kind::Bin(op, Box::new(lhs), Box::new(rhs)), s, e, &t)?;
        }
    }

    /// term = unary { ("*" | "/") unary }
    fn term(&mut self) -> Result<Node, ExprError> {
        let mut lhs = self.unary()?;
        loop {
            let op = match self.peek().tok {
                Tok::Star => BinOp::Mul,
                Tok::Slash => BinOp::Div,
                _ => return Ok(lhs),
            };
            let t = self.next();
            let rhs = self.unary()?;
            let (s, e) = (lhs.start, rhs.end);
            lhs = self.make(Kind::Bin(op, Box::new(lhs), Box::new(rhs)), s, e, &t)?;
        }
    }

    /// unary = ("-" | "+") unary | power
    fn unary(&mut self) -> Result<Node, ExprError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            let t = self.peek().clone();
            return Err(self.err_at(K::TooDeep { limit: MAX_DEPTH }, &t));
        }
        let r = match self.peek().tok {
            Tok::Minus => {
                let t = self.next();
                let a = self.unary()?;
                let e = a.end;
                self.make(Kind::Neg(Box::new(a)), t.col, e, &t)
            }
            Tok::Plus => {
                self.next();
                self.unary()
            }
            _ => self.power(),
        };
        self.depth -= 1;
        r
    }

    /// power = primary [ "^" unary ]   (right-associative, binds tighter than a leading sign)
    fn power(&mut self) -> Result<Node, ExprError> {
        let base = self.primary()?;
        if self.peek().tok != Tok::Caret {
            return Ok(base);
        }
        let t = self.next();
        let exp = self.unary()?;
        let (s, e) = (base.start, exp.end);
        self.make(
            Kind::Bin(BinOp::Pow, Box::new(base), Box::new(exp)),
            s,
            e,
            &t,
        )
    }

    /// primary = number | name | name "(" [ expr { "," expr } ] ")" | "(" expr ")"
    fn primary(&mut self) -> Result<Node, ExprError> {
        let t = self.next();
        let end = t.col + t.text.chars().count();
        match &t.tok {
            Tok::Num(v) => self.make(Kind::Num(*v), t.col, end, &t),
            Tok::LParen => {
                let inner = self.expr()?;
                let c = self.next();
                if c.tok != Tok::RParen {
                    return Err(self.err_at(
                        K::Unclosed {
                            open_column: t.col,
                            found: found(&c),
                        },
                        &c,
                    ));
                }
                // Parentheses only group; keep the inner node with the wider span.
                let mut inner = inner;
                inner.start = t.col;
                inner.end = c.col + 1;
                Ok(inner)
            }
            Tok::Name(name) => {
                if self.peek().tok == Tok::LParen {
                    self.call(&t, name)
                } else {
                    self.name(&t, name, end)
                }
            }
            Tok::Eof => Err(self.err_at(K::UnexpectedEnd, &t)),
            _ => Err(self.err_at(
                K::Unexpected {
                    found: t.text.clone(),
                },
                &t,
            )),
        }
    }

    fn name(&mut self, t: &Token, name: &str, end: usize) -> Result<Node, ExprError> {
        if name == "pi" {
            let pi = Kind::Named(name.to_string(), std::f64::consts::PI);
            return self.make(pi, t.col, end, t);
        }
        if Func::from_name(name).is_some() {
            return Err(self.err_at(
                K::MissingCall {
                    name: name.to_string(),
                },
                t,
            ));
        }
        let slot = match self.symbols {
            None => {
                if !self.names.iter().any(|n| n == name) {
                    self.names.push(name.to_string());
                }
                usize::MAX
            }
            Some(table) => match table.get(name) {
                Some(s) => s,
                None => {
                    if let Some(v) = table.constant(name) {
                        return self.make(Kind::Named(name.to_string(), v), t.col, end, t);
                    }
                    let cands = table
                        .names()
                        .iter()
                        .chain(table.constant_names())
                        .map(|s| s.as_str())
                        .chain(["pi"]);
                    return Err(self.err_at(
                        K::UnknownSymbol {
                            name: name.to_string(),
                            suggestion: closest(name, cands),
                        },
                        t,
                    ));
                }
            },
        };
        self.make(Kind::Sym(slot, name.to_string()), t.col, end, t)
    }

    fn call(&mut self, t: &Token, name: &str) -> Result<Node, ExprError> {
        let Some(f) = Func::from_name(name) else {
            let known = name == "pi"
                || self
                    .symbols
                    .is_some_and(|s| s.get(name).is_some() || s.constant(name).is_some());
            let kind = if known {
                K::NotAFunction {
                    name: name.to_string(),
                }
            } else {
                K::UnknownFunction {
                    name: name.to_string(),
                    suggestion: alias(name)
                        .map(str::to_string)
                        .or_else(|| closest(name, Func::ALL.iter().map(|f| f.name()))),
                }
            };
            return Err(self.err_at(kind, t));
        };
        let open = self.next();
        let mut args = Vec::new();
        let close = if self.peek().tok == Tok::RParen {
            self.next()
        } else {
            loop {
                self.depth += 1;
                let a = self.expr();
                self.depth -= 1;
                args.push(a?);
                let c = self.next();
                match c.tok {
                    Tok::Comma => continue,
                    Tok::RParen => break c,
                    Tok::Eof => {
                        return Err(self.err_at(
                            K::Unclosed {
                                open_column: open.col,
                                found: found(&c),
                            },
                            &c,
                        ))
                    }
                    _ => {
                        return Err(self.err_at(
                            K::BadArgumentList {
                                function: name.to_string(),
                                open_column: open.col,
                                found: found(&c),
                            },
                            &c,
                        ))
                    }
                }
            }
        };
        if args.len() != f.arity() {
            return Err(self.err_at(
                K::Arity {
                    name: name.to_string(),
                    expected: f.arity(),
                    got: args.len(),
                },
                t,
            ));
        }
        self.make(Kind::Call(f, args), t.col, close.col + 1, t)
    }
}

// ---- printing back to infix with minimal parentheses ----

/// Binding strength of a node when printed: 1 sum, 2 product, 3 sign, 4 power, 5 atom.
fn prec(n: &Node) -> u8 {
    match &n.kind {
        Kind::Num(v) if *v < 0.0 => 3,
        Kind::Num(_) | Kind::Named(..) | Kind::Sym(..) | Kind::Call(..) => 5,
        Kind::Neg(_) => 3,
        Kind::Bin(BinOp::Add | BinOp::Sub, ..) => 1,
        Kind::Bin(BinOp::Mul | BinOp::Div, ..) => 2,
        Kind::Bin(BinOp::Pow, ..) => 4,
    }
}

pub(crate) fn fmt_num(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e15 {
        format!("{}", v as i64)
    } else {
        format!("{v:?}")
    }
}

fn wrap(f: &mut fmt::Formatter<'_>, n: &Node, paren: bool) -> fmt::Result {
    if paren {
        write!(f, "({n})")
    } else {
        write!(f, "{n}")
    }
}

impl fmt::Display for Node {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // The left spine of a chain (`a + b + c`) without parentheses is printed iteratively, so a
        // long chain does not recurse once per term.
        let mut spine = vec![];
        let mut cur = self;
        while let Kind::Bin(op, a, _) = &cur.kind {
            let needs_paren = match op {
                BinOp::Pow => prec(a) <= 4,
                _ => prec(a) < prec(cur),
            };
            if needs_paren {
                break;
            }
            spine.push(cur);
            cur = a;
        }
        if spine.is_empty() {
            return self.fmt_one(f);
        }
        cur.fmt(f)?;
        for node in spine.into_iter().rev() {
            if let Kind::Bin(op, _, b) = &node.kind {
                let p = prec(node);
                let rp = match op {
                    BinOp::Pow => prec(b) < 3,
                    _ => prec(b) <= p,
                };
                match op {
                    BinOp::Add | BinOp::Sub => write!(f, " {} ", op.symbol())?,
                    _ => f.write_str(op.symbol())?,
                }
                wrap(f, b, rp)?;
            }
        }
        Ok(())
    }
}

impl Node {
    /// A placeholder leaf (what a node's children are replaced by when it is taken apart).
    pub(crate) fn empty() -> Node {
        Node {
            kind: Kind::Num(0.0),
            start: 0,
            end: 0,
            height: 1,
        }
    }

    fn fmt_one(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.kind {
            Kind::Num(v) => f.write_str(&fmt_num(*v)),
            Kind::Named(name, _) => f.write_str(name),
            Kind::Sym(_, name) => f.write_str(name),
            Kind::Neg(a) => {
                f.write_str("-")?;
                wrap(f, a, prec(a) < 4)
            }
            Kind::Bin(op, a, b) => {
                let p = prec(self);
                let (lp, rp) = match op {
                    BinOp::Pow => (prec(a) <= 4, prec(b) < 3),
                    _ => (prec(a) < p, prec(b) <= p),
                };
                wrap(f, a, lp)?;
                match op {
                    BinOp::Add | BinOp::Sub => write!(f, " {} ", op.symbol())?,
                    _ => f.write_str(op.symbol())?,
                }
                wrap(f, b, rp)
            }
            Kind::Call(func, args) => {
                write!(f, "{}(", func.name())?;
                for (i, a) in args.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "{a}")?;
                }
                f.write_str(")")
            }
        }
    }
}
