//! The Arrow schemas and rows of the ensemble tables: `ensemble_members` (every pooled candidate with its
//! cluster), `ensemble_clusters` (one row per cluster with its representative), `ensemble_calibration`
//! (every point the sweep and the Bayesian optimisation evaluated) and `ensemble_evaluation` (held-out ρ
//! per label of the ensemble, the single-program ablation, the baseline library and each run's own best
//! program). Columns are documented in `docs/schema.md`.

use std::sync::Arc;

use arrow::array::{ArrayRef, BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use arrow::error::ArrowError;

use super::calibrate::CalibrationRow;

fn schema(fields: &[(&str, DataType, bool)]) -> SchemaRef {
    Arc::new(Schema::new(
        fields
            .iter()
            .map(|(n, t, null)| Field::new(*n, t.clone(), *null))
            .collect::<Vec<_>>(),
    ))
}

fn s(v: Vec<String>) -> ArrayRef {
    Arc::new(StringArray::from(v))
}
fn i(v: Vec<i64>) -> ArrayRef {
    Arc::new(Int64Array::from(v))
}
fn x(v: Vec<f64>) -> ArrayRef {
    Arc::new(Float64Array::from(v))
}
fn xo(v: Vec<Option<f64>>) -> ArrayRef {
    Arc::new(Float64Array::from(v))
}
fn b(v: Vec<bool>) -> ArrayRef {
    Arc::new(BooleanArray::from(v))
}

/// One `ensemble_members` row.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MemberRow {
    /// The label.
    pub label: String,
    /// Where the candidate came from (stage, or run folder / stage).
    pub source: String,
    /// Its code hash.
    pub code_hash: String,
    /// Its cluster.
    pub cluster: u32,
    /// Training ν.
    pub nu: f64,
    /// Training ρ.
    pub rho: f64,
    /// Lines of code.
    pub lines: i64,
    /// Whether it represents its cluster.
    pub representative: bool,
    /// Euclidean distance of its signature to its cluster's mean signature.
    pub distance: f64,
}

/// The schema of `ensemble_members`.
pub fn members_schema() -> SchemaRef {
    schema(&[
        ("run_stage", DataType::Utf8, false),
        ("label", DataType::Utf8, false),
        ("source", DataType::Utf8, false),
        ("code_hash", DataType::Utf8, false),
        ("cluster_index", DataType::Int64, false),
        ("nu", DataType::Float64, false),
        ("rho", DataType::Float64, true),
        ("lines", DataType::Int64, false),
        ("representative", DataType::Boolean, false),
        ("distance", DataType::Float64, false),
    ])
}

/// The `ensemble_members` rows.
pub fn members_batch(stage: &str, rows: &[MemberRow]) -> Result<RecordBatch, ArrowError> {
    RecordBatch::try_new(
        members_schema(),
        vec![
            s(vec![stage.to_string(); rows.len()]),
            s(rows.iter().map(|r| r.label.clone()).collect()),
            s(rows.iter().map(|r| r.source.clone()).collect()),
            s(rows.iter().map(|r| r.code_hash.clone()).collect()),
            i(rows.iter().map(|r| i64::from(r.cluster)).collect()),
            x(rows.iter().map(|r| r.nu).collect()),
            xo(rows
                .iter()
                .map(|r| r.rho.is_finite().then_some(r.rho))
                .collect()),
            i(rows.iter().map(|r| r.lines).collect()),
            b(rows.iter().map(|r| r.representative).collect()),
            x(rows.iter().map(|r| r.distance).collect()),
        ],
    )
}

/// One `ensemble_clusters` row.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClusterRow {
    /// The label.
    pub label: String,
    /// Cluster number.
    pub cluster: u32,
    /// K of the label.
    pub k: u32,
    /// How K was chosen (`silhouette`, `weak-structure`, `too-few`, `fixed`).
    pub k_rule: String,
    /// Mean silhouette of the label's clustering (none for K = 1).
    pub silhouette: Option<f64>,
    /// Candidates in the cluster.
    pub size: u32,
    /// The representative's code hash.
    pub representative: String,
    /// Where the representative came from.
    pub source: String,
    /// The representative's ν.
    pub nu: f64,
    /// The representative's lines of code.
    pub lines: i64,
}

/// The schema of `ensemble_clusters`.
pub fn clusters_schema() -> SchemaRef {
    schema(&[
        ("run_stage", DataType::Utf8, false),
        ("label", DataType::Utf8, false),
        ("cluster_index", DataType::Int64, false),
        ("k", DataType::Int64, false),
        ("k_rule", DataType::Utf8, false),
        ("silhouette", DataType::Float64, true),
        ("size", DataType::Int64, false),
        ("representative", DataType::Utf8, false),
        ("source", DataType::Utf8, false),
        ("nu", DataType::Float64, false),
        ("lines", DataType::Int64, false),
    ])
}

