//! Cost of one annealing step of the reward-program experiment (simulate + annotate + score) and its
//! split, and the time of the paper-size experiment extrapolated from it.
//!
//! `cargo bench --bench optimise` (`OPT_BENCH_STEPS=N` to change the default 50 steps). For each of the
//! ten goals of `data/goals/pooltool.toml`, 40 chains (10 held-out scattered scenes × 2 seeds × dense and sparse)
//! run in lockstep exactly as the `optimise` stage runs them, with one Python worker per core and traces
//! at dt = 0.02 s. Printed: per sample, the time simulating (all chains, in parallel), annotating (dense
//! chains only: one worker-pool call per goal per step with the goal's detectors) and scoring (program
//! and verification rule), the wall time per sample, and the paper-size experiment (10 goals × 100
//! scenes × 3 seeds × 1000 samples × 2 reward types) extrapolated linearly from the measured wall time.
//! Then the batching effect: one goal's dense chains annotated 1 trace per call against 20 per call.

use std::time::Instant;

use annotrace::detect::{Library, SandboxLimits, WorkerPool};
use annotrace::envs::pool::PoolEnv;
use annotrace::optimise::{
    Chain, GoalTask, Layout, PoolProblem, RewardKind, Schedule, Settings, ShotBounds, Timings,
    run_chains, scenes,
};
use annotrace::reward::annotate::{detectors_for, probe_schema};
use annotrace::reward::goals::GoalSet;
use annotrace::reward::verify::Rule;
use annotrace::reward::{compile, labels_used};

fn add(t: &mut Timings, s: &Timings) {
    t.samples += s.samples;
    t.dense_samples += s.dense_samples;
    t.simulate_s += s.simulate_s;
    t.annotate_s += s.annotate_s;
    t.score_s += s.score_s;
}

fn main() {
    let steps: usize = std::env::var("OPT_BENCH_STEPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(50);
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let goals = GoalSet::load(&root.join("data/goals/pooltool.toml"), root).expect("goal file");
    let lib = Library::load(&root.join("data/libraries/pooltool")).expect("library");
    let pool = WorkerPool::new(SandboxLimits::default()).expect("workers");
    let schema = probe_schema(&lib, &pool);
    let mut env = PoolEnv::default();
    env.trace.dt = 0.02;
    let scenes = scenes(&env, Layout::Scatter, 10, 1000).expect("scenes");
    let settings = Settings {
        problem: PoolProblem::new(env, ShotBounds::default()).expect("bounds"),
        schedule: Schedule::default(),
        checkpoint: Some(50),
    };
    let task = |id: &str| {
        let g = goals.get(id).expect("goal");
        let program = compile(&g.program, &schema).expect("program");
        GoalTask {
            id: id.into(),
            detectors: detectors_for(&lib, &labels_used(&program)),
            program,
            rule: Rule::parse(&g.verify).expect("rule"),
        }
    };
    let chains_for = |kinds: &[RewardKind], n_scenes: usize| {
        let mut out = Vec::new();
        for (i, s) in scenes.iter().take(n_scenes).enumerate() {
            for seed in 0..2u64 {
                for &kind in kinds {
                    out.push(Chain {
                        goal: 0,
                        scene: s.clone(),
                        seed: (i as u64) << 8 | seed,
                        kind,
                        budget: steps,
                    });
                }
            }
        }
        out
    };
    println!(
        "optimise bench: {} workers, {steps} steps × 40 chains per goal, dt = 0.02 s",
        pool.workers()
    );
    println!(
        "{:<22} {:>6} {:>10} {:>12} {:>10} {:>12} {:>9}",
        "goal", "dets", "sim ms/s", "annot ms/ds", "score ms/s", "wall ms/s", "success"
    );
    let mut total = Timings::default();
    let mut wall = 0.0;
    for g in &goals.goals {
        let t = task(&g.id);
        let chains = chains_for(&[RewardKind::Dense, RewardKind::Sparse], 10);
        let t0 = Instant::now();
        let (rows, tm) = run_chains(
            &settings,
            std::slice::from_ref(&t),
            &chains,
            Some(&pool),
            |_| {},
        )
        .expect("chains");
        let w = t0.elapsed().as_secs_f64();
        wall += w;
        add(&mut total, &tm);
        let last = rows
            .iter()
            .filter(|r| r.budget == steps)
            .collect::<Vec<_>>();
        let succ = last.iter().filter(|r| r.success).count() as f64 / last.len().max(1) as f64;
        println!(
            "{:<22} {:>6} {:>10.2} {:>12.2} {:>10.3} {:>12.2} {:>9.3}",
            g.id,
            t.detectors.len(),
            1e3 * tm.simulate_s / tm.samples as f64,
            1e3 * tm.annotate_s / tm.dense_samples.max(1) as f64,
            1e3 * tm.score_s / tm.samples as f64,
            1e3 * w / tm.samples as f64,
            succ
        );
    }
    let per_sample = wall / total.samples as f64;
    println!(
        "all goals: {} samples ({} dense) in {wall:.1} s: simulate {:.2} ms/sample, annotate {:.2} ms/dense sample, \
         score {:.3} ms/sample, wall {:.2} ms/sample",
        total.samples,
        total.dense_samples,
        1e3 * total.simulate_s / total.samples as f64,
        1e3 * total.annotate_s / total.dense_samples as f64,
        1e3 * total.score_s / total.samples as f64,
        1e3 * per_sample
    );
    let full = 10.0 * 100.0 * 3.0 * 1000.0 * 2.0;
    println!(
        "paper size (10 goals × 100 scenes × 3 seeds × 1000 samples × 2 rewards = {full:.0} samples): \
         {:.1} h at the measured wall time per sample; annotation share {:.0} %",
        full * per_sample / 3600.0,
        100.0 * total.annotate_s / wall
    );
    // Batching: one goal's dense chains, one trace per pool call vs 20 per call.
    let t = task("two-cushions-pot-8");
    for n in [1usize, 10] {
        let chains = chains_for(&[RewardKind::Dense], n);
        let mut tm = Timings::default();
        if n == 1 {
            // 20 separate single-chain runs: one trace per worker call.
            for c in chains_for(&[RewardKind::Dense], 10) {
                let (_, s) = run_chains(
                    &settings,
                    std::slice::from_ref(&t),
                    &[c],
                    Some(&pool),
                    |_| {},
                )
                .expect("chain");
                add(&mut tm, &s);
            }
        } else {
            let (_, s) = run_chains(
                &settings,
                std::slice::from_ref(&t),
                &chains,
                Some(&pool),
                |_| {},
            )
            .expect("chains");
            add(&mut tm, &s);
        }
        println!(
            "batching: {} trace(s) per worker call: annotate {:.2} ms per dense sample",
            if n == 1 { 1 } else { chains.len() },
            1e3 * tm.annotate_s / tm.dense_samples as f64
        );
    }
}
