//! `annotrace evolve` and the `evolve` stage: fitness goes up on a seeded run, the grown library loads
//! and annotates, a killed search resumes to exactly the uninterrupted result, D_x is reused, the
//! baselines run on the same budget, and the paper's statistics come out of the SQL files.

use std::collections::BTreeMap;

use annotrace::detect::Library;

use crate::common::{TestRun, repo};

/// A simulate stage and an evolve stage with reproducible scores (no time penalty).
fn pipeline(extra: &str) -> String {
    format!(
        r#"[pipeline]
name = "evt"
seed = 6

[[stage]]
id = "sim"
kind = "simulate"
env = "pooltool"
scenes = 14
shots = 1
seed = 3
dt = 0.1

[[stage]]
id = "evo"
kind = "evolve"
inputs = ["sim"]
env = "pooltool"
library = "{lib}"
labels = ["ball slowing", "cushion rebound"]
budget = 8
parallel = 4
max_traces = 12
time_penalty = false
timeout = 3.0
workers = 2
{extra}
"#,
        lib = repo().join("data/libraries/pooltool").display()
    )
}

/// (label, step, code hash, status, ν rounded) of every candidate, in order.
fn candidates(t: &TestRun) -> Vec<String> {
    t.csv(
        "runs/evt",
        "SELECT label, step, island, code_hash, status, round(nu, 9) AS nu, parents FROM candidates \
         ORDER BY label_index, step",
    )
    .lines()
    .map(str::to_string)
    .collect()
}

fn by_label(t: &TestRun) -> BTreeMap<String, (f64, f64, bool)> {
    let csv = t.csv(
        "runs/evt",
        "SELECT label, seed_nu, best_nu, accepted FROM evolution_labels ORDER BY label_index",
    );
    csv.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (
                f[0].to_string(),
                (f[1].parse().unwrap(), f[2].parse().unwrap(), f[3] == "true"),
            )
        })
        .collect()
}

#[test]
fn a_seeded_search_raises_fitness_and_its_library_annotates() {
    let t = TestRun::new();
    t.write("p.toml", &pipeline(""));
    t.run(&["run", "p.toml"]).ok();
    let labels = by_label(&t);
    let (seed, best, accepted) = labels["ball slowing"];
    assert!(best > seed, "ball slowing: {seed} -> {best}");
    assert!(accepted);
    // The best never falls below the seed program.
    let (seed2, best2, _) = labels["cushion rebound"];
    assert!(best2 >= seed2);
    // Every candidate is recorded: seeds plus the budget per label, with every term of scored ones.
    let rows = candidates(&t);
    assert_eq!(rows.len() - 1, 2 * (8 + 1), "{rows:#?}");
    let terms = t.csv(
        "runs/evt",
        "SELECT count(*) AS n FROM candidates WHERE status IN ('ok', 'seed') AND \
         (rho IS NULL OR eta IS NULL OR lambda IS NULL OR psi IS NULL OR nu IS NULL OR \
         abs(nu - (rho + eta - lambda - psi)) > 1e-9 OR activation_rate IS NULL OR mean_time_s IS NULL)",
    );
    assert_eq!(terms.lines().nth(1), Some("0"), "{terms}");
    // Acceptance: ν > δ and a positive held-out ρ (the training ρ without held-out traces), recorded
    // with the d_p used.
    let bad = t.csv(
        "runs/evt",
        "SELECT count(*) AS n FROM evolution_labels WHERE dp <> 'kl' OR \
         accepted <> (acceptance = 'accepted') OR \
         (accepted AND (best_nu <= delta OR coalesce(holdout_rho, best_rho) <= 0)) OR \
         (acceptance = 'nonpositive_rho' AND coalesce(holdout_rho, best_rho) > 0)",
    );
    assert_eq!(bad.lines().nth(1), Some("0"), "{bad}");
    // ρ recomputed in SQL from the stored histograms and D_x equals the search's, to 1e-9.
    let sql =
        std::fs::read_to_string(repo().join("sql/evolution_fitness_correlation.sql")).unwrap();
    let check = t.csv(
        "runs/evt",
        &format!(
            "WITH s AS ({}) SELECT s.label, s.split, s.pairs, s.rho, \
             CASE WHEN s.split = 'train' THEN l.best_rho ELSE l.holdout_rho END AS rust_rho \
             FROM s JOIN evolution_labels AS l ON l.run_stage = s.run_stage AND l.label = s.label \
             ORDER BY s.label, s.split",
            sql.lines()
                .filter(|l| !l.trim_start().starts_with("--"))
                .collect::<Vec<_>>()
                .join("\n")
        ),
    );
    let rows: Vec<Vec<String>> = check
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    assert!(
        rows.iter().filter(|r| r[1] == "train").count() == 2,
        "{check}"
    );
    for r in &rows {
        let (sql_rho, rust_rho): (f64, f64) = (r[3].parse().unwrap(), r[4].parse().unwrap());
        assert!((sql_rho - rust_rho).abs() < 1e-9, "{check}");
    }
    // The grown library loads, holds the improved detector, and annotate uses it directly.
    let dir = t.path("runs/evt/exports/evo/library");
    let lib = Library::load(&dir).unwrap();
    assert_eq!(lib.detectors.len(), 12);
    let slowing = lib
        .detectors
        .iter()
        .find(|d| d.label == "ball slowing")
        .unwrap();
    let original = Library::load(&repo().join("data/libraries/pooltool")).unwrap();
    let before = original
        .detectors
        .iter()
        .find(|d| d.label == "ball slowing")
        .unwrap();
    assert_ne!(
        slowing.code, before.code,
        "the improved program replaced the original"
    );
    t.run(&[
        "annotate",
        "--run",
        "runs/evt",
        "--library",
        dir.to_str().unwrap(),
        "--workers",
        "2",
    ])
    .ok();
    let n = t.csv(
        "runs/evt",
        &format!(
            "SELECT count(*) AS n FROM annotations WHERE detector_id = '{}'",
            slowing.id
        ),
    );
    assert_ne!(n.lines().nth(1), Some("0"), "{n}");
}

