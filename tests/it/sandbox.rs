//! Hostile detectors, one per test: each is contained and reported while the batch goes on.
//!
//! Every test runs the hostile detector between two well-behaved ones over two traces, and checks the
//! hostile one's status and that the well-behaved ones still produced their patterns on both traces
//! (so a killed worker was replaced). Tests marked "OS layer" turn the Python layer off
//! (`python_guard: false`) to show that the process layers stop the same attack on their own.

use std::time::{Duration, Instant};

use annotrace::detect::{CandidateStatus, Detector, DetectorError, SandboxLimits, WorkerPool};
use annotrace::testutil::synthetic_trace;
use annotrace::trace::{Env, Trace};

const GOOD: &str = r#"
def find_pattern(trace):
    steps = trace["timesteps"]
    return [{"label": "probe", "start_timestep": steps[0]["index"], "end_timestep": steps[-1]["index"],
             "parameters": {"object_details": {"0": {"role": "any"}}}}]
"#;

fn limits(guard: bool) -> SandboxLimits {
    SandboxLimits {
        workers: 1,
        call_timeout: Duration::from_millis(1500),
        memory_bytes: 768 << 20,
        python_guard: guard,
        ..SandboxLimits::default()
    }
}

fn traces() -> Vec<Trace> {
    vec![
        synthetic_trace(Env::Phyre, 0, 5, 2),
        synthetic_trace(Env::Phyre, 1, 5, 2),
    ]
}

fn det(code: &str) -> Detector {
    Detector::new(Env::Phyre, "probe", code, "test")
}

/// Runs [good, hostile, good] over two traces and returns the hostile detector's statuses.
fn contain(code: &str, guard: bool) -> Vec<CandidateStatus> {
    let pool = WorkerPool::new(limits(guard)).expect("workers start");
    if guard {
        assert!(pool.layers().python_guard);
    }
    let good_a = det(GOOD);
    let good_b = det(&format!("{GOOD}\n# second copy\n"));
    let hostile = det(code);
    let batch = pool.run(&[good_a, hostile, good_b], &traces());
    assert_eq!(batch.results.len(), 6);
    let mut hostile_status = Vec::new();
    for r in &batch.results {
        if r.detector == 1 {
            hostile_status.push(r.status.clone());
        } else {
            assert_eq!(
                r.status,
                CandidateStatus::Ok,
                "well-behaved detector failed: {r:?}"
            );
            assert_eq!(r.patterns.len(), 1);
        }
    }
    hostile_status
}

fn wrap(body: &str) -> String {
    let body: String = body.lines().map(|l| format!("    {l}\n")).collect();
    format!("def find_pattern(trace):\n{body}    return []\n")
}

fn is_forbidden(s: &CandidateStatus) -> bool {
    matches!(
        s,
        CandidateStatus::Failed(DetectorError::Forbidden { line: Some(_), .. })
    )
}

fn is_permission_error(s: &CandidateStatus) -> bool {
    match s {
        CandidateStatus::Failed(DetectorError::Runtime { message, .. }) => {
            message.contains("PermissionError") || message.contains("Operation not permitted")
        }
        _ => false,
    }
}

#[test]
fn sandbox_layers_are_reported() {
    let pool = WorkerPool::new(limits(true)).unwrap();
    let l = pool.layers();
    assert!(l.rlimits && l.python_guard);
    assert!(!l.python.is_empty());
    // This project's machine (Linux 6.x) has both; elsewhere the pool reports what it found.
    if cfg!(target_os = "linux") && cfg!(target_arch = "x86_64") {
        assert!(l.no_new_privs, "{}", l.describe());
        assert_eq!(l.seccomp, "filter", "{}", l.describe());
    }
}

#[test]
fn reading_a_file_is_refused() {
    let s = contain(&wrap("return open('/etc/passwd').read()"), true);
    assert!(s.iter().all(is_forbidden), "{s:?}");
}

#[test]
fn reading_a_file_is_refused_by_the_os_layers() {
    let s = contain(&wrap("return [open('/etc/passwd').read()]"), false);
    assert!(s.iter().all(is_permission_error), "{s:?}");
}

