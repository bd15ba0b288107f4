//! `annotrace annotate`: runs a detector library over a run's traces, as a one-stage pipeline.
//!
//! The stage is recorded in the run's manifest as `annotate-<hash of env and library path>` and always
//! reruns (the run's traces may have changed since), replacing that stage's earlier tables. Prints one
//! line per detector (label, calls by status, annotations, mean time per trace) and the sandbox layers.

use std::path::PathBuf;

use annotrace::digest::hex;
use annotrace::pipeline::stages::annotate::{AnnotateSummary, KIND};
use annotrace::pipeline::stages::detector_setup::SandboxParams;
use annotrace::query::{Format, RenderOptions, render_string};
use annotrace::trace::Env;
use sha2::{Digest, Sha256};

use super::one_stage::{OneStage, absolute, existing_run, summary};
use super::worker_args::WorkerArgs;
use super::{CliError, CliResult, open_query};

/// The flags of the commands that run detectors (`annotate`, `accuracy`).
#[derive(clap::Args, Debug)]
pub(crate) struct SandboxArgs {
    /// Run folder holding the traces.
    #[arg(long)]
    pub run: PathBuf,
    /// Library folder (library.toml + one .py per detector); default: the built-in one, or
    /// ./data/libraries/<env> when present.
    #[arg(long)]
    pub library: Option<PathBuf>,
    /// Environment of the traces: pooltool, phyre or iphyre.
    #[arg(long, default_value = "pooltool")]
    pub env: Env,
    #[command(flatten)]
    pub limits: WorkerArgs,
}

impl SandboxArgs {
    /// The stage's sandbox parameters.
    pub(crate) fn params(&self) -> Result<SandboxParams, CliError> {
        Ok(SandboxParams {
            env: self.env,
            library: self.library.as_deref().map(absolute).transpose()?,
            workers: self.limits.workers,
            timeout: self.limits.timeout,
            memory_mb: self.limits.memory_mb,
        })
    }

    /// The stage's one-stage runner: recorded as `<kind>-<hash of env and library>` and always rerun
    /// (the run's traces may have changed since), replacing that stage's earlier tables.
    pub(crate) fn one_stage(
        &self,
        kind: &str,
        p: &SandboxParams,
    ) -> Result<OneStage<'_>, CliError> {
        existing_run(&self.run)?;
        // The key is kept from earlier versions (the library as TOML's debug form), so reruns replace
        // the same stage of runs made before.
        let library = match &p.library {
            Some(l) => format!("Some(String({l:?}))"),
            None => "None".to_string(),
        };
        let key = format!("{kind}\u{1}{}\u{1}{library}", p.env);
        Ok(OneStage {
            run: &self.run,
            id: format!("{kind}-{}", &hex(&Sha256::digest(key.as_bytes()))[..10]),
            force: true,
            remove_new_run_on_failure: false,
        })
    }
}

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    sandbox: SandboxArgs,
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    let args = args.sandbox;
    let params = args.params()?;
    let stage = args
        .one_stage("annotate", &params)?
        .run(&KIND, &params, quiet)?;
    let s: AnnotateSummary = summary(&stage, "annotate")?;
    println!(
        "annotated {} {} trace(s) with {} detector(s) of {}: {} annotation(s); calls: {}",
        s.traces,
        args.env,
        s.detectors,
        s.library,
        s.annotations,
        s.statuses
            .iter()
            .map(|(k, v)| format!("{v} {k}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    if let Some(layers) = &s.sandbox {
        println!(
            "sandbox: landlock {}, seccomp {}, python guard {}, Python {}",
            layers.landlock, layers.seccomp, layers.python_guard, layers.python,
        );
    }
    // Per-detector breakdown from the tables just written.
    let q = open_query(&args.run)?;
    let sql = format!(
        "SELECT c.label, count(*) AS calls, sum(CASE WHEN c.status = 'ok' THEN 1 ELSE 0 END) AS ok, \
         sum(c.n_patterns) AS annotations, round(avg(c.wall_s) * 1000, 3) AS mean_ms \
         FROM detector_calls c WHERE c.env = '{}' GROUP BY c.label ORDER BY c.label",
        args.env
    );
    let result = q.sql(&sql)?;
    print!(
        "{}",
        render_string(
            &result.schema,
            &result.batches,
            Format::Table,
            &RenderOptions::default()
        )
    );
    let failed = s.failed_calls();
    Ok(u8::from(failed > 0))
}
