//! The errors of summarising and identification.

use crate::envs::EnvError;
use crate::llm::LlmError;

/// Why a summary or an identification could not be made.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SummaryError {
    /// The model call failed (endpoint down, refused, budget, replay miss).
    #[error(transparent)]
    Llm(#[from] LlmError),
    /// A trace's images could not be drawn.
    #[error("trace {trace}: cannot draw its images: {source}")]
    Render {
        /// The trace.
        trace: String,
        /// Why.
        source: EnvError,
    },
    /// The task cannot be posed as asked (too few traces for the options, duplicate trace ids, …).
    #[error("identification: {0}")]
    Setup(String),
}
