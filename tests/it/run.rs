//! `annotrace run`: validation with file and line, skipping finished stages, rerunning what a change
//! touches, and resuming after a kill.

use annotrace::testutil::synthetic_trace;
use annotrace::trace::Env;

use crate::common::{Ran, TestRun};

/// A project with five JSON Lines files of pool traces, a summary query and an export.
fn project(t: &TestRun, precision: u32) {
    for f in 0..5 {
        let traces: Vec<_> = (0..5)
            .map(|i| synthetic_trace(Env::Pooltool, f * 10 + i, 8, 3))
            .collect();
        t.write_jsonl(&format!("data/part{f}.jsonl"), &traces);
    }
    t.write("sql/per_task.sql", "SELECT task_id, count(*) AS traces, avg(n_frames) AS frames FROM traces GROUP BY task_id ORDER BY task_id\n");
    pipeline(t, precision);
}

/// Writes only the pipeline file.
fn pipeline(t: &TestRun, precision: u32) {
    t.write(
        "pipelines/p.toml",
        &format!(
            r#"[pipeline]
name = "p"
seed = 3

[[stage]]
id = "ingest"
kind = "import"
env = "pooltool"
paths = ["data"]
traces_per_shard = 2

[[stage]]
id = "per_task"
kind = "sql"
inputs = ["ingest"]
query = "per_task.sql"

[[stage]]
id = "table"
kind = "export"
inputs = ["per_task"]
table = "per_task"
format = "latex"
precision = {precision}
"#
        ),
    );
}

fn explain(t: &TestRun) -> Vec<(String, String)> {
    let r = t.run(&["run", "pipelines/p.toml", "--explain"]);
    r.ok();
    r.stdout
        .lines()
        .skip(1)
        .map(|l| {
            let mut w = l.split_whitespace();
            let id = w.next().unwrap().to_string();
            let action = w.nth(2).unwrap().to_string();
            (id, action)
        })
        .collect()
}

fn all_rows(t: &TestRun) -> String {
    t.csv("runs/p", "SELECT trace_id, step, slot, object_id, x, y, vx FROM frames ORDER BY trace_id, step, slot")
}

#[test]
fn finished_stages_are_skipped_and_changes_rerun_downstream() {
    let t = TestRun::new();
    project(&t, 2);
    t.run(&["run", "pipelines/p.toml"])
        .ok()
        .stderr_has("[table] done");
    let manifest = std::fs::read_to_string(t.path("runs/p/manifest.json")).unwrap();
    assert_eq!(
        explain(&t),
        [
            ("ingest".into(), "cached".into()),
            ("per_task".into(), "cached".into()),
            ("table".into(), "cached".into())
        ]
    );
    let again = t.run(&["run", "pipelines/p.toml"]);
    again
        .ok()
        .stderr_has("[ingest] cached")
        .stderr_has("0 stage(s) ran, 3 cached");
    let m2: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(t.path("runs/p/manifest.json")).unwrap())
            .unwrap();
    let m1: serde_json::Value = serde_json::from_str(&manifest).unwrap();
    assert_eq!(
        m1["stages"], m2["stages"],
        "a cached run changes no stage record"
    );

    // A parameter of the last stage: only it reruns.
    pipeline(&t, 3);
    let plan = explain(&t);
    assert_eq!(plan[0].1, "cached");
    assert_eq!(plan[1].1, "cached");
    assert_eq!(plan[2].1, "run");
    t.run(&["run", "pipelines/p.toml"])
        .ok()
        .stderr_has("[per_task] cached")
        .stderr_has("[table] done");
    assert!(
        std::fs::read_to_string(t.path("runs/p/exports/per_task.tex"))
            .unwrap()
            .contains(".000 \\\\")
    );

    // An input file changes: everything downstream of the import reruns.
    let extra = vec![synthetic_trace(Env::Pooltool, 99, 8, 3)];
    t.write_jsonl("data/part5.jsonl", &extra);
    assert!(explain(&t).iter().all(|(_, a)| a == "run"));
    t.run(&["run", "pipelines/p.toml"]).ok();
    assert_eq!(
        t.csv("runs/p", "SELECT count(*) AS n FROM traces"),
        "n\n26\n"
    );

    // --force reruns a stage and what depends on it; --until stops after a stage.
    t.run(&["run", "pipelines/p.toml", "--force", "per_task"])
        .ok()
        .stderr_has("[ingest] cached")
        .stderr_has("[per_task] done")
        .stderr_has("[table] done");
    t.run(&[
        "run",
        "pipelines/p.toml",
        "--force",
        "ingest",
        "--until",
        "per_task",
    ])
    .ok()
    .stderr_has("[per_task] done");
    t.run(&["run", "pipelines/p.toml", "--until", "nope"])
        .code(2)
        .stderr_has("--until \"nope\": no such stage");
}

