//! Hostile SQL through `annotrace query` and the `sql`/`export` stages: statements that write (`COPY`,
//! `INSERT`, `CREATE`, `SET`) are refused with exit code 2 and change nothing; memory and time limits
//! stop queries that would run unbounded; aggregates and stage outputs are the same bytes on every run.

use std::path::Path;

use annotrace::testutil::synthetic_trace;
use annotrace::trace::Env;

use crate::common::TestRun;

/// A run `r` of pool traces imported `per_shard` to a file, so that queries read many files.
fn run_with_shards(t: &TestRun, traces: usize, per_shard: usize) {
    let all: Vec<_> = (0..traces)
        .map(|i| synthetic_trace(Env::Pooltool, i, 40 + i % 7, 4))
        .collect();
    t.write_jsonl("pool.jsonl", &all);
    t.run(&[
        "import",
        "--env",
        "pooltool",
        "pool.jsonl",
        "--run",
        "r",
        "--traces-per-shard",
        &per_shard.to_string(),
    ])
    .ok();
}

/// Every file under `dir` with its bytes, sorted by path.
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

fn trace_count(t: &TestRun) -> String {
    t.csv("r", "SELECT count(*) AS n FROM traces")
}

#[test]
fn copy_is_refused_anywhere_and_onto_a_tables_own_file() {
    let t = TestRun::new();
    run_with_shards(&t, 6, 3);
    let before = snapshot(&t.path("r"));
    let elsewhere = t.path("elsewhere");
    let target = elsewhere.join("sub/f.csv");
    let own = t.files("r/traces")[0].clone();
    let own = t.path("r/traces").join(own);
    for sql in [
        format!(
            "COPY (SELECT 'x' AS a) TO '{}' STORED AS CSV",
            target.display()
        ),
        format!(
            "EXPLAIN ANALYZE COPY (SELECT 'x' AS a) TO '{}' STORED AS CSV",
            target.display()
        ),
        format!(
            "COPY (SELECT * FROM traces LIMIT 1) TO '{}' STORED AS PARQUET",
            own.display()
        ),
        "COPY traces TO 'r/exports/all.parquet'".to_string(),
    ] {
        t.run(&["query", &sql, "--run", "r"])
            .code(2)
            .stderr_has("refused: COPY")
            .stderr_has("read-only");
    }
    assert!(!elsewhere.exists(), "COPY created {}", elsewhere.display());
    assert!(!t.path("r/exports").exists());
    assert_eq!(snapshot(&t.path("r")), before, "the run changed");
}

#[test]
fn insert_is_refused_and_the_table_keeps_its_rows_and_files() {
    let t = TestRun::new();
    run_with_shards(&t, 6, 3);
    let rows = trace_count(&t);
    let before = snapshot(&t.path("r"));
    for sql in [
        "INSERT INTO traces SELECT * FROM traces",
        "INSERT OVERWRITE traces SELECT * FROM traces",
        "DELETE FROM traces",
        "UPDATE traces SET n_steps = 0",
        "TRUNCATE TABLE traces",
    ] {
        let r = t.run(&["query", sql, "--run", "r"]);
        r.code(2).stderr_has("refused:");
    }
    t.run(&[
        "query",
        "INSERT INTO traces SELECT * FROM traces",
        "--run",
        "r",
    ])
    .stderr_has("refused: INSERT INTO traces");
    assert_eq!(trace_count(&t), rows);
    assert_eq!(snapshot(&t.path("r")), before, "the run changed");
}

