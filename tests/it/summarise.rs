//! `annotrace summarise` and the `summarise` stage: the offline summariser and chooser on simulated
//! traces; the LLM summariser (annotations and frames modes) and chooser against the local scripted chat
//! server (images as base64 PNG parts, an unreadable choice recorded as such), replay from the recorded
//! calls reproducing the tables, an endpoint failure and a resume that asks nothing twice; the summaries
//! pipeline end to end offline.

use serde_json::Value;

use crate::common::chat_server::{ChatServer, Reply, Seen};
use crate::common::{TestRun, repo};

/// The text parts of the last message, and its number of PNG images.
fn last_user(s: &Seen) -> (String, usize) {
    let m = s.body["messages"].as_array().unwrap().last().unwrap();
    match &m["content"] {
        Value::String(t) => (t.clone(), 0),
        Value::Array(parts) => (
            parts
                .iter()
                .filter_map(|p| p["text"].as_str())
                .collect::<Vec<_>>()
                .join("\n"),
            parts
                .iter()
                .filter(|p| {
                    p["image_url"]["url"]
                        .as_str()
                        .is_some_and(|u| u.starts_with("data:image/png;base64,"))
                })
                .count(),
        ),
        other => panic!("unexpected content {other}"),
    }
}

fn simulate(t: &TestRun, run: &str, scenes: &str) {
    t.run(&[
        "simulate", "--env", "pooltool", "--scenes", scenes, "--shots", "1", "--seed", "5", "--dt",
        "0.1", "--run", run,
    ])
    .ok();
}

fn summarise_args<'a>(run: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut a = vec![
        "summarise",
        "--run",
        run,
        "--env",
        "pooltool",
        "--traces",
        "8",
        "--seed",
        "3",
        "--workers",
        "1",
    ];
    a.extend_from_slice(extra);
    a
}

#[test]
fn offline_summaries_and_identification() {
    let t = TestRun::new();
    simulate(&t, "run", "10");
    let r = t.run(&summarise_args("run", &[]));
    r.ok()
        .stdout_has("8 offline summaries of pooltool-human annotations (12 patterns)")
        .stdout_has("identification by offline");
    let csv = t.csv(
        "run",
        "SELECT count(*) AS n, count(DISTINCT trace_id) AS traces, min(length(text)) > 40 AS long, \
         bool_and(usage_estimated) AS est, max(images) AS images, min(prompt_tokens) > 0 AS tin FROM summaries",
    );
    assert_eq!(csv.lines().nth(1), Some("8,8,true,true,0,true"), "{csv}");
    let text = t.csv("run", "SELECT text FROM summaries LIMIT 1");
    assert!(text.contains("billiards rollout"), "{text}");
    let trials = t.csv(
        "run",
        "SELECT count(*) AS n, min(options) AS o, max(options) AS o2, count(chosen) AS chosen, \
         bool_and(correct BETWEEN 1 AND 8) AS ok FROM identification",
    );
    assert_eq!(trials.lines().nth(1), Some("8,8,8,8,true"), "{trials}");
    // Every trial shows its own trace once among 8 distinct traces.
    let shown = t.csv("run", "SELECT trace_id, shown, correct FROM identification");
    for line in shown.lines().skip(1) {
        let (id, rest) = line.split_once(',').unwrap();
        let (list, correct) = rest
            .trim_matches('"')
            .rsplit_once("\",")
            .unwrap_or_else(|| {
                let (l, c) = rest.rsplit_once(',').unwrap();
                (l, c)
            });
        let list: Vec<&str> = list.trim_matches('"').split(',').collect();
        let correct: usize = correct.parse().unwrap();
        assert_eq!(list.len(), 8, "{line}");
        assert_eq!(list[correct - 1], id, "{line}");
        let mut d = list.clone();
        d.sort_unstable();
        d.dedup();
        assert_eq!(d.len(), 8, "{line}");
    }
    // The same command again is the recorded result; the SQL tables read the new tables.
    t.run(&summarise_args("run", &[]))
        .ok()
        .stdout_has("[recorded result]");
    // Too few traces for 8 options is the user's error.
    t.run(&summarise_args("run", &["--options", "9"]))
        .code(2)
        .stderr_has("at least 9 traces");
    t.run(&summarise_args("run", &["--labels", "no such label"]))
        .code(2)
        .stderr_has("no label");
    // A trace given twice cannot be told apart from itself: the user's error, before any summary.
    let ids = t.csv(
        "run",
        "SELECT trace_id FROM traces ORDER BY trace_id LIMIT 8",
    );
    let ids: Vec<&str> = ids.lines().skip(1).collect();
    let mut twice = summarise_args("twice", &["--trace", ids[0]]);
    for id in &ids {
        twice.extend_from_slice(&["--trace", id]);
    }
    simulate(&t, "twice", "10");
    t.run(&twice)
        .code(2)
        .stderr_has(&format!("trace {} is given twice", ids[0]));
    assert!(!t.path("twice/summaries").exists(), "no summaries written");
}

