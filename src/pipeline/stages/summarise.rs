//! `summarise`: summaries of a sample of the run's traces (`crate::summary`), their cost, and the
//! identification task on them, writing the `summaries` and `identification` tables.
//!
//! The summariser is `offline` (deterministic, from the annotations, no model), `frames` (an LLM shown
//! keyframes only: the baseline) or `annotations` (an LLM shown the initial image and the annotated
//! trace: the paper's). `identify` picks the chooser: `offline` (the annotation-overlap baseline),
//! `llm` (keyframes as images), `none`. Identification is part of this stage rather than a stage of
//! its own because a trial needs the summaries of all sampled traces together with its own trace and
//! annotations: the stage reads and annotates a block of 256 traces at a time, summarises them, and
//! keeps of each trace only its summary and what its trial needs (the chooser's [`TrialView`]:
//! evidence words offline, the drawn keyframes with a model), so the sample is never in memory at
//! once; a separate stage would read the traces back and annotate them again.
//!
//! With a model, one shard per summary and one per trial: a killed run, or an endpoint that went
//! down, resumes at the first unfinished one, and the LLM client serves the answers this run already
//! recorded before asking the endpoint. Offline, a shard holds a block of 64 traces' summaries or
//! trials (milliseconds of work; a file per trace cost more than the work).

use std::path::PathBuf;
use std::sync::Arc;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::detector_setup::{DetectorSetup, SandboxParams};
use super::llm_setup::{resumable_client, stage_prompts};
use super::trace_files::{pick_trace_ids, read_traces_by_id};
use crate::detect::{Annotation, Detector};
use crate::llm::{LlmClient, LlmSettings, Prompts};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::summary::table::{self, Setting, SummaryRow};
use crate::summary::{
    Chooser, IdentifyParams, LlmChooser, LlmMode, LlmSummariser, OfflineChooser, OfflineSummariser,
    Summariser, Summary, SummaryError, TraceImages, TrialView, add_templates,
};
use crate::trace::Env;

/// Who writes the summaries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum SummariserKind {
    /// Deterministic sentences from the annotations (no model).
    #[default]
    Offline,
    /// An LLM shown keyframes of the rollout only (the DeepPHY-style baseline).
    Frames,
    /// An LLM shown the initial image and the annotated trace (the paper's).
    Annotations,
}

impl SummariserKind {
    /// The name (`offline`, `frames`, `annotations`).
    pub fn as_str(self) -> &'static str {
        match self {
            SummariserKind::Offline => "offline",
            SummariserKind::Frames => "frames",
            SummariserKind::Annotations => "annotations",
        }
    }
}

/// Who picks summaries in the identification task.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ChooserKind {
    /// No identification task.
    None,
    /// The annotation-overlap baseline (no model, no images).
    #[default]
    Offline,
    /// An LLM shown keyframes of the trace.
    Llm,
}

impl ChooserKind {
    /// The name (`none`, `offline`, `llm`).
    pub fn as_str(self) -> &'static str {
        match self {
            ChooserKind::None => "none",
            ChooserKind::Offline => "offline",
            ChooserKind::Llm => "llm",
        }
    }
}

