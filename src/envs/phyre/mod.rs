//! PHYRE (Bakhtin et al., NeurIPS 2019), ball tier: 2,500 tasks in 25 templates where one red ball, placed
//! by the agent, must make the green body touch the blue or purple one for 3 s. Re-implemented after
//! PHYRE 0.2.2 on Box2D (box2d-rs, PHYRE's own engine; the default) or rapier2d, following
//! `docs/envs/phyre.md` §R1–§R7.
//!
//! **Owns:** the task set ([`TaskSet`], lazily indexed from the committed `data/tasks/phyre_ball_tasks.jsonl.zst`),
//! the physics constants ([`PhysicsParams`]), actions and their validity ([`BallAction`], [`Placement`],
//! DeepPHY's [`deepphy_action`]), the physics world ([`World`] over the Box2D and rapier2d backends), the episode loop with PHYRE's success rule
//! ([`episode::run`]), traces ([`trace_of`]), the evaluation folds ([`folds`]), seeded random actions
//! ([`random_valid_action`]), pictures ([`render`]) and outcome agreement with the original on balanced
//! outcome sets made offline ([`reference`](mod@reference)).
//! **Does not:** write Parquet or run stages (`pipeline/stages/simulate_phyre.rs`), read argv, or call
//! Python. Engine handles never leave this module: the boundary speaks in PHYRE body indices.
//!
//! **Entry point:** [`PhyreEnv`] (the [`Environment`](super::Environment) implementation), or an episode:
//!
//! ```
//! use annotrace::envs::phyre::{BallAction, PhysicsParams, RecordOptions, Status, TaskSet, episode};
//! let tasks = TaskSet::default_tasks().unwrap();
//! let task = tasks.get("00000:000").unwrap();
//! // A ball dropped onto the green ball: valid, simulated for up to 1000 steps.
//! let action = BallAction { x: 0.35, y: 0.6, r: 0.2 };
//! let result = episode::run(&task, &action, &PhysicsParams::default(), &RecordOptions::default()).unwrap();
//! assert_ne!(result.status, Status::InvalidInput);
//! ```

pub mod action;
mod box2d_compat;
mod box2d_world;
mod env;
pub mod episode;
mod error;
pub mod folds;
mod params;
mod rapier_world;
pub mod reference;
pub mod render;
mod sample;
mod task;
mod tasks;
pub mod to_trace;
mod world;

pub use action::{BallAction, MAX_RADIUS, MIN_RADIUS, Placement, UserBall, deepphy_action};
pub use env::{PhyreEnv, dataset_tasks};
pub use episode::{DEFAULT_STRIDE, EpisodeEvent, EpisodeResult, Frame, RecordOptions, Status};
pub use error::{PhyreError, Result};
pub use folds::{EvalSetup, Fold, fold};
pub use params::{Engine, PIXELS_PER_METRE, PhysicsParams};
pub use sample::{MAX_DRAWS, action_rng, random_valid_action};
pub use task::{Body, Color, Shape, Task};
pub use tasks::{DEFAULT_TASKS_FINGERPRINT, DEFAULT_TASKS_TEXT_SHA256, DEFAULT_TASKS_ZST, TaskSet};
pub use to_trace::{trace_columns, trace_of};
pub use world::{BodyState, ContactChange, World};

/// What code outside `envs/` needs to know about this environment: the PHYRE's 256-unit square scene.
pub const FACTS: super::EnvFacts = super::EnvFacts {
    env: crate::trace::Env::Phyre,
    scene_scale: 256.0,
    nearby_scale: 256.0,
    units: "scene pixels (256 × 256, y up); the radius is threshold_strength × 256",
};
