//! Deterministic synthetic traces for tests and benchmarks (not physics: smooth, plausible motion with
//! known numbers, so that tests can compute expected aggregates by hand).

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
            ball_id: if k == 0 { "cue".into() } else { k.to_string() },
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