/// The parameters of a `summarise` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct SummariseParams {
    /// Environment whose traces are summarised.
    pub env: Env,
    /// Traces to summarise, drawn with the seed from the run's traces of `env` (all when fewer).
    pub traces: u64,
    /// Only these traces (in this order) instead of a seeded sample.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trace_ids: Option<Vec<String>>,
    /// Summariser: offline (from the annotations, no model), frames (LLM, keyframes only: the
    /// baseline) or annotations (LLM, initial image + annotated trace).
    pub summariser: SummariserKind,
    /// Identification task after summarising: offline (annotation-overlap baseline), llm (keyframes
    /// shown to the model) or none.
    pub identify: ChooserKind,
    /// Summaries shown per identification trial, the trace's own included (the paper: 8).
    pub options: u64,
    /// Seed of the sample, the trials and the model requests (default: the pipeline's seed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Keyframes shown by the frames summariser and the LLM chooser.
    pub keyframes: u64,
    /// Size of the images (px; the paper: 512).
    pub image_size: u64,
    /// The longest summary asked of a model, in words.
    pub words: u64,
    /// With an LLM summariser or chooser: when no endpoint (llm.base_url, ANNOTRACE_LLM_BASE_URL) and
    /// no replay run is configured, write no rows and say so instead of failing.
    pub skip_without_endpoint: bool,
    /// Detector library of the annotations (default: the built-in library of the environment).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub library: Option<String>,
    /// Only these labels of the library annotate (growing subsets: the library-size ablation).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub labels: Option<Vec<String>>,
    /// LLM settings (endpoint, model, temperature, replay, …; docs/llm.md), over the ANNOTRACE_LLM_* variables.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub llm: Option<LlmSettings>,
    /// Folder of prompt templates overriding the built-in ones (default: the project's prompts/ when present).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prompts: Option<String>,
    /// Python worker processes (0 = one per core).
    pub workers: u64,
    /// Wall-clock limit of one detector call (s).
    pub timeout: f64,
    /// Address-space limit of a worker (MiB).
    pub memory_mb: u64,
}

impl Default for SummariseParams {
    fn default() -> Self {
        let s = SandboxParams::DEFAULT;
        SummariseParams {
            env: Env::Pooltool,
            traces: 20,
            trace_ids: None,
            summariser: SummariserKind::default(),
            identify: ChooserKind::default(),
            options: 8,
            seed: None,
            keyframes: 5,
            image_size: 512,
            words: 120,
            skip_without_endpoint: false,
            library: None,
            labels: None,
            llm: None,
            prompts: None,
            workers: s.workers,
            timeout: s.timeout,
            memory_mb: s.memory_mb,
        }
    }
}

/// What a `summarise` stage reports (its manifest summary; the command prints it).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SummariseSummary {
    /// Environment.
    pub env: String,
    /// Summariser.
    pub summariser: String,
    /// Its model (empty offline).
    pub model: String,
    /// Library of the annotations (empty when none were made).
    pub library: String,
    /// Detectors that annotated.
    pub patterns: u64,
    /// Traces summarised.
    pub traces: u64,
    /// Summaries written by this process (the rest by an earlier, interrupted one).
    pub summarised_now: u64,
    /// Mean seconds per summary.
    pub mean_seconds: f64,
    /// Mean prompt tokens per summary.
    pub mean_prompt_tokens: f64,
    /// Mean completion tokens per summary.
    pub mean_completion_tokens: f64,
    /// Chooser of the identification task (`none` when not run).
    pub chooser: String,
    /// Identification accuracy (absent when not run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<f64>,
    /// 1 / options.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chance: Option<f64>,
    /// Why nothing was done, when the stage skipped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
}

impl SummariseSummary {
    /// One line for the terminal.
    pub fn line(&self) -> String {
        if let Some(why) = &self.skipped {
            return format!("skipped: {why}");
        }
        let mut s = format!(
            "{} {} summaries{}{}: {:.3} s, {:.0} + {:.0} tokens per summary",
            self.traces,
            self.summariser,
            if self.model.is_empty() {
                String::new()
            } else {
                format!(" ({})", self.model)
            },
            if self.library.is_empty() {
                String::new()
            } else {
                format!(
                    " of {} annotations ({} patterns)",
                    self.library, self.patterns
                )
            },
            self.mean_seconds,
            self.mean_prompt_tokens,
            self.mean_completion_tokens,
        );
        if let (Some(a), Some(c)) = (self.accuracy, self.chance) {
            s.push_str(&format!(
                "; identification by {}: {:.1} % (chance {:.1} %)",
                self.chooser,
                100.0 * a,
                100.0 * c
            ));
        }
        s
    }
}

