//! `annotrace evolve`: learns detectors for labels over a run's traces, as a one-stage pipeline (the
//! `evolve` stage; docs/evolution.md).
//!
//! The stage id is `evolve-<hash of its settings>`: rerunning the same command after a kill resumes the
//! search where it stopped (finished rounds are replayed, not recomputed), and rerunning it after it
//! finished prints the recorded result; `--force` starts over. Prints one line per label (seed ν → best
//! ν, accepted or not), the share of wall time spent outside the proposer and the grown library's folder.

use std::path::PathBuf;

use annotrace::fitness::{Dp, Dx};
use annotrace::llm::LlmSettings;
use annotrace::pipeline::stages::evolve::{EvolveParams, EvolveSummary, KIND, ProposerChoice};
use annotrace::search::Strategy;
use annotrace::trace::Env;

use super::llm_args::LlmArgs;
use super::one_stage::{OneStage, absolute, existing_run, params_id, summary};
use super::worker_args::WorkerArgs;
use super::{CliError, CliResult};

/// The stage's defaults, shown by `--help`.
const D: EvolveParams = EvolveParams::DEFAULT;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder holding the traces (tables are added to it).
    #[arg(long)]
    run: PathBuf,
    /// Environment whose traces are used: pooltool, phyre or iphyre.
    #[arg(long, default_value = "pooltool")]
    env: Env,
    /// Starting library folder; default: the built-in one, or ./data/libraries/<env> when present.
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
    #[arg(long, default_value_t = D.budget)]
    budget: u64,
    /// Islands I.
    #[arg(long, default_value_t = D.islands)]
    islands: u64,
    /// Parents per proposal s.
    #[arg(long, default_value_t = D.prompt_size)]
    prompt_size: u64,
    /// Reset the weaker half of the islands every T_r steps (0: never).
    #[arg(long, default_value_t = D.reset_period)]
    reset_period: u64,
    /// Acceptance threshold δ on ν.
    #[arg(long, default_value_t = D.delta, allow_hyphen_values = true)]
    delta: f64,
    /// Also accept a best detector whose ρ on the held-out traces is ≤ 0 (default: never).
    #[arg(long)]
    allow_nonpositive_rho: bool,
    /// Annotation distance d_p: kl (symmetrised Kullback–Leibler), js (Jensen–Shannon) or
    /// cross-entropy (the paper's wording).
    #[arg(long, default_value_t = D.dp)]
    dp: Dp,
    /// Trace distance d_x: positions (the paper's) or invariant (each matched object's trajectory
    /// aligned by a rigid Procrustes fit first).
    #[arg(long, default_value_t = D.dx)]
    dx: Dx,
    /// Accuracy guard: also reject a best detector of an event-grounded label whose F1 against the
    /// simulator's ground truth on the held-out traces fell by more than --max-f1-drop.
    #[arg(long)]
    accuracy_guard: bool,
    /// The largest F1 drop the accuracy guard accepts.
    #[arg(long, default_value_t = D.max_f1_drop)]
    max_f1_drop: f64,
    /// Proposals requested at once.
    #[arg(long, default_value_t = D.parallel)]
    parallel: u64,
    /// 0: a round's prompts come from the database after the previous round; 1: from the one
    /// before, so the next round's requests are in flight while a round is scored (default: 1 with
    /// an LLM, 0 with mutate).
    #[arg(long, value_parser = clap::value_parser!(u64).range(0..=1))]
    lag: Option<u64>,
    /// Repair requests per failed child (proposers that repair).
    #[arg(long, default_value_t = D.repair_attempts)]
    repair_attempts: u64,
    /// Training traces at most (and held-out traces at most).
    #[arg(long, default_value_t = D.max_traces)]
    max_traces: u64,
    /// Fraction of traces held out (the acceptance test's ρ and the convergence statistics).
    #[arg(long, default_value_t = D.holdout)]
    holdout: f64,
    /// Training traces in the probe set.
    #[arg(long, default_value_t = D.probe)]
    probe: u64,
    /// Time bins b of the annotation histograms.
    #[arg(long, default_value_t = D.bins)]
    bins: u64,
    /// Normalised-time samples per trace for d_x.
    #[arg(long, default_value_t = D.samples)]
    samples: u64,
    /// Leave out the time penalty ψ (scores then do not depend on machine load: reproducible runs).
    #[arg(long)]
    no_time_penalty: bool,
    /// Detectors per 10 % bin compared on held-out traces (0: skip).
    #[arg(long, default_value_t = D.convergence_per_bin)]
    convergence_per_bin: u64,
    /// mutate proposer: edits per child at most.
    #[arg(long, default_value_t = D.max_edits)]
    max_edits: u64,
    /// Search seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Folder for the grown library (default: <run>/exports/<stage>/library).
    #[arg(long)]
    output: Option<PathBuf>,
    #[command(flatten)]
    limits: WorkerArgs,
    /// Start over instead of resuming or reusing an earlier identical search.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    llm: LlmArgs,
}

