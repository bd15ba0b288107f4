//! `suggest-labels`: pattern labels suggested from example traces (the paper's LLM-Labels, section
//! 4.2), written to the `suggested_labels` table, which an `evolve` stage takes as its labels
//! (`labels_from`).
//!
//! A seeded sample of `examples` traces of `env` is annotated with `library` in the sandboxed worker
//! pool; a model is shown each example's initial image and annotated trace and asked for `k` labels
//! (`summary::labels`: strict parsing, `max_repairs` repairs, every call in `llm_calls`). Without an
//! endpoint (`mode = "auto"`) or with `mode = "offline"` the deterministic baseline of
//! `summary::offline_labels` is used instead. A rerun serves the calls this run already recorded, and
//! `llm.replay` reproduces another run's table without an endpoint.

use std::path::PathBuf;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::detector_setup::{DetectorSetup, SandboxParams};
use super::llm_setup::{resumable_client, stage_prompts};
use super::trace_files::{pick_trace_ids, read_traces_by_id};
use crate::detect::Annotation;
use crate::llm::{LibraryEntry, LlmSettings};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::summary::table::{self, LabelSetting};
use crate::summary::{LabelAsk, LabelsError, LlmLabeller, TraceImages, add_templates};
use crate::trace::{Env, Trace};

/// Where the labels come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum SuggestMode {
    /// `llm` when an endpoint (llm.base_url, ANNOTRACE_LLM_BASE_URL) or a replay run is configured,
    /// else `offline`.
    #[default]
    Auto,
    /// Ask the model.
    Llm,
    /// The deterministic baseline: built-in labels the library lacks, then frequent pairs of the
    /// examples' annotations.
    Offline,
}

/// The parameters of a `suggest-labels` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct SuggestLabelsParams {
    /// Environment of the example traces.
    pub env: Env,
    /// Labels asked for (the paper: 12).
    pub k: u64,
    /// Example traces shown, drawn with the seed from the run's traces of `env`.
    pub examples: u64,
    /// Only these traces (in this order) instead of a seeded sample.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub trace_ids: Option<Vec<String>>,
    /// llm, offline, or auto (llm when an endpoint or replay run is configured).
    pub mode: SuggestMode,
    /// Repair requests after an answer with problems.
    pub max_repairs: u64,
    /// Detector library whose annotations the examples show (default: the built-in library of `env`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub library: Option<String>,
    /// True: the labels must be new to `library` (its labels are listed as taken). False: a whole
    /// library is proposed and may reuse its ideas (the paper's LLM-Labels libraries).
    pub new_only: bool,
    /// What the agent in these scenes tries to do (steers the suggestions).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub objective: Option<String>,
    /// An extra instruction added to the prompt's rules.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub guidance: Option<String>,
    /// Seed of the sample and the requests (default: the pipeline's seed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Size of the initial images (px; the paper: 512).
    pub image_size: u64,
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

impl Default for SuggestLabelsParams {
    fn default() -> Self {
        let s = SandboxParams::DEFAULT;
        SuggestLabelsParams {
            env: Env::Pooltool,
            k: 12,
            examples: 3,
            trace_ids: None,
            mode: SuggestMode::Auto,
            max_repairs: 2,
            library: None,
            new_only: true,
            objective: None,
            guidance: None,
            seed: None,
            image_size: 512,
            llm: None,
            prompts: None,
            workers: s.workers,
            timeout: s.timeout,
            memory_mb: s.memory_mb,
        }
    }
}

/// What a `suggest-labels` stage reports (its manifest summary; the command prints it).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SuggestLabelsSummary {
    /// Environment.
    pub env: String,
    /// `llm` or `offline`.
    pub origin: String,
    /// The model (empty offline).
    pub model: String,
    /// The labels, in order.
    pub labels: Vec<crate::summary::ProposedLabel>,
    /// Labels asked for.
    pub k: u64,
    /// The example traces shown.
    pub examples: Vec<String>,
    /// Model answers received (0 offline).
    pub answers: u64,
    /// Problems of rejected answers.
    pub problems: Vec<String>,
    /// Prompt tokens of all calls.
    pub prompt_tokens: u64,
    /// Completion tokens of all calls.
    pub completion_tokens: u64,
}

impl SuggestLabelsSummary {
    /// One line for the terminal.
    pub fn line(&self) -> String {
        let from = if self.model.is_empty() {
            "the offline baseline".to_string()
        } else {
            format!(
                "{} ({} answer(s), {} + {} tokens)",
                self.model, self.answers, self.prompt_tokens, self.completion_tokens
            )
        };
        format!(
            "{} of {} label(s) from {from} after {} {} example trace(s): {}",
            self.labels.len(),
            self.k,
            self.examples.len(),
            self.env,
            self.labels
                .iter()
                .map(|l| l.label.as_str())
                .collect::<Vec<_>>()
                .join("; ")
        )
    }
}

