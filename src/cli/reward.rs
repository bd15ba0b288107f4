//! `annotrace reward`: check a reward program, evaluate it on a trace of a run, or synthesise one
//! from a natural-language goal with an LLM.

use std::path::{Path, PathBuf};

use annotrace::builtin::Location;
use annotrace::detect::tables::{parameter_keys, read_annotations};
use annotrace::detect::{Annotation, Library, SandboxLimits, WorkerPool};
use annotrace::envs::Environment;
use annotrace::envs::pool::{PoolEnv, Scene, Shot};
use annotrace::reward::annotate::{annotate, detectors_for, probe_schema};
use annotrace::reward::{AnnotatedTrace, RewardError, Schema, compile, evaluate, labels_used};
use annotrace::store::{RunDir, read_trace};
use annotrace::trace::Env;

use super::{CliError, CliResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand, Debug)]
enum Command {
    /// Parse and check a program against a library's labels and parameter keys.
    Check(CheckArgs),
    /// Evaluate a program on one trace of a run: each clause's value, success and the dense score.
    Eval(EvalArgs),
    /// Ask the configured LLM for a program for a goal sentence, repairing it on parse, check or
    /// execution errors (calls recorded in --run DIR's llm_calls).
    Synthesise(Box<SynthArgs>),
}

#[derive(clap::Args, Debug)]
struct SynthArgs {
    /// The goal in natural language.
    goal: String,
    /// Environment of the goal.
    #[arg(long, default_value = "pooltool")]
    env: Env,
    /// Billiards scene: a scene JSON file, or SEED:INDEX for a generated 9-ball rack; PHYRE: a task
    /// id (default the first task); I-PHYRE: a game name (default the first game).
    #[arg(long, default_value = "1000:0")]
    scene: String,
    /// Library folder; default: the built-in one, or ./data/libraries/<env> when present.
    #[arg(long)]
    library: Option<PathBuf>,
    /// Repair rounds after the first answer.
    #[arg(long, default_value_t = 3)]
    max_repairs: usize,
    /// Request seed (sent to the endpoint; part of the replay key).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Sampling temperature.
    #[arg(long)]
    temperature: Option<f64>,
    /// Attach the scene's initial image (PNG) for a vision model.
    #[arg(long)]
    image: bool,
    /// Run folder to record the calls in (its llm_calls table).
    #[arg(long)]
    run: Option<PathBuf>,
    /// Write the accepted program to this file.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the first prompt and stop (no call).
    #[arg(long)]
    dry_run: bool,
    #[command(flatten)]
    llm: super::llm_args::LlmArgs,
}

#[derive(clap::Args, Debug)]
struct CheckArgs {
    /// The program (DSL text), or @FILE to read it from a file.
    program: String,
    /// Library folder; default: the built-in pooltool one, or ./data/libraries/pooltool when present.
    #[arg(long)]
    library: Option<PathBuf>,
    /// Do not learn parameter keys by annotating a few simulated shots (then any key is accepted).
    #[arg(long)]
    no_probe: bool,
}

#[derive(clap::Args, Debug)]
struct EvalArgs {
    /// The program (DSL text), or @FILE to read it from a file.
    program: String,
    /// Run folder.
    #[arg(long)]
    run: PathBuf,
    /// Trace id.
    #[arg(long)]
    trace: String,
    /// Library folder; default: the built-in one of the trace's environment, or
    /// ./data/libraries/<env> when present.
    #[arg(long)]
    library: Option<PathBuf>,
}

pub fn run(args: Args) -> CliResult {
    match args.command {
        Command::Check(a) => check(a),
        Command::Eval(a) => eval(a),
        Command::Synthesise(a) => synthesise(*a),
    }
}

/// The program text of an argument (`@FILE` reads a file).
pub(crate) fn program_text(arg: &str) -> Result<String, CliError> {
    match arg.strip_prefix('@') {
        Some(path) => std::fs::read_to_string(path)
            .map_err(|e| CliError::input(anyhow::anyhow!("{path}: {e}"))),
        None => Ok(arg.to_string()),
    }
}

