//! The tasks of the benchmark and what an attempt does to them: choosing tasks per environment, the
//! images an agent sees before acting, and applying a parsed [`Answer`] through the environments'
//! simulators ([`crate::envs::Environment`]).
//!
//! PHYRE tasks come from the test split of a ball-tier evaluation fold (`ball_within_template` or
//! `ball_cross_template`), round-robin over templates; I-PHYRE tasks are the 40 games in order, played at
//! DeepPHY's 10 fps; billiards tasks are seeded 9-ball racks played as DeepPHY does, on the evolving
//! table: each shot starts where the previous one left the balls, pocketed balls stay down, a pocketed
//! cue ball is put back on the head spot, and the task is solved when the 9-ball drops.

use serde::{Deserialize, Serialize};

use super::BenchError;
use super::action::{Answer, IPHYRE_FPS, Invalid};
use crate::envs::iphyre::{self, Click, Game, IphyreEnv, click_block};
use crate::envs::phyre::{self, EvalSetup, PhyreEnv, Placement, TaskSet, dataset_tasks};
use crate::envs::pool::deepphy::DeepphyAction;
use crate::envs::pool::{PoolEnv, Scene, SceneBall};
use crate::envs::{EnvError, Environment};
use crate::trace::{Body, Env, Trace};

/// A task's state before an attempt.
#[derive(Clone, Debug)]
pub enum TaskScene {
    /// A PHYRE task.
    Phyre(phyre::Task),
    /// An I-PHYRE game.
    Iphyre(Game),
    /// A billiards table (the rack, or where the previous shot left the balls).
    Pool(Scene),
}

impl TaskScene {
    /// The task id (`00004:012`, a game name, a rack id).
    pub fn id(&self) -> &str {
        match self {
            TaskScene::Phyre(t) => &t.task_id,
            TaskScene::Iphyre(g) => &g.name,
            TaskScene::Pool(s) => &s.scene_id,
        }
    }

    /// Removable I-PHYRE blocks (0 for other environments).
    pub fn blocks(&self) -> usize {
        match self {
            TaskScene::Iphyre(g) => g.eliminable().count(),
            _ => 0,
        }
    }

    /// The PHYRE goal sentence, if any.
    pub fn description(&self) -> Option<&str> {
        match self {
            TaskScene::Phyre(t) => Some(&t.description),
            _ => None,
        }
    }
}

/// Which billiards action format to use.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum PoolAction {
    /// DeepPHY's speed level and strike spot, φ aimed automatically at the lowest-numbered ball.
    #[default]
    Deepphy,
    /// Every shot parameter (V0, φ, θ, a, b) chosen by the agent.
    Free,
}

/// The simulators of the benchmark.
#[derive(Clone, Debug)]
pub struct Simulators {
    /// PHYRE.
    pub phyre: PhyreEnv,
    /// I-PHYRE at 10 fps.
    pub iphyre: IphyreEnv,
    /// Billiards (traces at dt 0.02 s).
    pub pool: PoolEnv,
}

impl Simulators {
    /// The benchmark's simulators: PHYRE as is, I-PHYRE at DeepPHY's 10 fps, billiards traces at 0.02 s.
    pub fn new() -> Result<Self, EnvError> {
        let mut iphyre = IphyreEnv::new()?;
        iphyre.params = iphyre::PhysicsParams::with_fps(IPHYRE_FPS);
        let mut pool = PoolEnv::default();
        pool.trace.dt = 0.02;
        Ok(Simulators {
            phyre: PhyreEnv::default(),
            iphyre,
            pool,
        })
    }
}

/// How the tasks of a benchmark are chosen.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskChoice {
    /// The environment.
    pub env: Env,
    /// How many tasks.
    pub count: usize,
    /// Only these task ids (PHYRE `00004:012`, I-PHYRE game names, billiards rack indices as numbers).
    pub ids: Vec<String>,
    /// PHYRE's evaluation setup.
    pub phyre_setup: EvalSetup,
    /// PHYRE's fold seed.
    pub phyre_fold: u64,
    /// Seed of the billiards racks.
    pub pool_seed: u64,
}

