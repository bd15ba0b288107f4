//! `annotrace simulate`: simulates billiards shots, PHYRE episodes or I-PHYRE episodes into a run, as a
//! one-stage pipeline.
//!
//! Dataset mode (`--scenes N --shots K --seed S`) and replay mode (billiards `--scene FILE --shot JSON`,
//! PHYRE `--task ID --action A`, I-PHYRE `--game G --clicks C`) both become a `simulate` stage
//! (`pipeline/stages/simulate.rs`) whose typed parameters the flags fill; it is recorded in the run's
//! manifest as `simulate-<hash of its parameters>`, so the same command again is a no-op and an
//! interrupted one resumes. Bad input (a scene file that is not JSON, a ball off the table, an invalid
//! shot, an unknown task or game, a flag of another environment) is reported with the flag at fault,
//! exit code 2, and nothing is written.

use std::path::{Path, PathBuf};

use annotrace::pipeline::stages::simulate::{
    IphyreSimParams, KIND, PhyreSimParams, PoolSimParams, ShardParams, SimulateParams,
};
use annotrace::trace::Env;

use super::one_stage::{OneStage, absolute, params_id, summary};
use super::{CliError, CliResult};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Environment to simulate: pooltool (billiards), phyre or iphyre.
    #[arg(long, default_value = "pooltool")]
    env: Env,
    /// Run folder to write into (created if needed).
    #[arg(long)]
    run: PathBuf,
    /// Dataset mode: number of random 9-ball racks (phyre: tasks; not for iphyre) [default: 10].
    #[arg(long, conflicts_with = "scene")]
    scenes: Option<u64>,
    /// Dataset mode: random shots per rack (phyre: actions per task; iphyre: click sets per game).
    #[arg(long, default_value_t = 1, conflicts_with = "scene")]
    shots: u64,
    /// Dataset mode: seed of the scenes and actions.
    #[arg(long, default_value_t = 0, conflicts_with = "scene")]
    seed: u64,
    /// pooltool replay mode: a scene JSON file (balls, cue ball, goal; see docs/envs/pool.md).
    #[arg(long, requires = "shot")]
    scene: Option<PathBuf>,
    /// pooltool replay mode: the shot, e.g. '{"V0": 3, "phi": 90, "theta": 0, "a": 0, "b": 0.2}'.
    #[arg(long, requires = "scene")]
    shot: Option<String>,
    /// pooltool: table file (geometry, ball and cue parameters); default: the built-in 7-ft table.
    #[arg(long)]
    table: Option<PathBuf>,
    /// pooltool: timestep spacing of the traces (s) [default: 0.01].
    #[arg(long)]
    dt: Option<f64>,
    /// pooltool: stop a shot after this many events (0 = no cap) [default: 100000].
    #[arg(long)]
    max_events: Option<u64>,
    /// pooltool: stop a shot at the first event at or after this time (s).
    #[arg(long)]
    max_time: Option<f64>,
    /// Scenes per output file (a resumed run redoes at most the unfinished shards; iphyre and phyre:
    /// traces per file).
    #[arg(long, default_value_t = 100)]
    scenes_per_shard: u64,
    /// iphyre dataset mode: comma-separated game and fold names (basic, noisy, compositional,
    /// multi_ball), or all [default: all].
    #[arg(long, conflicts_with = "game")]
    games: Option<String>,
    /// iphyre: physics steps per second, I-PHYRE's 60 or the gym wrappers' and DeepPHY's 10 [default: 60].
    #[arg(long, value_parser = ["60", "10"])]
    fps: Option<String>,
    /// iphyre replay mode: the game to play.
    #[arg(long, requires = "clicks")]
    game: Option<String>,
    /// iphyre replay mode: clicks `x,y,t;…` (px, s) or `k@t;…` (remove eliminable block k at t s).
    #[arg(long, requires = "game")]
    clicks: Option<String>,
    /// phyre dataset mode: comma-separated template ids (00003), task ids (00003:002), fold splits
    /// (ball_cross_template/0/test) or all; --scenes tasks round-robin over templates, --shots random
    /// valid actions per task [default: all].
    #[arg(long, conflicts_with = "task")]
    tasks: Option<String>,
    /// phyre replay mode: the task id, e.g. 00004:063.
    #[arg(long, requires = "action")]
    task: Option<String>,
    /// phyre replay mode: the action, `[x, y, r]` in [0, 1] (or '{"x": …, "y": …, "r": …}', or DeepPHY's
    /// '{"cell": 1-64, "radius": 1-8}').
    #[arg(long, requires = "task", allow_hyphen_values = true)]
    action: Option<String>,
    /// phyre: keep a frame every this many 60 Hz steps (6 = 10 frames/s; events keep every step)
    /// [default: 6].
    #[arg(long)]
    stride: Option<u64>,
    /// phyre: the physics engine, box2d (PHYRE's own, the default) or rapier; iphyre: chipmunk
    /// (annotrace's Chipmunk-faithful step, the default), rapier or box2d.
    #[arg(long, value_parser = ["box2d", "rapier", "chipmunk"])]
    engine: Option<String>,
}

/// Fails when a flag of another environment was given.
fn only_for(env: Env, flags: &[(&str, bool)]) -> Result<(), CliError> {
    let given: Vec<&str> = flags.iter().filter(|(_, g)| *g).map(|(f, _)| *f).collect();
    if given.is_empty() {
        return Ok(());
    }
    Err(CliError::input(anyhow::anyhow!(
        "{} {} not for --env {env}",
        given.join(", "),
        if given.len() == 1 { "is" } else { "are" }
    )))
}

