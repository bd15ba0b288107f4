//! Outcome agreement with the original PHYRE (phyre 0.2.2, Box2D) on balanced outcome sets: (task, action)
//! pairs with PHYRE's own `simulate_action` status, as `phyre_gen.py outcomes` writes them (JSON Lines,
//! optionally gzipped), replayed here and scored per original status.
//!
//! **Owns:** reading outcome sets ([`OutcomeSet`]), the replay and the status-by-status tally
//! ([`agreement`], [`Agreement`]).
//! **Does not:** run Python (the sets are made offline, docs/fidelity.md), print, or choose thresholds
//! (the tests and `examples/fidelity.rs` do).
//!
//! Random actions mostly fail in both simulators, which hides how many *solutions* survive the port; the
//! generator draws about 40 % solving, 45 % failing and 15 % invalid actions per template, and the tally
//! keeps the three apart.

use std::collections::BTreeMap;
use std::io::Read;

use serde::Deserialize;

use super::action::BallAction;
use super::episode::{self, Status};
use super::error::{PhyreError, Result};
use super::params::PhysicsParams;
use super::tasks::TaskSet;

/// One (task, action) pair with the original's status.
#[derive(Debug, Clone, PartialEq)]
pub struct OutcomePair {
    /// Task id (`00004:063`).
    pub task_id: String,
    /// The action in [0, 1]³.
    pub action: BallAction,
    /// PHYRE's status.
    pub status: Status,
    /// Steps PHYRE simulated (`None` for an invalid action).
    pub steps: Option<usize>,
}

#[derive(Deserialize)]
struct Line {
    task_id: String,
    action: [f64; 3],
    status: String,
    #[serde(default)]
    steps_simulated: Option<usize>,
}

/// An outcome set: the pairs in file order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OutcomeSet {
    /// The pairs.
    pub pairs: Vec<OutcomePair>,
}

fn bad(field: String, message: impl Into<String>) -> PhyreError {
    PhyreError::InvalidReference {
        field,
        message: message.into(),
    }
}

impl OutcomeSet {
    /// Parses `phyre_gen.py outcomes` JSON Lines (`task_id`, `action`, `status` as PHYRE's name,
    /// optional `steps_simulated`; other fields ignored). Blank lines are skipped.
    pub fn from_jsonl(text: &str) -> Result<OutcomeSet> {
        let mut pairs = Vec::new();
        for (n, line) in text.lines().enumerate() {
            if line.trim().is_empty() {
                continue;
            }
            let at = || format!("line {}", n + 1);
            let l: Line = serde_json::from_str(line).map_err(|e| bad(at(), e.to_string()))?;
            let status = match l.status.as_str() {
                "SOLVED" => Status::Solved,
                "NOT_SOLVED" => Status::NotSolved,
                "INVALID_INPUT" => Status::InvalidInput,
                other => {
                    return Err(bad(
                        format!("{} status", at()),
                        format!("{other:?} is not SOLVED, NOT_SOLVED or INVALID_INPUT"),
                    ));
                }
            };
            let action = BallAction {
                x: l.action[0],
                y: l.action[1],
                r: l.action[2],
            };
            action
                .validate()
                .map_err(|e| bad(format!("{} action", at()), e.to_string()))?;
            pairs.push(OutcomePair {
                task_id: l.task_id,
                action,
                status,
                steps: l.steps_simulated,
            });
        }
        Ok(OutcomeSet { pairs })
    }

    /// Like [`from_jsonl`](Self::from_jsonl), from bytes that are gzipped when they start with gzip's magic.
    pub fn from_bytes(bytes: &[u8]) -> Result<OutcomeSet> {
        if bytes.starts_with(&[0x1f, 0x8b]) {
            let mut text = String::new();
            flate2::read::GzDecoder::new(bytes)
                .read_to_string(&mut text)
                .map_err(|e| bad("gzip".into(), e.to_string()))?;
            OutcomeSet::from_jsonl(&text)
        } else {
            let text =
                std::str::from_utf8(bytes).map_err(|e| bad("utf-8".into(), e.to_string()))?;
            OutcomeSet::from_jsonl(text)
        }
    }
}

