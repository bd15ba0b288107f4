//! Publication and verified reading: a stage becomes visible all at once whatever the moment of a
//! kill, readers list files from the manifest (foreign files are ignored), damaged files are refused
//! with their name, `annotrace verify` lists them, and `run` redoes the stage that owns them.

use annotrace::testutil::synthetic_trace;
use annotrace::trace::Env;

use crate::common::TestRun;

/// Two imports (`base`: 3 traces, always finished first; `ingest`: 10 traces in 3 shards, the one
/// killed), an SQL summary and its export.
fn project(t: &TestRun) {
    let base: Vec<_> = (0..3)
        .map(|i| synthetic_trace(Env::Pooltool, i, 6, 3))
        .collect();
    t.write_jsonl("data/base.jsonl", &base);
    let more: Vec<_> = (10..20)
        .map(|i| synthetic_trace(Env::Pooltool, i, 6, 3))
        .collect();
    t.write_jsonl("data/ingest/a.jsonl", &more[..5]);
    t.write_jsonl("data/ingest/b.jsonl", &more[5..]);
    t.write(
        "p.toml",
        r#"[pipeline]
name = "p"
seed = 5

[[stage]]
id = "base"
kind = "import"
env = "pooltool"
paths = ["data/base.jsonl"]

[[stage]]
id = "ingest"
kind = "import"
env = "pooltool"
inputs = ["base"]
paths = ["data/ingest"]
traces_per_shard = 4

[[stage]]
id = "per_task"
kind = "sql"
inputs = ["ingest"]
sql = "SELECT task_id, count(*) AS traces, sum(n_frames) AS frames FROM traces GROUP BY task_id ORDER BY task_id"

[[stage]]
id = "table"
kind = "export"
inputs = ["per_task"]
table = "per_task"
format = "csv"
"#,
    );
}

fn all_rows(t: &TestRun, run: &str) -> String {
    t.csv(
        run,
        "SELECT trace_id, step, slot, object_id, x, y, vx FROM frames ORDER BY trace_id, step, slot",
    )
}

/// What a reader sees of the trace tables: traces, distinct trace ids in frames and timesteps, frame
/// rows whose trace is not in `traces`.
fn seen(t: &TestRun, run: &str) -> String {
    t.csv(
        run,
        "SELECT (SELECT count(*) FROM traces) AS traces, \
                (SELECT count(DISTINCT trace_id) FROM frames) AS framed, \
                (SELECT count(DISTINCT trace_id) FROM timesteps) AS stepped, \
                (SELECT count(*) FROM frames WHERE trace_id NOT IN (SELECT trace_id FROM traces)) AS orphans",
    )
}

/// A published file of `table` written by stage `ingest`.
fn an_ingest_file(t: &TestRun, run: &str, table: &str) -> String {
    let mut files: Vec<String> = t
        .files(run)
        .into_iter()
        .filter(|f| f.starts_with(&format!("{table}/env=pooltool/ingest.")))
        .collect();
    files.sort();
    files.into_iter().next().expect("ingest wrote a file")
}

/// Killed (abort, as kill -9) after every step of the commit of `ingest`, in turn: readers see the
/// run either without `ingest` (before the manifest says finished) or with all of it (after), never a
/// part, `verify` finds nothing damaged or foreign, and the next `run` ends with the tables and export
/// of an uninterrupted run.
#[test]
fn a_kill_at_any_commit_step_shows_the_old_or_the_new_state_and_resumes() {
    let t = TestRun::new();
    project(&t);
    t.run(&["run", "p.toml", "--run-dir", "fresh"]).ok();
    let expected = all_rows(&t, "fresh");
    let export = std::fs::read_to_string(t.path("fresh/exports/per_task.csv")).unwrap();
    let old = "traces,framed,stepped,orphans\n3,3,3,0\n";
    let new = "traces,framed,stepped,orphans\n13,13,13,0\n";
    assert_eq!(seen(&t, "fresh"), new);
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(t.path("fresh/manifest.json")).unwrap())
            .unwrap();
    // One file per shard and trace table (17 here).
    let files = manifest["stages"]["ingest"]["outputs"]
        .as_array()
        .unwrap()
        .len();
    assert!(files > 10, "{files}");

    let mut states = Vec::new();
    for k in 0.. {
        let run = format!("k{k}");
        let r = t.run_env(
            &["run", "p.toml", "--run-dir", &run],
            &[("ANNOTRACE_FAULT", &format!("ingest:commit-step={k}"))],
        );
        if r.code == Some(0) {
            // Past the last step: the fault never fired. The commit of n files has n + 3 steps.
            assert_eq!(k, files + 4, "a step per file and three more");
            break;
        }
        assert!(
            r.stderr.contains(&format!("stopped after commit step {k}")),
            "{}",
            r.stderr
        );
        let s = seen(&t, &run);
        assert!(
            s == old || s == new,
            "after commit step {k}, readers see {s}"
        );
        states.push(s == new);
        t.run(&["tables", "--run", &run, "--brief"]).ok();
        t.run(&["verify", "--run", &run]).ok();
        let resumed = t.run(&["run", "p.toml", "--run-dir", &run]);
        resumed.ok();
        assert_eq!(all_rows(&t, &run), expected, "resumed after step {k}");
        assert_eq!(
            std::fs::read_to_string(t.path(&format!("{run}/exports/per_task.csv"))).unwrap(),
            export
        );
        assert!(!t.path(&format!("{run}/.staging")).exists());
        t.run(&["verify", "--run", &run]).ok().stdout_has("; ok");
    }
    // Old until the manifest says finished, new from then on.
    assert!(states.first() == Some(&false) && states.last() == Some(&true));
    assert!(states.windows(2).all(|w| w[0] <= w[1]), "{states:?}");
}

