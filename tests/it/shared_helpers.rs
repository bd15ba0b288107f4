//! Helper results shared between the detectors of one run request (`HelperSharing`, "Helper results
//! shared" in `src/detect/worker.py`). Sharing may change what a call costs, never what it returns:
//! every test compares a detector's replies (patterns, printed text, errors) run among others with
//! sharing on against the same detector run alone with sharing off. The built-in libraries are held
//! to it on the originals' own traces, with and without their event logs; hand-written detectors
//! try what could make a shared result wrong (changing it, rebinding what the helper reads,
//! mutable state, printing, sets, arguments that compare equal but differ).

use std::time::Duration;

use annotrace::detect::{
    CallResult, CandidateStatus, Detector, HelperSharing, Library, Pattern, SandboxLimits,
    WorkerPool,
};
use annotrace::trace::{Env, Trace};
use serde_json::Value;

use crate::originals;

fn pool(share: HelperSharing, workers: usize) -> WorkerPool {
    WorkerPool::new(SandboxLimits {
        workers,
        call_timeout: Duration::from_secs(60),
        share_helpers: share,
        ..SandboxLimits::default()
    })
    .unwrap()
}

/// What a call answered: its status, patterns and printed text (timings left out).
type Reply = (CandidateStatus, Vec<Pattern>, String);

fn reply(r: &CallResult) -> Reply {
    (r.status.clone(), r.patterns.clone(), r.printed.clone())
}

/// Each detector's replies on every trace, all detectors in one request per trace.
fn together(share: HelperSharing, dets: &[Detector], traces: &[Trace]) -> Vec<Vec<Reply>> {
    let run = pool(share, 1).run(dets, traces);
    let mut out = vec![Vec::new(); dets.len()];
    for r in &run.results {
        out[r.detector].push(reply(r));
    }
    out
}

/// Each detector's replies on every trace, run alone with sharing off.
fn alone(dets: &[Detector], traces: &[Trace]) -> Vec<Vec<Reply>> {
    dets.iter()
        .map(|d| together(HelperSharing::Off, std::slice::from_ref(d), traces).remove(0))
        .collect()
}

/// Every reply ran and gave valid output.
fn all_ok(replies: &[Reply], what: &str) {
    assert!(
        replies.iter().all(|r| r.0 == CandidateStatus::Ok),
        "{what}: {replies:?}"
    );
}

fn library(env: Env) -> Library {
    Library::load(
        &crate::common::repo()
            .join("data/libraries")
            .join(env.as_str()),
    )
    .unwrap()
}

#[test]
fn built_in_libraries_answer_alike_with_their_helpers_shared_on_the_originals_traces() {
    for env in [Env::Phyre, Env::Iphyre, Env::Pooltool] {
        let lib = library(env);
        let full = originals::traces(env);
        let take = if env == Env::Pooltool { 8 } else { full.len() };
        let mut traces: Vec<Trace> = full[..take].to_vec();
        // Without the event log, PHYRE's and I-PHYRE's libraries find contacts from geometry:
        // the helper worth sharing.
        traces.extend(originals::blind(&full[..take]));
        let off = together(HelperSharing::Off, &lib.detectors, &traces);
        let always = together(HelperSharing::Always, &lib.detectors, &traces);
        let measured = together(HelperSharing::Measured, &lib.detectors, &traces);
        for (i, d) in lib.detectors.iter().enumerate() {
            all_ok(&off[i], &format!("{env} {}", d.label));
            assert_eq!(always[i], off[i], "{env} {}: shared (always)", d.label);
            assert_eq!(measured[i], off[i], "{env} {}: shared (measured)", d.label);
        }
    }
}

/// The helpers of the hand-written detectors: `_heavy` costs about a tenth of a second, so whether
/// a call computed it shows in its CPU time.
const PRELUDE: &str = r#"
SCALE = 1.0


def out(value):
    return [{"label": "x", "start_timestep": 0, "end_timestep": 0,
             "parameters": {"object_details": {}, "value": value}}]


