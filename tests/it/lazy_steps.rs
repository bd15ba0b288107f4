//! The worker builds a pooltool step's `objects` only when a detector first reads them
//! (`LazyStep` in `src/detect/worker.py`). These tests hold it to the eager build's semantics: every
//! way Python code can read a step gives the same answer on fresh (unbuilt) steps as on built ones,
//! in any order of first reads; unchanged balls are the same dict in consecutive steps exactly when
//! their state repeats; and code that can reach `dict`'s methods unbound sees every step built.

use annotrace::detect::{CandidateStatus, Detector, SandboxLimits, WorkerPool};
use annotrace::envs::pool::{PoolConfig, TraceOptions, dataset_trace};
use annotrace::trace::{Env, Trace};
use serde_json::Value;

/// Helpers the access-path detectors share: `plain` turns a value into JSON that keeps what JSON
/// would lose (dict or read-only dict, tuple or list, key order), `catch` records an exception.
const HELPERS: &str = r#"
def plain(v):
    if isinstance(v, dict):
        kind = "dict"
        try:
            v.update({})
        except TypeError:
            kind = "frozen"
        return [kind, [[plain(k), plain(x)] for k, x in v.items()]]
    if isinstance(v, tuple):
        return ["tuple", [plain(x) for x in v]]
    if isinstance(v, list):
        return ["list", [plain(x) for x in v]]
    if isinstance(v, (set, frozenset)):
        return ["set", sorted(repr(x) for x in v)]
    return v


def catch(f):
    try:
        return ["ok", plain(f())]
    except KeyError as e:
        return ["KeyError", str(e)]
    except TypeError as e:
        return ["TypeError", str(e)]
    except Exception as e:
        return ["Exception", str(e)]


