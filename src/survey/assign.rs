//! Which items a participant sees, in which order, and in which condition: a seeded shuffle that the
//! survey page computes in JavaScript (`assets/survey.js`, `assignment`) and this module computes in
//! Rust, bit for bit the same, so `import-survey` can check every answer against it.
//!
//! The recipe (also in `docs/report.md`):
//! 1. the participant id is 1–64 characters of `A–Z a–z 0–9 _ . -` ([`valid_participant`]);
//! 2. its key is FNV-1a 64 over its bytes; the stream is `SplitMix64(splitmix64(seed) XOR key)`
//!    (`crate::rng`);
//! 3. the order is a Fisher–Yates shuffle of the items `0..n` drawing `below(i + 1)` for `i = n−1 … 1`;
//! 4. one more draw `offset = below(c)` picks the conditions: item `k` is shown in condition
//!    `(k + offset) mod c`, so every participant sees each condition on `n/c` items (±1) and, over
//!    participants, every item is shown in every condition equally often in expectation.
//!
//! `below(n)` is `rng::SplitMix64::below`: `floor(u · n)` with `u` the top 53 bits over 2⁵³.
//!
//! **Does not:** choose the items (the `survey` stage does) or store answers.

use crate::rng::{SplitMix64, splitmix64};

/// The longest participant id.
pub const MAX_PARTICIPANT: usize = 64;

/// Whether `id` is a usable participant id: 1–64 of `A–Z a–z 0–9 _ . -`.
pub fn valid_participant(id: &str) -> bool {
    !id.is_empty()
        && id.len() <= MAX_PARTICIPANT
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'.' || b == b'-')
}

/// FNV-1a, 64 bits, of `bytes`.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// One item as a participant sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shown {
    /// The item (its index in the survey).
    pub item: usize,
    /// The condition it is shown in (an index into the survey's conditions).
    pub condition: usize,
}

/// What participant `participant` sees of a survey of `items` items in `conditions` conditions with
/// `seed`, in the order shown (position 1 first).
pub fn assignment(seed: u64, participant: &str, items: usize, conditions: usize) -> Vec<Shown> {
    let mut rng = SplitMix64::new(splitmix64(seed) ^ fnv1a64(participant.as_bytes()));
    let mut order: Vec<usize> = (0..items).collect();
    for i in (1..items).rev() {
        let j = rng.below(i + 1);
        order.swap(i, j);
    }
    let offset = rng.below(conditions);
    order
        .into_iter()
        .map(|item| Shown {
            item,
            condition: (item + offset) % conditions.max(1),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_seed_and_participant_give_the_same_order_and_others_differ() {
        let a = assignment(7, "P001", 20, 3);
        assert_eq!(a, assignment(7, "P001", 20, 3));
        assert_ne!(a, assignment(7, "P002", 20, 3));
        assert_ne!(a, assignment(8, "P001", 20, 3));
        // A permutation of the items.
        let mut items: Vec<usize> = a.iter().map(|s| s.item).collect();
        items.sort();
        assert_eq!(items, (0..20).collect::<Vec<_>>());
    }

    #[test]
    fn conditions_are_balanced_within_and_across_participants() {
        for p in ["a", "b", "P17", "x.y-z"] {
            let a = assignment(3, p, 20, 3);
            for c in 0..3 {
                let n = a.iter().filter(|s| s.condition == c).count();
                assert!((6..=7).contains(&n), "{p}: condition {c} shown {n} times");
            }
        }
        // Over 300 participants each item is shown in each condition about 100 times.
        let mut counts = [[0u32; 3]; 10];
        for k in 0..300 {
            for s in assignment(11, &format!("P{k:03}"), 10, 3) {
                counts[s.item][s.condition] += 1;
            }
        }
        for row in counts {
            for n in row {
                assert!((60..=140).contains(&n), "{counts:?}");
            }
        }
    }

    /// Pinned values: the page's JavaScript computes the same (the browser test checks it too), so a
    /// change here breaks every running study.
    #[test]
    fn the_recipe_is_pinned() {
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
        let a: Vec<(usize, usize)> = assignment(7, "P001", 5, 2)
            .into_iter()
            .map(|s| (s.item, s.condition))
            .collect();
        assert_eq!(a, PINNED);
    }
    /// Also computed by an independent Python transcription of the recipe.
    const PINNED: [(usize, usize); 5] = [(4, 1), (3, 0), (1, 0), (2, 1), (0, 1)];

    #[test]
    fn participant_ids_are_checked() {
        assert!(valid_participant("P001"));
        assert!(valid_participant("anna.b-2_x"));
        assert!(!valid_participant(""));
        assert!(!valid_participant("a b"));
        assert!(!valid_participant("a,b"));
        assert!(!valid_participant(&"x".repeat(65)));
    }
}