#[test]
fn landlock_and_seccomp_each_stop_file_access_alone() {
    let read = det(&wrap("return [open('/etc/hostname').read()]"));
    for (landlock, seccomp, errno) in [(true, false, "Errno 13"), (false, true, "Errno 1")] {
        let pool = WorkerPool::new(SandboxLimits {
            landlock,
            seccomp,
            ..limits(false)
        })
        .unwrap();
        let l = pool.layers();
        assert_eq!(l.landlock != "unavailable", landlock, "{}", l.describe());
        assert_eq!(l.seccomp == "filter", seccomp, "{}", l.describe());
        let batch = pool.run(std::slice::from_ref(&read), &traces()[..1]);
        match &batch.results[0].status {
            CandidateStatus::Failed(DetectorError::Runtime { message, .. }) => {
                assert!(message.contains(errno), "{message}")
            }
            other => panic!("landlock {landlock}, seccomp {seccomp}: {other:?}"),
        }
    }
}

#[test]
fn writing_a_file_is_refused_by_the_os_layers() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("owned.txt");
    let code = wrap(&format!(
        "open({:?}, 'w').write('x')",
        target.display().to_string()
    ));
    let s = contain(&code, false);
    assert!(s.iter().all(is_permission_error), "{s:?}");
    assert!(!target.exists());
    assert!(
        contain(&wrap("open('/tmp/x', 'w')"), true)
            .iter()
            .all(is_forbidden)
    );
}

#[test]
fn listing_a_directory_is_refused() {
    assert!(
        contain(&wrap("import os\nreturn os.listdir('/')"), true)
            .iter()
            .all(is_forbidden)
    );
    // The worker's already-imported `os` module, reached without the Python layer.
    let s = contain(&wrap("import os\nreturn os.listdir('/')"), false);
    assert!(s.iter().all(is_permission_error), "{s:?}");
}

#[test]
fn opening_a_socket_is_refused() {
    assert!(
        contain(&wrap("import socket\nsocket.socket()"), true)
            .iter()
            .all(is_forbidden)
    );
    // Without the Python layer: the socket module cannot even be loaded (Landlock), and the raw
    // syscall through the already-loaded ctypes fails with EPERM (seccomp).
    let s = contain(&wrap("import socket\nsocket.socket()"), false);
    assert!(s.iter().all(is_permission_error), "{s:?}");
    let raw = wrap(
        "import ctypes\nfd = ctypes.CDLL(None).socket(2, 1, 0)\nif fd < 0:\n    raise PermissionError('socket: Operation not permitted')\nreturn [fd]",
    );
    let s = contain(&raw, false);
    assert!(s.iter().all(is_permission_error), "{s:?}");
}

#[test]
fn spawning_a_process_or_forking_is_refused() {
    assert!(
        contain(&wrap("import subprocess\nsubprocess.run(['ls'])"), true)
            .iter()
            .all(is_forbidden)
    );
    let s = contain(&wrap("import os\nos.fork()"), false);
    assert!(s.iter().all(is_permission_error), "{s:?}");
    let s = contain(&wrap("import os\nos.execv('/bin/ls', ['ls'])"), false);
    assert!(s.iter().all(is_permission_error), "{s:?}");
    let s = contain(
        &wrap("import os\nos.posix_spawn('/bin/ls', ['ls'], {})"),
        false,
    );
    assert!(s.iter().all(is_permission_error), "{s:?}");
}

#[test]
fn an_endless_loop_times_out_and_the_batch_goes_on() {
    let t0 = Instant::now();
    let s = contain(&wrap("while True:\n    pass"), true);
    assert!(
        matches!(s[0], CandidateStatus::Failed(DetectorError::Timeout { .. })),
        "{s:?}"
    );
    // Not run again on the second trace: it already timed out once.
    assert!(
        matches!(s[1], CandidateStatus::Failed(DetectorError::Skipped { .. })),
        "{s:?}"
    );
    assert!(t0.elapsed() < Duration::from_secs(10));
}

#[test]
fn a_crash_among_gathered_replies_is_blamed_on_the_call_that_crashed() {
    // The worker writes a trace's replies together, so when it dies the replies of the calls before
    // the crash are lost with it; they run again, one reply at a time, and only the crashing call
    // fails. (OS layer test: with the Python layer off, a detector can reach ctypes and crash the
    // interpreter outright.)
    let s = contain(&wrap("import ctypes\nreturn ctypes.string_at(0)"), false);
    assert!(
        matches!(&s[0], CandidateStatus::Failed(DetectorError::Crashed { message }) if message.contains("signal 11")),
        "{s:?}"
    );
    assert!(
        matches!(s[1], CandidateStatus::Failed(DetectorError::Skipped { .. })),
        "{s:?}"
    );
}

