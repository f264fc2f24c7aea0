//! Errors of scene files: every message names the file, line, column and field, and shows the line.

use crate::expr::ExprError;
use std::ops::Range;
use std::path::Path;

pub use crate::located::{escape_invisible, SceneError, Source};

impl Source {
    /// Span of the value of `key = value` written on a line of its own in the table whose header
    /// starts at byte `header` (0: the top level), up to the next table header; None when the key
    /// is written otherwise (inline, dotted) or not at all.
    pub fn key_value_span(&self, header: usize, key: &str) -> Option<Range<usize>> {
        let mut start = header.min(self.text.len());
        for (k, line) in self.text[start..].split_inclusive('\n').enumerate() {
            let t = line.trim_start();
            if k > 0 && t.starts_with('[') {
                return None;
            }
            let value = t
                .strip_prefix(key)
                .and_then(|r| r.trim_start().strip_prefix('='))
                .map(str::trim_start);
            if let Some(v) = value.filter(|v| !v.is_empty()) {
                let from = start + line.len() - v.len();
                return Some(from..start + line.trim_end().len());
            }
            start += line.len();
        }
        None
    }

    /// An expression error, located inside the TOML string at `span` (the span includes quotes).
    pub fn expr_error(&self, span: Range<usize>, field: &str, e: &ExprError) -> SceneError {
        let raw = &self.text[span.start.min(self.text.len())..];
        let mut start = span.start;
        if raw.starts_with("\"\"\"") || raw.starts_with("'''") {
            start += 3;
            if self.text[start..].starts_with('\n') {
                start += 1;
            } else if self.text[start..].starts_with("\r\n") {
                start += 2;
            }
        } else if raw.starts_with('"') || raw.starts_with('\'') {
            start += 1;
        }
        let (line, col) = self.line_col(start);
        let rendered = e.render(&self.file.display().to_string(), line, col);
        // render() gives "file:line:col: error: message\n<excerpt>"; keep its position and excerpt.
        let (head, excerpt) = rendered.split_once('\n').unwrap_or((&rendered, ""));
        let (eline, ecol) = parse_position(head).unwrap_or((line, col));
        SceneError {
            file: self.file.clone(),
            line: eline,
            column: ecol,
            field: escape_invisible(field),
            message: escape_invisible(&e.message()),
            excerpt: excerpt.to_string(),
        }
    }

    /// A TOML syntax or type error. The field is reconstructed from the text: the table header in
    /// force at the error (array-of-tables entries counted, `[[model.bodies]]` -> `model.bodies[1]`)
    /// and the key on the error's line (best effort: empty for syntax errors outside a key/value).
    /// A missing field is named in full (`time.t1`), with the caret on its table's header.
    pub fn toml_error(&self, e: &toml::de::Error) -> SceneError {
        let msg = e.message().trim().to_string();
        let missing = msg
            .strip_prefix("missing field `")
            .and_then(|r| r.split_once('`'))
            .map(|(name, _)| name.to_string());
        let join = |table: String| match (&missing, table.is_empty()) {
            (Some(m), true) => m.clone(),
            (Some(m), false) => format!("{table}.{m}"),
            (None, _) => table,
        };
        match e.span() {
            Some(span) => {
                if let Some(open) = self.unclosed_inline_table(span.start, &msg) {
                    let (field, _) = self.field_at(open);
                    let (line, _) = self.line_col(span.start);
                    return self.error(
                        open..open + 1,
                        &field,
                        format!(
                            "this inline table `{{` is not closed: TOML reads on to line {line} \
                             and stops there ({msg}); end it with `}}`"
                        ),
                    );
                }
                let (field, on_header) = self.field_at(span.start);
                if missing.is_some() && !on_header && field.is_empty() {
                    // A missing top-level key: the span is the whole document, shown at its start.
                    return self.error(0..0, &join(field), msg);
                }
                let field = if on_header { join(field) } else { field };
                self.error(span, &field, msg)
            }
            None => self.general(&join(String::new()), msg),
        }
    }

    /// The `{` of an inline table still open at an inline-table syntax error reported on a later
    /// line (`{ a = 1, b = 2` then `[next]`: the parser only notices at the next header). Scans
    /// the text before the error for brackets outside strings and comments.
    fn unclosed_inline_table(&self, at: usize, msg: &str) -> Option<usize> {
        if !msg.contains("inline table") && !msg.contains("between key-value pairs") {
            return None;
        }
        let text = self.text.as_bytes();
        let at = at.min(text.len());
        let mut open: Vec<(u8, usize)> = Vec::new();
        let mut i = 0;
        while i < at {
            let rest = &text[i..at];
            match text[i] {
                b'#' => {
                    i += rest.iter().position(|&c| c == b'\n').unwrap_or(rest.len());
                }
                q @ (b'"' | b'\'') => {
                    let triple = rest.len() >= 3 && rest[1] == q && rest[2] == q;
                    let (skip, close): (usize, &[u8]) = if triple {
                        (3, if q == b'"' { b"\"\"\"" } else { b"'''" })
                    } else {
                        (1, if q == b'"' { b"\"" } else { b"'" })
                    };
                    let mut j = i + skip;
                    while j < at && !text[j..].starts_with(close) {
                        if q == b'"' && text[j] == b'\\' {
                            j += 1;
                        }
                        if !triple && text[j.min(at - 1)] == b'\n' {
                            break;
                        }
                        j += 1;
                    }
                    i = j + close.len();
                }
                b'{' | b'[' => {
                    open.push((text[i], i));
                    i += 1;
                }
                b'}' | b']' => {
                    open.pop();
                    i += 1;
                }
                _ => i += 1,
            }
        }
        let (_, brace) = open.iter().rev().find(|(c, _)| *c == b'{')?;
        let (brace_line, _) = self.line_col(*brace);
        (brace_line < self.line_col(at).0).then_some(*brace)
    }

