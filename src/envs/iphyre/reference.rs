//! Outcome agreement with the original I-PHYRE (iphyre 0.2.3 on pymunk 6.11.1): a reference set of
//! (game, click list, frame rate) pairs with the original's outcome, written by
//! `tools/iphyre_reference.py` (one JSON document) or by the balanced generator `iphyre_gen.py outcomes`
//! (JSON Lines, optionally gzipped, each line one click list with its 60 and 10 fps results), replayed
//! here and scored separately for the pairs the original solved and those it did not.
//!
//! **Owns:** the reference-set formats ([`ReferenceSet`]) and the replay and scoring ([`agreement`]).
//! **Does not:** run Python (the set is made offline) or decide thresholds (the tests do).
//!
//! Rapier is not Chipmunk, so trajectories differ; what is compared is whether every ball fell out
//! (success) and, as a secondary figure, the number of effective eliminations.

use std::collections::BTreeMap;
use std::io::Read;

use serde::Deserialize;

use super::action::Click;
use super::error::{IphyreError, Result};
use super::game::Games;
use super::params::PhysicsParams;
use super::step::Episode;

/// One (game, clicks, fps) pair with the original's outcome.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct ReferencePair {
    /// Game name.
    pub game: String,
    /// Frame rate the original ran at (60 or 10).
    pub fps: f64,
    /// Clicks `[x, y, t]`.
    pub clicks: Vec<[f64; 3]>,
    /// Whether the original solved it.
    pub success: bool,
    /// The original's effective eliminations.
    pub eliminations: usize,
    /// The original's time counter at the end (s).
    pub time: f64,
}

/// A reference set as `tools/iphyre_reference.py` writes it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
pub struct ReferenceSet {
    /// The pairs.
    pub pairs: Vec<ReferencePair>,
}

#[derive(Deserialize)]
struct OutcomeLine {
    game: String,
    actions: Vec<[f64; 3]>,
    results: Vec<OutcomeResult>,
}

#[derive(Deserialize)]
struct OutcomeResult {
    fps: f64,
    success: bool,
    eliminations: usize,
    time: f64,
}

fn bad(field: String, message: impl Into<String>) -> IphyreError {
    IphyreError::InvalidReference {
        field,
        message: message.into(),
    }
}

impl ReferenceSet {
    /// Parses the JSON document.
    pub fn from_json(text: &str) -> Result<ReferenceSet> {
        Ok(serde_json::from_str(text)?)
    }

    /// Parses `iphyre_gen.py outcomes` JSON Lines: per line `game`, `actions` (`[x, y, t]` clicks) and
    /// `results` (one per frame rate: `fps`, `success`, `eliminations`, `time`); other fields are
    /// ignored. Each result becomes one pair, in file order. Blank lines are skipped.
    pub fn from_outcomes_jsonl(text: &str) -> Result<ReferenceSet> {
        let mut pairs = Vec::new();
        for (n, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let l: OutcomeLine = serde_json::from_str(line)
                .map_err(|e| bad(format!("line {}", n + 1), e.to_string()))?;
            if l.results.is_empty() {
                return Err(bad(format!("line {} results", n + 1), "no results"));
            }
            for r in l.results {
                pairs.push(ReferencePair {
                    game: l.game.clone(),
                    fps: r.fps,
                    clicks: l.actions.clone(),
                    success: r.success,
                    eliminations: r.eliminations,
                    time: r.time,
                });
            }
        }
        Ok(ReferenceSet { pairs })
    }

    /// [`from_outcomes_jsonl`](Self::from_outcomes_jsonl) from bytes that are gzipped when they start
    /// with gzip's magic.
    pub fn from_outcomes_bytes(bytes: &[u8]) -> Result<ReferenceSet> {
        if bytes.starts_with(&[0x1f, 0x8b]) {
            let mut text = String::new();
            flate2::read::GzDecoder::new(bytes)
                .read_to_string(&mut text)
                .map_err(|e| bad("gzip".into(), e.to_string()))?;
            ReferenceSet::from_outcomes_jsonl(&text)
        } else {
            let text =
                std::str::from_utf8(bytes).map_err(|e| bad("utf-8".into(), e.to_string()))?;
            ReferenceSet::from_outcomes_jsonl(text)
        }
    }

    /// The pairs at frame rate `fps`.
    pub fn at_fps(&self, fps: f64) -> ReferenceSet {
        ReferenceSet {
            pairs: self
                .pairs
                .iter()
                .filter(|p| p.fps == fps)
                .cloned()
                .collect(),
        }
    }
}

/// How annotrace's outcomes compare with the original's.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Agreement {
    /// Pairs replayed.
    pub pairs: usize,
    /// Pairs whose success agrees.
    pub success_agree: usize,
    /// Pairs whose effective-elimination count agrees.
    pub eliminations_agree: usize,
    /// Pairs the original solved / annotrace solved.
    pub solved: (usize, usize),
    /// Pairs both solved (the original's successes reproduced).
    pub solved_both: usize,
    /// Per game: (pairs, success agreements).
    pub per_game: BTreeMap<String, (usize, usize)>,
    /// The pairs (by position) whose success disagrees.
    pub disagreements: Vec<usize>,
}

impl Agreement {
    /// Share of pairs whose success agrees (0 for an empty set).
    pub fn success_rate(&self) -> f64 {
        if self.pairs == 0 {
            0.0
        } else {
            self.success_agree as f64 / self.pairs as f64
        }
    }

    /// Share of the original's successes that annotrace also solves (1 when there are none).
    pub fn successes_reproduced(&self) -> f64 {
        if self.solved.0 == 0 {
            1.0
        } else {
            self.solved_both as f64 / self.solved.0 as f64
        }
    }

    /// Pairs neither solved (the original's failures reproduced).
    pub fn failed_both(&self) -> usize {
        self.success_agree - self.solved_both
    }
}

/// Replays every pair of `set` on `games` with `params` (its `fps` replaced by each pair's) and counts
/// agreements. Fails on a pair naming an unknown game or holding an invalid click.
pub fn agreement(set: &ReferenceSet, games: &Games, params: &PhysicsParams) -> Result<Agreement> {
    let mut a = Agreement::default();
    for (i, pair) in set.pairs.iter().enumerate() {
        let game = games.get(&pair.game)?;
        let clicks: Vec<Click> = pair
            .clicks
            .iter()
            .map(|&[x, y, t]| Click { x, y, t })
            .collect();
        let p = PhysicsParams {
            fps: pair.fps,
            ..params.clone()
        };
        let mut episode = Episode::new(game, &clicks, &p, false)?;
        while !episode.done() {
            episode.step();
        }
        let r = episode.finish();
        a.pairs += 1;
        let agree = r.success == pair.success;
        a.success_agree += usize::from(agree);
        a.eliminations_agree += usize::from(r.eliminations == pair.eliminations);
        a.solved.0 += usize::from(pair.success);
        a.solved.1 += usize::from(r.success);
        a.solved_both += usize::from(r.success && pair.success);
        let g = a.per_game.entry(pair.game.clone()).or_default();
        g.0 += 1;
        g.1 += usize::from(agree);
        if !agree {
            a.disagreements.push(i);
        }
    }
    Ok(a)
}
