-- Success against library size (the paper's library-size figure as a table): for annotation feedback, the
-- success rate (%) of task runs per environment, agent or model, library and number of patterns used,
-- mean and standard deviation over seeds. Benchmark stages with growing `labels` subsets give the points.
WITH per_task AS (
  SELECT env, CASE WHEN model = '' THEN agent ELSE agent || ': ' || model END AS agent, library, patterns,
         seed, task, MAX(CASE WHEN success THEN 1.0 ELSE 0.0 END) AS solved
  FROM benchmark
  WHERE feedback = 'annotations'
  GROUP BY env, agent, model, library, patterns, seed, task
),
per_seed AS (
  SELECT env, agent, library, patterns, seed, 100.0 * AVG(solved) AS rate
  FROM per_task
  GROUP BY env, agent, library, patterns, seed
)
SELECT env, agent, library, patterns,
       AVG(rate) AS success_mean, COALESCE(STDDEV_POP(rate), 0.0) AS success_std, COUNT(*) AS seeds
FROM per_seed
GROUP BY env, agent, library, patterns
ORDER BY env, agent, library, patterns
