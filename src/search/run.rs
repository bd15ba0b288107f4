//! One label's search (FunSearch, Algorithm 1 of appendix F, or a baseline) and the discovery loop
//! around it (Algorithm 2: one search per label, accept the best if ν > δ, grow the library).
//!
//! A search runs in *rounds* of `parallel` steps. Every step of round r samples an island and its
//! parents from the database after round r − 1 − `lag` ([`SearchConfig::lag`]), with a random generator
//! seeded from (run seed, label index, step) — so step k's choices do not depend on how earlier steps
//! were scheduled — and the proposer is asked for all of the round's children at once (concurrently:
//! an LLM proposer's requests overlap). Children are then checked and scored in step order as their
//! proposals come back, each result is applied to the database, and every T_r steps the weaker half of
//! the islands is reset. With `lag` 1 the search is a pipeline, as FunSearch's samplers and
//! evaluators are: round r + 1's requests are in flight while round r is evaluated, and since their
//! prompts come from the database before round r, the search is the same whether the two phases
//! overlap in time or not ([`SearchConfig::overlap`]). The round's records are handed to a
//! [`Checkpoint`]; a resumed search *replays* saved rounds (applying their records without proposing
//! or evaluating again) and continues with the first unsaved round. With a deterministic proposer
//! (`mutate`) and a deterministic score (ψ off) a resumed search therefore equals an uninterrupted one
//! record for record, under either lag.
//!
//! **Owns:** the round schedule, the search state rebuilt from records, checkpoints, the proposer's
//! busy time. **Does not:** score (`search::evaluator`, `fitness/`), sample parents
//! (`search::islands`), or make children (the [`Proposer`]).

use std::collections::{BTreeMap, HashMap};
use std::sync::Mutex;
use std::time::Instant;

use super::candidate::{CandidateRecord, code_hash};
use super::evaluator::{Evaluation, Evaluator};
use super::islands::{Database, Program, Strategy, Temperatures};
use super::proposer::{Parent, Proposal, ProposalRequest, ProposeError, Proposer, count_lines};
use crate::detect::DetectorError;
use crate::digest::words_u64;
use crate::rng::SplitMix64;

/// The knobs of a search (the paper's I, s, T_r, budget and δ, and ours).
#[derive(Clone, Debug, PartialEq)]
pub struct SearchConfig {
    /// How parents are picked.
    pub strategy: Strategy,
    /// Islands I.
    pub islands: usize,
    /// Prompt size s: parents per request.
    pub prompt_size: usize,
    /// Reset period T_r (steps); 0 never resets.
    pub reset_period: u64,
    /// Proposals per label.
    pub budget: u64,
    /// Acceptance threshold δ on ν.
    pub delta: f64,
    /// Accept a best program whose held-out ρ is ≤ 0 (when its ν > δ). Off by default: a detector whose
    /// annotation distances do not grow with the trace distances on unseen traces is noise.
    pub allow_nonpositive_rho: bool,
    /// Proposals requested at once (one round).
    pub parallel: usize,
    /// How many rounds old the database is that a round's prompts are built from: with 0, round r
    /// samples its parents from the database after round r − 1 (proposals and evaluation alternate);
    /// with 1, from the database after round r − 2, so round r's requests can be in flight while
    /// round r − 1 is evaluated. Values above 1 count as 1.
    pub lag: u64,
    /// With `lag` 1: send round r + 1's requests before round r is evaluated (the pipeline). `false`
    /// runs the same schedule one phase after the other: the same search, only slower (for tests and
    /// measurements). Ignored with `lag` 0.
    pub overlap: bool,
    /// Repair attempts per child that fails with a repairable error.
    pub repair_attempts: u32,
    /// Sampling temperatures.
    pub temperatures: Temperatures,
    /// The run seed.
    pub seed: u64,
}

impl SearchConfig {
    /// The defaults (the paper's settings where it gives them); the `evolve` stage's parameters and
    /// the CLI's flags take theirs from here.
    pub const DEFAULT: SearchConfig = SearchConfig {
        strategy: Strategy::Island,
        islands: 4,
        prompt_size: 2,
        reset_period: 100,
        budget: 200,
        delta: 0.0,
        allow_nonpositive_rho: false,
        parallel: 4,
        lag: 0,
        overlap: true,
        repair_attempts: 2,
        temperatures: Temperatures::DEFAULT,
        seed: 0,
    };
}

impl Default for SearchConfig {
    fn default() -> Self {
        SearchConfig::DEFAULT
    }
}