    /// Dotted field path at a byte offset, from the table headers above it and the key of its line.
    /// True with it when the offset is on a table header (the field is that table's).
    #[allow(clippy::too_many_lines)] // over 100 lines before the lint: to split, not to grow
    fn field_at(&self, offset: usize) -> (String, bool) {
        let offset = offset.min(self.text.len());
        let mut table = String::new();
        // Entries seen per array of tables, and the index of the current entry.
        let mut counts: std::collections::HashMap<String, usize> = Default::default();
        let mut current: std::collections::HashMap<String, usize> = Default::default();
        let header_name = |inner: &str| {
            let name = inner.trim();
            let ok = !name.is_empty()
                && name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "_-. \"".contains(c));
            ok.then(|| name.replace([' ', '"'], ""))
        };
        // `model.bodies.joints` -> `model.bodies[2].joints` (indices of the enclosing entries).
        let qualify = |name: &str, current: &std::collections::HashMap<String, usize>| {
            let mut out = String::new();
            let mut prefix = String::new();
            for (i, seg) in name.split('.').enumerate() {
                if i > 0 {
                    prefix.push('.');
                    out.push('.');
                }
                prefix.push_str(seg);
                out.push_str(seg);
                if prefix != name {
                    if let Some(k) = current.get(&prefix) {
                        out.push_str(&format!("[{k}]"));
                    }
                }
            }
            out
        };
        let mut line_start = 0;
        let mut body_start = 0;
        // The error is on a table header itself (a missing field): that header's table.
        let mut on_header = false;
        for line in self.text.split_inclusive('\n') {
            let here = line_start + line.len() > offset;
            let l = line.split('#').next().unwrap_or("").trim();
            let array = l
                .strip_prefix("[[")
                .and_then(|r| r.strip_suffix("]]"))
                .and_then(header_name);
            let plain = l
                .strip_prefix('[')
                .and_then(|r| r.strip_suffix(']'))
                .and_then(header_name);
            if here && array.is_none() && plain.is_none() {
                let inner = l.trim_matches(|c: char| c == '[' || c == ']' || c.is_whitespace());
                let header_like = l.starts_with('[')
                    && !l.contains([',', '='])
                    && inner.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_');
                if header_like {
                    // a malformed header (not a row of an array): the table it names, never the
                    // one above it
                    let name: String = inner
                        .chars()
                        .filter(|c| c.is_ascii_alphanumeric() || "_-.".contains(*c))
                        .collect();
                    return (name, false);
                }
                break;
            }
            if !here {
                line_start += line.len();
            }
            if let Some(name) = array {
                let k = counts.entry(name.clone()).or_insert(0);
                let idx = *k;
                *k += 1;
                // Entries of a nested array restart when their parent gets a new entry.
                let child = format!("{name}.");
                counts.retain(|n, _| !n.starts_with(&child));
                current.retain(|n, _| !n.starts_with(&child));
                current.insert(name.clone(), idx);
                table = format!("{}[{idx}]", qualify(&name, &current));
                body_start = line_start;
            } else if let Some(name) = plain {
                table = qualify(&name, &current);
                body_start = line_start;
            }
            if here {
                on_header = true;
                break;
            }
        }
        if on_header {
            return (table, true);
        }
        let key_line = &self.text[line_start..offset];
        let key = key_line
            .split_once('=')
            .map(|(k, _)| k)
            .unwrap_or(key_line)
            .trim()
            .trim_matches('"');
        let key_ok = !key.is_empty()
            && key
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.' || c == '-');
        let key = if key_ok {
            key.to_string()
        } else if key_line.trim().is_empty() {
            // The offset is at the key itself (unknown field): take the word there.
            self.text[offset..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == '-')
                .collect()
        } else {
            // Inside a value spanning lines (a multi-line array): the last `key =` above.
            self.text[body_start..line_start]
                .lines()
                .rev()
                .filter_map(|l| l.split_once('='))
                .map(|(k, _)| k.trim().trim_matches('"'))
                .find(|k| {
                    !k.is_empty()
                        && k.chars()
                            .all(|c| c.is_ascii_alphanumeric() || "_-.".contains(c))
                })
                .unwrap_or("")
                .to_string()
        };
        let field = match (table.is_empty(), key.is_empty()) {
            (_, true) => table,
            (true, false) => key,
            (false, false) => format!("{table}.{key}"),
        };
        (field, false)
    }
}

fn parse_position(head: &str) -> Option<(usize, usize)> {
    let mut parts = head.split_once(": error:")?.0.rsplitn(3, ':');
    let col = parts.next()?.parse().ok()?;
    let line = parts.next()?.parse().ok()?;
    Some((line, col))
}

/// An error reading the file itself.
pub fn io_error(file: &Path, e: String) -> SceneError {
    SceneError {
        file: file.to_path_buf(),
        line: 0,
        column: 0,
        field: String::new(),
        message: format!("cannot read the scene file: {e}"),
        excerpt: String::new(),
    }
}

/// A scene file that is not text ([`crate::input::text`]): located, never quoted.
pub fn not_text(file: &Path, e: crate::input::NotText) -> SceneError {
    SceneError {
        file: file.to_path_buf(),
        line: e.line,
        column: e.column,
        field: String::new(),
        message: format!("the scene file {}", e.message),
        excerpt: String::new(),
    }
}
