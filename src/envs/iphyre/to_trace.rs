//! Conversion of an [`EpisodeResult`] into an annotrace [`Trace`] in the paper's I-PHYRE layout
//! (docs/envs/iphyre.md §R5 and §R7): one timestep per physics step, objects as
//! `index, x1, y1, x2, y2, radius, eliminable, dynamic, joint, spring` plus `angle, vx, vy,
//! angular_velocity`; removed objects disappear from later timesteps.
//!
//! Events, each with a payload whose `agents` lists the object ids involved (decimal object indices,
//! as [`crate::trace::Object::object_id`] spells them):
//! `scheduled_action` (t = the click time; `x`, `y`), `action_ignored_t0`, `action_applied` (t = the time
//! counter; `x`, `y`, `t_scheduled`, `step`, `eliminated_object` or null, `effective`),
//! `contact_begin` / `contact_end` (`objects`, `step`), `ball_exit` (`object`, `step`) and `success`
//! (`step`).

use serde_json::{Value, json};

use super::game::Game;
use super::step::{EpisodeEvent, EpisodeResult};
use crate::trace::frames::{IphyreBody, IphyreFrames};
use crate::trace::{
    Body, Env, Event, IphyreObject, JsonMap, Object, Outcome, Timestep, Trace, TraceColumns,
    json_map,
};

/// The trace of `result`, played on `game`, named `trace_id`.
pub fn trace_of(result: &EpisodeResult, game: &Game, trace_id: &str) -> Trace {
    Trace {
        trace_id: trace_id.to_string(),
        env: Env::Iphyre,
        task_id: game.name.clone(),
        timesteps: timesteps_of(result, game),
        events: events_of(result, game),
        outcome: outcome_of(result),
        extra: extra_of(result, game),
    }
}

/// The trace's top-level fields: the game, its clicks and the simulator.
fn extra_of(result: &EpisodeResult, game: &Game) -> JsonMap {
    let clicks: Vec<Value> = result
        .clicks
        .iter()
        .map(|c| json!({"x": c.x, "y": c.y, "t": c.t}))
        .collect();
    json_map(json!({
        "task_index": game.index,
        "fold": game.fold,
        "actions": clicks,
        "simulator": {"engine": result.engine.description(), "fps": result.fps, "screen": [600, 600]},
    }))
}

/// The trace of `result` with its frames in columns (what the `simulate` stage writes): the same
/// trace as [`trace_of`], without an object per body per frame.
pub fn trace_columns(result: &EpisodeResult, game: &Game, trace_id: &str) -> TraceColumns {
    let bodies = game
        .objects
        .iter()
        .map(|o| IphyreBody {
            radius: o.radius,
            eliminable: if o.eliminable { 1.0 } else { 0.0 },
            dynamic: if o.dynamic { 1.0 } else { 0.0 },
            joint: o.joint,
            spring: o.spring,
        })
        .collect();
    let rows = result.frames.iter().map(|f| f.objects.len()).sum();
    let mut frames = IphyreFrames::new(bodies, result.frames.len(), rows);
    for f in &result.frames {
        frames.begin_step(f.step as i64, f.t);
        for s in &f.objects {
            frames.object(s.index, s.p1, s.p2, s.angle, s.velocity, s.angular_velocity);
        }
    }
    TraceColumns {
        trace_id: trace_id.to_string(),
        task_id: game.name.clone(),
        frames: frames.into(),
        events: events_of(result, game),
        outcome: outcome_of(result),
        extra: extra_of(result, game),
    }
}

/// A timestep per recorded frame, each object with its game's fixed properties.
fn timesteps_of(result: &EpisodeResult, game: &Game) -> Vec<Timestep> {
    result
        .frames
        .iter()
        .map(|f| Timestep {
            index: f.step as i64,
            t: f.t,
            objects: f
                .objects
                .iter()
                .map(|s| {
                    let o = &game.objects[s.index];
                    Object {
                        body: Body::Iphyre(IphyreObject {
                            index: s.index as i64,
                            x1: s.p1[0],
                            y1: s.p1[1],
                            x2: s.p2[0],
                            y2: s.p2[1],
                            radius: o.radius,
                            eliminable: if o.eliminable { 1.0 } else { 0.0 },
                            dynamic: if o.dynamic { 1.0 } else { 0.0 },
                            joint: o.joint,
                            spring: o.spring,
                            angle: Some(s.angle),
                            vx: Some(s.velocity[0]),
                            vy: Some(s.velocity[1]),
                            angular_velocity: Some(s.angular_velocity),
                        }),
                        extra: JsonMap::new(),
                    }
                })
                .collect(),
            extra: JsonMap::new(),
        })
        .collect()
}

/// The episode's events in the paper's form, each naming its objects as `agents`.
fn events_of(result: &EpisodeResult, game: &Game) -> Vec<Event> {
    let ids = |objects: &[usize]| objects.iter().map(|i| i.to_string()).collect::<Vec<_>>();
    result
        .events
        .iter()
        .map(|e| match e {
            EpisodeEvent::ScheduledAction(c) => Event::at(
                "scheduled_action",
                c.t,
                json!({"agents": [], "x": c.x, "y": c.y}),
            ),
            EpisodeEvent::ActionIgnoredT0(c) => Event::at(
                "action_ignored_t0",
                c.t,
                json!({"agents": [], "x": c.x, "y": c.y}),
            ),
            EpisodeEvent::ActionApplied {
                step,
                t,
                click,
                block,
            } => Event::at(
                "action_applied",
                *t,
                json!({
                    "agents": block.map(|b| ids(&[b])).unwrap_or_default(),
                    "step": step, "x": click.x, "y": click.y, "t_scheduled": click.t,
                    "eliminated_object": block, "effective": block.is_some(),
                }),
            ),
            EpisodeEvent::ContactBegin { step, t, objects } => Event::at(
                "contact_begin",
                *t,
                json!({"agents": ids(objects), "objects": objects, "step": step}),
            ),
            EpisodeEvent::ContactEnd { step, t, objects } => Event::at(
                "contact_end",
                *t,
                json!({"agents": ids(objects), "objects": objects, "step": step}),
            ),
            EpisodeEvent::BallExit { step, t, object } => Event::at(
                "ball_exit",
                *t,
                json!({"agents": ids(&[*object]), "object": object, "step": step}),
            ),
            EpisodeEvent::Success { step, t } => {
                let balls: Vec<usize> = game.balls().map(|b| b.index).collect();
                Event::at("success", *t, json!({"agents": ids(&balls), "step": step}))
            }
        })
        .collect()
}