/// The LLM flags as the stage's `llm` settings (only those given; paths made absolute).
fn llm_settings(a: &LlmArgs) -> Result<Option<LlmSettings>, CliError> {
    let mut s = a.settings();
    if let Some(r) = &s.replay {
        s.replay = Some(PathBuf::from(absolute(r)?));
    }
    Ok((s != LlmSettings::default()).then_some(s))
}

pub fn run(a: Args, quiet: bool) -> CliResult {
    existing_run(&a.run)?;
    let strategy: Strategy = a
        .strategy
        .parse()
        .map_err(|e: String| CliError::input(anyhow::anyhow!("--strategy: {e}")))?;
    let proposer = match a.proposer.as_str() {
        "mutate" => ProposerChoice::Mutate,
        "llm" => ProposerChoice::Llm,
        _ => ProposerChoice::Auto,
    };
    let labels: Vec<String> = a
        .labels
        .iter()
        .map(|l| l.trim().to_string())
        .filter(|l| !l.is_empty())
        .collect();
    let params = EvolveParams {
        env: a.env,
        library: a.library.as_deref().map(absolute).transpose()?,
        labels: (!a.labels.is_empty()).then_some(labels),
        labels_from: None,
        start_empty: false,
        strategy,
        proposer,
        llm: llm_settings(&a.llm)?,
        prompts: a.llm.prompts.as_deref().map(absolute).transpose()?,
        budget: a.budget,
        islands: a.islands,
        prompt_size: a.prompt_size,
        reset_period: a.reset_period,
        delta: a.delta,
        allow_nonpositive_rho: a.allow_nonpositive_rho,
        dp: a.dp,
        dx: a.dx,
        accuracy_guard: a.accuracy_guard,
        max_f1_drop: a.max_f1_drop,
        parallel: a.parallel,
        lag: a.lag,
        repair_attempts: a.repair_attempts,
        max_traces: a.max_traces,
        holdout: a.holdout,
        probe: a.probe,
        bins: a.bins,
        samples: a.samples,
        time_penalty: !a.no_time_penalty,
        convergence_per_bin: a.convergence_per_bin,
        max_edits: a.max_edits,
        seed: Some(a.seed),
        output: a.output.as_deref().map(absolute).transpose()?,
        workers: a.limits.workers,
        timeout: a.limits.timeout,
        memory_mb: a.limits.memory_mb,
    };
    let id = params_id("evolve", &params);
    let stage = OneStage {
        run: &a.run,
        id: id.clone(),
        force: a.force,
        remove_new_run_on_failure: false,
    }
    .run(&KIND, &params, quiet)?;
    let s: EvolveSummary = summary(&stage, "evolve")?;
    println!(
        "evolve {} ({} strategy, {} proposer, d_p {}, seed {}, budget {} per label){}: {} training / {} held-out trace(s)",
        id,
        s.strategy.as_str(),
        s.proposer,
        s.dp,
        s.seed,
        s.budget,
        if stage.cached {
            " [recorded result]"
        } else {
            ""
        },
        s.train,
        s.holdout,
    );
    for l in &s.labels {
        let t = &l.best_terms;
        let held = l
            .holdout_rho
            .map_or_else(|| "–".to_string(), |x| format!("{x:.4}"));
        let f1 = l.guard.map_or(String::new(), |g| {
            format!("  (F1 {:.3} → {:.3})", g.seed_f1, g.best_f1)
        });
        println!(
            "  {:<28} ν {:>8.4} → {:>8.4}  (ρ {:.4}, η {:.4}, λ {:.4}, ψ {:.4}; held-out ρ {held})  {} candidates  {}{f1}",
            l.label,
            l.seed_nu,
            l.best_nu,
            t.rho,
            t.eta,
            t.lambda,
            t.psi,
            l.candidates,
            l.acceptance.as_str()
        );
    }
    if let Some(f) = s.proposals.failures() {
        println!("proposals: {f}");
    }
    println!(
        "wall time outside the proposer: {:.1} % (lag {})",
        100.0 * s.outside_proposer_share,
        s.lag
    );
    println!(
        "library: {} (use it with: annotrace annotate --library <that folder>)",
        s.library
    );
    Ok(0)
}
