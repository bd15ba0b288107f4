//! `annotrace ensemble`: builds an ensemble library from the candidates of evolve stages (of this run
//! and of other run folders), as a one-stage pipeline (the `ensemble` stage; docs/ensemble.md).
//!
//! The stage id is `ensemble-<hash of its settings>`: rerunning the same command after a kill resumes
//! at the first unfinished label, and rerunning it after it finished prints the recorded result;
//! `--force` starts over.

use std::path::PathBuf;

use annotrace::pipeline::stages::ensemble::{EnsembleParams, EnsembleSummary, KIND};
use annotrace::trace::Env;

use super::one_stage::{OneStage, absolute, existing_run, params_id, summary};
use super::worker_args::WorkerArgs;
use super::{CliError, CliResult};

/// The stage's defaults, shown by `--help`.
const D: EnsembleParams = EnsembleParams::DEFAULT;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder holding the traces and the evolve stages' candidates (tables are added to it).
    #[arg(long)]
    run: PathBuf,
    /// Environment: pooltool, phyre or iphyre.
    #[arg(long, default_value = "pooltool")]
    env: Env,
    /// Evolve stages of the run to pool (comma-separated or repeated); default: every stage.
    #[arg(long, value_delimiter = ',')]
    evolve: Vec<String>,
    /// Other run folders whose candidates are pooled too (comma-separated or repeated).
    #[arg(long, value_delimiter = ',')]
    runs: Vec<PathBuf>,
    /// Labels to build (comma-separated or repeated); default: every label with a valid candidate.
    #[arg(long, value_delimiter = ',')]
    labels: Vec<String>,
    /// Candidates per label at most (the best by ν).
    #[arg(long, default_value_t = D.max_per_label)]
    max_per_label: u64,
    /// A fixed K per label (default: chosen by silhouette).
    #[arg(long)]
    k: Option<u64>,
    /// Largest K the silhouette rule tries.
    #[arg(long, default_value_t = D.k_max)]
    k_max: u64,
    /// Below this best mean silhouette, K = 1.
    #[arg(long, default_value_t = D.min_silhouette)]
    min_silhouette: f64,
    /// Traces of the fixed signature set.
    #[arg(long, default_value_t = D.signature_traces)]
    signature_traces: u64,
    /// Calibration traces at most.
    #[arg(long, default_value_t = D.calibration_traces)]
    calibration_traces: u64,
    /// Fraction of the run's traces kept for the test scores.
    #[arg(long, default_value_t = D.test_fraction)]
    test_fraction: f64,
    /// Test traces at most.
    #[arg(long, default_value_t = D.test_traces)]
    test_traces: u64,
    /// Starting activation threshold γ in [0, 1).
    #[arg(long, default_value_t = D.gamma)]
    gamma: f64,
    /// Starting spatial tolerance ε_s (environment's NEARBY_AT unit; default: the paper's).
    #[arg(long)]
    eps_s: Option<f64>,
    /// Starting temporal tolerance ε_t in timesteps (default: the paper's).
    #[arg(long)]
    eps_t: Option<f64>,
    /// Calibration (a): sweep points per label.
    #[arg(long, default_value_t = D.sweep_points)]
    sweep_points: u64,
    /// Calibration (b): Bayesian-optimisation steps (0: skip).
    #[arg(long, default_value_t = D.bo_iterations)]
    bo_iterations: u64,
    /// Baseline library folder for the comparison (default: the built-in one).
    #[arg(long)]
    baseline: Option<PathBuf>,
    /// Folder of the ensemble library (default: <run>/exports/<stage>/library; -SP beside it).
    #[arg(long)]
    output: Option<PathBuf>,
    /// Seed of the split, K-means and calibration.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    limits: WorkerArgs,
    /// Start over even if the same settings finished before.
    #[arg(long)]
    force: bool,
}

fn list(v: &[String]) -> Option<Vec<String>> {
    let v: Vec<String> = v
        .iter()
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect();
    (!v.is_empty()).then_some(v)
}

pub fn run(a: Args, quiet: bool) -> CliResult {
    existing_run(&a.run)?;
    let params = EnsembleParams {
        env: a.env,
        evolve: list(&a.evolve),
        runs: a
            .runs
            .iter()
            .map(|r| absolute(r))
            .collect::<Result<Vec<_>, CliError>>()?,
        labels: list(&a.labels),
        max_per_label: a.max_per_label,
        k: a.k,
        k_max: a.k_max,
        min_silhouette: a.min_silhouette,
        signature_traces: a.signature_traces,
        calibration_traces: a.calibration_traces,
        test_fraction: a.test_fraction,
        test_traces: a.test_traces,
        gamma: a.gamma,
        eps_s: a.eps_s,
        eps_t: a.eps_t,
        sweep_points: a.sweep_points,
        bo_iterations: a.bo_iterations,
        baseline: a.baseline.as_deref().map(absolute).transpose()?,
        output: a.output.as_deref().map(absolute).transpose()?,
        seed: Some(a.seed),
        workers: a.limits.workers,
        timeout: a.limits.timeout,
        memory_mb: a.limits.memory_mb,
        ..EnsembleParams::DEFAULT
    };
    let id = params_id("ensemble", &params);
    let stage = OneStage {
        run: &a.run,
        id: id.clone(),
        force: a.force,
        remove_new_run_on_failure: false,
    }
    .run(&KIND, &params, quiet)?;
    let s: EnsembleSummary = summary(&stage, "ensemble")?;
    println!(
        "ensemble {id} ({} source(s), seed {}){}: {} signature / {} calibration / {} test trace(s)",
        s.sources.len(),
        s.seed,
        if stage.cached {
            " [recorded result]"
        } else {
            ""
        },
        s.traces.0,
        s.traces.1,
        s.traces.2
    );
    for l in &s.labels {
        println!(
            "  {:<28} {} pooled, K = {} ({}), γ {:.3}, ε_s {:.5}, ε_t {}, weights {:?}",
            l.label, l.pooled, l.k, l.k_rule, l.gamma, l.eps_s, l.eps_t, l.weights
        );
    }
    println!(
        "calibration objective: {} ({})",
        s.objective, s.objective_note
    );
    for (v, r) in &s.test_rho {
        println!("test ρ {v}: {r:.4}");
    }
    println!("library: {} (-SP: {})", s.library, s.sp_library);
    Ok(0)
}
