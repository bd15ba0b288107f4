//! `evolve`: learns detectors for labels by evolutionary search over a run's traces (the paper's
//! Algorithms 1–3), starting from a library, and writes the `candidates`, `evolution_labels`,
//! `evolution_histograms`, `evolution_convergence` and `trace_distances` (training and held-out D_x)
//! tables and the grown library as a folder.
//!
//! Sharded runs (`annotrace run --shard i/n`): the stage is one unit, `NNNNN` (its position among the
//! pipeline's `evolve` stages), computed whole by the slice that owns it — its labels cannot be split,
//! since each label's novelty is scored against the library the labels before it grew (Algorithm 2) —
//! while sibling `evolve` stages (none upstream of another) are computed by other slices at the same
//! time. The commit replays the saved rounds, decides the D_x matrices (written, or reused from an
//! earlier stage, as in the unsharded run: a slice writes none) and writes the library folder.
//!
//! Resumable: each round of a label's search is a shard whose record holds the round's candidates, so a
//! killed stage replays its finished rounds and continues (an LLM search also answers the requests its
//! stopped attempt had recorded in `llm_calls` from there); each label's tables are written by a last
//! shard of that label. `lag` (unset: 1 with an LLM, 0 with mutate) decides whether the next round's
//! requests are in flight while a round is scored (`search::run`). The D_x matrix of the training set is looked up in the run's
//! `trace_distances` (any stage's) before it is computed.

use std::cell::RefCell;
use std::path::PathBuf;
use std::sync::Arc;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::detector_setup::{DetectorSetup, SandboxParams};
use super::trace_files::{HashSplit, env_trace_ids, read_split, split_ids};
use crate::fitness::table::{distances_batch, matrix_from_batches, set_id_with};
use crate::fitness::{DistanceMatrix, Dp, Dx};
use crate::llm::{LlmClient, LlmConfig, LlmSettings, Prompts};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::search::candidate::candidates_batch;
use crate::search::library_out::write_library;
use crate::search::run::Checkpoint;
use crate::search::tables::{
    SetIds, convergence_batch, histograms_batch, labels_batch, samples_batch,
};
use crate::search::{
    CandidateRecord, Discovery, EvalSettings, LlmProposer, MutateProposer, ProposalTally, Proposer,
    SearchConfig, SearchError, Strategy, Temperatures,
};
use crate::trace::{Env, Trace};

/// The `evolve` stage kind.
pub static KIND: StageKind = StageKind {
    name: "evolve",
    summary: "learn detectors for labels by evolutionary search (FunSearch islands, mutate or LLM proposer)",
    doc: "For each label in `labels` (default: every label of the library), searches for a detector program \
          maximising the paper's fitness ν = ρ + η − λ − ψ on the run's `env` traces (a training split; \
          `holdout` of them kept for the convergence statistics), starting from the library's detector \
          for the label (or a skeleton), and adds the best to the library when ν > delta and its ρ on the \
          held-out traces is positive (Algorithm 2; `allow_nonpositive_rho` drops the ρ test). `dp` chooses \
          the annotation distance d_p (kl, js or the paper's literal cross-entropy). \
          Every candidate goes to the candidates table; the grown library is written as a folder \
          (default exports/<stage>/library) that `annotate` reads. See docs/evolution.md.",
    writes: "candidates, evolution_labels, evolution_histograms, evolution_samples, evolution_convergence, trace_distances, exports/<stage>/library/",
    params: ParamsOf::of::<EvolveParams>(),
    build,
};

/// Where an evolve stage's children come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ProposerChoice {
    /// `llm` when an endpoint (llm.base_url or ANNOTRACE_LLM_BASE_URL) or a replay run is
    /// configured, else `mutate`.
    #[default]
    Auto,
    /// Syntax-tree edits of the parents (no model needed).
    Mutate,
    /// An OpenAI-compatible chat endpoint.
    Llm,
}

impl ProposerChoice {
    /// `auto`, `mutate` or `llm`.
    pub fn as_str(self) -> &'static str {
        match self {
            ProposerChoice::Auto => "auto",
            ProposerChoice::Mutate => "mutate",
            ProposerChoice::Llm => "llm",
        }
    }
}