/// The `suggest-labels` stage kind.
pub static KIND: StageKind = StageKind {
    name: "suggest-labels",
    summary: "pattern labels suggested from example traces (LLM with repair, or an offline baseline)",
    doc: "Draws `examples` traces of `env` from the run (seeded), annotates them with `library` in the \
          sandboxed worker pool, and asks a vision-language model shown each example's initial image (a \
          base64 PNG) and annotated trace for `k` labels, each with a description and the objects it \
          concerns (prompts/summary/labels.j2). The answer must be one JSON array of exactly `k` new, \
          distinct labels; an answer with problems is sent back with the list of problems up to \
          `max_repairs` times. Without an endpoint (mode auto) or with mode = \"offline\" a deterministic \
          baseline is used: the built-in human labels the library lacks, then the most frequent ordered \
          pairs \"A then B\" of the examples' annotations. Writes suggested_labels (one row per label); an \
          evolve stage with `labels_from` set to this stage learns detectors for them (docs/benchmark.md).",
    writes: "suggested_labels, llm_calls",
    params: ParamsOf::of::<SuggestLabelsParams>(),
    build,
};

/// The `suggest-labels` stage.
#[derive(Debug)]
pub struct SuggestLabelsStage {
    p: SuggestLabelsParams,
    setup: DetectorSetup,
    llm: LlmSettings,
    prompts: Option<PathBuf>,
    project: PathBuf,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: SuggestLabelsParams = def.params()?;
    let range = |k: &'static str, v: u64, min: u64, max: u64| {
        if v < min || v > max {
            Err(BuildError::param(
                k,
                format!("`{k}` must be in {min}..={max}, found {v}"),
            ))
        } else {
            Ok(v)
        }
    };
    range("k", p.k, 1, 100)?;
    range("examples", p.examples, 1, 20)?;
    range("max_repairs", p.max_repairs, 0, 10)?;
    range("image_size", p.image_size, 64, 1024)?;
    if let Some(ids) = &p.trace_ids
        && ids.is_empty()
    {
        return Err(BuildError::param("trace_ids", "give at least one trace id"));
    }
    if p.mode == SuggestMode::Offline && p.llm.is_some() {
        return Err(BuildError::param(
            "llm",
            "`llm` settings are not used with mode = \"offline\"",
        ));
    }
    let setup = DetectorSetup::new(
        &SandboxParams {
            env: p.env,
            library: p.library.clone(),
            workers: p.workers,
            timeout: p.timeout,
            memory_mb: p.memory_mb,
        },
        spec,
    )?;
    let mut llm = p.llm.clone().unwrap_or_default();
    if let Some(r) = &llm.replay {
        llm.replay = Some(spec.project_dir.join(r));
    }
    Ok(Box::new(SuggestLabelsStage {
        prompts: p.prompts.as_ref().map(|d| spec.project_dir.join(d)),
        p,
        setup,
        llm,
        project: spec.project_dir.clone(),
    }))
}

impl SuggestLabelsStage {
    fn endpoint_configured(&self) -> bool {
        self.llm.base_url.is_some()
            || self.llm.replay.is_some()
            || std::env::var(crate::llm::ENV_BASE_URL).is_ok_and(|v| !v.trim().is_empty())
    }

    fn uses_llm(&self) -> bool {
        match self.p.mode {
            SuggestMode::Llm => true,
            SuggestMode::Offline => false,
            SuggestMode::Auto => self.endpoint_configured(),
        }
    }

    fn seed(&self, ctx: &StageContext<'_>) -> u64 {
        self.p.seed.unwrap_or(ctx.seed())
    }

    /// The example traces: the given ids, or a seeded sample of the run's traces of `env`.
    fn examples(&self, ctx: &StageContext<'_>) -> Result<Vec<Trace>, StageError> {
        let ids = pick_trace_ids(
            ctx.run(),
            self.p.env,
            self.p.trace_ids.as_deref(),
            self.p.examples as usize,
            self.seed(ctx),
            0x1AB5,
        )?;
        if ids.is_empty() {
            return Err(StageError::TooFewTraces {
                stage: "suggest-labels",
                what: format!("{} traces in the run", self.p.env),
                needed: 1,
                found: 0,
                hint: ": add a simulate or import stage as input",
            });
        }
        read_traces_by_id(ctx.run(), &ids)
    }
}