fn killed(r: &Ran) {
    assert_ne!(
        r.code,
        Some(0),
        "the injected fault stops the run\n{}",
        r.stderr
    );
    assert!(r.stderr.contains("injected fault"), "{}", r.stderr);
}

/// Killed (abort, as kill -9) after some shards: nothing partial is visible, and the rerun resumes and
/// ends with exactly the tables of an uninterrupted run.
#[test]
fn a_killed_run_resumes_to_the_same_tables() {
    let fresh = TestRun::new();
    project(&fresh, 2);
    fresh.run(&["run", "pipelines/p.toml"]).ok();
    let expected = all_rows(&fresh);

    for fault in ["ingest:after-shards=4", "ingest:mid-shard=5"] {
        let t = TestRun::new();
        project(&t, 2);
        killed(&t.run_env(&["run", "pipelines/p.toml"], &[("ANNOTRACE_FAULT", fault)]));
        // Readers see no partial stage: the staged shards are not in the tables.
        assert_eq!(
            t.csv("runs/p", "SELECT count(*) AS n FROM frames"),
            "n\n0\n",
            "{fault}"
        );
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(t.path("runs/p/manifest.json")).unwrap())
                .unwrap();
        assert_eq!(m["stages"]["ingest"]["status"], "running");
        let staged = t.files("runs/p/.staging/ingest/_done");
        assert!(
            staged.len() >= 4,
            "{fault}: finished shards are kept: {staged:?}"
        );
        let resumed = t.run(&["run", "pipelines/p.toml"]);
        resumed.ok().stderr_has("resuming: finished shards kept");
        assert_eq!(all_rows(&t), expected, "{fault}: resumed tables differ");
        assert!(!t.path("runs/p/.staging").exists());
        assert!(
            t.files("runs/p").iter().all(|f| !f.ends_with(".tmp")),
            "{fault}: temporary files remain"
        );
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(t.path("runs/p/manifest.json")).unwrap())
                .unwrap();
        assert_eq!(m["stages"]["ingest"]["rows"]["traces"], 25);
        assert_eq!(m["stages"]["ingest"]["summary"]["traces"], 25);
    }
}

/// A stage that fails with an error (not a kill) leaves no partial output and is retried next time.
#[test]
fn a_failed_stage_is_recorded_and_retried() {
    let t = TestRun::new();
    project(&t, 2);
    let r = t.run_env(
        &["run", "pipelines/p.toml"],
        &[("ANNOTRACE_FAULT", "ingest:after-shards=2:fail")],
    );
    r.code(1).stderr_has("stage ingest failed: injected fault");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(t.path("runs/p/manifest.json")).unwrap())
            .unwrap();
    assert_eq!(m["stages"]["ingest"]["status"], "failed");
    assert!(!t.path("runs/p/.staging").exists());
    t.run(&["run", "pipelines/p.toml"]).ok();
    assert_eq!(
        t.csv("runs/p", "SELECT count(*) AS n FROM traces"),
        "n\n25\n"
    );
}