/// The parameters of an `evolve` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct EvolveParams {
    /// Environment whose traces are used.
    pub env: Env,
    /// Starting library folder, relative to the project folder (default: `data/libraries/<env>`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub library: Option<String>,
    /// Labels to learn, in order (default: the library's labels).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub labels: Option<Vec<String>>,
    /// Learn the labels a `suggest-labels` stage wrote (its id; it must be one of this stage's inputs)
    /// instead of `labels`, in their rank order.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub labels_from: Option<String>,
    /// Start from an empty library instead of `library`'s detectors: the grown library then holds
    /// only the accepted detectors of the learned labels (the paper's LLM-Labels libraries); `library`
    /// still names the environment's sandbox defaults.
    pub start_empty: bool,
    /// Search strategy.
    pub strategy: Strategy,
    /// Where children come from: syntax-tree edits (mutate) or an LLM; auto = llm when an endpoint
    /// (llm.base_url or ANNOTRACE_LLM_BASE_URL) or a replay run is configured, else mutate.
    pub proposer: ProposerChoice,
    /// LLM settings (base_url, model, parallel, timeout_s, call_timeout_s, max_retries, max_calls,
    /// max_tokens, temperature, replay, …; docs/llm.md), over the ANNOTRACE_LLM_* variables.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub llm: Option<LlmSettings>,
    /// Prompt template folder, relative to the project (default: `<project>/prompts` if present, else
    /// built-in).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prompts: Option<String>,
    /// Proposals per label.
    pub budget: u64,
    /// Islands I.
    pub islands: u64,
    /// Parents per proposal s.
    pub prompt_size: u64,
    /// Reset the weaker half of the islands every T_r steps (0: never).
    pub reset_period: u64,
    /// Acceptance threshold δ on ν.
    pub delta: f64,
    /// Also accept a best detector whose ρ on the held-out traces is ≤ 0 (default: never; noise).
    pub allow_nonpositive_rho: bool,
    /// Annotation distance d_p of ρ and η: kl (symmetrised Kullback–Leibler, 0 for identical
    /// annotations), js (Jensen–Shannon) or cross-entropy (the paper's wording; docs/evolution.md).
    pub dp: Dp,
    /// Trace distance d_x of ρ: positions (the paper's: matched objects where they are) or invariant
    /// (each matched object's trajectory aligned by a rigid Procrustes fit first; docs/evolution.md).
    pub dx: Dx,
    /// Accuracy guard of acceptance: for an event-grounded label, also reject a best program whose
    /// F1 against the simulator's ground truth on the held-out traces is below the seed's by more
    /// than `max_f1_drop` (docs/evolution.md).
    pub accuracy_guard: bool,
    /// The largest F1 drop the accuracy guard accepts.
    pub max_f1_drop: f64,
    /// Proposals requested at once.
    pub parallel: u64,
    /// Rounds between the database a round's prompts come from and the round: 0 samples round r's
    /// parents after round r − 1 is scored; 1 after round r − 2, so round r's requests are in flight
    /// while round r − 1 is scored (evaluation overlaps generation; the same seed and answers give
    /// the same search). Default: 1 with the LLM proposer, 0 with mutate (docs/evolution.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lag: Option<u64>,
    /// Repair requests per failed child (proposers that repair).
    pub repair_attempts: u64,
    /// Training traces at most (and held-out traces at most).
    pub max_traces: u64,
    /// Fraction of traces held out (the acceptance test's ρ and the convergence statistics).
    pub holdout: f64,
    /// Training traces in the probe set (cheap checks).
    pub probe: u64,
    /// Time bins b of the annotation histograms.
    pub bins: u64,
    /// Normalised-time samples per trace for d_x.
    pub samples: u64,
    /// Compute ψ from wall time (off: reproducible scores).
    pub time_penalty: bool,
    /// Detectors per 10 % bin compared on the held-out traces (0: skip).
    pub convergence_per_bin: u64,
    /// Mutate proposer: edits per child at most.
    pub max_edits: u64,
    /// Search seed (default: the pipeline's seed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Folder for the grown library, relative to the project (default:
    /// `<run>/exports/<stage>/library`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub output: Option<String>,
    /// Python worker processes (0 = one per core).
    pub workers: u64,
    /// Wall-clock limit of one detector call (s).
    pub timeout: f64,
    /// Address-space limit of a worker (MiB).
    pub memory_mb: u64,
}

impl EvolveParams {
    /// The defaults: the search's own ([`SearchConfig::DEFAULT`], [`EvalSettings::DEFAULT`]), the
    /// sandbox's ([`SandboxParams::DEFAULT`]) and this stage's.
    pub const DEFAULT: EvolveParams = {
        let search = SearchConfig::DEFAULT;
        let eval = EvalSettings::DEFAULT;
        let sandbox = SandboxParams::DEFAULT;
        EvolveParams {
            env: sandbox.env,
            library: None,
            labels: None,
            labels_from: None,
            start_empty: false,
            strategy: search.strategy,
            proposer: ProposerChoice::Auto,
            llm: None,
            prompts: None,
            budget: search.budget,
            islands: search.islands as u64,
            prompt_size: search.prompt_size as u64,
            reset_period: search.reset_period,
            delta: search.delta,
            allow_nonpositive_rho: search.allow_nonpositive_rho,
            dp: eval.dp,
            dx: Dx::Positions,
            accuracy_guard: false,
            max_f1_drop: 0.1,
            parallel: search.parallel as u64,
            lag: None,
            repair_attempts: search.repair_attempts as u64,
            max_traces: 100,
            holdout: 0.2,
            probe: eval.probe as u64,
            bins: eval.bins as u64,
            samples: 64,
            time_penalty: eval.time_penalty,
            convergence_per_bin: 3,
            max_edits: 2,
            seed: None,
            output: None,
            workers: sandbox.workers,
            timeout: sandbox.timeout,
            memory_mb: sandbox.memory_mb,
        }
    };
}

