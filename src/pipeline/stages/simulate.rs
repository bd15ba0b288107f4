//! `simulate`: runs an environment's simulator and writes the trace tables, sharded and resumable.
//!
//! Two modes. **Dataset**: `scenes` seeded 9-ball racks × `shots` random shots each; scene `i` and shot
//! `k` draw from RNGs derived from (`seed`, `i`) and (`seed`, `i`, `k`) alone, and every
//! `scenes_per_shard` scenes make one shard (one Parquet file per table, marked done when committed), so
//! the tables are byte-identical whatever the thread count and a killed run resumes at the first
//! unfinished shard. Shards run in parallel on rayon's pool. **Replay**: `scene_file` (scene JSON, see
//! `envs::pool::Scene`) and `shot` (`{V0, phi, theta, a, b}`) give exactly one trace. Bad input (a scene
//! that is not JSON, a ball off the table, overlapping balls, an invalid shot, an unreadable table file)
//! is caught when the stage is built, before anything is written.
//!
//! Ids: dataset scenes are `pool-<seed>-<index:06>` and their traces `<scene_id>-<shot:03>`; a replayed
//! trace is `<scene_id>-<first 8 hex digits of the shot's hash>`.

use std::collections::BTreeMap;

use arrow::array::RecordBatch;
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use sha2::{Digest, Sha256};

use crate::digest::hex;
use crate::envs::pool::{
    PoolConfig, Scene, Shot, SimOptions, TraceOptions, rack, simulate, trace_of,
};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::store::ParquetSink;
use crate::trace::batch::scene_batch;
use crate::trace::{Env, Trace, TraceBatchBuilder, schema};

/// The `simulate` stage kind.
pub static KIND: StageKind = StageKind {
    name: "simulate",
    summary: "simulate scenes × shots into the trace tables (billiards: pooltool 0.6.0 physics)",
    doc: "Simulates an environment and writes the scenes, traces, timesteps, frames and events tables. \
          Dataset mode: `scenes` seeded 9-ball racks with `shots` random shots each (half aimed at an object \
          ball, V0 0.5-6 m/s, spin on a disc of radius 0.6), deterministic in `seed` whatever the thread \
          count, sharded by `scenes_per_shard` and resumable. Replay mode: `scene_file` (scene JSON) and \
          `shot` ({V0, phi, theta, a, b}) give one trace. Timesteps are resampled every `dt` seconds from \
          the exact event-based solution; `max_events` / `max_time` stop runaway shots with terminal_status \
          max_events / max_time. See docs/envs/pool.md.",
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

/// Billiards `simulate` parameters.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct PoolSimParams {
    /// Dataset mode: number of random 9-ball racks.
    pub scenes: u64,
    /// Shots, seed and sharding.
    #[serde(flatten)]
    pub shards: ShardParams,
    /// Replay mode: scene JSON file, relative to the project folder.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scene_file: Option<String>,
    /// Replay mode: the shot as JSON, e.g. '{"V0": 3, "phi": 90, "theta": 0, "a": 0, "b": 0.2}'.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shot: Option<String>,
    /// Table file (geometry, ball and cue parameters), relative to the project folder (default:
    /// data/tables/pooltool_7ft.json, built in).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub table: Option<String>,
    /// Timestep spacing of the traces (s).
    pub dt: f64,
    /// Stop a shot after this many events (terminal_status max_events); 0 = no cap.
    pub max_events: u64,
    /// Stop a shot at the first event at or after this time (s) (terminal_status max_time).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_time: Option<f64>,
}

impl Default for PoolSimParams {
    fn default() -> Self {
        PoolSimParams {
            scenes: 10,
            shards: ShardParams::default(),
            scene_file: None,
            shot: None,
            table: None,
            dt: 0.01,
            max_events: 100_000,
            max_time: None,
        }
    }
}

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
        }
    }
}

/// I-PHYRE `simulate` parameters.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct IphyreSimParams {
    /// Click sets per game, seed and sharding.
    #[serde(flatten)]
    pub shards: ShardParams,
    /// Dataset mode: comma-separated game and fold names, or all (default all 40).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub games: Option<String>,
    /// Physics steps per second: 60 (I-PHYRE's default) or 10 (the gym wrappers and DeepPHY).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fps: Option<f64>,
    /// Replay mode: the game name.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub game: Option<String>,
    /// Replay mode: `x,y,t;…` clicks (px, s) or `k@t;…` (remove eliminable block k at t).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clicks: Option<String>,
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