def walk(v):
    if isinstance(v, dict):
        return {str(k): walk(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [walk(x) for x in v]
    return v


def setitem(s):
    s["x"] = 1


def delitem(s):
    del s["t"]


def ior(s):
    s |= {}


def kwargs(**kw):
    return kw


def part(s):
    return {k: s[k] for k in ("index", "t")}


# Each path's first operation is what meets a fresh step; the rest meet it built.
PATHS = [
    lambda s, n: s["objects"],
    lambda s, n: s.get("objects"),
    lambda s, n: s.get("objects", 7),
    lambda s, n: ["objects" in s, "t" in s, "zz" in s, len(s), bool(s), s["objects"]],
    lambda s, n: len(s),
    lambda s, n: [bool(s), s.get("t"), s["index"]],
    lambda s, n: list(s.keys()),
    lambda s, n: list(s.values()),
    lambda s, n: list(s.items()),
    lambda s, n: [k for k in s],
    lambda s, n: repr(s),
    lambda s, n: str(s),
    lambda s, n: f"{s}" + "%s" % (s,) + format(s),
    lambda s, n: dict(s),
    lambda s, n: {**s},
    lambda s, n: kwargs(**s),
    lambda s, n: s.copy(),
    lambda s, n: sorted(s),
    lambda s, n: walk(s),
    lambda s, n: list(reversed(s)),
    lambda s, n: {} | s,
    lambda s, n: s | {},
    lambda s, n: s | n,
    lambda s, n: s == part(s),
    lambda s, n: s != part(s),
    lambda s, n: part(s) == s,
    lambda s, n: part(s) != s,
    lambda s, n: [s == n, s != n, n == s, n != s, s == s, s == dict(n)],
    lambda s, n: [isinstance(s, dict), sorted(set(s)), max(s), list(enumerate(s)), ",".join(s), any(s)],
    lambda s, n: tuple(s),
    lambda s, n: max(s),
    lambda s, n: [catch(lambda: s.fromkeys([])), catch(lambda: s.fromkeys(["a"]))],
    lambda s, n: [catch(lambda: s.update({})), catch(lambda: s.pop("objects")),
                  catch(lambda: s.setdefault("objects", 1)), catch(lambda: s.clear()),
                  catch(lambda: s.popitem()), catch(lambda: setitem(s)), catch(lambda: delitem(s)),
                  catch(lambda: ior(s)), s["objects"]],
    lambda s, n: [catch(lambda: s["nope"]), s.get("nope", 5), s.get("t"), s["index"],
                  catch(lambda: hash(s)), catch(lambda: s < n), catch(lambda: s + 1)],
    lambda s, n: "{0[objects]}".format(s),
    lambda s, n: "{objects}".format(**s),
    lambda s, n: "%(objects)s" % s,
    lambda s, n: list(zip(s, s.values())),
    lambda s, n: [s.items() == n.items(), list(s.values()) == list(n.values()), s.keys() == n.keys()],
    lambda s, n: [{}.fromkeys(s), list(map(s.get, ["t", "objects", "index"]))],
]


def out(label, value):
    return [{"label": label, "start_timestep": 0, "end_timestep": 0,
             "parameters": {"object_details": {}, "value": value}}]
"#;

/// First reads by every path, each step's by path `k % len(PATHS)`, in an order that is neither
/// forwards nor backwards; then every step again through the next path, now built.
const PATHS_DETECTOR: &str = r#"
def find_pattern(trace):
    steps = trace["timesteps"]
    m = len(steps)
    order = sorted(range(m), key=lambda k: (k * 7919) % m)
    first = {}
    for k in order:
        first[k] = plain(PATHS[k % len(PATHS)](steps[k], steps[(k + 1) % m]))
    again = [plain(PATHS[(k + 1) % len(PATHS)](steps[k], steps[(k + 1) % m])) for k in range(m)]
    return out("paths", [[first[k] for k in range(m)], again, plain(trace)])
"#;

/// Reads the objects from the last step to the first, then reports which of them are shared with
/// the step before: the tuple, and each slot's dict.
const SHARING_DETECTOR: &str = r#"
def find_pattern(trace):
    steps = trace["timesteps"]
    for k in range(len(steps) - 1, -1, -1):
        steps[k]["objects"]
    shared = []
    for k in range(1, len(steps)):
        a, b = steps[k - 1]["objects"], steps[k]["objects"]
        shared.append([a is b, [x is y for x, y in zip(a, b)] if len(a) == len(b) else None])
    return out("sharing", shared)
"#;

/// Every way this code might reach `dict` itself, each of which must see the step built (the
/// detector is then run with every step built): each returns what it found for `objects`.
const UNBOUND_DETECTOR: &str = r#"
def via_param(isinstance, s):
    return isinstance(s, dict)


def find_pattern(trace):
    steps = trace["timesteps"]
    g = dict
    found = [
        dict.get(steps[1], "objects"),
        g.get(steps[2], "objects"),
        [d.get(steps[3], "objects") for d in (dict,)][0],
        via_param(lambda a, b: b.get(a, "objects"), steps[4]),
        list(dict.values(steps[5]))[2],
        dict.copy(steps[6])["objects"],
        [v for k, v in dict.items(steps[7]) if k == "objects"][0],
        "objects" in list(dict.keys(steps[8])),
    ]
    same = [f is steps[i + 1]["objects"] for i, f in enumerate(found[:7])] + [found[7]]
    return out("unbound", same)
"#;

/// The name `isinstance` bound in the code: its `isinstance(s, dict)` may hand `dict` to code.
const REBOUND_DETECTOR: &str = r#"
def find_pattern(trace):
    steps = trace["timesteps"]
    isinstance = lambda a, b: b.get(a, "objects")
    return out("rebound", [isinstance(steps[3], dict) is steps[3]["objects"]])
"#;

fn det(label: &str, code: &str) -> Detector {
    Detector::new(Env::Pooltool, label, &format!("{HELPERS}\n{code}"), "test")
}

fn pool() -> WorkerPool {
    WorkerPool::new(SandboxLimits {
        workers: 1,
        ..SandboxLimits::default()
    })
    .unwrap()
}

/// Simulated shots at dt 0.05 s; one with extra step fields; one whose object count changes
/// (every object new at the change); the PHYRE and I-PHYRE examples (sent as JSON, built eagerly).
fn traces() -> Vec<Trace> {
    let config = PoolConfig::default_7ft();
    let shot = |i: u64| dataset_trace(&config, 3, i, &TraceOptions { dt: 0.05 }).unwrap();
    // A shot ends when the last ball stops: two more steps where nothing moves, so that whole
    // steps repeat (their objects are one tuple).
    let mut resting = shot(0);
    for _ in 0..2 {
        let mut last = resting.timesteps.last().unwrap().clone();
        last.index += 1;
        last.t += 0.05;
        resting.timesteps.push(last);
    }
    let mut out = vec![resting, shot(1)];
    let mut extra = shot(2);
    extra.trace_id = "extra".into();
    for (k, ts) in extra.timesteps.iter_mut().enumerate() {
        if k % 3 == 1 {
            ts.extra
                .insert("note".into(), serde_json::json!({"k": [k, "x"]}));
            ts.extra.insert("z".into(), serde_json::json!(k));
        }
    }
    out.push(extra);
    let mut fewer = shot(3);
    fewer.trace_id = "fewer".into();
    let half = fewer.timesteps.len() / 2;
    for ts in &mut fewer.timesteps[half..] {
        ts.objects.pop();
    }
    out.push(fewer);
    out.push(crate::common::example_trace(Env::Phyre));
    out.push(crate::common::example_trace(Env::Iphyre));
    out
}

/// Each trace's `value` from one detector run alone on fresh workers (steps built when read).
fn values(d: &Detector, traces: &[Trace]) -> Vec<Value> {
    values_among(d, 0, traces)
}

/// Each trace's `value` from a detector run on fresh workers first among `others` more detectors
/// that read nothing; from `LAZY_BELOW` (6) detectors on, traces arrive built whole.
fn values_among(d: &Detector, others: usize, traces: &[Trace]) -> Vec<Value> {
    let mut batch: Vec<Detector> = vec![d.clone()];
    for i in 0..others {
        batch.push(Detector::new(
            Env::Pooltool,
            "other",
            &format!("def find_pattern(trace):\n    return []  # {i}\n"),
            "test",
        ));
    }
    let n = batch.len();
    let run = pool().run(&batch, traces);
    run.results
        .iter()
        .step_by(n)
        .zip(traces)
        .map(|(r, t)| {
            assert_eq!(
                r.status,
                CandidateStatus::Ok,
                "{} on {}: {r:?}",
                d.label,
                t.trace_id
            );
            r.patterns[0].parameters["value"].clone()
        })
        .collect()
}

#[test]
fn every_read_of_a_fresh_step_answers_as_the_built_step() {
    let traces = traces();
    assert!(
        traces[0].timesteps.len() > 2 * 40,
        "enough steps for every path"
    );
    let lazy = values(&det("paths", PATHS_DETECTOR), &traces);
    // The same code naming `dict` itself gets every step built before its call: the eager build.
    let eager = values(
        &det("paths", &format!("{PATHS_DETECTOR}\nEAGER = dict\n")),
        &traces,
    );
    // And traces built whole at load, for a run of many detectors.
    let whole = values_among(&det("paths", PATHS_DETECTOR), 5, &traces);
    for (((l, e), w), t) in lazy.iter().zip(&eager).zip(&whole).zip(&traces) {
        assert!(l == e, "trace {}: lazy and eager reads differ", t.trace_id);
        assert!(l == w, "trace {}: lazy and whole reads differ", t.trace_id);
    }
    // The trace read whole at the end is the paper's dict, key order and all: the objects after
    // `t`, extra step fields after the objects (as the JSON path and Rust write them).
    for (l, t) in lazy.iter().zip(&traces) {
        let steps = pairs(&l[2])
            .iter()
            .find(|p| p[0] == "timesteps")
            .map(|p| p[1][1].as_array().unwrap().clone())
            .unwrap();
        assert_eq!(steps.len(), t.timesteps.len());
        for (s, ts) in steps.iter().zip(&t.timesteps) {
            let keys: Vec<&str> = pairs(s).iter().map(|p| p[0].as_str().unwrap()).collect();
            let mut want = vec!["index", "t", "objects"];
            want.extend(ts.extra.keys().map(String::as_str));
            if t.env == Env::Pooltool {
                assert_eq!(keys, want, "trace {}", t.trace_id);
            }
        }
    }
    // Mutation is refused with the message it always had, fresh or built.
    let first = serde_json::to_string(&lazy[0][0]).unwrap();
    assert!(
        first.contains(
            r#"["TypeError","the trace is read-only; copy it first (dict(x), list(x))"]"#
        )
    );
    assert!(
        first.contains(
            r#"["TypeError","unsupported operand type(s) for +: 'FrozenDict' and 'int'"]"#
        )
    );
    assert!(first.contains(
        r#"["TypeError","'<' not supported between instances of 'FrozenDict' and 'FrozenDict'"]"#
    ));
    assert!(first.contains(r#"["TypeError","unhashable type: 'FrozenDict'"]"#));
    assert!(first.contains(r#"["KeyError","'nope'"]"#));
}

/// The (key, value) pairs of a `plain` read-only dict.
fn pairs(v: &Value) -> &Vec<Value> {
    assert_eq!(v[0], "frozen", "{v}");
    v[1].as_array().unwrap()
}

/// Whether two objects of a step are the same state (what the columns path compares bit for bit).
fn same(a: &annotrace::trace::Object, b: &annotrace::trace::Object) -> bool {
    format!("{a:?}") == format!("{b:?}")
}

#[test]
fn an_unchanged_ball_is_the_same_dict_in_consecutive_steps_whatever_was_read_first() {
    let traces: Vec<Trace> = traces()
        .into_iter()
        .filter(|t| t.env == Env::Pooltool)
        .collect();
    let got = values(&det("sharing", SHARING_DETECTOR), &traces);
    let eager = values(
        &det("sharing", &format!("{SHARING_DETECTOR}\nEAGER = dict\n")),
        &traces,
    );
    assert_eq!(got, eager);
    assert_eq!(
        got,
        values_among(&det("sharing", SHARING_DETECTOR), 5, &traces)
    );
    for (g, t) in got.iter().zip(&traces) {
        let want: Vec<Value> = t
            .timesteps
            .windows(2)
            .map(|w| {
                let (a, b) = (&w[0].objects, &w[1].objects);
                if a.len() != b.len() {
                    return serde_json::json!([false, null]);
                }
                let slots: Vec<bool> = a.iter().zip(b).map(|(x, y)| same(x, y)).collect();
                serde_json::json!([slots.iter().all(|&s| s), slots])
            })
            .collect();
        assert_eq!(g, &Value::Array(want), "trace {}", t.trace_id);
        let shared_slots = g
            .as_array()
            .unwrap()
            .iter()
            .filter(|p| {
                p[1].as_array()
                    .is_some_and(|s| s.contains(&Value::Bool(true)))
            })
            .count();
        assert!(shared_slots > 0, "some balls repeat in {}", t.trace_id);
    }
    assert!(
        repeats(&got[0]) >= 2,
        "the resting steps share their objects"
    );
}

fn repeats(v: &Value) -> usize {
    v.as_array()
        .unwrap()
        .iter()
        .filter(|p| p[0] == Value::Bool(true))
        .count()
}

#[test]
fn code_that_can_reach_dict_itself_sees_every_step_built() {
    let traces: Vec<Trace> = traces()
        .into_iter()
        .filter(|t| t.env == Env::Pooltool)
        .collect();
    for v in values(&det("unbound", UNBOUND_DETECTOR), &traces) {
        assert_eq!(v, serde_json::json!(vec![true; 8]));
    }
    for v in values(&det("rebound", REBOUND_DETECTOR), &traces) {
        assert_eq!(v, serde_json::json!([true]));
    }
}
