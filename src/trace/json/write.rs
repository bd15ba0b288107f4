//! Writes a [`Trace`] in the paper's JSON layout, streaming, without building a JSON tree first.
//!
//! Field order: `trace_id`, `environment`, `task_id`, the trace's unknown top-level fields, `timesteps`,
//! `events`, `outcome`. Inside objects the format's fields come first in the paper's order, then the
//! unknown ones in their input order. Floats are written in their shortest round-trip form, so reading
//! the output gives back the same `f64` values.

use std::io::Write;

use serde::ser::{Serialize, SerializeMap, SerializeSeq, Serializer};
use serde_json::Value;

use crate::trace::model::{Body, Event, JsonMap, Object, Outcome, Timestep, Trace};

/// A borrowed trace that serialises in the paper's layout.
pub struct PaperTrace<'a>(pub &'a Trace);

/// Writes one trace as compact JSON (no trailing newline).
pub fn write_trace(out: &mut impl Write, trace: &Trace, pretty: bool) -> serde_json::Result<()> {
    if pretty {
        serde_json::to_writer_pretty(out, &PaperTrace(trace))
    } else {
        serde_json::to_writer(out, &PaperTrace(trace))
    }
}

/// Writes a trace as compact JSON with an empty `timesteps` list: the bytes [`write_trace`] writes
/// for a copy of the trace without its timesteps, without making that copy (its events cloned only
/// to be written and dropped). This is the part of a load request that is not the steps (which
/// travel separately, `detect::protocol`).
pub fn write_trace_shell(out: &mut impl Write, trace: &Trace) -> serde_json::Result<()> {
    serde_json::to_writer(out, &Shell(trace))
}

/// The trace as a JSON value (for tests and small traces).
pub fn to_value(trace: &Trace) -> Value {
    serde_json::to_value(PaperTrace(trace))
        .expect("a trace always serialises: its floats are finite")
}

/// One timestep as a JSON value in the paper's layout (scene specs keep the initial timestep this way).
pub fn timestep_to_value(ts: &Timestep) -> Value {
    serde_json::to_value(StepJson(ts)).expect("a timestep always serialises: its floats are finite")
}

/// Writes a trace's timesteps as a JSON array in the paper's layout, except that an object whose JSON
/// is byte-for-byte the previous step's object in the same slot is written as `0`. This is how traces
/// other than pooltool's travel to a detector worker: static bodies (walls, bars, resting blocks) are
/// sent once, and the worker reuses the previous step's read-only dict for each `0`
/// (`load_steps` in `detect/worker.py`).
pub fn write_steps_sharing_repeats(
    out: &mut impl Write,
    steps: &[Timestep],
) -> serde_json::Result<()> {
    // Each object's JSON, for this step and the one before; the buffers are reused from step to step,
    // so only `prev[..prev_len]` is the previous step's.
    let mut prev: Vec<Vec<u8>> = Vec::new();
    let mut cur: Vec<Vec<u8>> = Vec::new();
    let mut prev_len = 0;
    out.write_all(b"[").map_err(serde_json::Error::io)?;
    for (i, ts) in steps.iter().enumerate() {
        let mut head = Vec::with_capacity(64);
        if i > 0 {
            head.push(b',');
        }
        head.extend_from_slice(b"{\"index\":");
        serde_json::to_writer(&mut head, &ts.index)?;
        head.extend_from_slice(b",\"t\":");
        serde_json::to_writer(&mut head, &ts.t)?;
        head.extend_from_slice(b",\"objects\":[");
        out.write_all(&head).map_err(serde_json::Error::io)?;
        for (j, o) in ts.objects.iter().enumerate() {
            if cur.len() <= j {
                cur.push(Vec::new());
            }
            let json = &mut cur[j];
            json.clear();
            serde_json::to_writer(&mut *json, &ObjectJson(o))?;
            let sep: &[u8] = if j > 0 { b"," } else { b"" };
            out.write_all(sep).map_err(serde_json::Error::io)?;
            if j < prev_len && prev[j] == *json {
                out.write_all(b"0").map_err(serde_json::Error::io)?;
            } else {
                out.write_all(json).map_err(serde_json::Error::io)?;
            }
        }
        out.write_all(b"]").map_err(serde_json::Error::io)?;
        for (k, v) in &ts.extra {
            out.write_all(b",").map_err(serde_json::Error::io)?;
            serde_json::to_writer(&mut *out, k)?;
            out.write_all(b":").map_err(serde_json::Error::io)?;
            serde_json::to_writer(&mut *out, v)?;
        }
        out.write_all(b"}").map_err(serde_json::Error::io)?;
        std::mem::swap(&mut prev, &mut cur);
        prev_len = ts.objects.len();
    }
    out.write_all(b"]").map_err(serde_json::Error::io)
}

