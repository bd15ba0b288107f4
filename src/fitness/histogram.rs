//! Annotation distance d_p (section 3.1 of the paper): per pattern, a normalised histogram of
//! activations over `b` time bins, compared by one of the [`Dp`] variants.
//!
//! **Histogram.** A detector's activation over one trace is a vector over the trace's N timesteps (1 where
//! one of its patterns covers the step, else 0). Bin k of b holds the timesteps at positions
//! `[k·N/b, (k+1)·N/b)` (normalised time, like d_x); its value is the *fraction* of its timesteps that
//! are active, so the histogram does not depend on the sampling rate. **Smoothing.** The histogram is
//! normalised with an additive ε = [`SMOOTHING`] per bin: `h_k = (c_k + ε) / (Σc + b·ε)`, so a pattern
//! absent from a trace has the uniform histogram (maximum entropy) and every logarithm is finite.
//! **Variants** ([`Dp`], all in nats, all symmetric):
//! - `cross-entropy`, the paper's word taken literally: `½(H(p, q) + H(q, p))` with
//!   `H(p, q) = −Σ p_k ln q_k`. It contains the histograms' entropies, so d_p(A, A) = H(p) > 0 (ln b for
//!   two silent traces).
//! - `kl`, the symmetrised Kullback–Leibler divergence `½(KL(p‖q) + KL(q‖p)) = ½ Σ (p_k − q_k) ln(p_k/q_k)`:
//!   the cross entropy minus the mean entropy, 0 for identical annotations. Bounded only by the
//!   smoothing: all activity in one bin on one trace and in another bin on the other gives
//!   `(h₊ − h₋)·ln(h₊/h₋)` ≈ 4.2 nats with b = 10 (h₊ = (1 + ε)/(1 + bε), h₋ = ε/(1 + bε)).
//! - `js`, the Jensen–Shannon divergence `½KL(p‖m) + ½KL(q‖m)`, `m = ½(p + q)`: 0 for identical
//!   annotations, at most ln 2, defined for zero bins even without smoothing.
//!
//! For a library of J patterns, d_p is the mean over the J patterns. The default b is
//! [`DEFAULT_BINS`] = 10.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Which distance compares two activation histograms (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Dp {
    /// Symmetrised cross entropy, `½(H(p, q) + H(q, p))`: the paper's wording; d_p(A, A) = H > 0.
    CrossEntropy,
    /// Symmetrised Kullback–Leibler divergence, `½(KL(p‖q) + KL(q‖p))`: 0 for identical annotations.
    #[default]
    Kl,
    /// Jensen–Shannon divergence: 0 for identical annotations, at most ln 2.
    Js,
}

impl Dp {
    /// Every variant, in documentation order.
    pub const ALL: [Dp; 3] = [Dp::CrossEntropy, Dp::Kl, Dp::Js];

    /// `cross-entropy`, `kl` or `js`.
    pub fn as_str(self) -> &'static str {
        match self {
            Dp::CrossEntropy => "cross-entropy",
            Dp::Kl => "kl",
            Dp::Js => "js",
        }
    }

    /// d_p of one pattern's histograms `p` and `q` (same length).
    pub fn pattern(self, p: &[f64], q: &[f64]) -> f64 {
        match self {
            Dp::CrossEntropy => 0.5 * (cross_entropy(p, q) + cross_entropy(q, p)),
            Dp::Kl => 0.5 * (kl(p, q) + kl(q, p)),
            Dp::Js => {
                let m: Vec<f64> = p.iter().zip(q).map(|(a, b)| 0.5 * (a + b)).collect();
                0.5 * (kl(p, &m) + kl(q, &m))
            }
        }
    }
}

impl std::fmt::Display for Dp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Dp {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Dp::ALL
            .into_iter()
            .find(|d| d.as_str() == s)
            .ok_or_else(|| format!("unknown d_p {s:?}: expected cross-entropy, kl or js"))
    }
}

/// Default number of time bins.
pub const DEFAULT_BINS: usize = 10;

/// Additive smoothing per bin (in units of "fraction of a bin active").
pub const SMOOTHING: f64 = 1e-2;

