//! The `suggest-labels` stage (and `annotrace suggest-labels` on a run with traces) against the local
//! scripted chat server: example traces shown as initial images and annotated text, a malformed answer
//! repaired, every call in `llm_calls`, replay into a fresh run reproducing the `suggested_labels`
//! table byte for byte; the offline baseline; and the pipeline suggest-labels → evolve (offline mutate
//! proposer, tiny budget, empty start) → benchmark with the evolved library as annotation feedback.

use serde_json::Value;

use crate::common::TestRun;
use crate::common::chat_server::{ChatServer, Reply, Seen};

const GOOD: &str = "<think>Three kinds of event stand out.</think>\n```json\n[\n {\"label\": \"long rail run\", \"description\": \"A ball rolls along a cushion for a while.\", \"objects\": [\"ball\", \"cushion\"], \"reason\": \"Position play.\"},\n {\"label\": \"stop shot\", \"description\": \"The cue ball stops dead at its first contact.\", \"objects\": [\"cue ball\"], \"reason\": \"Shows spin use.\"},\n {\"label\": \"ball cluster break\", \"description\": \"Several touching balls start moving at once.\", \"objects\": [\"ball\"], \"reason\": \"Opens the table.\"}\n]\n```";

/// The text parts of a message and its number of PNG images.
fn parts(m: &Value) -> (String, usize) {
    match &m["content"] {
        Value::String(t) => (t.clone(), 0),
        Value::Array(p) => (
            p.iter()
                .filter_map(|p| p["text"].as_str())
                .collect::<Vec<_>>()
                .join("\n"),
            p.iter()
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

fn messages(s: &Seen) -> Vec<Value> {
    s.body["messages"].as_array().unwrap().clone()
}

/// First a bullet list (malformed), then a valid array.
fn repairing_server() -> ChatServer {
    ChatServer::responder(|s| {
        if messages(s).len() == 1 {
            Reply::chat("- long rail run: a ball hugs the cushion\n- stop shot")
        } else {
            Reply::chat(GOOD)
        }
    })
}

fn simulate(t: &TestRun, run: &str) {
    t.run(&[
        "simulate", "--env", "pooltool", "--scenes", "6", "--shots", "1", "--seed", "5", "--dt",
        "0.1", "--run", run,
    ])
    .ok();
}

fn table_files(t: &TestRun, run: &str) -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<(String, Vec<u8>)> = t
        .files(&format!("{run}/suggested_labels"))
        .into_iter()
        .map(|f| {
            let b = std::fs::read(t.path(&format!("{run}/suggested_labels/{f}"))).unwrap();
            (f, b)
        })
        .collect();
    out.sort();
    out
}

#[test]
fn a_malformed_answer_is_repaired_recorded_and_replayed_byte_for_byte() {
    let server = repairing_server();
    let t = TestRun::new();
    simulate(&t, "run");
    let url = server.url();
    let args = [
        "suggest-labels",
        "--run",
        "run",
        "--env",
        "pooltool",
        "-k",
        "3",
        "--examples",
        "2",
        "--seed",
        "3",
        "--image-size",
        "128",
        "--llm-model",
        "vlm",
        "--llm-retries",
        "0",
    ];
    let mut first = args.to_vec();
    first.extend(["--llm-base-url", &url]);
    t.run(&first)
        .ok()
        .stdout_has("1. long rail run — A ball rolls along a cushion for a while.")
        .stdout_has("   objects: ball, cushion")
        .stdout_has("3. ball cluster break")
        .stderr_has("3 of 3 label(s) from vlm (2 answer(s)")
        .stderr_has("# repaired: answer 1: no JSON array");
    let seen = server.seen();
    assert_eq!(seen.len(), 2, "one answer, one repair");
    // The first request: two examples, each an initial image and its annotated trace.
    let m = messages(&seen[0]);
    let (text, images) = parts(&m[0]);
    assert_eq!(images, 2);
    assert!(
        text.contains("Example 2 (image: example 2: initial scene)"),
        "{text}"
    );
    assert!(text.contains("patterns (steps, time, label"), "{text}");
    assert!(text.contains("- cushion rebound (also:"), "{text}");
    assert!(text.contains("Propose exactly 3 patterns."), "{text}");
    // The repair: the answer back as the assistant's, then the problems.
    let m = messages(&seen[1]);
    assert_eq!(m.len(), 3);
    assert_eq!(m[1]["role"], "assistant");
    let (repair, _) = parts(&m[2]);
    assert!(
        repair.contains("no JSON array of patterns found"),
        "{repair}"
    );
    let calls = t.csv(
        "run",
        "SELECT purpose, status FROM llm_calls ORDER BY started_at",
    );
    assert_eq!(
        calls, "purpose,status\nsuggest_labels_examples,ok\nsuggest_labels_examples,ok\n",
        "{calls}"
    );
    let rows = t.csv(
        "run",
        "SELECT rank, label, objects, source, origin, model, k, problems LIKE '%no JSON array%' AS repaired FROM suggested_labels ORDER BY rank",
    );
    assert_eq!(
        rows,
        "rank,label,objects,source,origin,model,k,repaired\n\
         1,long rail run,\"[\"\"ball\"\",\"\"cushion\"\"]\",llm,llm,vlm,3,true\n\
         2,stop shot,\"[\"\"cue ball\"\"]\",llm,llm,vlm,3,true\n\
         3,ball cluster break,\"[\"\"ball\"\"]\",llm,llm,vlm,3,true\n",
        "{rows}"
    );
    // Replay into a fresh run with the same traces: no endpoint, the same table file, byte for byte.
    simulate(&t, "again");
    let mut replay: Vec<&str> = args.to_vec();
    replay[2] = "again";
    replay.extend(["--replay", "run"]);
    t.run(&replay).ok().stdout_has("1. long rail run");
    assert_eq!(server.seen().len(), 2, "the replay asked the endpoint");
    let all = "SELECT * FROM suggested_labels ORDER BY rank";
    assert_eq!(t.csv("run", all), t.csv("again", all));
    let (a, b) = (table_files(&t, "run"), table_files(&t, "again"));
    assert_eq!(a.len(), 1);
    assert_eq!(a[0].0, b[0].0);
    assert!(a[0].1 == b[0].1, "the replayed table's bytes differ");
}

#[test]
fn unusable_answers_fail_with_exit_1_and_the_offline_baseline_needs_no_model() {
    let server = ChatServer::responder(|_| Reply::chat("I would rather not."));
    let t = TestRun::new();
    simulate(&t, "run");
    let url = server.url();
    t.run(&[
        "suggest-labels",
        "--run",
        "run",
        "--env",
        "pooltool",
        "-k",
        "2",
        "--examples",
        "1",
        "--max-repairs",
        "1",
        "--image-size",
        "64",
        "--llm-model",
        "vlm",
        "--llm-retries",
        "0",
        "--llm-base-url",
        &url,
    ])
    .code(1)
    .stderr_has("no usable label in 2 answer(s)");
    assert_eq!(server.seen().len(), 2);
    // The offline baseline: every built-in label is in the library, so pairs mined from the examples.
    let r = t.run(&[
        "suggest-labels",
        "--run",
        "run",
        "--env",
        "pooltool",
        "-k",
        "4",
        "--examples",
        "4",
        "--offline",
        "--json",
    ]);
    r.ok()
        .stderr_has("from the offline baseline after 4 pooltool example trace(s)");
    let lines: Vec<Value> = r
        .stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(!lines.is_empty() && lines.len() <= 4, "{}", r.stdout);
    for l in &lines {
        assert_eq!(l["source"], "mined", "{l}");
        assert!(l["label"].as_str().unwrap().contains(" then "), "{l}");
    }
    // Whole-library mode: the built-in labels come first.
    let r = t.run(&[
        "suggest-labels",
        "--run",
        "run",
        "--env",
        "pooltool",
        "-k",
        "2",
        "--offline",
        "--whole-library",
    ]);
    r.ok()
        .stdout_has("1. cue strike")
        .stdout_has("2. ball collision");
}

#[test]
fn suggested_labels_evolve_into_a_library_the_benchmark_uses() {
    let server = ChatServer::responder(|_| Reply::chat(GOOD));
    let t = TestRun::new();
    let pipeline = format!(
        r#"[pipeline]
name = "llm-labels"
seed = 4

[[stage]]
id = "simulate"
kind = "simulate"
env = "pooltool"
scenes = 12
shots = 1
seed = 4
dt = 0.1

[[stage]]
id = "suggest"
kind = "suggest-labels"
inputs = ["simulate"]
env = "pooltool"
k = 3
examples = 2
new_only = false
image_size = 64
workers = 1
llm = {{ base_url = "{}", model = "vlm", max_retries = 0 }}

[[stage]]
id = "evolve_llm"
kind = "evolve"
inputs = ["suggest"]
env = "pooltool"
labels_from = "suggest"
start_empty = true
proposer = "mutate"
budget = 2
parallel = 2
max_traces = 8
holdout = 0.0
delta = -100.0
allow_nonpositive_rho = true
time_penalty = false
convergence_per_bin = 0
workers = 1

[[stage]]
id = "benchmark_llm_labels"
kind = "benchmark"
inputs = ["evolve_llm"]
env = "pooltool"
tasks = 1
seeds = 1
attempts = 2
agent = "random"
feedback = "annotations"
library_from = "evolve_llm"
workers = 1
"#,
        server.url()
    );
    t.write("p.toml", &pipeline);
    t.run(&["run", "p.toml", "--run-dir", "out"]).ok();
    assert_eq!(server.seen().len(), 1);
    let labels = t.csv(
        "out",
        "SELECT label, acceptance FROM evolution_labels ORDER BY label_index",
    );
    assert_eq!(
        labels,
        "label,acceptance\nlong rail run,accepted\nstop shot,accepted\nball cluster break,accepted\n",
        "{labels}"
    );
    let lib =
        std::fs::read_to_string(t.path("out/exports/evolve_llm/library/library.toml")).unwrap();
    assert!(lib.contains("name = \"pooltool-evolve_llm\""), "{lib}");
    assert!(
        !lib.contains("cue strike"),
        "an empty start keeps no built-in label: {lib}"
    );
    let bench = t.csv(
        "out",
        "SELECT DISTINCT library, patterns, feedback FROM benchmark",
    );
    assert_eq!(
        bench, "library,patterns,feedback\npooltool-evolve_llm,3,annotations\n",
        "{bench}"
    );
    // A library_from that is not an input is the pipeline's error, at its line.
    t.write(
        "bad.toml",
        &pipeline.replace("inputs = [\"evolve_llm\"]", "inputs = [\"simulate\"]"),
    );
    t.run(&["run", "bad.toml", "--run-dir", "out2"])
        .code(2)
        .stderr_has("must be one of the stage's inputs");
}
