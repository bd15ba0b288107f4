//! `annotrace simulate`: simulates billiards shots or I-PHYRE episodes into a run, as a one-stage pipeline.
//!
//! Dataset mode (`--scenes N --shots K --seed S`) and replay mode (`--scene FILE --shot JSON`) both
//! become a `simulate` stage (`pipeline/stages/simulate.rs`) recorded in the run's manifest as
//! `simulate-<hash of its arguments>`, so the same command again is a no-op and an interrupted one
//! resumes. Bad input (a scene file that is not JSON, a ball off the table, overlapping balls, an
//! invalid shot) is reported with the file or field at fault, exit code 2, and nothing is written.
//! `--env iphyre` takes `--games`/`--shots`/`--seed` (random click sets) or `--game`/`--clicks`
//! (a replay) and `--fps 60|10`; an unknown game or a bad click fails the same way.

use std::path::{Path, PathBuf};

use annotrace::digest::hex;
use annotrace::pipeline::{PipelineSpec, RunOptions, run as run_pipeline};
use anyhow::Context;
use serde::Serialize;
use sha2::{Digest, Sha256};

use super::progress::Terminal;
use super::{CliError, CliResult, fault_from_env, run_error};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Environment to simulate.
    #[arg(long, default_value = "pooltool", value_parser = ["pooltool", "iphyre", "phyre"])]
    env: String,
    /// Run folder to write into (created if needed).
    #[arg(long)]
    run: PathBuf,
    /// Dataset mode: number of random 9-ball racks.
    #[arg(long, default_value_t = 10, conflicts_with = "scene")]
    scenes: u64,
    /// Dataset mode: random shots per rack (iphyre: random click sets per game).
    #[arg(long, default_value_t = 1, conflicts_with = "scene")]
    shots: u64,
    /// Dataset mode: seed of racks and shots.
    #[arg(long, default_value_t = 0, conflicts_with = "scene")]
    seed: u64,
    /// Replay mode: a scene JSON file (balls, cue ball, goal; see docs/envs/pool.md).
    #[arg(long, requires = "shot")]
    scene: Option<PathBuf>,
    /// Replay mode: the shot, e.g. '{"V0": 3, "phi": 90, "theta": 0, "a": 0, "b": 0.2}'.
    #[arg(long, requires = "scene")]
    shot: Option<String>,
    /// Table file (geometry, ball and cue parameters); default: the built-in pooltool 7-ft table.
    #[arg(long)]
    table: Option<PathBuf>,
    /// Timestep spacing of the traces (s).
    #[arg(long, default_value_t = 0.01)]
    dt: f64,
    /// Stop a shot after this many events (0 = no cap).
    #[arg(long, default_value_t = 100_000)]
    max_events: u64,
    /// Stop a shot at the first event at or after this time (s).
    #[arg(long)]
    max_time: Option<f64>,
    /// Scenes per output file (a resumed run redoes at most the unfinished shards; iphyre: traces per file).
    #[arg(long, default_value_t = 100)]
    scenes_per_shard: u64,
    /// iphyre dataset mode: comma-separated game and fold names (basic, noisy, compositional,
    /// multi_ball), or all.
    #[arg(long, default_value = "all", conflicts_with = "game")]
    games: String,
    /// iphyre: physics steps per second (I-PHYRE's 60, or the gym wrappers' and DeepPHY's 10).
    #[arg(long, default_value = "60", value_parser = ["60", "10"])]
    fps: String,
    /// iphyre replay mode: the game to play.
    #[arg(long, requires = "clicks")]
    game: Option<String>,
    /// iphyre replay mode: clicks `x,y,t;…` (px, s) or `k@t;…` (remove eliminable block k at t s).
    #[arg(long, requires = "game")]
    clicks: Option<String>,
    /// phyre dataset mode: comma-separated template ids (00003), task ids (00003:002), fold splits
    /// (ball_cross_template/0/test) or all; --scenes tasks round-robin over templates, --shots random
    /// valid actions per task.
    #[arg(long, default_value = "all", conflicts_with = "task")]
    tasks: String,
    /// phyre replay mode: the task id, e.g. 00004:063.
    #[arg(long, requires = "action")]
    task: Option<String>,
    /// phyre replay mode: the action, `[x, y, r]` in [0, 1] (or '{"x": …, "y": …, "r": …}', or DeepPHY's
    /// '{"cell": 1-64, "radius": 1-8}').
    #[arg(long, requires = "task", allow_hyphen_values = true)]
    action: Option<String>,
    /// phyre: keep a frame every this many 60 Hz steps (6 = 10 frames/s; events keep every step).
    #[arg(long, default_value_t = 6)]
    stride: u64,
}