impl Default for EvolveParams {
    fn default() -> Self {
        EvolveParams::DEFAULT
    }
}

impl EvolveParams {
    /// The sandbox part.
    fn sandbox(&self) -> SandboxParams {
        SandboxParams {
            env: self.env,
            library: self.library.clone(),
            workers: self.workers,
            timeout: self.timeout,
            memory_mb: self.memory_mb,
        }
    }
}

/// What an `evolve` stage reports (its manifest summary, read back by `annotrace evolve`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EvolveSummary {
    /// The environment.
    pub env: Env,
    /// The search seed.
    pub seed: u64,
    /// The search strategy.
    pub strategy: Strategy,
    /// The proposer's name (`mutate`, or `llm:<model>`).
    pub proposer: String,
    /// Proposals per label.
    pub budget: u64,
    /// The annotation distance d_p.
    pub dp: Dp,
    /// The trace distance d_x (absent from summaries recorded before it was added: positions).
    #[serde(default)]
    pub dx_kind: Dx,
    /// Training traces.
    pub train: u64,
    /// Held-out traces.
    pub holdout: u64,
    /// The D_x matrix of the training set.
    pub dx: DxSummary,
    /// One entry per label, in order.
    pub labels: Vec<LabelSummary>,
    /// Labels whose best detector was added to the library.
    pub accepted: usize,
    /// The proposals of every label by outcome (a stage whose every proposal failed is an error
    /// instead; absent from summaries recorded before it was added).
    #[serde(default)]
    pub proposals: ProposalTally,
    /// The grown library's folder.
    pub library: String,
    /// Wall time of the stage (s).
    pub wall_s: f64,
    /// Wall time during which a proposal or repair was in flight (s), summed over the labels.
    pub propose_s: f64,
    /// Share of the labels' search wall time outside the proposer (no proposal in flight).
    pub outside_proposer_share: f64,
    /// The lag the search ran with (0: rounds alternate; 1: evaluation overlaps the next requests;
    /// absent from summaries recorded before it was added).
    #[serde(default)]
    pub lag: u64,
    /// The sandbox layers the workers run under.
    pub sandbox: Value,
}

/// The D_x matrix an `evolve` stage used.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DxSummary {
    /// Trace pairs.
    pub pairs: u64,
    /// Whether it was read from the run's `trace_distances` instead of computed.
    pub reused: bool,
    /// Seconds spent on it.
    pub seconds: f64,
}

/// One label's search, as an `evolve` stage reports it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LabelSummary {
    /// The label.
    pub label: String,
    /// ν of the starting detector.
    pub seed_nu: f64,
    /// ν of the best candidate.
    pub best_nu: f64,
    /// Every fitness term of the best candidate.
    pub best_terms: crate::fitness::FitnessTerms,
    /// Whether the best candidate was added to the library (ν > δ and held-out ρ > 0).
    pub accepted: bool,
    /// `accepted`, `below_delta` or `nonpositive_rho`.
    pub acceptance: crate::search::Acceptance,
    /// ρ of the best candidate on the held-out traces (none without enough of them).
    pub holdout_rho: Option<f64>,
    /// The accuracy guard's F1 of the seed and the best program (absent when it did not run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub guard: Option<crate::search::GuardCheck>,
    /// Candidates evaluated.
    pub candidates: u64,
    /// Best ν after each step.
    pub best_by_step: Vec<f64>,
    /// Wall time of the label's search (s).
    pub wall_s: f64,
    /// Wall time during which a proposal or repair was in flight (s).
    pub propose_s: f64,
}