#[test]
fn ddl_and_session_statements_are_refused() {
    let t = TestRun::new();
    run_with_shards(&t, 2, 2);
    let before = snapshot(&t.path("r"));
    for (sql, named) in [
        ("CREATE TABLE t AS SELECT 1 AS a", "CREATE TABLE t"),
        ("CREATE TABLE t (a INT)", "CREATE TABLE t"),
        ("CREATE VIEW v AS SELECT * FROM traces", "CREATE VIEW v"),
        (
            "CREATE EXTERNAL TABLE e STORED AS CSV LOCATION '/etc/hostname'",
            "CREATE EXTERNAL TABLE e",
        ),
        ("DROP TABLE traces", "DROP TABLE traces"),
        ("CREATE SCHEMA s", "CREATE SCHEMA s"),
        (
            "SET datafusion.execution.target_partitions = 8",
            "SET datafusion.execution.target_partitions",
        ),
        ("PREPARE p AS SELECT 1", "PREPARE p"),
    ] {
        t.run(&["query", sql, "--run", "r"])
            .code(2)
            .stderr_has(&format!("refused: {named}"));
    }
    // Reading statements still work.
    t.run(&["query", "DESCRIBE traces", "--run", "r"]).ok();
    t.run(&["query", "EXPLAIN SELECT count(*) FROM traces", "--run", "r"])
        .ok();
    t.run(&[
        "query",
        "SELECT count(*) FROM information_schema.tables",
        "--run",
        "r",
    ])
    .ok();
    assert_eq!(snapshot(&t.path("r")), before, "the run changed");
}

#[test]
fn out_may_not_drop_a_file_into_a_tables_folder() {
    let t = TestRun::new();
    run_with_shards(&t, 2, 2);
    let before = snapshot(&t.path("r"));
    for out in [
        "r/traces/env=pooltool/extra.parquet",
        "r/new_table/x.parquet",
        "r/exports/../traces/x.parquet",
    ] {
        t.run(&[
            "query",
            "SELECT * FROM traces",
            "--run",
            "r",
            "--format",
            "parquet",
            "--out",
            out,
        ])
        .code(2)
        .stderr_has("refused to write a query result inside run folder");
    }
    assert_eq!(snapshot(&t.path("r")), before, "the run changed");
    // Under exports/ and outside the run are fine.
    for out in ["r/exports/t.csv", "t.csv"] {
        t.run(&[
            "query",
            "SELECT 1 AS a",
            "--run",
            "r",
            "--format",
            "csv",
            "--out",
            out,
        ])
        .ok();
        assert_eq!(std::fs::read_to_string(t.path(out)).unwrap(), "a\n1\n");
    }
}

#[test]
fn a_time_limit_stops_an_unbounded_query() {
    let t = TestRun::new();
    run_with_shards(&t, 2, 2);
    let sql = "SELECT count(*) FROM generate_series(1, 100000000000)";
    let start = std::time::Instant::now();
    t.run(&["query", sql, "--run", "r", "--timeout", "1"])
        .code(2)
        .stderr_has("did not finish within its time limit of 1 s");
    let took = start.elapsed();
    assert!(took.as_secs_f64() < 20.0, "took {took:?}");
    // The same from the variable; the flag wins over it.
    t.run_env(
        &["query", sql, "--run", "r"],
        &[("ANNOTRACE_SQL_TIMEOUT", "0.5")],
    )
    .code(2)
    .stderr_has("time limit of 0.5 s");
    t.run_env(
        &["query", "SELECT 1", "--run", "r", "--timeout", "60"],
        &[("ANNOTRACE_SQL_TIMEOUT", "0.000001")],
    )
    .ok();
    t.run(&["query", "SELECT 1", "--run", "r", "--timeout", "-1"])
        .code(2);
    t.run_env(
        &["query", "SELECT 1", "--run", "r"],
        &[("ANNOTRACE_SQL_TIMEOUT", "soon")],
    )
    .code(2)
    .stderr_has("ANNOTRACE_SQL_TIMEOUT");
}

