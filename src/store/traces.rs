//! Reading whole traces back out of a run's tables by id (for export, `show`, `render`, and for the
//! stages that work on a chosen sample of traces: `summarise`, `suggest-labels`, `plot`).
//!
//! A trace's row in `traces` gives its environment partition; its `timesteps`, `frames` and `events`
//! rows are then read from that partition only, skipping row groups whose `trace_id` statistics
//! exclude every trace asked for, and sorted into table order before [`decode_trace`] rebuilds each
//! trace. [`read_traces`] does this for many traces together, reading each row group once.
//!
//! **Does not:** read every trace of a run (the stages that do read a shard's file set at a time:
//! `pipeline::stages::trace_files`).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fs::File;
use std::path::Path;

use arrow::array::{Array, ArrayRef, BooleanArray, RecordBatch, StringArray, UInt32Array};
use arrow::compute::{
    SortColumn, cast, concat_batches, filter_record_batch, lexsort_to_indices, take_record_batch,
};
use arrow::datatypes::{DataType, SchemaRef};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::file::statistics::Statistics;

use super::{RunDir, StoreError};
use crate::trace::batch::DecodeError;
use crate::trace::schema::table_schema;
use crate::trace::{Env, Trace, TraceRows, decode_trace};

/// A trace could not be read from a run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReadTraceError {
    /// No trace has this id.
    #[error(
        "no trace {trace_id:?} in run {run} (it holds {count} trace(s); list them with: annotrace query \"SELECT trace_id FROM traces\" --run {run})"
    )]
    NotFound {
        /// The id asked for.
        trace_id: String,
        /// The run folder.
        run: String,
        /// How many traces the run has.
        count: usize,
    },
    /// The files could not be read.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The rows do not form a valid trace.
    #[error(transparent)]
    Decode(#[from] DecodeError),
}

fn arrow_err(path: &Path, e: arrow::error::ArrowError) -> StoreError {
    StoreError::Parquet {
        path: path.to_path_buf(),
        source: parquet::errors::ParquetError::from(e),
    }
}

/// Traces whose rows one pass over the files gathers before they are decoded: bounds the Arrow rows
/// held at once (a 9-ball shot at dt 0.01 is about 5,600 frame rows) while each file is still opened
/// once per 64 traces instead of once per trace.
const CHUNK: usize = 64;

/// `ids` as a plain string array (the trace tables store them dictionary-encoded).
fn plain_ids(file: &Path, batch: &RecordBatch) -> Result<StringArray, StoreError> {
    let ids = batch.column_by_name("trace_id").ok_or_else(|| {
        arrow_err(
            file,
            arrow::error::ArrowError::SchemaError("no trace_id column".into()),
        )
    })?;
    let ids = if matches!(ids.data_type(), DataType::Utf8) {
        ids.clone()
    } else {
        cast(ids, &DataType::Utf8).map_err(|e| arrow_err(file, e))?
    };
    ids.as_any()
        .downcast_ref::<StringArray>()
        .cloned()
        .ok_or_else(|| {
            arrow_err(
                file,
                arrow::error::ArrowError::SchemaError("trace_id is not a string column".into()),
            )
        })
}

/// Whether the sorted `wanted` holds an id in `lo..=hi`.
fn any_within(wanted: &[&str], lo: &[u8], hi: &[u8]) -> bool {
    let at = wanted.partition_point(|w| w.as_bytes() < lo);
    wanted.get(at).is_some_and(|w| w.as_bytes() <= hi)
}

