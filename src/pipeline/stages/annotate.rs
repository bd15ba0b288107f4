//! `annotate`: runs a detector library over a run's traces in the sandboxed worker pool and writes the
//! `detectors`, `detector_calls` and `annotations` tables.
//!
//! Traces are read as [`FramedTrace`]s: a billiards trace's balls go from their frame columns
//! straight into the workers' load request, and its annotations need only its id and step times,
//! so no paper-layout object is built per ball per step (an ensemble library's combination reads
//! the balls from the columns too).
//!
//! One shard per trace file set (the files an `import` or `simulate` shard wrote), so a killed stage
//! resumes at the first unfinished set; the `detectors` rows are a last shard of their own. A detector
//! that fails (syntax, forbidden construct, exception, timeout, memory, invalid output) is a
//! `detector_calls` row with its status and error, never a failed stage.
//!
//! The sets form a pipeline of two threads: while the worker pool runs set k, and while the next set's
//! traces are read, a second thread turns set k − 1's results into annotations, writes its tables,
//! marks its shard finished and frees its traces (at most one set is being finished at a time, and
//! shard records are kept in set order). The reading and the finishing are the stage's own work; the
//! workers would otherwise wait through both. A set of more than `OVERLAP_MAX_ROWS` object rows is
//! finished before the next is read, so that large sets (an import's) do not double the peak memory.

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use std::collections::BTreeMap;

use super::detector_setup::{DetectorSetup, SandboxParams};
use super::trace_files::{read_framed_traces, trace_file_sets};
use crate::detect::tables::{annotations_batch, calls_batch, detectors_batch};
use crate::detect::{Annotation, BatchResult, CandidateStatus, Library, WorkerPool};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::trace::{Env, FramedTrace, Trace};

/// The most object rows a set may hold for it to be finished while the next set is read and run
/// (about 190 billiard shots at dt 0.01, half a gigabyte as `Trace`s and less while their balls
/// stay columns); a larger set is finished first.
const OVERLAP_MAX_ROWS: usize = 1 << 20;

/// The `annotate` stage kind.
pub static KIND: StageKind = StageKind {
    name: "annotate",
    summary: "run a detector library over the run's traces (sandboxed Python workers)",
    doc: "Runs every detector of a library (a folder with library.toml and one .py file per detector, see \
          docs/detectors.md) over every trace of `env` in the run, in a pool of sandboxed Python workers, \
          and writes the detectors, detector_calls (status, error, wall and CPU time per detector × trace) \
          and annotations tables. Failing detectors are recorded, not fatal. Default library: \
          data/libraries/<env>.",
    writes: "detectors, detector_calls, annotations",
    params: ParamsOf::of::<SandboxParams>(),
    build,
};

/// What an `annotate` stage reports (its manifest summary, read back by `annotrace annotate`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AnnotateSummary {
    /// The environment.
    pub env: Env,
    /// The library's name.
    pub library: String,
    /// Its detectors.
    pub detectors: u64,
    /// Traces annotated.
    pub traces: u64,
    /// Annotations written.
    pub annotations: u64,
    /// Detector calls by status (`ok`, `timeout`, `exception`, …).
    pub statuses: BTreeMap<String, u64>,
    /// The sandbox layers the workers ran under (absent when every shard was reused).
    pub sandbox: Option<crate::detect::SandboxLayers>,
    /// Seconds spent per phase (reading, batching, detector wall time, protocol, …), summed.
    pub timings: BTreeMap<String, f64>,
}

impl AnnotateSummary {
    /// Detector calls that did not succeed.
    pub fn failed_calls(&self) -> u64 {
        self.statuses
            .iter()
            .filter(|(k, _)| k.as_str() != "ok")
            .map(|(_, v)| v)
            .sum()
    }
}

/// The `annotate` stage.
#[derive(Debug)]
pub struct AnnotateStage {
    setup: DetectorSetup,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    Ok(Box::new(AnnotateStage {
        setup: DetectorSetup::new(&def.params()?, spec)?,
    }))
}

/// The annotations of a batch's successful calls; an ensemble library's member patterns are combined
/// into its ensemble annotations (`ensemble::activation`).
pub(crate) fn annotations_of(
    library: &Library,
    traces: &[Trace],
    batch: BatchResult,
) -> Vec<Annotation> {
    let out = patterns_of(library, |t| &traces[t], batch);
    crate::ensemble::activation::combine(&library.detectors, traces, out)
}

