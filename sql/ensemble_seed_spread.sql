-- The spread of ensemble libraries across discovery seeds (paper section 3.3: an ensemble should vary
-- less across seeds than single runs; docs/ensemble.md). Over every ensemble stage of the run that uses
-- the same test traces (pipelines/ensemble-seeds-pooltool.toml: same ensemble seed, different evolve
-- stages pooled), one row per variant: how many libraries, and the mean and the standard deviation over
-- those libraries of their mean ρ and mean F1 (event-grounded labels) on the test traces. `run` counts
-- each discovery run once, `baseline` once (it is the same library in every stage).
WITH per_library AS (
  SELECT variant,
         CASE WHEN variant IN ('ensemble', 'sp') THEN run_stage ELSE source END AS library,
         AVG(rho) AS rho,
         AVG(f1) AS f1
  FROM ensemble_evaluation
  GROUP BY variant, CASE WHEN variant IN ('ensemble', 'sp') THEN run_stage ELSE source END
)
SELECT variant,
       COUNT(*) AS libraries,
       AVG(rho) AS rho_mean,
       COALESCE(STDDEV(rho), 0.0) AS rho_std,
       AVG(f1) AS f1_mean,
       COALESCE(STDDEV(f1), 0.0) AS f1_std
FROM per_library
GROUP BY variant
ORDER BY CASE variant WHEN 'ensemble' THEN 0 WHEN 'sp' THEN 1 WHEN 'run' THEN 2 ELSE 3 END
