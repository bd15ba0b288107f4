//! A detector: Python source defining `find_pattern(trace)` for one label of one environment.

use std::fmt;
use std::sync::Arc;

use sha2::{Digest, Sha256};

use crate::digest::hex;
use crate::trace::Env;

/// A detector's id: the first 16 hex digits of the SHA-256 of its environment, label and code, so the
/// same program for the same label has the same id in every run.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct DetectorId(pub String);

impl DetectorId {
    /// The id of `code` detecting `label` in `env`.
    pub fn of(env: Env, label: &str, code: &str) -> Self {
        let mut h = Sha256::new();
        h.update(env.as_str().as_bytes());
        h.update([0]);
        h.update(label.as_bytes());
        h.update([0]);
        h.update(code.as_bytes());
        DetectorId(hex(&h.finalize()[..8]))
    }

    /// The id as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for DetectorId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// A detector program and what its output must say.
#[derive(Clone, Debug, PartialEq)]
pub struct Detector {
    /// Content hash of environment, label and code.
    pub id: DetectorId,
    /// The label its patterns carry (`cue strike`).
    pub label: String,
    /// Other spellings accepted in its output (case-insensitive), e.g. `cue_strike`.
    pub aliases: Vec<String>,
    /// The environment it reads.
    pub env: Env,
    /// Where it came from: a library file (`data/libraries/pooltool/cue_strike.py`), `evolve:<stage>`…
    pub source: String,
    /// The Python source.
    pub code: String,
    /// The value its patterns take in the annotation matrix (a library's weight; default 1). In an
    /// ensemble library, the member's reliability weight w.
    pub weight: f64,
    /// Set when the detector is a member of an ensemble library's label ([`Membership`]): its
    /// patterns are then combined with the other members' by activation clustering (`ensemble`)
    /// rather than reported as they are.
    pub ensemble: Option<Arc<Membership>>,
}

/// A label's settings in an ensemble library (its `[[ensemble]]` table; paper section 3.3).
#[derive(Clone, Debug, PartialEq)]
pub struct EnsembleSettings {
    /// The label.
    pub label: String,
    /// Activation threshold γ in [0, 1): a cluster fires when its normalised activation exceeds it.
    pub gamma: f64,
    /// Spatial tolerance ε_s, in the environment's `nearby_scale` unit (`envs::EnvFacts`): metres for
    /// pooltool, fractions of the 256-pixel PHYRE scene, fractions of the 600-pixel I-PHYRE screen.
    pub eps_s: f64,
    /// Temporal tolerance ε_t in timesteps.
    pub eps_t: f64,
    /// Number of K-means clusters (= members) the label was built with.
    pub k: u32,
    /// Ids of the label's member detectors, in manifest order.
    pub members: Vec<DetectorId>,
}

/// What a detector is as a member of an ensemble library's label.
#[derive(Clone, Debug, PartialEq)]
pub struct Membership {
    /// The label's settings (shared by its members).
    pub settings: Arc<EnsembleSettings>,
    /// Training reward t of the member (its ν in the search that produced it).
    pub reward: f64,
    /// The run or stage it came from (`<run folder>/<stage>` or `<stage>`).
    pub run: String,
    /// Its candidate id there (the `candidates.code_hash`).
    pub candidate: String,
    /// The K-means cluster it represents.
    pub cluster: u32,
}

impl Detector {
    /// A detector with no aliases and weight 1.
    pub fn new(env: Env, label: &str, code: &str, source: &str) -> Self {
        Detector {
            id: DetectorId::of(env, label, code),
            label: label.to_string(),
            aliases: Vec::new(),
            env,
            source: source.to_string(),
            code: code.to_string(),
            weight: 1.0,
            ensemble: None,
        }
    }

    /// Lines of code (the paper's length penalty counts these).
    pub fn lines(&self) -> usize {
        self.code.lines().count()
    }

    /// Whether `label` names this detector's label: equal ignoring case and treating `_`, `-` and runs
    /// of spaces alike, or one of its aliases.
    pub fn accepts_label(&self, label: &str) -> bool {
        if label == self.label {
            return true;
        }
        let l = normalise_label(label);
        normalise_label(&self.label) == l || self.aliases.iter().any(|a| normalise_label(a) == l)
    }
}

/// A label's canonical spelling for comparisons: lower case, `_`/`-` as spaces, single spaces, trimmed.
pub fn normalise_label(label: &str) -> String {
    label
        .to_lowercase()
        .replace(['_', '-'], " ")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_depend_on_env_label_and_code_and_labels_compare_loosely() {
        let a = Detector::new(
            Env::Pooltool,
            "cue strike",
            "def find_pattern(t): return []",
            "x",
        );
        let b = Detector::new(
            Env::Pooltool,
            "cue strike",
            "def find_pattern(t): return [] ",
            "x",
        );
        let c = Detector::new(
            Env::Phyre,
            "cue strike",
            "def find_pattern(t): return []",
            "x",
        );
        assert_ne!(a.id, b.id);
        assert_ne!(a.id, c.id);
        assert_eq!(a.id.as_str().len(), 16);
        assert!(a.accepts_label("Cue_Strike"));
        assert!(a.accepts_label(" cue  strike "));
        assert!(!a.accepts_label("ball collision"));
        let mut d = a.clone();
        d.aliases.push("stick hit".into());
        assert!(d.accepts_label("STICK-HIT"));
    }
}