/// The `evolve` stage.
#[derive(Debug)]
pub struct EvolveStage {
    setup: DetectorSetup,
    labels: Vec<String>,
    labels_from: Option<String>,
    start_empty: bool,
    config: SearchConfig,
    /// The `lag` parameter (`None`: by proposer).
    lag: Option<u64>,
    seed: Option<u64>,
    eval: EvalSettings,
    proposer: ProposerChoice,
    llm: LlmSettings,
    prompts: Option<PathBuf>,
    project: PathBuf,
    max_traces: usize,
    holdout: f64,
    samples: usize,
    dx: Dx,
    accuracy_guard: Option<crate::search::AccuracyGuard>,
    convergence_per_bin: usize,
    max_edits: u32,
    output: Option<PathBuf>,
    /// The stage's one unit in a sharded run: `NNNNN`, its position among the pipeline's `evolve`
    /// stages (so sibling searches fall to different slices).
    unit: String,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: EvolveParams = def.params()?;
    let setup = DetectorSetup::new(&p.sandbox(), spec)?;
    if let Some(from) = &p.labels_from {
        if p.labels.is_some() {
            return Err(BuildError::param(
                "labels_from",
                "give `labels` or `labels_from`, not both",
            ));
        }
        if !def.inputs.contains(from) {
            return Err(BuildError::param(
                "labels_from",
                format!("`labels_from` = {from:?} must be one of the stage's inputs"),
            ));
        }
        match spec.stages.iter().find(|s| &s.id == from) {
            Some(s) if s.kind.name == super::suggest_labels::KIND.name => {}
            _ => {
                return Err(BuildError::param(
                    "labels_from",
                    format!("`labels_from` = {from:?} must name a suggest-labels stage"),
                ));
            }
        }
    }
    let labels: Vec<String> = match &p.labels {
        Some(a) => a.clone(),
        None if p.labels_from.is_some() => vec!["(from suggest-labels)".to_string()],
        None => setup
            .library
            .labels()
            .into_iter()
            .map(str::to_string)
            .collect(),
    };
    if labels.iter().any(|l| l.trim().is_empty()) {
        return Err(BuildError::param(
            "labels",
            "labels must not be empty strings",
        ));
    }
    if labels.is_empty() {
        return Err(BuildError::param("labels", "no label to learn"));
    }
    if !(0.0..1.0).contains(&p.holdout) {
        return Err(BuildError::param(
            "holdout",
            format!("holdout must be in [0, 1), found {}", p.holdout),
        ));
    }
    if !p.delta.is_finite() {
        return Err(BuildError::param("delta", "delta must be a finite number"));
    }
    if !(0.0..=1.0).contains(&p.max_f1_drop) {
        return Err(BuildError::param(
            "max_f1_drop",
            format!("max_f1_drop must be in [0, 1], found {}", p.max_f1_drop),
        ));
    }
    if p.budget == 0 {
        return Err(BuildError::param("budget", "budget must be at least 1"));
    }
    if let Some(lag) = p.lag.filter(|&l| l > 1) {
        return Err(BuildError::param(
            "lag",
            format!("lag must be 0 or 1, found {lag}"),
        ));
    }
    let mut llm = p.llm.clone().unwrap_or_default();
    if let Some(r) = &llm.replay {
        llm.replay = Some(spec.project_dir.join(r));
    }
    Ok(Box::new(EvolveStage {
        labels,
        labels_from: p.labels_from.clone(),
        start_empty: p.start_empty,
        config: SearchConfig {
            strategy: p.strategy,
            islands: p.islands.max(1) as usize,
            prompt_size: p.prompt_size.max(1) as usize,
            reset_period: p.reset_period,
            budget: p.budget,
            delta: p.delta,
            allow_nonpositive_rho: p.allow_nonpositive_rho,
            parallel: p.parallel.max(1) as usize,
            lag: p.lag.unwrap_or(0),
            overlap: true,
            repair_attempts: p.repair_attempts.min(u64::from(u32::MAX)) as u32,
            temperatures: Temperatures::default(),
            seed: 0,
        },
        lag: p.lag,
        seed: p.seed,
        eval: EvalSettings {
            bins: p.bins.max(1) as usize,
            dp: p.dp,
            probe: p.probe.max(1) as usize,
            time_penalty: p.time_penalty,
        },
        proposer: p.proposer,
        max_traces: p.max_traces.max(2) as usize,
        holdout: p.holdout,
        samples: p.samples.max(2) as usize,
        dx: p.dx,
        accuracy_guard: p.accuracy_guard.then_some(crate::search::AccuracyGuard {
            max_drop: p.max_f1_drop,
            tolerance: 0.05,
        }),
        convergence_per_bin: p.convergence_per_bin as usize,
        max_edits: p.max_edits.clamp(1, u64::from(u32::MAX)) as u32,
        llm,
        prompts: p.prompts.as_ref().map(|d| spec.project_dir.join(d)),
        project: spec.project_dir.clone(),
        output: p.output.as_ref().map(|o| spec.project_dir.join(o)),
        unit: format!(
            "{:05}",
            spec.stages
                .iter()
                .take_while(|s| s.id != def.id)
                .filter(|s| s.kind.name == KIND.name)
                .count()
        ),
        setup,
    }))
}

/// The files of a written library folder (the runner removes a stage's files before it reruns).
fn library_files(dir: &std::path::Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .collect();
    out.sort();
    out
}

/// The proposer of a stage and, for the LLM proposer, its client (flushed at the end).
type ProposerAndClient = (Box<dyn Proposer>, Option<Arc<LlmClient>>);

/// Rounds checkpointed as shards of the stage.
struct StagingCheckpoint<'a, 'b> {
    ctx: &'a StageContext<'b>,
    failure: RefCell<Option<StageError>>,
    /// The LLM client, whose recorded calls are written out before each round is saved: every
    /// answer a saved round or a round still in flight received is then in `llm_calls`, for a resumed
    /// search to replay.
    calls: Option<Arc<LlmClient>>,
}

impl StagingCheckpoint<'_, '_> {
    fn shard(l: u32, r: u64) -> String {
        format!("L{l:03}.R{r:05}")
    }
    fn fail(&self, e: StageError) -> SearchError {
        let msg = e.to_string();
        *self.failure.borrow_mut() = Some(e);
        SearchError::Checkpoint(msg)
    }
}

