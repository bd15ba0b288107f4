//! Ball–pocket resolution (docs/envs/pool.md §P8 (d); pooltool
//! `physics/resolve/ball_pocket/__init__.py::CanonicalBallPocket`): the ball is moved to
//! (pocket x, pocket y, −depth) with v = ω = 0 and marked pocketed.

use super::super::state::{BallState, MotionState};
use super::super::table::Pocket;

pub fn resolve(state: &mut BallState, pocket: &Pocket) {
    state.r = [pocket.center[0], pocket.center[1], -pocket.depth];
    state.v = [0.0; 3];
    state.w = [0.0; 3];
    state.s = MotionState::Pocketed;
}

#[cfg(test)]
mod tests {
    use super::super::super::table::Table;
    use super::*;

    #[test]
    fn pocketed_ball_sits_in_pocket() {
        let t = Table::default_7ft();
        let pk = &t.pockets[0];
        let mut s = BallState {
            r: [0.0, 0.0, 0.028575],
            v: [1.0, 1.0, 0.0],
            w: [1.0, 2.0, 3.0],
            s: MotionState::Sliding,
            t: 0.0,
        };
        resolve(&mut s, pk);
        assert_eq!(s.s, MotionState::Pocketed);
        assert_eq!(s.r, [pk.center[0], pk.center[1], -pk.depth]);
        assert_eq!(s.v, [0.0; 3]);
    }
}
