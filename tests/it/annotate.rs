//! `annotrace annotate` / `accuracy` and the built-in pooltool library on simulated shots with known
//! events.

use std::path::Path;
use std::time::Duration;

use annotrace::detect::{CandidateStatus, Library, SandboxLimits, WorkerPool};
use annotrace::envs::pool::{
    PoolConfig, Scene, Shot, SimOptions, TraceOptions, aim, simulate, trace_of,
};
use annotrace::trace::Trace;

use crate::common::TestRun;

fn library() -> Library {
    Library::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("data/libraries/pooltool")).unwrap()
}

/// The cue ball drives the 9-ball straight into the right-top pocket (the to_trace test's scene).
fn straight_pot(v0: f64, b: f64, dt: f64) -> Trace {
    let c = PoolConfig::default_7ft();
    let scene = Scene::from_json_str(
        r#"{"balls":[{"id":"cue","x":0.5,"y":1.2},{"id":"9","x":0.75,"y":1.6}]}"#,
        &c,
    )
    .unwrap();
    let phi = aim::ghost_ball(&scene, &c, "9", "rt").unwrap();
    let shot = Shot {
        v0,
        phi,
        theta: 0.0,
        a: 0.0,
        b,
    };
    let sim = simulate(&scene.system(&c).unwrap(), &shot, &SimOptions::default()).unwrap();
    trace_of(
        &sim,
        &scene,
        &shot,
        &format!("pot-{v0}-{b}-{dt}"),
        &TraceOptions { dt },
    )
}

/// Per trace: (detector label, pattern objects, start step, end step) for every pattern found.
type Found = Vec<Vec<(String, Vec<String>, i64, i64)>>;

fn run_library(traces: &[Trace]) -> (Library, Found) {
    let lib = library();
    let pool = WorkerPool::new(SandboxLimits {
        workers: 2,
        call_timeout: Duration::from_secs(20),
        ..SandboxLimits::default()
    })
    .unwrap();
    let batch = pool.run(&lib.detectors, traces);
    let mut per_trace = vec![Vec::new(); traces.len()];
    for r in &batch.results {
        assert_eq!(
            r.status,
            CandidateStatus::Ok,
            "{}: {:?}",
            lib.detectors[r.detector].label,
            r.status
        );
        for p in &r.patterns {
            per_trace[r.trace].push((
                lib.detectors[r.detector].label.clone(),
                p.objects(),
                p.start_step,
                p.end_step,
            ));
        }
    }
    (lib, per_trace)
}

fn count(found: &[(String, Vec<String>, i64, i64)], label: &str) -> usize {
    found.iter().filter(|f| f.0 == label).count()
}

#[test]
fn the_pooltool_library_finds_the_known_events_of_a_straight_pot() {
    let traces = [
        straight_pot(2.5, 0.0, 0.01),
        straight_pot(2.5, 0.5, 0.1),
        straight_pot(0.4, 0.0, 0.01),
    ];
    let (_, found) = run_library(&traces);
    let pot = &found[0];
    // One strike at step 0, one cue-9 collision, the 9 pocketed, no cushion (a clean pot).
    let strike: Vec<_> = pot.iter().filter(|f| f.0 == "cue strike").collect();
    assert_eq!(strike.len(), 1);
    assert_eq!(
        (strike[0].2, strike[0].1.clone()),
        (0, vec!["cue".to_string()])
    );
    let hit: Vec<_> = pot.iter().filter(|f| f.0 == "ball collision").collect();
    assert_eq!(hit.len(), 1, "{pot:?}");
    let mut balls = hit[0].1.clone();
    balls.sort();
    assert_eq!(balls, vec!["9".to_string(), "cue".to_string()]);
    let t_hit = traces[0]
        .events
        .iter()
        .find(|e| e.kind == "physics_ball_ball")
        .and_then(|e| e.t)
        .unwrap();
    let step_of = |s: i64| traces[0].timesteps.iter().find(|t| t.index == s).unwrap().t;
    assert!(step_of(hit[0].2) <= t_hit && t_hit <= step_of(hit[0].3));
    assert!(hit[0].3 - hit[0].2 <= 1, "narrowest span: {hit:?}");
    let pocketed: Vec<_> = pot.iter().filter(|f| f.0 == "ball pocketed").collect();
    assert_eq!(pocketed.len(), 1);
    assert!(pocketed[0].1.contains(&"9".to_string()));
    assert!(count(pot, "sliding ball") >= 2 && count(pot, "rolling ball") >= 1);
    assert_eq!(
        count(pot, "spin shot"),
        0,
        "a centre-ball hit is not a spin shot"
    );
    assert_eq!(count(pot, "gentle touch"), 0, "2.5 m/s is not gentle");
    // The same pot with follow at coarse frames: a spin shot, still one collision and one pocketing.
    let follow = &found[1];
    assert_eq!(count(follow, "spin shot"), 1);
    assert_eq!(count(follow, "ball collision"), 1);
    // A soft shot: the collision is a gentle touch.
    assert!(count(&found[2], "gentle touch") <= count(&found[2], "ball collision"));
}