impl Checkpoint for StagingCheckpoint<'_, '_> {
    fn load(&self, l: u32, r: u64) -> Result<Option<Vec<CandidateRecord>>, SearchError> {
        let rec = self
            .ctx
            .finished_shard(&Self::shard(l, r))
            .map_err(|e| self.fail(e))?;
        match rec {
            None => Ok(None),
            Some(v) => {
                let records: Vec<CandidateRecord> = serde_json::from_value(v["records"].clone())
                    .map_err(|e| {
                        SearchError::Checkpoint(format!("unreadable round record: {e}"))
                    })?;
                self.ctx.progress().advance(
                    self.ctx.stage_id(),
                    records.iter().filter(|r| r.step >= 0).count() as u64,
                );
                Ok(Some(records))
            }
        }
    }
    fn save(&self, l: u32, r: u64, records: &[CandidateRecord]) -> Result<(), SearchError> {
        if let Some(client) = &self.calls {
            client
                .flush()
                .map_err(|e| SearchError::Checkpoint(format!("recording the LLM calls: {e}")))?;
        }
        self.ctx.progress().advance(
            self.ctx.stage_id(),
            records.iter().filter(|r| r.step >= 0).count() as u64,
        );
        self.ctx
            .finish_shard(&Self::shard(l, r), &json!({"records": records}))
            .map_err(|e| self.fail(e))
    }
}

impl EvolveStage {
    /// The proposer this stage uses (see the `proposer` parameter), and the LLM client behind it.
    fn proposer(&self, ctx: &StageContext<'_>, seed: u64) -> Result<ProposerAndClient, StageError> {
        let env_url = std::env::var(crate::llm::ENV_BASE_URL)
            .ok()
            .filter(|v| !v.trim().is_empty());
        let use_llm = match self.proposer {
            ProposerChoice::Llm => true,
            ProposerChoice::Mutate => false,
            ProposerChoice::Auto => {
                self.llm.base_url.is_some() || self.llm.replay.is_some() || env_url.is_some()
            }
        };
        if !use_llm {
            let m = MutateProposer::new(None, self.max_edits)?;
            return Ok((Box::new(m), None));
        }
        let mut settings = self.llm.clone();
        settings.seed = Some(settings.seed.unwrap_or(seed));
        // A resumed search answers the requests its stopped attempt already had answered (the round
        // being scored and the one in flight, which no saved round holds) from this run's
        // `llm_calls`, and sends only the others to the endpoint.
        let resuming = ctx
            .finished_shard(&StagingCheckpoint::shard(0, 0))?
            .is_some();
        if resuming && settings.replay.is_none() {
            settings.replay = Some(ctx.run().root().to_path_buf());
            settings.strict_replay = Some(false);
        }
        let config = LlmConfig::resolve(&settings, &|k| std::env::var(k).ok())?;
        let dir = self
            .prompts
            .clone()
            .or_else(|| Some(self.project.join("prompts")).filter(|d| d.is_dir()));
        let prompts = Prompts::load(dir.as_deref())?;
        let client = Arc::new(LlmClient::new(config, Some(ctx.run()))?);
        let proposer = LlmProposer::new(client.clone(), Arc::new(prompts));
        Ok((Box::new(proposer), Some(client)))
    }

    /// The run's traces of `env`, split into training and held-out sets (at least 3 traces, 2 for
    /// training). The split is made on the ids; only the traces it keeps are read.
    fn load_split(
        &self,
        ctx: &StageContext<'_>,
        env: Env,
        seed: u64,
    ) -> Result<(Vec<Trace>, Vec<Trace>), StageError> {
        let ids = env_trace_ids(ctx.run(), env)?;
        if ids.len() < 3 {
            return Err(StageError::TooFewTraces {
                stage: "evolve",
                what: format!("{env} traces in the run"),
                needed: 3,
                found: ids.len(),
                hint: ": add a simulate or import stage as input",
            });
        }
        let (train, holdout) = split_ids(
            ids,
            HashSplit {
                seed,
                salt: 0x401D,
                aside: self.holdout,
                max_kept: self.max_traces,
                max_aside: self.max_traces,
            },
        );
        if train.len() < 2 {
            return Err(StageError::TooFewTraces {
                stage: "evolve",
                what: "training traces after the held-out split".into(),
                needed: 2,
                found: train.len(),
                hint: ": lower `holdout` or add traces",
            });
        }
        read_split(ctx.run(), (train, holdout))
    }

    /// Writes the grown library (to `output`, default `exports/<stage>/library`) and returns its folder.
    fn write_evolved(
        &self,
        ctx: &StageContext<'_>,
        config: &SearchConfig,
        proposer: &str,
        library: &[crate::detect::Detector],
    ) -> Result<PathBuf, StageError> {
        let stage = ctx.stage_id();
        let env = self.setup.env;
        let out_dir = self
            .output
            .clone()
            .unwrap_or_else(|| ctx.run().exports_dir().join(stage).join("library"));
        let (name, from) = if self.start_empty {
            (format!("{env}-{stage}"), "an empty library".to_string())
        } else {
            (
                format!("{}-evolved", self.setup.library.name),
                self.setup.library.name.clone(),
            )
        };
        let description = format!(
            "{from} grown by evolve stage {stage} (seed {}, {} strategy, {} proposer, budget {} per label)",
            config.seed,
            config.strategy.as_str(),
            proposer,
            config.budget
        );
        write_library(&out_dir, &name, env, &description, library)
            .map_err(|e| StageError::io(&out_dir, e))?;
        Ok(out_dir)
    }

