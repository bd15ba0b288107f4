//! `annotrace show`: prints one trace of a run with its annotations as compact text for language models
//! (`detect::annotated_text`), followed by a token estimate (`detect::count_tokens`).

use std::path::PathBuf;

use annotrace::detect::tables::read_annotations;
use annotrace::detect::{annotated_text, count_tokens};
use annotrace::store::{RunDir, read_trace};

use super::{CliError, CliResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder.
    #[arg(long)]
    run: PathBuf,
    /// Trace id.
    #[arg(long)]
    trace: String,
    /// Leave out the final `# tokens:` line.
    #[arg(long)]
    no_count: bool,
}

pub fn run(args: Args) -> CliResult {
    let local = super::location::local_run(&args.run)?;
    let run = RunDir::new(local.path());
    let trace = read_trace(&run, &args.trace).map_err(CliError::of)?;
    let annotations = read_annotations(&run, trace.env, Some(&trace.trace_id))
        .map_err(|e| CliError::of(e).context("reading annotations"))?;
    let text = annotated_text(&trace, &annotations);
    print!("{text}");
    if !args.no_count {
        println!(
            "# tokens: {} (cl100k-style estimate, see docs/detectors.md)",
            count_tokens(&text)
        );
    }
    Ok(0)
}