#[derive(Serialize)]
struct OneStage {
    stage: Vec<SimulateStage>,
}

#[derive(Serialize, Default)]
struct SimulateStage {
    id: String,
    kind: &'static str,
    env: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    scenes: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    shots: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    seed: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    scene_file: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    shot: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    table: Option<String>,
    dt: f64,
    max_events: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    max_time: Option<f64>,
    scenes_per_shard: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    games: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fps: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    game: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    clicks: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tasks: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    task: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    action: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    stride: Option<u64>,
}

impl SimulateStage {
    /// The parameters every environment takes from the same flags; the rest unset.
    fn common(args: &Args) -> Self {
        SimulateStage {
            kind: "simulate",
            env: args.env.clone(),
            dt: args.dt,
            max_events: args.max_events,
            scenes_per_shard: args.scenes_per_shard.max(1),
            ..SimulateStage::default()
        }
    }
}

fn absolute(p: &Path, what: &str) -> Result<String, CliError> {
    let abs = std::path::absolute(p)
        .with_context(|| format!("resolving {}", p.display()))
        .map_err(CliError::input)?;
    if !abs.is_file() {
        return Err(CliError::input(anyhow::anyhow!(
            "{what} {}: no such file",
            p.display()
        )));
    }
    Ok(abs.to_string_lossy().into_owned())
}

pub fn run(args: Args, quiet: bool) -> CliResult {
    if args.env == "iphyre" {
        return run_iphyre(args, quiet);
    }
    if args.env == "phyre" {
        return run_phyre(args, quiet);
    }
    if args.task.is_some() {
        return Err(CliError::input(anyhow::anyhow!(
            "--task and --action are for --env phyre"
        )));
    }
    if args.game.is_some() {
        return Err(CliError::input(anyhow::anyhow!(
            "--game and --clicks are for --env iphyre"
        )));
    }
    let replay = args.scene.is_some();
    let stage = SimulateStage {
        scenes: (!replay).then_some(args.scenes),
        shots: (!replay).then_some(args.shots),
        seed: (!replay).then_some(args.seed),
        scene_file: args
            .scene
            .as_deref()
            .map(|p| absolute(p, "scene file"))
            .transpose()?,
        shot: args.shot.clone(),
        table: args
            .table
            .as_deref()
            .map(|p| absolute(p, "table file"))
            .transpose()?,
        max_time: args.max_time,
        ..SimulateStage::common(&args)
    };
    run_stage(stage, &args, quiet)
}

/// `--env iphyre`: random click sets on the chosen games, or one replayed click list.
fn run_iphyre(args: Args, quiet: bool) -> CliResult {
    if args.scene.is_some() || args.table.is_some() {
        return Err(CliError::input(anyhow::anyhow!(
            "--scene, --shot and --table are for --env pooltool; I-PHYRE replays take --game and --clicks"
        )));
    }
    let replay = args.game.is_some();
    let stage = SimulateStage {
        shots: (!replay).then_some(args.shots),
        seed: (!replay).then_some(args.seed),
        games: (!replay).then(|| args.games.clone()),
        fps: Some(if args.fps == "10" { 10.0 } else { 60.0 }),
        game: args.game.clone(),
        clicks: args.clicks.clone(),
        ..SimulateStage::common(&args)
    };
    run_stage(stage, &args, quiet)
}