/// A search could not go on.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SearchError {
    /// No seed program of the label could be scored.
    #[error("label {label:?}: no seed program could be evaluated: {message}")]
    Seed {
        /// The label.
        label: String,
        /// The seed's failure.
        message: String,
    },
    /// The proposer cannot be reached.
    #[error("label {label:?}")]
    Proposer {
        /// The label.
        label: String,
        /// The proposer's error.
        #[source]
        source: ProposeError,
    },
    /// Saving or loading a checkpoint failed.
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    /// Proposals were asked for and not one gave a program that ran: the search learned nothing (its
    /// best detectors are the seed programs).
    #[error(
        "all {} proposal(s) of the {proposer} proposer failed {}",
        tally.asked,
        tally.breakdown()
    )]
    AllProposalsFailed {
        /// The proposer's name (`llm:<model>`, `mutate`).
        proposer: String,
        /// The proposals by outcome, with the first failure.
        tally: super::tally::ProposalTally,
    },
}

/// Where a search keeps its finished rounds (round 0 holds the seed programs).
pub trait Checkpoint {
    /// The records of a finished round, if it was saved.
    fn load(
        &self,
        label_index: u32,
        round: u64,
    ) -> Result<Option<Vec<CandidateRecord>>, SearchError>;
    /// Saves a finished round.
    fn save(
        &self,
        label_index: u32,
        round: u64,
        records: &[CandidateRecord],
    ) -> Result<(), SearchError>;
}

/// A checkpoint in memory (for tests and one-shot searches); `stop_after` rounds saved in total makes
/// `save` fail, to simulate a kill.
#[derive(Debug, Default)]
pub struct MemoryCheckpoint {
    /// Saved rounds.
    pub rounds: Mutex<BTreeMap<(u32, u64), Vec<CandidateRecord>>>,
    /// Fail the save after this many rounds are stored.
    pub stop_after: Option<usize>,
}

impl Checkpoint for MemoryCheckpoint {
    fn load(&self, l: u32, r: u64) -> Result<Option<Vec<CandidateRecord>>, SearchError> {
        Ok(self
            .rounds
            .lock()
            .expect("not poisoned")
            .get(&(l, r))
            .cloned())
    }
    fn save(&self, l: u32, r: u64, records: &[CandidateRecord]) -> Result<(), SearchError> {
        let mut m = self.rounds.lock().expect("not poisoned");
        m.insert((l, r), records.to_vec());
        if self.stop_after.is_some_and(|n| m.len() >= n) {
            return Err(SearchError::Checkpoint(format!(
                "stopped after {} rounds",
                m.len()
            )));
        }
        Ok(())
    }
}

/// What one label's search found.
#[derive(Clone, Debug)]
pub struct LabelOutcome {
    /// The label.
    pub label: String,
    /// The best program (possibly the seed).
    pub best: Program,
    /// The best seed program's ν.
    pub seed_nu: f64,
    /// Every candidate, seed programs first, in step order.
    pub records: Vec<CandidateRecord>,
    /// Best ν after each step (the curve that should go up).
    pub best_by_step: Vec<f64>,
    /// Wall time of the search (s), this process only.
    pub wall_s: f64,
    /// Wall time during which at least one proposal or repair was in flight (s), this process only:
    /// the time the proposer had work. `wall_s − propose_s` is the time outside the proposer.
    pub propose_s: f64,
    /// Whether the proposer's budget ran out before the step budget.
    pub budget_exhausted: bool,
}

/// The generator of step `step` of label `label_index`'s search.
pub fn step_rng(seed: u64, label_index: u32, step: u64) -> SplitMix64 {
    SplitMix64::new(words_u64(&[seed, u64::from(label_index), step, 0x57E9]))
}

fn repairable(e: &DetectorError) -> bool {
    matches!(
        e.category(),
        "syntax" | "forbidden" | "no_find_pattern" | "runtime" | "invalid_output"
    )
}

/// The search state rebuilt from records (live or replayed).
struct State {
    db: Option<Database>,
    seen: HashMap<String, (Option<crate::fitness::FitnessTerms>, Option<String>)>,
    known: HashMap<String, String>,
    best_by_step: Vec<f64>,
}

impl State {
    /// No record applied yet.
    fn empty() -> Self {
        State {
            db: None,
            seen: HashMap::new(),
            known: HashMap::new(),
            best_by_step: Vec::new(),
        }
    }

