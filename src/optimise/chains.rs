//! A batch of annealing chains (goal × scene × seed × reward type × budget) advanced in lockstep over
//! any [`Problem`]: each step simulates every live chain's proposal in parallel, annotates the dense
//! chains' traces in one call to the detector runtime per goal (only the detectors the goal's program
//! uses), scores them, and verifies every sample with the goal's hand-written rule. A sparse chain's
//! billiards sample is checked on its columns ([`Simulated`]): its `Trace` is never built.
//!
//! Each chain has its own budget (its schedule cools over exactly that many samples) and stops when it
//! is spent. Its best-so-far sample is recorded when it ends and, with `checkpoint`, every `checkpoint`
//! samples on the way, with whether that sample verifies. The paper's budget axis is independent chains
//! of budgets 50, 100, …, 1000 (one row each); the checkpoints of one long chain are the cheaper
//! approximation (its early checkpoints come from a chain still running hot).

use std::time::Instant;

use rayon::prelude::*;
use serde_json::Value;

use super::OptimiseError;
use super::anneal::{Annealer, Schedule};
use super::problem::{Problem, Simulated};
use crate::detect::{Annotation, Detector, WorkerPool};
use crate::reward::annotate::annotate;
use crate::reward::verify::Rule;
use crate::reward::{AnnotatedTrace, Program, evaluate};
use crate::trace::Trace;

/// Which reward drives a chain.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum RewardKind {
    /// The goal's reward program on the annotated trace (dense, in [0, 1]).
    Dense,
    /// The goal's verification rule (1 when it holds, else 0).
    Sparse,
}

impl RewardKind {
    /// `dense` or `sparse`.
    pub fn as_str(self) -> &'static str {
        match self {
            RewardKind::Dense => "dense",
            RewardKind::Sparse => "sparse",
        }
    }
}

/// A goal ready to optimise.
#[derive(Debug, Clone)]
pub struct GoalTask {
    /// Goal id.
    pub id: String,
    /// The checked reward program.
    pub program: Program,
    /// The verification rule.
    pub rule: Rule,
    /// The detectors the program needs.
    pub detectors: Vec<Detector>,
}

/// One chain: which goal, scene, seed, reward and budget.
#[derive(Debug, Clone)]
pub struct Chain<S> {
    /// Index into the goals.
    pub goal: usize,
    /// The scene.
    pub scene: S,
    /// The chain's seed.
    pub seed: u64,
    /// The reward.
    pub kind: RewardKind,
    /// Samples of this chain (its schedule cools over exactly these).
    pub budget: usize,
}

/// Settings of a batch of chains.
#[derive(Debug, Clone)]
pub struct Settings<P> {
    /// What is searched.
    pub problem: P,
    /// The annealing schedule (its `budget` is replaced by each chain's).
    pub schedule: Schedule,
    /// Also record the best-so-far every this many samples (besides at each chain's end).
    pub checkpoint: Option<usize>,
}

/// The best-so-far of one chain at one checkpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckpointRow {
    /// Goal id.
    pub goal: String,
    /// Scene id.
    pub scene: String,
    /// Chain seed.
    pub seed: u64,
    /// Reward type.
    pub kind: RewardKind,
    /// Samples spent.
    pub budget: usize,
    /// The chain's whole budget (equal to `budget` for its last row).
    pub chain_budget: usize,
    /// Reward of the best sample so far.
    pub best_reward: f64,
    /// Whether the best sample's shot meets the verification rule.
    pub success: bool,
    /// Which sample (1-based) it was.
    pub best_sample: usize,
    /// Its action (the environment's action JSON).
    pub action: Value,
    /// Its point of the search box.
    pub point: Vec<f64>,
}

/// Where the time of a batch went (seconds, summed over steps).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Timings {
    /// Samples evaluated (chains × steps).
    pub samples: u64,
    /// Dense samples (annotated).
    pub dense_samples: u64,
    /// Simulating and converting to traces.
    pub simulate_s: f64,
    /// Running the detectors.
    pub annotate_s: f64,
    /// Evaluating reward programs and verification rules.
    pub score_s: f64,
    /// Simulations that failed (scored 0).
    pub failed_simulations: u64,
    /// Detector calls that failed.
    pub failed_calls: u64,
    /// Reward programs that raised a runtime error (scored 0).
    pub program_errors: u64,
    /// Samples whose action the environment refused (a PHYRE ball overlapping an object or
    /// crossing the border: `INVALID_INPUT`). They score 0 under both rewards and are never
    /// annotated or scored by the program.
    pub invalid_actions: u64,
}

