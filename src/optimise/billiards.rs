//! The billiards optimisation experiment: many annealing chains (goal × scene × seed × reward type)
//! advanced in lockstep, so that each step simulates every chain's proposal in parallel, annotates the
//! dense chains' traces in one call to the detector runtime per goal (only the detectors the goal's
//! program uses), scores them, and verifies every sample with the goal's hand-written rule.
//!
//! The best-so-far sample of each chain is recorded at every checkpoint (50, 100, …), with whether its
//! shot verifies: one run of budget N gives the whole success-versus-budget curve.

use std::time::Instant;

use rayon::prelude::*;

use super::OptimiseError;
use super::anneal::{Annealer, Dim, Schedule};
use crate::detect::{Annotation, Detector, WorkerPool};
use crate::envs::Environment;
use crate::envs::pool::{PoolEnv, Scene, Shot};
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

/// One chain: which goal, scene, seed and reward.
#[derive(Debug, Clone)]
pub struct Chain {
    /// Index into the goals.
    pub goal: usize,
    /// The scene.
    pub scene: Scene,
    /// The chain's seed.
    pub seed: u64,
    /// The reward.
    pub kind: RewardKind,
}

/// Bounds of the shot parameters searched (inside `PoolEnv::action_space()`'s legal ranges).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShotBounds {
    /// Cue speed (m/s).
    pub v0: (f64, f64),
    /// Elevation (degrees).
    pub theta: (f64, f64),
    /// Largest tip offset radius √(a² + b²) (× R); offsets outside are scaled onto it.
    pub max_offset: f64,
}

impl Default for ShotBounds {
    /// V0 in [0.2, 6] m/s, θ in [0°, 45°], offsets within 0.9 R (φ always spans [0°, 360°)).
    fn default() -> Self {
        ShotBounds {
            v0: (0.2, 6.0),
            theta: (0.0, 45.0),
            max_offset: 0.9,
        }
    }
}

impl ShotBounds {
    /// The search box, checked against the environment's legal ranges.
    pub fn dims(&self, env: &PoolEnv) -> Result<Vec<Dim>, OptimiseError> {
        let space = env.action_space();
        let legal = |name: &str| {
            space
                .iter()
                .find(|d| d.name == name)
                .map(|d| (d.low, d.high))
                .unwrap_or((f64::NEG_INFINITY, f64::INFINITY))
        };
        let inside = |name: &str, (lo, hi): (f64, f64)| {
            let (l, h) = legal(name);
            if lo >= l && hi <= h && lo < hi {
                Ok(())
            } else {
                Err(OptimiseError::Bounds(format!(
                    "{name} range [{lo}, {hi}] must be non-empty and inside the legal [{l}, {h}]"
                )))
            }
        };
        inside("V0", self.v0)?;
        inside("theta", self.theta)?;
        if !(self.max_offset > 0.0 && self.max_offset < 1.0) {
            return Err(OptimiseError::Bounds(format!(
                "max_offset must be in (0, 1) (a² + b² < 1), found {}",
                self.max_offset
            )));
        }
        let (plo, phi) = legal("phi");
        Ok(vec![
            Dim {
                low: self.v0.0,
                high: self.v0.1,
                periodic: false,
            },
            Dim {
                low: plo.max(0.0),
                high: phi.min(360.0),
                periodic: true,
            },
            Dim {
                low: self.theta.0,
                high: self.theta.1,
                periodic: false,
            },
            Dim {
                low: -self.max_offset,
                high: self.max_offset,
                periodic: false,
            },
            Dim {
                low: -self.max_offset,
                high: self.max_offset,
                periodic: false,
            },
        ])
    }

    /// The shot of a point of the box (tip offsets scaled into the allowed disc).
    pub fn shot(&self, x: &[f64]) -> Shot {
        let (mut a, mut b) = (x[3], x[4]);
        let r = a.hypot(b);
        if r > self.max_offset {
            a *= self.max_offset / r;
            b *= self.max_offset / r;
        }
        Shot {
            v0: x[0],
            phi: x[1],
            theta: x[2],
            a,
            b,
        }
    }
}

/// Settings of a batch of chains.
#[derive(Debug, Clone)]
pub struct Settings {
    /// The environment (its `trace.dt` sets the trace resolution the detectors see).
    pub env: PoolEnv,
    /// The shot box.
    pub bounds: ShotBounds,
    /// The annealing schedule (its budget is the number of samples per chain).
    pub schedule: Schedule,
    /// Record the best-so-far every this many samples.
    pub checkpoint: usize,
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
    /// Reward of the best sample so far.
    pub best_reward: f64,
    /// Whether the best sample's shot meets the verification rule.
    pub success: bool,
    /// Which sample (1-based) it was.
    pub best_sample: usize,
    /// Its shot.
    pub shot: Shot,
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
}

struct State {
    annealer: Annealer,
    best_success: bool,
    best_shot: Shot,
}

