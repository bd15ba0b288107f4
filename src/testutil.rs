//! Deterministic synthetic traces for tests and benchmarks (not physics: smooth, plausible motion with
//! known numbers, so that tests can compute expected aggregates by hand), and the importer's test oracle
//! ([`import_round_trip`]) shared by the fuzz target `json_import` and the seeded sweep of the test suite.

use serde_json::json;

use crate::trace::{
    Body, Env, Event, IphyreObject, JsonMap, Object, Outcome, PhyreObject, PoolBall, Timestep,
    Trace,
};

/// A trace of `env` with `steps` timesteps of `objects` objects each. Object `k` at step `s` sits at
/// `x = k + s·0.01`, `y = 2k` and moves with `vx = 1`, `vy = 0` (no velocity for I-PHYRE), so `avg(x)` over a trace is
/// `(objects-1)/2 + (steps-1)·0.005` and every speed is 1. Trace `index` succeeds when it is even.
pub fn synthetic_trace(env: Env, index: usize, steps: usize, objects: usize) -> Trace {
    let dt = 0.01;
    let timesteps = (0..steps)
        .map(|s| Timestep {
            index: s as i64,
            t: s as f64 * dt,
            objects: (0..objects).map(|k| object(env, k, s)).collect(),
            extra: JsonMap::new(),
        })
        .collect();
    let events = vec![
        Event {
            kind: "start".into(),
            t: Some(0.0),
            payload: Some(json!({"agents": ["0"]})),
            extra: JsonMap::new(),
        },
        Event {
            kind: "contact_begin".into(),
            t: Some((steps / 2) as f64 * dt),
            payload: Some(json!({"agents": ["0", "1"]})),
            extra: JsonMap::new(),
        },
    ];
    let mut metrics = JsonMap::new();
    metrics.insert("index".into(), json!(index));
    Trace {
        trace_id: format!("{env}-{index:06}"),
        env,
        task_id: format!("task-{:03}", index % 7),
        timesteps,
        events,
        outcome: Outcome {
            success: index.is_multiple_of(2),
            terminal_status: if index.is_multiple_of(2) {
                "success".into()
            } else {
                "timeout".into()
            },
            metrics,
            extra: JsonMap::new(),
        },
        extra: JsonMap::new(),
    }
}

fn object(env: Env, k: usize, s: usize) -> Object {
    let x = k as f64 + s as f64 * 0.01;
    let y = 2.0 * k as f64;
    let body = match env {
        Env::Pooltool => Body::Pool(PoolBall {
            kind: "ball".into(),
            ball_id: if k == 0 {
                "cue".into()
            } else {
                k.to_string().into()
            },
            position: [x, y, 0.028575],
            velocity: [1.0, 0.0, 0.0],
            angular_velocity: [0.0, 35.0, 0.0],
            motion_state_code: 3,
            motion_state: "rolling".into(),
            radius: 0.028575,
        }),
        Env::Phyre => Body::Phyre(PhyreObject {
            object_index: k as i64,
            shape: if k.is_multiple_of(2) {
                "ball".into()
            } else {
                "bar".into()
            },
            color: ["red", "green", "blue", "gray"][k % 4].into(),
            diameter: 10.0,
            x,
            y,
            angle: 0.0,
            vx: 1.0,
            vy: 0.0,
            angular_velocity: 0.0,
            is_user_input: k == 0,
        }),
        Env::Iphyre => Body::Iphyre(IphyreObject {
            index: k as i64,
            x1: x - 5.0,
            y1: y,
            x2: x + 5.0,
            y2: y,
            radius: 10.0,
            eliminable: (k % 2) as f64,
            dynamic: 1.0,
            joint: 0,
            spring: 0,
            angle: None,
            vx: None,
            vy: None,
            angular_velocity: None,
        }),
    };
    Object {
        body,
        extra: JsonMap::new(),
    }
}

/// The JSON importer's contract on any bytes, checked: reading `bytes` as `kind` ends in traces and
/// typed errors (never a panic), and every trace it accepts is storable and exportable without loss —
/// its Arrow rows decode to the same trace, and its export imports to the same trace. Returns the
/// number of traces accepted, or what broke the contract.
pub fn import_round_trip(
    bytes: &[u8],
    kind: crate::trace::json::SourceKind,
    env: Env,
) -> Result<usize, String> {
    use crate::trace::{TraceBatchBuilder, TraceRows, decode_trace, json};
    let mut accepted = 0;
    for result in json::read_bytes("fuzz", bytes, kind, env) {
        let trace = match result {
            Ok(t) => t,
            Err(e) => {
                if e.to_string().is_empty() {
                    return Err(format!("an error without a message: {e:?}"));
                }
                continue;
            }
        };
        accepted += 1;
        if let Some(what) = trace.first_non_finite() {
            return Err(format!("accepted a non-finite value {what:?}"));
        }
        let b = TraceBatchBuilder::from_trace(&trace, "scene", "fuzz")
            .map_err(|e| format!("the trace does not convert to Arrow rows: {e}"))?;
        let rows = TraceRows {
            env,
            trace: &b.traces,
            timesteps: &b.timesteps,
            frames: &b.frames,
            events: &b.events,
        };
        let back = decode_trace(&rows).map_err(|e| format!("its rows do not decode: {e}"))?;
        if back != trace {
            return Err(format!(
                "its rows decode to another trace:\n{back:?}\ninstead of\n{trace:?}"
            ));
        }
        // Read with its balls left as columns, it loads into a worker with the same bytes and
        // rebuilds to the same trace.
        let framed = crate::trace::FramedTrace::decode(&rows)
            .map_err(|e| format!("its rows do not decode as columns: {e}"))?;
        for detectors in [1, 12] {
            if crate::detect::protocol::load_request_framed("k", &framed, detectors)
                != crate::detect::protocol::load_request("k", &trace, detectors)
            {
                return Err(format!(
                    "read as columns, it loads into a worker with other bytes: {trace:?}"
                ));
            }
        }
        if framed.into_trace().ok().as_ref() != Some(&trace) {
            return Err(format!(
                "read as columns, it rebuilds to another trace: {trace:?}"
            ));
        }
        let text = json::to_value(&trace).to_string();
        let again = json::read_str("again", &text, env);
        match again.as_slice() {
            [Ok(t)] if *t == trace => {}
            [Ok(t)] => {
                return Err(format!(
                    "its export imports to another trace:\n{t:?}\ninstead of\n{trace:?}"
                ));
            }
            other => {
                return Err(format!(
                    "its export {text} does not import as one trace: {other:?}"
                ));
            }
        }
    }
    Ok(accepted)
}

/// Asserts that `docs/schema.md`'s section `## <table>` lists exactly `schema`'s columns, in order,
/// followed by the `env` partition column (the check every table-defining module runs on its tables).
#[cfg(test)]
pub(crate) fn assert_documented_columns(table: &str, schema: &arrow::datatypes::Schema) {
    let doc = include_str!("../docs/schema.md");
    let section = doc
        .split(&format!("\n## {table}\n"))
        .nth(1)
        .unwrap_or_else(|| panic!("docs/schema.md has no section {table}"));
    let section = section.split("\n## ").next().unwrap_or_default();
    let documented: Vec<&str> = section
        .lines()
        .filter(|l| l.starts_with("| `"))
        .filter_map(|l| l.split('`').nth(1))
        .collect();
    let mut expected: Vec<String> = schema.fields().iter().map(|f| f.name().clone()).collect();
    expected.push(crate::trace::schema::ENV_COLUMN.to_string());
    assert_eq!(documented, expected, "section {table}");
}
