-- One row per environment: how many traces, steps and frame rows a run holds, how long the traces
-- last and how often they succeed. Used by pipelines/quickstart.toml.
SELECT
    t.env,
    count(*)                                   AS traces,
    sum(t.n_steps)                             AS steps,
    sum(t.n_frames)                            AS frame_rows,
    sum(t.n_events)                            AS events,
    avg(t.t_end - t.t_start)                   AS mean_duration_s,
    avg(CASE WHEN t.success THEN 1.0 ELSE 0.0 END) AS success_rate
FROM traces AS t
GROUP BY t.env
ORDER BY t.env
