//! A finished [`Simulation`] as an annotrace [`Trace`] in the paper's PoolTool layout.
//!
//! * **Timesteps** lie on pooltool's `continuize` grid, t = 0, dt, 2·dt, … plus the time of the last
//!   event ([`resample`](super::resample)); every ball's state at each of them is evaluated from the closed-form
//!   motion after the latest event, not re-simulated. Every ball appears at every step
//!   (pocketed balls with `motion_state = "pocketed"`), as `kind, ball_id, position, velocity,
//!   angular_velocity, motion_state_code, motion_state, radius`.
//! * **Events** are `shot_prepared` (t = 0, the shot), then one `physics_<kind>` per simulated event
//!   (pooltool's kinds: `physics_stick_ball`, `physics_ball_ball`, `physics_ball_linear_cushion`,
//!   `physics_ball_circular_cushion`, `physics_ball_pocket`, `physics_sliding_rolling`,
//!   `physics_rolling_spinning`, `physics_rolling_stationary`, `physics_spinning_stationary`), then
//!   `shot_outcome` (t = end). Each payload has `agents` in pooltool's `ids` order (`"cue_stick"`, ball
//!   ids, cushion ids like `"12"` or `"8t"`, pocket ids like `"rt"`) plus the event's details.
//! * **Outcome**: see [`outcome`].

use serde_json::{Value, json};

use super::config::PoolConfig;
use super::events::{Agent, EventKind};
use super::rack;
use super::sample::{Cursor, sample_times};
use super::scene::Scene;
use super::shot::Shot;
use super::simulate::{SimOptions, Simulation, Status, simulate};
use crate::trace::frames::PoolFrames;
use crate::trace::{Event, JsonMap, Outcome, Trace, TraceColumns, json_map};

/// Options of the conversion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceOptions {
    /// Spacing of the timesteps (s). Default 0.01 s, the dt of pooltool's reference traces
    /// (`tools/pooltool/gen_traces.py`): a 5 s shot gives about 500 timesteps.
    pub dt: f64,
}

impl Default for TraceOptions {
    fn default() -> Self {
        TraceOptions { dt: 0.01 }
    }
}

/// The event-kind string of the trace format: `physics_` + pooltool's name.
pub fn event_kind_name(kind: EventKind) -> String {
    format!("physics_{}", kind.name())
}

fn shot_json(shot: &Shot) -> Value {
    json!({"V0": shot.v0, "phi": shot.phi, "theta": shot.theta, "a": shot.a, "b": shot.b})
}

/// Trace `pool-{seed}-{index:06}-000` of a random 9-ball dataset: scene `index` and its first shot as
/// `annotrace simulate --seed SEED` draws them, simulated with the default options (benches and tests
/// that need the CLI's traces without a run folder).
pub fn dataset_trace(
    config: &PoolConfig,
    seed: u64,
    index: u64,
    opts: &TraceOptions,
) -> super::Result<Trace> {
    let mut scene = Scene::nine_ball(config, rack::scene_seed(seed, index));
    scene.scene_id = format!("pool-{seed}-{index:06}");
    let shot = rack::dataset_shot(&scene, &mut rack::shot_rng(seed, index, 0));
    let sim = simulate(&scene.system(config)?, &shot, &SimOptions::default())?;
    let id = format!("{}-000", scene.scene_id);
    Ok(trace_of(&sim, &scene, &shot, &id, opts))
}

/// The names of the motion-state codes 0..=4, as the trace format spells them.
pub const STATE_NAMES: [&str; 5] = ["stationary", "spinning", "sliding", "rolling", "pocketed"];

/// The trace of `sim`, which simulated `shot` on `scene`. `trace_id` names it; `task_id` is the scene id.
/// The paper-layout form of [`trace_columns`].
pub fn trace_of(
    sim: &Simulation,
    scene: &Scene,
    shot: &Shot,
    trace_id: &str,
    opts: &TraceOptions,
) -> Trace {
    trace_columns(sim, scene, shot, trace_id, opts).into_trace()
}