    /// The D_x matrix of `train` (the training or held-out traces) and its set id: read from the run's
    /// `trace_distances` when an earlier stage stored it, else computed and written as shard `shard`.
    fn training_distances(
        &self,
        ctx: &StageContext<'_>,
        env: Env,
        train: &[Trace],
        shard: &str,
    ) -> Result<(DistanceMatrix, String, bool), StageError> {
        let ids: Vec<String> = train.iter().map(|t| t.trace_id.clone()).collect();
        let sid = set_id_with(&ids, self.samples, self.dx);
        // This stage's own matrix, computed by an earlier attempt (a resumed or sharded run) and
        // still staged, is not a reuse: its rows are this stage's, counted as an uninterrupted run
        // counts them.
        let own = ctx.staging().table_files("trace_distances")?;
        let published: Vec<PathBuf> = ctx
            .run()
            .table("trace_distances")?
            .files
            .into_iter()
            .filter(|f| f.env == Some(env))
            .map(|f| f.path)
            .collect();
        let staged = own.len();
        for (k, f) in own.into_iter().chain(published).enumerate() {
            let batches = crate::store::read_file(&f)?;
            if let Some(m) = matrix_from_batches(&sid, &ids, &batches) {
                return Ok((m, sid, k >= staged));
            }
        }
        let m = DistanceMatrix::compute_with(train, self.samples, self.dx);
        if ctx.slice().is_some() {
            // A slice's search: the commit decides whether the matrix is this stage's to write or an
            // earlier stage's to reuse (a sibling search may not have committed it yet), as the
            // unsharded run would.
            return Ok((m, sid, false));
        }
        let b = distances_batch(&sid, &m)?;
        ctx.write_batch("trace_distances", env, shard, &b)?;
        ctx.finish_shard(shard, &json!({"set_id": sid, "pairs": m.upper.len()}))?;
        Ok((m, sid, false))
    }
}

/// Where [`StagingCheckpoint::write_label`] writes a finished label's rows.
struct LabelTables<'a> {
    stage: &'a str,
    env: Env,
    config: &'a SearchConfig,
    sets: &'a SetIds,
    proposer: &'a str,
}

impl StagingCheckpoint<'_, '_> {
    /// Writes label number `m`'s candidates, summary and convergence rows as shard `L<m>.final`
    /// (once: a finished shard's row counts are read back), adding the counts to `rows`.
    fn write_label(
        &self,
        t: &LabelTables<'_>,
        m: u32,
        r: &crate::search::LabelResult,
        rows: &mut std::collections::BTreeMap<String, u64>,
    ) -> Result<(), SearchError> {
        let ctx = self.ctx;
        let o = &r.outcome;
        let shard = format!("L{m:03}.final");
        let done = ctx.finished_shard(&shard).map_err(|e| self.fail(e))?;
        if let Some(rec) = done {
            for (t, n) in rec["rows"].as_object().into_iter().flatten() {
                *rows.entry(t.clone()).or_default() += n.as_u64().unwrap_or(0);
            }
            return Ok(());
        }
        let mut written = serde_json::Map::new();
        let mut put = |table: &str,
                       b: Result<arrow::array::RecordBatch, arrow::error::ArrowError>|
         -> Result<(), SearchError> {
            let b = b.map_err(|e| self.fail(e.into()))?;
            if b.num_rows() == 0 {
                return Ok(());
            }
            let n = ctx
                .write_batch(table, t.env, &shard, &b)
                .map_err(|e| self.fail(e))?;
            *rows.entry(table.to_string()).or_default() += n;
            written.insert(table.into(), json!(n));
            Ok(())
        };
        put(
            "candidates",
            candidates_batch(t.stage, t.config.budget, &o.records),
        )?;
        put(
            "evolution_labels",
            labels_batch(t.stage, t.config, t.sets, t.proposer, m, r),
        )?;
        put("evolution_histograms", histograms_batch(t.stage, t.sets, r))?;
        put(
            "evolution_samples",
            samples_batch(t.stage, t.sets, &r.samples),
        )?;
        put(
            "evolution_convergence",
            convergence_batch(t.stage, &r.convergence),
        )?;
        ctx.finish_shard(&shard, &json!({"rows": written}))
            .map_err(|e| self.fail(e))
    }
}

