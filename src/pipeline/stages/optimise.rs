//! `optimise`: the reward-program experiment (paper section 5) in any environment — simulated
//! annealing of the action (billiards shot, PHYRE red ball, I-PHYRE removal times) for each goal of a
//! goal file on held-out scenes, with several seeds and budgets, driven by the goal's reward program
//! (dense) and by its binary verification (sparse). The programs come from the goal file or from a
//! `synthesise` stage's `reward_programs` table. Writes the `optimisation` table (one row per goal ×
//! scene × seed × reward type × budget), the success-versus-budget figure and, per goal, the
//! optimised-action figure (`exports/<stage>/`).
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
use crate::envs::iphyre::{Game, Games, IphyreEnv};
use crate::envs::phyre::{PhyreEnv, Task, TaskSet, dataset_tasks};
use crate::envs::pool::PoolEnv;
use crate::optimise::figure::{ActionFigure, action_svg};
use crate::optimise::plot::{curves, png, svg};
use crate::optimise::{
    Chain, CheckpointRow, GoalTask, IphyreProblem, Layout, PhyreProblem, PoolProblem, Problem,
    RewardKind, Schedule, Settings, ShotBounds, run_chains, scenes,
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

/// How the budgets of the success-versus-budget curve are spent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum BudgetAxis {
    /// The paper's: one independent annealing run per budget (its schedule cools over that budget).
    #[default]
    Independent,
    /// The checkpoints of one run of the largest budget (cheaper; early points come from a hot chain).
    Checkpoints,
}

/// Where the reward programs come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ProgramSource {
    /// `reward_programs` when an input stage is a `synthesise` stage, else `goals`.
    #[default]
    Auto,
    /// The goal file's hand-written programs.
    Goals,
    /// The `reward_programs` table of an input `synthesise` stage (goals it has no program for are
    /// skipped).
    RewardPrograms,
}

/// The parameters every environment's `optimise` stage has.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct OptimiseCommon {
    /// Goal file (sentence, program, verification rule per goal), relative to the project folder
    /// (default: `data/goals/<env>.toml`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub goals: Option<String>,
    /// Only these goals (default: every goal of the file).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub goal_ids: Option<Vec<String>>,
    /// Where the reward programs come from: the goal file or an input synthesise stage's table.
    pub programs: ProgramSource,
    /// Held-out scenes (billiards scenes, PHYRE tasks, I-PHYRE games) per goal.
    pub scenes: u64,
    /// Annealing seeds per goal × scene.
    pub seeds: u64,
    /// Largest number of samples per annealing run (N_o).
    pub budget: u64,
    /// Budget step: the curve has budgets step, 2·step, …, budget.
    pub checkpoint: u64,
    /// Independent runs per budget (the paper's) or checkpoints of one run.
    pub budget_axis: BudgetAxis,
    /// Reward types: dense (the reward program) and/or sparse (binary verification).
    pub rewards: Vec<RewardKind>,
    /// Frames in the optimised-action figure's strip (0 = no figure).
    pub frames: u64,
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

impl Default for OptimiseCommon {
    fn default() -> Self {
        let sandbox = SandboxParams::default();
        OptimiseCommon {
            goals: None,
            goal_ids: None,
            programs: ProgramSource::Auto,
            scenes: 10,
            seeds: 2,
            budget: 200,
            checkpoint: 50,
            budget_axis: BudgetAxis::Independent,
            rewards: vec![RewardKind::Dense, RewardKind::Sparse],
            frames: 5,
            title: "Reward programs vs binary rewards".into(),
            library: None,
            workers: sandbox.workers,
            timeout: sandbox.timeout,
            memory_mb: sandbox.memory_mb,
        }
    }
}

/// Billiards: scattered or racked scenes, shots in a box.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct PoolOptParams {
    /// Goals, scenes, seeds, budgets, rewards and sandbox.
    #[serde(flatten)]
    pub common: OptimiseCommon,
    /// Seed of the held-out scenes (pick one no training or library data used).
    pub scene_seed: u64,
    /// Held-out scenes: balls scattered over the table, or 9-ball racks.
    pub layout: Layout,
    /// Timestep of the simulated traces the detectors read (s).
    pub dt: f64,
    /// Largest cue speed searched (m/s).
    pub v0_max: f64,
    /// Largest cue elevation searched (deg).
    pub theta_max: f64,
}