/// Success, the time it came and I-PHYRE's reward as the trace's outcome.
fn outcome_of(result: &EpisodeResult) -> Outcome {
    let success_time = result.events.iter().find_map(|e| match e {
        EpisodeEvent::Success { t, .. } => Some(*t),
        _ => None,
    });
    Outcome {
        success: result.success,
        terminal_status: if result.success { "success" } else { "timeout" }.to_string(),
        metrics: json_map(json!({
            "success_time_s": success_time,
            "steps_simulated": result.steps,
            "sim_time_s": result.time,
            "effective_eliminations": result.eliminations,
            "reward": result.reward,
            "fps": result.fps,
        })),
        extra: JsonMap::new(),
    }
}

/// Test fixture: the `support` game with both eliminable blocks removed at 0.5 s, played at 10 fps (a
/// short episode that ends in success), and its trace named `trace_id`.
#[cfg(test)]
pub(super) fn support_episode(trace_id: &str) -> (Game, EpisodeResult, Trace) {
    use super::action::click_block;
    use super::game::Games;
    use super::params::PhysicsParams;
    use super::step::play;
    let games = Games::default_games().unwrap();
    let g = games.get("support").unwrap().clone();
    let clicks = [
        click_block(&g, 0, 0.5).unwrap(),
        click_block(&g, 1, 0.5).unwrap(),
    ];
    let r = play(&g, &clicks, &PhysicsParams::with_fps(10.0)).unwrap();
    let tr = trace_of(&r, &g, trace_id);
    (g, r, tr)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::iphyre::action::click_block;
    use crate::envs::iphyre::game::Games;
    use crate::envs::iphyre::params::PhysicsParams;
    use crate::envs::iphyre::step::play;

    #[test]
    fn trace_has_the_iphyre_layout_and_events() {
        let (_, r, tr) = support_episode("support-test");
        assert_eq!(tr.env, Env::Iphyre);
        assert_eq!(tr.timesteps.len(), r.steps + 1);
        assert_eq!(tr.timesteps[0].objects.len(), 3);
        assert_eq!(tr.timesteps.last().unwrap().objects.len(), 1);
        let Body::Iphyre(ball) = &tr.timesteps[0].objects[2].body else {
            panic!("not an I-PHYRE body");
        };
        assert_eq!(
            (ball.index, ball.x1, ball.y1, ball.radius),
            (2, 250.0, 340.0, 20.0)
        );
        let kinds: Vec<&str> = tr.events.iter().map(|e| e.kind.as_str()).collect();
        assert_eq!(&kinds[..2], ["scheduled_action", "scheduled_action"]);
        assert!(kinds.contains(&"action_applied") && kinds.contains(&"ball_exit"));
        assert_eq!(kinds.last(), Some(&"success"));
        let applied = tr
            .events
            .iter()
            .find(|e| e.kind == "action_applied")
            .unwrap();
        assert_eq!(applied.payload.as_ref().unwrap()["agents"], json!(["0"]));
        assert!(tr.outcome.success);
        assert_eq!(tr.outcome.metrics["effective_eliminations"], json!(2));
        // The trace names the engine that made it (the default: the Chipmunk step).
        let engine = tr.extra["simulator"]["engine"].as_str().unwrap();
        assert!(engine.starts_with("chipmunk-step"), "{engine}");
    }

    #[test]
    fn columns_give_the_same_trace_and_the_same_rows() {
        // Objects disappear mid-episode here (both blocks removed), so slots and ids shift.
        let (g, r, tr) = support_episode("support-cols");
        let cols = trace_columns(&r, &g, "support-cols");
        assert_eq!(cols.clone().into_trace(), tr);
        let want = crate::trace::TraceBatchBuilder::from_trace(&tr, "scene", "test").unwrap();
        let got = cols.batches("scene", "test").unwrap();
        assert_eq!(got.traces, want.traces);
        assert_eq!(got.timesteps, want.timesteps);
        assert_eq!(got.frames, want.frames);
        assert_eq!(got.events, want.events);
    }

    #[test]
    fn trace_fits_the_trace_tables() {
        let games = Games::default_games().unwrap();
        let g = games.get("pendulum").unwrap();
        let clicks = [
            click_block(g, 0, 1.0).unwrap(),
            click_block(g, 1, 2.0).unwrap(),
        ];
        let r = play(g, &clicks, &PhysicsParams::with_fps(10.0)).unwrap();
        let tr = trace_of(&r, g, "pendulum-test");
        let b = crate::trace::TraceBatchBuilder::from_trace(&tr, &tr.task_id, "test").unwrap();
        let objects: usize = tr.timesteps.iter().map(|t| t.objects.len()).sum();
        assert_eq!(b.traces.num_rows(), 1);
        assert_eq!(b.timesteps.num_rows(), tr.timesteps.len());
        assert_eq!(b.frames.num_rows(), objects);
        assert_eq!(b.events.num_rows(), tr.events.len());
    }
}
