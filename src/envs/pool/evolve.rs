//! Closed-form ball motion between events and the motion-state transition times
//! (docs/envs/pool.md §P3; pooltool `physics/evolve/__init__.py`,
//! `ptmath/utils.py::get_{slide,roll,spin}_time`).
//!
//! The arithmetic follows pooltool's (frame rotation by the heading φ for sliding, the
//! π/2 rotation for the rolling spin) so trajectories agree to a few ulps.

use super::params::BallParams;
use super::state::{BallState, MotionState};
use super::vec3::{self, V3};

/// The friction set used by [`evolve_rvw`] (pooltool passes modified sets during detection).
#[derive(Debug, Clone, Copy)]
pub struct MotionParams {
    pub r: f64,
    pub u_s: f64,
    pub u_sp: f64,
    pub u_r: f64,
    pub g: f64,
}

impl From<&BallParams> for MotionParams {
    fn from(p: &BallParams) -> Self {
        MotionParams {
            r: p.r,
            u_s: p.u_s,
            u_sp: p.u_sp,
            u_r: p.u_r,
            g: p.g,
        }
    }
}

/// `EPS = 100·eps(f64)` (pooltool `constants.EPS`).
pub const EPS: f64 = f64::EPSILON * 100.0;

/// Position, velocity, angular velocity.
pub type Rvw = [V3; 3];

#[inline]
fn rel_vel(rvw: &Rvw, r: f64) -> V3 {
    vec3::add(rvw[1], vec3::cross(rvw[2], [0.0, 0.0, -r]))
}

/// Duration of the slide: 2‖u‖/(7 μ_s g).
pub fn slide_time(rvw: &Rvw, r: f64, u_s: f64, g: f64) -> f64 {
    if u_s == 0.0 {
        return f64::INFINITY;
    }
    2.0 * vec3::norm(rel_vel(rvw, r)) / (7.0 * u_s * g)
}

/// Duration of the roll: ‖v‖/(μ_r g).
pub fn roll_time(rvw: &Rvw, u_r: f64, g: f64) -> f64 {
    if u_r == 0.0 {
        return f64::INFINITY;
    }
    vec3::norm(rvw[1]) / (u_r * g)
}

/// Duration of the spin: 2R|ω_z|/(5 μ_sp g).
pub fn spin_time(rvw: &Rvw, r: f64, u_sp: f64, g: f64) -> f64 {
    if u_sp == 0.0 {
        return f64::INFINITY;
    }
    rvw[2][2].abs() * 2.0 / 5.0 * r / u_sp / g
}

/// z-spin decay ω_z(t) = ω_z0 − sign(ω_z0)·α_sp·min(t, |ω_z0|/α_sp), α_sp = 5μ_sp g/(2R).
pub fn spin_decay(wz: f64, r: f64, u_sp: f64, g: f64, t: f64) -> f64 {
    if t == 0.0 || wz.abs() < EPS {
        return wz;
    }
    let alpha = 5.0 * u_sp * g / (2.0 * r);
    let t = if t > wz.abs() / alpha {
        wz.abs() / alpha
    } else {
        t
    };
    let sign = if wz > 0.0 { 1.0 } else { -1.0 };
    wz - sign * alpha * t
}

fn evolve_slide(rvw: &Rvw, p: &MotionParams, t: f64) -> Rvw {
    if t == 0.0 {
        return *rvw;
    }
    let phi = vec3::angle(rvw[1]);
    let (s, c) = phi.sin_cos();
    let (sm, cm) = (-phi).sin_cos();
    let v_b0 = vec3::rotate_z_cs(rvw[1], cm, sm);
    let w_b0 = vec3::rotate_z_cs(rvw[2], cm, sm);
    let u0 = vec3::rotate_z_cs(vec3::unit(rel_vel(rvw, p.r)), cm, sm);
    let k_r = 0.5 * p.u_s * p.g * (t * t);
    let r_b = [v_b0[0] * t - k_r * u0[0], -k_r * u0[1], 0.0];
    let k_v = p.u_s * p.g * t;
    let v_b = [
        v_b0[0] - k_v * u0[0],
        v_b0[1] - k_v * u0[1],
        v_b0[2] - k_v * u0[2],
    ];
    let k_w = 5.0 / 2.0 / p.r * p.u_s * p.g * t;
    // cross(u0, z) = (u0y, -u0x, 0)
    let cz = [u0[1], -u0[0], 0.0];
    let mut w_b = [w_b0[0] - k_w * cz[0], w_b0[1] - k_w * cz[1], w_b0[2]];
    w_b[2] = spin_decay(w_b[2], p.r, p.u_sp, p.g, t);
    let r_t = vec3::rotate_z_cs(r_b, c, s);
    [
        vec3::add(r_t, rvw[0]),
        vec3::rotate_z_cs(v_b, c, s),
        vec3::rotate_z_cs(w_b, c, s),
    ]
}

