//! `annotrace query "SQL"`: runs SQL over a run's tables and prints the result.
//!
//! The SQL only reads (the library refuses `COPY`, `INSERT`, `CREATE`, `SET`…); the one way to write a
//! result is `--out FILE`, a path the user names: outside the run, or under the run's `exports/`, never
//! elsewhere in the run folder. Limits come from `--memory-limit`/`--timeout`, else from
//! `ANNOTRACE_SQL_MEMORY_LIMIT`/`ANNOTRACE_SQL_TIMEOUT` (read here), else the library's defaults; the
//! engine from `--engine`, else `ANNOTRACE_SQL_ENGINE`, else this process (`ballista://HOST:PORT` needs
//! a build with `--features ballista`).

use std::io::Write;
use std::path::PathBuf;

use annotrace::pipeline::{Categorize, ErrorCategory};
use annotrace::query::read_only::check_output_path;
use annotrace::query::settings::parse_timeout;
use annotrace::query::{
    Engine, Format, MemoryLimit, QuerySettings, RenderOptions, RunQuery, render,
};
use annotrace::store::{AtomicFile, ParquetSink, RunDir};
use anyhow::Context;

use super::{CliError, CliResult};

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
    /// Write to this file (atomically) instead of standard output: a path outside the run folder, or
    /// under its exports/ folder.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Memory the query may use (e.g. 512MiB, 8G, 25%); operators that can spill go to the temporary
    /// folder, others fail. Default: ANNOTRACE_SQL_MEMORY_LIMIT, else 4 GiB or half the machine's
    /// memory, whichever is smaller.
    #[arg(long, value_name = "SIZE")]
    memory_limit: Option<MemoryLimit>,
    /// Stop the query with an error after this many seconds. Default: ANNOTRACE_SQL_TIMEOUT, else none.
    #[arg(long, value_name = "SECS", value_parser = parse_timeout)]
    timeout: Option<std::time::Duration>,
    /// Threads (DataFusion partitions) for the query. 1, the default, gives the same result bytes on
    /// every run; more is faster on large runs, but float aggregates may then differ in the last digits
    /// and rows without ORDER BY come in varying order.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=1024))]
    threads: u16,
    /// Where the query runs: `local` (this process), `ballista://HOST:PORT` (a Ballista scheduler whose
    /// executors see the run folder at the same path) or `ballista:standalone` (an in-process Ballista
    /// cluster). Default: ANNOTRACE_SQL_ENGINE, else local. Ballista needs a build with
    /// `--features ballista`.
    #[arg(long, value_name = "ENGINE")]
    engine: Option<Engine>,
}

pub fn run(args: Args) -> CliResult {
    // A run on object storage is read through a local copy (any local --out is outside it).
    let local = super::location::local_run(&args.run)?;
    if let Some(out) = &args.out {
        check_output_path(local.path(), out).map_err(CliError::input)?;
    }
    let mut settings =
        QuerySettings::resolve(args.memory_limit, args.timeout, &|k| std::env::var(k).ok())
            .map_err(CliError::input)?;
    settings.partitions = usize::from(args.threads);
    if let Some(engine) = args.engine {
        settings.engine = engine;
    }
    // Opening reads the manifest and checks every listed file: a damaged run folder is bad input (2),
    // a failing disk an I/O error (4), as the error's category says.
    let q = RunQuery::open_with(&RunDir::new(local.path()), settings)?;
    // The query's own faults (bad or refused SQL, over its limits) are the user's: exit code 2.
    let result = q.sql(&args.sql).map_err(|e| {
        if e.is_users() {
            CliError::input(e)
        } else if e.category() == ErrorCategory::Service {
            CliError::of(e)
        } else {
            CliError::failed(e)
        }
    })?;
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