impl Default for PoolOptParams {
    fn default() -> Self {
        PoolOptParams {
            common: OptimiseCommon::default(),
            scene_seed: 1000,
            layout: Layout::Scatter,
            dt: 0.02,
            v0_max: 6.0,
            theta_max: 45.0,
        }
    }
}

/// PHYRE: the red ball's (x, y, r) on ball-tier tasks.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct PhyreOptParams {
    /// Goals, scenes, seeds, budgets, rewards and sandbox.
    #[serde(flatten)]
    pub common: OptimiseCommon,
    /// Comma-separated template ids (00003), task ids (00003:002) or fold splits
    /// (ball_cross_template/0/test) the scenes are drawn from, round-robin over templates (default all).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tasks: Option<String>,
}

/// I-PHYRE: one removal time per eliminable block.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct IphyreOptParams {
    /// Goals, scenes, seeds, budgets, rewards and sandbox.
    #[serde(flatten)]
    pub common: OptimiseCommon,
    /// Comma-separated game and fold names the scenes cycle through (default all 40).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub games: Option<String>,
    /// Simulation frames per second.
    pub fps: f64,
    /// Latest removal time searched (s); a time in the box past it means "never".
    pub horizon: f64,
}

impl Default for IphyreOptParams {
    fn default() -> Self {
        IphyreOptParams {
            common: OptimiseCommon::default(),
            games: None,
            fps: 60.0,
            horizon: 5.0,
        }
    }
}

/// The parameters of an `optimise` stage: one set per environment, chosen by `env`.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "env", rename_all = "lowercase")]
pub enum OptimiseParams {
    /// Billiards shots (V0, phi, theta, a, b).
    Pooltool(PoolOptParams),
    /// PHYRE's red ball (x, y, r).
    Phyre(PhyreOptParams),
    /// I-PHYRE removal times.
    Iphyre(IphyreOptParams),
}

impl Default for OptimiseParams {
    fn default() -> Self {
        OptimiseParams::Pooltool(PoolOptParams::default())
    }
}

/// The `optimise` stage kind.
pub static KIND: StageKind = StageKind {
    name: "optimise",
    summary: "simulated annealing of actions for natural-language goals (dense vs sparse reward), any environment",
    doc: "For each goal of a goal file (default data/goals/<env>.toml), each of `scenes` held-out scenes \
          (billiards scenes, PHYRE tasks, I-PHYRE games) and each of `seeds` seeds, runs simulated annealing \
          over the action (pooltool: V0, phi, theta, a, b; phyre: the red ball's x, y, r; iphyre: one removal \
          time per eliminable block) with each reward type: `dense` scores the goal's reward program (from the \
          goal file, or from an input synthesise stage's reward_programs table) on the trace annotated by \
          the library's detectors (only those the program uses, batched over all chains per worker call), \
          `sparse` scores 1 when the goal's verification rule holds. Budgets are checkpoint, 2·checkpoint, \
          …, budget: by default one independent run per budget (the paper's), or the checkpoints of one run \
          (`budget_axis = \"checkpoints\"`). Writes the optimisation table, \
          exports/<stage>/success_vs_budget.svg and .png, and per goal action_<goal>.svg and .png (the best \
          action's rollout with the program).",
    writes: "optimisation, exports/<stage>/success_vs_budget.{svg,png}, exports/<stage>/action_<goal>.{svg,png}",
    params: ParamsOf::of::<OptimiseParams>(),
    build,
};

/// The scenes and action box of the stage's environment.
#[derive(Debug)]
enum EnvSetup {
    Pool {
        scene_seed: u64,
        layout: Layout,
        dt: f64,
        bounds: ShotBounds,
    },
    Phyre {
        tasks: Vec<String>,
    },
    Iphyre {
        games: Vec<Game>,
        fps: f64,
        horizon: f64,
    },
}

