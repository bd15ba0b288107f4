-- The fitness correlation ρ of Algorithm 3 recomputed in SQL from stored data: for every evolve stage and
-- label, the best program's activation histograms (evolution_histograms) give the pairwise annotation
-- distances D_p under the stage's d_p (evolution_labels.dp: kl, cross-entropy or js, docs/evolution.md),
-- the stored trace distances D_x (trace_distances, by the set ids of evolution_labels) the other side,
-- and ρ is their Pearson correlation, on the training traces (equal to evolution_labels.best_rho) and
-- on the held-out traces (equal to holdout_rho); split 'sample' gives the held-out ρ of every candidate
-- the convergence measurement sampled (equal to evolution_samples.holdout_rho; NULL where the detector's
-- annotations do not vary, which the search counts as 0). tests/it/evolve.rs checks all three to 1e-9. Change the d_p
-- expression here to try another annotation distance on a finished search without touching Rust.
WITH dp_pairs AS (
    SELECT a.run_stage, a.label, a.split, a.code_hash, a.set_id,
           a.trace_id AS trace_a, b.trace_id AS trace_b,
           sum(CASE l.dp
                   WHEN 'kl' THEN 0.5 * (a.value - b.value) * ln(a.value / b.value)
                   WHEN 'cross-entropy' THEN -0.5 * (a.value * ln(b.value) + b.value * ln(a.value))
                   ELSE 0.5 * (a.value * ln(2.0 * a.value / (a.value + b.value))
                             + b.value * ln(2.0 * b.value / (a.value + b.value)))
               END) AS d_p
    FROM evolution_histograms AS a
    JOIN evolution_histograms AS b
      ON a.run_stage = b.run_stage AND a.label = b.label AND a.split = b.split
     AND a.code_hash = b.code_hash AND a.bin = b.bin AND a.trace_index < b.trace_index
    JOIN evolution_labels AS l ON l.run_stage = a.run_stage AND l.label = a.label
    GROUP BY a.run_stage, a.label, a.split, a.code_hash, a.set_id, a.trace_id, b.trace_id
)
SELECT p.run_stage,
       p.label,
       p.split,
       p.code_hash,
       count(d.d_x)           AS pairs,
       corr(d.d_x, p.d_p)     AS rho
FROM dp_pairs AS p
JOIN trace_distances AS d
  ON d.set_id = p.set_id AND d.trace_a = p.trace_a AND d.trace_b = p.trace_b
GROUP BY p.run_stage, p.label, p.split, p.code_hash
ORDER BY p.run_stage, p.label, p.split, p.code_hash
