//! Fixed-dt resampling of a finished simulation (pooltool `continuize`; docs/envs/pool.md
//! §P10 "timesteps"): samples at t = 0, dt, 2dt, … (time accumulated as pooltool
//! does) and a last sample at the final event time. States come from the closed-form
//! motion evolved from the latest recorded state, not from re-simulation.

use super::evolve::evolve_state;
use super::simulate::Simulation;
use super::state::BallState;
use super::state::MotionState;

/// One resampled instant: time and every ball's state (in `sim.ball_ids` order).
#[derive(Debug, Clone)]
pub struct Sample {
    /// Time (s)
    pub t: f64,
    /// Every ball's state at `t`
    pub balls: Vec<BallState>,
}

/// The sample times pooltool's `continuize(dt)` produces for a shot ending at `t_end`.
pub fn sample_times(t_end: f64, dt: f64) -> Vec<f64> {
    if !dt.is_finite() || dt <= 0.0 || !t_end.is_finite() || t_end < 0.0 {
        return vec![];
    }
    let num = (t_end / dt).floor() as usize + 1;
    let mut out = Vec::with_capacity(num + 1);
    out.push(0.0);
    let mut elapsed = 0.0f64;
    for _ in 0..num.saturating_sub(1) {
        elapsed += dt;
        out.push(elapsed);
    }
    out.push(t_end);
    out
}

/// Resample every ball on a fixed `dt` (empty for a non-positive/non-finite dt).
///
/// Gives exactly [`state_at`](super::simulate::state_at) at every sample time, but walks each ball's history once with a cursor
/// instead of searching it per sample.
pub fn resample(sim: &Simulation, dt: f64) -> Vec<Sample> {
    let times = sample_times(sim.t_end, dt);
    let n = sim.ball_ids.len();
    let mut out: Vec<Sample> = times
        .iter()
        .map(|&t| Sample {
            t,
            balls: Vec::with_capacity(n),
        })
        .collect();
    for b in 0..n {
        let mut cursor = Cursor::new(sim, b);
        for sample in out.iter_mut() {
            sample.balls.push(cursor.state_at(sample.t));
        }
    }
    out
}

/// One ball's state at increasing times, walking its history once (what [`resample`] does per ball;
/// the trace builder uses it step by step, without a [`Sample`] per time).
pub struct Cursor<'a> {
    sim: &'a Simulation,
    ball: usize,
    /// The last history entry with time <= the latest time asked for.
    k: usize,
}

impl<'a> Cursor<'a> {
    /// At the start of ball `ball`'s history.
    pub fn new(sim: &'a Simulation, ball: usize) -> Self {
        Cursor { sim, ball, k: 0 }
    }

    /// The state at time `t` (clamped to the shot), bit for bit what
    /// [`state_at`](super::simulate::state_at) gives; times must not decrease between calls.
    pub fn state_at(&mut self, t: f64) -> BallState {
        let h = &self.sim.history[self.ball];
        let t = t.clamp(0.0, self.sim.t_end);
        // NOTE: `k` ends at the last history entry with time <= the sample time, as `state_at`'s
        // partition point does; history times never decrease and start at 0.
        while self.k + 1 < h.len() && h[self.k + 1].t <= t {
            self.k += 1;
        }
        let base = &h[self.k];
        let mut s = if matches!(base.s, MotionState::Stationary | MotionState::Pocketed) {
            *base
        } else {
            evolve_state(base, &self.sim.ball_params[self.ball], t - base.t)
        };
        s.t = t;
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::pool::rack::{dataset_shot, scene_seed, shot_rng};
    use crate::envs::pool::simulate::state_at;
    use crate::envs::pool::{PoolConfig, Scene, SimOptions, simulate};

    /// The cursor walk gives bit for bit what `state_at` gives, over random 9-ball shots.
    #[test]
    fn resample_equals_state_at() {
        let c = PoolConfig::default_7ft();
        for i in 0..20 {
            let scene = Scene::nine_ball(&c, scene_seed(1, i));
            let shot = dataset_shot(&scene, &mut shot_rng(1, i, 0));
            let sim = simulate(&scene.system(&c).unwrap(), &shot, &SimOptions::default()).unwrap();
            for s in resample(&sim, 0.01) {
                for (b, st) in s.balls.iter().enumerate() {
                    assert_eq!(
                        *st,
                        state_at(&sim, b, s.t).unwrap(),
                        "shot {i} ball {b} t {}",
                        s.t
                    );
                }
            }
        }
    }

    /// pooltool: floor(T/dt)+1 grid points plus the final event time (docs/envs/pool.md §P10).
    #[test]
    fn grid_matches_continuize() {
        let ts = sample_times(0.035, 0.01);
        assert_eq!(ts.len(), 5);
        assert_eq!(ts[0], 0.0);
        assert!((ts[3] - 0.03).abs() < 1e-15);
        assert_eq!(*ts.last().unwrap(), 0.035);
        assert!(sample_times(1.0, 0.0).is_empty());
        assert!(sample_times(1.0, f64::NAN).is_empty());
    }
}