/// The trace of `sim` with its frames in columns (what the `simulate` stage writes): every ball's
/// state on the resampling grid goes straight into column vectors.
pub fn trace_columns(
    sim: &Simulation,
    scene: &Scene,
    shot: &Shot,
    trace_id: &str,
    opts: &TraceOptions,
) -> TraceColumns {
    let mut times = sample_times(sim.t_end, opts.dt);
    // The final sample is the last event's time; drop it when it repeats the grid (t_end = k·dt, or
    // a shot without events), so that times stay strictly increasing.
    times.dedup_by(|later, earlier| *later <= *earlier);
    let mut frames = PoolFrames::new(
        sim.ball_ids.clone(),
        sim.ball_params.iter().map(|p| p.r).collect(),
        &STATE_NAMES,
        times.len(),
    );
    // Step by step, every ball's state straight into the columns (no `Sample` per time).
    let mut cursors: Vec<Cursor<'_>> = (0..sim.ball_ids.len())
        .map(|b| Cursor::new(sim, b))
        .collect();
    for (index, &t) in times.iter().enumerate() {
        frames.begin_step(index as i64, t);
        for (b, cursor) in cursors.iter_mut().enumerate() {
            let s = cursor.state_at(t);
            frames.ball(b, &s.r, &s.v, &s.w, s.s.as_int());
        }
    }
    let (events, outcome) = events_and_outcome(sim, scene, shot, opts.dt);
    TraceColumns {
        trace_id: trace_id.to_string(),
        task_id: scene.scene_id.clone(),
        frames: frames.into(),
        events,
        outcome,
        extra: JsonMap::new(),
    }
}

/// The event log (`shot_prepared`, the physics events, `shot_outcome`) and the outcome of a shot.
fn events_and_outcome(
    sim: &Simulation,
    scene: &Scene,
    shot: &Shot,
    dt: f64,
) -> (Vec<Event>, Outcome) {
    let out = outcome(sim, scene, shot, dt);
    let mut events = Vec::with_capacity(sim.events.len() + 2);
    let mut prepared =
        json!({"agents": [scene.cue_ball], "cue_ball": scene.cue_ball, "goal": scene.goal});
    prepared["shot"] = shot_json(shot);
    events.push(Event {
        kind: "shot_prepared".into(),
        t: Some(0.0),
        payload: Some(prepared),
        extra: JsonMap::new(),
    });
    for e in &sim.events {
        let ids: Vec<&str> = sim.event_ids(e);
        let mut payload = json!({"agents": ids});
        match (e.kind, e.agents()) {
            (EventKind::StickBall, _) => {
                payload["ball"] = json!(ids[1]);
                if let Value::Object(s) = shot_json(shot) {
                    payload.as_object_mut().expect("an object").extend(s);
                }
            }
            (EventKind::BallBall, _) => {
                let (a, b) = (&e.balls[0], &e.balls[1]);
                let dv = [a.1.v[0] - b.1.v[0], a.1.v[1] - b.1.v[1]];
                let n = [b.1.r[0] - a.1.r[0], b.1.r[1] - a.1.r[1]];
                let nn = (n[0] * n[0] + n[1] * n[1]).sqrt().max(f64::MIN_POSITIVE);
                payload["approach_speed"] = json!((dv[0] * n[0] + dv[1] * n[1]) / nn);
            }
            (EventKind::BallLinearCushion | EventKind::BallCircularCushion, _) => {
                payload["ball"] = json!(ids[0]);
                payload["cushion"] = json!(ids[1]);
                let before = e.balls[0].1.v;
                payload["speed"] = json!((before[0] * before[0] + before[1] * before[1]).sqrt());
            }
            (EventKind::BallPocket, _) => {
                payload["ball"] = json!(ids[0]);
                payload["pocket"] = json!(ids[1]);
            }
            (_, [Agent::Ball(_), ..]) => {
                payload["ball"] = json!(ids[0]);
                if let Some((_, before, after)) = e.balls.first() {
                    payload["from"] = json!(before.s.name());
                    payload["to"] = json!(after.s.name());
                }
            }
            _ => {}
        }
        events.push(Event {
            kind: event_kind_name(e.kind),
            t: Some(e.time),
            payload: Some(payload),
            extra: JsonMap::new(),
        });
    }
    let pocketed: Vec<Value> = out.metrics["pocketed"]
        .as_array()
        .map(|a| a.iter().map(|p| p["ball"].clone()).collect())
        .unwrap_or_default();
    events.push(Event {
        kind: "shot_outcome".into(),
        t: Some(sim.t_end),
        payload: Some(json!({
            "agents": pocketed,
            "success": out.success,
            "terminal_status": out.terminal_status,
        })),
        extra: JsonMap::new(),
    });

    (events, out)
}