/// A file no stage lists — here a file of another table's schema dropped into `traces/env=pooltool/`
/// — is ignored by readers and `run`, and reported by `verify`.
#[test]
fn a_foreign_file_is_ignored_by_readers_and_reported_by_verify() {
    let t = TestRun::new();
    project(&t);
    t.run(&["run", "p.toml", "--run-dir", "r"]).ok();
    let before = seen(&t, "r");
    let frames = an_ingest_file(&t, "r", "frames");
    std::fs::copy(
        t.path(&format!("r/{frames}")),
        t.path("r/traces/env=pooltool/dropped.parquet"),
    )
    .unwrap();
    std::fs::write(t.path("r/traces/env=pooltool/empty.parquet"), b"").unwrap();
    assert_eq!(seen(&t, "r"), before);
    t.run(&["tables", "--run", "r"]).ok();
    t.run(&["verify", "--run", "r"])
        .code(1)
        .stdout_has("foreign  traces/env=pooltool/dropped.parquet")
        .stdout_has("foreign  traces/env=pooltool/empty.parquet")
        .stdout_has("0 damaged, 2 foreign");
    t.run(&["run", "p.toml", "--run-dir", "r"])
        .ok()
        .stderr_has("0 stage(s) ran, 4 cached");
}

/// An empty, a truncated and a changed output: readers refuse the first two naming the file (exit 2),
/// `verify` names all three, and `run` reruns the stage that wrote each and says why.
#[test]
fn damaged_files_are_refused_named_and_rerun() {
    let t = TestRun::new();
    project(&t);
    t.run(&["run", "p.toml", "--run-dir", "fresh"]).ok();
    let expected = all_rows(&t, "fresh");
    type Damage = fn(&std::path::Path);
    let cases: [(&str, Damage, &str); 3] = [
        (
            "empty",
            |p| std::fs::write(p, b"").unwrap(),
            "is empty (0 bytes), manifest.json records",
        ),
        (
            "truncated",
            |p| {
                let bytes = std::fs::read(p).unwrap();
                std::fs::write(p, &bytes[..bytes.len() / 2]).unwrap();
            },
            "is truncated",
        ),
        (
            "changed",
            |p| {
                let mut bytes = std::fs::read(p).unwrap();
                let mid = bytes.len() / 2;
                bytes[mid] ^= 0x55;
                std::fs::write(p, &bytes).unwrap();
            },
            "differs from the",
        ),
    ];
    for (name, damage, problem) in cases {
        t.run(&["run", "p.toml", "--run-dir", name]).ok();
        let file = an_ingest_file(&t, name, "frames");
        damage(&t.path(&format!("{name}/{file}")));
        if name != "changed" {
            // Readers check sizes: the query fails and names the file.
            t.run(&["query", "SELECT count(*) FROM frames", "--run", name])
                .code(2)
                .stderr_has(&file)
                .stderr_has(problem)
                .stderr_has("annotrace verify");
        }
        t.run(&["verify", "--run", name])
            .code(1)
            .stdout_has(&format!("damaged  {file} (stage ingest): "))
            .stdout_has(problem);
        t.run(&["run", "p.toml", "--run-dir", name, "--explain"])
            .ok()
            .stdout_has("run (outputs damaged)");
        t.run(&["run", "p.toml", "--run-dir", name])
            .ok()
            .stderr_has(&format!("[ingest] {file} "))
            .stderr_has(problem)
            .stderr_has("running the stage again")
            .stderr_has("[ingest] done");
        assert_eq!(all_rows(&t, name), expected, "{name}");
        t.run(&["verify", "--run", name]).ok();
    }
}

/// A run folder written before checksums (manifest format 1, outputs as bare paths) is read as it is;
/// `run` records the checksums once and skips every stage.
#[test]
fn a_format_1_manifest_is_read_and_upgraded() {
    let t = TestRun::new();
    project(&t);
    t.run(&["run", "p.toml", "--run-dir", "r"]).ok();
    let expected = all_rows(&t, "r");
    let path = t.path("r/manifest.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    m["format"] = 1.into();
    for stage in m["stages"].as_object_mut().unwrap().values_mut() {
        let outputs: Vec<serde_json::Value> = stage["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| o["path"].clone())
            .collect();
        stage["outputs"] = outputs.into();
    }
    std::fs::write(&path, serde_json::to_string_pretty(&m).unwrap()).unwrap();
    assert_eq!(all_rows(&t, "r"), expected);
    t.run(&["verify", "--run", "r"])
        .ok()
        .stdout_has("no recorded checksum (manifest format 1)");
    t.run(&["run", "p.toml", "--run-dir", "r"])
        .ok()
        .stderr_has("format 1 upgraded to 2")
        .stderr_has("0 stage(s) ran, 4 cached");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(m["format"], 2);
    assert!(m["stages"]["ingest"]["outputs"][0]["sha256"].is_string());
    t.run(&["verify", "--run", "r"]).ok().stdout_has("; ok");

    // A newer format than this annotrace reads is refused with a clear message.
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("\"format\": 2", "\"format\": 9");
    std::fs::write(&path, text).unwrap();
    t.run(&["query", "SELECT 1", "--run", "r"])
        .code(2)
        .stderr_has("manifest format 9 is newer than this annotrace reads");
}
