//! PHYRE episodes per second, single-threaded, on each engine (Box2D, the default, and rapier2d): status
//! only and with full trace recording (default stride, events, conversion into a `Trace`), over a fixed
//! set of 50 tasks (two per template) × 4 seeded valid actions. Compare with PHYRE 0.2.2's 222 episodes/s
//! status-only (docs/envs/phyre.md §R7).

use criterion::{Criterion, Throughput, criterion_group, criterion_main};

use annotrace::envs::phyre::{
    BallAction, Engine, PhysicsParams, RecordOptions, Task, TaskSet, action_rng, dataset_tasks,
    episode, random_valid_action, trace_of,
};

fn workload() -> Vec<(Task, BallAction)> {
    let set = TaskSet::default_tasks().unwrap();
    let mut out = Vec::new();
    for (i, id) in dataset_tasks(set, 50, &[]).iter().enumerate() {
        let task = set.get(id).unwrap();
        for k in 0..4 {
            let a = random_valid_action(&task, &mut action_rng(0, i as u64, k))
                .unwrap()
                .unwrap();
            out.push((task.clone(), a));
        }
    }
    out
}

fn bench(c: &mut Criterion) {
    let work = workload();
    for (name, engine) in [("box2d", Engine::Box2d), ("rapier", Engine::Rapier)] {
        let params = PhysicsParams {
            engine,
            ..PhysicsParams::default()
        };
        let mut g = c.benchmark_group(format!("phyre/{name}"));
        g.sample_size(10);
        g.throughput(Throughput::Elements(work.len() as u64));
        g.bench_function("episodes_status_only", |b| {
            b.iter(|| {
                let mut solved = 0;
                for (task, a) in &work {
                    solved += usize::from(episode::status(task, a, &params).unwrap().code() == 1);
                }
                solved
            })
        });
        g.bench_function("episodes_recorded_traces", |b| {
            b.iter(|| {
                let mut rows = 0;
                for (task, a) in &work {
                    let r = episode::run(task, a, &params, &RecordOptions::default()).unwrap();
                    rows += trace_of(&r, task, "bench").frame_rows();
                }
                rows
            })
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
