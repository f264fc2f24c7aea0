//! Tokenizer. Positions are 1-based char columns.

use super::error::{ExprError, ExprErrorKind as K};

#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Tok {
    Num(f64),
    Name(String),
    Plus,
    Minus,
    Star,
    Slash,
    Caret,
    LParen,
    RParen,
    Comma,
    Eof,
}

#[derive(Debug, Clone)]
pub(crate) struct Token {
    pub tok: Tok,
    /// 1-based char column of the first char.
    pub col: usize,
    /// Source text of the token ("" for end of input).
    pub text: String,
}

fn is_start(c: char) -> bool {
    c.is_ascii_alphabetic() || c == '_'
}

fn is_cont(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

pub(crate) fn lex(src: &str) -> Result<Vec<Token>, ExprError> {
    let lx = Lexer {
        src,
        cs: src.chars().collect(),
    };
    let cs = &lx.cs;
    let mut out = Vec::new();
    let mut i = 0;
    while i < cs.len() {
        let c = cs[i];
        let simple = match c {
            '+' => Some(Tok::Plus),
            '-' => Some(Tok::Minus),
            '*' => Some(Tok::Star),
            '/' => Some(Tok::Slash),
            '^' => Some(Tok::Caret),
            '(' => Some(Tok::LParen),
            ')' => Some(Tok::RParen),
            ',' => Some(Tok::Comma),
            _ => None,
        };
        if let Some(tok) = simple {
            if c == '*' && cs.get(i + 1) == Some(&'*') {
                return Err(lx.err(K::DoubleStar, i, &cs[i..i + 2]));
            }
            out.push(Token {
                tok,
                col: i + 1,
                text: c.to_string(),
            });
            i += 1;
        } else if c.is_whitespace() {
            i += 1;
        } else if c.is_ascii_digit()
            || (c == '.' && cs.get(i + 1).is_some_and(|d| d.is_ascii_digit()))
        {
            let (token, end) = lx.number(i)?;
            out.push(token);
            i = end;
        } else if is_start(c) || c == '`' {
            let (token, end) = lx.name(i)?;
            out.push(token);
            i = end;
        } else {
            return Err(lx.err(K::UnexpectedChar(c), i, &cs[i..=i]));
        }
    }
    out.push(Token {
        tok: Tok::Eof,
        col: cs.len() + 1,
        text: String::new(),
    });
    Ok(out)
}

/// The source being tokenized, as chars.
struct Lexer<'a> {
    src: &'a str,
    cs: Vec<char>,
}

