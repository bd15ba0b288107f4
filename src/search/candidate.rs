//! One row of the `candidates` table: every program a search produced, valid or not, with every fitness
//! term and what it cost. Records are also the search's checkpoint: replaying them rebuilds its state.

use std::sync::Arc;

use arrow::array::{ArrayRef, Float64Array, Int64Array, RecordBatch, StringArray, UInt64Array};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use arrow::error::ArrowError;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::fitness::FitnessTerms;

/// Hash of a program's source: the first 16 hex digits of its SHA-256.
pub fn code_hash(code: &str) -> String {
    crate::digest::hex(&Sha256::digest(code.as_bytes())[..8])
}

/// A candidate's status: `ok` (scored), `seed` (g₀, scored), `duplicate` (same code as an earlier
/// candidate), `same_behaviour` (same probe output as an earlier one), `degenerate` (ran, but active
/// nowhere or everywhere), `proposer` (the proposer gave no program), `budget_exhausted`, or a
/// detector error category (`syntax`, `runtime`, `timeout`, …).
pub type Status = String;

/// One candidate of one label's search.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CandidateRecord {
    /// The label searched for.
    pub label: String,
    /// Position of the label in the run's label list.
    pub label_index: u32,
    /// The run seed.
    pub seed: u64,
    /// The search strategy (`island`, `hill-climb`, `best-of-n`).
    pub strategy: String,
    /// The proposer's name.
    pub proposer: String,
    /// The island the parents came from (−1 for the seed program).
    pub island: i64,
    /// The search step (−1 for the seed program).
    pub step: i64,
    /// Code hashes of the parents, best first.
    pub parents: Vec<String>,
    /// Hash of the code.
    pub code_hash: String,
    /// The code (empty when the proposer gave none).
    pub code: String,
    /// See [`Status`].
    pub status: Status,
    /// The error message, for failed candidates.
    pub error: Option<String>,
    /// Line of the error, when known.
    pub error_line: Option<u32>,
    /// Whether a failure happened on the probe set.
    pub failed_on_probe: bool,
    /// Repair attempts made.
    pub repairs: u32,
    /// Fitness terms, for scored candidates (and copied for duplicates).
    pub terms: Option<FitnessTerms>,
    /// Lines of code.
    pub lines: u64,
    /// Mean wall time per training trace (s).
    pub mean_time_s: Option<f64>,
    /// Fraction of training traces with at least one pattern.
    pub activation_rate: Option<f64>,
    /// Behaviour signature on the probe set.
    pub signature: Option<String>,
    /// Prompt tokens.
    pub tokens_in: u64,
    /// Completion tokens.
    pub tokens_out: u64,
    /// Proposer calls.
    pub calls: u32,
    /// Wall time inside the proposer (s).
    pub propose_s: f64,
    /// Wall time evaluating (s).
    pub eval_s: f64,
}

impl CandidateRecord {
    /// Whether the candidate was scored (and may enter the database).
    pub fn scored(&self) -> bool {
        matches!(self.status.as_str(), "ok" | "seed") && self.terms.is_some()
    }

    /// Whether the candidate ran without error (the appendix A "executable" count).
    pub fn executable(&self) -> bool {
        matches!(
            self.status.as_str(),
            "ok" | "seed" | "duplicate" | "same_behaviour" | "degenerate"
        )
    }
}