fn extras<M: SerializeMap>(m: &mut M, extra: &JsonMap) -> Result<(), M::Error> {
    for (k, v) in extra {
        m.serialize_entry(k, v)?;
    }
    Ok(())
}

impl Serialize for PaperTrace<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        trace_with_steps(self.0, &self.0.timesteps, s)
    }
}

/// A borrowed trace that serialises as [`PaperTrace`] with no timesteps.
struct Shell<'a>(&'a Trace);

impl Serialize for Shell<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        trace_with_steps(self.0, &[], s)
    }
}

/// `t` in the paper's layout, with `steps` as its timesteps.
fn trace_with_steps<S: Serializer>(t: &Trace, steps: &[Timestep], s: S) -> Result<S::Ok, S::Error> {
    let mut m = s.serialize_map(None)?;
    m.serialize_entry("trace_id", &t.trace_id)?;
    m.serialize_entry("environment", t.env.as_str())?;
    m.serialize_entry("task_id", &t.task_id)?;
    extras(&mut m, &t.extra)?;
    m.serialize_entry("timesteps", &Steps(steps))?;
    m.serialize_entry("events", &Events(&t.events))?;
    m.serialize_entry("outcome", &OutcomeJson(&t.outcome))?;
    m.end()
}

struct Steps<'a>(&'a [Timestep]);
struct StepJson<'a>(&'a Timestep);
struct Objects<'a>(&'a [Object]);
struct ObjectJson<'a>(&'a Object);
struct Events<'a>(&'a [Event]);
struct EventJson<'a>(&'a Event);
struct OutcomeJson<'a>(&'a Outcome);

impl Serialize for Steps<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(self.0.len()))?;
        for ts in self.0 {
            seq.serialize_element(&StepJson(ts))?;
        }
        seq.end()
    }
}

impl Serialize for StepJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let ts = self.0;
        let mut m = s.serialize_map(None)?;
        m.serialize_entry("index", &ts.index)?;
        m.serialize_entry("t", &ts.t)?;
        m.serialize_entry("objects", &Objects(&ts.objects))?;
        extras(&mut m, &ts.extra)?;
        m.end()
    }
}

impl Serialize for Objects<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(self.0.len()))?;
        for o in self.0 {
            seq.serialize_element(&ObjectJson(o))?;
        }
        seq.end()
    }
}

impl Serialize for ObjectJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut m = s.serialize_map(None)?;
        match &self.0.body {
            Body::Pool(b) => {
                m.serialize_entry("kind", &b.kind)?;
                m.serialize_entry("ball_id", &b.ball_id)?;
                m.serialize_entry("position", &b.position)?;
                m.serialize_entry("velocity", &b.velocity)?;
                m.serialize_entry("angular_velocity", &b.angular_velocity)?;
                m.serialize_entry("motion_state_code", &b.motion_state_code)?;
                m.serialize_entry("motion_state", &b.motion_state)?;
                m.serialize_entry("radius", &b.radius)?;
            }
            Body::Phyre(o) => {
                m.serialize_entry("object_index", &o.object_index)?;
                m.serialize_entry("shape", &o.shape)?;
                m.serialize_entry("color", &o.color)?;
                m.serialize_entry("diameter", &o.diameter)?;
                m.serialize_entry("x", &o.x)?;
                m.serialize_entry("y", &o.y)?;
                m.serialize_entry("angle", &o.angle)?;
                m.serialize_entry("vx", &o.vx)?;
                m.serialize_entry("vy", &o.vy)?;
                m.serialize_entry("angular_velocity", &o.angular_velocity)?;
                m.serialize_entry("is_user_input", &o.is_user_input)?;
            }
            Body::Iphyre(o) => {
                m.serialize_entry("index", &o.index)?;
                m.serialize_entry("x1", &o.x1)?;
                m.serialize_entry("y1", &o.y1)?;
                m.serialize_entry("x2", &o.x2)?;
                m.serialize_entry("y2", &o.y2)?;
                m.serialize_entry("radius", &o.radius)?;
                m.serialize_entry("eliminable", &o.eliminable)?;
                m.serialize_entry("dynamic", &o.dynamic)?;
                m.serialize_entry("joint", &o.joint)?;
                m.serialize_entry("spring", &o.spring)?;
                for (key, v) in [
                    ("angle", o.angle),
                    ("vx", o.vx),
                    ("vy", o.vy),
                    ("angular_velocity", o.angular_velocity),
                ] {
                    if let Some(v) = v {
                        m.serialize_entry(key, &v)?;
                    }
                }
            }
        }
        extras(&mut m, &self.0.extra)?;
        m.end()
    }
}

