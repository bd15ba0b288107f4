//! `annotate`: runs a detector library over a run's traces in the sandboxed worker pool and writes the
//! `detectors`, `detector_calls` and `annotations` tables.
//!
//! One shard per trace file set (the files an `import` or `simulate` shard wrote), so a killed stage
//! resumes at the first unfinished set; the `detectors` rows are a last shard of their own. A detector
//! that fails (syntax, forbidden construct, exception, timeout, memory, invalid output) is a
//! `detector_calls` row with its status and error, never a failed stage.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use arrow::array::RecordBatch;
use serde_json::{Value, json};

use super::trace_files::{read_traces, trace_file_sets};
use crate::builtin::Location;
use crate::detect::tables::{annotations_batch, calls_batch, detectors_batch};
use crate::detect::{Annotation, BatchResult, CandidateStatus, Library, SandboxLimits, WorkerPool};
use crate::pipeline::params::{ParamSpec, ParamType};
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::trace::{Env, Trace};

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
    params: SANDBOX_PARAMS,
    build,
};

/// Parameters shared by the stages that run detectors.
pub(crate) const SANDBOX_PARAMS: &[ParamSpec] = &[
    ParamSpec::optional(
        "env",
        ParamType::Choice(&["pooltool", "phyre", "iphyre"]),
        "\"pooltool\"",
        "environment whose traces are annotated",
    ),
    ParamSpec::maybe(
        "library",
        ParamType::Str,
        "library folder, relative to the project folder (default: data/libraries/<env>)",
    ),
    ParamSpec::optional(
        "workers",
        ParamType::Count,
        "0",
        "Python worker processes (0 = one per core)",
    ),
    ParamSpec::optional(
        "timeout",
        ParamType::Float,
        "10.0",
        "wall-clock limit of one detector call (s); a call past it is killed and marked timeout",
    ),
    ParamSpec::optional(
        "memory_mb",
        ParamType::Count,
        "2048",
        "address-space limit of a worker (MiB); a call past it is marked memory",
    ),
];

/// The library and sandbox settings of a stage that runs detectors.
#[derive(Debug)]
pub(crate) struct DetectorSetup {
    pub env: Env,
    pub library: Library,
    pub limits: SandboxLimits,
}

impl DetectorSetup {
    /// Reads `env`, `library`, `workers`, `timeout` and `memory_mb`; loads the library.
    pub(crate) fn from_params(def: &StageDef, spec: &PipelineSpec) -> Result<Self, BuildError> {
        let p = &def.params;
        let env: Env = p["env"]
            .as_str()
            .unwrap_or("pooltool")
            .parse()
            .map_err(|e: crate::trace::UnknownEnv| BuildError::param("env", e.to_string()))?;
        let dir = match p.get("library").and_then(Value::as_str) {
            Some(l) => Location::library(&spec.project_dir, Path::new(l)),
            None => Location::default_library(&spec.project_dir, env),
        };
        let library =
            Library::open(&dir).map_err(|e| BuildError::param("library", e.to_string()))?;
        if library.env != env {
            return Err(BuildError::param(
                "library",
                format!("library {dir} is for {}, not {env}", library.env),
            ));
        }
        let timeout = p["timeout"].as_f64().unwrap_or(10.0);
        if !(timeout > 0.0 && timeout.is_finite()) {
            return Err(BuildError::param(
                "timeout",
                format!("timeout must be > 0, found {timeout}"),
            ));
        }
        let mut limits = SandboxLimits::default();
        let workers = p["workers"].as_u64().unwrap_or(0) as usize;
        if workers > 0 {
            limits.workers = workers;
        }
        limits.call_timeout = Duration::from_secs_f64(timeout);
        limits.memory_bytes = p["memory_mb"].as_u64().unwrap_or(2048).max(64) << 20;
        Ok(DetectorSetup {
            env,
            library,
            limits,
        })
    }

    /// Starts the worker pool.
    pub(crate) fn pool(&self) -> Result<WorkerPool, StageError> {
        WorkerPool::new(self.limits.clone()).map_err(|e| StageError::Input(e.to_string()))
    }
}

/// The `annotate` stage.
#[derive(Debug)]
pub struct AnnotateStage {
    setup: DetectorSetup,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    Ok(Box::new(AnnotateStage {
        setup: DetectorSetup::from_params(def, spec)?,
    }))
}