#[test]
fn annotate_writes_the_tables_and_accuracy_scores_them() {
    let run = TestRun::new();
    let dir = run.path("r");
    run.run(&[
        "simulate",
        "--run",
        dir.to_str().unwrap(),
        "--scenes",
        "6",
        "--seed",
        "5",
        "--dt",
        "0.05",
    ])
    .ok();
    let out = run.run(&["annotate", "--run", dir.to_str().unwrap(), "--workers", "2"]);
    out.ok()
        .stdout_has("annotated 6 pooltool trace(s) with 12 detector(s)")
        .stdout_has("seccomp");
    let q = run.run(&[
        "query",
        "SELECT count(*) AS n, count(DISTINCT detector_id) AS d FROM detector_calls WHERE status = 'ok'",
        "--run",
        dir.to_str().unwrap(),
    ]);
    q.ok().stdout_has("| 72 | 12 |");
    let q = run.run(&[
        "query",
        "SELECT count(*) AS n FROM detectors",
        "--run",
        dir.to_str().unwrap(),
    ]);
    q.ok().stdout_has("| 12 |");
    let q = run.run(&[
        "query",
        "SELECT count(*) AS n FROM annotations WHERE label = 'cue strike' AND start_step = 0",
        "--run",
        dir.to_str().unwrap(),
    ]);
    q.ok().stdout_has("| 6 |");
    // Running it again replaces the stage's tables instead of adding to them.
    run.run(&[
        "annotate",
        "--run",
        dir.to_str().unwrap(),
        "--workers",
        "2",
        "-q",
    ])
    .ok();
    run.run(&[
        "query",
        "SELECT count(*) AS n FROM detectors",
        "--run",
        dir.to_str().unwrap(),
    ])
    .ok()
    .stdout_has("| 12 |");
    // The annotated trace as text for language models, with a token estimate.
    let shown = run.run(&[
        "show",
        "--run",
        dir.to_str().unwrap(),
        "--trace",
        "pool-5-000000-000",
    ]);
    shown
        .ok()
        .stdout_has("trace pool-5-000000-000 (pooltool, task pool-5-000000)")
        .stdout_has("scene: 10 balls: cue (")
        .stdout_has("\n0 t0.00 cue strike: cue struck cue ball")
        .stdout_has("# tokens: ");
    run.run(&["show", "--run", dir.to_str().unwrap(), "--trace", "nope"])
        .code(2)
        .stderr_has("no trace");
    let acc = run.run(&[
        "accuracy",
        "--run",
        dir.to_str().unwrap(),
        "--workers",
        "2",
        "-q",
    ]);
    acc.ok()
        .stdout_has("| cue strike | 6 | 6 | 6 | 0 | 0 | 1.000 | 1.000 | 1.000 |");
}

#[test]
fn a_library_that_is_not_there_is_an_input_error() {
    let run = TestRun::new();
    let dir = run.path("r");
    run.run(&[
        "simulate",
        "--run",
        dir.to_str().unwrap(),
        "--scenes",
        "1",
        "--dt",
        "0.1",
    ])
    .ok();
    run.run(&[
        "annotate",
        "--run",
        dir.to_str().unwrap(),
        "--library",
        "nowhere",
    ])
    .code(2)
    .stderr_has("library.toml");
}

