//! The in-memory trace model: a dense sequence of object states plus a sparse event log and an outcome.
//!
//! The types mirror the paper's per-environment JSON layout (see `docs/trace-format.md`) one to one, so
//! that a trace read from JSON or from the Parquet tables can be written back without loss. Fields of the
//! JSON that the format does not name are kept, in order, in the `extra` maps.

use serde_json::{Map, Value};

use super::{Env, ShortStr};

/// A JSON object that keeps its keys in input order.
pub type JsonMap = Map<String, Value>;

/// The fields of a JSON object; any other value gives no fields (how simulators build the
/// metrics and `extra` of the traces they write from a `json!` literal).
pub fn json_map(v: Value) -> JsonMap {
    match v {
        Value::Object(m) => m,
        _ => JsonMap::new(),
    }
}

/// One simulated episode.
#[derive(Clone, Debug, PartialEq)]
pub struct Trace {
    /// Unique id of the trace within a run.
    pub trace_id: String,
    /// The environment that produced it.
    pub env: Env,
    /// The task or scene family (`"00004:012"` for PHYRE, a game name for I-PHYRE, a rack id for billiards).
    pub task_id: String,
    /// The dense state sequence, in increasing `index` and `t`.
    pub timesteps: Vec<Timestep>,
    /// The sparse event log, in input order.
    pub events: Vec<Event>,
    /// How the episode ended.
    pub outcome: Outcome,
    /// Top-level fields the format does not name, kept verbatim.
    pub extra: JsonMap,
}

/// The state of every object at one instant.
#[derive(Clone, Debug, PartialEq)]
pub struct Timestep {
    /// Step number (the JSON `index`); strictly increasing along a trace.
    pub index: i64,
    /// Simulation time in seconds; strictly increasing along a trace.
    pub t: f64,
    /// The objects present at this step, in input order; ids are unique within a step.
    pub objects: Vec<Object>,
    /// Timestep fields the format does not name (`state`, `actions`, …), kept verbatim.
    pub extra: JsonMap,
}

/// One object's state at one step.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    /// The environment-specific state.
    pub body: Body,
    /// Object fields the format does not name, kept verbatim.
    pub extra: JsonMap,
}

/// An object's state in the layout of its environment.
#[derive(Clone, Debug, PartialEq)]
pub enum Body {
    /// A billiard ball.
    Pool(PoolBall),
    /// A PHYRE body.
    Phyre(PhyreObject),
    /// An I-PHYRE block or ball.
    Iphyre(IphyreObject),
}

/// A billiard ball (SI units, table frame: x across, y along the table, z up).
///
/// Its three strings are [`ShortStr`]s: a shot's trace has one `PoolBall` per ball per timestep,
/// and short ids, kinds and motion states then cost no heap allocation.
#[derive(Clone, Debug, PartialEq)]
pub struct PoolBall {
    /// Object kind, `"ball"` for balls.
    pub kind: ShortStr,
    /// Ball id: `"cue"`, `"1"` … `"15"`.
    pub ball_id: ShortStr,
    /// Centre position (m).
    pub position: [f64; 3],
    /// Centre velocity (m/s).
    pub velocity: [f64; 3],
    /// Angular velocity (rad/s).
    pub angular_velocity: [f64; 3],
    /// pooltool's motion-state integer: 0 stationary, 1 spinning, 2 sliding, 3 rolling, 4 pocketed.
    pub motion_state_code: i64,
    /// The motion state's name (`stationary`, `spinning`, `sliding`, `rolling`, `pocketed`).
    pub motion_state: ShortStr,
    /// Ball radius (m).
    pub radius: f64,
}

/// A PHYRE body (scene pixels, y up, angle in radians).
#[derive(Clone, Debug, PartialEq)]
pub struct PhyreObject {
    /// Body index within the task.
    pub object_index: i64,
    /// `ball`, `bar`, `jar`, `standingsticks`, …
    pub shape: String,
    /// PHYRE colour name: `red`, `green`, `blue`, `purple`, `gray`, `black`.
    pub color: String,
    /// Diameter (px).
    pub diameter: f64,
    /// Centre x (px).
    pub x: f64,
    /// Centre y (px).
    pub y: f64,
    /// Orientation (rad).
    pub angle: f64,
    /// Velocity x (px/s).
    pub vx: f64,
    /// Velocity y (px/s).
    pub vy: f64,
    /// Angular velocity (rad/s).
    pub angular_velocity: f64,
    /// True for the ball placed by the action.
    pub is_user_input: bool,
}

/// An I-PHYRE object: a capsule segment from (x1, y1) to (x2, y2), or a ball with both ends at its centre
/// (screen pixels, y down).
#[derive(Clone, Debug, PartialEq)]
pub struct IphyreObject {
    /// Original object index in the game (blocks first, then balls).
    pub index: i64,
    /// First end x (px).
    pub x1: f64,
    /// First end y (px).
    pub y1: f64,
    /// Second end x (px).
    pub x2: f64,
    /// Second end y (px).
    pub y2: f64,
    /// Capsule or ball radius (px).
    pub radius: f64,
    /// 1 when a click can remove it, else 0.
    pub eliminable: f64,
    /// 1 when it moves under gravity, else 0.
    pub dynamic: f64,
    /// 1-based index of the pin joint it belongs to, 0 for none.
    pub joint: i64,
    /// 1-based index of the spring it belongs to, 0 for none.
    pub spring: i64,
    /// Optional orientation (rad), when the producer records it.
    pub angle: Option<f64>,
    /// Optional centre velocity x (px/s), when the producer records it.
    pub vx: Option<f64>,
    /// Optional centre velocity y (px/s), when the producer records it.
    pub vy: Option<f64>,
    /// Optional angular velocity (rad/s), when the producer records it.
    pub angular_velocity: Option<f64>,
}

