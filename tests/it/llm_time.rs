//! The LLM client's time bounds, against the scripted chat server: a hung endpoint ends a call at its
//! time limit (exit code 3 from the command line) with "still waiting" notices on the way, a
//! `Retry-After` that does not fit in the call's time left ends it at once, and attempts recorded before
//! a `kill -9` are on disk.

use std::process::Stdio;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use annotrace::llm::{ChatRequest, LlmClient, LlmConfig, LlmError, WaitNotice, read_calls};
use annotrace::pipeline::{Categorize, ErrorCategory};
use annotrace::store::RunDir;

use crate::common::chat_server::{ChatServer, Reply};
use crate::common::{TestRun, repo};

/// An answer that comes after two minutes: a hung endpoint as far as a test is concerned.
fn hung() -> Reply {
    Reply::slow(120_000, Reply::chat("too late"))
}

fn ask(client: &LlmClient) -> Result<annotrace::llm::ChatReply, LlmError> {
    client.chat(&ChatRequest::new("test").user("q").seed(1))
}

#[test]
fn a_hung_endpoint_ends_the_call_at_its_time_limit_with_waiting_notices() {
    let server = ChatServer::start(vec![hung(), hung()]);
    let mut c = LlmConfig::new(server.url(), "m");
    c.call_timeout = Duration::from_secs(2);
    c.wait_notice = Duration::from_millis(500);
    c.backoff_base = Duration::from_millis(5);
    let client = LlmClient::new(c, None).unwrap();
    let notices: Arc<Mutex<Vec<WaitNotice>>> = Arc::default();
    let seen = notices.clone();
    client.set_wait_observer(Arc::new(move |n| seen.lock().unwrap().push(n.clone())));
    let t0 = Instant::now();
    let e = ask(&client).unwrap_err();
    let took = t0.elapsed();
    assert!(
        took >= Duration::from_millis(1900) && took < Duration::from_secs(6),
        "{took:?}"
    );
    assert!(matches!(e, LlmError::GaveUp { attempts: 1, .. }), "{e}");
    assert_eq!(e.category(), ErrorCategory::Service);
    let msg = e.to_string();
    assert!(
        msg.contains("the call's time limit of 2 s (call_timeout_s) is used up"),
        "{msg}"
    );
    assert!(msg.contains("no answer within 2.0 s"), "{msg}");
    // The request timeout (300 s by default) was cut to the call's limit: one attempt, not five.
    assert_eq!(server.seen().len(), 1);
    let notices = notices.lock().unwrap();
    assert!(notices.len() >= 2, "{notices:?}");
    let first = &notices[0];
    assert_eq!(
        (first.attempt, first.max_attempts, first.in_flight),
        (1, 5, 1)
    );
    assert!(first.waited >= Duration::from_millis(500), "{first:?}");
    assert!(
        first.to_string().starts_with(&format!(
            "waiting for {}/v1/chat/completions (attempt 1/5, ",
            server.url()
        )),
        "{first}"
    );
}

#[test]
fn a_retry_after_beyond_the_time_left_ends_the_call_at_once_and_one_within_it_is_honoured() {
    // Default limits (a call may take 300 s): a day-long Retry-After is not waited for, even in part.
    let server = ChatServer::start(vec![Reply::too_many("100000"), Reply::chat("never")]);
    let client = LlmClient::new(LlmConfig::new(server.url(), "m"), None).unwrap();
    let t0 = Instant::now();
    let e = ask(&client).unwrap_err();
    assert!(t0.elapsed() < Duration::from_secs(3), "{:?}", t0.elapsed());
    assert!(matches!(e, LlmError::GaveUp { attempts: 1, .. }), "{e}");
    assert_eq!(e.category(), ErrorCategory::Service);
    assert!(
        e.to_string()
            .contains("the endpoint asks to retry after 100000 s, more than the"),
        "{e}"
    );
    assert_eq!(server.seen().len(), 1);

    // The cap is the call's time left: 3 s do not fit in a 2 s call, 1 s does.
    let server = ChatServer::start(vec![Reply::too_many("3"), Reply::chat("never")]);
    let mut c = LlmConfig::new(server.url(), "m");
    c.call_timeout = Duration::from_secs(2);
    let e = ask(&LlmClient::new(c.clone(), None).unwrap()).unwrap_err();
    assert!(matches!(e, LlmError::GaveUp { .. }), "{e}");
    let server = ChatServer::start(vec![Reply::too_many("1"), Reply::chat("fine")]);
    c.base_url = Some(server.url());
    c.call_timeout = Duration::from_secs(10);
    let t0 = Instant::now();
    let reply = ask(&LlmClient::new(c, None).unwrap()).unwrap();
    assert_eq!((reply.content.as_str(), reply.attempts), ("fine", 2));
    assert!(t0.elapsed() >= Duration::from_millis(950));
}