#[test]
fn allocating_ten_gigabytes_is_a_memory_error() {
    let s = contain(
        &wrap("x = [0] * (10 * 1024 ** 3 // 8)\nreturn [len(x)]"),
        true,
    );
    assert!(
        matches!(s[0], CandidateStatus::Failed(DetectorError::Memory { .. })),
        "{s:?}"
    );
    assert!(
        matches!(s[1], CandidateStatus::Failed(DetectorError::Skipped { .. })),
        "{s:?}"
    );
    let s = contain(&wrap("x = bytes(10 * 1024 ** 3)\nreturn [len(x)]"), true);
    assert!(
        matches!(s[0], CandidateStatus::Failed(DetectorError::Memory { .. })),
        "{s:?}"
    );
}

#[test]
fn deep_recursion_is_a_runtime_error_with_its_line() {
    let code =
        "def f(n):\n    return f(n + 1) + 1\n\ndef find_pattern(trace):\n    return [f(0)]\n";
    let s = contain(code, true);
    for st in &s {
        match st {
            CandidateStatus::Failed(DetectorError::Runtime { message, line, .. }) => {
                assert!(message.contains("RecursionError"), "{message}");
                assert_eq!(*line, Some(2));
            }
            other => panic!("{other:?}"),
        }
    }
}

#[test]
fn printing_a_gigabyte_costs_no_memory() {
    // 1 GiB printed in 1 MiB lines: the sink keeps 4 KiB, so this is bounded by time only.
    let code = wrap("line = 'x' * (1 << 20)\nfor i in range(1024):\n    print(line)");
    let s = contain(&code, true);
    assert!(
        s.iter().all(|s| *s == CandidateStatus::Ok
            || matches!(
                s,
                CandidateStatus::Failed(
                    DetectorError::Timeout { .. } | DetectorError::Skipped { .. }
                )
            )),
        "{s:?}"
    );
}

#[test]
fn returning_a_hundred_megabyte_list_is_invalid_output() {
    let s = contain(&wrap("return ['x' * 100] * (1024 * 1024)"), true);
    for st in &s {
        match st {
            CandidateStatus::Failed(DetectorError::InvalidOutput { path, message }) => {
                assert_eq!(path, "$");
                assert!(message.contains("limit"), "{message}");
            }
            other => panic!("{other:?}"),
        }
    }
    // Under the pattern-count limit but over the byte limit.
    let s = contain(&wrap("return ['x' * (1 << 20)] * 100"), true);
    assert!(
        s.iter().all(|s| matches!(
            s,
            CandidateStatus::Failed(DetectorError::InvalidOutput { .. })
        )),
        "{s:?}"
    );
}

#[test]
fn introspection_escapes_are_refused() {
    for code in [
        "return ().__class__.__mro__[1].__subclasses__()",
        "return [c for c in ().__class__.__bases__[0].__subclasses__()]",
        "g = (x for x in [1])\nreturn [g.gi_frame.f_back.f_globals]",
        "return [find_pattern.__globals__['__builtins__']]",
        "return [getattr((), '__class__')]",
        "return [type(())]",
        "return [__builtins__]",
        "return [__import__('os')]",
        "return [eval('1')]",
        "return [globals()]",
    ] {
        let s = contain(&wrap(code), true);
        assert!(s.iter().all(is_forbidden), "{code}: {s:?}");
    }
    // Even if the code reaches an object, the trace it was given is read-only.
    let s = contain(&wrap("trace['timesteps'] = []"), true);
    assert!(
        s.iter().all(|s| matches!(s, CandidateStatus::Failed(DetectorError::Runtime { message, .. }) if message.contains("read-only"))),
        "{s:?}"
    );
}

