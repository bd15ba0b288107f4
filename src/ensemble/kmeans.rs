//! K-means over candidate signatures (linfa-clustering), seeded, and the rule that chooses K.
//!
//! **Rule for K** (`choose_k`): with K fixed by the caller, that K (at most the number of distinct
//! signatures). Otherwise every K in `2..=min(k_max, n − 1)` is fitted and scored by its mean silhouette
//! (Euclidean, the same geometry K-means minimises); the K with the highest mean silhouette wins (ties to
//! the smaller K), unless that silhouette is below `min_silhouette` (default 0.25, the usual reading of
//! "no substantial structure"), in which case K = 1. With fewer than 3 signatures, or all identical,
//! K = 1. A fit that leaves a cluster empty is not a valid K.
//!
//! Cluster numbers are canonical: cluster 0 holds the first signature, cluster 1 the first signature
//! not in cluster 0, and so on, so the numbering does not depend on linfa's internal order.
//!
//! **Owns:** fitting, the silhouette and the choice of K. **Does not:** compute signatures
//! (`ensemble::signature`) or pick representatives (`ensemble::represent`).

use linfa::DatasetBase;
use linfa::traits::{Fit, Predict};
use linfa_clustering::KMeans;
use ndarray::Array2;
use rand_xoshiro::Xoshiro256Plus;
use rand_xoshiro::rand_core::SeedableRng;

/// A clustering of n signatures.
#[derive(Clone, Debug, PartialEq)]
pub struct Clustering {
    /// Number of clusters.
    pub k: usize,
    /// Cluster of each signature (canonical numbering).
    pub assignment: Vec<usize>,
    /// Mean silhouette of the chosen clustering (`None` for K = 1).
    pub silhouette: Option<f64>,
    /// Mean silhouette of every K tried, in order.
    pub tried: Vec<(usize, f64)>,
    /// How K was decided: `fixed`, `silhouette`, `weak-structure` or `too-few`.
    pub rule: &'static str,
}

/// How K is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KRule {
    /// A fixed K (`None`: by silhouette).
    pub fixed: Option<usize>,
    /// Largest K tried.
    pub k_max: usize,
    /// Below this best mean silhouette, K = 1.
    pub min_silhouette: f64,
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// The mean silhouette of `assignment` (k clusters) over `points`; a point alone in its cluster scores 0.
pub fn silhouette(points: &[Vec<f64>], assignment: &[usize], k: usize) -> f64 {
    let n = points.len();
    if n == 0 || k < 2 {
        return 0.0;
    }
    let mut total = 0.0;
    for i in 0..n {
        let mut sum = vec![0.0; k];
        let mut count = vec![0usize; k];
        for j in 0..n {
            if i != j {
                sum[assignment[j]] += distance(&points[i], &points[j]);
                count[assignment[j]] += 1;
            }
        }
        let own = assignment[i];
        if count[own] == 0 {
            continue;
        }
        let a = sum[own] / count[own] as f64;
        let b = (0..k)
            .filter(|&c| c != own && count[c] > 0)
            .map(|c| sum[c] / count[c] as f64)
            .fold(f64::INFINITY, f64::min);
        if b.is_finite() {
            let m = a.max(b);
            if m > 0.0 {
                total += (b - a) / m;
            }
        }
    }
    total / n as f64
}

/// Renumbers clusters by first appearance; `None` when a cluster is empty.
fn canonical(raw: &[usize], k: usize) -> Option<Vec<usize>> {
    let mut map = vec![usize::MAX; k.max(raw.iter().max().map_or(0, |m| m + 1))];
    let mut next = 0;
    let mut out = Vec::with_capacity(raw.len());
    for &c in raw {
        if map[c] == usize::MAX {
            map[c] = next;
            next += 1;
        }
        out.push(map[c]);
    }
    (next == k).then_some(out)
}

/// Seeded K-means of `points` into `k` clusters (linfa, 10 restarts); `None` when a cluster ends empty
/// or the fit fails.
pub fn kmeans(points: &[Vec<f64>], k: usize, seed: u64) -> Option<Vec<usize>> {
    let n = points.len();
    if k == 0 || n < k {
        return None;
    }
    if k == 1 {
        return Some(vec![0; n]);
    }
    let d = points[0].len();
    let flat: Vec<f64> = points.iter().flat_map(|p| p.iter().copied()).collect();
    let data = Array2::from_shape_vec((n, d), flat).ok()?;
    let dataset = DatasetBase::from(data.clone());
    let rng = Xoshiro256Plus::seed_from_u64(seed);
    let model = KMeans::params_with_rng(k, rng)
        .n_runs(10)
        .max_n_iterations(300)
        .tolerance(1e-9)
        .fit(&dataset)
        .ok()?;
    let raw: Vec<usize> = model.predict(&data).to_vec();
    canonical(&raw, k)
}

