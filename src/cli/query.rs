//! `annotrace query "SQL"`: runs SQL over a run's tables and prints the result.

use std::io::Write;
use std::path::PathBuf;

use annotrace::query::{Format, RenderOptions, render};
use annotrace::store::{AtomicFile, ParquetSink};
use anyhow::Context;

use super::{CliError, CliResult, open_query};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// One SQL statement (DataFusion dialect). Tables: scenes, traces, timesteps, frames, events and any
    /// table written by a stage.
    sql: String,
    /// Run folder.
    #[arg(long)]
    run: PathBuf,
    /// Output format: table, csv, json, ndjson, markdown, latex (parquet with --out).
    #[arg(long, default_value = "table")]
    format: Format,
    /// Decimals for floats in table, markdown and latex output (csv and json keep full precision).
    #[arg(long, default_value_t = 4)]
    precision: usize,
    /// Write to this file (atomically) instead of standard output.
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run(args: Args) -> CliResult {
    let q = open_query(&args.run)?;
    // SQL mistakes are the user's: DataFusion's message is shown as is, exit code 2.
    let result = q.sql(&args.sql).map_err(CliError::input)?;
    let opts = RenderOptions {
        precision: Some(args.precision),
        title: None,
    };
    match (&args.out, args.format) {
        (Some(path), Format::Parquet) => {
            let mut sink =
                ParquetSink::create(path, result.schema.clone()).map_err(CliError::failed)?;
            for b in &result.batches {
                sink.write(b).map_err(CliError::failed)?;
            }
            sink.commit().map_err(CliError::failed)?;
        }
        (None, Format::Parquet) => {
            return Err(CliError::input(anyhow::anyhow!(
                "--format parquet needs --out FILE"
            )));
        }
        (Some(path), format) => {
            let mut f = AtomicFile::create(path)
                .with_context(|| format!("creating {}", path.display()))
                .map_err(CliError::failed)?;
            let mut buf = std::io::BufWriter::new(&mut f);
            render(&mut buf, &result.schema, &result.batches, format, &opts)
                .map_err(|e| CliError::failed(anyhow::Error::from(e)))?;
            buf.flush()
                .map_err(|e| CliError::failed(anyhow::Error::from(e)))?;
            drop(buf);
            f.commit()
                .with_context(|| format!("writing {}", path.display()))
                .map_err(CliError::failed)?;
        }
        (None, format) => {
            let stdout = std::io::stdout();
            let mut out = std::io::BufWriter::new(stdout.lock());
            render(&mut out, &result.schema, &result.batches, format, &opts)
                .and_then(|()| out.flush())
                .map_err(|e| CliError::failed(anyhow::Error::from(e)))?;
        }
    }
    Ok(0)
}
