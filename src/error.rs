//! [`Error`]: the one error type of the library's entry points, with a typed variant per kind of
//! failure. Each module keeps its own precise error (a [`SceneError`] knows its line, a
//! [`FormulationError`] its rows); they all convert into this one, and the Python binding turns
//! this one into Python's exceptions in one place, with the structured fields ([`Error::field`],
//! [`Error::location`], [`Error::rows`]) as attributes.

use crate::export::ExportError;
use crate::formulation::FormulationError;
use crate::output::OutputError;
use crate::scene::SceneError;
use crate::solve::{OverrideError, SettingError, SettingsError, UnknownName};
use std::path::PathBuf;

/// Every failure a user of the library can meet, by kind.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A scene file (or a robot file it names) is invalid: located (file, line, column, field).
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A setting (solver, time span, output) is invalid: `field` is its name at every door
    /// (`rtol`, `output_dt`; [`crate::solve::settings`]).
    #[error("{field}: {message}")]
    Settings { field: String, message: String },
    /// A file named in input is refused by the path rule ([`crate::input::resolve`]) or cannot be
    /// read as what it should be.
    #[error("{message}")]
    Input { message: String },
    /// The accelerations cannot be computed at a state (rank-deficient programme, singular
    /// system, non-finite terms, unrealizable actuation).
    #[error(transparent)]
    Formulation(#[from] FormulationError),
    /// The scene cannot be written in a simulator's format.
    #[error(transparent)]
    Export(#[from] ExportError),
    /// Writing or reading results failed (file named).
    #[error(transparent)]
    Output(#[from] OutputError),
    /// An argument of a library function is out of its domain (`field` names it).
    #[error("{field}: {message}")]
    Argument { field: String, message: String },
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Where a located error is: file, 1-based line and column.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    pub file: PathBuf,
    pub line: usize,
    pub column: usize,
}

impl Error {
    /// A refusal of the input path rule.
    pub fn input(message: impl Into<String>) -> Self {
        Error::Input {
            message: message.into(),
        }
    }

    /// An argument out of its domain.
    pub fn argument(field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Argument {
            field: field.into(),
            message: message.into(),
        }
    }

    /// Short name of the kind (`scene`, `settings`, ...), as reports and logs name it.
    pub fn kind(&self) -> &'static str {
        match self {
            Error::Scene(_) => "scene",
            Error::Settings { .. } => "settings",
            Error::Input { .. } => "input",
            Error::Formulation(_) => "formulation",
            Error::Export(_) => "export",
            Error::Output(_) => "output",
            Error::Argument { .. } => "argument",
        }
    }

    /// The field, setting or argument concerned (`model.bodies[1].mass`, `rtol`), if any.
    pub fn field(&self) -> Option<&str> {
        match self {
            Error::Scene(e) => (!e.field.is_empty()).then_some(e.field.as_str()),
            Error::Settings { field, .. } | Error::Argument { field, .. } => Some(field),
            _ => None,
        }
    }

    /// What is wrong, without the location and the field.
    pub fn message(&self) -> String {
        match self {
            Error::Scene(e) => e.message.clone(),
            Error::Settings { message, .. }
            | Error::Argument { message, .. }
            | Error::Input { message } => message.clone(),
            e => e.to_string(),
        }
    }

    /// File, line and column of a located error (a scene error with a position).
    pub fn location(&self) -> Option<Location> {
        match self {
            Error::Scene(e) if e.line > 0 => Some(Location {
                file: e.file.clone(),
                line: e.line,
                column: e.column,
            }),
            _ => None,
        }
    }

    /// The file concerned, located or not (a scene error, a result file).
    pub fn file(&self) -> Option<String> {
        match self {
            Error::Scene(e) => Some(e.file.display().to_string()),
            Error::Output(e) => Some(e.file().to_string()),
            _ => None,
        }
    }

    /// Indices of the programme rows at fault (a rank-deficient programme), if any.
    pub fn rows(&self) -> Option<&[usize]> {
        match self {
            Error::Formulation(FormulationError::RankDeficient { rows, .. }) => Some(rows),
            _ => None,
        }
    }
}

impl From<SettingsError> for Error {
    fn from(e: SettingsError) -> Self {
        Error::Settings {
            field: e.field.name().to_string(),
            message: e.message,
        }
    }
}

impl From<SettingError> for Error {
    fn from(e: SettingError) -> Self {
        Error::Settings {
            field: e.name,
            message: e.message,
        }
    }
}

impl From<OverrideError> for Error {
    fn from(e: OverrideError) -> Self {
        Error::Settings {
            field: e.field().to_string(),
            message: e.to_string(),
        }
    }
}

impl From<UnknownName> for Error {
    fn from(e: UnknownName) -> Self {
        Error::Settings {
            field: e.what.to_string(),
            message: e.to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::{Settings, SettingsField};

    #[test]
    fn every_kind_keeps_its_fields() {
        let e: Error = crate::solve::validate((0.0, -1.0), &Settings::default())
            .unwrap_err()
            .into();
        assert_eq!((e.kind(), e.field()), ("settings", Some("t1")));
        assert!(
            e.to_string().starts_with("t1: t1 = -1.0 must be after"),
            "{e}"
        );
        let e: Error = SettingsError {
            field: SettingsField::OutputDt,
            value: 0.0,
            message: "m".into(),
        }
        .into();
        assert_eq!(e.to_string(), "output_dt: m");
        let e: Error = FormulationError::RankDeficient {
            rank: 1,
            rows: vec![1],
            rcond: 0.0,
        }
        .into();
        assert_eq!((e.kind(), e.rows()), ("formulation", Some(&[1][..])));
        assert_eq!(e.field(), None);
        let e = Error::Scene(
            crate::scene::Scene::from_text(std::path::Path::new("s.toml"), "name = 1\n")
                .unwrap_err(),
        );
        let at = e.location().expect("located");
        assert_eq!((at.file.to_str(), at.line), (Some("s.toml"), 1));
        assert_eq!(e.field(), Some("name"));
    }
}
