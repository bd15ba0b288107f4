//! Sharded runs: a pipeline computed by separate `annotrace run --shard i/n` processes over one run
//! folder, one of them killed and rerun, then `--finalize`, gives the tables of the single-process run:
//! simulate, annotate and accuracy; an evolve stage run whole by a shard (killed and resumed) before a
//! sharded benchmark; an LLM benchmark asking each request once across shards and replaying byte for byte.

use std::os::unix::fs::MetadataExt;
use std::path::Path;
use std::process::{Child, Stdio};

use crate::common::{Ran, TestRun};

/// simulate (12 scenes in 6 units of 2) → annotate, accuracy → SQL.
pub(crate) const PIPELINE: &str = r#"[pipeline]
name = "p"
seed = 5

[[stage]]
id = "sim"
kind = "simulate"
env = "pooltool"
scenes = 12
shots = 1
scenes_per_shard = 2

[[stage]]
id = "ann"
kind = "annotate"
env = "pooltool"
inputs = ["sim"]

[[stage]]
id = "acc"
kind = "accuracy"
env = "pooltool"
inputs = ["sim"]

[[stage]]
id = "counts"
kind = "sql"
inputs = ["ann"]
sql = "SELECT detector_id, count(*) AS n, sum(end_step - start_step) AS steps FROM annotations GROUP BY detector_id ORDER BY detector_id"
"#;

fn spawn(t: &TestRun, args: &[&str], env: &[(&str, &str)]) -> Child {
    let mut c = t.cmd();
    for (k, v) in env {
        c.env(k, v);
    }
    c.args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("annotrace starts")
}

fn wait(child: Child) -> Ran {
    child.wait_with_output().expect("annotrace ends").into()
}

/// Every published file of a run (relative path → bytes), from its manifest.
fn published(run: &Path) -> Vec<(String, Vec<u8>)> {
    let m = crate::common::read_json(&run.join("manifest.json"));
    let mut out = Vec::new();
    for (_, stage) in m["stages"].as_object().unwrap() {
        assert_eq!(stage["status"], "finished", "{stage}");
        for o in stage["outputs"].as_array().unwrap() {
            let p = o["path"].as_str().unwrap().to_string();
            out.push((p.clone(), std::fs::read(run.join(&p)).unwrap()));
        }
    }
    out.sort();
    out
}

/// CSV with its rows sorted (the header first).
fn sorted(csv: String) -> String {
    let mut lines: Vec<&str> = csv.lines().collect();
    lines[1..].sort_unstable();
    lines.join("\n")
}

/// The tables of the pipeline's run.
pub(crate) const TABLES: [&str; 9] = [
    "scenes",
    "traces",
    "timesteps",
    "frames",
    "events",
    "detectors",
    "annotations",
    "accuracy",
    "counts",
];

/// `detector_calls` without its timing columns.
pub(crate) const CALLS_SQL: &str = "SELECT detector_id, trace_id, label, status, error, error_line, n_patterns FROM detector_calls";

/// The run's tables as `annotrace tables` prints them (names, row counts, schemas) and every table's
/// rows as sorted CSV (`detector_calls` without its timing columns, which differ between any two runs).
pub(crate) fn tables_and_rows(t: &TestRun, run: &str) -> (String, Vec<String>) {
    let tables = t.run(&["tables", "--run", run]);
    tables.ok();
    let mut rows = Vec::new();
    for name in TABLES {
        rows.push(sorted(t.csv(run, &format!("SELECT * FROM {name}"))));
    }
    rows.push(sorted(t.csv(run, CALLS_SQL)));
    (tables.stdout.clone(), rows)
}