/// The rows of `file` whose `trace_id` is one of `wanted` (sorted), reading only the row groups
/// whose `trace_id` statistics can hold one of them, each once. Any table with a `trace_id` column
/// (the trace tables, `annotations`) reads this way.
pub(crate) fn rows_of(file: &Path, wanted: &[&str]) -> Result<Vec<RecordBatch>, StoreError> {
    let f = File::open(file).map_err(|e| StoreError::io(file, e))?;
    let builder =
        ParquetRecordBatchReaderBuilder::try_new(f).map_err(|e| StoreError::parquet(file, e))?;
    let meta = builder.metadata().clone();
    let col = meta
        .file_metadata()
        .schema_descr()
        .columns()
        .iter()
        .position(|c| c.name() == "trace_id");
    let groups: Vec<usize> = (0..meta.num_row_groups())
        .filter(|&g| {
            let Some(c) = col else { return true };
            match meta.row_group(g).column(c).statistics() {
                Some(Statistics::ByteArray(s)) => match (s.min_bytes_opt(), s.max_bytes_opt()) {
                    (Some(lo), Some(hi)) => any_within(wanted, lo, hi),
                    _ => true,
                },
                _ => true,
            }
        })
        .collect();
    if groups.is_empty() {
        return Ok(Vec::new());
    }
    let reader = builder
        .with_row_groups(groups)
        .build()
        .map_err(|e| StoreError::parquet(file, e))?;
    let mut out = Vec::new();
    for batch in reader {
        let batch = batch.map_err(|e| arrow_err(file, e))?;
        let ids = plain_ids(file, &batch)?;
        // A trace's rows come in runs: look an id up only where it changes.
        let mut last: Option<(&str, bool)> = None;
        let mask: BooleanArray = (0..ids.len())
            .map(|i| {
                if ids.is_null(i) {
                    return Some(false);
                }
                let id = ids.value(i);
                Some(match last {
                    Some((l, keep)) if l == id => keep,
                    _ => {
                        let keep = wanted.binary_search(&id).is_ok();
                        last = Some((id, keep));
                        keep
                    }
                })
            })
            .collect();
        match mask.true_count() {
            0 => {}
            n if n == batch.num_rows() => out.push(batch),
            _ => out.push(filter_record_batch(&batch, &mask).map_err(|e| arrow_err(file, e))?),
        }
    }
    Ok(out)
}

/// The rows of each trace of `wanted` (sorted) in one table partition, each trace's sorted by
/// `sort_by` (a trace with no rows is absent).
fn table_rows(
    run: &RunDir,
    table: &str,
    env: Env,
    wanted: &[&str],
    sort_by: &[&str],
) -> Result<HashMap<String, RecordBatch>, StoreError> {
    let schema: SchemaRef = table_schema(table).expect("trace table");
    let mut batches = Vec::new();
    for f in run
        .table(table)?
        .files
        .iter()
        .filter(|f| f.env == Some(env))
    {
        batches.extend(rows_of(&f.path, wanted)?);
    }
    let dir = run.partition_dir(table, Some(env));
    let all = concat_batches(&schema, &batches).map_err(|e| arrow_err(&dir, e))?;
    drop(batches);
    by_trace(&dir, &all, sort_by)
}

/// `all`'s rows split by trace, each trace's sorted by `sort_by` (rows already in order, as a stage
/// writes them, are sliced without a copy; `dir` names the partition in errors).
fn by_trace(
    dir: &Path,
    all: &RecordBatch,
    sort_by: &[&str],
) -> Result<HashMap<String, RecordBatch>, StoreError> {
    let ids = plain_ids(dir, all)?;
    // Each trace's runs of rows (start, length), in file order: one run when a stage wrote it.
    let mut runs: HashMap<&str, Vec<(usize, usize)>> = HashMap::new();
    let mut start = 0;
    for i in 1..=ids.len() {
        if i == ids.len() || ids.value(i) != ids.value(start) {
            runs.entry(ids.value(start))
                .or_default()
                .push((start, i - start));
            start = i;
        }
    }
    let mut out = HashMap::with_capacity(runs.len());
    for (id, runs) in runs {
        let mine = if let [(start, len)] = runs[..] {
            all.slice(start, len)
        } else {
            let idx = runs
                .iter()
                .flat_map(|&(s, n)| s..s + n)
                .map(u32::try_from)
                .collect::<Result<UInt32Array, _>>()
                .map_err(|_| {
                    arrow_err(
                        dir,
                        arrow::error::ArrowError::ComputeError("over 2^32 rows".into()),
                    )
                })?;
            take_record_batch(all, &idx).map_err(|e| arrow_err(dir, e))?
        };
        let keys: Vec<&ArrayRef> = sort_by
            .iter()
            .map(|c| mine.column_by_name(c).expect("sort columns exist"))
            .collect();
        let sorted = if mine.num_rows() < 2 || rows_ordered(&keys) == Some(true) {
            mine
        } else {
            let columns: Vec<SortColumn> = keys
                .iter()
                .map(|k| SortColumn {
                    values: (*k).clone(),
                    options: None,
                })
                .collect();
            let order = lexsort_to_indices(&columns, None).map_err(|e| arrow_err(dir, e))?;
            take_record_batch(&mine, &order).map_err(|e| arrow_err(dir, e))?
        };
        out.insert(id.to_string(), sorted);
    }
    Ok(out)
}

