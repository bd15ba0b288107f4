//! Annotation cost of an ensemble library against a single one (paper §3.3 calls it negligible; issue
//! goal: at most 1.5× the single library's time for K ≤ 4 members per label).
//!
//! `cargo bench --bench ensemble` (`ENSEMBLE_BENCH_TRACES=N` to change the default 400 traces;
//! `ENSEMBLE_BENCH_KEEP=DIR` keeps the libraries it writes, `copies-k2`, `copies-k4`, `mutants-k2` and
//! `mutants-k4`, for timing them through `annotrace annotate --library`). The
//! single library is the built-in pooltool library (12 detectors). The ensemble libraries give every
//! label K members (K = 2 and 4), written with `ensemble::library::write` and loaded back through
//! `detect::Library` as the `annotate` stage loads them, in two kinds:
//! - **copies**: member k is the label's built-in detector with a comment naming k, so every member is a
//!   distinct program (its own id, compiled and called on its own) that behaves as the built-in one —
//!   the worst case for activation clustering, where every pattern joins a cluster;
//! - **mutants**: member 0 is the built-in detector, the others are distinct children of it from the
//!   offline `mutate` proposer (one seeded edit each: constants, comparisons), kept when they run
//!   without error on 8 probe traces the timed batches do not use — programs that differ as a search's
//!   candidates do.
//!
//! γ, ε_s, ε_t are PoolTool's paper defaults (0.5, 0.005, 1).
//!
//! Traces are `dataset_trace` shots of seed 7 at dt = 0.01 s, simulated outside the timer in chunks of
//! 100; each chunk goes through every library in turn, on one pool of one worker per core per library,
//! so a shared machine's drift weighs on all alike. The timer covers what `annotate` does per batch: the
//! worker-pool run (conversion, loading, calls, validation), building the annotations, and combining an
//! ensemble's member patterns into its ensemble annotations (`ensemble::activation::combine`). Printed
//! per library: wall time, traces/s, annotations with a digest of their rows (to check that a change
//! leaves them alone), the ratio to the single library, and where the time went — the pool's parts
//! summed over its threads (the workers' time inside `find_pattern`, wall and CPU; loading traces;
//! converting them and decoding the replies in Rust), the member patterns, and the wall and CPU time
//! (`/proc/thread-self/schedstat`) of building annotations and of combining them. On a shared machine
//! wall times mostly measure waiting for a core; the CPU times do not.

use std::path::Path;
use std::time::{Duration, Instant};

use annotrace::detect::{
    Annotation, CandidateStatus, Detector, HelperSharing, Library, SandboxLimits, WorkerPool,
};
use annotrace::ensemble::activation::combine;
use annotrace::ensemble::library::{LabelFile, MemberFile, write};
use annotrace::envs::pool::{PoolConfig, TraceOptions, dataset_trace};
use annotrace::search::MutateProposer;
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

/// An ensemble library of `k` members per label, member `m` of label `l` being `code(l, m)`,
/// written under `dir/name` and loaded back.
fn ensemble_of(
    base: &Library,
    k: usize,
    dir: &Path,
    name: &str,
    code: &dyn Fn(usize, usize) -> String,
) -> Library {
    let labels: Vec<LabelFile> = base
        .detectors
        .iter()
        .enumerate()
        .map(|(l, d)| LabelFile {
            label: d.label.clone(),
            gamma: 0.5,
            eps_s: 0.005,
            eps_t: 1.0,
            members: (0..k)
                .map(|m| MemberFile {
                    label: d.label.clone(),
                    code: code(l, m),
                    weight: 1.0,
                    reward: 1.0,
                    run: "bench".into(),
                    candidate: format!("{}-{m}", d.label),
                    cluster: m as u32,
                })
                .collect(),
        })
        .collect();
    let path = dir.join(name);
    write(&path, name, Env::Pooltool, "ensemble bench", &labels, true)
        .expect("the ensemble library is written");
    Library::load(&path).expect("the ensemble library loads")
}

