//! Algorithm 3 of the paper (Evaluate): ρ, η, λ, ψ and ν of a candidate from its per-trace activation
//! histograms, the training set's D_x matrix and the current library's histograms.
//!
//! Conventions where the paper is silent: ρ is Pearson's r over the pairs whose d_x is defined, and 0
//! when either side has no variance (a detector that says the same thing about every trace carries no
//! information). η averages d_p(candidate, library pattern j) over every training trace and every library
//! pattern (Algorithm 3 appends both traces of every pair, which weights each trace equally, as here);
//! with an empty library η = 0. λ counts lines as [`crate::search::count_lines`] does (non-blank,
//! non-comment). ψ compares mean wall time per trace; with no library time (μ undefined or 0) ψ = 0.

use super::distance::DistanceMatrix;
use super::histogram::Dp;
use super::terms::FitnessTerms;

/// The current library seen from the training set: each training trace's histogram per library detector,
/// and μ, the library's mean annotation time per trace and detector.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LibraryView {
    /// `hists[trace][detector]`: smoothed histograms (training-set order).
    pub hists: Vec<Vec<Vec<f64>>>,
    /// μ (s), `None` for an empty library.
    pub mean_time: Option<f64>,
}

/// What Evaluate needs of a candidate: its histogram on every training trace, its mean time and size.
#[derive(Clone, Debug, PartialEq)]
pub struct CandidateOutput {
    /// One histogram per training trace (training-set order).
    pub hists: Vec<Vec<f64>>,
    /// Mean wall time per trace (s).
    pub mean_time: f64,
    /// Lines of code.
    pub lines: usize,
}

/// λ = ln(min(lines, 1000)) / 5 (lines below 1 count as 1).
pub fn length_penalty(lines: usize) -> f64 {
    (lines.clamp(1, 1000) as f64).ln() / 5.0
}

/// ψ: 0 for t ≤ μ, (t − μ)/μ up to 1 at t = 2μ, 1 beyond; 0 when μ is not a positive number.
pub fn time_penalty(t: f64, mu: Option<f64>) -> f64 {
    match mu {
        Some(mu) if mu > 0.0 && mu.is_finite() && t.is_finite() => ((t - mu) / mu).clamp(0.0, 1.0),
        _ => 0.0,
    }
}

/// Pearson's correlation over the pairs where both values are finite; 0 when undefined.
pub fn pearson(x: &[f64], y: &[f64]) -> f64 {
    let pairs: Vec<(f64, f64)> = x
        .iter()
        .zip(y)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a, *b))
        .collect();
    let n = pairs.len() as f64;
    if pairs.len() < 2 {
        return 0.0;
    }
    let mx = pairs.iter().map(|p| p.0).sum::<f64>() / n;
    let my = pairs.iter().map(|p| p.1).sum::<f64>() / n;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in &pairs {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx).powi(2);
        syy += (b - my).powi(2);
    }
    // Relative tolerance: a spread of rounding noise is no spread.
    let tiny = |s: f64, m: f64| s <= 1e-24 * n * (1.0 + m * m);
    if tiny(sxx, mx) || tiny(syy, my) {
        return 0.0;
    }
    (sxy / (sxx.sqrt() * syy.sqrt())).clamp(-1.0, 1.0)
}

/// The pairwise annotation distances D_p of a candidate, in the order of [`DistanceMatrix::upper`].
pub fn annotation_distances(hists: &[Vec<f64>], dp: Dp) -> Vec<f64> {
    let n = hists.len();
    let mut out = Vec::with_capacity(n * n.saturating_sub(1) / 2);
    for i in 0..n {
        for j in i + 1..n {
            out.push(dp.pattern(&hists[i], &hists[j]));
        }
    }
    out
}

/// ρ of a candidate's histograms over a set of traces against that set's D_x (same order).
pub fn correlation(dx: &DistanceMatrix, hists: &[Vec<f64>], dp: Dp) -> f64 {
    pearson(&dx.upper, &annotation_distances(hists, dp))
}

