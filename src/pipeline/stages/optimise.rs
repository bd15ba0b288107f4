//! `optimise`: the reward-program experiment (paper section 5) — simulated annealing of billiards
//! shots for each goal of a goal file on held-out scenes, with several seeds, driven by the goal's
//! reward program (dense) and by its binary verification (sparse). Writes the `optimisation` table
//! (one row per goal × scene × seed × reward type × checkpoint) and the success-versus-budget figure
//! as `exports/<stage>/success_vs_budget.{svg,png}`.
//!
//! One shard per goal, so a killed run resumes at the first unfinished goal.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use arrow::array::{
    Array, AsArray, BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray,
};
use arrow::datatypes::{DataType, Field, Int64Type, Schema};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::detector_setup::{DetectorSetup, SandboxParams};
use crate::builtin::Location;
use crate::detect::Library;
use crate::envs::pool::PoolEnv;
use crate::optimise::plot::{curves, png, svg};
use crate::optimise::{
    Chain, GoalTask, Layout, RewardKind, Schedule, Settings, ShotBounds, run_chains, scenes,
};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::reward::annotate::{detectors_for, probe_schema};
use crate::reward::goals::GoalSet;
use crate::reward::verify::Rule;
use crate::reward::{compile, labels_used};
use crate::store::write_atomic;
use crate::trace::Env;

/// The parameters of an `optimise` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct OptimiseParams {
    /// Goal file (sentence, program, verification rule per goal), relative to the project folder.
    pub goals: String,
    /// Only these goals (default: every goal of the file).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub goal_ids: Option<Vec<String>>,
    /// Held-out 9-ball scenes per goal.
    pub scenes: u64,
    /// Seed of the held-out scenes (pick one no training or library data used).
    pub scene_seed: u64,
    /// Held-out scenes: balls scattered over the table, or 9-ball racks.
    pub layout: Layout,
    /// Annealing seeds per goal × scene.
    pub seeds: u64,
    /// Samples per annealing run (N_o).
    pub budget: u64,
    /// Record the best-so-far every this many samples.
    pub checkpoint: u64,
    /// Reward types: dense (the reward program) and/or sparse (binary verification).
    pub rewards: Vec<RewardKind>,
    /// Timestep of the simulated traces the detectors read (s).
    pub dt: f64,
    /// Largest cue speed searched (m/s).
    pub v0_max: f64,
    /// Largest cue elevation searched (deg).
    pub theta_max: f64,
    /// Title of the figure.
    pub title: String,
    /// Detector library (default: the goal file's `library`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub library: Option<String>,
    /// Python worker processes (0 = one per core).
    pub workers: u64,
    /// Wall-clock limit of one detector call (s); a call past it is killed and marked timeout.
    pub timeout: f64,
    /// Address-space limit of a worker (MiB); a call past it is marked memory.
    pub memory_mb: u64,
}

impl Default for OptimiseParams {
    fn default() -> Self {
        let sandbox = SandboxParams::default();
        OptimiseParams {
            goals: "data/goals/pooltool.toml".into(),
            goal_ids: None,
            scenes: 10,
            scene_seed: 1000,
            layout: Layout::Scatter,
            seeds: 2,
            budget: 200,
            checkpoint: 50,
            rewards: vec![RewardKind::Dense, RewardKind::Sparse],
            dt: 0.02,
            v0_max: 6.0,
            theta_max: 45.0,
            title: "Reward programs vs binary rewards".into(),
            library: None,
            workers: sandbox.workers,
            timeout: sandbox.timeout,
            memory_mb: sandbox.memory_mb,
        }
    }
}

/// The `optimise` stage kind.
pub static KIND: StageKind = StageKind {
    name: "optimise",
    summary: "simulated annealing of billiards shots for natural-language goals (dense vs sparse reward)",
    doc: "For each goal of a goal file (data/goals/pooltool.toml: the paper's 10 goals), each of `scenes` \
          held-out 9-ball scenes and each of `seeds` seeds, runs simulated annealing over the shot (V0, phi, \
          theta, a, b) for `budget` samples with each reward type: `dense` scores the goal's reward program \
          on the trace annotated by the library's detectors (only those the program uses, batched over all \
          chains per worker call), `sparse` scores 1 when the goal's verification rule holds. The best shot \
          so far is recorded every `checkpoint` samples with whether it verifies. Writes the optimisation \
          table and exports/<stage>/success_vs_budget.svg and .png.",
    writes: "optimisation, exports/<stage>/success_vs_budget.{svg,png}",
    params: ParamsOf::of::<OptimiseParams>(),
    build,
};

