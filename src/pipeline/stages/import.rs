//! `import`: reads traces in the paper's JSON format into the trace tables, streaming and sharded.
//!
//! Each input file is read once, a trace at a time. Consecutive input files of less than
//! [`GROUP_BYTES`] together form a group (a larger file is a group of its own), and every
//! `traces_per_shard` traces of a group make one shard, written as one Parquet file per table and
//! marked done, so a killed import resumes at the first unfinished shard. A folder of one-trace files
//! (what the originals' recorders write) thus gives shards of many traces, not a file set per trace. Trace ids come from a trace's `trace_id` field, else from the file name
//! (`<stem>`, `<stem>-L<line>` for JSON Lines, `<stem>-<position>` for arrays); a duplicate id, within
//! the import or against traces already in the run, rejects the trace. Without `skip_invalid` the first
//! invalid trace fails the stage and nothing is written; with it, invalid traces are listed in the
//! stage summary (file, trace, JSON path, category, message) and the rest is imported.

use std::collections::{BTreeMap, HashSet};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use arrow::array::{AsArray, RecordBatch};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::store::{ParquetSink, read_batches, read_file};
use crate::trace::batch::with_trace_id;
use crate::trace::json::{
    self, Fault, FaultKind, TraceConsumer, TraceError, TraceHeader, TraceLocation,
    default_trace_id, expand_paths,
};
use crate::trace::schema;
use crate::trace::{Env, Timestep, TraceBatchBuilder, TraceMeta};

/// The `import` stage kind.
pub static KIND: StageKind = StageKind {
    name: "import",
    summary: "import traces in the paper's JSON format (files, folders, JSON Lines)",
    doc: "Reads traces in the per-environment JSON layout of the paper (docs/trace-format.md) from .json files \
          (one trace or an array), .jsonl files (one trace per line) or folders of them, streaming, and writes \
          the scenes, traces, timesteps, frames and events tables. Invalid traces fail the stage unless \
          skip_invalid is set, in which case they are listed with the reason.",
    writes: "scenes, traces, timesteps, frames, events",
    params: ParamsOf::of::<ImportParams>(),
    build,
};

/// The parameters of an `import` stage (`env` and `paths` are required).
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
pub struct ImportParams {
    /// Environment of the traces.
    pub env: Env,
    /// Files or folders to import, relative to the project folder.
    pub paths: Vec<String>,
    /// Import the valid traces and list the invalid ones instead of failing.
    #[serde(default)]
    pub skip_invalid: bool,
    /// Traces per output file; consecutive input files under 128 MiB together share shards, so a
    /// folder of one-trace files makes files of many traces. A resumed import redoes at most the
    /// unfinished shard of each group.
    #[serde(default = "ImportParams::default_traces_per_shard")]
    pub traces_per_shard: u64,
    /// Frame rows of one trace kept in memory before the rest is spilled to a scratch file.
    #[serde(default = "ImportParams::default_spill_rows")]
    pub spill_rows: u64,
}

impl ImportParams {
    fn default_traces_per_shard() -> u64 {
        1000
    }
    fn default_spill_rows() -> u64 {
        65536
    }
}

impl Default for ImportParams {
    fn default() -> Self {
        ImportParams {
            env: Env::Pooltool,
            paths: Vec::new(),
            skip_invalid: false,
            traces_per_shard: Self::default_traces_per_shard(),
            spill_rows: Self::default_spill_rows(),
        }
    }
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: ImportParams = def.params()?;
    let mut paths = Vec::new();
    for path in &p.paths {
        let resolved = spec.project_dir.join(path);
        if !resolved.exists() {
            return Err(BuildError::param(
                "paths",
                format!("{} does not exist", resolved.display()),
            ));
        }
        paths.push(resolved);
    }
    if paths.is_empty() {
        return Err(BuildError::param("paths", "no paths given"));
    }
    Ok(Box::new(ImportStage {
        env: p.env,
        paths,
        spill_rows: usize::try_from(p.spill_rows.max(1)).unwrap_or(usize::MAX),
        skip_invalid: p.skip_invalid,
        per_shard: usize::try_from(p.traces_per_shard.max(1)).unwrap_or(usize::MAX),
        project_dir: spec.project_dir.clone(),
    }))
}

