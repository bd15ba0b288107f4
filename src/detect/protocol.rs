//! The framed protocol between the Rust side and a worker (`worker.py` documents the messages).
//!
//! A frame is a 4-byte little-endian length followed by that many bytes; a request's first byte is its
//! type (`T` load trace, `P` load a pooltool trace by columns, `E` evict traces, `C` compile, `R` run)
//! and the rest JSON (or columns, for `P`). Replies are JSON, except a run reply whose patterns travel in
//! CPython's `marshal` format (`M`, read by `marshal.rs`). A run request gets one reply per detector, in
//! order; an evict request gets none (it is sent behind a run request); every other request gets one
//! reply.

use std::io::{self, Write};

use serde_json::Value;

use crate::trace::Trace;

/// Request types.
pub(crate) const LOAD_TRACE: u8 = b'T';
pub(crate) const LOAD_POOL: u8 = b'P';
pub(crate) const EVICT: u8 = b'E';
pub(crate) const COMPILE: u8 = b'C';
pub(crate) const RUN: u8 = b'R';

/// Writes one request frame.
pub(crate) fn write_frame(out: &mut impl Write, kind: u8, body: &[u8]) -> io::Result<()> {
    let len = u32::try_from(body.len() + 1)
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "frame larger than 4 GiB"))?;
    // One write for the whole frame, so the worker wakes once per request.
    let mut frame = Vec::with_capacity(5 + body.len());
    frame.extend_from_slice(&len.to_le_bytes());
    frame.push(kind);
    frame.extend_from_slice(body);
    out.write_all(&frame)?;
    out.flush()
}

/// The body of a load request: `{"id": key, "trace": <the paper's dict without its timesteps>, "steps":
/// [...]}`, the timesteps written with repeated objects as `0` (see
/// [`write_steps_sharing_repeats`](crate::trace::json::write_steps_sharing_repeats)).
pub(crate) fn load_body(key: &str, trace: &Trace) -> Vec<u8> {
    let mut buf = Vec::with_capacity(64 + trace.frame_rows() * 128);
    buf.extend_from_slice(b"{\"id\":");
    serde_json::to_writer(&mut buf, key).expect("a string serialises");
    buf.extend_from_slice(b",\"trace\":");
    crate::trace::json::write_trace(&mut buf, &shell_of(trace), false)
        .expect("a trace always serialises");
    buf.extend_from_slice(b",\"steps\":");
    crate::trace::json::write_steps_sharing_repeats(&mut buf, &trace.timesteps)
        .expect("a trace always serialises");
    buf.push(b'}');
    buf
}

/// The trace without its timesteps (they travel separately).
fn shell_of(trace: &Trace) -> Trace {
    Trace {
        trace_id: trace.trace_id.clone(),
        env: trace.env,
        task_id: trace.task_id.clone(),
        timesteps: Vec::new(),
        events: trace.events.clone(),
        outcome: trace.outcome.clone(),
        extra: trace.extra.clone(),
    }
}

/// The request that loads `trace` under `key`: by columns for a pooltool trace whose objects carry no
/// unknown fields (floats travel as raw little-endian doubles, 5-8× cheaper for the worker than parsing
/// them from JSON), else the paper's JSON.
pub(crate) fn load_request(key: &str, trace: &Trace) -> (u8, Vec<u8>) {
    match pool_columns(key, trace) {
        Some(body) => (LOAD_POOL, body),
        None => (LOAD_TRACE, load_body(key, trace)),
    }
}