#[test]
fn three_shard_processes_one_killed_then_finalize_equal_the_single_process_run() {
    let t = TestRun::new();
    t.write("pipelines/p.toml", PIPELINE);
    t.run(&["run", "pipelines/p.toml", "--run-dir", "runs/single"])
        .ok();

    // Shard 1 owns units 1 and 4 of `sim`; it is killed half-way through the second (one thread, so
    // the order is fixed): unit 1 is finished, unit 4 is half written.
    let killed = t.run_env(
        &[
            "run",
            "pipelines/p.toml",
            "--run-dir",
            "runs/sharded",
            "--shard",
            "1/3",
        ],
        &[
            ("ANNOTRACE_FAULT", "sim:mid-shard=1"),
            ("RAYON_NUM_THREADS", "1"),
        ],
    );
    assert_ne!(killed.code, Some(0), "the fault kills the shard");
    let staged = t.path("runs/sharded/.staging/sim");
    assert!(staged.join("_done/00001.json").exists());
    assert!(!staged.join("_done/00004.json").exists());
    let half_written = t
        .files("runs/sharded/.staging/sim")
        .into_iter()
        .filter(|f| f.contains(".sim.00004.parquet.") && f.ends_with(".tmp"))
        .count();
    assert!(half_written > 0, "unit 4 is half written");
    let kept = staged.join("traces/env=pooltool/sim.00001.parquet");
    let kept_inode = std::fs::metadata(&kept).unwrap().ino();
    // Nothing is published before every slice is done.
    t.run(&["tables", "--run", "runs/sharded"])
        .ok()
        .stdout_has("traces: 0 rows in 0 file(s)");
    t.run(&[
        "run",
        "pipelines/p.toml",
        "--run-dir",
        "runs/sharded",
        "--finalize",
    ])
    .code(1)
    .stderr_has("stage sim: no slice is finished");

    // The three shards as separate processes (shard 1 rerun), then the finalisation.
    let args = |i: &'static str| {
        [
            "run",
            "pipelines/p.toml",
            "--run-dir",
            "runs/sharded",
            "--shard",
            i,
        ]
    };
    let children = [
        spawn(&t, &args("1/3"), &[]),
        spawn(&t, &args("0/3"), &[]),
        spawn(&t, &args("2/3"), &[]),
    ];
    let ran: Vec<Ran> = children.into_iter().map(wait).collect();
    for r in &ran {
        r.ok();
    }
    // The unit finished before the kill was kept, not computed again: the same file was moved into place.
    let published_unit = t.path("runs/sharded/traces/env=pooltool/sim.00001.parquet");
    assert_eq!(
        std::fs::metadata(&published_unit).unwrap().ino(),
        kept_inode
    );
    // The SQL stage is left to --finalize.
    assert!(!t.path("runs/sharded/counts").exists());
    t.run(&[
        "run",
        "pipelines/p.toml",
        "--run-dir",
        "runs/sharded",
        "--finalize",
    ])
    .ok()
    .stderr_has("[counts] done");

    assert_eq!(
        tables_and_rows(&t, "runs/sharded"),
        tables_and_rows(&t, "runs/single")
    );
    // Every published file is byte-identical, except detector_calls (wall and CPU seconds).
    let strip = |v: Vec<(String, Vec<u8>)>| -> Vec<(String, Vec<u8>)> {
        v.into_iter()
            .filter(|(p, _)| !p.starts_with("detector_calls/"))
            .collect()
    };
    let (a, b) = (
        strip(published(&t.path("runs/sharded"))),
        strip(published(&t.path("runs/single"))),
    );
    assert_eq!(
        a.iter().map(|(p, _)| p).collect::<Vec<_>>(),
        b.iter().map(|(p, _)| p).collect::<Vec<_>>()
    );
    for ((p, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "{p} differs from the single-process run");
    }
    // The summaries summed from the slices' records are the single process's.
    let summary = |run: &str, stage: &str| {
        crate::common::read_json(&t.path(run).join("manifest.json"))["stages"][stage]["summary"]
            .clone()
    };
    for stage in ["sim", "acc"] {
        assert_eq!(
            summary("runs/sharded", stage),
            summary("runs/single", stage)
        );
    }
    t.run(&["verify", "--run", "runs/sharded"]).ok();
    // Nothing of the protocol is left but the locks.
    assert!(!t.path("runs/sharded/.staging").exists());
}

