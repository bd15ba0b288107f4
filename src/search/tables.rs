//! The Arrow schemas and rows of the evolution tables besides `candidates`: `evolution_labels` (one row
//! per label searched: seed and best fitness, the d_p used, held-out ρ and the acceptance decision, time
//! inside and outside the proposer, the accuracy guard's F1), `evolution_histograms` (activation
//! histograms of each label's best program and of the sampled candidates), `evolution_samples` (the
//! candidates the convergence measurement ran on the held-out traces, with their held-out ρ) and
//! `evolution_convergence` (section 4.5's pairs).

use std::sync::Arc;

use arrow::array::{
    ArrayRef, BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray, UInt64Array,
};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use arrow::error::ArrowError;

use super::discover::{ConvergenceRow, LabelResult, SampleRow};
use super::run::SearchConfig;
use crate::fitness::{Dp, Dx};

/// The schema of `evolution_labels`.
pub fn labels_schema() -> SchemaRef {
    let f = |n: &str, t: DataType| Field::new(n, t, false);
    let fo = |n: &str, t: DataType| Field::new(n, t, true);
    Arc::new(Schema::new(vec![
        f("run_stage", DataType::Utf8),
        f("label", DataType::Utf8),
        f("label_index", DataType::Int64),
        f("seed", DataType::UInt64),
        f("strategy", DataType::Utf8),
        f("proposer", DataType::Utf8),
        f("budget", DataType::Int64),
        f("candidates", DataType::Int64),
        f("scored", DataType::Int64),
        f("seed_nu", DataType::Float64),
        f("best_nu", DataType::Float64),
        f("best_rho", DataType::Float64),
        f("best_eta", DataType::Float64),
        f("best_lambda", DataType::Float64),
        f("best_psi", DataType::Float64),
        f("best_code_hash", DataType::Utf8),
        f("best_lines", DataType::Int64),
        f("delta", DataType::Float64),
        f("accepted", DataType::Boolean),
        f("dp", DataType::Utf8),
        fo("holdout_rho", DataType::Float64),
        f("acceptance", DataType::Utf8),
        f("train_set_id", DataType::Utf8),
        fo("holdout_set_id", DataType::Utf8),
        f("wall_s", DataType::Float64),
        f("propose_s", DataType::Float64),
        fo("outside_proposer_share", DataType::Float64),
        f("dx", DataType::Utf8),
        fo("guard_seed_f1", DataType::Float64),
        fo("guard_best_f1", DataType::Float64),
    ]))
}

/// The `evolution_labels` row of one label.
pub fn labels_batch(
    stage: &str,
    config: &SearchConfig,
    sets: &SetIds,
    proposer: &str,
    index: u32,
    r: &LabelResult,
) -> Result<RecordBatch, ArrowError> {
    let dp = sets.dp;
    let o = &r.outcome;
    let t = &o.best.terms;
    let s = |v: &str| -> ArrayRef { Arc::new(StringArray::from(vec![v.to_string()])) };
    let i = |v: i64| -> ArrayRef { Arc::new(Int64Array::from(vec![v])) };
    let x = |v: f64| -> ArrayRef { Arc::new(Float64Array::from(vec![v])) };
    let share = (o.wall_s > 0.0).then(|| ((o.wall_s - o.propose_s) / o.wall_s).clamp(0.0, 1.0));
    RecordBatch::try_new(
        labels_schema(),
        vec![
            s(stage),
            s(&o.label),
            i(i64::from(index)),
            Arc::new(UInt64Array::from(vec![config.seed])),
            s(config.strategy.as_str()),
            s(proposer),
            i(config.budget as i64),
            i(o.records.iter().filter(|r| r.step >= 0).count() as i64),
            i(o.records
                .iter()
                .filter(|r| r.step >= 0 && r.scored())
                .count() as i64),
            x(o.seed_nu),
            x(t.nu),
            x(t.rho),
            x(t.eta),
            x(t.lambda),
            x(t.psi),
            s(&o.best.hash),
            i(o.best.lines as i64),
            x(config.delta),
            Arc::new(BooleanArray::from(vec![r.accepted])),
            s(dp.as_str()),
            Arc::new(Float64Array::from(vec![r.holdout_rho])),
            s(r.acceptance.as_str()),
            s(&sets.train),
            Arc::new(StringArray::from(vec![sets.holdout.clone()])),
            x(o.wall_s),
            x(o.propose_s),
            Arc::new(Float64Array::from(vec![share])),
            s(sets.dx.as_str()),
            Arc::new(Float64Array::from(vec![r.guard.map(|g| g.seed_f1)])),
            Arc::new(Float64Array::from(vec![r.guard.map(|g| g.best_f1)])),
        ],
    )
}

