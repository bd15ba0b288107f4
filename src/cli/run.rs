//! `annotrace run PIPELINE`: validates a pipeline file, then runs (or explains) it.

use std::path::PathBuf;

use annotrace::pipeline::{PipelineSpec, RunOptions, explain, run as run_pipeline};

use super::progress::Terminal;
use super::{CliResult, fault_from_env, run_error};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The pipeline file (TOML).
    pipeline: PathBuf,
    /// Run folder (default: the file's `run_dir`, else runs/<pipeline name> in the project folder).
    #[arg(long)]
    run_dir: Option<PathBuf>,
    /// Rerun this stage and every stage downstream of it, even if cached.
    #[arg(long, value_name = "STAGE")]
    force: Option<String>,
    /// Run only this stage and the stages it depends on.
    #[arg(long, value_name = "STAGE")]
    until: Option<String>,
    /// Print what would run (one line per stage: id, kind, fingerprint, action, inputs) and stop.
    #[arg(long)]
    explain: bool,
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    let spec = PipelineSpec::from_file(&args.pipeline)?;
    let opts = RunOptions {
        run_dir: args.run_dir,
        force: args.force,
        until: args.until,
        fault: fault_from_env()?,
        record_pipeline: true,
        remove_new_run_on_failure: false,
    };
    if args.explain {
        let (dir, plan) = explain(&spec, &opts).map_err(run_error)?;
        println!("pipeline {} -> {}", spec.name, dir.display());
        for p in plan {
            println!("{p}");
        }
        return Ok(0);
    }
    let progress = Terminal::new(quiet);
    let report = run_pipeline(&spec, &opts, &progress).map_err(run_error)?;
    if !quiet {
        let ran = report.stages.iter().filter(|s| !s.cached).count();
        eprintln!(
            "run {}: {} stage(s) ran, {} cached",
            report.run_dir.display(),
            ran,
            report.stages.len() - ran
        );
    }
    Ok(0)
}