/// Per label of `base`, `n` distinct `mutate` children of its built-in detector (up to 2 edits each,
/// seeds 1, 2, … in order) that run without error on every probe trace, preferring children whose
/// patterns there differ from the parent's (in number or span); fewer when 60 seeds do not give `n`.
/// Also returns how many of the children kept differ from their parent.
fn mutants(
    base: &Library,
    n: usize,
    probe: &[Trace],
    pool: &WorkerPool,
) -> (Vec<Vec<String>>, usize) {
    let proposer = MutateProposer::new(None, 2).expect("python3 for the mutate proposer");
    let spans = |d: &Detector| -> Option<Vec<Vec<(i64, i64)>>> {
        let batch = pool.run(std::slice::from_ref(d), probe);
        batch
            .results
            .iter()
            .map(|r| {
                (r.status == CandidateStatus::Ok).then(|| {
                    r.patterns
                        .iter()
                        .map(|p| (p.start_step, p.end_step))
                        .collect()
                })
            })
            .collect()
    };
    let mut differing = 0;
    let out = base
        .detectors
        .iter()
        .map(|d| {
            let parent = spans(d);
            let (mut other, mut same): (Vec<String>, Vec<String>) = (Vec::new(), Vec::new());
            for seed in 1..=60u64 {
                if other.len() == n {
                    break;
                }
                let Ok((code, _)) = proposer.mutate(&[d.code.as_str()], seed) else {
                    continue;
                };
                if code == d.code || other.contains(&code) || same.contains(&code) {
                    continue;
                }
                let child = Detector::new(Env::Pooltool, &d.label, &code, "mutant");
                match spans(&child) {
                    Some(s) if Some(&s) != parent.as_ref() => other.push(code),
                    Some(_) => same.push(code),
                    None => {}
                }
            }
            differing += other.len();
            other.extend(same);
            other.truncate(n);
            other
        })
        .collect();
    (out, differing.min(n * base.detectors.len()))
}

/// Where one library's time went, summed over batches.
#[derive(Default)]
struct Split {
    /// `WorkerPool::run` (conversion, loading, calls, validation).
    pool: f64,
    /// Building the annotations of successful calls.
    build: f64,
    /// `combine` (activation clustering into ensemble annotations).
    combine: f64,
    /// Of `pool`: the workers' time inside `find_pattern`, summed over workers.
    detector: f64,
    /// Of `pool`: loading traces into workers (round trip), summed over workers.
    load: f64,
    /// Of `pool`: converting traces for the workers in Rust, summed over threads.
    convert: f64,
    /// Of `pool`: decoding and validating patterns in Rust, summed over threads.
    decode: f64,
    /// Detector calls.
    calls: usize,
    /// Member patterns (annotations before the combination).
    patterns: usize,
    /// The workers' CPU time inside `find_pattern`, summed.
    detector_cpu: f64,
    /// CPU time of this thread building the annotations (`None` where the kernel does not say).
    build_cpu: Option<f64>,
    /// CPU time of this thread combining them.
    combine_cpu: Option<f64>,
}

/// CPU time of the calling thread (s), from Linux's `/proc/thread-self/schedstat` (nanoseconds on a
/// CPU): on a shared machine the wall time of a short Rust step mostly measures waiting for a core.
fn thread_cpu() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    Some(s.split_whitespace().next()?.parse::<f64>().ok()? * 1e-9)
}

fn add(total: &mut Option<f64>, from: Option<f64>, to: Option<f64>) {
    *total = match (from, to) {
        (Some(a), Some(b)) => Some(total.unwrap_or(0.0) + (b - a)),
        _ => None,
    };
}

/// What `annotate` does with one batch: run the pool, build the annotations of successful calls,
/// combine ensemble members. Returns the annotations.
fn annotate(
    pool: &WorkerPool,
    lib: &Library,
    traces: &[Trace],
    split: &mut Split,
) -> Vec<Annotation> {
    let t0 = Instant::now();
    let batch = pool.run(&lib.detectors, traces);
    let t1 = Instant::now();
    let c1 = thread_cpu();
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
    let t2 = Instant::now();
    let c2 = thread_cpu();
    split.patterns += anns.len();
    let out = combine(&lib.detectors, traces, anns);
    let t3 = Instant::now();
    let c3 = thread_cpu();
    if split.calls == 0 {
        (split.build_cpu, split.combine_cpu) = (Some(0.0), Some(0.0));
    }
    add(&mut split.build_cpu, c1, c2);
    add(&mut split.combine_cpu, c2, c3);
    split.detector_cpu += batch.results.iter().map(|r| r.cpu_s).sum::<f64>();
    split.pool += (t1 - t0).as_secs_f64();
    split.build += (t2 - t1).as_secs_f64();
    split.combine += (t3 - t2).as_secs_f64();
    split.detector += batch.stats.detector_wall_s;
    split.load += batch.stats.load_s;
    split.convert += batch.stats.convert_s;
    split.decode += batch.stats.decode_s;
    split.calls += batch.stats.calls;
    out
}

