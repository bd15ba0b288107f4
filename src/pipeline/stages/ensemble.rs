//! `ensemble`: builds an ensemble library (paper section 3.3) from the candidates of M evolve stages
//! (of this run, or of other run folders) of one environment, calibrates it, writes it beside the
//! single-program ablation "-SP", and scores both with the baseline library on test traces.
//!
//! Steps and shards (a killed stage resumes at the first unfinished one):
//! 1. `L<i>.clusters`, one per label: pool the label's valid candidates (`ensemble::pool`), run them
//!    over the signature traces, cluster their signatures (`ensemble::cluster`), write
//!    `ensemble_members` and `ensemble_clusters`.
//! 2. `calibration`: run the representatives over the calibration traces, sweep (γ, ε_s, ε_t) and run
//!    the Bayesian optimisation (`ensemble::calibrate`), write `ensemble_calibration`.
//! 3. `evaluation`: annotate the test traces with the ensemble, -SP, the baseline and each run's own best
//!    program; write `ensemble_evaluation` (held-out ρ per label and variant).
//!
//! The two library folders are written last from the shard records (default
//! `exports/<stage>/library` and `exports/<stage>/library-sp`).
//!
//! Traces: the run's traces of `env` are ordered by a hash of (seed, id); `test_fraction` of them are
//! test traces (at most `test_traces`), the others calibration traces (at most `calibration_traces`),
//! whose first `signature_traces` are the fixed signature set. The evolve stages may have trained on
//! any of them (their splits use their own seeds).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::detector_setup::{DetectorSetup, SandboxParams};
use super::llm_setup::{resumable_client, stage_prompts};
use super::trace_files::{HashSplit, env_trace_ids, read_split, split_ids};
use crate::detect::{Detector, Library, WorkerPool};
use crate::ensemble::activation::{LabelEnsemble, Member, combine};
use crate::ensemble::calibrate::{CalibrationSettings, HeldoutRho, calibrate};
use crate::ensemble::cluster::cluster_label;
use crate::ensemble::kmeans::KRule;
use crate::ensemble::library::{LabelFile, MemberFile, write};
use crate::ensemble::pool::{Pooled, Source, best_per_source, dedup, read_all};
use crate::ensemble::signature::{histograms, run, signature, trace_histogram};
use crate::ensemble::tables::{
    EvaluationRow, calibration_batch, clusters_batch, evaluation_batch, members_batch,
};
use crate::fitness::{DistanceMatrix, Dp, correlation};
use crate::llm::{LlmClient, LlmSettings, Prompts};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::store::RunDir;
use crate::summary::{
    IdentificationObjective, IdentifyParams, LlmChooser, LlmMode, LlmSummariser, TraceImages,
    add_templates,
};
use crate::trace::{Env, Trace};

/// The `ensemble` stage kind.
pub static KIND: StageKind = StageKind {
    name: "ensemble",
    summary: "pool the candidates of M evolve runs, K-means them per label, calibrate an ensemble library",
    doc: "Pools every valid candidate per label from the `candidates` tables of the evolve stages named in \
          `evolve` (default: the evolve stages among the inputs, else every stage of the run) and of the \
          run folders in `runs`; gives each a signature (its activation histograms on a fixed set of \
          signature traces, the histograms d_p compares); clusters each label's candidates with K-means \
          (linfa; K by silhouette over 2..=k_max, 1 below min_silhouette, or fixed `k`) and keeps one \
          representative per cluster (best ν, ties to shorter code). Calibrates the ensemble: weights \
          start at 1, (a) a seeded sweep of (γ, ε_s, ε_t) maximising held-out ρ, (b) Gaussian-process \
          Bayesian optimisation of weights and tolerances against `objective`. Writes the ensemble \
          library and the single-program ablation (-SP) as folders, and scores the ensemble, -SP, the \
          baseline library and each run's best program by ρ on test traces. See docs/ensemble.md.",
    writes: "ensemble_members, ensemble_clusters, ensemble_calibration, ensemble_evaluation, exports/<stage>/library/, exports/<stage>/library-sp/",
    params: ParamsOf::of::<EnsembleParams>(),
    build,
};

/// What calibration (b) maximises.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum ObjectiveChoice {
    /// Mean over labels of ρ of the ensemble's annotations on the calibration traces (offline).
    #[default]
    HeldoutRho,
    /// The paper's: `identification_traces` calibration traces are annotated, summarised by the LLM
    /// (initial image + annotated trace) and a vision-language model picks each trace's summary among
    /// `options`; the share of right picks. Needs an endpoint (or `llm.replay`); without one, held-out
    /// ρ is used and the output and manifest say so.
    Identification,
}

impl ObjectiveChoice {
    /// Its name.
    pub fn as_str(self) -> &'static str {
        match self {
            ObjectiveChoice::HeldoutRho => "heldout-rho",
            ObjectiveChoice::Identification => "identification",
        }
    }
}

