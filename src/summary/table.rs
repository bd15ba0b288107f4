//! The `summaries` table (one row per trace and summariser) and the `identification` table (one row
//! per trial), and the `suggested_labels` table (one row per suggested label), their Arrow schemas and
//! batches (`docs/schema.md`).

use std::sync::Arc;

use arrow::array::{BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use arrow::error::ArrowError;

use super::Summary;
use super::identify::Trial;

/// The summaries table's name.
pub const SUMMARIES: &str = "summaries";
/// The identification table's name.
pub const IDENTIFICATION: &str = "identification";

/// What every row of both tables says about its setting.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Setting {
    /// Library of the annotations (empty when the summariser reads none).
    pub library: String,
    /// Detectors that annotated.
    pub patterns: i64,
    /// Summariser name (`offline`, `frames`, `annotations`).
    pub summariser: String,
    /// The summariser's model (empty offline).
    pub model: String,
    /// The stage's seed.
    pub seed: i64,
}

/// One `summaries` row.
#[derive(Clone, Debug, PartialEq)]
pub struct SummaryRow {
    /// The trace.
    pub trace_id: String,
    /// The summary and its cost.
    pub summary: Summary,
}

fn field(n: &str, t: DataType, null: bool) -> Field {
    Field::new(n, t, null)
}

/// The Arrow schema of `summaries` (the `env` partition is added by the run folder).
pub fn summaries_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        field("trace_id", DataType::Utf8, false),
        field("library", DataType::Utf8, false),
        field("patterns", DataType::Int64, false),
        field("summariser", DataType::Utf8, false),
        field("model", DataType::Utf8, false),
        field("seed", DataType::Int64, false),
        field("text", DataType::Utf8, false),
        field("prompt_tokens", DataType::Int64, false),
        field("completion_tokens", DataType::Int64, false),
        field("usage_estimated", DataType::Boolean, false),
        field("images", DataType::Int64, false),
        field("seconds", DataType::Float64, false),
        field("call_id", DataType::Utf8, false),
    ]))
}

fn strings(n: usize, v: &str) -> Arc<StringArray> {
    Arc::new(StringArray::from_iter_values(std::iter::repeat_n(v, n)))
}

fn ints(n: usize, v: i64) -> Arc<Int64Array> {
    Arc::new(Int64Array::from_iter_values(std::iter::repeat_n(v, n)))
}

/// `rows` of `setting` as a `summaries` batch.
pub fn summaries_batch(setting: &Setting, rows: &[SummaryRow]) -> Result<RecordBatch, ArrowError> {
    let n = rows.len();
    let s =
        |f: fn(&SummaryRow) -> &str| Arc::new(StringArray::from_iter_values(rows.iter().map(f)));
    let i = |f: fn(&SummaryRow) -> u64| {
        Arc::new(Int64Array::from_iter_values(
            rows.iter().map(|r| f(r) as i64),
        ))
    };
    RecordBatch::try_new(
        summaries_schema(),
        vec![
            s(|r| &r.trace_id),
            strings(n, &setting.library),
            ints(n, setting.patterns),
            strings(n, &setting.summariser),
            strings(n, &setting.model),
            ints(n, setting.seed),
            s(|r| &r.summary.text),
            i(|r| r.summary.tokens_in),
            i(|r| r.summary.tokens_out),
            Arc::new(BooleanArray::from(
                rows.iter()
                    .map(|r| r.summary.usage_estimated)
                    .collect::<Vec<_>>(),
            )),
            i(|r| r.summary.images),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|r| r.summary.seconds),
            )),
            s(|r| &r.summary.call_id),
        ],
    )
}

/// The Arrow schema of `identification`.
pub fn identification_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        field("trace_id", DataType::Utf8, false),
        field("library", DataType::Utf8, false),
        field("patterns", DataType::Int64, false),
        field("summariser", DataType::Utf8, false),
        field("model", DataType::Utf8, false),
        field("seed", DataType::Int64, false),
        field("chooser", DataType::Utf8, false),
        field("chooser_model", DataType::Utf8, false),
        field("options", DataType::Int64, false),
        field("shown", DataType::Utf8, false),
        field("correct", DataType::Int64, false),
        field("chosen", DataType::Int64, true),
        field("success", DataType::Boolean, false),
        field("reason", DataType::Utf8, true),
        field("prompt_tokens", DataType::Int64, false),
        field("completion_tokens", DataType::Int64, false),
        field("seconds", DataType::Float64, false),
        field("call_id", DataType::Utf8, false),
    ]))
}

/// `trials` of `setting` with `chooser` (name, model) as an `identification` batch. Positions are
/// 1-based, as shown to the chooser; `shown` lists the trace ids shown, comma-separated.
pub fn identification_batch(
    setting: &Setting,
    chooser: (&str, &str),
    trials: &[Trial],
) -> Result<RecordBatch, ArrowError> {
    let n = trials.len();
    let s = |f: fn(&Trial) -> String| Arc::new(StringArray::from_iter_values(trials.iter().map(f)));
    let i = |f: fn(&Trial) -> i64| Arc::new(Int64Array::from_iter_values(trials.iter().map(f)));
    RecordBatch::try_new(
        identification_schema(),
        vec![
            s(|t| t.trace_id.clone()),
            strings(n, &setting.library),
            ints(n, setting.patterns),
            strings(n, &setting.summariser),
            strings(n, &setting.model),
            ints(n, setting.seed),
            strings(n, chooser.0),
            strings(n, chooser.1),
            i(|t| t.shown.len() as i64),
            s(|t| t.shown.join(",")),
            i(|t| t.correct as i64 + 1),
            Arc::new(Int64Array::from(
                trials
                    .iter()
                    .map(|t| t.chosen.map(|c| c as i64 + 1))
                    .collect::<Vec<_>>(),
            )),
            Arc::new(BooleanArray::from(
                trials.iter().map(Trial::success).collect::<Vec<_>>(),
            )),
            Arc::new(
                trials
                    .iter()
                    .map(|t| t.reason.as_deref())
                    .collect::<StringArray>(),
            ),
            i(|t| t.tokens_in as i64),
            i(|t| t.tokens_out as i64),
            Arc::new(Float64Array::from_iter_values(
                trials.iter().map(|t| t.seconds),
            )),
            s(|t| t.call_id.clone()),
        ],
    )
}

