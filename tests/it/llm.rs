//! The LLM client, the llm proposer and `annotrace suggest-labels` against a local scripted
//! chat-completions server (`common::chat_server`): answers, retries, timeouts, the budget, the
//! `llm_calls` table, replay without the server, and the API key staying out of every record.

use std::sync::Arc;
use std::time::{Duration, Instant};

use annotrace::detect::DetectorError;
use annotrace::llm::{
    ChatRequest, LlmClient, LlmConfig, LlmError, Prompts, ReplayConfig, extract_code, read_calls,
};
use annotrace::search::{LlmProposer, Parent, ProposalRequest, ProposeError, Proposer};
use annotrace::store::RunDir;
use annotrace::trace::Env;

use crate::common::TestRun;
use crate::common::chat_server::{ChatServer, Reply};

const GOOD: &str = "def find_pattern(trace):\n    out = []\n    for e in trace.get(\"events\", []):\n        if e[\"kind\"] == \"physics_ball_linear_cushion\":\n            out.append({\"label\": \"cushion rebound\", \"start_timestep\": 0, \"end_timestep\": 0, \"parameters\": {\"object_details\": {}}})\n    return out\n";

/// A configuration for `server` with fast retries.
fn config(server: &ChatServer) -> LlmConfig {
    let mut c = LlmConfig::new(server.url(), "test-model");
    c.backoff_base = Duration::from_millis(5);
    c.backoff_max = Duration::from_secs(5);
    c.timeout = Duration::from_secs(10);
    c
}

fn ask(client: &LlmClient, text: &str, seed: u64) -> Result<annotrace::llm::ChatReply, LlmError> {
    client.chat(&ChatRequest::new("test").user(text).seed(seed))
}

#[test]
fn a_good_answer_comes_back_with_its_usage_and_is_recorded() {
    let server = ChatServer::start(vec![Reply::chat(&format!(
        "Here is the detector:\n```python\n{GOOD}```\nIt scans events."
    ))]);
    let t = TestRun::new();
    let run = RunDir::new(t.path("run"));
    let client = LlmClient::new(config(&server), Some(&run)).unwrap();
    let req = ChatRequest::new("evolve")
        .system("sys")
        .user("write code")
        .seed(42);
    let reply = client.chat(&req).unwrap();
    assert_eq!(extract_code(&reply.content).unwrap(), GOOD);
    assert_eq!(
        (reply.tokens_in, reply.tokens_out, reply.usage_estimated),
        (100, 20, false)
    );
    assert_eq!((reply.attempts, reply.replayed), (1, false));
    let seen = server.seen();
    assert_eq!(seen[0].path, "/v1/chat/completions");
    assert_eq!(seen[0].body["model"], "test-model");
    assert_eq!(seen[0].body["seed"], 42);
    assert_eq!(seen[0].authorization, None);
    client.flush().unwrap();
    let rows = read_calls(&run).unwrap();
    assert_eq!(rows.len(), 1);
    let r = &rows[0];
    assert_eq!(
        (r.status.as_str(), r.http_status, r.attempt),
        ("ok", Some(200), 1)
    );
    assert_eq!(
        (r.purpose.as_str(), r.model.as_str(), r.seed),
        ("evolve", "test-model", Some(42))
    );
    assert_eq!(r.request_hash, client.request_hash(&req));
    assert_eq!(r.request_hash, reply.request_hash);
    assert_eq!(r.call_id, reply.call_id);
    assert_eq!((r.tokens_in, r.tokens_out), (100, 20));
    assert_eq!(r.content.as_deref(), Some(reply.content.as_str()));
    assert!(r.request_json.contains("write code"));
    assert!(
        r.response_json
            .as_deref()
            .unwrap()
            .contains("chat.completion")
    );
    assert_eq!(r.endpoint, format!("{}/v1/chat/completions", server.url()));
}

#[test]
fn tokens_are_estimated_when_the_server_sends_no_usage() {
    let server = ChatServer::start(vec![Reply::chat_no_usage("hello world")]);
    let client = LlmClient::new(config(&server), None).unwrap();
    let reply = ask(&client, "say hello world please", 1).unwrap();
    assert!(reply.usage_estimated);
    assert_eq!(reply.tokens_out, 2);
    assert!(reply.tokens_in >= 4 + 3 + 4, "{}", reply.tokens_in);
    assert_eq!(client.usage().tokens(), reply.tokens_in + reply.tokens_out);
}

