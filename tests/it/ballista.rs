//! SQL on Ballista (feature `ballista`): `annotrace query --engine ballista://HOST:PORT` and `sql` stages
//! run against a Ballista standalone cluster — a scheduler and an executor started in this test process
//! on loopback — and give the same results as the local engine; `ballista:standalone` too. The cluster
//! reads only the published files; an unreachable scheduler is exit 3, a writing statement exit 2.
//! Without the feature, a Ballista engine is refused with the feature to build with (exit 2).

use annotrace::testutil::synthetic_trace;
use annotrace::trace::Env;

use crate::common::TestRun;

/// A run with one imported billiards trace, in `runs/p`.
fn one_trace() -> TestRun {
    let t = TestRun::new();
    t.write_jsonl(
        "data/pool.jsonl",
        &[synthetic_trace(Env::Pooltool, 0, 5, 2)],
    );
    t.run(&[
        "import",
        "--env",
        "pooltool",
        "data/pool.jsonl",
        "--run",
        "runs/p",
    ])
    .ok();
    t
}

#[cfg(not(feature = "ballista"))]
#[test]
fn without_the_feature_a_ballista_engine_names_the_feature() {
    let t = one_trace();
    for engine in ["ballista://127.0.0.1:50050", "ballista:standalone"] {
        t.run(&["query", "SELECT 1", "--run", "runs/p", "--engine", engine])
            .code(2)
            .stderr_has("--features ballista");
        t.run_env(
            &["query", "SELECT 1", "--run", "runs/p"],
            &[("ANNOTRACE_SQL_ENGINE", engine)],
        )
        .code(2)
        .stderr_has("--features ballista");
    }
    t.write(
        "pipelines/q.toml",
        "[pipeline]\nname = \"q\"\n\n[[stage]]\nid = \"n\"\nkind = \"sql\"\n\
         sql = \"SELECT 1 AS one\"\nengine = \"ballista://127.0.0.1:50050\"\n",
    );
    t.run(&["run", "pipelines/q.toml", "--explain"])
        .code(2)
        .stderr_has("pipelines/q.toml:8")
        .stderr_has("--features ballista");
}

#[cfg(feature = "ballista")]
mod on_a_cluster {
    use std::sync::OnceLock;
    use std::time::Duration;

    use annotrace::testutil::synthetic_trace;
    use annotrace::trace::Env;
    use ballista_core::serde::BallistaCodec;
    use ballista_core::serde::protobuf::scheduler_grpc_client::SchedulerGrpcClient;

    use super::one_trace;
    use crate::common::TestRun;

