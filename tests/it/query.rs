//! `annotrace query` and `annotrace tables`: SQL over imported traces, checked against numbers
//! computed here from the same synthetic traces.

use annotrace::testutil::synthetic_trace;
use annotrace::trace::{Body, Env};

use crate::common::TestRun;

/// Imports `n` synthetic traces of each environment into run `r`.
fn setup(n: usize) -> (TestRun, Vec<annotrace::trace::Trace>) {
    let t = TestRun::new();
    let mut all = Vec::new();
    for env in Env::ALL {
        let traces: Vec<_> = (0..n)
            .map(|i| synthetic_trace(env, i, 10 + i, 3 + i % 3))
            .collect();
        let file = format!("{env}.jsonl");
        t.write_jsonl(&file, &traces);
        t.run(&[
            "import",
            "--env",
            env.as_str(),
            &file,
            "--run",
            "r",
            "--traces-per-shard",
            "4",
        ])
        .ok();
        all.extend(traces);
    }
    (t, all)
}

#[test]
fn counts_and_aggregates_match_the_traces() {
    let (t, traces) = setup(9);
    // Row counts per table and environment.
    for env in Env::ALL {
        let mine: Vec<_> = traces.iter().filter(|tr| tr.env == env).collect();
        let frames: usize = mine.iter().map(|tr| tr.frame_rows()).sum();
        let steps: usize = mine.iter().map(|tr| tr.timesteps.len()).sum();
        let got = t.csv(
            "r",
            &format!(
                "SELECT (SELECT count(*) FROM traces WHERE env = '{env}') AS traces, \
                    (SELECT count(*) FROM frames WHERE env = '{env}') AS frames, \
                    (SELECT count(*) FROM timesteps WHERE env = '{env}') AS steps, \
                    (SELECT count(*) FROM events WHERE env = '{env}') AS events"
            ),
        );
        assert_eq!(
            got,
            format!(
                "traces,frames,steps,events\n{},{frames},{steps},{}\n",
                mine.len(),
                mine.len() * 2
            )
        );
    }
    // An aggregate: mean x per trace, against the value computed from the model.
    let got = t.csv("r", "SELECT trace_id, avg(x) AS mean_x FROM frames WHERE env = 'pooltool' GROUP BY trace_id ORDER BY trace_id");
    let mut expected = String::from("trace_id,mean_x\n");
    for tr in traces.iter().filter(|tr| tr.env == Env::Pooltool) {
        let xs: Vec<f64> = tr
            .timesteps
            .iter()
            .flat_map(|s| {
                s.objects.iter().map(|o| match &o.body {
                    Body::Pool(b) => b.position[0],
                    _ => unreachable!(),
                })
            })
            .collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        expected.push_str(&format!("{},{mean}\n", tr.trace_id));
    }
    let parse = |s: &str| -> Vec<(String, f64)> {
        s.lines()
            .skip(1)
            .map(|l| {
                let (a, b) = l.split_once(',').unwrap();
                (a.to_string(), b.parse().unwrap())
            })
            .collect()
    };
    for ((ga, gb), (ea, eb)) in parse(&got).into_iter().zip(parse(&expected)) {
        assert_eq!(ga, ea);
        assert!((gb - eb).abs() < 1e-12, "{ga}: {gb} vs {eb}");
    }
    // Success rate and a join across tables.
    let got = t.csv("r", "SELECT avg(CASE WHEN success THEN 1.0 ELSE 0.0 END) AS rate FROM traces WHERE env = 'phyre'");
    assert_eq!(got, "rate\n0.5555555555555556\n");
    let got = t.csv("r", "SELECT count(*) AS n FROM events e JOIN traces t ON e.trace_id = t.trace_id AND e.env = t.env WHERE e.kind = 'contact_begin' AND array_length(e.agents) = 2");
    assert_eq!(got, "n\n27\n");
}

#[test]
fn output_formats_and_sql_errors() {
    let (t, _) = setup(2);
    let sql = "SELECT env, count(*) AS n, avg(vx) AS mean_vx FROM frames GROUP BY env ORDER BY env";
    let table = t.run(&["query", sql, "--run", "r"]);
    table.ok();
    insta::assert_snapshot!(table.stdout, @r"
    +----------+----+---------+
    | env      | n  | mean_vx |
    +----------+----+---------+
    | iphyre   | 74 |         |
    | phyre    | 74 |  1.0000 |
    | pooltool | 74 |  1.0000 |
    +----------+----+---------+
    3 rows
    ");
    let latex = t.run(&[
        "query",
        sql,
        "--run",
        "r",
        "--format",
        "latex",
        "--precision",
        "2",
    ]);
    latex
        .ok()
        .stdout_has("\\begin{tabular}{lrr}")
        .stdout_has("phyre & 74 & 1.00 \\\\");
    let md = t.run(&["query", sql, "--run", "r", "--format", "markdown"]);
    md.ok().stdout_has("| :--- | ---: | ---: |");
    let json = t.run(&["query", sql, "--run", "r", "--format", "json"]);
    let v: serde_json::Value = serde_json::from_str(&json.stdout).unwrap();
    assert_eq!(v[1]["n"], 74);
    assert!(v[0]["mean_vx"].is_null());
    t.run(&[
        "query",
        sql,
        "--run",
        "r",
        "--format",
        "parquet",
        "--out",
        "out.parquet",
    ])
    .ok();
    assert!(t.path("out.parquet").exists());
    // DataFusion's own message, exit 2.
    t.run(&["query", "SELECT nope FROM traces", "--run", "r"])
        .code(2)
        .stderr_has("No field named nope");
    t.run(&["query", "SELECT 1", "--run", "missing"])
        .code(2)
        .stderr_has("no such run folder");
    t.run(&["query", "SELECT 1", "--run", "r", "--format", "xlsx"])
        .code(2)
        .stderr_has("unknown format");
}

#[test]
fn tables_lists_rows_and_schemas() {
    let (t, _) = setup(2);
    let r = t.run(&["tables", "--run", "r"]);
    r.ok()
        .stdout_has("frames: 222 rows in 3 file(s)")
        .stdout_has("traces: 6 rows in 3 file(s)")
        .stdout_has("  object_id            Dictionary(Int32, Utf8) not null")
        .stdout_has("  env                  Utf8 not null");
}
