//! Error type of the I-PHYRE environment: every fallible entry point (loading games, validating
//! clicks, building a world) returns [`IphyreError`]; nothing here panics on bad input.

use thiserror::Error;

/// Why an I-PHYRE operation could not run. Messages name the value or field at fault.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum IphyreError {
    /// The games document is malformed: a missing field, a bad index, a non-finite coordinate.
    #[error("invalid I-PHYRE game data: {field}: {message}")]
    InvalidGame {
        /// The JSON path at fault (`games[3].objects[2].x1`, …).
        field: String,
        /// What is wrong with it.
        message: String,
    },
    /// A game name that the loaded games do not have.
    #[error("unknown I-PHYRE game {name:?} (known: {known})")]
    UnknownGame {
        /// The name asked for.
        name: String,
        /// The first few known names, comma-separated.
        known: String,
    },
    /// A click is unusable: not finite, off the 600×600 screen, or after the episode ends.
    #[error("invalid click actions[{index}]: {message}")]
    InvalidClick {
        /// Position of the click in the action list.
        index: usize,
        /// What is wrong with it.
        message: String,
    },
    /// A discrete action names an eliminable block the game does not have.
    #[error("invalid discrete action: block {block} (the game has {count} eliminable blocks)")]
    InvalidBlock {
        /// The eliminable-block number asked for (0-based, in object order).
        block: usize,
        /// How many eliminable blocks the game has.
        count: usize,
    },
    /// Physics parameters are out of range (a non-positive fps, a negative radius, …).
    #[error("invalid I-PHYRE physics parameter {field}: {message}")]
    InvalidParams {
        /// The parameter at fault.
        field: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// An outcome set (pairs with the original's outcome, `reference.rs`) is malformed.
    #[error("invalid I-PHYRE outcome set: {field}: {message}")]
    InvalidReference {
        /// Where (`line 17 results[1]`, `gzip`, …).
        field: String,
        /// What is wrong with it.
        message: String,
    },
    /// A JSON document could not be parsed.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
}

/// `Result` with [`IphyreError`].
pub type Result<T> = std::result::Result<T, IphyreError>;
