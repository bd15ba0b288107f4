//! The `simulate` stage with `env = "iphyre"`: I-PHYRE episodes (`engine`: the Chipmunk-faithful step by
//! default, or rapier2d or Box2D; `envs::iphyre`) into the
//! trace tables, sharded and resumable like the billiards datasets.
//!
//! **Owns:** the I-PHYRE half of the `simulate` stage: reading its parameters, choosing the
//! (game, click set) work list, trace and scene ids, and simulating one work item into its scene row,
//! trace and counts.
//! **Does not:** declare the stage kind or its parameter list (`simulate.rs`, which routes here), or
//! simulate anything itself (`envs::iphyre`).
//!
//! Two modes. **Dataset**: for every selected game (`games`: names and fold names, default all 40),
//! `shots` seeded random click sets (`envs::iphyre::random_clicks`, drawn from (`seed`, game index,
//! sample) alone, so the tables do not depend on sharding or thread count). The work list is game-major;
//! every `scenes_per_shard` traces make one shard. **Replay**: `game` and `clicks` give one trace; a click
//! list is `x,y,t` items (screen pixels, seconds) or `k@t` items ("remove eliminable block k at t"),
//! separated by `;`. Bad input (an unknown game or fold, a click off the screen, non-finite, or after the
//! episode, a block number the game lacks, an fps that is not positive) fails when the stage is built,
//! before anything is written.
//!
//! Ids: scenes are `iphyre-<game>` (one row per game, written by the shard holding its first trace);
//! dataset traces are `iphyre-<seed>-<game>-<sample:04>`, a replay is `iphyre-<game>-<first 8 hex digits
//! of the click list's hash>`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use sha2::{Digest, Sha256};

use super::shards::{Count, ItemOutput, ShardTotals, replay_pair};
use super::{ShardParams, SimulateSummary, Simulation};
use crate::digest::hex;
use crate::envs::iphyre::{
    Click, Engine, Episode, Game, Games, PhysicsParams, click_block, clicks_rng, random_clicks,
    trace_columns, validate_clicks,
};
use crate::pipeline::registry::BuildError;
use crate::pipeline::spec::PipelineSpec;
use crate::pipeline::stage::StageError;
use crate::trace::Env;
use crate::trace::batch::scene_batch;

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
    /// Physics engine: `chipmunk` (default; annotrace's Chipmunk-faithful step, which reproduces the
    /// original's trajectories bit for bit on the balanced sets, docs/fidelity.md), `rapier` (rapier2d,
    /// the default before; 87–88 % of the original's held-out successes) or `box2d`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub engine: Option<Engine>,
    /// Replay mode: the game name.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub game: Option<String>,
    /// Replay mode: `x,y,t;…` clicks (px, s) or `k@t;…` (remove eliminable block k at t).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clicks: Option<String>,
}

/// The most games a dataset can select (I-PHYRE has 40), for the stage's count limits.
pub(super) const GAMES_AT_MOST: u64 = 40;

/// What to simulate.
#[derive(Debug)]
enum Work {
    /// `samples` random click sets on each game.
    Dataset {
        games: Vec<Game>,
        samples: u64,
        seed: u64,
    },
    /// One game, one click list.
    Replay { game: Box<Game>, clicks: Vec<Click> },
}

/// I-PHYRE episodes for the `simulate` stage.
#[derive(Debug)]
pub(crate) struct IphyreSimulation {
    params: PhysicsParams,
    work: Work,
}

/// Builds the I-PHYRE `simulate` stage from its parameters.
pub(super) fn build(
    p: &IphyreSimParams,
    spec: &PipelineSpec,
) -> Result<IphyreSimulation, BuildError> {
    let fps = p.fps.unwrap_or(60.0);
    let params = PhysicsParams {
        engine: p.engine.unwrap_or_default(),
        ..PhysicsParams::with_fps(fps)
    };
    params
        .validate()
        .map_err(|e| BuildError::param("fps", e.to_string()))?;
    let all = Games::default_games().map_err(|e| BuildError::param("games", e.to_string()))?;
    let work = match replay_pair(("game", p.game.as_deref()), ("clicks", p.clicks.as_deref()))? {
        Some((name, text)) => {
            let game = all
                .get(name)
                .map_err(|e| BuildError::param("game", format!("`game`: {e}")))?;
            let clicks = parse_clicks(text, game, params.max_time)
                .map_err(|m| BuildError::param("clicks", format!("`clicks` {m}")))?;
            Work::Replay {
                game: Box::new(game.clone()),
                clicks,
            }
        }
        None => Work::Dataset {
            games: select_games(&all, p.games.as_deref().unwrap_or("all"))
                .map_err(|m| BuildError::param("games", format!("`games`: {m}")))?,
            samples: p.shards.shots,
            seed: p.shards.seed.unwrap_or(spec.seed),
        },
    };
    Ok(IphyreSimulation { params, work })
}

