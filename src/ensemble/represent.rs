//! Representatives: one detector per K-means cluster (best ν, ties to shorter code, then to the
//! smaller code hash), and the single-program ablation "-SP" (the best candidate per label over every
//! run, by the same order).
//!
//! **Owns:** those two choices. **Does not:** cluster (`kmeans`) or write libraries (`library`).

use std::cmp::Ordering;

use super::pool::Pooled;

/// Whether `a` ranks before `b`: higher ν, then fewer lines, then smaller code hash.
fn better(a: &Pooled, b: &Pooled) -> Ordering {
    b.nu.total_cmp(&a.nu)
        .then(a.lines.cmp(&b.lines))
        .then_with(|| a.code_hash.cmp(&b.code_hash))
}

/// The index of each cluster's representative among `pooled` (`assignment[i]` is candidate i's
/// cluster; clusters `0..k`).
pub fn representatives(pooled: &[Pooled], assignment: &[usize], k: usize) -> Vec<usize> {
    (0..k)
        .filter_map(|c| {
            (0..pooled.len())
                .filter(|&i| assignment[i] == c)
                .min_by(|&i, &j| better(&pooled[i], &pooled[j]))
        })
        .collect()
}

/// The single best program of a label's pool ("-SP"), if any.
pub fn single_best(pooled: &[Pooled]) -> Option<usize> {
    (0..pooled.len()).min_by(|&i, &j| better(&pooled[i], &pooled[j]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(hash: &str, nu: f64, lines: i64) -> Pooled {
        Pooled {
            source: "evolve".into(),
            label: "x".into(),
            code_hash: hash.into(),
            code: String::new(),
            nu,
            rho: 0.0,
            lines,
            seed: 0,
        }
    }

    #[test]
    fn best_nu_then_shorter_code_then_hash() {
        let pool = vec![
            p("d", 0.5, 10),
            p("c", 0.7, 30),
            p("b", 0.7, 20),
            p("a", 0.2, 5),
            p("e", 0.2, 5),
        ];
        // Clusters {0, 1, 2} and {3, 4}.
        let reps = representatives(&pool, &[0, 0, 0, 1, 1], 2);
        assert_eq!(reps, vec![2, 3]);
        assert_eq!(single_best(&pool), Some(2));
        assert_eq!(single_best(&[]), None);
    }
}
