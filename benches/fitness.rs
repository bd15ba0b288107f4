//! Fitness speed: evaluating one candidate detector on 100 billiards training traces (worker-pool run
//! of the candidate on every trace + annotation histograms + D_p + ρ + η, as the search does it), and the
//! pairwise D_x matrix of 1000 traces.
//!
//! `cargo bench --bench fitness` (`FITNESS_BENCH_TRACES=N` for the D_x size, default 1000). Traces are
//! `annotrace simulate --seed 7` shots: the 100 training traces at the default dt = 0.01 s, the D_x traces
//! at dt = 0.1 s (1000 traces at 0.01 s would hold about a gigabyte of frames; D_x resamples every trace
//! to 64 normalised-time frames first, so the pairwise part does not depend on dt). The candidate is the
//! built-in "ball slowing" detector with one constant changed per iteration (a new program each time, as
//! in a search: compiled once per worker, traces already cached in the workers), scored against the rest
//! of the built-in library. The timers cover only the measured work; simulation is outside them.

use std::collections::HashMap;
use std::time::Instant;

use annotrace::detect::{Detector, Library, SandboxLimits, WorkerPool};
use annotrace::envs::pool::{PoolConfig, TraceOptions, dataset_trace};
use annotrace::fitness::DistanceMatrix;
use annotrace::search::count_lines;
use annotrace::search::evaluator::{EvalSettings, Evaluation, Evaluator, library_view};
use annotrace::trace::Trace;

const SEED: u64 = 7;

fn traces(config: &PoolConfig, n: usize, dt: f64) -> Vec<Trace> {
    (0..n)
        .map(|i| {
            dataset_trace(config, SEED, i as u64, &TraceOptions { dt })
                .expect("a dataset shot simulates")
        })
        .collect()
}

fn main() {
    let n_dx: usize = std::env::var("FITNESS_BENCH_TRACES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000);
    let cores = std::thread::available_parallelism()
        .map(|c| c.get())
        .unwrap_or(1);
    let config = PoolConfig::default_7ft();
    let lib = Library::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/libraries/pooltool"),
    )
    .expect("the built-in library loads");

    // --- One candidate on 100 training traces.
    let train = traces(&config, 100, 0.01);
    let frames: usize = train.iter().map(|t| t.frame_rows()).sum();
    let pool = WorkerPool::new(SandboxLimits {
        workers: cores,
        trace_cache: 128,
        ..SandboxLimits::default()
    })
    .expect("workers start");
    let dx = DistanceMatrix::compute(&train, 64);
    let label = "ball slowing";
    let others: Vec<Detector> = lib
        .detectors
        .iter()
        .filter(|d| !d.accepts_label(label))
        .cloned()
        .collect();
    let view = library_view(&pool, &others, &train, 10);
    let base = lib
        .detectors
        .iter()
        .find(|d| d.accepts_label(label))
        .expect("the library has ball slowing")
        .code
        .clone();
    let evaluator = Evaluator {
        pool: &pool,
        env: lib.env,
        label: label.into(),
        traces: &train,
        dx: &dx,
        library: &view,
        settings: EvalSettings::default(),
    };
    // Warm-up: the traces are loaded into the workers once (a search's steady state).
    let known = HashMap::new();
    let _ = evaluator.evaluate(&base, count_lines(&base), &known, true);
    let iterations = 10;
    let mut times = Vec::new();
    let mut statuses: HashMap<&'static str, usize> = HashMap::new();
    for k in 0..iterations {
        // A new program each time (a comment changes its id, not its behaviour).
        let code = format!("{base}\n# candidate {k}\n");
        let t0 = Instant::now();
        let e = evaluator.evaluate(&code, count_lines(&code), &known, false);
        times.push(t0.elapsed().as_secs_f64());
        let s = match e {
            Evaluation::Scored { .. } => "scored",
            Evaluation::Degenerate { .. } => "degenerate",
            Evaluation::SameBehaviour { .. } => "same behaviour",
            Evaluation::Failed { .. } => "failed",
        };
        *statuses.entry(s).or_default() += 1;
    }
    times.sort_by(f64::total_cmp);
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    println!(
        "fitness: evaluate one candidate on {} training traces ({frames} frame rows, dt 0.01 s), {cores} worker(s): \
         mean {:.3} s, median {:.3} s, min {:.3} s over {iterations} candidates ({statuses:?}); goal <= 0.5 s",
        train.len(),
        mean,
        times[times.len() / 2],
        times[0],
    );
    // The fitness arithmetic alone (histograms given): D_p over all pairs, ρ, η.
    let hists: Vec<Vec<f64>> = view.hists.iter().map(|h| h[0].clone()).collect();
    let out = annotrace::fitness::CandidateOutput {
        hists,
        mean_time: 0.001,
        lines: 100,
    };
    let t0 = Instant::now();
    let reps = 200;
    for _ in 0..reps {
        std::hint::black_box(annotrace::fitness::evaluate(
            &dx,
            &view,
            &out,
            true,
            annotrace::fitness::Dp::default(),
        ));
    }
    println!(
        "fitness: D_p + rho + eta + lambda + psi for 100 traces ({} pairs, {} library detectors): {:.3} ms",
        dx.upper.len(),
        others.len(),
        t0.elapsed().as_secs_f64() * 1e3 / reps as f64
    );
    drop(pool);
    drop(train);

    // --- D_x of n_dx traces.
    let t_sim = Instant::now();
    let many = traces(&config, n_dx, 0.1);
    let sim_s = t_sim.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let m = DistanceMatrix::compute(&many, 64);
    let dx_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let m1 = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool")
        .install(|| DistanceMatrix::compute(&many, 64));
    let dx1_s = t1.elapsed().as_secs_f64();
    assert_eq!(m.upper.len(), m1.upper.len());
    println!(
        "fitness: D_x of {n_dx} traces ({} pairs, 64 samples each; simulated in {sim_s:.1} s outside the timer): \
         {dx_s:.3} s on {cores} thread(s), {dx1_s:.3} s on 1 thread",
        m.upper.len()
    );
}
