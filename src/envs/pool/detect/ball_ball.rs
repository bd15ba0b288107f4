//! Ball–ball collision time (docs/envs/pool.md §P7 "Ball–ball (quartic)";
//! pooltool `solve.py::ball_ball_collision_coeffs` and `simulate.py::get_next_ball_ball_collision`).
//!
//! With A = a₂−a₁, B = b₂−b₁, C = c₂−c₁, contact ‖C + Bt + At²‖ = 2R gives the quartic
//! `a=A·A, b=2A·B, c=B·B+2A·C, d=2B·C, e=C·C−4R²` (both balls take ball 1's radius).

use super::super::params::BallParams;
use super::super::state::BallState;
use super::super::vec3;
use super::roots;
use super::{REACH_SLACK, Trajectory};

/// Quartic coefficients for the pair (pooltool's exact expression order).
pub fn coefficients(t1: &Trajectory, t2: &Trajectory, r: f64) -> [f64; 5] {
    let (ax, ay) = (t2.ax - t1.ax, t2.ay - t1.ay);
    let (bx, by) = (t2.bx - t1.bx, t2.by - t1.by);
    let (cx, cy) = (t2.cx - t1.cx, t2.cy - t1.cy);
    [
        ax * ax + ay * ay,
        2.0 * ax * bx + 2.0 * ay * by,
        bx * bx + 2.0 * ax * cx + 2.0 * ay * cy + by * by,
        2.0 * bx * cx + 2.0 * by * cy,
        cx * cx + cy * cy - 4.0 * r * r,
    ]
}

/// Time until the pair collides (relative to now), ∞ if never, 0 if already overlapping.
/// Pruning as in pooltool: ∞ if either ball is pocketed or both are non-translating.
/// `horizon`: time until the earliest pending transition of either ball (see `detect`).
pub fn collision_time(
    s1: &BallState,
    p1: &BallParams,
    t1: &Trajectory,
    s2: &BallState,
    p2: &BallParams,
    t2: &Trajectory,
    horizon: f64,
) -> f64 {
    if !s1.s.is_on_table() || !s2.s.is_on_table() {
        return f64::INFINITY;
    }
    if s1.s.is_nontranslating() && s2.s.is_nontranslating() {
        return f64::INFINITY;
    }
    let d = vec3::norm(vec3::sub(s1.r, s2.r));
    if d < p1.r + p2.r {
        return 0.0;
    }
    if horizon.is_finite() {
        let reach = t1.reach(horizon) + t2.reach(horizon);
        if d - 2.0 * p1.r > reach * (1.0 + REACH_SLACK) + 1e-9 {
            return f64::INFINITY;
        }
    }
    let c = coefficients(t1, t2, p1.r);
    roots::smallest_positive_real(roots::quartic(c[0], c[1], c[2], c[3], c[4]).as_slice())
}

#[cfg(test)]
mod tests {
    use super::super::super::state::MotionState;
    use super::*;

    /// Head-on: cue rolling at 1 m/s towards a resting ball 0.5 m away (centre to centre).
    /// Contact when the cue has covered 0.5 − 2R: x(t) = v t − ½ μ_r g t². Tol 1e-12 s.
    #[test]
    fn head_on_time() {
        let p = BallParams::pool_default();
        let s1 = BallState {
            r: [0.2, 0.5, p.r],
            v: [1.0, 0.0, 0.0],
            w: [0.0, 1.0 / p.r, 0.0],
            s: MotionState::Rolling,
            t: 0.0,
        };
        let s2 = BallState::at_rest(0.7, 0.5, p.r);
        let (t1, t2) = (Trajectory::of(&s1, &p), Trajectory::of(&s2, &p));
        let t = collision_time(&s1, &p, &t1, &s2, &p, &t2, f64::INFINITY);
        let dist = 0.5 - 2.0 * p.r;
        let k = 0.5 * p.u_r * p.g;
        let expect = (1.0 - (1.0 - 4.0 * k * dist).sqrt()) / (2.0 * k);
        assert!((t - expect).abs() < 1e-12, "{t} vs {expect}");
        // with a horizon shorter than the contact time the pair is skipped
        assert_eq!(
            collision_time(&s1, &p, &t1, &s2, &p, &t2, 0.1),
            f64::INFINITY
        );
        // a horizon past it finds it
        assert!((collision_time(&s1, &p, &t1, &s2, &p, &t2, 1.0) - expect).abs() < 1e-12);
    }
}
