//! Optimising actions for reward programs: a seeded simulated annealer over a continuous action box
//! ([`anneal`]), each environment's action as such a box ([`problem`]: billiards shots, PHYRE's red
//! ball, I-PHYRE's removal times), and the experiment of the paper's section 5 ([`chains`]): goals ×
//! scenes × seeds × reward types × budgets (dense reward program vs sparse binary verification), each
//! chain's best sample judged by the goal's hand-written verification rule; the plot of success
//! against budget and the optimised-action figure ([`plot`], [`figure`]).
//!
//! **Owns:** the annealer, the search boxes, the lockstep batch of chains and its timing split, the
//! figures.
//! **Does not:** define rewards (`reward/`), run detectors itself (it calls `detect::WorkerPool`
//! through `reward::annotate`), write tables (`pipeline/stages/optimise.rs`).

pub mod anneal;
pub mod chains;
pub mod figure;
pub mod plot;
pub mod problem;
pub mod scenes;

pub use anneal::{Annealer, Dim, Schedule};
pub use chains::{
    Chain, CheckpointRow, GoalTask, RewardKind, Settings, Timings, invalid_action, run_chains,
};
pub use problem::{IphyreProblem, PhyreProblem, PoolProblem, Problem, ShotBounds, Simulated};
pub use scenes::{Layout, scenes};

/// Why the optimisation experiment could not run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OptimiseError {
    /// The shot bounds are empty or outside the environment's legal ranges.
    #[error("{0}")]
    Bounds(String),
    /// A scene could not be built.
    #[error(transparent)]
    Env(#[from] crate::envs::EnvError),
    /// A scattered scene found no free spot for a ball.
    #[error("scatter scene {index}: no free spot for ball {ball}")]
    Scatter {
        /// The scene's index.
        index: usize,
        /// The ball.
        ball: &'static str,
    },
    /// The caller broke a precondition (an annotrace bug).
    #[error("internal error, please report it: {0}")]
    Internal(&'static str),
}
