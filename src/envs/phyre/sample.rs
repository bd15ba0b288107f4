//! Seeded random actions for datasets: uniform draws from [0, 1]³ until one is valid for the task, as
//! PHYRE's `ActionSimulator.sample()` does (about a quarter of draws overlap a body). The RNG is the
//! crate's [`SplitMix64`] ([`keyed_stream`]), seeded from (`seed`, task, sample number) alone, so a
//! dataset does not depend on sharding or thread count.

use super::action::{BallAction, Placement};
use super::error::Result;
use super::task::Task;
use crate::rng::{SplitMix64, keyed_stream};

/// Draws tried before giving up on a task whose free space is tiny.
pub const MAX_DRAWS: usize = 10_000;

/// The RNG of sample `sample` on the task at sorted position `task_index`, for dataset seed `seed`.
pub fn action_rng(seed: u64, task_index: u64, sample: u64) -> SplitMix64 {
    keyed_stream(seed ^ 0x5048_5952_4500_0000, task_index, sample)
}

/// A uniformly drawn action whose ball fits in `task` (or `None` after [`MAX_DRAWS`] invalid draws).
pub fn random_valid_action(task: &Task, rng: &mut SplitMix64) -> Result<Option<BallAction>> {
    for _ in 0..MAX_DRAWS {
        let a = BallAction {
            x: rng.next_f64(),
            y: rng.next_f64(),
            r: rng.next_f64(),
        };
        if let Placement::Valid(_) = a.place(task)? {
            return Ok(Some(a));
        }
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::phyre::tasks::TaskSet;

    #[test]
    fn random_actions_are_seeded_and_valid() {
        let set = TaskSet::default_tasks().unwrap();
        for (i, id) in ["00000:000", "00013:050", "00021:099"].iter().enumerate() {
            let task = set.get(id).unwrap();
            let a = random_valid_action(&task, &mut action_rng(3, i as u64, 0))
                .unwrap()
                .unwrap();
            let b = random_valid_action(&task, &mut action_rng(3, i as u64, 0))
                .unwrap()
                .unwrap();
            assert_eq!(a, b);
            assert!(a.place(&task).unwrap().ball().is_some());
            let c = random_valid_action(&task, &mut action_rng(3, i as u64, 1))
                .unwrap()
                .unwrap();
            assert_ne!(a, c);
        }
    }
}
