//! Benchmarks of the foundation: importing paper-format JSON into the Parquet tables (frame rows per
//! second), and a SQL group-by over one million frame rows.
//!
//! `cargo bench --bench tables`. As a yardstick for the import, the same JSON Lines bytes are also
//! parsed into `serde_json::Value` trees and dropped: the cost of reading the JSON and nothing else.

use std::path::Path;

use annotrace::pipeline::{PipelineSpec, RunOptions, run};
use annotrace::query::RunQuery;
use annotrace::store::RunDir;
use annotrace::testutil::synthetic_trace;
use annotrace::trace::{Env, json};
use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};

/// Writes `traces` pool traces of `steps` × 16 balls as JSON Lines; returns the frame row count.
fn write_jsonl(path: &Path, traces: usize, steps: usize) -> u64 {
    let mut text = String::new();
    for i in 0..traces {
        text.push_str(&json::to_value(&synthetic_trace(Env::Pooltool, i, steps, 16)).to_string());
        text.push('\n');
    }
    std::fs::write(path, text).unwrap();
    (traces * steps * 16) as u64
}

fn import(dir: &Path, input: &Path) {
    let text = format!(
        "[[stage]]\nid = \"import\"\nkind = \"import\"\nenv = \"pooltool\"\npaths = [\"{}\"]\n",
        input.display()
    );
    let spec = PipelineSpec::from_toml(&dir.join("bench.toml"), &text).unwrap();
    let opts = RunOptions {
        run_dir: Some(dir.join("run")),
        ..RunOptions::default()
    };
    run(&spec, &opts, &()).unwrap();
}

fn bench_import(c: &mut Criterion) {
    let data = tempfile::tempdir().unwrap();
    let input = data.path().join("traces.jsonl");
    let rows = write_jsonl(&input, 40, 250);
    let mut g = c.benchmark_group("import");
    g.sample_size(10);
    g.throughput(Throughput::Elements(rows));
    g.bench_function("pooltool_jsonl_160k_frame_rows", |b| {
        b.iter_batched(
            || tempfile::tempdir().unwrap(),
            |dir| import(dir.path(), &input),
            BatchSize::PerIteration,
        )
    });
    let bytes = std::fs::read(&input).unwrap();
    g.bench_function("serde_json_value_parse_only", |b| {
        b.iter(|| {
            for line in bytes.split(|&c| c == b'\n').filter(|l| !l.is_empty()) {
                let v: serde_json::Value = serde_json::from_slice(line).unwrap();
                std::hint::black_box(v);
            }
        })
    });
    g.finish();
}

fn bench_group_by(c: &mut Criterion) {
    let data = tempfile::tempdir().unwrap();
    let input = data.path().join("traces.jsonl");
    // 250 traces × 250 steps × 16 balls = 1,000,000 frame rows.
    let rows = write_jsonl(&input, 250, 250);
    import(data.path(), &input);
    let q = RunQuery::open(&RunDir::new(data.path().join("run"))).unwrap();
    let mut g = c.benchmark_group("sql");
    g.sample_size(10);
    g.throughput(Throughput::Elements(rows));
    g.bench_function("group_by_object_1m_frame_rows", |b| {
        b.iter(|| {
            let r = q
                .sql("SELECT object_id, count(*) AS n, avg(sqrt(vx * vx + vy * vy)) AS speed, max(x) AS max_x FROM frames GROUP BY object_id")
                .unwrap();
            assert_eq!(r.num_rows(), 16);
        })
    });
    g.bench_function("group_by_trace_1m_frame_rows", |b| {
        b.iter(|| {
            let r = q.sql("SELECT trace_id, avg(x) AS mean_x, max(t) AS t_end FROM frames GROUP BY trace_id").unwrap();
            assert_eq!(r.num_rows(), 250);
        })
    });
    g.finish();
}

criterion_group!(benches, bench_import, bench_group_by);
criterion_main!(benches);