#[test]
fn a_killed_search_resumes_and_equals_an_uninterrupted_one() {
    let whole = TestRun::new();
    whole.write("p.toml", &pipeline(""));
    whole.run(&["run", "p.toml"]).ok();
    let expected = candidates(&whole);

    let t = TestRun::new();
    t.write("p.toml", &pipeline(""));
    // Shards: dx, then label 0's rounds 0 (seed), 1, 2: stop (abort, as kill -9) after round 1.
    let r = t.run_env(
        &["run", "p.toml"],
        &[("ANNOTRACE_FAULT", "evo:after-shards=3")],
    );
    assert_ne!(r.code, Some(0), "the fault should stop the run");
    let r = t.run(&["run", "p.toml"]);
    r.ok().stderr_has("resuming");
    assert_eq!(candidates(&t), expected);
    assert_eq!(
        std::fs::read_to_string(t.path("runs/evt/exports/evo/library/ball_slowing.py")).unwrap(),
        std::fs::read_to_string(whole.path("runs/evt/exports/evo/library/ball_slowing.py"))
            .unwrap()
    );
}

#[test]
fn baselines_run_on_the_same_budget_and_the_distance_matrix_is_reused() {
    let t = TestRun::new();
    let extra = r#"
[[stage]]
id = "hill"
kind = "evolve"
inputs = ["sim"]
env = "pooltool"
labels = ["ball slowing"]
strategy = "hill-climb"
budget = 8
parallel = 4
max_traces = 12
time_penalty = false
timeout = 3.0
workers = 2
convergence_per_bin = 0

[[stage]]
id = "bon"
kind = "evolve"
inputs = ["sim"]
env = "pooltool"
labels = ["ball slowing"]
strategy = "best-of-n"
budget = 8
parallel = 4
max_traces = 12
time_penalty = false
timeout = 3.0
workers = 2
convergence_per_bin = 0

[[stage]]
id = "stats"
kind = "sql"
inputs = ["evo", "hill", "bon"]
query = "evolution_learning_stats.sql"

[[stage]]
id = "stats_tex"
kind = "export"
inputs = ["stats"]
table = "stats"
format = "latex"

[[stage]]
id = "conv"
kind = "sql"
inputs = ["evo"]
query = "evolution_convergence.sql"

[[stage]]
id = "progress"
kind = "sql"
inputs = ["evo", "hill", "bon"]
query = "evolution_progress.sql"
"#;
    t.write("p.toml", &pipeline(extra));
    std::fs::create_dir_all(t.path("sql")).unwrap();
    for f in [
        "evolution_learning_stats.sql",
        "evolution_convergence.sql",
        "evolution_progress.sql",
    ] {
        std::fs::copy(repo().join("sql").join(f), t.path("sql").join(f)).unwrap();
    }
    t.run(&["run", "p.toml"]).ok();
    let per_stage = t.csv(
        "runs/evt",
        "SELECT run_stage, strategy, count(*) AS n FROM candidates WHERE step >= 0 \
         GROUP BY run_stage, strategy ORDER BY run_stage",
    );
    assert!(per_stage.contains("bon,best-of-n,8"), "{per_stage}");
    assert!(per_stage.contains("hill,hill-climb,8"), "{per_stage}");
    // best-of-n always mutates the seed program.
    let parents = t.csv(
        "runs/evt",
        "SELECT count(DISTINCT parents) AS n FROM candidates WHERE run_stage = 'bon' AND step >= 0",
    );
    assert_eq!(parents.lines().nth(1), Some("1"), "{parents}");
    // One D_x matrix for the three searches over the same training set (11 of the 14 traces after
    // the held-out split): 11·10/2 pairs, written once. (3 held-out traces are too few for a
    // held-out ρ, so no held-out D_x.)
    let dx = t.csv(
        "runs/evt",
        "SELECT count(*) AS n, count(DISTINCT set_id) AS sets FROM trace_distances",
    );
    assert_eq!(dx.lines().nth(1), Some("55,1"), "{dx}");
    // Appendix A's table, the convergence bins and the progress curve.
    let stats = t.csv("runs/evt", "SELECT * FROM stats");
    assert!(
        stats.starts_with("env,candidates,executable_pct,best_fitness"),
        "{stats}"
    );
    assert!(stats.contains("pooltool,32,"), "{stats}");
    let tex = std::fs::read_to_string(t.path("runs/evt/exports/stats.tex")).unwrap();
    assert!(tex.contains("tabular"), "{tex}");
    let conv = t.csv("runs/evt", "SELECT * FROM conv");
    assert!(conv.starts_with("env,bin,"), "{conv}");
    let progress = t.csv(
        "runs/evt",
        "SELECT min(best_so_far_nu - seed_nu) AS d FROM progress",
    );
    let d: f64 = progress.lines().nth(1).unwrap().parse().unwrap();
    assert!(d >= 0.0, "{progress}");
}

