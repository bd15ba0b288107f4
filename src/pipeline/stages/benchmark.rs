//! `benchmark`: DeepPHY's agent loop (`crate::bench`) over PHYRE, I-PHYRE or billiards tasks, for each
//! of `seeds` seeds, writing the `benchmark` table (one row per attempt).
//!
//! One shard per (seed, task), named `KKKKK-sSSS-tTTTTT` with `K = seed × tasks + task` its unit index:
//! a killed or failed run (an endpoint down mid-benchmark) resumes at the first unfinished task, and the
//! stage is shardable (`annotrace run --shard i/n` computes the (seed, task) units `K ≡ i mod n`; every
//! unit's draws and requests are keyed by (seed, task, attempt) alone, so its rows do not depend on
//! which process plays it or on what it played before). An LLM agent's client replays the answers this
//! run already recorded before asking the endpoint, so the calls of a task interrupted half-way are not
//! asked again; with `llm.replay` pointing at another run it reproduces that run's table without an
//! endpoint. Each process's client records its own `llm_calls` files (named after its session).

use std::path::PathBuf;
use std::sync::Arc;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::detector_setup::{DetectorSetup, SandboxParams};
use super::llm_setup::{resumable_client, stage_prompts};
use crate::bench::agent::{AgentKind, add_templates};
use crate::bench::{
    Agent, Annotator, BenchError, FeedbackMode, Format, LlmAgent, PoolAction, RandomAgent,
    SearchAgent, Settings, Simulators, TaskChoice, choose_tasks, play_task, table,
};
use crate::envs::phyre::EvalSetup;
use crate::llm::{LlmClient, LlmSettings};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::trace::Env;

/// PHYRE's ball-tier evaluation setups.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum PhyreSetup {
    /// `ball_within_template`.
    #[default]
    BallWithinTemplate,
    /// `ball_cross_template`.
    BallCrossTemplate,
}

/// The parameters of a `benchmark` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct BenchmarkParams {
    /// Environment: pooltool, phyre or iphyre.
    pub env: Env,
    /// Tasks (PHYRE: from the fold's test split, round-robin over templates; I-PHYRE: games in order;
    /// pooltool: seeded 9-ball racks).
    pub tasks: u64,
    /// Only these tasks (PHYRE `00004:012`, I-PHYRE game names, pooltool rack indices).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub task_ids: Option<Vec<String>>,
    /// PHYRE evaluation setup.
    pub phyre_setup: PhyreSetup,
    /// PHYRE fold seed.
    pub phyre_fold: u64,
    /// Seed of the pooltool racks.
    pub pool_seed: u64,
    /// Pooltool action format: deepphy (speed and strike spot, automatic aim) or free (V0, phi, theta, a, b).
    pub pool_action: PoolAction,
    /// Attempts per task (the paper: 10).
    pub attempts: u64,
    /// Agent: random, search or llm.
    pub agent: AgentKind,
    /// With agent = llm: when no endpoint (llm.base_url, ANNOTRACE_LLM_BASE_URL) and no replay run is
    /// configured, write no rows and say so instead of failing.
    pub skip_without_endpoint: bool,
    /// Feedback after a failed attempt: none, image-only (keyframes) or annotations (annotated trace text).
    pub feedback: FeedbackMode,
    /// Seeds (the table's standard deviations are over seeds).
    pub seeds: u64,
    /// Seed of the agents' draws and the model requests (default: the pipeline's seed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Search agent: candidates simulated per attempt at most.
    pub search_budget: u64,
    /// Keyframes per failed rollout (image-only feedback).
    pub keyframes: u64,
    /// Size of the images (px).
    pub image_size: u64,
    /// Detector library of the annotations (default: the built-in library of the environment).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub library: Option<String>,
    /// The library an `evolve` or `ensemble` stage grew (its id; it must be one of this stage's inputs),
    /// instead of `library`: e.g. the library evolved from a `suggest-labels` stage's labels (the paper's
    /// LLM-Labels rows). Read when the stage runs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub library_from: Option<String>,
    /// Only these labels of the library annotate (a single one: the -SP ablation; growing subsets: the
    /// library-size ablation). Default: every label.
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

