//! The simulated system: table, balls (ids, parameters, initial states), cue specs and
//! resolution-model parameters (pooltool `System` minus the cue's shot parameters, which
//! are a separate [`super::shot::Shot`]).

use std::sync::Arc;

use super::error::{PoolError, Result};
use super::params::{CueSpecs, ModelParams};
use super::state::Ball;
use super::table::Table;
use super::vec3;

#[derive(Debug, Clone)]
/// What a shot is played on: table, balls, cue and resolution models (pooltool `System` without the shot).
pub struct System {
    /// Table geometry
    pub table: Arc<Table>,
    /// balls in pooltool dict order (the order matters only for exact-time ties)
    pub balls: Vec<Ball>,
    /// The cue
    pub cue: CueSpecs,
    /// Resolution-model parameters (pooltool 0.6.0 defaults)
    pub models: ModelParams,
    /// id of the ball the cue strikes (pooltool default "cue")
    pub cue_ball_id: String,
}

impl System {
    /// A system with the default models and `"cue"` as the cue ball.
    pub fn new(table: Arc<Table>, balls: Vec<Ball>, cue: CueSpecs) -> System {
        System {
            table,
            balls,
            cue,
            models: ModelParams::default(),
            cue_ball_id: "cue".to_string(),
        }
    }

    /// Index of ball `id`.
    pub fn ball_index(&self, id: &str) -> Option<usize> {
        self.balls.iter().position(|b| b.id == id)
    }

    /// Checks everything `simulate` relies on; returns the cue-ball index.
    pub fn validate(&self) -> Result<usize> {
        if self.balls.is_empty() {
            return Err(PoolError::InvalidSystem("no balls".into()));
        }
        for (i, b) in self.balls.iter().enumerate() {
            b.params.validate()?;
            let s = &b.state;
            if !vec3::is_finite(s.r)
                || !vec3::is_finite(s.v)
                || !vec3::is_finite(s.w)
                || !s.t.is_finite()
            {
                return Err(PoolError::InvalidSystem(format!(
                    "ball {} has a non-finite state",
                    b.id
                )));
            }
            if self.balls[..i].iter().any(|o| o.id == b.id) {
                return Err(PoolError::InvalidSystem(format!(
                    "duplicate ball id {}",
                    b.id
                )));
            }
        }
        if !(self.cue.mass > 0.0 && self.cue.end_mass > 0.0) {
            return Err(PoolError::InvalidSystem("cue masses must be > 0".into()));
        }
        self.ball_index(&self.cue_ball_id)
            .ok_or_else(|| PoolError::UnknownBall(self.cue_ball_id.clone()))
    }
}