/// The library: the folder given, or data/libraries/<env> of the current folder, or the built-in one.
pub(crate) fn library_dir(given: Option<&Path>, env: Env) -> Location {
    match given {
        Some(p) => Location::Disk(p.to_path_buf()),
        None => Location::default_library(Path::new("."), env),
    }
}

pub(crate) fn load_library(dir: &Location) -> Result<Library, CliError> {
    Library::open(dir).map_err(CliError::of)
}

pub(crate) fn pool() -> Result<WorkerPool, CliError> {
    WorkerPool::new(SandboxLimits::default())
        .map_err(|e| CliError::of(e).context("starting the detector workers"))
}

/// A program error as the CLI prints it: the message, then the offending line with a caret.
pub(crate) fn show_error(text: &str, e: &RewardError) -> anyhow::Error {
    let line = text
        .lines()
        .nth(e.pos.line.saturating_sub(1) as usize)
        .unwrap_or("");
    let caret = " ".repeat(e.pos.col.saturating_sub(1) as usize);
    anyhow::anyhow!("{e}\n  | {line}\n  | {caret}^")
}

fn check(a: CheckArgs) -> CliResult {
    let text = program_text(&a.program)?;
    let lib = load_library(&library_dir(a.library.as_deref(), Env::Pooltool))?;
    let schema = if a.no_probe {
        Schema::from_library(&lib)
    } else {
        probe_schema(&lib, &pool()?)
    };
    let program = compile(&text, &schema).map_err(|e| CliError::input(show_error(&text, &e)))?;
    println!(
        "ok: {} program for library {} ({} label(s) used: {})",
        program.env,
        lib.name,
        labels_used(&program).len(),
        labels_used(&program).join(", ")
    );
    Ok(0)
}

fn eval(a: EvalArgs) -> CliResult {
    let text = program_text(&a.program)?;
    if !a.run.is_dir() {
        return Err(CliError::input(anyhow::anyhow!(
            "{}: no such run folder",
            a.run.display()
        )));
    }
    let run = RunDir::new(&a.run);
    let trace = read_trace(&run, &a.trace).map_err(CliError::of)?;
    let lib = load_library(&library_dir(a.library.as_deref(), trace.env))?;
    if lib.env != trace.env {
        return Err(CliError::input(anyhow::anyhow!(
            "library {} is for {}, the trace is {}",
            lib.name,
            lib.env,
            trace.env
        )));
    }
    // This trace's annotations by the library, if the run holds them; the parameter keys are
    // learned from every trace's (read a file at a time, no row kept).
    let ours = |d: &str| lib.detectors.iter().any(|x| x.id.0 == d);
    let stored: Vec<Annotation> = match run.table("annotations") {
        Ok(_) => read_annotations(&run, trace.env, Some(&trace.trace_id))
            .map_err(|e| CliError::of(e).context("reading annotations"))?
            .into_iter()
            .filter(|x| ours(&x.detector_id.0))
            .collect(),
        Err(_) => Vec::new(),
    };
    let mut schema = Schema::from_library(&lib);
    let (annotations, source) = if !stored.is_empty() {
        let keys = parameter_keys(&run, trace.env, ours)
            .map_err(|e| CliError::of(e).context("reading annotations"))?;
        schema.learn_label_keys(keys);
        (stored, "the run's annotations table")
    } else {
        let pool = pool()?;
        schema = probe_schema(&lib, &pool);
        let (anns, failed) = annotate(
            &pool,
            &detectors_for(&lib, &[]),
            std::slice::from_ref(&trace),
        );
        if failed > 0 {
            eprintln!("warning: {failed} detector call(s) failed on this trace");
        }
        schema.learn_keys(&anns);
        (anns, "the library, run now in the sandboxed workers")
    };
    let program = compile(&text, &schema).map_err(|e| CliError::input(show_error(&text, &e)))?;
    let at = AnnotatedTrace::new(&trace, &annotations);
    let result = evaluate(&program, &at).map_err(|e| CliError::input(show_error(&text, &e)))?;
    println!(
        "trace {} ({}), annotations from {source}",
        trace.trace_id, trace.env
    );
    for (i, c) in result.clauses.iter().enumerate() {
        let one_line: String = c.text.split_whitespace().collect::<Vec<_>>().join(" ");
        println!(
            "clause {:>2}  {:<5}  {:.3}  {one_line}",
            i + 1,
            c.truth,
            c.score
        );
    }
    println!("success: {}", result.success);
    println!("score: {:.4}", result.score);
    Ok(0)
}

