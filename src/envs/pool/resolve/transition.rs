//! Transition resolution (docs/envs/pool.md §P3; pooltool
//! `physics/resolve/transition/__init__.py::CanonicalTransition`): set the new motion
//! state; entering spinning zeroes v and ω_xy, entering stationary zeroes v and ω.

use super::super::events::EventKind;
use super::super::state::{BallState, MotionState};

/// Apply a transition event to the ball state.
pub fn resolve(state: &mut BallState, kind: EventKind) {
    let end = match kind {
        EventKind::SlidingRolling => MotionState::Rolling,
        EventKind::RollingSpinning => MotionState::Spinning,
        EventKind::RollingStationary | EventKind::SpinningStationary => MotionState::Stationary,
        _ => return,
    };
    state.s = end;
    if end == MotionState::Spinning {
        state.v = [0.0; 3];
        state.w[0] = 0.0;
        state.w[1] = 0.0;
    }
    if end == MotionState::Stationary {
        state.v = [0.0; 3];
        state.w = [0.0; 3];
    }
}