    fn apply(&mut self, r: &CandidateRecord, cfg: &SearchConfig, label_index: u32) {
        if !r.code.is_empty() {
            self.seen
                .entry(r.code_hash.clone())
                .or_insert((r.terms, r.signature.clone()));
        }
        if let Some(sig) = &r.signature {
            self.known.entry(sig.clone()).or_insert(r.code_hash.clone());
        }
        if r.scored() {
            let p = Program {
                hash: r.code_hash.clone(),
                code: r.code.clone(),
                terms: r.terms.expect("scored"),
                lines: r.lines as usize,
            };
            match &mut self.db {
                None => {
                    self.db = Some(Database::new(
                        cfg.strategy,
                        cfg.islands,
                        p,
                        cfg.temperatures,
                    ))
                }
                Some(db) if r.step < 0 => {
                    // A further seed program: onto every island.
                    for i in 0..db.islands() {
                        db.insert(i, p.clone());
                    }
                }
                Some(db) => db.insert(r.island.max(0) as usize, p),
            }
        }
        if r.step >= 0 {
            let step = r.step as u64;
            if let Some(db) = &mut self.db {
                self.best_by_step.push(db.best().terms.nu);
                if cfg.reset_period > 0 && (step + 1).is_multiple_of(cfg.reset_period) {
                    let mut rng = SplitMix64::new(words_u64(&[
                        cfg.seed,
                        u64::from(label_index),
                        step,
                        0x4E5E7,
                    ]));
                    db.reset(&mut rng);
                }
            }
        }
    }
}

/// Everything one label's search needs.
pub struct LabelSearch<'a> {
    /// The knobs.
    pub config: &'a SearchConfig,
    /// Position of the label in the run's label list.
    pub label_index: u32,
    /// Scores candidates (knows the label, traces and library).
    pub evaluator: &'a Evaluator<'a>,
    /// Makes children.
    pub proposer: &'a dyn Proposer,
    /// The seed programs g₀ (the library's detectors for the label, or the skeleton).
    pub seeds: Vec<String>,
    /// Labels of the current library.
    pub library_labels: Vec<String>,
    /// Keeps finished rounds.
    pub checkpoint: &'a dyn Checkpoint,
}