/// What ties a label's rows to the distance tables: the d_p used and the `trace_distances` set ids of
/// the training and held-out traces (in the order of their rows), with the traces' ids.
#[derive(Clone, Debug, PartialEq)]
pub struct SetIds {
    /// The annotation distance.
    pub dp: Dp,
    /// The trace distance.
    pub dx: Dx,
    /// `set_id` of the training traces' D_x.
    pub train: String,
    /// Training trace ids, in D_x order.
    pub train_ids: Vec<String>,
    /// `set_id` of the held-out traces' D_x (none without a held-out ρ).
    pub holdout: Option<String>,
    /// Held-out trace ids, in D_x order.
    pub holdout_ids: Vec<String>,
}

/// The schema of `evolution_histograms`: the best program of each label, its smoothed activation
/// histogram per trace and bin, on the training (`split = 'train'`) and held-out (`'holdout'`) traces,
/// and every candidate sampled for the convergence measurement on the held-out traces (`'sample'`,
/// one `code_hash` per candidate; written with at least `MIN_HOLDOUT` held-out traces).
pub fn histograms_schema() -> SchemaRef {
    let f = |n: &str, t: DataType| Field::new(n, t, false);
    Arc::new(Schema::new(vec![
        f("run_stage", DataType::Utf8),
        f("label", DataType::Utf8),
        f("code_hash", DataType::Utf8),
        f("split", DataType::Utf8),
        f("set_id", DataType::Utf8),
        f("trace_index", DataType::Int64),
        f("trace_id", DataType::Utf8),
        f("bin", DataType::Int64),
        f("value", DataType::Float64),
    ]))
}

/// The `evolution_histograms` rows of one label.
pub fn histograms_batch(
    stage: &str,
    sets: &SetIds,
    r: &LabelResult,
) -> Result<RecordBatch, ArrowError> {
    let o = &r.outcome;
    let (mut hash_col, mut split_col, mut set_col, mut index_col, mut id_col, mut bin_col) = (
        Vec::<&str>::new(),
        Vec::<&str>::new(),
        Vec::<&str>::new(),
        Vec::<i64>::new(),
        Vec::<&str>::new(),
        Vec::<i64>::new(),
    );
    let mut value_col = Vec::<f64>::new();
    let mut parts = vec![
        (
            o.best.hash.as_str(),
            "train",
            Some(sets.train.as_str()),
            &sets.train_ids,
            &r.train_hists,
        ),
        (
            o.best.hash.as_str(),
            "holdout",
            sets.holdout.as_deref(),
            &sets.holdout_ids,
            &r.holdout_hists,
        ),
    ];
    for sample in &r.samples {
        if sample.hists.len() == sets.holdout_ids.len() {
            parts.push((
                sample.code_hash.as_str(),
                "sample",
                sets.holdout.as_deref(),
                &sets.holdout_ids,
                &sample.hists,
            ));
        }
    }
    for (hash, split, set, ids, hists) in parts {
        let Some(set) = set else { continue };
        for (t, (id, h)) in ids.iter().zip(hists).enumerate() {
            for (b, v) in h.iter().enumerate() {
                hash_col.push(hash);
                split_col.push(split);
                set_col.push(set);
                index_col.push(t as i64);
                id_col.push(id.as_str());
                bin_col.push(b as i64);
                value_col.push(*v);
            }
        }
    }
    let n = split_col.len();
    RecordBatch::try_new(
        histograms_schema(),
        vec![
            Arc::new(StringArray::from(vec![stage; n])),
            Arc::new(StringArray::from(vec![o.label.as_str(); n])),
            Arc::new(StringArray::from(hash_col)),
            Arc::new(StringArray::from(split_col)),
            Arc::new(StringArray::from(set_col)),
            Arc::new(Int64Array::from(index_col)),
            Arc::new(StringArray::from(id_col)),
            Arc::new(Int64Array::from(bin_col)),
            Arc::new(Float64Array::from(value_col)),
        ],
    )
}

