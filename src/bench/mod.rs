//! The physics-reasoning benchmark: DeepPHY's agent loop over PHYRE, I-PHYRE and billiards tasks, with
//! the paper's feedback after a failed attempt (`docs/benchmark.md`).
//!
//! Per task an agent gets up to N attempts (10 by default, as the paper); after a failed attempt it gets
//! feedback and tries again; the loop stops at the first success. Answers are text in DeepPHY's formats
//! ([`action`]), parsed strictly; an invalid answer (unparsable, out of range, an occluding PHYRE ball)
//! uses up an attempt and is recorded with its reason.
//!
//! **Owns:** the answer formats and their parsing ([`action`]), the choice of tasks and applying answers
//! through the environments ([`task`]), the images and feedback an agent sees ([`feedback`]), the
//! agents and their prompts (`prompts/bench/`, [`agent`]), the attempt loop ([`run`]) and the
//! `benchmark` table ([`table`]). **Does not:** simulate physics (`envs`), run detectors in-process (the
//! `detect::WorkerPool` does), speak HTTP (`llm`), or touch the run folder (the `benchmark` stage does).

pub mod action;
pub mod agent;
pub mod feedback;
pub mod run;
pub mod table;
pub mod task;

pub use action::{Answer, Format, Invalid, parse};
pub use agent::{Agent, AgentKind, LlmAgent, RandomAgent, SearchAgent};
pub use feedback::FeedbackMode;
pub use run::{Annotator, Played, Row, Settings, play_task};
pub use task::{PoolAction, Simulators, TaskChoice, TaskScene, choose_tasks};

/// Why a benchmark could not go on (an invalid answer is not an error: it is a row).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BenchError {
    /// A simulator or renderer failed.
    #[error(transparent)]
    Env(#[from] crate::envs::EnvError),
    /// The model could not be asked (endpoint, budget, replay miss, template).
    #[error(transparent)]
    Llm(#[from] crate::llm::LlmError),
    /// A task id that does not exist.
    #[error("{0}")]
    UnknownTask(String),
    /// An annotrace bug.
    #[error("internal error, please report it: {0}")]
    Internal(String),
}