fn evolve_roll(rvw: &Rvw, p: &MotionParams, t: f64) -> Rvw {
    if t == 0.0 {
        return *rvw;
    }
    let vh = vec3::unit(rvw[1]);
    let k_r = 0.5 * p.u_r * p.g * (t * t);
    let r = vec3::sub(
        vec3::add(rvw[0], vec3::scale(rvw[1], t)),
        vec3::scale(vh, k_r),
    );
    let v = vec3::sub(rvw[1], vec3::scale(vh, p.u_r * p.g * t));
    let half_pi = std::f64::consts::FRAC_PI_2;
    // pooltool: w = coordinate_rotation(v / R, π/2)
    let vr = [v[0] / p.r, v[1] / p.r, v[2] / p.r];
    let mut w = vec3::rotate_z_cs(vr, half_pi.cos(), half_pi.sin());
    w[2] = spin_decay(rvw[2][2], p.r, p.u_sp, p.g, t);
    [r, v, w]
}

fn evolve_spin(rvw: &Rvw, p: &MotionParams, t: f64) -> Rvw {
    let mut out = *rvw;
    out[2][2] = spin_decay(rvw[2][2], p.r, p.u_sp, p.g, t);
    out
}

/// Evolve `rvw` in motion state `s` by `t` seconds, chaining slide → roll → spin →
/// stationary when `t` runs past a transition (pooltool `evolve_ball_motion`).
/// Returns the new `rvw` and the motion state reached.
pub fn evolve_rvw(s: MotionState, rvw: &Rvw, p: &MotionParams, t: f64) -> (Rvw, MotionState) {
    let mut rvw = *rvw;
    let mut t = t;
    let mut s = s;
    if matches!(s, MotionState::Stationary | MotionState::Pocketed) {
        return (rvw, s);
    }
    if s == MotionState::Sliding {
        let d = slide_time(&rvw, p.r, p.u_s, p.g);
        if t >= d {
            rvw = evolve_slide(&rvw, p, d);
            s = MotionState::Rolling;
            t -= d;
        } else {
            return (evolve_slide(&rvw, p, t), MotionState::Sliding);
        }
    }
    if s == MotionState::Rolling {
        let d = roll_time(&rvw, p.u_r, p.g);
        if t >= d {
            rvw = evolve_roll(&rvw, p, d);
            t -= d; // now spinning
        } else {
            return (evolve_roll(&rvw, p, t), MotionState::Rolling);
        }
    }
    // spinning
    let d = spin_time(&rvw, p.r, p.u_sp, p.g);
    if t >= d {
        (evolve_spin(&rvw, p, d), MotionState::Stationary)
    } else {
        (evolve_spin(&rvw, p, t), MotionState::Spinning)
    }
}

/// Evolve a [`BallState`] by `dt` with the ball's own parameters. The returned state has
/// `t = state.t + dt` and the motion state actually reached.
pub fn evolve_state(state: &BallState, params: &BallParams, dt: f64) -> BallState {
    let (rvw, s) = evolve_rvw(
        state.s,
        &[state.r, state.v, state.w],
        &MotionParams::from(params),
        dt,
    );
    BallState {
        r: rvw[0],
        v: rvw[1],
        w: rvw[2],
        s,
        t: state.t + dt,
    }
}