/// A digest of annotation rows (their `Debug` text, in order), to check that a change to the
/// annotation path leaves its output alone.
fn digest(anns: &[Annotation], into: &mut Vec<u8>) {
    for a in anns {
        into.extend_from_slice(format!("{a:?}\n").as_bytes());
    }
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
    // `ENSEMBLE_BENCH_KEEP=DIR` writes the libraries into DIR and keeps them, so that the same
    // libraries can be timed through `annotrace annotate --library DIR/<name>`.
    let keep = std::env::var_os("ENSEMBLE_BENCH_KEEP").map(std::path::PathBuf::from);
    let tmp = keep.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("annotrace-ensemble-bench-{}", std::process::id()))
    });
    let workers = std::thread::available_parallelism()
        .map(|c| c.get())
        .unwrap_or(1);
    let new_pool = || {
        WorkerPool::new(SandboxLimits {
            workers,
            call_timeout: Duration::from_secs(30),
            // As `annotate`'s workers do: the members' shared helpers computed once per trace.
            share_helpers: HelperSharing::Measured,
            ..SandboxLimits::default()
        })
        .expect("workers start")
    };
    let config = PoolConfig::default_7ft();
    // Mutants are chosen on traces the timed batches do not use.
    let probe: Vec<Trace> = (0..8)
        .map(|i| {
            dataset_trace(&config, SEED + 1, i, &TraceOptions::default())
                .expect("a dataset shot simulates")
        })
        .collect();
    let (children, differing) = mutants(&base, 3, &probe, &new_pool());
    let mut libs = vec![("single".to_string(), base.clone())];
    for k in [2, 4] {
        let copy = |l: usize, m: usize| {
            format!("{}\n# ensemble bench member {m}\n", base.detectors[l].code)
        };
        libs.push((
            format!("copies K={k}"),
            ensemble_of(&base, k, &tmp, &format!("copies-k{k}"), &copy),
        ));
    }
    for k in [2, 4] {
        // Member 0 is the built-in detector, the others its mutate children (a label with fewer
        // children has fewer members).
        let lib = {
            let codes: Vec<Vec<String>> = base
                .detectors
                .iter()
                .zip(&children)
                .map(|(d, c)| {
                    std::iter::once(d.code.clone())
                        .chain(c.iter().cloned())
                        .take(k)
                        .collect()
                })
                .collect();
            let kmin = codes.iter().map(Vec::len).min().unwrap_or(0);
            assert_eq!(kmin, k, "every label has {k} working members");
            ensemble_of(&base, k, &tmp, &format!("mutants-k{k}"), &|l, m| {
                codes[l][m].clone()
            })
        };
        libs.push((format!("mutants K={k}"), lib));
    }
    println!(
        "ensemble: {} labels of {} over {n} simulated traces (dt 0.01 s), {workers} worker(s); {differing} of {} mutate children annotate the probe traces differently from their parent",
        base.detectors.len(),
        base.name,
        children.iter().map(Vec::len).sum::<usize>()
    );
    struct Run {
        name: String,
        lib: Library,
        pool: WorkerPool,
        wall: f64,
        split: Split,
        annotations: usize,
        rows: Vec<u8>,
    }
    let mut runs: Vec<Run> = libs
        .into_iter()
        .map(|(name, lib)| Run {
            name,
            lib,
            pool: new_pool(),
            wall: 0.0,
            split: Split::default(),
            annotations: 0,
            rows: Vec::new(),
        })
        .collect();
    for lo in (0..n).step_by(CHUNK) {
        let traces = chunk(&config, lo, (lo + CHUNK).min(n));
        for r in &mut runs {
            let t0 = Instant::now();
            let anns = annotate(&r.pool, &r.lib, &traces, &mut r.split);
            r.wall += t0.elapsed().as_secs_f64();
            r.annotations += anns.len();
            digest(&anns, &mut r.rows);
        }
    }
    let base_wall = runs[0].wall;
    for r in &runs {
        let s = &r.split;
        println!(
            "  {:<14} {:>2} detectors: {:.2} s wall, {:.0} traces/s, {} annotations (rows {}), {:.2}x the single library",
            r.name,
            r.lib.detectors.len(),
            r.wall,
            n as f64 / r.wall,
            r.annotations,
            &annotrace::digest::sha256_hex(&r.rows)[..12],
            r.wall / base_wall
        );
        println!(
            "  {:<14}    pool {:.2} s (summed over {workers} thread(s): find_pattern {:.2} s wall / {:.2} s CPU in {} calls, loads {:.2} s, conversion {:.2} s, decoding {:.2} s)",
            "", s.pool, s.detector, s.detector_cpu, s.calls, s.load, s.convert, s.decode,
        );
        let cpu = |c: Option<f64>| c.map_or("?".to_string(), |c| format!("{c:.3}"));
        println!(
            "  {:<14}    {} patterns, annotations built {:.3} s wall / {} s CPU, combined {:.3} s wall / {} s CPU",
            "",
            s.patterns,
            s.build,
            cpu(s.build_cpu),
            s.combine,
            cpu(s.combine_cpu)
        );
    }
    if keep.is_none() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
}