/// A finished label's summary entry and its terminal fragment (`label: ν a → b`).
fn label_summary(r: &crate::search::LabelResult) -> (LabelSummary, String) {
    let o = &r.outcome;
    let summary = LabelSummary {
        label: o.label.clone(),
        seed_nu: o.seed_nu,
        best_nu: o.best.terms.nu,
        best_terms: o.best.terms,
        accepted: r.accepted,
        acceptance: r.acceptance,
        holdout_rho: r.holdout_rho,
        guard: r.guard,
        candidates: o.records.len() as u64,
        best_by_step: o.best_by_step.clone(),
        wall_s: o.wall_s,
        propose_s: o.propose_s,
    };
    let rho = r
        .holdout_rho
        .map_or(String::new(), |x| format!(", held-out ρ {x:.3}"));
    let verdict = match r.acceptance {
        crate::search::Acceptance::Accepted => "",
        crate::search::Acceptance::BelowDelta => " (rejected: ν ≤ δ)",
        crate::search::Acceptance::NonpositiveRho => " (rejected: ρ ≤ 0)",
        crate::search::Acceptance::AccuracyDrop => " (rejected: F1 fell)",
    };
    let guard = r.guard.map_or(String::new(), |g| {
        format!(", F1 {:.3} → {:.3}", g.seed_f1, g.best_f1)
    });
    let line = format!(
        "{}: ν {:.4} → {:.4}{rho}{guard}{verdict}",
        o.label, o.seed_nu, o.best.terms.nu,
    );
    (summary, line)
}

/// Runs `f` with the LLM client's "still waiting" notices shown as notes of the stage's progress (so
/// the command line prints them with its other progress lines rather than as log lines).
fn with_wait_notices<T>(
    ctx: &StageContext<'_>,
    client: Option<&LlmClient>,
    f: impl FnOnce() -> T,
) -> T {
    let Some(client) = client else {
        return f();
    };
    let (tx, rx) = std::sync::mpsc::channel::<String>();
    client.set_wait_observer(Arc::new(move |n| {
        let _ = tx.send(n.to_string());
    }));
    /// Drops the observer (the only sender) however `f` ends, which ends the printing thread.
    struct Clear<'c>(&'c LlmClient);
    impl Drop for Clear<'_> {
        fn drop(&mut self) {
            self.0.clear_wait_observer();
        }
    }
    let (progress, stage) = (ctx.progress(), ctx.stage_id());
    std::thread::scope(|s| {
        s.spawn(move || {
            for line in rx {
                progress.note(stage, &line);
            }
        });
        let _clear = Clear(client);
        f()
    })
}

