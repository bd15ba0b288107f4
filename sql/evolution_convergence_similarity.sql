-- Section 4.5's convergence similarity recomputed in SQL from stored data: for every evolve stage and
-- label, each candidate the convergence measurement sampled (evolution_samples) is compared with every
-- sampled candidate of the label's final bin on the held-out traces, from their smoothed activation
-- histograms (evolution_histograms, split = 'sample'): per trace exp(-½(KL(p‖q) + KL(q‖p))), the mean
-- over traces. One row per pair, equal to evolution_convergence's similarity to 1e-9
-- (tests/it/evolve.rs). Group by bin to get the per-bin table of sql/evolution_convergence.sql, or edit
-- the similarity expression to try another one on a finished search. Written with at least 8 held-out
-- traces (the held-out set with its own D_x).
WITH final_bin AS (
    SELECT run_stage, label, max(bin) AS bin
    FROM evolution_samples
    GROUP BY run_stage, label
),
finals AS (
    SELECT s.run_stage, s.label, s.code_hash
    FROM evolution_samples AS s
    JOIN final_bin AS f ON f.run_stage = s.run_stage AND f.label = s.label AND f.bin = s.bin
),
h AS (
    SELECT run_stage, label, code_hash, trace_index, bin, value
    FROM evolution_histograms
    WHERE split = 'sample'
),
per_trace AS (
    SELECT s.run_stage, s.label, s.bin AS budget_bin, s.code_hash, f.code_hash AS final_hash,
           a.trace_index,
           exp(-sum(0.5 * (a.value - b.value) * ln(a.value / b.value))) AS similarity
    FROM evolution_samples AS s
    JOIN finals AS f ON f.run_stage = s.run_stage AND f.label = s.label
    JOIN h AS a ON a.run_stage = s.run_stage AND a.label = s.label AND a.code_hash = s.code_hash
    JOIN h AS b ON b.run_stage = f.run_stage AND b.label = f.label AND b.code_hash = f.code_hash
               AND b.trace_index = a.trace_index AND b.bin = a.bin
    GROUP BY s.run_stage, s.label, s.bin, s.code_hash, f.code_hash, a.trace_index
)
SELECT run_stage,
       label,
       budget_bin AS bin,
       code_hash,
       final_hash,
       avg(similarity) AS similarity,
       count(*)        AS traces
FROM per_trace
GROUP BY run_stage, label, budget_bin, code_hash, final_hash
ORDER BY run_stage, label, budget_bin, code_hash, final_hash