/// The tasks of `choice`, in benchmark order.
pub fn choose_tasks(sims: &Simulators, choice: &TaskChoice) -> Result<Vec<TaskScene>, BenchError> {
    match choice.env {
        Env::Phyre => {
            let set = TaskSet::default_tasks().map_err(EnvError::from)?;
            let test = phyre::fold(set, choice.phyre_setup, choice.phyre_fold).test;
            let pool: Vec<String> = if choice.ids.is_empty() {
                test
            } else {
                if let Some(bad) = choice.ids.iter().find(|id| !set.contains(id)) {
                    return Err(BenchError::UnknownTask(format!("no PHYRE task {bad:?}")));
                }
                choice.ids.clone()
            };
            dataset_tasks(set, choice.count, &pool)
                .iter()
                .map(|id| {
                    set.get(id)
                        .map(TaskScene::Phyre)
                        .map_err(|e| BenchError::Env(e.into()))
                })
                .collect()
        }
        Env::Iphyre => {
            let all = sims.iphyre.games.all();
            let games: Vec<&Game> = if choice.ids.is_empty() {
                all.iter().collect()
            } else {
                choice
                    .ids
                    .iter()
                    .map(|id| {
                        sims.iphyre
                            .games
                            .get(id)
                            .map_err(|_| BenchError::UnknownTask(format!("no I-PHYRE game {id:?}")))
                    })
                    .collect::<Result<_, _>>()?
            };
            Ok(games
                .into_iter()
                .take(choice.count)
                .map(|g| TaskScene::Iphyre(g.clone()))
                .collect())
        }
        Env::Pooltool => {
            let n = if choice.ids.is_empty() {
                choice.count
            } else {
                let mut max = 0;
                for id in &choice.ids {
                    let i: usize = id.parse().map_err(|_| {
                        BenchError::UnknownTask(format!(
                            "billiards task ids are rack indices (0, 1, …), not {id:?}"
                        ))
                    })?;
                    max = max.max(i + 1);
                }
                max
            };
            let scenes = sims.pool.scenes(n, choice.pool_seed)?;
            let picked: Vec<Scene> = if choice.ids.is_empty() {
                scenes
            } else {
                choice
                    .ids
                    .iter()
                    .map(|id| scenes[id.parse::<usize>().unwrap_or(0)].clone())
                    .take(choice.count)
                    .collect()
            };
            Ok(picked.into_iter().map(TaskScene::Pool).collect())
        }
    }
}

/// What one valid attempt did.
#[derive(Clone, Debug)]
pub struct Rollout {
    /// The simulated trace.
    pub trace: Trace,
    /// Whether the task was solved.
    pub success: bool,
    /// The state the next attempt starts from (billiards: the evolved table; others: unchanged).
    pub next: TaskScene,
}

/// Applies `answer` to `scene`: `Err(Ok(invalid))` when the answer is not a valid action there (out of
/// range, occluding), `Err(Err(e))` when a simulator failed.
pub fn attempt(
    sims: &Simulators,
    scene: &TaskScene,
    answer: &Answer,
) -> Result<Rollout, Result<Invalid, BenchError>> {
    let env_err = |e: EnvError| Err(BenchError::Env(e));
    match (scene, answer) {
        (TaskScene::Phyre(task), Answer::Phyre { cell, radius }) => {
            let action = phyre::deepphy_action(*cell, *radius)
                .map_err(|e| Ok(Invalid::OutOfRange(e.to_string())))?;
            match action.place(task).map_err(|e| env_err(e.into()))? {
                Placement::Valid(_) => {}
                Placement::OutsideScene => {
                    return Err(Ok(Invalid::OutOfRange(format!(
                        "a radius-{radius} ball in cell {cell} crosses the scene border"
                    ))));
                }
                Placement::Occludes { body } => {
                    let what = task
                        .bodies
                        .get(body)
                        .map(|b| format!("the {} {}", b.color.name(), b.shape_type))
                        .unwrap_or_else(|| format!("body {body}"));
                    return Err(Ok(Invalid::Occluding(format!(
                        "a radius-{radius} ball in cell {cell} overlaps {what}"
                    ))));
                }
            }
            let trace = sims.phyre.simulate(task, &action).map_err(env_err)?;
            Ok(Rollout {
                success: sims.phyre.success(&trace),
                trace,
                next: scene.clone(),
            })
        }
        (TaskScene::Iphyre(game), Answer::Iphyre(removals)) => {
            let dt = 1.0 / IPHYRE_FPS;
            let clicks: Vec<Click> = removals
                .iter()
                .map(|r| {
                    // A removal at t = 0 happens at the first step (I-PHYRE drops clicks at exactly 0).
                    let t = if r.time <= 0.0 { dt } else { r.time };
                    click_block(game, r.index as usize, t)
                        .map_err(|e| Ok(Invalid::OutOfRange(e.to_string())))
                })
                .collect::<Result<_, _>>()?;
            sims.iphyre
                .validate(game, &clicks)
                .map_err(|e| Ok(Invalid::OutOfRange(e.to_string())))?;
            let trace = sims.iphyre.simulate(game, &clicks).map_err(env_err)?;
            Ok(Rollout {
                success: sims.iphyre.success(&trace),
                trace,
                next: scene.clone(),
            })
        }
        (TaskScene::Pool(table), Answer::PoolDeepphy(_) | Answer::PoolFree(_)) => {
            let shot = match answer {
                Answer::PoolDeepphy(a) => DeepphyAction::to_shot(a, table)
                    .map_err(|e| Ok(Invalid::OutOfRange(e.to_string())))?,
                Answer::PoolFree(s) => *s,
                _ => unreachable!("matched above"),
            };
            sims.pool
                .validate(table, &shot)
                .map_err(|e| Ok(Invalid::OutOfRange(e.to_string())))?;
            let trace = sims.pool.simulate(table, &shot).map_err(env_err)?;
            let success = sims.pool.success(&trace);
            let next = TaskScene::Pool(evolved_table(sims, table, &trace));
            Ok(Rollout {
                trace,
                success,
                next,
            })
        }
        _ => Err(Err(BenchError::Internal(format!(
            "an answer of another environment for task {}",
            scene.id()
        )))),
    }
}

