//! Algorithm 2 of the paper (DiscoverPatternDetectors): one search per label, in order; the best
//! program joins the library when its ν exceeds δ **and** its ρ on the held-out traces is positive
//! (unless `allow_nonpositive_rho`), and later labels are scored for novelty against the grown
//! library. Also the convergence measurement of section 4.5 on held-out traces.
//!
//! **Held-out ρ.** The best program is run on the held-out traces and ρ is recomputed there against
//! their own D_x ([`Discovery::holdout_dx`]); a held-out trace it fails on counts as no activation.
//! With fewer than [`MIN_HOLDOUT`] held-out traces there is no held-out ρ and the training ρ decides.
//!
//! **Accuracy guard** (optional, beyond the paper). Fitness is not meaning: a child with higher ν
//! and positive held-out ρ can fire on other moments than the label names. With
//! [`AccuracyGuard`] set, a best program of an event-grounded label (`detect::accuracy::grounded`)
//! that passed the ν and ρ tests is also scored against the simulator's ground truth on the held-out
//! traces (the training traces when there are none), next to the label's seed program(s); when its
//! F1 is lower than theirs by more than `max_drop` it is rejected (`accuracy_drop`).
//!
//! **Sampled candidates.** The convergence measurement runs up to `convergence_per_bin` scored
//! candidates of every 10 % bin on the held-out traces; their held-out histograms and ρ are kept
//! ([`SampleRow`]) so SQL can recompute both ρ and the convergence similarity. A held-out trace a
//! sampled candidate fails on counts as no activation (as for the best program's held-out ρ).
//!
//! The seed programs of a label are the library's detectors for that label (when it has some), which
//! are left out of the library the label's candidates are compared with (a detector is not novel with
//! respect to itself); otherwise the skeleton g₀. An accepted program replaces the library's detectors
//! of its label.

use super::candidate::CandidateRecord;
use super::evaluator::{EvalSettings, Evaluator, library_view};
use super::proposer::Proposer;
use super::run::{Checkpoint, LabelOutcome, LabelSearch, SearchConfig, SearchError};
use super::skeleton::skeleton;
use crate::detect::{CandidateStatus, Detector, WorkerPool};
use crate::fitness::histogram::{activation, histogram, similarity};
use crate::fitness::{DistanceMatrix, correlation};
use crate::trace::{Env, Trace};

/// One pair of the convergence measurement: a detector of bin `bin` against one of the final bin.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ConvergenceRow {
    /// The label.
    pub label: String,
    /// The 10 % bin of the search budget (0–9) the detector comes from.
    pub bin: u32,
    /// The detector's code hash.
    pub code_hash: String,
    /// The final-bin detector's code hash.
    pub final_hash: String,
    /// Mean annotation similarity over the held-out traces ([`similarity`]).
    pub similarity: f64,
    /// Held-out traces compared.
    pub traces: u64,
}

/// One candidate sampled for the convergence measurement, run on the held-out traces.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SampleRow {
    /// The label.
    pub label: String,
    /// The 10 % bin of the search budget (0–9).
    pub bin: u32,
    /// Its search step.
    pub step: i64,
    /// Its code hash.
    pub code_hash: String,
    /// Its ν on the training traces.
    pub nu: f64,
    /// Its ρ on the training traces.
    pub rho: f64,
    /// Its ρ on the held-out traces (`None` with fewer than [`MIN_HOLDOUT`] of them).
    pub holdout_rho: Option<f64>,
    /// Held-out traces it failed on (counted as no activation).
    pub failed_traces: u64,
    /// Its smoothed activation histograms on the held-out traces (held-out order).
    pub hists: Vec<Vec<f64>>,
}

/// The optional accuracy guard of acceptance (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccuracyGuard {
    /// The largest F1 drop (seed − best) still accepted.
    pub max_drop: f64,
    /// Time tolerance (s) of the matching, as the `accuracy` stage's.
    pub tolerance: f64,
}

/// F1 of the seed and the best program against ground truth, as the guard measured it.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GuardCheck {
    /// F1 of the label's seed program(s).
    pub seed_f1: f64,
    /// F1 of the best program.
    pub best_f1: f64,
    /// Traces scored (scorable held-out traces, else scorable training traces).
    pub traces: u64,
}

/// Fewest held-out traces for a held-out ρ: 8 traces make 28 pairs; a correlation over fewer pairs is
/// mostly noise (3 traces, 3 pairs, gave ρ from −0.9 to 0.9 for the same detector).
pub const MIN_HOLDOUT: usize = 8;