/// The smoothed, normalised activation histogram of one detector over one trace: `active[i]` says whether
/// timestep position i (0-based, of `active.len()`) is covered.
pub fn histogram(active: &[bool], bins: usize) -> Vec<f64> {
    let n = active.len();
    let bins = bins.max(1);
    let mut frac = vec![0.0; bins];
    if n > 0 {
        let mut count = vec![0usize; bins];
        let mut on = vec![0usize; bins];
        for (i, &a) in active.iter().enumerate() {
            let k = ((i * bins).checked_div(n).unwrap_or(0)).min(bins - 1);
            count[k] += 1;
            on[k] += usize::from(a);
        }
        for k in 0..bins {
            if count[k] > 0 {
                frac[k] = on[k] as f64 / count[k] as f64;
            }
        }
    }
    let total: f64 = frac.iter().sum::<f64>() + bins as f64 * SMOOTHING;
    frac.iter().map(|c| (c + SMOOTHING) / total).collect()
}

/// Cross entropy `H(p, q) = −Σ p_k ln q_k` (nats).
pub fn cross_entropy(p: &[f64], q: &[f64]) -> f64 {
    p.iter().zip(q).map(|(a, b)| -a * b.ln()).sum()
}

/// Kullback–Leibler divergence `KL(p‖q) = Σ p_k ln(p_k / q_k)` (nats), with `0 · ln(0 / q) = 0`.
pub fn kl(p: &[f64], q: &[f64]) -> f64 {
    p.iter()
        .zip(q)
        .filter(|(a, _)| **a > 0.0)
        .map(|(a, b)| a * (a / b).ln())
        .sum()
}

/// Entropy `H(p)` (nats).
pub fn entropy(p: &[f64]) -> f64 {
    cross_entropy(p, p)
}

/// d_p of two annotation matrices given as one histogram per pattern (same patterns, same order): the
/// mean of [`Dp::pattern`] over patterns (`NaN` for no pattern).
pub fn annotation_distance(a: &[Vec<f64>], b: &[Vec<f64>], dp: Dp) -> f64 {
    if a.is_empty() || a.len() != b.len() {
        return f64::NAN;
    }
    a.iter().zip(b).map(|(p, q)| dp.pattern(p, q)).sum::<f64>() / a.len() as f64
}

/// Annotation similarity in (0, 1], 1 for identical histograms: `exp(−½(KL(p‖q) + KL(q‖p)))`, the
/// exponential of minus the `kl` d_p (half the Jeffreys divergence), whichever d_p the search scores
/// with. Used for the convergence statistics.
pub fn similarity(p: &[f64], q: &[f64]) -> f64 {
    (-Dp::Kl.pattern(p, q)).exp()
}

