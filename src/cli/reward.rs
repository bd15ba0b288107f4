//! `annotrace reward`: check a reward program, evaluate it on a trace of a run, or synthesise one
//! from a natural-language goal with an LLM.

use std::path::{Path, PathBuf};

use annotrace::detect::{Annotation, Library, SandboxLimits, WorkerPool};
use annotrace::pipeline::stages::annotate::read_annotations;
use annotrace::reward::annotate::{annotate, detectors_for, probe_schema};
use annotrace::reward::{AnnotatedTrace, RewardError, Schema, compile, evaluate, labels_used};
use annotrace::store::{ReadTraceError, RunDir, read_trace};
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
}

#[derive(clap::Args, Debug)]
struct CheckArgs {
    /// The program (DSL text), or @FILE to read it from a file.
    program: String,
    /// Library folder; default: data/libraries/pooltool.
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
    /// Library folder; default: data/libraries/<env of the trace>.
    #[arg(long)]
    library: Option<PathBuf>,
}

pub fn run(args: Args) -> CliResult {
    match args.command {
        Command::Check(a) => check(a),
        Command::Eval(a) => eval(a),
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

/// The library folder: the one given, or data/libraries/<env> of the current folder, or the crate's.
pub(crate) fn library_dir(given: Option<&Path>, env: Env) -> PathBuf {
    if let Some(p) = given {
        return p.to_path_buf();
    }
    let local = Path::new("data/libraries").join(env.as_str());
    if local.join("library.toml").is_file() {
        local
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("data/libraries")
            .join(env.as_str())
    }
}

pub(crate) fn load_library(dir: &Path) -> Result<Library, CliError> {
    Library::load(dir).map_err(|e| CliError::input(anyhow::anyhow!("{e}")))
}

pub(crate) fn pool() -> Result<WorkerPool, CliError> {
    WorkerPool::new(SandboxLimits::default())
        .map_err(|e| CliError::failed(anyhow::anyhow!("starting the detector workers: {e}")))
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
    let trace = read_trace(&run, &a.trace).map_err(|e| match e {
        ReadTraceError::NotFound { .. } => CliError::input(e),
        other => CliError::failed(other),
    })?;
    let lib = load_library(&library_dir(a.library.as_deref(), trace.env))?;
    if lib.env != trace.env {
        return Err(CliError::input(anyhow::anyhow!(
            "library {} is for {}, the trace is {}",
            lib.name,
            lib.env,
            trace.env
        )));
    }
    // The run's annotations of this library (all traces: they teach the parameter keys).
    let stored: Vec<Annotation> = match run.table("annotations") {
        Ok(_) => read_annotations(&run, trace.env, None)
            .map_err(|e| CliError::failed(anyhow::anyhow!("reading annotations: {e}")))?
            .into_iter()
            .filter(|x| lib.detectors.iter().any(|d| d.id == x.detector_id))
            .collect(),
        Err(_) => Vec::new(),
    };
    let mut schema = Schema::from_library(&lib);
    let (annotations, source) = if stored.iter().any(|x| x.trace_id == trace.trace_id) {
        schema.learn_keys(&stored);
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
