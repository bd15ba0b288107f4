//! PHYRE: fidelity against PHYRE 0.2.2 (Box2D) on a committed reference set, PHYRE's folds, and the
//! `simulate --env phyre` / `render` commands.
//!
//! `tests/data/phyre/reference.jsonl` holds (task, action, status) triples produced by the original
//! (`make_reference.py`, Python 3.9 + phyre 0.2.2; see docs/fidelity.md); `folds.json` holds the sizes
//! and SHA-256 digests of `phyre.get_fold` for both ball-tier setups and seeds 0–9.

use std::collections::BTreeMap;

use annotrace::envs::phyre::{
    BallAction, EvalSetup, PhysicsParams, Placement, Status, TaskSet, episode, fold,
};
use sha2::{Digest, Sha256};

use crate::common::{read_json, repo};

struct RefRow {
    task_id: String,
    action: BallAction,
    status: i64,
}

fn reference() -> Vec<RefRow> {
    let text = std::fs::read_to_string(repo().join("tests/data/phyre/reference.jsonl")).unwrap();
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            let a = &v["action"];
            RefRow {
                task_id: v["task_id"].as_str().unwrap().to_string(),
                action: BallAction {
                    x: a[0].as_f64().unwrap(),
                    y: a[1].as_f64().unwrap(),
                    r: a[2].as_f64().unwrap(),
                },
                status: v["status"].as_i64().unwrap(),
            }
        })
        .collect()
}

/// (validity agreement, success agreement on valid pairs, valid pairs, per-template success disagreements).
fn agreement(
    rows: &[RefRow],
    params: &PhysicsParams,
) -> (f64, f64, usize, BTreeMap<String, usize>) {
    let set = TaskSet::default_tasks().unwrap();
    let (mut valid_same, mut succ_same, mut valid_n) = (0usize, 0usize, 0usize);
    let mut bad = BTreeMap::new();
    for r in rows {
        let task = set.get(&r.task_id).unwrap();
        let ours = episode::status(&task, &r.action, params).unwrap();
        valid_same += usize::from((ours == Status::InvalidInput) == (r.status == 0));
        if r.status != 0 && ours != Status::InvalidInput {
            valid_n += 1;
            if (ours == Status::Solved) == (r.status == 1) {
                succ_same += 1;
            } else {
                *bad.entry(r.task_id[..5].to_string()).or_insert(0) += 1;
            }
        }
    }
    (
        valid_same as f64 / rows.len() as f64,
        succ_same as f64 / valid_n.max(1) as f64,
        valid_n,
        bad,
    )
}

#[test]
fn validity_and_success_agree_with_phyre_on_the_reference_set() {
    let rows = reference();
    assert!(rows.len() >= 700, "reference set has {} rows", rows.len());
    let (validity, success, n, bad) = agreement(&rows, &PhysicsParams::default());
    eprintln!(
        "validity {validity:.4}, success {success:.4} on {n} valid pairs; disagreements per template: {bad:?}"
    );
    // The validity rule is PHYRE's own geometry: it must agree everywhere.
    assert_eq!(validity, 1.0, "validity agreement {validity}");
    assert!(n >= 500, "only {n} valid pairs");
    assert!(
        success >= 0.80,
        "success agreement {success:.3} (docs/fidelity.md records the measured rate)"
    );
}

/// A parameter sweep for tuning (docs/fidelity.md); run with `cargo test --test it phyre_tuning_sweep -- --ignored --nocapture`.
#[test]
#[ignore]
fn phyre_tuning_sweep() {
    let rows = reference();
    for solver_iterations in [4, 8] {
        for touch_distance in [0.0, 0.005, 0.01, 0.02] {
            let params = PhysicsParams {
                solver_iterations,
                touch_distance,
                ..PhysicsParams::default()
            };
            let (v, s, n, bad) = agreement(&rows, &params);
            eprintln!(
                "iters {solver_iterations} touch {touch_distance}: validity {v:.4} success {s:.4} (n {n}) {bad:?}"
            );
        }
    }
}

#[test]
fn folds_match_phyre_get_fold_for_seeds_0_to_9() {
    let expected = read_json(&repo().join("tests/data/phyre/folds.json"));
    let set = TaskSet::default_tasks().unwrap();
    let digest = |ids: &[String]| {
        let h = Sha256::digest(ids.join("\n").as_bytes());
        h.iter().map(|b| format!("{b:02x}")).collect::<String>()
    };
    for setup in EvalSetup::ALL {
        for seed in 0..10u64 {
            let f = fold(set, setup, seed);
            let e = &expected[format!("{}/{seed}", setup.name())];
            for (name, ids) in [("train", &f.train), ("dev", &f.dev), ("test", &f.test)] {
                assert_eq!(
                    e[name][0].as_u64().unwrap() as usize,
                    ids.len(),
                    "{} {seed} {name}",
                    setup.name()
                );
                assert_eq!(
                    e[name][1].as_str().unwrap(),
                    digest(ids),
                    "{} {seed} {name}",
                    setup.name()
                );
            }
        }
    }
}

#[test]
fn reference_solving_actions_replay_as_valid_balls() {
    let set = TaskSet::default_tasks().unwrap();
    for r in reference().iter().filter(|r| r.status == 1).take(20) {
        let task = set.get(&r.task_id).unwrap();
        assert!(
            matches!(r.action.place(&task).unwrap(), Placement::Valid(_)),
            "{}",
            r.task_id
        );
    }
}

/// Where the time goes: computed vs replayed steps on the reference set (debug build; figures for
/// tuning only, speed is measured in benches/phyre.rs).
#[test]
#[ignore]
fn phyre_step_profile() {
    let set = TaskSet::default_tasks().unwrap();
    let rows = reference();
    for (sleep_linear, sleep_time) in [(0.01, 0.5), (0.05, 0.5), (0.1, 0.5), (0.1, 0.25)] {
        let params = PhysicsParams { sleep_linear, sleep_time, ..PhysicsParams::default() };
        let t0 = std::time::Instant::now();
        let (mut steps, mut computed, mut n, mut same) = (0, 0, 0, 0);
        for r in rows.iter().filter(|r| r.status != 0) {
            let task = set.get(&r.task_id).unwrap();
            let res = episode::run(&task, &r.action, &params, &annotrace::envs::phyre::RecordOptions { stride: 0, record: false }).unwrap();
            steps += res.steps;
            computed += res.computed_steps;
            n += 1;
            same += usize::from((res.status == Status::Solved) == (r.status == 1));
        }
        eprintln!("sleep {sleep_linear} m/s after {sleep_time} s: {n} episodes, {steps} steps, {computed} computed, agreement {:.4}, {:.1} ms/episode", same as f64 / n as f64, t0.elapsed().as_secs_f64() * 1e3 / n as f64);
    }
}