/// The `summarise` stage kind.
pub static KIND: StageKind = StageKind {
    name: "summarise",
    summary: "natural-language summaries of traces (offline or LLM), their cost, and the identification task",
    doc: "Draws `traces` traces of `env` from the run (seeded), annotates them with a detector library in the \
          sandboxed worker pool when the summariser or chooser needs annotations, and summarises each: \
          `offline` writes deterministic sentences from the annotations (no model), `frames` asks an LLM \
          shown keyframes only (the DeepPHY-style baseline), `annotations` asks it with the initial image \
          and the annotated trace (the paper's). Each summary's seconds and prompt/completion tokens go to \
          the summaries table (sql/summary_cost.sql gives the paper's summary-cost table). Then, unless \
          identify = \"none\", the identification task: per trace, a chooser sees the trace and `options` \
          summaries (its own and seeded distractors) and picks one; trials go to the identification table \
          (sql/identification_accuracy.sql). docs/benchmark.md.",
    writes: "summaries, identification",
    params: ParamsOf::of::<SummariseParams>(),
    build,
};

/// The `summarise` stage.
#[derive(Debug)]
pub struct SummariseStage {
    p: SummariseParams,
    setup: Option<DetectorSetup>,
    detectors: Vec<Detector>,
    llm: LlmSettings,
    prompts: Option<PathBuf>,
    project: PathBuf,
}

fn in_range(k: &'static str, v: u64, min: u64, max: u64) -> Result<u64, BuildError> {
    if v < min || v > max {
        Err(BuildError::param(
            k,
            format!("`{k}` must be in {min}..={max}, found {v}"),
        ))
    } else {
        Ok(v)
    }
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: SummariseParams = def.params()?;
    in_range("traces", p.traces, 1, 100_000)?;
    in_range("options", p.options, 2, 64)?;
    in_range("keyframes", p.keyframes, 1, 20)?;
    in_range("image_size", p.image_size, 64, 1024)?;
    in_range("words", p.words, 10, 2000)?;
    if p.identify != ChooserKind::None {
        let n = p
            .trace_ids
            .as_ref()
            .map_or(p.traces, |ids| ids.len() as u64);
        if n < p.options {
            return Err(BuildError::param(
                "traces",
                format!(
                    "the identification task shows {} summaries per trial, so it needs at least {} traces, found {n} (or set identify = \"none\")",
                    p.options, p.options
                ),
            ));
        }
    }
    let uses_llm = p.summariser != SummariserKind::Offline || p.identify == ChooserKind::Llm;
    if !uses_llm && p.llm.is_some() {
        return Err(BuildError::param(
            "llm",
            "`llm` settings are only used with summariser = \"frames\" or \"annotations\" or identify = \"llm\"",
        ));
    }
    let needs_annotations =
        p.summariser != SummariserKind::Frames || p.identify == ChooserKind::Offline;
    let setup = if needs_annotations {
        Some(DetectorSetup::new(
            &SandboxParams {
                env: p.env,
                library: p.library.clone(),
                workers: p.workers,
                timeout: p.timeout,
                memory_mb: p.memory_mb,
            },
            spec,
        )?)
    } else {
        for (given, key) in [
            (p.library.is_some(), "library"),
            (p.labels.is_some(), "labels"),
        ] {
            if given {
                return Err(BuildError::param(
                    key,
                    format!(
                        "`{key}` is not used: the frames summariser with identify = \"llm\" or \"none\" reads no annotations"
                    ),
                ));
            }
        }
        None
    };
    let detectors = match (&setup, &p.labels) {
        (None, _) => Vec::new(),
        (Some(s), None) => s.library.detectors.clone(),
        (Some(s), Some(labels)) => {
            let known = s.library.labels();
            let norm = |l: &str| crate::detect::normalise_label(l);
            if labels.is_empty() {
                return Err(BuildError::param("labels", "give at least one label"));
            }
            if let Some(bad) = labels
                .iter()
                .find(|l| !known.iter().any(|k| norm(k) == norm(l)))
            {
                return Err(BuildError::param(
                    "labels",
                    format!(
                        "library {} has no label {bad:?} (it has: {})",
                        s.library.name,
                        known.join(", ")
                    ),
                ));
            }
            crate::reward::annotate::detectors_for(&s.library, labels)
        }
    };
    let mut llm = p.llm.clone().unwrap_or_default();
    if let Some(r) = &llm.replay {
        llm.replay = Some(spec.project_dir.join(r));
    }
    Ok(Box::new(SummariseStage {
        prompts: p.prompts.as_ref().map(|d| spec.project_dir.join(d)),
        p,
        setup,
        detectors,
        llm,
        project: spec.project_dir.clone(),
    }))
}