fn labels_error(e: LabelsError) -> StageError {
    match e {
        LabelsError::Llm(e) => StageError::Llm(Box::new(e)),
        LabelsError::Render(crate::summary::SummaryError::Render { trace, source }) => {
            StageError::Simulation {
                item: format!("trace {trace}"),
                source: Box::new(source),
            }
        }
        LabelsError::Render(crate::summary::SummaryError::Llm(e)) => StageError::Llm(Box::new(e)),
        other => StageError::Labels(other.to_string()),
    }
}

impl Stage for SuggestLabelsStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({
            "library": self.setup.library.fingerprint(),
            "worker": crate::detect::worker_fingerprint(),
            "templates": crate::summary::labels::LABEL_TEMPLATES.iter().map(|(n, t)| format!("{n}:{}", crate::digest::sha256_hex(t.as_bytes()))).collect::<Vec<_>>(),
            "llm": self.uses_llm(),
        }))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let env = self.p.env;
        let seed = self.seed(ctx);
        let traces = self.examples(ctx)?;
        let pool = self.setup.pool()?;
        let annotations: Vec<Annotation> =
            crate::reward::annotate::annotate(&pool, &self.setup.library.detectors, &traces).0;
        drop(pool);
        let ask = LabelAsk {
            env,
            k: self.p.k as usize,
            known: if self.p.new_only {
                LibraryEntry::of(&self.setup.library)
            } else {
                Vec::new()
            },
            objective: self.p.objective.clone(),
            guidance: self.p.guidance.clone(),
        };
        let (suggested, origin, model) = if self.uses_llm() {
            let client = resumable_client(&self.llm, seed, ctx.run())?;
            let prompts = stage_prompts(self.prompts.as_ref(), &self.project, add_templates)?;
            let images =
                TraceImages::new(self.p.image_size as u32).map_err(|e| StageError::Simulation {
                    item: "renderer".into(),
                    source: Box::new(e),
                })?;
            let labeller = LlmLabeller {
                client: &client,
                prompts: &prompts,
                images: &images,
                max_repairs: self.p.max_repairs as usize,
                seed,
                temperature: None,
            };
            let result = labeller.suggest(&ask, &traces, &annotations);
            // Every call is recorded, whether or not its answer was usable.
            client.flush()?;
            (
                result.map_err(labels_error)?,
                "llm",
                client.model().to_string(),
            )
        } else {
            let labels = crate::summary::offline_labels(&ask, &traces, &annotations)?;
            if labels.is_empty() {
                return Err(StageError::Labels(format!(
                    "the offline baseline found no new label: every built-in {env} label is in library {} and the {} example trace(s) show no pair of patterns; add examples or use a model",
                    self.setup.library.name,
                    traces.len()
                )));
            }
            (
                crate::summary::Suggested {
                    labels,
                    ..Default::default()
                },
                "offline",
                String::new(),
            )
        };
        let examples: Vec<String> = traces.iter().map(|t| t.trace_id.clone()).collect();
        let setting = LabelSetting {
            run_stage: ctx.stage_id().to_string(),
            origin: origin.into(),
            model: model.clone(),
            k: self.p.k as i64,
            library: self.setup.library.name.clone(),
            examples: examples.clone(),
            calls: suggested.calls.clone(),
            problems: suggested.problems.clone(),
            prompt_tokens: suggested.tokens_in as i64,
            completion_tokens: suggested.tokens_out as i64,
            seconds: suggested.seconds,
            seed: seed as i64,
        };
        let n = ctx.write_batch(
            table::SUGGESTED_LABELS,
            env,
            "labels",
            &table::suggested_labels_batch(&setting, &suggested.labels)?,
        )?;
        let s = SuggestLabelsSummary {
            env: env.to_string(),
            origin: origin.into(),
            model,
            labels: suggested.labels.clone(),
            k: self.p.k,
            examples,
            answers: suggested.calls.len() as u64,
            problems: suggested.problems,
            prompt_tokens: suggested.tokens_in,
            completion_tokens: suggested.tokens_out,
        };
        Ok(StageOutput {
            rows: [(table::SUGGESTED_LABELS.to_string(), n)]
                .into_iter()
                .collect(),
            files: Vec::new(),
            line: s.line(),
            summary: serde_json::to_value(&s).map_err(|e| StageError::Internal(e.to_string()))?,
        })
    }
}

/// The labels a finished `suggest-labels` stage `stage` wrote in `run`, by rank.
pub fn read_suggested_labels(
    run: &crate::store::RunDir,
    stage: &str,
) -> Result<Vec<String>, StageError> {
    let mut batches = Vec::new();
    for f in run.table(table::SUGGESTED_LABELS)?.files {
        batches.extend(crate::store::read_file(&f.path)?);
    }
    Ok(table::suggested_labels_of(&batches, stage))
}