/// What an `import` stage reports (its manifest summary, read back by `annotrace import`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ImportSummary {
    /// The environment.
    pub env: Env,
    /// Input files read.
    pub files: u64,
    /// Traces imported.
    pub traces: u64,
    /// Invalid traces skipped (with `skip_invalid`).
    pub rejected_count: u64,
    /// The first rejections: file, line or trace number, task id, JSON path, fault kind and message.
    pub rejected: Vec<Value>,
}

/// The `import` stage.
#[derive(Debug)]
pub struct ImportStage {
    env: Env,
    paths: Vec<PathBuf>,
    skip_invalid: bool,
    per_shard: usize,
    /// Frame rows of one trace held in memory before they are spilled, so that a trace of any length
    /// is imported with bounded memory.
    spill_rows: usize,
    project_dir: PathBuf,
}

impl Stage for ImportStage {
    /// The files behind the paths, with their sizes and modification times (editing an input reruns),
    /// and how files are grouped into shards (so that a resumed import never takes the finished shards
    /// of another grouping, such as the one shard per file of earlier versions, for its own).
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        let files = expand_paths(&self.paths)?;
        let mut out = Vec::with_capacity(files.len());
        for f in files {
            let meta = std::fs::metadata(&f).map_err(|source| json::SourceError {
                path: f.clone(),
                source,
            })?;
            let mtime = meta
                .modified()
                .ok()
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                .map_or(0, |d| d.as_nanos());
            let shown = f
                .strip_prefix(&self.project_dir)
                .unwrap_or(&f)
                .to_string_lossy()
                .into_owned();
            out.push(json!({"path": shown, "bytes": meta.len(), "mtime_ns": mtime.to_string()}));
        }
        Ok(json!({"files": out, "group_bytes": GROUP_BYTES}))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let files = expand_paths(&self.paths)?;
        ctx.progress().set_total(ctx.stage_id(), files.len() as u64);
        let mut trace_ids = string_column(ctx, "traces", "trace_id")?;
        let mut scene_ids = string_column(ctx, "scenes", "scene_id")?;
        let mut totals = Totals::default();
        let groups = file_groups(&files)?;
        // The open shard, carried from a file to the next one of its group.
        let mut carried: Option<OpenShard> = None;
        let mut offset = 0;
        for (fi, file) in files.iter().enumerate() {
            if fi == 0 || groups[fi] != groups[fi - 1] {
                offset = 0;
            }
            let stem = file
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or("trace")
                .to_string();
            let mut consumer = Importer {
                ctx,
                stage: self,
                file_index: fi,
                group: groups[fi],
                offset,
                file,
                stem,
                builder: TraceBatchBuilder::new(),
                spill: None,
                spills: 0,
                first_step: None,
                next_ordinal: 0,
                shard: carried.take(),
                trace_ids: &mut trace_ids,
                scene_ids: &mut scene_ids,
                totals: &mut totals,
                failure: None,
            };
            json::read_file(file, self.env, &mut consumer)?;
            if let Some(err) = consumer.failure.take() {
                return Err(err);
            }
            offset += consumer.next_ordinal;
            if groups.get(fi + 1) == Some(&groups[fi]) {
                carried = consumer.shard.take();
            } else {
                consumer.close_shard()?;
            }
            ctx.progress().advance(ctx.stage_id(), 1);
        }
        let line = format!(
            "{} traces, {} frame rows from {} file(s){}",
            totals.traces,
            totals.rows.get("frames").copied().unwrap_or(0),
            files.len(),
            if totals.rejected_count > 0 {
                format!("; {} invalid trace(s) skipped", totals.rejected_count)
            } else {
                String::new()
            }
        );
        Ok(StageOutput {
            rows: totals.rows.clone(),
            files: Vec::new(),
            summary: serde_json::to_value(ImportSummary {
                env: self.env,
                files: files.len() as u64,
                traces: totals.traces,
                rejected_count: totals.rejected_count,
                rejected: totals.rejected,
            })
            .unwrap_or(Value::Null),
            line,
        })
    }
}

