//! Optimising actions for reward programs: a seeded simulated annealer over a continuous action box
//! ([`anneal`]) and the billiards experiment of the paper's section 5 ([`billiards`]): goals × scenes ×
//! seeds × reward types (dense reward program vs sparse binary verification), best-so-far recorded
//! at checkpoints, success judged by each goal's hand-written verification rule; the plot of success
//! against budget ([`plot`]).
//!
//! **Owns:** the annealer, the lockstep batch of chains and its timing split, the plot.
//! **Does not:** define rewards (`reward/`), run detectors itself (it calls `detect::WorkerPool`
//! through `reward::annotate`), write tables (`pipeline/stages/optimise.rs`).

pub mod anneal;
pub mod billiards;
pub mod plot;
pub mod scenes;

pub use anneal::{Annealer, Dim, Schedule};
pub use billiards::{
    Chain, CheckpointRow, GoalTask, RewardKind, Settings, ShotBounds, Timings, run_chains,
};
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