/// `<u32 header length><header JSON><f64 block>`; see `load_pool_columns` in worker.py.
///
/// Most balls sit still most of the time (about 70 % of the object rows of a random 9-ball shot repeat
/// the row before), and the trace the worker builds is read-only, so a ball whose state is bit-for-bit
/// the previous step's (same slot, id, kind, state and ten floats) is not sent again: the worker reuses
/// that step's dict. The header holds the trace without timesteps; each step's index, object count and
/// the slots whose objects are new (`null` when all are, as in the first step); a table of the distinct
/// (ball id, kind, state code, state) and each new object's row in it. The block holds every step's
/// `t`, then position, velocity and angular velocity of each new object (three 3-vectors), then their
/// radii.
fn pool_columns(key: &str, trace: &Trace) -> Option<Vec<u8>> {
    use crate::trace::{Body, Env, PoolBall};
    if trace.env != Env::Pooltool {
        return None;
    }
    fn same(a: &PoolBall, b: &PoolBall) -> bool {
        let bits = |x: &PoolBall| {
            let mut v = [0u64; 10];
            for (i, f) in x
                .position
                .iter()
                .chain(&x.velocity)
                .chain(&x.angular_velocity)
                .chain(std::iter::once(&x.radius))
                .enumerate()
            {
                v[i] = f.to_bits();
            }
            v
        };
        a.ball_id == b.ball_id
            && a.kind == b.kind
            && a.motion_state_code == b.motion_state_code
            && a.motion_state == b.motion_state
            && bits(a) == bits(b)
    }
    let mut protos: Vec<(&str, &str, i64, &str)> = Vec::new();
    let mut proto: Vec<u32> = Vec::new();
    let mut changed: Vec<Option<Vec<u32>>> = Vec::with_capacity(trace.timesteps.len());
    let mut vecs: Vec<u8> = Vec::new();
    let mut radii: Vec<u8> = Vec::new();
    let mut prev: Vec<&PoolBall> = Vec::new();
    let mut row: Vec<&PoolBall> = Vec::new();
    for ts in &trace.timesteps {
        row.clear();
        let all_new = prev.len() != ts.objects.len();
        let mut slots = Vec::new();
        for (j, o) in ts.objects.iter().enumerate() {
            let Body::Pool(b) = &o.body else { return None };
            if !o.extra.is_empty() {
                return None;
            }
            row.push(b);
            if !all_new && same(prev[j], b) {
                continue;
            }
            slots.push(u32::try_from(j).ok()?);
            let key = (
                b.ball_id.as_str(),
                b.kind.as_str(),
                b.motion_state_code,
                b.motion_state.as_str(),
            );
            let k = match protos.iter().position(|p| *p == key) {
                Some(k) => k,
                None => {
                    protos.push(key);
                    protos.len() - 1
                }
            };
            proto.push(u32::try_from(k).ok()?);
            for v in b
                .position
                .iter()
                .chain(&b.velocity)
                .chain(&b.angular_velocity)
            {
                vecs.extend_from_slice(&v.to_le_bytes());
            }
            radii.extend_from_slice(&b.radius.to_le_bytes());
        }
        changed.push((!all_new).then_some(slots));
        std::mem::swap(&mut prev, &mut row);
    }
    let step_extra: Option<Vec<&crate::trace::JsonMap>> = trace
        .timesteps
        .iter()
        .any(|t| !t.extra.is_empty())
        .then(|| trace.timesteps.iter().map(|t| &t.extra).collect());
    let shell = shell_of(trace);
    let mut header = Vec::with_capacity(4096 + 4 * proto.len());
    header.extend_from_slice(b"{\"id\":");
    serde_json::to_writer(&mut header, key).ok()?;
    header.extend_from_slice(b",\"trace\":");
    crate::trace::json::write_trace(&mut header, &shell, false).ok()?;
    let rest = serde_json::json!({
        "index": trace.timesteps.iter().map(|t| t.index).collect::<Vec<_>>(),
        "n": trace.timesteps.iter().map(|t| t.objects.len()).collect::<Vec<_>>(),
        "changed": changed,
        "protos": protos,
        "proto": proto,
        "step_extra": step_extra,
    });
    header.push(b',');
    let rest = serde_json::to_vec(&rest).ok()?;
    header.extend_from_slice(&rest[1..]);
    let steps = trace.timesteps.len();
    let mut body = Vec::with_capacity(4 + header.len() + 8 * steps + vecs.len() + radii.len());
    body.extend_from_slice(&u32::try_from(header.len()).ok()?.to_le_bytes());
    body.extend_from_slice(&header);
    for ts in &trace.timesteps {
        body.extend_from_slice(&ts.t.to_le_bytes());
    }
    body.extend_from_slice(&vecs);
    body.extend_from_slice(&radii);
    Some(body)
}

