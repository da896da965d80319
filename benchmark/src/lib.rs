//! `dh-benchmark`: the open-loop R1–R3 suite — task registry, record model, answer parsers,
//! exact per-record scorers (docs/protocol.md#answer-parsing, #record-scores), aggregation and
//! weight calibration (#aggregation).
//!
//! The original scorer is Python; every parser here reproduces its behaviour including
//! Python's Unicode classes, `json.loads` and `str()` (see [`pyunicode`] and [`pyjson`]).

pub mod error;
pub mod parse;
pub mod predictions;
pub mod pyjson;
pub mod pyunicode;

pub use error::{Error, Result};
pub mod record;
pub mod score;
pub mod task;

pub use record::Record;
pub use score::{score_answer, score_record, RecordScore, ScoreOptions, ScoreParams};
pub use task::{AnswerKind, Rank, Scorer, TaskId, TaskSpec, TASKS};
pub mod aggregate;
pub mod calibrate;

pub use aggregate::{summarize, Stats, Summary, TaskOutcome};
pub use calibrate::{calibrate, Calibration, CalibrationParams};