impl Default for BenchmarkParams {
    fn default() -> Self {
        let s = SandboxParams::DEFAULT;
        BenchmarkParams {
            env: Env::Phyre,
            tasks: 20,
            task_ids: None,
            phyre_setup: PhyreSetup::default(),
            phyre_fold: 0,
            pool_seed: 2000,
            pool_action: PoolAction::default(),
            attempts: 10,
            agent: AgentKind::default(),
            skip_without_endpoint: false,
            feedback: FeedbackMode::default(),
            seeds: 3,
            seed: None,
            search_budget: 16,
            keyframes: 5,
            image_size: 256,
            library: None,
            library_from: None,
            labels: None,
            llm: None,
            prompts: None,
            workers: s.workers,
            timeout: s.timeout,
            memory_mb: s.memory_mb,
        }
    }
}

/// What a `benchmark` stage reports (its manifest summary; the command prints it).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BenchmarkSummary {
    /// Environment.
    pub env: String,
    /// Agent kind.
    pub agent: String,
    /// Model (empty for offline agents).
    pub model: String,
    /// Feedback mode.
    pub feedback: String,
    /// Library of the annotations (empty when none).
    pub library: String,
    /// Tasks per seed.
    pub tasks: u64,
    /// Seeds.
    pub seeds: u64,
    /// Attempts per task.
    pub attempts: u64,
    /// Task runs (task × seed) solved.
    pub solved: u64,
    /// solved / (tasks × seeds).
    pub success_rate: f64,
    /// Attempts played in all.
    pub attempts_played: u64,
    /// Attempts played by this process (the rest were finished by an earlier, interrupted one).
    pub attempts_played_now: u64,
    /// Harness seconds of the attempts played now (everything but the agent).
    pub harness_s: f64,
    /// Agent seconds of the attempts played now.
    pub agent_s: f64,
    /// Why nothing was played, when the stage skipped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
}

impl BenchmarkSummary {
    /// Harness milliseconds per attempt played now.
    pub fn harness_ms_per_attempt(&self) -> f64 {
        if self.attempts_played_now == 0 {
            0.0
        } else {
            1000.0 * self.harness_s / self.attempts_played_now as f64
        }
    }

    /// One line for the terminal.
    pub fn line(&self) -> String {
        if let Some(why) = &self.skipped {
            return format!("skipped: {why}");
        }
        let total = self.tasks * self.seeds;
        // A resumed or sharded run's commit may have played nothing itself: no harness figure then.
        let harness = if self.attempts_played_now == 0 {
            String::new()
        } else {
            format!(
                "; harness {:.1} ms per attempt",
                self.harness_ms_per_attempt()
            )
        };
        format!(
            "{} {}{} agent, {} feedback{}: {}/{} task runs solved ({:.1} %) over {} seed(s), {} attempts{harness}",
            self.env,
            self.agent,
            if self.model.is_empty() {
                String::new()
            } else {
                format!(" ({})", self.model)
            },
            self.feedback,
            if self.library.is_empty() {
                String::new()
            } else {
                format!(" ({})", self.library)
            },
            self.solved,
            total,
            100.0 * self.success_rate,
            self.seeds,
            self.attempts_played,
        )
    }
}

/// The `benchmark` stage kind.
pub static KIND: StageKind = StageKind {
    name: "benchmark",
    summary: "DeepPHY-style agent loop: attempts with feedback on PHYRE, I-PHYRE or billiards tasks",
    doc: "For each of `seeds` seeds and each of `tasks` tasks, an agent (random, search or an LLM) answers in \
          DeepPHY's action format (PHYRE `Cell: N, Radius: R` on the numbered 8x8 grid; I-PHYRE a JSON list of \
          {time, index} removals at 10 fps; pooltool speed and strike spot with automatic aim, or a free shot), \
          up to `attempts` times; the answer is parsed strictly and simulated, an invalid answer (unparsable, \
          out of range, an occluding ball) uses up an attempt, a failed one is followed by feedback (none, \
          image-only keyframes, or the annotated trace from a detector library), and the loop stops at the \
          first success. Writes one row per attempt to the benchmark table; sql/benchmark_table1.sql makes \
          the paper's Table 1 from it (docs/benchmark.md).",
    writes: "benchmark",
    params: ParamsOf::of::<BenchmarkParams>(),
    build,
};