/// Runs every chain for the schedule's budget; `on_step` is called after each step with the number
/// of steps done. Needs `pool` when any chain is dense.
pub fn run_chains(
    settings: &Settings,
    goals: &[GoalTask],
    chains: &[Chain],
    pool: Option<&WorkerPool>,
    mut on_step: impl FnMut(usize),
) -> Result<(Vec<CheckpointRow>, Timings), OptimiseError> {
    let dims = settings.bounds.dims(&settings.env)?;
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
    let mut states: Vec<State> = chains
        .iter()
        .map(|c| State {
            annealer: Annealer::new(dims.clone(), settings.schedule, c.seed),
            best_success: false,
            best_shot: Shot::default(),
        })
        .collect();
    let mut rows = Vec::new();
    let mut timings = Timings::default();
    let budget = settings.schedule.budget;
    let every = settings.checkpoint.max(1);
    for step in 0..budget {
        let xs: Vec<Vec<f64>> = states.iter_mut().map(|s| s.annealer.propose()).collect();
        let shots: Vec<Shot> = xs.iter().map(|x| settings.bounds.shot(x)).collect();
        let t0 = Instant::now();
        let traces = simulate_all(settings, chains, &shots, step);
        timings.simulate_s += t0.elapsed().as_secs_f64();
        timings.failed_simulations += traces.iter().filter(|t| t.is_none()).count() as u64;

        // Annotate the dense chains' traces, one pool call per goal.
        let t1 = Instant::now();
        let anns = match pool {
            Some(pool) => annotate_dense(pool, goals, chains, &traces, &mut timings),
            None => vec![Vec::new(); chains.len()],
        };
        timings.annotate_s += t1.elapsed().as_secs_f64();

        let t2 = Instant::now();
        let scored = score_all(goals, chains, &traces, &anns);
        timings.score_s += t2.elapsed().as_secs_f64();
        timings.program_errors += scored.iter().filter(|s| s.2).count() as u64;
        timings.samples += chains.len() as u64;

        for (i, ((x, (score, verified, _)), shot)) in
            xs.into_iter().zip(scored).zip(shots).enumerate()
        {
            let st = &mut states[i];
            st.annealer.observe(x, score);
            if st
                .annealer
                .best()
                .is_some_and(|b| b.2 == st.annealer.samples())
            {
                st.best_success = verified;
                st.best_shot = shot;
            }
        }
        let done = step + 1;
        if done % every == 0 || done == budget {
            rows.extend(checkpoint(goals, chains, &states, done));
        }
        on_step(done);
    }
    Ok((rows, timings))
}

/// Step `step`'s shot of every chain, simulated in parallel (`None` where the simulation failed);
/// trace `i` is named `opt-<i>-<step>`.
fn simulate_all(
    settings: &Settings,
    chains: &[Chain],
    shots: &[Shot],
    step: usize,
) -> Vec<Option<Trace>> {
    chains
        .par_iter()
        .zip(shots.par_iter())
        .enumerate()
        .map(|(i, (c, shot))| {
            let mut t = settings.env.simulate(&c.scene, shot).ok()?;
            t.trace_id = format!("opt-{i}-{step}");
            Some(t)
        })
        .collect()
}

/// The annotations of the dense chains' traces (one pool call per goal, with that goal's
/// detectors), by chain; sparse chains and failed simulations get none.
fn annotate_dense(
    pool: &WorkerPool,
    goals: &[GoalTask],
    chains: &[Chain],
    traces: &[Option<Trace>],
    timings: &mut Timings,
) -> Vec<Vec<Annotation>> {
    let mut anns: Vec<Vec<Annotation>> = vec![Vec::new(); chains.len()];
    for (g, goal) in goals.iter().enumerate() {
        let idx: Vec<usize> = (0..chains.len())
            .filter(|&i| {
                chains[i].goal == g && chains[i].kind == RewardKind::Dense && traces[i].is_some()
            })
            .collect();
        if idx.is_empty() {
            continue;
        }
        let batch: Vec<Trace> = idx.iter().filter_map(|&i| traces[i].clone()).collect();
        let (found, failed) = annotate(pool, &goal.detectors, &batch);
        timings.failed_calls += failed as u64;
        timings.dense_samples += idx.len() as u64;
        for a in found {
            if let Some(&i) = idx
                .iter()
                .find(|&&i| traces[i].as_ref().is_some_and(|t| t.trace_id == a.trace_id))
            {
                anns[i].push(a);
            }
        }
    }
    anns
}

/// Every chain's (reward, verified success, program error) for its trace: sparse chains score
/// the goal's rule, dense chains its reward program over the annotations.
fn score_all(
    goals: &[GoalTask],
    chains: &[Chain],
    traces: &[Option<Trace>],
    anns: &[Vec<Annotation>],
) -> Vec<(f64, bool, bool)> {
    chains
        .par_iter()
        .enumerate()
        .map(|(i, c)| {
            let Some(trace) = &traces[i] else {
                return (0.0, false, false);
            };
            let goal = &goals[c.goal];
            let verified = goal.rule.holds(trace).unwrap_or(false);
            match c.kind {
                RewardKind::Sparse => (if verified { 1.0 } else { 0.0 }, verified, false),
                RewardKind::Dense => {
                    let at = AnnotatedTrace::new(trace, &anns[i]);
                    match evaluate(&goal.program, &at) {
                        Ok(e) => (e.score, verified, false),
                        Err(_) => (0.0, verified, true),
                    }
                }
            }
        })
        .collect()
}

/// Every chain's best shot so far, as the checkpoint rows after `done` steps.
fn checkpoint(
    goals: &[GoalTask],
    chains: &[Chain],
    states: &[State],
    done: usize,
) -> Vec<CheckpointRow> {
    chains
        .iter()
        .zip(states)
        .map(|(c, st)| {
            let (_, best, k) = st.annealer.best().unwrap_or((&[], 0.0, 0));
            CheckpointRow {
                goal: goals[c.goal].id.clone(),
                scene: c.scene.scene_id.clone(),
                seed: c.seed,
                kind: c.kind,
                budget: done,
                best_reward: best,
                success: st.best_success,
                best_sample: k,
                shot: st.best_shot,
            }
        })
        .collect()
}