impl Serialize for Events<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(self.0.len()))?;
        for e in self.0 {
            seq.serialize_element(&EventJson(e))?;
        }
        seq.end()
    }
}

impl Serialize for EventJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let e = self.0;
        let mut m = s.serialize_map(None)?;
        m.serialize_entry("kind", &e.kind)?;
        if let Some(t) = e.t {
            m.serialize_entry("t", &t)?;
        }
        if let Some(p) = &e.payload {
            m.serialize_entry("payload", p)?;
        }
        extras(&mut m, &e.extra)?;
        m.end()
    }
}

impl Serialize for OutcomeJson<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let o = self.0;
        let mut m = s.serialize_map(None)?;
        m.serialize_entry("success", &o.success)?;
        m.serialize_entry("terminal_status", &o.terminal_status)?;
        m.serialize_entry("metrics", &o.metrics)?;
        extras(&mut m, &o.extra)?;
        m.end()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::synthetic_trace;
    use crate::trace::Env;

    #[test]
    fn a_shell_is_the_trace_written_without_its_timesteps() {
        for env in Env::ALL {
            let mut t = synthetic_trace(env, 3, 5, 2);
            t.extra.insert("source".into(), Value::from("test"));
            t.extra
                .insert("z_last".into(), serde_json::json!({"a": [1, 2.5]}));
            let mut want = Vec::new();
            let mut copy = t.clone();
            copy.timesteps.clear();
            write_trace(&mut want, &copy, false).unwrap();
            let mut got = Vec::new();
            write_trace_shell(&mut got, &t).unwrap();
            assert_eq!(
                String::from_utf8(got).unwrap(),
                String::from_utf8(want).unwrap(),
                "{env}"
            );
            assert!(!t.events.is_empty(), "{env}: the shell carries the events");
        }
    }

    #[test]
    fn repeated_objects_are_written_once_and_only_against_the_step_before() {
        let mut t = synthetic_trace(Env::Phyre, 0, 4, 3);
        // Step 1 repeats step 0; step 2 keeps one object; step 3 repeats step 1 (not step 2) in full.
        t.timesteps[1].objects = t.timesteps[0].objects.clone();
        t.timesteps[2].objects = t.timesteps[1].objects[..1].to_vec();
        t.timesteps[3].objects = t.timesteps[1].objects.clone();
        let mut out = Vec::new();
        write_steps_sharing_repeats(&mut out, &t.timesteps).unwrap();
        let steps: Value = serde_json::from_slice(&out).unwrap();
        let objects = |s: usize| steps[s]["objects"].as_array().unwrap().clone();
        assert!(objects(0).iter().all(Value::is_object));
        assert!(objects(1).iter().all(|o| o == &Value::from(0)));
        assert_eq!(objects(2), vec![Value::from(0)]);
        // Slot 0 repeats step 2's object; slots 1 and 2 had no object in step 2, so they are written.
        let s3 = objects(3);
        assert_eq!(s3[0], Value::from(0));
        assert!(s3[1].is_object() && s3[2].is_object());
        // Everything else is the paper's layout.
        let full = to_value(&t);
        for (s, step) in steps.as_array().unwrap().iter().enumerate() {
            assert_eq!(step["index"], full["timesteps"][s]["index"]);
            assert_eq!(step["t"], full["timesteps"][s]["t"]);
        }
        assert_eq!(s3[1], full["timesteps"][3]["objects"][1]);
    }
}
