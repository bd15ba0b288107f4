//! `annotrace simulate` and the billiards engine behind it: replay against pooltool 0.6.0 reference
//! shots, the dataset mode end to end (simulate → query), determinism across thread counts, resumption
//! after a kill, replay mode, and bad input.

use std::collections::BTreeMap;

use annotrace::envs::pool::reference::{RefTrace, compare};
use annotrace::envs::pool::{SimOptions, Status, resample, simulate};
use serde_json::Value;

use crate::common::{TestRun, repo};

/// Replays one trimmed pooltool 0.6.0 shot (`tests/data/pooltool_ref/`, provenance in
/// `data/README.md`) and checks: the ordered ball–ball / cushion / pocket events (kinds and ids)
/// exactly; their times within 1e-4 s (the traces round initial positions to 1e-10 m, which rack
/// contacts amplify); final positions within 1 mm; the count of all events (transitions included);
/// and the dt resampler against pooltool's `continuize` samples within 0.1 mm.
fn replay(name: &str) {
    let path = repo().join(format!("tests/data/pooltool_ref/{name}.json"));
    let text = std::fs::read_to_string(&path).unwrap();
    let v: Value = serde_json::from_str(&text).unwrap();
    let r = RefTrace::from_value(&v).unwrap();
    let sim = simulate(&r.system, &r.shot, &SimOptions::default()).unwrap();
    assert_eq!(sim.status, Status::Settled);
    let c = compare(&r, &sim);
    assert!(
        c.sequence_equal,
        "{name}: collision sequence differs: {c:?}"
    );
    assert!(
        c.max_dt < 1e-4,
        "{name}: event times differ by {} s",
        c.max_dt
    );
    assert!(
        c.max_final_dist < 1e-3,
        "{name}: final positions differ by {} m",
        c.max_final_dist
    );
    assert_eq!(c.n_all_ref, c.n_all_sim, "{name}: total event count");
    assert!(
        (sim.t_end - r.t_final).abs() < 1e-4,
        "{name}: t_end {} vs {}",
        sim.t_end,
        r.t_final
    );
    // The trimmed files keep every 25th continuize sample and the last one.
    let dt = v["meta"]["dt"].as_f64().unwrap();
    let samples = resample(&sim, dt);
    let steps = v["timesteps"].as_array().unwrap();
    assert_eq!(
        samples.len(),
        (r.t_final / dt).floor() as usize + 2,
        "{name}: sample count"
    );
    let mut worst: f64 = 0.0;
    for (k, step) in steps.iter().enumerate() {
        let s = if k == steps.len() - 1 {
            samples.last().unwrap()
        } else {
            &samples[k * 25]
        };
        assert!((s.t - step["t"].as_f64().unwrap()).abs() < 1e-6);
        for (b, id) in sim.ball_ids.iter().enumerate() {
            let p = &step["balls"][id]["pos"];
            for axis in 0..2 {
                worst = worst.max((s.balls[b].r[axis] - p[axis].as_f64().unwrap()).abs());
            }
        }
    }
    assert!(
        worst < 1e-4,
        "{name}: resampled positions differ by {worst} m"
    );
}

#[test]
fn replay_pooltool_shot_001_ball_ball_chain() {
    replay("shot_001");
}

#[test]
fn replay_pooltool_shot_005_single_cushion() {
    replay("shot_005");
}

#[test]
fn replay_pooltool_shot_006_stronge_stick_branches() {
    replay("shot_006");
}

#[test]
fn replay_pooltool_shot_023_jaws_and_pocket() {
    replay("shot_023");
}

#[test]
fn replay_pooltool_shot_032_jaw() {
    replay("shot_032");
}

#[test]
fn replay_pooltool_shot_058_pocket() {
    replay("shot_058");
}

/// Every file below `dir` with its bytes.
fn tree(t: &TestRun, dir: &str) -> BTreeMap<String, Vec<u8>> {
    t.files(dir)
        .into_iter()
        .filter(|f| f.ends_with(".parquet"))
        .map(|f| {
            let bytes = std::fs::read(t.path(dir).join(&f)).unwrap();
            (f, bytes)
        })
        .collect()
}

