//! Reading one whole trace back out of a run's tables (for export and for building detector input).
//!
//! The trace's row in `traces` gives its environment partition; its `timesteps`, `frames` and `events`
//! rows are then read from that partition only, skipping row groups whose `trace_id` statistics exclude
//! it, and sorted into table order before [`decode_trace`] rebuilds the trace.

use std::fs::File;
use std::path::Path;
use std::sync::Arc;

use arrow::array::{Array, ArrayRef, RecordBatch, StringArray};
use arrow::compute::kernels::cmp::eq;
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

/// The rows of `file` whose `trace_id` equals `id`, skipping row groups that cannot hold it.
fn rows_of(file: &Path, id: &str) -> Result<Vec<RecordBatch>, StoreError> {
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
                    (Some(lo), Some(hi)) => lo <= id.as_bytes() && id.as_bytes() <= hi,
                    _ => true,
                },
                _ => true,
            }
        })
        .collect();
    let reader = builder
        .with_row_groups(groups)
        .build()
        .map_err(|e| StoreError::parquet(file, e))?;
    let needle: ArrayRef = Arc::new(StringArray::new_scalar(id).into_inner());
    let mut out = Vec::new();
    for batch in reader {
        let batch = batch.map_err(|e| arrow_err(file, e))?;
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
        let mask =
            eq(&ids, &arrow::array::Scalar::new(needle.clone())).map_err(|e| arrow_err(file, e))?;
        if mask.true_count() > 0 {
            out.push(filter_record_batch(&batch, &mask).map_err(|e| arrow_err(file, e))?);
        }
    }
    Ok(out)
}

/// All rows of trace `id` in one table partition, sorted by `sort_by`.
fn table_rows(
    run: &RunDir,
    table: &str,
    env: Env,
    id: &str,
    sort_by: &[&str],
) -> Result<RecordBatch, StoreError> {
    let schema: SchemaRef = table_schema(table).expect("trace table");
    let mut batches = Vec::new();
    for f in run
        .table(table)?
        .files
        .iter()
        .filter(|f| f.env == Some(env))
    {
        batches.extend(rows_of(&f.path, id)?);
    }
    let dir = run.partition_dir(table, Some(env));
    let all = concat_batches(&schema, &batches).map_err(|e| arrow_err(&dir, e))?;
    if sort_by.is_empty() || all.num_rows() < 2 {
        return Ok(all);
    }
    let columns: Vec<SortColumn> = sort_by
        .iter()
        .map(|c| SortColumn {
            values: all.column_by_name(c).expect("sort columns exist").clone(),
            options: None,
        })
        .collect();
    let idx = lexsort_to_indices(&columns, None).map_err(|e| arrow_err(&dir, e))?;
    take_record_batch(&all, &idx).map_err(|e| arrow_err(&dir, e))
}

/// Reads trace `trace_id` from the run's tables.
pub fn read_trace(run: &RunDir, trace_id: &str) -> Result<Trace, ReadTraceError> {
    let mut count = 0usize;
    let mut found: Option<(Env, RecordBatch)> = None;
    for f in run.table("traces")?.files {
        let Some(env) = f.env else { continue };
        count += super::read_file(&f.path)?
            .iter()
            .map(RecordBatch::num_rows)
            .sum::<usize>();
        if found.is_none() {
            let rows = rows_of(&f.path, trace_id)?;
            if let Some(first) = rows.into_iter().find(|b| b.num_rows() > 0) {
                found = Some((env, first.slice(0, 1)));
            }
        }
    }
    let Some((env, trace_row)) = found else {
        return Err(ReadTraceError::NotFound {
            trace_id: trace_id.to_string(),
            run: run.root().display().to_string(),
            count,
        });
    };
    let timesteps = table_rows(run, "timesteps", env, trace_id, &["step"])?;
    let frames = table_rows(run, "frames", env, trace_id, &["step", "slot"])?;
    let events = table_rows(run, "events", env, trace_id, &["seq"])?;
    Ok(decode_trace(&TraceRows {
        env,
        trace: &trace_row,
        timesteps: &timesteps,
        frames: &frames,
        events: &events,
    })?)
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
