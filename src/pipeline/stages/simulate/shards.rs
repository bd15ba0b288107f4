//! The shard machinery every environment's `simulate` shares: work items `0..total` cut into shards
//! of `per_shard` items, run in parallel on rayon's pool, each shard's tables written to its own
//! Parquet files and committed, its counts recorded so a killed stage resumes at the first unfinished
//! shard; and the checks every environment makes (trace ids new to the run, replay parameters given in
//! pairs).
//!
//! **Owns:** [`run_shards`], [`ShardSinks`], [`ShardTotals`], [`check_ids_are_new`], [`replay_pair`].
//! **Does not:** know any environment (each `Simulation` fills a shard's items).

use std::collections::BTreeMap;

use arrow::array::RecordBatch;
use rayon::prelude::*;
use serde_json::{Value, json};

use crate::pipeline::registry::BuildError;
use crate::pipeline::stage::{StageContext, StageError};
use crate::store::{ColumnSink, ParquetSink};
use crate::trace::view::ColumnView;
use crate::trace::{Env, TraceColumns, schema};

/// The sums of a stage's shard records: each numeric field (`traces`, `successes`, …) and the rows
/// written per table.
#[derive(Default)]
pub(crate) struct ShardTotals {
    fields: BTreeMap<String, f64>,
    /// Rows written per table.
    pub(crate) rows: BTreeMap<String, u64>,
}

impl ShardTotals {
    /// The sum of a numeric field as a count (0 when no shard reported it).
    pub(crate) fn count(&self, field: &str) -> u64 {
        self.fields.get(field).copied().unwrap_or(0.0) as u64
    }

    /// The sum of a numeric field.
    pub(crate) fn sum(&self, field: &str) -> f64 {
        self.fields.get(field).copied().unwrap_or(0.0)
    }
}

/// Splits `0..total` into shards of `per_shard` items, runs them in parallel (rayon) and sums their
/// records. A shard an earlier run finished is skipped (its record reused). Otherwise `fill(sinks, lo,
/// hi)` simulates items `lo..hi` into the shard's files and returns the shard's counts as a JSON
/// object; the files are then committed and the counts, with the rows written per table (`rows`),
/// recorded as the shard's record.
pub(crate) fn run_shards(
    ctx: &StageContext<'_>,
    env: Env,
    total: u64,
    per_shard: u64,
    fill: impl Fn(&mut ShardSinks<'_, '_>, u64, u64) -> Result<Value, StageError> + Sync,
) -> Result<ShardTotals, StageError> {
    let per_shard = per_shard.max(1);
    let shards: Vec<(u64, u64)> = (0..total.div_ceil(per_shard))
        .map(|s| (s * per_shard, ((s + 1) * per_shard).min(total)))
        .collect();
    let records: Vec<Value> = shards
        .par_iter()
        .enumerate()
        .map(|(i, &(lo, hi))| {
            let name = format!("{i:05}");
            if !ctx.owns(&name) {
                // Another process's slice (`--shard`): its records are summed at the commit.
                return Ok(json!({}));
            }
            if let Some(record) = ctx.finished_shard(&name)? {
                ctx.progress().advance(ctx.stage_id(), hi - lo);
                return Ok(record);
            }
            let mut sinks = ShardSinks::new(ctx, env, name.clone());
            let mut record = fill(&mut sinks, lo, hi)?;
            record["rows"] = json!(sinks.commit()?);
            ctx.finish_shard(&name, &record)?;
            Ok(record)
        })
        .collect::<Result<_, StageError>>()?;
    let mut totals = ShardTotals::default();
    for r in &records {
        for (k, v) in r.as_object().into_iter().flatten() {
            if k == "rows" {
                for (t, n) in v.as_object().into_iter().flatten() {
                    *totals.rows.entry(t.clone()).or_default() += n.as_u64().unwrap_or(0);
                }
            } else if let Some(x) = v.as_f64() {
                *totals.fields.entry(k.clone()).or_default() += x;
            }
        }
    }
    Ok(totals)
}

/// The two parameters of a replay (`scene_file` and `shot`, `game` and `clicks`, `task` and `action`):
/// both given, or neither (dataset mode, `None`); one without the other is an error on the missing one.
pub(crate) fn replay_pair<'p>(
    (first, a): (&'static str, Option<&'p str>),
    (second, b): (&'static str, Option<&'p str>),
) -> Result<Option<(&'p str, &'p str)>, BuildError> {
    match (a, b) {
        (Some(a), Some(b)) => Ok(Some((a, b))),
        (Some(_), None) => Err(BuildError::param(
            second,
            format!("replay mode needs `{second}` with `{first}`"),
        )),
        (None, Some(_)) => Err(BuildError::param(
            first,
            format!("replay mode needs `{first}` with `{second}`"),
        )),
        (None, None) => Ok(None),
    }
}