#[test]
fn dataset_mode_writes_queryable_tables() {
    let t = TestRun::new();
    t.run(&[
        "simulate", "--env", "pooltool", "--scenes", "6", "--shots", "2", "--seed", "5", "--run",
        "r", "--dt", "0.05",
    ])
    .ok()
    .stdout_has("simulated 12 pooltool trace(s)");
    let csv = t.csv(
        "r",
        "SELECT count(*) AS n, count(DISTINCT scene_id) AS scenes FROM traces",
    );
    assert_eq!(csv.lines().nth(1), Some("12,6"), "{csv}");
    let csv = t.csv("r", "SELECT count(*) FROM scenes");
    assert_eq!(csv.lines().nth(1), Some("6"));
    // Every trace starts with the cue strike and ends with the outcome; agents are extracted.
    let csv = t.csv(
        "r",
        "SELECT kind, agents FROM events WHERE seq = 1 GROUP BY kind, agents",
    );
    assert_eq!(
        csv.lines().nth(1),
        Some("physics_stick_ball,\"[cue_stick, cue]\""),
        "{csv}"
    );
    let csv = t.csv("r", "SELECT DISTINCT kind FROM events ORDER BY kind");
    assert!(
        csv.contains("physics_ball_ball")
            && csv.contains("physics_sliding_rolling")
            && csv.contains("shot_outcome"),
        "{csv}"
    );
    // Ten balls at every step, with the paper's motion-state fields.
    let csv = t.csv("r", "SELECT min(n_objects), max(n_objects) FROM timesteps");
    assert_eq!(csv.lines().nth(1), Some("10,10"));
    let csv = t.csv("r", "SELECT DISTINCT motion_state_code, motion_state FROM frames WHERE motion_state = 'stationary'");
    assert_eq!(csv.lines().nth(1), Some("0,stationary"));
    let csv = t.csv("r", "SELECT count(*) FROM traces WHERE terminal_status IN ('potted_9', 'no_pocket', 'scratch', 'pocketed_other')");
    assert_eq!(csv.lines().nth(1), Some("12"));
    // The same command again is cached.
    t.run(&[
        "simulate", "--scenes", "6", "--shots", "2", "--seed", "5", "--run", "r", "--dt", "0.05",
    ])
    .ok()
    .stdout_has("already simulated");
}

#[test]
fn output_is_byte_identical_whatever_the_thread_count() {
    let t = TestRun::new();
    let args = |run: &'static str| {
        vec![
            "simulate",
            "--scenes",
            "5",
            "--shots",
            "1",
            "--seed",
            "9",
            "--scenes-per-shard",
            "2",
            "--dt",
            "0.1",
            "--run",
            run,
        ]
    };
    t.run_env(&args("one"), &[("RAYON_NUM_THREADS", "1")]).ok();
    t.run_env(&args("two"), &[("RAYON_NUM_THREADS", "2")]).ok();
    let (a, b) = (tree(&t, "one"), tree(&t, "two"));
    assert_eq!(a.len(), 15, "3 shards × 5 tables: {:?}", a.keys());
    assert_eq!(a, b);
}

/// One shard of 11 scenes × 2 shots: with three threads its items are simulated in chunks of 6 on
/// every thread while the shard's thread writes the chunk before; the file is the one-thread file.
#[test]
fn one_shard_simulated_on_several_threads_is_the_one_thread_shard() {
    let t = TestRun::new();
    let args = |run: &'static str| {
        vec![
            "simulate",
            "--scenes",
            "11",
            "--shots",
            "2",
            "--seed",
            "12",
            "--scenes-per-shard",
            "11",
            "--dt",
            "0.1",
            "--run",
            run,
        ]
    };
    t.run_env(&args("one"), &[("RAYON_NUM_THREADS", "1")]).ok();
    t.run_env(&args("three"), &[("RAYON_NUM_THREADS", "3")])
        .ok();
    let (a, b) = (tree(&t, "one"), tree(&t, "three"));
    assert_eq!(a.len(), 5, "1 shard × 5 tables: {:?}", a.keys());
    assert_eq!(a, b);
    t.run(&[
        "query",
        "--run",
        "three",
        "--format",
        "csv",
        "select count(*) as n from traces",
    ])
    .ok()
    .stdout_has("22");
}