#[test]
fn a_memory_limit_stops_a_query_that_would_hold_everything() {
    let t = TestRun::new();
    run_with_shards(&t, 2, 2);
    // array_agg holds every value and cannot spill.
    let sql = "SELECT array_agg(value) FROM generate_series(1, 10000000)";
    t.run(&["query", sql, "--run", "r", "--memory-limit", "8MiB"])
        .code(2)
        .stderr_has("needs more memory than the SQL memory limit of 8 MiB");
    t.run_env(
        &["query", sql, "--run", "r"],
        &[("ANNOTRACE_SQL_MEMORY_LIMIT", "4M")],
    )
    .code(2)
    .stderr_has("memory limit of 4 MiB");
    // A sort spills within its bounds and finishes.
    let sorted = t.run(&[
        "query",
        "SELECT value FROM generate_series(1, 300000) ORDER BY value DESC LIMIT 2",
        "--run",
        "r",
        "--memory-limit",
        "2MiB",
        "--format",
        "csv",
    ]);
    sorted.ok();
    assert_eq!(sorted.stdout, "value\n300000\n299999\n");
    t.run(&["query", "SELECT 1", "--run", "r", "--memory-limit", "lots"])
        .code(2)
        .stderr_has("not a memory size");
    t.run_env(
        &["query", "SELECT 1", "--run", "r"],
        &[("ANNOTRACE_SQL_MEMORY_LIMIT", "0")],
    )
    .code(2)
    .stderr_has("ANNOTRACE_SQL_MEMORY_LIMIT");
}

/// Float aggregates over many files: parallel partial aggregation merged them in varying order, so the
/// last digits changed from run to run.
#[test]
fn float_aggregates_are_the_same_on_every_run() {
    let t = TestRun::new();
    run_with_shards(&t, 60, 2);
    let sql = "SELECT avg(x * 1.1) AS a, stddev(vx) AS s, sum(y / 3.0) AS t, var_pop(x + y) AS v \
               FROM frames";
    let first = t.csv("r", sql);
    for _ in 0..8 {
        assert_eq!(t.csv("r", sql), first);
    }
}

/// A project importing many small shards, with an `sql` stage and an `export` stage over it.
fn project(t: &TestRun, sql_stage: &str, export_stage: &str) {
    let all: Vec<_> = (0..60)
        .map(|i| synthetic_trace(Env::Pooltool, i, 40 + i % 7, 4))
        .collect();
    t.write_jsonl("data/pool.jsonl", &all);
    t.write(
        "pipelines/p.toml",
        &format!(
            r#"[pipeline]
name = "p"

[[stage]]
id = "ingest"
kind = "import"
env = "pooltool"
paths = ["data"]
traces_per_shard = 2

[[stage]]
id = "summary"
kind = "sql"
inputs = ["ingest"]
{sql_stage}

[[stage]]
id = "export_summary"
kind = "export"
inputs = ["summary"]
{export_stage}
"#
        ),
    );
}

#[test]
fn sql_and_export_stages_refuse_writes() {
    let t = TestRun::new();
    let target = t.path("elsewhere/f.csv");
    project(
        &t,
        &format!(
            "sql = \"COPY (SELECT 'x' AS a) TO '{}' STORED AS CSV\"",
            target.display()
        ),
        "table = \"summary\"",
    );
    t.run(&["run", "pipelines/p.toml"])
        .code(2)
        .stderr_has("refused: COPY");
    assert!(!t.path("elsewhere").exists());

    let t = TestRun::new();
    project(
        &t,
        "sql = \"SELECT count(*) AS n FROM traces\"",
        "sql = \"INSERT INTO traces SELECT * FROM traces\"",
    );
    t.run(&["run", "pipelines/p.toml"])
        .code(2)
        .stderr_has("refused: INSERT INTO traces");
    assert_eq!(
        t.csv("runs/p", "SELECT count(*) AS n FROM traces"),
        "n\n60\n"
    );
    assert_eq!(t.files("runs/p/traces").len(), 30);

    let t = TestRun::new();
    project(
        &t,
        "sql = \"CREATE VIEW v AS SELECT * FROM traces\"",
        "table = \"summary\"",
    );
    t.run(&["run", "pipelines/p.toml"])
        .code(2)
        .stderr_has("refused: CREATE VIEW v");
}

