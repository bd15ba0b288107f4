//! The shard machinery every environment's `simulate` shares: work items `0..total` cut into shards
//! of `per_shard` items, each shard's tables written to its own Parquet files and committed, its counts
//! recorded so a killed stage resumes at the first unfinished shard; and the checks every environment
//! makes (trace ids new to the run, replay parameters given in pairs).
//!
//! **Parallelism.** Shards run in parallel on rayon's pool, and so do the items inside a shard: a
//! shard's thread writes one chunk of items while the next chunk is simulated ([`fill_shard`]), so
//! when fewer shards are left than threads (500 PHYRE tasks are 5 shards of 100: on two threads the
//! last one ran alone), the idle threads simulate the last shards' items instead of waiting. Items
//! are written in order, so the files do not depend on the thread count.
//!
//! **Owns:** [`run_shards`], [`ItemOutput`], [`ShardSinks`], [`ShardTotals`], [`check_ids_are_new`],
//! [`replay_pair`].
//! **Does not:** know any environment (each `Simulation` simulates one item into an [`ItemOutput`]).

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

/// A count an item reports for its shard's record: a whole number (`successes`) or a measure
/// (`reward`).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Count {
    /// Summed as an integer, recorded as one.
    Int(u64),
    /// Summed in item order, recorded as a float.
    Float(f64),
}

impl Count {
    /// Adds another item's count of the same field (an integer to an integer, a float to a float;
    /// a field reported both ways becomes a float).
    fn add(&mut self, other: Count) {
        *self = match (*self, other) {
            (Count::Int(a), Count::Int(b)) => Count::Int(a + b),
            (Count::Int(a), Count::Float(b)) => Count::Float(a as f64 + b),
            (Count::Float(a), Count::Int(b)) => Count::Float(a + b as f64),
            (Count::Float(a), Count::Float(b)) => Count::Float(a + b),
        };
    }
}

/// What simulating one work item gives, to be written in item order: the scene row to write before
/// its traces (when the item opens a scene), its traces, the scene they belong to, and its counts.
pub(crate) struct ItemOutput {
    /// The `scenes` row(s) to write first, if this item opens its scene.
    pub(crate) scene: Option<RecordBatch>,
    /// The scene id of the item's traces.
    pub(crate) scene_id: String,
    /// The item's traces, in the order they are written.
    pub(crate) traces: Vec<TraceColumns>,
    /// Counts summed into the shard's record after `traces` (which the writer counts; every item
    /// names the same fields).
    pub(crate) counts: Vec<(&'static str, Count)>,
}

/// The `source` column of the rows a `simulate` stage writes: `simulate:<stage id>`.
pub(crate) fn source(ctx: &StageContext<'_>) -> String {
    format!("simulate:{}", ctx.stage_id())
}

/// Splits `0..total` into shards of `per_shard` items, runs them in parallel (rayon) and sums their
/// records. A shard an earlier run finished is skipped (its record reused). Otherwise its items are
/// simulated with `simulate(i)` and written in order into the shard's files ([`fill_shard`]); the
/// files are then committed and the summed counts, with the rows written per table (`rows`),
/// recorded as the shard's record.
pub(crate) fn run_shards(
    ctx: &StageContext<'_>,
    env: Env,
    total: u64,
    per_shard: u64,
    simulate: impl Fn(u64) -> Result<ItemOutput, StageError> + Sync,
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
            let mut record = fill_shard(ctx, &mut sinks, lo, hi, &simulate)?;
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

/// Items simulated ahead of a shard's writer: twice the threads (at least 2, at most 32), enough for
/// every idle thread to take one while the writer writes the chunk before.
fn chunk_len() -> u64 {
    (2 * rayon::current_num_threads()).clamp(2, 32) as u64
}

/// Simulates items `lo..hi` of one shard and writes them in order; the shard's summed counts as a
/// JSON object. The shard's thread writes chunk k while chunk k + 1 is simulated (`rayon::join`: the
/// simulation is taken by an idle thread, or run by this one after the writes), so the files are the
/// same for any thread count. An item that fails stops the shard with its error when the writer
/// reaches it: the first failing item in order, as a sequential loop would report it.
fn fill_shard(
    ctx: &StageContext<'_>,
    sinks: &mut ShardSinks<'_, '_>,
    lo: u64,
    hi: u64,
    simulate: &(impl Fn(u64) -> Result<ItemOutput, StageError> + Sync),
) -> Result<Value, StageError> {
    let chunk = chunk_len();
    let simulate_chunk = |a: u64, b: u64| -> Vec<Result<ItemOutput, StageError>> {
        (a..b).into_par_iter().map(simulate).collect()
    };
    // The shard's counts, in the order the items name them.
    let mut counts: Vec<(&'static str, Count)> = Vec::new();
    let mut at = lo;
    let mut ready = simulate_chunk(lo, (lo + chunk).min(hi));
    while !ready.is_empty() {
        let next = at + ready.len() as u64;
        let (written, upcoming) = rayon::join(
            || -> Result<(), StageError> {
                for (k, item) in ready.into_iter().enumerate() {
                    let index = at + k as u64;
                    let out = item?;
                    if let Some(scene) = &out.scene {
                        sinks.write("scenes", scene)?;
                    }
                    let traces = ("traces", Count::Int(out.traces.len() as u64));
                    for trace in out.traces {
                        sinks.write_columns(trace, &out.scene_id, index == lo)?;
                    }
                    for (field, count) in std::iter::once(traces).chain(out.counts) {
                        match counts.iter_mut().find(|(f, _)| *f == field) {
                            Some((_, sum)) => sum.add(count),
                            None => counts.push((field, count)),
                        }
                    }
                    ctx.progress().advance(ctx.stage_id(), 1);
                }
                Ok(())
            },
            || simulate_chunk(next, (next + chunk).min(hi)),
        );
        written?;
        ready = upcoming;
        at = next;
    }
    let mut record = serde_json::Map::new();
    for (field, count) in counts {
        let value = match count {
            Count::Int(n) => json!(n),
            Count::Float(x) => json!(x),
        };
        record.insert(field.to_string(), value);
    }
    Ok(Value::Object(record))
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
            source: source(ctx),
            ordinal,
            sinks: BTreeMap::new(),
            column_sinks: BTreeMap::new(),
        }
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