impl LabelSearch<'_> {
    fn base_record(&self, island: i64, step: i64) -> CandidateRecord {
        CandidateRecord {
            label: self.evaluator.label.clone(),
            label_index: self.label_index,
            seed: self.config.seed,
            strategy: self.config.strategy.as_str().into(),
            proposer: self.proposer.name().into(),
            island,
            step,
            parents: Vec::new(),
            code_hash: String::new(),
            code: String::new(),
            status: String::new(),
            error: None,
            error_line: None,
            failed_on_probe: false,
            repairs: 0,
            terms: None,
            lines: 0,
            mean_time_s: None,
            activation_rate: None,
            signature: None,
            tokens_in: 0,
            tokens_out: 0,
            calls: 0,
            propose_s: 0.0,
            eval_s: 0.0,
        }
    }

    /// Checks, scores and records one piece of code (used for seeds, children and repairs).
    fn score_into(
        &self,
        rec: &mut CandidateRecord,
        code: String,
        state: &State,
    ) -> Option<DetectorError> {
        let t0 = Instant::now();
        let mut failure = None;
        rec.code_hash = code_hash(&code);
        rec.lines = count_lines(&code) as u64;
        rec.code = code;
        if let Some((terms, sig)) = state.seen.get(&rec.code_hash) {
            rec.status = "duplicate".into();
            rec.terms = *terms;
            rec.signature = sig.clone();
        } else {
            match self
                .evaluator
                .evaluate(&rec.code, rec.lines as usize, &state.known, rec.step < 0)
            {
                Evaluation::Failed { error, on_probe } => {
                    rec.status = error.category().into();
                    rec.error_line = error.line();
                    rec.error = Some(error.to_string());
                    rec.failed_on_probe = on_probe;
                    rec.terms = None;
                    rec.signature = None;
                    failure = Some(error);
                }
                Evaluation::SameBehaviour { of, signature } => {
                    rec.status = "same_behaviour".into();
                    rec.error = Some(format!("behaves like {of} on the probe set"));
                    rec.signature = Some(signature);
                }
                Evaluation::Degenerate {
                    reason,
                    mean_time,
                    activation_rate,
                    signature,
                } => {
                    rec.status = "degenerate".into();
                    rec.error = Some(format!(
                        "degenerate pattern: {reason} on every training trace"
                    ));
                    rec.mean_time_s = Some(mean_time);
                    rec.activation_rate = Some(activation_rate);
                    rec.signature = Some(signature);
                }
                Evaluation::Scored {
                    terms,
                    mean_time,
                    activation_rate,
                    signature,
                } => {
                    rec.status = "ok".into();
                    rec.error = None;
                    rec.error_line = None;
                    rec.failed_on_probe = false;
                    rec.terms = Some(terms);
                    rec.mean_time_s = Some(mean_time);
                    rec.activation_rate = Some(activation_rate);
                    rec.signature = Some(signature);
                }
            }
        }
        rec.eval_s += t0.elapsed().as_secs_f64();
        failure
    }

    fn request(&self, island: usize, parents: &[Program], seed: u64, step: u64) -> ProposalRequest {
        ProposalRequest {
            env: self.evaluator.env,
            label: self.evaluator.label.clone(),
            parents: parents
                .iter()
                .map(|p| Parent {
                    code: p.code.clone(),
                    fitness: Some(p.terms),
                    lines: p.lines,
                })
                .collect(),
            library_labels: self.library_labels.clone(),
            seed,
            island,
            step,
        }
    }

    /// The record of one step: the proposal's child checked and scored, repaired while it fails with a
    /// repairable error and the proposer offers repairs.
    fn settle(
        &self,
        (step, island, parents, seed): Plan,
        proposal: Result<Proposal, ProposeError>,
        took: f64,
        state: &State,
        busy: &Busy,
    ) -> Result<CandidateRecord, SearchError> {
        let cfg = self.config;
        // An unreachable or refusing backend ends the run.
        let fatal = |source: ProposeError| SearchError::Proposer {
            label: self.evaluator.label.clone(),
            source,
        };
        let mut rec = self.base_record(island as i64, step as i64);
        rec.parents = parents.iter().map(|p| p.hash.clone()).collect();
        rec.propose_s = took;
        let p = match proposal {
            Err(e @ (ProposeError::Unavailable(_) | ProposeError::Refused(_))) => {
                return Err(fatal(e));
            }
            Err(e) => {
                rec.status = if matches!(e, ProposeError::BudgetExhausted(_)) {
                    "budget_exhausted".into()
                } else {
                    "proposer".into()
                };
                rec.error = Some(e.to_string());
                return Ok(rec);
            }
            Ok(p) => p,
        };
        rec.tokens_in = p.tokens_in;
        rec.tokens_out = p.tokens_out;
        rec.calls = p.calls;
        let mut failure = self.score_into(&mut rec, p.code, state);
        let req = self.request(island, &parents, seed, step);
        while rec.repairs < cfg.repair_attempts {
            let Some(err) = failure.take() else { break };
            if !repairable(&err) {
                break;
            }
            let (fixed, dt) =
                busy.time(|| self.proposer.repair(&req, &rec.code, &err, rec.repairs + 1));
            rec.propose_s += dt;
            match fixed {
                Ok(Some(p)) => {
                    rec.repairs += 1;
                    rec.tokens_in += p.tokens_in;
                    rec.tokens_out += p.tokens_out;
                    rec.calls += p.calls;
                    failure = self.score_into(&mut rec, p.code, state);
                }
                Ok(None) => break,
                Err(e @ (ProposeError::Unavailable(_) | ProposeError::Refused(_))) => {
                    return Err(fatal(e));
                }
                Err(_) => break,
            }
        }
        Ok(rec)
    }

    /// Round 0: the seed programs, scored (and checkpointed when any scored), or replayed from
    /// the checkpoint. A scored seed's status is `seed`.
    fn seed_round(&self) -> Result<Vec<CandidateRecord>, SearchError> {
        if let Some(r) = self.checkpoint.load(self.label_index, 0)? {
            return Ok(r);
        }
        // Seeds are scored against each other (a repeated seed is a duplicate); the caller
        // rebuilds its state from the records.
        let mut state = State::empty();
        let mut out = Vec::new();
        for code in &self.seeds {
            let mut rec = self.base_record(-1, -1);
            self.score_into(&mut rec, code.clone(), &state);
            if rec.status == "ok" {
                rec.status = "seed".into();
            }
            state.apply(&rec, self.config, self.label_index);
            out.push(rec);
        }
        if out.iter().any(CandidateRecord::scored) {
            self.checkpoint.save(self.label_index, 0, &out)?;
        }
        Ok(out)
    }

    /// The plan of every step of `steps`: its island, parents and request seed, sampled from `db` with
    /// the step's own generator (so a plan depends only on the seed, the label, the step and `db`).
    fn plan(&self, db: &Database, steps: std::ops::Range<u64>) -> Vec<Plan> {
        let cfg = self.config;
        steps
            .map(|step| {
                let mut rng = step_rng(cfg.seed, self.label_index, step);
                let (island, parents) = db.sample(cfg.prompt_size, &mut rng);
                (step, island, parents, rng.next_u64())
            })
            .collect()
    }

    /// Sends every planned request at once, each on its own scoped thread (the proposer's own limits,
    /// such as an LLM client's slots, decide how many are answered at the same time).
    fn launch<'scope, 'env>(
        &'env self,
        sc: &'scope std::thread::Scope<'scope, 'env>,
        plans: Vec<Plan>,
        busy: &'env Busy,
    ) -> Launched<'scope> {
        let proposer = self.proposer;
        plans
            .into_iter()
            .map(|plan| {
                let req = self.request(plan.1, &plan.2, plan.3, plan.0);
                let handle = sc.spawn(move || busy.time(|| proposer.propose(&req)));
                (plan, handle)
            })
            .collect()
    }

    /// Settles a launched round: each child is checked and scored as soon as its proposal is back,
    /// in step order (later proposals, and with a lag the next round's, are still in flight), and
    /// applied to `state`. Calls `on_first_answer` once the first proposal is back, before it is
    /// scored. Sets `exhausted` when the proposer's budget ran out.
    fn settle_round(
        &self,
        launched: Launched<'_>,
        state: &mut State,
        busy: &Busy,
        exhausted: &mut bool,
        mut on_first_answer: impl FnMut(),
    ) -> Result<Vec<CandidateRecord>, SearchError> {
        let mut records = Vec::with_capacity(launched.len());
        for (plan, handle) in launched {
            let (proposal, took) = handle.join().unwrap_or_else(|_| {
                (
                    Err(ProposeError::Other("the proposer panicked".into())),
                    0.0,
                )
            });
            if records.is_empty() {
                on_first_answer();
            }
            let rec = self.settle(plan, proposal, took, state, busy)?;
            *exhausted |= rec.status == "budget_exhausted";
            state.apply(&rec, self.config, self.label_index);
            records.push(rec);
        }
        Ok(records)
    }

    /// The steps of round `round` (1-based).
    fn steps(&self, round: u64) -> std::ops::Range<u64> {
        let per_round = self.config.parallel.max(1) as u64;
        (round - 1) * per_round..(round * per_round).min(self.config.budget)
    }

    /// Runs (or resumes) the search.
    ///
    /// Round r's parents are sampled from the database after round r − 1 − `lag` (round 0 is the
    /// seed programs; earlier rounds count as round 0). With `lag` 1 and `overlap`, round r + 1's
    /// requests are sent once round r − 1 is settled (when round r's requests went out only now, as
    /// the first round's do, once round r's first answer is back), and round r is evaluated while
    /// they are in flight. Saved rounds are replayed first (their records applied without proposing or
    /// evaluating), keeping the database before the last of them, so a resumed search plans its next
    /// rounds from the same databases as an uninterrupted one.
    pub fn run(&self) -> Result<LabelOutcome, SearchError> {
        let cfg = self.config;
        let started = Instant::now();
        let busy = Busy::default();
        let mut state = State::empty();
        let mut all = Vec::new();
        let label = self.evaluator.label.clone();
        let seeds = self.seed_round()?;
        for r in &seeds {
            state.apply(r, cfg, self.label_index);
        }
        let Some(seed_nu) = state.db.as_ref().map(|d| d.best().terms.nu) else {
            let message = seeds
                .iter()
                .filter_map(|r| r.error.clone())
                .next()
                .unwrap_or_else(|| "no seed program given".into());
            return Err(SearchError::Seed { label, message });
        };
        all.extend(seeds);
        let rounds = cfg.budget.div_ceil(cfg.parallel.max(1) as u64);
        let lagged = cfg.lag >= 1;
        let mut exhausted = false;
        // The database before the last applied round (the seeds' while no round is applied).
        let mut before_last = state.db.clone().expect("seeded");
        let mut first_live = 1;
        while first_live <= rounds {
            let Some(saved) = self.checkpoint.load(self.label_index, first_live)? else {
                break;
            };
            before_last = state.db.clone().expect("seeded");
            for r in &saved {
                state.apply(r, cfg, self.label_index);
                exhausted |= r.status == "budget_exhausted";
            }
            all.extend(saved);
            first_live += 1;
        }
        std::thread::scope(|sc| -> Result<(), SearchError> {
            let mut next: Option<Launched<'_>> = None;
            let mut round = first_live;
            while round <= rounds && !exhausted {
                let (current, fresh) = match next.take() {
                    Some(l) => (l, false),
                    None => {
                        let db = if lagged && round == first_live {
                            &before_last
                        } else {
                            state.db.as_ref().expect("seeded")
                        };
                        (
                            self.launch(sc, self.plan(db, self.steps(round)), &busy),
                            true,
                        )
                    }
                };
                // With a lag, round + 1 is planned from the database after round − 1: the one now.
                // With the overlap it is launched now, or, when round's own requests went out just
                // now (the first round, or after a resume), once round's first answer is back, so
                // that round's requests reach the endpoint's slots before round + 1's (the client
                // queues waiting requests by step, but a request that finds a free slot takes it).
                // Without the overlap it is launched once round is settled.
                let mut deferred = None;
                if lagged && round < rounds {
                    let plans =
                        self.plan(state.db.as_ref().expect("seeded"), self.steps(round + 1));
                    if cfg.overlap && !fresh {
                        next = Some(self.launch(sc, plans, &busy));
                    } else {
                        deferred = Some(plans);
                    }
                }
                let on_first_answer = || {
                    if let Some(plans) = deferred.take_if(|_| cfg.overlap) {
                        next = Some(self.launch(sc, plans, &busy));
                    }
                };
                let records =
                    self.settle_round(current, &mut state, &busy, &mut exhausted, on_first_answer)?;
                self.checkpoint.save(self.label_index, round, &records)?;
                all.extend(records);
                if let Some(plans) = deferred.filter(|_| !exhausted) {
                    next = Some(self.launch(sc, plans, &busy));
                }
                round += 1;
            }
            // Requests of a round that will not run (the budget ran out) are left to finish; their
            // answers are not used.
            Ok(())
        })?;
        let db = state.db.as_ref().expect("seeded");
        Ok(LabelOutcome {
            label,
            best: db.best().clone(),
            seed_nu,
            records: all,
            best_by_step: state.best_by_step,
            wall_s: started.elapsed().as_secs_f64(),
            propose_s: busy.total(),
            budget_exhausted: exhausted,
        })
    }
}

