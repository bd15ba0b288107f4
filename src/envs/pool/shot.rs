//! The cue shot (docs/envs/pool.md §P8 (a)): `Shot { V0, phi, theta, a, b }`
//! in pooltool's units — V0 in m/s, φ and θ in degrees, (a, b) contact offsets in units
//! of R (+a = left side, +b = top). Validation returns errors instead of panicking.

use serde::{Deserialize, Serialize};

use super::error::{PoolError, Result};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
/// A cue shot in pooltool's parameters; `V0` is the JSON name of `v0`.
pub struct Shot {
    /// cue speed (m/s), ≥ 0
    #[serde(rename = "V0")]
    pub v0: f64,
    /// aim direction in degrees (0 = +x, counter-clockwise)
    pub phi: f64,
    /// cue elevation in degrees
    pub theta: f64,
    /// side offset / R (+ = left)
    pub a: f64,
    /// vertical offset / R (+ = top)
    pub b: f64,
}

impl Default for Shot {
    /// pooltool's `Cue` defaults: V0 = 2, φ = 0, θ = 0, a = 0, b = 0.25.
    fn default() -> Self {
        Shot {
            v0: 2.0,
            phi: 0.0,
            theta: 0.0,
            a: 0.0,
            b: 0.25,
        }
    }
}

/// The fastest cue speed a shot may have (m/s): well above a hard break (about 10–12 m/s), far below
/// speeds at which the event-based solver's states overflow.
pub const MAX_V0: f64 = 20.0;

impl Shot {
    /// Checks the shot: finite values, V0 ≥ 0, a² + b² < 1, θ within [−90°, 90°]; the error names the field.
    pub fn validate(&self) -> Result<()> {
        let vals = [self.v0, self.phi, self.theta, self.a, self.b];
        if vals.iter().any(|x| !x.is_finite()) {
            return Err(PoolError::InvalidShot(format!(
                "non-finite parameter in {self:?}"
            )));
        }
        if !(0.0..=MAX_V0).contains(&self.v0) {
            return Err(PoolError::InvalidShot(format!(
                "V0 must be in [0, {MAX_V0}] m/s, got {}",
                self.v0
            )));
        }
        if self.a * self.a + self.b * self.b >= 1.0 {
            return Err(PoolError::InvalidShot(format!(
                "a² + b² must be < 1, got a={}, b={}",
                self.a, self.b
            )));
        }
        if !(-90.0..=90.0).contains(&self.theta) {
            return Err(PoolError::InvalidShot(format!(
                "theta must be within [-90, 90] degrees, got {}",
                self.theta
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation() {
        assert!(Shot::default().validate().is_ok());
        assert!(
            Shot {
                v0: -1.0,
                ..Shot::default()
            }
            .validate()
            .is_err()
        );
        assert!(
            Shot {
                a: 0.8,
                b: 0.6,
                ..Shot::default()
            }
            .validate()
            .is_err()
        );
        assert!(
            Shot {
                phi: f64::NAN,
                ..Shot::default()
            }
            .validate()
            .is_err()
        );
        assert!(
            Shot {
                v0: f64::INFINITY,
                ..Shot::default()
            }
            .validate()
            .is_err()
        );
        assert!(
            Shot {
                v0: 0.0,
                ..Shot::default()
            }
            .validate()
            .is_ok()
        );
    }
}