/// The `optimise` stage.
#[derive(Debug)]
pub struct OptimiseStage {
    goals: GoalSet,
    goal_ids: Vec<String>,
    library: Library,
    setup: DetectorSetup,
    scenes: usize,
    scene_seed: u64,
    layout: Layout,
    seeds: u64,
    budget: usize,
    checkpoint: usize,
    rewards: Vec<RewardKind>,
    dt: f64,
    bounds: ShotBounds,
    title: String,
    goals_text: String,
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: OptimiseParams = def.params()?;
    // The project's file, else the built-in one (pipelines run from another folder).
    let goals_at = Location::file(&spec.project_dir, std::path::Path::new(&p.goals));
    let goals_path = goals_at.path();
    let goals = GoalSet::open(&goals_at, &spec.project_dir)
        .map_err(|e| BuildError::param("goals", e.to_string()))?;
    if goals.env != Env::Pooltool {
        return Err(BuildError::param(
            "goals",
            format!(
                "optimise drives the billiards simulator; {} is for {}",
                goals_path.display(),
                goals.env
            ),
        ));
    }
    let goals_text = goals_at
        .read_to_string()
        .map_err(|e| BuildError::param("goals", e.to_string()))?;
    let goal_ids: Vec<String> = match &p.goal_ids {
        Some(ids) => ids.clone(),
        None => goals.goals.iter().map(|g| g.id.clone()).collect(),
    };
    if let Some(bad) = goal_ids.iter().find(|id| goals.get(id).is_none()) {
        return Err(BuildError::param(
            "goal_ids",
            format!("no goal {bad:?} in {}", goals_path.display()),
        ));
    }
    // The sandbox settings; the library is the goal file's unless one is given.
    let sandbox = SandboxParams {
        env: Env::Pooltool,
        library: p
            .library
            .clone()
            .or_else(|| goals.library.as_ref().map(|l| l.as_param())),
        workers: p.workers,
        timeout: p.timeout,
        memory_mb: p.memory_mb,
    };
    let setup = DetectorSetup::new(&sandbox, spec)?;
    let library = setup.library.clone();
    let rewards = p.rewards.clone();
    if rewards.is_empty() {
        return Err(BuildError::param(
            "rewards",
            "give at least one reward type",
        ));
    }
    let count = |k: &'static str, v: u64, min: u64| -> Result<u64, BuildError> {
        if v < min {
            Err(BuildError::param(
                k,
                format!("`{k}` must be >= {min}, found {v}"),
            ))
        } else {
            Ok(v)
        }
    };
    let dt = p.dt;
    if !(dt > 0.0 && dt <= 1.0) {
        return Err(BuildError::param(
            "dt",
            format!("dt must be in (0, 1] s, found {dt}"),
        ));
    }
    let bounds = ShotBounds {
        v0: (0.2_f64.min(p.v0_max / 2.0), p.v0_max),
        theta: (0.0, p.theta_max),
        ..ShotBounds::default()
    };
    bounds
        .dims(&PoolEnv::default())
        .map_err(|e| BuildError::param("v0_max", e.to_string()))?;
    Ok(Box::new(OptimiseStage {
        scenes: count("scenes", p.scenes, 1)? as usize,
        scene_seed: p.scene_seed,
        layout: p.layout,
        seeds: count("seeds", p.seeds, 1)?,
        budget: count("budget", p.budget, 1)? as usize,
        checkpoint: count("checkpoint", p.checkpoint, 1)? as usize,
        goals,
        goal_ids,
        library,
        setup,
        rewards,
        dt,
        bounds,
        title: p.title.clone(),
        goals_text,
    }))
}

fn schema() -> Arc<Schema> {
    let f = |n: &str, t: DataType| Field::new(n, t, false);
    Arc::new(Schema::new(vec![
        f("goal", DataType::Utf8),
        f("scene", DataType::Utf8),
        f("seed", DataType::Int64),
        f("reward_type", DataType::Utf8),
        f("budget", DataType::Int64),
        f("success", DataType::Boolean),
        f("best_reward", DataType::Float64),
        f("best_sample", DataType::Int64),
        f("v0", DataType::Float64),
        f("phi", DataType::Float64),
        f("theta", DataType::Float64),
        f("a", DataType::Float64),
        f("b", DataType::Float64),
    ]))
}

/// SplitMix64's output function without the increment ([`crate::rng::finalize`]): the sample
/// seeds of existing `optimise` tables were derived with it, so it is not [`crate::rng::splitmix64`].
fn mix(x: u64) -> u64 {
    crate::rng::finalize(x)
}

