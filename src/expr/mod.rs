//! Expressions of scene files: parsed once, compiled to bytecode, evaluated over any [`crate::scalar::Scalar`].
//!
//! Programme rows, constraints and forces in a scene file are strings such as
//! `"l*sin(theta) - x0"` or `"tip.vel.y + k*r'"`. [`Expr::compile`] parses one against a
//! [`SymbolTable`] (names → slot indices chosen by the caller), folds constant subexpressions and
//! emits a compact stack-machine bytecode. [`Expr::eval`] runs it over `f64` for values and over
//! `num_dual` numbers for exact first and second derivatives: one code path, no finite
//! differences, no symbolic differentiation.
//!
//! # Grammar
//!
//! ```text
//! expr    = term { ("+" | "-") term } ;
//! term    = unary { ("*" | "/") unary } ;
//! unary   = ("-" | "+") unary | power ;
//! power   = primary [ "^" unary ] ;                  (* right-associative *)
//! primary = number | name | name "(" [ expr { "," expr } ] ")" | "(" expr ")" ;
//! number  = ( digits [ "." { digit } ] | "." digits ) [ ("e" | "E") [ "+" | "-" ] digits ] ;
//! name    = part { "." part } [ "'" | "''" ] ;       (* tip.vel.y, r', r'' *)
//! part    = ( letter | "_" ) { letter | digit | "_" }      (* ASCII *)
//!         | "`" { any char but "`", "'" and a line break } "`" ;   (* `joint_8.0` *)
//! ```
//!
//! A backquoted part is a robot file's name that is not an identifier: `` `joint_8.0`' `` is the
//! velocity of joint `joint_8.0`, `` `link_8.0`.pos.x `` a signal of link `link_8.0`. The name the
//! caller sees has the backquotes removed; [`written`] spells a name back as a row writes it.
//!
//! Whitespace (including newlines) separates tokens. Multiplication is explicit (`2*x`).
//!
//! # Precedence (loosest first)
//!
//! | level | operators   | associativity | example                  |
//! |-------|-------------|---------------|--------------------------|
//! | 1     | `+` `-`     | left          | `a-b-c = (a-b)-c`        |
//! | 2     | `*` `/`     | left          | `a/b/c = (a/b)/c`        |
//! | 3     | unary `-` `+` | prefix      | `2*-3 = -6`              |
//! | 4     | `^`         | right         | `2^3^2 = 512`, `-2^2 = -4`, `2^-1 = 0.5` |
//!
//! # Functions and constants
//!
//! `sin cos tan asin acos atan exp log sqrt abs sinh cosh tanh` take one argument, `atan2(y, x)`
//! two; `log` is the natural logarithm. `pi` is built in and reserved; further named constants
//! come from [`SymbolTable::define`] and are folded at compile time. Names carry no meaning
//! here: `r'` and `r''` are ordinary names whose apostrophes [`Expr::time_order`] counts, so the
//! caller can tell position-, velocity- and acceleration-level rows apart.
//!
//! # Derivatives
//!
//! Integer constant exponents compile to `powi` (`x^2` to a multiplication), other constants to
//! `powf`, symbolic exponents to num-dual's `powd` = `exp(y ln x)` (derivatives need `x > 0`;
//! a negative base with an integer-valued exponent is evaluated as `±(-x)^y`). `abs` has
//! derivative `sign(x)` (+1 at 0). `atan2` has finite derivatives everywhere but the origin,
//! also on the `y` axis where num-dual's own `atan2` divides by zero. The value part of a dual
//! result equals the f64 result up to rounding (num-dual divides as `a * (1/b)`).
//!
//! # Example
//!
//! ```
//! use progmo::expr::{Expr, SymbolTable};
//! use num_dual::Dual64;
//!
//! let mut symbols = SymbolTable::new();
//! let q = symbols.insert("q");
//! let v = symbols.insert("q'");
//! symbols.define("l", 0.5);
//! let g = Expr::compile("l*sin(q) + q'^2", &symbols).unwrap();
//! assert!(g.uses(v) && g.time_order() == 1);
//!
//! let mut stack = Vec::with_capacity(g.max_stack());
//! let value = g.eval(&[0.3, 2.0], &mut stack);
//! // d/dq through a dual number in slot q.
//! let d = g.eval(&[Dual64::new(0.3, 1.0), Dual64::new(2.0, 0.0)], &mut Vec::new());
//! assert_eq!(d.eps, 0.5 * 0.3f64.cos());
//! # let _ = (q, value);
//!
//! let err = Expr::compile("sin(qq)", &symbols).unwrap_err();
//! assert_eq!(err.render("scene.toml", 12, 20),
//!     "scene.toml:12:24: error: unknown symbol `qq` (did you mean `q`?)\n    sin(qq)\n        ^^");
//! ```
//!
//! # Why an own parser
//!
//! `exmex` 0.21 cannot differentiate `atan2`, `abs`, `min`, `max`, and its symbolic
//! differentiation is a separate path from evaluation; `evalexpr` is AGPL; `fasteval` and `meval`
//! are unmaintained. A small bytecode evaluated generically over num-dual types differentiates
//! everything exactly with the same code that computes values, and lets errors point at the
//! scene file (see [`ExprError::render`]).

