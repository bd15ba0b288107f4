-- Success rate by reward type and budget: mean over goals × scenes per seed, then mean and standard
-- deviation over seeds (the paper's figure 6 as a table). Written by the optimise stage's rows.
WITH per_seed AS (
  SELECT reward_type, budget, seed, AVG(CASE WHEN success THEN 1.0 ELSE 0.0 END) AS rate
  FROM optimisation
  GROUP BY reward_type, budget, seed
)
SELECT reward_type,
       budget,
       COUNT(*) AS seeds,
       AVG(rate) AS success_mean,
       COALESCE(STDDEV_POP(rate), 0.0) AS success_std
FROM per_seed
GROUP BY reward_type, budget
ORDER BY reward_type, budget
