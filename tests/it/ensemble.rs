//! `ensemble` (paper section 3.3): an offline learn → ensemble pipeline for pooltool at a tiny size,
//! its tables and library folders, the library read back by `annotate` and `show`, and resumption after
//! a kill in the middle of the ensemble stage; calibration (b) against the identification objective
//! through the local scripted chat server, replayed from the recorded calls, and its offline fallback.

use crate::common::chat_server::{ChatServer, Reply};
use crate::common::{TestRun, repo};

/// Simulate, two seeded evolve stages over the same labels, an ensemble stage, the comparison.
fn pipeline() -> String {
    let evolve = |s: u32| {
        format!(
            r#"
[[stage]]
id = "evo{s}"
kind = "evolve"
inputs = ["sim"]
env = "pooltool"
library = "{lib}"
labels = ["ball slowing", "cushion rebound"]
seed = {s}
budget = 3
parallel = 3
max_traces = 12
time_penalty = false
convergence_per_bin = 0
timeout = 3.0
workers = 2
"#,
            lib = repo().join("data/libraries/pooltool").display()
        )
    };
    format!(
        r#"[pipeline]
name = "ens"
seed = 6

[[stage]]
id = "sim"
kind = "simulate"
env = "pooltool"
scenes = 20
shots = 1
seed = 3
dt = 0.1
{}{}
[[stage]]
id = "ens"
kind = "ensemble"
inputs = ["evo1", "evo2"]
env = "pooltool"
signature_traces = 4
calibration_traces = 8
test_fraction = 0.35
test_traces = 8
sweep_points = 4
bo_iterations = 3
timeout = 3.0
workers = 2

[[stage]]
id = "cmp"
kind = "sql"
inputs = ["ens"]
query = "{sql}"
"#,
        evolve(1),
        evolve(2),
        sql = repo().join("sql/ensemble_comparison.sql").display()
    )
}

/// Every ensemble table, as CSV, in a stable order.
fn tables(t: &TestRun) -> Vec<String> {
    [
        "SELECT label, source, code_hash, cluster_index, nu, representative, distance FROM ensemble_members ORDER BY label, code_hash",
        "SELECT label, cluster_index, k, k_rule, silhouette, size, representative, nu FROM ensemble_clusters ORDER BY label, cluster_index",
        "SELECT method, objective, label, iteration, gamma, eps_s, eps_t, weights, score, chosen FROM ensemble_calibration ORDER BY method, label, iteration",
        "SELECT variant, source, label, traces, rho, activation_rate, f1 FROM ensemble_evaluation ORDER BY variant, source, label",
        "SELECT variant, libraries, labels, rho_mean, rho_std_over_seeds FROM cmp ORDER BY variant",
    ]
    .iter()
    .map(|q| t.csv("runs/ens", q))
    .collect()
}

