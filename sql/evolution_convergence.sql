-- Section 4.5 of the paper ("Evolution of detector programs through learning"): annotation similarity on
-- held-out traces between detectors sampled from each 10 % bin of a search's budget and the detectors of
-- its final bin, mean and standard deviation per environment and bin over every label searched.
-- Similarity is exp(-(d_p - (H(p) + H(q))/2)) per trace, 1 for identical histograms (docs/evolution.md).
SELECT
    v.env,
    v.bin                       AS bin,
    10 * v.bin                  AS budget_pct_from,
    10 * v.bin + 10             AS budget_pct_to,
    count(*)                    AS pairs,
    avg(v.similarity)           AS similarity_mean,
    stddev(v.similarity)        AS similarity_std
FROM evolution_convergence AS v
GROUP BY v.env, v.bin
ORDER BY v.env, v.bin