/// The parameters of an `ensemble` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct EnsembleParams {
    /// Environment whose candidates and traces are used.
    pub env: Env,
    /// Evolve stages of this run whose candidates are pooled (default: the evolve stages among the
    /// inputs; with none, every stage of the run's candidates table).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub evolve: Option<Vec<String>>,
    /// Other run folders (relative to the project) whose candidates of `env` are all pooled.
    pub runs: Vec<String>,
    /// Labels to build (default: every label with a valid candidate).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub labels: Option<Vec<String>>,
    /// Candidates per label at most (the best by ν).
    pub max_per_label: u64,
    /// A fixed K per label (default: chosen by silhouette).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k: Option<u64>,
    /// Largest K tried by the silhouette rule.
    pub k_max: u64,
    /// Below this best mean silhouette, K = 1.
    pub min_silhouette: f64,
    /// Traces of the fixed signature set (the first calibration traces).
    pub signature_traces: u64,
    /// Calibration traces at most.
    pub calibration_traces: u64,
    /// Fraction of the run's traces kept for the test scores.
    pub test_fraction: f64,
    /// Test traces at most.
    pub test_traces: u64,
    /// Time bins b of the activation histograms.
    pub bins: u64,
    /// Annotation distance d_p of ρ (kl, js, cross-entropy).
    pub dp: Dp,
    /// Normalised-time samples per trace for d_x.
    pub samples: u64,
    /// Starting activation threshold γ in [0, 1).
    pub gamma: f64,
    /// Starting spatial tolerance ε_s in the environment's NEARBY_AT unit (pooltool metres, PHYRE
    /// fractions of 256 px, I-PHYRE fractions of 600 px; default: the paper's 0.005, 0.05, 0.00625).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eps_s: Option<f64>,
    /// Starting temporal tolerance ε_t in timesteps (default: the paper's 1, 4, 2).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eps_t: Option<f64>,
    /// Calibration (a): sweep points per label besides the starting point.
    pub sweep_points: u64,
    /// Calibration (b): expected-improvement steps of the Bayesian optimisation (0: skip it).
    pub bo_iterations: u64,
    /// The objective of calibration (b): heldout-rho (offline) or identification (the paper's; an LLM).
    pub objective: ObjectiveChoice,
    /// Identification objective: calibration traces it uses (the first ones; at least `options`).
    pub identification_traces: u64,
    /// Identification objective: summaries shown per trial, one of them the trace's own.
    pub options: u64,
    /// Identification objective: keyframes the chooser is shown.
    pub keyframes: u64,
    /// Identification objective: image size (px) of the initial image and keyframes.
    pub image_size: u64,
    /// Identification objective: words a summary may have at most.
    pub words: u64,
    /// LLM settings of the identification objective (endpoint, model, replay, …; docs/llm.md), over
    /// the ANNOTRACE_LLM_* variables.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub llm: Option<LlmSettings>,
    /// Prompt template folder, relative to the project (default: `<project>/prompts` if present, else
    /// built-in).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prompts: Option<String>,
    /// Baseline library for the comparison, relative to the project (default: the project's
    /// `data/libraries/<env>` when it has one, else the built-in library).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub baseline: Option<String>,
    /// Folder of the ensemble library, relative to the project (default:
    /// `<run>/exports/<stage>/library`; -SP is written beside it with `-sp` appended).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub output: Option<String>,
    /// Seed of the split, K-means and calibration (default: the pipeline's seed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Python worker processes (0 = one per core).
    pub workers: u64,
    /// Wall-clock limit of one detector call (s).
    pub timeout: f64,
    /// Address-space limit of a worker (MiB).
    pub memory_mb: u64,
}

impl EnsembleParams {
    /// The defaults.
    pub const DEFAULT: EnsembleParams = EnsembleParams {
        env: Env::Pooltool,
        evolve: None,
        runs: Vec::new(),
        labels: None,
        max_per_label: 32,
        k: None,
        k_max: 4,
        min_silhouette: 0.25,
        signature_traces: 12,
        calibration_traces: 24,
        test_fraction: 0.3,
        test_traces: 40,
        bins: 10,
        dp: Dp::Kl,
        samples: 64,
        gamma: 0.5,
        eps_s: None,
        eps_t: None,
        sweep_points: 24,
        bo_iterations: 12,
        objective: ObjectiveChoice::HeldoutRho,
        identification_traces: 20,
        options: 8,
        keyframes: 5,
        image_size: 256,
        words: 120,
        llm: None,
        prompts: None,
        baseline: None,
        output: None,
        seed: None,
        workers: SandboxParams::DEFAULT.workers,
        timeout: SandboxParams::DEFAULT.timeout,
        memory_mb: SandboxParams::DEFAULT.memory_mb,
    };
}

impl Default for EnsembleParams {
    fn default() -> Self {
        EnsembleParams::DEFAULT
    }
}

/// The paper's spatiotemporal tolerances (ε_s in the environment's NEARBY_AT unit, ε_t in timesteps).
pub fn paper_tolerances(env: Env) -> (f64, f64) {
    match env {
        Env::Phyre => (0.05, 4.0),
        Env::Iphyre => (0.00625, 2.0),
        Env::Pooltool => (0.005, 1.0),
    }
}

/// One label of an `ensemble` stage's summary.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EnsembleLabelSummary {
    /// The label.
    pub label: String,
    /// Distinct valid candidates pooled.
    pub pooled: u64,
    /// Clusters (= members).
    pub k: u64,
    /// How K was chosen.
    pub k_rule: String,
    /// Calibrated γ.
    pub gamma: f64,
    /// Calibrated ε_s.
    pub eps_s: f64,
    /// Calibrated ε_t.
    pub eps_t: f64,
    /// Calibrated member weights.
    pub weights: Vec<f64>,
}

