//! `annotrace import`: imports paper-format JSON traces into a run, as a one-stage pipeline.
//!
//! The import is recorded in the run's manifest as stage `import-<hash of its arguments>`, so running
//! the same import again is a no-op and an interrupted one resumes.

use std::path::{Path, PathBuf};

use annotrace::digest::hex;
use annotrace::pipeline::stages::import::{ImportParams, ImportSummary, KIND};
use annotrace::query::{Format, RenderOptions, render_string};
use annotrace::trace::Env;
use arrow::array::{RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema};
use sha2::{Digest, Sha256};

use super::one_stage::{OneStage, absolute, summary};
use super::{CliError, CliResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Environment of the traces: pooltool, phyre or iphyre.
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
    /// Traces per output file (consecutive input files under 128 MiB share shards; a resumed import
    /// redoes at most the unfinished shard of each group).
    #[arg(long, default_value_t = 1000)]
    traces_per_shard: u64,
}

fn parse_env(s: &str) -> Result<Env, String> {
    s.parse()
        .map_err(|e: annotrace::trace::UnknownEnv| e.to_string())
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    let mut paths = Vec::new();
    for p in &args.paths {
        let abs = absolute(p)?;
        if !Path::new(&abs).exists() {
            return Err(CliError::input(anyhow::anyhow!(
                "{}: no such file or folder",
                p.display()
            )));
        }
        paths.push(abs);
    }
    // The id's key is kept from earlier versions, so an import into an existing run is recognised.
    let key = format!(
        "{}\n{}\n{}\n{}",
        args.env,
        paths.join("\n"),
        args.skip_invalid,
        args.traces_per_shard
    );
    let id = format!("import-{}", &hex(&Sha256::digest(key.as_bytes()))[..10]);
    let params = ImportParams {
        env: args.env,
        paths,
        skip_invalid: args.skip_invalid,
        traces_per_shard: args.traces_per_shard.max(1),
        ..ImportParams::default()
    };
    let stage = OneStage {
        run: &args.run,
        id,
        force: false,
        remove_new_run_on_failure: true,
    }
    .run(&KIND, &params, quiet)?;
    let s: ImportSummary = summary(&stage, "import")?;
    let traces = s.traces;
    let frames = stage.rows.get("frames").copied().unwrap_or(0);
    let rejected = s.rejected_count;
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
        println!("{}", rejections_table(&s.rejected));
        if rejected as usize > s.rejected.len() {
            println!(
                "(the manifest lists the first {} of them)",
                s.rejected.len()
            );
        }
        return Ok(1);
    }
    Ok(0)
}

fn rejections_table(rows: &[serde_json::Value]) -> String {
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
