//! The `simulate` stage with `env = "phyre"`: PHYRE ball-tier episodes (Box2D or rapier2d, `envs::phyre`) into the
//! trace tables, sharded and resumable like the other environments.
//!
//! **Owns:** the PHYRE half of the `simulate` stage: reading its parameters, choosing the (task, action)
//! work list, scene and trace ids, and simulating one work item (a task and action) into its scene row,
//! trace and counts.
//! **Does not:** declare the stage kind or its parameter list (`simulate.rs`, which routes here), or
//! simulate anything itself (`envs::phyre`).
//!
//! Two modes. **Dataset**: `scenes` tasks taken round-robin over templates from the `tasks` selection
//! (default all 2,500; items are `all`, template ids `00003`, task ids `00003:002`, and fold splits
//! `ball_within_template/0/test`), with `shots` seeded random valid actions each (uniform draws from
//! [0, 1]³ until the ball fits, from (`seed`, task, sample) alone, so the tables do not depend on sharding
//! or thread count). Every `scenes_per_shard` traces make one shard. **Replay**: `task` and `action`
//! (`[x, y, r]`, `{"x", "y", "r"}` or DeepPHY's `{"cell": 1-64, "radius": 1-8}`) give one trace, which
//! may end `INVALID_INPUT`. Bad input (an unknown task, template or fold, an action out of [0, 1] or not
//! finite, a stride outside 1..=1000) fails when the stage is built, before anything is written.
//!
//! Ids: scenes are `phyre-<template>-<variant>` (one row per task, written with its first trace); dataset
//! traces are `phyre-<seed>-<template>-<variant>-<sample:03>`, a replay `phyre-<template>-<variant>-<8 hex
//! digits of the action's hash>`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use sha2::{Digest, Sha256};

use super::shards::{Count, ItemOutput, ShardTotals, replay_pair};
use super::{ShardParams, SimulateSummary, Simulation};
use crate::digest::hex;
use crate::envs::phyre::{
    BallAction, DEFAULT_STRIDE, DEFAULT_TASKS_FINGERPRINT, Engine, EvalSetup, PhyreEnv,
    PhysicsParams, RecordOptions, Status, Task, TaskSet, action_rng, dataset_tasks, episode, fold,
    random_valid_action, trace_columns,
};
use crate::pipeline::registry::BuildError;
use crate::pipeline::spec::PipelineSpec;
use crate::pipeline::stage::StageError;
use crate::trace::Env;
use crate::trace::batch::scene_batch;

/// PHYRE `simulate` parameters.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct PhyreSimParams {
    /// Dataset mode: number of tasks, round-robin over the templates `tasks` selects.
    pub scenes: u64,
    /// Shots, seed and sharding.
    #[serde(flatten)]
    pub shards: ShardParams,
    /// Dataset mode: comma-separated template ids (00003), task ids (00003:002), fold splits
    /// (ball_cross_template/0/test) or all (default); `shots` random valid actions per task.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tasks: Option<String>,
    /// Replay mode: the task id (00004:063).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub task: Option<String>,
    /// Replay mode: `[x, y, r]` in [0, 1], `{"x", "y", "r"}`, or DeepPHY's `{"cell": 1-64, "radius":
    /// 1-8}`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub action: Option<String>,
    /// Keep a frame every this many 60 Hz steps (default 6, i.e. 10 frames/s; events keep every
    /// step).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stride: Option<u64>,
    /// Physics engine: `box2d` (default; PHYRE's own engine, reproduces 97 % of its solving actions)
    /// or `rapier` (rapier2d, 62 %; docs/fidelity.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub engine: Option<Engine>,
}

impl Default for PhyreSimParams {
    fn default() -> Self {
        PhyreSimParams {
            scenes: 10,
            shards: ShardParams::default(),
            tasks: None,
            task: None,
            action: None,
            stride: None,
            engine: None,
        }
    }
}

/// What to simulate.
#[derive(Debug)]
enum Work {
    /// `samples` random valid actions on each task.
    Dataset {
        tasks: Vec<String>,
        samples: u64,
        seed: u64,
    },
    /// One task, one action.
    Replay { task: String, action: BallAction },
}

/// PHYRE episodes for the `simulate` stage.
#[derive(Debug)]
pub(crate) struct PhyreSimulation {
    params: PhysicsParams,
    record: RecordOptions,
    work: Work,
}

