//! Scoring a candidate program: the cheap checks, then Evaluate (Algorithm 3) on the training set, all in
//! the sandboxed [`WorkerPool`] (candidate code never runs in this process).
//!
//! Order of work for one candidate: run it on the *probe set* (the first `probe` training traces); any
//! failure there (syntax, forbidden construct, exception, timeout, invalid output) ends the evaluation
//! early. The probe activations are hashed into a *behaviour signature*; a candidate behaving exactly
//! like one already evaluated in this search is not evaluated further. Otherwise it runs on the remaining
//! traces (a failure on any of them fails the candidate). A degenerate pattern (active nowhere, or
//! everywhere) is recorded but not scored; otherwise its histograms are scored against the training
//! set's D_x and the library's histograms.

use std::collections::HashMap;

use sha2::{Digest, Sha256};

use crate::detect::{BatchResult, CandidateStatus, Detector, DetectorError, WorkerPool};
use crate::fitness::histogram::{activation, histogram};
use crate::fitness::{CandidateOutput, DistanceMatrix, Dp, FitnessTerms, LibraryView, evaluate};
use crate::trace::{Env, Trace};

/// Settings of candidate evaluation.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalSettings {
    /// Time bins b of the annotation histograms.
    pub bins: usize,
    /// The annotation distance d_p of ρ and η.
    pub dp: Dp,
    /// Training traces in the probe set.
    pub probe: usize,
    /// Whether ψ is computed (off makes scores independent of machine load).
    pub time_penalty: bool,
}

impl EvalSettings {
    /// The defaults.
    pub const DEFAULT: EvalSettings = EvalSettings {
        bins: crate::fitness::histogram::DEFAULT_BINS,
        dp: Dp::Kl,
        probe: 8,
        time_penalty: true,
    };
}

impl Default for EvalSettings {
    fn default() -> Self {
        EvalSettings::DEFAULT
    }
}

/// What evaluating one candidate found.
#[derive(Clone, Debug, PartialEq)]
pub enum Evaluation {
    /// It failed on a probe or training trace (`on_probe` tells which).
    Failed {
        /// The first failure.
        error: DetectorError,
        /// Whether it failed on the probe set (early stop).
        on_probe: bool,
    },
    /// It behaves exactly like an earlier candidate on the probe set.
    SameBehaviour {
        /// The earlier candidate's code hash.
        of: String,
        /// The behaviour signature.
        signature: String,
    },
    /// It ran on every training trace but its pattern is degenerate: active nowhere, or at every
    /// timestep of every trace. Such a pattern says nothing about the traces (ρ = 0) while its histograms
    /// differ maximally from the library's (a large η), so it is not scored and never becomes a parent.
    Degenerate {
        /// `silent` or `always on`.
        reason: &'static str,
        /// Mean wall time per trace (s).
        mean_time: f64,
        /// Fraction of training traces where it reports at least one pattern.
        activation_rate: f64,
        /// The behaviour signature.
        signature: String,
    },
    /// It was scored.
    Scored {
        /// Every fitness term.
        terms: FitnessTerms,
        /// Mean wall time per trace (s).
        mean_time: f64,
        /// Fraction of training traces where it reports at least one pattern.
        activation_rate: f64,
        /// The behaviour signature.
        signature: String,
    },
}

/// Per trace: the activation vector, the wall time (s) and the number of patterns.
type Activations = (Vec<Vec<bool>>, Vec<f64>, Vec<usize>);

/// The per-trace activations of detector 0 of a batch, or its first failure.
fn activations(batch: &BatchResult, traces: &[Trace]) -> Result<Activations, DetectorError> {
    let mut act = vec![Vec::new(); traces.len()];
    let mut time = vec![0.0; traces.len()];
    let mut count = vec![0usize; traces.len()];
    for r in &batch.results {
        if let CandidateStatus::Failed(e) = &r.status {
            return Err(e.clone());
        }
        let steps: Vec<i64> = traces[r.trace].timesteps.iter().map(|t| t.index).collect();
        act[r.trace] = activation(
            &steps,
            r.patterns.iter().map(|p| (p.start_step, p.end_step)),
        );
        time[r.trace] = r.wall_s;
        count[r.trace] = r.patterns.len();
    }
    Ok((act, time, count))
}