/// Fails when a trace id this stage would write (`ids`, walked only when the run holds traces) is
/// already in the run, written by another stage (e.g. an earlier dataset command with the same seed);
/// the stage's own earlier output was removed by the runner before a rerun. With `env`, only that
/// environment's traces count.
pub(crate) fn check_ids_are_new(
    ctx: &StageContext<'_>,
    env: Option<Env>,
    ids: impl IntoIterator<Item = String>,
) -> Result<(), StageError> {
    let existing: std::collections::HashSet<String> = crate::store::trace_ids(ctx.run())?
        .into_iter()
        .filter(|(e, _)| env.is_none_or(|env| *e == env))
        .map(|(_, id)| id)
        .collect();
    if existing.is_empty() {
        return Ok(());
    }
    if let Some(id) = ids.into_iter().find(|id| existing.contains(id)) {
        return Err(StageError::Input(format!(
            "trace id {id:?} is already in the run {} (written by another stage); use another seed or run folder",
            ctx.run().root().display()
        )));
    }
    Ok(())
}

/// The open Parquet files of one shard, one per table.
pub(crate) struct ShardSinks<'a, 'c> {
    ctx: &'a StageContext<'c>,
    env: Env,
    name: String,
    /// The tables' `source`: `simulate:<stage id>`.
    source: String,
    /// This shard's start order in the run, for the mid-shard fault point.
    ordinal: usize,
    sinks: BTreeMap<&'static str, ParquetSink>,
    /// The `timesteps` and `frames` files, written from column views.
    column_sinks: BTreeMap<&'static str, ColumnSink>,
}

impl<'a, 'c> ShardSinks<'a, 'c> {
    /// No file open yet; shard `name` of `env`, counted as started.
    fn new(ctx: &'a StageContext<'c>, env: Env, name: String) -> Self {
        let ordinal = ctx.shard_started();
        ShardSinks {
            ctx,
            env,
            name,
            source: format!("simulate:{}", ctx.stage_id()),
            ordinal,
            sinks: BTreeMap::new(),
            column_sinks: BTreeMap::new(),
        }
    }

    /// The `source` column of the rows this stage writes (`simulate:<stage id>`).
    pub(crate) fn source(&self) -> &str {
        &self.source
    }

    /// Appends one trace's rows to the `traces`, `timesteps`, `frames` and `events` files, straight
    /// from its columns (no paper-layout objects are built; `timesteps` and `frames` through the
    /// column writer, no Arrow arrays either); a trace with a non-finite state (a
    /// simulator that blew up) is an error naming it, never NaN in a table. For the shard's first trace
    /// (`first`) the mid-shard fault point fires between the frames and the events, so a crash test
    /// finds some of the shard's files half written.
    pub(crate) fn write_columns(
        &mut self,
        trace: TraceColumns,
        scene_id: &str,
        first: bool,
    ) -> Result<(), StageError> {
        if let Some((step, object, field)) = trace.frames.first_non_finite() {
            return Err(StageError::NonFinite {
                trace: trace.trace_id.clone(),
                step,
                object,
                field,
            });
        }
        let t = trace.tables(scene_id, &self.source)?;
        self.write("traces", &t.traces)?;
        self.write_views("timesteps", t.timestep_rows, &t.timesteps)?;
        self.write_views("frames", t.frame_rows, &t.frames)?;
        if first {
            self.ctx.checkpoint_mid_shard(self.ordinal)?;
        }
        self.write("events", &t.events)
    }

    /// Appends `rows` rows given as column views to `table`'s file (the column writer), opening it
    /// on first use (no rows open nothing).
    fn write_views(
        &mut self,
        table: &'static str,
        rows: usize,
        views: &[ColumnView<'_>],
    ) -> Result<(), StageError> {
        if rows == 0 {
            return Ok(());
        }
        if !self.column_sinks.contains_key(table) {
            let schema = schema::table_schema(table)
                .ok_or_else(|| StageError::Internal(format!("no schema for table {table}")))?;
            let sink = self
                .ctx
                .staging()
                .column_sink(table, Some(self.env), &self.name, schema)?;
            self.column_sinks.insert(table, sink);
        }
        if let Some(sink) = self.column_sinks.get_mut(table) {
            sink.append(rows, views)?;
        }
        Ok(())
    }

    /// Appends `batch` to `table`'s file, opening it on first use (empty batches open nothing).
    pub(crate) fn write(
        &mut self,
        table: &'static str,
        batch: &RecordBatch,
    ) -> Result<(), StageError> {
        if batch.num_rows() == 0 {
            return Ok(());
        }
        if !self.sinks.contains_key(table) {
            let schema = schema::table_schema(table)
                .ok_or_else(|| StageError::Internal(format!("no schema for table {table}")))?;
            let sink = self
                .ctx
                .staging()
                .sink(table, Some(self.env), &self.name, schema)?;
            self.sinks.insert(table, sink);
        }
        if let Some(sink) = self.sinks.get_mut(table) {
            sink.write(batch)?;
        }
        Ok(())
    }

    /// Commits every file; the rows written per table.
    pub(crate) fn commit(self) -> Result<BTreeMap<String, u64>, StageError> {
        let mut rows = BTreeMap::new();
        for (table, sink) in self.sinks {
            let (_, n) = sink.commit()?;
            rows.insert(table.to_string(), n as u64);
        }
        for (table, sink) in self.column_sinks {
            let (_, n) = sink.commit()?;
            rows.insert(table.to_string(), n as u64);
        }
        Ok(rows)
    }
}