/// Whether rows are in non-decreasing order of the integer `keys` (compared in turn), with no nulls:
/// `Some(true)` or `Some(false)`, or `None` when a key is not a 32- or 64-bit integer column without
/// nulls (the caller then sorts). Rows a stage wrote for one trace are in order already.
fn rows_ordered(keys: &[&ArrayRef]) -> Option<bool> {
    let order = key_order(keys)?;
    let n = keys.first().map_or(0, |k| k.len());
    Some((1..n).all(|i| order(i - 1, i) != std::cmp::Ordering::Greater))
}

/// The order of two rows by the integer `keys`, compared in turn; `None` when a key is not a 32- or
/// 64-bit integer column without nulls.
pub(crate) fn key_order<'a>(
    keys: &[&'a ArrayRef],
) -> Option<impl Fn(usize, usize) -> std::cmp::Ordering + 'a> {
    use arrow::array::{AsArray, Int32Array, Int64Array};
    /// A sort key's values.
    enum Key<'a> {
        I64(&'a Int64Array),
        I32(&'a Int32Array),
    }
    let keys: Vec<Key<'a>> = keys
        .iter()
        .map(|k| {
            if k.null_count() > 0 {
                return None;
            }
            match k.data_type() {
                DataType::Int64 => Some(Key::I64(k.as_primitive())),
                DataType::Int32 => Some(Key::I32(k.as_primitive())),
                _ => None,
            }
        })
        .collect::<Option<_>>()?;
    Some(move |a: usize, b: usize| {
        for k in &keys {
            let o = match k {
                Key::I64(x) => x.value(a).cmp(&x.value(b)),
                Key::I32(x) => x.value(a).cmp(&x.value(b)),
            };
            if o != std::cmp::Ordering::Equal {
                return o;
            }
        }
        std::cmp::Ordering::Equal
    })
}

/// Reads trace `trace_id` from the run's tables.
pub fn read_trace(run: &RunDir, trace_id: &str) -> Result<Trace, ReadTraceError> {
    let mut traces = read_traces(run, &[trace_id])?;
    Ok(traces.pop().expect("one trace per id"))
}

/// Reads the traces `ids` from the run's tables, in that order (an id given twice is read once and
/// given twice). The `traces` files are read once; the other tables' files once per 64 distinct
/// traces of an environment, each row group that can hold one of them once, where a trace read at a
/// time would open every file of the partition and scan its row groups again.
pub fn read_traces<S: AsRef<str>>(run: &RunDir, ids: &[S]) -> Result<Vec<Trace>, ReadTraceError> {
    let wanted: HashSet<&str> = ids.iter().map(AsRef::as_ref).collect();
    // Each wanted trace's environment and `traces` row (the first, if an id were in two partitions).
    let mut count = 0usize;
    let mut rows: HashMap<String, (Env, RecordBatch)> = HashMap::new();
    for f in run.table("traces")?.files {
        let Some(env) = f.env else { continue };
        for b in super::read_file(&f.path)? {
            count += b.num_rows();
            let ids = plain_ids(&f.path, &b)?;
            for i in 0..ids.len() {
                if ids.is_valid(i)
                    && wanted.contains(ids.value(i))
                    && !rows.contains_key(ids.value(i))
                {
                    rows.insert(ids.value(i).to_string(), (env, b.slice(i, 1)));
                }
            }
        }
    }
    if let Some(missing) = ids.iter().find(|i| !rows.contains_key(i.as_ref())) {
        return Err(ReadTraceError::NotFound {
            trace_id: missing.as_ref().to_string(),
            run: run.root().display().to_string(),
            count,
        });
    }
    let mut by_env: BTreeMap<Env, Vec<&str>> = BTreeMap::new();
    for (id, (env, _)) in &rows {
        by_env.entry(*env).or_default().push(id);
    }
    let mut read: HashMap<&str, Trace> = HashMap::with_capacity(rows.len());
    // A trace with no rows in a table (no events, say) decodes from that table's empty batch.
    let empty = |table: &str| RecordBatch::new_empty(table_schema(table).expect("trace table"));
    let (no_steps, no_frames, no_events) = (empty("timesteps"), empty("frames"), empty("events"));
    for (env, mut of_env) in by_env {
        of_env.sort_unstable();
        for chunk in of_env.chunks(CHUNK) {
            let steps = table_rows(run, "timesteps", env, chunk, &["step"])?;
            let frames = table_rows(run, "frames", env, chunk, &["step", "slot"])?;
            let events = table_rows(run, "events", env, chunk, &["seq"])?;
            for &id in chunk {
                let trace = decode_trace(&TraceRows {
                    env,
                    trace: &rows[id].1,
                    timesteps: steps.get(id).unwrap_or(&no_steps),
                    frames: frames.get(id).unwrap_or(&no_frames),
                    events: events.get(id).unwrap_or(&no_events),
                })?;
                read.insert(id, trace);
            }
        }
    }
    // In the order asked for; a trace asked for again is a copy.
    let mut left: HashMap<&str, usize> = HashMap::new();
    for id in ids {
        *left.entry(id.as_ref()).or_default() += 1;
    }
    let mut out = Vec::with_capacity(ids.len());
    for id in ids {
        let id = id.as_ref();
        let n = left.get_mut(id).expect("counted");
        *n -= 1;
        out.push(if *n == 0 {
            read.remove(id).expect("read above")
        } else {
            read[id].clone()
        });
    }
    Ok(out)
}

