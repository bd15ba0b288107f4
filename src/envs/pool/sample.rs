//! Fixed-dt resampling of a finished simulation (pooltool `continuize`; reference
//! §3.1/§3.2 "timesteps"): samples at t = 0, dt, 2dt, … (time accumulated as pooltool
//! does) and a last sample at the final event time. States come from the closed-form
//! motion evolved from the latest recorded state, not from re-simulation.

use super::simulate::{Simulation, state_at};
use super::state::BallState;

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
    if !(dt > 0.0) || !dt.is_finite() || !t_end.is_finite() || t_end < 0.0 {
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
pub fn resample(sim: &Simulation, dt: f64) -> Vec<Sample> {
    sample_times(sim.t_end, dt)
        .into_iter()
        .map(|t| Sample {
            t,
            balls: (0..sim.ball_ids.len())
                .filter_map(|b| state_at(sim, b, t))
                .collect(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// pooltool: floor(T/dt)+1 grid points plus the final event time (reference §3.2).
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
