//! `annotrace run PIPELINE`: validates a pipeline file, then runs (or explains) it — whole, as one
//! slice of a sharded run (`--shard i/n`, or `--shard auto` from a batch scheduler's environment), or
//! as the finalisation of a sharded run (`--finalize`).

use std::path::PathBuf;

use annotrace::pipeline::{
    PipelineSpec, RunOptions, Slice, explain, run as run_pipeline, run_shard,
};

use super::progress::Terminal;
use super::{CliError, CliResult, fault_from_env, run_error};

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
    /// Compute slice i of n (0-based) of every shardable stage into the shared run folder, as one of n
    /// processes; `auto` reads SLURM_ARRAY_TASK_ID / SLURM_ARRAY_TASK_COUNT (minus
    /// SLURM_ARRAY_TASK_MIN) or Kubernetes' JOB_COMPLETION_INDEX with ANNOTRACE_SHARD_COUNT.
    /// Unshardable stages after the last shardable one are left to --finalize (docs/pipelines.md).
    #[arg(long, value_name = "i/n|auto", conflicts_with_all = ["force", "finalize"])]
    shard: Option<String>,
    /// After a sharded run: commit every stage whose slices are all done (an error names the missing
    /// ones), then run the remaining stages.
    #[arg(long)]
    finalize: bool,
}

/// The slice `--shard` names: `i/n`, or `auto` from the scheduler's environment.
fn slice_of(spec: &str) -> Result<Slice, CliError> {
    if spec != "auto" {
        return spec
            .parse()
            .map_err(|e: String| CliError::input(anyhow::anyhow!("--shard: {e}")));
    }
    let var = |name: &str| -> Result<Option<usize>, CliError> {
        match std::env::var(name) {
            Ok(v) if !v.trim().is_empty() => v.trim().parse().map(Some).map_err(|_| {
                CliError::input(anyhow::anyhow!(
                    "--shard auto: {name}={v:?} is not a non-negative integer"
                ))
            }),
            _ => Ok(None),
        }
    };
    let (index, count, from) = if let Some(id) = var("SLURM_ARRAY_TASK_ID")? {
        let min = var("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
        let count = var("ANNOTRACE_SHARD_COUNT")?
            .or(var("SLURM_ARRAY_TASK_COUNT")?)
            .ok_or_else(|| {
                CliError::input(anyhow::anyhow!(
                    "--shard auto: SLURM_ARRAY_TASK_ID is set but neither SLURM_ARRAY_TASK_COUNT nor ANNOTRACE_SHARD_COUNT"
                ))
            })?;
        let index = id.checked_sub(min).ok_or_else(|| {
            CliError::input(anyhow::anyhow!(
                "--shard auto: SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}"
            ))
        })?;
        (index, count, "SLURM_ARRAY_TASK_ID")
    } else if let Some(index) = var("JOB_COMPLETION_INDEX")? {
        let count = var("ANNOTRACE_SHARD_COUNT")?.ok_or_else(|| {
            CliError::input(anyhow::anyhow!(
                "--shard auto: JOB_COMPLETION_INDEX is set but not ANNOTRACE_SHARD_COUNT (set it to the Job's completions)"
            ))
        })?;
        (index, count, "JOB_COMPLETION_INDEX")
    } else {
        return Err(CliError::input(anyhow::anyhow!(
            "--shard auto: none of SLURM_ARRAY_TASK_ID (a Slurm job array) or JOB_COMPLETION_INDEX (a Kubernetes Indexed Job) is set; give --shard i/n"
        )));
    };
    Slice::new(index, count)
        .map_err(|e| CliError::input(anyhow::anyhow!("--shard auto ({from}): {e}")))
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    let spec = PipelineSpec::from_file(&args.pipeline)?;
    let slice = args.shard.as_deref().map(slice_of).transpose()?;
    let opts = RunOptions {
        run_dir: args.run_dir,
        force: args.force,
        until: args.until,
        fault: fault_from_env()?,
        record_pipeline: true,
        remove_new_run_on_failure: false,
        finalize: args.finalize,
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
    let report = match slice {
        Some(slice) => run_shard(&spec, &opts, slice, &progress).map_err(run_error)?,
        None => run_pipeline(&spec, &opts, &progress).map_err(run_error)?,
    };
    if !quiet {
        let ran = report.stages.iter().filter(|s| !s.cached).count();
        let what = slice.map_or(String::new(), |s| format!(" (shard {s})"));
        eprintln!(
            "run {}{what}: {} stage(s) ran, {} cached",
            report.run_dir.display(),
            ran,
            report.stages.len() - ran
        );
    }
    Ok(0)
}
