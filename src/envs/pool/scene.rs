//! Scenes: where the balls are before the shot, which ball the cue strikes and what counts as success.
//!
//! A scene comes from a seeded 9-ball rack ([`Scene::nine_ball`]) or from JSON
//! ([`Scene::from_json_str`]):
//!
//! ```json
//! {"scene_id": "corner-cut", "cue_ball": "cue", "goal": {"pot": "9", "pocket": "rt"},
//!  "balls": [{"id": "cue", "x": 0.5, "y": 0.4}, {"id": "9", "x": 0.8, "y": 1.7}]}
//! ```
//!
//! Positions are ball centres in metres in the table frame (x across, y along, origin at the bottom-left
//! corner of the playing area). Only `balls` is required; `cue_ball` defaults to `"cue"`, `goal` to
//! potting the 9-ball (or any object ball when there is no 9-ball), `scene_id` to `"scene"`. Every ball
//! must lie inside the cushions and no two may overlap; errors name the field at fault.

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::config::PoolConfig;
use super::error::{PoolError, Result};
use super::rack;
use super::state::{Ball, BallState};
use super::system::System;

/// One ball of a scene, at rest on the cloth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneBall {
    /// Ball id: `"cue"`, `"1"` … `"15"` (any non-empty string is accepted).
    pub id: String,
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
}

/// The success rule of a scene: pot a ball, optionally in a given pocket.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Goal {
    /// The ball to pot, or `"any"` for any object ball (not the cue ball).
    pub pot: String,
    /// The pocket it must drop into (`lb`, `lc`, `lt`, `rb`, `rc`, `rt`); any pocket when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pocket: Option<String>,
}

impl Goal {
    /// The 9-ball task's rule (DeepPHY): the 9-ball is pocketed, in any pocket.
    pub fn pot_nine() -> Goal {
        Goal {
            pot: "9".into(),
            pocket: None,
        }
    }
}

/// An initial condition: ball positions, the struck ball and the goal.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Scene id (unique within a run).
    pub scene_id: String,
    /// The balls, in order (the order only matters for exactly simultaneous events).
    pub balls: Vec<SceneBall>,
    /// Id of the ball the cue strikes.
    pub cue_ball: String,
    /// The success rule.
    pub goal: Goal,
    /// The seed of a generated rack, if the scene is one.
    pub seed: Option<u64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneJson {
    #[serde(default)]
    scene_id: Option<String>,
    #[serde(default)]
    cue_ball: Option<String>,
    #[serde(default)]
    goal: Option<Goal>,
    #[serde(default)]
    seed: Option<u64>,
    balls: Vec<SceneBall>,
}

fn invalid(field: impl Into<String>, message: impl Into<String>) -> PoolError {
    PoolError::InvalidScene {
        field: field.into(),
        message: message.into(),
    }
}

impl Scene {
    /// A seeded 9-ball rack on `config`'s table: the 1-ball at the apex, the 9-ball in the middle, the
    /// others shuffled, the cue ball behind the head string; the goal is potting the 9-ball.
    pub fn nine_ball(config: &PoolConfig, seed: u64) -> Scene {
        let balls = rack::nine_ball_positions(&config.table, config.ball.r, seed)
            .into_iter()
            .map(|(id, x, y)| SceneBall { id, x, y })
            .collect();
        Scene {
            scene_id: format!("nine_ball-{seed}"),
            balls,
            cue_ball: "cue".into(),
            goal: Goal::pot_nine(),
            seed: Some(seed),
        }
    }

    /// A scene from JSON text, validated against `config`'s table.
    pub fn from_json_str(text: &str, config: &PoolConfig) -> Result<Scene> {
        let raw: SceneJson = serde_json::from_str(text)?;
        let has_nine = raw.balls.iter().any(|b| b.id == "9");
        let scene = Scene {
            scene_id: raw.scene_id.unwrap_or_else(|| "scene".into()),
            cue_ball: raw.cue_ball.unwrap_or_else(|| "cue".into()),
            goal: raw.goal.unwrap_or(Goal {
                pot: if has_nine { "9".into() } else { "any".into() },
                pocket: None,
            }),
            seed: raw.seed,
            balls: raw.balls,
        };
        scene.validate(config)?;
        Ok(scene)
    }

