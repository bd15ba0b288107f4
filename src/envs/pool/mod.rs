//! Billiards: an event-based pool simulator that re-implements pooltool 0.6.0's default physics.
//!
//! **Owns:** the physics (closed-form motion, event detection, resolution models, the event loop in
//! `simulate.rs`, following `docs/envs/pool.md` §P1–§P10 section by section), table / ball /
//! cue parameters as data ([`PoolConfig`], default `data/tables/pooltool_7ft.json`), scenes ([`Scene`]:
//! seeded 9-ball racks or explicit JSON), shots ([`Shot`] with validation, [`aim`] helpers, the
//! [`deepphy`] action adapter), the conversion of a [`Simulation`] into an annotrace
//! [`Trace`](crate::trace::Trace) on a fixed `dt` ([`to_trace`]), the success rule and outcome, PNG
//! rendering ([`render`]), and comparison with pooltool reference traces ([`reference`](mod@reference)).
//! **Does not:** write Parquet or run stages (`pipeline/stages/simulate.rs` does), read argv, or print.
//!
//! **Entry point:** [`PoolEnv`] (the [`Environment`](super::Environment) implementation), or the
//! engine directly:
//!
//! ```
//! use annotrace::envs::pool::{simulate, PoolConfig, Scene, Shot, SimOptions};
//! let config = PoolConfig::default_7ft();
//! let scene = Scene::nine_ball(&config, 7);
//! let system = scene.system(&config).unwrap();
//! let shot = Shot { v0: 3.0, phi: 95.0, theta: 2.0, a: 0.1, b: 0.2 }; // m/s, degrees, ×R
//! let sim = simulate(&system, &shot, &SimOptions::default()).unwrap();
//! assert_eq!(sim.events[0].kind.name(), "stick_ball");
//! ```

pub mod aim;
mod cache;
mod config;
pub mod deepphy;
mod detect;
mod env;
mod error;
mod events;
mod evolve;
mod params;
pub mod rack;
pub mod reference;
pub mod render;
mod resolve;
mod sample;
mod scene;
mod shot;
mod simulate;
mod state;
mod system;
mod table;
pub mod to_trace;
mod vec3;

pub use config::PoolConfig;
pub use env::PoolEnv;
pub use error::{PoolError, Result};
pub use events::{Agent, Event, EventKind};
pub use params::{BallParams, CueSpecs, DEFAULT_TABLE_JSON, ModelParams};
pub use sample::{Sample, resample, sample_times};
pub use scene::{Goal, Scene, SceneBall};
pub use shot::Shot;
pub use simulate::{SimOptions, Simulation, Status, simulate, state_at};
pub use state::{Ball, BallState, MotionState};
pub use system::System;
pub use table::{CircularCushion, CushionDirection, LinearCushion, Pocket, Table};
pub use to_trace::{TraceOptions, dataset_trace, outcome, trace_columns, trace_of};
pub use vec3::V3;

/// What code outside `envs/` needs to know about this environment: the long side of pooltool's default 7-ft table (1.9812 m); positions are table metres.
pub const FACTS: super::EnvFacts = super::EnvFacts {
    env: crate::trace::Env::Pooltool,
    scene_scale: 1.9812,
    nearby_scale: 1.0,
    units: "table metres (the table is about 0.99 m wide and 1.98 m long); threshold 0.1 is 10 cm",
};