/// The body of a compile request.
pub(crate) fn compile_body(id: &str, code: &str) -> Vec<u8> {
    serde_json::to_vec(&serde_json::json!({"id": id, "code": code})).expect("serialises")
}

/// The body of a run request: run each detector in turn on the trace; one reply per detector, written
/// as each call ends (`flush_s` 0) or gathered and written together at most `flush_s` after the last
/// write (before the next call starts) and at the end.
pub(crate) fn run_body(detectors: &[&str], trace: &str, flush_s: f64) -> Vec<u8> {
    serde_json::to_vec(
        &serde_json::json!({"detectors": detectors, "trace": trace, "flush": flush_s}),
    )
    .expect("serialises")
}

/// The wall and CPU seconds of a marshal reply, read without decoding its patterns.
pub(crate) fn marshal_times(bytes: &[u8]) -> Option<(f64, f64)> {
    let f = |i: usize| Some(f64::from_le_bytes(bytes.get(i..i + 8)?.try_into().ok()?));
    (bytes.first() == Some(&MARSHAL_REPLY)).then_some(())?;
    Some((f(1)?, f(9)?))
}

/// The body of an evict request.
pub(crate) fn evict_body(keys: &[String]) -> Vec<u8> {
    serde_json::to_vec(&serde_json::json!({"ids": keys})).expect("serialises")
}

/// The first byte of a run reply whose patterns travel in `marshal` format: `M`, the call's wall and CPU
/// seconds (two little-endian f64), the length of what it printed (u32 LE) and that text (UTF-8), then
/// `marshal.dumps(patterns, 4)`.
pub(crate) const MARSHAL_REPLY: u8 = b'M';

/// Parses a reply: JSON, or a run reply with marshalled patterns, returned in the JSON reply's shape
/// (`ok`, `wall`, `cpu`, `printed`, `patterns`). The patterns are decoded under a budget of
/// `max_output_bytes`; an output the decoder refuses becomes an `invalid_output` error reply with its
/// path, as the worker's own checks produce.
pub(crate) fn parse_reply(bytes: &[u8], max_output_bytes: usize) -> Result<Value, String> {
    if bytes.first() != Some(&MARSHAL_REPLY) {
        return serde_json::from_slice(bytes)
            .map_err(|e| format!("unreadable reply from the worker: {e}"));
    }
    let bad = || "unreadable reply from the worker: a truncated marshal frame".to_string();
    let (wall, cpu) = marshal_times(bytes).ok_or_else(bad)?;
    let n = bytes
        .get(17..21)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
        .ok_or_else(bad)?;
    let printed = bytes.get(21..21 + n).ok_or_else(bad)?;
    let mut v = serde_json::json!({
        "ok": true,
        "wall": wall,
        "cpu": cpu,
        "printed": String::from_utf8_lossy(printed),
    });
    match super::marshal::decode(&bytes[21 + n..], max_output_bytes) {
        Ok(patterns) => v["patterns"] = patterns,
        Err(e) => {
            v["ok"] = Value::Bool(false);
            v["error"] = serde_json::json!({
                "category": "invalid_output",
                "path": e.path,
                "message": e.message,
            });
        }
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_is_its_length_then_its_type_then_its_body() {
        let mut buf = Vec::new();
        write_frame(&mut buf, RUN, b"{}").unwrap();
        assert_eq!(buf, b"\x03\x00\x00\x00R{}");
    }
}