/// The `benchmark` stage.
#[derive(Debug)]
pub struct BenchmarkStage {
    env: Env,
    choice: TaskChoice,
    format: Format,
    attempts: usize,
    agent: AgentKind,
    skip_without_endpoint: bool,
    feedback: FeedbackMode,
    seeds: u64,
    seed: Option<u64>,
    search_budget: usize,
    keyframes: usize,
    image_size: u32,
    setup: Option<DetectorSetup>,
    detectors: Vec<crate::detect::Detector>,
    library_from: Option<String>,
    labels: Option<Vec<String>>,
    llm: LlmSettings,
    prompts: Option<PathBuf>,
    project: PathBuf,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: BenchmarkParams = def.params()?;
    let at_least = |k: &'static str, v: u64, min: u64, max: u64| -> Result<u64, BuildError> {
        if v < min || v > max {
            Err(BuildError::param(
                k,
                format!("`{k}` must be in {min}..={max}, found {v}"),
            ))
        } else {
            Ok(v)
        }
    };
    let format = match (p.env, p.pool_action) {
        (Env::Phyre, _) => Format::PhyreGrid,
        (Env::Iphyre, _) => Format::IphyreRemovals,
        (Env::Pooltool, PoolAction::Deepphy) => Format::PoolDeepphy,
        (Env::Pooltool, PoolAction::Free) => Format::PoolFree,
    };
    if let Some(from) = &p.library_from {
        if p.feedback != FeedbackMode::Annotations {
            return Err(BuildError::param(
                "library_from",
                "`library_from` is only used with feedback = \"annotations\"",
            ));
        }
        if p.library.is_some() {
            return Err(BuildError::param(
                "library_from",
                "give `library` or `library_from`, not both",
            ));
        }
        if !def.inputs.contains(from) {
            return Err(BuildError::param(
                "library_from",
                format!("`library_from` = {from:?} must be one of the stage's inputs"),
            ));
        }
        match spec.stages.iter().find(|s| &s.id == from) {
            Some(s) if ["evolve", "ensemble"].contains(&s.kind.name) => {}
            _ => {
                return Err(BuildError::param(
                    "library_from",
                    format!("`library_from` = {from:?} must name an evolve or ensemble stage"),
                ));
            }
        }
    }
    let setup = if p.feedback == FeedbackMode::Annotations {
        let sandbox = SandboxParams {
            env: p.env,
            library: p.library.clone(),
            workers: p.workers,
            timeout: p.timeout,
            memory_mb: p.memory_mb,
        };
        Some(DetectorSetup::new(&sandbox, spec)?)
    } else {
        for (given, key) in [
            (p.library.is_some(), "library"),
            (p.labels.is_some(), "labels"),
        ] {
            if given {
                return Err(BuildError::param(
                    key,
                    format!("`{key}` is only used with feedback = \"annotations\""),
                ));
            }
        }
        None
    };
    let detectors = match &setup {
        // The grown library is read when the stage runs; its labels are checked then.
        _ if p.library_from.is_some() => Vec::new(),
        None => Vec::new(),
        Some(s) => select_detectors(&s.library, p.labels.as_deref())
            .map_err(|e| BuildError::param("labels", e))?,
    };
    let mut llm = p.llm.clone().unwrap_or_default();
    if let Some(r) = &llm.replay {
        llm.replay = Some(spec.project_dir.join(r));
    }
    if p.agent != AgentKind::Llm && p.llm.is_some() {
        return Err(BuildError::param(
            "llm",
            format!(
                "`llm` settings are only used with agent = \"llm\", not {:?}",
                p.agent.as_str()
            ),
        ));
    }
    let stage = BenchmarkStage {
        env: p.env,
        choice: TaskChoice {
            env: p.env,
            count: at_least("tasks", p.tasks, 1, 100_000)? as usize,
            ids: p.task_ids.clone().unwrap_or_default(),
            phyre_setup: match p.phyre_setup {
                PhyreSetup::BallWithinTemplate => EvalSetup::WithinTemplate,
                PhyreSetup::BallCrossTemplate => EvalSetup::CrossTemplate,
            },
            phyre_fold: p.phyre_fold,
            pool_seed: p.pool_seed,
        },
        format,
        attempts: at_least("attempts", p.attempts, 1, 1000)? as usize,
        agent: p.agent,
        skip_without_endpoint: p.skip_without_endpoint,
        feedback: p.feedback,
        seeds: at_least("seeds", p.seeds, 1, 1000)?,
        seed: p.seed,
        search_budget: at_least("search_budget", p.search_budget, 1, 100_000)? as usize,
        keyframes: at_least("keyframes", p.keyframes, 1, 20)? as usize,
        image_size: at_least("image_size", p.image_size, 64, 1024)? as u32,
        setup,
        detectors,
        library_from: p.library_from.clone(),
        labels: p.labels.clone(),
        llm,
        prompts: p.prompts.as_ref().map(|d| spec.project_dir.join(d)),
        project: spec.project_dir.clone(),
    };
    // The tasks must exist (an unknown id is the pipeline's error, reported at its line).
    let sims = Simulators::new().map_err(|e| BuildError::param("env", e.to_string()))?;
    choose_tasks(&sims, &stage.choice).map_err(|e| BuildError::param("task_ids", e.to_string()))?;
    Ok(Box::new(stage))
}