/// Index of a status in [`Agreement::by_status`]: SOLVED, NOT_SOLVED, INVALID_INPUT.
pub fn status_slot(s: Status) -> usize {
    match s {
        Status::Solved => 0,
        Status::NotSolved => 1,
        Status::InvalidInput => 2,
    }
}

/// How annotrace's statuses compare with the original's.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Agreement {
    /// `by_status[original][ours]`, slots as [`status_slot`].
    pub by_status: [[usize; 3]; 3],
    /// Per template: (pairs, agreements).
    pub per_template: BTreeMap<String, (usize, usize)>,
    /// Positions (in the set) of the pairs whose status differs.
    pub disagreements: Vec<usize>,
    /// annotrace's status for every pair, in set order.
    pub ours: Vec<Status>,
    /// Pairs both simulators solve (with the original's step count known).
    pub both_solved: usize,
    /// Of those, the pairs solved at the same physics step (the original's `steps_simulated` is the
    /// step count minus one): a trajectory-level check, since the step moves with any divergence.
    pub same_solving_step: usize,
}

impl Agreement {
    /// Pairs the original gave status `s`.
    pub fn original(&self, s: Status) -> usize {
        self.by_status[status_slot(s)].iter().sum()
    }

    /// Of the pairs the original gave status `s`, those annotrace gave the same.
    pub fn reproduced(&self, s: Status) -> usize {
        self.by_status[status_slot(s)][status_slot(s)]
    }

    /// All pairs.
    pub fn pairs(&self) -> usize {
        self.by_status.iter().flatten().sum()
    }

    /// Pairs with the same status.
    pub fn agree(&self) -> usize {
        (0..3).map(|i| self.by_status[i][i]).sum()
    }

    /// Share of pairs with the same status (0 for an empty set).
    pub fn rate(&self) -> f64 {
        self.agree() as f64 / self.pairs().max(1) as f64
    }

    /// Share of the original's `s` pairs reproduced (1 when there are none).
    pub fn reproduced_rate(&self, s: Status) -> f64 {
        let n = self.original(s);
        if n == 0 {
            1.0
        } else {
            self.reproduced(s) as f64 / n as f64
        }
    }
}

/// Replays every pair of `set` with `params` and tallies the statuses. Fails on an unknown task id.
pub fn agreement(set: &OutcomeSet, tasks: &TaskSet, params: &PhysicsParams) -> Result<Agreement> {
    let mut a = Agreement::default();
    for (i, pair) in set.pairs.iter().enumerate() {
        let task = tasks.get(&pair.task_id)?;
        let run = episode::run(
            &task,
            &pair.action,
            params,
            &episode::RecordOptions {
                stride: 0,
                record: false,
            },
        )?;
        let ours = run.status;
        if let (Status::Solved, Status::Solved, Some(steps)) = (pair.status, ours, pair.steps) {
            a.both_solved += 1;
            a.same_solving_step += usize::from(run.steps == steps + 1);
        }
        a.by_status[status_slot(pair.status)][status_slot(ours)] += 1;
        let same = ours == pair.status;
        let t = a
            .per_template
            .entry(pair.task_id.chars().take(5).collect())
            .or_default();
        t.0 += 1;
        t.1 += usize::from(same);
        if !same {
            a.disagreements.push(i);
        }
        a.ours.push(ours);
    }
    Ok(a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_parse_and_bad_lines_are_named() {
        let text = "{\"task_id\":\"00000:000\",\"action\":[0.35,0.6,0.2],\"status\":\"NOT_SOLVED\",\"steps_simulated\":1000}\n\n\
                    {\"task_id\":\"00000:000\",\"action\":[0.5,0.5,0.5],\"status\":\"INVALID_INPUT\",\"steps_simulated\":null}\n";
        let set = OutcomeSet::from_jsonl(text).unwrap();
        assert_eq!(set.pairs.len(), 2);
        assert_eq!(set.pairs[0].steps, Some(1000));
        assert_eq!(set.pairs[1].status, Status::InvalidInput);
        let e = OutcomeSet::from_jsonl("{\"task_id\":\"x\",\"action\":[0,0,0],\"status\":\"WON\"}")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 1") && e.contains("WON"), "{e}");
        let e = OutcomeSet::from_jsonl(
            "\n{\"task_id\":\"x\",\"action\":[2,0,0],\"status\":\"SOLVED\"}",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("line 2 action"), "{e}");
    }
}
