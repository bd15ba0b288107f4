-- Identification accuracy (%) from the identification table: per environment, summariser, chooser and
-- library (with the number of patterns that annotated), the share of trials whose chooser picked the
-- trace's own summary among `options`, beside chance (100 / options). Growing `labels` subsets of one
-- library give the library-size ablation of the identification task.
SELECT env,
       CASE WHEN model = '' THEN summariser ELSE summariser || ': ' || model END AS summariser,
       CASE WHEN chooser_model = '' THEN chooser ELSE chooser || ': ' || chooser_model END AS chooser,
       library,
       patterns,
       MAX(options) AS options,
       COUNT(*) AS trials,
       100.0 * AVG(CASE WHEN success THEN 1.0 ELSE 0.0 END) AS accuracy,
       100.0 / MAX(options) AS chance,
       SUM(CASE WHEN chosen IS NULL THEN 1 ELSE 0 END) AS unreadable
FROM identification
GROUP BY env, summariser, model, chooser, chooser_model, library, patterns
ORDER BY env, summariser, chooser, library, patterns