impl Stage for EvolveStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        let h = |s: &str| crate::search::code_hash(s);
        Ok(json!({
            "library": self.setup.library.fingerprint(),
            "worker": crate::detect::worker_fingerprint(),
            "mutate": h(crate::search::mutate::MUTATE_PY),
            "skeleton": h(&crate::search::skeleton::skeleton(self.setup.env, "x")),
            "dx_version": crate::fitness::table::DX_VERSION,
        }))
    }

    /// One unit, the whole search (see the module documentation): computed by the slice that owns
    /// it, then replayed from its saved rounds by the commit, which writes the tables' last parts
    /// and the library folder.
    fn shardable(&self) -> bool {
        true
    }

    /// Sibling searches read the same traces and write only their own tables; the D_x matrix they
    /// may share is decided at the commit, in run order.
    fn runs_beside_siblings(&self) -> bool {
        true
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        if !ctx.owns(&self.unit) {
            // Another slice's search (`--shard`).
            return Ok(StageOutput::default());
        }
        if ctx
            .finished_shard(&StagingCheckpoint::shard(0, 0))?
            .is_some()
        {
            ctx.progress().note(
                ctx.stage_id(),
                "replaying the rounds an earlier attempt or slice saved",
            );
        }
        let env = self.setup.env;
        let mut config = self.config.clone();
        config.seed = self.seed.unwrap_or(ctx.seed());
        let labels = match &self.labels_from {
            None => self.labels.clone(),
            Some(id) => {
                let l = super::suggest_labels::read_suggested_labels(ctx.run(), id)?;
                if l.is_empty() {
                    return Err(StageError::Input(format!(
                        "`labels_from`: stage {id:?} wrote no suggested_labels rows"
                    )));
                }
                l
            }
        };
        let (train, holdout) = self.load_split(ctx, env, config.seed)?;
        ctx.progress()
            .set_total(ctx.stage_id(), config.budget * labels.len() as u64);
        let t_dx = std::time::Instant::now();
        let (dx, train_set, reused) = self.training_distances(ctx, env, &train, "dx")?;
        let (holdout_dx, holdout_set, holdout_reused) =
            if holdout.len() >= crate::search::discover::MIN_HOLDOUT {
                let (m, sid, r) = self.training_distances(ctx, env, &holdout, "dx_holdout")?;
                (m, Some(sid), r)
            } else {
                let empty = DistanceMatrix {
                    ids: Vec::new(),
                    upper: Vec::new(),
                };
                (empty, None, true)
            };
        let sets = SetIds {
            dp: self.eval.dp,
            dx: self.dx,
            train: train_set,
            train_ids: dx.ids.clone(),
            holdout: holdout_set,
            holdout_ids: holdout_dx.ids.clone(),
        };
        let dx_s = t_dx.elapsed().as_secs_f64();
        let mut limits = self.setup.limits.clone();
        limits.trace_cache = limits.trace_cache.max(train.len() + holdout.len() + 4);
        let pool = crate::detect::WorkerPool::new(limits)?;
        let (proposer, llm_client) = self.proposer(ctx, config.seed)?;
        // Overlap by default when proposals are slow (a model), not with the offline proposer.
        config.lag = self.lag.unwrap_or(u64::from(llm_client.is_some()));
        let checkpoint = StagingCheckpoint {
            ctx,
            failure: RefCell::new(None),
            calls: llm_client.clone(),
        };
        let stage = ctx.stage_id().to_string();
        let discovery = Discovery {
            pool: &pool,
            env,
            train: &train,
            holdout: &holdout,
            dx: &dx,
            holdout_dx: &holdout_dx,
            config: &config,
            eval: self.eval.clone(),
            proposer: proposer.as_ref(),
            checkpoint: &checkpoint,
            source: format!("evolve:{stage}"),
            convergence_per_bin: self.convergence_per_bin,
            accuracy_guard: self.accuracy_guard,
        };
        let mut rows: std::collections::BTreeMap<String, u64> = Default::default();
        let mut label_lines = Vec::new();
        let mut labels_summary = Vec::new();
        let mut after = |m: u32, r: &crate::search::LabelResult| -> Result<(), SearchError> {
            let (summary, line) = label_summary(r);
            labels_summary.push(summary);
            label_lines.push(line);
            let tables = LabelTables {
                stage: &stage,
                env,
                config: &config,
                sets: &sets,
                proposer: proposer.name(),
            };
            checkpoint.write_label(&tables, m, r, &mut rows)
        };
        let base = if self.start_empty {
            Vec::new()
        } else {
            self.setup.library.detectors.clone()
        };
        let result = with_wait_notices(ctx, llm_client.as_deref(), || {
            discovery.run(base, &labels, &mut after)
        });
        if let Some(c) = &llm_client {
            c.flush()?;
        }
        let (library, results) = match result {
            Ok(x) => x,
            Err(e) => {
                return Err(checkpoint
                    .failure
                    .borrow_mut()
                    .take()
                    .unwrap_or_else(|| e.into()));
            }
        };
        // A search whose every proposal failed learned nothing: its "accepted" detectors would be
        // the seed programs. Partial failures are reported in the summary.
        let proposals = ProposalTally::of(results.iter().flat_map(|r| &r.outcome.records));
        if proposals.all_failed() {
            return Err(SearchError::AllProposalsFailed {
                proposer: proposer.name().to_string(),
                tally: proposals,
            }
            .into());
        }
        if !reused {
            *rows.entry("trace_distances".into()).or_default() += dx.upper.len() as u64;
        }
        if !holdout_reused {
            *rows.entry("trace_distances".into()).or_default() += holdout_dx.upper.len() as u64;
        }
        if library.is_empty() {
            return Err(StageError::Input(format!(
                "start_empty: none of the {} label(s) was accepted, so the grown library would be empty; \
                 raise `budget`, lower `delta` or set allow_nonpositive_rho = true",
                labels.len()
            )));
        }
        if ctx.slice().is_some() {
            // The commit replays the saved rounds and writes the library folder.
            return Ok(StageOutput::default());
        }
        let out_dir = self.write_evolved(ctx, &config, proposer.name(), &library)?;
        let wall: f64 = results.iter().map(|r| r.outcome.wall_s).sum();
        let prop: f64 = results.iter().map(|r| r.outcome.propose_s).sum();
        let accepted = results.iter().filter(|r| r.accepted).count();
        let failures = proposals
            .failures()
            .map(|f| format!("; {f}"))
            .unwrap_or_default();
        let line = format!(
            "{} label(s) on {} training / {} held-out {env} trace(s), {accepted} accepted; {}{failures}; library: {}",
            results.len(),
            train.len(),
            holdout.len(),
            label_lines.join("; "),
            out_dir.display()
        );
        Ok(StageOutput {
            rows,
            files: library_files(&out_dir),
            summary: serde_json::to_value(EvolveSummary {
                env,
                seed: config.seed,
                strategy: config.strategy,
                proposer: proposer.name().to_string(),
                budget: config.budget,
                dp: self.eval.dp,
                dx_kind: self.dx,
                train: train.len() as u64,
                holdout: holdout.len() as u64,
                dx: DxSummary {
                    pairs: dx.upper.len() as u64,
                    reused,
                    seconds: dx_s,
                },
                labels: labels_summary,
                accepted,
                proposals,
                library: out_dir.to_string_lossy().into_owned(),
                wall_s: wall,
                propose_s: prop,
                outside_proposer_share: if wall > 0.0 {
                    (wall - prop) / wall
                } else {
                    0.0
                },
                lag: config.lag,
                sandbox: serde_json::to_value(pool.layers()).unwrap_or(Value::Null),
            })
            .unwrap_or(Value::Null),
            line,
        })
    }
}
