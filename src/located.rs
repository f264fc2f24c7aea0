//! Located errors: a problem in an input file (a scene, a robot file) named by file, line, column
//! and field, with the line quoted under the quoting rule of [`crate::input`]. The importers and
//! the scene loader both report through it; it knows neither.

use std::fmt;
use std::ops::Range;
use std::path::PathBuf;

/// A problem with a scene file, located in it.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneError {
    /// The scene file.
    pub file: PathBuf,
    /// 1-based line (0 when the error has no position, e.g. the file cannot be read).
    pub line: usize,
    /// 1-based column.
    pub column: usize,
    /// The field concerned (`model.bodies[1].mass`), empty when not applicable.
    pub field: String,
    /// What is wrong.
    pub message: String,
    /// The offending source line and a caret, if known.
    pub excerpt: String,
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if self.line > 0 {
            write!(f, ":{}:{}", self.line, self.column)?;
        }
        write!(f, ": error: ")?;
        if !self.field.is_empty() {
            write!(f, "{}: ", self.field)?;
        }
        write!(f, "{}", self.message)?;
        if !self.excerpt.is_empty() {
            write!(f, "\n{}", self.excerpt)?;
        }
        Ok(())
    }
}

impl std::error::Error for SceneError {}

/// The text of a scene file with its name, for locating errors.
#[derive(Clone, Debug)]
pub struct Source {
    pub file: PathBuf,
    pub text: String,
    /// Empty for the text of one file. Otherwise `text` was composed from pieces of several files
    /// (an MJCF file with its `<include>`s expanded): the pieces in order, covering `text`, each
    /// with the file it came from; lines and errors are reported in that file.
    pub spliced: Vec<Splice>,
}

/// A piece of a composed [`Source`]: `text[range]` is `source.text[offset..]`.
#[derive(Clone, Debug)]
pub struct Splice {
    pub range: Range<usize>,
    pub source: std::sync::Arc<Source>,
    pub offset: usize,
}

impl Source {
    /// The text of one file.
    pub fn new(file: PathBuf, text: String) -> Self {
        Source {
            file,
            text,
            spliced: vec![],
        }
    }

    /// For a composed text: the file's source an offset came from, the offset there, and the
    /// bytes left in that piece.
    fn origin(&self, offset: usize) -> Option<(&Source, usize, usize)> {
        let k = self
            .spliced
            .partition_point(|s| s.range.end <= offset)
            .min(self.spliced.len().checked_sub(1)?);
        let s = &self.spliced[k];
        let into = offset.saturating_sub(s.range.start).min(s.range.len());
        Some((&s.source, s.offset + into, s.range.len() - into))
    }

    /// The file a byte offset of the text came from (`file` unless the text is composed).
    pub fn file_at(&self, offset: usize) -> &std::path::Path {
        match self.origin(offset) {
            Some((src, at, _)) => src.file_at(at),
            None => &self.file,
        }
    }

    /// 1-based (line, column) of a byte offset, in the file it came from ([`Source::file_at`]).
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        if let Some((src, at, _)) = self.origin(offset) {
            return src.line_col(at);
        }
        let offset = offset.min(self.text.len());
        let before = &self.text[..offset];
        let line = before.matches('\n').count() + 1;
        let start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
        (line, self.text[start..offset].chars().count() + 1)
    }

    /// The line at an error with a caret, under the quoting rule of [`crate::input`]: nothing
    /// for text that is not quotable, else one line of at most `QUOTE_WIDTH` characters.
    pub(crate) fn excerpt(&self, line: usize, column: usize, width: usize) -> String {
        if !crate::input::quotable(&self.text) {
            return String::new();
        }
        let text = self.text.lines().nth(line - 1).unwrap_or("");
        let (text, column) = crate::input::excerpt_line(text, column);
        let room = text.chars().count().saturating_sub(column - 1).max(1);
        format!(
            "    {text}\n    {}{}",
            " ".repeat(column.saturating_sub(1)),
            "^".repeat(width.clamp(1, room))
        )
    }

    /// An error at a byte span (in the file the span came from).
    pub fn error(&self, span: Range<usize>, field: &str, message: impl Into<String>) -> SceneError {
        if let Some((src, at, left)) = self.origin(span.start) {
            return src.error(at..at + span.len().min(left), field, message);
        }
        let (line, column) = self.line_col(span.start);
        let first_line_len = self.text
            [span.start.min(self.text.len())..span.end.min(self.text.len())]
            .lines()
            .next()
            .map(|l| l.chars().count())
            .unwrap_or(1);
        SceneError {
            file: self.file.clone(),
            line,
            column,
            field: escape_invisible(field),
            message: escape_invisible(&message.into()),
            excerpt: self.excerpt(line, column, first_line_len),
        }
    }

    /// An error without a position.
    pub fn general(&self, field: &str, message: impl Into<String>) -> SceneError {
        SceneError {
            file: self.file.clone(),
            line: 0,
            column: 0,
            field: escape_invisible(field),
            message: escape_invisible(&message.into()),
            excerpt: String::new(),
        }
    }
}

/// Characters a terminal does not show (controls, zero-width and format characters, non-ASCII
/// spaces) written as `\u{200b}`, so a message about a name shows what is in it.
pub fn escape_invisible(s: &str) -> String {
    let invisible = |c: char| {
        (c.is_control() && c != '\n')
            || (c.is_whitespace() && c != ' ' && c != '\n')
            || matches!(c as u32,
                0xAD | 0x34F | 0x61C | 0x115F | 0x1160 | 0x17B4 | 0x17B5 | 0x180B..=0x180F
                | 0x200B..=0x200F | 0x202A..=0x202E | 0x2060..=0x206F | 0x3164 | 0xFE00..=0xFE0F
                | 0xFEFF | 0xFFA0 | 0xFFF0..=0xFFFB | 0xE0000..=0xE0FFF)
    };
    if !s.chars().any(invisible) {
        return s.to_string();
    }
    s.chars()
        .map(|c| {
            if invisible(c) {
                format!("\\u{{{:x}}}", c as u32)
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// The nearest of `candidates` to a misspelt `name` (edit distance within a third of its
/// length), for "did you mean" (the expression parser's rule).
pub fn nearest<'a>(name: &str, candidates: impl Iterator<Item = &'a str>) -> Option<String> {
    crate::expr::closest(name, candidates)
}

/// ` (did you mean `x`?)` or nothing.
pub fn did_you_mean<'a>(name: &str, candidates: impl Iterator<Item = &'a str>) -> String {
    nearest(name, candidates)
        .map(|s| format!(" (did you mean `{s}`?)"))
        .unwrap_or_default()
}
