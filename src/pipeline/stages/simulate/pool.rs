//! Billiards for the `simulate` stage: seeded 9-ball racks × random shots, or one replayed shot, with
//! pooltool 0.6.0's physics (`envs::pool`).
//!
//! **Owns:** the billiards parameters ([`PoolSimParams`]), the work list, trace and scene ids, and
//! simulating one work item (a rack and its shots). **Does not:** simulate (`envs::pool`) or run and write
//! shards (`shards`).
//!
//! Two modes. **Dataset**: `scenes` seeded 9-ball racks × `shots` random shots each; scene `i` and shot
//! `k` draw from RNGs derived from (`seed`, `i`) and (`seed`, `i`, `k`) alone, so the tables are
//! byte-identical whatever the thread count and sharding. **Replay**: `scene_file` (scene JSON, see
//! `envs::pool::Scene`) and `shot` (`{V0, phi, theta, a, b}`) give exactly one trace. Bad input (a scene
//! that is not JSON, a ball off the table, overlapping balls, an invalid shot, an unreadable table file)
//! is caught when the stage is built, before anything is written.
//!
//! Ids: dataset scenes are `pool-<seed>-<index:06>` and their traces `<scene_id>-<shot:03>`; a replayed
//! trace is `<scene_id>-<first 8 hex digits of the shot's hash>`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use sha2::{Digest, Sha256};

use super::shards::{Count, ItemOutput, ShardTotals, replay_pair};
use super::{ShardParams, SimulateSummary, Simulation};
use crate::digest::hex;
use crate::envs::pool::{
    PoolConfig, Scene, Shot, SimOptions, TraceOptions, rack, simulate, trace_columns,
};
use crate::pipeline::registry::BuildError;
use crate::pipeline::spec::PipelineSpec;
use crate::pipeline::stage::StageError;
use crate::trace::Env;
use crate::trace::batch::scene_batch;

/// The most timesteps one billiards trace may have: a trace is built in memory before it is written
/// (16 balls × 1 M timesteps ≈ 2.4 GB of frame rows).
pub const MAX_TIMESTEPS: u64 = 1_000_000;
/// The longest a shot is assumed to last when `max_time` is not given (s), for the memory bound: balls
/// on pooltool's table stop well within it.
pub const SHOT_HORIZON_S: f64 = 60.0;

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

/// What to simulate.
#[derive(Debug)]
enum Work {
    /// Random racks and shots.
    Dataset { scenes: u64, shots: u64, seed: u64 },
    /// One scene, one shot.
    Replay { scene: Box<Scene>, shot: Shot },
}

/// Billiards shots for the `simulate` stage.
#[derive(Debug)]
pub(crate) struct PoolSimulation {
    config: PoolConfig,
    /// The table file's text, when one was given (enters the fingerprint).
    table_text: Option<String>,
    work: Work,
    sim: SimOptions,
    trace: TraceOptions,
}

/// Builds the billiards simulation from its parameters.
pub(super) fn build(p: &PoolSimParams, spec: &PipelineSpec) -> Result<PoolSimulation, BuildError> {
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
    // A trace is built in memory before it is written: bound its timesteps before simulating.
    let horizon = p.max_time.unwrap_or(SHOT_HORIZON_S);
    let steps = horizon / dt;
    if steps > MAX_TIMESTEPS as f64 {
        return Err(BuildError::param(
            "dt",
            format!(
                "`dt`: {dt} s gives up to {steps:.0} timesteps per shot over {horizon} s (`max_time`, \
                 default horizon {SHOT_HORIZON_S} s); the limit is {MAX_TIMESTEPS} (about 2.4 GB of frames \
                 for a full rack): use dt >= {:.1e} or a smaller max_time",
                horizon / MAX_TIMESTEPS as f64
            ),
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
    Ok(PoolSimulation {
        config,
        table_text,
        work,
        sim: SimOptions {
            max_events: usize::try_from(p.max_events).unwrap_or(usize::MAX),
            t_final: max_time,
        },
        trace: TraceOptions { dt },
    })
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

impl Simulation for PoolSimulation {
    fn env(&self) -> Env {
        Env::Pooltool
    }

    /// Scenes: each writes one trace per shot.
    fn items(&self) -> u64 {
        match &self.work {
            Work::Dataset { scenes, .. } => *scenes,
            Work::Replay { .. } => 1,
        }
    }

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

    /// Billiards trace ids must be new across every environment's traces.
    fn id_scope(&self) -> Option<Env> {
        None
    }

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

    fn simulate_item(&self, index: u64, source: &str) -> Result<ItemOutput, StageError> {
        let (scene, shots) = self.scene_work(index);
        let system = scene
            .system(&self.config)
            .map_err(|e| StageError::Simulation {
                item: format!("scene {}", scene.scene_id),
                source: e.into(),
            })?;
        let mut spec = scene.to_json();
        spec["table"] = json!(self.config.name);
        spec["index"] = json!(index);
        let batch = scene_batch(
            &scene.scene_id,
            &scene.scene_id,
            source,
            scene.balls.len(),
            &spec,
        )?;
        let (mut successes, mut capped, mut events) = (0u64, 0u64, 0u64);
        let mut traces = Vec::with_capacity(shots.len());
        for (trace_id, shot) in &shots {
            let sim = simulate(&system, shot, &self.sim).map_err(|e| StageError::Simulation {
                item: format!("trace {trace_id}"),
                source: e.into(),
            })?;
            let trace = trace_columns(&sim, &scene, shot, trace_id, &self.trace);
            successes += u64::from(trace.outcome.success);
            capped += u64::from(matches!(
                trace.outcome.terminal_status.as_str(),
                "max_events" | "max_time"
            ));
            events += sim.events.len() as u64;
            traces.push(trace);
        }
        Ok(ItemOutput {
            scene: Some(batch),
            scene_id: scene.scene_id,
            counts: vec![
                ("successes", Count::Int(successes)),
                ("capped", Count::Int(capped)),
                ("physics_events", Count::Int(events)),
            ],
            traces,
        })
    }

    fn report(&self, sums: &ShardTotals) -> (SimulateSummary, String) {
        let (traces, successes) = (sums.count("traces"), sums.count("successes"));
        let (capped, events) = (sums.count("capped"), sums.count("physics_events"));
        let frames = sums.rows.get("frames").copied().unwrap_or(0);
        let line = format!(
            "{traces} pool trace(s), {successes} successful, {capped} capped; {events} physics events, {frames} frame rows"
        );
        let summary = SimulateSummary {
            env: Env::Pooltool,
            traces,
            successes,
            capped: Some(capped),
            physics_events: Some(events),
            table: Some(self.config.name.clone()),
            dt: Some(self.trace.dt),
            ..SimulateSummary::default()
        };
        (summary, line)
    }
}

impl PoolSimulation {
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