fn summary_error(e: SummaryError) -> StageError {
    match e {
        SummaryError::Llm(e) => StageError::Llm(Box::new(e)),
        SummaryError::Render { trace, source } => StageError::Simulation {
            item: format!("trace {trace}"),
            source: Box::new(source),
        },
        SummaryError::Setup(m) => StageError::Input(m),
    }
}

/// The LLM pieces, when a summariser or the chooser needs a model.
struct Model {
    client: Arc<LlmClient>,
    prompts: Arc<Prompts>,
    images: Arc<TraceImages>,
}

impl SummariseStage {
    fn uses_llm(&self) -> bool {
        self.p.summariser != SummariserKind::Offline || self.p.identify == ChooserKind::Llm
    }

    fn endpoint_configured(&self) -> bool {
        self.llm.base_url.is_some()
            || self.llm.replay.is_some()
            || std::env::var(crate::llm::ENV_BASE_URL).is_ok_and(|v| !v.trim().is_empty())
    }

    fn seed(&self, ctx: &StageContext<'_>) -> u64 {
        self.p.seed.unwrap_or(ctx.seed())
    }

    /// The ids of the traces: the given ones, or a seeded sample of the run's traces of `env` (sorted).
    fn trace_ids(&self, ctx: &StageContext<'_>) -> Result<Vec<String>, StageError> {
        let mut ids = pick_trace_ids(
            ctx.run(),
            self.p.env,
            self.p.trace_ids.as_deref(),
            self.p.traces as usize,
            self.seed(ctx),
            0x5A,
        )?;
        if self.p.trace_ids.is_none() {
            ids.sort();
        }
        let needed = if self.p.identify == ChooserKind::None {
            1
        } else {
            self.p.options as usize
        };
        if ids.len() < needed {
            return Err(StageError::TooFewTraces {
                stage: "summarise",
                what: format!("{} traces in the run", self.p.env),
                needed,
                found: ids.len(),
                hint: ": simulate or import more, or lower `options`",
            });
        }
        Ok(ids)
    }

    fn model(&self, ctx: &StageContext<'_>) -> Result<Option<Model>, StageError> {
        if !self.uses_llm() {
            return Ok(None);
        }
        let client = resumable_client(&self.llm, self.seed(ctx), ctx.run())?;
        let prompts = stage_prompts(self.prompts.as_ref(), &self.project, add_templates)?;
        let images =
            TraceImages::new(self.p.image_size as u32).map_err(|e| StageError::Simulation {
                item: "renderer".into(),
                source: Box::new(e),
            })?;
        Ok(Some(Model {
            client: Arc::new(client),
            prompts: Arc::new(prompts),
            images: Arc::new(images),
        }))
    }
}

/// Traces summarised (or trials run) per shard of the stage. With a model, one: a call takes seconds
/// and may fail, and a resumed run asks again only for the trace it stopped on. Offline, a block: the
/// work takes well under a millisecond per trace, and a file and an `fsync` per trace were a fifth of
/// a 2,000-trace run.
fn shard_block(offline: bool) -> usize {
    if offline { OFFLINE_BLOCK } else { 1 }
}

/// Traces per shard of the offline summariser and chooser.
const OFFLINE_BLOCK: usize = 64;

/// Traces read (and annotated) at a time: a whole number of shards of either size, so that the
/// stage holds a block's traces, not the sample's (the bench's billiards shots take 1.6 MB each),
/// and keeps of each trace only its summary and what its trial needs ([`TrialView`]).
const READ_BLOCK: usize = 4 * OFFLINE_BLOCK;

