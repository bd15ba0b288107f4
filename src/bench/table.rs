//! The `benchmark` table: one row per attempt (`docs/schema.md`), its Arrow schema and batches.

use std::sync::Arc;

use arrow::array::{BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};

use super::run::Row;

/// The table's name.
pub const TABLE: &str = "benchmark";

/// The Arrow schema of `benchmark` (the `env` partition is added by the run folder).
pub fn schema() -> SchemaRef {
    let f = |n: &str, t: DataType, null: bool| Field::new(n, t, null);
    Arc::new(Schema::new(vec![
        f("task", DataType::Utf8, false),
        f("seed", DataType::Int64, false),
        f("attempt", DataType::Int64, false),
        f("action", DataType::Utf8, false),
        f("valid", DataType::Boolean, false),
        f("reason", DataType::Utf8, true),
        f("success", DataType::Boolean, false),
        f("format", DataType::Utf8, false),
        f("feedback", DataType::Utf8, false),
        f("library", DataType::Utf8, false),
        f("patterns", DataType::Int64, false),
        f("agent", DataType::Utf8, false),
        f("model", DataType::Utf8, false),
        f("prompt_tokens", DataType::Int64, false),
        f("completion_tokens", DataType::Int64, false),
        f("seconds", DataType::Float64, false),
        f("simulations", DataType::Int64, false),
    ]))
}

/// `rows` as a batch.
pub fn batch(rows: &[Row]) -> Result<RecordBatch, arrow::error::ArrowError> {
    let s = |f: fn(&Row) -> &str| Arc::new(StringArray::from_iter_values(rows.iter().map(f)));
    let i = |f: fn(&Row) -> i64| Arc::new(Int64Array::from_iter_values(rows.iter().map(f)));
    RecordBatch::try_new(
        schema(),
        vec![
            s(|r| &r.task),
            i(|r| r.seed),
            i(|r| r.attempt),
            s(|r| &r.action),
            Arc::new(BooleanArray::from(
                rows.iter().map(|r| r.valid).collect::<Vec<_>>(),
            )),
            Arc::new(
                rows.iter()
                    .map(|r| r.reason.as_deref())
                    .collect::<StringArray>(),
            ),
            Arc::new(BooleanArray::from(
                rows.iter().map(|r| r.success).collect::<Vec<_>>(),
            )),
            s(|r| &r.format),
            s(|r| &r.feedback),
            s(|r| &r.library),
            i(|r| r.patterns),
            s(|r| &r.agent),
            s(|r| &r.model),
            i(|r| r.prompt_tokens),
            i(|r| r.completion_tokens),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|r| r.seconds),
            )),
            i(|r| r.simulations),
        ],
    )
}
