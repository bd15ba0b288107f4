//! `annotrace accuracy`: scores a library's event-grounded labels against the simulator's events of a
//! run (precision, recall, F1 per label), as a one-stage `accuracy` pipeline; prints a Markdown table.

use annotrace::pipeline::stages::accuracy::{AccuracyParams, AccuracySummary, KIND};

use super::CliResult;
use super::annotate::SandboxArgs;
use super::one_stage::summary;

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    sandbox: SandboxArgs,
    /// Time tolerance (s) around a detection's span.
    #[arg(long, default_value_t = AccuracyParams::default().tolerance)]
    tolerance: f64,
    /// Same-pair contacts closer than this (s) are one event.
    #[arg(long, default_value_t = AccuracyParams::default().merge)]
    merge: f64,
    /// Give the detectors the traces without their event log (scoring still uses it).
    #[arg(long)]
    hide_events: bool,
    /// List up to N disagreements per label (missed truth events, false detections).
    #[arg(long, value_name = "N", default_value_t = 0)]
    list: u64,
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    let params = AccuracyParams {
        sandbox: args.sandbox.params()?,
        tolerance: args.tolerance,
        merge: args.merge,
        hide_events: args.hide_events,
        list: args.list,
        ..AccuracyParams::default()
    };
    let stage = args
        .sandbox
        .one_stage("accuracy", &params.sandbox)?
        .run(&KIND, &params, quiet)?;
    let s: AccuracySummary = summary(&stage, "accuracy")?;
    println!("{}", s.markdown);
    if !s.misses.is_empty() {
        println!(
            "| label | trace | kind | t_start | t_end | objects |\n|---|---|---|---:|---:|---|"
        );
        for m in &s.misses {
            println!(
                "| {} | {} | {} | {:.3} | {:.3} | {} |",
                m.label,
                m.trace_id,
                m.kind,
                m.t_start,
                m.t_end,
                m.objects.join(" ")
            );
        }
        println!();
    }
    println!(
        "{} trace(s), tolerance {} s, contacts merged within {} s{}",
        s.traces,
        s.tolerance,
        s.merge,
        if s.hide_events {
            ", detectors given no event log"
        } else {
            ""
        }
    );
    Ok(0)
}
