-- Ensemble library vs its single-program ablation (-SP) vs the baseline library vs each discovery run's
-- own best programs, on an ensemble stage's test traces (paper section 3.3 and the -SP ablation;
-- docs/ensemble.md). One row per ensemble stage and variant: mean ρ and F1 over labels; for `run`, the
-- mean over the M runs of their per-run means and the spread (standard deviation) over the runs' seeds.
WITH per_library AS (
  SELECT run_stage, variant, source, COUNT(*) AS labels, AVG(rho) AS rho, AVG(f1) AS f1
  FROM ensemble_evaluation
  GROUP BY run_stage, variant, source
)
SELECT run_stage,
       variant,
       COUNT(*) AS libraries,
       MAX(labels) AS labels,
       AVG(rho) AS rho_mean,
       COALESCE(STDDEV(rho), 0.0) AS rho_std_over_seeds,
       AVG(f1) AS f1_mean,
       COALESCE(STDDEV(f1), 0.0) AS f1_std_over_seeds
FROM per_library
GROUP BY run_stage, variant
ORDER BY run_stage, CASE variant WHEN 'ensemble' THEN 0 WHEN 'sp' THEN 1 WHEN 'run' THEN 2 ELSE 3 END