/// A billiards scene from a JSON file or `SEED:INDEX`.
fn pool_scene(spec: &str, env: &PoolEnv) -> Result<Scene, CliError> {
    if let Some((seed, index)) = spec.split_once(':')
        && let (Ok(seed), Ok(index)) = (seed.parse::<u64>(), index.parse::<usize>())
    {
        return env
            .scenes(index + 1, seed)
            .map_err(|e| CliError::input(anyhow::anyhow!("--scene {spec}: {e}")))
            .map(|mut v| v.remove(index));
    }
    let text = std::fs::read_to_string(spec).map_err(|e| {
        CliError::input(anyhow::anyhow!(
            "--scene {spec}: {e} (give a scene JSON file or SEED:INDEX)"
        ))
    })?;
    Scene::from_json_str(&text, &env.config)
        .map_err(|e| CliError::input(anyhow::anyhow!("--scene {spec}: {e}")))
}

/// The scene in words: table, pockets, balls.
fn scene_summary(scene: &Scene, env: &PoolEnv) -> String {
    let t = &env.config.table;
    let pockets: Vec<String> = t
        .pockets
        .iter()
        .map(|p| format!("{} ({:.2}, {:.2})", p.id, p.center[0], p.center[1]))
        .collect();
    let balls: Vec<String> = scene
        .balls
        .iter()
        .map(|b| format!("{} ({:.3}, {:.3})", b.id, b.x, b.y))
        .collect();
    format!(
        "Billiards table {:.3} m wide (x) by {:.3} m long (y), origin at the bottom-left corner. Pockets: {}.\n\
         The cue strikes ball {:?}. Balls at rest (id, x, y in metres): {}.\n\
         The action is one shot: speed V0 (m/s), aim angle phi (degrees from +x), elevation theta, tip offsets a, b.",
        t.w,
        t.l,
        pockets.join(", "),
        scene.cue_ball,
        balls.join(", ")
    )
}

/// A PHYRE task (`--scene 00003:002`, default the first task) or I-PHYRE game (`--scene support`,
/// default the first game) in words, with a probe episode of it.
fn other_scene(env: Env, spec: &str) -> Result<(String, annotrace::trace::Trace), CliError> {
    use annotrace::optimise::{IphyreProblem, PhyreProblem, Problem};
    let bad = |e: String| CliError::input(anyhow::anyhow!("--scene {spec}: {e}"));
    match env {
        Env::Phyre => {
            let set =
                annotrace::envs::phyre::TaskSet::default_tasks().map_err(|e| bad(e.to_string()))?;
            let id = if set.contains(spec) {
                spec.to_string()
            } else {
                set.id_at(0).unwrap_or_default().to_string()
            };
            let task = set.get(&id).map_err(|e| bad(e.to_string()))?;
            let problem = PhyreProblem::default();
            let trace = problem
                .simulate(&task, &[0.5, 0.95, 0.1])
                .map_err(|e| CliError::failed(anyhow::anyhow!("simulating the probe: {e}")))?;
            Ok((problem.describe(&task), trace))
        }
        Env::Iphyre => {
            let ienv = annotrace::envs::iphyre::IphyreEnv::new().map_err(|e| bad(e.to_string()))?;
            let game = ienv
                .games
                .get(spec)
                .cloned()
                .unwrap_or_else(|_| ienv.games.all()[0].clone());
            let problem = IphyreProblem {
                env: ienv,
                horizon: 5.0,
                never: 0.25,
            };
            let never = vec![10.0; game.eliminable().count()];
            let trace = problem
                .simulate(&game, &never)
                .map_err(|e| CliError::failed(anyhow::anyhow!("simulating the probe: {e}")))?;
            Ok((problem.describe(&game), trace))
        }
        Env::Pooltool => Err(bad("billiards scenes are handled above".into())),
    }
}

