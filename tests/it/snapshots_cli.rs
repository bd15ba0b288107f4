//! Snapshots of the command-line output people read: pipeline validation errors, `run --explain`,
//! `query` tables, `stages`, and help texts. A change to any of them shows up as a snapshot diff to
//! review (`cargo insta review`, or `INSTA_UPDATE=always cargo test --test it snapshots_cli` and read
//! the diff of `tests/it/snapshots/`).
//!
//! Every command runs in a fresh temporary folder with relative paths, so no temporary path reaches the
//! output; the output holds no timings.

use crate::common::{Ran, TestRun, repo};

/// The exit code and both streams, as one stable text.
fn transcript(r: &Ran) -> String {
    let mut out = format!(
        "exit: {}\n",
        r.code.map_or("signal".into(), |c| c.to_string())
    );
    if !r.stdout.is_empty() {
        out.push_str("--- stdout\n");
        out.push_str(&r.stdout);
    }
    if !r.stderr.is_empty() {
        out.push_str("--- stderr\n");
        out.push_str(&r.stderr);
    }
    out
}

/// `text` with every 12-digit hex word (a stage fingerprint in `run --explain`) replaced by
/// `[fingerprint]`: fingerprints hash the resolved input paths, which lie in a fresh temporary folder.
fn redact_fingerprints(text: &str) -> String {
    text.split_inclusive(' ')
        .map(|w| {
            let word = w.trim_end();
            if word.len() == 12
                && word
                    .bytes()
                    .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
            {
                format!("[fingerprint]{}", &w[word.len()..])
            } else {
                w.to_string()
            }
        })
        .collect()
}

/// Runs `annotrace ARGS…` with help texts wrapped at 100 columns whatever the terminal.
fn run(t: &TestRun, args: &[&str]) -> Ran {
    t.run_env(args, &[("COLUMNS", "100"), ("LINES", "50")])
}

/// Runs `annotrace run pipelines/<name>.toml` on a pipeline file with this text.
fn run_pipeline(t: &TestRun, name: &str, text: &str, extra: &[&str]) -> Ran {
    let file = format!("pipelines/{name}.toml");
    t.write(&file, text);
    let mut args = vec!["run", file.as_str()];
    args.extend_from_slice(extra);
    run(t, &args)
}

/// A project folder with the committed billiards example trace and a two-stage pipeline.
fn small_project() -> TestRun {
    let t = TestRun::new();
    std::fs::copy(
        repo().join("data/examples/pooltool_straight_shot.json"),
        t.path("shot.json"),
    )
    .unwrap();
    t.write(
        "pipelines/small.toml",
        r#"[pipeline]
name = "small"
seed = 7

[[stage]]
id = "ingest"
kind = "import"
env = "pooltool"
paths = ["shot.json"]

[[stage]]
id = "count"
kind = "sql"
inputs = ["ingest"]
sql = "SELECT env, count(*) AS traces FROM traces GROUP BY env"
"#,
    );
    t
}

#[test]
fn pipeline_validation_errors() {
    let t = TestRun::new();
    let cases: &[(&str, &str)] = &[
        (
            "syntax",
            "[pipeline]\nname = \"x\"\n\n[[stage]]\nid = \"a\"\nkind = \"import\"\npaths = [\"p.json\"\n",
        ),
        (
            "unknown_kind",
            "[[stage]]\nid = \"a\"\nkind = \"anotate\"\n",
        ),
        (
            "unknown_key",
            "[[stage]]\nid = \"a\"\nkind = \"import\"\nenv = \"pooltool\"\npaths = [\"x.json\"]\ncolour = \"red\"\n",
        ),
        (
            "did_you_mean",
            "[[stage]]\nid = \"a\"\nkind = \"evolve\"\nbudgte = 3\n",
        ),
        (
            "wrong_type",
            "[[stage]]\nid = \"a\"\nkind = \"import\"\nenv = \"pooltool\"\npaths = [\"x.json\"]\ntraces_per_shard = \"many\"\n",
        ),
        (
            "other_env_param",
            "[[stage]]\nid = \"a\"\nkind = \"simulate\"\nenv = \"phyre\"\ngames = \"all\"\n",
        ),
        (
            "unknown_input",
            "[[stage]]\nid = \"a\"\nkind = \"sql\"\ninputs = [\"per_tsk\"]\nsql = \"SELECT 1\"\n",
        ),
        (
            "cycle",
            "[[stage]]\nid = \"a\"\nkind = \"sql\"\ninputs = [\"c\"]\nsql = \"SELECT 1\"\n\n\
             [[stage]]\nid = \"c\"\nkind = \"sql\"\ninputs = [\"a\"]\nsql = \"SELECT 1\"\n",
        ),
    ];
    let mut all = String::new();
    for (name, text) in cases {
        let r = run_pipeline(&t, name, text, &[]);
        all.push_str(&format!("=== {name}\n{}\n", transcript(&r)));
    }
    insta::assert_snapshot!(all);
}

#[test]
fn run_explain_before_and_after() {
    let t = small_project();
    let before = run(&t, &["run", "pipelines/small.toml", "--explain"]);
    run(&t, &["--quiet", "run", "pipelines/small.toml"]).ok();
    let after = run(&t, &["run", "pipelines/small.toml", "--explain"]);
    insta::assert_snapshot!(redact_fingerprints(&format!(
        "=== before the run\n{}\n=== after the run\n{}",
        transcript(&before),
        transcript(&after)
    )));
}

#[test]
fn query_table_output() {
    let t = small_project();
    run(&t, &["--quiet", "run", "pipelines/small.toml"]).ok();
    let traces = run(
        &t,
        &[
            "query",
            "--run",
            "runs/small",
            "SELECT trace_id, env, success, terminal_status FROM traces ORDER BY trace_id",
        ],
    );
    let events = run(
        &t,
        &[
            "query",
            "--run",
            "runs/small",
            "SELECT kind, count(*) AS n FROM events GROUP BY kind ORDER BY kind",
        ],
    );
    let empty = run(
        &t,
        &[
            "query",
            "--run",
            "runs/small",
            "SELECT trace_id FROM traces WHERE false",
        ],
    );
    let markdown = run(
        &t,
        &[
            "query",
            "--run",
            "runs/small",
            "--format",
            "markdown",
            "SELECT * FROM count",
        ],
    );
    insta::assert_snapshot!(format!(
        "=== traces\n{}\n=== events\n{}\n=== no rows\n{}\n=== markdown\n{}",
        transcript(&traces),
        transcript(&events),
        transcript(&empty),
        transcript(&markdown)
    ));
}

#[test]
fn stages_simulate() {
    let r = run(&TestRun::new(), &["stages", "simulate"]);
    insta::assert_snapshot!(transcript(&r));
}

#[test]
fn stages_evolve() {
    let r = run(&TestRun::new(), &["stages", "evolve"]);
    insta::assert_snapshot!(transcript(&r));
}

#[test]
fn help() {
    let r = run(&TestRun::new(), &["--help"]);
    insta::assert_snapshot!(transcript(&r));
}

#[test]
fn simulate_help() {
    let r = run(&TestRun::new(), &["simulate", "--help"]);
    insta::assert_snapshot!(transcript(&r));
}