#[test]
fn shards_resume_wait_for_missing_slices_and_take_over_absent_ones() {
    let t = TestRun::new();
    t.write("pipelines/p.toml", PIPELINE);
    let run = |extra: &[&str]| {
        let mut a = vec!["run", "pipelines/p.toml", "--run-dir", "runs/r"];
        a.extend_from_slice(extra);
        t.run(&a)
    };
    // One slice of `sim` only: nothing is committed and --finalize names the missing slice.
    run(&["--shard", "0/2", "--until", "sim"])
        .ok()
        .stderr_has("(shard 0/2)");
    run(&["--finalize"])
        .code(1)
        .stderr_has("stage sim: slice(s) 1/2 not finished");
    // Two processes with the same index at once: the second waits for the first, then finds its own
    // slice done.
    let twice = |_| {
        spawn(
            &t,
            &[
                "run",
                "pipelines/p.toml",
                "--run-dir",
                "runs/r",
                "--shard",
                "0/2",
                "--until",
                "sim",
            ],
            &[],
        )
    };
    let duplicates: Vec<Child> = (0..2).map(twice).collect();
    for child in duplicates {
        wait(child).ok();
    }
    // A shard that needs `sim` while slice 1/2 has no process computes that slice itself, commits
    // `sim`, does the same for `ann` (which `acc` waits for, being after it in the run order), and
    // computes its slice of `acc`, the last shardable stage, whose other slice it leaves: no one
    // waits for it.
    run(&["--shard", "0/2"])
        .ok()
        .stderr_has("[sim] shard 0/2: slice 1/2 has no running process; computing it here")
        .stderr_has("[sim] done: 12 pool trace(s)")
        .stderr_has("[ann] shard 0/2: slice 1/2 has no running process; computing it here");
    run(&["--finalize"])
        .code(1)
        .stderr_has("stage acc: slice(s) 1/2 not finished");
    // `--shard auto` from a Slurm array numbered 1..2: task 2 is slice 1/2.
    t.run_env(
        &[
            "run",
            "pipelines/p.toml",
            "--run-dir",
            "runs/r",
            "--shard",
            "auto",
        ],
        &[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "2"),
        ],
    )
    .ok()
    .stderr_has("(shard 1/2)")
    .stderr_has("[acc] done");
    run(&["--finalize"]).ok().stderr_has("[counts] done");
    assert_eq!(
        t.csv("runs/r", "SELECT count(*) AS n FROM traces"),
        "n\n12\n"
    );
}

#[test]
fn shard_options_are_checked() {
    let t = TestRun::new();
    t.write("pipelines/p.toml", PIPELINE);
    for (shard, message) in [
        (
            "3/3",
            "--shard: shard index 3 is out of range for 3 shard(s)",
        ),
        ("0/0", "the shard count must be at least 1"),
        ("one", "bad shard \"one\": expected i/n"),
        ("auto", "--shard auto: none of SLURM_ARRAY_TASK_ID"),
    ] {
        t.run(&["run", "pipelines/p.toml", "--shard", shard])
            .code(2)
            .stderr_has(message);
    }
    t.run_env(
        &["run", "pipelines/p.toml", "--shard", "auto"],
        &[("JOB_COMPLETION_INDEX", "4")],
    )
    .code(2)
    .stderr_has("ANNOTRACE_SHARD_COUNT");
    t.run_env(
        &["run", "pipelines/p.toml", "--shard", "auto"],
        &[
            ("JOB_COMPLETION_INDEX", "4"),
            ("ANNOTRACE_SHARD_COUNT", "4"),
        ],
    )
    .code(2)
    .stderr_has("--shard auto (JOB_COMPLETION_INDEX): shard index 4 is out of range for 4");
    t.run(&["run", "pipelines/p.toml", "--shard", "0/2", "--finalize"])
        .code(2);
}

/// simulate (12 scenes in 6 units) → evolve (offline mutate proposer, 2 labels, tiny budget; run
/// whole by one shard) → benchmark (2 seeds × 3 racks = 6 (seed, task) units, annotated feedback from
/// the grown library) → SQL.
const EVOLVE_BENCH_PIPELINE: &str = r#"[pipeline]
name = "q"
seed = 5

[[stage]]
id = "sim"
kind = "simulate"
env = "pooltool"
scenes = 12
shots = 1
scenes_per_shard = 2

