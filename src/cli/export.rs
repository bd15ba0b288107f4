//! `annotrace export`: writes one trace of a run in the paper's JSON format.

use std::io::Write;
use std::path::PathBuf;

use annotrace::store::{AtomicFile, ReadTraceError, RunDir, read_trace};
use annotrace::trace::json::write_trace;
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
    /// Output file (written atomically); default: standard output.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Indent the JSON.
    #[arg(long)]
    pretty: bool,
}

pub fn run(args: Args) -> CliResult {
    let run = RunDir::new(&args.run);
    let trace = read_trace(&run, &args.trace).map_err(|e| match e {
        ReadTraceError::NotFound { .. } => CliError::input(e),
        other => CliError::failed(other),
    })?;
    match &args.out {
        Some(path) => {
            let mut f = AtomicFile::create(path)
                .with_context(|| format!("creating {}", path.display()))
                .map_err(CliError::failed)?;
            write_trace(&mut std::io::BufWriter::new(&mut f), &trace, args.pretty)
                .with_context(|| format!("writing {}", path.display()))
                .map_err(CliError::failed)?;
            f.write_all(b"\n")
                .map_err(|e| CliError::failed(anyhow::Error::from(e)))?;
            f.commit()
                .with_context(|| format!("writing {}", path.display()))
                .map_err(CliError::failed)?;
        }
        None => {
            let stdout = std::io::stdout();
            let mut out = std::io::BufWriter::new(stdout.lock());
            write_trace(&mut out, &trace, args.pretty)
                .map_err(|e| CliError::failed(anyhow::Error::from(std::io::Error::from(e))))?;
            writeln!(out)
                .and_then(|()| out.flush())
                .map_err(|e| CliError::failed(anyhow::Error::from(e)))?;
        }
    }
    Ok(0)
}