/// The `optimise` stage.
#[derive(Debug)]
pub struct OptimiseStage {
    env: Env,
    setup_env: EnvSetup,
    goals: GoalSet,
    goal_ids: Vec<String>,
    programs_from_table: bool,
    library: Library,
    setup: DetectorSetup,
    scenes: usize,
    seeds: u64,
    budgets: Vec<usize>,
    axis: BudgetAxis,
    rewards: Vec<RewardKind>,
    frames: usize,
    title: String,
    goals_text: String,
    summary_extra: Value,
}

fn count(k: &'static str, v: u64, min: u64) -> Result<u64, BuildError> {
    if v < min {
        Err(BuildError::param(
            k,
            format!("`{k}` must be >= {min}, found {v}"),
        ))
    } else {
        Ok(v)
    }
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: OptimiseParams = def.params()?;
    let (env, common, setup_env, extra) = match p {
        OptimiseParams::Pooltool(q) => {
            if !(q.dt > 0.0 && q.dt <= 1.0) {
                return Err(BuildError::param(
                    "dt",
                    format!("dt must be in (0, 1] s, found {}", q.dt),
                ));
            }
            let bounds = ShotBounds {
                v0: (0.2_f64.min(q.v0_max / 2.0), q.v0_max),
                theta: (0.0, q.theta_max),
                ..ShotBounds::default()
            };
            bounds
                .dims(&PoolEnv::default())
                .map_err(|e| BuildError::param("v0_max", e.to_string()))?;
            let extra = json!({
                "scene_seed": q.scene_seed, "layout": format!("{:?}", q.layout).to_lowercase(), "dt": q.dt,
                "bounds": {"v0": bounds.v0, "theta": bounds.theta, "max_offset": bounds.max_offset},
            });
            let setup = EnvSetup::Pool {
                scene_seed: q.scene_seed,
                layout: q.layout,
                dt: q.dt,
                bounds,
            };
            (Env::Pooltool, q.common, setup, extra)
        }
        OptimiseParams::Phyre(q) => {
            let set =
                TaskSet::default_tasks().map_err(|e| BuildError::param("tasks", e.to_string()))?;
            let only = match &q.tasks {
                Some(list) => super::simulate::select_tasks(set, list)
                    .map_err(|e| BuildError::param("tasks", e))?,
                None => Vec::new(),
            };
            let n = q.common.scenes as usize;
            let tasks = dataset_tasks(set, n, &only);
            if tasks.len() < n.min(1) {
                return Err(BuildError::param("tasks", "selects no task"));
            }
            let extra = json!({"tasks": tasks});
            (Env::Phyre, q.common, EnvSetup::Phyre { tasks }, extra)
        }
        OptimiseParams::Iphyre(q) => {
            let env = IphyreEnv::new().map_err(|e| BuildError::param("games", e.to_string()))?;
            let games = match &q.games {
                Some(list) => super::simulate::select_games(&env.games, list)
                    .map_err(|e| BuildError::param("games", e))?,
                None => env.games.all().to_vec(),
            };
            let params = crate::envs::iphyre::PhysicsParams::with_fps(q.fps);
            params
                .validate()
                .map_err(|e| BuildError::param("fps", e.to_string()))?;
            if !(q.horizon > 0.0 && q.horizon <= params.max_time) {
                return Err(BuildError::param(
                    "horizon",
                    format!(
                        "horizon must be in (0, {}] s, found {}",
                        params.max_time, q.horizon
                    ),
                ));
            }
            let extra = json!({"games": games.iter().map(|g| g.name.clone()).collect::<Vec<_>>(), "fps": q.fps, "horizon": q.horizon});
            let setup = EnvSetup::Iphyre {
                games,
                fps: q.fps,
                horizon: q.horizon,
            };
            (Env::Iphyre, q.common, setup, extra)
        }
    };
    let c = common;
    // The project's file, else the built-in one (pipelines run from another folder).
    let goals_rel = c
        .goals
        .clone()
        .unwrap_or_else(|| format!("data/goals/{env}.toml"));
    let goals_at = Location::file(&spec.project_dir, std::path::Path::new(&goals_rel));
    let goals_path = goals_at.path();
    let goals = GoalSet::open(&goals_at, &spec.project_dir)
        .map_err(|e| BuildError::param("goals", e.to_string()))?;
    if goals.env != env {
        return Err(BuildError::param(
            "goals",
            format!(
                "{} is for {}, but this stage optimises {env} (set `env`)",
                goals_path.display(),
                goals.env
            ),
        ));
    }
    let goals_text = goals_at
        .read_to_string()
        .map_err(|e| BuildError::param("goals", e.to_string()))?;
    let goal_ids: Vec<String> = match &c.goal_ids {
        Some(ids) => ids.clone(),
        None => goals.goals.iter().map(|g| g.id.clone()).collect(),
    };
    if let Some(bad) = goal_ids.iter().find(|id| goals.get(id).is_none()) {
        return Err(BuildError::param(
            "goal_ids",
            format!("no goal {bad:?} in {}", goals_path.display()),
        ));
    }
    let synth_input = def.inputs.iter().any(|i| {
        spec.stages
            .iter()
            .any(|s| &s.id == i && s.kind.name == super::synthesise::KIND.name)
    });
    let programs_from_table = match c.programs {
        ProgramSource::Auto => synth_input,
        ProgramSource::Goals => false,
        ProgramSource::RewardPrograms if synth_input => true,
        ProgramSource::RewardPrograms => {
            return Err(BuildError::param(
                "programs",
                "reward_programs needs a synthesise stage among the stage's `inputs`",
            ));
        }
    };
    // The sandbox settings; the library is the goal file's unless one is given.
    let sandbox = SandboxParams {
        env,
        library: c
            .library
            .clone()
            .or_else(|| goals.library.as_ref().map(|l| l.as_param())),
        workers: c.workers,
        timeout: c.timeout,
        memory_mb: c.memory_mb,
    };
    let setup = DetectorSetup::new(&sandbox, spec)?;
    let library = setup.library.clone();
    if c.rewards.is_empty() {
        return Err(BuildError::param(
            "rewards",
            "give at least one reward type",
        ));
    }
    let budget = count("budget", c.budget, 1)? as usize;
    let step = count("checkpoint", c.checkpoint, 1)? as usize;
    let mut budgets: Vec<usize> = (1..)
        .map(|k| k * step)
        .take_while(|&b| b < budget)
        .collect();
    budgets.push(budget);
    Ok(Box::new(OptimiseStage {
        env,
        setup_env,
        scenes: count("scenes", c.scenes, 1)? as usize,
        seeds: count("seeds", c.seeds, 1)?,
        budgets,
        axis: c.budget_axis,
        goals,
        goal_ids,
        programs_from_table,
        library,
        setup,
        rewards: c.rewards.clone(),
        frames: c.frames as usize,
        title: c.title.clone(),
        goals_text,
        summary_extra: extra,
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
        f("action", DataType::Utf8),
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
        let schedule = Schedule::default();
        match &self.setup_env {
            EnvSetup::Pool {
                scene_seed,
                layout,
                dt,
                bounds,
            } => {
                let mut env = PoolEnv::default();
                env.trace.dt = *dt;
                let scenes = scenes(&env, *layout, self.scenes, *scene_seed)?;
                let problem = PoolProblem::new(env, *bounds)?;
                self.run_env(ctx, problem, schedule, &scenes)
            }
            EnvSetup::Phyre { tasks } => {
                let set = TaskSet::default_tasks()
                    .map_err(|e| StageError::Input(format!("PHYRE tasks: {e}")))?;
                let scenes: Vec<Task> = tasks
                    .iter()
                    .map(|id| {
                        set.get(id).map_err(|e| StageError::Simulation {
                            item: format!("task {id}"),
                            source: Box::new(e),
                        })
                    })
                    .collect::<Result<_, _>>()?;
                let problem = PhyreProblem {
                    env: PhyreEnv::default(),
                };
                self.run_env(ctx, problem, schedule, &scenes)
            }
            EnvSetup::Iphyre {
                games,
                fps,
                horizon,
            } => {
                let mut env = IphyreEnv::new().map_err(|e| StageError::Simulation {
                    item: "I-PHYRE games".into(),
                    source: Box::new(e),
                })?;
                env.params = crate::envs::iphyre::PhysicsParams::with_fps(*fps);
                let _: &Games = &env.games;
                let scenes: Vec<Game> = (0..self.scenes)
                    .map(|i| games[i % games.len()].clone())
                    .collect();
                let problem = IphyreProblem {
                    env,
                    horizon: *horizon,
                    never: 0.25,
                };
                self.run_env(ctx, problem, schedule, &scenes)
            }
        }
    }
}

/// A goal's program text and where it came from.
struct ProgramText {
    text: String,
    origin: &'static str,
}

impl OptimiseStage {
    fn max_budget(&self) -> usize {
        *self.budgets.last().expect("at least one budget")
    }

    /// Every goal's program: the goal file's, or the input synthesise stage's accepted one.
    fn programs(
        &self,
        ctx: &StageContext<'_>,
    ) -> Result<BTreeMap<String, ProgramText>, StageError> {
        let mut out = BTreeMap::new();
        if !self.programs_from_table {
            for id in &self.goal_ids {
                let g = self.goals.get(id).expect("checked at build");
                out.insert(
                    id.clone(),
                    ProgramText {
                        text: g.program.clone(),
                        origin: "goal file",
                    },
                );
            }
            return Ok(out);
        }
        let rows = super::synthesise::read_programs(ctx.run())?;
        if rows.is_empty() {
            return Err(StageError::Input(
                "the run has no reward_programs rows: the input synthesise stage wrote none".into(),
            ));
        }
        for r in rows {
            if let (Some(text), true) = (r.program, self.goal_ids.contains(&r.goal)) {
                out.insert(
                    r.goal,
                    ProgramText {
                        text,
                        origin: if r.origin == "llm" {
                            "synthesised"
                        } else {
                            "goal file"
                        },
                    },
                );
            }
        }
        Ok(out)
    }

    fn run_env<P: Problem>(
        &self,
        ctx: &StageContext<'_>,
        problem: P,
        schedule: Schedule,
        scenes: &[P::Scene],
    ) -> Result<StageOutput, StageError> {
        let settings = Settings {
            problem,
            schedule,
            checkpoint: match self.axis {
                BudgetAxis::Independent => None,
                BudgetAxis::Checkpoints => Some(self.budgets[0]),
            },
        };
        let programs = self.programs(ctx)?;
        let todo: Vec<&String> = self
            .goal_ids
            .iter()
            .filter(|g| programs.contains_key(*g))
            .collect();
        let skipped: Vec<&String> = self
            .goal_ids
            .iter()
            .filter(|g| !programs.contains_key(*g))
            .collect();
        ctx.progress()
            .set_total(ctx.stage_id(), (todo.len() * self.max_budget()) as u64);
        let mut pool = None;
        let mut schema = None;
        let mut records = Vec::new();
        for id in todo {
            let gi = self.goal_ids.iter().position(|g| g == id).expect("listed");
            let shard = format!("{gi:03}");
            if let Some(r) = ctx.finished_shard(&shard)? {
                records.push(r);
                ctx.progress()
                    .advance(ctx.stage_id(), self.max_budget() as u64);
                continue;
            }
            if pool.is_none() {
                pool = Some(self.setup.pool()?);
            }
            let pool_ref = pool.as_ref().expect("just started");
            let schema = schema.get_or_insert_with(|| probe_schema(&self.library, pool_ref));
            let prog = &programs[id];
            let task = self.goal_task(id, &prog.text, schema)?;
            let (chains, seed_index) = self.chains(ctx.seed(), gi, scenes);
            let mut record = self.run_goal(
                ctx,
                &settings,
                &shard,
                task,
                &chains,
                &seed_index,
                pool_ref,
                scenes,
            )?;
            record["program_origin"] = json!(prog.origin);
            records.push(record);
        }
        let (cs, mut files) = self.plot(ctx)?;
        for r in &records {
            for f in r["figures"].as_array().into_iter().flatten() {
                if let Some(f) = f.as_str() {
                    files.push(PathBuf::from(f));
                }
            }
        }
        Ok(self.output(&records, &cs, files, &skipped))
    }

    /// Goal `id`'s compiled reward program and verification rule, with the detectors it uses.
    fn goal_task(
        &self,
        id: &str,
        program: &str,
        schema: &crate::reward::Schema,
    ) -> Result<GoalTask, StageError> {
        let goal = self.goals.get(id).expect("checked at build");
        let program = compile(program, schema).map_err(|source| StageError::Goal {
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

    /// The chains of goal number `gi`: every scene × seed × reward type (× budget when the budgets
    /// are independent runs), seeded from the run's seed; and each chain seed's index 0..seeds.
    fn chains<S: Clone>(
        &self,
        run_seed: u64,
        gi: usize,
        scenes: &[S],
    ) -> (Vec<Chain<S>>, BTreeMap<u64, i64>) {
        let budgets = match self.axis {
            BudgetAxis::Independent => self.budgets.clone(),
            BudgetAxis::Checkpoints => vec![self.max_budget()],
        };
        let mut chains = Vec::new();
        let mut index = BTreeMap::new();
        for (si, scene) in scenes.iter().enumerate() {
            for s in 0..self.seeds {
                let seed = mix(run_seed ^ mix(gi as u64 + 1) ^ mix((si as u64) << 20 | s));
                index.insert(seed, s as i64);
                for &budget in &budgets {
                    for &kind in &self.rewards {
                        chains.push(Chain {
                            goal: 0,
                            scene: scene.clone(),
                            seed,
                            kind,
                            budget,
                        });
                    }
                }
            }
        }
        (chains, index)
    }

    /// Runs one goal's chains, writes its rows as shard `shard` and its action figure, and returns the
    /// shard's record.
    #[allow(clippy::too_many_arguments)]
    fn run_goal<P: Problem>(
        &self,
        ctx: &StageContext<'_>,
        settings: &Settings<P>,
        shard: &str,
        task: GoalTask,
        chains: &[Chain<P::Scene>],
        seed_index: &BTreeMap<u64, i64>,
        pool: &crate::detect::WorkerPool,
        scenes: &[P::Scene],
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
        let wall = t0.elapsed().as_secs_f64();
        let figures = self.action_figure(ctx, &settings.problem, &task, &rows, scenes)?;
        let batch = rows_batch(&rows, seed_index)?;
        ctx.checkpoint_mid_shard(ordinal)?;
        let n = ctx.write_batch("optimisation", self.env, shard, &batch)?;
        let record = json!({
            "goal": task.id,
            "rows": n,
            "chains": chains.len(),
            "wall_s": wall,
            "figures": figures,
            "timings": {
                "samples": timings.samples, "dense_samples": timings.dense_samples,
                "simulate_s": timings.simulate_s, "annotate_s": timings.annotate_s,
                "score_s": timings.score_s, "failed_simulations": timings.failed_simulations,
                "failed_calls": timings.failed_calls, "program_errors": timings.program_errors,
                "invalid_actions": timings.invalid_actions,
            },
        });
        ctx.finish_shard(shard, &record)?;
        Ok(record)
    }

    /// The optimised-action figure of a goal: the best dense row at the largest budget (a verified
    /// one first, then the highest reward), its action simulated again and drawn as a strip with the
    /// goal and the program. Returns the files written (none when `frames` is 0 or no dense row).
    fn action_figure<P: Problem>(
        &self,
        ctx: &StageContext<'_>,
        problem: &P,
        task: &GoalTask,
        rows: &[CheckpointRow],
        scenes: &[P::Scene],
    ) -> Result<Vec<String>, StageError> {
        if self.frames == 0 {
            return Ok(Vec::new());
        }
        let top = self.max_budget();
        let best = rows
            .iter()
            .filter(|r| r.kind == RewardKind::Dense && r.budget == top && !r.point.is_empty())
            .max_by(|a, b| {
                (a.success, a.best_reward)
                    .partial_cmp(&(b.success, b.best_reward))
                    .unwrap_or(std::cmp::Ordering::Equal)
            });
        let Some(best) = best else {
            return Ok(Vec::new());
        };
        let Some(scene) = scenes.iter().find(|s| problem.scene_id(s) == best.scene) else {
            return Ok(Vec::new());
        };
        let sim_err = |e: crate::envs::EnvError| StageError::Simulation {
            item: format!("optimised action of goal {} on {}", task.id, best.scene),
            source: Box::new(e),
        };
        let trace = problem.simulate(scene, &best.point).map_err(sim_err)?;
        let strip = problem.strip(scene, &trace, self.frames).map_err(sim_err)?;
        let sentence = self
            .goals
            .get(&task.id)
            .map(|g| g.sentence.clone())
            .unwrap_or_default();
        let caption = format!(
            "{} · action {} · reward {:.3} · {} (sample {} of {})",
            best.scene,
            rounded(&best.action),
            best.best_reward,
            if best.success {
                "verified"
            } else {
                "not verified"
            },
            best.best_sample,
            top
        );
        let svg_text = action_svg(&ActionFigure {
            goal: &sentence,
            caption: &caption,
            program: &task.program.source,
            strip: &strip,
        })
        .map_err(StageError::Internal)?;
        let dir = ctx.run().exports_dir().join(ctx.stage_id());
        std::fs::create_dir_all(&dir).map_err(|e| StageError::io(&dir, e))?;
        let svg_path = dir.join(format!("action_{}.svg", task.id));
        write_atomic(&svg_path, svg_text.as_bytes()).map_err(|e| StageError::io(&svg_path, e))?;
        let png_path = dir.join(format!("action_{}.png", task.id));
        write_atomic(&png_path, &strip).map_err(|e| StageError::io(&png_path, e))?;
        Ok(vec![
            svg_path.to_string_lossy().into_owned(),
            png_path.to_string_lossy().into_owned(),
        ])
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
            "{}: {} ({} goals × {} scenes × {} seeds)",
            self.env,
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
        skipped: &[&String],
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
        let origins: BTreeMap<String, Value> = records
            .iter()
            .filter_map(|r| Some((r["goal"].as_str()?.to_string(), r["program_origin"].clone())))
            .collect();
        let mut rows = BTreeMap::new();
        rows.insert("optimisation".to_string(), rows_total);
        StageOutput {
            rows,
            files,
            summary: json!({
                "env": self.env, "goals": self.goal_ids, "goal_file": self.goals.path, "library": self.library.name,
                "programs": origins, "skipped_goals": skipped,
                "scenes": self.scenes, "seeds": self.seeds,
                "budgets": self.budgets, "budget_axis": self.axis,
                "environment": self.summary_extra,
                "timings": totals, "final_success": last,
            }),
            line: format!(
                "{}: {} goal(s) × {} scene(s) × {} seed(s), budgets {}..{} ({}){}: final success {}",
                self.env,
                records.len(),
                self.scenes,
                self.seeds,
                self.budgets[0],
                self.max_budget(),
                match self.axis {
                    BudgetAxis::Independent => "independent runs",
                    BudgetAxis::Checkpoints => "checkpoints of one run",
                },
                if skipped.is_empty() {
                    String::new()
                } else {
                    format!(", {} goal(s) without a program skipped", skipped.len())
                },
                last.iter()
                    .map(|(k, v)| format!("{k} {v:.3}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

/// `v` with every number rounded to 3 decimals, as compact JSON (for captions).
fn rounded(v: &Value) -> String {
    fn walk(v: &Value) -> Value {
        match v {
            Value::Number(n) => n
                .as_f64()
                .map(|f| json!((f * 1000.0).round() / 1000.0))
                .unwrap_or_else(|| v.clone()),
            Value::Array(a) => Value::Array(a.iter().map(walk).collect()),
            Value::Object(o) => {
                Value::Object(o.iter().map(|(k, x)| (k.clone(), walk(x))).collect())
            }
            other => other.clone(),
        }
    }
    walk(v).to_string()
}

/// The `optimisation` rows of one goal as a batch (seeds as their index 0..seeds).
fn rows_batch(
    rows: &[CheckpointRow],
    seed_index: &BTreeMap<u64, i64>,
) -> Result<RecordBatch, arrow::error::ArrowError> {
    RecordBatch::try_new(
        schema(),
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
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|r| r.action.to_string()),
            )),
        ],
    )
}
