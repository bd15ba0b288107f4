-- The paper's summary-cost table from the summaries table: mean seconds and mean tokens (prompt +
-- completion) per summary, one row per (summariser, model, library kind) and two columns per environment.
-- Seconds are the model's latency for LLM summarisers and the wall time of the offline summariser;
-- tokens are the server's usage, or cl100k-style estimates when it reported none (usage_estimated).
WITH per_method AS (
  SELECT env,
         CASE WHEN model = '' THEN summariser ELSE summariser || ': ' || model END AS method,
         -- The library without its environment prefix (pooltool-human, phyre-human → human), so that one
         -- row holds a kind of library across the environments, as the paper's Human-Labels row.
         CASE WHEN library = '' THEN '' ELSE regexp_replace(library, '^(pooltool|phyre|iphyre)-', '') || ', ' || CAST(patterns AS VARCHAR) || ' patterns' END AS annotations,
         AVG(seconds) AS seconds, AVG(prompt_tokens + completion_tokens) AS tokens, COUNT(*) AS summaries
  FROM summaries
  GROUP BY env, summariser, model, library, patterns
)
SELECT method,
       annotations,
       MAX(CASE WHEN env = 'phyre' THEN CAST(CAST(seconds AS DECIMAL(12, 3)) AS VARCHAR) END) AS "PHYRE seconds",
       MAX(CASE WHEN env = 'phyre' THEN CAST(CAST(tokens AS DECIMAL(12, 0)) AS VARCHAR) END) AS "PHYRE tokens",
       MAX(CASE WHEN env = 'iphyre' THEN CAST(CAST(seconds AS DECIMAL(12, 3)) AS VARCHAR) END) AS "I-PHYRE seconds",
       MAX(CASE WHEN env = 'iphyre' THEN CAST(CAST(tokens AS DECIMAL(12, 0)) AS VARCHAR) END) AS "I-PHYRE tokens",
       MAX(CASE WHEN env = 'pooltool' THEN CAST(CAST(seconds AS DECIMAL(12, 3)) AS VARCHAR) END) AS "PoolTool seconds",
       MAX(CASE WHEN env = 'pooltool' THEN CAST(CAST(tokens AS DECIMAL(12, 0)) AS VARCHAR) END) AS "PoolTool tokens",
       SUM(summaries) AS summaries
FROM per_method
GROUP BY method, annotations
ORDER BY method, annotations