mod affine;
mod compile;
mod cse;
mod error;
mod lexer;
mod parser;
mod tape;
#[cfg(test)]
mod tests;

pub use affine::Affine;
pub use compile::Expr;
pub use error::{closest, ExprError, ExprErrorKind};
pub use parser::Func;

use std::collections::HashMap;

/// Ordered names → slot indices. The caller fills a slot array `&[S]` in this order.
///
/// Optionally also named constants ([`SymbolTable::define`]), folded into the bytecode at
/// compile time (scene parameters such as masses and lengths). A slot wins over a constant of
/// the same name; `pi` is reserved.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SymbolTable {
    names: Vec<String>,
    index: HashMap<String, usize>,
    const_names: Vec<String>,
    consts: HashMap<String, f64>,
}

impl SymbolTable {
    pub fn new() -> Self {
        Self::default()
    }

    /// The slot of `name`, appending it if new.
    pub fn insert(&mut self, name: impl Into<String>) -> usize {
        let name = name.into();
        if let Some(&i) = self.index.get(&name) {
            return i;
        }
        let i = self.names.len();
        self.index.insert(name.clone(), i);
        self.names.push(name);
        i
    }

    pub fn get(&self, name: &str) -> Option<usize> {
        self.index.get(name).copied()
    }

    /// The name of `slot`.
    pub fn name(&self, slot: usize) -> Option<&str> {
        self.names.get(slot).map(|s| s.as_str())
    }

    /// All names in slot order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Define (or redefine) a named constant.
    pub fn define(&mut self, name: impl Into<String>, value: f64) {
        let name = name.into();
        if self.consts.insert(name.clone(), value).is_none() {
            self.const_names.push(name);
        }
    }

    /// The value of a named constant.
    pub fn constant(&self, name: &str) -> Option<f64> {
        self.consts.get(name).copied()
    }

    /// Names of the defined constants, in definition order.
    pub fn constant_names(&self) -> &[String] {
        &self.const_names
    }

    /// Number of slots.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }
}

impl<S: Into<String>> FromIterator<S> for SymbolTable {
    fn from_iter<I: IntoIterator<Item = S>>(iter: I) -> Self {
        let mut t = SymbolTable::new();
        for n in iter {
            t.insert(n);
        }
        t
    }
}

/// Number of trailing apostrophes: `r` → 0, `r'` → 1, `r''` → 2.
pub fn time_order(name: &str) -> u8 {
    name.bytes().rev().take_while(|&b| b == b'\'').count() as u8
}

/// The name without trailing apostrophes: `r''` → `r`.
pub fn base_name(name: &str) -> &str {
    name.trim_end_matches('\'')
}

/// `name` as an expression writes it: unchanged when every `.`-separated part is an identifier,
/// else with the non-identifier head in backquotes: `joint_8.0'` -> `` `joint_8.0`' ``,
/// `link_8.0.x` -> `` `link_8.0`.x `` (a last part that is a component word of a signal or of a
/// ball or free joint, `x y z vx vy vz wx wy wz qw qx qy qz`, stays bare).
pub fn written(name: &str) -> String {
    let base = base_name(name);
    let primes = &name[base.len()..];
    let ident = |p: &str| {
        let mut c = p.chars();
        matches!(c.next(), Some(ch) if ch.is_ascii_alphabetic() || ch == '_')
            && c.all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
    };
    if base.split('.').all(ident) {
        return name.to_string();
    }
    const COMPONENTS: [&str; 13] = [
        "x", "y", "z", "vx", "vy", "vz", "wx", "wy", "wz", "qw", "qx", "qy", "qz",
    ];
    match base.rsplit_once('.') {
        Some((head, last)) if COMPONENTS.contains(&last) => format!("`{head}`.{last}{primes}"),
        _ => format!("`{base}`{primes}"),
    }
}

/// The symbol names `source` references (not functions, not `pi`), in order of first appearance,
/// without resolving them. Lets the caller build the symbol table (e.g. create body-point
/// signals such as `tip.vel.y` on demand) before compiling.
pub fn referenced_names(source: &str) -> Result<Vec<String>, ExprError> {
    parser::parse(source, None).map(|(_, names)| names)
}
