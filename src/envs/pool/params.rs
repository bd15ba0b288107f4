//! Ball, cue and resolution-model parameters (docs/envs/pool.md §P2, §P8).
//!
//! Values are data, not constants: [`BallParams`] and [`CueSpecs`] are read from
//! `pooltool_table.json` (written by `tools/pooltool/dump_geom.py`) or from a
//! `pooltool-trace/1` file's `meta`. [`ModelParams`] holds the parameters of pooltool
//! 0.6.0's default `Resolver` (VERSION 9); its `Default` is that resolver.

use serde::{Deserialize, Serialize};

use super::error::{PoolError, Result};

/// Per-ball physical parameters (pooltool `BallParams`, SI units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BallParams {
    /// mass (kg)
    pub m: f64,
    /// radius (m)
    #[serde(rename = "R")]
    pub r: f64,
    /// sliding friction ball–cloth
    pub u_s: f64,
    /// rolling friction
    pub u_r: f64,
    /// spinning friction (units of length)
    pub u_sp: f64,
    /// ball–ball friction (unused by the Alciatore friction model)
    #[serde(default = "default_u_b")]
    pub u_b: f64,
    /// ball–ball restitution
    pub e_b: f64,
    /// cushion restitution
    pub e_c: f64,
    /// cushion friction
    pub f_c: f64,
    /// gravity (m/s²)
    pub g: f64,
}

fn default_u_b() -> f64 {
    0.05
}

impl BallParams {
    /// Checks that every parameter is finite and in its physical range.
    pub fn validate(&self) -> Result<()> {
        let all = [
            self.m, self.r, self.u_s, self.u_r, self.u_sp, self.e_b, self.e_c, self.f_c, self.g,
        ];
        if all.iter().any(|x| !x.is_finite()) {
            return Err(PoolError::Data("non-finite ball parameter".into()));
        }
        if self.m <= 0.0 || self.r <= 0.0 || self.g <= 0.0 {
            return Err(PoolError::Data("ball m, R and g must be > 0".into()));
        }
        if self.u_s < 0.0 || self.u_r < 0.0 || self.u_sp < 0.0 || self.f_c < 0.0 {
            return Err(PoolError::Data("friction coefficients must be >= 0".into()));
        }
        if !(self.e_c > 0.0 && self.e_c <= 1.0 && self.e_b >= 0.0 && self.e_b <= 1.0) {
            return Err(PoolError::Data("restitution out of range".into()));
        }
        Ok(())
    }
}

/// Cue specification (pooltool `CueSpecs`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CueSpecs {
    /// cue mass (kg)
    #[serde(rename = "M")]
    pub mass: f64,
    /// cue length (m), GUI only
    #[serde(default)]
    pub length: f64,
    /// tip radius (m), GUI only (not used by the instantaneous-point model)
    #[serde(default)]
    pub tip_radius: f64,
    /// end mass (kg), used for squirt
    pub end_mass: f64,
}

/// Parameters of the default resolution models (pooltool 0.6.0 `default_resolver`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ModelParams {
    /// Alciatore ball–ball friction curve μ = a + b·exp(−c·|Δv_surface|)
    pub alciatore_a: f64,
    /// Alciatore curve parameter b
    pub alciatore_b: f64,
    /// Alciatore curve parameter c (s/m)
    pub alciatore_c: f64,
    /// Stronge compliant cushion ω_t/ω_n
    pub omega_ratio: f64,
    /// Stronge normal stiffness used to build ω_n (results do not depend on it)
    pub stronge_k_n: f64,
    /// stick–ball english throttle
    pub english_throttle: f64,
    /// stick–ball squirt throttle
    pub squirt_throttle: f64,
}

impl Default for ModelParams {
    fn default() -> Self {
        ModelParams {
            alciatore_a: 0.009951,
            alciatore_b: 0.108,
            alciatore_c: 1.088,
            omega_ratio: 1.8,
            stronge_k_n: 1000.0,
            english_throttle: 1.0,
            squirt_throttle: 1.0,
        }
    }
}

/// The parameter part of `pooltool_table.json`.
#[derive(Debug, Clone, Deserialize)]
struct ParamFile {
    ball_params: BallParams,
    cue_specs: CueSpecs,
}

/// The default table JSON (`data/tables/pooltool_7ft.json`, Apache-2.0, from pooltool 0.6.0), compiled in.
pub const DEFAULT_TABLE_JSON: &str = include_str!("../../../data/tables/pooltool_7ft.json");

impl BallParams {
    /// Ball parameters from a `pooltool_table.json` document.
    pub fn from_table_json(json: &str) -> Result<BallParams> {
        let f: ParamFile = serde_json::from_str(json)?;
        f.ball_params.validate()?;
        Ok(f.ball_params)
    }
    /// pooltool's `POOL_GENERIC` parameters, read from the shipped table JSON.
    pub fn pool_default() -> BallParams {
        Self::from_table_json(DEFAULT_TABLE_JSON).expect("shipped table JSON is valid")
    }
}

impl CueSpecs {
    /// Cue specs from a table JSON document (`cue_specs`).
    pub fn from_table_json(json: &str) -> Result<CueSpecs> {
        let f: ParamFile = serde_json::from_str(json)?;
        if !(f.cue_specs.mass > 0.0 && f.cue_specs.end_mass > 0.0) {
            return Err(PoolError::Data("cue masses must be > 0".into()));
        }
        Ok(f.cue_specs)
    }
    /// pooltool's default cue, read from the compiled-in table file.
    pub fn pool_default() -> CueSpecs {
        Self::from_table_json(DEFAULT_TABLE_JSON).expect("shipped table JSON is valid")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Source: docs/envs/pool.md §P2 table (pooltool 0.6.0 POOL_GENERIC).
    #[test]
    fn defaults_match_reference() {
        let p = BallParams::pool_default();
        assert_eq!(p.m, 0.170097);
        assert_eq!(p.r, 0.028575);
        assert_eq!(p.u_s, 0.2);
        assert_eq!(p.u_r, 0.01);
        assert!((p.u_sp - 0.0127).abs() < 1e-12);
        assert_eq!(p.e_b, 0.95);
        assert_eq!(p.e_c, 0.85);
        assert_eq!(p.f_c, 0.2);
        let c = CueSpecs::pool_default();
        assert_eq!(c.mass, 0.567);
        assert!((c.end_mass - 0.170097 / 30.0).abs() < 1e-9);
    }

    #[test]
    fn bad_json_is_an_error() {
        assert!(BallParams::from_table_json("{}").is_err());
        assert!(BallParams::from_table_json("not json").is_err());
    }
}
