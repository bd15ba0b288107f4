//! Calibration of an ensemble library (paper section 3.3, "reliability weighting and tolerance
//! optimisation"): weights start at 1; (a) a seeded sweep of (γ, ε_s, ε_t) per label maximising the
//! correlation-based reward ρ of the ensemble's annotations on held-out traces; (b) Bayesian
//! optimisation (`gp`) of every label's weights and tolerances together against an [`Objective`].
//!
//! **Objectives.** [`HeldoutRho`] (the mean over labels of held-out ρ) is the offline objective. The
//! paper's objective for (b) is identification accuracy (annotated traces summarised in language, a
//! vision-language model picks the matching summary among 8); it plugs in as another [`Objective`]
//! implementation: `score` receives a whole candidate library configuration ([`LabelEnsemble`]s with
//! weights, γ and tolerances) and returns a number to maximise. Which objective ran is part of the
//! result ([`Calibrated::objective`]).
//!
//! **Sweep (a).** Per label: the starting point (γ₀, ε_s₀, ε_t₀), then `points` seeded draws with
//! γ ~ U[0, 0.95), ε_s = ε_s₀ · 2^U[−2, 3], ε_t = round(U[0, 4 · max(ε_t₀, 1)]); the best ρ wins, ties
//! to the earlier point.
//!
//! **Bayesian optimisation (b).** One vector per library: per label γ/0.95, (log₂(ε_s/ε_s₀) + 2)/5,
//! ε_t / (4 · max(ε_t₀, 1)) and each weight / 2 (weights in [0, 2]). The sweep's optimum is the first
//! point, three seeded random points follow, then `iterations` points of maximal expected improvement
//! under a GP with length scale 0.25·√d. The best point evaluated wins (so (b) never scores below (a)).
//!
//! **Owns:** the search over parameters. **Does not:** run detectors (the member patterns are computed
//! once, by the caller) or summarise traces (the summary module's objective would).

use super::activation::LabelEnsemble;
use super::gp::{Gp, next_point};
use super::signature::trace_histogram;
use crate::detect::Annotation;
use crate::fitness::{DistanceMatrix, Dp, correlation};
use crate::rng::SplitMix64;
use crate::trace::Trace;

/// An objective failed (the seam for objectives that call models).
#[derive(Debug, thiserror::Error)]
#[error("calibration objective {objective}: {message}")]
pub struct ObjectiveError {
    /// The objective's name.
    pub objective: String,
    /// What went wrong.
    pub message: String,
}

/// What calibration (b) maximises: a score of a whole library configuration.
pub trait Objective {
    /// Its name, recorded in the stage output and the run manifest (`heldout-rho`, …).
    fn name(&self) -> &str;
    /// The score of `ensembles` (one per label, with weights, γ, ε_s, ε_t set); larger is better.
    fn score(&mut self, ensembles: &[LabelEnsemble]) -> Result<f64, ObjectiveError>;
}

/// The offline objective: mean over labels of ρ between the held-out traces' D_x and the d_p of the
/// label's ensemble annotations there. The member patterns on those traces are computed once.
#[derive(Debug)]
pub struct HeldoutRho<'a> {
    traces: &'a [Trace],
    /// Member patterns per trace (trace order).
    by_trace: Vec<Vec<&'a Annotation>>,
    dx: &'a DistanceMatrix,
    bins: usize,
    dp: Dp,
}

impl<'a> HeldoutRho<'a> {
    /// The objective over `traces` (in D_x order) with the members' patterns `anns` on them.
    pub fn new(
        traces: &'a [Trace],
        anns: &'a [Annotation],
        dx: &'a DistanceMatrix,
        bins: usize,
        dp: Dp,
    ) -> Self {
        let by_trace = crate::detect::by_trace(traces, anns);
        HeldoutRho {
            traces,
            by_trace,
            dx,
            bins,
            dp,
        }
    }

    /// ρ of one label's ensemble.
    pub fn label_rho(&self, e: &LabelEnsemble) -> f64 {
        let hists: Vec<Vec<f64>> = self
            .traces
            .iter()
            .zip(&self.by_trace)
            .map(|(t, anns)| {
                let out = e.annotate_trace(t, anns);
                let refs: Vec<&Annotation> = out.iter().collect();
                trace_histogram(t, &refs, self.bins)
            })
            .collect();
        correlation(self.dx, &hists, self.dp)
    }
}

