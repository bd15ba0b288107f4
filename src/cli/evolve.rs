//! `annotrace evolve`: learns detectors for labels over a run's traces, as a one-stage pipeline (the
//! `evolve` stage; docs/evolution.md).
//!
//! The stage id is `evolve-<hash of its settings>`: rerunning the same command after a kill resumes the
//! search where it stopped (finished rounds are replayed, not recomputed), and rerunning it after it
//! finished prints the recorded result; `--force` starts over. Prints one line per label (seed ν → best
//! ν, accepted or not), the share of wall time spent outside the proposer and the grown library's folder.

use std::path::{Path, PathBuf};

use annotrace::digest::hex;
use annotrace::pipeline::{PipelineSpec, RunOptions, run as run_pipeline};
use anyhow::Context;
use sha2::{Digest, Sha256};

use super::progress::Terminal;
use super::{CliError, CliResult, fault_from_env, run_error};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder holding the traces (tables are added to it).
    #[arg(long)]
    run: PathBuf,
    /// Environment whose traces are used.
    #[arg(long, default_value = "pooltool", value_parser = ["pooltool", "phyre", "iphyre"])]
    env: String,
    /// Starting library folder; default: data/libraries/<env>.
    #[arg(long)]
    library: Option<PathBuf>,
    /// Labels to learn, in order (comma-separated or repeated); default: the library's labels.
    #[arg(long, value_delimiter = ',')]
    labels: Vec<String>,
    /// Search strategy.
    #[arg(long, default_value = "island", value_parser = ["island", "hill-climb", "best-of-n"])]
    strategy: String,
    /// Where children come from: syntax-tree edits (mutate) or an LLM; auto = llm when an endpoint
    /// (--llm-base-url, ANNOTRACE_LLM_BASE_URL) or --replay is given, else mutate.
    #[arg(long, default_value = "auto", value_parser = ["auto", "mutate", "llm"])]
    proposer: String,
    /// Proposals per label.
    #[arg(long, default_value_t = 200)]
    budget: u64,
    /// Islands I.
    #[arg(long, default_value_t = 4)]
    islands: u64,
    /// Parents per proposal s.
    #[arg(long, default_value_t = 2)]
    prompt_size: u64,
    /// Reset the weaker half of the islands every T_r steps (0: never).
    #[arg(long, default_value_t = 100)]
    reset_period: u64,
    /// Acceptance threshold δ on ν.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    delta: f64,
    /// Proposals requested at once.
    #[arg(long, default_value_t = 4)]
    parallel: u64,
    /// Repair requests per failed child (proposers that repair).
    #[arg(long, default_value_t = 2)]
    repair_attempts: u64,
    /// Training traces at most (and held-out traces at most).
    #[arg(long, default_value_t = 100)]
    max_traces: u64,
    /// Fraction of traces held out for the convergence statistics.
    #[arg(long, default_value_t = 0.2)]
    holdout: f64,
    /// Training traces in the probe set.
    #[arg(long, default_value_t = 8)]
    probe: u64,
    /// Time bins b of the annotation histograms.
    #[arg(long, default_value_t = 10)]
    bins: u64,
    /// Normalised-time samples per trace for d_x.
    #[arg(long, default_value_t = 64)]
    samples: u64,
    /// Leave out the time penalty ψ (scores then do not depend on machine load: reproducible runs).
    #[arg(long)]
    no_time_penalty: bool,
    /// Detectors per 10 % bin compared on held-out traces (0: skip).
    #[arg(long, default_value_t = 3)]
    convergence_per_bin: u64,
    /// mutate proposer: edits per child at most.
    #[arg(long, default_value_t = 2)]
    max_edits: u64,
    /// Search seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Folder for the grown library (default: <run>/exports/<stage>/library).
    #[arg(long)]
    output: Option<PathBuf>,
    /// Python worker processes (0 = one per core).
    #[arg(long, default_value_t = 0)]
    workers: u64,
    /// Wall-clock limit of one detector call (s).
    #[arg(long, default_value_t = 10.0)]
    timeout: f64,
    /// Address-space limit of a worker (MiB).
    #[arg(long, default_value_t = 2048)]
    memory_mb: u64,
    /// Start over instead of resuming or reusing an earlier identical search.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    llm: super::suggest_labels::LlmArgs,
}

/// The LLM flags as the stage's `llm` table (only those given), and `--prompts`.
fn llm_table(a: &super::suggest_labels::LlmArgs) -> Result<toml::Table, CliError> {
    let s = a.settings();
    let mut t = toml::Table::new();
    if let Some(v) = s.base_url {
        t.insert("base_url".into(), v.into());
    }
    if let Some(v) = s.model {
        t.insert("model".into(), v.into());
    }
    if let Some(v) = s.timeout_s {
        t.insert("timeout_s".into(), toml::Value::Float(v));
    }
    if let Some(v) = s.max_retries {
        t.insert("max_retries".into(), toml::Value::Integer(i64::from(v)));
    }
    if let Some(v) = s.parallel {
        t.insert("parallel".into(), toml::Value::Integer(v as i64));
    }
    if let Some(v) = s.max_calls {
        t.insert(
            "max_calls".into(),
            toml::Value::Integer(v.min(i64::MAX as u64) as i64),
        );
    }
    if let Some(v) = s.max_tokens {
        t.insert(
            "max_tokens".into(),
            toml::Value::Integer(v.min(i64::MAX as u64) as i64),
        );
    }
    if let Some(v) = &s.replay {
        t.insert("replay".into(), abs(v)?.into());
    }
    if let Some(v) = s.strict_replay {
        t.insert("strict_replay".into(), toml::Value::Boolean(v));
    }
    Ok(t)
}

