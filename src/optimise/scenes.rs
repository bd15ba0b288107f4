//! Held-out billiards scenes for the optimisation experiment: seeded 9-ball racks, or the nine balls
//! and the cue ball scattered over the table (the default: from a tight rack, most goals' "the cue
//! ball first hits ball k" cannot happen, since k is buried in the cluster).

use super::OptimiseError;
use crate::envs::Environment;
use crate::envs::pool::rack::scene_seed;
use crate::envs::pool::{Goal, PoolEnv, Scene, SceneBall};
use crate::rng::SplitMix64;

/// How the balls of a scene are laid out.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Layout {
    /// A 9-ball rack with the cue ball behind the head string (`PoolEnv::scenes`).
    Rack,
    /// Cue ball and balls 1–9 at uniform random spots, at least one ball diameter apart (gap ≥ R
    /// between surfaces), at least two radii from the cushions and 12 cm from every pocket centre.
    Scatter,
}

impl std::str::FromStr for Layout {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "rack" => Ok(Layout::Rack),
            "scatter" => Ok(Layout::Scatter),
            _ => Err(format!("layout is \"rack\" or \"scatter\", found {s:?}")),
        }
    }
}

/// `n` scenes of `layout`; scene `i` depends only on (`seed`, `i`).
pub fn scenes(
    env: &PoolEnv,
    layout: Layout,
    n: usize,
    seed: u64,
) -> Result<Vec<Scene>, OptimiseError> {
    match layout {
        Layout::Rack => Ok(env.scenes(n, seed)?),
        Layout::Scatter => (0..n).map(|i| scatter(env, seed, i)).collect(),
    }
}

fn scatter(env: &PoolEnv, seed: u64, i: usize) -> Result<Scene, OptimiseError> {
    let r = env.config.ball.r;
    let t = &env.config.table;
    let mut rng = SplitMix64::new(scene_seed(seed ^ 0x5CA7_7E12, i as u64));
    let ids = ["cue", "1", "2", "3", "4", "5", "6", "7", "8", "9"];
    let mut balls: Vec<SceneBall> = Vec::new();
    for id in ids {
        let mut placed = false;
        for _ in 0..10_000 {
            let (x, y) = (
                rng.uniform(2.0 * r, t.w - 2.0 * r),
                rng.uniform(2.0 * r, t.l - 2.0 * r),
            );
            let free = balls.iter().all(|b| (b.x - x).hypot(b.y - y) >= 3.0 * r)
                && t.pockets
                    .iter()
                    .all(|p| (p.center[0] - x).hypot(p.center[1] - y) >= 0.12);
            if free {
                balls.push(SceneBall {
                    id: id.into(),
                    x,
                    y,
                });
                placed = true;
                break;
            }
        }
        if !placed {
            return Err(OptimiseError::Scatter { index: i, ball: id });
        }
    }
    let scene = Scene {
        scene_id: format!("scatter-{seed}-{i:06}"),
        balls,
        cue_ball: "cue".into(),
        goal: Goal::pot_nine(),
        seed: Some(seed),
    };
    scene
        .validate(&env.config)
        .map_err(crate::envs::EnvError::from)?;
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scattered_scenes_are_valid_seeded_and_spread_out() {
        let env = PoolEnv::default();
        let a = scenes(&env, Layout::Scatter, 20, 4).unwrap();
        assert_eq!(a, scenes(&env, Layout::Scatter, 20, 4).unwrap());
        assert_ne!(a[0], scenes(&env, Layout::Scatter, 1, 5).unwrap()[0]);
        for s in &a {
            assert_eq!(s.balls.len(), 10);
            let ys: Vec<f64> = s.balls.iter().map(|b| b.y).collect();
            let spread = ys.iter().cloned().fold(f64::MIN, f64::max)
                - ys.iter().cloned().fold(f64::MAX, f64::min);
            assert!(spread > 0.5, "balls spread along the table");
        }
        assert_eq!(scenes(&env, Layout::Rack, 2, 4).unwrap().len(), 2);
    }
}