/// The detectors of `library` that annotate: those of `labels` (each must be a label of the library),
/// or all.
fn select_detectors(
    library: &crate::detect::Library,
    labels: Option<&[String]>,
) -> Result<Vec<crate::detect::Detector>, String> {
    let Some(labels) = labels else {
        return Ok(library.detectors.clone());
    };
    let known = library.labels();
    let norm = |l: &str| crate::detect::normalise_label(l);
    if labels.is_empty() {
        return Err("give at least one label".into());
    }
    if let Some(bad) = labels
        .iter()
        .find(|l| !known.iter().any(|k| norm(k) == norm(l)))
    {
        return Err(format!(
            "library {} has no label {bad:?} (it has: {})",
            library.name,
            known.join(", ")
        ));
    }
    Ok(crate::reward::annotate::detectors_for(library, labels))
}

/// An agent and, for the LLM agent, its client (flushed after every task).
type AgentAndClient = (Box<dyn Agent>, Option<Arc<LlmClient>>);

fn bench_error(task: &str, e: BenchError) -> StageError {
    match e {
        BenchError::Llm(e) => StageError::Llm(Box::new(e)),
        BenchError::Env(e) => StageError::Simulation {
            item: format!("task {task}"),
            source: Box::new(e),
        },
        BenchError::UnknownTask(m) => StageError::Input(m),
        other => StageError::Internal(other.to_string()),
    }
}

impl BenchmarkStage {
    /// The library (name) and detectors that annotate: `library_from`'s grown library, read from the
    /// manifest summary of that finished stage, or the one loaded when the stage was built.
    fn annotating(
        &self,
        ctx: &StageContext<'_>,
    ) -> Result<(String, Vec<crate::detect::Detector>), StageError> {
        let Some(setup) = &self.setup else {
            return Ok((String::new(), Vec::new()));
        };
        let Some(id) = &self.library_from else {
            return Ok((setup.library.name.clone(), self.detectors.clone()));
        };
        let manifest = crate::store::manifest::Manifest::load(ctx.run())?;
        let path = manifest
            .as_ref()
            .and_then(|m| m.stages.get(id))
            .filter(|r| r.status == crate::store::manifest::StageStatus::Finished)
            .and_then(|r| r.summary["library"].as_str().map(PathBuf::from))
            .ok_or_else(|| {
                StageError::Input(format!(
                    "`library_from`: stage {id:?} has not finished in this run or names no library"
                ))
            })?;
        let library = crate::detect::Library::open(&crate::builtin::Location::Disk(path.clone()))?;
        if library.env != self.env {
            return Err(StageError::Input(format!(
                "`library_from`: the library of stage {id:?} ({}) is for {}, not {}",
                path.display(),
                library.env,
                self.env
            )));
        }
        let detectors = select_detectors(&library, self.labels.as_deref())
            .map_err(|e| StageError::Input(format!("`labels`: {e}")))?;
        Ok((library.name, detectors))
    }

