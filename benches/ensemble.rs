//! Annotation cost of an ensemble library against a single one (paper §3.3 calls it negligible; issue
//! goal: at most 1.5× the single library's time for K ≤ 4 members per label).
//!
//! `cargo bench --bench ensemble` (`ENSEMBLE_BENCH_TRACES=N` to change the default 400 traces). The
//! single library is the built-in pooltool library (12 detectors). The ensemble libraries give every
//! label K members (K = 2 and 4), written with `ensemble::library::write` and loaded back through
//! `detect::Library` as the `annotate` stage loads them: member k is the label's built-in detector with a
//! comment naming k, so every member is a distinct program (its own id, compiled and called on its own)
//! whose patterns overlap the others' — the worst case for activation clustering, where every pattern
//! joins a cluster. γ, ε_s, ε_t are PoolTool's paper defaults (0.5, 0.005, 1).
//!
//! Traces are `dataset_trace` shots of seed 7 at dt = 0.01 s, simulated outside the timer in chunks of
//! 100; each chunk goes through every library in turn, on one pool of one worker per core per library,
//! so a shared machine's drift weighs on all alike. The timer covers what `annotate` does per batch: the
//! worker-pool run (conversion, loading, calls, validation), building the annotations, and combining an
//! ensemble's member patterns into its ensemble annotations (`ensemble::activation::combine`). Printed
//! per library: wall time, traces/s, annotations, and the ratio to the single library.

use std::path::Path;
use std::time::{Duration, Instant};

use annotrace::detect::{Annotation, CandidateStatus, Library, SandboxLimits, WorkerPool};
use annotrace::ensemble::activation::combine;
use annotrace::ensemble::library::{LabelFile, MemberFile, write};
use annotrace::envs::pool::{PoolConfig, TraceOptions, dataset_trace};
use annotrace::trace::{Env, Trace};

const SEED: u64 = 7;
const CHUNK: usize = 100;

fn chunk(config: &PoolConfig, lo: usize, hi: usize) -> Vec<Trace> {
    (lo..hi)
        .map(|i| {
            dataset_trace(config, SEED, i as u64, &TraceOptions::default())
                .expect("a dataset shot simulates")
        })
        .collect()
}

/// An ensemble library of `k` members per label of `base`, written under `dir` and loaded back.
fn ensemble_of(base: &Library, k: usize, dir: &Path) -> Library {
    let labels: Vec<LabelFile> = base
        .detectors
        .iter()
        .map(|d| LabelFile {
            label: d.label.clone(),
            gamma: 0.5,
            eps_s: 0.005,
            eps_t: 1.0,
            members: (0..k)
                .map(|m| MemberFile {
                    label: d.label.clone(),
                    code: format!("{}\n# ensemble bench member {m}\n", d.code),
                    weight: 1.0,
                    reward: 1.0,
                    run: "bench".into(),
                    candidate: format!("{}-{m}", d.label),
                    cluster: m as u32,
                })
                .collect(),
        })
        .collect();
    let path = dir.join(format!("ensemble-k{k}"));
    write(
        &path,
        &format!("bench-k{k}"),
        Env::Pooltool,
        "ensemble bench",
        &labels,
        true,
    )
    .expect("the ensemble library is written");
    Library::load(&path).expect("the ensemble library loads")
}

/// What `annotate` does with one batch: run the pool, build the annotations of successful calls,
/// combine ensemble members.
fn annotate(pool: &WorkerPool, lib: &Library, traces: &[Trace]) -> usize {
    let batch = pool.run(&lib.detectors, traces);
    let mut anns = Vec::new();
    for r in &batch.results {
        if r.status != CandidateStatus::Ok {
            continue;
        }
        let det = &lib.detectors[r.detector];
        for (seq, p) in r.patterns.iter().enumerate() {
            anns.push(Annotation::new(det, &traces[r.trace], seq, p.clone()));
        }
    }
    combine(&lib.detectors, traces, anns).len()
}

fn main() {
    // Accept and ignore the arguments cargo bench passes (`--bench`, filters).
    let n: usize = std::env::var("ENSEMBLE_BENCH_TRACES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(400);
    let base =
        Library::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("data/libraries/pooltool"))
            .expect("the built-in library loads");
    let tmp = std::env::temp_dir().join(format!("annotrace-ensemble-bench-{}", std::process::id()));
    let mut libs = vec![("single".to_string(), base.clone())];
    for k in [2, 4] {
        libs.push((format!("ensemble K={k}"), ensemble_of(&base, k, &tmp)));
    }
    let workers = std::thread::available_parallelism()
        .map(|c| c.get())
        .unwrap_or(1);
    println!(
        "ensemble: {} labels of {} over {n} simulated traces (dt 0.01 s), {workers} worker(s)",
        base.detectors.len(),
        base.name
    );
    struct Run {
        name: String,
        lib: Library,
        pool: WorkerPool,
        wall: f64,
        annotations: usize,
    }
    let mut runs: Vec<Run> = libs
        .into_iter()
        .map(|(name, lib)| Run {
            name,
            lib,
            pool: WorkerPool::new(SandboxLimits {
                workers,
                call_timeout: Duration::from_secs(30),
                ..SandboxLimits::default()
            })
            .expect("workers start"),
            wall: 0.0,
            annotations: 0,
        })
        .collect();
    let config = PoolConfig::default_7ft();
    for lo in (0..n).step_by(CHUNK) {
        let traces = chunk(&config, lo, (lo + CHUNK).min(n));
        for r in &mut runs {
            let t0 = Instant::now();
            r.annotations += annotate(&r.pool, &r.lib, &traces);
            r.wall += t0.elapsed().as_secs_f64();
        }
    }
    let base_wall = runs[0].wall;
    for r in &runs {
        println!(
            "  {:<14} {} detectors: {:.2} s wall, {:.0} traces/s, {} annotations, {:.2}x the single library",
            r.name,
            r.lib.detectors.len(),
            r.wall,
            n as f64 / r.wall,
            r.annotations,
            r.wall / base_wall
        );
    }
    let _ = std::fs::remove_dir_all(&tmp);
}
