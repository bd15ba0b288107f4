//! The developer tools in `tools/` that run on annotrace's own output: `worker_replay.py` records the
//! requests `annotate` sends a worker and replays them through the worker's functions.

use crate::common::{TestRun, repo};

/// `python3 tools/worker_replay.py ARGS…` in the test's folder.
fn replay_tool(t: &TestRun, args: &[&str]) -> crate::common::Ran {
    std::process::Command::new("python3")
        .arg(repo().join("tools/worker_replay.py"))
        .args(args)
        .current_dir(t.path(""))
        .output()
        .expect("python3 runs")
        .into()
}

#[test]
fn worker_replay_records_annotates_requests_and_replays_them_with_the_same_replies() {
    let t = TestRun::new();
    t.run(&[
        "simulate", "--env", "pooltool", "--scenes", "4", "--shots", "1", "--seed", "2", "--dt",
        "0.05", "--run", "r",
    ])
    .ok();
    let before = t.files("r");
    let exe = env!("CARGO_BIN_EXE_annotrace");
    replay_tool(
        &t,
        &[
            "capture",
            "--run",
            "r",
            "--out",
            "s.stream",
            "--annotrace",
            exe,
        ],
    )
    .ok()
    .stdout_has("into s.stream");
    // The capture annotates a copy: the run is as it was.
    assert_eq!(t.files("r"), before);
    assert!(!t.path("s.stream.partial").exists());
    let digest = |r: &crate::common::Ran| {
        r.stdout
            .lines()
            .find_map(|l| l.strip_prefix("replies sha256 "))
            .map(str::to_string)
            .unwrap_or_else(|| panic!("no digest in {}", r.stdout))
    };
    let first = replay_tool(&t, &["replay", "s.stream", "--passes", "2"]);
    first
        .ok()
        .stdout_has("4 traces, 48 detector calls, best of 2 passes");
    for part in ["load", "evict", "compile", "run", "total"] {
        assert!(
            first
                .stdout
                .lines()
                .any(|l| l.trim_start().starts_with(part)),
            "{part}: {}",
            first.stdout
        );
    }
    let again = replay_tool(&t, &["replay", "s.stream", "--passes", "1"]);
    assert_eq!(digest(&first), digest(again.ok()));
    // With helper results shared between a request's detectors, as `annotate`'s workers run them:
    // the same replies.
    for share in ["always", "measured"] {
        let shared = replay_tool(
            &t,
            &["replay", "s.stream", "--passes", "1", "--share", share],
        );
        assert_eq!(digest(&first), digest(shared.ok()), "--share {share}");
    }
    // A stream cut inside a frame is refused with where it ends.
    let bytes = std::fs::read(t.path("s.stream")).unwrap();
    std::fs::write(t.path("cut.stream"), &bytes[..bytes.len() - 3]).unwrap();
    replay_tool(&t, &["replay", "cut.stream"])
        .code(1)
        .stderr_has("cut off at byte");
    // A run folder that does not exist.
    replay_tool(
        &t,
        &[
            "capture",
            "--run",
            "nope",
            "--out",
            "x.stream",
            "--annotrace",
            exe,
        ],
    )
    .code(1)
    .stderr_has("nope: no such run folder");
}