/// η: mean d_p between the candidate's histogram and each library detector's, over traces (0 for an
/// empty library).
pub fn novelty(cand: &[Vec<f64>], library: &LibraryView, dp: Dp) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (t, h) in cand.iter().enumerate() {
        for lib in library.hists.get(t).into_iter().flatten() {
            sum += dp.pattern(h, lib);
            n += 1;
        }
    }
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// Every fitness term of a candidate (Algorithm 3) with annotation distance `dp`. `time_penalty` off
/// makes ψ = 0 (for runs that must be bit-for-bit reproducible: wall time is not).
pub fn evaluate(
    dx: &DistanceMatrix,
    library: &LibraryView,
    cand: &CandidateOutput,
    use_time_penalty: bool,
    dp: Dp,
) -> FitnessTerms {
    let rho = correlation(dx, &cand.hists, dp);
    let eta = novelty(&cand.hists, library, dp);
    let lambda = length_penalty(cand.lines);
    let psi = if use_time_penalty {
        time_penalty(cand.mean_time, library.mean_time)
    } else {
        0.0
    };
    FitnessTerms::new(rho, eta, lambda, psi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fitness::histogram::histogram;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn penalties_by_hand() {
        assert_eq!(length_penalty(1), 0.0);
        assert!(close(length_penalty(100), 100f64.ln() / 5.0));
        assert!(close(length_penalty(5000), 1000f64.ln() / 5.0));
        assert!(close(length_penalty(1000), 1.381551055796427));
        assert_eq!(time_penalty(0.5, Some(1.0)), 0.0);
        assert_eq!(time_penalty(1.0, Some(1.0)), 0.0);
        assert!(close(time_penalty(1.25, Some(1.0)), 0.25));
        assert_eq!(time_penalty(2.0, Some(1.0)), 1.0);
        assert_eq!(time_penalty(9.0, Some(1.0)), 1.0);
        assert_eq!(time_penalty(9.0, None), 0.0);
    }

    #[test]
    fn pearson_by_hand() {
        assert!(close(pearson(&[1.0, 2.0, 3.0], &[2.0, 4.0, 6.0]), 1.0));
        assert!(close(pearson(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]), -1.0));
        // x = (1,2,3), y = (1,3,2): cov = 0.5·2/... r = 0.5.
        assert!(close(pearson(&[1.0, 2.0, 3.0], &[1.0, 3.0, 2.0]), 0.5));
        assert_eq!(pearson(&[1.0, 2.0, 3.0], &[5.0, 5.0, 5.0]), 0.0);
        // NaN pairs are left out.
        assert!(close(
            pearson(&[1.0, f64::NAN, 2.0, 3.0], &[2.0, 0.0, 4.0, 6.0]),
            1.0
        ));
    }

    #[test]
    fn evaluate_combines_the_terms() {
        // Three traces at x-offsets 0, 1, 3 (D_x = 1, 3, 2 for pairs 01, 02, 12).
        let dx = DistanceMatrix {
            ids: vec!["a".into(), "b".into(), "c".into()],
            upper: vec![1.0, 3.0, 2.0],
        };
        // Candidate: active in bin 0 on a, bins 0-1 on b, bin 1 on c.
        let hists = vec![
            histogram(&[true, false], 2),
            histogram(&[true, true], 2),
            histogram(&[false, true], 2),
        ];
        let ce = Dp::CrossEntropy;
        let pattern_distance = |p: &[f64], q: &[f64]| ce.pattern(p, q);
        let dp = annotation_distances(&hists, ce);
        assert!(close(dp[0], pattern_distance(&hists[0], &hists[1])));
        assert!(close(dp[2], pattern_distance(&hists[1], &hists[2])));
        let library = LibraryView {
            hists: vec![
                vec![histogram(&[true, true], 2)],
                vec![histogram(&[true, true], 2)],
                vec![histogram(&[true, true], 2)],
            ],
            mean_time: Some(0.010),
        };
        let cand = CandidateOutput {
            hists: hists.clone(),
            mean_time: 0.015,
            lines: 20,
        };
        let f = evaluate(&dx, &library, &cand, true, ce);
        assert!(close(f.rho, pearson(&dx.upper, &dp)));
        let eta = (pattern_distance(&hists[0], &library.hists[0][0])
            + pattern_distance(&hists[1], &library.hists[1][0])
            + pattern_distance(&hists[2], &library.hists[2][0]))
            / 3.0;
        assert!(close(f.eta, eta));
        assert!(close(f.lambda, 20f64.ln() / 5.0));
        assert!(close(f.psi, 0.5));
        assert!(close(f.nu, f.rho + f.eta - f.lambda - f.psi));
        assert_eq!(evaluate(&dx, &library, &cand, false, ce).psi, 0.0);
        // Empty library: η = 0, ψ = 0.
        let g = evaluate(&dx, &LibraryView::default(), &cand, true, ce);
        assert_eq!((g.eta, g.psi), (0.0, 0.0));
        // Under kl, η and ρ use the divergence; a candidate identical to the library has η = 0.
        let k = evaluate(&dx, &library, &cand, false, Dp::Kl);
        assert!(close(k.rho, correlation(&dx, &hists, Dp::Kl)));
        let same = CandidateOutput {
            hists: library.hists.iter().map(|h| h[0].clone()).collect(),
            mean_time: 0.0,
            lines: 1,
        };
        assert_eq!(evaluate(&dx, &library, &same, false, Dp::Kl).eta, 0.0);
        assert!(evaluate(&dx, &library, &same, false, ce).eta > 0.6);
    }

    #[test]
    fn eta_by_hand_for_both_variants() {
        // One trace, a library pattern fully active in bin 0 of 2, the candidate in bin 1.
        let hi = (1.0 + crate::fitness::histogram::SMOOTHING)
            / (1.0 + 2.0 * crate::fitness::histogram::SMOOTHING);
        let lo = 1.0 - hi;
        let library = LibraryView {
            hists: vec![vec![vec![hi, lo]]],
            mean_time: None,
        };
        let cand = vec![histogram(&[false, true], 2)];
        // kl: ½(KL + KL) = (hi − lo)·ln(hi/lo); cross entropy adds the entropy −hi ln hi − lo ln lo.
        let kl = (hi - lo) * (hi / lo).ln();
        let ent = -hi * hi.ln() - lo * lo.ln();
        assert!(close(novelty(&cand, &library, Dp::Kl), kl));
        assert!(close(novelty(&cand, &library, Dp::CrossEntropy), kl + ent));
        // With 0.01 smoothing: hi = 1.01/1.02, lo = 0.01/1.02; kl = 0.98039… · ln 101 = 4.52456…
        assert!(close(kl, 0.9803921568627451 * 101f64.ln()));
    }
}
