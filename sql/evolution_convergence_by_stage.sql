-- Section 4.5 of the paper per evolve stage: like evolution_convergence.sql (annotation similarity on
-- held-out traces between detectors of each 10 % bin of the budget and those of the final bin, mean and
-- standard deviation over every label searched), one row per environment, evolve stage and bin.
SELECT
    v.env,
    v.run_stage,
    v.bin                       AS bin,
    10 * v.bin                  AS budget_pct_from,
    10 * v.bin + 10             AS budget_pct_to,
    count(*)                    AS pairs,
    avg(v.similarity)           AS similarity_mean,
    stddev(v.similarity)        AS similarity_std
FROM evolution_convergence AS v
GROUP BY v.env, v.run_stage, v.bin
ORDER BY v.env, v.run_stage, v.bin
