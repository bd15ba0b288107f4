//! `annotrace render`: draws a trace of a run as a PNG (one instant, or a strip of frames): billiards
//! traces on the table, I-PHYRE traces on their 600×600 screen (`--indices` numbers the eliminable
//! blocks as DeepPHY shows them), PHYRE traces on their 256×256 scene in PHYRE's palette (`--grid` adds
//! DeepPHY's numbered 8×8 grid). `--env iphyre --game NAME` and `--task ID` (PHYRE) draw a game's or a
//! task's initial scene without a run.

use std::io::Write;
use std::path::PathBuf;

use annotrace::envs::iphyre::Games as IphyreGames;
use annotrace::envs::iphyre::render::{
    self as iphyre_render, RenderOptions as IphyreRenderOptions, render_scene_png,
};
use annotrace::envs::phyre::TaskSet as PhyreTasks;
use annotrace::envs::phyre::render::{self as phyre_render, RenderOptions as PhyreRenderOptions};
use annotrace::envs::pool::PoolConfig;
use annotrace::envs::pool::render::{RenderOptions, render_png, render_strip_png, strip_times};
use annotrace::store::{AtomicFile, RunDir, read_trace};
use annotrace::trace::Env;

use super::{CliError, CliResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder.
    #[arg(long, required_unless_present_any = ["game", "task"])]
    run: Option<PathBuf>,
    /// Trace id.
    #[arg(long, required_unless_present_any = ["game", "task"])]
    trace: Option<String>,
    /// With --game: the environment whose game to draw (only iphyre has built-in games).
    #[arg(long, value_parser = ["iphyre"], requires = "game")]
    env: Option<String>,
    /// I-PHYRE: draw this game's initial scene (no run needed), e.g. `support`.
    #[arg(long, conflicts_with_all = ["run", "trace", "frames", "t"])]
    game: Option<String>,
    /// I-PHYRE: number the eliminable blocks 0…k−1 (the action indices DeepPHY shows a VLM).
    #[arg(long)]
    indices: bool,
    /// PHYRE: draw this task's initial scene (no run needed), e.g. `00004:063`.
    #[arg(long, conflicts_with_all = ["run", "trace", "frames", "t", "game"])]
    task: Option<String>,
    /// PHYRE: draw DeepPHY's 8×8 grid with cells numbered 1–64 from the top-left.
    #[arg(long)]
    grid: bool,
    /// Time to draw (s); the nearest timestep is shown. Default: 0 (the initial state).
    #[arg(long, conflicts_with = "frames")]
    t: Option<f64>,
    /// Draw K frames evenly spread over the trace, side by side.
    #[arg(long)]
    frames: Option<usize>,
    /// Output PNG file (written atomically).
    #[arg(long)]
    out: PathBuf,
    /// Width and height of one frame in pixels.
    #[arg(long, default_value_t = 512)]
    size: u32,
    /// pooltool: table file the trace was simulated on; default: the built-in 7-ft table.
    #[arg(long)]
    table: Option<PathBuf>,
}

pub fn run(args: Args) -> CliResult {
    if !(64..=4096).contains(&args.size) {
        return Err(CliError::input(anyhow::anyhow!(
            "--size must be within 64..=4096 pixels, found {}",
            args.size
        )));
    }
    if args.frames == Some(0) {
        return Err(CliError::input(anyhow::anyhow!(
            "--frames must be at least 1"
        )));
    }
    if let Some(t) = args.t
        && !t.is_finite()
    {
        return Err(CliError::input(anyhow::anyhow!(
            "--t must be a finite number of seconds"
        )));
    }
    if let Some(name) = &args.game {
        let games = IphyreGames::default_games().map_err(CliError::failed)?;
        let game = games.get(name).map_err(CliError::input)?;
        let opts = IphyreRenderOptions {
            size: args.size,
            block_indices: args.indices,
            time_label: false,
        };
        let png = render_scene_png(game, &opts).map_err(CliError::input)?;
        return write_png(&args.out, &png);
    }
    let phyre_opts = PhyreRenderOptions {
        size: args.size,
        grid: args.grid,
    };
    if let Some(id) = &args.task {
        let tasks = PhyreTasks::default_tasks().map_err(CliError::failed)?;
        let task = tasks.get(id).map_err(CliError::input)?;
        let png = phyre_render::render_task_png(&task, &phyre_opts).map_err(CliError::input)?;
        return write_png(&args.out, &png);
    }
    let (Some(run_dir), Some(trace_id)) = (&args.run, &args.trace) else {
        return Err(CliError::input(anyhow::anyhow!(
            "--run and --trace are needed (or --env iphyre --game NAME for a game's initial scene)"
        )));
    };
    let config = match &args.table {
        Some(p) => PoolConfig::from_file(p).map_err(CliError::input)?,
        None => PoolConfig::default_7ft(),
    };
    let run = RunDir::new(run_dir);
    let trace = read_trace(&run, trace_id).map_err(CliError::of)?;
    if trace.env == Env::Iphyre {
        let games = IphyreGames::default_games().map_err(CliError::failed)?;
        let game = games.get(&trace.task_id).ok();
        let opts = IphyreRenderOptions {
            size: args.size,
            block_indices: args.indices,
            time_label: true,
        };
        let png = match args.frames {
            Some(k) => {
                iphyre_render::render_strip_png(&trace, game, &strip_times(&trace, k), &opts)
            }
            None => iphyre_render::render_png(&trace, game, args.t.unwrap_or(0.0), &opts),
        }
        .map_err(CliError::input)?;
        return write_png(&args.out, &png);
    }
    if trace.env == Env::Phyre {
        let tasks = PhyreTasks::default_tasks().map_err(CliError::failed)?;
        let task = tasks.get(&trace.task_id).map_err(|e| {
            CliError::input(anyhow::anyhow!(
                "trace {}: cannot draw its scene: {e}",
                trace.trace_id
            ))
        })?;
        let png = match args.frames {
            Some(k) => {
                phyre_render::render_strip_png(&trace, &task, &strip_times(&trace, k), &phyre_opts)
            }
            None => phyre_render::render_png(&trace, &task, args.t.unwrap_or(0.0), &phyre_opts),
        }
        .map_err(CliError::input)?;
        return write_png(&args.out, &png);
    }
    if trace.env != Env::Pooltool {
        return Err(CliError::input(anyhow::anyhow!(
            "trace {} is a {} trace; only pooltool traces can be rendered so far",
            trace.trace_id,
            trace.env
        )));
    }
    let opts = RenderOptions { size: args.size };
    let png = match args.frames {
        Some(k) => render_strip_png(&trace, &config, &strip_times(&trace, k), &opts),
        None => render_png(&trace, &config, args.t.unwrap_or(0.0), &opts),
    }
    .map_err(CliError::input)?;
    write_png(&args.out, &png)
}

/// Writes `png` to `out` atomically.
fn write_png(out: &std::path::Path, png: &[u8]) -> CliResult {
    let mut f = AtomicFile::create(out).map_err(|e| CliError::io(out, e))?;
    f.write_all(png).map_err(|e| CliError::io(out, e))?;
    f.commit().map_err(|e| CliError::io(out, e))?;
    Ok(0)
}