/// The games a `games` list names: `all`, game names and fold names (`basic`, `noisy`,
/// `compositional`, `multi_ball`), comma-separated; kept in I-PHYRE's game order, each once.
pub fn select_games(all: &Games, list: &str) -> Result<Vec<Game>, String> {
    let mut chosen = vec![false; all.all().len()];
    for item in list.split(',').map(str::trim) {
        if item.is_empty() {
            continue;
        }
        if item == "all" {
            chosen.iter_mut().for_each(|c| *c = true);
            continue;
        }
        let fold = all.fold(item);
        if !fold.is_empty() {
            for g in fold {
                chosen[g.index] = true;
            }
            continue;
        }
        let g = all.get(item).map_err(|e| format!("{item:?}: {e}"))?;
        chosen[g.index] = true;
    }
    let games: Vec<Game> = all
        .all()
        .iter()
        .filter(|g| chosen[g.index])
        .cloned()
        .collect();
    if games.is_empty() {
        return Err(format!("{list:?} selects no game"));
    }
    Ok(games)
}

/// Parses a click list: `;`-separated items, each `x,y,t` (pixels, seconds) or `k@t` (eliminable block
/// `k`, 0-based in object order, at `t` seconds, clicked at its centre). Every click is validated
/// against the 600×600 screen and the episode length `max_time`.
pub fn parse_clicks(text: &str, game: &Game, max_time: f64) -> Result<Vec<Click>, String> {
    let mut clicks = Vec::new();
    for (i, item) in text.split(';').map(str::trim).enumerate() {
        if item.is_empty() {
            continue;
        }
        let number = |s: &str, what: &str| -> Result<f64, String> {
            s.trim()
                .parse::<f64>()
                .map_err(|_| format!("item {} ({item:?}): {what} {s:?} is not a number", i + 1))
        };
        let click = if let Some((k, t)) = item.split_once('@') {
            let k: usize = k.trim().parse().map_err(|_| {
                format!(
                    "item {} ({item:?}): block {k:?} is not a block number (0, 1, …)",
                    i + 1
                )
            })?;
            let t = number(t, "time")?;
            click_block(game, k, t).map_err(|e| format!("item {} ({item:?}): {e}", i + 1))?
        } else {
            let parts: Vec<&str> = item.split(',').collect();
            let [x, y, t] = parts[..] else {
                return Err(format!(
                    "item {} ({item:?}) is neither `x,y,t` nor `k@t`",
                    i + 1
                ));
            };
            Click {
                x: number(x, "x")?,
                y: number(y, "y")?,
                t: number(t, "t")?,
            }
        };
        clicks.push(click);
    }
    validate_clicks(&clicks, max_time).map_err(|e| format!("{text:?}: {e}"))?;
    Ok(clicks)
}

impl IphyreSimulation {
    /// Number of traces.
    fn total(&self) -> u64 {
        match &self.work {
            Work::Dataset { games, samples, .. } => games.len() as u64 * samples,
            Work::Replay { .. } => 1,
        }
    }

    /// Work item `i` (game-major): the game, the sample number, the trace id and the clicks.
    fn item(&self, i: u64) -> (&Game, u64, String, Vec<Click>) {
        match &self.work {
            Work::Dataset {
                games,
                samples,
                seed,
            } => {
                let game = &games[(i / samples) as usize];
                let sample = i % samples;
                let clicks = random_clicks(game, &mut clicks_rng(*seed, game.index as u64, sample));
                let id = format!("iphyre-{seed}-{}-{sample:04}", game.name);
                (game, sample, id, clicks)
            }
            Work::Replay { game, clicks } => {
                let text: Vec<String> = clicks
                    .iter()
                    .map(|c| format!("{:?},{:?},{:?}", c.x, c.y, c.t))
                    .collect();
                let h = hex(&Sha256::digest(text.join(";").as_bytes()));
                let id = format!("iphyre-{}-{}", game.name, &h[..8]);
                (game, 0, id, clicks.clone())
            }
        }
    }
}

