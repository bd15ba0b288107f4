//! Error type of the PHYRE environment: loading tasks, checking actions and parameters. Every fallible entry
//! point returns [`PhyreError`]; nothing here panics on bad input.

use thiserror::Error;

/// Why a PHYRE operation could not run. Messages name the value or field at fault.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum PhyreError {
    /// The task file is malformed: not gzip, not JSON, a missing field, a bad body index.
    #[error("invalid PHYRE task data: {field}: {message}")]
    InvalidTask {
        /// Where (`line 17`, `00003:002 bodies[4].shapes[0]`, …).
        field: String,
        /// What is wrong with it.
        message: String,
    },
    /// A task id that the task set does not have.
    #[error(
        "unknown PHYRE task {id:?} (ball-tier task ids look like \"00004:063\": template 00000-00024, then a variant number)"
    )]
    UnknownTask {
        /// The id asked for.
        id: String,
    },
    /// An action that is not a finite point of the action space.
    #[error("invalid PHYRE action: {field}: {message}")]
    InvalidAction {
        /// The component at fault (`x`, `y`, `r`, `cell`, `radius`, `action`).
        field: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// A physics or recording parameter is out of range.
    #[error("invalid PHYRE parameter {field}: {message}")]
    InvalidParams {
        /// The parameter at fault.
        field: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// An evaluation setup or fold that PHYRE does not define.
    #[error(
        "unknown PHYRE evaluation fold {setup:?} seed {seed} (setups: ball_within_template, ball_cross_template; seeds 0-9)"
    )]
    UnknownFold {
        /// The setup asked for.
        setup: String,
        /// The fold seed asked for.
        seed: u64,
    },
    /// An outcome set (pairs with the original's status, `reference.rs`) is malformed.
    #[error("invalid PHYRE outcome set: {field}: {message}")]
    InvalidReference {
        /// Where (`line 17 status`, `gzip`, …).
        field: String,
        /// What is wrong with it.
        message: String,
    },
}

/// `Result` with [`PhyreError`].
pub type Result<T> = std::result::Result<T, PhyreError>;