[[stage]]
id = "evo"
kind = "evolve"
inputs = ["sim"]
env = "pooltool"
proposer = "mutate"
labels = ["ball slowing", "cushion rebound"]
budget = 4
parallel = 2
max_traces = 12
time_penalty = false
timeout = 3.0
workers = 1

[[stage]]
id = "bench"
kind = "benchmark"
inputs = ["evo"]
env = "pooltool"
tasks = 3
seeds = 2
attempts = 2
agent = "random"
feedback = "annotations"
library_from = "evo"
workers = 1

[[stage]]
id = "solved"
kind = "sql"
inputs = ["bench"]
sql = "SELECT seed, task, max(CAST(success AS INT)) AS solved, count(*) AS attempts FROM benchmark GROUP BY seed, task ORDER BY seed, task"
"#;

/// The evolve and benchmark tables as sorted CSV, without the columns that hold seconds (they differ
/// between any two runs).
fn evolve_bench_rows(t: &TestRun, run: &str) -> Vec<String> {
    [
        "SELECT * FROM scenes",
        "SELECT * FROM traces",
        "SELECT * FROM events",
        "SELECT * EXCLUDE (mean_time_s, propose_s, eval_s) FROM candidates",
        "SELECT * EXCLUDE (wall_s, propose_s, outside_proposer_share) FROM evolution_labels",
        "SELECT * FROM evolution_histograms",
        "SELECT * FROM evolution_samples",
        "SELECT * FROM evolution_convergence",
        "SELECT * FROM trace_distances",
        "SELECT * FROM benchmark",
        "SELECT * FROM solved",
    ]
    .into_iter()
    .map(|q| sorted(t.csv(run, q)))
    .collect()
}