impl Body {
    /// The first numeric state field that is not finite (`NaN` or infinite), by name.
    pub fn non_finite(&self) -> Option<&'static str> {
        let check = |fields: &[(&'static str, f64)]| {
            fields.iter().find(|(_, v)| !v.is_finite()).map(|(n, _)| *n)
        };
        match self {
            Body::Pool(b) => {
                let [p, v, w] = [b.position, b.velocity, b.angular_velocity];
                check(&[
                    ("position", p[0] + p[1] + p[2]),
                    ("velocity", v[0] + v[1] + v[2]),
                    ("angular_velocity", w[0] + w[1] + w[2]),
                ])
            }
            Body::Phyre(o) => check(&[("x", o.x), ("y", o.y), ("angle", o.angle)]),
            Body::Iphyre(o) => check(&[("x1", o.x1), ("y1", o.y1), ("x2", o.x2), ("y2", o.y2)]),
        }
    }
}

/// One entry of the sparse event log.
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    /// Event kind (`physics_ball_ball`, `contact_begin`, `scheduled_action`, …).
    pub kind: String,
    /// Time in seconds, when the event has one.
    pub t: Option<f64>,
    /// The event's payload, verbatim (`None` when the field is absent).
    pub payload: Option<serde_json::Value>,
    /// Event fields other than `kind`, `t` and `payload`, kept verbatim.
    pub extra: JsonMap,
}

impl Event {
    /// An event of `kind` at time `t` with `payload` and no other fields, as simulators log them.
    pub fn at(kind: &str, t: f64, payload: Value) -> Event {
        Event {
            kind: kind.to_string(),
            t: Some(t),
            payload: Some(payload),
            extra: JsonMap::new(),
        }
    }
}

/// How an episode ended.
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome {
    /// Whether the task's success rule held.
    pub success: bool,
    /// Why the episode stopped (`success`, `timeout`, `INVALID_INPUT`, `max_events`, …).
    pub terminal_status: String,
    /// Numeric or structured metrics, verbatim.
    pub metrics: JsonMap,
    /// Outcome fields other than `success`, `terminal_status` and `metrics`, kept verbatim.
    pub extra: JsonMap,
}

impl Object {
    /// The object's id as a string: a ball id, or the decimal object index.
    pub fn object_id(&self) -> String {
        self.body.object_id()
    }
}

impl Body {
    /// The object's id as a string: a ball id, or the decimal object index.
    pub fn object_id(&self) -> String {
        match self {
            Body::Pool(b) => b.ball_id.to_string(),
            Body::Phyre(o) => o.object_index.to_string(),
            Body::Iphyre(o) => o.index.to_string(),
        }
    }

    /// The environment whose layout this body follows.
    pub fn env(&self) -> Env {
        match self {
            Body::Pool(_) => Env::Pooltool,
            Body::Phyre(_) => Env::Phyre,
            Body::Iphyre(_) => Env::Iphyre,
        }
    }

    /// The planar centre shared by every environment: the ball centre, the PHYRE body centre, or the
    /// midpoint of an I-PHYRE segment.
    pub fn centre(&self) -> (f64, f64) {
        match self {
            Body::Pool(b) => (b.position[0], b.position[1]),
            Body::Phyre(o) => (o.x, o.y),
            Body::Iphyre(o) => ((o.x1 + o.x2) / 2.0, (o.y1 + o.y2) / 2.0),
        }
    }
}

impl Trace {
    /// The first object state that is not finite: (timestep index, object position in the step,
    /// field). Simulators that blow up produce these; no table may hold them.
    pub fn first_non_finite(&self) -> Option<(i64, usize, &'static str)> {
        self.timesteps.iter().find_map(|ts| {
            ts.objects
                .iter()
                .enumerate()
                .find_map(|(k, o)| o.body.non_finite().map(|f| (ts.index, k, f)))
        })
    }

    /// Number of object rows over all timesteps (the trace's share of the `frames` table).
    pub fn frame_rows(&self) -> usize {
        self.timesteps.iter().map(|ts| ts.objects.len()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::synthetic_trace;

    #[test]
    fn non_finite_states_are_found_with_their_place() {
        for env in Env::ALL {
            let mut t = synthetic_trace(env, 0, 4, 3);
            assert_eq!(t.first_non_finite(), None, "{env}");
            match &mut t.timesteps[2].objects[1].body {
                Body::Pool(b) => b.velocity[1] = f64::NAN,
                Body::Phyre(o) => o.y = f64::INFINITY,
                Body::Iphyre(o) => o.x2 = f64::NEG_INFINITY,
            }
            let (step, object, field) = t.first_non_finite().expect("found");
            assert_eq!((step, object), (t.timesteps[2].index, 1), "{env}");
            assert!(["velocity", "y", "x2"].contains(&field), "{env}: {field}");
        }
    }
}
