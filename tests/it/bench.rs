//! `annotrace bench`: one case end to end (the `simulate` child, Parquet counted from the footers, the
//! JSON record), the `annotate` case, the Parquet settings comparison on the run it kept (both
//! writers), and bad flags.

use serde_json::Value;

use crate::common::TestRun;

/// `annotrace bench --cases <case> --scale <scale> --threads 1`, keeping its run folders in `dir`
/// and its JSON record in `json`.
fn bench_one(
    t: &TestRun,
    case: &str,
    scale: &str,
    dir: &std::path::Path,
    json: &std::path::Path,
) -> crate::common::Ran {
    t.run(&[
        "bench",
        "--cases",
        case,
        "--scale",
        scale,
        "--threads",
        "1",
        "--dir",
        dir.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ])
}

#[test]
fn a_case_is_measured_from_the_files_it_wrote_and_settings_compare_on_them() {
    let t = TestRun::new();
    let dir = t.path("b");
    let json = t.path("b.jsonl");
    let r = bench_one(&t, "iphyre", "0.04", &dir, &json);
    r.ok().stdout_has("| iphyre |");
    let text = std::fs::read_to_string(&json).unwrap();
    let m: Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    // 40 games × 1 click set: 40 traces, every frame row counted, the files' bytes summed.
    assert_eq!(m["items"], 40);
    assert_eq!(m["traces"], 40);
    assert!(m["frame_rows"].as_u64().unwrap() > 40);
    assert!(m["parquet_bytes"].as_u64().unwrap() > m["frames_bytes"].as_u64().unwrap());
    assert!(m["wall_s"].as_f64().unwrap() > 0.0 && m["cpu_s"].as_f64().unwrap() > 0.0);
    assert!(m["frame_rows_per_cpu_s"].as_f64().unwrap() > 0.0);
    // The profile that built the binary, named as its folder is (`debug`, `release`, `dist`): this test's
    // executable sits in `<target>/<profile>/deps/`, beside the binary's own `<target>/<profile>/`.
    let exe = std::env::current_exe().unwrap();
    let profile = exe
        .parent()
        .and_then(|deps| deps.parent())
        .and_then(|p| p.file_name());
    let profile = profile.unwrap().to_str().unwrap().to_string();
    assert_eq!(m["profile"], profile.as_str());
    // The same frame rows as the run's own table.
    let q = t.run(&[
        "query",
        "SELECT count(*) AS n FROM frames",
        "--run",
        dir.join("iphyre-t1").to_str().unwrap(),
        "--format",
        "csv",
    ]);
    q.ok().stdout_has(&m["frame_rows"].to_string());
    let s = t.run(&[
        "bench",
        "--settings",
        dir.join("iphyre-t1").to_str().unwrap(),
    ]);
    s.ok()
        .stdout_has("40 trace(s)")
        .stdout_has(&format!("; profile {profile}"))
        .stdout_has("64 Ki-row pages (the default now: other tables)")
        .stdout_has(
            "| column writer, zstd 1 (the default now: timesteps and frames; PHYRE's and I-PHYRE's float pages) |",
        )
        .stdout_has("raw literals for per-row floats (billiards' default now) |")
        .stdout_has("| column writer, lz4 (raw) |")
        .stdout_has("| lz4 (raw) |");
}

#[test]
fn the_annotate_case_times_the_built_in_library_over_shots_it_simulated_first() {
    let t = TestRun::new();
    let dir = t.path("b");
    let json = t.path("b.jsonl");
    let r = bench_one(&t, "annotate", "0.005", &dir, &json);
    r.ok().stdout_has("| annotate |");
    // annotate's own per-label table stays out of the bench's.
    assert!(!r.stdout.contains("| label "), "{}", r.stdout);
    let text = std::fs::read_to_string(&json).unwrap();
    let m: Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    assert_eq!(m["case"], "annotate");
    assert_eq!(m["items"], 10);
    assert_eq!(m["traces"], 10);
    assert_eq!(m["unit"], "traces");
    // Only what annotate wrote is counted: its tables, no frames.
    assert_eq!(m["frames_bytes"], 0);
    assert!(m["parquet_bytes"].as_u64().unwrap() > 0);
    let (wall, cpu) = (m["wall_s"].as_f64().unwrap(), m["cpu_s"].as_f64().unwrap());
    assert!(wall > 0.0 && cpu > 0.0);
    assert!((m["wall_ms_per_item"].as_f64().unwrap() - wall * 100.0).abs() < 1e-6);
    // The timed copy holds the annotate stage's output; the simulated input it was copied from
    // does not (a later thread count gets a fresh copy of it).
    let calls = |run: &str| {
        t.run(&[
            "query",
            "SELECT count(DISTINCT trace_id) AS n FROM detector_calls",
            "--run",
            dir.join(run).to_str().unwrap(),
            "--format",
            "csv",
        ])
    };
    calls("annotate-t1").ok().stdout_has("10");
    let untouched = calls("annotate-input");
    assert_ne!(untouched.code, Some(0), "{}", untouched.stdout);
    untouched.stderr_has("detector_calls");
}

#[test]
fn bad_flags_are_input_errors() {
    let t = TestRun::new();
    t.run(&["bench", "--cases", "nope"])
        .code(2)
        .stderr_has("unknown case");
    t.run(&["bench", "--threads", "0"])
        .code(2)
        .stderr_has("--threads");
    t.run(&["bench", "--scale=-1"])
        .code(2)
        .stderr_has("--scale");
}