/// The suggested-labels table's name (one row per label of a `suggest-labels` stage).
pub const SUGGESTED_LABELS: &str = "suggested_labels";

/// What every row of a `suggested_labels` batch says about its suggestion.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LabelSetting {
    /// The stage that suggested them.
    pub run_stage: String,
    /// `llm` or `offline`.
    pub origin: String,
    /// The model (empty offline).
    pub model: String,
    /// Labels asked for.
    pub k: i64,
    /// The library whose annotations the examples showed.
    pub library: String,
    /// The example traces shown, in order.
    pub examples: Vec<String>,
    /// The calls' `llm_calls.request_hash`, in order.
    pub calls: Vec<String>,
    /// The problems of rejected answers.
    pub problems: Vec<String>,
    /// Prompt tokens of all calls.
    pub prompt_tokens: i64,
    /// Completion tokens of all calls.
    pub completion_tokens: i64,
    /// Model seconds of all calls.
    pub seconds: f64,
    /// The stage's seed.
    pub seed: i64,
}

/// The Arrow schema of `suggested_labels`.
pub fn suggested_labels_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        field("run_stage", DataType::Utf8, false),
        field("rank", DataType::Int64, false),
        field("label", DataType::Utf8, false),
        field("description", DataType::Utf8, false),
        field("objects", DataType::Utf8, false),
        field("reason", DataType::Utf8, false),
        field("source", DataType::Utf8, false),
        field("origin", DataType::Utf8, false),
        field("model", DataType::Utf8, false),
        field("k", DataType::Int64, false),
        field("library", DataType::Utf8, false),
        field("examples", DataType::Utf8, false),
        field("requests", DataType::Utf8, false),
        field("problems", DataType::Utf8, false),
        field("prompt_tokens", DataType::Int64, false),
        field("completion_tokens", DataType::Int64, false),
        field("seconds", DataType::Float64, false),
        field("seed", DataType::Int64, false),
    ]))
}

/// `labels` (rank 1, 2, … in order) as a `suggested_labels` batch.
pub fn suggested_labels_batch(
    s: &LabelSetting,
    labels: &[super::ProposedLabel],
) -> Result<RecordBatch, ArrowError> {
    let n = labels.len();
    let col = |f: fn(&super::ProposedLabel) -> String| {
        Arc::new(StringArray::from_iter_values(labels.iter().map(f)))
    };
    let list = |v: &[String]| serde_json::to_string(v).unwrap_or_default();
    RecordBatch::try_new(
        suggested_labels_schema(),
        vec![
            strings(n, &s.run_stage),
            Arc::new(Int64Array::from_iter_values(1..=n as i64)),
            col(|l| l.label.clone()),
            col(|l| l.description.clone()),
            col(|l| serde_json::to_string(&l.objects).unwrap_or_default()),
            col(|l| l.reason.clone()),
            col(|l| l.source.clone()),
            strings(n, &s.origin),
            strings(n, &s.model),
            ints(n, s.k),
            strings(n, &s.library),
            strings(n, &list(&s.examples)),
            strings(n, &list(&s.calls)),
            strings(n, &list(&s.problems)),
            ints(n, s.prompt_tokens),
            ints(n, s.completion_tokens),
            Arc::new(Float64Array::from_iter_values(std::iter::repeat_n(
                s.seconds, n,
            ))),
            ints(n, s.seed),
        ],
    )
}

/// The labels a `suggest-labels` stage wrote (its `run_stage` rows of `batches`), by rank.
pub fn suggested_labels_of(batches: &[RecordBatch], stage: &str) -> Vec<String> {
    use arrow::array::AsArray;
    let mut out: Vec<(i64, String)> = Vec::new();
    for b in batches {
        let (Some(st), Some(rank), Some(label)) = (
            b.column_by_name("run_stage"),
            b.column_by_name("rank"),
            b.column_by_name("label"),
        ) else {
            continue;
        };
        let (Some(st), Some(rank), Some(label)) = (
            st.as_string_opt::<i32>(),
            rank.as_primitive_opt::<arrow::datatypes::Int64Type>(),
            label.as_string_opt::<i32>(),
        ) else {
            continue;
        };
        for i in 0..b.num_rows() {
            if st.value(i) == stage {
                out.push((rank.value(i), label.value(i).to_string()));
            }
        }
    }
    out.sort();
    out.into_iter().map(|(_, l)| l).collect()
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_suggested_labels_columns_are_documented() {
        crate::testutil::assert_documented_columns(
            super::SUGGESTED_LABELS,
            &super::suggested_labels_schema(),
        );
    }
}