impl Stage for OptimiseStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({
            "goals": self.goals_text,
            "library": self.library.fingerprint(),
            "worker": crate::detect::worker_fingerprint(),
        }))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let mut env = PoolEnv::default();
        env.trace.dt = self.dt;
        let scenes = scenes(&env, self.layout, self.scenes, self.scene_seed)?;
        let settings = Settings {
            env,
            bounds: self.bounds,
            schedule: Schedule {
                budget: self.budget,
                ..Schedule::default()
            },
            checkpoint: self.checkpoint,
        };
        ctx.progress()
            .set_total(ctx.stage_id(), (self.goal_ids.len() * self.budget) as u64);
        let mut pool = None;
        let mut schema = None;
        let mut records = Vec::new();
        for (gi, id) in self.goal_ids.iter().enumerate() {
            let shard = format!("{gi:03}");
            if let Some(r) = ctx.finished_shard(&shard)? {
                records.push(r);
                ctx.progress().advance(ctx.stage_id(), self.budget as u64);
                continue;
            }
            if pool.is_none() {
                pool = Some(self.setup.pool()?);
            }
            let pool_ref = pool.as_ref().expect("just started");
            let schema = schema.get_or_insert_with(|| probe_schema(&self.library, pool_ref));
            let task = self.goal_task(id, schema)?;
            let chains = self.chains(ctx.seed(), gi, &scenes);
            records.push(self.run_goal(ctx, &settings, &shard, task, &chains, pool_ref)?);
        }
        let (cs, files) = self.plot(ctx)?;
        Ok(self.output(&records, &cs, files))
    }
}

impl OptimiseStage {
    /// Goal `id`'s compiled reward program and verification rule, with the detectors it uses.
    fn goal_task(&self, id: &str, schema: &crate::reward::Schema) -> Result<GoalTask, StageError> {
        let goal = self.goals.get(id).expect("checked at build");
        let program = compile(&goal.program, schema).map_err(|source| StageError::Goal {
            id: id.to_string(),
            part: "program",
            source: Box::new(source),
        })?;
        let rule = Rule::parse(&goal.verify).map_err(|source| StageError::Goal {
            id: id.to_string(),
            part: "verify",
            source: Box::new(source),
        })?;
        Ok(GoalTask {
            id: id.to_string(),
            detectors: detectors_for(&self.library, &labels_used(&program)),
            program,
            rule,
        })
    }

    /// The chains of goal number `gi`: every scene × seed × reward type, seeded from the run's seed.
    fn chains(&self, run_seed: u64, gi: usize, scenes: &[crate::envs::pool::Scene]) -> Vec<Chain> {
        let mut chains = Vec::new();
        for (si, scene) in scenes.iter().enumerate() {
            for s in 0..self.seeds {
                let seed = mix(run_seed ^ mix(gi as u64 + 1) ^ mix((si as u64) << 20 | s));
                for &kind in &self.rewards {
                    chains.push(Chain {
                        goal: 0,
                        scene: scene.clone(),
                        seed,
                        kind,
                    });
                }
            }
        }
        chains
    }

    /// Runs one goal's chains, writes its rows as shard `shard` and returns the shard's record.
    fn run_goal(
        &self,
        ctx: &StageContext<'_>,
        settings: &Settings,
        shard: &str,
        task: GoalTask,
        chains: &[Chain],
        pool: &crate::detect::WorkerPool,
    ) -> Result<Value, StageError> {
        let ordinal = ctx.shard_started();
        let t0 = std::time::Instant::now();
        let progress = ctx.progress();
        let (rows, timings) = run_chains(
            settings,
            std::slice::from_ref(&task),
            chains,
            Some(pool),
            |_| progress.advance(ctx.stage_id(), 1),
        )?;
        // Chain seeds are hashes; the table records the seed's index 0..seeds.
        let seed_index: BTreeMap<u64, i64> = chains
            .iter()
            .enumerate()
            .map(|(i, c)| {
                (
                    c.seed,
                    ((i / self.rewards.len()) as u64 % self.seeds) as i64,
                )
            })
            .collect();
        let wall = t0.elapsed().as_secs_f64();
        let batch = rows_batch(&rows, &seed_index)?;
        ctx.checkpoint_mid_shard(ordinal)?;
        let n = ctx.write_batch("optimisation", Env::Pooltool, shard, &batch)?;
        let record = json!({
            "goal": task.id,
            "rows": n,
            "chains": chains.len(),
            "wall_s": wall,
            "timings": {
                "samples": timings.samples, "dense_samples": timings.dense_samples,
                "simulate_s": timings.simulate_s, "annotate_s": timings.annotate_s,
                "score_s": timings.score_s, "failed_simulations": timings.failed_simulations,
                "failed_calls": timings.failed_calls, "program_errors": timings.program_errors,
            },
        });
        ctx.finish_shard(shard, &record)?;
        Ok(record)
    }

