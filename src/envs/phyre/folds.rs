//! PHYRE's evaluation folds for the ball tier (`phyre.get_fold`, docs/envs/phyre.md §R6), reproduced exactly:
//! the same task ids in train, dev and test for every seed, as PHYRE 0.2.2 computes them.
//!
//! PHYRE orders ids with `stable_shuffle`: sort by the MD5 hex digest of `id + salt`. **Within-template**
//! (seed s): each template's tasks are shuffled with salt `ball_online_ind_tasks{s}`, the first 80 % go to
//! train and the rest to test; dev is split off the train ids (salt `make_dev{s}`, 80 % stay). **Cross-
//! template**: the templates are shuffled with salt `ball_cross_template_half_{s}`, the first 20 of 25
//! templates train and the last 5 test; dev takes 4 of the 20 train templates (salt
//! `dev_ball_cross_template_half_{s}`). PHYRE reports the mean over seeds 0–9; any seed works here.

use std::str::FromStr;

use md5::{Digest, Md5};

use super::error::PhyreError;
use super::tasks::TaskSet;

/// PHYRE's train share.
const TRAIN_SHARE: f64 = 0.8;

/// A ball-tier evaluation setup.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EvalSetup {
    /// `ball_within_template`: every template in train and test, different tasks.
    WithinTemplate,
    /// `ball_cross_template`: test templates never seen in training.
    CrossTemplate,
}

impl EvalSetup {
    /// Both setups.
    pub const ALL: [EvalSetup; 2] = [EvalSetup::WithinTemplate, EvalSetup::CrossTemplate];

    /// PHYRE's name.
    pub fn name(self) -> &'static str {
        match self {
            EvalSetup::WithinTemplate => "ball_within_template",
            EvalSetup::CrossTemplate => "ball_cross_template",
        }
    }
}

impl FromStr for EvalSetup {
    type Err = PhyreError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        EvalSetup::ALL
            .into_iter()
            .find(|e| e.name() == s)
            .ok_or_else(|| PhyreError::UnknownFold {
                setup: s.to_string(),
                seed: 0,
            })
    }
}

/// One fold: task ids, each list sorted.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Fold {
    /// Training tasks.
    pub train: Vec<String>,
    /// Development tasks (split off the training tasks).
    pub dev: Vec<String>,
    /// Test tasks.
    pub test: Vec<String>,
}

/// PHYRE's `stable_shuffle`: `items` sorted by the MD5 of `item + salt`.
pub fn stable_shuffle<S: AsRef<str>>(items: &[S], salt: &str) -> Vec<String> {
    let mut keyed: Vec<([u8; 16], String)> = items
        .iter()
        .map(|s| {
            let mut h = Md5::new();
            h.update(s.as_ref().as_bytes());
            h.update(salt.as_bytes());
            (h.finalize().into(), s.as_ref().to_string())
        })
        .collect();
    keyed.sort();
    keyed.into_iter().map(|(_, s)| s).collect()
}

fn share(n: usize) -> usize {
    (n as f64 * TRAIN_SHARE).round_ties_even() as usize
}

fn sorted(mut v: Vec<String>) -> Vec<String> {
    v.sort();
    v
}

/// Fold `seed` of `setup` over `tasks` (the 2,500 ball-tier tasks give PHYRE's folds).
pub fn fold(tasks: &TaskSet, setup: EvalSetup, seed: u64) -> Fold {
    let templates = tasks.templates();
    match setup {
        EvalSetup::WithinTemplate => {
            let (mut train, mut test) = (Vec::new(), Vec::new());
            for tpl in &templates {
                let ids = stable_shuffle(
                    &tasks.template_tasks(tpl),
                    &format!("ball_online_ind_tasks{seed}"),
                );
                let k = share(ids.len());
                if k == 0 {
                    continue;
                }
                train.extend_from_slice(&ids[..k]);
                test.extend_from_slice(&ids[k..]);
            }
            let shuffled = stable_shuffle(&train, &format!("make_dev{seed}"));
            let k = (shuffled.len() as f64 * TRAIN_SHARE) as usize;
            Fold {
                train: sorted(shuffled[..k].to_vec()),
                dev: sorted(shuffled[k..].to_vec()),
                test: sorted(test),
            }
        }
        EvalSetup::CrossTemplate => {
            let order = stable_shuffle(&templates, &format!("ball_cross_template_half_{seed}"));
            let k = share(order.len());
            let ids_of = |tpls: &[String]| -> Vec<String> {
                sorted(
                    tpls.iter()
                        .flat_map(|t| tasks.template_tasks(t))
                        .map(str::to_string)
                        .collect(),
                )
            };
            let dev_order =
                stable_shuffle(&order[..k], &format!("dev_ball_cross_template_half_{seed}"));
            let kd = (dev_order.len() as f64 * TRAIN_SHARE) as usize;
            Fold {
                train: ids_of(&dev_order[..kd]),
                dev: ids_of(&dev_order[kd..]),
                test: ids_of(&order[k..]),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fold_sizes_and_phyres_cross_template_test_set() {
        let set = TaskSet::default_tasks().unwrap();
        let w = fold(set, EvalSetup::WithinTemplate, 0);
        assert_eq!((w.train.len(), w.dev.len(), w.test.len()), (1600, 400, 500));
        let c = fold(set, EvalSetup::CrossTemplate, 0);
        assert_eq!((c.train.len(), c.dev.len(), c.test.len()), (1600, 400, 500));
        // docs/envs/phyre.md §R6: fold 0's test templates.
        let mut tpls: Vec<&str> = c.test.iter().map(|t| &t[..5]).collect();
        tpls.dedup();
        assert_eq!(tpls, ["00003", "00004", "00014", "00015", "00019"]);
        assert_ne!(fold(set, EvalSetup::WithinTemplate, 1).test, w.test);
        assert_eq!(
            "ball_cross_template".parse::<EvalSetup>().unwrap(),
            EvalSetup::CrossTemplate
        );
        assert!("ball_x".parse::<EvalSetup>().is_err());
    }
}