/// Whether the environment refused the action of `trace` (PHYRE's `INVALID_INPUT`): the trace holds
/// the scene without the user's ball, so no reward program or rule is asked about it.
pub fn invalid_action(trace: &Trace) -> bool {
    refused(&trace.outcome)
}

fn refused(outcome: &crate::trace::Outcome) -> bool {
    outcome.terminal_status == "INVALID_INPUT"
}

struct State {
    annealer: Annealer,
    best_success: bool,
    best_x: Vec<f64>,
}

/// Runs every chain for its budget; `on_step` is called after each step with the number of steps
/// done (the largest budget in all). Needs `pool` when any chain is dense.
pub fn run_chains<P: Problem>(
    settings: &Settings<P>,
    goals: &[GoalTask],
    chains: &[Chain<P::Scene>],
    pool: Option<&WorkerPool>,
    mut on_step: impl FnMut(usize),
) -> Result<(Vec<CheckpointRow>, Timings), OptimiseError> {
    if chains.iter().any(|c| c.goal >= goals.len()) {
        return Err(OptimiseError::Internal(
            "a chain names a goal that does not exist",
        ));
    }
    if pool.is_none() && chains.iter().any(|c| c.kind == RewardKind::Dense) {
        return Err(OptimiseError::Internal(
            "dense chains need a detector worker pool",
        ));
    }
    let problem = &settings.problem;
    let mut states: Vec<State> = chains
        .iter()
        .map(|c| State {
            annealer: Annealer::new(
                problem.dims(&c.scene),
                Schedule {
                    budget: c.budget,
                    ..settings.schedule
                },
                c.seed,
            ),
            best_success: false,
            best_x: Vec::new(),
        })
        .collect();
    let mut rows = Vec::new();
    let mut timings = Timings::default();
    let steps = chains.iter().map(|c| c.budget).max().unwrap_or(0);
    for step in 0..steps {
        let live: Vec<bool> = chains.iter().map(|c| step < c.budget).collect();
        let xs: Vec<Option<Vec<f64>>> = states
            .iter_mut()
            .zip(&live)
            .map(|(s, &l)| l.then(|| s.annealer.propose()))
            .collect();
        let t0 = Instant::now();
        let mut traces = simulate_all(problem, chains, &xs, step);
        timings.simulate_s += t0.elapsed().as_secs_f64();
        let n_live = live.iter().filter(|&&l| l).count() as u64;
        timings.failed_simulations += n_live - traces.iter().flatten().count() as u64;
        timings.invalid_actions += traces
            .iter()
            .flatten()
            .filter(|t| refused(t.outcome()))
            .count() as u64;

        // Annotate the dense chains' traces, one pool call per goal.
        let t1 = Instant::now();
        let anns = match pool {
            Some(pool) => annotate_dense(pool, goals, chains, &mut traces, &mut timings),
            None => vec![Vec::new(); chains.len()],
        };
        timings.annotate_s += t1.elapsed().as_secs_f64();

        let t2 = Instant::now();
        let scored = score_all(goals, chains, &traces, &anns);
        timings.score_s += t2.elapsed().as_secs_f64();
        timings.program_errors += scored.iter().filter(|s| s.2).count() as u64;
        timings.samples += n_live;

        // Freeing a step's traces (thousands of small allocations each) on every core rather
        // than on this thread alone, between the parallel phases.
        traces.into_par_iter().for_each(drop);

        let done = step + 1;
        for (i, (x, (score, verified, _))) in xs.into_iter().zip(scored).enumerate() {
            let Some(x) = x else { continue };
            let st = &mut states[i];
            st.annealer.observe(x.clone(), score);
            if st
                .annealer
                .best()
                .is_some_and(|b| b.2 == st.annealer.samples())
            {
                st.best_success = verified;
                st.best_x = x;
            }
            let at_checkpoint = settings.checkpoint.is_some_and(|k| done % k.max(1) == 0);
            if done == chains[i].budget || at_checkpoint {
                rows.push(row(problem, goals, &chains[i], st, done));
            }
        }
        on_step(done);
    }
    Ok((rows, timings))
}

