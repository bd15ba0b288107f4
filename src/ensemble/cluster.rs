//! One label's clustering: signatures → K-means (K by [`KRule`]) → one representative per cluster, as
//! `ensemble_members` and `ensemble_clusters` rows. Candidates whose signature could not be computed (a
//! call failed on a signature trace) take no part.
//!
//! **Owns:** assembling those steps for one label. **Does not:** run detectors (`signature`) or fit
//! K-means (`kmeans`).

use super::kmeans::{Clustering, KRule, choose_k};
use super::pool::Pooled;
use super::represent::representatives;
use super::tables::{ClusterRow, MemberRow};

/// A label's clustering and its rows.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelClusters {
    /// The clustering of the candidates with signatures.
    pub clustering: Clustering,
    /// Indices (into the pooled list) of the candidates with signatures, in clustering order.
    pub clustered: Vec<usize>,
    /// Index (into the pooled list) of each cluster's representative, by cluster.
    pub representatives: Vec<usize>,
    /// `ensemble_members` rows.
    pub members: Vec<MemberRow>,
    /// `ensemble_clusters` rows.
    pub clusters: Vec<ClusterRow>,
}

/// Clusters `pooled` (one label) by `signatures` (same order; `None`: left out).
pub fn cluster_label(
    pooled: &[Pooled],
    signatures: &[Option<Vec<f64>>],
    rule: KRule,
    seed: u64,
) -> LabelClusters {
    let clustered: Vec<usize> = (0..pooled.len())
        .filter(|&i| signatures[i].is_some())
        .collect();
    let points: Vec<Vec<f64>> = clustered
        .iter()
        .map(|&i| signatures[i].clone().unwrap_or_default())
        .collect();
    let clustering = choose_k(&points, rule, seed);
    let sub: Vec<Pooled> = clustered.iter().map(|&i| pooled[i].clone()).collect();
    let reps_sub = representatives(&sub, &clustering.assignment, clustering.k);
    let reps: Vec<usize> = reps_sub.iter().map(|&j| clustered[j]).collect();
    let dim = points.first().map_or(0, Vec::len);
    let mut centres = vec![vec![0.0; dim]; clustering.k];
    let mut sizes = vec![0u32; clustering.k];
    for (p, &c) in points.iter().zip(&clustering.assignment) {
        sizes[c] += 1;
        for (a, v) in centres[c].iter_mut().zip(p) {
            *a += v;
        }
    }
    for (c, n) in centres.iter_mut().zip(&sizes) {
        for a in c.iter_mut() {
            *a /= f64::from((*n).max(1));
        }
    }
    let label = pooled.first().map(|p| p.label.clone()).unwrap_or_default();
    let members = clustered
        .iter()
        .zip(&points)
        .zip(&clustering.assignment)
        .map(|((&i, p), &c)| {
            let q = &pooled[i];
            MemberRow {
                label: q.label.clone(),
                source: q.source.clone(),
                code_hash: q.code_hash.clone(),
                cluster: c as u32,
                nu: q.nu,
                rho: q.rho,
                lines: q.lines,
                representative: reps.contains(&i),
                distance: p
                    .iter()
                    .zip(&centres[c])
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum::<f64>()
                    .sqrt(),
            }
        })
        .collect();
    let clusters = reps
        .iter()
        .enumerate()
        .map(|(c, &i)| {
            let q = &pooled[i];
            ClusterRow {
                label: label.clone(),
                cluster: c as u32,
                k: clustering.k as u32,
                k_rule: clustering.rule.to_string(),
                silhouette: clustering.silhouette,
                size: sizes[c],
                representative: q.code_hash.clone(),
                source: q.source.clone(),
                nu: q.nu,
                lines: q.lines,
            }
        })
        .collect();
    LabelClusters {
        clustering,
        clustered,
        representatives: reps,
        members,
        clusters,
    }
}
