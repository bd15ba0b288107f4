//! Annotation distance d_p (section 3.1 of the paper): per pattern, a normalised histogram of
//! activations over `b` time bins, compared by cross entropy.
//!
//! **Histogram.** A detector's activation over one trace is a vector over the trace's N timesteps (1 where
//! one of its patterns covers the step, else 0). Bin k of b holds the timesteps at positions
//! `[k·N/b, (k+1)·N/b)` (normalised time, like d_x); its value is the *fraction* of its timesteps that
//! are active, so the histogram does not depend on the sampling rate. **Smoothing.** The histogram is
//! normalised with an additive ε = [`SMOOTHING`] per bin: `h_k = (c_k + ε) / (Σc + b·ε)`, so a pattern
//! absent from a trace has the uniform histogram (maximum entropy) and every logarithm is finite.
//! **Cross entropy** is not symmetric; d_p uses its symmetrised form
//! `½(H(h₁, h₂) + H(h₂, h₁))` with `H(p, q) = −Σ p_k ln q_k` (nats). For a library of J patterns, d_p
//! is the mean over the J patterns. The default b is [`DEFAULT_BINS`] = 10.

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

/// Entropy `H(p)` (nats).
pub fn entropy(p: &[f64]) -> f64 {
    cross_entropy(p, p)
}

/// The symmetrised cross entropy of two histograms: d_p for one pattern.
pub fn pattern_distance(p: &[f64], q: &[f64]) -> f64 {
    0.5 * (cross_entropy(p, q) + cross_entropy(q, p))
}

/// d_p of two annotation matrices given as one histogram per pattern (same patterns, same order): the
/// mean of [`pattern_distance`] over patterns (`NaN` for no pattern).
pub fn annotation_distance(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    if a.is_empty() || a.len() != b.len() {
        return f64::NAN;
    }
    a.iter()
        .zip(b)
        .map(|(p, q)| pattern_distance(p, q))
        .sum::<f64>()
        / a.len() as f64
}

/// Annotation similarity in (0, 1], 1 for identical histograms: `exp(−(d_p − ½(H(p) + H(q))))`, i.e. the
/// exponential of minus half the Jeffreys divergence. Used for the convergence statistics.
pub fn similarity(p: &[f64], q: &[f64]) -> f64 {
    (-(pattern_distance(p, q) - 0.5 * (entropy(p) + entropy(q)))).exp()
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
        assert!(close(pattern_distance(&p, &q), 0.5 * (h + rev)));
        // Identical uniform histograms over b bins: ln b.
        assert!(close(pattern_distance(&p, &p), 2f64.ln()));
        assert!(close(similarity(&q, &q), 1.0));
        assert!(similarity(&p, &q) < 1.0);
        // Mean over patterns.
        let d = annotation_distance(&[p.to_vec(), q.to_vec()], &[p.to_vec(), p.to_vec()]);
        assert!(close(d, 0.5 * (2f64.ln() + pattern_distance(&q, &p))));
        assert!(annotation_distance(&[], &[]).is_nan());
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
