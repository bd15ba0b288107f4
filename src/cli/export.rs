//! `annotrace export`: writes one trace of a run in the paper's JSON format.

use std::io::Write;
use std::path::PathBuf;

use annotrace::store::{AtomicFile, RunDir, read_trace};
use annotrace::trace::json::write_trace;

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
    let local = super::location::local_run(&args.run)?;
    let run = RunDir::new(local.path());
    let trace = read_trace(&run, &args.trace).map_err(CliError::of)?;
    match &args.out {
        Some(path) => {
            let mut f = AtomicFile::create(path).map_err(|e| CliError::io(path, e))?;
            write_trace(&mut std::io::BufWriter::new(&mut f), &trace, args.pretty)
                .map_err(|e| CliError::io(path, e.into()))?;
            f.write_all(b"\n").map_err(|e| CliError::io(path, e))?;
            f.commit().map_err(|e| CliError::io(path, e))?;
        }
        None => {
            let stdout = std::io::stdout();
            let mut out = std::io::BufWriter::new(stdout.lock());
            write_trace(&mut out, &trace, args.pretty)
                .map_err(|e| CliError::of(std::io::Error::from(e)).context("standard output"))?;
            writeln!(out)
                .and_then(|()| out.flush())
                .map_err(|e| CliError::of(e).context("standard output"))?;
        }
    }
    Ok(0)
}
