//! Motion-transition detection (docs/envs/pool.md §P3 "Transition events";
//! pooltool `evolution/event_based/cache.py::_next_transition`): sliding → rolling,
//! rolling → spinning/stationary, spinning → stationary, at absolute times.

use super::super::events::EventKind;
use super::super::evolve;
use super::super::params::BallParams;
use super::super::state::{BallState, MotionState};

/// Next transition of a ball whose state was set at absolute time `state.t`:
/// `(absolute time, kind)`, or `None` for stationary/pocketed balls.
pub fn next_transition(state: &BallState, p: &BallParams) -> Option<(f64, EventKind)> {
    let (dt, from, to) = evolve::next_transition(state, p)?;
    let kind = match (from, to) {
        (MotionState::Sliding, _) => EventKind::SlidingRolling,
        (MotionState::Rolling, MotionState::Spinning) => EventKind::RollingSpinning,
        (MotionState::Rolling, _) => EventKind::RollingStationary,
        _ => EventKind::SpinningStationary,
    };
    Some((state.t + dt, kind))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rolling with z-spin that outlasts the roll → rolling_spinning (§P3).
    #[test]
    fn rolling_with_english_goes_to_spinning() {
        let p = BallParams::pool_default();
        let st = BallState {
            r: [0.5, 0.5, p.r],
            v: [0.1, 0.0, 0.0],
            w: [0.0, 0.1 / p.r, 30.0],
            s: MotionState::Rolling,
            t: 1.0,
        };
        let (t, k) = next_transition(&st, &p).unwrap();
        assert_eq!(k, EventKind::RollingSpinning);
        assert!((t - 1.0 - 0.1 / (p.u_r * p.g)).abs() < 1e-12);
        let st2 = BallState {
            w: [0.0, 0.1 / p.r, 0.0],
            ..st
        };
        assert_eq!(
            next_transition(&st2, &p).unwrap().1,
            EventKind::RollingStationary
        );
    }
}