#[test]
fn rate_limits_and_server_errors_are_retried_honouring_retry_after() {
    let server = ChatServer::start(vec![
        Reply::too_many("1"),
        Reply::status(500),
        Reply::status(503),
        Reply::chat("fine"),
    ]);
    let t = TestRun::new();
    let run = RunDir::new(t.path("run"));
    let client = LlmClient::new(config(&server), Some(&run)).unwrap();
    let t0 = Instant::now();
    let reply = ask(&client, "q", 3).unwrap();
    // Retry-After: 1 is a floor under the 5 ms backoff.
    assert!(
        t0.elapsed() >= Duration::from_millis(950),
        "{:?}",
        t0.elapsed()
    );
    assert_eq!((reply.content.as_str(), reply.attempts), ("fine", 4));
    assert_eq!(server.seen().len(), 4);
    assert_eq!(client.usage().requests, 4);
    assert_eq!(client.usage().calls, 1);
    drop(client);
    let rows = read_calls(&run).unwrap();
    let got: Vec<(i32, &str, Option<i32>)> = rows
        .iter()
        .map(|r| (r.attempt, r.status.as_str(), r.http_status))
        .collect();
    assert_eq!(
        got,
        [
            (1, "http_error", Some(429)),
            (2, "http_error", Some(500)),
            (3, "http_error", Some(503)),
            (4, "ok", Some(200))
        ]
    );
    assert!(rows.iter().all(|r| r.call_id == rows[0].call_id));
    assert!(rows[0].error.as_deref().unwrap().contains("429"));
}