def _heavy(trace):
    acc = 0
    for i in range(2000000):
        acc = (acc * 31 + i) % 1000003
    steps = trace.get("timesteps", [])
    return {"n": len(steps), "acc": acc, "scaled": [SCALE * s.get("t", 0.0) for s in steps[:5]],
            "nested": [[1, 2], {"k": [3]}], "steps": steps[:2]}


def _inner(trace):
    return 1


def _outer(trace):
    return [_inner(trace), len(trace.get("timesteps", []))]


def _depth(trace):
    def down(n):
        return 0 if n == 0 else 1 + down(n - 1)
    try:
        return down(1500)
    except Exception:
        return -1
"#;

/// A detector of label `x` (its patterns' label); `name` is its source, for messages, and a comment
/// on its first line, so that detectors with the same body are distinct programs.
fn det(name: &str, body: &str) -> Detector {
    Detector::new(
        Env::Phyre,
        "x",
        &format!("# {name}\n{PRELUDE}\n{body}"),
        name,
    )
}

const READER: &str = r#"
def find_pattern(trace):
    h = _heavy(trace)
    return out([h["n"], h["acc"], h["scaled"], h["nested"], len(h["steps"]), sorted(h), _outer(trace)])
"#;

const CHANGER: &str = r#"
def find_pattern(trace):
    h = _heavy(trace)
    h["n"] = -1
    h["scaled"].append(99.0)
    h["nested"][0].append(7)
    h["nested"][1]["k"].clear()
    h["new"] = True
    h2 = _heavy(trace)
    return out([h2["n"], h2["nested"], h["n"]])
"#;

fn traces() -> Vec<Trace> {
    vec![
        crate::common::example_trace(Env::Phyre),
        originals::traces(Env::Phyre)[0].clone(),
    ]
}

#[test]
fn a_detector_that_changes_a_shared_result_changes_only_its_own_copy() {
    let dets = [
        det("changer", CHANGER),
        det("reader", READER),
        det("changer again", CHANGER),
        det("reader again", READER),
    ];
    let traces = traces();
    let shared = pool(HelperSharing::Always, 1).run(&dets, &traces);
    let mut got = vec![Vec::new(); dets.len()];
    for r in &shared.results {
        got[r.detector].push(reply(r));
    }
    assert_eq!(got, alone(&dets, &traces));
    // It was shared: the first caller computed `_heavy`, the later ones were handed copies.
    for t in 0..traces.len() {
        let cpu = |d: usize| {
            shared
                .results
                .iter()
                .find(|r| r.detector == d && r.trace == t)
                .unwrap()
                .cpu_s
        };
        assert!(
            cpu(0) > 0.05,
            "the first call computes the helper: {}",
            cpu(0)
        );
        for d in 1..dets.len() {
            assert!(
                cpu(d) < cpu(0) / 5.0,
                "detector {d} on trace {t} computed the helper again: {} against {}",
                cpu(d),
                cpu(0)
            );
        }
    }
}

