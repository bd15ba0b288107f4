-- The paper's Table 1 from the benchmark table: success rate (%) of task runs, mean ± standard deviation
-- over seeds, one row per (agent or model, feedback [library, patterns]; billiards free-shot agents apart)
-- and one column per environment. A task run is solved when one of its attempts succeeded.
WITH attempts AS (
  SELECT env,
         CASE WHEN format = 'pool-free' THEN agent || ' (free shot)' ELSE agent END AS agent,
         CASE WHEN model = '' THEN '' ELSE ': ' || model END AS model,
         CASE WHEN library = '' THEN feedback
              ELSE feedback || ' (' || library || ', ' || CAST(patterns AS VARCHAR) || ' patterns)' END AS feedback,
         seed, task, success
  FROM benchmark
),
per_task AS (
  SELECT env, agent, model, feedback, seed, task,
         MAX(CASE WHEN success THEN 1.0 ELSE 0.0 END) AS solved
  FROM attempts
  GROUP BY env, agent, model, feedback, seed, task
),
per_seed AS (
  SELECT env, agent, model, feedback, seed, 100.0 * AVG(solved) AS rate, COUNT(*) AS tasks
  FROM per_task
  GROUP BY env, agent, model, feedback, seed
),
cells AS (
  SELECT env, agent || model AS agent, feedback,
         AVG(rate) AS mean, COALESCE(STDDEV_POP(rate), 0.0) AS std, COUNT(*) AS seeds, MAX(tasks) AS tasks
  FROM per_seed
  GROUP BY env, agent, model, feedback
)
SELECT agent,
       feedback,
       MAX(CASE WHEN env = 'phyre' THEN CAST(CAST(mean AS DECIMAL(10, 2)) AS VARCHAR) || ' ± ' || CAST(CAST(std AS DECIMAL(10, 2)) AS VARCHAR) END) AS "PHYRE",
       MAX(CASE WHEN env = 'iphyre' THEN CAST(CAST(mean AS DECIMAL(10, 2)) AS VARCHAR) || ' ± ' || CAST(CAST(std AS DECIMAL(10, 2)) AS VARCHAR) END) AS "I-PHYRE",
       MAX(CASE WHEN env = 'pooltool' THEN CAST(CAST(mean AS DECIMAL(10, 2)) AS VARCHAR) || ' ± ' || CAST(CAST(std AS DECIMAL(10, 2)) AS VARCHAR) END) AS "PoolTool",
       MAX(seeds) AS seeds,
       SUM(tasks) AS tasks
FROM cells
GROUP BY agent, feedback
ORDER BY agent, feedback
