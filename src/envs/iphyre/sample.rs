//! Seeded random click sets for datasets, in the style of iphyre's `utils.generate_actions` (docs/envs/iphyre.md
//! §R6): every eliminable block is clicked at its centre at a time drawn from {0.1, 0.2, …, 6.9} s, and
//! skipped with probability 0.2. The RNG is the crate's [`SplitMix64`] ([`keyed_stream`]), seeded from
//! (`seed`, game index, sample number) alone, so a dataset does not depend on sharding or thread count.

use super::action::Click;
use super::game::Game;
use crate::rng::{SplitMix64, keyed_stream};

/// Probability that a block is left alone in a random click set.
pub const SKIP_PROBABILITY: f64 = 0.2;

/// Click times are multiples of 0.1 s from 0.1 to this many tenths (6.9 s).
pub const MAX_TENTHS: u64 = 69;

/// The RNG of click set `sample` on game `game_index` of a dataset seeded with `seed`.
pub fn clicks_rng(seed: u64, game_index: u64, sample: u64) -> SplitMix64 {
    keyed_stream(seed ^ 0x1F4E_7A3D_0000_0000, game_index, sample)
}

/// A random click set for `game`, sorted by time; always valid for a 15 s episode (may be empty).
pub fn random_clicks(game: &Game, rng: &mut SplitMix64) -> Vec<Click> {
    let mut clicks = Vec::new();
    for block in game.eliminable() {
        let skip = rng.next_f64() < SKIP_PROBABILITY;
        let tenths = 1 + rng.below(MAX_TENTHS as usize) as u64;
        if skip {
            continue;
        }
        let [x, y] = block.centre();
        clicks.push(Click {
            x,
            y,
            t: tenths as f64 / 10.0,
        });
    }
    clicks.sort_by(|a, b| a.t.total_cmp(&b.t));
    clicks
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::iphyre::action::validate_clicks;
    use crate::envs::iphyre::game::Games;

    #[test]
    fn random_clicks_are_seeded_valid_and_on_block_centres() {
        let games = Games::default_games().unwrap();
        let mut total = (0, 0);
        for g in games.all() {
            let a = random_clicks(g, &mut clicks_rng(7, g.index as u64, 0));
            let b = random_clicks(g, &mut clicks_rng(7, g.index as u64, 0));
            assert_eq!(a, b, "{}: not deterministic", g.name);
            validate_clicks(&a, 15.0).unwrap();
            for c in &a {
                assert!(
                    (0.1..=6.9 + 1e-12).contains(&c.t),
                    "{}: t = {}",
                    g.name,
                    c.t
                );
                assert!(
                    g.eliminable().any(|o| o.centre() == [c.x, c.y]),
                    "{}: {c:?}",
                    g.name
                );
            }
            assert!(a.windows(2).all(|w| w[0].t <= w[1].t));
            total.0 += a.len();
            total.1 += g.eliminable().count();
        }
        // About 80% of the blocks get a click (binomial over ~150 blocks; a wide band).
        let share = total.0 as f64 / total.1 as f64;
        assert!((0.6..0.95).contains(&share), "share clicked {share}");
        let other = random_clicks(&games.all()[0], &mut clicks_rng(8, 0, 0));
        let again = random_clicks(&games.all()[0], &mut clicks_rng(7, 0, 1));
        let first = random_clicks(&games.all()[0], &mut clicks_rng(7, 0, 0));
        assert!(
            other != first || again != first,
            "seed and sample number must change the draw"
        );
    }
}
