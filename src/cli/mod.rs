//! The command line: one file per command turns clap arguments into library calls and prints results.
//!
//! Exit codes are decided in one place, [`exit_code`], from the library's
//! [`ErrorCategory`](annotrace::pipeline::ErrorCategory) of the error a command returns:
//!
//! | code | category | meaning |
//! |---|---|---|
//! | 0 | | success (a broken pipe on the output also exits quietly with 0) |
//! | 1 | `Failed` | the command finished but some items failed (invalid traces skipped, a stage failed at run time, an unusable answer, damaged or foreign files found by `verify`) |
//! | 2 | `Input` | bad input or configuration (a malformed file, an unknown option value, an invalid pipeline, a missing file) |
//! | 3 | `Service` | an external service is unavailable (the LLM endpoint unreachable or failing after retries, the Python detector workers cannot start) |
//! | 4 | `Io` | reading or writing the run folder or an output failed (disk full, permission denied) |
//! | 5 | `Locked` | another annotrace process holds the run folder |
//! | 70 | `Internal` | a bug in annotrace (please report it) |
//!
//! The environment is read here only: `ANNOTRACE_LOG` (log filter, e.g. `debug`) and `ANNOTRACE_FAULT`
//! (a test switch that stops a run on purpose, see `docs/pipelines.md`), `ANNOTRACE_PYTHON` (the
//! detector workers' interpreter, e.g. `pypy3`; default `python3` on the `PATH`); the LLM endpoint's
//! `ANNOTRACE_LLM_BASE_URL`, `ANNOTRACE_LLM_MODEL`, `ANNOTRACE_LLM_API_KEY` and `ANNOTRACE_PROMPTS`
//! are read in `llm_args.rs` ([`llm_args::LlmArgs`], see `docs/llm.md`).

mod accuracy;
mod annotate;
mod bench;
mod benchmark;
mod ensemble;
mod evolve;
mod export;
mod import;
mod import_survey;
mod llm_args;
mod location;
mod one_stage;
mod plot;
mod progress;
mod query;
mod render;
mod report;
mod reward;
mod run;
mod show;
mod simulate;
mod stages;
mod suggest_labels;
mod summarise;
mod survey;
mod tables;
mod verify;
mod worker_args;

use std::process::ExitCode;

use annotrace::pipeline::{Categorize, ErrorCategory};
use clap::{Parser, Subcommand};

/// The exit code of each error category: the one table of the command line (documented above, in
/// README's "Exit codes" and in docs/pipelines.md).
pub fn exit_code(category: ErrorCategory) -> u8 {
    match category {
        ErrorCategory::Failed => 1,
        ErrorCategory::Input => 2,
        ErrorCategory::Service => 3,
        ErrorCategory::Io => 4,
        ErrorCategory::Locked => 5,
        ErrorCategory::Internal => 70,
    }
}

/// An error with its category (which decides the exit code).
#[derive(Debug)]
pub struct CliError {
    pub category: ErrorCategory,
    pub error: anyhow::Error,
}

impl CliError {
    /// An error of a given category.
    pub fn new(category: ErrorCategory, error: impl Into<anyhow::Error>) -> Self {
        CliError {
            category,
            error: error.into(),
        }
    }
    /// Bad input or configuration that the command line itself detects (an option's value, a
    /// combination of options).
    pub fn input(error: impl Into<anyhow::Error>) -> Self {
        CliError::new(ErrorCategory::Input, error)
    }
    /// The command ran but did not succeed (an unusable answer, a summary that cannot be read).
    pub fn failed(error: impl Into<anyhow::Error>) -> Self {
        CliError::new(ErrorCategory::Failed, error)
    }
    /// An I/O error on `path` (a file the command writes or reads): a missing file is the user's
    /// input, anything else an I/O failure.
    pub fn io(path: &std::path::Path, error: std::io::Error) -> Self {
        CliError::new(
            error.category(),
            anyhow::Error::from(error).context(path.display().to_string()),
        )
    }
    /// Adds context to the message, keeping the category.
    pub fn context(self, context: impl std::fmt::Display + Send + Sync + 'static) -> Self {
        CliError {
            category: self.category,
            error: self.error.context(context),
        }
    }
    /// An error of the library, with the category it knows.
    pub fn of<E>(error: E) -> Self
    where
        E: Categorize + std::error::Error + Send + Sync + 'static,
    {
        CliError::new(error.category(), error)
    }
}