/// One step's plan: (step, island, parents, request seed).
type Plan = (u64, usize, Vec<Program>, u64);

/// A round whose requests are in flight: each plan with the thread asking the proposer (the proposal
/// and the seconds it took).
type Launched<'scope> = Vec<(
    Plan,
    std::thread::ScopedJoinHandle<'scope, (Result<Proposal, ProposeError>, f64)>,
)>;

/// The wall time during which at least one call to the proposer was running: the union of the
/// calls' intervals, whichever thread made them.
#[derive(Debug, Default)]
struct Busy(Mutex<BusyState>);

#[derive(Debug, Default)]
struct BusyState {
    running: usize,
    since: Option<Instant>,
    total: f64,
}

impl Busy {
    /// Runs `f` as a call to the proposer; returns its result and its own duration (s).
    fn time<T>(&self, f: impl FnOnce() -> T) -> (T, f64) {
        let t = Instant::now();
        {
            let mut b = self.0.lock().unwrap_or_else(|p| p.into_inner());
            if b.running == 0 {
                b.since = Some(t);
            }
            b.running += 1;
        }
        let out = f();
        let end = Instant::now();
        let mut b = self.0.lock().unwrap_or_else(|p| p.into_inner());
        b.running -= 1;
        if b.running == 0
            && let Some(since) = b.since.take()
        {
            b.total += end.duration_since(since).as_secs_f64();
        }
        (out, end.duration_since(t).as_secs_f64())
    }

