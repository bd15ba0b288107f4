//! `simulate`: runs an environment's simulator and writes the trace tables (scenes, traces, timesteps,
//! frames, events), sharded and resumable.
//!
//! **Owns:** the stage kind, its parameters (one struct per environment, chosen by `env`), the
//! `Simulation` trait each environment implements, and the stage that drives any of them.
//! **Does not:** simulate (`envs::*`), or know how shards are cut, written and resumed (`shards`).
//!
//! Layout: `shards.rs` (the machinery every environment shares), `pool.rs`, `phyre.rs`, `iphyre.rs`
//! (one environment each). Every environment draws item `i` from RNGs derived from (`seed`, `i`) alone,
//! so the tables are byte-identical whatever the thread count, and a killed stage resumes at the first
//! unfinished shard.

mod iphyre;
mod phyre;
mod pool;
mod shards;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;

pub use self::iphyre::{IphyreSimParams, parse_clicks, select_games};
pub use self::phyre::{PhyreSimParams, select_tasks};
pub use self::pool::{PoolSimParams, parse_shot};
use self::shards::{ItemOutput, ShardTotals, check_ids_are_new, run_shards};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::trace::Env;

/// The `simulate` stage kind.
pub static KIND: StageKind = StageKind {
    name: "simulate",
    summary: "simulate an environment into the trace tables (billiards, PHYRE or I-PHYRE; dataset or replay)",
    doc: "Simulates `env` and writes the scenes, traces, timesteps, frames and events tables. pooltool: \
          `scenes` seeded 9-ball racks × `shots` random shots (pooltool 0.6.0 physics, timesteps every \
          `dt` s; docs/envs/pool.md), or a replay of `scene_file` + `shot`. phyre: `scenes` ball-tier \
          tasks (round-robin over the templates `tasks` selects) × `shots` random valid red balls, or a \
          replay of `task` + `action` (docs/envs/phyre.md). iphyre: every game `games` selects × `shots` \
          random click sets at `fps`, or a replay of `game` + `clicks` (docs/envs/iphyre.md). Dataset \
          runs are deterministic in `seed` whatever the thread count, sharded by `scenes_per_shard` and \
          resumable. A parameter of another environment is an error.",
    writes: "scenes, traces, timesteps, frames, events",
    params: ParamsOf::of::<SimulateParams>(),
    build,
};

/// The parameters of a `simulate` stage: one set per environment, chosen by `env`.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "env", rename_all = "lowercase")]
pub enum SimulateParams {
    /// Billiards (pooltool 0.6.0 physics).
    Pooltool(PoolSimParams),
    /// PHYRE's ball tier.
    Phyre(PhyreSimParams),
    /// I-PHYRE.
    Iphyre(IphyreSimParams),
}

impl Default for SimulateParams {
    fn default() -> Self {
        SimulateParams::Pooltool(PoolSimParams::default())
    }
}

/// The parameters every environment's `simulate` stage has.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct ShardParams {
    /// Dataset mode: random shots (actions, click sets) per scene (task, game).
    pub shots: u64,
    /// Dataset mode: seed of scenes and shots (default: the pipeline's seed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Scenes per output file; a resumed run redoes at most the unfinished shards.
    pub scenes_per_shard: u64,
}

impl Default for ShardParams {
    fn default() -> Self {
        ShardParams {
            shots: 1,
            seed: None,
            scenes_per_shard: 100,
        }
    }
}

/// What a `simulate` stage reports (its manifest summary); fields that do not apply to the
/// environment are absent.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct SimulateSummary {
    /// The environment.
    pub env: Env,
    /// Traces written.
    pub traces: u64,
    /// Traces whose goal was reached.
    pub successes: u64,
    /// Traces stopped by `max_events` / `max_time` (0 for PHYRE and I-PHYRE).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub capped: Option<u64>,
    /// Billiards: physics events over all traces.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub physics_events: Option<u64>,
    /// Billiards: the table's name.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub table: Option<String>,
    /// Billiards: timestep spacing (s).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dt: Option<f64>,
    /// PHYRE: actions refused as invalid input.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub invalid: Option<u64>,
    /// PHYRE: physics steps over all traces.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub steps: Option<u64>,
    /// PHYRE: frames kept every this many steps.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stride: Option<u64>,
    /// I-PHYRE: blocks removed over all traces.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eliminations: Option<u64>,
    /// I-PHYRE: mean episode reward.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_reward: Option<f64>,
    /// I-PHYRE: physics steps per second.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
}

impl SimulateSummary {
    /// As the manifest's JSON.
    pub fn to_json(&self) -> Value {
        serde_json::to_value(self).unwrap_or(Value::Null)
    }
}

