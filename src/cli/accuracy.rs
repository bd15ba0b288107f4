//! `annotrace accuracy`: scores a library's event-grounded labels against the simulator's events of a
//! run (precision, recall, F1 per label), as a one-stage `accuracy` pipeline; prints a Markdown table.

use std::path::PathBuf;

use super::CliResult;
use super::annotate::{DetectArgs, run_one};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder holding simulated traces.
    #[arg(long)]
    run: PathBuf,
    /// Library folder; default: the built-in one, or ./data/libraries/<env> when present.
    #[arg(long)]
    library: Option<PathBuf>,
    /// Environment of the run's traces to score.
    #[arg(long, default_value = "pooltool", value_parser = ["pooltool", "iphyre", "phyre"])]
    env: String,
    /// Time tolerance (s) around a detection's span.
    #[arg(long, default_value_t = 0.05)]
    tolerance: f64,
    /// Same-pair contacts closer than this (s) are one event.
    #[arg(long, default_value_t = 0.05)]
    merge: f64,
    /// Give the detectors the traces without their event log (scoring still uses it).
    #[arg(long)]
    hide_events: bool,
    /// Python worker processes (0 = one per core).
    #[arg(long, default_value_t = 0)]
    workers: u64,
    /// Wall-clock limit of one detector call (s).
    #[arg(long, default_value_t = 10.0)]
    timeout: f64,
    /// Address-space limit of a worker (MiB).
    #[arg(long, default_value_t = 2048)]
    memory_mb: u64,
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    let a = DetectArgs {
        run: &args.run,
        library: args.library.as_deref(),
        env: &args.env,
        workers: args.workers,
        timeout: args.timeout,
        memory_mb: args.memory_mb,
    };
    let mut extra = toml::Table::new();
    extra.insert("tolerance".into(), toml::Value::Float(args.tolerance));
    extra.insert("merge".into(), toml::Value::Float(args.merge));
    extra.insert("hide_events".into(), toml::Value::Boolean(args.hide_events));
    let stage = run_one("accuracy", &a, extra, quiet)?;
    println!("{}", stage.summary["markdown"].as_str().unwrap_or_default());
    println!("{}", stage_line(&stage.summary));
    Ok(0)
}

fn stage_line(s: &serde_json::Value) -> String {
    format!(
        "{} trace(s), tolerance {} s, contacts merged within {} s{}",
        s["traces"],
        s["tolerance"],
        s["merge"],
        if s["hide_events"] == true {
            ", detectors given no event log"
        } else {
            ""
        }
    )
}