#[test]
fn bad_input_is_refused_with_exit_2() {
    let t = TestRun::new();
    std::fs::create_dir_all(t.path("empty")).unwrap();
    t.run(&["evolve", "--run", "empty", "--labels", "rolling ball"])
        .code(2)
        .stderr_has("at least 3 pooltool traces");
    t.run(&["evolve", "--run", "nowhere"]).code(2);
    t.write("p.toml", &pipeline("").replace("budget = 8", "budget = 0"));
    t.run(&["run", "p.toml"]).code(2).stderr_has("budget");
    t.write("p.toml", &pipeline("dp = \"kld\""));
    t.run(&["run", "p.toml"])
        .code(2)
        .stderr_has("dp")
        .stderr_has("kl");
    t.run(&["evolve", "--run", "empty", "--dp", "entropy"])
        .code(2)
        .stderr_has("cross-entropy");
}

#[test]
fn the_llm_proposer_drives_a_search_with_repairs_through_a_chat_server() {
    use crate::common::chat_server::{ChatServer, Reply};
    use annotrace::search::skeleton::skeleton;
    use annotrace::trace::Env;

    let good =
        skeleton(Env::Pooltool, "moving ball").replace("THRESHOLD = 0.05", "THRESHOLD = 0.3");
    let answer = format!("Here is a better detector:\n\n```python\n{good}```\n");
    let server = ChatServer::responder(move |seen| {
        if seen.last_message().contains("syntax") {
            Reply::chat(&answer)
        } else {
            Reply::chat("```python\ndef find_pattern(trace:\n    return []\n```")
        }
    });
    let t = TestRun::new();
    t.run(&[
        "simulate", "--run", "r", "--scenes", "8", "--seed", "4", "--dt", "0.1", "-q",
    ])
    .ok();
    let r = t.run(&[
        "evolve",
        "--run",
        "r",
        "--labels",
        "moving ball",
        "--budget",
        "2",
        "--parallel",
        "2",
        "--no-time-penalty",
        "--workers",
        "2",
        "--llm-base-url",
        &server.url(),
        "--llm-model",
        "scripted",
    ]);
    r.ok()
        .stdout_has("llm:scripted proposer")
        .stdout_has("outside the proposer");
    let rows = t.csv(
        "r",
        "SELECT step, proposer, status, repairs, calls, tokens_in > 0 AS paid FROM candidates \
         WHERE step >= 0 ORDER BY step",
    );
    assert!(rows.contains("0,llm:scripted,"), "{rows}");
    for line in rows.lines().skip(1) {
        // Each child came back broken, was repaired once and then ran (or repeated the repaired one).
        assert!(line.ends_with(",1,2,true"), "{rows}");
        assert!(!line.contains(",syntax,"), "{rows}");
    }
    let calls = t.csv("r", "SELECT count(*) AS n FROM llm_calls");
    assert_eq!(calls.lines().nth(1), Some("4"), "{calls}");
}

