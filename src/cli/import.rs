//! `annotrace import`: imports paper-format JSON traces into a run, as a one-stage pipeline.
//!
//! The import is recorded in the run's manifest as stage `import-<hash of its arguments>`, so running
//! the same import again is a no-op and an interrupted one resumes.

use std::path::PathBuf;

use annotrace::digest::hex;
use annotrace::pipeline::{PipelineSpec, RunOptions, run as run_pipeline};
use annotrace::query::{Format, RenderOptions, render_string};
use annotrace::trace::Env;
use anyhow::Context;
use arrow::array::{RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema};
use serde::Serialize;
use sha2::{Digest, Sha256};

use super::progress::Terminal;
use super::{CliError, CliResult, fault_from_env, run_error};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Environment of the traces.
    #[arg(long, value_parser = parse_env)]
    env: Env,
    /// JSON files (one trace or an array), JSON Lines files (.jsonl) or folders of them.
    #[arg(required = true)]
    paths: Vec<PathBuf>,
    /// Run folder to import into (created if needed).
    #[arg(long)]
    run: PathBuf,
    /// Import the valid traces and print a table of the invalid ones (exit code 1 if any).
    #[arg(long)]
    skip_invalid: bool,
    /// Traces per output file (a resumed import redoes at most one shard per input file).
    #[arg(long, default_value_t = 1000)]
    traces_per_shard: u64,
}

fn parse_env(s: &str) -> Result<Env, String> {
    s.parse()
        .map_err(|e: annotrace::trace::UnknownEnv| e.to_string())
}

#[derive(Serialize)]
struct OneStage {
    stage: Vec<ImportStage>,
}

#[derive(Serialize)]
struct ImportStage {
    id: String,
    kind: &'static str,
    env: String,
    paths: Vec<String>,
    skip_invalid: bool,
    traces_per_shard: u64,
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    let mut paths = Vec::new();
    for p in &args.paths {
        let abs = std::path::absolute(p)
            .with_context(|| format!("resolving {}", p.display()))
            .map_err(CliError::input)?;
        if !abs.exists() {
            return Err(CliError::input(anyhow::anyhow!(
                "{}: no such file or folder",
                p.display()
            )));
        }
        paths.push(abs.to_string_lossy().into_owned());
    }
    let key = format!(
        "{}\n{}\n{}\n{}",
        args.env,
        paths.join("\n"),
        args.skip_invalid,
        args.traces_per_shard
    );
    let id = format!("import-{}", &hex(&Sha256::digest(key.as_bytes()))[..10]);
    let pipeline = OneStage {
        stage: vec![ImportStage {
            id: id.clone(),
            kind: "import",
            env: args.env.to_string(),
            paths,
            skip_invalid: args.skip_invalid,
            traces_per_shard: args.traces_per_shard.max(1),
        }],
    };
    let text = toml::to_string(&pipeline)
        .map_err(|e| CliError::failed(anyhow::anyhow!("internal error: {e}")))?;
    let spec = PipelineSpec::from_toml(std::path::Path::new("annotrace-import.toml"), &text)
        .map_err(CliError::input)?;
    let opts = RunOptions {
        run_dir: Some(args.run.clone()),
        fault: fault_from_env()?,
        remove_new_run_on_failure: true,
        ..RunOptions::default()
    };
    let report = run_pipeline(&spec, &opts, &Terminal::new(quiet)).map_err(run_error)?;
    let stage = report.stages.first().ok_or_else(|| {
        CliError::failed(anyhow::anyhow!("internal error: the import did not run"))
    })?;
    let summary = &stage.summary;
    let traces = summary["traces"].as_u64().unwrap_or(0);
    let frames = stage.rows.get("frames").copied().unwrap_or(0);
    let rejected = summary["rejected_count"].as_u64().unwrap_or(0);
    println!(
        "{} {traces} {} trace(s) ({frames} frame rows) into {}{}",
        if stage.cached {
            "already imported:"
        } else {
            "imported"
        },
        args.env,
        args.run.display(),
        if stage.cached { " (nothing to do)" } else { "" }
    );
    if rejected > 0 {
        println!("{rejected} invalid trace(s) skipped:");
        println!("{}", rejections_table(&summary["rejected"]));
        if rejected as usize > summary["rejected"].as_array().map_or(0, Vec::len) {
            println!(
                "(the manifest lists the first {} of them)",
                summary["rejected"].as_array().map_or(0, Vec::len)
            );
        }
        return Ok(1);
    }
    Ok(0)
}

fn rejections_table(rows: &serde_json::Value) -> String {
    let rows = rows.as_array().cloned().unwrap_or_default();
    let col = |f: &dyn Fn(&serde_json::Value) -> String| -> StringArray {
        rows.iter().map(|r| Some(f(r))).collect()
    };
    let schema = std::sync::Arc::new(Schema::new(
        ["where", "task_id", "json_path", "kind", "message"]
            .map(|n| Field::new(n, DataType::Utf8, true))
            .to_vec(),
    ));
    let batch = RecordBatch::try_new(
        schema.clone(),
        vec![
            std::sync::Arc::new(col(&|r| match r["line"].as_u64() {
                Some(line) => format!("{}:{line}", r["file"].as_str().unwrap_or("")),
                None => format!("{} #{}", r["file"].as_str().unwrap_or(""), r["trace"]),
            })),
            std::sync::Arc::new(col(&|r| r["task_id"].as_str().unwrap_or("").to_string())),
            std::sync::Arc::new(col(&|r| r["path"].as_str().unwrap_or("").to_string())),
            std::sync::Arc::new(col(&|r| r["kind"].as_str().unwrap_or("").to_string())),
            std::sync::Arc::new(col(&|r| r["message"].as_str().unwrap_or("").to_string())),
        ],
    )
    .expect("columns match the schema");
    render_string(&schema, &[batch], Format::Table, &RenderOptions::default())
}