    /// The busy time so far, counting a call still running up to now.
    fn total(&self) -> f64 {
        let b = self.0.lock().unwrap_or_else(|p| p.into_inner());
        b.total + b.since.map_or(0.0, |s| s.elapsed().as_secs_f64())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::detect::{SandboxLimits, WorkerPool};
    use crate::fitness::{DistanceMatrix, LibraryView};
    use crate::search::evaluator::EvalSettings;
    use crate::search::skeleton::skeleton;
    use crate::testutil::synthetic_trace;
    use crate::trace::{Env, Trace};

    /// Proposes a broken child first, then repairs it into a working one; counts its calls.
    struct Scripted {
        good: String,
        calls: Mutex<Vec<String>>,
    }

    impl Proposer for Scripted {
        fn name(&self) -> &str {
            "scripted"
        }
        fn propose(&self, req: &ProposalRequest) -> Result<Proposal, ProposeError> {
            self.calls
                .lock()
                .unwrap()
                .push(format!("propose {}", req.step));
            Ok(Proposal {
                code: "def find_pattern(trace:\n    return []\n".into(),
                tokens_in: 10,
                tokens_out: 5,
                calls: 1,
            })
        }
        fn repair(
            &self,
            _req: &ProposalRequest,
            _code: &str,
            error: &DetectorError,
            attempt: u32,
        ) -> Result<Option<Proposal>, ProposeError> {
            self.calls
                .lock()
                .unwrap()
                .push(format!("repair {attempt} {}", error.category()));
            Ok(Some(Proposal {
                code: self.good.clone(),
                tokens_in: 3,
                tokens_out: 2,
                calls: 1,
            }))
        }
    }

    fn traces() -> Vec<Trace> {
        // Synthetic traces whose balls drift at 1 m/s, trace i moving 0.2·i m further after step 15.
        (0..5)
            .map(|i| {
                let mut t = synthetic_trace(Env::Pooltool, i, 30, 2);
                for (s, ts) in t.timesteps.iter_mut().enumerate() {
                    for o in &mut ts.objects {
                        if let crate::trace::Body::Pool(b) = &mut o.body {
                            b.position[0] += (i as f64) * 0.2 * (s as f64) / 30.0
                                * if s > 15 { 1.0 } else { 0.0 };
                        }
                    }
                }
                t
            })
            .collect()
    }

    #[test]
    fn failed_children_are_repaired_and_rounds_replay_from_a_checkpoint() {
        let traces = traces();
        let pool = WorkerPool::new(SandboxLimits {
            workers: 1,
            ..SandboxLimits::default()
        })
        .unwrap();
        let dx = DistanceMatrix::compute(&traces, 16);
        let library = LibraryView::default();
        let evaluator = Evaluator {
            pool: &pool,
            env: Env::Pooltool,
            label: "moving".into(),
            traces: &traces,
            dx: &dx,
            library: &library,
            settings: EvalSettings {
                probe: 2,
                time_penalty: false,
                ..EvalSettings::default()
            },
        };
        let seed = skeleton(Env::Pooltool, "moving");
        let good = seed.replace("THRESHOLD = 0.05", "THRESHOLD = 0.5");
        let proposer = Scripted {
            good: good.clone(),
            calls: Mutex::new(Vec::new()),
        };
        let config = SearchConfig {
            budget: 2,
            parallel: 1,
            ..SearchConfig::default()
        };
        let checkpoint = MemoryCheckpoint::default();
        let search = LabelSearch {
            config: &config,
            label_index: 0,
            evaluator: &evaluator,
            proposer: &proposer,
            seeds: vec![seed],
            library_labels: Vec::new(),
            checkpoint: &checkpoint,
        };
        let out = search.run().unwrap();
        assert_eq!(out.records.len(), 3);
        let first = &out.records[1];
        assert_eq!(first.repairs, 1, "{first:?}");
        assert_eq!(first.code, good);
        assert!(
            matches!(
                first.status.as_str(),
                "ok" | "degenerate" | "same_behaviour"
            ),
            "{first:?}"
        );
        assert_eq!((first.tokens_in, first.tokens_out, first.calls), (13, 7, 2));
        // The second child repairs to the same code: a duplicate, not evaluated again.
        assert_eq!(out.records[2].status, "duplicate");
        assert_eq!(
            *proposer.calls.lock().unwrap(),
            vec![
                "propose 0",
                "repair 1 syntax",
                "propose 1",
                "repair 1 syntax"
            ]
        );
        assert_eq!(out.best_by_step.len(), 2);
        // A second run over the same checkpoint replays every round: the proposer is not asked again.
        let again = Scripted {
            good,
            calls: Mutex::new(Vec::new()),
        };
        let search = LabelSearch {
            proposer: &again,
            ..search
        };
        let replay = search.run().unwrap();
        assert_eq!(replay.records, out.records);
        assert!(again.calls.lock().unwrap().is_empty());
    }

    /// A deterministic proposer whose child depends on its first parent and the request's seed (the
    /// parent's `THRESHOLD` scaled), answering after a delay that varies with the seed when `delay`
    /// is set; records the steps it was asked for.
    struct FromParent {
        delay: bool,
        asked: Mutex<Vec<u64>>,
        /// (step, asked at, answered at) of every proposal.
        times: Mutex<Vec<(u64, Instant, Instant)>>,
    }

    impl FromParent {
        fn new(delay: bool) -> Self {
            FromParent {
                delay,
                asked: Mutex::new(Vec::new()),
                times: Mutex::new(Vec::new()),
            }
        }
    }

    impl Proposer for FromParent {
        fn name(&self) -> &str {
            "from-parent"
        }
        fn propose(&self, req: &ProposalRequest) -> Result<Proposal, ProposeError> {
            self.asked.lock().unwrap().push(req.step);
            let asked = Instant::now();
            if self.delay {
                std::thread::sleep(std::time::Duration::from_millis(req.seed % 7 * 15));
            }
            self.times
                .lock()
                .unwrap()
                .push((req.step, asked, Instant::now()));
            let parent = &req.parents[0].code;
            let (head, rest) = parent.split_once("THRESHOLD = ").expect("a threshold");
            let (value, tail) = rest.split_once('\n').expect("a line");
            let t: f64 = value.parse().expect("a number");
            let factor = 0.4 + (req.seed % 1000) as f64 / 800.0;
            Ok(Proposal {
                code: format!("{head}THRESHOLD = {:.6}\n{tail}", t * factor),
                ..Proposal::default()
            })
        }
        fn repair(
            &self,
            _: &ProposalRequest,
            _: &str,
            _: &DetectorError,
            _: u32,
        ) -> Result<Option<Proposal>, ProposeError> {
            Ok(None)
        }
    }

    /// What a search decided, without the wall times.
    fn decisions(records: &[CandidateRecord]) -> Vec<String> {
        records
            .iter()
            .map(|r| {
                format!(
                    "{} {} {:?} {} {} {:?} {:?}",
                    r.step, r.island, r.parents, r.code_hash, r.status, r.terms, r.signature
                )
            })
            .collect()
    }

    #[test]
    fn a_lagged_search_is_the_same_overlapped_or_not_and_resumes_without_asking_again() {
        let traces = traces();
        let pool = WorkerPool::new(SandboxLimits {
            workers: 2,
            ..SandboxLimits::default()
        })
        .unwrap();
        let dx = DistanceMatrix::compute(&traces, 16);
        let library = LibraryView::default();
        let evaluator = Evaluator {
            pool: &pool,
            env: Env::Pooltool,
            label: "moving".into(),
            traces: &traces,
            dx: &dx,
            library: &library,
            settings: EvalSettings {
                probe: 2,
                time_penalty: false,
                ..EvalSettings::default()
            },
        };
        let run = |config: &SearchConfig, proposer: &FromParent, checkpoint: &MemoryCheckpoint| {
            LabelSearch {
                config,
                label_index: 0,
                evaluator: &evaluator,
                proposer,
                seeds: vec![skeleton(Env::Pooltool, "moving")],
                library_labels: Vec::new(),
                checkpoint,
            }
            .run()
        };
        let lagged = SearchConfig {
            budget: 12,
            parallel: 3,
            islands: 2,
            lag: 1,
            seed: 5,
            ..SearchConfig::default()
        };
        // Overlapped, with answers arriving in a different order than they were asked.
        let slow = FromParent::new(true);
        let overlapped = run(&lagged, &slow, &MemoryCheckpoint::default()).unwrap();
        assert_eq!(overlapped.records.len(), 13);
        // Round 1's requests went out alone: round 2's (steps 3–5) only once step 0 was answered,
        // so they cannot take the endpoint's free slots from round 1's.
        let times = slow.times.lock().unwrap().clone();
        let step0 = times.iter().find(|t| t.0 == 0).expect("step 0").2;
        for &(step, asked, _) in times.iter().filter(|t| (3..6).contains(&t.0)) {
            assert!(
                asked >= step0,
                "step {step} was asked before step 0's answer"
            );
        }
        assert!(overlapped.propose_s > 0.0 && overlapped.propose_s <= overlapped.wall_s);
        // The same schedule one phase after the other: the same search.
        let sequential = SearchConfig {
            overlap: false,
            ..lagged.clone()
        };
        let fast = FromParent::new(false);
        let plain = run(&sequential, &fast, &MemoryCheckpoint::default()).unwrap();
        assert_eq!(decisions(&plain.records), decisions(&overlapped.records));
        assert_eq!(plain.best.hash, overlapped.best.hash);
        assert_eq!(plain.best_by_step, overlapped.best_by_step);
        // Killed when round 2 is saved (round 3's requests are in flight): the resumed search
        // replays rounds 0–2 (steps 0–5), asks for rounds 3 and 4 only (round 3 again), and ends
        // where the uninterrupted one did.
        let checkpoint = MemoryCheckpoint {
            stop_after: Some(3),
            ..MemoryCheckpoint::default()
        };
        let first = FromParent::new(true);
        assert!(matches!(
            run(&lagged, &first, &checkpoint),
            Err(SearchError::Checkpoint(_))
        ));
        let checkpoint = MemoryCheckpoint {
            rounds: Mutex::new(checkpoint.rounds.into_inner().unwrap()),
            stop_after: None,
        };
        let again = FromParent::new(true);
        let resumed = run(&lagged, &again, &checkpoint).unwrap();
        assert_eq!(decisions(&resumed.records), decisions(&overlapped.records));
        let mut asked = again.asked.into_inner().unwrap();
        asked.sort_unstable();
        assert_eq!(asked, (6..12).collect::<Vec<u64>>());
        // Lag 0 plans every round from the round before: round 2 already sees round 1's children.
        let unlagged = SearchConfig {
            lag: 0,
            ..lagged.clone()
        };
        let zero = run(
            &unlagged,
            &FromParent::new(false),
            &MemoryCheckpoint::default(),
        )
        .unwrap();
        assert_eq!(zero.records.len(), 13);
    }
}
