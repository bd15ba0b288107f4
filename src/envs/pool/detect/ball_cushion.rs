//! Ball–cushion collision times (docs/envs/pool.md §P7):
//! * linear segment: quadratic A t² + B t + C = 0 with A = l·a, B = l·b,
//!   C = l₀ + l·c ± R‖l‖ (+ for SIDE1, − for SIDE2, both for BOTH); a root counts if it is
//!   real, > EPS and the ball centre then projects onto the segment (s ∈ [0, 1]);
//! * circular jaw: quartic ‖r(t) − p‖² = (ρ + R)², halved.
//!
//! Mirrors pooltool `solve.py::ball_linear_cushion_collision_time` and
//! `ball_circular_cushion_collision_coeffs`.

use super::super::evolve::{self, EPS, MotionParams};
use super::super::params::BallParams;
use super::super::state::BallState;
use super::super::table::{CircularCushion, CushionDirection, LinearCushion};
use super::super::vec3;
use super::roots;
use super::{REACH_SLACK, Trajectory};

/// Time until the ball meets the linear cushion segment, ∞ if never.
pub fn linear_time(
    st: &BallState,
    p: &BallParams,
    tr: &Trajectory,
    seg: &LinearCushion,
    horizon: f64,
) -> f64 {
    if st.s.is_nontranslating() {
        return f64::INFINITY;
    }
    if horizon.is_finite() {
        let d = seg.distance_2d(st.r[0], st.r[1]) - p.r;
        if d > tr.reach(horizon) * (1.0 + REACH_SLACK) + 1e-9 {
            return f64::INFINITY;
        }
    }
    let (lx, ly, l0) = (seg.lx, seg.ly, seg.l0);
    let a = lx * tr.ax + ly * tr.ay;
    let b = lx * tr.bx + ly * tr.by;
    let base = l0 + lx * tr.cx + ly * tr.cy;
    let rl = p.r * (lx * lx + ly * ly).sqrt();
    let mut cand = [f64::NAN; 4];
    match seg.direction {
        CushionDirection::Side1 => {
            let (r1, r2) = roots::quadratic_real(a, b, base + rl);
            cand[0] = r1;
            cand[1] = r2;
        }
        CushionDirection::Side2 => {
            let (r1, r2) = roots::quadratic_real(a, b, base - rl);
            cand[0] = r1;
            cand[1] = r2;
        }
        CushionDirection::Both => {
            let (r1, r2) = roots::quadratic_real(a, b, base + rl);
            let (r3, r4) = roots::quadratic_real(a, b, base - rl);
            cand = [r1, r2, r3, r4];
        }
    }
    // pooltool evolves with (u_s, u_sp, u_r) = (μ, 1, μ) for the on-segment test
    let mp = MotionParams {
        r: p.r,
        u_s: tr.mu,
        u_sp: 1.0,
        u_r: tr.mu,
        g: p.g,
    };
    let rvw = [st.r, st.v, st.w];
    let d12 = vec3::sub(seg.p2, seg.p1);
    let dd = vec3::dot(d12, d12);
    let mut min_time = f64::INFINITY;
    for root in cand {
        if root.is_nan() || root <= EPS {
            continue;
        }
        if root >= min_time {
            continue;
        }
        let (rv, _) = evolve::evolve_rvw(st.s, &rvw, &mp, root);
        let s_score = -vec3::dot(vec3::sub(seg.p1, rv[0]), d12) / dd;
        if !(0.0..=1.0).contains(&s_score) {
            continue;
        }
        min_time = root;
    }
    min_time
}

/// Quartic coefficients for a jaw/pocket circle of centre (a, b) and contact radius `rad`.
pub fn circle_coefficients(tr: &Trajectory, a: f64, b: f64, rad: f64) -> [f64; 5] {
    let (ax, ay, bx, by, cx, cy) = (tr.ax, tr.ay, tr.bx, tr.by, tr.cx, tr.cy);
    [
        0.5 * (ax * ax + ay * ay),
        ax * bx + ay * by,
        ax * (cx - a) + ay * (cy - b) + 0.5 * (bx * bx + by * by),
        bx * (cx - a) + by * (cy - b),
        0.5 * (a * a + b * b + cx * cx + cy * cy - rad * rad) - (cx * a + cy * b),
    ]
}