/// The annotations of a batch's successful calls.
pub(crate) fn annotations_of(
    library: &Library,
    traces: &[Trace],
    batch: &BatchResult,
) -> Vec<Annotation> {
    let mut out = Vec::new();
    for r in &batch.results {
        if r.status != CandidateStatus::Ok {
            continue;
        }
        let det = &library.detectors[r.detector];
        for (seq, p) in r.patterns.iter().enumerate() {
            out.push(Annotation::new(det, &traces[r.trace], seq, p.clone()));
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

impl Stage for AnnotateStage {
    /// The library's content hash and the sandbox limits.
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({
            "library": self.setup.library.fingerprint(),
            "worker": crate::detect::worker_fingerprint(),
        }))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let lib = &self.setup.library;
        let env = self.setup.env;
        let sets = trace_file_sets(ctx.run(), env)?;
        ctx.progress().set_total(ctx.stage_id(), sets.len() as u64);
        let mut pool: Option<WorkerPool> = None;
        let mut records = Vec::new();
        for (i, set) in sets.iter().enumerate() {
            let shard = format!("{i:05}");
            if let Some(r) = ctx.finished_shard(&shard)? {
                records.push(r);
                ctx.progress().advance(ctx.stage_id(), 1);
                continue;
            }
            if pool.is_none() {
                pool = Some(self.setup.pool()?);
            }
            let pool = pool.as_ref().expect("just started");
            let r0 = std::time::Instant::now();
            let traces = read_traces(ctx.run(), set)?;
            let read_s = r0.elapsed().as_secs_f64();
            let b0 = std::time::Instant::now();
            let batch = pool.run(&lib.detectors, &traces);
            let batch_s = b0.elapsed().as_secs_f64();
            let anns = annotations_of(lib, &traces, &batch);
            let ids: Vec<&str> = traces.iter().map(|t| t.trace_id.as_str()).collect();
            let mut rows = BTreeMap::new();
            let calls = calls_batch(&lib.detectors, &ids, &batch.results)?;
            rows.insert(
                "detector_calls",
                write(ctx, "detector_calls", env, &shard, &calls)?,
            );
            if !anns.is_empty() {
                let b = annotations_batch(&anns)?;
                rows.insert("annotations", write(ctx, "annotations", env, &shard, &b)?);
            }
            let s = &batch.stats;
            let record = json!({
                "traces": traces.len(),
                "annotations": anns.len(),
                "statuses": status_counts(&batch),
                "rows": rows,
                "layers": pool.layers(),
                "stats": {"read_s": read_s, "batch_s": batch_s, "calls": s.calls, "detector_wall_s": s.detector_wall_s,
                          "round_trip_s": s.round_trip_s, "convert_s": s.convert_s,
                          "load_s": s.load_s, "compile_s": s.compile_s, "decode_s": s.decode_s,
                          "restarts": s.restarts},
            });
            ctx.finish_shard(&shard, &record)?;
            records.push(record);
            ctx.progress().advance(ctx.stage_id(), 1);
        }
        if ctx.finished_shard("detectors")?.is_none() {
            let b = detectors_batch(&lib.name, &lib.detectors)?;
            let n = write(ctx, "detectors", env, "detectors", &b)?;
            ctx.finish_shard("detectors", &json!({"rows": {"detectors": n}}))?;
        }
        let mut rows: BTreeMap<String, u64> = BTreeMap::new();
        rows.insert("detectors".into(), lib.detectors.len() as u64);
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
            summary: json!({
                "env": env.as_str(),
                "library": lib.name,
                "detectors": lib.detectors.len(),
                "traces": traces,
                "annotations": anns,
                "statuses": statuses,
                "sandbox": layers,
                "timings": stats,
            }),
            line,
        })
    }
}

/// Writes one batch as a staged file of `table` and returns its row count.
pub(crate) fn write(
    ctx: &StageContext<'_>,
    table: &str,
    env: Env,
    shard: &str,
    batch: &RecordBatch,
) -> Result<u64, StageError> {
    let mut sink = ctx
        .staging()
        .sink(table, Some(env), shard, batch.schema())?;
    sink.write(batch)?;
    let (_, n) = sink.commit()?;
    Ok(n as u64)
}

/// Reads the `annotations` rows of `env` in the run (of one trace when `trace` is given), in file order.
pub fn read_annotations(
    run: &crate::store::RunDir,
    env: Env,
    trace: Option<&str>,
) -> Result<Vec<Annotation>, StageError> {
    use arrow::array::{Array, AsArray};
    use arrow::datatypes::{Float64Type, Int32Type, Int64Type};
    let mut out = Vec::new();
    for f in run.table("annotations")?.files {
        if f.env != Some(env) {
            continue;
        }
        for b in crate::store::read_file(&f.path)? {
            let col = |n: &str| {
                b.column_by_name(n).cloned().ok_or_else(|| {
                    StageError::Input(format!("{}: no column {n}", f.path.display()))
                })
            };
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
            let json = |a: &arrow::array::StringArray, i: usize| {
                (!a.is_null(i)).then(|| serde_json::from_str(a.value(i)).unwrap_or(Value::Null))
            };
            for i in 0..b.num_rows() {
                if trace.is_some_and(|t| t != tr.value(i)) {
                    continue;
                }
                let objs = objects.value(i);
                let objs = objs.as_string::<i32>();
                out.push(Annotation {
                    detector_id: crate::detect::DetectorId(det.value(i).to_string()),
                    trace_id: tr.value(i).to_string(),
                    label: label.value(i).to_string(),
                    seq: seq.value(i).max(0) as usize,
                    start_step: s0.value(i),
                    end_step: s1.value(i),
                    t_start: if t0.is_null(i) { f64::NAN } else { t0.value(i) },
                    t_end: if t1.is_null(i) { f64::NAN } else { t1.value(i) },
                    objects: (0..objs.len()).map(|k| objs.value(k).to_string()).collect(),
                    parameters: match serde_json::from_str(params.value(i)) {
                        Ok(Value::Object(m)) => m,
                        _ => Default::default(),
                    },
                    provenance: json(prov, i),
                    metadata: json(meta, i),
                    activation: act.value(i),
                });
            }
        }
    }
    Ok(out)
}