#[test]
fn helpers_whose_results_may_differ_between_detectors_are_not_shared() {
    // Each case: code placed after the prelude, and what its detector reports besides `_heavy`'s
    // scaled times and `_outer`'s answer (TRACE holds the trace for the functions without one).
    let cases = [
        // A constant the helper reads, rebound after the prelude.
        ("rebinds SCALE", "SCALE = 2.0\n", "0"),
        // The same `_outer` code, calling a different `_inner`.
        ("own inner", "def _inner(trace):\n    return 5\n", "0"),
        // Mutable module state the helper reads, changed between calls.
        (
            "reads a list",
            "EXTRA = [1.0]\n\n\ndef _sum(trace):\n    return sum(EXTRA) + len(trace)\n",
            "EXTRA.append(2.0) or _sum(TRACE[0])",
        ),
        // A function attribute set anywhere: no helper of the detector is shared.
        ("attribute", "out.tag = 3\n", "out.tag"),
        // `global` anywhere: likewise.
        (
            "global",
            "def _g():\n    global SCALE\n    SCALE = 3.0\n",
            "_g() or SCALE",
        ),
        // A mutable default.
        (
            "default",
            "def _d(trace, acc=[]):\n    acc.append(1)\n    return len(acc)\n",
            "[_d(TRACE[0]), _d(TRACE[0])]",
        ),
        // A helper that catches what the depth of its call can raise: called deep down first, then
        // from the top (the recursion limit is 2,000 frames).
        (
            "deep caller",
            "def _dive(n):\n    return _depth(TRACE[0]) if n == 0 else _dive(n - 1)\n",
            "_dive(800)",
        ),
        ("shallow caller", "", "_depth(TRACE[0])"),
    ];
    let mut dets = vec![det("base", READER)];
    for (name, code, extra) in cases {
        dets.push(det(
            name,
            &format!(
                "TRACE = [None]\n{code}\n\ndef find_pattern(trace):\n    TRACE[0] = trace\n    \
                 return out([_heavy(trace)[\"scaled\"], _outer(trace), {extra}])\n"
            ),
        ));
    }
    dets.push(det("base again", READER));
    let traces = traces();
    let got = together(HelperSharing::Always, &dets, &traces);
    let want = alone(&dets, &traces);
    for (i, d) in dets.iter().enumerate() {
        all_ok(&want[i], &d.source);
        assert_eq!(got[i], want[i], "{}", d.source);
    }
    // What sharing by name or by code alone would have got wrong is really different here.
    let value = |i: usize, t: usize| want[i][t].1[0].parameters["value"].clone();
    for t in 0..traces.len() {
        let base = value(0, t);
        let scaled = |v: &Value, at: usize| v[at].as_array().unwrap().clone();
        let twice: Vec<f64> = scaled(&base, 2)
            .iter()
            .map(|x| 2.0 * x.as_f64().unwrap())
            .collect();
        let rebound: Vec<f64> = scaled(&value(1, t), 0)
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(rebound, twice);
        assert!(twice.iter().any(|x| *x != 0.0));
        assert_eq!(base[6][0], 1);
        assert_eq!(value(2, t)[1][0], 5);
        assert_eq!(value(7, t)[2], -1);
        assert_eq!(value(8, t)[2], 1500);
    }
}

#[test]
fn printing_sets_errors_and_arguments_that_compare_equal_keep_their_own_answers() {
    let code = r#"
def _loud(trace):
    print("computing for", len(trace.get("timesteps", [])))
    return 1


def _set(trace):
    return {"b%d" % i for i in range(40)} | {"a", "z"}


def _fails(trace):
    return trace["no such key"]


def _echo(trace, x, *rest, **kw):
    return [repr(x), repr(rest), sorted(kw.items())]


def find_pattern(trace):
    got = [_loud(trace), list(_set(trace))]
    got.append([_echo(trace, v) for v in (1, 1.0, True, 0.0, -0.0, "1", (1,), (1.0,), max, min)])
    got.append(_echo(trace, 1, 2, k=(0.0,)))
    got.append(_echo(trace, 1, 2, k=(-0.0,)))
    got.append(_echo(trace, [1]))
    # Calls that cannot be shared, past the point where the detector calls the helper directly.
    got.append([_echo(trace, [i])[0] for i in range(150)][-1])
    got.append([_echo({"timesteps": ()}, i)[0] for i in range(150)][-1])
    got.append(_echo(trace, 2.5))
    try:
        _fails(trace)
    except KeyError as e:
        got.append("KeyError %s" % e)
    return out(got)
"#;
    let failing = "def find_pattern(trace):\n    _heavy(trace)\n    return _fails(trace)\n\n\ndef _fails(trace):\n    return trace[\"missing\"]\n";
    let dets = [
        det("one", code),
        det("two", code),
        det("fails", failing),
        det("fails too", failing),
        det("three", code),
    ];
    let traces = traces();
    let got = together(HelperSharing::Always, &dets, &traces);
    let want = alone(&dets, &traces);
    assert_eq!(got, want);
    assert!(want[0][0].2.contains("computing for"), "{:?}", want[0][0]);
    assert_eq!(want[2][0].0.as_str(), "runtime", "{:?}", want[2][0]);
}