/// The schema of the `candidates` table.
pub fn candidates_schema() -> SchemaRef {
    let f = |n: &str, t: DataType, null: bool| Field::new(n, t, null);
    Arc::new(Schema::new(vec![
        f("run_stage", DataType::Utf8, false),
        f("label", DataType::Utf8, false),
        f("label_index", DataType::Int64, false),
        f("seed", DataType::UInt64, false),
        f("strategy", DataType::Utf8, false),
        f("proposer", DataType::Utf8, false),
        f("island", DataType::Int64, false),
        f("step", DataType::Int64, false),
        f("budget", DataType::Int64, false),
        f("parents", DataType::Utf8, false),
        f("code_hash", DataType::Utf8, false),
        f("code", DataType::Utf8, false),
        f("status", DataType::Utf8, false),
        f("executable", DataType::Boolean, false),
        f("error", DataType::Utf8, true),
        f("error_line", DataType::Int64, true),
        f("failed_on_probe", DataType::Boolean, false),
        f("repairs", DataType::Int64, false),
        f("rho", DataType::Float64, true),
        f("eta", DataType::Float64, true),
        f("lambda", DataType::Float64, true),
        f("psi", DataType::Float64, true),
        f("nu", DataType::Float64, true),
        f("lines", DataType::Int64, false),
        f("mean_time_s", DataType::Float64, true),
        f("activation_rate", DataType::Float64, true),
        f("signature", DataType::Utf8, true),
        f("tokens_in", DataType::UInt64, false),
        f("tokens_out", DataType::UInt64, false),
        f("calls", DataType::Int64, false),
        f("propose_s", DataType::Float64, false),
        f("eval_s", DataType::Float64, false),
    ]))
}

/// The rows of `records`, produced by stage `stage` with `budget` steps per label.
pub fn candidates_batch(
    stage: &str,
    budget: u64,
    records: &[CandidateRecord],
) -> Result<RecordBatch, ArrowError> {
    let s = |f: &dyn Fn(&CandidateRecord) -> String| -> ArrayRef {
        Arc::new(StringArray::from(records.iter().map(f).collect::<Vec<_>>()))
    };
    let so = |f: &dyn Fn(&CandidateRecord) -> Option<String>| -> ArrayRef {
        Arc::new(StringArray::from(records.iter().map(f).collect::<Vec<_>>()))
    };
    let i = |f: &dyn Fn(&CandidateRecord) -> i64| -> ArrayRef {
        Arc::new(Int64Array::from(records.iter().map(f).collect::<Vec<_>>()))
    };
    let fo = |f: &dyn Fn(&CandidateRecord) -> Option<f64>| -> ArrayRef {
        Arc::new(Float64Array::from(
            records.iter().map(f).collect::<Vec<_>>(),
        ))
    };
    let u = |f: &dyn Fn(&CandidateRecord) -> u64| -> ArrayRef {
        Arc::new(UInt64Array::from(records.iter().map(f).collect::<Vec<_>>()))
    };
    let b = |f: &dyn Fn(&CandidateRecord) -> bool| -> ArrayRef {
        Arc::new(arrow::array::BooleanArray::from(
            records.iter().map(f).collect::<Vec<_>>(),
        ))
    };
    let term =
        |g: fn(&FitnessTerms) -> f64| fo(&move |r: &CandidateRecord| r.terms.as_ref().map(g));
    RecordBatch::try_new(
        candidates_schema(),
        vec![
            s(&|_| stage.to_string()),
            s(&|r| r.label.clone()),
            i(&|r| i64::from(r.label_index)),
            u(&|r| r.seed),
            s(&|r| r.strategy.clone()),
            s(&|r| r.proposer.clone()),
            i(&|r| r.island),
            i(&|r| r.step),
            i(&|_| budget as i64),
            s(&|r| r.parents.join(",")),
            s(&|r| r.code_hash.clone()),
            s(&|r| r.code.clone()),
            s(&|r| r.status.clone()),
            b(&|r| r.executable()),
            so(&|r| r.error.clone()),
            Arc::new(Int64Array::from(
                records
                    .iter()
                    .map(|r| r.error_line.map(i64::from))
                    .collect::<Vec<_>>(),
            )),
            b(&|r| r.failed_on_probe),
            i(&|r| i64::from(r.repairs)),
            term(|t| t.rho),
            term(|t| t.eta),
            term(|t| t.lambda),
            term(|t| t.psi),
            term(|t| t.nu),
            i(&|r| r.lines as i64),
            fo(&|r| r.mean_time_s),
            fo(&|r| r.activation_rate),
            so(&|r| r.signature.clone()),
            u(&|r| r.tokens_in),
            u(&|r| r.tokens_out),
            i(&|r| i64::from(r.calls)),
            fo(&|r| Some(r.propose_s)),
            fo(&|r| Some(r.eval_s)),
        ],
    )
}
