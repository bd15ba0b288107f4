//! Aiming helpers (pooltool `aim.at_pos`, `aim.at_ball`) and the ghost-ball aim for a pocket.
//!
//! Angles are the shot's φ in degrees, counter-clockwise from +x, in [0, 360).

use super::config::PoolConfig;
use super::error::{PoolError, Result};
use super::scene::{Scene, SceneBall};

/// φ (degrees, in [0, 360)) of the direction from `from` to `to` (planar positions, m).
pub fn at_pos(from: (f64, f64), to: (f64, f64)) -> f64 {
    (to.1 - from.1)
        .atan2(to.0 - from.0)
        .to_degrees()
        .rem_euclid(360.0)
}

fn ball<'a>(scene: &'a Scene, id: &str) -> Result<&'a SceneBall> {
    scene
        .ball(id)
        .ok_or_else(|| PoolError::UnknownBall(id.to_string()))
}

/// φ aiming the cue ball straight at the centre of ball `target` (a full-ball hit).
pub fn at_ball(scene: &Scene, target: &str) -> Result<f64> {
    let c = ball(scene, &scene.cue_ball)?;
    let t = ball(scene, target)?;
    Ok(at_pos((c.x, c.y), (t.x, t.y)))
}

/// φ aiming the cue ball at the ghost ball that sends `target` towards the centre of `pocket`: the
/// point 2R behind the target on the pocket–target line. Straight-line geometry only (no throw).
pub fn ghost_ball(scene: &Scene, config: &PoolConfig, target: &str, pocket: &str) -> Result<f64> {
    let c = ball(scene, &scene.cue_ball)?;
    let t = ball(scene, target)?;
    let p = config
        .table
        .pockets
        .iter()
        .find(|p| p.id == pocket)
        .ok_or_else(|| PoolError::InvalidShot(format!("no pocket {pocket:?} on the table")))?;
    let (dx, dy) = (p.center[0] - t.x, p.center[1] - t.y);
    let d = (dx * dx + dy * dy).sqrt();
    if d == 0.0 {
        return at_ball(scene, target);
    }
    let two_r = 2.0 * config.ball.r;
    let ghost = (t.x - two_r * dx / d, t.y - two_r * dy / d);
    Ok(at_pos((c.x, c.y), ghost))
}

/// The object ball with the lowest number (ids that parse as integers; the cue ball excluded).
pub fn lowest_numbered_ball(scene: &Scene) -> Option<&str> {
    scene
        .balls
        .iter()
        .filter(|b| b.id != scene.cue_ball)
        .filter_map(|b| b.id.parse::<u32>().ok().map(|n| (n, b.id.as_str())))
        .min()
        .map(|(_, id)| id)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> Scene {
        Scene::from_json_str(
            r#"{"balls":[{"id":"cue","x":0.5,"y":0.5},{"id":"3","x":0.5,"y":1.0},{"id":"2","x":0.8,"y":0.8}]}"#,
            &PoolConfig::default_7ft(),
        )
        .unwrap()
    }

    #[test]
    fn straight_up_is_ninety_degrees() {
        assert!((at_ball(&scene(), "3").unwrap() - 90.0).abs() < 1e-12);
        assert!((at_pos((0.0, 0.0), (0.0, -1.0)) - 270.0).abs() < 1e-12);
        assert!(at_ball(&scene(), "7").is_err());
    }

    #[test]
    fn ghost_ball_sits_two_radii_behind_the_target() {
        let c = PoolConfig::default_7ft();
        let s = scene();
        // target "3" at (0.5, 1.0) into the left-centre pocket at (-0.0685, 0.9906): the ghost is to
        // the right of the target, so the cue (below it) aims slightly right of straight up.
        let phi = ghost_ball(&s, &c, "3", "lc").unwrap();
        assert!(phi < 90.0 && phi > 80.0, "{phi}");
        assert!(ghost_ball(&s, &c, "3", "nowhere").is_err());
        assert_eq!(lowest_numbered_ball(&s), Some("2"));
    }
}