impl Objective for HeldoutRho<'_> {
    fn name(&self) -> &str {
        "heldout-rho"
    }
    fn score(&mut self, ensembles: &[LabelEnsemble]) -> Result<f64, ObjectiveError> {
        if ensembles.is_empty() {
            return Ok(0.0);
        }
        Ok(ensembles.iter().map(|e| self.label_rho(e)).sum::<f64>() / ensembles.len() as f64)
    }
}

/// One evaluated point of a calibration, for the `ensemble_calibration` table.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationRow {
    /// `sweep` or `bo`.
    pub method: String,
    /// The label (every label of the point has a row in `bo`).
    pub label: String,
    /// Point number within the method (per label for `sweep`).
    pub iteration: u32,
    /// γ.
    pub gamma: f64,
    /// ε_s.
    pub eps_s: f64,
    /// ε_t.
    pub eps_t: f64,
    /// The member weights.
    pub weights: Vec<f64>,
    /// The score: the label's ρ (`sweep`) or the objective of the whole point (`bo`).
    pub score: f64,
    /// Whether this point was chosen.
    pub chosen: bool,
}

/// Settings of a calibration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CalibrationSettings {
    /// Sweep points per label besides the starting point.
    pub sweep_points: usize,
    /// Expected-improvement steps of (b) (0: skip (b)).
    pub bo_iterations: usize,
    /// Seed.
    pub seed: u64,
}

/// The result of a calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct Calibrated {
    /// The calibrated label ensembles.
    pub ensembles: Vec<LabelEnsemble>,
    /// Every evaluated point.
    pub rows: Vec<CalibrationRow>,
    /// The mean held-out ρ after the sweep.
    pub sweep_rho: f64,
    /// The objective of (b): its name, its score at the sweep optimum and at the chosen point.
    pub objective: Option<(String, f64, f64)>,
}

/// Sweep (a): each label's (γ, ε_s, ε_t) maximising its held-out ρ (see the module docs).
pub fn sweep(
    start: &[LabelEnsemble],
    rho: &HeldoutRho<'_>,
    points: usize,
    seed: u64,
) -> (Vec<LabelEnsemble>, Vec<CalibrationRow>) {
    let mut out = Vec::new();
    let mut rows = Vec::new();
    for (li, e0) in start.iter().enumerate() {
        let mut rng = SplitMix64::new(crate::rng::splitmix64(
            seed ^ (li as u64).wrapping_mul(0x9E37),
        ));
        let tmax = 4.0 * e0.eps_t.max(1.0);
        let mut best: Option<(f64, LabelEnsemble, usize)> = None;
        let first = rows.len();
        for i in 0..=points {
            let mut e = e0.clone();
            if i > 0 {
                e.gamma = rng.uniform(0.0, 0.95);
                e.eps_s = e0.eps_s * 2f64.powf(rng.uniform(-2.0, 3.0));
                e.eps_t = rng.uniform(0.0, tmax).round();
            }
            let r = rho.label_rho(&e);
            rows.push(CalibrationRow {
                method: "sweep".into(),
                label: e.label.clone(),
                iteration: i as u32,
                gamma: e.gamma,
                eps_s: e.eps_s,
                eps_t: e.eps_t,
                weights: e.members.iter().map(|m| m.weight).collect(),
                score: r,
                chosen: false,
            });
            if best.as_ref().is_none_or(|b| r > b.0) {
                best = Some((r, e, rows.len() - 1));
            }
        }
        let (_, e, at) = best.expect("at least the starting point");
        rows[at].chosen = true;
        debug_assert!(at >= first);
        out.push(e);
    }
    (out, rows)
}

