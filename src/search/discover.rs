//! Algorithm 2 of the paper (DiscoverPatternDetectors): one search per label, in order; the best
//! program joins the library when its ν exceeds δ **and** its ρ on the held-out traces is positive
//! (unless `allow_nonpositive_rho`), and later labels are scored for novelty against the grown
//! library. Also the convergence measurement of section 4.5 on held-out traces.
//!
//! **Held-out ρ.** The best program is run on the held-out traces and ρ is recomputed there against
//! their own D_x ([`Discovery::holdout_dx`]); a held-out trace it fails on counts as no activation.
//! With fewer than [`MIN_HOLDOUT`] held-out traces there is no held-out ρ and the training ρ decides.
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
}

impl Acceptance {
    /// `accepted`, `below_delta` or `nonpositive_rho`.
    pub fn as_str(self) -> &'static str {
        match self {
            Acceptance::Accepted => "accepted",
            Acceptance::BelowDelta => "below_delta",
            Acceptance::NonpositiveRho => "nonpositive_rho",
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
                seeds,
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
            let acceptance = Acceptance::decide(
                outcome.best.terms.nu,
                self.config.delta,
                holdout_rho.unwrap_or(outcome.best.terms.rho),
                self.config.allow_nonpositive_rho,
            );
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
            let convergence = if self.convergence_per_bin > 0 && !self.holdout.is_empty() {
                self.convergence(&det_label, &outcome.records)
            } else {
                Vec::new()
            };
            let result = LabelResult {
                outcome,
                accepted,
                acceptance,
                holdout_rho,
                train_hists,
                holdout_hists,
                convergence,
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

    /// Section 4.5: detectors from each 10 % bin of the search compared with those of the final bin.
    pub fn convergence(&self, label: &str, records: &[CandidateRecord]) -> Vec<ConvergenceRow> {
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
            return Vec::new();
        };
        let chosen: Vec<(u32, CandidateRecord)> = (0..=last)
            .flat_map(|b| pick(&bins[b]).into_iter().map(move |r| (b as u32, r)))
            .collect();
        let dets: Vec<Detector> = chosen
            .iter()
            .map(|(_, r)| Detector::new(self.env, label, &r.code, "convergence"))
            .collect();
        let batch = self.pool.run(&dets, self.holdout);
        // hists[detector][trace], None where the call failed.
        let mut hists = vec![vec![None; self.holdout.len()]; dets.len()];
        for r in &batch.results {
            if r.status != CandidateStatus::Ok {
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
            hists[r.detector][r.trace] = Some(histogram(&a, self.eval.bins));
        }
        let finals: Vec<usize> = (0..chosen.len())
            .filter(|&i| chosen[i].0 == last as u32)
            .collect();
        let mut out = Vec::new();
        for (i, (bin, r)) in chosen.iter().enumerate() {
            for &f in &finals {
                let (mut sum, mut n) = (0.0, 0u64);
                for (a, b) in hists[i].iter().zip(&hists[f]) {
                    if let (Some(p), Some(q)) = (a, b) {
                        sum += similarity(p, q);
                        n += 1;
                    }
                }
                if n > 0 {
                    out.push(ConvergenceRow {
                        label: label.to_string(),
                        bin: *bin,
                        code_hash: r.code_hash.clone(),
                        final_hash: chosen[f].1.code_hash.clone(),
                        similarity: sum / n as f64,
                        traces: n,
                    });
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::Acceptance;

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
}