impl Lexer<'_> {
    /// An error of `kind` at the 0-based char index `col`, on the chars `text`.
    fn err(&self, kind: K, col: usize, text: &[char]) -> ExprError {
        ExprError::new(kind, col + 1, &text.iter().collect::<String>(), self.src)
    }

    /// The number starting at `start` and the index after it.
    fn number(&self, start: usize) -> Result<(Token, usize), ExprError> {
        let cs = &self.cs;
        let mut i = start;
        // digits [. digits] [(e|E) [+-] digits]
        while i < cs.len() && cs[i].is_ascii_digit() {
            i += 1;
        }
        if i < cs.len() && cs[i] == '.' {
            i += 1;
            while i < cs.len() && cs[i].is_ascii_digit() {
                i += 1;
            }
        }
        let mut bad_exponent = false;
        if i < cs.len() && (cs[i] == 'e' || cs[i] == 'E') {
            let mut j = i + 1;
            if j < cs.len() && (cs[j] == '+' || cs[j] == '-') {
                j += 1;
            }
            let digits = j;
            while j < cs.len() && cs[j].is_ascii_digit() {
                j += 1;
            }
            if j > digits {
                i = j;
            } else {
                bad_exponent = true;
                i = digits;
            }
        }
        if bad_exponent {
            return Err(self.err(
                K::BadNumber {
                    text: cs[start..i].iter().collect(),
                    reason: "the exponent needs digits",
                },
                start,
                &cs[start..i],
            ));
        }
        if i < cs.len() && (cs[i] == '.' || cs[i].is_ascii_digit()) {
            let mut j = i;
            while j < cs.len() && (cs[j] == '.' || is_cont(cs[j])) {
                j += 1;
            }
            return Err(self.err(
                K::BadNumber {
                    text: cs[start..j].iter().collect(),
                    reason: "too many `.`",
                },
                start,
                &cs[start..j],
            ));
        }
        let text: String = cs[start..i].iter().collect();
        if i < cs.len() && is_start(cs[i]) {
            let mut j = i;
            while j < cs.len() && is_cont(cs[j]) {
                j += 1;
            }
            let name: String = cs[i..j].iter().collect();
            return Err(self.err(K::ImplicitMul { number: text, name }, i, &cs[i..j]));
        }
        // The scanned text always has Rust float syntax.
        let v: f64 = text.parse().unwrap_or(f64::NAN);
        if !v.is_finite() {
            return Err(self.err(
                K::BadNumber {
                    text: text.clone(),
                    reason: "out of range",
                },
                start,
                &cs[start..i],
            ));
        }
        let token = Token {
            tok: Tok::Num(v),
            col: start + 1,
            text,
        };
        Ok((token, i))
    }

    /// The name starting at `start` and the index after it. A part is an identifier or a
    /// backquoted name of a robot file (`` `joint_8.0` ``: any characters but a backquote, a quote
    /// and a line break); the token's name is the parts joined by `.`, quotes removed.
    fn name(&self, start: usize) -> Result<(Token, usize), ExprError> {
        let cs = &self.cs;
        let mut i = start;
        let mut name = String::new();
        // part ("." part)* "'"{0,2}
        loop {
            if cs.get(i) == Some(&'`') {
                let open = i;
                i += 1;
                while i < cs.len() && !matches!(cs[i], '`' | '\n' | '\'') {
                    i += 1;
                }
                if cs.get(i) != Some(&'`') {
                    let end = (i + 1).min(cs.len());
                    return Err(self.err(
                        K::BadName {
                            text: cs[open..end].iter().collect(),
                            reason: "a backquoted name needs its closing backquote (and holds no `'` or line break)",
                        },
                        open,
                        &cs[open..end],
                    ));
                }
                if i == open + 1 {
                    return Err(self.err(
                        K::BadName {
                            text: "``".into(),
                            reason: "a backquoted name is not empty",
                        },
                        open,
                        &cs[open..=i],
                    ));
                }
                name.extend(&cs[open + 1..i]);
                i += 1;
            } else {
                let from = i;
                while i < cs.len() && is_cont(cs[i]) {
                    i += 1;
                }
                name.extend(&cs[from..i]);
            }
            if i < cs.len() && cs[i] == '.' {
                if cs.get(i + 1).is_some_and(|&d| is_start(d) || d == '`') {
                    name.push('.');
                    i += 1;
                    continue;
                }
                return Err(self.err(
                    K::BadName {
                        text: cs[start..=i].iter().collect(),
                        reason: "expected a name part after `.` (a name of the robot file that is not an identifier is written in backquotes: `` `joint_8.0` ``)",
                    },
                    start,
                    &cs[start..=i],
                ));
            }
            break;
        }
        let primes = cs[i..].iter().take_while(|&&p| p == '\'').count();
        i += primes;
        if primes > 2 {
            return Err(self.err(
                K::BadName {
                    text: cs[start..i].iter().collect(),
                    reason: "at most two `'` (velocity `'`, acceleration `''`)",
                },
                start,
                &cs[start..i],
            ));
        }
        name.extend(&cs[i - primes..i]);
        let text: String = cs[start..i].iter().collect();
        let token = Token {
            tok: Tok::Name(name),
            col: start + 1,
            text,
        };
        Ok((token, i))
    }
}