/// The trace ids of one `traces` file, in its row order (a null id reads as empty).
pub(crate) fn file_trace_ids(file: &Path) -> Result<Vec<String>, StoreError> {
    let mut out = Vec::new();
    for b in super::read_file(file)? {
        let ids = plain_ids(file, &b)?;
        out.extend(ids.iter().map(|id| id.unwrap_or_default().to_string()));
    }
    Ok(out)
}

/// The ids of every trace in the run, with their environment, sorted.
pub fn trace_ids(run: &RunDir) -> Result<Vec<(Env, String)>, StoreError> {
    let mut out = Vec::new();
    for f in run.table("traces")?.files {
        let Some(env) = f.env else { continue };
        for b in super::read_file(&f.path)? {
            if let Some(ids) = b
                .column_by_name("trace_id")
                .and_then(|c| c.as_any().downcast_ref::<StringArray>())
            {
                out.extend(ids.iter().flatten().map(|s| (env, s.to_string())));
            }
        }
    }
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow::array::{Float64Array, Int32Array, Int64Array};
    use std::sync::Arc;

    #[test]
    fn rows_are_split_by_trace_and_sorted_only_when_out_of_order() {
        // `timesteps` rows: trace a in order in one run; b out of order and in two runs around c.
        let rows: [(&str, i64); 7] = [
            ("a", 0),
            ("a", 1),
            ("b", 2),
            ("c", 0),
            ("b", 0),
            ("b", 1),
            ("a", 2),
        ];
        let schema = table_schema("timesteps").unwrap();
        let ids: Vec<&str> = rows.iter().map(|r| r.0).collect();
        let steps: Vec<i64> = rows.iter().map(|r| r.1).collect();
        let ts: Vec<f64> = rows.iter().map(|r| r.1 as f64 / 10.0).collect();
        let mut columns: Vec<ArrayRef> = vec![
            cast(&StringArray::from(ids), schema.field(0).data_type()).unwrap(),
            Arc::new(Int64Array::from(steps)),
            Arc::new(Float64Array::from(ts)),
            Arc::new(Int32Array::from(vec![1; 7])),
        ];
        columns.push(arrow::array::new_null_array(schema.field(4).data_type(), 7));
        let all = RecordBatch::try_new(schema, columns).unwrap();
        let split = by_trace(Path::new("timesteps"), &all, &["step"]).unwrap();
        let steps_of = |id: &str| -> Vec<i64> {
            let b = &split[id];
            let s = b.column_by_name("step").unwrap().as_any();
            s.downcast_ref::<Int64Array>().unwrap().values().to_vec()
        };
        assert_eq!(split.len(), 3);
        assert_eq!(steps_of("a"), [0, 1, 2]);
        assert_eq!(steps_of("b"), [0, 1, 2]);
        assert_eq!(steps_of("c"), [0]);
        // Each trace's times travel with its steps.
        let t = split["b"].column_by_name("t").unwrap();
        let t = t.as_any().downcast_ref::<Float64Array>().unwrap();
        assert_eq!(t.values().to_vec(), [0.0, 0.1, 0.2]);
    }
}
