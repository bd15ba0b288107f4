//! `annotrace survey`: writes a run's survey page (the `survey` stage kind, as a one-stage pipeline
//! recorded as `survey`; it always reruns, since the run's summaries may have changed) and prints where
//! its page is and how to send it to participants.

use std::path::PathBuf;

use annotrace::pipeline::stages::survey::{KIND, SurveyParams, SurveySummary};
use annotrace::trace::Env;

use super::CliResult;
use super::one_stage::{OneStage, absolute, existing_run, summary};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder (with a `summaries` table: run `annotrace summarise` once per condition first).
    #[arg(long)]
    run: PathBuf,
    /// Page folder (default: <run>/exports/survey); its old contents are replaced.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Seed of the trace sample and of every participant's shuffle.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// List participant ids P001…PNNN as links on the start page (0: participants type an id).
    #[arg(long, default_value_t = 0)]
    participants: u64,
    /// Items: traces drawn with the seed among those summarised in every condition (0: all).
    #[arg(long, default_value_t = 20)]
    traces: u64,
    /// Only this trace (repeatable), instead of a seeded sample.
    #[arg(long = "trace")]
    trace_ids: Vec<String>,
    /// Only traces of this environment (repeatable).
    #[arg(long)]
    env: Vec<Env>,
    /// A condition to compare (repeatable; default: every summariser in the run), e.g. frames.
    #[arg(long = "condition")]
    conditions: Vec<String>,
    /// Side of the animations (px).
    #[arg(long, default_value_t = 320)]
    size: u64,
    /// Frames per second of simulated time.
    #[arg(long, default_value_t = 10.0)]
    fps: f64,
    /// At most this many frames per animation.
    #[arg(long, default_value_t = 150)]
    max_frames: u64,
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    existing_run(&args.run)?;
    let params = SurveyParams {
        out: args.out.as_deref().map(absolute).transpose()?,
        envs: args.env,
        traces: args.traces,
        trace_ids: args.trace_ids,
        conditions: args.conditions,
        seed: Some(args.seed),
        participants: args.participants,
        size: args.size,
        fps: args.fps,
        max_frames: args.max_frames,
        ..SurveyParams::default()
    };
    let stage = OneStage {
        run: &args.run,
        id: "survey".into(),
        force: true,
        remove_new_run_on_failure: false,
    }
    .run(&KIND, &params, quiet)?;
    let s: SurveySummary = summary(&stage, "survey")?;
    let total: u64 = s.items.values().sum();
    let page = if PathBuf::from(&s.index).is_absolute() {
        PathBuf::from(&s.index)
    } else {
        args.run.join(&s.index)
    };
    println!(
        "survey {} (seed {}): {total} item(s) ({}), conditions: {}; {:.1} MB; open {} \
         (or {}#p=ID for participant ID)",
        s.survey,
        s.seed,
        s.items
            .iter()
            .map(|(e, n)| format!("{n} {e}"))
            .collect::<Vec<_>>()
            .join(", "),
        s.conditions.join(", "),
        s.bytes as f64 / 1e6,
        page.display(),
        page.display()
    );
    Ok(0)
}