#[test]
fn a_killed_ensemble_stage_resumes_to_the_same_tables_and_its_library_annotates() {
    let whole = TestRun::new();
    whole.write("p.toml", &pipeline());
    whole.run(&["run", "p.toml"]).ok();
    let expected = tables(&whole);
    // Both runs' candidates were pooled, every label got at least one cluster, and every variant was
    // scored on the test traces.
    assert!(
        expected[0].contains("evo1") && expected[0].contains("evo2"),
        "{}",
        expected[0]
    );
    for label in ["ball slowing", "cushion rebound"] {
        assert!(expected[1].contains(label), "{}", expected[1]);
    }
    for variant in ["ensemble", "sp", "baseline", "run"] {
        assert!(expected[3].contains(variant), "{}", expected[3]);
    }
    assert!(
        expected[2].contains("sweep") && expected[2].contains("bo,heldout-rho"),
        "{}",
        expected[2]
    );
    let manifest = std::fs::read_to_string(whole.path("runs/ens/manifest.json")).unwrap();
    assert!(
        manifest.contains("\"objective\": \"heldout-rho\""),
        "the manifest records the objective"
    );
    let lib = whole.path("runs/ens/exports/ens/library");
    let toml = std::fs::read_to_string(lib.join("library.toml")).unwrap();
    assert!(
        toml.contains("[[ensemble]]")
            && toml.contains("candidate = ")
            && toml.contains("eps_s = ")
            && toml.contains("reward = ")
    );
    assert!(
        whole
            .path("runs/ens/exports/ens/library-sp/library.toml")
            .is_file()
    );

    // Killed (abort, as kill -9) after the first label's shard; the rerun resumes and ends equal.
    let t = TestRun::new();
    t.write("p.toml", &pipeline());
    let r = t.run_env(
        &["run", "p.toml"],
        &[("ANNOTRACE_FAULT", "ens:after-shards=1")],
    );
    assert_ne!(r.code, Some(0), "the fault should stop the run");
    t.run(&["run", "p.toml"]).ok().stderr_has("resuming");
    assert_eq!(tables(&t), expected);
    assert_eq!(
        std::fs::read_to_string(t.path("runs/ens/exports/ens/library/library.toml")).unwrap(),
        toml
    );

    // The ensemble library annotates like any other: ensemble annotations with an activation in
    // (γ, 1] and their members, shown by `show`.
    let lib = lib.display().to_string();
    whole
        .run(&[
            "annotate",
            "--run",
            "runs/ens",
            "--env",
            "pooltool",
            "--library",
            &lib,
            "--workers",
            "2",
        ])
        .ok();
    let acts = whole.csv(
        "runs/ens",
        "SELECT count(*) AS n, min(activation) AS lo, max(activation) AS hi, \
                sum(CASE WHEN metadata LIKE '%\"ensemble\"%' THEN 1 ELSE 0 END) AS ens \
         FROM annotations",
    );
    let row: Vec<f64> = acts
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap_or(f64::NAN))
        .collect();
    if row[0] > 0.0 {
        assert_eq!(
            row[0], row[3],
            "every annotation is an ensemble annotation: {acts}"
        );
        assert!(row[1] > 0.0 && row[2] <= 1.0, "{acts}");
        let trace = whole.csv(
            "runs/ens",
            "SELECT trace_id FROM annotations ORDER BY trace_id LIMIT 1",
        );
        let trace = trace.lines().nth(1).unwrap().to_string();
        whole
            .run(&["show", "--run", "runs/ens", "--trace", &trace])
            .ok()
            .stdout_has("[ensemble a=");
    }
    let dets = whole.csv(
        "runs/ens",
        "SELECT count(*) AS n FROM detectors WHERE source LIKE '%ensemble:%'",
    );
    assert_eq!(dets, "n\n2\n", "one pseudo-detector per ensemble label");
}

#[test]
fn bad_ensemble_parameters_are_refused_with_the_parameter_named() {
    let t = TestRun::new();
    t.write(
        "p.toml",
        &pipeline().replace("sweep_points = 4", "sweep_points = 4\ngamma = 1.5"),
    );
    t.run(&["run", "p.toml"]).code(2).stderr_has("gamma");
    t.write(
        "p.toml",
        &pipeline().replace("sweep_points = 4", "sweep_points = 4\nruns = [\"nowhere\"]"),
    );
    t.run(&["run", "p.toml"])
        .code(2)
        .stderr_has("not a run folder");
    // No candidates to pool: the run has traces but no evolve stage.
    t.run(&[
        "simulate", "--run", "bare", "--scenes", "16", "--seed", "1", "--dt", "0.1", "-q",
    ])
    .ok();
    t.run(&[
        "ensemble",
        "--run",
        "bare",
        "--signature-traces",
        "2",
        "--calibration-traces",
        "4",
    ])
    .code(2)
    .stderr_has("no valid pooltool candidate");
}

/// The tiny pipeline with calibration (b) maximising identification accuracy (8 calibration traces,
/// 8 summaries per trial, one BO step after the 4 starting points), with `llm` as its LLM settings.
fn identification_pipeline(llm: &str) -> String {
    pipeline().replace(
        "bo_iterations = 3",
        &format!(
            "bo_iterations = 1\nobjective = \"identification\"\nidentification_traces = 8\noptions = 8\nkeyframes = 2\nimage_size = 96\n{llm}"
        ),
    )
}