/// The ball's next transition: `(relative time, kind)` where kind is the new state.
/// Mirrors pooltool `cache.py::_next_transition`.
pub fn next_transition(
    state: &BallState,
    p: &BallParams,
) -> Option<(f64, MotionState, MotionState)> {
    let rvw = [state.r, state.v, state.w];
    match state.s {
        MotionState::Stationary | MotionState::Pocketed => None,
        MotionState::Spinning => Some((
            spin_time(&rvw, p.r, p.u_sp, p.g),
            MotionState::Spinning,
            MotionState::Stationary,
        )),
        MotionState::Rolling => {
            let tsp = spin_time(&rvw, p.r, p.u_sp, p.g);
            let tr = roll_time(&rvw, p.u_r, p.g);
            if tsp > tr {
                Some((tr, MotionState::Rolling, MotionState::Spinning))
            } else {
                Some((tr, MotionState::Rolling, MotionState::Stationary))
            }
        }
        MotionState::Sliding => Some((
            slide_time(&rvw, p.r, p.u_s, p.g),
            MotionState::Sliding,
            MotionState::Rolling,
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> BallParams {
        BallParams::pool_default()
    }

    /// Hand-computable: a rolling ball stops after d = v0²/(2 μ_r g) in τ = v0/(μ_r g).
    /// Source: §P3 rolling row. Tolerance 1e-12 m (closed form, only rounding).
    #[test]
    fn rolling_ball_stop_distance() {
        let p = params();
        let v0 = 1.3;
        let st = BallState {
            r: [0.2, 0.3, p.r],
            v: [v0, 0.0, 0.0],
            w: [0.0, v0 / p.r, 0.0],
            s: MotionState::Rolling,
            t: 0.0,
        };
        let (tau, _, to) = next_transition(&st, &p).unwrap();
        assert!((tau - v0 / (p.u_r * p.g)).abs() < 1e-12);
        assert_eq!(to, MotionState::Stationary);
        let end = evolve_state(&st, &p, 100.0);
        assert_eq!(end.s, MotionState::Stationary);
        let d = v0 * v0 / (2.0 * p.u_r * p.g);
        assert!(
            (end.r[0] - 0.2 - d).abs() < 1e-12,
            "{} vs {}",
            end.r[0] - 0.2,
            d
        );
        assert!(end.v.iter().all(|x| x.abs() < 1e-12));
    }

    /// Sliding: u shrinks at (7/2) μ_s g, so τ_s = 2‖u0‖/(7 μ_s g); at τ_s the ball rolls
    /// (u = 0). Stun shot from rest spin: v_f = 5/7 v0. Tolerance 1e-12.
    #[test]
    fn stun_shot_reaches_five_sevenths() {
        let p = params();
        let v0 = 2.0;
        let st = BallState {
            r: [0.5, 0.5, p.r],
            v: [0.0, v0, 0.0],
            w: [0.0; 3],
            s: MotionState::Sliding,
            t: 0.0,
        };
        let (tau, _, _) = next_transition(&st, &p).unwrap();
        assert!((tau - 2.0 * v0 / (7.0 * p.u_s * p.g)).abs() < 1e-12);
        let (rvw, s) = evolve_rvw(st.s, &[st.r, st.v, st.w], &MotionParams::from(&p), tau);
        assert_eq!(s, MotionState::Rolling);
        assert!((rvw[1][1] - 5.0 / 7.0 * v0).abs() < 1e-12);
        let u = vec3::add(rvw[1], vec3::cross(rvw[2], [0.0, 0.0, -p.r]));
        assert!(vec3::norm(u) < 1e-12);
    }

    /// Spin decay: τ_sp = 2R|ω_z|/(5 μ_sp g); ω_z → 0 exactly then.
    #[test]
    fn spin_decays_to_zero() {
        let p = params();
        let st = BallState {
            r: [0.5, 0.5, p.r],
            v: [0.0; 3],
            w: [0.0, 0.0, -20.0],
            s: MotionState::Spinning,
            t: 0.0,
        };
        let (tau, _, to) = next_transition(&st, &p).unwrap();
        assert_eq!(to, MotionState::Stationary);
        assert!((tau - 2.0 * p.r * 20.0 / (5.0 * p.u_sp * p.g)).abs() < 1e-12);
        let half = evolve_state(&st, &p, tau / 2.0);
        assert!((half.w[2] + 10.0).abs() < 1e-9);
        let end = evolve_state(&st, &p, tau);
        assert_eq!(end.s, MotionState::Stationary);
        assert!(end.w[2].abs() < 1e-12);
    }
}
