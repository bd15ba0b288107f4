//! `annotrace suggest-labels`: asks the configured LLM for K new pattern labels for an environment and
//! prints them.
//!
//! When `--run DIR` holds traces of the environment, the command runs the `suggest-labels` stage
//! (`pipeline::stages::suggest_labels`, the same code as in a pipeline): the model is shown `--examples`
//! example traces (initial image and annotated trace), the answer is parsed strictly with repairs, the
//! labels go to `DIR/suggested_labels`, and `--offline` uses the baseline without a model. Otherwise
//! (no run, or one without traces) only the trace layout and the library's labels are sent
//! (`prompts/suggest_labels.j2`), as a quick way to try an endpoint.
//!
//! The endpoint comes from `ANNOTRACE_LLM_BASE_URL`, `ANNOTRACE_LLM_MODEL` and `ANNOTRACE_LLM_API_KEY`
//! (flags override the first two); with `--run DIR` the call is recorded in `DIR/llm_calls`, and
//! `--replay DIR` answers from a recorded run without the endpoint. Output: one numbered label per line
//! with its description and reason, or JSON Lines (`{"label", "description", "reason"}`) with `--json`;
//! a summary (model, tokens, labels dropped as already known) goes to stderr.

use std::path::{Path, PathBuf};

use annotrace::builtin::Location;
use annotrace::detect::Library;
use annotrace::llm::{
    LabelsContext, LabelsError, LibraryEntry, LlmClient, SuggestParams, suggest_labels,
};
use annotrace::store::RunDir;
use annotrace::trace::Env;
use anyhow::anyhow;

use super::llm_args::{LlmArgs, llm_error};
use super::{CliError, CliResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Library folder whose labels the suggestions must not repeat; default: the built-in one of --env,
    /// or ./data/libraries/<env> when present.
    #[arg(long)]
    library: Option<PathBuf>,
    /// Environment (default: the library's).
    #[arg(long)]
    env: Option<Env>,
    /// How many labels to ask for (the paper: 12).
    #[arg(short, long, default_value_t = 12)]
    k: usize,
    /// Example traces of --run shown to the model (initial image + annotated trace); 0 sends none.
    #[arg(long, default_value_t = 3)]
    examples: u64,
    /// With example traces: repair requests after an answer with problems.
    #[arg(long, default_value_t = 2)]
    max_repairs: u64,
    /// With example traces: propose a whole library that may reuse the library's ideas, instead of labels
    /// new to it.
    #[arg(long)]
    whole_library: bool,
    /// With example traces: size of the initial images (px).
    #[arg(long, default_value_t = 512)]
    image_size: u64,
    /// With example traces: the offline baseline (built-in labels the library lacks, then frequent
    /// pairs of the examples' annotations) instead of a model.
    #[arg(long)]
    offline: bool,
    /// Run folder to record the call in (its llm_calls table).
    #[arg(long)]
    run: Option<PathBuf>,
    /// What the agent in these scenes tries to do (steers the suggestions).
    #[arg(long)]
    objective: Option<String>,
    /// An extra instruction added to the prompt's rules.
    #[arg(long)]
    guidance: Option<String>,
    /// Request seed (sent to the endpoint; part of the replay key).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Sampling temperature.
    #[arg(long)]
    temperature: Option<f64>,
    /// Print the suggestions as JSON Lines.
    #[arg(long)]
    json: bool,
    /// Print the prompt and stop (no call).
    #[arg(long)]
    dry_run: bool,
    #[command(flatten)]
    llm: LlmArgs,
}

fn load_library(args: &Args) -> Result<Library, CliError> {
    let dir = match (&args.library, &args.env) {
        (Some(d), _) => Location::Disk(d.clone()),
        (None, Some(env)) => Location::default_library(Path::new("."), *env),
        (None, None) => {
            return Err(CliError::input(anyhow!(
                "give --library DIR or --env (whose default is the built-in library of <env>)"
            )));
        }
    };
    let lib = Library::open(&dir)?;
    if let Some(env) = args.env
        && env != lib.env
    {
        return Err(CliError::input(anyhow!(
            "{dir}: the library is for {}, not --env {env}",
            lib.env
        )));
    }
    Ok(lib)
}

/// Whether `--run` holds traces of `env` to show as examples.
fn run_has_traces(args: &Args, env: Env) -> Result<bool, CliError> {
    let Some(run) = &args.run else {
        return Ok(false);
    };
    if args.examples == 0 || !run.join("manifest.json").is_file() {
        return Ok(false);
    }
    let ids = annotrace::store::trace_ids(&RunDir::new(run))
        .map_err(|e| CliError::new(annotrace::pipeline::Categorize::category(&e), anyhow!(e)))?;
    Ok(ids.iter().any(|(e, _)| *e == env))
}