    /// The figure of success against budget, from every staged shard (this attempt's and an earlier
    /// one's): the curves and the two files written.
    fn plot(
        &self,
        ctx: &StageContext<'_>,
    ) -> Result<(Vec<crate::optimise::plot::Curve>, Vec<PathBuf>), StageError> {
        let mut points: Vec<(String, u64, u64, bool)> = Vec::new();
        for f in ctx.staging().table_files("optimisation")? {
            for b in crate::store::read_file(&f)? {
                let kind = b.column(3).as_string::<i32>().clone();
                let seed = b.column(2).as_primitive::<Int64Type>().clone();
                let budget = b.column(4).as_primitive::<Int64Type>().clone();
                let success = b.column(5).as_boolean().clone();
                for i in 0..b.num_rows() {
                    points.push((
                        kind.value(i).to_string(),
                        budget.value(i) as u64,
                        seed.value(i) as u64,
                        success.value(i) && !success.is_null(i),
                    ));
                }
            }
        }
        let cs = curves(points.iter().map(|(k, b, s, ok)| (k.as_str(), *b, *s, *ok)));
        let dir = ctx.run().exports_dir().join(ctx.stage_id());
        std::fs::create_dir_all(&dir).map_err(|e| StageError::io(&dir, e))?;
        let title = format!(
            "{} ({} goals × {} scenes × {} seeds)",
            self.title,
            self.goal_ids.len(),
            self.scenes,
            self.seeds
        );
        let svg_path = dir.join("success_vs_budget.svg");
        write_atomic(&svg_path, svg(&cs, &title).as_bytes())
            .map_err(|e| StageError::io(&svg_path, e))?;
        let png_path = dir.join("success_vs_budget.png");
        write_atomic(&png_path, &png(&cs).map_err(StageError::Internal)?)
            .map_err(|e| StageError::io(&png_path, e))?;
        Ok((cs, vec![svg_path, png_path]))
    }

    /// The stage's output: rows, summed timings and the final success rate of each reward type.
    fn output(
        &self,
        records: &[Value],
        cs: &[crate::optimise::plot::Curve],
        files: Vec<PathBuf>,
    ) -> StageOutput {
        let mut totals: BTreeMap<String, f64> = BTreeMap::new();
        let mut rows_total = 0u64;
        for r in records {
            rows_total += r["rows"].as_u64().unwrap_or(0);
            for (k, v) in r["timings"].as_object().into_iter().flatten() {
                *totals.entry(k.clone()).or_default() += v.as_f64().unwrap_or(0.0);
            }
        }
        let last: BTreeMap<String, f64> = cs
            .iter()
            .filter_map(|c| c.points.last().map(|p| (c.name.clone(), p.mean)))
            .collect();
        let mut rows = BTreeMap::new();
        rows.insert("optimisation".to_string(), rows_total);
        StageOutput {
            rows,
            files,
            summary: json!({
                "goals": self.goal_ids, "goal_file": self.goals.path, "library": self.library.name,
                "scenes": self.scenes, "scene_seed": self.scene_seed, "layout": format!("{:?}", self.layout).to_lowercase(), "seeds": self.seeds,
                "budget": self.budget, "checkpoint": self.checkpoint, "dt": self.dt,
                "bounds": {"v0": self.bounds.v0, "theta": self.bounds.theta, "max_offset": self.bounds.max_offset},
                "timings": totals, "final_success": last,
            }),
            line: format!(
                "{} goal(s) × {} scene(s) × {} seed(s), budget {}: final success {}",
                self.goal_ids.len(),
                self.scenes,
                self.seeds,
                self.budget,
                last.iter()
                    .map(|(k, v)| format!("{k} {v:.3}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

/// The `optimisation` rows of one goal as a batch (seeds as their index 0..seeds).
fn rows_batch(
    rows: &[crate::optimise::CheckpointRow],
    seed_index: &BTreeMap<u64, i64>,
) -> Result<RecordBatch, arrow::error::ArrowError> {
    RecordBatch::try_new(
        schema_ref(),
        vec![
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.goal.as_str()),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.scene.as_str()),
            )),
            Arc::new(Int64Array::from_iter_values(
                rows.iter()
                    .map(|r| seed_index.get(&r.seed).copied().unwrap_or(0)),
            )),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.kind.as_str()),
            )),
            Arc::new(Int64Array::from_iter_values(
                rows.iter().map(|r| r.budget as i64),
            )),
            Arc::new(BooleanArray::from(
                rows.iter().map(|r| r.success).collect::<Vec<_>>(),
            )),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|r| r.best_reward),
            )),
            Arc::new(Int64Array::from_iter_values(
                rows.iter().map(|r| r.best_sample as i64),
            )),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|r| r.shot.v0),
            )),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|r| r.shot.phi),
            )),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|r| r.shot.theta),
            )),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|r| r.shot.a),
            )),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|r| r.shot.b),
            )),
        ],
    )
}

fn schema_ref() -> Arc<Schema> {
    schema()
}