/// Step `step`'s point of every live chain, simulated in parallel (`None` where the chain is done or
/// the simulation failed); trace `i` is named `opt-<i>-<step>`. A dense chain's sample is a
/// [`Trace`] (for the detectors); a sparse chain's stays as the problem hands it over (billiards:
/// columns, which its rule reads without the trace being built).
fn simulate_all<P: Problem>(
    problem: &P,
    chains: &[Chain<P::Scene>],
    xs: &[Option<Vec<f64>>],
    step: usize,
) -> Vec<Option<Simulated>> {
    chains
        .par_iter()
        .zip(xs.par_iter())
        .enumerate()
        .map(|(i, (c, x))| {
            let mut s = problem.sample(&c.scene, x.as_deref()?).ok()?;
            s.set_trace_id(format!("opt-{i}-{step}"));
            Some(match c.kind {
                RewardKind::Dense => Simulated::Trace(s.into_trace()),
                RewardKind::Sparse => s,
            })
        })
        .collect()
}

/// The annotations of the dense chains' traces (one pool call per goal, with that goal's
/// detectors), by chain; sparse chains and failed simulations get none. The traces are moved into
/// each goal's batch and back (no copy of a trace per sample).
fn annotate_dense<S>(
    pool: &WorkerPool,
    goals: &[GoalTask],
    chains: &[Chain<S>],
    traces: &mut [Option<Simulated>],
    timings: &mut Timings,
) -> Vec<Vec<Annotation>> {
    let mut anns: Vec<Vec<Annotation>> = vec![Vec::new(); chains.len()];
    for (g, goal) in goals.iter().enumerate() {
        let idx: Vec<usize> = (0..chains.len())
            .filter(|&i| {
                chains[i].goal == g
                    && chains[i].kind == RewardKind::Dense
                    && traces[i].as_ref().is_some_and(|t| !refused(t.outcome()))
            })
            .collect();
        if idx.is_empty() {
            continue;
        }
        // Dense samples are traces already (`simulate_all`): no copy.
        let batch: Vec<Trace> = idx
            .iter()
            .filter_map(|&i| traces[i].take().map(Simulated::into_trace))
            .collect();
        let (found, failed) = annotate(pool, &goal.detectors, &batch);
        timings.failed_calls += failed as u64;
        timings.dense_samples += idx.len() as u64;
        let chain_of: std::collections::HashMap<&str, usize> = batch
            .iter()
            .zip(&idx)
            .map(|(t, &i)| (t.trace_id.as_str(), i))
            .collect();
        for a in found {
            if let Some(&i) = chain_of.get(a.trace_id.as_str()) {
                anns[i].push(a);
            }
        }
        for (t, &i) in batch.into_iter().zip(&idx) {
            traces[i] = Some(Simulated::Trace(t));
        }
    }
    anns
}

/// Every chain's (reward, verified success, program error) for its trace: sparse chains score
/// the goal's rule, dense chains its reward program over the annotations; a failed simulation or
/// an invalid action (`invalid_action`) scores 0 and does not verify.
fn score_all<S: Sync>(
    goals: &[GoalTask],
    chains: &[Chain<S>],
    traces: &[Option<Simulated>],
    anns: &[Vec<Annotation>],
) -> Vec<(f64, bool, bool)> {
    chains
        .par_iter()
        .enumerate()
        .map(|(i, c)| {
            let Some(sample) = &traces[i] else {
                return (0.0, false, false);
            };
            if refused(sample.outcome()) {
                return (0.0, false, false);
            }
            let goal = &goals[c.goal];
            let verified = sample.holds(&goal.rule).unwrap_or(false);
            match c.kind {
                RewardKind::Sparse => (if verified { 1.0 } else { 0.0 }, verified, false),
                RewardKind::Dense => {
                    // Dense samples are traces already (`simulate_all`): borrowed, not built.
                    let trace = sample.trace();
                    let at = AnnotatedTrace::new(&trace, &anns[i]);
                    match evaluate(&goal.program, &at) {
                        Ok(e) => (e.score, verified, false),
                        Err(_) => (0.0, verified, true),
                    }
                }
            }
        })
        .collect()
}

/// A chain's best sample so far, as its row after `done` samples.
fn row<P: Problem>(
    problem: &P,
    goals: &[GoalTask],
    c: &Chain<P::Scene>,
    st: &State,
    done: usize,
) -> CheckpointRow {
    let (_, best, k) = st.annealer.best().unwrap_or((&[], 0.0, 0));
    CheckpointRow {
        goal: goals[c.goal].id.clone(),
        scene: problem.scene_id(&c.scene),
        seed: c.seed,
        kind: c.kind,
        budget: done,
        chain_budget: c.budget,
        best_reward: best,
        success: st.best_success,
        best_sample: k,
        action: problem.action_json(&c.scene, &st.best_x),
        point: st.best_x.clone(),
    }
}
