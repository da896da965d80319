//! One error type for the whole world crate. Every variant names what the user must fix;
//! the binding crate maps each category to one Python exception class.

use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A scenario file (or a value inside it) is invalid. `at` is the 1-based line and column
    /// of the field in the file (shown as `file:line:column:` like compilers do).
    #[error("{file}{}: field `{field}` = {value}: {message}", .at.map_or(String::new(), |(l, c)| format!(":{l}:{c}")))]
    Scenario { file: String, at: Option<(usize, usize)>, field: String, value: String, message: String },
    /// A road network could not be read or lacks what was asked of it.
    #[error("{file}: {message}")]
    Map { file: String, message: String },
    /// A runtime setting or an action is invalid.
    #[error("config `{field}` = {value}: {message}")]
    Config { field: String, value: String, message: String },
    /// The simulation was used out of order (step before reset, ...) or failed internally.
    #[error("simulation: {0}")]
    Simulation(String),
    #[error("render: {0}")]
    Render(String),
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub fn scenario(
        file: impl AsRef<Path>,
        field: impl Into<String>,
        value: impl std::fmt::Display,
        message: impl Into<String>,
    ) -> Self {
        Error::Scenario {
            file: file.as_ref().display().to_string(),
            at: None,
            field: field.into(),
            value: value.to_string(),
            message: message.into(),
        }
    }
    /// Sets the line and column of a scenario error (other errors are returned unchanged).
    pub fn at(self, line: usize, column: usize) -> Self {
        match self {
            Error::Scenario { file, field, value, message, .. } => {
                Error::Scenario { file, at: Some((line, column)), field, value, message }
            }
            other => other,
        }
    }
    pub fn map(file: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Error::Map { file: file.as_ref().display().to_string(), message: message.into() }
    }
    pub fn config(
        field: impl Into<String>,
        value: impl std::fmt::Display,
        message: impl Into<String>,
    ) -> Self {
        Error::Config { field: field.into(), value: value.to_string(), message: message.into() }
    }
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io { path: path.as_ref().display().to_string(), source }
    }
}
