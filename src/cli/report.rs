//! `annotrace report`: writes a run's static web report (the `report` stage kind, as a one-stage
//! pipeline recorded as `report`; it always reruns, since the run may have changed since) and prints
//! where its page is.

use std::path::PathBuf;

use annotrace::pipeline::stages::report::{KIND, ReportParams, ReportSummary};
use annotrace::trace::Env;

use super::CliResult;
use super::one_stage::{OneStage, absolute, existing_run, summary};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder.
    #[arg(long)]
    run: PathBuf,
    /// Report folder (default: <run>/exports/report); its old contents are replaced.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Only traces of this environment (repeatable).
    #[arg(long)]
    env: Vec<Env>,
    /// Only this trace (repeatable).
    #[arg(long)]
    trace: Vec<String>,
    /// At most this many traces per environment.
    #[arg(long)]
    max_traces: Option<u64>,
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    existing_run(&args.run)?;
    let params = ReportParams {
        out: args.out.as_deref().map(absolute).transpose()?,
        envs: args.env,
        traces: args.trace,
        max_traces: args.max_traces,
        merge: None,
    };
    let stage = OneStage {
        run: &args.run,
        id: "report".into(),
        force: true,
        remove_new_run_on_failure: false,
    }
    .run(&KIND, &params, quiet)?;
    let s: ReportSummary = summary(&stage, "report")?;
    let total: u64 = s.traces.values().sum();
    let page = if PathBuf::from(&s.index).is_absolute() {
        PathBuf::from(&s.index)
    } else {
        args.run.join(&s.index)
    };
    println!(
        "report of {total} trace(s) ({}), libraries: {}; open {}",
        s.traces
            .iter()
            .map(|(e, n)| format!("{n} {e}"))
            .collect::<Vec<_>>()
            .join(", "),
        if s.libraries.is_empty() {
            "none".to_string()
        } else {
            s.libraries.join(", ")
        },
        page.display()
    );
    Ok(0)
}
