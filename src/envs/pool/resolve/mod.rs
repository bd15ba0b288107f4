//! Event resolution models: pooltool 0.6.0's default `Resolver` (VERSION 9;
//! docs/envs/pool.md §P8): frictional-inelastic ball–ball with the Alciatore
//! friction curve, Stronge compliant cushions, canonical pocket, instantaneous-point cue
//! strike with squirt, canonical transitions.

pub mod ball_ball;
pub mod ball_cushion;
pub mod ball_pocket;
pub mod stick_ball;
pub mod toms748;
pub mod transition;

/// Gap inserted at every contact by the `make_kiss` placement (pooltool `MIN_DIST`).
pub const MIN_DIST: f64 = 1e-6;