#[test]
fn retries_stop_at_the_limit_and_client_errors_are_not_retried() {
    let server = ChatServer::start(vec![
        Reply::status(500),
        Reply::status(502),
        Reply::status(500),
    ]);
    let mut c = config(&server);
    c.max_retries = 2;
    let client = LlmClient::new(c, None).unwrap();
    match ask(&client, "q", 1).unwrap_err() {
        LlmError::Status {
            status,
            attempts,
            body_excerpt,
            ..
        } => {
            assert_eq!((status, attempts), (500, 3));
            assert!(body_excerpt.contains("scripted 500"), "{body_excerpt}");
        }
        e => panic!("expected a status error, got {e}"),
    }
    let server = ChatServer::start(vec![Reply::status(400), Reply::chat("never")]);
    let client = LlmClient::new(config(&server), None).unwrap();
    let e = ask(&client, "q", 1).unwrap_err();
    assert!(
        matches!(
            e,
            LlmError::Status {
                status: 400,
                attempts: 1,
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(server.seen().len(), 1);
}

#[test]
fn a_slow_answer_times_out_and_is_retried_then_reported() {
    let server = ChatServer::start(vec![
        Reply::slow(3000, Reply::chat("late")),
        Reply::slow(3000, Reply::chat("late again")),
    ]);
    let t = TestRun::new();
    let run = RunDir::new(t.path("run"));
    let mut c = config(&server);
    c.timeout = Duration::from_millis(300);
    c.max_retries = 1;
    let client = LlmClient::new(c, Some(&run)).unwrap();
    let e = ask(&client, "q", 1).unwrap_err();
    assert!(matches!(e, LlmError::Timeout { attempts: 2, .. }), "{e}");
    assert!(e.is_unavailable());
    drop(client);
    let rows = read_calls(&run).unwrap();
    assert_eq!(rows.len(), 2);
    assert!(
        rows.iter()
            .all(|r| r.status == "timeout" && r.http_status.is_none())
    );

    // A slow answer within the timeout is fine.
    let server = ChatServer::start(vec![Reply::slow(200, Reply::chat("slow but fine"))]);
    let client = LlmClient::new(config(&server), None).unwrap();
    assert_eq!(ask(&client, "q", 1).unwrap().content, "slow but fine");
}

#[test]
fn an_unreachable_endpoint_is_a_connection_error_after_retries() {
    let port = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().port()
    };
    let mut c = LlmConfig::new(format!("http://127.0.0.1:{port}"), "m");
    c.backoff_base = Duration::from_millis(5);
    c.max_retries = 2;
    let client = LlmClient::new(c, None).unwrap();
    let e = ask(&client, "q", 1).unwrap_err();
    assert!(matches!(e, LlmError::Connection { attempts: 3, .. }), "{e}");
}

#[test]
fn a_garbage_body_is_a_bad_response_and_garbage_content_a_typed_extraction_error() {
    let server = ChatServer::start(vec![
        Reply::Raw {
            code: 200,
            body: "<html>captive portal</html>".into(),
        },
        Reply::chat("I am sorry, I cannot write that detector."),
    ]);
    let client = LlmClient::new(config(&server), None).unwrap();
    let e = ask(&client, "q", 1).unwrap_err();
    assert!(matches!(e, LlmError::BadResponse { .. }), "{e}");
    assert!(e.to_string().contains("captive portal"), "{e}");
    assert_eq!(server.seen().len(), 1, "a bad body is not retried");
    let reply = ask(&client, "q", 2).unwrap();
    assert!(matches!(
        extract_code(&reply.content),
        Err(annotrace::llm::ExtractError::NoCode { .. })
    ));
}

#[test]
fn the_budget_stops_calls_cleanly() {
    let server = ChatServer::responder(|_| Reply::chat("ok"));
    let t = TestRun::new();
    let run = RunDir::new(t.path("run"));
    let mut c = config(&server);
    c.budget.max_calls = Some(2);
    let client = LlmClient::new(c, Some(&run)).unwrap();
    ask(&client, "a", 1).unwrap();
    ask(&client, "b", 2).unwrap();
    let e = ask(&client, "c", 3).unwrap_err();
    assert!(e.is_budget(), "{e}");
    assert!(e.to_string().contains("max_calls = 2"), "{e}");
    assert_eq!(server.seen().len(), 2, "no request is sent past the budget");
    drop(client);
    assert_eq!(read_calls(&run).unwrap().len(), 2);

    // Tokens: 120 per call against a cap of 200 allows two calls.
    let mut c = config(&server);
    c.budget.max_tokens = Some(200);
    let client = LlmClient::new(c, None).unwrap();
    ask(&client, "a", 1).unwrap();
    ask(&client, "b", 1).unwrap();
    assert!(ask(&client, "c", 1).unwrap_err().is_budget());
    assert_eq!(client.usage().tokens(), 240);
}

#[test]
fn requests_in_flight_never_exceed_the_parallel_slots() {
    let server = ChatServer::responder(|_| Reply::slow(150, Reply::chat("ok")));
    let mut c = config(&server);
    c.parallel = 2;
    let client = Arc::new(LlmClient::new(c, None).unwrap());
    let handles: Vec<_> = (0..6)
        .map(|i| {
            let client = client.clone();
            std::thread::spawn(move || ask(&client, &format!("q{i}"), i).unwrap())
        })
        .collect();
    for h in handles {
        h.join().unwrap();
    }
    assert_eq!(server.seen().len(), 6);
    assert!(server.max_in_flight() <= 2, "{}", server.max_in_flight());
    assert_eq!(client.usage().calls, 6);
}

#[test]
fn a_recorded_run_replays_without_the_server_and_a_strict_miss_is_an_error() {
    let t = TestRun::new();
    let recorded = RunDir::new(t.path("recorded"));
    let (first, second, again) = {
        let server = ChatServer::start(vec![
            Reply::chat("answer one"),
            Reply::chat("answer two"),
            Reply::chat("answer one, second time"),
        ]);
        let client = LlmClient::new(config(&server), Some(&recorded)).unwrap();
        let a = ask(&client, "question one", 1).unwrap();
        let b = ask(&client, "question two", 2).unwrap();
        let c = ask(&client, "question one", 1).unwrap();
        (a, b, c)
    }; // the server is gone from here on
    let mut c = LlmConfig {
        model: "test-model".into(),
        replay: Some(ReplayConfig {
            run: recorded.root().to_path_buf(),
            strict: true,
        }),
        ..LlmConfig::default()
    };
    let replayed_into = RunDir::new(t.path("replayed"));
    let client = LlmClient::new(c.clone(), Some(&replayed_into)).unwrap();
    let a = ask(&client, "question one", 1).unwrap();
    let b = ask(&client, "question two", 2).unwrap();
    let a2 = ask(&client, "question one", 1).unwrap();
    assert_eq!(
        (a.content.as_str(), a.replayed, a.attempts),
        (first.content.as_str(), true, 0)
    );
    assert_eq!(b.content, second.content);
    assert_eq!(
        a2.content, again.content,
        "repeated requests replay in recorded order"
    );
    assert_eq!(
        (a.tokens_in, a.tokens_out),
        (first.tokens_in, first.tokens_out)
    );
    // A different seed is a different request.
    match ask(&client, "question one", 9).unwrap_err() {
        LlmError::ReplayMiss {
            request_hash,
            purpose,
            source_dir,
        } => {
            assert_eq!(purpose, "test");
            assert_eq!(source_dir, recorded.root());
            assert_eq!(request_hash.len(), 64);
        }
        e => panic!("expected a replay miss, got {e}"),
    }
    assert_eq!(client.usage().replayed, 3);
    drop(client);
    // Replayed answers recorded into another run are marked as such.
    let rows = read_calls(&replayed_into).unwrap();
    assert_eq!(rows.len(), 3);
    assert!(
        rows.iter()
            .all(|r| r.replayed && r.attempt == 0 && r.status == "ok")
    );
    // A model change misses too.
    c.model = "other-model".into();
    let client = LlmClient::new(c, None).unwrap();
    assert!(matches!(
        ask(&client, "question one", 1),
        Err(LlmError::ReplayMiss { .. })
    ));
}

#[test]
fn non_strict_replay_falls_back_to_the_endpoint() {
    let t = TestRun::new();
    let recorded = RunDir::new(t.path("recorded"));
    let server = ChatServer::start(vec![Reply::chat("recorded"), Reply::chat("live")]);
    {
        let client = LlmClient::new(config(&server), Some(&recorded)).unwrap();
        ask(&client, "known", 1).unwrap();
    }
    let mut c = config(&server);
    c.replay = Some(ReplayConfig {
        run: recorded.root().to_path_buf(),
        strict: false,
    });
    let client = LlmClient::new(c, Some(&recorded)).unwrap();
    assert_eq!(ask(&client, "known", 1).unwrap().content, "recorded");
    let live = ask(&client, "new", 1).unwrap();
    assert_eq!((live.content.as_str(), live.replayed), ("live", false));
    assert_eq!(server.seen().len(), 2);
    drop(client);
    // Replaying into the run it came from adds only the live call.
    assert_eq!(read_calls(&recorded).unwrap().len(), 2);
}

#[test]
fn the_api_key_is_sent_but_never_recorded() {
    const KEY: &str = "sk-test-SECRET-0123456789";
    let server = ChatServer::start(vec![
        Reply::EchoAuth,
        Reply::Status {
            code: 401,
            retry_after: None,
            body: format!("{{\"error\":\"bad key {KEY}\"}}"),
        },
    ]);
    let t = TestRun::new();
    let run = RunDir::new(t.path("run"));
    let mut c = config(&server);
    c.api_key = Some(annotrace::llm::ApiKey::new(KEY));
    assert!(!format!("{c:?}").contains(KEY));
    let client = LlmClient::new(c, Some(&run)).unwrap();
    assert!(!format!("{client:?}").contains(KEY));
    let echoed = ask(&client, "q", 1).unwrap();
    assert_eq!(
        echoed.content, "Bearer [redacted]",
        "answers reach callers scrubbed"
    );
    assert_eq!(
        server.seen()[0].authorization.as_deref(),
        Some(format!("Bearer {KEY}").as_str())
    );
    let e = ask(&client, "q", 2).unwrap_err();
    assert!(!e.to_string().contains(KEY), "{e}");
    drop(client);
    let rows = read_calls(&run).unwrap();
    assert_eq!(rows.len(), 2);
    for r in &rows {
        let text = format!("{r:?}");
        assert!(!text.contains(KEY), "the key leaked into llm_calls: {text}");
    }
    assert_eq!(rows[0].content.as_deref(), Some("Bearer [redacted]"));
    // Nor into the files' bytes (Parquet pages are compressed, so also check the SQL view).
    let out = t.run(&[
        "query",
        "SELECT * FROM llm_calls",
        "--run",
        "run",
        "--format",
        "csv",
    ]);
    out.ok();
    assert!(!out.stdout.contains(KEY));
    assert!(out.stdout.contains("[redacted]"));
}

/// An endpoint that echoes the key in an error body (retried: the WARN line) and in its answer (the
/// "it starts: …" extraction error): the key appears nowhere in what the command prints.
#[test]
fn an_endpoint_echoing_the_key_never_gets_it_printed() {
    const KEY: &str = "sk-echo-SECRET-9876543210";
    let server = ChatServer::start(vec![
        Reply::Status {
            code: 500,
            retry_after: Some("0".into()),
            body: format!("{{\"error\":\"upstream rejected {KEY}\"}}"),
        },
        Reply::EchoAuth,
    ]);
    let t = TestRun::new();
    let lib = crate::common::repo().join("data/libraries/pooltool");
    let env = [
        ("ANNOTRACE_LLM_BASE_URL", server.url()),
        ("ANNOTRACE_LLM_MODEL", "m".to_string()),
        ("ANNOTRACE_LLM_API_KEY", KEY.to_string()),
    ];
    let env_ref: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let out = cli(
        &t,
        &[
            "suggest-labels",
            "--library",
            lib.to_str().unwrap(),
            "--run",
            "run",
        ],
        &env_ref,
    );
    assert_ne!(out.code, Some(0), "an answer without labels fails");
    assert!(
        !out.stderr.contains(KEY) && !out.stdout.contains(KEY),
        "the key was printed: {}{}",
        out.stdout,
        out.stderr
    );
    assert!(out.stderr.contains("[redacted]"), "{}", out.stderr);
}

fn proposal_request() -> ProposalRequest {
    ProposalRequest {
        env: Env::Pooltool,
        label: "cushion rebound".into(),
        parents: vec![Parent {
            code: "def find_pattern(trace):\n    return []\n".into(),
            fitness: Some(annotrace::fitness::FitnessTerms::new(0.42, 0.3, 0.14, 0.0)),
            lines: 2,
        }],
        library_labels: vec!["cue strike".into()],
        seed: 77,
        island: 1,
        step: 5,
    }
}

#[test]
fn the_llm_proposer_proposes_and_repairs_through_the_client() {
    let broken = "def find_pattern(trace)\n    return []\n";
    let server = ChatServer::start(vec![
        // Prose and fences around good code.
        Reply::chat(&format!(
            "Sure. I tightened the event check.\n\n```python\n{GOOD}```\n\nThis should score higher."
        )),
        // Code with a syntax error (the validator will reject it)...
        Reply::chat(&format!("```python\n{broken}```")),
        // ...and its repair.
        Reply::chat(&format!("Fixed the missing colon:\n```python\n{GOOD}```")),
        // Garbage.
        Reply::chat("I'm not able to help with that."),
    ]);
    let t = TestRun::new();
    let run = RunDir::new(t.path("run"));
    let client = Arc::new(LlmClient::new(config(&server), Some(&run)).unwrap());
    let p = LlmProposer::new(client.clone(), Arc::new(Prompts::builtin()));
    assert_eq!(p.name(), "llm:test-model");
    let req = proposal_request();

    let child = p.propose(&req).unwrap();
    assert_eq!(child.code, GOOD);
    assert_eq!(
        (child.tokens_in, child.tokens_out, child.calls),
        (100, 20, 1)
    );
    let prompt = server.seen()[0].last_message();
    assert!(
        prompt.contains("Pattern to detect: cushion rebound"),
        "{prompt}"
    );
    assert!(prompt.contains("score 0.5800"), "{prompt}");
    assert!(prompt.contains("motion_state_code"), "{prompt}");
    assert_eq!(server.seen()[0].body["seed"], 77);
    assert_eq!(server.seen()[0].body["messages"][0]["role"], "system");

    let bad = p.propose(&req).unwrap();
    assert_eq!(bad.code, broken);
    let error = DetectorError::Syntax {
        message: "expected ':'".into(),
        line: Some(1),
        column: Some(24),
    };
    let fixed = p
        .repair(&req, &bad.code, &error, 1)
        .unwrap()
        .expect("the llm proposer repairs");
    assert_eq!(fixed.code, GOOD);
    let repair_prompt = server.seen()[2].last_message();
    for needle in [
        "category: syntax",
        "message: expected ':'",
        "line: 1",
        "column: 24",
        "def find_pattern(trace)\n    return []",
    ] {
        assert!(
            repair_prompt.contains(needle),
            "{needle:?} not in:\n{repair_prompt}"
        );
    }
    assert_ne!(
        server.seen()[2].body["seed"],
        77,
        "a repair asks with its own seed"
    );

    match p.propose(&req) {
        Err(ProposeError::Other(m)) => assert!(m.contains("no usable code"), "{m}"),
        other => panic!("expected a failed step, got {other:?}"),
    }
    drop(p);
    client.flush().unwrap();
    let purposes: Vec<String> = read_calls(&run)
        .unwrap()
        .into_iter()
        .map(|r| r.purpose)
        .collect();
    assert_eq!(purposes, ["evolve", "evolve", "repair", "evolve"]);
}

#[test]
fn the_llm_proposer_reports_budget_and_outage_as_the_search_expects() {
    let server = ChatServer::responder(|_| Reply::status(503));
    let mut c = config(&server);
    c.max_retries = 1;
    c.budget.max_calls = Some(1);
    let p = LlmProposer::new(
        Arc::new(LlmClient::new(c, None).unwrap()),
        Arc::new(Prompts::builtin()),
    );
    let req = proposal_request();
    assert!(matches!(p.propose(&req), Err(ProposeError::Unavailable(_))));
    assert!(matches!(
        p.propose(&req),
        Err(ProposeError::BudgetExhausted(_))
    ));
}

/// Runs `annotrace ARGS…` with exactly the LLM variables given (none inherited from the caller's shell).
fn cli(t: &TestRun, args: &[&str], env: &[(&str, &str)]) -> crate::common::Ran {
    let mut c = t.cmd();
    for k in [
        "ANNOTRACE_LLM_BASE_URL",
        "ANNOTRACE_LLM_MODEL",
        "ANNOTRACE_LLM_API_KEY",
        "ANNOTRACE_PROMPTS",
    ] {
        c.env_remove(k);
    }
    for (k, v) in env {
        c.env(k, v);
    }
    c.args(args).output().expect("annotrace runs").into()
}

const LABELS_ANSWER: &str = "<think>The library covers contacts; what about speed and geometry?</think>\nHere are my suggestions:\n```json\n[\n  {\"reason\": \"Shows wasted cue energy.\", \"description\": \"The cue ball stops dead at the first contact.\", \"label\": \"stop shot\"},\n  {\"reason\": \"Already known.\", \"description\": \"The stick hits the cue ball.\", \"label\": \"Cue Strike\"},\n  {\"reason\": \"Position play.\", \"description\": \"A ball travels along a cushion for a while.\", \"label\": \"ball hugs the rail\"}\n]\n```";

#[test]
fn suggest_labels_prints_new_labels_records_the_call_and_replays_offline() {
    let server = ChatServer::start(vec![Reply::chat(LABELS_ANSWER)]);
    let t = TestRun::new();
    let lib = crate::common::repo().join("data/libraries/pooltool");
    let lib = lib.to_str().unwrap();
    let env = [
        ("ANNOTRACE_LLM_BASE_URL", server.url()),
        ("ANNOTRACE_LLM_MODEL", "test-model".to_string()),
        ("ANNOTRACE_LLM_API_KEY", "sk-cli-key-abcdefgh".to_string()),
    ];
    let env_ref: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let args = [
        "suggest-labels",
        "--env",
        "pooltool",
        "--library",
        lib,
        "-k",
        "5",
        "--run",
        "run",
        "--seed",
        "3",
    ];
    let out = cli(&t, &args, &env_ref);
    out.ok()
        .stdout_has("1. stop shot — The cue ball stops dead at the first contact.")
        .stdout_has("   why: Shows wasted cue energy.")
        .stdout_has("2. ball hugs the rail — A ball travels along a cushion")
        .stderr_has("dropped as already in the library: Cue Strike")
        .stderr_has("2 new label(s) from test-model (100 + 20 tokens");
    assert!(!out.stdout.contains("Cue Strike"));
    let seen = server.seen();
    assert_eq!(seen.len(), 1);
    let prompt = seen[0].last_message();
    assert!(prompt.contains("Propose 5 new patterns."), "{prompt}");
    assert!(
        prompt.contains("- cushion rebound (also: rail rebound, cushion bounce)"),
        "{prompt}"
    );
    assert_eq!(
        seen[0].authorization.as_deref(),
        Some("Bearer sk-cli-key-abcdefgh")
    );
    let csv = t.csv(
        "run",
        "SELECT purpose, status, model, seed, tokens_in FROM llm_calls",
    );
    assert_eq!(
        csv.trim(),
        "purpose,status,model,seed,tokens_in\nsuggest_labels,ok,test-model,3,100"
    );
    let all = t.csv("run", "SELECT * FROM llm_calls");
    assert!(!all.contains("sk-cli-key-abcdefgh"));
    drop(server);

    // Replay: no endpoint, same output.
    let replay_env = [("ANNOTRACE_LLM_MODEL", "test-model")];
    let mut replay_args = args.to_vec();
    replay_args.truncate(args.len() - 4); // drop --run run --seed 3
    replay_args.extend(["--seed", "3", "--replay", "run", "--json"]);
    let r = cli(&t, &replay_args, &replay_env);
    r.ok().stderr_has("replayed");
    let lines: Vec<serde_json::Value> = r
        .stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    assert_eq!(lines[0]["label"], "stop shot");
    assert_eq!(lines[1]["label"], "ball hugs the rail");

    // A request that was never recorded (another k) fails strictly with exit 2.
    let mut miss = replay_args.clone();
    let k = miss.iter().position(|a| *a == "5").unwrap();
    miss[k] = "4";
    cli(&t, &miss, &replay_env)
        .code(2)
        .stderr_has("no recorded answer for request");
}

#[test]
fn suggest_labels_reports_bad_configuration_and_unusable_answers() {
    let t = TestRun::new();
    let lib = crate::common::repo().join("data/libraries/pooltool");
    let lib = lib.to_str().unwrap();
    cli(
        &t,
        &["suggest-labels", "--library", lib],
        &[("ANNOTRACE_LLM_MODEL", "m")],
    )
    .code(2)
    .stderr_has("ANNOTRACE_LLM_BASE_URL");
    cli(
        &t,
        &["suggest-labels", "--library", lib, "--env", "phyre"],
        &[],
    )
    .code(2)
    .stderr_has("the library is for pooltool");
    let server = ChatServer::start(vec![Reply::chat("No idea, sorry.")]);
    let env = [
        ("ANNOTRACE_LLM_BASE_URL", server.url()),
        ("ANNOTRACE_LLM_MODEL", "m".into()),
    ];
    let env_ref: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
    cli(
        &t,
        &["suggest-labels", "--library", lib, "--run", "run"],
        &env_ref,
    )
    .code(1)
    .stderr_has("no labels in the answer");
    // The failed answer is still recorded.
    assert_eq!(
        t.csv("run", "SELECT count(*) AS n FROM llm_calls").trim(),
        "n\n1"
    );
    // A bullet-list answer works too; a local endpoint is reached directly despite a proxy setting.
    let server = ChatServer::start(vec![Reply::chat(
        "- Jump shot: the cue ball leaves the cloth\n- Stop shot",
    )]);
    let env = [
        ("ANNOTRACE_LLM_BASE_URL", server.url()),
        ("ANNOTRACE_LLM_MODEL", "m".into()),
        ("HTTP_PROXY", "http://127.0.0.1:9".into()),
        ("http_proxy", "http://127.0.0.1:9".into()),
        ("ALL_PROXY", "http://127.0.0.1:9".into()),
    ];
    let env_ref: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
    cli(
        &t,
        &["suggest-labels", "--library", lib, "-k", "2"],
        &env_ref,
    )
    .ok()
    .stdout_has("1. Jump shot — the cue ball leaves the cloth\n2. Stop shot\n");
}

#[test]
fn a_proposer_built_from_settings_records_into_the_run_and_uses_the_prompts_folder() {
    let server = ChatServer::start(vec![Reply::chat(&format!("```python\n{GOOD}```"))]);
    let t = TestRun::new();
    let run = RunDir::new(t.path("run"));
    let prompts = t.path("prompts");
    t.write("prompts/system.j2", "You are a terse detector author.\n");
    let settings: annotrace::llm::LlmSettings =
        toml::from_str("model = \"m-from-file\"\ntemperature = 0.7\nparallel = 2").unwrap();
    let url = server.url();
    let lookup = move |k: &str| (k == "ANNOTRACE_LLM_BASE_URL").then(|| url.clone());
    let p = LlmProposer::from_settings(&settings, &lookup, Some(&run), Some(&prompts)).unwrap();
    assert_eq!(p.name(), "llm:m-from-file");
    assert_eq!(p.propose(&proposal_request()).unwrap().code, GOOD);
    let body = &server.seen()[0].body;
    assert_eq!(body["temperature"], 0.7);
    assert_eq!(
        body["messages"][0]["content"],
        "You are a terse detector author.\n"
    );
    drop(p);
    assert_eq!(read_calls(&run).unwrap()[0].purpose, "evolve");
}