/// The `suggest-labels` stage on `--run`'s traces.
fn run_stage(args: &Args, library: &Library, quiet: bool) -> CliResult {
    use super::one_stage::{OneStage, absolute, params_id, summary};
    use annotrace::pipeline::stages::suggest_labels::{
        KIND, SuggestLabelsParams, SuggestLabelsSummary, SuggestMode,
    };
    let run = args.run.as_ref().expect("checked by the caller");
    let mut llm = args.llm.settings();
    if let Some(r) = &llm.replay {
        llm.replay = Some(PathBuf::from(absolute(r)?));
    }
    if args.temperature.is_some() {
        llm.temperature = args.temperature;
    }
    llm.seed = Some(args.seed);
    let params = SuggestLabelsParams {
        env: library.env,
        k: args.k as u64,
        examples: args.examples,
        mode: if args.offline {
            SuggestMode::Offline
        } else {
            SuggestMode::Llm
        },
        max_repairs: args.max_repairs,
        library: args.library.as_deref().map(absolute).transpose()?,
        new_only: !args.whole_library,
        objective: args.objective.clone(),
        guidance: args.guidance.clone(),
        seed: Some(args.seed),
        llm: (!args.offline).then_some(llm),
        prompts: args.llm.prompts.as_deref().map(absolute).transpose()?,
        image_size: args.image_size,
        ..SuggestLabelsParams::default()
    };
    // A replay gives the same table under the same stage id.
    let mut id_params = params.clone();
    if let Some(l) = &mut id_params.llm {
        l.base_url = None;
        l.replay = None;
        l.strict_replay = None;
    }
    let id = params_id("suggest-labels", &id_params);
    let stage = OneStage {
        run,
        id: id.clone(),
        force: false,
        remove_new_run_on_failure: false,
    }
    .run(&KIND, &params, quiet)?;
    let s: SuggestLabelsSummary = summary(&stage, "suggest-labels")?;
    for (i, l) in s.labels.iter().enumerate() {
        if args.json {
            println!(
                "{}",
                serde_json::to_string(l).map_err(|e| CliError::failed(anyhow!(e)))?
            );
        } else {
            println!("{}. {} — {}", i + 1, l.label, l.description);
            if !l.objects.is_empty() {
                println!("   objects: {}", l.objects.join(", "));
            }
            if !l.reason.is_empty() {
                println!("   why: {}", l.reason);
            }
        }
    }
    if !quiet {
        eprintln!("# suggest-labels {id}: {}", s.line());
        for p in &s.problems {
            eprintln!("# repaired: {p}");
        }
        eprintln!("# recorded in {}", run.join("suggested_labels").display());
    }
    Ok(0)
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    if args.k == 0 || args.k > 100 {
        return Err(CliError::input(anyhow!(
            "-k must be between 1 and 100, got {}",
            args.k
        )));
    }
    let library = load_library(&args)?;
    if !args.dry_run && run_has_traces(&args, library.env)? {
        return run_stage(&args, &library, quiet);
    }
    if args.offline {
        return Err(CliError::input(anyhow!(
            "--offline needs example traces: give --run DIR holding {} traces (and --examples ≥ 1)",
            library.env
        )));
    }
    let prompts = args.llm.prompts()?;
    if args.dry_run {
        let text = prompts
            .render(
                "suggest_labels.j2",
                LabelsContext {
                    env: library.env,
                    k: args.k,
                    library: LibraryEntry::of(&library),
                    objective: args.objective.clone(),
                    guidance: args.guidance.clone(),
                },
            )
            .map_err(CliError::input)?;
        print!("{text}");
        return Ok(0);
    }
    let config = args.llm.config(args.seed)?;
    let record = args.run.as_ref().map(RunDir::new);
    let client = LlmClient::new(config, record.as_ref()).map_err(llm_error)?;
    let params = SuggestParams {
        env: library.env,
        k: args.k,
        objective: args.objective.clone(),
        guidance: args.guidance.clone(),
        seed: args.seed,
        temperature: args.temperature,
    };
    let result = suggest_labels(&client, &prompts, &library, &params);
    // The call is recorded whether or not its answer parsed.
    client.flush().map_err(llm_error)?;
    let s = match result {
        Ok(s) => s,
        Err(LabelsError::Llm(e)) => return Err(llm_error(e)),
        Err(e) => return Err(CliError::failed(e)),
    };
    for (i, l) in s.labels.iter().enumerate() {
        if args.json {
            println!(
                "{}",
                serde_json::to_string(l).map_err(|e| CliError::failed(anyhow!(e)))?
            );
        } else {
            match l.description.is_empty() {
                true => println!("{}. {}", i + 1, l.label),
                false => println!("{}. {} — {}", i + 1, l.label, l.description),
            }
            if !l.reason.is_empty() {
                println!("   why: {}", l.reason);
            }
        }
    }
    if !quiet {
        let r = &s.reply;
        let mut how = Vec::new();
        if r.usage_estimated {
            how.push("estimated");
        }
        if r.replayed {
            how.push("replayed");
        }
        let how = if how.is_empty() {
            String::new()
        } else {
            format!(", {}", how.join(", "))
        };
        eprintln!(
            "# {} new label(s) from {} ({} + {} tokens{how}; call {})",
            s.labels.len(),
            client.model(),
            r.tokens_in,
            r.tokens_out,
            r.call_id
        );
        if !s.duplicates.is_empty() {
            eprintln!(
                "# dropped as already in the library: {}",
                s.duplicates.join(", ")
            );
        }
        if let Some(run) = &args.run {
            eprintln!("# recorded in {}", run.join("llm_calls").display());
        }
    }
    if s.labels.is_empty() {
        return Err(CliError::failed(anyhow!(
            "the model proposed no new label (all {} were already in the library)",
            s.duplicates.len()
        )));
    }
    Ok(0)
}
