//! Errors of the result writers and readers.

/// What went wrong, and in which file (`file` is a path, or a label such as `<memory>` for writers
/// that are not files).
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// Creating, writing, flushing or reading failed.
    #[error("{file}: {what}: {source}")]
    Io {
        file: String,
        what: String,
        #[source]
        source: std::io::Error,
    },
    /// The MCAP writer failed.
    #[error("{file}: {what}: {}", chain(source))]
    Mcap {
        file: String,
        what: String,
        #[source]
        source: mcap::McapError,
    },
    /// JSON serialization failed.
    #[error("{file}: {what}: {source}")]
    Json {
        file: String,
        what: String,
        #[source]
        source: serde_json::Error,
    },
    /// A CSV file could not be parsed: `line` is 1-based, `column` 1-based (0 when the whole line
    /// is bad), `header` the column's name when known.
    #[error(
        "{file}: line {line}, column {column}{}: {message}",
        header_suffix(header)
    )]
    Parse {
        file: String,
        line: u64,
        column: usize,
        header: Option<String>,
        message: String,
    },
    /// Data inconsistent with the layout (wrong number of values, mismatched names, ...).
    #[error("{file}: {message}")]
    Invalid { file: String, message: String },
}

/// An error and its sources, joined by ": ".
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut src = e.source();
    while let Some(e) = src {
        s.push_str(": ");
        s.push_str(&e.to_string());
        src = e.source();
    }
    s
}

fn header_suffix(h: &Option<String>) -> String {
    match h {
        Some(h) => format!(" ({h})"),
        None => String::new(),
    }
}

impl OutputError {
    /// The file (or label) concerned.
    pub fn file(&self) -> &str {
        match self {
            OutputError::Io { file, .. }
            | OutputError::Mcap { file, .. }
            | OutputError::Json { file, .. }
            | OutputError::Parse { file, .. }
            | OutputError::Invalid { file, .. } => file,
        }
    }
    pub(crate) fn io(file: &str, what: impl Into<String>, source: std::io::Error) -> Self {
        OutputError::Io {
            file: file.to_string(),
            what: what.into(),
            source,
        }
    }
    pub(crate) fn mcap(file: &str, what: impl Into<String>, source: mcap::McapError) -> Self {
        OutputError::Mcap {
            file: file.to_string(),
            what: what.into(),
            source,
        }
    }
    pub(crate) fn invalid(file: &str, message: impl Into<String>) -> Self {
        OutputError::Invalid {
            file: file.to_string(),
            message: message.into(),
        }
    }

    /// An equivalent error (sources that are not `Clone` are kept as text), to report a remembered
    /// error again.
    pub(crate) fn replay(&self) -> OutputError {
        match self {
            OutputError::Io { file, what, source } => OutputError::Io {
                file: file.clone(),
                what: what.clone(),
                source: std::io::Error::new(source.kind(), source.to_string()),
            },
            OutputError::Parse {
                file,
                line,
                column,
                header,
                message,
            } => OutputError::Parse {
                file: file.clone(),
                line: *line,
                column: *column,
                header: header.clone(),
                message: message.clone(),
            },
            OutputError::Invalid { file, message } => OutputError::Invalid {
                file: file.clone(),
                message: message.clone(),
            },
            OutputError::Mcap { file, what, source } => OutputError::Invalid {
                file: file.clone(),
                message: format!("{what}: {}", chain(source)),
            },
            OutputError::Json { file, what, source } => OutputError::Invalid {
                file: file.clone(),
                message: format!("{what}: {source}"),
            },
        }
    }
}
