//! `annotrace render`: draws a billiards trace of a run as a PNG (one instant, or a strip of frames).

use std::io::Write;
use std::path::PathBuf;

use annotrace::envs::pool::PoolConfig;
use annotrace::envs::pool::render::{RenderOptions, render_png, render_strip_png, strip_times};
use annotrace::store::{AtomicFile, ReadTraceError, RunDir, read_trace};
use annotrace::trace::Env;
use anyhow::Context;

use super::{CliError, CliResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder.
    #[arg(long)]
    run: PathBuf,
    /// Trace id.
    #[arg(long)]
    trace: String,
    /// Time to draw (s); the nearest timestep is shown. Default: 0 (the initial table).
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
    /// Table file the trace was simulated on; default: the built-in pooltool 7-ft table.
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
    let config = match &args.table {
        Some(p) => PoolConfig::from_file(p).map_err(CliError::input)?,
        None => PoolConfig::default_7ft(),
    };
    let run = RunDir::new(&args.run);
    let trace = read_trace(&run, &args.trace).map_err(|e| match e {
        ReadTraceError::NotFound { .. } => CliError::input(e),
        other => CliError::failed(other),
    })?;
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
    let mut f = AtomicFile::create(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))
        .map_err(CliError::failed)?;
    f.write_all(&png)
        .with_context(|| format!("writing {}", args.out.display()))
        .map_err(CliError::failed)?;
    f.commit()
        .with_context(|| format!("writing {}", args.out.display()))
        .map_err(CliError::failed)?;
    Ok(0)
}