    /// A Ballista standalone cluster (scheduler + one executor with 2 task slots) on loopback, shared by
    /// the tests of this file and kept until the test process ends. Returns the engine to pass.
    fn cluster() -> &'static str {
        static CLUSTER: OnceLock<(tokio::runtime::Runtime, String)> = OnceLock::new();
        &CLUSTER
            .get_or_init(|| {
                let rt = tokio::runtime::Builder::new_multi_thread()
                    .worker_threads(2)
                    .thread_name("test-ballista")
                    .enable_all()
                    .build()
                    .expect("runtime");
                let port = rt.block_on(async {
                    let addr = ballista_scheduler::standalone::new_standalone_scheduler()
                        .await
                        .expect("scheduler starts");
                    let url = format!("http://localhost:{}", addr.port());
                    let mut tries = 0;
                    let client = loop {
                        match SchedulerGrpcClient::connect(url.clone()).await {
                            Ok(c) => break c,
                            Err(e) => {
                                tries += 1;
                                assert!(tries < 100, "scheduler at {url} never answered: {e}");
                                tokio::time::sleep(Duration::from_millis(100)).await;
                            }
                        }
                    };
                    ballista_executor::new_standalone_executor(client, 2, BallistaCodec::default())
                        .await
                        .expect("executor starts");
                    addr.port()
                });
                (rt, format!("ballista://localhost:{port}"))
            })
            .1
    }

    /// Imports synthetic traces of every environment (partitioned trace tables, several files each), then
    /// runs a pipeline whose `sql` stages compute the same summaries locally and on `engine`, one of them
    /// reading another stage's result table.
    fn project(engine: &str) -> TestRun {
        let t = TestRun::new();
        for env in Env::ALL {
            let traces: Vec<_> = (0..7)
                .map(|i| synthetic_trace(env, i, 9 + i, 2 + i % 3))
                .collect();
            t.write_jsonl(&format!("data/{env}.jsonl"), &traces);
        }
        let summary = "SELECT t.env, t.trace_id, count(*) AS frames, avg(f.x) AS mean_x, \
                       max(f.y) AS max_y, min(t.task_id) AS task \
                       FROM traces t JOIN frames f ON f.trace_id = t.trace_id AND f.env = t.env \
                       GROUP BY t.env, t.trace_id ORDER BY t.env, t.trace_id";
        let per_env = "SELECT env, count(*) AS traces, sum(frames) AS frames, \
                       string_agg(trace_id, ',' ORDER BY trace_id) AS ids \
                       FROM {input} GROUP BY env ORDER BY env";
        let mut pipeline = String::from("[pipeline]\nname = \"p\"\nseed = 1\n");
        for env in Env::ALL {
            pipeline.push_str(&format!(
                "\n[[stage]]\nid = \"import_{env}\"\nkind = \"import\"\nenv = \"{env}\"\n\
                 paths = [\"data/{env}.jsonl\"]\ntraces_per_shard = 3\n"
            ));
        }
        let imports = Env::ALL.map(|e| format!("\"import_{e}\"")).join(", ");
        for (suffix, engine_line) in [
            ("local", String::new()),
            ("cluster", format!("engine = \"{engine}\"\n")),
        ] {
            pipeline.push_str(&format!(
                "\n[[stage]]\nid = \"summary_{suffix}\"\nkind = \"sql\"\ninputs = [{imports}]\n\
                 sql = \"{summary}\"\n{engine_line}\
                 \n[[stage]]\nid = \"per_env_{suffix}\"\nkind = \"sql\"\ninputs = [\"summary_{suffix}\"]\n\
                 sql = \"{}\"\n{engine_line}",
                per_env.replace("{input}", &format!("summary_{suffix}"))
            ));
        }
        t.write("pipelines/p.toml", &pipeline);
        t.run(&["run", "pipelines/p.toml"])
            .ok()
            .stderr_has("[per_env_cluster] done");
        t
    }

    /// `annotrace query SQL --run runs/p --format csv [--engine E]`.
    fn csv(t: &TestRun, sql: &str, engine: Option<&str>) -> String {
        let mut args = vec!["query", sql, "--run", "runs/p", "--format", "csv"];
        if let Some(e) = engine {
            args.extend(["--engine", e]);
        }
        let r = t.run(&args);
        r.ok();
        r.stdout
    }

    /// The column lines `annotrace tables` prints for `table` (name, type, nullability).
    fn columns(tables: &str, table: &str) -> Vec<String> {
        let mut lines = tables
            .lines()
            .skip_while(|l| !l.starts_with(&format!("{table}: ")));
        let head = lines
            .next()
            .unwrap_or_else(|| panic!("{table} not listed:\n{tables}"));
        let rows = head.split(' ').nth(1).unwrap().to_string();
        std::iter::once(rows)
            .chain(
                lines
                    .take_while(|l| l.starts_with("  "))
                    .map(str::to_string),
            )
            .collect()
    }

    #[test]
    fn sql_stages_and_queries_on_a_cluster_match_the_local_engine() {
        let engine = cluster();
        let t = project(engine);

        // The stages' tables: the same rows (to the last bit: csv keeps full precision) and the same
        // column types, whether the query ran here or on the cluster.
        for table in ["summary", "per_env"] {
            let local = csv(&t, &format!("SELECT * FROM {table}_local"), None);
            let cluster = csv(&t, &format!("SELECT * FROM {table}_cluster"), None);
            assert_eq!(local, cluster, "{table}");
            assert!(local.lines().count() > 3, "{local}");
        }
        let tables = t.run(&["tables", "--run", "runs/p"]);
        tables.ok();
        for table in ["summary", "per_env"] {
            assert_eq!(
                columns(&tables.stdout, &format!("{table}_local")),
                columns(&tables.stdout, &format!("{table}_cluster"))
            );
        }

        // `annotrace query --engine`: trace tables (env partitions, several files), a stage's table, an
        // absent trace table (scenes), window functions, nested types and a subquery.
        for sql in [
            "SELECT env, count(*) AS n, avg(vx) AS mean_vx, sum(x) AS sx FROM frames GROUP BY env ORDER BY env",
            "SELECT env, trace_id, n_frames, success FROM traces ORDER BY env, trace_id",
            "SELECT * FROM summary_local ORDER BY env, trace_id",
            "SELECT count(*) AS n FROM scenes",
            "SELECT e.env, e.kind, count(*) AS n, max(array_length(e.agents)) AS agents FROM events e \
             JOIN traces t ON e.trace_id = t.trace_id AND e.env = t.env GROUP BY e.env, e.kind ORDER BY 1, 2",
            "SELECT trace_id, step, x, rank() OVER (PARTITION BY trace_id ORDER BY x DESC, step) AS r \
             FROM frames WHERE env = 'pooltool' ORDER BY trace_id, step, x",
            "SELECT env, trace_id FROM traces WHERE n_frames > (SELECT avg(n_frames) FROM traces) \
             ORDER BY env, trace_id",
        ] {
            let local = csv(&t, sql, None);
            assert_eq!(csv(&t, sql, Some(engine)), local, "{sql}");
        }
        // The variable names the engine when no flag does; the flag wins over it.
        let sql = "SELECT env, count(*) AS n FROM timesteps GROUP BY env ORDER BY env";
        let by_var = t.run_env(
            &["query", sql, "--run", "runs/p", "--format", "csv"],
            &[("ANNOTRACE_SQL_ENGINE", engine)],
        );
        by_var.ok();
        assert_eq!(by_var.stdout, csv(&t, sql, None));
        t.run_env(
            &["query", sql, "--run", "runs/p", "--engine", "local"],
            &[("ANNOTRACE_SQL_ENGINE", "ballista://127.0.0.1:1")],
        )
        .ok();

        // An in-process cluster started for the one query.
        let sql = "SELECT env, count(DISTINCT trace_id) AS traces, avg(y) AS mean_y FROM frames GROUP BY env ORDER BY env";
        assert_eq!(
            csv(&t, sql, Some("ballista:standalone")),
            csv(&t, sql, None)
        );
    }

    #[test]
    fn the_cluster_reads_published_files_only_and_refuses_writes() {
        let engine = cluster();
        let t = project(engine);
        let count = "SELECT count(*) AS n FROM frames";
        let before = csv(&t, count, Some(engine));
        assert_eq!(before, csv(&t, count, None));
        // A foreign file in a table folder (a copy of a published one) is seen by neither engine.
        let folder = t.path("runs/p/frames/env=pooltool");
        let published = std::fs::read_dir(&folder)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|x| x == "parquet"))
            .unwrap();
        std::fs::copy(&published, folder.join("foreign.parquet")).unwrap();
        assert_eq!(csv(&t, count, Some(engine)), before);
        assert_eq!(csv(&t, count, None), before);

        // Writes are refused before anything reaches the cluster.
        t.run(&[
            "query",
            "COPY (SELECT * FROM traces) TO '/tmp/annotrace-ballista-copy.csv'",
            "--run",
            "runs/p",
            "--engine",
            engine,
        ])
        .code(2)
        .stderr_has("read-only");
        // A bad column is the query's fault: exit 2 with DataFusion's message.
        t.run(&[
            "query",
            "SELECT no_such_column FROM traces",
            "--run",
            "runs/p",
            "--engine",
            engine,
        ])
        .code(2)
        .stderr_has("no_such_column");
    }

    #[test]
    fn an_unreachable_scheduler_is_an_unavailable_service() {
        let t = one_trace();
        // Port 1 on loopback: nothing listens there, the connection is refused at once.
        t.run(&[
            "query",
            "SELECT count(*) FROM traces",
            "--run",
            "runs/p",
            "--engine",
            "ballista://127.0.0.1:1",
        ])
        .code(3)
        .stderr_has("the SQL engine ballista://127.0.0.1:1 is unavailable");
        // A malformed engine is a bad option value.
        t.run(&[
            "query",
            "SELECT 1",
            "--run",
            "runs/p",
            "--engine",
            "ballista://host:port",
        ])
        .code(2)
        .stderr_has("the port must be a number");
        // A pipeline's sql stage with an unreachable engine fails with the same category.
        t.write(
            "pipelines/q.toml",
            "[pipeline]\nname = \"q\"\nrun_dir = \"runs/p\"\n\n[[stage]]\nid = \"n\"\nkind = \"sql\"\n\
             sql = \"SELECT count(*) AS n FROM traces\"\nengine = \"ballista://127.0.0.1:1\"\n",
        );
        t.run(&["run", "pipelines/q.toml"])
            .code(3)
            .stderr_has("unavailable");
    }
}