/// Input files of less than this many bytes share shards with their neighbours (about 100 billiard
/// shots of the paper's JSON at dt 0.01; thousands of PHYRE or I-PHYRE traces): enough traces per
/// file set for the stages that work a set at a time, while a resumed import reads again at most
/// this much of what an earlier attempt finished.
pub const GROUP_BYTES: u64 = 128 << 20;

/// For each input file, the index of the first file of its group: consecutive files whose sizes
/// add up to at most [`GROUP_BYTES`] (a larger file stands alone).
fn file_groups(files: &[PathBuf]) -> Result<Vec<usize>, StageError> {
    let mut out = Vec::with_capacity(files.len());
    let (mut start, mut bytes) = (0usize, 0u64);
    for (i, f) in files.iter().enumerate() {
        let size = std::fs::metadata(f)
            .map_err(|source| json::SourceError {
                path: f.clone(),
                source,
            })?
            .len();
        if i == 0 || bytes.saturating_add(size) > GROUP_BYTES {
            start = i;
            bytes = 0;
        }
        bytes = bytes.saturating_add(size);
        out.push(start);
    }
    Ok(out)
}

/// The values of a string column over the run's published files and this stage's finished shards.
fn string_column(
    ctx: &StageContext<'_>,
    table: &str,
    column: &str,
) -> Result<HashSet<String>, StageError> {
    let mut out = HashSet::new();
    let mut files: Vec<PathBuf> = ctx
        .run()
        .table(table)?
        .files
        .into_iter()
        .map(|f| f.path)
        .collect();
    files.extend(ctx.staging().table_files(table)?);
    for f in files {
        for batch in read_file(&f)? {
            if let Some(col) = batch
                .column_by_name(column)
                .and_then(|c| c.as_string_opt::<i32>())
            {
                out.extend(col.iter().flatten().map(str::to_owned));
            }
        }
    }
    Ok(out)
}

/// At most this many rejected traces are listed in the manifest; all are counted.
const MAX_LISTED_REJECTIONS: usize = 1000;

#[derive(Default)]
struct Totals {
    traces: u64,
    rows: BTreeMap<String, u64>,
    rejected_count: u64,
    rejected: Vec<Value>,
}

impl Totals {
    fn add_record(&mut self, record: &Value) {
        self.traces += record["traces"].as_u64().unwrap_or(0);
        if let Some(rows) = record["rows"].as_object() {
            for (t, n) in rows {
                *self.rows.entry(t.clone()).or_default() += n.as_u64().unwrap_or(0);
            }
        }
        for r in record["rejected"].as_array().into_iter().flatten() {
            self.rejected_count += 1;
            if self.rejected.len() < MAX_LISTED_REJECTIONS {
                self.rejected.push(r.clone());
            }
        }
    }
}

/// A rejected trace as a JSON row of the stage summary.
pub fn rejection_row(e: &TraceError) -> Value {
    json!({
        "file": e.location.file.to_string_lossy(),
        "line": e.location.line,
        "trace": e.location.ordinal,
        "task_id": e.task_id,
        "path": e.fault.path,
        "kind": e.fault.kind.as_str(),
        "message": e.fault.message,
    })
}

/// The shard being written.
struct OpenShard {
    name: String,
    /// Whether an earlier attempt finished it (its traces are read and dropped).
    done: bool,
    ordinal: usize,
    sinks: BTreeMap<&'static str, ParquetSink>,
    traces: u64,
    rejected: Vec<Value>,
}

struct Importer<'a, 'c> {
    ctx: &'a StageContext<'c>,
    stage: &'a ImportStage,
    file_index: usize,
    /// The index of the first file of this file's group (names its shards).
    group: usize,
    /// Traces in the group's earlier files.
    offset: usize,
    file: &'a Path,
    stem: String,
    builder: TraceBatchBuilder,
    /// Frame rows of the current trace spilled to disk (written with a placeholder trace id).
    spill: Option<ParquetSink>,
    spills: usize,
    first_step: Option<Timestep>,
    next_ordinal: usize,
    shard: Option<OpenShard>,
    trace_ids: &'a mut HashSet<String>,
    scene_ids: &'a mut HashSet<String>,
    totals: &'a mut Totals,
    failure: Option<StageError>,
}