/// One environment's side of the `simulate` stage: a list of work items, each writing one or more
/// traces. The stage cuts the items into shards, runs them in parallel and resumes them
/// (`shards::run_shards`); an environment only says what its items are and how to fill a shard.
pub(crate) trait Simulation: Send + Sync + std::fmt::Debug {
    /// The environment (the tables' `env=` partition).
    fn env(&self) -> Env;
    /// Number of work items (a billiards scene with its shots, a PHYRE action, an I-PHYRE click set).
    fn items(&self) -> u64;
    /// The trace ids item `i` writes.
    fn trace_ids(&self, i: u64) -> Vec<String>;
    /// Whose traces the ids must not clash with: this environment's (default), or every one (`None`).
    fn id_scope(&self) -> Option<Env> {
        Some(self.env())
    }
    /// What decides whether cached output is still valid beyond the parameters (the resolved seed,
    /// hashes of data files).
    fn fingerprint_extra(&self) -> Result<Value, StageError>;
    /// Simulates work item `index` (its scene row when it opens the scene, its traces, its counts for
    /// the shard's record); `source` is the `source` column of the rows. Items are independent of one
    /// another (any thread may simulate any item; `shards` writes them in order).
    fn simulate_item(&self, index: u64, source: &str) -> Result<ItemOutput, StageError>;
    /// The stage's summary and terminal line from the summed shard counts.
    fn report(&self, sums: &ShardTotals) -> (SimulateSummary, String);
}

/// The `simulate` stage: drives one environment's `Simulation`.
#[derive(Debug)]
pub struct SimulateStage {
    sim: Box<dyn Simulation>,
    per_shard: u64,
}

/// The most traces one `simulate` stage may write (its work list and ids are built in memory).
pub const MAX_TRACES: u64 = 100_000_000;
/// The most shots (actions, click sets) per scene.
pub const MAX_SHOTS: u64 = 1_000_000;
/// The most scenes per shard (a shard's counts are kept in memory until it commits).
pub const MAX_SCENES_PER_SHARD: u64 = 1_000_000;

/// Checks the counts every environment shares against [`MAX_TRACES`], [`MAX_SHOTS`] and
/// [`MAX_SCENES_PER_SHARD`], naming the parameter and the limit.
fn check_counts(scenes: u64, shards: &ShardParams) -> Result<(), BuildError> {
    if shards.shots > MAX_SHOTS {
        return Err(BuildError::param(
            "shots",
            format!(
                "`shots`: {} is over the limit of {MAX_SHOTS} per scene",
                shards.shots
            ),
        ));
    }
    if shards.scenes_per_shard > MAX_SCENES_PER_SHARD {
        return Err(BuildError::param(
            "scenes_per_shard",
            format!(
                "`scenes_per_shard`: {} is over the limit of {MAX_SCENES_PER_SHARD}",
                shards.scenes_per_shard
            ),
        ));
    }
    match scenes.checked_mul(shards.shots) {
        Some(n) if n <= MAX_TRACES => Ok(()),
        _ => Err(BuildError::param(
            "scenes",
            format!(
                "`scenes`: {scenes} scenes × {} shots is over the limit of {MAX_TRACES} traces per stage \
                 (split the work over several stages or runs)",
                shards.shots
            ),
        )),
    }
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let params: SimulateParams = def.params()?;
    let scenes = match &params {
        SimulateParams::Pooltool(p) => p.scenes,
        SimulateParams::Phyre(p) => p.scenes,
        SimulateParams::Iphyre(_) => iphyre::GAMES_AT_MOST,
    };
    check_counts(scenes, params.shards())?;
    let sim: Box<dyn Simulation> = match &params {
        SimulateParams::Pooltool(p) => Box::new(pool::build(p, spec)?),
        SimulateParams::Phyre(p) => Box::new(phyre::build(p, spec)?),
        SimulateParams::Iphyre(p) => Box::new(iphyre::build(p, spec)?),
    };
    Ok(Box::new(SimulateStage {
        sim,
        per_shard: params.shards().scenes_per_shard.max(1),
    }))
}

impl SimulateParams {
    /// The parameters every environment has.
    pub fn shards(&self) -> &ShardParams {
        match self {
            SimulateParams::Pooltool(p) => &p.shards,
            SimulateParams::Phyre(p) => &p.shards,
            SimulateParams::Iphyre(p) => &p.shards,
        }
    }
}

impl Stage for SimulateStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        self.sim.fingerprint_extra()
    }

    /// Its units are the shards of `scenes_per_shard` items, named by index.
    fn shardable(&self) -> bool {
        true
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let sim = &self.sim;
        let total = sim.items();
        check_ids_are_new(
            ctx,
            sim.id_scope(),
            (0..total).flat_map(|i| sim.trace_ids(i)),
        )?;
        ctx.progress().set_total(ctx.stage_id(), total);
        let source = shards::source(ctx);
        let sums = run_shards(ctx, sim.env(), total, self.per_shard, |i| {
            sim.simulate_item(i, &source)
        })?;
        let (summary, line) = sim.report(&sums);
        Ok(StageOutput {
            rows: sums.rows,
            files: Vec::new(),
            summary: summary.to_json(),
            line,
        })
    }
}