/// What an `ensemble` stage reports (its manifest summary).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct EnsembleSummary {
    /// The environment.
    pub env: Env,
    /// The seed.
    pub seed: u64,
    /// The pooled sources (stages, run folders).
    pub sources: Vec<String>,
    /// Per label.
    pub labels: Vec<EnsembleLabelSummary>,
    /// The objective calibration (b) maximised (`heldout-rho` offline).
    pub objective: String,
    /// What the objective means, in words.
    pub objective_note: String,
    /// Mean held-out ρ after the sweep (a).
    pub sweep_rho: f64,
    /// The objective at the sweep's optimum and at the chosen point of (b) (absent when (b) was off).
    pub bo: Option<(f64, f64)>,
    /// Mean test ρ over labels per variant (`ensemble`, `sp`, `baseline`, `run`).
    pub test_rho: BTreeMap<String, f64>,
    /// Signature / calibration / test traces.
    pub traces: (u64, u64, u64),
    /// The ensemble library folder.
    pub library: String,
    /// The -SP library folder.
    pub sp_library: String,
}

/// The `ensemble` stage.
#[derive(Debug)]
pub struct EnsembleStage {
    p: EnsembleParams,
    evolve: Option<Vec<String>>,
    runs: Vec<(String, PathBuf)>,
    baseline: Library,
    limits: crate::detect::SandboxLimits,
    eps: (f64, f64),
    output: Option<PathBuf>,
    llm: LlmSettings,
    prompts: Option<PathBuf>,
    project: PathBuf,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: EnsembleParams = def.params()?;
    let setup = DetectorSetup::new(
        &SandboxParams {
            env: p.env,
            library: p.baseline.clone(),
            workers: p.workers,
            timeout: p.timeout,
            memory_mb: p.memory_mb,
        },
        spec,
    )
    .map_err(|e| match e.param {
        Some("library") => BuildError::param("baseline", e.message),
        _ => e,
    })?;
    if !(0.0..1.0).contains(&p.gamma) {
        return Err(BuildError::param(
            "gamma",
            format!("gamma must be in [0, 1), found {}", p.gamma),
        ));
    }
    if !(0.0..1.0).contains(&p.test_fraction) || p.test_fraction == 0.0 {
        return Err(BuildError::param(
            "test_fraction",
            format!("test_fraction must be in (0, 1), found {}", p.test_fraction),
        ));
    }
    for (name, v) in [("eps_s", p.eps_s), ("eps_t", p.eps_t)] {
        if v.is_some_and(|v| !(v.is_finite() && v >= 0.0)) {
            return Err(BuildError::param(
                name,
                format!("{name} must be a number ≥ 0"),
            ));
        }
    }
    if !p.min_silhouette.is_finite() {
        return Err(BuildError::param(
            "min_silhouette",
            "min_silhouette must be a finite number",
        ));
    }
    if p.k == Some(0) || p.k_max == 0 {
        return Err(BuildError::param("k", "k and k_max must be at least 1"));
    }
    if p.signature_traces < 2 || p.calibration_traces < p.signature_traces.max(3) {
        return Err(BuildError::param(
            "calibration_traces",
            "signature_traces must be ≥ 2 and calibration_traces ≥ max(signature_traces, 3)",
        ));
    }
    if p.objective == ObjectiveChoice::Identification {
        if p.options < 2 || p.identification_traces < p.options {
            return Err(BuildError::param(
                "identification_traces",
                "options must be ≥ 2 and identification_traces ≥ options",
            ));
        }
        if p.calibration_traces < p.identification_traces {
            return Err(BuildError::param(
                "identification_traces",
                "identification_traces must be ≤ calibration_traces (they are calibration traces)",
            ));
        }
        if !(64..=1024).contains(&p.image_size) {
            return Err(BuildError::param(
                "image_size",
                format!("image_size must be in 64..=1024, found {}", p.image_size),
            ));
        }
    } else if p.llm.is_some() {
        return Err(BuildError::param(
            "llm",
            "`llm` settings are only used with objective = \"identification\"",
        ));
    }
    let mut llm = p.llm.clone().unwrap_or_default();
    if let Some(r) = &llm.replay {
        llm.replay = Some(spec.project_dir.join(r));
    }
    let mut runs = Vec::new();
    for r in &p.runs {
        let dir = spec.project_dir.join(r);
        if !dir.join("manifest.json").is_file() {
            return Err(BuildError::param(
                "runs",
                format!("{}: not a run folder (no manifest.json)", dir.display()),
            ));
        }
        runs.push((r.clone(), dir));
    }
    let evolve = p.evolve.clone().or_else(|| {
        let ins: Vec<String> = def
            .inputs
            .iter()
            .filter(|i| {
                spec.stages
                    .iter()
                    .any(|s| &s.id == *i && s.kind.name == "evolve")
            })
            .cloned()
            .collect();
        (!ins.is_empty()).then_some(ins)
    });
    let (es, et) = paper_tolerances(p.env);
    Ok(Box::new(EnsembleStage {
        eps: (p.eps_s.unwrap_or(es), p.eps_t.unwrap_or(et)),
        evolve,
        runs,
        baseline: setup.library,
        limits: setup.limits,
        output: p.output.as_ref().map(|o| spec.project_dir.join(o)),
        llm,
        prompts: p.prompts.as_ref().map(|d| spec.project_dir.join(d)),
        project: spec.project_dir.clone(),
        p,
    }))
}