/// Why a label's best program did or did not join the library.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Acceptance {
    /// ν > δ and ρ > 0 (or ρ ≤ 0 allowed by `allow_nonpositive_rho`).
    Accepted,
    /// ν ≤ δ.
    BelowDelta,
    /// ν > δ but ρ ≤ 0 (held-out ρ, or the training ρ without a held-out set).
    NonpositiveRho,
    /// ν > δ and ρ > 0, but with the accuracy guard on, its F1 against ground truth fell by more than
    /// the guard allows.
    AccuracyDrop,
}

impl Acceptance {
    /// `accepted`, `below_delta` or `nonpositive_rho`.
    pub fn as_str(self) -> &'static str {
        match self {
            Acceptance::Accepted => "accepted",
            Acceptance::BelowDelta => "below_delta",
            Acceptance::NonpositiveRho => "nonpositive_rho",
            Acceptance::AccuracyDrop => "accuracy_drop",
        }
    }

    /// Algorithm 2's test with the ρ guard: `rho` is the held-out ρ when there is one, else the
    /// training ρ.
    pub fn decide(nu: f64, delta: f64, rho: f64, allow_nonpositive_rho: bool) -> Acceptance {
        if nu.is_nan() || nu <= delta {
            Acceptance::BelowDelta
        } else if !allow_nonpositive_rho && (rho.is_nan() || rho <= 0.0) {
            Acceptance::NonpositiveRho
        } else {
            Acceptance::Accepted
        }
    }

    /// The accuracy guard on top of [`Acceptance::decide`]: an accepted program whose F1 is below the
    /// seed's by more than `max_drop` becomes [`Acceptance::AccuracyDrop`].
    pub fn guard(self, check: Option<&GuardCheck>, max_drop: f64) -> Acceptance {
        match (self, check) {
            (Acceptance::Accepted, Some(c)) if c.seed_f1 - c.best_f1 > max_drop => {
                Acceptance::AccuracyDrop
            }
            (a, _) => a,
        }
    }
}

/// The result of one label.
#[derive(Clone, Debug)]
pub struct LabelResult {
    /// The search's outcome.
    pub outcome: LabelOutcome,
    /// Whether the best program joined the library (see [`Acceptance`]).
    pub accepted: bool,
    /// The acceptance decision and its reason.
    pub acceptance: Acceptance,
    /// ρ of the best program on the held-out traces (`None` with fewer than [`MIN_HOLDOUT`]).
    pub holdout_rho: Option<f64>,
    /// The best program's activation histograms on the training traces (training order), as ρ and η
    /// saw them: the `evolution_histograms` rows, from which SQL recomputes ρ.
    pub train_hists: Vec<Vec<f64>>,
    /// Its histograms on the held-out traces (empty with fewer than [`MIN_HOLDOUT`]).
    pub holdout_hists: Vec<Vec<f64>>,
    /// Convergence pairs on the held-out traces (empty without held-out traces).
    pub convergence: Vec<ConvergenceRow>,
    /// The candidates the convergence measurement sampled, with their held-out histograms and ρ.
    pub samples: Vec<SampleRow>,
    /// The accuracy guard's measurement (`None` when the guard is off, the label is not
    /// event-grounded, the best program is a seed program, or no trace is scorable).
    pub guard: Option<GuardCheck>,
}

/// Everything the discovery loop needs.
pub struct Discovery<'a> {
    /// The sandboxed workers.
    pub pool: &'a WorkerPool,
    /// The environment.
    pub env: Env,
    /// Training traces (D_x order).
    pub train: &'a [Trace],
    /// Held-out traces (the acceptance ρ and the convergence statistics).
    pub holdout: &'a [Trace],
    /// D_x of the training traces.
    pub dx: &'a DistanceMatrix,
    /// D_x of the held-out traces (empty when there are fewer than [`MIN_HOLDOUT`]).
    pub holdout_dx: &'a DistanceMatrix,
    /// Search knobs.
    pub config: &'a SearchConfig,
    /// Evaluation settings.
    pub eval: EvalSettings,
    /// Makes children.
    pub proposer: &'a dyn Proposer,
    /// Keeps finished rounds.
    pub checkpoint: &'a dyn Checkpoint,
    /// Where accepted detectors say they came from (`evolve:<stage>`).
    pub source: String,
    /// Detectors sampled per 10 % bin for the convergence measurement (0 = skip it).
    pub convergence_per_bin: usize,
    /// The accuracy guard of acceptance (`None`: off).
    pub accuracy_guard: Option<AccuracyGuard>,
}

