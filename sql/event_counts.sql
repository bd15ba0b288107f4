-- How often each event kind occurs per environment, with the first and last time it is seen.
SELECT env, kind, count(*) AS n, min(t) AS first_t, max(t) AS last_t
FROM events
GROUP BY env, kind
ORDER BY env, n DESC, kind