/// Summaries name the request seed (so they differ by trace); choices pick the summary whose
/// number is the seed of the request modulo 8, plus one (a deterministic, imperfect chooser).
fn scripted() -> ChatServer {
    ChatServer::responder(|s| {
        let seed = s.body["seed"].as_u64().unwrap_or(0);
        if s.body
            .to_string()
            .contains("Which summary describes this rollout?")
        {
            Reply::chat(&format!("Answer: {}", seed % 8 + 1))
        } else {
            Reply::chat(&format!("The balls move (request {seed})."))
        }
    })
}

#[test]
fn identification_calibration_runs_through_the_chat_server_and_replays() {
    let server = scripted();
    let t = TestRun::new();
    let llm = format!(
        "llm = {{ base_url = \"{}\", model = \"vlm\", max_retries = 0 }}",
        server.url()
    );
    t.write("p.toml", &identification_pipeline(&llm));
    t.run(&["run", "p.toml"]).ok();
    // 5 points (the sweep's optimum, 3 random, 1 EI step) × 8 traces × (summary + choice).
    let asked = server.seen().len();
    assert_eq!(asked, 80, "calls to the endpoint");
    let calls = t.csv(
        "runs/ens",
        "SELECT purpose, count(*) AS n FROM llm_calls GROUP BY purpose ORDER BY purpose",
    );
    assert_eq!(
        calls, "purpose,n\nidentify,40\nsummarise_annotations,40\n",
        "{calls}"
    );
    let bo = t.csv(
        "runs/ens",
        "SELECT DISTINCT objective, score FROM ensemble_calibration WHERE method = 'bo' ORDER BY score",
    );
    assert!(
        bo.lines().skip(1).all(|l| l.starts_with("identification,")),
        "{bo}"
    );
    // Scores are identification accuracies: multiples of 1/8 in [0, 1].
    for l in bo.lines().skip(1) {
        let v: f64 = l.split(',').nth(1).unwrap().parse().unwrap();
        assert!((0.0..=1.0).contains(&v) && (v * 8.0).fract() == 0.0, "{bo}");
    }
    let manifest = std::fs::read_to_string(t.path("runs/ens/manifest.json")).unwrap();
    assert!(
        manifest.contains("\"objective\": \"identification\""),
        "manifest"
    );
    assert!(
        manifest.contains("maximised identification accuracy"),
        "manifest note"
    );

    // Replayed into a fresh run from the recorded calls: the endpoint is not asked again and the
    // calibration and the library are the same.
    let r = TestRun::new();
    let replay = format!(
        "llm = {{ replay = \"{}\", model = \"vlm\" }}",
        t.path("runs/ens").display()
    );
    r.write("p.toml", &identification_pipeline(&replay));
    r.run(&["run", "p.toml"]).ok();
    assert_eq!(server.seen().len(), asked, "the replay asked the endpoint");
    let q = "SELECT method, objective, label, iteration, gamma, eps_s, eps_t, weights, score, chosen FROM ensemble_calibration ORDER BY method, label, iteration";
    assert_eq!(t.csv("runs/ens", q), r.csv("runs/ens", q));
    assert_eq!(
        std::fs::read_to_string(t.path("runs/ens/exports/ens/library/library.toml")).unwrap(),
        std::fs::read_to_string(r.path("runs/ens/exports/ens/library/library.toml")).unwrap()
    );

    // No endpoint and no replay: calibration (b) falls back to held-out ρ and says so.
    let o = TestRun::new();
    o.write("p.toml", &identification_pipeline(""));
    o.run_env(&["run", "p.toml"], &[("ANNOTRACE_LLM_BASE_URL", "")])
        .ok()
        .stderr_has("objective heldout-rho");
    let manifest = std::fs::read_to_string(o.path("runs/ens/manifest.json")).unwrap();
    assert!(
        manifest.contains("\"objective\": \"heldout-rho\""),
        "fallback objective"
    );
    assert!(
        manifest.contains("identification was asked for but no endpoint"),
        "fallback note"
    );
    assert_eq!(server.seen().len(), asked);
}