/// [`annotations_of`] for traces read from a run's tables (their balls may still be columns).
fn framed_annotations_of(
    library: &Library,
    traces: &[FramedTrace],
    batch: BatchResult,
) -> Vec<Annotation> {
    let out = patterns_of(library, |t| traces[t].shell(), batch);
    crate::ensemble::activation::combine_framed(&library.detectors, traces, out)
}

/// One annotation per pattern of a batch's successful calls, in the batch's order; `trace(t)` is the
/// batch's trace `t` (its id and step times are read).
fn patterns_of<'t>(
    library: &Library,
    trace: impl Fn(usize) -> &'t Trace,
    batch: BatchResult,
) -> Vec<Annotation> {
    let mut out = Vec::new();
    for r in batch.results {
        if r.status != CandidateStatus::Ok {
            continue;
        }
        let det = &library.detectors[r.detector];
        for (seq, p) in r.patterns.into_iter().enumerate() {
            out.push(Annotation::new(det, trace(r.trace), seq, p));
        }
    }
    out
}

/// Counts of call statuses, for summaries.
pub(crate) fn status_counts(batch: &BatchResult) -> BTreeMap<String, u64> {
    let mut out = BTreeMap::new();
    for r in &batch.results {
        *out.entry(r.status.as_str().to_string()).or_default() += 1;
    }
    out
}

/// One set the worker pool has run, waiting to be finished.
struct RanSet {
    /// The shard the set's tables are written as.
    shard: String,
    traces: Vec<FramedTrace>,
    batch: BatchResult,
    /// `pool.layers()`, for the shard record.
    layers: Value,
    /// Seconds spent reading the set's traces and running the pool over them.
    read_s: f64,
    batch_s: f64,
}

/// Finishes one annotated set: its annotations and call rows written as its shard's tables, the
/// shard marked finished; returns the shard's record. Frees the set's traces and results.
fn finish_set(
    ctx: &StageContext<'_>,
    lib: &Library,
    env: Env,
    set: RanSet,
) -> Result<Value, StageError> {
    let RanSet {
        shard,
        traces,
        batch,
        layers,
        read_s,
        batch_s,
    } = set;
    let shard = shard.as_str();
    let ids: Vec<&str> = traces.iter().map(|t| t.shell().trace_id.as_str()).collect();
    let mut rows = BTreeMap::new();
    let calls = calls_batch(&lib.detectors, &ids, &batch.results)?;
    rows.insert(
        "detector_calls",
        ctx.write_batch("detector_calls", env, shard, &calls)?,
    );
    drop(calls);
    let statuses = status_counts(&batch);
    let s = batch.stats.clone();
    let anns = framed_annotations_of(lib, &traces, batch);
    if !anns.is_empty() {
        let b = annotations_batch(&anns)?;
        rows.insert(
            "annotations",
            ctx.write_batch("annotations", env, shard, &b)?,
        );
    }
    let record = json!({
        "traces": traces.len(),
        "annotations": anns.len(),
        "statuses": statuses,
        "rows": rows,
        "layers": layers,
        "stats": {"read_s": read_s, "batch_s": batch_s, "calls": s.calls, "detector_wall_s": s.detector_wall_s,
                  "round_trip_s": s.round_trip_s, "convert_s": s.convert_s,
                  "load_s": s.load_s, "compile_s": s.compile_s, "decode_s": s.decode_s,
                  "restarts": s.restarts},
    });
    ctx.finish_shard(shard, &record)?;
    Ok(record)
}