/// Time until the ball meets the circular cushion (jaw), ∞ if never.
pub fn circular_time(
    st: &BallState,
    p: &BallParams,
    tr: &Trajectory,
    jaw: &CircularCushion,
    horizon: f64,
) -> f64 {
    if st.s.is_nontranslating() {
        return f64::INFINITY;
    }
    let rad = jaw.radius + p.r;
    if horizon.is_finite() {
        let d =
            ((st.r[0] - jaw.center[0]).powi(2) + (st.r[1] - jaw.center[1]).powi(2)).sqrt() - rad;
        if d > tr.reach(horizon) * (1.0 + REACH_SLACK) + 1e-9 {
            return f64::INFINITY;
        }
    }
    let c = circle_coefficients(tr, jaw.center[0], jaw.center[1], rad);
    roots::smallest_positive_real(roots::quartic(c[0], c[1], c[2], c[3], c[4]).as_slice())
}

#[cfg(test)]
mod tests {
    use super::super::super::state::MotionState;
    use super::super::super::table::Table;
    use super::*;

    /// A ball rolling straight at the +x rail (cushion "15", x = 0.9906, SIDE1) from
    /// x = 0.5: contact when x + R = 0.9906, x(t) = x0 + v t − ½ μ_r g t². Tol 1e-12 s.
    #[test]
    fn straight_into_side_rail() {
        let t = Table::default_7ft();
        let p = BallParams::pool_default();
        let st = BallState {
            r: [0.5, 0.5, p.r],
            v: [1.0, 0.0, 0.0],
            w: [0.0, 1.0 / p.r, 0.0],
            s: MotionState::Rolling,
            t: 0.0,
        };
        let tr = Trajectory::of(&st, &p);
        let seg = t.linear.iter().find(|c| c.id == "15").unwrap();
        let time = linear_time(&st, &p, &tr, seg, f64::INFINITY);
        let dist = 0.9906 - p.r - 0.5;
        let k = 0.5 * p.u_r * p.g;
        let expect = (1.0 - (1.0 - 4.0 * k * dist).sqrt()) / (2.0 * k);
        assert!((time - expect).abs() < 1e-9, "{time} vs {expect}");
        // the opposite rail (x = 0) is behind it: only the polynomial's spurious root after
        // the ball has stopped (pooltool finds it too; the transition fires first)
        let seg3 = t.linear.iter().find(|c| c.id == "3").unwrap();
        let t_roll = 1.0 / (p.u_r * p.g);
        assert!(linear_time(&st, &p, &tr, seg3, f64::INFINITY) > t_roll);
        // a segment on another rail whose projection misses: the y = 0 rail
        let seg18 = t.linear.iter().find(|c| c.id == "18").unwrap();
        assert_eq!(
            linear_time(&st, &p, &tr, seg18, f64::INFINITY),
            f64::INFINITY
        );
    }

    /// Jaw: heading straight at jaw "14t" centre; contact at distance ρ + R.
    #[test]
    fn straight_into_jaw() {
        let t = Table::default_7ft();
        let p = BallParams::pool_default();
        let jaw = t.circular.iter().find(|c| c.id == "14t").unwrap();
        let y = jaw.center[1];
        let st = BallState {
            r: [0.6, y, p.r],
            v: [1.0, 0.0, 0.0],
            w: [0.0, 1.0 / p.r, 0.0],
            s: MotionState::Rolling,
            t: 0.0,
        };
        let tr = Trajectory::of(&st, &p);
        let time = circular_time(&st, &p, &tr, jaw, f64::INFINITY);
        let dist = jaw.center[0] - jaw.radius - p.r - 0.6;
        let k = 0.5 * p.u_r * p.g;
        let expect = (1.0 - (1.0 - 4.0 * k * dist).sqrt()) / (2.0 * k);
        assert!((time - expect).abs() < 1e-9, "{time} vs {expect}");
    }
}
