-- Success rate per goal and reward type at the largest budget of the run (mean over scenes and seeds),
-- with the mean best reward found.
SELECT goal,
       reward_type,
       MAX(budget) AS budget,
       AVG(CASE WHEN success THEN 1.0 ELSE 0.0 END) AS success_rate,
       AVG(best_reward) AS best_reward
FROM optimisation
WHERE budget = (SELECT MAX(budget) FROM optimisation)
GROUP BY goal, reward_type
ORDER BY goal, reward_type