impl Importer<'_, '_> {
    fn shard_name(&self, chunk: usize) -> String {
        format!("{:05}-{chunk:05}", self.group)
    }

    /// Makes `chunk` the open shard, closing the previous one.
    fn enter_chunk(&mut self, chunk: usize) -> Result<(), StageError> {
        let name = self.shard_name(chunk);
        if self.shard.as_ref().is_some_and(|s| s.name == name) {
            return Ok(());
        }
        self.close_shard()?;
        let done = match self.ctx.finished_shard(&name)? {
            Some(record) => {
                self.totals.add_record(&record);
                true
            }
            None => false,
        };
        let ordinal = if done {
            usize::MAX
        } else {
            self.ctx.shard_started()
        };
        self.shard = Some(OpenShard {
            name,
            done,
            ordinal,
            sinks: BTreeMap::new(),
            traces: 0,
            rejected: Vec::new(),
        });
        Ok(())
    }

    /// Commits the open shard's files and marks it done.
    fn close_shard(&mut self) -> Result<(), StageError> {
        let Some(shard) = self.shard.take() else {
            return Ok(());
        };
        if shard.done {
            return Ok(());
        }
        let mut rows = BTreeMap::new();
        for (table, sink) in shard.sinks {
            let (_, n) = sink.commit()?;
            rows.insert(table.to_string(), n as u64);
        }
        let record = json!({"traces": shard.traces, "rows": rows, "rejected": shard.rejected});
        self.totals.add_record(&record);
        self.ctx.finish_shard(&shard.name, &record)
    }

    /// Moves the buffered frame rows of the current trace to its spill file.
    fn spill_frames(&mut self) -> Result<(), StageError> {
        let batch = self.builder.take_frames("")?;
        if self.spill.is_none() {
            self.spills += 1;
            let path = self
                .ctx
                .staging()
                .scratch_dir()
                .join(format!("{:05}-{}.parquet", self.file_index, self.spills));
            self.spill = Some(ParquetSink::create(path, schema::FRAMES.clone())?);
        }
        self.spill.as_mut().expect("created above").write(&batch)?;
        Ok(())
    }

    /// Drops the spill file of a rejected trace.
    fn drop_spill(&mut self) {
        // Dropping an uncommitted sink removes its temporary file.
        self.spill = None;
    }

    /// Copies the spilled rows of an accepted trace into the shard, with its real id.
    fn write_spill(&mut self, trace_id: &str) -> Result<(), StageError> {
        let Some(sink) = self.spill.take() else {
            return Ok(());
        };
        let (path, _) = sink.commit()?;
        for batch in read_batches(&path)? {
            let batch = with_trace_id(&batch?, trace_id)?;
            self.write("frames", &batch)?;
        }
        std::fs::remove_file(&path).map_err(|e| crate::store::StoreError::Io {
            path: path.clone(),
            source: e,
        })?;
        Ok(())
    }

    fn write(&mut self, table: &'static str, batch: &RecordBatch) -> Result<(), StageError> {
        if batch.num_rows() == 0 {
            return Ok(());
        }
        let shard = self
            .shard
            .as_mut()
            .expect("a shard is open while traces arrive");
        if !shard.sinks.contains_key(table) {
            let schema = schema::table_schema(table).expect("trace tables have schemas");
            let sink = self
                .ctx
                .staging()
                .sink(table, Some(self.stage.env), &shard.name, schema)?;
            shard.sinks.insert(table, sink);
        }
        shard
            .sinks
            .get_mut(table)
            .expect("inserted above")
            .write(batch)?;
        Ok(())
    }