#[test]
fn evolve_and_benchmark_in_a_sharded_run_equal_the_single_process_run() {
    let t = TestRun::new();
    t.write("pipelines/q.toml", EVOLVE_BENCH_PIPELINE);
    t.run(&["run", "pipelines/q.toml", "--run-dir", "runs/single"])
        .ok();
    let args = |i: &'static str| {
        [
            "run",
            "pipelines/q.toml",
            "--run-dir",
            "runs/sharded",
            "--shard",
            i,
        ]
    };
    // Shard 1 alone: it takes over the absent slices of `sim`, then, waiting for `evo` (one unit,
    // owned by slice 0) before `bench`, computes that slice too and is killed after two saved rounds.
    let killed = t.run_env(&args("1/3"), &[("ANNOTRACE_FAULT", "evo:after-shards=2")]);
    assert_ne!(killed.code, Some(0), "the fault kills the shard");
    let evo = t.path("runs/sharded/.staging/evo/_done");
    assert!(evo.join("L000.R00000.json").exists(), "a round was saved");
    // Rerun, it takes slice 0 of `evo` over again, goes on from the saved rounds, commits `evo`, and
    // is killed in its second benchmark unit (units 1 and 4 are its own: seed 0 task 1, seed 1 task 1).
    let killed = t.run_env(&args("1/3"), &[("ANNOTRACE_FAULT", "bench:mid-shard=1")]);
    assert_ne!(killed.code, Some(0), "the fault kills the shard");
    killed
        .stderr_has("[evo] shard 1/3: slice 0/3 has no running process; computing it here")
        .stderr_has("[evo] done: 2 label(s)");
    let err = &killed.stderr;
    let replayed = err
        .find("[evo] replaying the rounds")
        .expect("the saved rounds are replayed");
    assert!(
        replayed < err.find("[evo] done: slice 0/3 done").unwrap(),
        "{err}"
    );
    let bench = t.path("runs/sharded/.staging/bench/_done");
    assert!(bench.join("00001-s000-t00001.json").exists());
    assert!(!bench.join("00004-s001-t00001.json").exists());
    let kept = t
        .path("runs/sharded/.staging/bench/benchmark/env=pooltool/bench.00001-s000-t00001.parquet");
    let kept_inode = std::fs::metadata(&kept).unwrap().ino();
    t.run(&[
        "run",
        "pipelines/q.toml",
        "--run-dir",
        "runs/sharded",
        "--finalize",
    ])
    .code(1)
    .stderr_has("stage bench: no slice is finished");

    // The three shards as separate processes, then the finalisation.
    let children = [
        spawn(&t, &args("2/3"), &[]),
        spawn(&t, &args("1/3"), &[]),
        spawn(&t, &args("0/3"), &[]),
    ];
    for r in children.into_iter().map(wait) {
        r.ok();
    }
    let published_unit =
        t.path("runs/sharded/benchmark/env=pooltool/bench.00001-s000-t00001.parquet");
    assert_eq!(
        std::fs::metadata(&published_unit).unwrap().ino(),
        kept_inode,
        "the finished unit was kept, not played again"
    );
    assert!(
        !t.path("runs/sharded/solved").exists(),
        "SQL is left to --finalize"
    );
    t.run(&[
        "run",
        "pipelines/q.toml",
        "--run-dir",
        "runs/sharded",
        "--finalize",
    ])
    .ok()
    .stderr_has("[solved] done");

    assert_eq!(
        evolve_bench_rows(&t, "runs/sharded"),
        evolve_bench_rows(&t, "runs/single")
    );
    // Every published file — tables and the exported library folder — is byte-identical, except
    // the two evolve tables with seconds columns (compared above without them).
    let strip = |v: Vec<(String, Vec<u8>)>| -> Vec<(String, Vec<u8>)> {
        v.into_iter()
            .filter(|(p, _)| !p.starts_with("candidates/") && !p.starts_with("evolution_labels/"))
            .collect()
    };
    let (a, b) = (
        strip(published(&t.path("runs/sharded"))),
        strip(published(&t.path("runs/single"))),
    );
    assert_eq!(
        a.iter().map(|(p, _)| p).collect::<Vec<_>>(),
        b.iter().map(|(p, _)| p).collect::<Vec<_>>()
    );
    assert!(a.iter().any(|(p, _)| p.starts_with("exports/evo/library/")));
    assert!(a.iter().any(|(p, _)| p.starts_with("benchmark/")));
    for ((p, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "{p} differs from the single-process run");
    }
    let record = |run: &str, stage: &str| {
        crate::common::read_json(&t.path(run).join("manifest.json"))["stages"][stage].clone()
    };
    // The rows per table the manifest records (the resumed evolve counts its own D_x rows, as the
    // uninterrupted one does; the benchmark sums its units' records).
    for stage in ["sim", "evo", "bench", "solved"] {
        assert_eq!(
            record("runs/sharded", stage)["rows"],
            record("runs/single", stage)["rows"],
            "{stage}"
        );
    }
    let summary = |run: &str| record(run, "bench")["summary"].clone();
    for key in [
        "solved",
        "attempts_played",
        "success_rate",
        "tasks",
        "seeds",
    ] {
        assert_eq!(
            summary("runs/sharded")[key],
            summary("runs/single")[key],
            "{key}"
        );
    }
    let evo = |run: &str| record(run, "evo")["summary"].clone();
    assert_eq!(
        evo("runs/sharded")["dx"]["pairs"],
        evo("runs/single")["dx"]["pairs"]
    );
    assert_eq!(evo("runs/sharded")["dx"]["reused"], false);
    assert_eq!(
        evo("runs/sharded")["labels"].as_array().map(Vec::len),
        Some(2)
    );
    t.run(&["verify", "--run", "runs/sharded"]).ok();
    assert!(!t.path("runs/sharded/.staging").exists());
}

/// A benchmark with the LLM agent (2 seeds × 3 PHYRE tasks, image-only feedback) whose `llm` settings
/// are `llm`.
fn llm_bench_pipeline(llm: &str) -> String {
    format!(
        r#"[pipeline]
name = "l"
seed = 9

[[stage]]
id = "bench"
kind = "benchmark"
env = "phyre"
agent = "llm"
feedback = "image-only"
tasks = 3
seeds = 2
attempts = 3
llm = {{ {llm}, model = "vlm", max_retries = 0 }}
"#
    )
}