/// The activation of a detector over a trace with timestep indices `steps` (increasing), from its
/// patterns' inclusive `[start, end]` step ranges.
pub fn activation(steps: &[i64], ranges: impl IntoIterator<Item = (i64, i64)>) -> Vec<bool> {
    let mut out = vec![false; steps.len()];
    for (s, e) in ranges {
        let lo = steps.partition_point(|&x| x < s);
        let hi = steps.partition_point(|&x| x <= e);
        for v in out.iter_mut().take(hi).skip(lo) {
            *v = true;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn histograms_are_activation_fractions_per_bin_smoothed() {
        // 4 steps in 2 bins, first bin fully active: fractions (1, 0).
        let h = histogram(&[true, true, false, false], 2);
        let t = 1.0 + 2.0 * SMOOTHING;
        assert!(close(h[0], (1.0 + SMOOTHING) / t) && close(h[1], SMOOTHING / t));
        // Absent pattern: uniform.
        let u = histogram(&[false; 7], 4);
        assert!(u.iter().all(|&x| close(x, 0.25)));
        // Sampling rate does not matter: twice as many steps, same histogram.
        assert_eq!(
            histogram(&[true, false], 2),
            histogram(&[true, true, false, false], 2)
        );
    }

    #[test]
    fn cross_entropy_by_hand() {
        let p = [0.5, 0.5];
        let q = [0.25, 0.75];
        let h = -(0.5 * 0.25f64.ln() + 0.5 * 0.75f64.ln());
        assert!(close(cross_entropy(&p, &q), h));
        let rev = -(0.25 * 0.5f64.ln() + 0.75 * 0.5f64.ln());
        let ce = Dp::CrossEntropy;
        assert!(close(ce.pattern(&p, &q), 0.5 * (h + rev)));
        // Hand-computed: H(p,q) = 0.5·ln 4 + 0.5·ln(4/3) = 0.836988…, H(q,p) = ln 2.
        assert!(close(
            ce.pattern(&p, &q),
            0.5 * (0.8369882167858358 + std::f64::consts::LN_2)
        ));
        // Identical uniform histograms over b bins: ln b, not 0.
        assert!(close(ce.pattern(&p, &p), 2f64.ln()));
        assert!(close(similarity(&q, &q), 1.0));
        assert!(similarity(&p, &q) < 1.0);
        // Mean over patterns.
        let d = annotation_distance(&[p.to_vec(), q.to_vec()], &[p.to_vec(), p.to_vec()], ce);
        assert!(close(d, 0.5 * (2f64.ln() + ce.pattern(&q, &p))));
        assert!(annotation_distance(&[], &[], ce).is_nan());
    }

    #[test]
    fn kl_is_zero_for_identical_annotations_and_matches_hand_values() {
        let p = [0.5, 0.5];
        let q = [0.25, 0.75];
        // KL(p‖q) = 0.5 ln 2 + 0.5 ln(2/3) = 0.143841…; KL(q‖p) = 0.25 ln 0.5 + 0.75 ln 1.5 = 0.130812…
        assert!(close(kl(&p, &q), 0.14384103622589045));
        assert!(close(kl(&q, &p), 0.13081203594113694));
        assert!(close(
            Dp::Kl.pattern(&p, &q),
            0.5 * (0.14384103622589045 + 0.13081203594113694)
        ));
        // The cross entropy minus the mean entropy.
        let ent = 0.5 * (entropy(&p) + entropy(&q));
        assert!(close(
            Dp::Kl.pattern(&p, &q),
            Dp::CrossEntropy.pattern(&p, &q) - ent
        ));
        // d_p(A, A) = 0 for every annotation, silent (uniform) or concentrated, one or several patterns.
        let a = [
            histogram(&[true, true, false, false, false], 3),
            histogram(&[false; 9], 3),
            histogram(&[true; 4], 3),
        ];
        for h in &a {
            assert_eq!(Dp::Kl.pattern(h, h), 0.0);
            assert_eq!(Dp::Js.pattern(h, h), 0.0);
        }
        assert_eq!(annotation_distance(&a, &a, Dp::Kl), 0.0);
        assert!(Dp::CrossEntropy.pattern(&a[1], &a[1]) > 1.0);
        // Symmetric.
        assert_eq!(Dp::Kl.pattern(&p, &q), Dp::Kl.pattern(&q, &p));
        // similarity is exp(−kl).
        assert!(close(similarity(&p, &q), (-Dp::Kl.pattern(&p, &q)).exp()));
    }

    #[test]
    fn js_by_hand_is_bounded_by_ln_2_and_takes_zero_bins() {
        let p = [0.5, 0.5];
        let q = [0.25, 0.75];
        // m = (0.375, 0.625): ½[0.5 ln(0.5/0.375) + 0.5 ln(0.5/0.625)]
        //                  + ½[0.25 ln(0.25/0.375) + 0.75 ln(0.75/0.625)] = 0.033822…
        let want = 0.5 * (0.5 * (0.5f64 / 0.375).ln() + 0.5 * (0.5f64 / 0.625).ln())
            + 0.5 * (0.25 * (0.25f64 / 0.375).ln() + 0.75 * (0.75f64 / 0.625).ln());
        assert!(close(Dp::Js.pattern(&p, &q), want));
        assert!(close(want, 0.033822075568605205));
        // Disjoint supports (no smoothing): exactly ln 2.
        assert!(close(Dp::Js.pattern(&[1.0, 0.0], &[0.0, 1.0]), 2f64.ln()));
        // Smoothed disjoint histograms: finite under every variant; kl = (h₊ − h₋)·ln(h₊/h₋).
        let (a, b) = (histogram(&[true, false], 2), histogram(&[false, true], 2));
        for d in Dp::ALL {
            assert!(d.pattern(&a, &b).is_finite(), "{d}");
        }
        let hi = (1.0 + SMOOTHING) / (1.0 + 2.0 * SMOOTHING);
        let lo = SMOOTHING / (1.0 + 2.0 * SMOOTHING);
        assert!(close(Dp::Kl.pattern(&a, &b), (hi - lo) * (hi / lo).ln()));
    }

    #[test]
    fn dp_names_round_trip() {
        for d in Dp::ALL {
            assert_eq!(d.as_str().parse::<Dp>(), Ok(d));
            assert_eq!(serde_json::to_value(d).unwrap(), d.as_str());
        }
        assert!("kl-divergence".parse::<Dp>().is_err());
    }

    #[test]
    fn activation_covers_inclusive_ranges_of_step_indices() {
        let steps = [0, 2, 4, 6, 8];
        assert_eq!(
            activation(&steps, [(2, 4), (7, 100)]),
            vec![false, true, true, false, true]
        );
    }
}