/// The `ensemble_clusters` rows.
pub fn clusters_batch(stage: &str, rows: &[ClusterRow]) -> Result<RecordBatch, ArrowError> {
    RecordBatch::try_new(
        clusters_schema(),
        vec![
            s(vec![stage.to_string(); rows.len()]),
            s(rows.iter().map(|r| r.label.clone()).collect()),
            i(rows.iter().map(|r| i64::from(r.cluster)).collect()),
            i(rows.iter().map(|r| i64::from(r.k)).collect()),
            s(rows.iter().map(|r| r.k_rule.clone()).collect()),
            xo(rows.iter().map(|r| r.silhouette).collect()),
            i(rows.iter().map(|r| i64::from(r.size)).collect()),
            s(rows.iter().map(|r| r.representative.clone()).collect()),
            s(rows.iter().map(|r| r.source.clone()).collect()),
            x(rows.iter().map(|r| r.nu).collect()),
            i(rows.iter().map(|r| r.lines).collect()),
        ],
    )
}

/// The schema of `ensemble_calibration`.
pub fn calibration_schema() -> SchemaRef {
    schema(&[
        ("run_stage", DataType::Utf8, false),
        ("method", DataType::Utf8, false),
        ("objective", DataType::Utf8, false),
        ("label", DataType::Utf8, false),
        ("iteration", DataType::Int64, false),
        ("gamma", DataType::Float64, false),
        ("eps_s", DataType::Float64, false),
        ("eps_t", DataType::Float64, false),
        ("weights", DataType::Utf8, false),
        ("score", DataType::Float64, false),
        ("chosen", DataType::Boolean, false),
    ])
}

/// The `ensemble_calibration` rows; `objective` names what `bo` rows scored (`sweep` rows score ρ).
pub fn calibration_batch(
    stage: &str,
    objective: &str,
    rows: &[CalibrationRow],
) -> Result<RecordBatch, ArrowError> {
    RecordBatch::try_new(
        calibration_schema(),
        vec![
            s(vec![stage.to_string(); rows.len()]),
            s(rows.iter().map(|r| r.method.clone()).collect()),
            s(rows
                .iter()
                .map(|r| {
                    if r.method == "sweep" {
                        "heldout-rho".to_string()
                    } else {
                        objective.to_string()
                    }
                })
                .collect()),
            s(rows.iter().map(|r| r.label.clone()).collect()),
            i(rows.iter().map(|r| i64::from(r.iteration)).collect()),
            x(rows.iter().map(|r| r.gamma).collect()),
            x(rows.iter().map(|r| r.eps_s).collect()),
            x(rows.iter().map(|r| r.eps_t).collect()),
            s(rows
                .iter()
                .map(|r| serde_json::to_string(&r.weights).unwrap_or_default())
                .collect()),
            x(rows.iter().map(|r| r.score).collect()),
            b(rows.iter().map(|r| r.chosen).collect()),
        ],
    )
}

/// One `ensemble_evaluation` row: a library variant's ρ for a label on the test traces.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EvaluationRow {
    /// `ensemble`, `sp`, `baseline` or `run` (one run's own best program).
    pub variant: String,
    /// For `run`: which run (stage); else empty.
    pub source: String,
    /// The label.
    pub label: String,
    /// Test traces.
    pub traces: u32,
    /// ρ of the label's annotations against D_x on the test traces.
    pub rho: f64,
    /// Fraction of test traces where the label fired at least once.
    pub activation_rate: f64,
    /// F1 against the simulator's event log (`detect::accuracy`), for event-grounded labels on
    /// scorable traces.
    pub f1: Option<f64>,
}

/// The schema of `ensemble_evaluation`.
pub fn evaluation_schema() -> SchemaRef {
    schema(&[
        ("run_stage", DataType::Utf8, false),
        ("variant", DataType::Utf8, false),
        ("source", DataType::Utf8, false),
        ("label", DataType::Utf8, false),
        ("traces", DataType::Int64, false),
        ("rho", DataType::Float64, false),
        ("activation_rate", DataType::Float64, false),
        ("f1", DataType::Float64, true),
    ])
}

/// The `ensemble_evaluation` rows.
pub fn evaluation_batch(stage: &str, rows: &[EvaluationRow]) -> Result<RecordBatch, ArrowError> {
    RecordBatch::try_new(
        evaluation_schema(),
        vec![
            s(vec![stage.to_string(); rows.len()]),
            s(rows.iter().map(|r| r.variant.clone()).collect()),
            s(rows.iter().map(|r| r.source.clone()).collect()),
            s(rows.iter().map(|r| r.label.clone()).collect()),
            i(rows.iter().map(|r| i64::from(r.traces)).collect()),
            x(rows.iter().map(|r| r.rho).collect()),
            x(rows.iter().map(|r| r.activation_rate).collect()),
            xo(rows.iter().map(|r| r.f1).collect()),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn docs_match_the_schemas() {
        for (table, schema) in [
            ("ensemble_members", members_schema()),
            ("ensemble_clusters", clusters_schema()),
            ("ensemble_calibration", calibration_schema()),
            ("ensemble_evaluation", evaluation_schema()),
        ] {
            crate::testutil::assert_documented_columns(table, &schema);
        }
    }
}
