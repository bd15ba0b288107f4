//! Detector runtime speed: the built-in pooltool library (12 detectors) over simulated 9-ball shots, with
//! one worker and with one worker per core.
//!
//! `cargo bench --bench detect` (`DETECT_BENCH_TRACES=N` to change the default 1000 traces). The traces
//! are those of `annotrace simulate --seed 7` at the default dt = 0.01 s, simulated in chunks of 100
//! outside the timer (1000 traces at once would hold about a gigabyte of frames). Each configuration has
//! one `WorkerPool` and the configurations take each chunk in turn, so that a shared machine's drift
//! weighs on all alike. The timer covers `WorkerPool::run` only: converting each trace, loading it into
//! a worker, compiling the detectors (once per worker), running them, validating the output. Printed
//! per configuration: wall time, traces/s, detector calls/s, the speed-up over one worker, and where the
//! time went (`RunStats`): detector time inside the workers, and the overhead (conversion, loading,
//! compiling, protocol and validation) as a share of detector time; then the last 16 traces again (five
//! passes) while still cached in the workers (the steady state of a search, where many candidates run
//! over one training set), where only the calls and the protocol remain.

use std::time::{Duration, Instant};

use annotrace::detect::{Library, RunStats, SandboxLimits, WorkerPool};
use annotrace::envs::pool::{PoolConfig, TraceOptions, dataset_trace};
use annotrace::trace::Trace;

const SEED: u64 = 7;
const CHUNK: usize = 100;
const CACHED_PASSES: usize = 5;

fn chunk(config: &PoolConfig, lo: usize, hi: usize) -> Vec<Trace> {
    (lo..hi)
        .map(|i| {
            dataset_trace(config, SEED, i as u64, &TraceOptions::default())
                .expect("a dataset shot simulates")
        })
        .collect()
}

fn main() {
    // Accept and ignore the arguments cargo bench passes (`--bench`, filters).
    let n: usize = std::env::var("DETECT_BENCH_TRACES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000);
    let lib = Library::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/libraries/pooltool"),
    )
    .expect("the built-in library loads");
    let config = PoolConfig::default_7ft();
    let cores = std::thread::available_parallelism()
        .map(|c| c.get())
        .unwrap_or(1);
    let mut configs = vec![1];
    if cores > 1 {
        configs.push(cores);
    }
    println!(
        "detect: {} detectors of {} over {n} simulated traces (dt 0.01 s), {cores} core(s)",
        lib.detectors.len(),
        lib.name
    );
    // One pool per configuration; each chunk goes through every configuration in turn, so that a
    // shared machine's drift (its speed moves by ±30 % over minutes) weighs on all of them alike.
    struct Config {
        workers: usize,
        pool: WorkerPool,
        total: RunStats,
        wall: f64,
        failed: usize,
    }
    let mut runs: Vec<Config> = configs
        .iter()
        .map(|&workers| Config {
            workers,
            pool: WorkerPool::new(SandboxLimits {
                workers,
                call_timeout: Duration::from_secs(30),
                ..SandboxLimits::default()
            })
            .expect("workers start"),
            total: RunStats::default(),
            wall: 0.0,
            failed: 0,
        })
        .collect();
    let (mut frames, mut steps) = (0usize, 0usize);
    for lo in (0..n).step_by(CHUNK) {
        let traces = chunk(&config, lo, (lo + CHUNK).min(n));
        frames += traces.iter().map(Trace::frame_rows).sum::<usize>();
        steps += traces.iter().map(|t| t.timesteps.len()).sum::<usize>();
        for r in &mut runs {
            let t0 = Instant::now();
            let batch = r.pool.run(&lib.detectors, &traces);
            r.wall += t0.elapsed().as_secs_f64();
            r.failed += batch
                .results
                .iter()
                .filter(|c| c.status.error().is_some())
                .count();
            r.total.add(&batch.stats);
        }
    }
    // Steady state of a search: the last 16 traces again, still cached in the workers, so only the
    // calls and the protocol remain; five passes per configuration, alternating, summed.
    let last = chunk(&config, n.saturating_sub(16), n);
    let mut cached: Vec<(f64, RunStats)> = vec![(0.0, RunStats::default()); runs.len()];
    for _ in 0..CACHED_PASSES {
        for (r, (wall, stats)) in runs.iter().zip(&mut cached) {
            let t0 = Instant::now();
            stats.add(&r.pool.run(&lib.detectors, &last).stats);
            *wall += t0.elapsed().as_secs_f64();
        }
    }
    let base = runs[0].wall;
    for (r, (cached_wall, c)) in runs.iter().zip(&cached) {
        let (workers, wall, total) = (r.workers, r.wall, &r.total);
        println!(
            "  {workers} worker(s): {wall:.2} s wall, {:.0} traces/s, {:.0} calls/s, speed-up {:.2}x, {} failed call(s)",
            n as f64 / wall,
            total.calls as f64 / wall,
            base / wall,
            r.failed,
        );
        println!(
            "    detector time {:.2} s ({:.3} ms/call); overhead {:.1}% of it: convert {:.2} s, load {:.2} s (building dicts {:.2} s), compile {:.2} s, protocol+validation {:.2} s; decoding in Rust (overlapped) {:.2} s",
            total.detector_wall_s,
            1000.0 * total.detector_wall_s / total.calls.max(1) as f64,
            100.0 * total.overhead(),
            total.convert_s,
            total.load_s,
            total.build_s,
            total.compile_s,
            total.round_trip_s - total.detector_wall_s,
            total.decode_s,
        );
        println!(
            "    cached re-run of {} traces ×{CACHED_PASSES}: {cached_wall:.3} s wall, {} trace load(s), detector time {:.3} s, protocol+validation {:.1}% of it, decoding {:.3} s",
            last.len(),
            c.traces_loaded,
            c.detector_wall_s,
            100.0 * (c.round_trip_s - c.detector_wall_s) / c.detector_wall_s.max(1e-9),
            c.decode_s,
        );
    }
    println!("  ({steps} timesteps, {frames} frame rows in all)");
}