/// `--env phyre`: random valid actions on the chosen tasks, or one replayed action.
fn run_phyre(args: Args, quiet: bool) -> CliResult {
    if args.scene.is_some() || args.table.is_some() || args.game.is_some() {
        return Err(CliError::input(anyhow::anyhow!(
            "--scene, --shot, --table, --game and --clicks are for other environments; PHYRE replays take --task and --action"
        )));
    }
    let replay = args.task.is_some();
    let stage = SimulateStage {
        scenes: (!replay).then_some(args.scenes),
        shots: (!replay).then_some(args.shots),
        seed: (!replay).then_some(args.seed),
        tasks: (!replay).then(|| args.tasks.clone()),
        task: args.task.clone(),
        action: args.action.clone(),
        stride: Some(args.stride),
        ..SimulateStage::common(&args)
    };
    run_stage(stage, &args, quiet)
}

/// Runs `stage` as a one-stage pipeline into `--run` and prints what it did.
fn run_stage(mut stage: SimulateStage, args: &Args, quiet: bool) -> CliResult {
    let key = toml::to_string(&stage)
        .map_err(|e| CliError::failed(anyhow::anyhow!("internal error: {e}")))?;
    stage.id = format!("simulate-{}", &hex(&Sha256::digest(key.as_bytes()))[..10]);
    let text = toml::to_string(&OneStage { stage: vec![stage] })
        .map_err(|e| CliError::failed(anyhow::anyhow!("internal error: {e}")))?;
    let spec = PipelineSpec::from_toml(Path::new("annotrace-simulate.toml"), &text)
        .map_err(|e| CliError::input(anyhow::anyhow!("{}", as_flag_error(&e))))?;
    let opts = RunOptions {
        run_dir: Some(args.run.clone()),
        fault: fault_from_env()?,
        ..RunOptions::default()
    };
    let report = run_pipeline(&spec, &opts, &Terminal::new(quiet)).map_err(run_error)?;
    let stage = report.stages.first().ok_or_else(|| {
        CliError::failed(anyhow::anyhow!(
            "internal error: the simulation did not run"
        ))
    })?;
    let s = &stage.summary;
    let detail = if args.env == "phyre" {
        format!("{} invalid input", s["invalid"].as_u64().unwrap_or(0))
    } else if args.env == "iphyre" {
        format!(
            "mean reward {:.1}",
            s["mean_reward"].as_f64().unwrap_or(0.0)
        )
    } else {
        format!("{} capped", s["capped"].as_u64().unwrap_or(0))
    };
    println!(
        "{} {} {} trace(s) ({} successful, {detail}; {} frame rows) into {}{}",
        if stage.cached {
            "already simulated:"
        } else {
            "simulated"
        },
        s["traces"].as_u64().unwrap_or(0),
        args.env,
        s["successes"].as_u64().unwrap_or(0),
        stage.rows.get("frames").copied().unwrap_or(0),
        args.run.display(),
        if stage.cached { " (nothing to do)" } else { "" }
    );
    Ok(0)
}

/// A validation error of the one-stage pipeline the command builds, worded for the command line: the
/// internal file, line and stage id are dropped and the parameter is named as its flag
/// (`` `game`: unknown I-PHYRE game "nope" `` → `--game: unknown I-PHYRE game "nope"`).
fn as_flag_error(e: &annotrace::pipeline::SpecError) -> String {
    let annotrace::pipeline::SpecError::Invalid { message, .. } = e else {
        return e.to_string();
    };
    let rest = match message.strip_prefix("stage \"") {
        Some(r) => r.split_once("\": ").map_or(message.as_str(), |(_, m)| m),
        None => message.as_str(),
    };
    match rest.strip_prefix('`').and_then(|r| r.split_once("`: ")) {
        Some((key, m)) => format!("--{}: {m}", key.replace('_', "-")),
        None => rest.to_string(),
    }
}
