//! Conversion of an [`EpisodeResult`] into an annotrace [`Trace`] in the paper's PHYRE layout
//! (`object_index, shape, color, diameter, x, y, angle, vx, vy, angular_velocity, is_user_input`; scene
//! pixels, y up). Every body is in every kept frame, the four walls included (shape `wall`), the red
//! user ball last. `x, y` is the body origin as PHYRE stores it (for jars the base, not the centre of
//! mass).
//!
//! Events, each with a payload whose `agents` lists the body ids involved (decimal body indices):
//! `user_ball_placed` (`x`, `y`, `radius`, `action`), `invalid_input` (`reason`, `body`),
//! `contact_begin` / `contact_end` (`objects`, `step`), `goal_relation_begin` / `goal_relation_end`
//! (`step`, `held_steps`) and `success` (`step`).

use serde_json::json;

use super::episode::{EpisodeEvent, EpisodeResult, Status};
use super::params::{Engine, PIXELS_PER_METRE};
use super::task::{Color, Task};
use crate::trace::frames::{PhyreBody, PhyreFrames};
use crate::trace::{
    Body, Env, Event, JsonMap, Object, Outcome, PhyreObject, Timestep, Trace, TraceColumns,
    json_map,
};

/// The trace's shape name of a body: PHYRE's shape type, `wall` for the four walls.
fn shape_name(task: &Task, index: usize) -> &str {
    match task.bodies.get(index) {
        Some(b) if b.is_wall => "wall",
        Some(b) => &b.shape_type,
        None => "ball",
    }
}

/// The trace of `result`, played on `task`, named `trace_id`.
pub fn trace_of(result: &EpisodeResult, task: &Task, trace_id: &str) -> Trace {
    Trace {
        trace_id: trace_id.to_string(),
        env: Env::Phyre,
        task_id: task.task_id.clone(),
        timesteps: timesteps_of(result, task),
        events: events_of(result, task),
        outcome: outcome_of(result),
        extra: extra_of(result, task),
    }
}

/// The trace's top-level fields: the task, goal, action, user ball and simulator.
fn extra_of(result: &EpisodeResult, task: &Task) -> JsonMap {
    let a = result.action;
    let ball = result
        .placement
        .ball()
        .map(|b| json!({"x": b.x, "y": b.y, "radius": b.radius}));
    json_map(json!({
        "template_id": task.template_id,
        "description": task.description,
        "goal": {"body1": task.body1, "body2": task.body2, "relationships": task.relationships},
        "action": {"x": a.x, "y": a.y, "r": a.r},
        "user_ball": ball,
        "simulator": {
            "engine": engine_name(result.engine), "fps": 1.0 / result.dt, "stride": result.stride,
            "pixels_per_metre": PIXELS_PER_METRE, "scene": [task.width, task.height],
            "coordinates": "pixels, origin bottom-left, y up",
        },
    }))
}

/// The trace of `result` with its frames in columns (what the `simulate` stage writes): the same
/// trace as [`trace_of`], without an object per body per frame.
pub fn trace_columns(result: &EpisodeResult, task: &Task, trace_id: &str) -> TraceColumns {
    let n = task.bodies.len();
    let user_diameter = result.placement.ball().map_or(0.0, |b| 2.0 * b.radius);
    let bodies: Vec<PhyreBody> = (0..=n)
        .map(|i| match task.bodies.get(i) {
            Some(b) => PhyreBody {
                shape: shape_name(task, i).to_string(),
                color: b.color.name(),
                diameter: b.diameter,
                is_user_input: false,
            },
            None => PhyreBody {
                shape: "ball".to_string(),
                color: Color::Red.name(),
                diameter: user_diameter,
                is_user_input: true,
            },
        })
        .collect();
    let rows = result.frames.iter().map(|f| f.bodies.len()).sum();
    let mut frames = PhyreFrames::new(bodies, result.frames.len(), rows);
    for f in &result.frames {
        frames.begin_step(f.step as i64, f.step as f64 * result.dt);
        for s in &f.bodies {
            frames.body(s.index, [s.x, s.y, s.angle, s.vx, s.vy, s.angular_velocity]);
        }
    }
    TraceColumns {
        trace_id: trace_id.to_string(),
        task_id: task.task_id.clone(),
        frames: frames.into(),
        events: events_of(result, task),
        outcome: outcome_of(result),
        extra: extra_of(result, task),
    }
}

/// The engine as traces name it.
fn engine_name(engine: Engine) -> &'static str {
    match engine {
        Engine::Box2d => "box2d-rs 0.0.4 (Box2D 2.4.1)",
        Engine::Rapier => "rapier2d",
    }
}

