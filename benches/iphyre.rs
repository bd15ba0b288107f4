//! I-PHYRE episodes per second, single-threaded, at 60 fps: with full trace recording (every step's
//! object states, the events, conversion into a `Trace`), and outcome only. The games are the eight of
//! the original's speed script (`tools/phyre/iphyre_speed.py`: support, hole, angle, pendulum,
//! spring, hinder_fill, multi_ball_stack, multi_ball_spring), each with `PER_GAME` seeded random click
//! sets in iphyre's `generate_actions` style (`envs::iphyre::random_clicks`), so the work is that of the
//! script's `simulate()` column (docs/envs/iphyre.md §R6: 105 episodes/s mean over these games, pymunk 6.11.1).
//!
//! `cargo bench --bench iphyre`. A one-off pass before criterion prints, per game, episodes/s and
//! steps/s with recording, and the mean over games (the figure the original's table reports), then
//! the same at 10 fps. The engine is the default one (the Chipmunk step); `IPHYRE_BENCH_ENGINE=rapier`
//! (or `box2d`) measures another in the same way.

use std::hint::black_box;
use std::time::Instant;

use annotrace::envs::iphyre::{
    Click, Engine, Episode, Game, Games, PhysicsParams, clicks_rng, random_clicks, trace_of,
};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

const GAMES: [&str; 8] = [
    "support",
    "hole",
    "angle",
    "pendulum",
    "spring",
    "hinder_fill",
    "multi_ball_stack",
    "multi_ball_spring",
];
const PER_GAME: u64 = 20;
const SEED: u64 = 1;

fn workload(games: &Games) -> Vec<(Game, Vec<Click>)> {
    let mut out = Vec::new();
    for name in GAMES {
        let g = games.get(name).expect("a known game");
        for k in 0..PER_GAME {
            let clicks = random_clicks(g, &mut clicks_rng(SEED, g.index as u64, k));
            out.push((g.clone(), clicks));
        }
    }
    out
}

/// One episode; with `record`, every frame and the conversion into a trace. Returns the steps done.
fn episode(game: &Game, clicks: &[Click], params: &PhysicsParams, record: bool) -> usize {
    let mut e = Episode::new(game, clicks, params, record).expect("valid clicks");
    while !e.done() {
        e.step();
    }
    let r = e.finish();
    let steps = r.steps;
    if record {
        black_box(trace_of(&r, game, "bench"));
    } else {
        black_box(r.success);
    }
    steps
}

fn one_off(work: &[(Game, Vec<Click>)], params: &PhysicsParams) {
    let mut rates = Vec::new();
    for chunk in work.chunks(PER_GAME as usize) {
        let t0 = Instant::now();
        let steps: usize = chunk.iter().map(|(g, c)| episode(g, c, params, true)).sum();
        let s = t0.elapsed().as_secs_f64();
        let eps = chunk.len() as f64 / s;
        println!(
            "iphyre {:>3} fps  {:<18} {:>8.1} episodes/s  {:>9.0} steps/s (recording)",
            params.fps,
            chunk[0].0.name,
            eps,
            steps as f64 / s
        );
        rates.push(eps);
    }
    let mean = rates.iter().sum::<f64>() / rates.len() as f64;
    let t0 = Instant::now();
    for (g, c) in work {
        episode(g, c, params, true);
    }
    let overall = work.len() as f64 / t0.elapsed().as_secs_f64();
    println!(
        "iphyre {:>3} fps  mean over games {mean:.1} episodes/s; all {} episodes {overall:.1} episodes/s (recording)",
        params.fps,
        work.len()
    );
}

/// The default parameters at `fps`, on the engine `IPHYRE_BENCH_ENGINE` names (default: the default).
fn params_at(fps: f64) -> PhysicsParams {
    let engine = std::env::var("IPHYRE_BENCH_ENGINE").map_or(Engine::default(), |name| {
        Engine::from_name(&name).expect("IPHYRE_BENCH_ENGINE: chipmunk, rapier or box2d")
    });
    PhysicsParams {
        engine,
        ..PhysicsParams::with_fps(fps)
    }
}

fn bench(c: &mut Criterion) {
    let games = Games::default_games().expect("built-in games");
    let work = workload(&games);
    eprintln!("engine: {}", params_at(60.0).engine.name());
    one_off(&work, &params_at(60.0));
    one_off(&work, &params_at(10.0));
    let mut g = c.benchmark_group("iphyre");
    g.sample_size(10);
    g.throughput(Throughput::Elements(work.len() as u64));
    for (name, fps, record) in [
        ("60fps_record", 60.0, true),
        ("60fps_outcome", 60.0, false),
        ("10fps_record", 10.0, true),
    ] {
        let params = params_at(fps);
        g.bench_function(name, |b| {
            b.iter(|| {
                for (game, clicks) in &work {
                    episode(game, clicks, &params, record);
                }
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
