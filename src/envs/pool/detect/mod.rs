//! Event detection (docs/envs/pool.md §P7): collision times for ball–ball,
//! ball–cushion (linear and circular) and ball–pocket, plus motion transitions.
//!
//! Every translating ball follows r(t) = c + b t + a t² until its next transition;
//! [`Trajectory`] builds those coefficients exactly like pooltool's `solve.py` (rotated
//! slip direction). Each detector also takes a `horizon` (time until the earliest
//! transition of the balls involved): a root beyond it can never become the next event,
//! because the transition fires first and invalidates the cached time, so a cheap
//! reachability bound lets us skip the polynomial solve. This is an optimisation that
//! does not change which events are found.

pub mod ball_ball;
pub mod ball_cushion;
pub mod ball_pocket;
pub mod roots;
pub mod transition;

use super::params::BallParams;
use super::state::{BallState, MotionState};
use super::vec3;

/// Planar trajectory r(t) = c + b t + a t² of a ball (zero a, b if non-translating).
#[derive(Debug, Clone, Copy, Default)]
pub struct Trajectory {
    pub ax: f64,
    pub ay: f64,
    pub bx: f64,
    pub by: f64,
    pub cx: f64,
    pub cy: f64,
    /// the friction coefficient μ used (μ_s sliding, μ_r otherwise)
    pub mu: f64,
    /// |v|
    pub speed: f64,
    /// rolling: straight-line deceleration along v̂
    pub rolling: bool,
}

impl Trajectory {
    pub fn of(st: &BallState, p: &BallParams) -> Trajectory {
        let (cx, cy) = (st.r[0], st.r[1]);
        if st.s.is_nontranslating() {
            let mu = if st.s == MotionState::Sliding {
                p.u_s
            } else {
                p.u_r
            };
            return Trajectory {
                cx,
                cy,
                mu,
                ..Default::default()
            };
        }
        let mu = if st.s == MotionState::Sliding {
            p.u_s
        } else {
            p.u_r
        };
        let phi = vec3::angle(st.v);
        let v = vec3::norm(st.v);
        let (sin_phi, cos_phi) = phi.sin_cos();
        // get_u: rolling → (1,0,0); zero slip → (1,0,0); else unit slip rotated by −φ
        let u = if st.s == MotionState::Rolling {
            [1.0, 0.0, 0.0]
        } else {
            let rel = st.rel_velocity(p.r);
            if rel[0] == 0.0 && rel[1] == 0.0 && rel[2] == 0.0 {
                [1.0, 0.0, 0.0]
            } else {
                vec3::rotate_z(vec3::unit(rel), -phi)
            }
        };
        let k = -0.5 * mu * p.g;
        Trajectory {
            ax: k * (u[0] * cos_phi - u[1] * sin_phi),
            ay: k * (u[0] * sin_phi + u[1] * cos_phi),
            bx: v * cos_phi,
            by: v * sin_phi,
            cx,
            cy,
            mu,
            speed: v,
            rolling: st.s == MotionState::Rolling,
        }
    }

    /// Upper bound of the distance travelled within `horizon` seconds.
    #[inline]
    pub fn reach(&self, horizon: f64) -> f64 {
        if self.speed == 0.0 && self.ax == 0.0 && self.ay == 0.0 {
            return 0.0;
        }
        let acc = 2.0 * (self.ax * self.ax + self.ay * self.ay).sqrt();
        if self.rolling && acc > 0.0 {
            // straight deceleration: distance until the stop is at most v²/(2 acc)
            let h = horizon.min(self.speed / acc);
            return self.speed * h - 0.5 * acc * h * h;
        }
        self.speed * horizon + 0.5 * acc * horizon * horizon
    }
}

/// Relative slack added to reachability bounds before skipping a solve.
pub(crate) const REACH_SLACK: f64 = 1e-6;