#[test]
fn detectors_see_the_paper_dict_whichever_way_the_trace_travels() {
    // A pooltool trace goes to the worker by columns; one with an unknown object field as JSON, as do
    // other environments' traces. All must arrive as exactly the paper's dict (values and key order).
    let plain = straight_pot(2.5, 0.3, 0.1);
    let mut odd = plain.clone();
    odd.trace_id = "odd".into();
    odd.timesteps[0].objects[0]
        .extra
        .insert("note".into(), serde_json::json!("x"));
    odd.timesteps[1]
        .extra
        .insert("state".into(), serde_json::json!({"k": [1, 2]}));
    fn traces_base_clone(t: &Trace) -> Trace {
        let mut c = t.clone();
        c.timesteps[0].objects[0].extra.clear();
        c
    }
    let echo = annotrace::detect::Detector::new(
        annotrace::trace::Env::Pooltool,
        "echo",
        "def find_pattern(trace):\n    return [{'label': 'echo', 'start_timestep': 0, 'end_timestep': 0, 'parameters': {'object_details': {}, 'trace': trace}}]\n",
        "test",
    );
    let pool = WorkerPool::new(SandboxLimits {
        workers: 1,
        ..SandboxLimits::default()
    })
    .unwrap();
    // Only a timestep field: still by columns, with the field in place.
    let mut stepped = traces_base_clone(&odd);
    stepped.trace_id = "stepped".into();
    // PHYRE and I-PHYRE traces travel as JSON with repeated objects (static bodies) sent once.
    let phyre = crate::common::example_trace(annotrace::trace::Env::Phyre);
    let iphyre = crate::common::example_trace(annotrace::trace::Env::Iphyre);
    let traces = [plain, odd, stepped, phyre, iphyre];
    let batch = pool.run(&[echo], &traces);
    for (r, t) in batch.results.iter().zip(&traces) {
        assert_eq!(r.status, CandidateStatus::Ok, "{r:?}");
        let got = serde_json::to_string(&r.patterns[0].parameters["trace"]).unwrap();
        let want = serde_json::to_string(&annotrace::trace::json::to_value(t)).unwrap();
        assert_eq!(got, want, "trace {}", t.trace_id);
        assert!(t.trace_id != "stepped" || got.contains(r#""state":{"k":[1,2]}"#));
    }
}

#[test]
fn without_an_event_log_the_contacts_are_inferred_from_the_timesteps() {
    let mut pot = straight_pot(2.5, 0.0, 0.01);
    pot.events.clear();
    let (_, found) = run_library(&[pot]);
    let found = &found[0];
    assert_eq!(count(found, "cue strike"), 1, "{found:?}");
    let hit: Vec<_> = found.iter().filter(|f| f.0 == "ball collision").collect();
    assert_eq!(hit.len(), 1, "{found:?}");
    assert!(hit[0].1.contains(&"9".to_string()) && hit[0].1.contains(&"cue".to_string()));
    let pocketed: Vec<_> = found.iter().filter(|f| f.0 == "ball pocketed").collect();
    assert_eq!(pocketed.len(), 1);
    assert!(pocketed[0].1.contains(&"9".to_string()));
    assert_eq!(count(found, "cushion rebound"), 0, "{found:?}");
    assert!(count(found, "rolling ball") >= 1 && count(found, "sliding ball") >= 1);
}

#[test]
fn an_imported_file_set_is_annotated_as_the_pool_annotates_its_traces() {
    // 150 shots in one imported file set. The stage takes the set's rows in the order the importer
    // wrote them (grouped by trace, in step order) without sorting them, and rebuilds each trace
    // from them: what the detectors find must be what they find on the traces themselves.
    let traces: Vec<Trace> = (0..150)
        .map(|i| straight_pot(0.6 + 0.02 * i as f64, [-0.3, 0.0, 0.3][i % 3], 0.05))
        .collect();
    let run = TestRun::new();
    let src = run.write_jsonl("shots.jsonl", &traces);
    let dir = run.path("r");
    let dir = dir.to_str().unwrap();
    run.run(&[
        "import",
        "--env",
        "pooltool",
        src.to_str().unwrap(),
        "--run",
        dir,
        "-q",
    ])
    .ok();
    run.run(&["annotate", "--run", dir, "--workers", "2"])
        .ok()
        .stdout_has("annotated 150 pooltool trace(s) with 12 detector(s)");
    let mut stored: Vec<String> = run
        .csv(
            dir,
            "SELECT trace_id, label, start_step, end_step FROM annotations",
        )
        .lines()
        .skip(1)
        .map(str::to_string)
        .collect();
    stored.sort();
    let (_, found) = run_library(&traces);
    let mut expected: Vec<String> = found
        .iter()
        .zip(&traces)
        .flat_map(|(f, t)| {
            f.iter()
                .map(move |(label, _, s, e)| format!("{},{label},{s},{e}", t.trace_id))
        })
        .collect();
    expected.sort();
    assert!(expected.len() > 150, "{} patterns", expected.len());
    assert_eq!(stored, expected);
    // Every call is a row, every trace has the 12.
    run.run(&[
        "query",
        "SELECT count(*) AS n, count(DISTINCT trace_id) AS t FROM detector_calls WHERE status = 'ok'",
        "--run",
        dir,
    ])
    .ok()
    .stdout_has("| 1800 | 150 |");
}

/// The rows of a finished `annotate` stage, sorted, without the timing columns of `detector_calls`.
fn annotate_rows(t: &TestRun, run: &str) -> (String, String) {
    (
        t.csv(
            run,
            "SELECT detector_id, trace_id, label, seq, start_step, end_step, objects, parameters, \
             activation FROM annotations ORDER BY detector_id, trace_id, seq",
        ),
        t.csv(
            run,
            "SELECT detector_id, trace_id, status, error, n_patterns FROM detector_calls \
             ORDER BY detector_id, trace_id",
        ),
    )
}

/// Sets are finished on a second thread while the next one runs: a kill or a failure after some of
/// them leaves no partial table, and the resumed stage ends with the tables of an uninterrupted run.
#[test]
fn a_killed_or_failed_annotate_stage_resumes_to_the_same_tables() {
    let t = TestRun::new();
    let pipeline = "[pipeline]\nname = \"p\"\nseed = 4\n\n[[stage]]\nid = \"sim\"\nkind = \"simulate\"\n\
                    scenes = 10\nshots = 1\ndt = 0.1\nscenes_per_shard = 2\n\n[[stage]]\nid = \"ann\"\n\
                    kind = \"annotate\"\nworkers = 2\n";
    t.write("pipelines/p.toml", pipeline);
    t.run(&["run", "pipelines/p.toml", "--run-dir", "fresh"])
        .ok();
    let expected = annotate_rows(&t, "fresh");
    assert!(expected.0.lines().count() > 10, "{}", expected.0);
    assert_eq!(expected.1.lines().count(), 1 + 10 * 12);
    for (dir, fault) in [
        ("killed", "ann:after-shards=2"),
        ("failed", "ann:after-shards=3:fail"),
    ] {
        let r = t.run_env(
            &["run", "pipelines/p.toml", "--run-dir", dir],
            &[("ANNOTRACE_FAULT", fault)],
        );
        assert_ne!(r.code, Some(0), "{fault}: the fault stops the run");
        assert!(r.stderr.contains("injected fault"), "{fault}: {}", r.stderr);
        for table in ["annotations", "detector_calls"] {
            assert!(
                !t.path(&format!("{dir}/{table}")).exists(),
                "{fault}: no partial {table} table is published"
            );
        }
        t.run(&["run", "pipelines/p.toml", "--run-dir", dir]).ok();
        assert_eq!(annotate_rows(&t, dir), expected, "{fault}");
    }
}

/// `accuracy` with `use_annotations` scores each trace file set from that set's stored annotations
/// (read by trace id, not the run's whole table): over three sets it gives the table that running the
/// detectors again gives.
#[test]
fn accuracy_from_stored_annotations_equals_accuracy_from_running_the_detectors() {
    let t = TestRun::new();
    let pipeline = |stored: bool| {
        format!(
            r#"[pipeline]
name = "acc"
seed = 5

[[stage]]
id = "sim"
kind = "simulate"
env = "pooltool"
scenes = 6
shots = 1
dt = 0.05
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
inputs = ["sim", "ann"]
use_annotations = {stored}
"#
        )
    };
    let sql = "SELECT * FROM accuracy ORDER BY label";
    let mut tables = Vec::new();
    for stored in [true, false] {
        let file = format!("pipelines/acc-{stored}.toml");
        let run = format!("runs/{stored}");
        t.write(&file, &pipeline(stored));
        t.run(&["run", &file, "--run-dir", &run, "-q"]).ok();
        tables.push(t.csv(&run, sql));
    }
    assert_eq!(
        t.csv("runs/true", "SELECT count(*) AS n FROM traces"),
        "n\n6\n"
    );
    assert!(tables[0].contains("cue strike,6,6,6,"), "{}", tables[0]);
    assert_eq!(tables[0], tables[1]);
}
