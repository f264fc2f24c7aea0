//! Compile errors with source positions and caret rendering.

use std::fmt::Write as _;

/// What went wrong. The `Display` text is the human message without position.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ExprErrorKind {
    #[error("empty expression")]
    Empty,
    #[error("unexpected character `{0}`{hint}", hint = if .0.is_alphabetic() { " (names are ASCII: letters, digits, `_`)" } else { "" })]
    UnexpectedChar(char),
    #[error("malformed number `{text}`: {reason}")]
    BadNumber { text: String, reason: &'static str },
    #[error("missing operator between `{number}` and `{name}`: multiplication must be explicit, write `{number}*{name}`")]
    ImplicitMul { number: String, name: String },
    #[error("malformed name `{text}`: {reason}")]
    BadName { text: String, reason: &'static str },
    #[error("`**` is not an operator; write powers with `^`")]
    DoubleStar,
    #[error("unexpected `{found}`, expected a number, name or `(`")]
    Unexpected { found: String },
    #[error("unexpected end of input, expected a number, name or `(`")]
    UnexpectedEnd,
    #[error("expected `)` to close `(` opened at column {open_column}, found {found}")]
    Unclosed { open_column: usize, found: String },
    #[error("expected `,` or `)` in the arguments of `{function}` (opened at column {open_column}), found {found}")]
    BadArgumentList {
        function: String,
        open_column: usize,
        found: String,
    },
    #[error("unmatched `)`")]
    UnmatchedClose,
    #[error("unexpected `{found}` after a complete expression (missing operator?)")]
    Trailing { found: String },
    #[error("unknown symbol {}{}", shown(.name), suggest(.suggestion))]
    UnknownSymbol {
        name: String,
        suggestion: Option<String>,
    },
    #[error("unknown function `{name}`{}", suggest(.suggestion))]
    UnknownFunction {
        name: String,
        suggestion: Option<String>,
    },
    #[error("`{name}` is a symbol, not a function")]
    NotAFunction { name: String },
    #[error("function `{name}` needs arguments: `{name}(...)`")]
    MissingCall { name: String },
    #[error("function `{name}` takes {expected} argument{}, got {got}", if *.expected == 1 { "" } else { "s" })]
    Arity {
        name: String,
        expected: usize,
        got: usize,
    },
    #[error("expression nested too deeply (limit {limit})")]
    TooDeep { limit: usize },
    #[error("constant subexpression evaluates to {value}")]
    NonFinite { value: f64 },
}

fn suggest(s: &Option<String>) -> String {
    match s {
        Some(s) => format!(" (did you mean {}?)", shown(s)),
        None => String::new(),
    }
}

/// A name inside a message: `` `q` ``, or `` `` `joint_8.0` `` `` when it needs backquotes.
pub(crate) fn shown(name: &str) -> String {
    let w = crate::expr::written(name);
    if w.contains('`') {
        format!("`` {w} ``")
    } else {
        format!("`{w}`")
    }
}

/// A compile error: message kind, 1-based character column in the source, the offending token
/// text (empty at end of input) and the source itself for caret rendering.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{kind} (column {column})")]
pub struct ExprError {
    pub kind: ExprErrorKind,
    /// 1-based char index into the source; `len + 1` at end of input.
    pub column: usize,
    /// The offending token as written (may be empty at end of input).
    pub token: String,
    /// The expression source.
    pub input: String,
}

impl ExprError {
    pub(crate) fn new(kind: ExprErrorKind, column: usize, token: &str, input: &str) -> Self {
        ExprError {
            kind,
            column: column.max(1),
            token: token.to_string(),
            input: input.to_string(),
        }
    }

    /// The human message without position (same as `kind.to_string()`).
    pub fn message(&self) -> String {
        self.kind.to_string()
    }

    /// Line (0-based, within the source) and 1-based column within that line of the error.
    fn line_col(&self) -> (usize, usize, &str) {
        let mut line_no = 0;
        let mut line_start = 0; // char index
        for (i, ch) in self.input.chars().enumerate() {
            if i + 1 >= self.column {
                break;
            }
            if ch == '\n' {
                line_no += 1;
                line_start = i + 1;
            }
        }
        let line = self.input.split('\n').nth(line_no).unwrap_or("");
        let line = line.strip_suffix('\r').unwrap_or(line);
        (line_no, self.column - line_start, line)
    }

    /// Two lines: the source line holding the error and a caret under the offending token.
    pub fn caret(&self) -> String {
        let (_, col, line) = self.line_col();
        let mut out = String::new();
        out.push_str(line);
        out.push('\n');
        // Keep tabs so the caret lines up in terminals.
        for ch in line.chars().take(col - 1) {
            out.push(if ch == '\t' { '\t' } else { ' ' });
        }
        let width = self.token.chars().count().max(1);
        for _ in 0..width {
            out.push('^');
        }
        out
    }

    /// Render for a scene file: `file:line:col: error: message`, then the expression line and a
    /// caret. `line` is the file line of the TOML value and `col_offset` the 1-based file column
    /// of the expression's first character; newlines inside the expression are followed.
    pub fn render(&self, file: &str, line: usize, col_offset: usize) -> String {
        let (dl, col, _) = self.line_col();
        let (fl, fc) = if dl == 0 {
            (line, col_offset + col - 1)
        } else {
            (line + dl, col)
        };
        let mut out = String::new();
        let _ = writeln!(out, "{file}:{fl}:{fc}: error: {}", self.kind);
        for l in self.caret().lines() {
            let _ = writeln!(out, "    {l}");
        }
        out.pop();
        out
    }
}

/// Levenshtein distance over chars.
pub(crate) fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for (i, ca) in a.chars().enumerate() {
        cur[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[b.len()]
}

/// The closest candidate within a length-dependent edit distance, first one on ties.
pub fn closest<'a>(name: &str, candidates: impl Iterator<Item = &'a str>) -> Option<String> {
    let n = name.chars().count();
    let limit = (n / 3).max(1);
    let mut best: Option<(usize, &str)> = None;
    for c in candidates {
        let d = edit_distance(name, c);
        if d <= limit && best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, c));
        }
    }
    best.map(|(_, c)| c.to_string())
}
