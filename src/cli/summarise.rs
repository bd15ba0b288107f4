//! `annotrace summarise`: summaries of a run's traces and the identification task as a one-stage
//! pipeline (the `summarise` stage; docs/benchmark.md). Offline by default (deterministic summaries
//! from the built-in library's annotations, the annotation-overlap chooser); `--summariser frames|annotations`
//! and `--identify llm` ask the configured endpoint, `--replay RUN` answers from RUN's recorded calls.

use std::path::PathBuf;

use annotrace::llm::LlmSettings;
use annotrace::pipeline::stages::summarise::{
    ChooserKind, KIND, SummariseParams, SummariseSummary, SummariserKind,
};
use annotrace::trace::Env;

use super::llm_args::LlmArgs;
use super::one_stage::{OneStage, absolute, existing_run, kebab, params_id, summary};
use super::worker_args::WorkerArgs;
use super::{CliError, CliResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder whose traces are summarised (the tables are written there).
    #[arg(long)]
    run: PathBuf,
    /// Environment.
    #[arg(long, default_value = "pooltool")]
    env: Env,
    /// Traces to summarise (a seeded sample of the run's traces of --env).
    #[arg(long, default_value_t = 20)]
    traces: u64,
    /// Only these traces; repeat or comma-separate.
    #[arg(long = "trace", value_delimiter = ',')]
    trace_ids: Vec<String>,
    /// Summariser: offline (from annotations, no model), frames (LLM, keyframes only) or annotations
    /// (LLM, initial image + annotated trace).
    #[arg(long, default_value = "offline", value_parser = ["offline", "frames", "annotations"])]
    summariser: String,
    /// Identification task chooser: offline (annotation-overlap baseline), llm, or none.
    #[arg(long, default_value = "offline", value_parser = ["offline", "llm", "none"])]
    identify: String,
    /// Summaries per identification trial, the trace's own included.
    #[arg(long, default_value_t = 8)]
    options: u64,
    /// Seed of the sample, the trials and the model requests.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Keyframes shown by the frames summariser and the LLM chooser.
    #[arg(long, default_value_t = 5)]
    keyframes: u64,
    /// Image size (px).
    #[arg(long, default_value_t = 512)]
    image_size: u64,
    /// The longest summary asked of a model, in words.
    #[arg(long, default_value_t = 120)]
    words: u64,
    /// Detector library of the annotations (default: the built-in one of the environment).
    #[arg(long)]
    library: Option<PathBuf>,
    /// Only these labels of the library annotate; comma-separated or repeated.
    #[arg(long, value_delimiter = ',')]
    labels: Vec<String>,
    #[command(flatten)]
    limits: WorkerArgs,
    /// Start over instead of resuming or reusing an identical earlier run of this command.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    llm: LlmArgs,
}

pub fn run(a: Args, quiet: bool) -> CliResult {
    existing_run(&a.run)?;
    let summariser: SummariserKind = kebab("summariser", &a.summariser)?;
    let identify: ChooserKind = kebab("identify", &a.identify)?;
    let uses_llm = summariser != SummariserKind::Offline || identify == ChooserKind::Llm;
    let mut llm = a.llm.settings();
    if let Some(r) = &llm.replay {
        llm.replay = Some(PathBuf::from(absolute(r)?));
    }
    if !uses_llm && llm != LlmSettings::default() {
        return Err(CliError::input(anyhow::anyhow!(
            "the LLM flags are only used with --summariser frames|annotations or --identify llm"
        )));
    }
    let params = SummariseParams {
        env: a.env,
        traces: a.traces,
        trace_ids: (!a.trace_ids.is_empty()).then(|| a.trace_ids.clone()),
        summariser,
        identify,
        options: a.options,
        seed: Some(a.seed),
        keyframes: a.keyframes,
        image_size: a.image_size,
        words: a.words,
        skip_without_endpoint: false,
        library: a.library.as_deref().map(absolute).transpose()?,
        labels: (!a.labels.is_empty()).then(|| a.labels.clone()),
        llm: (uses_llm && llm != LlmSettings::default()).then_some(llm),
        prompts: a.llm.prompts.as_deref().map(absolute).transpose()?,
        workers: a.limits.workers,
        timeout: a.limits.timeout,
        memory_mb: a.limits.memory_mb,
    };
    // A replay gives the same tables under the same stage id: the id leaves out where answers come
    // from (the endpoint's address, the replay run).
    let mut id_params = params.clone();
    if let Some(l) = &mut id_params.llm {
        l.base_url = None;
        l.replay = None;
        l.strict_replay = None;
    }
    let id = params_id("summarise", &id_params);
    let stage = OneStage {
        run: &a.run,
        id: id.clone(),
        force: a.force,
        remove_new_run_on_failure: false,
    }
    .run(&KIND, &params, quiet)?;
    let s: SummariseSummary = summary(&stage, "summarise")?;
    println!(
        "summarise {id}{}: {}",
        if stage.cached {
            " [recorded result]"
        } else {
            ""
        },
        s.line()
    );
    Ok(0)
}
