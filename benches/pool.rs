//! Billiards speed: random 9-ball shots simulated single-threaded, alone, with the states resampled on
//! the default dt = 0.01 s grid (what pooltool's `continuize` does), and converted into the paper-layout
//! `Trace` (every ball at every step as an object with its id and motion-state strings).
//!
//! `cargo bench --bench pool`. The shots are those of `annotrace simulate`: a seeded rack per scene and
//! a dataset shot (half aimed at a random object ball ±4°, half uniform; V0 ~ U(0.5, 6) m/s, (a, b) on a
//! disc of radius 0.6, θ mostly U(0, 5)°), the same distribution as `tools/pooltool/gen_traces.py`, so
//! `tools/pooltool/bench.py --phase main` times pooltool 0.6.0 on comparable work. Inputs are built
//! outside the timer; each iteration simulates `SHOTS` shots. A one-off pass before criterion prints
//! shots/s, events/shot and the time of the very first shot (no warm-up cost: nothing is compiled or
//! cached at run time).
//!
//! With `POOL_REF_DIR` pointing at the output of `gen_traces.py --n 200 --seed 777`, the pass also times
//! exactly the shots `bench.py --phase main --n 200 --seed 777` gives pooltool (same racks, same cue
//! parameters), read from those traces.

use std::hint::black_box;
use std::time::Instant;

use annotrace::envs::pool::reference::RefTrace;
use annotrace::envs::pool::{
    Goal, PoolConfig, Scene, SceneBall, Shot, SimOptions, System, TraceOptions, rack, resample,
    simulate, trace_of,
};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

const SHOTS: usize = 200;
const SEED: u64 = 777;

fn jobs(config: &PoolConfig, n: usize) -> Vec<(Scene, System, Shot)> {
    (0..n as u64)
        .map(|i| {
            let scene = Scene::nine_ball(config, rack::scene_seed(SEED, i));
            let shot = rack::dataset_shot(&scene, &mut rack::shot_rng(SEED, i, 0));
            let system = scene.system(config).expect("a rack is a valid scene");
            (scene, system, shot)
        })
        .collect()
}

/// The shots of a `gen_traces.py` directory, as (scene, system, shot).
fn reference_jobs(dir: &str) -> Vec<(Scene, System, Shot)> {
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .expect("POOL_REF_DIR is a directory")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("shot_"))
        })
        .collect();
    paths.sort();
    paths
        .iter()
        .map(|p| {
            let r = RefTrace::from_json_str(&std::fs::read_to_string(p).unwrap()).unwrap();
            let scene = Scene {
                scene_id: "ref".into(),
                balls: r
                    .system
                    .balls
                    .iter()
                    .map(|b| SceneBall {
                        id: b.id.clone(),
                        x: b.state.r[0],
                        y: b.state.r[1],
                    })
                    .collect(),
                cue_ball: r.system.cue_ball_id.clone(),
                goal: Goal::pot_nine(),
                seed: None,
            };
            (scene, r.system, r.shot)
        })
        .collect()
}

fn time_jobs(label: &str, jobs: &[(Scene, System, Shot)]) {
    let opts = SimOptions::default();
    let (mut events, mut steps) = (0usize, 0usize);
    let t0 = Instant::now();
    for (_, system, shot) in jobs {
        let sim = simulate(system, shot, &opts).expect("valid shot");
        events += sim.events.len();
        black_box(&sim);
    }
    let sim_s = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    for (_, system, shot) in jobs {
        let sim = simulate(system, shot, &opts).expect("valid shot");
        black_box(resample(&sim, 0.01));
    }
    let resample_s = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    for (scene, system, shot) in jobs {
        let sim = simulate(system, shot, &opts).expect("valid shot");
        let trace = trace_of(&sim, scene, shot, "bench", &TraceOptions::default());
        steps += trace.timesteps.len();
        black_box(&trace);
    }
    let both_s = t0.elapsed().as_secs_f64();
    let n = jobs.len() as f64;
    println!(
        "pool {label}: {} shots; simulate {:.0} shots/s ({:.1} events/shot, {:.2} µs/event); \
         simulate + resample at dt = 0.01 s {:.0} shots/s; simulate + paper-layout trace {:.0} shots/s \
         ({:.0} timesteps/shot)",
        jobs.len(),
        n / sim_s,
        events as f64 / n,
        sim_s * 1e6 / events as f64,
        n / resample_s,
        n / both_s,
        steps as f64 / n,
    );
}

fn report(config: &PoolConfig) {
    if let Ok(dir) = std::env::var("POOL_REF_DIR") {
        time_jobs("bench.py's shots (POOL_REF_DIR)", &reference_jobs(&dir));
    }
    let jobs = jobs(config, 2000);
    let t0 = Instant::now();
    black_box(simulate(&jobs[0].1, &jobs[0].2, &SimOptions::default()).expect("valid shot"));
    println!(
        "pool: first shot of the process {:.3} ms",
        t0.elapsed().as_secs_f64() * 1e3
    );
    time_jobs("random 9-ball shots (seed 777)", &jobs);
}

fn bench_pool(c: &mut Criterion) {
    let config = PoolConfig::default_7ft();
    report(&config);
    let jobs = jobs(&config, SHOTS);
    let opts = SimOptions::default();
    let mut g = c.benchmark_group("pool");
    g.throughput(Throughput::Elements(SHOTS as u64));
    g.sample_size(20);
    g.bench_function("simulate_9ball_shots", |b| {
        b.iter(|| {
            for (_, system, shot) in &jobs {
                black_box(simulate(system, shot, &opts).expect("valid shot"));
            }
        })
    });
    g.bench_function("simulate_and_resample_dt_0.01", |b| {
        b.iter(|| {
            for (_, system, shot) in &jobs {
                let sim = simulate(system, shot, &opts).expect("valid shot");
                black_box(resample(&sim, 0.01));
            }
        })
    });
    g.bench_function("simulate_and_trace_dt_0.01", |b| {
        b.iter(|| {
            for (scene, system, shot) in &jobs {
                let sim = simulate(system, shot, &opts).expect("valid shot");
                black_box(trace_of(
                    &sim,
                    scene,
                    shot,
                    "bench",
                    &TraceOptions::default(),
                ));
            }
        })
    });
    g.finish();
}

criterion_group!(benches, bench_pool);
criterion_main!(benches);
