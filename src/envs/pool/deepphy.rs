//! DeepPHY's PoolTool action format as an adapter (`docs/envs/pool.md` "DeepPHY action adapter"): a discrete
//! speed and strike spot, with φ aimed automatically at the lowest-numbered ball on the table.
//!
//! The answer text `Speed: High, Strikespot: Top Left Spin` maps to V0 ∈ {2, 5, 8} m/s and a cue-tip
//! offset (a, b) with a ∈ {+0.35 (left), 0, −0.35 (right)} and b ∈ {+0.5 (top), 0, −0.5 (bottom)}
//! (pooltool's sign convention: +a is left English, +b is top spin); θ = 0.

use serde::{Deserialize, Serialize};

use super::aim;
use super::error::{PoolError, Result};
use super::scene::Scene;
use super::shot::Shot;

/// DeepPHY's speed levels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Speed {
    /// V0 = 2 m/s.
    Low,
    /// V0 = 5 m/s.
    Medium,
    /// V0 = 8 m/s.
    High,
}

/// Vertical strike spot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Height {
    /// b = +0.5 (follow).
    Top,
    /// b = 0.
    Middle,
    /// b = −0.5 (draw).
    Bottom,
}

/// Side spin.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// a = +0.35.
    Left,
    /// a = 0.
    Center,
    /// a = −0.35.
    Right,
}

/// One DeepPHY action.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct DeepphyAction {
    /// Cue speed level.
    pub speed: Speed,
    /// Vertical strike spot.
    pub height: Height,
    /// Side spin.
    pub side: Side,
}

impl DeepphyAction {
    /// Every action of the discrete space (3 × 3 × 3 = 27), in a fixed order.
    pub fn all() -> Vec<DeepphyAction> {
        let mut out = Vec::with_capacity(27);
        for speed in [Speed::Low, Speed::Medium, Speed::High] {
            for height in [Height::Top, Height::Middle, Height::Bottom] {
                for side in [Side::Left, Side::Center, Side::Right] {
                    out.push(DeepphyAction {
                        speed,
                        height,
                        side,
                    });
                }
            }
        }
        out
    }

    /// Parses DeepPHY's answer format, `Speed: {Low|Medium|High}, Strikespot: {Top|Middle|Bottom}
    /// {Left |""|Right }Spin` (case-insensitive; extra text around it is ignored).
    pub fn parse(text: &str) -> Result<DeepphyAction> {
        let lower = text.to_ascii_lowercase();
        let bad = |what: &str| {
            PoolError::InvalidShot(format!(
                "DeepPHY action {text:?}: {what} (expected e.g. \"Speed: High, Strikespot: Top Left Spin\")"
            ))
        };
        let after = |key: &str| -> Option<String> {
            let i = lower.find(key)? + key.len();
            let rest = lower[i..].trim_start_matches([':', ' ', '\t']);
            Some(
                rest.split([',', '\n', '.'])
                    .next()
                    .unwrap_or("")
                    .trim()
                    .to_string(),
            )
        };
        let speed = match after("speed")
            .as_deref()
            .map(|s| s.split_whitespace().next().unwrap_or(""))
        {
            Some("low") => Speed::Low,
            Some("medium") => Speed::Medium,
            Some("high") => Speed::High,
            _ => return Err(bad("no speed Low, Medium or High")),
        };
        let spot = after("strikespot").ok_or_else(|| bad("no Strikespot"))?;
        let words: Vec<&str> = spot.split_whitespace().collect();
        let height = match words.first().copied() {
            Some("top") => Height::Top,
            Some("middle") => Height::Middle,
            Some("bottom") => Height::Bottom,
            _ => return Err(bad("strike spot must start with Top, Middle or Bottom")),
        };
        let side = match words.get(1).copied() {
            Some("left") => Side::Left,
            Some("right") => Side::Right,
            Some("spin") | None => Side::Center,
            Some(_) => return Err(bad("side must be Left, Right or nothing")),
        };
        Ok(DeepphyAction {
            speed,
            height,
            side,
        })
    }

    /// The action in DeepPHY's text form.
    pub fn text(&self) -> String {
        let speed = match self.speed {
            Speed::Low => "Low",
            Speed::Medium => "Medium",
            Speed::High => "High",
        };
        let height = match self.height {
            Height::Top => "Top",
            Height::Middle => "Middle",
            Height::Bottom => "Bottom",
        };
        let side = match self.side {
            Side::Left => "Left ",
            Side::Center => "",
            Side::Right => "Right ",
        };
        format!("Speed: {speed}, Strikespot: {height} {side}Spin")
    }

    /// The shot on `scene`: φ at the lowest-numbered object ball (`pt.aim.at_ball`), θ = 0.
    pub fn to_shot(&self, scene: &Scene) -> Result<Shot> {
        let target = aim::lowest_numbered_ball(scene).ok_or_else(|| {
            PoolError::InvalidShot("DeepPHY aim: no numbered object ball on the table".into())
        })?;
        let v0 = match self.speed {
            Speed::Low => 2.0,
            Speed::Medium => 5.0,
            Speed::High => 8.0,
        };
        let b = match self.height {
            Height::Top => 0.5,
            Height::Middle => 0.0,
            Height::Bottom => -0.5,
        };
        let a = match self.side {
            Side::Left => 0.35,
            Side::Center => 0.0,
            Side::Right => -0.35,
        };
        Ok(Shot {
            v0,
            phi: aim::at_ball(scene, target)?,
            theta: 0.0,
            a,
            b,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::pool::PoolConfig;

    #[test]
    fn parses_and_prints_every_action() {
        for a in DeepphyAction::all() {
            assert_eq!(DeepphyAction::parse(&a.text()).unwrap(), a, "{}", a.text());
            assert!(
                a.to_shot(&Scene::nine_ball(&PoolConfig::default_7ft(), 1))
                    .unwrap()
                    .validate()
                    .is_ok()
            );
        }
        let a = DeepphyAction::parse("I think... Speed: medium, Strikespot: Bottom Right Spin.")
            .unwrap();
        assert_eq!(
            (a.speed, a.height, a.side),
            (Speed::Medium, Height::Bottom, Side::Right)
        );
        assert!(DeepphyAction::parse("Speed: fast").is_err());
        assert!(DeepphyAction::parse("Speed: Low, Strikespot: Sideways").is_err());
    }

    #[test]
    fn aims_at_the_one_ball_of_a_rack() {
        let c = PoolConfig::default_7ft();
        let s = Scene::nine_ball(&c, 4);
        let shot = DeepphyAction::parse("Speed: High, Strikespot: Top Spin")
            .unwrap()
            .to_shot(&s)
            .unwrap();
        assert_eq!(shot.phi, aim::at_ball(&s, "1").unwrap());
        assert_eq!((shot.v0, shot.a, shot.b), (8.0, 0.0, 0.5));
    }
}
