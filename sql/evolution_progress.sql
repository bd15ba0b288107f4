-- How fitness moved during each label's search: per label and 10 % bin of the budget, the best ν found so
-- far (the seed program counts from the start), the best and mean ν of the bin's scored candidates, and
-- the bin's candidates and executable share. The best-so-far column should go up.
WITH seeds AS (
    SELECT run_stage, label, max(nu) AS seed_nu
    FROM candidates WHERE step < 0 GROUP BY run_stage, label
),
binned AS (
    SELECT c.run_stage, c.env, c.label, c.label_index,
           CAST(floor(10.0 * c.step / c.budget) AS BIGINT) AS bin,
           c.nu, c.status, c.executable
    FROM candidates AS c WHERE c.step >= 0
),
per_bin AS (
    SELECT run_stage, env, label, label_index, bin,
           count(*) AS candidates,
           100.0 * avg(CASE WHEN executable THEN 1.0 ELSE 0.0 END) AS executable_pct,
           max(nu) AS bin_best_nu,
           avg(nu) AS bin_mean_nu
    FROM binned GROUP BY run_stage, env, label, label_index, bin
)
SELECT p.env, p.run_stage, p.label, p.bin,
       p.candidates, p.executable_pct,
       s.seed_nu,
       p.bin_best_nu, p.bin_mean_nu,
       greatest(s.seed_nu, coalesce(max(p.bin_best_nu) OVER (
           PARTITION BY p.run_stage, p.label ORDER BY p.bin
           ROWS BETWEEN UNBOUNDED PRECEDING AND CURRENT ROW), s.seed_nu)) AS best_so_far_nu
FROM per_bin AS p JOIN seeds AS s ON s.run_stage = p.run_stage AND s.label = p.label
ORDER BY p.env, p.run_stage, p.label_index, p.bin
