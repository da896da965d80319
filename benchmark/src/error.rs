//! Typed errors of the open-loop suite; every message names the file, field or value at fault.

/// Errors of `dh-benchmark`. User input never panics; it ends up here.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A record lacks a field or holds a value of the wrong type.
    #[error("{context}: field `{field}`: {reason}")]
    Record { context: String, field: String, reason: String },
    /// A task id or file stem that is not one of the 14 open-loop tasks.
    #[error("unknown open-loop task `{0}` (expected one of R1_1_A … R3_2 or a release file stem)")]
    UnknownTask(String),
    /// A predictions file whose name maps to no task.
    #[error("{file}: unknown task file ({expected})")]
    UnknownTaskFile { file: String, expected: String },
    /// A predictions file (or a whole run) yields no record to score; `reason` gives the
    /// first skipped line's fault, so a wrong layout never reads as a score of 0.
    #[error("{context}: nothing to score: {reason}")]
    NothingToScore { context: String, reason: String },
    /// Invalid calibration input or parameters.
    #[error("calibration: {0}")]
    Calibration(String),
}

/// Result alias of the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