/// What to simulate.
#[derive(Debug)]
enum Work {
    /// Random racks and shots.
    Dataset { scenes: u64, shots: u64, seed: u64 },
    /// One scene, one shot.
    Replay { scene: Box<Scene>, shot: Shot },
}

/// The `simulate` stage.
#[derive(Debug)]
pub struct SimulateStage {
    config: PoolConfig,
    /// The table file's text, when one was given (enters the fingerprint).
    table_text: Option<String>,
    work: Work,
    sim: SimOptions,
    trace: TraceOptions,
    per_shard: u64,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    match def.params::<SimulateParams>()? {
        SimulateParams::Pooltool(p) => build_pool(&p, spec),
        SimulateParams::Phyre(p) => super::simulate_phyre::build(&p, spec),
        SimulateParams::Iphyre(p) => super::simulate_iphyre::build(&p, spec),
    }
}

fn build_pool(p: &PoolSimParams, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let (config, table_text) = match &p.table {
        None => (PoolConfig::default_7ft(), None),
        Some(t) => {
            let path = spec.project_dir.join(t);
            let text = std::fs::read_to_string(&path).map_err(|e| {
                BuildError::param("table", format!("{}: cannot read: {e}", path.display()))
            })?;
            let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("table");
            let config = PoolConfig::from_json_str(name, &text)
                .map_err(|e| BuildError::param("table", format!("{}: {e}", path.display())))?;
            (config, Some(text))
        }
    };
    let dt = p.dt;
    if !(dt > 0.0 && dt.is_finite()) {
        return Err(BuildError::param(
            "dt",
            format!("dt must be > 0, found {dt}"),
        ));
    }
    let max_time = p.max_time;
    if let Some(t) = max_time
        && (t.is_nan() || t <= 0.0)
    {
        return Err(BuildError::param(
            "max_time",
            format!("max_time must be > 0, found {t}"),
        ));
    }
    let work = match replay_pair(
        ("scene_file", p.scene_file.as_deref()),
        ("shot", p.shot.as_deref()),
    )? {
        Some((file, shot_text)) => {
            let path = spec.project_dir.join(file);
            let text = std::fs::read_to_string(&path).map_err(|e| {
                BuildError::param(
                    "scene_file",
                    format!("{}: cannot read: {e}", path.display()),
                )
            })?;
            let scene = Scene::from_json_str(&text, &config)
                .map_err(|e| BuildError::param("scene_file", format!("{}: {e}", path.display())))?;
            let shot = parse_shot(shot_text).map_err(|m| BuildError::param("shot", m))?;
            Work::Replay {
                scene: Box::new(scene),
                shot,
            }
        }
        None => Work::Dataset {
            scenes: p.scenes,
            shots: p.shards.shots,
            seed: p.shards.seed.unwrap_or(spec.seed),
        },
    };
    Ok(Box::new(SimulateStage {
        config,
        table_text,
        work,
        sim: SimOptions {
            max_events: usize::try_from(p.max_events).unwrap_or(usize::MAX),
            t_final: max_time,
        },
        trace: TraceOptions { dt },
        per_shard: p.shards.scenes_per_shard.max(1),
    }))
}

/// Parses and validates a shot given as JSON (`{"V0": …, "phi": …, "theta": …, "a": …, "b": …}`).
pub fn parse_shot(text: &str) -> Result<Shot, String> {
    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct ShotJson {
        #[serde(rename = "V0")]
        v0: f64,
        phi: f64,
        #[serde(default)]
        theta: f64,
        #[serde(default)]
        a: f64,
        #[serde(default)]
        b: f64,
    }
    let s: ShotJson = serde_json::from_str(text).map_err(|e| {
        format!(
            "shot {text:?} is not a shot object {{\"V0\", \"phi\", \"theta\", \"a\", \"b\"}}: {e}"
        )
    })?;
    let shot = Shot {
        v0: s.v0,
        phi: s.phi,
        theta: s.theta,
        a: s.a,
        b: s.b,
    };
    shot.validate().map_err(|e| e.to_string())?;
    Ok(shot)
}

