//! `annotrace import`: the paper's JSON format in, every fault reported with file, trace and JSON path.

use annotrace::testutil::synthetic_trace;
use annotrace::trace::Env;
use serde_json::{Value, json};

use crate::common::{TestRun, example, read_json};

fn import(t: &TestRun, env: &str, path: &str, run: &str) -> crate::common::Ran {
    t.run(&["import", "--env", env, path, "--run", run])
}

/// Import → export → import → export gives the input back, for every field of every environment.
#[test]
fn round_trip_is_lossless_for_every_environment() {
    for env in Env::ALL {
        let t = TestRun::new();
        let src = example(env);
        let original = read_json(&src);
        t.run(&[
            "import",
            "--env",
            env.as_str(),
            src.to_str().unwrap(),
            "--run",
            "a",
        ])
        .ok();
        let id = src.file_stem().unwrap().to_str().unwrap();
        t.run(&["export", "--run", "a", "--trace", id, "--out", "first.json"])
            .ok();
        let mut first = read_json(&t.path("first.json"));
        assert_eq!(first["trace_id"], id);
        t.run(&["import", "--env", env.as_str(), "first.json", "--run", "b"])
            .ok();
        t.run(&[
            "export",
            "--run",
            "b",
            "--trace",
            id,
            "--out",
            "second.json",
        ])
        .ok();
        let second = read_json(&t.path("second.json"));
        assert_eq!(first, second, "{env}: second round trip differs");
        first.as_object_mut().unwrap().remove("trace_id");
        assert_eq!(first, original, "{env}: export differs from the input");
    }
}

/// Fields the format does not name are kept at every level, in order.
#[test]
fn unknown_fields_survive_at_every_level() {
    let t = TestRun::new();
    let mut v = read_json(&example(Env::Phyre));
    v["simulator"] = json!({"engine": "box2d", "fps": 60});
    v["timesteps"][0]["solved_state"] = json!(false);
    v["timesteps"][1]["objects"][2]["user"] = json!(true);
    v["events"][0]["step"] = json!(0);
    v["outcome"]["stock_result"] = json!({"solved": false});
    t.write("x.json", &v.to_string());
    t.run(&["import", "--env", "phyre", "x.json", "--run", "r"])
        .ok();
    t.run(&["export", "--run", "r", "--trace", "x", "--out", "back.json"])
        .ok();
    let mut back = read_json(&t.path("back.json"));
    back.as_object_mut().unwrap().remove("trace_id");
    assert_eq!(back, v);
    let keys: Vec<&String> = back.as_object().unwrap().keys().collect();
    assert!(
        keys.iter().position(|k| *k == "simulator") < keys.iter().position(|k| *k == "timesteps")
    );
}

/// Writes a variant of the pooltool example with one fault, imports it, and checks the message.
fn rejects(edit: impl FnOnce(&mut Value), env: &str, path: &str, kind: &str) {
    let t = TestRun::new();
    let mut v = read_json(&example(Env::Pooltool));
    edit(&mut v);
    t.write("bad.json", &v.to_string());
    let r = import(&t, env, "bad.json", "run");
    r.code(2)
        .stderr_has("bad.json")
        .stderr_has("trace #0")
        .stderr_has(&format!("at {path}:"))
        .stderr_has(&format!("[{kind}]"));
    assert!(
        !t.path("run").exists(),
        "a failed import into a new run leaves nothing behind"
    );
}

#[test]
fn a_wrong_type_names_its_json_path() {
    rejects(
        |v| v["timesteps"][3]["objects"][1]["position"][0] = json!("abc"),
        "pooltool",
        "$.timesteps[3].objects[1].position[0]",
        "type",
    );
}

#[test]
fn a_missing_field_names_its_json_path() {
    rejects(
        |v| drop(v.as_object_mut().unwrap().remove("task_id")),
        "pooltool",
        "$.task_id",
        "missing",
    );
    rejects(
        |v| {
            drop(
                v["timesteps"][2]["objects"][0]
                    .as_object_mut()
                    .unwrap()
                    .remove("ball_id"),
            )
        },
        "pooltool",
        "$.timesteps[2].objects[0].ball_id",
        "missing",
    );
    rejects(
        |v| drop(v["outcome"].as_object_mut().unwrap().remove("success")),
        "pooltool",
        "$.outcome.success",
        "missing",
    );
}

#[test]
fn duplicate_object_ids_in_a_timestep_are_rejected() {
    rejects(
        |v| v["timesteps"][4]["objects"][1]["ball_id"] = json!("cue"),
        "pooltool",
        "$.timesteps[4].objects[1]",
        "duplicate_object",
    );
}

