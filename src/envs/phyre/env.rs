//! [`PhyreEnv`]: PHYRE behind the [`Environment`] trait, plus the dataset order of tasks.

use sha2::{Digest, Sha256};

use super::action::BallAction;
use super::episode::{RecordOptions, run};
use super::params::PhysicsParams;
use super::task::Task;
use super::tasks::TaskSet;
use super::to_trace::trace_of;
use crate::digest::hex;
use crate::envs::{ActionDim, EnvError, Environment};
use crate::trace::{Env, Trace};

/// The PHYRE ball-tier environment: the committed 2,500 tasks, PHYRE's physics, a frame stride.
#[derive(Debug, Clone, Default)]
pub struct PhyreEnv {
    /// Physics constants.
    pub params: PhysicsParams,
    /// What to record.
    pub record: RecordOptions,
}

impl PhyreEnv {
    /// The trace id of a replayed action: `phyre-<template>-<variant>-<8 hex digits of the action>`.
    pub fn trace_id(task_id: &str, action: &BallAction) -> String {
        let h = Sha256::digest(format!("{:?} {:?} {:?}", action.x, action.y, action.r).as_bytes());
        format!("phyre-{}-{}", task_id.replace(':', "-"), hex(&h[..4]))
    }

    /// The trace id of sample `k` on task `task_id` in a dataset seeded with `seed`.
    pub fn dataset_trace_id(seed: u64, task_id: &str, k: u64) -> String {
        format!("phyre-{seed}-{}-{k:03}", task_id.replace(':', "-"))
    }
}

/// The tasks a dataset of `n` tasks uses, in order: template by template round-robin (task `i` is variant
/// `i / T` of template `i mod T`, T the number of templates), so even a few dozen tasks cover every
/// template. `only` restricts to the given template ids (`00003`) and task ids (`00003:002`).
pub fn dataset_tasks(set: &TaskSet, n: usize, only: &[String]) -> Vec<String> {
    let wanted: std::collections::HashSet<&str> = only.iter().map(String::as_str).collect();
    let keep = |id: &str| {
        wanted.is_empty()
            || wanted.contains(id)
            || id.split(':').next().is_some_and(|t| wanted.contains(t))
    };
    let per_template: Vec<Vec<&str>> = set
        .templates()
        .into_iter()
        .map(|t| {
            set.template_tasks(t)
                .into_iter()
                .filter(|id| keep(id))
                .collect::<Vec<_>>()
        })
        .filter(|v| !v.is_empty())
        .collect();
    let total: usize = per_template.iter().map(Vec::len).sum();
    let mut out = Vec::with_capacity(n.min(total));
    let mut round = 0;
    while out.len() < n.min(total) {
        for ids in &per_template {
            if let Some(id) = ids.get(round)
                && out.len() < n
            {
                out.push(id.to_string());
            }
        }
        round += 1;
    }
    out
}

impl Environment for PhyreEnv {
    type Scene = Task;
    type Action = BallAction;

    fn env(&self) -> Env {
        Env::Phyre
    }

    /// The first `n` tasks in [`dataset_tasks`] order (fewer when `n` exceeds 2,500); the tasks are
    /// fixed, so `seed` does not change them.
    fn scenes(&self, n: usize, seed: u64) -> Result<Vec<Task>, EnvError> {
        let _ = seed;
        let set = TaskSet::default_tasks()?;
        dataset_tasks(set, n, &[])
            .iter()
            .map(|id| set.get(id).map_err(EnvError::from))
            .collect()
    }

    fn action_space(&self) -> Vec<ActionDim> {
        vec![
            ActionDim {
                name: "x",
                unit: "1",
                low: 0.0,
                high: 1.0,
                doc: "ball centre x as a fraction of the scene (× 255 px, truncated)",
            },
            ActionDim {
                name: "y",
                unit: "1",
                low: 0.0,
                high: 1.0,
                doc: "ball centre y, upwards, as a fraction of the scene (× 255 px, truncated)",
            },
            ActionDim {
                name: "r",
                unit: "1",
                low: 0.0,
                high: 1.0,
                doc: "ball radius: 2 + r·30 px, rounded",
            },
        ]
    }

    fn validate(&self, scene: &Task, action: &BallAction) -> Result<(), EnvError> {
        let _ = scene;
        self.params.validate()?;
        action.validate()?;
        Ok(())
    }

    fn simulate(&self, scene: &Task, action: &BallAction) -> Result<Trace, EnvError> {
        let result = run(scene, action, &self.params, &self.record)?;
        Ok(trace_of(
            &result,
            scene,
            &PhyreEnv::trace_id(&scene.task_id, action),
        ))
    }

    fn render(&self, trace: &Trace, t: f64) -> Result<Vec<u8>, EnvError> {
        let set = TaskSet::default_tasks()?;
        let task = set.get(&trace.task_id)?;
        super::render::render_png(trace, &task, t, &super::render::RenderOptions::default())
            .map_err(|e| EnvError::Render(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dataset_order_covers_templates_first() {
        let set = TaskSet::default_tasks().unwrap();
        let ids = dataset_tasks(set, 30, &[]);
        assert_eq!(ids.len(), 30);
        assert_eq!(
            (ids[0].as_str(), ids[1].as_str(), ids[25].as_str()),
            ("00000:000", "00001:000", "00000:001")
        );
        let t3 = set.template_tasks("00003");
        let t7 = set.template_tasks("00007")[3].to_string();
        let only = dataset_tasks(set, 4, &["00003".into(), t7.clone()]);
        assert_eq!(only, [t3[0], t7.as_str(), t3[1], t3[2]]);
        assert_eq!(dataset_tasks(set, 9999, &[]).len(), 2500);
    }

    #[test]
    fn environment_simulates_and_renders() {
        let env = PhyreEnv::default();
        let scenes = env.scenes(2, 0).unwrap();
        let a = BallAction {
            x: 0.5,
            y: 0.9,
            r: 0.2,
        };
        env.validate(&scenes[1], &a).unwrap();
        let tr = env.simulate(&scenes[1], &a).unwrap();
        assert_eq!(tr.env, Env::Phyre);
        assert!(tr.trace_id.starts_with("phyre-00001-000-"));
        let png = env.render(&tr, 0.0).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        assert!(
            env.validate(
                &scenes[0],
                &BallAction {
                    x: 2.0,
                    y: 0.0,
                    r: 0.0
                }
            )
            .is_err()
        );
    }
}
