//! `annotrace benchmark`: DeepPHY's agent loop on one environment as a one-stage pipeline (the
//! `benchmark` stage; docs/benchmark.md). Rerunning the same command resumes an interrupted benchmark
//! (an endpoint that went down) at the first unfinished task; `--replay RUN` reproduces RUN's table from
//! its recorded calls without an endpoint.

use std::path::PathBuf;

use annotrace::bench::agent::AgentKind;
use annotrace::bench::{FeedbackMode, PoolAction};
use annotrace::llm::LlmSettings;
use annotrace::pipeline::stages::benchmark::{BenchmarkParams, BenchmarkSummary, KIND, PhyreSetup};
use annotrace::trace::Env;

use super::llm_args::LlmArgs;
use super::one_stage::{OneStage, absolute, kebab, params_id, summary};
use super::worker_args::WorkerArgs;
use super::{CliError, CliResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder the benchmark table is written to (created when missing).
    #[arg(long)]
    run: PathBuf,
    /// Environment: pooltool, phyre or iphyre.
    #[arg(long, default_value = "phyre")]
    env: Env,
    /// Tasks (PHYRE: the fold's test split round-robin over templates; I-PHYRE: games in order;
    /// pooltool: seeded 9-ball racks).
    #[arg(long, default_value_t = 20)]
    tasks: u64,
    /// Only these tasks (PHYRE 00004:012, I-PHYRE game names, pooltool rack indices); repeat or comma-separate.
    #[arg(long = "task", value_delimiter = ',')]
    task_ids: Vec<String>,
    /// PHYRE evaluation setup.
    #[arg(long, default_value = "ball_within_template", value_parser = ["ball_within_template", "ball_cross_template"])]
    phyre_setup: String,
    /// PHYRE fold seed.
    #[arg(long, default_value_t = 0)]
    phyre_fold: u64,
    /// Seed of the pooltool racks.
    #[arg(long, default_value_t = 2000)]
    pool_seed: u64,
    /// Pooltool action format: deepphy (speed, strike spot, automatic aim) or free (V0, phi, theta, a, b).
    #[arg(long, default_value = "deepphy", value_parser = ["deepphy", "free"])]
    pool_action: String,
    /// Attempts per task.
    #[arg(long, default_value_t = 10)]
    attempts: u64,
    /// Agent.
    #[arg(long, default_value = "random", value_parser = ["random", "search", "llm"])]
    agent: String,
    /// Feedback after a failed attempt.
    #[arg(long, default_value = "none", value_parser = ["none", "image-only", "annotations"])]
    feedback: String,
    /// Seeds (standard deviations are over seeds).
    #[arg(long, default_value_t = 3)]
    seeds: u64,
    /// Seed of the agents' draws and model requests.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Search agent: candidates simulated per attempt at most.
    #[arg(long, default_value_t = 16)]
    search_budget: u64,
    /// Keyframes per failed rollout (image-only feedback).
    #[arg(long, default_value_t = 5)]
    keyframes: u64,
    /// Image size (px).
    #[arg(long, default_value_t = 256)]
    image_size: u64,
    /// Detector library of the annotations feedback (default: the built-in one of the environment).
    #[arg(long)]
    library: Option<PathBuf>,
    /// Only these labels of the library annotate (one: the -SP ablation); comma-separated or repeated.
    #[arg(long, value_delimiter = ',')]
    labels: Vec<String>,
    #[command(flatten)]
    limits: WorkerArgs,
    /// Start over instead of resuming or reusing an identical earlier benchmark.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    llm: LlmArgs,
}

pub fn run(a: Args, quiet: bool) -> CliResult {
    let agent: AgentKind = kebab("agent", &a.agent)?;
    let feedback: FeedbackMode = kebab("feedback", &a.feedback)?;
    let pool_action: PoolAction = kebab("pool-action", &a.pool_action)?;
    let phyre_setup: PhyreSetup = kebab("phyre-setup", &a.phyre_setup)?;
    let mut llm = a.llm.settings();
    if let Some(r) = &llm.replay {
        llm.replay = Some(PathBuf::from(absolute(r)?));
    }
    let llm = (agent == AgentKind::Llm && llm != LlmSettings::default()).then_some(llm);
    if agent != AgentKind::Llm && a.llm.settings() != LlmSettings::default() {
        return Err(CliError::input(anyhow::anyhow!(
            "the LLM flags are only used with --agent llm"
        )));
    }
    let params = BenchmarkParams {
        env: a.env,
        tasks: a.tasks,
        task_ids: (!a.task_ids.is_empty()).then_some(a.task_ids.clone()),
        phyre_setup,
        phyre_fold: a.phyre_fold,
        pool_seed: a.pool_seed,
        pool_action,
        attempts: a.attempts,
        agent,
        skip_without_endpoint: false,
        feedback,
        seeds: a.seeds,
        seed: Some(a.seed),
        search_budget: a.search_budget,
        keyframes: a.keyframes,
        image_size: a.image_size,
        library: a.library.as_deref().map(absolute).transpose()?,
        library_from: None,
        labels: (!a.labels.is_empty()).then(|| a.labels.clone()),
        llm,
        prompts: a.llm.prompts.as_deref().map(absolute).transpose()?,
        workers: a.limits.workers,
        timeout: a.limits.timeout,
        memory_mb: a.limits.memory_mb,
    };
    // A replay gives the same table under the same stage id: the id leaves out where answers come from
    // (the endpoint's address, the replay run).
    let mut id_params = params.clone();
    if let Some(l) = &mut id_params.llm {
        l.base_url = None;
        l.replay = None;
        l.strict_replay = None;
    }
    let id = params_id("benchmark", &id_params);
    let stage = OneStage {
        run: &a.run,
        id: id.clone(),
        force: a.force,
        remove_new_run_on_failure: false,
    }
    .run(&KIND, &params, quiet)?;
    let s: BenchmarkSummary = summary(&stage, "benchmark")?;
    println!(
        "benchmark {id}{}: {}",
        if stage.cached {
            " [recorded result]"
        } else {
            ""
        },
        s.line()
    );
    Ok(0)
}