#[test]
fn time_and_index_must_increase() {
    rejects(
        |v| v["timesteps"][5]["t"] = json!(0.1),
        "pooltool",
        "$.timesteps[5].t",
        "order",
    );
    rejects(
        |v| v["timesteps"][5]["index"] = json!(4),
        "pooltool",
        "$.timesteps[5].index",
        "order",
    );
}

#[test]
fn an_environment_that_contradicts_env_is_rejected() {
    rejects(|_| {}, "phyre", "$.environment", "env_mismatch");
}

#[test]
fn nan_and_infinity_are_rejected_with_their_position() {
    let t = TestRun::new();
    let text = std::fs::read_to_string(example(Env::Pooltool)).unwrap();
    // Python's json.dumps writes NaN literals; the first velocity of the cue ball becomes one.
    let bad = text.replacen(
        "\"velocity\": [\n      0.0",
        "\"velocity\": [\n      NaN",
        1,
    );
    assert_ne!(bad, text);
    t.write("nan.json", &bad);
    let r = import(&t, "pooltool", "nan.json", "run");
    r.code(2)
        .stderr_has("nan.json:")
        .stderr_has("[non_finite]")
        .stderr_has("NaN is not a finite number");
    t.write("big.json", &text.replacen("0.028575", "1e999", 1));
    import(&t, "pooltool", "big.json", "run")
        .code(2)
        .stderr_has("[non_finite]");
    assert!(!t.path("run").exists());
}

#[test]
fn malformed_json_gives_line_and_column() {
    let t = TestRun::new();
    let text = std::fs::read_to_string(example(Env::Phyre)).unwrap();
    let cut = &text[..text.len() / 2];
    t.write("cut.json", cut);
    import(&t, "phyre", "cut.json", "run")
        .code(2)
        .stderr_has("cut.json:")
        .stderr_has("[syntax]");
    t.write(
        "garbage.json",
        "{\"environment\": \"phyre\", \"task_id\": oops}",
    );
    import(&t, "phyre", "garbage.json", "run")
        .code(2)
        .stderr_has("garbage.json:1:")
        .stderr_has("invalid JSON");
    assert!(!t.path("run").exists());
}

/// A failed import into an existing run adds nothing to it.
#[test]
fn a_failed_import_into_an_existing_run_changes_no_table() {
    let t = TestRun::new();
    import(&t, "phyre", example(Env::Phyre).to_str().unwrap(), "run").ok();
    let before = t.files("run");
    let mut good = synthetic_trace(Env::Phyre, 1, 5, 3);
    good.trace_id = "fine".into();
    let mut lines = annotrace::trace::json::to_value(&good).to_string();
    lines.push_str("\n{\"environment\": \"phyre\"}\n");
    t.write("mixed.jsonl", &lines);
    import(&t, "phyre", "mixed.jsonl", "run")
        .code(2)
        .stderr_has("mixed.jsonl:2")
        .stderr_has("$.task_id");
    let after: Vec<String> = t
        .files("run")
        .into_iter()
        .filter(|f| f.ends_with(".parquet"))
        .collect();
    let before: Vec<String> = before
        .into_iter()
        .filter(|f| f.ends_with(".parquet"))
        .collect();
    assert_eq!(before, after);
    assert_eq!(t.csv("run", "SELECT count(*) AS n FROM traces"), "n\n1\n");
}

/// `--skip-invalid` imports the good traces of a JSON Lines file and tabulates the bad ones.
#[test]
fn skip_invalid_imports_the_rest_and_prints_the_rejections() {
    let t = TestRun::new();
    let traces: Vec<_> = (0..3)
        .map(|i| synthetic_trace(Env::Iphyre, i, 6, 3))
        .collect();
    let mut lines: Vec<String> = traces
        .iter()
        .map(|tr| {
            let mut v = annotrace::trace::json::to_value(tr);
            v.as_object_mut().unwrap().remove("trace_id");
            v.to_string()
        })
        .collect();
    let mut bad: Value = serde_json::from_str(&lines[1]).unwrap();
    bad["timesteps"][2]["objects"][0]["joint"] = json!(1.5);
    lines[1] = bad.to_string();
    lines.insert(2, String::new()); // blank lines are skipped
    lines.push("not json at all".into());
    t.write("mixed.jsonl", &(lines.join("\n") + "\n"));
    let r = t.run(&[
        "import",
        "--env",
        "iphyre",
        "mixed.jsonl",
        "--run",
        "run",
        "--skip-invalid",
    ]);
    r.code(1)
        .stdout_has("imported 2 iphyre trace(s)")
        .stdout_has("2 invalid trace(s) skipped")
        .stdout_has("mixed.jsonl:2")
        .stdout_has("$.timesteps[2].objects[0].joint")
        .stdout_has("mixed.jsonl:5");
    assert_eq!(
        t.csv("run", "SELECT trace_id FROM traces ORDER BY trace_id"),
        "trace_id\nmixed-L1\nmixed-L4\n"
    );
}