/// A server that summarises and chooses: summaries name the request's position, choices are
/// `Answer: 1`, except the first choice, which is unreadable.
fn scripted() -> ChatServer {
    let count = std::sync::atomic::AtomicUsize::new(0);
    ChatServer::responder(move |s| {
        let (text, _) = last_user(s);
        if text.contains("Which summary describes this rollout?") {
            if count.fetch_add(1, std::sync::atomic::Ordering::SeqCst) == 0 {
                Reply::chat("I cannot tell.")
            } else {
                Reply::chat("Summary 1 mentions the cue ball.\nAnswer: 1")
            }
        } else {
            let seed = s.body["seed"].as_u64().unwrap_or(0);
            Reply::chat(&format!(
                "<think>hm</think>The cue ball moves (request {seed})."
            ))
        }
    })
}

#[test]
fn llm_summaries_identification_and_replay() {
    let server = scripted();
    let t = TestRun::new();
    simulate(&t, "run", "8");
    let url = server.url();
    let llm = [
        "--summariser",
        "annotations",
        "--identify",
        "llm",
        "--llm-model",
        "vlm",
        "--llm-retries",
        "0",
        "--image-size",
        "128",
        "--llm-base-url",
        &url,
    ];
    t.run(&summarise_args("run", &llm))
        .ok()
        .stdout_has("8 annotations summaries (vlm) of pooltool-human annotations");
    let seen = server.seen();
    assert_eq!(seen.len(), 16);
    // Summaries: the initial image and the annotated trace.
    let (text, images) = last_user(&seen[0]);
    assert_eq!(images, 1);
    assert!(text.contains("patterns (steps, time, label"), "{text}");
    assert!(text.contains("at most 120 words"), "{text}");
    // Choices: 5 keyframes and 8 numbered summaries.
    let (text, images) = last_user(&seen[8]);
    assert_eq!(images, 5);
    assert!(
        text.contains("Summary 8:") && !text.contains("Summary 9:"),
        "{text}"
    );
    assert!(text.contains("The cue ball moves (request"), "{text}");
    let csv = t.csv(
        "run",
        "SELECT summariser, model, prompt_tokens, completion_tokens, images, text LIKE '%think%' AS think FROM summaries LIMIT 1",
    );
    assert_eq!(
        csv.lines().nth(1),
        Some("annotations,vlm,100,20,1,false"),
        "{csv}"
    );
    let trials = t.csv(
        "run",
        "SELECT count(*) AS n, count(chosen) AS read, sum(CASE WHEN reason LIKE 'unparsable%' THEN 1 ELSE 0 END) AS bad, \
         max(chooser_model) AS m FROM identification",
    );
    assert_eq!(trials.lines().nth(1), Some("8,7,1,vlm"), "{trials}");
    let calls = t.csv(
        "run",
        "SELECT purpose, count(*) AS n FROM llm_calls GROUP BY purpose ORDER BY purpose",
    );
    assert_eq!(
        calls, "purpose,n\nidentify,8\nsummarise_annotations,8\n",
        "{calls}"
    );
    // Replay into a fresh run with the same traces: no endpoint, the same tables.
    simulate(&t, "again", "8");
    let mut replay: Vec<&str> = summarise_args("again", &llm[..10]);
    replay.extend_from_slice(&["--replay", "run"]);
    t.run(&replay).ok();
    assert_eq!(server.seen().len(), 16, "the replay asked the endpoint");
    for q in [
        "SELECT trace_id, text, prompt_tokens, completion_tokens, seconds FROM summaries ORDER BY trace_id",
        "SELECT trace_id, shown, correct, chosen, reason, seconds FROM identification ORDER BY trace_id",
    ] {
        assert_eq!(t.csv("run", q), t.csv("again", q), "{q}");
    }
}

#[test]
fn frames_summaries_resume_after_an_endpoint_failure() {
    // Three summaries, then the endpoint fails.
    let n = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let k = n.clone();
    let server = ChatServer::responder(move |_| {
        if k.fetch_add(1, std::sync::atomic::Ordering::SeqCst) < 3 {
            Reply::chat("Balls roll.")
        } else {
            Reply::status(503)
        }
    });
    let t = TestRun::new();
    simulate(&t, "run", "8");
    let url = server.url();
    let args = [
        "--summariser",
        "frames",
        "--identify",
        "none",
        "--llm-model",
        "vlm",
        "--llm-retries",
        "0",
        "--image-size",
        "128",
        "--keyframes",
        "3",
    ];
    let mut first: Vec<&str> = summarise_args("run", &args);
    first.extend_from_slice(&["--llm-base-url", &url]);
    t.run(&first).code(3);
    let seen = server.seen();
    assert_eq!(seen.len(), 4);
    assert_eq!(last_user(&seen[0]).1, 3, "three keyframes");
    // A working endpoint: the rerun asks only the 5 unfinished summaries.
    let server2 = ChatServer::responder(|_| Reply::chat("Balls roll."));
    let url2 = server2.url();
    let mut second: Vec<&str> = summarise_args("run", &args);
    second.extend_from_slice(&["--llm-base-url", &url2]);
    t.run(&second).ok().stdout_has("8 frames summaries (vlm)");
    assert_eq!(server2.seen().len(), 5);
    let csv = t.csv(
        "run",
        "SELECT count(*) AS n, max(library) AS lib, max(patterns) AS p FROM summaries",
    );
    assert_eq!(csv.lines().nth(1), Some("8,,0"), "{csv}");
}

