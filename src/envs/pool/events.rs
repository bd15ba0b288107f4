//! Event kinds, agents and the tie-break tiers (docs/envs/pool.md §P5, §P6;
//! pooltool `events/datatypes.py`, `simulate.py::get_event_priority`).

use serde::{Deserialize, Serialize};

use super::state::BallState;

/// Event types with pooltool's string names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum EventKind {
    /// Cue stick strikes the cue ball
    StickBall,
    /// Two balls collide
    BallBall,
    /// A ball hits a straight cushion segment
    BallLinearCushion,
    /// A ball hits a circular jaw (knuckle)
    BallCircularCushion,
    /// A ball drops into a pocket
    BallPocket,
    /// Sliding → rolling
    SlidingRolling,
    /// Rolling → spinning (in place)
    RollingSpinning,
    /// Rolling → stationary
    RollingStationary,
    /// Spinning → stationary
    SpinningStationary,
}

impl EventKind {
    /// Every kind, in pooltool's enum order.
    pub const ALL: [EventKind; 9] = [
        EventKind::StickBall,
        EventKind::BallBall,
        EventKind::BallLinearCushion,
        EventKind::BallCircularCushion,
        EventKind::BallPocket,
        EventKind::SlidingRolling,
        EventKind::RollingSpinning,
        EventKind::RollingStationary,
        EventKind::SpinningStationary,
    ];

    /// pooltool's `EventType` string value.
    pub fn name(self) -> &'static str {
        match self {
            EventKind::StickBall => "stick_ball",
            EventKind::BallBall => "ball_ball",
            EventKind::BallLinearCushion => "ball_linear_cushion",
            EventKind::BallCircularCushion => "ball_circular_cushion",
            EventKind::BallPocket => "ball_pocket",
            EventKind::SlidingRolling => "sliding_rolling",
            EventKind::RollingSpinning => "rolling_spinning",
            EventKind::RollingStationary => "rolling_stationary",
            EventKind::SpinningStationary => "spinning_stationary",
        }
    }

    /// The kind with pooltool's name `s`.
    pub fn from_name(s: &str) -> Option<EventKind> {
        EventKind::ALL.iter().copied().find(|k| k.name() == s)
    }

    /// A motion-state transition (one ball agent).
    pub fn is_transition(self) -> bool {
        matches!(
            self,
            EventKind::SlidingRolling
                | EventKind::RollingSpinning
                | EventKind::RollingStationary
                | EventKind::SpinningStationary
        )
    }

    /// A ball–ball or ball–cushion collision.
    pub fn is_collision(self) -> bool {
        matches!(
            self,
            EventKind::BallBall | EventKind::BallLinearCushion | EventKind::BallCircularCushion
        )
    }

    /// Tie-break tier for exactly simultaneous candidates (lower wins): stick 1,
    /// transitions and pocket 2, ball–ball and cushions 3.
    pub fn tier(self) -> u8 {
        match self {
            EventKind::StickBall => 1,
            EventKind::BallPocket => 2,
            k if k.is_transition() => 2,
            _ => 3,
        }
    }
}

impl std::fmt::Display for EventKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// An event participant, by index into the system's balls / the table's components.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Agent {
    /// the cue stick (pooltool id "cue_stick")
    Cue,
    /// A ball, by index into the system's balls
    Ball(usize),
    /// A linear cushion, by index into `Table::linear`
    LinearCushion(usize),
    /// A jaw, by index into `Table::circular`
    CircularCushion(usize),
    /// A pocket, by index into `Table::pockets`
    Pocket(usize),
}

/// One resolved event. `agents` is pooltool's `ids` order; `balls` holds each ball
/// agent's state before and after resolution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    /// The event kind
    pub kind: EventKind,
    /// Absolute time (s)
    pub time: f64,
    /// The agents in pooltool's `ids` order (`n_agents` of them are meaningful)
    pub agents: [Agent; 2],
    /// number of meaningful entries in `agents` (1 for transitions)
    pub n_agents: u8,
    /// (ball index, before, after)
    pub balls: Vec<(usize, BallState, BallState)>,
}

impl Event {
    /// The meaningful agents.
    pub fn agents(&self) -> &[Agent] {
        &self.agents[..self.n_agents as usize]
    }
    /// Indices of the balls involved.
    pub fn ball_indices(&self) -> impl Iterator<Item = usize> + '_ {
        self.agents().iter().filter_map(|a| {
            if let Agent::Ball(i) = a {
                Some(*i)
            } else {
                None
            }
        })
    }
    /// Whether ball `i` takes part.
    pub fn involves_ball(&self, i: usize) -> bool {
        self.ball_indices().any(|b| b == i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Names and tiers from docs/envs/pool.md §P5.
    #[test]
    fn names_and_tiers() {
        for k in EventKind::ALL {
            assert_eq!(EventKind::from_name(k.name()), Some(k));
        }
        assert_eq!(EventKind::StickBall.tier(), 1);
        assert_eq!(EventKind::BallPocket.tier(), 2);
        assert_eq!(EventKind::SlidingRolling.tier(), 2);
        assert_eq!(EventKind::BallBall.tier(), 3);
        assert_eq!(EventKind::BallCircularCushion.tier(), 3);
    }
}