    /// Whether an endpoint or a replay run is configured for the LLM agent.
    fn endpoint_configured(&self) -> bool {
        self.llm.base_url.is_some()
            || self.llm.replay.is_some()
            || std::env::var(crate::llm::ENV_BASE_URL).is_ok_and(|v| !v.trim().is_empty())
    }

    /// The agent (and the LLM client to flush at the end).
    fn agent(
        &self,
        ctx: &StageContext<'_>,
        sims: &Simulators,
    ) -> Result<AgentAndClient, StageError> {
        match self.agent {
            AgentKind::Random => Ok((Box::new(RandomAgent), None)),
            AgentKind::Search => Ok((
                Box::new(SearchAgent {
                    budget: self.search_budget,
                    sims: sims.clone(),
                }),
                None,
            )),
            AgentKind::Llm => {
                let seed = self.seed.unwrap_or(ctx.seed());
                let client = Arc::new(resumable_client(&self.llm, seed, ctx.run())?);
                let prompts = stage_prompts(self.prompts.as_ref(), &self.project, add_templates)?;
                Ok((
                    Box::new(LlmAgent {
                        client: client.clone(),
                        prompts: Arc::new(prompts),
                    }),
                    Some(client),
                ))
            }
        }
    }
}

/// The unit of (seed index `seed`, task number `task` of `tasks`): `KKKKK-sSSS-tTTTTT`, whose leading
/// number `K = seed × tasks + task` decides its slice in a sharded run.
fn unit_name(seed: u64, task: usize, tasks: usize) -> String {
    let k = seed * tasks as u64 + task as u64;
    format!("{k:05}-s{seed:03}-t{task:05}")
}