impl Stage for SimulateStage {
    /// The resolved seed and the table file's hash: a changed table or pipeline seed reruns.
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        let table = self
            .table_text
            .as_ref()
            .map(|t| hex(&Sha256::digest(t.as_bytes())));
        let work = match &self.work {
            Work::Dataset { seed, .. } => json!({"seed": seed}),
            Work::Replay { scene, .. } => json!({"scene": scene.to_json()}),
        };
        Ok(json!({"table": table, "work": work}))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let total = match &self.work {
            Work::Dataset { scenes, .. } => *scenes,
            Work::Replay { .. } => 1,
        };
        // Trace ids must be new across every environment's traces.
        check_ids_are_new(ctx, None, (0..total).flat_map(|i| self.trace_ids(i)))?;
        ctx.progress().set_total(ctx.stage_id(), total);
        let sums = run_shards(
            ctx,
            Env::Pooltool,
            total,
            self.per_shard,
            |sinks, lo, hi| self.fill_shard(ctx, sinks, lo, hi),
        )?;
        let (traces, successes) = (sums.count("traces"), sums.count("successes"));
        let (capped, events) = (sums.count("capped"), sums.count("physics_events"));
        let rows = sums.rows;
        let frames = rows.get("frames").copied().unwrap_or(0);
        let line = format!(
            "{traces} pool trace(s), {successes} successful, {capped} capped; {events} physics events, {frames} frame rows"
        );
        Ok(StageOutput {
            rows,
            files: Vec::new(),
            summary: SimulateSummary {
                env: Env::Pooltool,
                traces,
                successes,
                capped: Some(capped),
                physics_events: Some(events),
                table: Some(self.config.name.clone()),
                dt: Some(self.trace.dt),
                ..SimulateSummary::default()
            }
            .to_json(),
            line,
        })
    }
}

/// The sums of a stage's shard records: each numeric field (`traces`, `successes`, …) and the rows
/// written per table.
#[derive(Default)]
pub(super) struct ShardTotals {
    fields: BTreeMap<String, f64>,
    /// Rows written per table.
    pub(super) rows: BTreeMap<String, u64>,
}

impl ShardTotals {
    /// The sum of a numeric field as a count (0 when no shard reported it).
    pub(super) fn count(&self, field: &str) -> u64 {
        self.fields.get(field).copied().unwrap_or(0.0) as u64
    }

    /// The sum of a numeric field.
    pub(super) fn sum(&self, field: &str) -> f64 {
        self.fields.get(field).copied().unwrap_or(0.0)
    }
}

/// Splits `0..total` into shards of `per_shard` items, runs them in parallel (rayon) and sums their
/// records. A shard an earlier run finished is skipped (its record reused). Otherwise `fill(sinks, lo,
/// hi)` simulates items `lo..hi` into the shard's files and returns the shard's counts as a JSON
/// object; the files are then committed and the counts, with the rows written per table (`rows`),
/// recorded as the shard's record.
pub(super) fn run_shards(
    ctx: &StageContext<'_>,
    env: Env,
    total: u64,
    per_shard: u64,
    fill: impl Fn(&mut ShardSinks<'_, '_>, u64, u64) -> Result<Value, StageError> + Sync,
) -> Result<ShardTotals, StageError> {
    let per_shard = per_shard.max(1);
    let shards: Vec<(u64, u64)> = (0..total.div_ceil(per_shard))
        .map(|s| (s * per_shard, ((s + 1) * per_shard).min(total)))
        .collect();
    let records: Vec<Value> = shards
        .par_iter()
        .enumerate()
        .map(|(i, &(lo, hi))| {
            let name = format!("{i:05}");
            if let Some(record) = ctx.finished_shard(&name)? {
                ctx.progress().advance(ctx.stage_id(), hi - lo);
                return Ok(record);
            }
            let mut sinks = ShardSinks::new(ctx, env, name.clone());
            let mut record = fill(&mut sinks, lo, hi)?;
            record["rows"] = json!(sinks.commit()?);
            ctx.finish_shard(&name, &record)?;
            Ok(record)
        })
        .collect::<Result<_, StageError>>()?;
    let mut totals = ShardTotals::default();
    for r in &records {
        for (k, v) in r.as_object().into_iter().flatten() {
            if k == "rows" {
                for (t, n) in v.as_object().into_iter().flatten() {
                    *totals.rows.entry(t.clone()).or_default() += n.as_u64().unwrap_or(0);
                }
            } else if let Some(x) = v.as_f64() {
                *totals.fields.entry(k.clone()).or_default() += x;
            }
        }
    }
    Ok(totals)
}