#[test]
fn an_llm_benchmark_sharded_asks_each_request_once_and_replays_byte_for_byte() {
    use crate::common::chat_server::{ChatServer, Reply};
    // The answer depends on the request alone (its number of earlier attempts), as a model at
    // temperature 0 with a fixed seed would.
    let server = ChatServer::responder(|s| {
        let turn = s.body["messages"]
            .as_array()
            .map_or(0, |m| m.iter().filter(|m| m["role"] == "assistant").count());
        Reply::chat(&format!("Cell: {}, Radius: 2", 10 + 7 * turn))
    });
    let t = TestRun::new();
    let live = llm_bench_pipeline(&format!("base_url = \"{}\"", server.url()));
    t.write("pipelines/live.toml", &live);
    t.run(&["run", "pipelines/live.toml", "--run-dir", "runs/single"])
        .ok();
    let single_asked = server.seen().len();
    assert!(single_asked >= 6, "{single_asked}");

    // Two shard processes against the endpoint: every request is asked once in all, each process
    // records its own llm_calls files, and the table equals the single process's but for the
    // model's seconds.
    let args =
        |p: &'static str, i: &'static str| ["run", p, "--run-dir", "runs/sharded", "--shard", i];
    let children = [
        spawn(&t, &args("pipelines/live.toml", "0/2"), &[]),
        spawn(&t, &args("pipelines/live.toml", "1/2"), &[]),
    ];
    for r in children.into_iter().map(wait) {
        r.ok();
    }
    t.run(&[
        "run",
        "pipelines/live.toml",
        "--run-dir",
        "runs/sharded",
        "--finalize",
    ])
    .ok();
    assert_eq!(
        server.seen().len(),
        2 * single_asked,
        "each request asked once more"
    );
    let rows = "SELECT * EXCLUDE (seconds) FROM benchmark";
    assert_eq!(
        sorted(t.csv("runs/sharded", rows)),
        sorted(t.csv("runs/single", rows))
    );
    let sessions = t.csv(
        "runs/sharded",
        "SELECT count(DISTINCT session) AS sessions, count(*) AS calls FROM llm_calls",
    );
    assert_eq!(sessions, format!("sessions,calls\n2,{single_asked}\n"));
    drop(server);

    // Sharded again without an endpoint, replaying the single run's calls: the benchmark files are
    // the single run's, byte for byte.
    t.write(
        "pipelines/replay.toml",
        &llm_bench_pipeline("replay = \"runs/single\""),
    );
    let children = [
        spawn(&t, &args("pipelines/replay.toml", "1/2"), &[]),
        spawn(&t, &args("pipelines/replay.toml", "0/2"), &[]),
    ];
    for r in children.into_iter().map(wait) {
        r.ok();
    }
    let bench_files = |run: &str| -> Vec<(String, Vec<u8>)> {
        published(&t.path(run))
            .into_iter()
            .filter(|(p, _)| p.starts_with("benchmark/"))
            .collect()
    };
    let (a, b) = (bench_files("runs/sharded"), bench_files("runs/single"));
    assert_eq!(a.len(), 6, "one file per (seed, task)");
    assert_eq!(
        a.iter().map(|(p, _)| p).collect::<Vec<_>>(),
        b.iter().map(|(p, _)| p).collect::<Vec<_>>()
    );
    for ((p, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "{p}: the replayed file differs");
    }
}

/// simulate → two sibling searches over the same training split (same seed; the islands and the
/// hill-climb strategies), none an input of the other → SQL over both.
const SIBLINGS_PIPELINE: &str = r#"[pipeline]
name = "s"
seed = 5

[[stage]]
id = "sim"
kind = "simulate"
env = "pooltool"
scenes = 12
shots = 1
scenes_per_shard = 2

[[stage]]
id = "evo_a"
kind = "evolve"
inputs = ["sim"]
env = "pooltool"
proposer = "mutate"
labels = ["ball slowing", "cushion rebound"]
budget = 4
parallel = 2
max_traces = 12
time_penalty = false
timeout = 3.0
workers = 1

