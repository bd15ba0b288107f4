//! `report`: writes the run's static web report (`report::SiteWriter`): the trace list, the trace
//! player with its pattern timeline, and each trace's annotated text, in a folder that opens from the
//! file system.
//!
//! The stage picks the traces shown from each trace file set's `traces` file alone (`trace_files`;
//! the `traces` and `max_traces` filters), then reads whole only the sets that hold one of them, and
//! only their annotations (grouped into libraries through the `detectors` table; a detector in several
//! libraries counts for each, duplicate rows once), and, for environments with an `accuracy` table,
//! the simulator's ground truth of each scorable trace (`detect::accuracy::truth`). The text is
//! `detect::annotated_text` of all the trace's annotations in file order, exactly what `annotrace
//! show` prints.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::path::PathBuf;

use arrow::array::{Array, AsArray};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::trace_files::{read_traces, set_trace_ids, trace_file_sets};
use crate::detect::accuracy::{scorable, truth};
use crate::detect::tables::read_annotations_of;
use crate::detect::{Annotation, annotated_text, count_tokens};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::report::{LibraryAnnotations, ReportError, SiteWriter, TraceViews};
use crate::store::{RunDir, StoreError, read_file};
use crate::trace::Env;

/// The `report` stage kind.
pub static KIND: StageKind = StageKind {
    name: "report",
    summary: "write a static web report: trace list, trace player, pattern timeline, show text",
    doc: "Writes a static site (index.html, assets, one small script per trace loaded on demand) that \
          opens from the file system without a server: a trace list with filters (environment, outcome, \
          label, a WHERE over its columns), the trace player (the scene in the colours of `annotrace \
          render`, play/pause/scrub/speed, object ids on hover), the pattern timeline beneath it (a \
          section per library, two libraries chosen at a time, the ground truth when the run has an \
          accuracy table, simulator events as ticks; a shared playhead; clicking an annotation seeks the \
          player, hovering it highlights its objects) and the annotated text as `annotrace show` prints \
          it with its token estimate. The folder is built aside and swapped in whole.",
    writes: "exports/<stage>/ (index.html, viewer.js, viewer.css, data/)",
    params: ParamsOf::of::<ReportParams>(),
    build,
};

/// The parameters of a `report` stage.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct ReportParams {
    /// Folder to write the report to, relative to the project folder (default:
    /// `<run>/exports/<stage>`). Its old contents are replaced.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub out: Option<String>,
    /// Only these environments (default: every environment in the run).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub envs: Vec<Env>,
    /// Only these trace ids (default: every trace).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub traces: Vec<String>,
    /// At most this many traces per environment, in file order (default: all).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_traces: Option<u64>,
    /// Merge window (s) of the ground truth's contact bursts, as the `accuracy` stage's `merge`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub merge: Option<f64>,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: ReportParams = def.params()?;
    if p.max_traces == Some(0) {
        return Err(BuildError::param("max_traces", "must be at least 1"));
    }
    let merge = p.merge.unwrap_or(0.05);
    if !(merge.is_finite() && merge >= 0.0) {
        return Err(BuildError::param(
            "merge",
            format!("must be a finite number of seconds ≥ 0, found {merge}"),
        ));
    }
    if let Some(o) = &p.out
        && (o.is_empty() || PathBuf::from(o).file_name().is_none())
    {
        return Err(BuildError::param(
            "out",
            format!("{o:?} is not a folder path"),
        ));
    }
    Ok(Box::new(ReportStage {
        out: p.out.as_ref().map(|o| spec.project_dir.join(o)),
        envs: p.envs,
        traces: p.traces.into_iter().collect(),
        max_traces: p.max_traces,
        merge,
    }))
}

/// The `report` stage.
#[derive(Debug)]
pub struct ReportStage {
    out: Option<PathBuf>,
    envs: Vec<Env>,
    traces: BTreeSet<String>,
    max_traces: Option<u64>,
    merge: f64,
}

/// What a `report` stage records in the manifest.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReportSummary {
    /// The report folder.
    pub folder: String,
    /// Its page.
    pub index: String,
    /// Traces in the report, per environment.
    pub traces: BTreeMap<String, u64>,
    /// The libraries whose annotations it shows.
    pub libraries: Vec<String>,
    /// Environments shown with ground truth.
    pub truth: Vec<String>,
}

impl From<ReportError> for StageError {
    fn from(e: ReportError) -> Self {
        match e {
            ReportError::Io { path, source } => StageError::Io { path, source },
            ReportError::Internal(m) => StageError::Internal(m),
            other => StageError::Input(other.to_string()),
        }
    }
}

/// `detector_id → libraries` from the run's `detectors` table (empty when it has none).
fn detector_libraries(run: &RunDir) -> Result<HashMap<String, BTreeSet<String>>, StageError> {
    let mut out: HashMap<String, BTreeSet<String>> = HashMap::new();
    for f in run.table("detectors")?.files {
        for b in read_file(&f.path)? {
            let col = |n: &str| {
                b.column_by_name(n)
                    .cloned()
                    .ok_or_else(|| StoreError::Schema {
                        path: f.path.clone(),
                        message: format!("no column {n}"),
                    })
            };
            let (ids, libs) = (col("detector_id")?, col("library")?);
            let (ids, libs) = (ids.as_string::<i32>(), libs.as_string::<i32>());
            for i in 0..b.num_rows() {
                if !ids.is_null(i) && !libs.is_null(i) {
                    out.entry(ids.value(i).to_string())
                        .or_default()
                        .insert(libs.value(i).to_string());
                }
            }
        }
    }
    Ok(out)
}

