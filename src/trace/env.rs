//! The three simulation environments a trace can come from.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// A simulation environment. Its string form (`pooltool`, `phyre`, `iphyre`) is the value of a trace's
/// `environment` field, of the `env=` partition of the run's tables and of `--env` on the command line.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    PartialOrd,
    Ord,
    Hash,
    Default,
    Serialize,
    Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Env {
    /// Billiards in the style of pooltool: 3D ball states, an exact event log. The default.
    #[default]
    Pooltool,
    /// PHYRE: a 256×256 2D scene of balls, bars and jars; place a red ball.
    Phyre,
    /// I-PHYRE: a 600×600 2D scene of capsule blocks and balls; remove blocks at chosen times.
    Iphyre,
}

impl Env {
    /// Every environment, in a fixed order.
    pub const ALL: [Env; 3] = [Env::Pooltool, Env::Phyre, Env::Iphyre];

    /// The canonical lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            Env::Pooltool => "pooltool",
            Env::Phyre => "phyre",
            Env::Iphyre => "iphyre",
        }
    }
}

impl fmt::Display for Env {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The error for a string that names no environment.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown environment {found:?} (expected one of: pooltool, phyre, iphyre)")]
pub struct UnknownEnv {
    /// What was given.
    pub found: String,
}

impl FromStr for Env {
    type Err = UnknownEnv;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Env::ALL
            .into_iter()
            .find(|e| e.as_str().eq_ignore_ascii_case(s))
            .ok_or_else(|| UnknownEnv {
                found: s.to_string(),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_its_own_names_case_insensitively() {
        for env in Env::ALL {
            assert_eq!(env.as_str().parse::<Env>().unwrap(), env);
            assert_eq!(env.as_str().to_uppercase().parse::<Env>().unwrap(), env);
        }
        let err = "pool".parse::<Env>().unwrap_err();
        assert!(err.to_string().contains("\"pool\""));
    }
}