impl<E> From<E> for CliError
where
    E: Categorize + std::error::Error + Send + Sync + 'static,
{
    fn from(error: E) -> Self {
        CliError::of(error)
    }
}

/// Every command returns the exit code it wants on success: 0, or
/// `exit_code(ErrorCategory::Failed)` when it finished with failed items.
pub type CliResult = Result<u8, CliError>;

#[derive(Parser, Debug)]
#[command(
    name = "annotrace",
    version,
    about = "Discover high-level patterns in physics simulation traces",
    long_about = "annotrace stores simulation traces as Parquet tables in a run folder, runs pipelines of stages \
                  over them, and answers SQL over the results.\n\nExit codes: 0 success; 1 finished with failed \
                  items or a stage failed; 2 bad input or configuration; 3 an external service is unavailable \
                  (LLM endpoint, Python detector workers); 4 an I/O error on the run folder or an output \
                  (disk full, permission); 5 the run folder is locked by another process; 70 internal error."
)]
struct Cli {
    /// Print only errors (no progress, no summaries on stderr).
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run a pipeline file (resumes where an interrupted run stopped; skips finished stages).
    Run(run::Args),
    /// List the stage kinds a pipeline can use, with their parameters.
    Stages(stages::Args),
    /// Simulate billiards shots, I-PHYRE or PHYRE episodes into a run (a random dataset, or one replay).
    Simulate(simulate::Args),
    /// Draw a run's trace, an I-PHYRE game or a PHYRE task as a PNG (one instant or a strip of frames).
    Render(render::Args),
    /// Import traces in the paper's JSON format into a run.
    Import(import::Args),
    /// Run a detector library over a run's traces in sandboxed Python workers.
    Annotate(annotate::Args),
    /// Score a library's event-grounded labels against simulator events (precision/recall/F1).
    Accuracy(accuracy::Args),
    /// Learn detectors for labels by evolutionary search over a run's traces (resumable).
    Evolve(evolve::Args),
    /// Build an ensemble library from the candidates of several evolve stages (K-means, calibration).
    Ensemble(ensemble::Args),
    /// Play DeepPHY-style physics-reasoning tasks with an agent (random, search or an LLM) and feedback.
    Benchmark(benchmark::Args),
    /// Summarise traces (offline from annotations, or an LLM), with their cost and the identification task.
    Summarise(summarise::Args),
    /// Print a trace with its annotations as compact text for language models, with a token count.
    Show(show::Args),
    /// Draw a figure of a run as SVG and PNG (success-budget, convergence, library-size, identification-size, fitness, learning-stats, annotation-examples).
    Plot(plot::Args),
    /// Write a run's static web report: trace list, trace player, pattern timeline, annotated text.
    Report(report::Args),
    /// Write a survey page: rollout animations beside one summary each, rated 1–7 (seeded per participant).
    Survey(survey::Args),
    /// Read the survey page's response CSVs into the survey_responses table (checked against the survey).
    ImportSurvey(import_survey::Args),
    /// Reward programs: check one, evaluate it on a trace, or synthesise one from a goal sentence.
    Reward(reward::Args),
    /// Ask the configured LLM for K pattern labels, shown example traces of --run (or --offline: a baseline).
    SuggestLabels(suggest_labels::Args),
    /// Write one trace of a run back in the paper's JSON format.
    Export(export::Args),
    /// Run SQL over a run's tables.
    Query(query::Args),
    /// List a run's tables with row counts and schemas.
    Tables(tables::Args),
    /// Check a run's files against the sizes and SHA-256 sums in its manifest; list foreign files.
    Verify(verify::Args),
    /// Measure `simulate` and `annotate` end to end (command line to Parquet) for each row of the throughput table.
    Bench(bench::Args),
}