/// The trace's annotations by library (libraries in name order; rows of a detector that two
/// annotate stages both wrote are kept once per library).
fn by_library(
    annotations: &[&Annotation],
    libraries: &HashMap<String, BTreeSet<String>>,
) -> Vec<LibraryAnnotations> {
    let mut groups: BTreeMap<String, Vec<Annotation>> = BTreeMap::new();
    let mut seen: BTreeSet<(String, String, usize, i64, i64)> = BTreeSet::new();
    let unknown: BTreeSet<String> = ["annotations".to_string()].into();
    for a in annotations {
        let libs = libraries.get(&a.detector_id.0).unwrap_or(&unknown);
        for lib in libs {
            let key = (
                lib.clone(),
                a.detector_id.0.clone(),
                a.seq,
                a.start_step,
                a.end_step,
            );
            if seen.insert(key) {
                groups.entry(lib.clone()).or_default().push((*a).clone());
            }
        }
    }
    groups
        .into_iter()
        .map(|(library, annotations)| LibraryAnnotations {
            library,
            annotations,
        })
        .collect()
}

impl Stage for ReportStage {
    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let run = ctx.run();
        let stage = ctx.stage_id();
        let folder = self
            .out
            .clone()
            .unwrap_or_else(|| run.exports_dir().join(stage));
        let libraries = detector_libraries(run)?;
        let accuracy = run.table("accuracy")?;
        let envs: Vec<Env> = if self.envs.is_empty() {
            Env::ALL.to_vec()
        } else {
            self.envs.clone()
        };
        // Which trace file sets to read, and how many traces they hold.
        let mut sets = Vec::new();
        for &env in &envs {
            sets.extend(trace_file_sets(run, env)?);
        }
        ctx.progress().set_total(stage, sets.len() as u64);
        // The traces shown, chosen from each set's `traces` file alone (in set order, after the
        // `traces` and `max_traces` filters), so that only sets holding one are read whole and only
        // their annotations are read.
        let mut counts: BTreeMap<String, u64> = BTreeMap::new();
        let mut picked: Vec<HashSet<String>> = Vec::with_capacity(sets.len());
        for set in &sets {
            let mut keep = HashSet::new();
            for id in set_trace_ids(run, set)? {
                if !self.traces.is_empty() && !self.traces.contains(&id) {
                    continue;
                }
                let n = counts.entry(set.env.as_str().to_string()).or_default();
                if self.max_traces.is_some_and(|m| *n >= m) {
                    continue;
                }
                *n += 1;
                keep.insert(id);
            }
            picked.push(keep);
        }
        let mut writer = SiteWriter::create(&folder)?;
        let mut all_libraries: BTreeSet<String> = BTreeSet::new();
        let mut truth_envs: BTreeSet<String> = BTreeSet::new();
        for (set, keep) in sets.iter().zip(&picked) {
            let env = set.env;
            if keep.is_empty() {
                ctx.progress().advance(stage, 1);
                continue;
            }
            // This set's shown traces' annotations only: the run's are never held at once.
            let ids: Vec<&str> = keep.iter().map(String::as_str).collect();
            let mut annotations: HashMap<String, Vec<Annotation>> = HashMap::new();
            for a in read_annotations_of(run, env, &ids)? {
                annotations.entry(a.trace_id.clone()).or_default().push(a);
            }
            let with_truth = accuracy.files.iter().any(|f| f.env == Some(env));
            for trace in read_traces(run, set)? {
                if !keep.contains(&trace.trace_id) {
                    continue;
                }
                let anns: Vec<Annotation> = annotations
                    .get(&trace.trace_id)
                    .cloned()
                    .unwrap_or_default();
                let text = annotated_text(&trace, &anns);
                let refs: Vec<&Annotation> = anns.iter().collect();
                let libs = by_library(&refs, &libraries);
                all_libraries.extend(libs.iter().map(|l| l.library.clone()));
                let truth = (with_truth && scorable(env, &trace)).then(|| {
                    truth_envs.insert(env.as_str().to_string());
                    truth(env, &trace, self.merge)
                });
                let views = TraceViews {
                    libraries: libs,
                    truth,
                    tokens: count_tokens(&text),
                    text,
                };
                writer.add(&trace, &views)?;
            }
            ctx.progress().advance(stage, 1);
        }
        if writer.is_empty() {
            return Err(StageError::TooFewTraces {
                stage: "report",
                what: "traces in the run (after the `envs`, `traces` and `max_traces` filters)"
                    .into(),
                needed: 1,
                found: 0,
                hint: ": simulate or import traces first",
            });
        }
        let n = writer.len();
        let libs: Vec<String> = all_libraries.into_iter().collect();
        let title = format!(
            "annotrace report · {}",
            run.root()
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_else(|| "run".into())
        );
        let files = writer.finish(&title, &libs)?;
        let shown = |p: &std::path::Path| {
            p.strip_prefix(run.root())
                .unwrap_or(p)
                .to_string_lossy()
                .into_owned()
        };
        let summary = ReportSummary {
            folder: shown(&folder),
            index: shown(&folder.join("index.html")),
            traces: counts,
            libraries: libs,
            truth: truth_envs.into_iter().collect(),
        };
        let line = format!("{n} traces -> {}", summary.index);
        Ok(StageOutput {
            rows: Default::default(),
            files,
            summary: serde_json::to_value(&summary).unwrap_or(Value::Null),
            line,
        })
    }

    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        // The page's code is part of the output.
        Ok(json!({"viewer": crate::digest::sha256_hex(crate::report::VIEWER_JS.as_bytes())}))
    }
}