/// A shard record's label entry: the representatives (code hashes, by cluster) and the -SP pick.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct LabelRecord {
    label: String,
    pooled: u64,
    k_rule: String,
    representatives: Vec<String>,
    sp: Option<String>,
}

/// The calibration record: per label γ, ε_s, ε_t and weights, and the objective's figures.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct CalibrationRecord {
    labels: Vec<(String, f64, f64, f64, Vec<f64>)>,
    sweep_rho: f64,
    objective: String,
    bo: Option<(f64, f64)>,
}

/// The LLM pieces of the identification objective.
struct Model {
    client: Arc<LlmClient>,
    prompts: Arc<Prompts>,
    images: Arc<TraceImages>,
}

impl EnsembleStage {
    /// Whether calibration (b) runs the identification objective (asked for, with an endpoint).
    fn identification(&self) -> bool {
        self.p.objective == ObjectiveChoice::Identification
            && self.p.bo_iterations > 0
            && self.endpoint_configured()
    }

    /// Whether an endpoint or a replay run is configured for the identification objective.
    fn endpoint_configured(&self) -> bool {
        self.llm.base_url.is_some()
            || self.llm.replay.is_some()
            || std::env::var(crate::llm::ENV_BASE_URL).is_ok_and(|v| !v.trim().is_empty())
    }

    /// The client, prompts and renderer of the identification objective. Answers this run already
    /// recorded are served again (a resumed calibration asks nothing twice).
    fn model(&self, ctx: &StageContext<'_>, seed: u64) -> Result<Model, StageError> {
        let client = resumable_client(&self.llm, seed, ctx.run())?;
        let prompts = stage_prompts(self.prompts.as_ref(), &self.project, add_templates)?;
        let images =
            TraceImages::new(self.p.image_size as u32).map_err(|e| StageError::Simulation {
                item: "renderer".into(),
                source: Box::new(e),
            })?;
        Ok(Model {
            client: Arc::new(client),
            prompts: Arc::new(prompts),
            images: Arc::new(images),
        })
    }

    /// Calibration (b) against the identification objective on the first `identification_traces`
    /// calibration traces (the sweep (a) still maximises ρ, as in the paper).
    fn calibrate_identification(
        &self,
        ctx: &StageContext<'_>,
        start: &[LabelEnsemble],
        rho: &HeldoutRho<'_>,
        calib: &[Trace],
        anns: &[crate::detect::Annotation],
        settings: CalibrationSettings,
    ) -> Result<crate::ensemble::calibrate::Calibrated, StageError> {
        let seed = settings.seed;
        let m = self.model(ctx, seed)?;
        let summariser = LlmSummariser {
            client: m.client.clone(),
            prompts: m.prompts.clone(),
            images: m.images.clone(),
            mode: LlmMode::Annotations,
            keyframes: self.p.keyframes as usize,
            words: self.p.words as usize,
            seed,
        };
        let chooser = LlmChooser {
            client: m.client.clone(),
            prompts: m.prompts.clone(),
            images: m.images.clone(),
            keyframes: self.p.keyframes as usize,
        };
        let traces = &calib[..(self.p.identification_traces as usize).min(calib.len())];
        let mut objective = IdentificationObjective::new(
            traces,
            anns,
            &summariser,
            &chooser,
            IdentifyParams {
                options: self.p.options as usize,
                seed,
            },
        );
        let c = calibrate(start, rho, &mut objective, settings);
        m.client.flush()?;
        c.map_err(|e| StageError::Input(e.to_string()))
    }

    fn detector(&self, p: &Pooled) -> Detector {
        Detector::new(
            self.p.env,
            &p.label,
            &p.code,
            &format!("ensemble:{}:{}", p.source, p.code_hash),
        )
    }

    /// The run's traces of `env`: (calibration, test), by the seeded hash order.
    fn traces(
        &self,
        ctx: &StageContext<'_>,
        seed: u64,
    ) -> Result<(Vec<Trace>, Vec<Trace>), StageError> {
        let (calib, test) = split_ids(
            env_trace_ids(ctx.run(), self.p.env)?,
            HashSplit {
                seed,
                salt: 0xE5E,
                aside: self.p.test_fraction,
                max_kept: self.p.calibration_traces as usize,
                max_aside: self.p.test_traces as usize,
            },
        );
        if calib.len() < self.p.signature_traces as usize || calib.len() < 3 || test.len() < 3 {
            return Err(StageError::TooFewTraces {
                stage: "ensemble",
                what: format!(
                    "{} calibration traces (≥ max(signature_traces, 3)) and 3 test traces",
                    self.p.env
                ),
                needed: (self.p.signature_traces as usize).max(3) + 3,
                found: calib.len() + test.len(),
                hint: ": simulate more traces or lower signature_traces / test_fraction",
            });
        }
        read_split(ctx.run(), (calib, test))
    }
}