fn existing_file(p: &Path, what: &str) -> Result<String, CliError> {
    let abs = absolute(p)?;
    if !Path::new(&abs).is_file() {
        return Err(CliError::input(anyhow::anyhow!(
            "{what} {}: no such file",
            p.display()
        )));
    }
    Ok(abs)
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    let pool_flags = [
        ("--scene/--shot", args.scene.is_some()),
        ("--table", args.table.is_some()),
        ("--dt", args.dt.is_some()),
        ("--max-events", args.max_events.is_some()),
        ("--max-time", args.max_time.is_some()),
    ];
    let phyre_flags = [
        ("--tasks", args.tasks.is_some()),
        ("--task/--action", args.task.is_some()),
        ("--stride", args.stride.is_some()),
    ];
    let iphyre_flags = [
        ("--games", args.games.is_some()),
        ("--game/--clicks", args.game.is_some()),
        ("--fps", args.fps.is_some()),
    ];
    let params = match args.env {
        Env::Pooltool => {
            only_for(args.env, &[("--engine", args.engine.is_some())])?;
            only_for(args.env, &phyre_flags)?;
            only_for(args.env, &iphyre_flags)?;
            SimulateParams::Pooltool(pool_params(&args)?)
        }
        Env::Phyre => {
            only_for(args.env, &pool_flags)?;
            only_for(args.env, &iphyre_flags)?;
            let replay = args.task.is_some();
            SimulateParams::Phyre(PhyreSimParams {
                scenes: args.scenes.unwrap_or(PhyreSimParams::default().scenes),
                shards: shard_params(&args, replay),
                tasks: (!replay).then(|| args.tasks.clone().unwrap_or_else(|| "all".into())),
                task: args.task.clone(),
                action: args.action.clone(),
                stride: Some(args.stride.unwrap_or(6)),
                engine: match args.engine.as_deref() {
                    None => None,
                    Some(name) => Some(
                        annotrace::envs::phyre::Engine::from_name(name).ok_or_else(|| {
                            CliError::input(anyhow::anyhow!(
                                "--engine {name} is not a PHYRE engine: PHYRE takes box2d or rapier"
                            ))
                        })?,
                    ),
                },
            })
        }
        Env::Iphyre => {
            only_for(args.env, &pool_flags)?;
            only_for(args.env, &phyre_flags)?;
            only_for(args.env, &[("--scenes", args.scenes.is_some())])?;
            let replay = args.game.is_some();
            SimulateParams::Iphyre(IphyreSimParams {
                shards: shard_params(&args, replay),
                games: (!replay).then(|| args.games.clone().unwrap_or_else(|| "all".into())),
                fps: Some(if args.fps.as_deref() == Some("10") {
                    10.0
                } else {
                    60.0
                }),
                engine: args
                    .engine
                    .as_deref()
                    .and_then(annotrace::envs::iphyre::Engine::from_name),
                game: args.game.clone(),
                clicks: args.clicks.clone(),
            })
        }
    };
    run_stage(params, &args, quiet)
}

/// Shots, seed and sharding; a replay has no seed.
fn shard_params(args: &Args, replay: bool) -> ShardParams {
    ShardParams {
        shots: args.shots,
        seed: (!replay).then_some(args.seed),
        scenes_per_shard: args.scenes_per_shard.max(1),
    }
}

fn pool_params(args: &Args) -> Result<PoolSimParams, CliError> {
    let d = PoolSimParams::default();
    let replay = args.scene.is_some();
    Ok(PoolSimParams {
        scenes: args.scenes.unwrap_or(d.scenes),
        shards: shard_params(args, replay),
        scene_file: args
            .scene
            .as_deref()
            .map(|p| existing_file(p, "scene file"))
            .transpose()?,
        shot: args.shot.clone(),
        table: args
            .table
            .as_deref()
            .map(|p| existing_file(p, "table file"))
            .transpose()?,
        dt: args.dt.unwrap_or(d.dt),
        max_events: args.max_events.unwrap_or(d.max_events),
        max_time: args.max_time,
    })
}

/// Runs the stage into `--run` and prints what it did.
fn run_stage(params: SimulateParams, args: &Args, quiet: bool) -> CliResult {
    let stage = OneStage {
        run: &args.run,
        id: params_id("simulate", &params),
        force: false,
        remove_new_run_on_failure: false,
    }
    .run(&KIND, &params, quiet)?;
    let s: annotrace::pipeline::stages::simulate::SimulateSummary = summary(&stage, "simulate")?;
    let detail = match args.env {
        Env::Phyre => format!("{} invalid input", s.invalid.unwrap_or(0)),
        Env::Iphyre => format!("mean reward {:.1}", s.mean_reward.unwrap_or(0.0)),
        Env::Pooltool => format!("{} capped", s.capped.unwrap_or(0)),
    };
    println!(
        "{} {} {} trace(s) ({} successful, {detail}; {} frame rows) into {}{}",
        if stage.cached {
            "already simulated:"
        } else {
            "simulated"
        },
        s.traces,
        args.env,
        s.successes,
        stage.rows.get("frames").copied().unwrap_or(0),
        args.run.display(),
        if stage.cached { " (nothing to do)" } else { "" }
    );
    Ok(0)
}