/// Builds the PHYRE `simulate` stage from its parameters.
pub(super) fn build(
    p: &PhyreSimParams,
    spec: &PipelineSpec,
) -> Result<PhyreSimulation, BuildError> {
    let set = TaskSet::default_tasks().map_err(|e| BuildError::param("tasks", e.to_string()))?;
    let stride = p.stride.unwrap_or(DEFAULT_STRIDE as u64);
    let stride = usize::try_from(stride).unwrap_or(usize::MAX);
    episode::validate_stride(stride)
        .map_err(|e| BuildError::param("stride", format!("`stride`: {e}")))?;
    let work = match replay_pair(("task", p.task.as_deref()), ("action", p.action.as_deref()))? {
        Some((id, text)) => {
            if !set.contains(id) {
                return Err(BuildError::param(
                    "task",
                    format!(
                        "`task`: {}",
                        crate::envs::phyre::PhyreError::UnknownTask { id: id.to_string() }
                    ),
                ));
            }
            let action = BallAction::from_json_str(text)
                .map_err(|e| BuildError::param("action", format!("`action`: {e}")))?;
            Work::Replay {
                task: id.to_string(),
                action,
            }
        }
        None => {
            let only = select_tasks(set, p.tasks.as_deref().unwrap_or("all"))
                .map_err(|m| BuildError::param("tasks", format!("`tasks`: {m}")))?;
            Work::Dataset {
                tasks: dataset_tasks(set, usize::try_from(p.scenes).unwrap_or(usize::MAX), &only),
                samples: p.shards.shots,
                seed: p.shards.seed.unwrap_or(spec.seed),
            }
        }
    };
    Ok(PhyreSimulation {
        params: PhysicsParams {
            engine: p.engine.unwrap_or_default(),
            ..PhysicsParams::default()
        },
        record: RecordOptions {
            stride,
            record: true,
        },
        work,
    })
}

/// The task ids a `tasks` list selects: comma-separated `all`, template ids (`00003`), task ids
/// (`00003:002`) and fold splits (`ball_cross_template/0/test`: setup, seed, `train`/`dev`/`test`). An
/// empty result means every task.
pub fn select_tasks(set: &TaskSet, list: &str) -> Result<Vec<String>, String> {
    let mut out = Vec::new();
    for item in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        if item == "all" {
            return Ok(Vec::new());
        }
        if let Some((setup, rest)) = item.split_once('/') {
            let setup: EvalSetup = setup.parse().map_err(|e| format!("{item:?}: {e}"))?;
            let (seed, split) = rest.split_once('/').ok_or_else(|| {
                format!("{item:?}: a fold split is <setup>/<seed>/<train|dev|test>")
            })?;
            let seed: u64 = seed
                .parse()
                .map_err(|_| format!("{item:?}: fold seed {seed:?} is not a whole number"))?;
            let f = fold(set, setup, seed);
            let ids = match split {
                "train" => f.train,
                "dev" => f.dev,
                "test" => f.test,
                other => {
                    return Err(format!(
                        "{item:?}: split {other:?} is not train, dev or test"
                    ));
                }
            };
            out.extend(ids);
        } else if set.contains(item) || !set.template_tasks(item).is_empty() {
            out.push(item.to_string());
        } else {
            return Err(format!(
                "{item:?} is neither a PHYRE ball-tier task id (00004:063), a template id (00000-00024), a fold split (ball_within_template/0/test) nor all"
            ));
        }
    }
    if out.is_empty() {
        return Err(format!("{list:?} selects no task"));
    }
    Ok(out)
}

impl PhyreSimulation {
    /// Number of traces.
    fn total(&self) -> u64 {
        match &self.work {
            Work::Dataset { tasks, samples, .. } => tasks.len() as u64 * samples,
            Work::Replay { .. } => 1,
        }
    }

    /// Work item `i` (task-major): the task id, the sample number and the trace id.
    fn item(&self, i: u64) -> (&str, u64, String) {
        match &self.work {
            Work::Dataset {
                tasks,
                samples,
                seed,
            } => {
                let task = &tasks[(i / samples) as usize];
                let sample = i % samples;
                (
                    task,
                    sample,
                    PhyreEnv::dataset_trace_id(*seed, task, sample),
                )
            }
            Work::Replay { task, action } => (task, 0, PhyreEnv::trace_id(task, action)),
        }
    }

    /// The action of item `i` on `task`.
    fn action(&self, task: &Task, sample: u64, set: &TaskSet) -> Result<BallAction, StageError> {
        match &self.work {
            Work::Replay { action, .. } => Ok(*action),
            Work::Dataset { seed, .. } => {
                let index = set.position(&task.task_id).unwrap_or(0) as u64;
                random_valid_action(task, &mut action_rng(*seed, index, sample))
                    .map_err(|e| StageError::Simulation {
                        item: format!("task {}", task.task_id),
                        source: e.into(),
                    })?
                    .ok_or_else(|| StageError::Simulation {
                        item: format!("task {}", task.task_id),
                        source: format!(
                            "no valid action found in {} draws",
                            crate::envs::phyre::MAX_DRAWS
                        )
                        .into(),
                    })
            }
        }
    }
}

