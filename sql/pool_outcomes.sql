-- Billiards shots by how they ended: how many, how often the 9-ball was potted, and the mean length,
-- physics-event count and balls pocketed per shot. Used by pipelines/quickstart.toml.
SELECT
    terminal_status,
    count(*)                                                                   AS shots,
    avg(CASE WHEN success THEN 1.0 ELSE 0.0 END)                               AS success_rate,
    avg(t_end - t_start)                                                       AS mean_duration_s,
    avg(CAST(regexp_match(metrics, '"n_events":([0-9]+)')[1] AS DOUBLE))       AS mean_events,
    avg(CAST(regexp_match(metrics, '"balls_pocketed":([0-9]+)')[1] AS DOUBLE)) AS mean_pocketed
FROM traces
WHERE env = 'pooltool' AND source LIKE 'simulate:%'
GROUP BY terminal_status
ORDER BY shots DESC, terminal_status
