//! One test per exit-code category (the table in `cli/mod.rs`, README and docs/pipelines.md), with the
//! real binary: 2 bad input, 3 an unavailable service, 4 an I/O error, 5 a locked run.

use std::fs::File;
use std::process::Stdio;

use crate::common::{Ran, TestRun, repo};

/// A small run of billiards traces in `run/`.
fn small_run() -> TestRun {
    let t = TestRun::new();
    t.run(&[
        "simulate", "--run", "run", "--scenes", "4", "--shots", "1", "--seed", "1", "--dt", "0.1",
    ])
    .ok();
    t
}

/// A loopback address where nothing listens (a port bound and released at once).
fn closed_port_url() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    drop(l);
    format!("http://127.0.0.1:{port}/v1")
}

#[test]
fn an_unreachable_llm_endpoint_exits_3_in_every_command() {
    let t = small_run();
    let url = closed_port_url();
    let lib = repo().join("data/libraries/pooltool");
    let lib = lib.to_str().unwrap();
    t.run_env(
        &["suggest-labels", "--library", lib, "--llm-retries", "0"],
        &[
            ("ANNOTRACE_LLM_BASE_URL", url.as_str()),
            ("ANNOTRACE_LLM_MODEL", "m"),
        ],
    )
    .code(3)
    .stderr_has("cannot reach the endpoint");
    t.run(&[
        "evolve",
        "--run",
        "run",
        "--labels",
        "ball slowing",
        "--budget",
        "2",
        "--proposer",
        "llm",
        "--llm-base-url",
        &url,
        "--llm-model",
        "m",
        "--llm-retries",
        "0",
        "--workers",
        "1",
    ])
    .code(3)
    .stderr_has("unavailable");
}

#[test]
fn a_bad_pipeline_file_exits_2() {
    let t = TestRun::new();
    t.write(
        "p.toml",
        "[pipeline]\nname = \"bad\"\n\n[[stage]]\nid = \"a\"\nkind = \"simulat\"\n",
    );
    t.run(&["run", "p.toml"])
        .code(2)
        .stderr_has("unknown stage kind");
    t.run(&["run", "missing.toml"]).code(2);
}

#[test]
fn a_full_disk_exits_4() {
    let t = small_run();
    let id = t.csv(
        "run",
        "SELECT trace_id FROM traces ORDER BY trace_id LIMIT 1",
    );
    let id = id.lines().nth(1).expect("a trace id").to_string();
    let out: Ran = t
        .cmd()
        .args(["export", "--run", "run", "--trace", &id])
        .stdout(Stdio::from(File::create("/dev/full").unwrap()))
        .output()
        .unwrap()
        .into();
    out.code(4).stderr_has("standard output");
}

#[test]
fn a_locked_run_exits_5() {
    let t = small_run();
    let lock = File::create(t.path("run/.lock")).unwrap();
    lock.try_lock().expect("the run is not in use");
    t.run(&[
        "simulate", "--run", "run", "--scenes", "5", "--shots", "1", "--seed", "1", "--dt", "0.1",
    ])
    .code(5)
    .stderr_has("another annotrace process");
    drop(lock);
}

#[test]
fn detector_workers_without_python_exit_3() {
    let t = small_run();
    let empty = t.path("no-python");
    std::fs::create_dir_all(&empty).unwrap();
    t.run_env(
        &["annotate", "--run", "run", "--workers", "1"],
        &[("PATH", empty.to_str().unwrap())],
    )
    .code(3)
    .stderr_has("no Python 3 interpreter");
}