/// Maps a point of the unit cube onto the label ensembles (see the module docs).
fn decode(x: &[f64], base: &[LabelEnsemble], start: &[LabelEnsemble]) -> Vec<LabelEnsemble> {
    let mut i = 0;
    base.iter()
        .zip(start)
        .map(|(b, s)| {
            let mut e = b.clone();
            e.gamma = 0.95 * x[i];
            e.eps_s = s.eps_s * 2f64.powf(5.0 * x[i + 1] - 2.0);
            e.eps_t = (4.0 * s.eps_t.max(1.0) * x[i + 2]).round();
            i += 3;
            for m in &mut e.members {
                m.weight = 2.0 * x[i];
                i += 1;
            }
            e
        })
        .collect()
}

fn encode(e: &[LabelEnsemble], start: &[LabelEnsemble]) -> Vec<f64> {
    let mut x = Vec::new();
    for (e, s) in e.iter().zip(start) {
        x.push((e.gamma / 0.95).clamp(0.0, 1.0));
        let r = if s.eps_s > 0.0 && e.eps_s > 0.0 {
            ((e.eps_s / s.eps_s).log2() + 2.0) / 5.0
        } else {
            0.4
        };
        x.push(r.clamp(0.0, 1.0));
        x.push((e.eps_t / (4.0 * s.eps_t.max(1.0))).clamp(0.0, 1.0));
        for m in &e.members {
            x.push((m.weight / 2.0).clamp(0.0, 1.0));
        }
    }
    x
}

/// Runs (a) then (b) (see the module docs). `start` carries the members, their rewards and the starting
/// tolerances; the weights are reset to 1.
pub fn calibrate(
    start: &[LabelEnsemble],
    rho: &HeldoutRho<'_>,
    objective: &mut dyn Objective,
    settings: CalibrationSettings,
) -> Result<Calibrated, ObjectiveError> {
    let mut unit: Vec<LabelEnsemble> = start.to_vec();
    for e in &mut unit {
        for m in &mut e.members {
            m.weight = 1.0;
        }
    }
    let (swept, mut rows) = sweep(&unit, rho, settings.sweep_points, settings.seed);
    let sweep_rho = if swept.is_empty() {
        0.0
    } else {
        swept.iter().map(|e| rho.label_rho(e)).sum::<f64>() / swept.len() as f64
    };
    if settings.bo_iterations == 0 || swept.is_empty() {
        return Ok(Calibrated {
            ensembles: swept,
            rows,
            sweep_rho,
            objective: None,
        });
    }
    let mut rng = SplitMix64::new(crate::rng::splitmix64(settings.seed ^ 0xB0));
    let x0 = encode(&swept, &unit);
    let d = x0.len();
    let mut xs = vec![x0];
    for _ in 0..3 {
        xs.push((0..d).map(|_| rng.next_f64()).collect());
    }
    let mut ys = Vec::new();
    for x in &xs {
        ys.push(objective.score(&decode(x, &swept, &unit))?);
    }
    let start_score = ys[0];
    let length = 0.25 * (d as f64).sqrt();
    for _ in 0..settings.bo_iterations {
        let (bi, &by) = ys
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(&a.0)))
            .expect("evaluated points");
        let x = match Gp::fit(&xs, &ys, length) {
            Some(gp) => next_point(&gp, &xs[bi].clone(), by, 512, &mut rng),
            None => (0..d).map(|_| rng.next_f64()).collect(),
        };
        ys.push(objective.score(&decode(&x, &swept, &unit))?);
        xs.push(x);
    }
    // The best point; ties to the earlier (the sweep optimum first).
    let mut best = 0;
    for i in 1..ys.len() {
        if ys[i] > ys[best] {
            best = i;
        }
    }
    for (it, (x, y)) in xs.iter().zip(&ys).enumerate() {
        for e in decode(x, &swept, &unit) {
            rows.push(CalibrationRow {
                method: "bo".into(),
                label: e.label.clone(),
                iteration: it as u32,
                gamma: e.gamma,
                eps_s: e.eps_s,
                eps_t: e.eps_t,
                weights: e.members.iter().map(|m| m.weight).collect(),
                score: *y,
                chosen: it == best,
            });
        }
    }
    let ensembles = if best == 0 {
        swept
    } else {
        decode(&xs[best], &swept, &unit)
    };
    Ok(Calibrated {
        ensembles,
        rows,
        sweep_rho,
        objective: Some((objective.name().to_string(), start_score, ys[best])),
    })
}