/// With enough held-out traces the acceptance uses the held-out ρ: the held-out D_x is stored as its
/// own set, the best program's held-out histograms are stored, and SQL recomputes that ρ to 1e-9.
#[test]
fn acceptance_uses_the_held_out_rho_and_sql_recomputes_it() {
    let t = TestRun::new();
    let p = pipeline("holdout = 0.5\nconvergence_per_bin = 0")
        .replace("scenes = 14", "scenes = 24")
        .replace(
            "labels = [\"ball slowing\", \"cushion rebound\"]",
            "labels = [\"ball slowing\"]",
        )
        .replace("budget = 8", "budget = 2");
    t.write("p.toml", &p);
    t.run(&["run", "p.toml"]).ok();
    let row = t.csv(
        "runs/evt",
        "SELECT holdout_rho IS NOT NULL AS has, holdout_set_id IS NOT NULL AS set, \
         accepted = (best_nu > delta AND holdout_rho > 0) AS rule FROM evolution_labels",
    );
    assert_eq!(row.lines().nth(1), Some("true,true,true"), "{row}");
    let sets = t.csv(
        "runs/evt",
        "SELECT count(DISTINCT set_id) AS n FROM trace_distances",
    );
    assert_eq!(sets.lines().nth(1), Some("2"), "{sets}");
    let sql =
        std::fs::read_to_string(repo().join("sql/evolution_fitness_correlation.sql")).unwrap();
    let body: Vec<&str> = sql
        .lines()
        .filter(|l| !l.trim_start().starts_with("--"))
        .collect();
    let check = t.csv(
        "runs/evt",
        &format!(
            "WITH s AS ({}) SELECT abs(s.rho - l.holdout_rho) < 1e-9 AS same, s.pairs >= 28 AS enough \
             FROM s JOIN evolution_labels AS l ON l.run_stage = s.run_stage AND l.label = s.label \
             WHERE s.split = 'holdout'",
            body.join("\n")
        ),
    );
    assert_eq!(check.lines().nth(1), Some("true,true"), "{check}");
}

/// Reads an SQL file of the repository without its comment lines.
fn sql_body(name: &str) -> String {
    std::fs::read_to_string(repo().join("sql").join(name))
        .unwrap()
        .lines()
        .filter(|l| !l.trim_start().starts_with("--"))
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn sampled_candidates_keep_their_held_out_rho_and_sql_recomputes_it_and_the_convergence() {
    let t = TestRun::new();
    let p = pipeline(
        "holdout = 0.5\nconvergence_per_bin = 2\ndx = \"invariant\"\naccuracy_guard = true",
    )
    .replace("scenes = 14", "scenes = 24");
    t.write("p.toml", &p);
    t.run(&["run", "p.toml"]).ok();
    let labels = t.csv("runs/evt", "SELECT DISTINCT dx FROM evolution_labels");
    assert_eq!(labels, "dx\ninvariant\n", "{labels}");
    let samples = t.csv(
        "runs/evt",
        "SELECT count(*) AS n, count(holdout_rho) AS rho, count(DISTINCT bin) AS bins FROM evolution_samples",
    );
    let n: Vec<i64> = samples
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(n[0] >= 2 && n[0] == n[1] && n[2] >= 1, "{samples}");
    // ρ of every sampled candidate, recomputed from its stored held-out histograms and D_x.
    let rho = t.csv(
        "runs/evt",
        &format!(
            "WITH s AS ({}) SELECT count(*) AS n, max(abs(coalesce(s.rho, 0.0) - e.holdout_rho)) AS diff \
             FROM s JOIN evolution_samples AS e ON e.run_stage = s.run_stage AND e.label = s.label \
             AND e.code_hash = s.code_hash WHERE s.split = 'sample'",
            sql_body("evolution_fitness_correlation.sql")
        ),
    );
    let row: Vec<f64> = rho
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(row[0], n[0] as f64, "{rho}");
    assert!(row[1] < 1e-9, "{rho}");
    // The convergence similarity, pair by pair.
    let conv = t.csv(
        "runs/evt",
        &format!(
            "WITH s AS ({}) SELECT count(*) AS n, max(abs(s.similarity - c.similarity)) AS diff, \
             sum(CASE WHEN s.traces = c.traces THEN 1 ELSE 0 END) AS same_traces, \
             (SELECT count(*) FROM evolution_convergence) AS rust \
             FROM s JOIN evolution_convergence AS c ON c.run_stage = s.run_stage AND c.label = s.label \
             AND c.bin = s.bin AND c.code_hash = s.code_hash AND c.final_hash = s.final_hash",
            sql_body("evolution_convergence_similarity.sql")
        ),
    );
    let row: Vec<f64> = conv
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        row[0] > 0.0 && row[0] == row[3] && row[2] == row[0],
        "{conv}"
    );
    assert!(row[1] < 1e-9, "{conv}");
}