/// Scores candidates for one label against one training set and library.
pub struct Evaluator<'a> {
    /// The worker pool.
    pub pool: &'a WorkerPool,
    /// The environment.
    pub env: Env,
    /// The label being learned.
    pub label: String,
    /// The training traces (D_x order).
    pub traces: &'a [Trace],
    /// D_x of the training traces.
    pub dx: &'a DistanceMatrix,
    /// The current library on the training traces.
    pub library: &'a LibraryView,
    /// Settings.
    pub settings: EvalSettings,
}

impl Evaluator<'_> {
    /// Evaluates `code` (with `lines` lines); `known` maps behaviour signatures seen in this search to
    /// the code hash that first showed them. `seed` scores a degenerate pattern anyway (a seed program
    /// must found the islands).
    pub fn evaluate(
        &self,
        code: &str,
        lines: usize,
        known: &HashMap<String, String>,
        seed: bool,
    ) -> Evaluation {
        let det = Detector::new(self.env, &self.label, code, "evolve");
        let p = self
            .settings
            .probe
            .clamp(1, self.traces.len().max(1))
            .min(self.traces.len());
        let (probe, rest) = self.traces.split_at(p);
        let first = self.pool.run(std::slice::from_ref(&det), probe);
        let (mut act, mut time, mut count) = match activations(&first, probe) {
            Ok(x) => x,
            Err(error) => {
                return Evaluation::Failed {
                    error,
                    on_probe: true,
                };
            }
        };
        let mut h = Sha256::new();
        for a in &act {
            h.update((a.len() as u64).to_le_bytes());
            h.update(a.iter().map(|&b| u8::from(b)).collect::<Vec<u8>>());
        }
        let signature = crate::digest::hex(&h.finalize()[..8]);
        if let Some(of) = known.get(&signature) {
            return Evaluation::SameBehaviour {
                of: of.clone(),
                signature,
            };
        }
        if !rest.is_empty() {
            let second = self.pool.run(std::slice::from_ref(&det), rest);
            match activations(&second, rest) {
                Ok((a, t, c)) => {
                    act.extend(a);
                    time.extend(t);
                    count.extend(c);
                }
                Err(error) => {
                    return Evaluation::Failed {
                        error,
                        on_probe: false,
                    };
                }
            }
        }
        let n = act.len().max(1) as f64;
        let mean_time = time.iter().sum::<f64>() / n;
        let activation_rate = count.iter().filter(|&&c| c > 0).count() as f64 / n;
        let reason = if act.iter().all(|a| !a.contains(&true)) {
            Some("silent")
        } else if act.iter().all(|a| !a.contains(&false)) {
            Some("always on")
        } else {
            None
        };
        if let Some(reason) = reason.filter(|_| !seed) {
            return Evaluation::Degenerate {
                reason,
                mean_time,
                activation_rate,
                signature,
            };
        }
        let out = CandidateOutput {
            hists: act
                .iter()
                .map(|a| histogram(a, self.settings.bins))
                .collect(),
            mean_time,
            lines,
        };
        let terms = evaluate(
            self.dx,
            self.library,
            &out,
            self.settings.time_penalty,
            self.settings.dp,
        );
        Evaluation::Scored {
            terms,
            mean_time: out.mean_time,
            activation_rate,
            signature,
        }
    }
}

/// Runs `detectors` (the current library) on the training traces: their histograms and mean time μ.
/// A failing call counts as no activation on that trace.
pub fn library_view(
    pool: &WorkerPool,
    detectors: &[Detector],
    traces: &[Trace],
    bins: usize,
) -> LibraryView {
    if detectors.is_empty() {
        return LibraryView {
            hists: vec![Vec::new(); traces.len()],
            mean_time: None,
        };
    }
    let batch = pool.run(detectors, traces);
    let mut hists = vec![vec![histogram(&[], bins); detectors.len()]; traces.len()];
    let (mut sum, mut n) = (0.0, 0usize);
    for r in &batch.results {
        sum += r.wall_s;
        n += 1;
        if r.status != CandidateStatus::Ok {
            continue;
        }
        let steps: Vec<i64> = traces[r.trace].timesteps.iter().map(|t| t.index).collect();
        let a = activation(
            &steps,
            r.patterns.iter().map(|p| (p.start_step, p.end_step)),
        );
        hists[r.trace][r.detector] = histogram(&a, bins);
    }
    LibraryView {
        hists,
        mean_time: (n > 0).then(|| sum / n as f64),
    }
}