#[test]
fn summaries_pipeline_runs_offline() {
    let t = TestRun::new();
    let text = std::fs::read_to_string(repo().join("pipelines/summaries.toml")).unwrap();
    // Smaller: 8 traces per environment.
    let text = text
        .replace("scenes = 24", "scenes = 8")
        .replace(
            "games = \"all\"",
            "games = \"support,hinder,seesaw,direction,angle,fill,hole,impulse\"",
        )
        .replace("traces = 20", "traces = 8");
    t.write("pipelines/s.toml", &text);
    std::fs::create_dir_all(t.path("sql")).unwrap();
    for f in ["summary_cost.sql", "identification_accuracy.sql"] {
        std::fs::copy(repo().join("sql").join(f), t.path("sql").join(f)).unwrap();
    }
    t.run(&["run", "pipelines/s.toml", "--run-dir", "out"])
        .ok()
        .stderr_has("skipped: an LLM summariser");
    let cost = std::fs::read_to_string(t.path("out/exports/summary_cost.md")).unwrap();
    assert!(cost.contains("| offline "), "{cost}");
    let ident = t.csv(
        "out",
        "SELECT env, trials, options FROM identification_accuracy ORDER BY env",
    );
    assert_eq!(
        ident, "env,trials,options\niphyre,8,8\nphyre,8,8\npooltool,8,8\n",
        "{ident}"
    );
    assert!(t.path("out/exports/summary_cost.tex").is_file());
}

/// Offline, a shard holds a block of 64 summaries or trials: 70 traces make two of each. A kill or a
/// failure after some blocks publishes nothing, and the stage run again (resumed after the kill) ends
/// with an uninterrupted run's tables.
#[test]
fn offline_summaries_in_blocks_resume_to_the_same_tables() {
    let t = TestRun::new();
    let pipeline = "[pipeline]\nname = \"p\"\nseed = 4\n\n[[stage]]\nid = \"sim\"\nkind = \"simulate\"\n\
                    scenes = 70\nshots = 1\ndt = 0.1\nscenes_per_shard = 35\n\n[[stage]]\nid = \"sum\"\n\
                    kind = \"summarise\"\ntraces = 70\nworkers = 2\n";
    t.write("pipelines/p.toml", pipeline);
    t.run(&["run", "pipelines/p.toml", "--run-dir", "fresh"])
        .ok();
    let rows = |run: &str| {
        (
            t.csv(
                run,
                "SELECT * EXCLUDE (seconds) FROM summaries ORDER BY trace_id",
            ),
            t.csv(
                run,
                "SELECT * EXCLUDE (seconds) FROM identification ORDER BY trace_id",
            ),
        )
    };
    let expected = rows("fresh");
    assert_eq!(expected.0.lines().count(), 71, "{}", expected.0);
    assert_eq!(expected.1.lines().count(), 71, "{}", expected.1);
    for table in ["summaries", "identification"] {
        let files = std::fs::read_dir(t.path(&format!("fresh/{table}/env=pooltool")))
            .unwrap()
            .count();
        assert_eq!(files, 2, "{table}: two blocks of traces");
    }
    // Shards finish in the order s00000, s00064, i00000, i00064.
    for (dir, fault) in [
        ("killed", "sum:after-shards=1"),
        ("failed", "sum:after-shards=3:fail"),
    ] {
        let r = t.run_env(
            &["run", "pipelines/p.toml", "--run-dir", dir],
            &[("ANNOTRACE_FAULT", fault)],
        );
        assert_ne!(r.code, Some(0), "{fault}: the fault stops the run");
        assert!(r.stderr.contains("injected fault"), "{fault}: {}", r.stderr);
        for table in ["summaries", "identification"] {
            assert!(
                !t.path(&format!("{dir}/{table}")).exists(),
                "{fault}: no partial {table} table is published"
            );
        }
        let again = t.run(&["run", "pipelines/p.toml", "--run-dir", dir]);
        again.ok();
        if dir == "killed" {
            // The first block's summaries are kept, not made again.
            again.stderr_has("resuming: finished shards kept");
        }
        assert_eq!(rows(dir), expected, "{fault}");
    }
}