impl Discovery<'_> {
    /// Runs Algorithm 2 from library `base` over `labels`; `after_label` sees each label's result as soon
    /// as it is known (to persist it). Returns the grown library and every label's result.
    pub fn run(
        &self,
        base: Vec<Detector>,
        labels: &[String],
        after_label: &mut dyn FnMut(u32, &LabelResult) -> Result<(), SearchError>,
    ) -> Result<(Vec<Detector>, Vec<LabelResult>), SearchError> {
        let mut library = base;
        let mut results = Vec::new();
        for (m, label) in labels.iter().enumerate() {
            let own: Vec<&Detector> = library.iter().filter(|d| d.accepts_label(label)).collect();
            let seeds: Vec<String> = if own.is_empty() {
                vec![skeleton(self.env, label)]
            } else {
                own.iter().map(|d| d.code.clone()).collect()
            };
            let det_label = own.first().map_or(label.clone(), |d| d.label.clone());
            let others: Vec<Detector> = library
                .iter()
                .filter(|d| !d.accepts_label(label))
                .cloned()
                .collect();
            let view = library_view(self.pool, &others, self.train, self.eval.bins);
            let evaluator = Evaluator {
                pool: self.pool,
                env: self.env,
                label: det_label.clone(),
                traces: self.train,
                dx: self.dx,
                library: &view,
                settings: self.eval.clone(),
            };
            let search = LabelSearch {
                config: self.config,
                label_index: m as u32,
                evaluator: &evaluator,
                proposer: self.proposer,
                seeds: seeds.clone(),
                library_labels: others.iter().map(|d| d.label.clone()).collect(),
                checkpoint: self.checkpoint,
            };
            let outcome = search.run()?;
            let train_hists = self.histograms(&det_label, &outcome.best.code, self.train);
            let holdout_hists = if self.holdout.len() >= MIN_HOLDOUT
                && self.holdout_dx.len() == self.holdout.len()
            {
                self.histograms(&det_label, &outcome.best.code, self.holdout)
            } else {
                Vec::new()
            };
            let holdout_rho = (!holdout_hists.is_empty())
                .then(|| correlation(self.holdout_dx, &holdout_hists, self.eval.dp));
            let mut acceptance = Acceptance::decide(
                outcome.best.terms.nu,
                self.config.delta,
                holdout_rho.unwrap_or(outcome.best.terms.rho),
                self.config.allow_nonpositive_rho,
            );
            let guard = match self.accuracy_guard {
                Some(g) if acceptance == Acceptance::Accepted => {
                    let check = self.guard_check(&det_label, &seeds, &outcome.best.code, g);
                    acceptance = acceptance.guard(check.as_ref(), g.max_drop);
                    check
                }
                _ => None,
            };
            let accepted = acceptance == Acceptance::Accepted;
            if accepted {
                let aliases = own.first().map(|d| d.aliases.clone()).unwrap_or_default();
                let weight = own.first().map_or(1.0, |d| d.weight);
                library.retain(|d| !d.accepts_label(label));
                let mut d = Detector::new(self.env, &det_label, &outcome.best.code, &self.source);
                d.aliases = aliases;
                d.weight = weight;
                library.push(d);
            }
            let (convergence, samples) = if self.convergence_per_bin > 0 && !self.holdout.is_empty()
            {
                self.convergence(&det_label, &outcome.records)
            } else {
                (Vec::new(), Vec::new())
            };
            let result = LabelResult {
                outcome,
                accepted,
                acceptance,
                holdout_rho,
                train_hists,
                holdout_hists,
                convergence,
                samples,
                guard,
            };
            after_label(m as u32, &result)?;
            results.push(result);
        }
        Ok((library, results))
    }

    /// The activation histograms of `code` on `traces` (a trace it fails on counts as no activation).
    pub fn histograms(&self, label: &str, code: &str, traces: &[Trace]) -> Vec<Vec<f64>> {
        let det = Detector::new(self.env, label, code, "best");
        let batch = self.pool.run(std::slice::from_ref(&det), traces);
        let mut hists = vec![histogram(&[], self.eval.bins); traces.len()];
        for r in &batch.results {
            if r.status != CandidateStatus::Ok {
                continue;
            }
            let steps: Vec<i64> = traces[r.trace].timesteps.iter().map(|t| t.index).collect();
            let a = activation(
                &steps,
                r.patterns.iter().map(|p| (p.start_step, p.end_step)),
            );
            hists[r.trace] = histogram(&a, self.eval.bins);
        }
        hists
    }

    /// The accuracy guard's F1 of the seed program(s) and of `best` for `label` (see the module docs);
    /// `None` when the label is not event-grounded in the environment, `best` is a seed, or no trace
    /// is scorable.
    pub fn guard_check(
        &self,
        label: &str,
        seeds: &[String],
        best: &str,
        guard: AccuracyGuard,
    ) -> Option<GuardCheck> {
        use crate::detect::accuracy::{grounded, scorable, score_trace, truth};
        use crate::detect::{Annotation, normalise_label};
        if seeds.iter().any(|s| s == best) {
            return None;
        }
        let norm = normalise_label(label);
        let g = grounded(self.env)
            .iter()
            .copied()
            .find(|g| normalise_label(g) == norm)?;
        let pick = if self.holdout.is_empty() {
            self.train
        } else {
            self.holdout
        };
        let traces: Vec<Trace> = pick
            .iter()
            .filter(|t| scorable(self.env, t))
            .cloned()
            .collect();
        if traces.is_empty() {
            return None;
        }
        let mut dets: Vec<Detector> = seeds
            .iter()
            .map(|c| Detector::new(self.env, label, c, "seed"))
            .collect();
        dets.push(Detector::new(self.env, label, best, "best"));
        let batch = self.pool.run(&dets, &traces);
        let n_seeds = seeds.len();
        let f1 = |best_side: bool| -> f64 {
            let mut scores = std::collections::BTreeMap::new();
            for (ti, t) in traces.iter().enumerate() {
                let anns: Vec<Annotation> = batch
                    .results
                    .iter()
                    .filter(|r| {
                        r.trace == ti
                            && r.status == CandidateStatus::Ok
                            && (r.detector >= n_seeds) == best_side
                    })
                    .flat_map(|r| {
                        r.patterns
                            .iter()
                            .enumerate()
                            .map(|(seq, p)| Annotation::new(&dets[r.detector], t, seq, p.clone()))
                    })
                    .collect();
                let refs: Vec<&Annotation> = anns.iter().collect();
                let events: Vec<_> = truth(self.env, t, guard.tolerance)
                    .into_iter()
                    .filter(|e| e.label == g)
                    .collect();
                score_trace(&[g], &events, &refs, guard.tolerance, &mut scores);
            }
            scores
                .get(g)
                .map_or(0.0, crate::detect::accuracy::LabelScore::f1)
        };
        Some(GuardCheck {
            seed_f1: f1(false),
            best_f1: f1(true),
            traces: traces.len() as u64,
        })
    }

    /// Section 4.5: detectors from each 10 % bin of the search compared with those of the final bin,
    /// and the sampled detectors' held-out histograms and ρ.
    pub fn convergence(
        &self,
        label: &str,
        records: &[CandidateRecord],
    ) -> (Vec<ConvergenceRow>, Vec<SampleRow>) {
        let budget = self.config.budget.max(1);
        let mut bins: Vec<Vec<&CandidateRecord>> = vec![Vec::new(); 10];
        for r in records.iter().filter(|r| r.step >= 0 && r.status == "ok") {
            let b = ((r.step as u64 * 10) / budget).min(9) as usize;
            bins[b].push(r);
        }
        let k = self.convergence_per_bin;
        let pick = |v: &Vec<&CandidateRecord>| -> Vec<CandidateRecord> {
            if v.len() <= k {
                return v.iter().map(|r| (*r).clone()).collect();
            }
            (0..k).map(|i| v[i * v.len() / k].clone()).collect()
        };
        let Some(last) = (0..10).rev().find(|&b| !bins[b].is_empty()) else {
            return (Vec::new(), Vec::new());
        };
        let chosen: Vec<(u32, CandidateRecord)> = (0..=last)
            .flat_map(|b| pick(&bins[b]).into_iter().map(move |r| (b as u32, r)))
            .collect();
        let dets: Vec<Detector> = chosen
            .iter()
            .map(|(_, r)| Detector::new(self.env, label, &r.code, "convergence"))
            .collect();
        let batch = self.pool.run(&dets, self.holdout);
        // hists[detector][trace]; a failed call counts as no activation.
        let silent = histogram(&[], self.eval.bins);
        let mut hists = vec![vec![silent; self.holdout.len()]; dets.len()];
        let mut failed = vec![0u64; dets.len()];
        for r in &batch.results {
            if r.status != CandidateStatus::Ok {
                failed[r.detector] += 1;
                continue;
            }
            let steps: Vec<i64> = self.holdout[r.trace]
                .timesteps
                .iter()
                .map(|t| t.index)
                .collect();
            let a = activation(
                &steps,
                r.patterns.iter().map(|p| (p.start_step, p.end_step)),
            );
            hists[r.detector][r.trace] = histogram(&a, self.eval.bins);
        }
        let finals: Vec<usize> = (0..chosen.len())
            .filter(|&i| chosen[i].0 == last as u32)
            .collect();
        let mut out = Vec::new();
        for (i, (bin, r)) in chosen.iter().enumerate() {
            for &f in &finals {
                let n = hists[i].len();
                let sum: f64 = hists[i]
                    .iter()
                    .zip(&hists[f])
                    .map(|(p, q)| similarity(p, q))
                    .sum();
                if n > 0 {
                    out.push(ConvergenceRow {
                        label: label.to_string(),
                        bin: *bin,
                        code_hash: r.code_hash.clone(),
                        final_hash: chosen[f].1.code_hash.clone(),
                        similarity: sum / n as f64,
                        traces: n as u64,
                    });
                }
            }
        }
        let with_rho =
            self.holdout.len() >= MIN_HOLDOUT && self.holdout_dx.len() == self.holdout.len();
        let samples = chosen
            .into_iter()
            .zip(hists)
            .zip(failed)
            .map(|(((bin, r), h), failed_traces)| SampleRow {
                label: label.to_string(),
                bin,
                step: r.step,
                nu: r.terms.as_ref().map_or(f64::NAN, |t| t.nu),
                rho: r.terms.as_ref().map_or(f64::NAN, |t| t.rho),
                holdout_rho: with_rho.then(|| correlation(self.holdout_dx, &h, self.eval.dp)),
                code_hash: r.code_hash,
                failed_traces,
                hists: h,
            })
            .collect();
        (out, samples)
    }
}