impl Stage for BenchmarkStage {
    /// Each (seed, task) is a unit of its own (see the module documentation).
    fn shardable(&self) -> bool {
        true
    }

    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({
            "library": self.setup.as_ref().map(|s| s.library.fingerprint()),
            "detectors": self.detectors.iter().map(|d| d.label.clone()).collect::<Vec<_>>(),
            "worker": self.setup.as_ref().map(|_| crate::detect::worker_fingerprint()),
            "templates": crate::bench::agent::TEMPLATES.iter().map(|(n, t)| format!("{n}:{}", crate::digest::sha256_hex(t.as_bytes()))).collect::<Vec<_>>(),
            "endpoint": (self.agent == AgentKind::Llm).then(|| self.endpoint_configured()),
            // The units' names (`KKKKK-sSSS-tTTTTT` since they became shardable; before, `sSSS-tTTTTT`):
            // a stage interrupted under the old names restarts rather than resuming beside them.
            "units": 2,
        }))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let sims = Simulators::new().map_err(|e| StageError::Simulation {
            item: "simulators".into(),
            source: Box::new(e),
        })?;
        let tasks = choose_tasks(&sims, &self.choice).map_err(|e| bench_error("-", e))?;
        if self.agent == AgentKind::Llm && self.skip_without_endpoint && !self.endpoint_configured()
        {
            let summary = BenchmarkSummary {
                env: self.env.to_string(),
                agent: self.agent.as_str().into(),
                feedback: self.feedback.as_str().into(),
                skipped: Some("agent = llm but no endpoint (ANNOTRACE_LLM_BASE_URL) or replay run is configured".into()),
                ..BenchmarkSummary::default()
            };
            return Ok(StageOutput {
                line: summary.line(),
                summary: serde_json::to_value(&summary)
                    .map_err(|e| StageError::Internal(e.to_string()))?,
                ..StageOutput::default()
            });
        }
        let (library, detectors) = self.annotating(ctx)?;
        let (agent, client) = self.agent(ctx, &sims)?;
        let settings = Settings {
            format: self.format,
            feedback: self.feedback,
            attempts: self.attempts,
            keyframes: self.keyframes,
            image_size: self.image_size,
            seed: self.seed.unwrap_or(ctx.seed()),
            library: library.clone(),
            patterns: detectors.len(),
        };
        let pool = match &self.setup {
            Some(s) => Some(s.pool()?),
            None => None,
        };
        let annotator = match (&pool, &self.setup) {
            (Some(p), Some(_)) => Some(Annotator {
                pool: p,
                detectors: &detectors,
            }),
            _ => None,
        };
        ctx.progress()
            .set_total(ctx.stage_id(), self.seeds * tasks.len() as u64);
        let (mut rows, mut solved, mut attempts_total) = (0u64, 0u64, 0u64);
        let (mut harness_s, mut agent_s, mut played) = (0.0, 0.0, 0u64);
        for seed in 0..self.seeds {
            for (i, task) in tasks.iter().enumerate() {
                let shard = unit_name(seed, i, tasks.len());
                if !ctx.owns(&shard) {
                    // Another process's slice (`--shard`): its record is summed at the commit.
                    continue;
                }
                let record = match ctx.finished_shard(&shard)? {
                    Some(r) => r,
                    None => {
                        let result =
                            play_task(&sims, agent.as_ref(), annotator, &settings, seed, i, task);
                        let p = match result {
                            Ok(p) => p,
                            Err(e) => {
                                if let Some(c) = &client {
                                    let _ = c.flush();
                                }
                                return Err(bench_error(task.id(), e));
                            }
                        };
                        let ordinal = ctx.shard_started();
                        ctx.checkpoint_mid_shard(ordinal)?;
                        let n = ctx.write_batch(
                            table::TABLE,
                            self.env,
                            &shard,
                            &table::batch(&p.rows)?,
                        )?;
                        played += n;
                        harness_s += p.harness_s;
                        agent_s += p.agent_s;
                        let record = json!({
                            "task": task.id(), "rows": n, "solved": p.rows.iter().any(|r| r.success),
                            "harness_s": p.harness_s, "agent_s": p.agent_s,
                        });
                        if let Some(c) = &client {
                            c.flush()?;
                        }
                        ctx.finish_shard(&shard, &record)?;
                        record
                    }
                };
                rows += record["rows"].as_u64().unwrap_or(0);
                attempts_total += record["rows"].as_u64().unwrap_or(0);
                solved += u64::from(record["solved"].as_bool().unwrap_or(false));
                ctx.progress().advance(ctx.stage_id(), 1);
            }
        }
        if let Some(c) = &client {
            c.flush()?;
        }
        let total = self.seeds * tasks.len() as u64;
        let summary = BenchmarkSummary {
            env: self.env.to_string(),
            agent: self.agent.as_str().into(),
            model: agent.model(),
            feedback: self.feedback.as_str().into(),
            library,
            tasks: tasks.len() as u64,
            seeds: self.seeds,
            attempts: self.attempts as u64,
            solved,
            success_rate: solved as f64 / total.max(1) as f64,
            attempts_played: attempts_total,
            attempts_played_now: played,
            harness_s,
            agent_s,
            skipped: None,
        };
        Ok(StageOutput {
            rows: [(table::TABLE.to_string(), rows)].into_iter().collect(),
            files: Vec::new(),
            line: summary.line(),
            summary: serde_json::to_value(&summary)
                .map_err(|e| StageError::Internal(e.to_string()))?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_spread_seeds_and_tasks_over_slices() {
        assert_eq!(unit_name(0, 3, 20), "00003-s000-t00003");
        assert_eq!(unit_name(2, 1, 20), "00041-s002-t00001");
        // 2 seeds × 3 tasks over 4 slices: every unit in exactly one slice, the slices balanced.
        let slices: Vec<crate::pipeline::Slice> = (0..4)
            .map(|i| crate::pipeline::Slice::new(i, 4).unwrap())
            .collect();
        let mut per = [0; 4];
        for seed in 0..2 {
            for task in 0..3 {
                let owners: Vec<usize> = (0..4)
                    .filter(|&i| slices[i].owns(&unit_name(seed, task, 3)))
                    .collect();
                assert_eq!(owners.len(), 1, "seed {seed} task {task}");
                per[owners[0]] += 1;
            }
        }
        assert_eq!(per, [2, 2, 1, 1]);
    }

    #[test]
    fn defaults_build_and_unknown_tasks_are_refused() {
        let p = BenchmarkParams::default();
        assert_eq!(
            (p.attempts, p.agent, p.feedback),
            (10, AgentKind::Random, FeedbackMode::None)
        );
    }
}