/// Where a shot left the balls: the last timestep's balls that are not pocketed; a pocketed cue ball
/// goes back on the head spot (moved up the table past any ball in the way). Falls back to `before`
/// when the result is not a valid scene.
pub fn evolved_table(sims: &Simulators, before: &Scene, trace: &Trace) -> Scene {
    let Some(last) = trace.timesteps.last() else {
        return before.clone();
    };
    let config = &sims.pool.config;
    let r = config.ball.r;
    let (w, l) = (config.table.w, config.table.l);
    let mut balls: Vec<SceneBall> = Vec::new();
    let mut cue_down = true;
    for o in &last.objects {
        let Body::Pool(b) = &o.body else { continue };
        if b.motion_state == "pocketed" || b.motion_state_code == 4 {
            continue;
        }
        if b.ball_id == before.cue_ball {
            cue_down = false;
        }
        balls.push(SceneBall {
            id: b.ball_id.to_string(),
            x: b.position[0].clamp(r, w - r),
            y: b.position[1].clamp(r, l - r),
        });
    }
    if cue_down {
        let mut y = l / 4.0;
        while y < l - r
            && balls
                .iter()
                .any(|b| (b.x - w / 2.0).hypot(b.y - y) < 2.0 * r + 1e-6)
        {
            y += 2.0 * r;
        }
        balls.insert(
            0,
            SceneBall {
                id: before.cue_ball.clone(),
                x: w / 2.0,
                y,
            },
        );
    }
    let next = Scene {
        balls,
        ..before.clone()
    };
    if next.validate(config).is_ok() {
        next
    } else {
        before.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::action::{Format, parse};

    fn choice(env: Env, n: usize) -> TaskChoice {
        TaskChoice {
            env,
            count: n,
            ids: vec![],
            phyre_setup: EvalSetup::WithinTemplate,
            phyre_fold: 0,
            pool_seed: 3,
        }
    }

    #[test]
    fn tasks_come_from_the_test_fold_round_robin() {
        let sims = Simulators::new().unwrap();
        let t = choose_tasks(&sims, &choice(Env::Phyre, 30)).unwrap();
        assert_eq!(t.len(), 30);
        let templates: std::collections::BTreeSet<&str> = t.iter().map(|s| &s.id()[..5]).collect();
        assert_eq!(templates.len(), 25);
        let test = phyre::fold(
            TaskSet::default_tasks().unwrap(),
            EvalSetup::WithinTemplate,
            0,
        )
        .test;
        assert!(t.iter().all(|s| test.iter().any(|id| id == s.id())));
        assert_eq!(
            choose_tasks(&sims, &choice(Env::Iphyre, 3)).unwrap()[0].id(),
            "support"
        );
        assert_eq!(
            choose_tasks(&sims, &choice(Env::Pooltool, 2))
                .unwrap()
                .len(),
            2
        );
    }

    #[test]
    fn an_occluding_phyre_ball_is_invalid_and_a_free_one_simulates() {
        let sims = Simulators::new().unwrap();
        let task = choose_tasks(&sims, &choice(Env::Phyre, 1))
            .unwrap()
            .remove(0);
        let mut occluding = 0;
        let mut valid = 0;
        for cell in 1..=64 {
            let a = parse(Format::PhyreGrid, &format!("Cell: {cell}, Radius: 8"), 0).unwrap();
            match attempt(&sims, &task, &a) {
                Ok(r) => {
                    valid += 1;
                    assert_eq!(r.trace.env, Env::Phyre);
                    break;
                }
                Err(Ok(Invalid::Occluding(_) | Invalid::OutOfRange(_))) => occluding += 1,
                Err(e) => panic!("{e:?}"),
            }
        }
        assert!(occluding > 0 && valid == 1);
    }

    #[test]
    fn the_pool_table_evolves_between_shots() {
        let sims = Simulators::new().unwrap();
        let rack = choose_tasks(&sims, &choice(Env::Pooltool, 1))
            .unwrap()
            .remove(0);
        let a = parse(
            Format::PoolDeepphy,
            "Speed: High, Strikespot: Middle Spin",
            0,
        )
        .unwrap();
        let r = attempt(&sims, &rack, &a).unwrap();
        let (TaskScene::Pool(before), TaskScene::Pool(after)) = (&rack, &r.next) else {
            panic!()
        };
        assert_ne!(before.balls, after.balls, "the break moved the balls");
        assert!(after.balls.iter().any(|b| b.id == "cue"));
    }
}
