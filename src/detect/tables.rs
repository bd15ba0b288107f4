//! The Arrow schemas and record batches of the tables the detector runtime fills: `detectors`,
//! `detector_calls` and `annotations` (documented in `docs/schema.md`), and reading annotations back
//! from a run ([`read_annotations`]). Writing them to the run is the `annotate` stage's job.

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
use crate::store::StoreError;
use crate::trace::Env;

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
            // The map is written as the `Value::Object` holding it would be, without a copy of it.
            Arc::new(StringArray::from_iter_values(rows.iter().map(|a| {
                serde_json::to_string(&a.parameters).unwrap_or_else(|_| "{}".into())
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

/// The trace of the first `annotations` row of `env` in the run, in file order (`None` when there is
/// none); only up to the first non-empty batch is read.
pub fn first_annotated_trace(
    run: &crate::store::RunDir,
    env: Env,
) -> Result<Option<String>, StoreError> {
    use arrow::array::{Array, AsArray};
    for f in run.table("annotations")?.files {
        if f.env != Some(env) {
            continue;
        }
        for b in crate::store::read_file(&f.path)? {
            if b.num_rows() == 0 {
                continue;
            }
            let ids = column(&f.path, &b, "trace_id")?;
            let ids = ids.as_string::<i32>();
            if ids.is_valid(0) {
                return Ok(Some(ids.value(0).to_string()));
            }
        }
    }
    Ok(None)
}

/// Reads the `annotations` rows of `env` in the run (of one trace when `trace` is given), in file order.
pub fn read_annotations(
    run: &crate::store::RunDir,
    env: Env,
    trace: Option<&str>,
) -> Result<Vec<Annotation>, StoreError> {
    if let Some(t) = trace {
        return read_annotations_of(run, env, &[t]);
    }
    let mut out = Vec::new();
    for f in run.table("annotations")?.files {
        if f.env != Some(env) {
            continue;
        }
        for b in crate::store::read_file(&f.path)? {
            decode_annotations(&f.path, &b, &mut out)?;
        }
    }
    Ok(out)
}

/// Per label, the top-level parameter keys of the `annotations` rows of `env` whose detector `keep`
/// accepts: what a reward program may filter each label's patterns by. Reads a file at a time and
/// keeps no row, so it costs the memory of one file whatever the run's size.
pub fn parameter_keys(
    run: &crate::store::RunDir,
    env: Env,
    keep: impl Fn(&str) -> bool,
) -> Result<std::collections::BTreeMap<String, std::collections::BTreeSet<String>>, StoreError> {
    use arrow::array::AsArray;
    let mut out: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> =
        Default::default();
    for f in run.table("annotations")?.files {
        if f.env != Some(env) {
            continue;
        }
        for b in crate::store::read_file(&f.path)? {
            let col = |n: &str| column(&f.path, &b, n);
            let (det, label, params) = (col("detector_id")?, col("label")?, col("parameters")?);
            let (det, label, params) = (
                det.as_string::<i32>(),
                label.as_string::<i32>(),
                params.as_string::<i32>(),
            );
            for i in 0..b.num_rows() {
                if !keep(det.value(i)) {
                    continue;
                }
                let keys = out.entry(label.value(i).to_string()).or_default();
                if let Ok(serde_json::Value::Object(m)) =
                    serde_json::from_str::<serde_json::Value>(params.value(i))
                {
                    keys.extend(m.into_iter().map(|(k, _)| k));
                }
            }
        }
    }
    Ok(out)
}

/// The annotations of the traces `wanted` (any order) of `env`, in file order. Only the row groups
/// whose `trace_id` statistics can hold one of them are read (an `annotate` stage writes a file per
/// trace file set, so a set's annotations come from its own file): a stage that works a set at a
/// time holds that set's annotations, not the run's.
pub fn read_annotations_of(
    run: &crate::store::RunDir,
    env: Env,
    wanted: &[&str],
) -> Result<Vec<Annotation>, StoreError> {
    let mut out = Vec::new();
    if wanted.is_empty() {
        return Ok(out);
    }
    // `rows_of` looks ids up by binary search.
    let mut wanted = wanted.to_vec();
    wanted.sort_unstable();
    for f in run.table("annotations")?.files {
        if f.env != Some(env) {
            continue;
        }
        for b in crate::store::rows_of(&f.path, &wanted)? {
            decode_annotations(&f.path, &b, &mut out)?;
        }
    }
    Ok(out)
}

/// Column `name` of a batch read from `path`, or an error naming both.
fn column(path: &std::path::Path, b: &RecordBatch, name: &str) -> Result<ArrayRef, StoreError> {
    b.column_by_name(name)
        .cloned()
        .ok_or_else(|| StoreError::Schema {
            path: path.to_path_buf(),
            message: format!("no column {name}"),
        })
}

/// Appends the rows of an `annotations` batch read from `path`.
fn decode_annotations(
    path: &std::path::Path,
    b: &RecordBatch,
    out: &mut Vec<Annotation>,
) -> Result<(), StoreError> {
    use arrow::array::{Array, AsArray};
    use arrow::datatypes::{Float64Type, Int32Type, Int64Type};
    let col = |n: &str| column(path, b, n);
    let (det, tr, label) = (col("detector_id")?, col("trace_id")?, col("label")?);
    let (det, tr, label) = (
        det.as_string::<i32>(),
        tr.as_string::<i32>(),
        label.as_string::<i32>(),
    );
    let (seq, s0, s1) = (col("seq")?, col("start_step")?, col("end_step")?);
    let seq = seq.as_primitive::<Int32Type>();
    let (s0, s1) = (
        s0.as_primitive::<Int64Type>(),
        s1.as_primitive::<Int64Type>(),
    );
    let (t0, t1) = (col("t_start")?, col("t_end")?);
    let (t0, t1) = (
        t0.as_primitive::<Float64Type>(),
        t1.as_primitive::<Float64Type>(),
    );
    let (objects, params) = (col("objects")?, col("parameters")?);
    let (objects, params) = (objects.as_list::<i32>(), params.as_string::<i32>());
    let (prov, meta, act) = (col("provenance")?, col("metadata")?, col("activation")?);
    let (prov, meta) = (prov.as_string::<i32>(), meta.as_string::<i32>());
    let act = act.as_primitive::<Float64Type>();
    let json = |a: &StringArray, i: usize| {
        (!a.is_null(i)).then(|| serde_json::from_str(a.value(i)).unwrap_or(serde_json::Value::Null))
    };
    for i in 0..b.num_rows() {
        let objs = objects.value(i);
        let objs = objs.as_string::<i32>();
        out.push(Annotation {
            detector_id: super::DetectorId(det.value(i).to_string()),
            trace_id: tr.value(i).to_string(),
            label: label.value(i).to_string(),
            seq: seq.value(i).max(0) as usize,
            start_step: s0.value(i),
            end_step: s1.value(i),
            t_start: if t0.is_null(i) { f64::NAN } else { t0.value(i) },
            t_end: if t1.is_null(i) { f64::NAN } else { t1.value(i) },
            objects: (0..objs.len()).map(|k| objs.value(k).to_string()).collect(),
            parameters: match serde_json::from_str(params.value(i)) {
                Ok(serde_json::Value::Object(m)) => m,
                _ => Default::default(),
            },
            provenance: json(prov, i),
            metadata: json(meta, i),
            activation: act.value(i),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `docs/schema.md` lists exactly the columns of each detector table, in order, plus `env`.
    #[test]
    fn docs_match_the_schemas() {
        for (table, schema) in [
            ("detectors", detectors_schema()),
            ("detector_calls", calls_schema()),
            ("annotations", annotations_schema()),
        ] {
            crate::testutil::assert_documented_columns(table, &schema);
        }
    }
}