impl Stage for EnsembleStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({
            "baseline": self.baseline.fingerprint(),
            "worker": crate::detect::worker_fingerprint(),
            "endpoint": (self.p.objective == ObjectiveChoice::Identification).then(|| self.endpoint_configured()),
            "runs": self.runs.iter().map(|(r, d)| {
                let m = std::fs::read(d.join("manifest.json")).unwrap_or_default();
                (r.clone(), crate::digest::sha256_hex(&m))
            }).collect::<Vec<_>>(),
        }))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let env = self.p.env;
        let seed = self.p.seed.unwrap_or(ctx.seed());
        let stage = ctx.stage_id().to_string();
        let mut sources = vec![Source {
            run: RunDir::new(ctx.run().root()),
            name: String::new(),
            stages: self.evolve.clone(),
        }];
        for (name, dir) in &self.runs {
            sources.push(Source {
                run: RunDir::new(dir),
                name: name.clone(),
                stages: None,
            });
        }
        let raw = read_all(&sources, env, self.p.labels.as_deref())?;
        if raw.is_empty() {
            return Err(StageError::Input(format!(
                "ensemble: no valid {env} candidate in the pooled candidates tables (stages {}{}): add evolve stages as inputs or name them in `evolve`",
                self.evolve
                    .as_ref()
                    .map_or("all".to_string(), |s| s.join(", ")),
                if self.runs.is_empty() {
                    String::new()
                } else {
                    format!(
                        ", runs {}",
                        self.runs
                            .iter()
                            .map(|r| r.0.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                }
            )));
        }
        let labels: Vec<String> = match &self.p.labels {
            Some(ls) => ls
                .iter()
                .filter(|l| raw.contains_key(*l))
                .cloned()
                .collect(),
            None => raw.keys().cloned().collect(),
        };
        let pooled: BTreeMap<&str, Vec<Pooled>> = labels
            .iter()
            .map(|l| (l.as_str(), dedup(&raw[l], self.p.max_per_label as usize)))
            .collect();
        let (calib, test) = self.traces(ctx, seed)?;
        let sig_traces = &calib[..self.p.signature_traces as usize];
        let bins = self.p.bins.max(1) as usize;
        ctx.progress()
            .set_total(ctx.stage_id(), labels.len() as u64 + 2);
        let mut pool: Option<WorkerPool> = None;
        let cache = calib.len() + test.len() + 4;
        let rule = KRule {
            fixed: self.p.k.map(|k| k as usize),
            k_max: self.p.k_max as usize,
            min_silhouette: self.p.min_silhouette,
        };
        let mut rows: BTreeMap<String, u64> = BTreeMap::new();
        // 1. One shard per label: signatures and clusters.
        let mut records: Vec<LabelRecord> = Vec::new();
        for (li, label) in labels.iter().enumerate() {
            let shard = format!("L{li:03}.clusters");
            if let Some(r) = ctx.finished_shard(&shard)? {
                add_rows(&mut rows, &r);
                records.push(serde_json::from_value(r["label"].clone()).map_err(|e| {
                    StageError::Internal(format!("unreadable shard record {shard}: {e}"))
                })?);
                ctx.progress().advance(ctx.stage_id(), 1);
                continue;
            }
            let list = &pooled[label.as_str()];
            let dets: Vec<Detector> = list.iter().map(|p| self.detector(p)).collect();
            let (anns, ok) = run(
                ensure_pool(&mut pool, &self.limits, cache)?,
                &dets,
                sig_traces,
            );
            let hists = histograms(&dets, sig_traces, &anns, bins);
            let sigs: Vec<Option<Vec<f64>>> = hists
                .iter()
                .zip(&ok)
                .map(|(h, &ok)| ok.then(|| signature(h)))
                .collect();
            let lc = cluster_label(list, &sigs, rule, crate::rng::splitmix64(seed ^ li as u64));
            let ordinal = ctx.shard_started();
            let mut written = serde_json::Map::new();
            if !lc.members.is_empty() {
                let n = ctx.write_batch(
                    "ensemble_members",
                    env,
                    &shard,
                    &members_batch(&stage, &lc.members)?,
                )?;
                written.insert("ensemble_members".into(), json!(n));
            }
            ctx.checkpoint_mid_shard(ordinal)?;
            if !lc.clusters.is_empty() {
                let n = ctx.write_batch(
                    "ensemble_clusters",
                    env,
                    &shard,
                    &clusters_batch(&stage, &lc.clusters)?,
                )?;
                written.insert("ensemble_clusters".into(), json!(n));
            }
            let sp = crate::ensemble::represent::single_best(
                &lc.clustered
                    .iter()
                    .map(|&i| list[i].clone())
                    .collect::<Vec<_>>(),
            )
            .map(|j| list[lc.clustered[j]].code_hash.clone());
            let rec = LabelRecord {
                label: label.clone(),
                pooled: list.len() as u64,
                k_rule: lc.clustering.rule.to_string(),
                representatives: lc
                    .representatives
                    .iter()
                    .map(|&i| list[i].code_hash.clone())
                    .collect(),
                sp,
            };
            let record = json!({"rows": written, "label": rec});
            ctx.finish_shard(&shard, &record)?;
            add_rows(&mut rows, &record);
            records.push(rec);
            ctx.progress().advance(ctx.stage_id(), 1);
        }
        let find = |label: &str, hash: &str| -> Result<Pooled, StageError> {
            pooled
                .get(label)
                .and_then(|l| l.iter().find(|p| p.code_hash == hash))
                .cloned()
                .ok_or_else(|| StageError::Internal(format!("candidate {hash} of {label:?} is no longer in the pool (did an input change?)")))
        };
        // The representatives as label ensembles (weights 1, starting tolerances).
        let mut members_of: Vec<(String, Vec<Pooled>)> = Vec::new();
        for r in &records {
            let reps = r
                .representatives
                .iter()
                .map(|h| find(&r.label, h))
                .collect::<Result<Vec<_>, _>>()?;
            if !reps.is_empty() {
                members_of.push((r.label.clone(), reps));
            }
        }
        let start: Vec<LabelEnsemble> = members_of
            .iter()
            .map(|(label, reps)| LabelEnsemble {
                env,
                label: label.clone(),
                gamma: self.p.gamma,
                eps_s: self.eps.0,
                eps_t: self.eps.1,
                members: reps
                    .iter()
                    .map(|p| Member {
                        id: self.detector(p).id,
                        weight: 1.0,
                        reward: p.nu,
                    })
                    .collect(),
            })
            .collect();
        let rep_dets: Vec<Detector> = members_of
            .iter()
            .flat_map(|(_, reps)| reps.iter().map(|p| self.detector(p)))
            .collect();
        // 2. Calibration.
        let calibration: CalibrationRecord = match ctx.finished_shard("calibration")? {
            Some(r) => {
                add_rows(&mut rows, &r);
                serde_json::from_value(r["calibration"].clone()).map_err(|e| {
                    StageError::Internal(format!("unreadable calibration record: {e}"))
                })?
            }
            None => {
                let (anns, _) = run(
                    ensure_pool(&mut pool, &self.limits, cache)?,
                    &rep_dets,
                    &calib,
                );
                let dx = DistanceMatrix::compute(&calib, self.p.samples.max(2) as usize);
                let rho = HeldoutRho::new(&calib, &anns, &dx, bins, self.p.dp);
                let settings = CalibrationSettings {
                    sweep_points: self.p.sweep_points as usize,
                    bo_iterations: self.p.bo_iterations as usize,
                    seed,
                };
                let c = if self.identification() {
                    if calib.len() < self.p.options as usize {
                        return Err(StageError::TooFewTraces {
                            stage: "ensemble",
                            what: format!(
                                "{env} calibration traces for the identification objective"
                            ),
                            needed: self.p.options as usize,
                            found: calib.len(),
                            hint: ": simulate more traces or lower `options`",
                        });
                    }
                    self.calibrate_identification(ctx, &start, &rho, &calib, &anns, settings)?
                } else {
                    let mut objective = HeldoutRho::new(&calib, &anns, &dx, bins, self.p.dp);
                    calibrate(&start, &rho, &mut objective, settings)
                        .map_err(|e| StageError::Input(e.to_string()))?
                };
                let name = if self.identification() {
                    ObjectiveChoice::Identification
                } else {
                    ObjectiveChoice::HeldoutRho
                }
                .as_str()
                .to_string();
                let mut written = serde_json::Map::new();
                if !c.rows.is_empty() {
                    let n = ctx.write_batch(
                        "ensemble_calibration",
                        env,
                        "calibration",
                        &calibration_batch(&stage, &name, &c.rows)?,
                    )?;
                    written.insert("ensemble_calibration".into(), json!(n));
                }
                let rec = CalibrationRecord {
                    labels: c
                        .ensembles
                        .iter()
                        .map(|e| {
                            (
                                e.label.clone(),
                                e.gamma,
                                e.eps_s,
                                e.eps_t,
                                e.members.iter().map(|m| m.weight).collect(),
                            )
                        })
                        .collect(),
                    sweep_rho: c.sweep_rho,
                    objective: name,
                    bo: c.objective.as_ref().map(|o| (o.1, o.2)),
                };
                let record = json!({"rows": written, "calibration": rec});
                ctx.finish_shard("calibration", &record)?;
                add_rows(&mut rows, &record);
                rec
            }
        };
        ctx.progress().advance(ctx.stage_id(), 1);
        // The libraries.
        let lib_dir = self
            .output
            .clone()
            .unwrap_or_else(|| ctx.run().exports_dir().join(&stage).join("library"));
        let sp_dir = lib_dir.with_file_name(format!(
            "{}-sp",
            lib_dir
                .file_name()
                .map(|f| f.to_string_lossy().into_owned())
                .unwrap_or_default()
        ));
        let mut label_files = Vec::new();
        let mut sp_files = Vec::new();
        let mut summary_labels = Vec::new();
        for ((label, reps), r) in members_of
            .iter()
            .zip(records.iter().filter(|r| !r.representatives.is_empty()))
        {
            let (_, gamma, eps_s, eps_t, weights) = calibration
                .labels
                .iter()
                .find(|l| &l.0 == label)
                .cloned()
                .unwrap_or((
                    label.clone(),
                    self.p.gamma,
                    self.eps.0,
                    self.eps.1,
                    vec![1.0; reps.len()],
                ));
            let member = |p: &Pooled, w: f64, c: u32| MemberFile {
                label: label.clone(),
                code: p.code.clone(),
                weight: w,
                reward: p.nu,
                run: p.source.clone(),
                candidate: p.code_hash.clone(),
                cluster: c,
            };
            label_files.push(LabelFile {
                label: label.clone(),
                gamma,
                eps_s,
                eps_t,
                members: reps
                    .iter()
                    .zip(&weights)
                    .enumerate()
                    .map(|(c, (p, &w))| member(p, w, c as u32))
                    .collect(),
            });
            if let Some(h) = &r.sp {
                let p = find(label, h)?;
                sp_files.push(LabelFile {
                    label: label.clone(),
                    gamma,
                    eps_s,
                    eps_t,
                    members: vec![member(&p, 1.0, 0)],
                });
            }
            summary_labels.push(EnsembleLabelSummary {
                label: label.clone(),
                pooled: r.pooled,
                k: reps.len() as u64,
                k_rule: r.k_rule.clone(),
                gamma,
                eps_s,
                eps_t,
                weights,
            });
        }
        let lib_name = format!("{env}-ensemble");
        let description = format!(
            "Ensemble library of {} label(s) from {} source(s), ensemble stage {stage} (seed {seed}, objective {})",
            label_files.len(),
            sources.len(),
            calibration.objective
        );
        write(&lib_dir, &lib_name, env, &description, &label_files, true)
            .map_err(|e| StageError::io(&lib_dir, e))?;
        write(
            &sp_dir,
            &format!("{env}-ensemble-sp"),
            env,
            &format!("Single-program ablation (-SP) of {lib_name}"),
            &sp_files,
            false,
        )
        .map_err(|e| StageError::io(&sp_dir, e))?;
        let ensemble_lib = Library::load(&lib_dir)?;
        let sp_lib = Library::load(&sp_dir)?;
        // 3. Evaluation on the test traces.
        let eval_rows: Vec<EvaluationRow> = match ctx.finished_shard("evaluation")? {
            Some(r) => {
                add_rows(&mut rows, &r);
                serde_json::from_value(r["evaluation"].clone()).map_err(|e| {
                    StageError::Internal(format!("unreadable evaluation record: {e}"))
                })?
            }
            None => {
                let dx = DistanceMatrix::compute(&test, self.p.samples.max(2) as usize);
                let labels_built: Vec<String> = members_of.iter().map(|m| m.0.clone()).collect();
                let mut variants: Vec<(String, String, Vec<Detector>)> = vec![
                    (
                        "ensemble".into(),
                        String::new(),
                        ensemble_lib.detectors.clone(),
                    ),
                    ("sp".into(), String::new(), sp_lib.detectors.clone()),
                    (
                        "baseline".into(),
                        self.baseline.name.clone(),
                        self.baseline.detectors.clone(),
                    ),
                ];
                let mut per_run: BTreeMap<String, Vec<Detector>> = BTreeMap::new();
                for l in &labels_built {
                    for p in best_per_source(&raw[l]) {
                        per_run
                            .entry(p.source.clone())
                            .or_default()
                            .push(self.detector(&p));
                    }
                }
                for (src, dets) in per_run {
                    variants.push(("run".into(), src, dets));
                }
                let mut all: Vec<Detector> = Vec::new();
                for (_, _, ds) in &variants {
                    for d in ds {
                        if !all.iter().any(|a| a.id == d.id) {
                            all.push(d.clone());
                        }
                    }
                }
                let (anns, _) = run(ensure_pool(&mut pool, &self.limits, cache)?, &all, &test);
                let mut out = Vec::new();
                for (variant, source, dets) in &variants {
                    let mine: Vec<crate::detect::Annotation> = anns
                        .iter()
                        .filter(|a| dets.iter().any(|d| d.id == a.detector_id))
                        .cloned()
                        .collect();
                    let combined = combine(dets, &test, mine);
                    for l in &labels_built {
                        let norm = crate::detect::normalise_label(l);
                        let of_label: Vec<&crate::detect::Annotation> = combined
                            .iter()
                            .filter(|a| crate::detect::normalise_label(&a.label) == norm)
                            .collect();
                        if !dets
                            .iter()
                            .any(|d| crate::detect::normalise_label(&d.label) == norm)
                        {
                            continue;
                        }
                        let own = crate::detect::by_trace(&test, of_label.iter().copied());
                        let hists: Vec<Vec<f64>> = test
                            .iter()
                            .zip(&own)
                            .map(|(t, own)| trace_histogram(t, own, bins))
                            .collect();
                        let fired = own.iter().filter(|own| !own.is_empty()).count();
                        let f1 = label_f1(env, &test, &of_label, l);
                        out.push(EvaluationRow {
                            variant: variant.clone(),
                            source: source.clone(),
                            label: l.clone(),
                            traces: test.len() as u32,
                            rho: correlation(&dx, &hists, self.p.dp),
                            activation_rate: fired as f64 / test.len() as f64,
                            f1,
                        });
                    }
                }
                let mut written = serde_json::Map::new();
                if !out.is_empty() {
                    let n = ctx.write_batch(
                        "ensemble_evaluation",
                        env,
                        "evaluation",
                        &evaluation_batch(&stage, &out)?,
                    )?;
                    written.insert("ensemble_evaluation".into(), json!(n));
                }
                let record = json!({"rows": written, "evaluation": out});
                ctx.finish_shard("evaluation", &record)?;
                add_rows(&mut rows, &record);
                out
            }
        };
        ctx.progress().advance(ctx.stage_id(), 1);
        let mut test_rho: BTreeMap<String, f64> = BTreeMap::new();
        for v in ["ensemble", "sp", "baseline", "run"] {
            let xs: Vec<f64> = eval_rows
                .iter()
                .filter(|r| r.variant == v)
                .map(|r| r.rho)
                .collect();
            if !xs.is_empty() {
                test_rho.insert(v.into(), xs.iter().sum::<f64>() / xs.len() as f64);
            }
        }
        let note = match (self.p.objective, self.identification()) {
            (ObjectiveChoice::Identification, true) => format!(
                "calibration (b) maximised identification accuracy: {} calibration traces annotated, summarised by the LLM and identified among {} summaries by the LLM chooser (calls in llm_calls)",
                self.p.identification_traces, self.p.options
            ),
            (ObjectiveChoice::Identification, false) => "identification was asked for but no endpoint (llm.base_url, ANNOTRACE_LLM_BASE_URL) or llm.replay is configured: calibration (b) maximised held-out ρ on the calibration traces instead".to_string(),
            (ObjectiveChoice::HeldoutRho, _) => "calibration (b) maximised held-out ρ on the calibration traces (offline objective)".to_string(),
        };
        let line = format!(
            "{} label(s) from {} source(s), K = [{}]; objective {}; test ρ ensemble {:.3}, -SP {:.3}, baseline {:.3}; library: {}",
            summary_labels.len(),
            sources.len(),
            summary_labels
                .iter()
                .map(|l| l.k.to_string())
                .collect::<Vec<_>>()
                .join(", "),
            calibration.objective,
            test_rho.get("ensemble").copied().unwrap_or(f64::NAN),
            test_rho.get("sp").copied().unwrap_or(f64::NAN),
            test_rho.get("baseline").copied().unwrap_or(f64::NAN),
            lib_dir.display()
        );
        let mut files = library_files(&lib_dir);
        files.extend(library_files(&sp_dir));
        Ok(StageOutput {
            rows,
            files,
            summary: serde_json::to_value(EnsembleSummary {
                env,
                seed,
                sources: {
                    let mut s: Vec<String> =
                        raw.values().flatten().map(|p| p.source.clone()).collect();
                    s.sort();
                    s.dedup();
                    s
                },
                labels: summary_labels,
                objective: calibration.objective.clone(),
                objective_note: note,
                sweep_rho: calibration.sweep_rho,
                bo: calibration.bo,
                test_rho,
                traces: (
                    sig_traces.len() as u64,
                    calib.len() as u64,
                    test.len() as u64,
                ),
                library: lib_dir.to_string_lossy().into_owned(),
                sp_library: sp_dir.to_string_lossy().into_owned(),
            })
            .unwrap_or(Value::Null),
            line,
        })
    }
}

