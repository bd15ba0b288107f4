//! The framed protocol between the Rust side and a worker (`worker.py` documents the messages).
//!
//! A frame is a 4-byte little-endian length followed by that many bytes; a request's first byte is its
//! type (`T` load trace, `P` load a pooltool trace by columns, `E` evict traces, `C` compile, `R` run)
//! and the rest JSON (or columns, for `P`). Replies are JSON, except a run reply whose patterns travel in
//! CPython's `marshal` format (`M`, read by `marshal.rs`). A run request gets one reply per detector, in
//! order; an evict request gets none (it is sent behind a run request); every other request gets one
//! reply.
//!
//! Owns the request bodies and the one parser of replies: [`parse_reply`] turns a frame into a
//! [`WorkerReply`] (done, or failed with a typed [`WorkerError`] that maps to a
//! [`DetectorError`]), so no caller reads reply JSON by key (only the spawner reads the ready
//! message's fields, through [`parse_json`]). Does not own the pipes, timeouts or restarts
//! (`worker.rs`, `pool.rs`).

use std::io::{self, Write};

use serde_json::Value;

use super::error::DetectorError;
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
    crate::trace::json::write_trace_shell(&mut buf, trace).expect("a trace always serialises");
    buf.extend_from_slice(b",\"steps\":");
    crate::trace::json::write_steps_sharing_repeats(&mut buf, &trace.timesteps)
        .expect("a trace always serialises");
    buf.push(b'}');
    buf
}

/// Runs of fewer detectors than this get a pooltool trace with its steps' objects built when first
/// read; larger runs get it built whole at load. The whole built-in library (12 detectors) reads
/// about two thirds of a trace's ball states (`ball slowing` walks every rolling stretch), and
/// building those a step at a time costs more than building all of them in one pass; a reward
/// program's 1–4 detectors read far fewer (`docs/performance.md`, "Lazy step objects").
pub(crate) const LAZY_BELOW: usize = 6;

/// The request that loads `trace` under `key` for a run of `detectors` detectors: by columns for a
/// pooltool trace whose objects carry no unknown fields (floats travel as raw little-endian doubles,
/// 5-8× cheaper for the worker than parsing them from JSON; objects built lazily when `detectors` is
/// under [`LAZY_BELOW`]), else the paper's JSON.
pub(crate) fn load_request(key: &str, trace: &Trace, detectors: usize) -> (u8, Vec<u8>) {
    use crate::trace::{Body, Env, PoolSteps};
    let plain = trace.env == Env::Pooltool
        && trace.timesteps.iter().all(|t| {
            t.objects
                .iter()
                .all(|o| matches!(o.body, Body::Pool(_)) && o.extra.is_empty())
        });
    let body = plain
        .then(|| {
            pool_columns(
                key,
                trace,
                &PoolSteps::of_trace(trace),
                detectors < LAZY_BELOW,
            )
        })
        .flatten();
    match body {
        Some(body) => (LOAD_POOL, body),
        None => (LOAD_TRACE, load_body(key, trace)),
    }
}

/// The request that loads a trace read from a run's tables: [`load_request`]'s bytes, written
/// straight from the frame rows when they are still columns (no `Object` built per ball per step).
pub(crate) fn load_request_framed(
    key: &str,
    trace: &crate::trace::FramedTrace,
    detectors: usize,
) -> (u8, Vec<u8>) {
    let Some(rows) = trace.pool_rows() else {
        // Its objects are built: the shell is the whole trace.
        return load_request(key, trace.shell(), detectors);
    };
    match pool_columns(key, trace.shell(), &rows.steps(), detectors < LAZY_BELOW) {
        Some(body) => (LOAD_POOL, body),
        // Too large for the columns' u32 counts: the paper's JSON of the whole trace, as
        // `load_request` sends it (its objects were checked when the trace was read).
        None => match trace.clone().into_trace() {
            Ok(whole) => load_request(key, &whole, detectors),
            Err(_) => load_request(key, trace.shell(), detectors),
        },
    }
}

