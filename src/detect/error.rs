//! Errors of the detector runtime: what went wrong with one detector call ([`DetectorError`], data the
//! repair prompt feeds back to an LLM) and what stops the runtime itself ([`DetectError`]).

use std::fmt;

use serde::{Deserialize, Serialize};

/// Why one detector produced no annotations for one trace. A failing detector is data, not `Err`: the
/// batch goes on and this value is recorded (`detector_calls.status` / `.error`) and can be shown to an
/// LLM (its `Display` names the line, column or JSON path at fault).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "category", rename_all = "snake_case")]
#[non_exhaustive]
pub enum DetectorError {
    /// The code is not valid Python.
    Syntax {
        /// What the parser said.
        message: String,
        /// 1-based line, when known.
        line: Option<u32>,
        /// 1-based column, when known.
        column: Option<u32>,
    },
    /// The code uses a construct the sandbox refuses (an import, a dunder attribute, `eval`, …).
    Forbidden {
        /// What was refused.
        message: String,
        /// 1-based line.
        line: Option<u32>,
        /// 1-based column.
        column: Option<u32>,
    },
    /// The code defines no `find_pattern(trace)`.
    NoFindPattern {
        /// The message.
        message: String,
    },
    /// The detector raised an exception.
    Runtime {
        /// The exception's type name (`KeyError`, `ZeroDivisionError`, …).
        exception: Option<String>,
        /// `Type: message`.
        message: String,
        /// 1-based line in the detector's code where it was raised.
        line: Option<u32>,
    },
    /// The call ran past its time limit; the worker was killed and replaced.
    Timeout {
        /// The limit (s).
        seconds: f64,
    },
    /// The call ran past its memory limit (`MemoryError` or killed); the worker was replaced.
    Memory {
        /// The address-space limit (bytes).
        limit_bytes: u64,
    },
    /// The output breaks the pattern contract.
    InvalidOutput {
        /// JSON path of the fault (`$[3].end_timestep`).
        path: String,
        /// What is wrong.
        message: String,
    },
    /// The worker died for another reason (a signal, a bug); the worker was replaced.
    Crashed {
        /// What is known: exit status and the end of its standard error.
        message: String,
    },
    /// The detector was not run on this trace because it already failed fatally (timeout, memory,
    /// crash) on another trace of the batch.
    Skipped {
        /// The earlier failure.
        message: String,
    },
}

impl DetectorError {
    /// The category string stored in `detector_calls.status` (`syntax`, `forbidden`, `timeout`, …).
    pub fn category(&self) -> &'static str {
        match self {
            DetectorError::Syntax { .. } => "syntax",
            DetectorError::Forbidden { .. } => "forbidden",
            DetectorError::NoFindPattern { .. } => "no_find_pattern",
            DetectorError::Runtime { .. } => "runtime",
            DetectorError::Timeout { .. } => "timeout",
            DetectorError::Memory { .. } => "memory",
            DetectorError::InvalidOutput { .. } => "invalid_output",
            DetectorError::Crashed { .. } => "crashed",
            DetectorError::Skipped { .. } => "skipped",
        }
    }

    /// The 1-based line at fault, when one is known.
    pub fn line(&self) -> Option<u32> {
        match self {
            DetectorError::Syntax { line, .. }
            | DetectorError::Forbidden { line, .. }
            | DetectorError::Runtime { line, .. } => *line,
            _ => None,
        }
    }

    /// Whether the failure ends the detector's batch (it is not run on further traces).
    pub fn is_fatal(&self) -> bool {
        matches!(
            self,
            DetectorError::Timeout { .. }
                | DetectorError::Memory { .. }
                | DetectorError::Crashed { .. }
                | DetectorError::Syntax { .. }
                | DetectorError::Forbidden { .. }
                | DetectorError::NoFindPattern { .. }
        )
    }
}

fn at(f: &mut fmt::Formatter<'_>, line: Option<u32>, column: Option<u32>) -> fmt::Result {
    match (line, column) {
        (Some(l), Some(c)) => write!(f, " (line {l}, column {c})"),
        (Some(l), None) => write!(f, " (line {l})"),
        _ => Ok(()),
    }
}

impl fmt::Display for DetectorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DetectorError::Syntax {
                message,
                line,
                column,
            } => {
                write!(f, "syntax error: {message}")?;
                at(f, *line, *column)
            }
            DetectorError::Forbidden {
                message,
                line,
                column,
            } => {
                write!(f, "forbidden: {message}")?;
                at(f, *line, *column)
            }
            DetectorError::NoFindPattern { message } => write!(f, "{message}"),
            DetectorError::Runtime { message, line, .. } => {
                write!(f, "runtime error: {message}")?;
                at(f, *line, None)
            }
            DetectorError::Timeout { seconds } => {
                write!(f, "timeout: the call ran longer than {seconds} s")
            }
            DetectorError::Memory { limit_bytes } => write!(
                f,
                "memory: the call needed more than the {} MiB limit",
                limit_bytes >> 20
            ),
            DetectorError::InvalidOutput { path, message } => {
                write!(f, "invalid output at {path}: {message}")
            }
            DetectorError::Crashed { message } => write!(f, "worker crashed: {message}"),
            DetectorError::Skipped { message } => {
                write!(f, "not run after an earlier failure: {message}")
            }
        }
    }
}

/// The outcome of one detector on one trace (or of compiling it).
#[derive(Clone, Debug, PartialEq)]
pub enum CandidateStatus {
    /// It ran and its output is valid.
    Ok,
    /// It failed; the error says how.
    Failed(DetectorError),
}

impl CandidateStatus {
    /// `ok` or the error's category.
    pub fn as_str(&self) -> &'static str {
        match self {
            CandidateStatus::Ok => "ok",
            CandidateStatus::Failed(e) => e.category(),
        }
    }

    /// The error, if it failed.
    pub fn error(&self) -> Option<&DetectorError> {
        match self {
            CandidateStatus::Ok => None,
            CandidateStatus::Failed(e) => Some(e),
        }
    }
}

/// The runtime itself failed (not one detector): no Python, a worker that cannot start, a broken pipe
/// outside any call.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DetectError {
    /// No usable Python interpreter.
    #[error("no Python 3 interpreter found ({tried}): {message}")]
    NoPython {
        /// What was tried.
        tried: String,
        /// Why it failed.
        message: String,
    },
    /// A worker could not be started or did not say it was ready.
    #[error("detector worker failed to start: {message}")]
    Spawn {
        /// What happened, with the end of the worker's standard error.
        message: String,
    },
    /// The sandbox lacks a layer the limits require.
    #[error("sandbox layer {layer} is required but not available on this system")]
    LayerUnavailable {
        /// The layer (`seccomp`, `landlock`).
        layer: &'static str,
    },
    /// The worker broke the protocol (an annotrace bug).
    #[error("internal error, please report it: {0}")]
    Internal(String),
}