/// `annotrace evolve` with an LLM proposer against `server`, budget 4 for one label.
fn evolve_with(t: &TestRun, server: &crate::common::chat_server::ChatServer) -> crate::common::Ran {
    t.run(&[
        "evolve",
        "--run",
        "r",
        "--labels",
        "moving ball",
        "--budget",
        "4",
        "--parallel",
        "2",
        "--repair-attempts",
        "0",
        "--no-time-penalty",
        "--workers",
        "1",
        "--llm-base-url",
        &server.url(),
        "--llm-model",
        "scripted",
    ])
}

#[test]
fn a_search_whose_every_llm_proposal_failed_is_a_failure_and_partial_failures_are_reported() {
    use crate::common::chat_server::{ChatServer, Reply};
    use annotrace::search::skeleton::skeleton;
    use annotrace::trace::Env;
    use std::sync::atomic::{AtomicUsize, Ordering};

    let t = TestRun::new();
    t.run(&[
        "simulate", "--run", "r", "--scenes", "8", "--seed", "4", "--dt", "0.1", "-q",
    ])
    .ok();
    // Every answer is prose without code: the library's seed would have been "accepted" before.
    let garbage = ChatServer::responder(|_| Reply::chat("lorem ipsum, no code today"));
    evolve_with(&t, &garbage)
        .code(1)
        .stderr_has("all 4 proposal(s) of the llm:scripted proposer failed (4 without a program, 0 whose program did not run)")
        .stderr_has("the first: label \"moving ball\" step ")
        .stderr_has("no Python code in the answer; it starts: lorem ipsum");
    assert_eq!(garbage.seen().len(), 4);
    // The failed stage committed nothing, but the calls are recorded.
    let tables = t.run(&["tables", "--run", "r"]);
    assert!(!tables.stdout.contains("candidates"), "{}", tables.stdout);
    let calls = t.csv("r", "SELECT count(*) AS n FROM llm_calls");
    assert_eq!(calls.lines().nth(1), Some("4"), "{calls}");

    // One garbage answer among good ones: the search succeeds and says what failed.
    let good =
        skeleton(Env::Pooltool, "moving ball").replace("THRESHOLD = 0.05", "THRESHOLD = 0.3");
    let answer = format!("```python\n{good}```\n");
    let n = AtomicUsize::new(0);
    let mixed = ChatServer::responder(move |_| {
        if n.fetch_add(1, Ordering::SeqCst) == 0 {
            Reply::chat("sorry, I cannot help with that")
        } else {
            Reply::chat(&answer)
        }
    });
    evolve_with(&t, &mixed)
        .ok()
        .stdout_has("proposals: 1 of 4 proposal(s) failed (1 without a program, 0 whose program did not run)")
        .stdout_has("it starts: sorry, I cannot help");
}

/// An endpoint that refuses the request itself (401: bad credentials) is a configuration error, exit 2
/// as in `suggest-labels`, not an unreachable service (3); it is not retried.
#[test]
fn an_endpoint_refusing_the_request_ends_evolve_as_bad_configuration() {
    use crate::common::chat_server::{ChatServer, Reply};

    let t = TestRun::new();
    t.run(&[
        "simulate", "--run", "r", "--scenes", "8", "--seed", "4", "--dt", "0.1", "-q",
    ])
    .ok();
    let refusing = ChatServer::responder(|_| Reply::Status {
        code: 401,
        retry_after: None,
        body: "{\"error\":\"invalid api key\"}".into(),
    });
    evolve_with(&t, &refusing)
        .code(2)
        .stderr_has("proposer refused")
        .stderr_has("401");
    // `evolve_with` runs two proposals per round, and with lag 1 (the LLM default) the next round's
    // two are sent before the first round is scored: each asked once, none retried.
    let seen = refusing.seen();
    let bodies: std::collections::BTreeSet<String> =
        seen.iter().map(|s| s.body.to_string()).collect();
    assert!(seen.len() <= 4, "{} requests", seen.len());
    assert_eq!(bodies.len(), seen.len(), "a request was retried");
}

