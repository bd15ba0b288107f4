//! Cue-stick strike (docs/envs/pool.md §P8 (a); pooltool
//! `physics/resolve/stick_ball/instantaneous_point/__init__.py` and `squirt.py`):
//! instantaneous point contact (Alciatore TP A-30) plus squirt (TP A-31).

use super::super::params::{BallParams, CueSpecs, ModelParams};
use super::super::shot::Shot;
use super::super::state::{BallState, MotionState};
use super::super::vec3::{self, V3};

/// Ball velocity and angular velocity right after the strike (before squirt), in the
/// table frame (pooltool `cue_strike`). `q = R·(a′, c′, b′)`.
fn cue_strike(
    m: f64,
    big_m: f64,
    r: f64,
    v0: f64,
    phi_deg: f64,
    theta_deg: f64,
    q: V3,
) -> (V3, V3) {
    let phi = phi_deg * (std::f64::consts::PI / 180.0);
    let theta = theta_deg * (std::f64::consts::PI / 180.0);
    let i_m = 2.0 / 5.0 * (r * r);
    let (a, c, b) = (q[0], q[1], q[2]);
    let (st, ct) = (theta.sin(), theta.cos());
    let temp = a * a + (b * ct) * (b * ct) + (c * st) * (c * st) - 2.0 * b * c * ct * st;
    let denominator = 1.0 + m / big_m + temp / i_m;
    let v = 2.0 * v0 / denominator;
    let v_b = [-v * 0.0, -v * ct, -v * 0.0];
    let vec = [-c * st + b * ct, a * st, -a * ct];
    let k = v / i_m;
    let w_b = [k * vec[0], k * vec[1], k * vec[2]];
    let rot = phi + std::f64::consts::PI / 2.0;
    (vec3::rotate_z(v_b, rot), vec3::rotate_z(w_b, rot))
}

/// Squirt angle (rad) for side offset `a` (pooltool `get_squirt_angle`).
pub fn squirt_angle(m_b: f64, m_e: f64, a: f64, throttle: f64) -> f64 {
    let m_r = m_b / m_e;
    let aa = 1.0 - a * a;
    let num = 5.0 / 2.0 * a * aa.sqrt();
    let den = 1.0 + m_r + 5.0 / 2.0 * aa;
    -throttle * num.atan2(den)
}

/// Resolve the strike in place: new v, ω, state sliding (position unchanged).
/// The shot must have been validated (`a² + b² < 1`).
pub fn resolve(
    state: &mut BallState,
    p: &BallParams,
    cue: &CueSpecs,
    model: &ModelParams,
    shot: &Shot,
) {
    let theta_rad = shot.theta * std::f64::consts::PI / 180.0;
    let cue_c = (1.0 - shot.a * shot.a - shot.b * shot.b).sqrt();
    let ball_a = shot.a;
    let ball_c = theta_rad.cos() * cue_c - theta_rad.sin() * shot.b;
    let ball_b = theta_rad.sin() * cue_c + theta_rad.cos() * shot.b;
    let q = [p.r * ball_a, p.r * ball_c, p.r * ball_b];
    let (v, w) = cue_strike(p.m, cue.mass, p.r, shot.v0, shot.phi, shot.theta, q);
    let alpha = squirt_angle(p.m, cue.end_mass, ball_a, model.squirt_throttle);
    state.v = vec3::rotate_z(v, alpha);
    state.w = vec3::scale(w, model.english_throttle);
    state.s = MotionState::Sliding;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strike(shot: Shot) -> BallState {
        let p = BallParams::pool_default();
        let mut s = BallState::at_rest(0.5, 0.5, p.r);
        resolve(
            &mut s,
            &p,
            &CueSpecs::pool_default(),
            &ModelParams::default(),
            &shot,
        );
        s
    }

    /// Natural roll at b = 0.4 (θ = 0): the slip velocity is zero right after the strike,
    /// so there is no sliding phase (slide time 0). Source: §P8 (a) check. Tol 1e-12.
    #[test]
    fn natural_roll_at_b_0_4() {
        let p = BallParams::pool_default();
        let s = strike(Shot {
            v0: 2.0,
            phi: 30.0,
            theta: 0.0,
            a: 0.0,
            b: 0.4,
        });
        let u = s.rel_velocity(p.r);
        assert!(vec3::norm(u) < 1e-12 * vec3::norm(s.v), "u = {:?}", u);
        // heading = φ with no side spin (no squirt)
        assert!((vec3::angle(s.v) - 30f64.to_radians()).abs() < 1e-12);
        // speed: v = 2 V0 / (1 + m/M + (b R)²/(2/5 R²))
        let expect = 2.0 * 2.0 / (1.0 + p.m / 0.567 + 0.16 / 0.4);
        assert!((vec3::norm(s.v) - expect).abs() < 1e-12);
    }

    /// Side spin at θ = 0 only squirts: heading rotated by the squirt angle (a = 0.5 gives
    /// ≈ −1.9°, docs/envs/pool.md §P8 (a): "a straight line at 88.1°" for φ = 90°).
    #[test]
    fn squirt_with_side_spin() {
        let s = strike(Shot {
            v0: 2.0,
            phi: 90.0,
            theta: 0.0,
            a: 0.5,
            b: 0.0,
        });
        let heading = vec3::angle(s.v).to_degrees();
        assert!((heading - 88.1).abs() < 0.05, "heading {heading}");
        assert!(s.w[2] < 0.0); // left english (+a) gives ω_z = −A cosθ·v/(I/m) < 0
    }
}