/// `<u32 header length><header JSON><f64 block>`; see `load_pool_columns` in worker.py. `shell`
/// gives the trace's fields and its steps' indices, times and unknown fields, `steps` its balls
/// (from the same trace's objects, or from its frame rows: the bytes are the same).
///
/// Most balls sit still most of the time (about 70 % of the object rows of a random 9-ball shot repeat
/// the row before), and the trace the worker builds is read-only, so a ball whose state is bit-for-bit
/// the previous step's (same slot, id, kind, state and ten floats) is not sent again: the worker reuses
/// that step's dict. Every new object gets the next number (its *state*, counted from 0 in step order).
///
/// The header holds the trace without timesteps; each step's index; a table of the distinct (ball id,
/// kind, state code, state); the counts of states (`states`) and of `u32` words in the rows block
/// (`words`); each step's extra fields, when any step has some; `lazy`: whether the worker builds a
/// step's objects only when code first reads them. The block holds, in order:
/// - every step's `t` (f64);
/// - each state's position, velocity and angular velocity (three 3-vectors of f64), then each
///   state's radius (f64);
/// - each state's row in the (id, kind, state) table (u32);
/// - each step's first new state, and after the last step the number of states (u32): the states new
///   in a run of steps are one contiguous range, which the worker builds together;
/// - each step's *start* (u32): where its row begins in the rows block;
/// - the rows (u32): a row is the object count `n` followed by the state of each of the `n` slots. A
///   step whose objects all repeat the previous step's shares that step's row (the same start), so the
///   worker can build any step's objects on its own, without the steps before it, and give steps that
///   share a row one tuple, as it always has (`load_pool_columns` in worker.py).
///
/// All numbers are little-endian.
fn pool_columns(
    key: &str,
    shell: &Trace,
    steps: &crate::trace::PoolSteps<'_>,
    lazy: bool,
) -> Option<Vec<u8>> {
    use crate::trace::BallView;
    if steps.len() != shell.timesteps.len() {
        return None;
    }
    // The floats first: a moving ball differs there, so its strings are never compared.
    fn same(a: &BallView<'_>, b: &BallView<'_>) -> bool {
        let bits = |x: &BallView<'_>| {
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
        bits(a) == bits(b)
            && a.motion_state_code == b.motion_state_code
            && a.ball_id == b.ball_id
            && a.kind == b.kind
            && a.motion_state == b.motion_state
    }
    let mut protos: Vec<(&str, &str, i64, &str)> = Vec::new();
    let mut proto: Vec<u32> = Vec::new();
    let mut starts: Vec<u32> = Vec::with_capacity(steps.len());
    let mut firsts: Vec<u32> = Vec::with_capacity(steps.len() + 1);
    let mut rows: Vec<u32> = Vec::new();
    // Each slot's current state.
    let mut current: Vec<u32> = Vec::new();
    let mut vecs: Vec<u8> = Vec::new();
    let mut radii: Vec<u8> = Vec::new();
    let mut prev: Vec<BallView<'_>> = Vec::new();
    let mut row: Vec<BallView<'_>> = Vec::new();
    // Each slot's last row in `protos`.
    let mut last: Vec<Option<usize>> = Vec::new();
    for k in 0..steps.len() {
        row.clear();
        row.extend(steps.balls(k));
        firsts.push(u32::try_from(proto.len()).ok()?);
        let all_new = prev.len() != row.len();
        if all_new {
            current.clear();
            current.resize(row.len(), 0);
        }
        let mut changed = false;
        for (j, b) in row.iter().enumerate() {
            if !all_new && same(&prev[j], b) {
                continue;
            }
            changed = true;
            current[j] = u32::try_from(proto.len()).ok()?;
            let key = (b.ball_id, b.kind, b.motion_state_code, b.motion_state);
            // The slot's previous row usually has the same (id, kind, state): try it before the
            // table (a linear search comparing strings).
            let k = match last.get(j).copied().flatten().filter(|&k| protos[k] == key) {
                Some(k) => k,
                None => match protos.iter().position(|p| *p == key) {
                    Some(k) => k,
                    None => {
                        protos.push(key);
                        protos.len() - 1
                    }
                },
            };
            if last.len() <= j {
                last.resize(j + 1, None);
            }
            last[j] = Some(k);
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
        // A new row when any slot changed (or the count did, or this is the first step), else the
        // previous step's.
        if all_new || changed || starts.is_empty() {
            let start = u32::try_from(rows.len()).ok()?;
            rows.push(u32::try_from(current.len()).ok()?);
            rows.extend_from_slice(&current);
            starts.push(start);
        } else {
            starts.push(*starts.last().expect("not the first step"));
        }
        std::mem::swap(&mut prev, &mut row);
    }
    let step_extra: Option<Vec<&crate::trace::JsonMap>> = shell
        .timesteps
        .iter()
        .any(|t| !t.extra.is_empty())
        .then(|| shell.timesteps.iter().map(|t| &t.extra).collect());
    let mut header = Vec::with_capacity(4096 + 4 * proto.len());
    header.extend_from_slice(b"{\"id\":");
    serde_json::to_writer(&mut header, key).ok()?;
    header.extend_from_slice(b",\"trace\":");
    crate::trace::json::write_trace_shell(&mut header, shell).ok()?;
    let rest = serde_json::json!({
        "index": shell.timesteps.iter().map(|t| t.index).collect::<Vec<_>>(),
        "protos": protos,
        "states": proto.len(),
        "words": rows.len(),
        "lazy": lazy,
        "step_extra": step_extra,
    });
    header.push(b',');
    let rest = serde_json::to_vec(&rest).ok()?;
    header.extend_from_slice(&rest[1..]);
    let n_steps = shell.timesteps.len();
    firsts.push(u32::try_from(proto.len()).ok()?);
    let words = proto.len() + firsts.len() + starts.len() + rows.len();
    let mut body =
        Vec::with_capacity(4 + header.len() + 8 * n_steps + vecs.len() + radii.len() + 4 * words);
    body.extend_from_slice(&u32::try_from(header.len()).ok()?.to_le_bytes());
    body.extend_from_slice(&header);
    for ts in &shell.timesteps {
        body.extend_from_slice(&ts.t.to_le_bytes());
    }
    body.extend_from_slice(&vecs);
    body.extend_from_slice(&radii);
    for w in proto.iter().chain(&firsts).chain(&starts).chain(&rows) {
        body.extend_from_slice(&w.to_le_bytes());
    }
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

/// A worker's reply to a load, compile or run request, parsed once: `{"ok": true, ...}` or
/// `{"ok": false, "error": {...}}` (anything without `"ok": true` is a failure).
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum WorkerReply {
    /// The request succeeded. Fields a reply does not carry are 0, empty or null.
    Done {
        /// Wall seconds of `find_pattern` (run replies).
        wall: f64,
        /// CPU seconds of `find_pattern` (run replies).
        cpu: f64,
        /// Seconds the worker spent building the trace's dicts (load replies).
        build: f64,
        /// What the detector printed (run replies).
        printed: String,
        /// The patterns it returned, not yet validated (run replies).
        patterns: Value,
    },
    /// The request failed.
    Failed {
        /// Wall seconds at the top level of the reply (0: the worker puts a call's times inside
        /// `error`).
        wall: f64,
        /// CPU seconds at the top level of the reply.
        cpu: f64,
        /// What went wrong.
        error: WorkerError,
    },
}

impl WorkerReply {
    /// The typed form of a JSON reply.
    pub(crate) fn from_json(mut v: Value) -> Self {
        let wall = v["wall"].as_f64().unwrap_or(0.0);
        let cpu = v["cpu"].as_f64().unwrap_or(0.0);
        if v["ok"] == Value::Bool(true) {
            WorkerReply::Done {
                wall,
                cpu,
                build: v["build"].as_f64().unwrap_or(0.0),
                printed: v["printed"].as_str().unwrap_or_default().to_string(),
                patterns: v["patterns"].take(),
            }
        } else {
            WorkerReply::Failed {
                wall,
                cpu,
                error: WorkerError::from_json(&v["error"]),
            }
        }
    }

    /// Wall and CPU seconds of the call.
    pub(crate) fn times(&self) -> (f64, f64) {
        match self {
            WorkerReply::Done { wall, cpu, .. } | WorkerReply::Failed { wall, cpu, .. } => {
                (*wall, *cpu)
            }
        }
    }
}

/// The `error` object of a failed reply (`_error` in worker.py); missing fields are empty.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct WorkerError {
    /// `syntax`, `forbidden`, `no_find_pattern`, `runtime`, `memory`, `invalid_output`, or another
    /// word the Rust side does not know.
    pub category: String,
    /// The message.
    pub message: String,
    /// 1-based line in the detector's source, when known.
    pub line: Option<u32>,
    /// Column, when known.
    pub column: Option<u32>,
    /// The Python exception's type (runtime errors).
    pub exception: Option<String>,
    /// Where in the output an invalid output went wrong (`$` when not given).
    pub path: String,
    /// Whether the worker exits after this error.
    pub fatal: bool,
}

impl WorkerError {
    fn from_json(e: &Value) -> Self {
        let s = |k: &str| e[k].as_str().unwrap_or_default().to_string();
        let n = |k: &str| e[k].as_u64().map(|v| v as u32);
        WorkerError {
            category: s("category"),
            message: s("message"),
            line: n("line"),
            column: n("column"),
            exception: e["exception"].as_str().map(str::to_string),
            path: e["path"].as_str().unwrap_or("$").to_string(),
            fatal: e["fatal"] == Value::Bool(true),
        }
    }

    /// Whether the worker is gone after this error (it exits after a fatal error, and after running
    /// out of memory).
    pub(crate) fn ends_worker(&self) -> bool {
        self.fatal || self.category == "memory"
    }

    /// The typed error; a memory error reports the sandbox's `memory_bytes` limit.
    pub(crate) fn to_detector_error(&self, memory_bytes: u64) -> DetectorError {
        let message = self.message.clone();
        match self.category.as_str() {
            "syntax" => DetectorError::Syntax {
                message,
                line: self.line,
                column: self.column,
            },
            "forbidden" => DetectorError::Forbidden {
                message,
                line: self.line,
                column: self.column,
            },
            "no_find_pattern" => DetectorError::NoFindPattern { message },
            "runtime" => DetectorError::Runtime {
                exception: self.exception.clone(),
                message,
                line: self.line,
            },
            "memory" => DetectorError::Memory {
                limit_bytes: memory_bytes,
            },
            "invalid_output" => DetectorError::InvalidOutput {
                path: self.path.clone(),
                message,
            },
            other => DetectorError::Crashed {
                message: format!("worker error {other}: {message}"),
            },
        }
    }
}

/// Parses a reply frame as JSON, untyped: for the worker's ready message, whose fields only the
/// spawner reads. Every other reply goes through [`parse_reply`].
pub(crate) fn parse_json(bytes: &[u8]) -> Result<Value, String> {
    serde_json::from_slice(bytes).map_err(|e| format!("unreadable reply from the worker: {e}"))
}

/// Parses a reply: JSON, or a run reply with marshalled patterns. The patterns are decoded under a
/// budget of `max_output_bytes`; an output the decoder refuses becomes an `invalid_output` failure
/// with its path, as the worker's own checks produce.
pub(crate) fn parse_reply(bytes: &[u8], max_output_bytes: usize) -> Result<WorkerReply, String> {
    if bytes.first() != Some(&MARSHAL_REPLY) {
        return parse_json(bytes).map(WorkerReply::from_json);
    }
    let bad = || "unreadable reply from the worker: a truncated marshal frame".to_string();
    let (wall, cpu) = marshal_times(bytes).ok_or_else(bad)?;
    let n = bytes
        .get(17..21)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
        .ok_or_else(bad)?;
    let printed = bytes.get(21..21 + n).ok_or_else(bad)?;
    Ok(
        match super::marshal::decode(&bytes[21 + n..], max_output_bytes) {
            Ok(patterns) => WorkerReply::Done {
                wall,
                cpu,
                build: 0.0,
                printed: String::from_utf8_lossy(printed).into_owned(),
                patterns,
            },
            Err(e) => WorkerReply::Failed {
                wall,
                cpu,
                error: WorkerError {
                    category: "invalid_output".into(),
                    message: e.message,
                    path: e.path,
                    ..WorkerError::default()
                },
            },
        },
    )
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

    #[test]
    fn replies_parse_into_done_or_failed_with_their_fields() {
        let done = parse_reply(
            br#"{"ok":true,"wall":0.5,"cpu":0.25,"printed":"hi","patterns":[1]}"#,
            0,
        )
        .unwrap();
        assert_eq!(
            done,
            WorkerReply::Done {
                wall: 0.5,
                cpu: 0.25,
                build: 0.0,
                printed: "hi".into(),
                patterns: serde_json::json!([1]),
            }
        );
        assert_eq!(done.times(), (0.5, 0.25));
        let failed = parse_reply(
            br#"{"ok":false,"error":{"category":"runtime","message":"boom","line":3,"exception":"KeyError","wall":1.0}}"#,
            0,
        )
        .unwrap();
        let WorkerReply::Failed { wall, error, .. } = failed else {
            panic!("{failed:?}");
        };
        assert_eq!(wall, 0.0);
        assert!(!error.ends_worker());
        assert_eq!(
            error.to_detector_error(7),
            DetectorError::Runtime {
                exception: Some("KeyError".into()),
                message: "boom".into(),
                line: Some(3),
            }
        );
        // No "ok": a failure; a memory error ends the worker and reports the limit.
        let WorkerReply::Failed { error, .. } =
            parse_reply(br#"{"error":{"category":"memory"}}"#, 0).unwrap()
        else {
            panic!("not a failure");
        };
        assert!(error.ends_worker());
        assert_eq!(
            error.to_detector_error(7),
            DetectorError::Memory { limit_bytes: 7 }
        );
        assert!(parse_reply(b"{", 0).is_err());
    }

    /// What the worker does with a `P` frame, seen from inside: `load_pool_columns` called directly
    /// (the worker's code without its last line, `main()`, so it neither locks down nor serves).
    fn in_worker(frame: &[u8], check: &str) -> serde_json::Value {
        use std::process::{Command, Stdio};
        let code = super::super::worker::WORKER_PY
            .trim_end()
            .strip_suffix("main()")
            .expect("worker.py ends by calling main()");
        let script =
            format!("{code}\nFRAME = b''.join(iter(lambda: _IN.read(1 << 20), b''))\n{check}\n");
        let mut child = Command::new("python3")
            .args(["-s", "-S", "-B", "-c", &script])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("python3 runs");
        child.stdin.take().unwrap().write_all(frame).unwrap();
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "{out:?}");
        serde_json::from_slice(&out.stdout).unwrap()
    }

    type Request = (u8, Vec<u8>);

    /// The load request of a trace read from its rows, and of the same trace rebuilt whole.
    fn both_requests(trace: &Trace, detectors: usize) -> (Request, Request, bool) {
        use crate::trace::{FramedTrace, TraceBatchBuilder, TraceRows, decode_trace};
        let b = TraceBatchBuilder::from_trace(trace, "scene", "test").unwrap();
        let rows = TraceRows {
            env: trace.env,
            trace: &b.traces,
            timesteps: &b.timesteps,
            frames: &b.frames,
            events: &b.events,
        };
        let framed = FramedTrace::decode(&rows).unwrap();
        let whole = decode_trace(&rows).unwrap();
        (
            load_request_framed("k", &framed, detectors),
            load_request("k", &whole, detectors),
            framed.is_columns(),
        )
    }

    #[test]
    fn a_trace_whose_balls_are_still_columns_loads_with_the_bytes_its_objects_give() {
        let config = crate::envs::pool::PoolConfig::default_7ft();
        let opts = crate::envs::pool::TraceOptions { dt: 0.02 };
        for seed in [3, 11] {
            let mut trace = crate::envs::pool::dataset_trace(&config, seed, 0, &opts).unwrap();
            for detectors in [1, 12] {
                let (framed, whole, columns) = both_requests(&trace, detectors);
                assert!(columns);
                assert_eq!(framed.0, LOAD_POOL);
                assert!(framed == whole, "seed {seed}, {detectors} detectors");
            }
            // Unknown fields on a step travel in the header; on a ball, the trace goes as JSON.
            trace.timesteps[2]
                .extra
                .insert("camera".into(), serde_json::json!("top"));
            let (framed, whole, columns) = both_requests(&trace, 12);
            assert!(columns && framed.0 == LOAD_POOL && framed == whole);
            trace.timesteps[4].objects[0]
                .extra
                .insert("chalk".into(), serde_json::json!(true));
            let (framed, whole, columns) = both_requests(&trace, 12);
            assert!(!columns && framed.0 == LOAD_TRACE && framed == whole);
        }
        // Balls that come and go (a step with fewer objects) and strings that change.
        let mut trace = crate::envs::pool::dataset_trace(&config, 5, 0, &opts).unwrap();
        trace.timesteps[6].objects.truncate(3);
        if let crate::trace::Body::Pool(b) = &mut trace.timesteps[7].objects[1].body {
            b.ball_id = "99".into();
            b.kind = "ghost".into();
        }
        let (framed, whole, columns) = both_requests(&trace, 3);
        assert!(columns && framed == whole);
    }

    #[test]
    fn a_pool_trace_loads_with_no_step_objects_built_and_builds_each_step_alone() {
        let config = crate::envs::pool::PoolConfig::default_7ft();
        let trace = crate::envs::pool::dataset_trace(
            &config,
            1,
            0,
            &crate::envs::pool::TraceOptions { dt: 0.05 },
        )
        .unwrap();
        let (kind, body) = load_request("k", &trace, 1);
        assert_eq!(kind, LOAD_POOL);
        let mut frame = vec![kind];
        frame.extend(body);
        let got = in_worker(
            &frame,
            r#"
key, trace = load_pool_columns(FRAME)
steps = trace["timesteps"]
r = {"steps": len(steps), "lazy": sum(type(s) is LazyStep for s in steps)}
k = len(steps) // 2
steps[k]["t"], steps[k].get("index"), len(steps[k]), "objects" in steps[k], steps[k].get("zz")
r["after_other_reads"] = type(steps[k]).__name__ + "/" + str(type(steps[k]) is LazyStep)
builder = steps[k]._lazy[0]
objs = steps[k]["objects"]
r["built"] = [i for i, s in enumerate(steps) if type(s) is not LazyStep]
r["class"] = type(steps[k]) is FrozenDict and not hasattr(steps[k], "_lazy")
r["states"] = sum(b is not None for b in builder.balls)
r["all_states"] = len(builder.balls)
r["objects"] = len(objs)
_OUT.write(json.dumps(r).encode())
"#,
        );
        let m = trace.timesteps.len();
        assert_eq!(got["steps"], m);
        assert_eq!(got["lazy"], m, "no step is built by loading");
        assert_eq!(got["after_other_reads"], "FrozenDict/True");
        assert_eq!(got["built"], serde_json::json!([m / 2]));
        assert_eq!(got["class"], true, "a built step is a plain FrozenDict");
        assert_eq!(got["objects"], trace.timesteps[m / 2].objects.len());
        // Only the ball dicts of that step's block of steps (and the older states its balls hold).
        let (states, all) = (got["states"].as_u64(), got["all_states"].as_u64());
        assert!(states >= got["objects"].as_u64() && states < all, "{got}");
    }

    #[test]
    fn only_code_that_can_hold_the_dict_type_gets_every_step_built() {
        let flagged = [
            "dict.get(s, 'objects')",
            "g = dict",
            "f([dict])",
            "isinstance = f\nisinstance(s, dict)",
            "def f(isinstance):\n    return isinstance(s, dict)",
            "f(isinstance=g)\nisinstance(s, dict)",
            "for isinstance in x:\n    pass\nisinstance(s, dict)",
            "match s:\n    case isinstance:\n        isinstance(s, dict)",
            "match s:\n    case dict():\n        pass",
            "isinstance(s, *[dict])",
            "isinstance(s, [dict])",
            "dict = 1",
        ];
        let not_flagged = [
            "dict(s)",
            "dict(**s, a=1)",
            "isinstance(s, dict)",
            "isinstance(s, (list, dict))",
            "issubclass(c, dict)",
            "s.dict",
            "'dict.get(s)'",
            "\"isinstance = 1\"\nisinstance(s, dict)",
            "lambda dict: dict(s)",
        ];
        let cases: Vec<&str> = flagged.iter().chain(&not_flagged).copied().collect();
        let got = in_worker(
            b"",
            &format!(
                "_OUT.write(json.dumps([reads_dict_unbound(ast.parse(c)) for c in {}]).encode())",
                serde_json::to_string(&cases).unwrap()
            ),
        );
        let want = flagged
            .iter()
            .map(|_| true)
            .chain(not_flagged.iter().map(|_| false));
        for ((c, g), w) in cases.iter().zip(got.as_array().unwrap()).zip(want) {
            assert_eq!(g, &serde_json::Value::Bool(w), "{c}");
        }
    }

    #[test]
    fn a_marshal_reply_carries_its_times_and_printed_text() {
        let mut frame = vec![MARSHAL_REPLY];
        frame.extend(1.5f64.to_le_bytes());
        frame.extend(0.5f64.to_le_bytes());
        frame.extend(2u32.to_le_bytes());
        frame.extend(b"ok");
        frame.extend([b'[', 0, 0, 0, 0]); // marshal: an empty list
        let reply = parse_reply(&frame, 1 << 20).unwrap();
        assert_eq!(reply.times(), (1.5, 0.5));
        match reply {
            WorkerReply::Done {
                printed, patterns, ..
            } => {
                assert_eq!(printed, "ok");
                assert_eq!(patterns, serde_json::json!([]));
            }
            other => panic!("{other:?}"),
        }
        assert!(parse_reply(&frame[..10], 1 << 20).is_err());
    }
}
