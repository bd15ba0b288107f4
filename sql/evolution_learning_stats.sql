-- Appendix A of the paper ("Pattern Learning Statistics"): one row per environment over every candidate
-- program the evolve stages of the run produced (seed programs excluded). Executable = ran on every
-- training trace without error (status ok, duplicate, same_behaviour or degenerate); fitness statistics
-- are over scored candidates (status ok); activation % is the mean share of training traces in which an
-- executable candidate reports at least one pattern. Used by pipelines/quickstart.toml.
SELECT
    c.env,
    count(*)                                                        AS candidates,
    100.0 * avg(CASE WHEN c.executable THEN 1.0 ELSE 0.0 END)       AS executable_pct,
    max(c.nu)                                                       AS best_fitness,
    avg(c.nu)                                                       AS avg_fitness,
    stddev(c.nu)                                                    AS fitness_std,
    avg(CAST(c.lines AS DOUBLE))                                    AS avg_lines,
    100.0 * avg(c.activation_rate)                                  AS activation_pct
FROM candidates AS c
WHERE c.step >= 0
GROUP BY c.env
ORDER BY c.env
