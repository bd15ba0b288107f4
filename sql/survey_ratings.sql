-- The human study of summaries (the paper's appendix D): ratings (1–7 Likert) per condition, per
-- environment and over all environments (env = 'all'): participants, ratings, mean and standard
-- deviation (population, as the project's figures). Reads `survey_responses` (annotrace import-survey).
SELECT env, condition,
       count(DISTINCT participant) AS participants,
       count(*) AS n,
       round(avg(CAST(rating AS DOUBLE)), 3) AS mean,
       round(stddev_pop(CAST(rating AS DOUBLE)), 3) AS std
FROM (
    SELECT env, condition, participant, rating FROM survey_responses
    UNION ALL
    SELECT 'all' AS env, condition, participant, rating FROM survey_responses
) AS r
GROUP BY env, condition
ORDER BY env = 'all', env, condition
