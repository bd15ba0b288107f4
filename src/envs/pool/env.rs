//! [`PoolEnv`]: billiards behind the [`Environment`] trait.

use super::config::PoolConfig;
use super::render::{self, RenderOptions};
use super::scene::Scene;
use super::shot::Shot;
use super::simulate::{SimOptions, simulate};
use super::to_trace::{TraceOptions, trace_columns};
use crate::envs::{ActionDim, EnvError, Environment};
use crate::trace::{Env, Trace, TraceColumns};

/// The billiards environment: a table config, simulation caps and the trace's `dt`.
#[derive(Debug, Clone)]
pub struct PoolEnv {
    /// Table, balls and cue.
    pub config: PoolConfig,
    /// Event and time caps.
    pub sim: SimOptions,
    /// Timestep spacing of the traces.
    pub trace: TraceOptions,
}

impl Default for PoolEnv {
    /// The default 7-ft table, default caps, dt = 0.01 s.
    fn default() -> Self {
        PoolEnv {
            config: PoolConfig::default_7ft(),
            sim: SimOptions::default(),
            trace: TraceOptions::default(),
        }
    }
}

impl PoolEnv {
    /// The trace id [`Environment::simulate`] gives a shot: `<scene_id>-shot`.
    pub fn trace_id(scene: &Scene) -> String {
        format!("{}-shot", scene.scene_id)
    }

    /// [`Environment::simulate`]'s trace in columns, before its paper-layout `Trace` is built (the
    /// optimiser checks sparse samples on these: `Rule::holds_on_columns`).
    pub fn simulate_columns(&self, scene: &Scene, action: &Shot) -> Result<TraceColumns, EnvError> {
        let system = scene.system(&self.config)?;
        let sim = simulate(&system, action, &self.sim)?;
        Ok(trace_columns(
            &sim,
            scene,
            action,
            &PoolEnv::trace_id(scene),
            &self.trace,
        ))
    }
}

impl Environment for PoolEnv {
    type Scene = Scene;
    type Action = Shot;

    fn env(&self) -> Env {
        Env::Pooltool
    }

    /// Seeded 9-ball racks: scene `i` is the rack of `rack::scene_seed(seed, i)`, named
    /// `pool-<seed>-<i:06>` (the ids the `simulate` stage gives them).
    fn scenes(&self, n: usize, seed: u64) -> Result<Vec<Scene>, EnvError> {
        Ok((0..n as u64)
            .map(|i| {
                let mut scene = Scene::nine_ball(&self.config, super::rack::scene_seed(seed, i));
                scene.scene_id = format!("pool-{seed}-{i:06}");
                scene
            })
            .collect())
    }

    fn action_space(&self) -> Vec<ActionDim> {
        vec![
            ActionDim {
                name: "V0",
                unit: "m/s",
                low: 0.0,
                high: 10.0,
                doc: "cue speed (≥ 0; the upper bound is a sampling range, not a rule)",
            },
            ActionDim {
                name: "phi",
                unit: "deg",
                low: 0.0,
                high: 360.0,
                doc: "aim direction, counter-clockwise from +x",
            },
            ActionDim {
                name: "theta",
                unit: "deg",
                low: 0.0,
                high: 90.0,
                doc: "cue elevation",
            },
            ActionDim {
                name: "a",
                unit: "R",
                low: -1.0,
                high: 1.0,
                doc: "side offset of the tip (+ left); a² + b² < 1",
            },
            ActionDim {
                name: "b",
                unit: "R",
                low: -1.0,
                high: 1.0,
                doc: "vertical offset of the tip (+ top); a² + b² < 1",
            },
        ]
    }

    fn validate(&self, scene: &Scene, action: &Shot) -> Result<(), EnvError> {
        scene.validate(&self.config)?;
        action.validate()?;
        Ok(())
    }

    fn simulate(&self, scene: &Scene, action: &Shot) -> Result<Trace, EnvError> {
        Ok(self.simulate_columns(scene, action)?.into_trace())
    }

    fn render(&self, trace: &Trace, t: f64) -> Result<Vec<u8>, EnvError> {
        render::render_png(trace, &self.config, t, &RenderOptions::default())
    }
}