impl Simulation for IphyreSimulation {
    /// The resolved seed, the games and the engine: a changed pipeline seed reruns the stage.
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        let work = match &self.work {
            Work::Dataset {
                games,
                samples,
                seed,
            } => json!({
                "seed": seed,
                "samples": samples,
                "games": games.iter().map(|g| g.name.as_str()).collect::<Vec<_>>(),
            }),
            Work::Replay { game, clicks } => json!({
                "game": game.name,
                "clicks": clicks.iter().map(|c| [c.x, c.y, c.t]).collect::<Vec<_>>(),
            }),
        };
        let games_hash = hex(&Sha256::digest(
            crate::envs::iphyre::DEFAULT_GAMES_JSON.as_bytes(),
        ));
        let mut fp = json!({"env": "iphyre", "fps": self.params.fps, "games_data": &games_hash[..16], "work": work});
        // rapier2d, the engine of the runs made before the field existed, leaves the fingerprint as it
        // was (those runs stay valid for `engine = "rapier"`); every other engine, the default Chipmunk
        // step included, is in it, so no run reuses another engine's traces.
        if self.params.engine != Engine::Rapier {
            fp["engine"] = json!(self.params.engine.name());
        }
        Ok(fp)
    }

    fn env(&self) -> Env {
        Env::Iphyre
    }

    fn items(&self) -> u64 {
        self.total()
    }

    fn trace_ids(&self, i: u64) -> Vec<String> {
        vec![self.item(i).2]
    }

    fn simulate_item(&self, index: u64, source: &str) -> Result<ItemOutput, StageError> {
        let (game, sample, trace_id, clicks) = self.item(index);
        let scene_id = format!("iphyre-{}", game.name);
        let scene = if sample == 0 {
            let spec = json!({
                "game": game.name,
                "index": game.index,
                "fold": game.fold,
                "fps": self.params.fps,
                "engine": self.params.engine.name(),
                "objects": game.objects.len(),
                "eliminable": game.eliminable().count(),
                "joints": game.joints,
                "springs": game.springs,
            });
            Some(scene_batch(
                &scene_id,
                &game.name,
                source,
                game.objects.len(),
                &spec,
            )?)
        } else {
            None
        };
        let result = Episode::new(game, &clicks, &self.params, true)
            .map_err(|e| StageError::Simulation {
                item: format!("trace {trace_id}"),
                source: e.into(),
            })?
            .run();
        let trace = trace_columns(&result, game, &trace_id);
        Ok(ItemOutput {
            scene,
            scene_id,
            traces: vec![trace],
            counts: vec![
                ("successes", Count::Int(u64::from(result.success))),
                ("eliminations", Count::Int(result.eliminations as u64)),
                ("reward", Count::Float(result.reward)),
            ],
        })
    }

    fn report(&self, sums: &ShardTotals) -> (SimulateSummary, String) {
        let (traces, successes) = (sums.count("traces"), sums.count("successes"));
        let (eliminations, reward) = (sums.count("eliminations"), sums.sum("reward"));
        let frames = sums.rows.get("frames").copied().unwrap_or(0);
        let mean_reward = if traces > 0 {
            reward / traces as f64
        } else {
            0.0
        };
        let line = format!(
            "{traces} iphyre trace(s) at {} fps, {successes} successful, {eliminations} blocks removed, mean reward {mean_reward:.1}; {frames} frame rows",
            self.params.fps
        );
        let summary = SimulateSummary {
            env: Env::Iphyre,
            traces,
            successes,
            capped: Some(0),
            eliminations: Some(eliminations),
            mean_reward: Some(mean_reward),
            fps: Some(self.params.fps),
            ..SimulateSummary::default()
        };
        (summary, line)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn games_select_by_name_and_fold_in_game_order() {
        let all = Games::default_games().unwrap();
        let names = |l: &str| -> Vec<String> {
            select_games(&all, l)
                .unwrap()
                .into_iter()
                .map(|g| g.name)
                .collect()
        };
        assert_eq!(names("hole, support"), ["support", "hole"]);
        assert_eq!(names("all").len(), 40);
        assert_eq!(names("basic,support").len(), 10);
        assert_eq!(names("multi_ball").len(), 10);
        let err = select_games(&all, "suport").unwrap_err();
        assert!(err.contains("suport"), "{err}");
        assert!(select_games(&all, " , ").is_err());
    }

    #[test]
    fn click_lists_parse_both_forms_and_name_the_bad_item() {
        let all = Games::default_games().unwrap();
        let g = all.get("support").unwrap();
        let c = parse_clicks("250,400,0.5; 1@1.5", g, 15.0).unwrap();
        assert_eq!(
            c,
            [
                Click {
                    x: 250.0,
                    y: 400.0,
                    t: 0.5
                },
                Click {
                    x: 250.0,
                    y: 500.0,
                    t: 1.5
                }
            ]
        );
        for (bad, needle) in [
            ("250,400", "neither"),
            ("250,abc,1", "y \"abc\""),
            ("7@1", "block 7"),
            ("x@1", "block number"),
            ("250,400,16", "after the episode"),
            ("700,400,1", "off the"),
            ("250,400,NaN", "not finite"),
        ] {
            let err = parse_clicks(bad, g, 15.0).unwrap_err();
            assert!(err.contains(needle), "{bad}: {err}");
        }
        assert!(parse_clicks("", g, 15.0).unwrap().is_empty());
    }

    #[test]
    fn the_fingerprint_names_every_engine_but_rapier() {
        let all = Games::default_games().unwrap();
        let fingerprint = |engine: Option<Engine>| {
            let sim = IphyreSimulation {
                params: PhysicsParams {
                    engine: engine.unwrap_or_default(),
                    ..PhysicsParams::default()
                },
                work: Work::Replay {
                    game: Box::new(all.get("support").unwrap().clone()),
                    clicks: Vec::new(),
                },
            };
            sim.fingerprint_extra().unwrap()
        };
        // Runs made on rapier2d before the engine field existed keep their fingerprint...
        assert!(fingerprint(Some(Engine::Rapier)).get("engine").is_none());
        // ...and the default (the Chipmunk step) never reuses them.
        assert_eq!(fingerprint(None)["engine"], "chipmunk");
        assert_eq!(fingerprint(Some(Engine::Box2d))["engine"], "box2d");
        let (default, rapier) = (fingerprint(None), fingerprint(Some(Engine::Rapier)));
        assert_ne!(default, rapier);
    }
}