/// The schema of `evolution_samples`: one row per candidate the convergence measurement sampled.
pub fn samples_schema() -> SchemaRef {
    let f = |n: &str, t: DataType| Field::new(n, t, false);
    let fo = |n: &str, t: DataType| Field::new(n, t, true);
    Arc::new(Schema::new(vec![
        f("run_stage", DataType::Utf8),
        f("label", DataType::Utf8),
        f("bin", DataType::Int64),
        f("step", DataType::Int64),
        f("code_hash", DataType::Utf8),
        fo("nu", DataType::Float64),
        fo("rho", DataType::Float64),
        fo("holdout_rho", DataType::Float64),
        f("failed_traces", DataType::Int64),
        fo("holdout_set_id", DataType::Utf8),
    ]))
}

/// The `evolution_samples` rows of one label.
pub fn samples_batch(
    stage: &str,
    sets: &SetIds,
    rows: &[SampleRow],
) -> Result<RecordBatch, ArrowError> {
    let fin = |v: f64| v.is_finite().then_some(v);
    RecordBatch::try_new(
        samples_schema(),
        vec![
            Arc::new(StringArray::from(vec![stage; rows.len()])),
            Arc::new(StringArray::from(
                rows.iter().map(|r| r.label.as_str()).collect::<Vec<_>>(),
            )),
            Arc::new(Int64Array::from(
                rows.iter().map(|r| i64::from(r.bin)).collect::<Vec<_>>(),
            )),
            Arc::new(Int64Array::from(
                rows.iter().map(|r| r.step).collect::<Vec<_>>(),
            )),
            Arc::new(StringArray::from(
                rows.iter()
                    .map(|r| r.code_hash.as_str())
                    .collect::<Vec<_>>(),
            )),
            Arc::new(Float64Array::from(
                rows.iter().map(|r| fin(r.nu)).collect::<Vec<_>>(),
            )),
            Arc::new(Float64Array::from(
                rows.iter().map(|r| fin(r.rho)).collect::<Vec<_>>(),
            )),
            Arc::new(Float64Array::from(
                rows.iter()
                    .map(|r| r.holdout_rho.and_then(fin))
                    .collect::<Vec<_>>(),
            )),
            Arc::new(Int64Array::from(
                rows.iter()
                    .map(|r| r.failed_traces as i64)
                    .collect::<Vec<_>>(),
            )),
            Arc::new(StringArray::from(vec![sets.holdout.clone(); rows.len()])),
        ],
    )
}

/// The schema of `evolution_convergence`.
pub fn convergence_schema() -> SchemaRef {
    let f = |n: &str, t: DataType| Field::new(n, t, false);
    Arc::new(Schema::new(vec![
        f("run_stage", DataType::Utf8),
        f("label", DataType::Utf8),
        f("bin", DataType::Int64),
        f("code_hash", DataType::Utf8),
        f("final_hash", DataType::Utf8),
        f("similarity", DataType::Float64),
        f("traces", DataType::Int64),
    ]))
}

/// The `evolution_convergence` rows.
pub fn convergence_batch(stage: &str, rows: &[ConvergenceRow]) -> Result<RecordBatch, ArrowError> {
    RecordBatch::try_new(
        convergence_schema(),
        vec![
            Arc::new(StringArray::from(vec![stage.to_string(); rows.len()])),
            Arc::new(StringArray::from(
                rows.iter().map(|r| r.label.clone()).collect::<Vec<_>>(),
            )),
            Arc::new(Int64Array::from(
                rows.iter().map(|r| i64::from(r.bin)).collect::<Vec<_>>(),
            )),
            Arc::new(StringArray::from(
                rows.iter().map(|r| r.code_hash.clone()).collect::<Vec<_>>(),
            )),
            Arc::new(StringArray::from(
                rows.iter()
                    .map(|r| r.final_hash.clone())
                    .collect::<Vec<_>>(),
            )),
            Arc::new(Float64Array::from(
                rows.iter().map(|r| r.similarity).collect::<Vec<_>>(),
            )),
            Arc::new(Int64Array::from(
                rows.iter().map(|r| r.traces as i64).collect::<Vec<_>>(),
            )),
        ],
    )
}