/// A scripted model answering each evolve request with the skeleton of the prompt's label, its
/// threshold set by the prompt's search step, after `ms` milliseconds: the same request always gets
/// the same child.
fn stepwise_model(ms: u64) -> crate::common::chat_server::ChatServer {
    use crate::common::chat_server::{ChatServer, Reply};
    use annotrace::search::skeleton::skeleton;
    use annotrace::trace::Env;
    ChatServer::responder(move |seen| {
        let prompt = seen.last_message();
        let field = |name: &str| {
            prompt
                .lines()
                .find_map(|l| l.strip_prefix(name))
                .unwrap_or_default()
                .trim()
                .to_string()
        };
        let step: u64 = field("Search step:").parse().unwrap_or(0);
        let code = skeleton(Env::Pooltool, &field("Pattern to detect:")).replace(
            "THRESHOLD = 0.05",
            &format!("THRESHOLD = {:.3}", 0.02 + 0.037 * step as f64),
        );
        Reply::slow(ms, Reply::chat(&format!("```python\n{code}```\n")))
    })
}

/// The search steps a scripted model was asked for after its first `skip` requests, sorted.
fn steps_asked(server: &crate::common::chat_server::ChatServer, skip: usize) -> Vec<u64> {
    let mut steps: Vec<u64> = server
        .seen()
        .iter()
        .skip(skip)
        .filter_map(|s| {
            s.last_message()
                .lines()
                .find_map(|l| l.strip_prefix("Search step:"))
                .and_then(|v| v.trim().parse().ok())
        })
        .collect();
    steps.sort_unstable();
    steps
}

/// With `lag = 1` an LLM search sends round r + 1's requests while round r is scored; killed after
/// round 1 is saved (round 2 being scored or in flight), it resumes without asking the model for
/// saved rounds or for calls its stopped attempt recorded in `llm_calls`, and ends with exactly the
/// candidates of an uninterrupted run.
#[test]
fn an_overlapped_llm_search_resumes_without_asking_again_and_equals_an_uninterrupted_one() {
    let stage = |url: &str| {
        pipeline(&format!(
            "proposer = \"llm\"\nlag = 1\nllm = {{ base_url = \"{url}\", model = \"scripted\" }}"
        ))
        .replace(
            "labels = [\"ball slowing\", \"cushion rebound\"]",
            "labels = [\"ball slowing\"]",
        )
        .replace("budget = 8", "budget = 12")
    };
    let whole = TestRun::new();
    let server = stepwise_model(50);
    whole.write("p.toml", &stage(&server.url()));
    whole.run(&["run", "p.toml"]).ok();
    assert_eq!(steps_asked(&server, 0), (0..12).collect::<Vec<u64>>());
    let expected = candidates(&whole);
    assert_eq!(expected.len(), 1 + 1 + 12, "{expected:?}");

    let t = TestRun::new();
    let model = stepwise_model(50);
    t.write("p.toml", &stage(&model.url()));
    // Shards: dx, then rounds 0 (seed) and 1: the process aborts after saving round 1.
    let r = t.run_env(
        &["run", "p.toml"],
        &[("ANNOTRACE_FAULT", "evo:after-shards=3")],
    );
    assert_ne!(r.code, Some(0), "the fault should stop the run");
    assert!(steps_asked(&model, 0).starts_with(&[0, 1, 2, 3]));
    // The steps whose answers the stopped attempt recorded (its last second's may be lost).
    let calls = t.csv(
        "runs/evt",
        "SELECT request_json FROM llm_calls WHERE status = 'ok'",
    );
    let recorded: std::collections::BTreeSet<u64> = calls
        .split("Search step: ")
        .skip(1)
        .filter_map(|rest| {
            let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
            digits.parse().ok()
        })
        .collect();
    assert!(recorded.is_superset(&(0..4).collect()), "{recorded:?}");
    let before = model.seen().len();
    t.run(&["run", "p.toml"]).ok().stderr_has("resuming");
    let unrecorded: Vec<u64> = (4..12).filter(|s| !recorded.contains(s)).collect();
    assert_eq!(steps_asked(&model, before), unrecorded);
    assert_eq!(candidates(&t), expected);
}
