//! The Arrow schemas and record batches of the tables the detector runtime fills: `detectors`,
//! `detector_calls` and `annotations` (documented in `docs/schema.md`). Writing them to the run is the
//! `annotate` stage's job.

use std::sync::Arc;

use arrow::array::{
    ArrayRef, Float64Array, Int32Array, Int64Array, ListBuilder, RecordBatch, StringArray,
    StringBuilder,
};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use arrow::error::ArrowError;

use super::annotation::Annotation;
use super::detector::Detector;
use super::pool::CallResult;

fn utf8(name: &str, nullable: bool) -> Field {
    Field::new(name, DataType::Utf8, nullable)
}

/// The `detectors` table: one row per detector of a library.
pub fn detectors_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        utf8("detector_id", false),
        utf8("label", false),
        utf8("library", false),
        utf8("source", false),
        utf8("code", false),
        Field::new("lines", DataType::Int64, false),
        Field::new("weight", DataType::Float64, false),
        utf8("aliases", false),
    ]))
}

/// The `detector_calls` table: one row per detector × trace, with its status and timing.
pub fn calls_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        utf8("detector_id", false),
        utf8("trace_id", false),
        utf8("label", false),
        utf8("status", false),
        utf8("error", true),
        Field::new("error_line", DataType::Int32, true),
        Field::new("n_patterns", DataType::Int64, false),
        Field::new("wall_s", DataType::Float64, false),
        Field::new("cpu_s", DataType::Float64, false),
    ]))
}

/// The `annotations` table: one row per pattern found.
pub fn annotations_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        utf8("detector_id", false),
        utf8("trace_id", false),
        utf8("label", false),
        Field::new("seq", DataType::Int32, false),
        Field::new("start_step", DataType::Int64, false),
        Field::new("end_step", DataType::Int64, false),
        Field::new("t_start", DataType::Float64, true),
        Field::new("t_end", DataType::Float64, true),
        Field::new(
            "objects",
            DataType::List(Arc::new(Field::new("item", DataType::Utf8, true))),
            false,
        ),
        utf8("parameters", false),
        utf8("provenance", true),
        utf8("metadata", true),
        Field::new("activation", DataType::Float64, false),
    ]))
}

fn strings<'a>(it: impl Iterator<Item = &'a str>) -> ArrayRef {
    Arc::new(StringArray::from_iter_values(it))
}

/// The `detectors` rows of a library's detectors.
pub fn detectors_batch(library: &str, detectors: &[Detector]) -> Result<RecordBatch, ArrowError> {
    RecordBatch::try_new(
        detectors_schema(),
        vec![
            strings(detectors.iter().map(|d| d.id.as_str())),
            strings(detectors.iter().map(|d| d.label.as_str())),
            strings(detectors.iter().map(|_| library)),
            strings(detectors.iter().map(|d| d.source.as_str())),
            strings(detectors.iter().map(|d| d.code.as_str())),
            Arc::new(Int64Array::from_iter_values(
                detectors.iter().map(|d| d.lines() as i64),
            )),
            Arc::new(Float64Array::from_iter_values(
                detectors.iter().map(|d| d.weight),
            )),
            Arc::new(StringArray::from_iter_values(
                detectors
                    .iter()
                    .map(|d| serde_json::to_string(&d.aliases).unwrap_or_default()),
            )),
        ],
    )
}

/// The `detector_calls` rows of a batch's results (`trace_ids[r.trace]` names each trace).
pub fn calls_batch(
    detectors: &[Detector],
    trace_ids: &[&str],
    results: &[CallResult],
) -> Result<RecordBatch, ArrowError> {
    let err: Vec<Option<String>> = results
        .iter()
        .map(|r| {
            r.status
                .error()
                .map(|e| serde_json::to_string(e).unwrap_or_default())
        })
        .collect();
    RecordBatch::try_new(
        calls_schema(),
        vec![
            strings(results.iter().map(|r| detectors[r.detector].id.as_str())),
            strings(results.iter().map(|r| trace_ids[r.trace])),
            strings(results.iter().map(|r| detectors[r.detector].label.as_str())),
            strings(results.iter().map(|r| r.status.as_str())),
            Arc::new(StringArray::from(err)),
            Arc::new(Int32Array::from_iter(results.iter().map(|r| {
                r.status.error().and_then(|e| e.line()).map(|l| l as i32)
            }))),
            Arc::new(Int64Array::from_iter_values(
                results.iter().map(|r| r.patterns.len() as i64),
            )),
            Arc::new(Float64Array::from_iter_values(
                results.iter().map(|r| r.wall_s),
            )),
            Arc::new(Float64Array::from_iter_values(
                results.iter().map(|r| r.cpu_s),
            )),
        ],
    )
}

/// The `annotations` rows.
pub fn annotations_batch(rows: &[Annotation]) -> Result<RecordBatch, ArrowError> {
    let mut objects = ListBuilder::new(StringBuilder::new());
    for a in rows {
        for o in &a.objects {
            objects.values().append_value(o);
        }
        objects.append(true);
    }
    let json_opt = |v: &Option<serde_json::Value>| v.as_ref().map(|v| v.to_string());
    let finite = |x: f64| x.is_finite().then_some(x);
    RecordBatch::try_new(
        annotations_schema(),
        vec![
            strings(rows.iter().map(|a| a.detector_id.as_str())),
            strings(rows.iter().map(|a| a.trace_id.as_str())),
            strings(rows.iter().map(|a| a.label.as_str())),
            Arc::new(Int32Array::from_iter_values(
                rows.iter().map(|a| a.seq as i32),
            )),
            Arc::new(Int64Array::from_iter_values(
                rows.iter().map(|a| a.start_step),
            )),
            Arc::new(Int64Array::from_iter_values(
                rows.iter().map(|a| a.end_step),
            )),
            Arc::new(Float64Array::from_iter(
                rows.iter().map(|a| finite(a.t_start)),
            )),
            Arc::new(Float64Array::from_iter(
                rows.iter().map(|a| finite(a.t_end)),
            )),
            Arc::new(objects.finish()),
            Arc::new(StringArray::from_iter_values(rows.iter().map(|a| {
                serde_json::Value::Object(a.parameters.clone()).to_string()
            }))),
            Arc::new(StringArray::from(
                rows.iter()
                    .map(|a| json_opt(&a.provenance))
                    .collect::<Vec<_>>(),
            )),
            Arc::new(StringArray::from(
                rows.iter()
                    .map(|a| json_opt(&a.metadata))
                    .collect::<Vec<_>>(),
            )),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|a| a.activation),
            )),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `docs/schema.md` lists exactly the columns of each detector table, in order, plus `env`.
    #[test]
    fn docs_match_the_schemas() {
        let doc = include_str!("../../docs/schema.md");
        for (table, schema) in [
            ("detectors", detectors_schema()),
            ("detector_calls", calls_schema()),
            ("annotations", annotations_schema()),
        ] {
            let section = doc
                .split(&format!("\n## {table}\n"))
                .nth(1)
                .unwrap_or_else(|| panic!("docs/schema.md has no section {table}"));
            let section = section.split("\n## ").next().unwrap_or_default();
            let documented: Vec<&str> = section
                .lines()
                .filter(|l| l.starts_with("| `"))
                .filter_map(|l| l.split('`').nth(1))
                .collect();
            let mut expected: Vec<String> =
                schema.fields().iter().map(|f| f.name().clone()).collect();
            expected.push("env".into());
            assert_eq!(documented, expected, "section {table}");
        }
    }
}