impl Stage for AnnotateStage {
    /// The library's content hash and the sandbox limits.
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({
            "library": self.setup.library.fingerprint(),
            "worker": crate::detect::worker_fingerprint(),
        }))
    }

    /// Its units are the trace file sets, named by index; the `detectors` table is written at the
    /// commit.
    fn shardable(&self) -> bool {
        true
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let lib = &self.setup.library;
        let env = self.setup.env;
        let sets = trace_file_sets(ctx.run(), env)?;
        ctx.progress().set_total(ctx.stage_id(), sets.len() as u64);
        let mut pool: Option<WorkerPool> = None;
        let mut records = Vec::new();
        std::thread::scope(|sc| -> Result<(), StageError> {
            // The set being finished on the second thread, if any.
            let mut finishing: Option<std::thread::ScopedJoinHandle<'_, _>> = None;
            let join = |finishing: &mut Option<std::thread::ScopedJoinHandle<'_, _>>,
                        records: &mut Vec<Value>|
             -> Result<(), StageError> {
                if let Some(h) = finishing.take() {
                    let record = h.join().unwrap_or_else(|_| {
                        Err(StageError::Internal(
                            "the thread finishing an annotated trace set panicked".into(),
                        ))
                    })?;
                    records.push(record);
                    ctx.progress().advance(ctx.stage_id(), 1);
                }
                Ok(())
            };
            for (i, set) in sets.iter().enumerate() {
                let shard = format!("{i:05}");
                if !ctx.owns(&shard) {
                    // Another process's slice (`--shard`): its record is summed at the commit.
                    continue;
                }
                if let Some(r) = ctx.finished_shard(&shard)? {
                    join(&mut finishing, &mut records)?;
                    records.push(r);
                    ctx.progress().advance(ctx.stage_id(), 1);
                    continue;
                }
                if pool.is_none() {
                    pool = Some(self.setup.pool()?);
                }
                let pool = pool.as_ref().expect("just started");
                let r0 = std::time::Instant::now();
                let traces = read_framed_traces(ctx.run(), set)?;
                let read_s = r0.elapsed().as_secs_f64();
                let b0 = std::time::Instant::now();
                let batch = pool.run_framed(&lib.detectors, &traces);
                let batch_s = b0.elapsed().as_secs_f64();
                join(&mut finishing, &mut records)?;
                let rows: usize = traces.iter().map(FramedTrace::frame_rows).sum();
                let set = RanSet {
                    shard,
                    traces,
                    batch,
                    layers: serde_json::to_value(pool.layers()).unwrap_or(Value::Null),
                    read_s,
                    batch_s,
                };
                finishing = Some(sc.spawn(move || finish_set(ctx, lib, env, set)));
                if rows > OVERLAP_MAX_ROWS {
                    // A large set is finished before the next is read: two of them in memory at once
                    // would double the stage's peak.
                    join(&mut finishing, &mut records)?;
                }
            }
            join(&mut finishing, &mut records)
        })?;
        if ctx.owns("detectors") && ctx.finished_shard("detectors")?.is_none() {
            // An ensemble library also lists one pseudo-detector per ensemble label, the id its
            // annotations carry.
            let mut dets = lib.detectors.clone();
            dets.extend(crate::ensemble::activation::ensemble_detectors(lib));
            let b = detectors_batch(&lib.name, &dets)?;
            let n = ctx.write_batch("detectors", env, "detectors", &b)?;
            ctx.finish_shard("detectors", &json!({"rows": {"detectors": n}}))?;
        }
        let mut rows: BTreeMap<String, u64> = BTreeMap::new();
        rows.insert(
            "detectors".into(),
            (lib.detectors.len() + crate::ensemble::activation::ensemble_detectors(lib).len())
                as u64,
        );
        let mut statuses: BTreeMap<String, u64> = BTreeMap::new();
        let (mut traces, mut anns) = (0u64, 0u64);
        let mut layers = Value::Null;
        let mut stats: BTreeMap<String, f64> = BTreeMap::new();
        for r in &records {
            for (k, v) in r["stats"].as_object().into_iter().flatten() {
                *stats.entry(k.clone()).or_default() += v.as_f64().unwrap_or(0.0);
            }
            traces += r["traces"].as_u64().unwrap_or(0);
            anns += r["annotations"].as_u64().unwrap_or(0);
            for (k, v) in r["statuses"].as_object().into_iter().flatten() {
                *statuses.entry(k.clone()).or_default() += v.as_u64().unwrap_or(0);
            }
            for (t, n) in r["rows"].as_object().into_iter().flatten() {
                *rows.entry(t.clone()).or_default() += n.as_u64().unwrap_or(0);
            }
            if layers.is_null() {
                layers = r["layers"].clone();
            }
        }
        let failed: u64 = statuses
            .iter()
            .filter(|(k, _)| k.as_str() != "ok")
            .map(|(_, v)| v)
            .sum();
        let line = format!(
            "{traces} {env} trace(s) × {} detector(s) of {}: {anns} annotation(s), {failed} failed call(s)",
            lib.detectors.len(),
            lib.name
        );
        Ok(StageOutput {
            rows,
            files: Vec::new(),
            summary: serde_json::to_value(AnnotateSummary {
                env,
                library: lib.name.clone(),
                detectors: lib.detectors.len() as u64,
                traces,
                annotations: anns,
                statuses,
                sandbox: serde_json::from_value(layers).ok(),
                timings: stats,
            })
            .unwrap_or(Value::Null),
            line,
        })
    }
}
