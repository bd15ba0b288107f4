//! I-PHYRE (interactive physical reasoning, Li et al. ICLR 2024): 40 games of capsule blocks and balls on
//! a 600×600 screen, where an agent removes eliminable blocks at chosen times so that every ball falls out
//! of the bottom. Re-implemented after iphyre 0.2.3 (pymunk 6.11.1), following `docs/envs/iphyre.md` §R1–§R9,
//! on annotrace's Chipmunk-faithful step by default (the `chipmunk-step` crate: the original's
//! trajectories bit for bit), or on rapier2d (`engine = "rapier"`) or box2d-rs set to Chipmunk's semantics
//! (`engine = "box2d"`).
//!
//! **Owns:** the games as data ([`Games`], default `data/games/iphyre_games.json`), the physics constants
//! ([`PhysicsParams`], [`Engine`]), the world in either engine ([`World`]: bodies, capsules, rods, springs,
//! contact events),
//! clicks and their quirks ([`Click`], [`ClickSchedule`], the discrete adapter [`click_block`], seeded
//! random click sets [`random_clicks`]), the episode loop ([`Episode`] in `step.rs`), success and
//! reward ([`success`]), the conversion into an annotrace [`Trace`](crate::trace::Trace)
//! ([`trace_of`]), pictures ([`render`]) and outcome agreement with the original on a reference set made
//! offline ([`reference`](mod@reference)).
//! **Does not:** write Parquet or run stages (`pipeline/stages/simulate_iphyre.rs`), read argv, print, or
//! run Python. rapier handles never leave this module: the boundary speaks in the games' object indices.
//!
//! **Entry point:** [`IphyreEnv`] (the [`Environment`](super::Environment) implementation), or an episode
//! directly:
//!
//! ```
//! use annotrace::envs::iphyre::{Games, PhysicsParams, click_block, play};
//! let games = Games::default_games().unwrap();
//! let support = games.get("support").unwrap();
//! // Remove both eliminable blocks at 0.5 s (one per step); the ball falls out of the screen.
//! let clicks = [click_block(support, 0, 0.5).unwrap(), click_block(support, 1, 0.5).unwrap()];
//! let result = play(support, &clicks, &PhysicsParams::with_fps(10.0)).unwrap();
//! assert!(result.success);
//! assert_eq!(result.eliminations, 2);
//! ```

pub mod action;
mod box2d_world;
mod chipmunk_world;
mod env;
mod error;
mod game;
mod params;
mod rapier_world;
pub mod reference;
pub mod render;
mod sample;
mod step;
pub mod success;
pub mod to_trace;
mod world;

pub use action::{Click, ClickSchedule, Due, SCREEN, click_block, hits_block, validate_clicks};
pub use env::IphyreEnv;
pub use error::{IphyreError, Result};
pub use game::{DEFAULT_GAMES_JSON, FOLDS, Game, GameObject, Games, ObjectKind};
pub use params::{Engine, PhysicsParams};
pub use sample::{MAX_TENTHS, SKIP_PROBABILITY, clicks_rng, random_clicks};
pub use step::{Episode, EpisodeEvent, EpisodeResult, Frame, play};
pub use to_trace::{trace_columns, trace_of};
pub use world::{ContactChange, ObjectState, World};

/// What code outside `envs/` needs to know about this environment: the I-PHYRE's 600-pixel square screen.
pub const FACTS: super::EnvFacts = super::EnvFacts {
    env: crate::trace::Env::Iphyre,
    scene_scale: 600.0,
    nearby_scale: 600.0,
    units: "screen pixels (600 × 600, y down); the radius is threshold_strength × 600",
};