#[test]
fn a_killed_simulation_resumes_to_the_same_tables() {
    let t = TestRun::new();
    let pipeline = "[pipeline]\nname = \"p\"\nseed = 4\n\n[[stage]]\nid = \"sim\"\nkind = \"simulate\"\nscenes = 6\nshots = 1\ndt = 0.1\nscenes_per_shard = 2\n";
    t.write("pipelines/p.toml", pipeline);
    let killed = t.run_env(
        &["run", "pipelines/p.toml", "--run-dir", "killed"],
        &[
            ("ANNOTRACE_FAULT", "sim:after-shards=1"),
            ("RAYON_NUM_THREADS", "1"),
        ],
    );
    assert_ne!(killed.code, Some(0), "the fault stops the run");
    t.run(&["run", "pipelines/p.toml", "--run-dir", "killed"])
        .ok();
    t.run(&["run", "pipelines/p.toml", "--run-dir", "fresh"])
        .ok();
    let (a, b) = (tree(&t, "killed"), tree(&t, "fresh"));
    assert_eq!(a.len(), 15);
    assert_eq!(a, b);
}

const SCENE: &str = r#"{"scene_id": "corner", "balls": [{"id": "cue", "x": 0.5, "y": 1.2}, {"id": "9", "x": 0.75, "y": 1.6}]}"#;

#[test]
fn replay_mode_simulates_one_scene_and_shot() {
    let t = TestRun::new();
    t.write("scene.json", SCENE);
    // φ = 57.1° sends the cue ball into the 9-ball's ghost-ball spot for the right-top pocket.
    t.run(&[
        "simulate",
        "--scene",
        "scene.json",
        "--shot",
        r#"{"V0": 2.5, "phi": 57.1, "theta": 0, "a": 0, "b": 0}"#,
        "--run",
        "r",
    ])
    .ok()
    .stdout_has("simulated 1 pooltool trace(s)");
    let csv = t.csv("r", "SELECT scene_id, success, terminal_status FROM traces");
    assert_eq!(csv.lines().nth(1), Some("corner,true,potted_9"), "{csv}");
    let csv = t.csv(
        "r",
        "SELECT agents FROM events WHERE kind = 'physics_ball_pocket'",
    );
    assert_eq!(csv.lines().nth(1), Some("\"[9, rt]\""), "{csv}");
}

#[test]
fn bad_input_names_the_fault_exits_2_and_writes_nothing() {
    let t = TestRun::new();
    let shot = r#"{"V0": 2, "phi": 90}"#;
    t.write("notjson.json", "balls: cue");
    t.run(&[
        "simulate",
        "--scene",
        "notjson.json",
        "--shot",
        shot,
        "--run",
        "r",
    ])
    .code(2)
    .stderr_has("notjson.json");
    t.write(
        "off.json",
        r#"{"balls": [{"id": "cue", "x": 1.5, "y": 0.5}]}"#,
    );
    t.run(&[
        "simulate", "--scene", "off.json", "--shot", shot, "--run", "r",
    ])
    .code(2)
    .stderr_has("balls[0].x")
    .stderr_has("off the table");
    t.write(
        "overlap.json",
        r#"{"balls": [{"id": "cue", "x": 0.5, "y": 0.5}, {"id": "1", "x": 0.52, "y": 0.5}]}"#,
    );
    t.run(&[
        "simulate",
        "--scene",
        "overlap.json",
        "--shot",
        shot,
        "--run",
        "r",
    ])
    .code(2)
    .stderr_has("overlaps");
    t.write("scene.json", SCENE);
    t.run(&[
        "simulate",
        "--scene",
        "scene.json",
        "--shot",
        r#"{"V0": 2, "phi": 90, "a": 0.9, "b": 0.9}"#,
        "--run",
        "r",
    ])
    .code(2)
    .stderr_has("shot")
    .stderr_has("a² + b² must be < 1");
    t.run(&[
        "simulate",
        "--scene",
        "scene.json",
        "--shot",
        r#"{"V0": -1, "phi": 90}"#,
        "--run",
        "r",
    ])
    .code(2)
    .stderr_has("V0");
    t.run(&[
        "simulate",
        "--scene",
        "missing.json",
        "--shot",
        shot,
        "--run",
        "r",
    ])
    .code(2)
    .stderr_has("missing.json");
    assert!(!t.path("r").exists(), "nothing is written on bad input");
}