#[cfg(test)]
mod tests {
    use super::{Acceptance, GuardCheck};

    #[test]
    fn acceptance_needs_nu_above_delta_and_positive_rho_unless_allowed() {
        let d = Acceptance::decide;
        assert_eq!(d(0.5, 0.0, 0.2, false), Acceptance::Accepted);
        assert_eq!(d(0.0, 0.0, 0.2, false), Acceptance::BelowDelta);
        assert_eq!(d(f64::NAN, 0.0, 0.2, false), Acceptance::BelowDelta);
        // The quickstart's old case: ν high from η alone, ρ = −0.06.
        assert_eq!(d(2.5, 0.0, -0.06, false), Acceptance::NonpositiveRho);
        assert_eq!(d(2.5, 0.0, 0.0, false), Acceptance::NonpositiveRho);
        assert_eq!(d(2.5, 0.0, f64::NAN, false), Acceptance::NonpositiveRho);
        assert_eq!(d(2.5, 0.0, -0.06, true), Acceptance::Accepted);
        assert_eq!(d(-1.0, 0.0, 0.9, true), Acceptance::BelowDelta);
    }

    #[test]
    fn the_accuracy_guard_rejects_only_an_accepted_program_whose_f1_fell_too_far() {
        let c = |seed_f1, best_f1| GuardCheck {
            seed_f1,
            best_f1,
            traces: 10,
        };
        let a = Acceptance::Accepted;
        // "gentle touch" of learn-pooltool: 1.000 → 0.007.
        assert_eq!(a.guard(Some(&c(1.0, 0.007)), 0.1), Acceptance::AccuracyDrop);
        assert_eq!(
            a.guard(Some(&c(0.985, 0.878)), 0.1),
            Acceptance::AccuracyDrop
        );
        assert_eq!(a.guard(Some(&c(0.985, 0.9)), 0.1), Acceptance::Accepted);
        assert_eq!(a.guard(Some(&c(0.5, 0.9)), 0.1), Acceptance::Accepted);
        assert_eq!(a.guard(None, 0.1), Acceptance::Accepted);
        let r = Acceptance::NonpositiveRho;
        assert_eq!(r.guard(Some(&c(1.0, 0.0)), 0.1), Acceptance::NonpositiveRho);
        assert_eq!(Acceptance::AccuracyDrop.as_str(), "accuracy_drop");
    }
}