/// Clusters `points` with K chosen by `rule` (see the module docs).
pub fn choose_k(points: &[Vec<f64>], rule: KRule, seed: u64) -> Clustering {
    let n = points.len();
    let one = |why: &'static str, tried: Vec<(usize, f64)>| Clustering {
        k: 1.min(n),
        assignment: vec![0; n],
        silhouette: None,
        tried,
        rule: why,
    };
    let mut distinct: Vec<&Vec<f64>> = Vec::new();
    for p in points {
        if !distinct.iter().any(|q| distance(p, q) == 0.0) {
            distinct.push(p);
        }
    }
    if let Some(k) = rule.fixed {
        let k = k.clamp(1, distinct.len().max(1));
        if k == 1 {
            return one("fixed", Vec::new());
        }
        if let Some(a) = kmeans(points, k, seed) {
            let s = silhouette(points, &a, k);
            return Clustering {
                k,
                assignment: a,
                silhouette: Some(s),
                tried: vec![(k, s)],
                rule: "fixed",
            };
        }
        return one("fixed", Vec::new());
    }
    if n < 3 || distinct.len() < 2 {
        return one("too-few", Vec::new());
    }
    let hi = rule.k_max.min(n - 1).min(distinct.len());
    let mut best: Option<(usize, f64, Vec<usize>)> = None;
    let mut tried = Vec::new();
    for k in 2..=hi {
        let Some(a) = kmeans(points, k, seed) else {
            continue;
        };
        let s = silhouette(points, &a, k);
        tried.push((k, s));
        if best.as_ref().is_none_or(|b| s > b.1) {
            best = Some((k, s, a));
        }
    }
    match best {
        Some((k, s, a)) if s >= rule.min_silhouette => Clustering {
            k,
            assignment: a,
            silhouette: Some(s),
            tried,
            rule: "silhouette",
        },
        _ => one("weak-structure", tried),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three well-separated blobs of 5 points in 4-D, interleaved.
    fn blobs() -> (Vec<Vec<f64>>, Vec<usize>) {
        let centres = [
            [0.0, 0.0, 0.0, 0.0],
            [1.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 1.0],
        ];
        let mut rng = crate::rng::SplitMix64::new(7);
        let (mut pts, mut truth) = (Vec::new(), Vec::new());
        for i in 0..15 {
            let c = i % 3;
            pts.push(
                centres[c]
                    .iter()
                    .map(|x| x + 0.02 * (rng.next_f64() - 0.5))
                    .collect(),
            );
            truth.push(c);
        }
        (pts, truth)
    }

    #[test]
    fn known_clusters_are_found_and_k_is_chosen_by_silhouette() {
        let (pts, truth) = blobs();
        let rule = KRule {
            fixed: None,
            k_max: 6,
            min_silhouette: 0.25,
        };
        let c = choose_k(&pts, rule, 3);
        assert_eq!(c.k, 3, "{:?}", c.tried);
        assert_eq!(c.rule, "silhouette");
        // Canonical numbering: the blobs appear in order 0, 1, 2, so the assignment is the truth.
        assert_eq!(c.assignment, truth);
        assert!(c.silhouette.unwrap() > 0.9);
        assert_eq!(
            c.tried.iter().map(|t| t.0).collect::<Vec<_>>(),
            vec![2, 3, 4, 5, 6]
        );
        // Seeded: the same seed gives the same clustering; another seed finds the same blobs.
        assert_eq!(choose_k(&pts, rule, 3), c);
        assert_eq!(choose_k(&pts, rule, 99).assignment, truth);
        // Fixed K.
        let f = choose_k(
            &pts,
            KRule {
                fixed: Some(2),
                ..rule
            },
            3,
        );
        assert_eq!((f.k, f.rule), (2, "fixed"));
    }

    #[test]
    fn no_structure_or_too_few_points_give_one_cluster() {
        let rule = KRule {
            fixed: None,
            k_max: 4,
            min_silhouette: 0.25,
        };
        let same = vec![vec![0.5, 0.5]; 6];
        assert_eq!(choose_k(&same, rule, 1).k, 1);
        let two = vec![vec![0.0], vec![1.0]];
        let c = choose_k(&two, rule, 1);
        assert_eq!((c.k, c.rule, c.assignment), (1, "too-few", vec![0, 0]));
        // Evenly spaced points on a line: weak structure.
        let line: Vec<Vec<f64>> = (0..12).map(|i| vec![i as f64]).collect();
        let c = choose_k(
            &line,
            KRule {
                min_silhouette: 0.9,
                ..rule
            },
            1,
        );
        assert_eq!((c.k, c.rule), (1, "weak-structure"));
    }

    #[test]
    fn silhouette_by_hand() {
        // Points 0, 1 | 10: a(0) = 1, b(0) = 10 → 0.9; a(1) = 1, b(1) = 9 → 8/9; singleton → 0.
        let pts = vec![vec![0.0], vec![1.0], vec![10.0]];
        let s = silhouette(&pts, &[0, 0, 1], 2);
        assert!((s - (0.9 + 8.0 / 9.0) / 3.0).abs() < 1e-12);
    }
}
