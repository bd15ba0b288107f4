//! Error type of the pool engine: every fallible entry point (loading data, validating a
//! shot or a scene, simulating) returns [`PoolError`]; the engine never panics on bad input.

use thiserror::Error;

/// Why a pool operation could not run. Messages name the value or field at fault.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum PoolError {
    /// A shot parameter is out of range or not finite.
    #[error("invalid shot: {0}")]
    InvalidShot(String),
    /// The system (balls, cue, table) cannot be simulated.
    #[error("invalid system: {0}")]
    InvalidSystem(String),
    /// A scene is unusable: a ball off the table, overlapping balls, a bad field.
    #[error("invalid scene: {field}: {message}")]
    InvalidScene {
        /// The JSON field at fault (`balls[3].x`, `goal.pot`, …).
        field: String,
        /// What is wrong with it.
        message: String,
    },
    /// Table, ball or cue parameter data is malformed.
    #[error("invalid table/parameter data: {0}")]
    Data(String),
    /// A JSON document could not be parsed.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    /// A file could not be read.
    #[error("io: {0}")]
    Io(#[from] std::io::Error),
    /// A ball id that the system does not have.
    #[error("unknown ball id {0:?}")]
    UnknownBall(String),
}

/// `Result` with [`PoolError`].
pub type Result<T> = std::result::Result<T, PoolError>;
