-- Appendix A of the paper ("Pattern Learning Statistics") per evolve stage: like
-- evolution_learning_stats.sql (candidates, % executable, best / average / std of ν over scored
-- candidates, average lines, activation %), one row per environment and evolve stage, with the stage's
-- annotation distance d_p and the mean held-out ρ of the detectors it accepted. Lets several searches in
-- one run folder (the d_p comparison of docs/evolution.md, the learn-<env> pipelines) be told apart.
WITH per_stage AS (
    SELECT l.run_stage,
           min(l.dp)                                                     AS dp,
           count(*)                                                      AS labels,
           sum(CASE WHEN l.accepted THEN 1 ELSE 0 END)                   AS accepted,
           avg(CASE WHEN l.accepted THEN l.holdout_rho END)              AS accepted_holdout_rho
    FROM evolution_labels AS l
    GROUP BY l.run_stage
)
SELECT
    c.env,
    c.run_stage,
    s.dp,
    count(*)                                                        AS candidates,
    100.0 * avg(CASE WHEN c.executable THEN 1.0 ELSE 0.0 END)       AS executable_pct,
    max(c.nu)                                                       AS best_fitness,
    avg(c.nu)                                                       AS avg_fitness,
    stddev(c.nu)                                                    AS fitness_std,
    avg(CAST(c.lines AS DOUBLE))                                    AS avg_lines,
    100.0 * avg(c.activation_rate)                                  AS activation_pct,
    min(s.labels)                                                   AS labels,
    min(s.accepted)                                                 AS accepted,
    min(s.accepted_holdout_rho)                                     AS accepted_holdout_rho
FROM candidates AS c
JOIN per_stage AS s ON s.run_stage = c.run_stage
WHERE c.step >= 0
GROUP BY c.env, c.run_stage, s.dp
ORDER BY c.env, c.run_stage