/// Numbers that would exhaust the machine (a reliability campaign found each one allocating until the
/// kernel killed the process, or writing NaN states) are refused before anything is allocated or
/// written, naming the flag and the limit.
#[test]
fn absurd_numbers_are_refused_before_allocating() {
    let t = TestRun::new();
    t.write("scene.json", SCENE);
    let cases: &[(&[&str], &str)] = &[
        (
            &["--dt", "1e-7"],
            "--dt: 0.0000001 s gives up to 600000000 timesteps per shot",
        ),
        (&["--dt", "1e-9", "--max-time", "5"], "the limit is 1000000"),
        (
            &["--scenes", "5000000000000"],
            "is over the limit of 100000000 traces per stage",
        ),
        (
            &["--scenes", "100000000", "--shots", "100000000"],
            "--shots: 100000000 is over the limit of 1000000 per scene",
        ),
        (
            &["--env", "phyre", "--scenes", "200000", "--shots", "1000"],
            "over the limit of 100000000 traces",
        ),
        (
            &[
                "--scene",
                "scene.json",
                "--shot",
                r#"{"V0": 1e308, "phi": 90}"#,
            ],
            "V0 must be in [0, 20] m/s",
        ),
    ];
    for (flags, message) in cases {
        let mut args = vec!["simulate", "--run", "r"];
        args.extend_from_slice(flags);
        t.run(&args).code(2).stderr_has(message);
    }
    assert!(!t.path("r").exists(), "nothing is written on bad input");
}

#[test]
fn a_second_dataset_with_the_same_seed_is_refused() {
    let t = TestRun::new();
    t.run(&[
        "simulate", "--scenes", "2", "--seed", "5", "--dt", "0.1", "--run", "r",
    ])
    .ok();
    t.run(&[
        "simulate", "--scenes", "3", "--seed", "5", "--dt", "0.1", "--run", "r",
    ])
    .code(2)
    .stderr_has("\"pool-5-000000-000\" is already in the run");
    t.run(&[
        "simulate", "--scenes", "3", "--seed", "6", "--dt", "0.1", "--run", "r",
    ])
    .ok();
    let csv = t.csv("r", "SELECT count(*) FROM traces");
    assert_eq!(csv.lines().nth(1), Some("5"));
}

/// `envs::pool::dataset_trace` (what the benches use) is the trace `annotrace simulate --seed` writes.
#[test]
fn dataset_trace_is_what_simulate_writes() {
    use annotrace::envs::pool::{PoolConfig, TraceOptions, dataset_trace};
    let t = TestRun::new();
    t.run(&["simulate", "--run", "r", "--scenes", "2", "--seed", "7"])
        .ok();
    let exported = t.run(&["export", "--run", "r", "--trace", "pool-7-000001-000"]);
    exported.ok();
    let from_cli: Value = serde_json::from_str(&exported.stdout).unwrap();
    let trace = dataset_trace(&PoolConfig::default_7ft(), 7, 1, &TraceOptions::default()).unwrap();
    assert_eq!(from_cli, annotrace::trace::json::to_value(&trace));
}