impl Simulation for PhyreSimulation {
    /// The resolved seed, the tasks, the stride, the engine and the task data: a changed pipeline seed
    /// or engine reruns.
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        let work = match &self.work {
            Work::Dataset {
                tasks,
                samples,
                seed,
            } => json!({
                "seed": seed,
                "samples": samples,
                "tasks": hex(&Sha256::digest(tasks.join(",").as_bytes())),
                "n_tasks": tasks.len(),
            }),
            Work::Replay { task, action } => {
                json!({"task": task, "action": [action.x, action.y, action.r]})
            }
        };
        Ok(
            json!({"env": "phyre", "engine": self.params.engine.name(), "stride": self.record.stride, "tasks_data": DEFAULT_TASKS_FINGERPRINT, "work": work}),
        )
    }

    fn env(&self) -> Env {
        Env::Phyre
    }

    fn items(&self) -> u64 {
        self.total()
    }

    fn trace_ids(&self, i: u64) -> Vec<String> {
        vec![self.item(i).2]
    }

    fn simulate_item(&self, index: u64, source: &str) -> Result<ItemOutput, StageError> {
        let tasks_error = |e: crate::envs::phyre::PhyreError| StageError::Simulation {
            item: "PHYRE tasks".to_string(),
            source: e.into(),
        };
        let set = TaskSet::default_tasks().map_err(tasks_error)?;
        let (task_id, sample, trace_id) = self.item(index);
        let task = set.get(task_id).map_err(tasks_error)?;
        let scene_id = format!("phyre-{}", task_id.replace(':', "-"));
        let scene = if sample == 0 {
            let spec = json!({
                "task_id": task.task_id,
                "template_id": task.template_id,
                "description": task.description,
                "goal": {"body1": task.body1, "body2": task.body2, "relationships": task.relationships},
                "bodies": task.bodies.len(),
            });
            Some(scene_batch(
                &scene_id,
                task_id,
                source,
                task.bodies.len(),
                &spec,
            )?)
        } else {
            None
        };
        let action = self.action(&task, sample, set)?;
        let result = episode::run(&task, &action, &self.params, &self.record).map_err(|e| {
            StageError::Simulation {
                item: format!("trace {trace_id}"),
                source: e.into(),
            }
        })?;
        let trace = trace_columns(&result, &task, &trace_id);
        Ok(ItemOutput {
            scene,
            scene_id,
            traces: vec![trace],
            counts: vec![
                (
                    "successes",
                    Count::Int(u64::from(result.status == Status::Solved)),
                ),
                (
                    "invalid",
                    Count::Int(u64::from(result.status == Status::InvalidInput)),
                ),
                ("steps", Count::Int(result.steps as u64)),
            ],
        })
    }

    fn report(&self, sums: &ShardTotals) -> (SimulateSummary, String) {
        let (traces, successes) = (sums.count("traces"), sums.count("successes"));
        let (invalid, steps) = (sums.count("invalid"), sums.count("steps"));
        let frames = sums.rows.get("frames").copied().unwrap_or(0);
        let line = format!(
            "{traces} phyre trace(s), {successes} solved, {invalid} invalid input; {steps} physics steps, {frames} frame rows (stride {})",
            self.record.stride
        );
        let summary = SimulateSummary {
            env: Env::Phyre,
            traces,
            successes,
            capped: Some(0),
            invalid: Some(invalid),
            steps: Some(steps),
            stride: Some(self.record.stride as u64),
            ..SimulateSummary::default()
        };
        (summary, line)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn task_selections_and_their_errors() {
        let set = TaskSet::default_tasks().unwrap();
        assert!(select_tasks(set, "all").unwrap().is_empty());
        assert_eq!(
            select_tasks(set, "00003, 00004:063").unwrap(),
            ["00003", "00004:063"]
        );
        assert_eq!(
            select_tasks(set, "ball_cross_template/0/test")
                .unwrap()
                .len(),
            500
        );
        assert!(select_tasks(set, "00099").unwrap_err().contains("00099"));
        assert!(
            select_tasks(set, "ball_cross_template/x/test")
                .unwrap_err()
                .contains("seed")
        );
        assert!(
            select_tasks(set, "ball_cross_template/0/val")
                .unwrap_err()
                .contains("val")
        );
        assert!(select_tasks(set, "nope/0/test").is_err());
    }
}