/// A JSON Lines record cut short at its end is reported on its own line, whether the import stops at it
/// or skips it (the fail-fast message used to name the next line).
#[test]
fn a_truncated_record_is_named_by_its_own_line_in_both_modes() {
    let t = TestRun::new();
    let good =
        annotrace::trace::json::to_value(&synthetic_trace(Env::Pooltool, 0, 4, 2)).to_string();
    t.write("cut.jsonl", &format!("{good}\n{{\"broken\": \n"));
    t.run(&["import", "--env", "pooltool", "cut.jsonl", "--run", "a"])
        .code(2)
        .stderr_has("cut.jsonl:2:");
    let r = t.run(&[
        "import",
        "--env",
        "pooltool",
        "cut.jsonl",
        "--run",
        "b",
        "--skip-invalid",
    ]);
    r.code(1).stdout_has("cut.jsonl:2 ");
    assert!(!r.stdout.contains("cut.jsonl:3"), "{}", r.stdout);
}

/// Folders are imported recursively in sorted order; a trace id already in the run is refused.
#[test]
fn folders_arrays_and_duplicate_ids() {
    let t = TestRun::new();
    let a: Vec<Value> = (0..2)
        .map(|i| annotrace::trace::json::to_value(&synthetic_trace(Env::Pooltool, i, 4, 2)))
        .collect();
    let mut no_ids = a.clone();
    for v in &mut no_ids {
        v.as_object_mut().unwrap().remove("trace_id");
    }
    t.write("in/sub/arr.json", &Value::Array(no_ids).to_string());
    t.write("in/one.json", &a[0].to_string());
    t.write("in/ignored.txt", "not a trace");
    t.run(&["import", "--env", "pooltool", "in", "--run", "run"])
        .ok()
        .stdout_has("imported 3 pooltool trace(s)");
    assert_eq!(
        t.csv("run", "SELECT trace_id FROM traces ORDER BY trace_id"),
        "trace_id\narr-0\narr-1\npooltool-000000\n"
    );
    // Same content, other file: the id is taken.
    t.write("again.json", &a[0].to_string());
    import(&t, "pooltool", "again.json", "run")
        .code(2)
        .stderr_has("[duplicate_trace]")
        .stderr_has("pooltool-000000");
    // The same import again is recognised and skipped.
    t.run(&["import", "--env", "pooltool", "in", "--run", "run"])
        .ok()
        .stdout_has("already imported");
}

/// A seeded sweep of the JSON importer, the cheap counterpart of the `json_import` fuzz target
/// (fuzz/): the examples of every environment, as `.json` and as JSON Lines, edited at random
/// (bytes changed, ranges dropped or repeated, numbers swapped for hostile literals, the text cut
/// short), must each end in traces and typed errors, and every accepted trace must survive the trip
/// to Arrow rows and back (also read with its balls left as columns, loading into a detector worker
/// with the bytes its objects give) and through export (`testutil::import_round_trip`).
#[test]
fn no_input_makes_the_json_importer_panic_or_lose_an_accepted_trace() {
    let (cases, accepted) = sweep_json_import(0x0bad_5eed_1234_5678, 60, None);
    assert_eq!(cases, 360);
    // Some edits keep a valid trace (a changed digit, a repeated object field), so both paths run.
    assert!(accepted > 0, "no edited input was accepted");
}

/// The same sweep for `ANNOTRACE_SWEEP_SECONDS` (default 60) with a seed from `ANNOTRACE_SWEEP_SEED`
/// (default the clock), for a machine without the nightly toolchain:
/// `ANNOTRACE_SWEEP_SECONDS=600 cargo test --test it -- --ignored --nocapture json_importer_for_a_while`.
#[test]
#[ignore = "runs for a minute or more; see its doc"]
fn the_json_importer_for_a_while() {
    let var = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<u64>().ok());
    let secs = var("ANNOTRACE_SWEEP_SECONDS").unwrap_or(60);
    let seed = var("ANNOTRACE_SWEEP_SEED").unwrap_or_else(|| {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as u64)
            | 1
    });
    let until = std::time::Instant::now() + std::time::Duration::from_secs(secs);
    let (cases, accepted) = sweep_json_import(seed, u64::MAX, Some(until));
    eprintln!(
        "json importer sweep: seed {seed}, {secs} s, {cases} inputs, {accepted} traces accepted"
    );
}

