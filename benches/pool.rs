//! Billiards speed: random 9-ball shots simulated single-threaded, with and without resampling the
//! result into a trace on the default dt = 0.01 s grid.
//!
//! `cargo bench --bench pool`. The shots are those of `annotrace simulate`: a seeded rack per scene and
//! a dataset shot (half aimed at a random object ball ±4°, half uniform; V0 ~ U(0.5, 6) m/s, (a, b) on a
//! disc of radius 0.6, θ mostly U(0, 5)°), the same distribution as `tools/pooltool/gen_traces.py`, so
//! `tools/pooltool/bench.py --phase main` times pooltool 0.6.0 on comparable work. Inputs are built
//! outside the timer; each iteration simulates `SHOTS` shots. A one-off pass before criterion prints
//! shots/s, events/shot and the time of the very first shot (no warm-up cost: nothing is compiled or
//! cached at run time).

use std::hint::black_box;
use std::time::Instant;

use annotrace::envs::pool::{
    PoolConfig, Scene, Shot, SimOptions, System, TraceOptions, rack, simulate, trace_of,
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

fn report(config: &PoolConfig) {
    let jobs = jobs(config, 2000);
    let opts = SimOptions::default();
    let t0 = Instant::now();
    let first = simulate(&jobs[0].1, &jobs[0].2, &opts).expect("valid shot");
    let first_s = t0.elapsed().as_secs_f64();
    black_box(first);
    let (mut events, mut steps) = (0usize, 0usize);
    let t0 = Instant::now();
    for (_, system, shot) in &jobs {
        let sim = simulate(system, shot, &opts).expect("valid shot");
        events += sim.events.len();
        black_box(&sim);
    }
    let sim_s = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    for (scene, system, shot) in &jobs {
        let sim = simulate(system, shot, &opts).expect("valid shot");
        let trace = trace_of(&sim, scene, shot, "bench", &TraceOptions::default());
        steps += trace.timesteps.len();
        black_box(&trace);
    }
    let both_s = t0.elapsed().as_secs_f64();
    let n = jobs.len() as f64;
    println!(
        "pool: {} shots; first shot {:.3} ms; simulate {:.0} shots/s ({:.1} events/shot, {:.2} µs/event); \
         simulate + trace at dt = 0.01 s {:.0} shots/s ({:.0} timesteps/shot)",
        jobs.len(),
        first_s * 1e3,
        n / sim_s,
        events as f64 / n,
        sim_s * 1e6 / events as f64,
        n / both_s,
        steps as f64 / n,
    );
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
