//! Ball kinematic state: position/velocity/angular velocity (`rvw`) plus the motion state
//! (docs/envs/pool.md §P1, §P3).

use serde::{Deserialize, Serialize};

use super::params::BallParams;
use super::vec3::{self, V3};

/// pooltool's motion-state integers: 0 stationary, 1 spinning, 2 sliding, 3 rolling, 4 pocketed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[repr(u8)]
pub enum MotionState {
    /// At rest
    Stationary = 0,
    /// Spinning in place about z
    Spinning = 1,
    /// Sliding on the cloth
    Sliding = 2,
    /// Rolling without slip
    Rolling = 3,
    /// In a pocket
    Pocketed = 4,
}

impl MotionState {
    /// The state with pooltool's integer code `s`.
    pub fn from_int(s: i64) -> Option<MotionState> {
        Some(match s {
            0 => MotionState::Stationary,
            1 => MotionState::Spinning,
            2 => MotionState::Sliding,
            3 => MotionState::Rolling,
            4 => MotionState::Pocketed,
            _ => return None,
        })
    }
    /// pooltool's integer code.
    pub fn as_int(self) -> u8 {
        self as u8
    }
    /// The state's name (`stationary`, `spinning`, `sliding`, `rolling`, `pocketed`).
    pub fn name(self) -> &'static str {
        match self {
            MotionState::Stationary => "stationary",
            MotionState::Spinning => "spinning",
            MotionState::Sliding => "sliding",
            MotionState::Rolling => "rolling",
            MotionState::Pocketed => "pocketed",
        }
    }
    /// {stationary, spinning, pocketed}: the centre does not move.
    pub fn is_nontranslating(self) -> bool {
        matches!(
            self,
            MotionState::Stationary | MotionState::Spinning | MotionState::Pocketed
        )
    }
    /// {spinning, sliding, rolling}
    pub fn is_energetic(self) -> bool {
        matches!(
            self,
            MotionState::Spinning | MotionState::Sliding | MotionState::Rolling
        )
    }
    /// Whether the ball is still on the table (not pocketed).
    pub fn is_on_table(self) -> bool {
        self != MotionState::Pocketed
    }
}

/// A ball's state at time `t`: rows r, v, ω of pooltool's `rvw` and the motion state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BallState {
    /// Centre position (m)
    pub r: V3,
    /// Centre velocity (m/s)
    pub v: V3,
    /// Angular velocity (rad/s)
    pub w: V3,
    /// Motion state
    pub s: MotionState,
    /// Time of the state (s)
    pub t: f64,
}

impl BallState {
    /// A ball at rest at `(x, y)` on the cloth (centre at z = R).
    pub fn at_rest(x: f64, y: f64, radius: f64) -> BallState {
        BallState {
            r: [x, y, radius],
            v: [0.0; 3],
            w: [0.0; 3],
            s: MotionState::Stationary,
            t: 0.0,
        }
    }

    /// Contact-point (slip) velocity with the cloth: u = v + ω × (−R ẑ).
    pub fn rel_velocity(&self, radius: f64) -> V3 {
        vec3::add(self.v, vec3::cross(self.w, [0.0, 0.0, -radius]))
    }

    /// Linear + rotational kinetic energy (pooltool `get_ball_energy`).
    pub fn energy(&self, p: &BallParams) -> f64 {
        let nv = vec3::norm(self.v);
        let nw = vec3::norm(self.w);
        let lke = p.m * (nv * nv) / 2.0;
        let rke = (2.0 / 5.0 * p.m * (p.r * p.r)) * (nw * nw) / 2.0;
        lke + rke
    }
}

/// A ball: string id (pooltool style: "cue", "1".."9"), parameters and current state.
#[derive(Debug, Clone)]
pub struct Ball {
    /// Ball id
    pub id: String,
    /// Physical parameters
    pub params: BallParams,
    /// Initial state
    pub state: BallState,
}