/// F1 of `label`'s annotations `anns` on the scorable `traces` against the event log (the `accuracy`
/// stage's default tolerance and merge, 0.05 s); `None` when the label is not event-grounded in `env`
/// or no trace is scorable.
fn label_f1(
    env: Env,
    traces: &[Trace],
    anns: &[&crate::detect::Annotation],
    label: &str,
) -> Option<f64> {
    use crate::detect::accuracy::{grounded, scorable, score_trace, truth};
    let norm = crate::detect::normalise_label(label);
    let g = grounded(env)
        .iter()
        .copied()
        .find(|g| crate::detect::normalise_label(g) == norm)?;
    let mut scores = BTreeMap::new();
    let mut scored = false;
    for (t, mine) in traces
        .iter()
        .zip(crate::detect::by_trace(traces, anns.iter().copied()))
        .filter(|(t, _)| scorable(env, t))
    {
        scored = true;
        let events: Vec<_> = truth(env, t, 0.05)
            .into_iter()
            .filter(|e| e.label == g)
            .collect();
        score_trace(&[g], &events, &mine, 0.05, &mut scores);
    }
    if !scored {
        return None;
    }
    scores.get(g).map(|s| s.f1())
}

/// The stage's worker pool, started on first use (a fully resumed stage starts none). Its candidates
/// and members carry the same preludes and the stage uses their patterns, not their calls' times:
/// they share helper results (`HelperSharing::Measured`).
fn ensure_pool<'p>(
    pool: &'p mut Option<WorkerPool>,
    limits: &crate::detect::SandboxLimits,
    cache: usize,
) -> Result<&'p WorkerPool, StageError> {
    if pool.is_none() {
        let mut l = limits.clone();
        l.trace_cache = l.trace_cache.max(cache);
        l.share_helpers = crate::detect::HelperSharing::Measured;
        *pool = Some(WorkerPool::new(l)?);
    }
    Ok(pool.as_ref().expect("just started"))
}

fn add_rows(rows: &mut BTreeMap<String, u64>, record: &Value) {
    for (t, n) in record["rows"].as_object().into_iter().flatten() {
        *rows.entry(t.clone()).or_default() += n.as_u64().unwrap_or(0);
    }
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