/// Edits the examples `per_form` times per environment and layout (or until `until`), checking
/// each edited file with the importer's oracle; (inputs, traces accepted). Panics with the input on
/// a broken contract.
fn sweep_json_import(seed: u64, per_form: u64, until: Option<std::time::Instant>) -> (u64, usize) {
    use annotrace::testutil::import_round_trip;
    use annotrace::trace::json::SourceKind;

    const BYTES: &[u8] = b"{}[]\":,0123456789eE.+-ntrufalsNI \n\t\\u\xff\x00";
    const LITERALS: &[&str] = &[
        "NaN",
        "1e999",
        "-1e999",
        "-0",
        "1e-400",
        "9223372036854775808",
        "-9223372036854775809",
        "1.5",
        "null",
        "\"x\"",
        "[]",
        "{}",
        "true",
        "\"\\ud800\"",
        "[[[[[[[[",
        "-",
    ];
    let mut state = seed | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let forms: Vec<(Env, Vec<u8>, SourceKind)> = Env::ALL
        .iter()
        .flat_map(|&env| {
            let pretty = std::fs::read(example(env)).unwrap();
            let compact = serde_json::to_vec(&read_json(&example(env))).unwrap();
            let mut lines = compact.clone();
            lines.push(b'\n');
            lines.extend_from_slice(&compact);
            [
                (env, pretty, SourceKind::Json),
                (env, lines, SourceKind::JsonLines),
            ]
        })
        .collect();
    for (env, base, kind) in &forms {
        assert!(
            import_round_trip(base, *kind, *env).unwrap() >= 1,
            "{env}: the example itself is accepted"
        );
    }
    let (mut cases, mut accepted) = (0u64, 0usize);
    'rounds: for _ in 0..per_form {
        for (env, base, kind) in &forms {
            if until.is_some_and(|u| std::time::Instant::now() >= u) {
                break 'rounds;
            }
            let mut b = base.clone();
            for _ in 0..1 + next() % 3 {
                let at = (next() as usize) % b.len().max(1);
                match next() % 5 {
                    0 if !b.is_empty() => b[at] = BYTES[next() as usize % BYTES.len()],
                    1 => {
                        let end = (at + 1 + next() as usize % 24).min(b.len());
                        b.drain(at..end);
                    }
                    2 => {
                        let end = (at + 1 + next() as usize % 40).min(b.len());
                        let piece = b[at..end].to_vec();
                        b.splice(at..at, piece);
                    }
                    3 => {
                        // Swap the number starting at or after `at` for a literal.
                        let Some(s) = (at..b.len()).find(|&i| b[i].is_ascii_digit()) else {
                            continue;
                        };
                        let e = (s..b.len())
                            .find(|&i| {
                                !matches!(b[i], b'0'..=b'9' | b'.' | b'e' | b'E' | b'-' | b'+')
                            })
                            .unwrap_or(b.len());
                        let lit = LITERALS[next() as usize % LITERALS.len()];
                        b.splice(s..e, lit.bytes());
                    }
                    _ => b.truncate(at),
                }
            }
            cases += 1;
            match import_round_trip(&b, *kind, *env) {
                Ok(n) => accepted += n,
                Err(e) => panic!(
                    "{env} {kind:?}: {e}\ninput: {}",
                    String::from_utf8_lossy(&b)
                ),
            }
        }
    }
    (cases, accepted)
}

/// A folder of one-trace files (as the originals' recorders write them) is imported into shards of
/// many traces, not a file set per trace: small consecutive files share shards.
#[test]
fn a_folder_of_one_trace_files_makes_one_file_set() {
    let t = TestRun::new();
    for i in 0..6 {
        let v = annotrace::trace::json::to_value(&synthetic_trace(Env::Pooltool, i, 4, 2));
        t.write(&format!("shots/shot{i}.json"), &v.to_string());
    }
    t.run(&["import", "--run", "r", "--env", "pooltool", "shots"])
        .ok()
        .stdout_has("imported 6 pooltool trace(s)");
    let tables = t.run(&["tables", "--run", "r"]);
    tables
        .ok()
        .stdout_has("traces: 6 rows in 1 file(s)")
        .stdout_has("frames: 48 rows in 1 file(s)");
    assert_eq!(
        t.csv("r", "SELECT trace_id FROM traces ORDER BY trace_id"),
        "trace_id\npooltool-000000\npooltool-000001\npooltool-000002\npooltool-000003\npooltool-000004\npooltool-000005\n"
    );
}
