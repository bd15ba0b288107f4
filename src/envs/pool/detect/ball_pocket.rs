//! Ball–pocket time (docs/envs/pool.md §P7 "Ball–pocket (quartic)"): the
//! circle quartic with contact radius = the pocket radius, i.e. the event fires when the
//! ball *centre* enters the pocket circle (pooltool `solve.py::ball_pocket_collision_coeffs`).

use super::super::params::BallParams;
use super::super::state::BallState;
use super::super::table::Pocket;
use super::ball_cushion::circle_coefficients;
use super::roots;
use super::{REACH_SLACK, Trajectory};

/// Time until the ball centre enters the pocket circle, ∞ if never.
pub fn pocket_time(
    st: &BallState,
    _p: &BallParams,
    tr: &Trajectory,
    pocket: &Pocket,
    horizon: f64,
) -> f64 {
    if st.s.is_nontranslating() {
        return f64::INFINITY;
    }
    if horizon.is_finite() {
        let d = ((st.r[0] - pocket.center[0]).powi(2) + (st.r[1] - pocket.center[1]).powi(2))
            .sqrt()
            - pocket.radius;
        if d > tr.reach(horizon) * (1.0 + REACH_SLACK) + 1e-9 {
            return f64::INFINITY;
        }
    }
    let c = circle_coefficients(tr, pocket.center[0], pocket.center[1], pocket.radius);
    roots::smallest_positive_real(roots::quartic(c[0], c[1], c[2], c[3], c[4]).as_slice())
}

#[cfg(test)]
mod tests {
    use super::super::super::evolve::evolve_state;
    use super::super::super::state::MotionState;
    use super::super::super::table::Table;
    use super::*;

    /// A ball sliding diagonally into the "lb" corner pocket: the event time is when the
    /// centre is exactly at the pocket radius (checked by evolving to it; tol 1e-9 m).
    #[test]
    fn pocket_when_centre_crosses_circle() {
        let t = Table::default_7ft();
        let p = BallParams::pool_default();
        let pk = t.pockets.iter().find(|q| q.id == "lb").unwrap();
        let st = BallState {
            r: [0.3, 0.3, p.r],
            v: [-1.5, -1.5, 0.0],
            w: [0.0; 3],
            s: MotionState::Sliding,
            t: 0.0,
        };
        let tr = Trajectory::of(&st, &p);
        let time = pocket_time(&st, &p, &tr, pk, f64::INFINITY);
        assert!(time.is_finite() && time > 0.0);
        let at = evolve_state(&st, &p, time);
        let d = ((at.r[0] - pk.center[0]).powi(2) + (at.r[1] - pk.center[1]).powi(2)).sqrt();
        assert!((d - pk.radius).abs() < 1e-9, "d={d}");
    }
}