/// The per-trace records of the finished shard `shard`, which covers `n` traces (a shard of one
/// trace written by an earlier version holds its record alone).
fn shard_records(shard: &str, record: Value, n: usize) -> Result<Vec<Value>, StageError> {
    let records = match record {
        Value::Array(v) => v,
        one => vec![one],
    };
    if records.len() != n {
        return Err(StageError::Internal(format!(
            "finished shard {shard} records {} trace(s) where this stage has {n}; \
             run the stage again with --force to start it afresh",
            records.len()
        )));
    }
    Ok(records)
}

fn summary_of(record: &Value) -> Summary {
    Summary {
        text: record["text"].as_str().unwrap_or_default().to_string(),
        tokens_in: record["prompt_tokens"].as_u64().unwrap_or(0),
        tokens_out: record["completion_tokens"].as_u64().unwrap_or(0),
        usage_estimated: record["usage_estimated"].as_bool().unwrap_or(false),
        seconds: record["seconds"].as_f64().unwrap_or(0.0),
        images: record["images"].as_u64().unwrap_or(0),
        call_id: record["call_id"].as_str().unwrap_or_default().to_string(),
    }
}

impl Stage for SummariseStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({
            "library": self.setup.as_ref().map(|s| s.library.fingerprint()),
            "detectors": self.detectors.iter().map(|d| d.label.clone()).collect::<Vec<_>>(),
            "worker": self.setup.as_ref().map(|_| crate::detect::worker_fingerprint()),
            "templates": crate::summary::TEMPLATES.iter().map(|(n, t)| format!("{n}:{}", crate::digest::sha256_hex(t.as_bytes()))).collect::<Vec<_>>(),
            "endpoint": self.uses_llm().then(|| self.endpoint_configured()),
        }))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let env = self.p.env;
        let chooser_kind = self.p.identify;
        if self.uses_llm() && self.p.skip_without_endpoint && !self.endpoint_configured() {
            let s = SummariseSummary {
                env: env.to_string(),
                summariser: self.p.summariser.as_str().into(),
                chooser: chooser_kind.as_str().into(),
                skipped: Some("an LLM summariser or chooser, but no endpoint (ANNOTRACE_LLM_BASE_URL) or replay run is configured".into()),
                ..SummariseSummary::default()
            };
            return Ok(StageOutput {
                line: s.line(),
                summary: serde_json::to_value(&s)
                    .map_err(|e| StageError::Internal(e.to_string()))?,
                ..StageOutput::default()
            });
        }
        let seed = self.seed(ctx);
        let ids = self.trace_ids(ctx)?;
        let params = IdentifyParams {
            options: self.p.options as usize,
            seed,
        };
        if chooser_kind != ChooserKind::None {
            // Before any work: a trace given twice, or fewer traces than options, cannot make trials.
            crate::summary::check_trials(&ids, &params).map_err(summary_error)?;
        }
        let model = self.model(ctx)?;
        let summariser: Box<dyn Summariser> = match (self.p.summariser, &model) {
            (SummariserKind::Offline, _) => Box::new(OfflineSummariser),
            (kind, Some(m)) => Box::new(LlmSummariser {
                client: m.client.clone(),
                prompts: m.prompts.clone(),
                images: m.images.clone(),
                mode: if kind == SummariserKind::Frames {
                    LlmMode::Frames
                } else {
                    LlmMode::Annotations
                },
                keyframes: self.p.keyframes as usize,
                words: self.p.words as usize,
                seed,
            }),
            (_, None) => return Err(StageError::Internal("no LLM client".into())),
        };
        let chooser: Option<Box<dyn Chooser>> = match (chooser_kind, &model) {
            (ChooserKind::None, _) => None,
            (ChooserKind::Offline, _) => Some(Box::new(OfflineChooser)),
            (ChooserKind::Llm, Some(m)) => Some(Box::new(LlmChooser {
                client: m.client.clone(),
                prompts: m.prompts.clone(),
                images: m.images.clone(),
                keyframes: self.p.keyframes as usize,
            })),
            (ChooserKind::Llm, None) => return Err(StageError::Internal("no LLM client".into())),
        };
        let reads_annotations = self.p.summariser != SummariserKind::Frames;
        let setting = Setting {
            library: match (&self.setup, reads_annotations) {
                (Some(s), true) => s.library.name.clone(),
                _ => String::new(),
            },
            patterns: if reads_annotations {
                self.detectors.len() as i64
            } else {
                0
            },
            summariser: summariser.name().to_string(),
            model: summariser.model(),
            seed: seed as i64,
        };
        let flush = || -> Result<(), StageError> {
            if let Some(m) = &model {
                m.client.flush()?;
            }
            Ok(())
        };
        let failed = |e: SummaryError| -> StageError {
            match flush() {
                Ok(()) => summary_error(e),
                Err(f) => f,
            }
        };
        let n = ids.len();
        let trials = if chooser.is_some() { n as u64 } else { 0 };
        ctx.progress().set_total(ctx.stage_id(), n as u64 + trials);
        // Summaries, and what each trial will need of its trace, a block of traces read at a time.
        let summary_block = shard_block(self.p.summariser == SummariserKind::Offline);
        let trial_block = shard_block(chooser_kind == ChooserKind::Offline);
        let mut pool = None;
        let mut summaries = Vec::with_capacity(n);
        let mut views: Vec<Option<TrialView>> = vec![None; n];
        let mut now = 0u64;
        for start in (0..n).step_by(READ_BLOCK) {
            let end = (start + READ_BLOCK).min(n);
            // The shards of this block an earlier, interrupted run finished.
            let mut summary_shards = Vec::new();
            for at in (start..end).step_by(summary_block) {
                let to = (at + summary_block).min(end);
                let shard = format!("s{at:05}");
                let done = match ctx.finished_shard(&shard)? {
                    Some(r) => Some(shard_records(&shard, r, to - at)?),
                    None => None,
                };
                summary_shards.push((at, to, shard, done));
            }
            let mut open_trials = Vec::new();
            if chooser.is_some() {
                for at in (start..end).step_by(trial_block) {
                    if ctx.finished_shard(&format!("i{at:05}"))?.is_none() {
                        open_trials.extend(at..(at + trial_block).min(end));
                    }
                }
            }
            let summarise_now = summary_shards.iter().any(|s| s.3.is_none());
            let (traces, annotations) = if summarise_now || !open_trials.is_empty() {
                let traces = read_traces_by_id(ctx.run(), &ids[start..end])?;
                // Each trace's own annotations (summaries and trials read one trace's at a time).
                let annotations: Vec<Vec<Annotation>> = match &self.setup {
                    Some(s) => {
                        let pool = match &mut pool {
                            Some(p) => p,
                            None => pool.insert(s.pool()?),
                        };
                        crate::detect::by_trace(
                            &traces,
                            crate::reward::annotate::annotate(pool, &self.detectors, &traces).0,
                        )
                    }
                    None => traces.iter().map(|_| Vec::new()).collect(),
                };
                (traces, annotations)
            } else {
                (Vec::new(), Vec::new())
            };
            for (at, to, shard, done) in summary_shards {
                let records = match done {
                    Some(r) => r,
                    None => {
                        let mut rows = Vec::with_capacity(to - at);
                        let mut records = Vec::with_capacity(to - at);
                        for k in at - start..to - start {
                            let trace = &traces[k];
                            let s = summariser
                                .summarise(trace, &annotations[k])
                                .map_err(failed)?;
                            records.push(json!({
                                "trace": trace.trace_id, "text": s.text, "prompt_tokens": s.tokens_in,
                                "completion_tokens": s.tokens_out, "usage_estimated": s.usage_estimated,
                                "seconds": s.seconds, "images": s.images, "call_id": s.call_id,
                            }));
                            rows.push(SummaryRow {
                                trace_id: trace.trace_id.clone(),
                                summary: s,
                            });
                        }
                        ctx.write_batch(
                            table::SUMMARIES,
                            env,
                            &shard,
                            &table::summaries_batch(&setting, &rows)?,
                        )?;
                        flush()?;
                        ctx.finish_shard(&shard, &Value::Array(records.clone()))?;
                        now += rows.len() as u64;
                        records
                    }
                };
                summaries.extend(records.iter().map(summary_of));
                ctx.progress().advance(ctx.stage_id(), (to - at) as u64);
            }
            if let Some(chooser) = &chooser {
                for i in open_trials {
                    let k = i - start;
                    views[i] = Some(chooser.view(&traces[k], &annotations[k]).map_err(failed)?);
                }
            }
        }
        drop(pool);
        // The identification task, a block of trials per shard.
        let (mut accuracy, mut chance) = (None, None);
        let mut rows = std::collections::BTreeMap::new();
        rows.insert(table::SUMMARIES.to_string(), n as u64);
        if let Some(chooser) = &chooser {
            let texts: Vec<String> = summaries.iter().map(|s| s.text.clone()).collect();
            let mut right = 0u64;
            for start in (0..n).step_by(trial_block) {
                let end = (start + trial_block).min(n);
                let shard = format!("i{start:05}");
                let records = match ctx.finished_shard(&shard)? {
                    Some(r) => shard_records(&shard, r, end - start)?,
                    None => {
                        let mut trials = Vec::with_capacity(end - start);
                        for (i, view) in views.iter_mut().enumerate().take(end).skip(start) {
                            let view = view.take().ok_or_else(|| {
                                StageError::Internal(format!(
                                    "trial {i} has no view of its trace: its shard {shard} was finished while the stage ran"
                                ))
                            })?;
                            trials.push(
                                crate::summary::identify_trial(
                                    &ids,
                                    &view,
                                    &texts,
                                    chooser.as_ref(),
                                    &params,
                                    i,
                                )
                                .map_err(failed)?,
                            );
                        }
                        ctx.write_batch(
                            table::IDENTIFICATION,
                            env,
                            &shard,
                            &table::identification_batch(
                                &setting,
                                (chooser.name(), &chooser.model()),
                                &trials,
                            )?,
                        )?;
                        flush()?;
                        let records: Vec<Value> = trials
                            .iter()
                            .map(|t| json!({"trace": t.trace_id, "success": t.success()}))
                            .collect();
                        ctx.finish_shard(&shard, &Value::Array(records.clone()))?;
                        records
                    }
                };
                right += records
                    .iter()
                    .filter(|r| r["success"].as_bool().unwrap_or(false))
                    .count() as u64;
                ctx.progress().advance(ctx.stage_id(), (end - start) as u64);
            }
            accuracy = Some(right as f64 / n.max(1) as f64);
            chance = Some(1.0 / self.p.options as f64);
            rows.insert(table::IDENTIFICATION.to_string(), n as u64);
        }
        flush()?;
        let n = summaries.len().max(1) as f64;
        let s = SummariseSummary {
            env: env.to_string(),
            summariser: setting.summariser.clone(),
            model: setting.model.clone(),
            library: setting.library.clone(),
            patterns: setting.patterns as u64,
            traces: n as u64,
            summarised_now: now,
            mean_seconds: summaries.iter().map(|s| s.seconds).sum::<f64>() / n,
            mean_prompt_tokens: summaries.iter().map(|s| s.tokens_in as f64).sum::<f64>() / n,
            mean_completion_tokens: summaries.iter().map(|s| s.tokens_out as f64).sum::<f64>() / n,
            chooser: chooser_kind.as_str().into(),
            accuracy,
            chance,
            skipped: None,
        };
        Ok(StageOutput {
            rows,
            files: Vec::new(),
            line: s.line(),
            summary: serde_json::to_value(&s).map_err(|e| StageError::Internal(e.to_string()))?,
        })
    }
}