/// The two parameters of a replay (`scene_file` and `shot`, `game` and `clicks`, `task` and `action`):
/// both given, or neither (dataset mode, `None`); one without the other is an error on the missing one.
pub(super) fn replay_pair<'p>(
    (first, a): (&'static str, Option<&'p str>),
    (second, b): (&'static str, Option<&'p str>),
) -> Result<Option<(&'p str, &'p str)>, BuildError> {
    match (a, b) {
        (Some(a), Some(b)) => Ok(Some((a, b))),
        (Some(_), None) => Err(BuildError::param(
            second,
            format!("replay mode needs `{second}` with `{first}`"),
        )),
        (None, Some(_)) => Err(BuildError::param(
            first,
            format!("replay mode needs `{first}` with `{second}`"),
        )),
        (None, None) => Ok(None),
    }
}

/// Fails when a trace id this stage would write (`ids`, walked only when the run holds traces) is
/// already in the run, written by another stage (e.g. an earlier dataset command with the same seed);
/// the stage's own earlier output was removed by the runner before a rerun. With `env`, only that
/// environment's traces count.
pub(super) fn check_ids_are_new(
    ctx: &StageContext<'_>,
    env: Option<Env>,
    ids: impl IntoIterator<Item = String>,
) -> Result<(), StageError> {
    let existing: std::collections::HashSet<String> = crate::store::trace_ids(ctx.run())?
        .into_iter()
        .filter(|(e, _)| env.is_none_or(|env| *e == env))
        .map(|(_, id)| id)
        .collect();
    if existing.is_empty() {
        return Ok(());
    }
    if let Some(id) = ids.into_iter().find(|id| existing.contains(id)) {
        return Err(StageError::Input(format!(
            "trace id {id:?} is already in the run {} (written by another stage); use another seed or run folder",
            ctx.run().root().display()
        )));
    }
    Ok(())
}

/// The open Parquet files of one shard, one per table (also used by the other environments' halves).
pub(super) struct ShardSinks<'a, 'c> {
    ctx: &'a StageContext<'c>,
    env: Env,
    name: String,
    /// The tables' `source`: `simulate:<stage id>`.
    source: String,
    /// This shard's start order in the run, for the mid-shard fault point.
    ordinal: usize,
    sinks: BTreeMap<&'static str, ParquetSink>,
    builder: TraceBatchBuilder,
}

impl<'a, 'c> ShardSinks<'a, 'c> {
    /// No file open yet; shard `name` of `env`, counted as started.
    fn new(ctx: &'a StageContext<'c>, env: Env, name: String) -> Self {
        let ordinal = ctx.shard_started();
        ShardSinks {
            ctx,
            env,
            name,
            source: format!("simulate:{}", ctx.stage_id()),
            ordinal,
            sinks: BTreeMap::new(),
            builder: TraceBatchBuilder::new(),
        }
    }

    /// The `source` column of the rows this stage writes (`simulate:<stage id>`).
    pub(super) fn source(&self) -> &str {
        &self.source
    }

    /// Appends one trace's rows to the `traces`, `timesteps`, `frames` and `events` files. For the
    /// shard's first trace (`first`) the mid-shard fault point fires between the frames and the events,
    /// so a crash test finds some of the shard's files half written.
    pub(super) fn write_trace(
        &mut self,
        trace: &Trace,
        scene_id: &str,
        first: bool,
    ) -> Result<(), StageError> {
        for ts in &trace.timesteps {
            self.builder.push_timestep(ts);
        }
        let b = self.builder.finish(&crate::trace::TraceMeta {
            trace_id: &trace.trace_id,
            scene_id,
            task_id: &trace.task_id,
            events: &trace.events,
            outcome: &trace.outcome,
            extra: &trace.extra,
            source: &self.source,
        })?;
        self.write("traces", &b.traces)?;
        self.write("timesteps", &b.timesteps)?;
        self.write("frames", &b.frames)?;
        if first {
            self.ctx.checkpoint_mid_shard(self.ordinal)?;
        }
        self.write("events", &b.events)
    }

    /// Appends `batch` to `table`'s file, opening it on first use (empty batches open nothing).
    pub(super) fn write(
        &mut self,
        table: &'static str,
        batch: &RecordBatch,
    ) -> Result<(), StageError> {
        if batch.num_rows() == 0 {
            return Ok(());
        }
        if !self.sinks.contains_key(table) {
            let schema = schema::table_schema(table)
                .ok_or_else(|| StageError::Internal(format!("no schema for table {table}")))?;
            let sink = self
                .ctx
                .staging()
                .sink(table, Some(self.env), &self.name, schema)?;
            self.sinks.insert(table, sink);
        }
        if let Some(sink) = self.sinks.get_mut(table) {
            sink.write(batch)?;
        }
        Ok(())
    }

