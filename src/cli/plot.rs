//! `annotrace plot`: draws one figure of a run (the `plot` stage kind, as a one-stage pipeline
//! recorded as `plot-<kind>`; it always reruns) and prints the files it wrote.

use std::path::PathBuf;

use annotrace::pipeline::stages::plot::{KIND, PlotFormat, PlotParams, PlotSummary};
use annotrace::plot::PlotKind;

use super::one_stage::{OneStage, existing_run, summary};
use super::{CliError, CliResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder.
    #[arg(long)]
    run: PathBuf,
    /// The figure: success-budget, convergence, library-size, identification-size, fitness, learning-stats,
    /// annotation-examples.
    kind: String,
    /// File name stem under <run>/exports/ (default: the figure's name).
    #[arg(long)]
    file: Option<String>,
    /// Files to write: both, svg or png.
    #[arg(long, default_value = "both", value_parser = ["both", "svg", "png"])]
    format: String,
    /// Title line.
    #[arg(long)]
    title: Option<String>,
    /// annotation-examples: the trace (default: the first annotated trace).
    #[arg(long)]
    trace: Option<String>,
    /// annotation-examples: frames above the timeline.
    #[arg(long, default_value_t = 5)]
    frames: u32,
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    existing_run(&args.run)?;
    let kind: PlotKind = args
        .kind
        .parse()
        .map_err(|e: String| CliError::input(anyhow::anyhow!(e)))?;
    let params = PlotParams {
        plot: Some(kind),
        file: args.file,
        format: match args.format.as_str() {
            "svg" => PlotFormat::Svg,
            "png" => PlotFormat::Png,
            _ => PlotFormat::Both,
        },
        title: args.title,
        trace: args.trace,
        frames: args.frames,
        skip_empty: false,
    };
    let stage = OneStage {
        run: &args.run,
        id: format!("plot-{}", kind.name()),
        force: true,
        remove_new_run_on_failure: false,
    }
    .run(&KIND, &params, quiet)?;
    let s: PlotSummary = summary(&stage, "plot")?;
    for f in &s.files {
        println!("{}", args.run.join(f).display());
    }
    Ok(0)
}