/// Parses arguments, runs the command, prints errors and returns the exit code.
pub fn main() -> ExitCode {
    quiet_on_closed_pipe();
    let cli = Cli::parse();
    init_logging(cli.quiet);
    if let Some(python) = std::env::var_os("ANNOTRACE_PYTHON").filter(|p| !p.is_empty()) {
        annotrace::detect::set_default_python(python.into());
    }
    let result = match cli.command {
        Command::Run(a) => run::run(a, cli.quiet),
        Command::Stages(a) => stages::run(a),
        Command::Simulate(a) => simulate::run(a, cli.quiet),
        Command::Render(a) => render::run(a),
        Command::Import(a) => import::run(a, cli.quiet),
        Command::Annotate(a) => annotate::run(a, cli.quiet),
        Command::Accuracy(a) => accuracy::run(a, cli.quiet),
        Command::Evolve(a) => evolve::run(a, cli.quiet),
        Command::Ensemble(a) => ensemble::run(a, cli.quiet),
        Command::Benchmark(a) => benchmark::run(a, cli.quiet),
        Command::Summarise(a) => summarise::run(a, cli.quiet),
        Command::Show(a) => show::run(a),
        Command::Plot(a) => plot::run(a, cli.quiet),
        Command::Report(a) => report::run(a, cli.quiet),
        Command::Survey(a) => survey::run(a, cli.quiet),
        Command::ImportSurvey(a) => import_survey::run(a, cli.quiet),
        Command::Reward(a) => reward::run(a),
        Command::SuggestLabels(a) => suggest_labels::run(a, cli.quiet),
        Command::Export(a) => export::run(a),
        Command::Query(a) => query::run(a),
        Command::Tables(a) => tables::run(a),
        Command::Verify(a) => verify::run(a),
        Command::Bench(a) => bench::run(a),
    };
    match result {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            if is_broken_pipe(&e.error) {
                return ExitCode::SUCCESS;
            }
            eprintln!("error: {}", error_text(&e.error));
            ExitCode::from(exit_code(e.category))
        }
    }
}

/// A reader that closes the pipe early (`annotrace stages | head -1`) ends the command quietly with
/// exit code 0, as a returned broken-pipe error does: `println!` panics on a closed stdout, so a panic
/// hook recognises that one panic and exits; every other panic goes to the default hook.
fn quiet_on_closed_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or_default();
        if message.starts_with("failed printing to stdout") && message.contains("Broken pipe") {
            std::process::exit(0);
        }
        default(info);
    }));
}

/// The error and its causes on one line (a cause its parent already printed is left out).
fn error_text(e: &anyhow::Error) -> String {
    annotrace::pipeline::error_chain(e.as_ref())
}

fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

fn init_logging(quiet: bool) {
    let default = if quiet { "error" } else { "warn" };
    let filter = tracing_subscriber::EnvFilter::try_from_env("ANNOTRACE_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
}

/// Opens a run for SQL (a local folder, or `s3://…` through a pulled copy); a folder that does not
/// exist is the user's mistake (exit 2).
pub(crate) fn open_query(dir: &std::path::Path) -> Result<OpenQuery, CliError> {
    let local = location::local_run(dir)?;
    let query = annotrace::query::RunQuery::open(&annotrace::store::RunDir::new(local.path()))?;
    Ok(OpenQuery {
        query,
        _local: local,
    })
}

/// A run's query session, with the local copy it reads (kept as long as the session).
pub(crate) struct OpenQuery {
    query: annotrace::query::RunQuery,
    _local: location::LocalRun,
}

impl std::ops::Deref for OpenQuery {
    type Target = annotrace::query::RunQuery;
    fn deref(&self) -> &Self::Target {
        &self.query
    }
}

/// The fault plan from `ANNOTRACE_FAULT`, for tests of resumption.
pub(crate) fn fault_from_env() -> Result<Option<annotrace::pipeline::FaultPlan>, CliError> {
    match std::env::var("ANNOTRACE_FAULT") {
        Ok(s) if !s.is_empty() => s
            .parse()
            .map(Some)
            .map_err(|e: String| CliError::input(anyhow::anyhow!("ANNOTRACE_FAULT: {e}"))),
        _ => Ok(None),
    }
}

/// A runner error, with its category.
pub(crate) fn run_error(e: annotrace::pipeline::RunError) -> CliError {
    CliError::of(e)
}

#[cfg(test)]
mod tests {
    use super::error_text;

    #[derive(Debug, thiserror::Error)]
    #[error("External: {0}")]
    struct Echoes(#[source] Inner);

    #[derive(Debug, thiserror::Error)]
    #[error("data corruption detected")]
    struct Inner;

    #[test]
    fn a_cause_already_printed_by_its_parent_is_printed_once() {
        let e = anyhow::Error::new(Echoes(Inner)).context("f.parquet");
        assert_eq!(
            error_text(&e),
            "f.parquet: External: data corruption detected"
        );
        assert_eq!(
            format!("{e:#}"),
            "f.parquet: External: data corruption detected: data corruption detected"
        );
        let plain = anyhow::anyhow!("no column x").context("reading t.parquet");
        assert_eq!(error_text(&plain), "reading t.parquet: no column x");
    }
}