    /// Commits every file; the rows written per table.
    pub(super) fn commit(self) -> Result<BTreeMap<String, u64>, StageError> {
        let mut rows = BTreeMap::new();
        for (table, sink) in self.sinks {
            let (_, n) = sink.commit()?;
            rows.insert(table.to_string(), n as u64);
        }
        Ok(rows)
    }
}

impl SimulateStage {
    /// The trace ids of scene `index`.
    fn trace_ids(&self, index: u64) -> Vec<String> {
        match &self.work {
            Work::Dataset { shots, seed, .. } => (0..*shots)
                .map(|k| format!("pool-{seed}-{index:06}-{k:03}"))
                .collect(),
            Work::Replay { .. } => self
                .scene_work(index)
                .1
                .into_iter()
                .map(|(id, _)| id)
                .collect(),
        }
    }

    /// The (scene, shots) pairs of scenes `lo..hi`.
    fn scene_work(&self, index: u64) -> (Scene, Vec<(String, Shot)>) {
        match &self.work {
            Work::Dataset { shots, seed, .. } => {
                let mut scene = Scene::nine_ball(&self.config, rack::scene_seed(*seed, index));
                scene.scene_id = format!("pool-{seed}-{index:06}");
                let list = (0..*shots)
                    .map(|k| {
                        let mut rng = rack::shot_rng(*seed, index, k);
                        (
                            format!("{}-{k:03}", scene.scene_id),
                            rack::dataset_shot(&scene, &mut rng),
                        )
                    })
                    .collect();
                (scene, list)
            }
            Work::Replay { scene, shot } => {
                let text = format!(
                    "{:?} {:?} {:?} {:?} {:?}",
                    shot.v0, shot.phi, shot.theta, shot.a, shot.b
                );
                let h = hex(&Sha256::digest(text.as_bytes()));
                (
                    (**scene).clone(),
                    vec![(format!("{}-{}", scene.scene_id, &h[..8]), *shot)],
                )
            }
        }
    }

    /// Simulates items `lo..hi` into one shard's files; the shard's counts.
    fn fill_shard(
        &self,
        ctx: &StageContext<'_>,
        sinks: &mut ShardSinks<'_, '_>,
        lo: u64,
        hi: u64,
    ) -> Result<Value, StageError> {
        let (mut traces, mut successes, mut capped, mut events) = (0u64, 0u64, 0u64, 0u64);
        for index in lo..hi {
            let (scene, shots) = self.scene_work(index);
            let system = scene
                .system(&self.config)
                .map_err(|e| StageError::Input(format!("scene {}: {e}", scene.scene_id)))?;
            let mut spec = scene.to_json();
            spec["table"] = json!(self.config.name);
            spec["index"] = json!(index);
            let batch = scene_batch(
                &scene.scene_id,
                &scene.scene_id,
                sinks.source(),
                scene.balls.len(),
                &spec,
            )?;
            sinks.write("scenes", &batch)?;
            for (trace_id, shot) in &shots {
                let sim = simulate(&system, shot, &self.sim)
                    .map_err(|e| StageError::Input(format!("trace {trace_id}: {e}")))?;
                let trace = trace_of(&sim, &scene, shot, trace_id, &self.trace);
                traces += 1;
                successes += u64::from(trace.outcome.success);
                capped += u64::from(matches!(
                    trace.outcome.terminal_status.as_str(),
                    "max_events" | "max_time"
                ));
                events += sim.events.len() as u64;
                sinks.write_trace(&trace, &scene.scene_id, index == lo)?;
            }
            ctx.progress().advance(ctx.stage_id(), 1);
        }
        Ok(json!({
            "traces": traces,
            "successes": successes,
            "capped": capped,
            "physics_events": events,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shots_parse_with_defaults_and_bad_ones_name_the_problem() {
        let s = parse_shot(r#"{"V0": 2, "phi": 90}"#).unwrap();
        assert_eq!((s.v0, s.phi, s.theta, s.a, s.b), (2.0, 90.0, 0.0, 0.0, 0.0));
        assert!(
            parse_shot(r#"{"V0": -1, "phi": 0}"#)
                .unwrap_err()
                .contains("V0")
        );
        assert!(
            parse_shot(r#"{"V0": 1, "phi": 0, "a": 0.8, "b": 0.8}"#)
                .unwrap_err()
                .contains("a²")
        );
        assert!(
            parse_shot(r#"{"V0": 1, "phi": 0, "spin": 1}"#)
                .unwrap_err()
                .contains("spin")
        );
        assert!(parse_shot("fast").is_err());
    }
}
