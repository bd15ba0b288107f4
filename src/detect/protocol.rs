//! The framed protocol between the Rust side and a worker (`worker.py` documents the messages).
//!
//! A frame is a 4-byte little-endian length followed by that many bytes; a request's first byte is its
//! type (`T` load trace, `E` evict traces, `C` compile, `R` run) and the rest JSON. Replies are JSON.
//! One reply per request, in order, so the worker is always idle when a request is written.

use std::io::{self, Read, Write};

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
    out.write_all(&len.to_le_bytes())?;
    out.write_all(&[kind])?;
    out.write_all(body)?;
    out.flush()
}

/// Reads one reply frame; `max` bounds its length (a larger frame is an error, not an allocation).
pub(crate) fn read_frame(input: &mut impl Read, max: usize) -> io::Result<Vec<u8>> {
    let mut len = [0u8; 4];
    input.read_exact(&mut len)?;
    let n = u32::from_le_bytes(len) as usize;
    if n > max {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("reply of {n} bytes exceeds the {max}-byte bound"),
        ));
    }
    let mut buf = vec![0u8; n];
    input.read_exact(&mut buf)?;
    Ok(buf)
}

/// The body of a load request: `{"id": key, "trace": <the paper's dict>}`.
pub(crate) fn load_body(key: &str, trace: &Trace) -> Vec<u8> {
    let mut buf = Vec::with_capacity(64 + trace.frame_rows() * 256);
    buf.extend_from_slice(b"{\"id\":");
    serde_json::to_writer(&mut buf, key).expect("a string serialises");
    buf.extend_from_slice(b",\"trace\":");
    // Streamed in the paper's layout, without building a JSON tree first.
    crate::trace::json::write_trace(&mut buf, trace, false).expect("a trace always serialises");
    buf.push(b'}');
    buf
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
fn pool_columns(key: &str, trace: &Trace) -> Option<Vec<u8>> {
    use crate::trace::{Body, Env};
    if trace.env != Env::Pooltool {
        return None;
    }
    let n_obj = trace.frame_rows();
    let mut ids = Vec::with_capacity(n_obj);
    let mut kinds = Vec::with_capacity(n_obj);
    let mut codes = Vec::with_capacity(n_obj);
    let mut states = Vec::with_capacity(n_obj);
    let mut block: Vec<u8> = Vec::with_capacity((trace.timesteps.len() + 10 * n_obj) * 8);
    for ts in &trace.timesteps {
        block.extend_from_slice(&ts.t.to_le_bytes());
    }
    for ts in &trace.timesteps {
        for o in &ts.objects {
            let Body::Pool(b) = &o.body else { return None };
            if !o.extra.is_empty() {
                return None;
            }
            ids.push(b.ball_id.as_str());
            kinds.push(b.kind.as_str());
            codes.push(b.motion_state_code);
            states.push(b.motion_state.as_str());
            for v in b
                .position
                .iter()
                .chain(&b.velocity)
                .chain(&b.angular_velocity)
            {
                block.extend_from_slice(&v.to_le_bytes());
            }
            block.extend_from_slice(&b.radius.to_le_bytes());
        }
    }
    let step_extra: Option<Vec<&crate::trace::JsonMap>> = trace
        .timesteps
        .iter()
        .any(|t| !t.extra.is_empty())
        .then(|| trace.timesteps.iter().map(|t| &t.extra).collect());
    let shell = Trace {
        trace_id: trace.trace_id.clone(),
        env: trace.env,
        task_id: trace.task_id.clone(),
        timesteps: Vec::new(),
        events: trace.events.clone(),
        outcome: trace.outcome.clone(),
        extra: trace.extra.clone(),
    };
    let header = serde_json::json!({
        "id": key,
        "trace": crate::trace::json::to_value(&shell),
        "n": trace.timesteps.iter().map(|t| t.objects.len()).collect::<Vec<_>>(),
        "index": trace.timesteps.iter().map(|t| t.index).collect::<Vec<_>>(),
        "ball_id": ids,
        "kind": kinds,
        "code": codes,
        "state": states,
        "step_extra": step_extra,
    });
    let header = serde_json::to_vec(&header).ok()?;
    let mut body = Vec::with_capacity(4 + header.len() + block.len());
    body.extend_from_slice(&u32::try_from(header.len()).ok()?.to_le_bytes());
    body.extend_from_slice(&header);
    body.extend_from_slice(&block);
    Some(body)
}

/// The body of a compile request.
pub(crate) fn compile_body(id: &str, code: &str) -> Vec<u8> {
    serde_json::to_vec(&serde_json::json!({"id": id, "code": code})).expect("serialises")
}

/// The body of a run request: run each detector in turn on the trace; one reply per detector.
pub(crate) fn run_body(detectors: &[&str], trace: &str) -> Vec<u8> {
    serde_json::to_vec(&serde_json::json!({"detectors": detectors, "trace": trace}))
        .expect("serialises")
}

/// The body of an evict request.
pub(crate) fn evict_body(keys: &[String]) -> Vec<u8> {
    serde_json::to_vec(&serde_json::json!({"ids": keys})).expect("serialises")
}

/// Parses a reply.
pub(crate) fn parse_reply(bytes: &[u8]) -> Result<Value, String> {
    serde_json::from_slice(bytes).map_err(|e| format!("unreadable reply from the worker: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip_and_oversized_frames_are_refused() {
        let mut buf = Vec::new();
        write_frame(&mut buf, RUN, b"{}").unwrap();
        assert_eq!(&buf[..4], &3u32.to_le_bytes());
        let back = read_frame(&mut &buf[..], 16).unwrap();
        assert_eq!(back, b"R{}");
        let err = read_frame(&mut &buf[..], 2).unwrap_err();
        assert!(err.to_string().contains("exceeds"));
    }
}
