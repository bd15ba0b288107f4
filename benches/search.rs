//! The search against a slow model: the share of wall time outside the proposer, with and without
//! overlapping evaluation and generation (`evolve --lag 0|1`).
//!
//! `cargo bench --bench search [-- --scenes 150 --dt 0.1 --latency-ms 1000 --parallel 4,32 --rounds 8 --lag 0,1]`
//! (a debug build: `cargo bench --profile dev --bench search`). It simulates `--scenes` billiards
//! shots with the `annotrace` binary, starts the test suite's scripted OpenAI-compatible server
//! (`tests/it/common/chat_server.rs`) answering every request after `--latency-ms` with a new child
//! (the skeleton detector with a marker pattern at a step only that child marks, so every child is
//! distinct and fully evaluated), then runs `annotrace evolve` for one label with `--parallel P
//! --llm-parallel P` and `--lag 0` and `--lag 1`, `--rounds` rounds each, and prints per run the
//! mean evaluation time per child (`candidates.eval_s`), the label's search wall time, the time a proposal or repair was in flight (`propose_s`), the share
//! outside the proposer (`evolution_labels.outside_proposer_share`), the candidates by status and the
//! most requests the server answered at once.

#[path = "../tests/it/common/chat_server.rs"]
mod chat_server;

use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use annotrace::search::skeleton::skeleton;
use annotrace::trace::Env;
use chat_server::{ChatServer, Reply};

const BIN: &str = env!("CARGO_BIN_EXE_annotrace");
const LABEL: &str = "moving ball";

/// `name value` pairs after `--`.
fn arg(name: &str, default: &str) -> String {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1).cloned())
        .unwrap_or_else(|| default.to_string())
}

fn annotrace(dir: &Path, args: &[&str]) -> String {
    let out = Command::new(BIN)
        .current_dir(dir)
        .args(args)
        .output()
        .expect("run annotrace");
    assert!(
        out.status.success(),
        "annotrace {args:?} failed: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Child `k`: the skeleton, plus one-step patterns on the last 12 steps of a trace spelling k + 1 in
/// binary (the balls are at rest there), so no two children share code or behaviour on the probe
/// traces.
fn child(k: u64) -> String {
    let base = skeleton(Env::Pooltool, LABEL);
    let marker = format!(
        "    n = len(steps)\n    for b in range(12):\n        if ({k} + 1) >> b & 1 and n > b:\n            \
         out.append((\"cue\", n - 1 - b, n - 1 - b))\n    out.sort(key=lambda r: (r[1], r[0]))"
    );
    base.replace("    out.sort(key=lambda r: (r[1], r[0]))", &marker)
}

fn main() {
    let scenes = arg("--scenes", "150");
    let dt = arg("--dt", "0.1");
    let latency: u64 = arg("--latency-ms", "1000").parse().expect("--latency-ms");
    let rounds: u64 = arg("--rounds", "8").parse().expect("--rounds");
    let parallels: Vec<u64> = arg("--parallel", "4,32")
        .split(',')
        .map(|p| p.trim().parse().expect("--parallel"))
        .collect();
    let lags: Vec<String> = arg("--lag", "0,1").split(',').map(String::from).collect();

    let dir = tempfile::tempdir().expect("a temporary folder");
    let t = std::time::Instant::now();
    annotrace(
        dir.path(),
        &[
            "simulate", "--env", "pooltool", "--scenes", &scenes, "--shots", "1", "--seed", "1",
            "--dt", &dt, "--run", "r", "-q",
        ],
    );
    println!(
        "simulated {scenes} billiards shots (dt {dt} s) in {:.1} s; model latency {latency} ms",
        t.elapsed().as_secs_f64()
    );
    println!(
        "| parallel | lag | children | statuses | evaluation per child (s) | search wall (s) | proposer busy (s) | outside the proposer | most in flight |"
    );
    println!("|---:|---:|---:|---|---:|---:|---:|---:|---:|");
    for &parallel in &parallels {
        for lag in &lags {
            let budget = (parallel * rounds).to_string();
            let p = parallel.to_string();
            let counter = Arc::new(AtomicU64::new(0));
            let c = counter.clone();
            let server = ChatServer::responder(move |_| {
                let k = c.fetch_add(1, Ordering::SeqCst);
                Reply::slow(
                    latency,
                    Reply::chat(&format!("```python\n{}```\n", child(k))),
                )
            });
            let out = annotrace(
                dir.path(),
                &[
                    "evolve",
                    "--run",
                    "r",
                    "--labels",
                    LABEL,
                    "--budget",
                    &budget,
                    "--parallel",
                    &p,
                    "--llm-parallel",
                    &p,
                    "--lag",
                    lag,
                    "--proposer",
                    "llm",
                    "--llm-base-url",
                    &server.url(),
                    "--llm-model",
                    "scripted",
                    "--no-time-penalty",
                    "--convergence-per-bin",
                    "0",
                    "--seed",
                    "1",
                    "-q",
                ],
            );
            let asked = server.seen().len();
            let stage = out
                .split_whitespace()
                .nth(1)
                .expect("evolve prints its stage id")
                .to_string();
            let q =
                |sql: &str| annotrace(dir.path(), &["query", "--run", "r", "--format", "csv", sql]);
            let row = q(&format!(
                "SELECT wall_s, propose_s, outside_proposer_share FROM evolution_labels \
                 WHERE run_stage = '{stage}'"
            ));
            let f: Vec<f64> = row
                .lines()
                .nth(1)
                .expect("a label row")
                .split(',')
                .map(|x| x.parse().expect("a number"))
                .collect();
            let eval = q(&format!(
                "SELECT avg(eval_s) AS e FROM candidates WHERE run_stage = '{stage}' AND step >= 0"
            ));
            let eval: f64 = eval
                .lines()
                .nth(1)
                .and_then(|l| l.parse().ok())
                .unwrap_or(f64::NAN);
            let statuses = q(&format!(
                "SELECT status, count(*) AS n FROM candidates WHERE run_stage = '{stage}' \
                 AND step >= 0 GROUP BY status ORDER BY status"
            ));
            let statuses: Vec<String> = statuses
                .lines()
                .skip(1)
                .map(|l| l.replace(',', " "))
                .collect();
            println!(
                "| {parallel} | {lag} | {asked} | {} | {:.3} | {:.2} | {:.2} | {:.1} % | {} |",
                statuses.join(", "),
                eval,
                f[0],
                f[1],
                100.0 * f[2],
                server.max_in_flight()
            );
        }
    }
}
