//! Success and reward (docs/envs/iphyre.md §R4): an episode succeeds when every ball's centre is below the
//! bottom edge (y > 600, y down) within the episode; the reward is −1/fps per step, −10 per effective
//! elimination and +1000 on success.

use super::action::SCREEN;
use super::world::World;

/// Reward for a solved game.
pub const SUCCESS_REWARD: f64 = 1000.0;
/// Penalty for each click that removed a block.
pub const ELIMINATION_PENALTY: f64 = 10.0;

/// Whether a ball centre at height `y` (px, y down) has fallen out of the screen ("into the abyss").
pub fn ball_out(y: f64) -> bool {
    y > SCREEN
}

/// Whether every ball of the world has fallen out (false for a world without balls).
pub fn all_balls_out(world: &World) -> bool {
    let mut any = false;
    for o in world
        .objects()
        .iter()
        .filter(|o| o.kind == super::game::ObjectKind::Ball)
    {
        any = true;
        match world.centre(o.index) {
            Some(c) if ball_out(c[1]) => {}
            _ => return false,
        }
    }
    any
}

/// The episode reward: `−steps/fps − 10·eliminations (+ 1000 on success)`.
pub fn reward(steps: usize, fps: f64, eliminations: usize, success: bool) -> f64 {
    let bonus = if success { SUCCESS_REWARD } else { 0.0 };
    bonus - steps as f64 / fps - ELIMINATION_PENALTY * eliminations as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reward_arithmetic_matches_the_reference_examples() {
        // One elimination, success at 8.5 s at 60 fps: 1000 − 8.5 − 10 = 981.5 (docs/envs/iphyre.md §R4).
        assert!((reward(510, 60.0, 1, true) - 981.5).abs() < 1e-9);
        // A failure with 3 eliminations over the full 15 s: −15 − 30 = −45.
        assert!((reward(900, 60.0, 3, false) + 45.0).abs() < 1e-9);
        // The exported support trace: 2 eliminations, success after 509 steps (8.48 s) → 971.5.
        assert!((reward(509, 60.0, 2, true) - 971.5167).abs() < 1e-3);
        // At 10 fps a step costs 0.1.
        assert!((reward(10, 10.0, 0, false) + 1.0).abs() < 1e-12);
    }

    #[test]
    fn out_means_strictly_below_the_bottom_edge() {
        assert!(!ball_out(600.0));
        assert!(ball_out(600.01));
    }
}