    /// Checks ids, positions (finite, inside the cushions, not overlapping), the cue ball and the goal.
    pub fn validate(&self, config: &PoolConfig) -> Result<()> {
        let r = config.ball.r;
        let (w, l) = (config.table.w, config.table.l);
        if self.balls.is_empty() {
            return Err(invalid("balls", "a scene needs at least one ball"));
        }
        // A ball touching a cushion line exactly is allowed; rounding in JSON may put it a hair inside.
        let tol = 1e-9;
        for (i, b) in self.balls.iter().enumerate() {
            if b.id.is_empty() {
                return Err(invalid(format!("balls[{i}].id"), "empty ball id"));
            }
            if let Some(j) = self.balls[..i].iter().position(|o| o.id == b.id) {
                return Err(invalid(
                    format!("balls[{i}].id"),
                    format!("ball id {:?} is used twice (first at balls[{j}])", b.id),
                ));
            }
            for (name, v, lo, hi) in [("x", b.x, r, w - r), ("y", b.y, r, l - r)] {
                if !v.is_finite() {
                    return Err(invalid(
                        format!("balls[{i}].{name}"),
                        format!("ball {:?}: {name} is not a finite number", b.id),
                    ));
                }
                if v < lo - tol || v > hi + tol {
                    return Err(invalid(
                        format!("balls[{i}].{name}"),
                        format!(
                            "ball {:?} is off the table: {name} = {v} m, but centres must lie in [{lo:.6}, {hi:.6}] m (table {w} × {l} m, ball radius {r} m)",
                            b.id
                        ),
                    ));
                }
            }
            for (j, o) in self.balls[..i].iter().enumerate() {
                let d = ((b.x - o.x).powi(2) + (b.y - o.y).powi(2)).sqrt();
                if d < 2.0 * r - tol {
                    return Err(invalid(
                        format!("balls[{i}]"),
                        format!(
                            "ball {:?} overlaps ball {:?} (balls[{j}]): centres {d:.6} m apart, less than 2R = {:.6} m",
                            b.id,
                            o.id,
                            2.0 * r
                        ),
                    ));
                }
            }
        }
        if !self.balls.iter().any(|b| b.id == self.cue_ball) {
            return Err(invalid(
                "cue_ball",
                format!("no ball has id {:?}", self.cue_ball),
            ));
        }
        if self.goal.pot != "any" && !self.balls.iter().any(|b| b.id == self.goal.pot) {
            return Err(invalid(
                "goal.pot",
                format!(
                    "no ball has id {:?} (use \"any\" for any object ball)",
                    self.goal.pot
                ),
            ));
        }
        if let Some(p) = &self.goal.pocket
            && !config.table.pockets.iter().any(|k| &k.id == p)
        {
            let known: Vec<&str> = config.table.pockets.iter().map(|k| k.id.as_str()).collect();
            return Err(invalid(
                "goal.pocket",
                format!("no pocket {p:?} (pockets: {})", known.join(", ")),
            ));
        }
        Ok(())
    }

    /// The system to simulate: every ball at rest at its position, with `config`'s parameters.
    pub fn system(&self, config: &PoolConfig) -> Result<System> {
        self.validate(config)?;
        let p = config.ball;
        let balls = self
            .balls
            .iter()
            .map(|b| Ball {
                id: b.id.clone(),
                params: p,
                state: BallState::at_rest(b.x, b.y, p.r),
            })
            .collect();
        let mut sys = System::new(config.table.clone(), balls, config.cue);
        sys.cue_ball_id = self.cue_ball.clone();
        Ok(sys)
    }

    /// The scene as JSON (the format [`Scene::from_json_str`] reads), as stored in the `scenes` table.
    pub fn to_json(&self) -> Value {
        let mut v = json!({
            "scene_id": self.scene_id,
            "cue_ball": self.cue_ball,
            "goal": self.goal,
            "balls": self.balls,
        });
        if let Some(seed) = self.seed {
            v["seed"] = json!(seed);
        }
        v
    }

    /// The position of ball `id`.
    pub fn ball(&self, id: &str) -> Option<&SceneBall> {
        self.balls.iter().find(|b| b.id == id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> PoolConfig {
        PoolConfig::default_7ft()
    }

    #[test]
    fn rack_round_trips_through_json() {
        let c = config();
        let s = Scene::nine_ball(&c, 3);
        assert_eq!(s.balls.len(), 10);
        let back = Scene::from_json_str(&s.to_json().to_string(), &c).unwrap();
        assert_eq!(back, s);
    }

    #[test]
    fn bad_scenes_name_the_field() {
        let c = config();
        let err = |t: &str| Scene::from_json_str(t, &c).unwrap_err().to_string();
        let off = err(r#"{"balls":[{"id":"cue","x":1.5,"y":0.5}]}"#);
        assert!(
            off.contains("balls[0].x") && off.contains("off the table"),
            "{off}"
        );
        let overlap =
            err(r#"{"balls":[{"id":"cue","x":0.5,"y":0.5},{"id":"1","x":0.51,"y":0.5}]}"#);
        assert!(
            overlap.contains("balls[1]") && overlap.contains("overlaps"),
            "{overlap}"
        );
        let no_cue = err(r#"{"balls":[{"id":"1","x":0.5,"y":0.5}]}"#);
        assert!(no_cue.contains("cue_ball"), "{no_cue}");
        let unknown = err(r#"{"balls":[],"colour":1}"#);
        assert!(unknown.contains("unknown field `colour`"), "{unknown}");
        let pocket = err(
            r#"{"goal":{"pot":"1","pocket":"zz"},"balls":[{"id":"cue","x":0.5,"y":0.5},{"id":"1","x":0.5,"y":1.0}]}"#,
        );
        assert!(pocket.contains("goal.pocket"), "{pocket}");
        assert!(err("not json").contains("json"));
    }

    #[test]
    fn goal_defaults_to_the_nine_ball_or_any() {
        let c = config();
        let s = Scene::from_json_str(
            r#"{"balls":[{"id":"cue","x":0.5,"y":0.5},{"id":"9","x":0.5,"y":1.0}]}"#,
            &c,
        )
        .unwrap();
        assert_eq!(s.goal, Goal::pot_nine());
        let s = Scene::from_json_str(
            r#"{"balls":[{"id":"cue","x":0.5,"y":0.5},{"id":"3","x":0.5,"y":1.0}]}"#,
            &c,
        )
        .unwrap();
        assert_eq!(s.goal.pot, "any");
    }
}
