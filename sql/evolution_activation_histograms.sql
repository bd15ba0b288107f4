-- Activation histograms of each label's best program (evolution_histograms): per evolve stage, label,
-- split (training or held-out traces) and time bin, the mean and standard deviation over traces of the
-- smoothed share of activity in that bin (docs/evolution.md, "d_p"). Where in a trace a detector fires.
SELECT run_stage,
       label,
       split,
       bin,
       count(*)        AS traces,
       avg(value)      AS share_mean,
       stddev(value)   AS share_std
FROM evolution_histograms
WHERE split IN ('train', 'holdout')
GROUP BY run_stage, label, split, bin
ORDER BY run_stage, label, split, bin