    fn accept(&mut self, loc: &TraceLocation, h: TraceHeader) -> Result<(), StageError> {
        let trace_id = h
            .trace_id
            .clone()
            .unwrap_or_else(|| default_trace_id(&self.stem, loc));
        if self.trace_ids.contains(&trace_id) {
            self.builder.discard();
            self.drop_spill();
            let fault = Fault::new(
                "$.trace_id",
                FaultKind::DuplicateTrace,
                format!(
                    "trace id {trace_id:?} is already in the run (set a distinct `trace_id` field, or import into another run)"
                ),
            );
            return self.reject(TraceError {
                location: loc.clone(),
                task_id: Some(h.task_id),
                fault,
            });
        }
        let source = match loc.line {
            Some(line) => format!("{}:{line}", self.file.display()),
            None => format!("{}#{}", self.file.display(), loc.ordinal),
        };
        let batches = self.builder.finish(&TraceMeta {
            trace_id: &trace_id,
            scene_id: &h.task_id,
            task_id: &h.task_id,
            events: &h.events,
            outcome: &h.outcome,
            extra: &h.extra,
            source: &source,
        })?;
        if !self.scene_ids.contains(&h.task_id) {
            let step = self
                .first_step
                .as_ref()
                .map(json::timestep_to_value)
                .unwrap_or(Value::Null);
            let n = self.first_step.as_ref().map_or(0, |s| s.objects.len());
            let spec = json!({"initial_timestep": step, "from_trace": trace_id});
            let scene = crate::trace::batch::scene_batch(
                &h.task_id,
                &h.task_id,
                &format!("import:{}", self.ctx.stage_id()),
                n,
                &spec,
            )?;
            self.write("scenes", &scene)?;
            self.scene_ids.insert(h.task_id.clone());
        }
        self.write("traces", &batches.traces)?;
        self.write("timesteps", &batches.timesteps)?;
        self.write_spill(&trace_id)?;
        self.write("frames", &batches.frames)?;
        let ordinal = self.shard.as_ref().map_or(0, |s| s.ordinal);
        // The mid-shard fault fires with some of the shard's files half written.
        self.ctx.checkpoint_mid_shard(ordinal)?;
        self.write("events", &batches.events)?;
        self.trace_ids.insert(trace_id);
        if let Some(s) = self.shard.as_mut() {
            s.traces += 1;
        }
        Ok(())
    }

    fn reject(&mut self, e: TraceError) -> Result<(), StageError> {
        if !self.stage.skip_invalid {
            return Err(StageError::InvalidTrace(Box::new(e)));
        }
        if let Some(s) = self.shard.as_mut() {
            s.rejected.push(rejection_row(&e));
        }
        Ok(())
    }
}

impl TraceConsumer for Importer<'_, '_> {
    fn timestep(&mut self, ts: Timestep) {
        if self.failure.is_some() {
            return;
        }
        let chunk = (self.offset + self.next_ordinal) / self.stage.per_shard;
        if let Err(e) = self.enter_chunk(chunk) {
            self.failure = Some(e);
            return;
        }
        if self.shard.as_ref().is_some_and(|s| s.done) {
            return;
        }
        self.builder.push_timestep(&ts);
        if self.first_step.is_none() {
            self.first_step = Some(ts);
        }
        if self.builder.buffered_frames() >= self.stage.spill_rows
            && let Err(e) = self.spill_frames()
        {
            self.failure = Some(e);
        }
    }

    fn finish(
        &mut self,
        loc: &TraceLocation,
        result: Result<TraceHeader, TraceError>,
    ) -> ControlFlow<()> {
        self.next_ordinal = loc.ordinal + 1;
        let first_step = self.first_step.take();
        if self.failure.is_some() {
            return ControlFlow::Break(());
        }
        let outcome = (|| {
            self.enter_chunk((self.offset + loc.ordinal) / self.stage.per_shard)?;
            if self.shard.as_ref().is_some_and(|s| s.done) {
                self.builder.discard();
                return Ok(());
            }
            self.first_step = first_step;
            let r = match result {
                Ok(h) => self.accept(loc, h),
                Err(e) => {
                    self.builder.discard();
                    self.drop_spill();
                    self.reject(e)
                }
            };
            self.first_step = None;
            r
        })();
        match outcome {
            Ok(()) => ControlFlow::Continue(()),
            Err(e) => {
                self.failure = Some(e);
                ControlFlow::Break(())
            }
        }
    }
}