/// `dict`'s methods called unbound write past FrozenDict's refusals; a detector that can reach the
/// type reads a private copy, so the detector after it still sees the trace as it was loaded.
#[test]
fn unbound_dict_methods_change_only_the_callers_copy() {
    for code in [
        "dict.update(trace, {'timesteps': ()})\nreturn [{'bad': 1}] if trace['timesteps'] else []",
        "dict.clear(trace['timesteps'][0])",
        "d = dict\nd.pop(trace, 'timesteps')\nd.setdefault(trace, 'timesteps', ())",
        "for s in trace['timesteps']:\n    dict.update(s, {'index': -5})",
    ] {
        let s = contain(&wrap(code), true);
        assert!(s.iter().all(|s| *s == CandidateStatus::Ok), "{code}: {s:?}");
    }
}

/// Lists nested in lists of a trace arrive as tuples too: nothing a detector holds can be changed in
/// place for the next one.
#[test]
fn nested_lists_of_a_trace_are_read_only() {
    let mut ts = traces();
    for t in &mut ts {
        t.extra
            .insert("nested".into(), serde_json::json!([[1, 2], [[3]]]));
    }
    let hostile = det(&wrap("trace['nested'][0].append(9)"));
    let check = det(r#"
def find_pattern(trace):
    n = trace["nested"]
    if n != ((1, 2), ((3,),)):
        return [{"label": "probe", "start_timestep": 0, "end_timestep": 0, "parameters": {"seen": repr(n)}}]
    return []
"#);
    let pool = WorkerPool::new(limits(true)).expect("workers start");
    let batch = pool.run(&[hostile, check], &ts);
    for r in &batch.results {
        if r.detector == 0 {
            assert!(
                matches!(&r.status, CandidateStatus::Failed(DetectorError::Runtime { message, .. }) if message.contains("AttributeError")),
                "{r:?}"
            );
        } else {
            assert_eq!(r.status, CandidateStatus::Ok, "{r:?}");
            assert!(r.patterns.is_empty(), "{:?}", r.patterns);
        }
    }
}

#[test]
fn environment_variables_hold_no_secrets() {
    assert!(
        contain(&wrap("import os\nreturn list(os.environ)"), true)
            .iter()
            .all(is_forbidden)
    );
    // Without the Python layer the environment is readable, but it was scrubbed.
    // SAFETY: tests in this binary do not read this variable concurrently.
    unsafe { std::env::set_var("ANNOTRACE_TEST_SECRET", "hunter2") };
    let pool = WorkerPool::new(limits(false)).unwrap();
    let code = "import os\ndef find_pattern(trace):\n    return [{'label': 'probe', 'start_timestep': 0, 'end_timestep': 0, 'parameters': {'object_details': {}, 'env': dict(os.environ)}}]\n";
    let batch = pool.run(&[det(code)], &traces()[..1]);
    let r = &batch.results[0];
    assert_eq!(r.status, CandidateStatus::Ok, "{r:?}");
    let env = r.patterns[0].parameters["env"].as_object().unwrap();
    let mut keys: Vec<&str> = env.keys().map(String::as_str).collect();
    keys.sort();
    assert!(
        keys.iter()
            .all(|k| ["LC_ALL", "LC_CTYPE", "PYTHONHASHSEED"].contains(k)),
        "{keys:?}"
    );
}

#[test]
fn sleeping_past_the_timeout_is_killed() {
    assert!(
        contain(&wrap("import time\ntime.sleep(5)"), true)
            .iter()
            .all(is_forbidden)
    );
    // The OS layers do not stop sleeping; the wall-clock timer does.
    let t0 = Instant::now();
    let s = contain(&wrap("import time\ntime.sleep(30)"), false);
    assert!(
        matches!(s[0], CandidateStatus::Failed(DetectorError::Timeout { .. })),
        "{s:?}"
    );
    assert!(t0.elapsed() < Duration::from_secs(10));
}

#[test]
fn syntax_errors_and_missing_functions_are_typed() {
    let s = contain("def find_pattern(trace)\n    return []\n", true);
    assert!(
        s.iter().all(|s| matches!(
            s,
            CandidateStatus::Failed(DetectorError::Syntax {
                line: Some(1),
                column: Some(_),
                ..
            })
        )),
        "{s:?}"
    );
    let s = contain("def other(trace):\n    return []\n", true);
    assert!(
        s.iter().all(|s| matches!(
            s,
            CandidateStatus::Failed(DetectorError::NoFindPattern { .. })
        )),
        "{s:?}"
    );
    let s = contain(&wrap("return [1 / 0]"), true);
    assert!(
        s.iter().all(|s| matches!(s, CandidateStatus::Failed(DetectorError::Runtime { line: Some(2), exception: Some(e), .. }) if e == "ZeroDivisionError")),
        "{s:?}"
    );
}

#[test]
fn invalid_output_is_reported_with_its_json_path() {
    let code = "def find_pattern(trace):\n    return [{'label': 'probe', 'start_timestep': 3, 'end_timestep': 1, 'parameters': {'object_details': {}}}]\n";
    let s = contain(code, true);
    assert!(
        s.iter().all(|s| matches!(s, CandidateStatus::Failed(DetectorError::InvalidOutput { path, .. }) if path == "$[0].end_timestep")),
        "{s:?}"
    );
    let s = contain(&wrap("return [{1, 2}]"), true);
    assert!(
        s.iter().all(|s| matches!(s, CandidateStatus::Failed(DetectorError::InvalidOutput { message, .. }) if message.contains("set"))),
        "{s:?}"
    );
    let s = contain("def find_pattern(trace):\n    return None\n", true);
    assert!(
        s.iter().all(|s| matches!(s, CandidateStatus::Failed(DetectorError::InvalidOutput { path, .. }) if path == "$")),
        "{s:?}"
    );
}

/// What a detector returns reaches Rust as `json.dumps` would have written it, whichever way it
/// travels: marshalled (plain dicts, lists, tuples, shared sub-values, integer keys, integers past 64
/// bits) or as JSON (values holding the trace's own read-only dicts, which marshal refuses).
#[test]
fn outputs_reach_rust_as_json_would_carry_them() {
    let pool = WorkerPool::new(limits(true)).expect("workers start");
    let marshalled = det(r#"
def find_pattern(trace):
    shared = [1.5, -2, "é"]
    return [{"label": "Probe", "start_timestep": 0, "end_timestep": 1,
             "parameters": {"object_details": {3: {"role": "r", "p": (0.25, 1e300)}},
                            "a": shared, "b": shared, "big": 2 ** 70, "neg": -(2 ** 40),
                            True: None, None: False}}]
"#);
    let as_json = det(r#"
def find_pattern(trace):
    first = trace["timesteps"][0]
    return [{"label": "probe", "start_timestep": 0, "end_timestep": 0,
             "parameters": {"object_details": {"0": {"role": "r"}}, "step": first}}]
"#);
    let batch = pool.run(&[marshalled, as_json], &traces()[..1]);
    let params: Vec<serde_json::Value> = batch
        .results
        .iter()
        .map(|r| {
            assert_eq!(r.status, CandidateStatus::Ok, "{r:?}");
            serde_json::Value::Object(r.patterns[0].parameters.clone())
        })
        .collect();
    assert_eq!(
        params[0],
        serde_json::json!({
            "object_details": {"3": {"role": "r", "p": [0.25, 1e300]}},
            "a": [1.5, -2, "é"], "b": [1.5, -2, "é"],
            "big": 1180591620717411303424.0, "neg": -1099511627776i64,
            "true": null, "null": false,
        })
    );
    assert_eq!(params[1]["step"]["index"], 0);
    assert!(params[1]["step"]["objects"].is_array(), "{}", params[1]);
}

/// `cpu_s` is the worker's CPU time of the call, exact under the worker's CPU limit. (The process-wide
/// clock, once RLIMIT_CPU is set, moves only at scheduler ticks: calls under a millisecond mostly read
/// 0.0.)
#[test]
fn a_short_call_s_cpu_time_is_measured() {
    let pool = WorkerPool::new(limits(true)).expect("workers start");
    let busy = "def find_pattern(trace):\n    x = 0\n    for i in range(20000):\n        x += i\n    return []\n";
    let dets: Vec<Detector> = (0..5)
        .map(|k| det(&format!("{busy}# copy {k}\n")))
        .collect();
    let batch = pool.run(&dets, &traces());
    assert_eq!(batch.results.len(), 10);
    for r in &batch.results {
        assert_eq!(r.status, CandidateStatus::Ok, "{r:?}");
        assert!(
            r.cpu_s > 0.0 && r.cpu_s <= r.wall_s + 1e-3,
            "cpu {} s, wall {} s",
            r.cpu_s,
            r.wall_s
        );
    }
}