fn abs(p: &Path) -> Result<String, CliError> {
    Ok(std::path::absolute(p)
        .with_context(|| format!("resolving {}", p.display()))
        .map_err(CliError::input)?
        .to_string_lossy()
        .into_owned())
}

pub fn run(a: Args, quiet: bool) -> CliResult {
    if !a.run.is_dir() {
        return Err(CliError::input(anyhow::anyhow!(
            "{}: no such run folder",
            a.run.display()
        )));
    }
    let int = |v: u64| toml::Value::Integer(v.min(i64::MAX as u64) as i64);
    let mut stage = toml::Table::new();
    stage.insert("kind".into(), "evolve".into());
    stage.insert("env".into(), a.env.clone().into());
    if let Some(lib) = &a.library {
        stage.insert("library".into(), abs(lib)?.into());
    }
    if !a.labels.is_empty() {
        let labels: Vec<toml::Value> = a
            .labels
            .iter()
            .map(|l| l.trim().to_string())
            .filter(|l| !l.is_empty())
            .map(toml::Value::from)
            .collect();
        stage.insert("labels".into(), toml::Value::Array(labels));
    }
    stage.insert("strategy".into(), a.strategy.clone().into());
    stage.insert("proposer".into(), a.proposer.clone().into());
    for (k, v) in [
        ("budget", a.budget),
        ("islands", a.islands),
        ("prompt_size", a.prompt_size),
        ("reset_period", a.reset_period),
        ("parallel", a.parallel),
        ("repair_attempts", a.repair_attempts),
        ("max_traces", a.max_traces),
        ("probe", a.probe),
        ("bins", a.bins),
        ("samples", a.samples),
        ("convergence_per_bin", a.convergence_per_bin),
        ("max_edits", a.max_edits),
        ("seed", a.seed),
        ("workers", a.workers),
        ("memory_mb", a.memory_mb),
    ] {
        stage.insert(k.into(), int(v));
    }
    stage.insert("delta".into(), toml::Value::Float(a.delta));
    stage.insert("holdout".into(), toml::Value::Float(a.holdout));
    stage.insert("timeout".into(), toml::Value::Float(a.timeout));
    stage.insert(
        "time_penalty".into(),
        toml::Value::Boolean(!a.no_time_penalty),
    );
    if let Some(o) = &a.output {
        stage.insert("output".into(), abs(o)?.into());
    }
    let llm = llm_table(&a.llm)?;
    if !llm.is_empty() {
        stage.insert("llm".into(), toml::Value::Table(llm));
    }
    if let Some(p) = &a.llm.prompts {
        stage.insert("prompts".into(), abs(p)?.into());
    }
    let key = toml::to_string(&stage).unwrap_or_default();
    let id = format!("evolve-{}", &hex(&Sha256::digest(key.as_bytes()))[..10]);
    stage.insert("id".into(), id.clone().into());
    let mut doc = toml::Table::new();
    doc.insert(
        "stage".into(),
        toml::Value::Array(vec![toml::Value::Table(stage)]),
    );
    let text = toml::to_string(&doc)
        .map_err(|e| CliError::failed(anyhow::anyhow!("internal error: {e}")))?;
    let spec = PipelineSpec::from_toml(Path::new("annotrace-evolve.toml"), &text)
        .map_err(CliError::input)?;
    let opts = RunOptions {
        run_dir: Some(a.run.clone()),
        force: a.force.then(|| id.clone()),
        fault: fault_from_env()?,
        ..RunOptions::default()
    };
    let report = run_pipeline(&spec, &opts, &Terminal::new(quiet)).map_err(run_error)?;
    let stage = report.stages.into_iter().next().ok_or_else(|| {
        CliError::failed(anyhow::anyhow!("internal error: the stage did not run"))
    })?;
    let s = &stage.summary;
    println!(
        "evolve {} ({} strategy, {} proposer, seed {}, budget {} per label){}: {} training / {} held-out trace(s)",
        id,
        s["strategy"].as_str().unwrap_or("?"),
        s["proposer"].as_str().unwrap_or("?"),
        s["seed"],
        s["budget"],
        if stage.cached {
            " [recorded result]"
        } else {
            ""
        },
        s["train"],
        s["holdout"],
    );
    for l in s["labels"].as_array().into_iter().flatten() {
        let t = &l["best_terms"];
        println!(
            "  {:<28} ν {:>8.4} → {:>8.4}  (ρ {:.4}, η {:.4}, λ {:.4}, ψ {:.4})  {} candidates  {}",
            l["label"].as_str().unwrap_or("?"),
            l["seed_nu"].as_f64().unwrap_or(f64::NAN),
            l["best_nu"].as_f64().unwrap_or(f64::NAN),
            t["rho"].as_f64().unwrap_or(f64::NAN),
            t["eta"].as_f64().unwrap_or(f64::NAN),
            t["lambda"].as_f64().unwrap_or(f64::NAN),
            t["psi"].as_f64().unwrap_or(f64::NAN),
            l["candidates"],
            if l["accepted"].as_bool() == Some(true) {
                "accepted"
            } else {
                "rejected"
            }
        );
    }
    println!(
        "wall time outside the proposer: {:.1} %",
        100.0 * s["outside_proposer_share"].as_f64().unwrap_or(0.0)
    );
    println!(
        "library: {} (use it with: annotrace annotate --library <that folder>)",
        s["library"].as_str().unwrap_or("?")
    );
    Ok(0)
}