#[test]
fn stage_limits_stop_queries_and_bad_limits_are_invalid_pipelines() {
    let t = TestRun::new();
    project(
        &t,
        "sql = \"SELECT count(*) AS n FROM generate_series(1, 100000000000)\"\ntimeout_s = 1",
        "table = \"summary\"",
    );
    t.run(&["run", "pipelines/p.toml"])
        .code(2)
        .stderr_has("time limit of 1 s");

    let t = TestRun::new();
    project(
        &t,
        "sql = \"SELECT count(*) AS n FROM traces\"",
        "sql = \"SELECT array_agg(value) AS v FROM generate_series(1, 10000000)\"\nmemory_limit = \"8MiB\"",
    );
    t.run(&["run", "pipelines/p.toml"])
        .code(2)
        .stderr_has("memory limit of 8 MiB");
    // The variable applies to stages too.
    let t2 = TestRun::new();
    project(
        &t2,
        "sql = \"SELECT array_agg(value) AS v FROM generate_series(1, 10000000)\"",
        "table = \"summary\"",
    );
    t2.run_env(
        &["run", "pipelines/p.toml"],
        &[("ANNOTRACE_SQL_MEMORY_LIMIT", "8MiB")],
    )
    .code(2)
    .stderr_has("memory limit of 8 MiB");

    for (bad, message) in [
        ("memory_limit = \"lots\"", "\"lots\" is not a memory size"),
        ("timeout_s = -2", "must be a positive number of seconds"),
    ] {
        let t = TestRun::new();
        project(
            &t,
            &format!("sql = \"SELECT 1 AS a\"\n{bad}"),
            "table = \"summary\"",
        );
        t.run(&["run", "pipelines/p.toml"])
            .code(2)
            .stderr_has("p.toml:16: stage \"summary\"")
            .stderr_has(message);
    }
}

/// The same pipeline run afresh gives byte-identical result tables and exports, including an
/// aggregate of floats over many files and a query without ORDER BY.
#[test]
fn sql_stage_tables_and_exports_are_byte_identical_across_runs() {
    let t = TestRun::new();
    project(
        &t,
        "sql = \"SELECT task_id, avg(n_frames * 1.1) AS a, stddev(t_end * 3.3) AS s, \
         (SELECT avg(x * 1.1) FROM frames) AS mean_x, (SELECT stddev(vx) FROM frames) AS sd_vx \
         FROM traces GROUP BY task_id\"",
        "sql = \"SELECT trace_id, x, vx FROM frames WHERE step % 5 = 0\"\nformat = \"csv\"\nfile = \"frames.csv\"",
    );
    let mut first: Option<Vec<(String, Vec<u8>)>> = None;
    for _ in 0..4 {
        let _ = std::fs::remove_dir_all(t.path("runs"));
        t.run(&["run", "pipelines/p.toml", "--quiet"]).ok();
        let mut got = snapshot(&t.path("runs/p/summary"));
        got.extend(snapshot(&t.path("runs/p/exports")));
        assert_eq!(
            got.len(),
            2,
            "{:?}",
            got.iter().map(|f| &f.0).collect::<Vec<_>>()
        );
        match &first {
            None => first = Some(got),
            Some(f) => assert!(
                f == &got,
                "a rerun changed the bytes of the sql table or export"
            ),
        }
    }
}

/// The quickstart's own summary query over a run of many files, several times.
#[test]
fn the_quickstart_summary_is_reproducible() {
    let t = TestRun::new();
    run_with_shards(&t, 60, 2);
    let sql = std::fs::read_to_string(crate::common::repo().join("sql/trace_summary.sql")).unwrap();
    // Without its leading comment, which the command line would take for an option.
    let sql: String = sql
        .lines()
        .filter(|l| !l.starts_with("--"))
        .collect::<Vec<_>>()
        .join("\n");
    let first = t.csv("r", &sql);
    for _ in 0..5 {
        assert_eq!(t.csv("r", &sql), first);
    }
}