/// The outcome of a shot.
///
/// * `success`: the scene's goal ball (the 9-ball for 9-ball scenes; any object ball for `"any"`) was
///   pocketed, in the goal's pocket if it names one. A scratch does not undo it (DeepPHY's rule).
/// * `terminal_status`: `max_events` or `max_time` when a cap stopped the run; otherwise
///   `potted_<ball>` on success (`potted_9`), `scratch` when the cue ball was pocketed, `pocketed_other`
///   when other balls were, and `no_pocket`.
/// * `metrics`: `balls_pocketed`, `pocketed` (`[{ball, pocket, t}]` in order), `cue_ball_pocketed`,
///   `first_contact` (the first ball the cue ball hits, or null), `n_events` (physics events),
///   `n_ball_ball`, `n_cushion`, `duration_s`, `shot` (`{V0, phi, theta, a, b}`), `dt`, `sim_status`.
pub fn outcome(sim: &Simulation, scene: &Scene, shot: &Shot, dt: f64) -> Outcome {
    let cue = scene.cue_ball.as_str();
    let mut pocketed = Vec::new();
    let mut first_contact: Option<&str> = None;
    let (mut n_bb, mut n_cushion) = (0u64, 0u64);
    for e in &sim.events {
        let ids = sim.event_ids(e);
        match e.kind {
            EventKind::BallPocket => {
                pocketed.push(json!({"ball": ids[0], "pocket": ids[1], "t": e.time}))
            }
            EventKind::BallBall => {
                n_bb += 1;
                if first_contact.is_none() && ids.contains(&cue) {
                    first_contact = ids.iter().copied().find(|b| *b != cue);
                }
            }
            EventKind::BallLinearCushion | EventKind::BallCircularCushion => n_cushion += 1,
            _ => {}
        }
    }
    let goal_hit = pocketed.iter().find(|p| {
        let ball = p["ball"].as_str().unwrap_or_default();
        let ball_ok = if scene.goal.pot == "any" {
            ball != cue
        } else {
            ball == scene.goal.pot
        };
        ball_ok
            && scene
                .goal
                .pocket
                .as_ref()
                .is_none_or(|k| p["pocket"].as_str() == Some(k.as_str()))
    });
    let success = goal_hit.is_some();
    let cue_pocketed = pocketed.iter().any(|p| p["ball"] == cue);
    let terminal_status = match sim.status {
        Status::MaxEvents => "max_events".to_string(),
        Status::MaxTime => "max_time".to_string(),
        Status::Settled => match goal_hit {
            Some(p) => format!("potted_{}", p["ball"].as_str().unwrap_or_default()),
            None if cue_pocketed => "scratch".into(),
            None if !pocketed.is_empty() => "pocketed_other".into(),
            None => "no_pocket".into(),
        },
    };
    let sim_status = match sim.status {
        Status::Settled => "settled",
        Status::MaxEvents => "max_events",
        Status::MaxTime => "max_time",
    };
    let metrics = json_map(json!({
        "balls_pocketed": pocketed.len(),
        "pocketed": pocketed,
        "cue_ball_pocketed": cue_pocketed,
        "first_contact": first_contact,
        "n_events": sim.events.len(),
        "n_ball_ball": n_bb,
        "n_cushion": n_cushion,
        "duration_s": sim.t_end,
        "shot": shot_json(shot),
        "dt": dt,
        "sim_status": sim_status,
    }));
    Outcome {
        success,
        terminal_status,
        metrics,
        extra: JsonMap::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::pool::{PoolConfig, SimOptions, resample, simulate};
    use crate::trace::{Body, Object, PoolBall, PoolSteps};

    fn straight_pot() -> (Scene, Shot) {
        // The 9-ball 0.3 m in front of the right-top pocket's line, the cue ball behind it.
        let c = PoolConfig::default_7ft();
        let scene = Scene::from_json_str(
            r#"{"balls":[{"id":"cue","x":0.5,"y":1.2},{"id":"9","x":0.75,"y":1.6}]}"#,
            &c,
        )
        .unwrap();
        let phi = crate::envs::pool::aim::ghost_ball(&scene, &c, "9", "rt").unwrap();
        (
            scene,
            Shot {
                v0: 2.5,
                phi,
                theta: 0.0,
                a: 0.0,
                b: 0.0,
            },
        )
    }

    #[test]
    fn a_potted_nine_is_a_success_with_the_pocket_named() {
        let c = PoolConfig::default_7ft();
        let (scene, shot) = straight_pot();
        let sim = simulate(&scene.system(&c).unwrap(), &shot, &SimOptions::default()).unwrap();
        let tr = trace_of(&sim, &scene, &shot, "t0", &TraceOptions::default());
        assert!(tr.outcome.success, "{:?}", tr.outcome);
        assert_eq!(tr.outcome.terminal_status, "potted_9");
        assert_eq!(tr.outcome.metrics["pocketed"][0]["pocket"], "rt");
        assert_eq!(tr.outcome.metrics["first_contact"], "9");
        // Timesteps: the continuize grid, strictly increasing, every ball at every step.
        assert_eq!(tr.timesteps[1].t, 0.01);
        assert!(tr.timesteps.windows(2).all(|w| w[0].t < w[1].t));
        assert!(tr.timesteps.iter().all(|s| s.objects.len() == 2));
        assert_eq!(tr.timesteps.last().unwrap().t, sim.t_end);
        // Events: shot_prepared, the physics events in order, shot_outcome.
        assert_eq!(tr.events[0].kind, "shot_prepared");
        assert_eq!(tr.events[1].kind, "physics_stick_ball");
        assert_eq!(
            tr.events[1].payload.as_ref().unwrap()["agents"],
            json!(["cue_stick", "cue"])
        );
        let pocket = tr
            .events
            .iter()
            .find(|e| e.kind == "physics_ball_pocket")
            .unwrap();
        assert_eq!(
            pocket.payload.as_ref().unwrap()["agents"],
            json!(["9", "rt"])
        );
        assert_eq!(tr.events.last().unwrap().kind, "shot_outcome");
        let Body::Pool(nine) = &tr.timesteps.last().unwrap().objects[1].body else {
            panic!("a pool ball")
        };
        assert_eq!(
            (nine.motion_state_code, nine.motion_state.as_str()),
            (4, "pocketed")
        );
    }

    #[test]
    fn state_names_follow_the_motion_state_codes() {
        use crate::envs::pool::MotionState;
        for code in 0..5 {
            let s = MotionState::from_int(code).unwrap();
            assert_eq!(STATE_NAMES[usize::from(s.as_int())], s.name());
        }
    }

    #[test]
    fn columns_give_the_rows_of_the_paper_layout() {
        // A 9-ball break: balls change motion state, some are pocketed, every ball at every step.
        let c = PoolConfig::default_7ft();
        for index in 0..3 {
            let tr = dataset_trace(&c, 7, index, &TraceOptions { dt: 0.05 }).unwrap();
            let mut scene = Scene::nine_ball(&c, rack::scene_seed(7, index));
            scene.scene_id = format!("pool-7-{index:06}");
            let shot = rack::dataset_shot(&scene, &mut rack::shot_rng(7, index, 0));
            let sim = simulate(&scene.system(&c).unwrap(), &shot, &SimOptions::default()).unwrap();
            let cols = trace_columns(
                &sim,
                &scene,
                &shot,
                &tr.trace_id,
                &TraceOptions { dt: 0.05 },
            );
            assert_eq!(cols.frames.first_non_finite(), None);
            // The paper layout built object by object from the resampled states, as trace_of did
            // before the columns: the same timesteps.
            let mut samples = resample(&sim, 0.05);
            samples.dedup_by(|later, earlier| later.t <= earlier.t);
            assert_eq!(tr.timesteps.len(), samples.len());
            for (k, (ts, sample)) in tr.timesteps.iter().zip(&samples).enumerate() {
                assert_eq!((ts.index, ts.t), (k as i64, sample.t));
                let objects: Vec<Object> = sample
                    .balls
                    .iter()
                    .enumerate()
                    .map(|(b, s)| Object {
                        body: Body::Pool(PoolBall {
                            kind: "ball".into(),
                            ball_id: sim.ball_ids[b].as_str().into(),
                            position: s.r,
                            velocity: s.v,
                            angular_velocity: s.w,
                            motion_state_code: i64::from(s.s.as_int()),
                            motion_state: s.s.name().into(),
                            radius: sim.ball_params[b].r,
                        }),
                        extra: JsonMap::new(),
                    })
                    .collect();
                assert_eq!(ts.objects, objects);
            }
            // What the verification rules read: the same from the columns as from the trace.
            let crate::trace::Frames::Pool(frames) = &cols.frames else {
                panic!("billiards columns")
            };
            let (a, b) = (PoolSteps::of_trace(&tr), PoolSteps::of_frames(frames));
            assert_eq!(a.len(), b.len());
            for k in 0..a.len() {
                assert_eq!(a.t(k).to_bits(), b.t(k).to_bits());
                assert_eq!(
                    a.balls(k).collect::<Vec<_>>(),
                    b.balls(k).collect::<Vec<_>>()
                );
                assert_eq!(b.balls(k).count(), 10);
                assert_eq!(a.ball(k, "cue"), b.ball(k, "cue"));
                assert!(b.ball(k, "cue").is_some() && b.ball(k, "nope").is_none());
            }
            for t in [-1.0, 0.0, 0.013, 0.05, 0.5, 1e9] {
                assert_eq!(a.count_until(t), b.count_until(t));
            }
            let want = crate::trace::TraceBatchBuilder::from_trace(&tr, "s", "test").unwrap();
            let got = cols.batches("s", "test").unwrap();
            assert_eq!(got.traces, want.traces);
            assert_eq!(got.timesteps, want.timesteps);
            assert_eq!(got.frames, want.frames);
            assert_eq!(got.events, want.events);
        }
    }

    #[test]
    fn a_still_cue_gives_one_timestep_and_no_pocket() {
        let c = PoolConfig::default_7ft();
        let (scene, shot) = straight_pot();
        let shot = Shot { v0: 0.0, ..shot };
        let sim = simulate(&scene.system(&c).unwrap(), &shot, &SimOptions::default()).unwrap();
        let tr = trace_of(&sim, &scene, &shot, "t0", &TraceOptions::default());
        assert_eq!(tr.timesteps.len(), 1);
        assert_eq!(tr.outcome.terminal_status, "no_pocket");
        assert!(!tr.outcome.success);
    }

    #[test]
    fn a_capped_run_says_so() {
        let c = PoolConfig::default_7ft();
        let (scene, shot) = straight_pot();
        let opts = SimOptions {
            max_events: 1,
            t_final: None,
        };
        let sim = simulate(&scene.system(&c).unwrap(), &shot, &opts).unwrap();
        let tr = trace_of(&sim, &scene, &shot, "t0", &TraceOptions::default());
        assert_eq!(tr.outcome.terminal_status, "max_events");
        let opts = SimOptions {
            max_events: 0,
            t_final: Some(0.2),
        };
        let sim = simulate(&scene.system(&c).unwrap(), &shot, &opts).unwrap();
        assert_eq!(
            outcome(&sim, &scene, &shot, 0.01).terminal_status,
            "max_time"
        );
    }
}
