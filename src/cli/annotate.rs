//! `annotrace annotate`: runs a detector library over a run's traces, as a one-stage pipeline.
//!
//! The stage is recorded in the run's manifest as `annotate-<hash of env and library path>` and always
//! reruns (the run's traces may have changed since), replacing that stage's earlier tables. Prints one
//! line per detector (label, calls by status, annotations, mean time per trace) and the sandbox layers.

use std::path::{Path, PathBuf};

use annotrace::digest::hex;
use annotrace::pipeline::{PipelineSpec, RunOptions, StageReport, run as run_pipeline};
use annotrace::query::{Format, RenderOptions, render_string};
use anyhow::Context;
use sha2::{Digest, Sha256};

use super::progress::Terminal;
use super::{CliError, CliResult, fault_from_env, open_query, run_error};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder holding the traces.
    #[arg(long)]
    run: PathBuf,
    /// Library folder (library.toml + one .py per detector); default: data/libraries/<env>.
    #[arg(long)]
    library: Option<PathBuf>,
    /// Environment whose traces are annotated.
    #[arg(long, default_value = "pooltool", value_parser = ["pooltool", "phyre", "iphyre"])]
    env: String,
    /// Python worker processes (0 = one per core).
    #[arg(long, default_value_t = 0)]
    workers: u64,
    /// Wall-clock limit of one detector call (s).
    #[arg(long, default_value_t = 10.0)]
    timeout: f64,
    /// Address-space limit of a worker (MiB).
    #[arg(long, default_value_t = 2048)]
    memory_mb: u64,
}

/// Settings shared by `annotate` and `accuracy`.
pub(crate) struct DetectArgs<'a> {
    pub run: &'a Path,
    pub library: Option<&'a Path>,
    pub env: &'a str,
    pub workers: u64,
    pub timeout: f64,
    pub memory_mb: u64,
}

/// Runs one stage of `kind` with the detector settings plus `extra` parameters; returns its report.
pub(crate) fn run_one(
    kind: &str,
    a: &DetectArgs<'_>,
    extra: toml::Table,
    quiet: bool,
) -> Result<StageReport, CliError> {
    if !a.run.is_dir() {
        return Err(CliError::input(anyhow::anyhow!(
            "{}: no such run folder",
            a.run.display()
        )));
    }
    let mut stage = toml::Table::new();
    stage.insert("kind".into(), kind.into());
    stage.insert("env".into(), a.env.into());
    if let Some(lib) = a.library {
        let abs = std::path::absolute(lib)
            .with_context(|| format!("resolving {}", lib.display()))
            .map_err(CliError::input)?;
        stage.insert("library".into(), abs.to_string_lossy().into_owned().into());
    }
    let key = format!("{kind}\u{1}{}\u{1}{:?}", a.env, stage.get("library"));
    let id = format!("{kind}-{}", &hex(&Sha256::digest(key.as_bytes()))[..10]);
    stage.insert("id".into(), id.clone().into());
    stage.insert("workers".into(), toml::Value::Integer(a.workers as i64));
    stage.insert("timeout".into(), toml::Value::Float(a.timeout));
    stage.insert("memory_mb".into(), toml::Value::Integer(a.memory_mb as i64));
    stage.extend(extra);
    let mut doc = toml::Table::new();
    doc.insert(
        "stage".into(),
        toml::Value::Array(vec![toml::Value::Table(stage)]),
    );
    let text = toml::to_string(&doc)
        .map_err(|e| CliError::failed(anyhow::anyhow!("internal error: {e}")))?;
    let spec = PipelineSpec::from_toml(Path::new(&format!("annotrace-{kind}.toml")), &text)
        .map_err(CliError::input)?;
    let opts = RunOptions {
        run_dir: Some(a.run.to_path_buf()),
        force: Some(id),
        fault: fault_from_env()?,
        ..RunOptions::default()
    };
    let report = run_pipeline(&spec, &opts, &Terminal::new(quiet)).map_err(run_error)?;
    report
        .stages
        .into_iter()
        .next()
        .ok_or_else(|| CliError::failed(anyhow::anyhow!("internal error: the stage did not run")))
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    let a = DetectArgs {
        run: &args.run,
        library: args.library.as_deref(),
        env: &args.env,
        workers: args.workers,
        timeout: args.timeout,
        memory_mb: args.memory_mb,
    };
    let stage = run_one("annotate", &a, toml::Table::new(), quiet)?;
    let s = &stage.summary;
    println!(
        "annotated {} {} trace(s) with {} detector(s) of {}: {} annotation(s); calls: {}",
        s["traces"],
        args.env,
        s["detectors"],
        s["library"].as_str().unwrap_or("?"),
        s["annotations"],
        s["statuses"]
            .as_object()
            .map(|m| m
                .iter()
                .map(|(k, v)| format!("{v} {k}"))
                .collect::<Vec<_>>()
                .join(", "))
            .unwrap_or_default()
    );
    if let Some(layers) = s.get("sandbox").filter(|l| !l.is_null()) {
        println!(
            "sandbox: landlock {}, seccomp {}, python guard {}, Python {}",
            layers["landlock"].as_str().unwrap_or("?"),
            layers["seccomp"].as_str().unwrap_or("?"),
            layers["python_guard"],
            layers["python"].as_str().unwrap_or("?"),
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
    let result = q.sql(&sql).map_err(CliError::failed)?;
    print!(
        "{}",
        render_string(
            &result.schema,
            &result.batches,
            Format::Table,
            &RenderOptions::default()
        )
    );
    let failed: u64 = s["statuses"]
        .as_object()
        .into_iter()
        .flatten()
        .filter(|(k, _)| k.as_str() != "ok")
        .map(|(_, v)| v.as_u64().unwrap_or(0))
        .sum();
    Ok(u8::from(failed > 0))
}
