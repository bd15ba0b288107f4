//! `annotrace simulate`: simulates billiards shots into a run, as a one-stage pipeline.
//!
//! Dataset mode (`--scenes N --shots K --seed S`) and replay mode (`--scene FILE --shot JSON`) both
//! become a `simulate` stage (`pipeline/stages/simulate.rs`) recorded in the run's manifest as
//! `simulate-<hash of its arguments>`, so the same command again is a no-op and an interrupted one
//! resumes. Bad input (a scene file that is not JSON, a ball off the table, overlapping balls, an
//! invalid shot) is reported with the file or field at fault, exit code 2, and nothing is written.

use std::path::{Path, PathBuf};

use annotrace::pipeline::{PipelineSpec, RunOptions, hex, run as run_pipeline};
use anyhow::Context;
use serde::Serialize;
use sha2::{Digest, Sha256};

use super::progress::Terminal;
use super::{CliError, CliResult, fault_from_env, run_error};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Environment to simulate.
    #[arg(long, default_value = "pooltool", value_parser = ["pooltool"])]
    env: String,
    /// Run folder to write into (created if needed).
    #[arg(long)]
    run: PathBuf,
    /// Dataset mode: number of random 9-ball racks.
    #[arg(long, default_value_t = 10, conflicts_with = "scene")]
    scenes: u64,
    /// Dataset mode: random shots per rack.
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
    /// Scenes per output file (a resumed run redoes at most the unfinished shards).
    #[arg(long, default_value_t = 100)]
    scenes_per_shard: u64,
}

#[derive(Serialize)]
struct OneStage {
    stage: Vec<SimulateStage>,
}

#[derive(Serialize)]
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
    let replay = args.scene.is_some();
    let mut stage = SimulateStage {
        id: String::new(),
        kind: "simulate",
        env: args.env.clone(),
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
        dt: args.dt,
        max_events: args.max_events,
        max_time: args.max_time,
        scenes_per_shard: args.scenes_per_shard.max(1),
    };
    let key = toml::to_string(&stage)
        .map_err(|e| CliError::failed(anyhow::anyhow!("internal error: {e}")))?;
    stage.id = format!("simulate-{}", &hex(&Sha256::digest(key.as_bytes()))[..10]);
    let text = toml::to_string(&OneStage { stage: vec![stage] })
        .map_err(|e| CliError::failed(anyhow::anyhow!("internal error: {e}")))?;
    let spec = PipelineSpec::from_toml(Path::new("annotrace-simulate.toml"), &text)
        .map_err(CliError::input)?;
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
    println!(
        "{} {} {} trace(s) ({} successful, {} capped; {} frame rows) into {}{}",
        if stage.cached {
            "already simulated:"
        } else {
            "simulated"
        },
        s["traces"].as_u64().unwrap_or(0),
        args.env,
        s["successes"].as_u64().unwrap_or(0),
        s["capped"].as_u64().unwrap_or(0),
        stage.rows.get("frames").copied().unwrap_or(0),
        args.run.display(),
        if stage.cached { " (nothing to do)" } else { "" }
    );
    Ok(0)
}