[[stage]]
id = "evo_b"
kind = "evolve"
inputs = ["sim"]
env = "pooltool"
proposer = "mutate"
strategy = "hill-climb"
labels = ["ball slowing"]
budget = 4
parallel = 2
max_traces = 12
time_penalty = false
timeout = 3.0
workers = 1

[[stage]]
id = "best"
kind = "sql"
inputs = ["evo_a", "evo_b"]
sql = "SELECT run_stage, label, best_nu, accepted FROM evolution_labels ORDER BY run_stage, label"
"#;

#[test]
fn sibling_evolve_stages_run_side_by_side_in_shards_and_equal_the_single_process_run() {
    let t = TestRun::new();
    t.write("pipelines/s.toml", SIBLINGS_PIPELINE);
    t.run(&["run", "pipelines/s.toml", "--run-dir", "runs/single"])
        .ok();
    let args = |i: &'static str| {
        [
            "run",
            "pipelines/s.toml",
            "--run-dir",
            "runs/sharded",
            "--shard",
            i,
        ]
    };
    // Slice 0 owns `evo_a` (unit 0), slice 1 `evo_b` (unit 1): each computes its own search without
    // waiting for the other's.
    let children = [spawn(&t, &args("0/2"), &[]), spawn(&t, &args("1/2"), &[])];
    let ran: Vec<Ran> = children.into_iter().map(wait).collect();
    for r in &ran {
        r.ok();
    }
    ran[0].stderr_has("[evo_a] computing slice 0/2");
    ran[1].stderr_has("[evo_b] computing slice 1/2");
    for r in &ran {
        assert!(
            !r.stderr.lines().any(|l| l.starts_with("[evo_b]")
                && l.contains("waiting for stage(s)")
                && l.contains("evo_a")),
            "evo_b waited for evo_a: {}",
            r.stderr
        );
    }
    t.run(&[
        "run",
        "pipelines/s.toml",
        "--run-dir",
        "runs/sharded",
        "--finalize",
    ])
    .ok()
    .stderr_has("[best] done");

    let rows = |run: &str| -> Vec<String> {
        [
            "SELECT * EXCLUDE (mean_time_s, propose_s, eval_s) FROM candidates",
            "SELECT * EXCLUDE (wall_s, propose_s, outside_proposer_share) FROM evolution_labels",
            "SELECT * FROM evolution_histograms",
            "SELECT * FROM evolution_convergence",
            "SELECT * FROM trace_distances",
            "SELECT * FROM best",
        ]
        .into_iter()
        .map(|q| sorted(t.csv(run, q)))
        .collect()
    };
    assert_eq!(rows("runs/sharded"), rows("runs/single"));
    let strip = |v: Vec<(String, Vec<u8>)>| -> Vec<(String, Vec<u8>)> {
        v.into_iter()
            .filter(|(p, _)| !p.starts_with("candidates/") && !p.starts_with("evolution_labels/"))
            .collect()
    };
    let (a, b) = (
        strip(published(&t.path("runs/sharded"))),
        strip(published(&t.path("runs/single"))),
    );
    assert_eq!(
        a.iter().map(|(p, _)| p).collect::<Vec<_>>(),
        b.iter().map(|(p, _)| p).collect::<Vec<_>>()
    );
    for ((p, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "{p} differs from the single-process run");
    }
    // The shared D_x matrix is written once, by the first search in run order; the second reuses it,
    // in both runs.
    let dx: Vec<&String> = a
        .iter()
        .map(|(p, _)| p)
        .filter(|p| p.starts_with("trace_distances/"))
        .collect();
    assert!(
        !dx.is_empty() && dx.iter().all(|p| p.contains("/evo_a.")),
        "{dx:?}"
    );
    let record = |run: &str, stage: &str| {
        crate::common::read_json(&t.path(run).join("manifest.json"))["stages"][stage].clone()
    };
    for stage in ["evo_a", "evo_b"] {
        assert_eq!(
            record("runs/sharded", stage)["rows"],
            record("runs/single", stage)["rows"],
            "{stage}"
        );
    }
    assert_eq!(
        record("runs/sharded", "evo_b")["summary"]["dx"]["reused"],
        true
    );
    t.run(&["verify", "--run", "runs/sharded"]).ok();
}