#[test]
fn a_hung_endpoint_fails_a_pipeline_within_its_bound_with_progress_on_stderr() {
    let server = ChatServer::responder(|_| hung());
    let t = TestRun::new();
    t.write(
        "p.toml",
        &format!(
            r#"[pipeline]
name = "hang"

[[stage]]
id = "sim"
kind = "simulate"
env = "pooltool"
scenes = 6
shots = 1
seed = 3
dt = 0.1

[[stage]]
id = "evo"
kind = "evolve"
inputs = ["sim"]
env = "pooltool"
library = "{lib}"
labels = ["ball slowing"]
budget = 2
parallel = 2
workers = 1
llm = {{ base_url = "{url}", model = "m", call_timeout_s = 3, wait_notice_s = 1 }}
"#,
            lib = repo().join("data/libraries/pooltool").display(),
            url = server.url()
        ),
    );
    let t0 = Instant::now();
    let out = t.run(&["run", "p.toml"]);
    let took = t0.elapsed();
    out.code(3)
        .stderr_has("gave up after 1 attempt(s)")
        .stderr_has("the call's time limit of 3 s (call_timeout_s) is used up")
        .stderr_has(&format!(
            "[evo] waiting for {}/v1/chat/completions (attempt 1/5, ",
            server.url()
        ))
        .stderr_has("2 requests unanswered");
    assert!(took < Duration::from_secs(60), "{took:?}");
}

#[test]
fn attempts_recorded_before_a_kill_survive_it() {
    // The first attempt fails (recorded), the retry hangs: the process is killed while it waits.
    let server = ChatServer::start(vec![Reply::status(503), hung()]);
    let t = TestRun::new();
    let lib = repo().join("data/libraries/pooltool");
    let mut child = t
        .cmd()
        .args([
            "suggest-labels",
            "--library",
            lib.to_str().unwrap(),
            "--run",
            "run",
            "--llm-base-url",
            &server.url(),
            "--llm-model",
            "m",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while server.seen().len() < 2 {
        assert!(t0.elapsed() < Duration::from_secs(30), "no retry came");
        std::thread::sleep(Duration::from_millis(50));
    }
    // The client writes a recorded row within about a second, even while it waits.
    std::thread::sleep(Duration::from_millis(1600));
    child.kill().unwrap();
    child.wait().unwrap();
    let rows = read_calls(&RunDir::new(t.path("run"))).unwrap();
    let got: Vec<(i32, &str, Option<i32>)> = rows
        .iter()
        .map(|r| (r.attempt, r.status.as_str(), r.http_status))
        .collect();
    assert_eq!(got, [(1, "http_error", Some(503))]);
}

#[test]
fn waiting_for_a_free_slot_does_not_count_against_a_calls_time_limit() {
    // One slot, answers after 1.5 s, a 2 s limit per call: the second call waits 1.5 s for the slot
    // (the run's own queue), then has its whole limit for the endpoint.
    let server = ChatServer::start(vec![
        Reply::slow(1500, Reply::chat("first")),
        Reply::slow(1500, Reply::chat("second")),
    ]);
    let mut c = LlmConfig::new(server.url(), "m");
    c.parallel = 1;
    c.call_timeout = Duration::from_secs(2);
    let client = LlmClient::new(c, None).unwrap();
    let answers: Vec<String> = std::thread::scope(|s| {
        let calls: Vec<_> = (0..2)
            .map(|i| {
                let client = &client;
                s.spawn(move || {
                    std::thread::sleep(Duration::from_millis(100 * i));
                    ask(client).map(|r| r.content)
                })
            })
            .collect();
        calls
            .into_iter()
            .map(|h| h.join().unwrap().unwrap())
            .collect()
    });
    assert_eq!(answers, ["first", "second"]);
}
