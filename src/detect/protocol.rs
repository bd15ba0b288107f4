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

/// The body of a compile request.
pub(crate) fn compile_body(id: &str, code: &str) -> Vec<u8> {
    serde_json::to_vec(&serde_json::json!({"id": id, "code": code})).expect("serialises")
}

/// The body of a run request.
pub(crate) fn run_body(detector: &str, trace: &str) -> Vec<u8> {
    serde_json::to_vec(&serde_json::json!({"detector": detector, "trace": trace}))
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