#[test]
fn pipeline_errors_name_file_line_and_key() {
    let t = TestRun::new();
    project(&t, 2);
    let base = std::fs::read_to_string(t.path("pipelines/p.toml")).unwrap();
    let cases = [
        (
            base.replace(
                "traces_per_shard = 2",
                "traces_per_shard = 2\ncolour = \"red\"",
            ),
            "pipelines/p.toml:11: unknown key `colour` in stage \"ingest\" (kind import)",
        ),
        (
            base.replace("kind = \"sql\"", "kind = \"sqll\""),
            "pipelines/p.toml:14: unknown stage kind \"sqll\"; did you mean \"sql\"?",
        ),
        (
            base.replace("inputs = [\"per_task\"]", "inputs = [\"per_tsk\"]"),
            "pipelines/p.toml:21: stage \"table\" names input \"per_tsk\"",
        ),
        (
            base.replace("inputs = [\"ingest\"]", "inputs = [\"table\"]"),
            "stages form a cycle",
        ),
        (
            base.replace("traces_per_shard = 2", "traces_per_shard = \"two\""),
            "pipelines/p.toml:10: stage \"ingest\": `traces_per_shard` must be a non-negative integer, found a string",
        ),
        (
            base.replace("paths = [\"data\"]", "paths = [\"nodata\"]"),
            "pipelines/p.toml:9: stage \"ingest\": ",
        ),
        (
            base.replace("seed = 3", "seed = 3\nsede = 4"),
            "pipelines/p.toml:4: unknown key `sede` in [pipeline]",
        ),
        (
            base.replace(
                "[[stage]]\nid = \"per_task\"",
                "[[stage]\nid = \"per_task\"",
            ),
            "pipelines/p.toml:12: invalid TOML",
        ),
    ];
    for (text, expected) in cases {
        t.write(
            "pipelines/bad.toml",
            &text.replace("name = \"p\"", "name = \"bad\""),
        );
        let r = t.run(&["run", "pipelines/bad.toml"]);
        r.code(2)
            .stderr_has(&expected.replace("p.toml", "bad.toml"));
        assert!(
            !t.path("runs/bad").exists(),
            "nothing runs before validation passes"
        );
    }
}

/// Long traces spill their frame rows to disk while they are read; the tables are the same as without
/// spilling, and a rejected long trace leaves nothing behind.
#[test]
fn spilled_traces_give_the_same_tables() {
    let t = TestRun::new();
    let mut traces: Vec<_> = (0..3)
        .map(|i| synthetic_trace(Env::Phyre, i, 120, 5))
        .collect();
    t.write_jsonl("long.jsonl", &traces);
    traces[1].timesteps[100].t = 0.0; // time goes back: rejected after ~500 rows were spilled
    t.write_jsonl("bad.jsonl", &traces[1..2]);
    let pipeline = |spill: usize| {
        format!(
            "[[stage]]\nid = \"a\"\nkind = \"import\"\nenv = \"phyre\"\npaths = [\"long.jsonl\"]\nspill_rows = {spill}\n\n\
             [[stage]]\nid = \"b\"\nkind = \"import\"\nenv = \"phyre\"\npaths = [\"bad.jsonl\"]\nspill_rows = {spill}\nskip_invalid = true\n"
        )
    };
    let rows = |name: &str, spill: usize| {
        t.write(&format!("{name}.toml"), &pipeline(spill));
        t.run(&["run", &format!("{name}.toml"), "--run-dir", name])
            .ok();
        assert!(t.files(name).iter().all(|f| !f.contains("_spill")));
        t.csv(name, "SELECT trace_id, step, slot, object_id, x, y, vx, color FROM frames ORDER BY trace_id, step, slot")
    };
    let spilled = rows("spilled", 50);
    assert_eq!(spilled, rows("whole", 1_000_000));
    assert_eq!(spilled.lines().count(), 1 + 3 * 120 * 5);
    assert_eq!(
        t.csv("spilled", "SELECT sum(n_frames) AS n FROM traces"),
        "n\n1800\n"
    );
}

/// A reader that closes the pipe after the first bytes (`annotrace stages | head -c 1`) ends the
/// command quietly with exit code 0: no panic message, no exit code 101.
#[test]
fn a_closed_pipe_ends_a_command_quietly() {
    use std::io::Read;
    use std::process::Stdio;
    let t = TestRun::new();
    t.write(
        "p.toml",
        "[[stage]]\nid = \"one\"\nkind = \"sql\"\nsql = \"SELECT 1 AS one\"\n",
    );
    t.run(&["run", "p.toml", "--run-dir", "r"]).ok();
    for args in [
        &["stages"][..],
        &["run", "p.toml", "--run-dir", "r", "--explain"][..],
        &["tables", "--run", "r"][..],
        &[
            "query",
            "SELECT * FROM generate_series(1, 200000)",
            "--run",
            "r",
        ][..],
    ] {
        let mut child = t
            .cmd()
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("annotrace runs");
        let mut out = child.stdout.take().unwrap();
        let mut first = [0u8; 1];
        out.read_exact(&mut first).expect("some output");
        drop(out);
        let done = child.wait_with_output().expect("exits");
        let stderr = String::from_utf8_lossy(&done.stderr);
        assert_eq!(done.status.code(), Some(0), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}