fn synthesise(a: SynthArgs) -> CliResult {
    use super::llm_args::llm_error;
    use annotrace::llm::LlmClient;
    use annotrace::reward::synth::{SynthRequest, prompt, synthesise as run_synthesis};

    let env = a.env;
    let lib = load_library(&library_dir(a.library.as_deref(), env))?;
    if lib.env != env {
        return Err(CliError::input(anyhow::anyhow!(
            "library {} is for {}, not {env}",
            lib.name,
            lib.env
        )));
    }
    let pool_env = PoolEnv::default();
    let probe_trace;
    let mut annotations = Vec::new();
    let mut image = None;
    let (schema, scene_text) = if env == Env::Pooltool {
        let scene = pool_scene(&a.scene, &pool_env)?;
        let workers = pool()?;
        let mut schema = probe_schema(&lib, &workers);
        // A probe shot of the scene: programs must run on it (OBJECT_ID, NEARBY_AT objects exist).
        let shot = Shot {
            v0: 2.0,
            phi: 90.0,
            theta: 0.0,
            a: 0.0,
            b: 0.0,
        };
        let trace = pool_env
            .simulate(&scene, &shot)
            .map_err(|e| CliError::failed(anyhow::anyhow!("simulating the probe shot: {e}")))?;
        let (anns, _) = annotate(&workers, &lib.detectors, std::slice::from_ref(&trace));
        schema.learn_keys(&anns);
        if a.image {
            image = Some(
                pool_env
                    .render(&trace, 0.0)
                    .map_err(|e| CliError::failed(anyhow::anyhow!("rendering the scene: {e}")))?,
            );
        }
        annotations = anns;
        let text = scene_summary(&scene, &pool_env);
        probe_trace = Some(trace);
        (schema, text)
    } else {
        // PHYRE / I-PHYRE: the task or game in words, and a probe episode (no click, a small ball)
        // that programs must run on.
        let (text, trace) = other_scene(env, &a.scene)?;
        probe_trace = Some(trace);
        (Schema::from_library(&lib), text)
    };
    // Few-shot examples: the built-in goal file's goals, never this sentence.
    let examples = annotrace::reward::goals::GoalSet::open(
        &annotrace::builtin::Location::file(
            std::path::Path::new("."),
            std::path::Path::new(&format!("data/goals/{env}.toml")),
        ),
        std::path::Path::new("."),
    )
    .map(|g| annotrace::reward::synth::few_shot(&g.goals, None, &a.goal, 3))
    .unwrap_or_default();
    let req = SynthRequest {
        goal: &a.goal,
        schema: &schema,
        scene_summary: scene_text,
        examples,
        image,
        probe: probe_trace.as_ref().map(|t| (t, annotations.as_slice())),
        max_repairs: a.max_repairs,
        seed: a.seed,
        temperature: a.temperature,
    };
    if a.dry_run {
        println!("{}", prompt(&req));
        return Ok(0);
    }
    let config = a.llm.config(a.seed)?;
    let record = a.run.as_ref().map(RunDir::new);
    let client = LlmClient::new(config, record.as_ref()).map_err(llm_error)?;
    let result = run_synthesis(&client, &req);
    client.flush().map_err(llm_error)?;
    let result = result.map_err(llm_error)?;
    for (i, at) in result.attempts.iter().enumerate() {
        eprintln!(
            "attempt {} ({}, call {}): {}",
            i + 1,
            at.purpose,
            at.call_id,
            at.error.as_deref().unwrap_or("accepted")
        );
    }
    match result.program {
        Some(p) => {
            if let Some(out) = &a.out {
                annotrace::store::write_atomic(out, format!("{}\n", p.source.trim()).as_bytes())
                    .map_err(|e| CliError::io(out, e))?;
            }
            println!("{}", p.source.trim());
            Ok(0)
        }
        None => Err(CliError::failed(anyhow::anyhow!(
            "no valid program after {} attempt(s); the last error: {}",
            result.attempts.len(),
            result
                .attempts
                .last()
                .and_then(|x| x.error.clone())
                .unwrap_or_default()
        ))),
    }
}