/// A timestep per recorded frame; the user's ball is the object after the task's bodies.
fn timesteps_of(result: &EpisodeResult, task: &Task) -> Vec<Timestep> {
    let n = task.bodies.len();
    let user_diameter = result.placement.ball().map_or(0.0, |b| 2.0 * b.radius);
    let statics: Vec<(String, &'static str, f64)> = (0..=n)
        .map(|i| match task.bodies.get(i) {
            Some(b) => (shape_name(task, i).to_string(), b.color.name(), b.diameter),
            None => ("ball".to_string(), Color::Red.name(), user_diameter),
        })
        .collect();
    result
        .frames
        .iter()
        .map(|f| Timestep {
            index: f.step as i64,
            t: f.step as f64 * result.dt,
            objects: f
                .bodies
                .iter()
                .map(|s| {
                    let (shape, color, diameter) = &statics[s.index.min(n)];
                    Object {
                        body: Body::Phyre(PhyreObject {
                            object_index: s.index as i64,
                            shape: shape.clone(),
                            color: color.to_string(),
                            diameter: *diameter,
                            x: s.x,
                            y: s.y,
                            angle: s.angle,
                            vx: s.vx,
                            vy: s.vy,
                            angular_velocity: s.angular_velocity,
                            is_user_input: s.index == n,
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
fn events_of(result: &EpisodeResult, task: &Task) -> Vec<Event> {
    let t = |step: usize| step as f64 * result.dt;
    let ids = |objects: &[usize]| objects.iter().map(|i| i.to_string()).collect::<Vec<_>>();
    let goal = [task.body1, task.body2];
    let a = result.action;
    result
        .events
        .iter()
        .map(|e| match e {
            EpisodeEvent::UserBallPlaced { index, ball } => Event::at(
                "user_ball_placed",
                0.0,
                json!({"agents": ids(&[*index]), "x": ball.x, "y": ball.y, "radius": ball.radius,
                       "action": [a.x, a.y, a.r]}),
            ),
            EpisodeEvent::InvalidInput { reason, body } => Event::at(
                "invalid_input",
                0.0,
                json!({"agents": body.map(|b| ids(&[b])).unwrap_or_default(), "reason": reason,
                       "body": body, "action": [a.x, a.y, a.r]}),
            ),
            EpisodeEvent::ContactBegin { step, objects } => Event::at(
                "contact_begin",
                t(*step),
                json!({"agents": ids(objects), "objects": objects, "step": step}),
            ),
            EpisodeEvent::ContactEnd { step, objects } => Event::at(
                "contact_end",
                t(*step),
                json!({"agents": ids(objects), "objects": objects, "step": step}),
            ),
            EpisodeEvent::GoalRelationBegin { step } => Event::at(
                "goal_relation_begin",
                t(*step),
                json!({"agents": ids(&goal), "objects": goal, "step": step}),
            ),
            EpisodeEvent::GoalRelationEnd { step, held_steps } => Event::at(
                "goal_relation_end",
                t(*step),
                json!({"agents": ids(&goal), "objects": goal, "step": step, "held_steps": held_steps}),
            ),
            EpisodeEvent::Success { step } => Event::at(
                "success",
                t(*step),
                json!({"agents": ids(&goal), "objects": goal, "step": step}),
            ),
        })
        .collect()
}

/// PHYRE's status as the trace's outcome.
fn outcome_of(result: &EpisodeResult) -> Outcome {
    let t = |step: usize| step as f64 * result.dt;
    let solved = result.status == Status::Solved;
    let terminal = match result.status {
        Status::Solved => "success",
        Status::NotSolved => "timeout",
        Status::InvalidInput => "INVALID_INPUT",
    };
    Outcome {
        success: solved,
        terminal_status: terminal.to_string(),
        metrics: json_map(json!({
            "status": result.status.name(),
            "status_code": result.status.code(),
            "steps_simulated": result.steps,
            "sim_time_s": t(result.steps),
            "success_time_s": solved.then(|| t(result.steps)),
            "goal_first_step": result.goal_first_step,
        })),
        extra: JsonMap::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::phyre::action::BallAction;
    use crate::envs::phyre::episode::{RecordOptions, run};
    use crate::envs::phyre::params::PhysicsParams;
    use crate::envs::phyre::tasks::TaskSet;

    #[test]
    fn trace_has_the_phyre_layout_and_fills_the_tables() {
        let task = TaskSet::default_tasks().unwrap().get("00002:007").unwrap();
        let a = BallAction {
            x: 0.2,
            y: 0.9,
            r: 0.3,
        };
        let r = run(
            &task,
            &a,
            &PhysicsParams::default(),
            &RecordOptions::default(),
        )
        .unwrap();
        let tr = trace_of(&r, &task, "t");
        assert_eq!((tr.env, tr.task_id.as_str()), (Env::Phyre, "00002:007"));
        assert_eq!(tr.timesteps.len(), r.frames.len());
        let first = &tr.timesteps[0].objects;
        assert_eq!(first.len(), task.bodies.len() + 1);
        let Body::Phyre(wall) = &first[0].body else {
            panic!()
        };
        assert_eq!(
            (wall.shape.as_str(), wall.color.as_str()),
            ("wall", "black")
        );
        let Body::Phyre(user) = &first.last().unwrap().body else {
            panic!()
        };
        assert!(user.is_user_input && user.color == "red" && user.shape == "ball");
        assert_eq!((user.x, user.y, user.diameter), (51.0, 229.0, 22.0));
        assert_eq!(tr.events[0].kind, "user_ball_placed");
        assert_eq!(tr.outcome.metrics["steps_simulated"], json!(r.steps));
        // The columnar path gives the same trace and the same rows.
        let cols = trace_columns(&r, &task, "t");
        assert_eq!(cols.clone().into_trace(), tr);
        let want = crate::trace::TraceBatchBuilder::from_trace(&tr, "scene", "test").unwrap();
        let got = cols.batches("scene", "test").unwrap();
        assert_eq!(
            (got.traces, got.timesteps, got.frames, got.events),
            (want.traces, want.timesteps, want.frames, want.events)
        );
        let b = crate::trace::TraceBatchBuilder::from_trace(&tr, &tr.task_id, "test").unwrap();
        assert_eq!(b.frames.num_rows(), tr.frame_rows());
        assert_eq!(b.events.num_rows(), tr.events.len());
        assert_eq!(b.timesteps.num_rows(), tr.timesteps.len());
    }
}
