//! The `llm_calls` table: one row per HTTP attempt (and per replayed answer), appended to the run as
//! small Parquet files, and read back for replay.
//!
//! Parquet files cannot grow, so "appending" means adding files: a client buffers rows and writes
//! `llm_calls/llm-<session>.<nnnnn>.parquet` (atomically, through [`ParquetSink`]) every
//! [`FLUSH_EVERY`] rows, as soon as the oldest buffered row is [`FLUSH_AFTER`] old (checked on every
//! row and by the client's watch thread, `llm::waiting`, several times a second — so also while the
//! client waits on a hung request or a `Retry-After`), on `CallLog::flush` and when dropped. A killed
//! process loses at most the attempts that ended in its last second or so; no reader ever sees a
//! partial file. Every text column has the API key
//! scrubbed before it is stored.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::Mutex;
use std::time::{SystemTime, UNIX_EPOCH};

use arrow::array::{
    Array, ArrayRef, AsArray, BooleanArray, Float64Array, Int32Array, Int64Array, RecordBatch,
    StringArray, TimestampMillisecondArray, UInt64Array,
};
use arrow::datatypes::{
    DataType, Field, Float64Type, Int32Type, Int64Type, Schema, SchemaRef, TimeUnit,
    TimestampMillisecondType, UInt64Type,
};

use super::error::LlmError;
use crate::store::{ParquetSink, RunDir, read_file, shard_file_name};

/// The table's name (its folder in the run).
pub const TABLE: &str = "llm_calls";

/// Rows buffered before a file is written.
pub const FLUSH_EVERY: usize = 16;

/// The longest a recorded call waits in the buffer before it is written (a kill loses no older call).
pub const FLUSH_AFTER: std::time::Duration = std::time::Duration::from_secs(1);

/// The outcome of one attempt, as stored in `llm_calls.status`.
pub mod status {
    /// A chat completion was received and parsed.
    pub const OK: &str = "ok";
    /// The endpoint answered with an HTTP error status.
    pub const HTTP_ERROR: &str = "http_error";
    /// No complete answer within the timeout.
    pub const TIMEOUT: &str = "timeout";
    /// The endpoint could not be reached or the connection broke.
    pub const CONNECTION: &str = "connection";
    /// 200, but not a chat completion.
    pub const BAD_RESPONSE: &str = "bad_response";
}

/// One row of `llm_calls`.
#[derive(Clone, Debug, PartialEq)]
pub struct CallRecord {
    /// `<session>-<n>`: the logical call (retries share it).
    pub call_id: String,
    /// The client session (one per client: start time and process id).
    pub session: String,
    /// 1-based attempt number; 0 for a replayed answer.
    pub attempt: i32,
    /// The caller's purpose tag.
    pub purpose: String,
    /// The model.
    pub model: String,
    /// The endpoint without credentials or query (empty when replayed without one).
    pub endpoint: String,
    /// SHA-256 of the request body (model, messages, sampling parameters, seed): the replay key.
    pub request_hash: String,
    /// SHA-256 of the messages alone.
    pub prompt_hash: String,
    /// The request's seed.
    pub seed: Option<u64>,
    /// The JSON body sent (the key is never in it; it travels in a header).
    pub request_json: String,
    /// The raw answer body, if one arrived.
    pub response_json: Option<String>,
    /// The assistant's text, for `ok` rows.
    pub content: Option<String>,
    /// See [`status`].
    pub status: String,
    /// The HTTP status, if an answer arrived.
    pub http_status: Option<i32>,
    /// What went wrong.
    pub error: Option<String>,
    /// Prompt tokens (0 unless `ok`).
    pub tokens_in: i64,
    /// Completion tokens (0 unless `ok`).
    pub tokens_out: i64,
    /// Token counts are estimates (the server sent no `usage`).
    pub usage_estimated: bool,
    /// Wall time of the attempt (ms).
    pub latency_ms: f64,
    /// The row records an answer served from a recording.
    pub replayed: bool,
    /// When the attempt started (Unix ms).
    pub started_at_ms: i64,
}

/// The Arrow schema of `llm_calls` (documented in `docs/schema.md` and `docs/llm.md`).
pub fn schema() -> SchemaRef {
    let s = |n: &str, null: bool| Field::new(n, DataType::Utf8, null);
    Arc::new(Schema::new(vec![
        s("call_id", false),
        s("session", false),
        Field::new("attempt", DataType::Int32, false),
        s("purpose", false),
        s("model", false),
        s("endpoint", false),
        s("request_hash", false),
        s("prompt_hash", false),
        Field::new("seed", DataType::UInt64, true),
        s("request_json", false),
        s("response_json", true),
        s("content", true),
        s("status", false),
        Field::new("http_status", DataType::Int32, true),
        s("error", true),
        Field::new("tokens_in", DataType::Int64, false),
        Field::new("tokens_out", DataType::Int64, false),
        Field::new("usage_estimated", DataType::Boolean, false),
        Field::new("latency_ms", DataType::Float64, false),
        Field::new("replayed", DataType::Boolean, false),
        Field::new(
            "started_at",
            DataType::Timestamp(TimeUnit::Millisecond, Some("UTC".into())),
            false,
        ),
        s("annotrace_version", false),
    ]))
}

/// Record batch of rows.
pub fn batch(rows: &[CallRecord]) -> Result<RecordBatch, arrow::error::ArrowError> {
    let st = |f: fn(&CallRecord) -> &str| -> ArrayRef {
        Arc::new(StringArray::from_iter_values(rows.iter().map(f)))
    };
    let opt = |f: fn(&CallRecord) -> Option<&str>| -> ArrayRef {
        Arc::new(rows.iter().map(f).collect::<StringArray>())
    };
    RecordBatch::try_new(
        schema(),
        vec![
            st(|r| &r.call_id),
            st(|r| &r.session),
            Arc::new(Int32Array::from_iter_values(rows.iter().map(|r| r.attempt))),
            st(|r| &r.purpose),
            st(|r| &r.model),
            st(|r| &r.endpoint),
            st(|r| &r.request_hash),
            st(|r| &r.prompt_hash),
            Arc::new(rows.iter().map(|r| r.seed).collect::<UInt64Array>()),
            st(|r| &r.request_json),
            opt(|r| r.response_json.as_deref()),
            opt(|r| r.content.as_deref()),
            st(|r| &r.status),
            Arc::new(rows.iter().map(|r| r.http_status).collect::<Int32Array>()),
            opt(|r| r.error.as_deref()),
            Arc::new(Int64Array::from_iter_values(
                rows.iter().map(|r| r.tokens_in),
            )),
            Arc::new(Int64Array::from_iter_values(
                rows.iter().map(|r| r.tokens_out),
            )),
            Arc::new(
                rows.iter()
                    .map(|r| Some(r.usage_estimated))
                    .collect::<BooleanArray>(),
            ),
            Arc::new(Float64Array::from_iter_values(
                rows.iter().map(|r| r.latency_ms),
            )),
            Arc::new(
                rows.iter()
                    .map(|r| Some(r.replayed))
                    .collect::<BooleanArray>(),
            ),
            Arc::new(
                TimestampMillisecondArray::from_iter_values(rows.iter().map(|r| r.started_at_ms))
                    .with_timezone("UTC"),
            ),
            Arc::new(StringArray::from_iter_values(
                rows.iter().map(|_| crate::VERSION),
            )),
        ],
    )
}

/// Reads every row of a run's `llm_calls` table, ordered by start time, call and attempt.
pub fn read_calls(run: &RunDir) -> Result<Vec<CallRecord>, LlmError> {
    let mut out = Vec::new();
    for file in run.table(TABLE)?.files {
        for b in read_file(&file.path)? {
            rows_of(&b, &file.path, &mut out)?;
        }
    }
    out.sort_by(|a, b| order_key(a).cmp(&order_key(b)));
    Ok(out)
}

/// Start time, then session and the call's number within it (numerically: `s-10` after `s-9`), then
/// attempt.
fn order_key(r: &CallRecord) -> (i64, &str, u64, i32) {
    let n = r
        .call_id
        .rsplit_once('-')
        .and_then(|(_, n)| n.parse().ok())
        .unwrap_or(0);
    (r.started_at_ms, r.session.as_str(), n, r.attempt)
}

fn rows_of(
    b: &RecordBatch,
    path: &std::path::Path,
    out: &mut Vec<CallRecord>,
) -> Result<(), LlmError> {
    let col = |name: &str, ty: &DataType| -> Result<&ArrayRef, LlmError> {
        let c = b.column_by_name(name).ok_or_else(|| LlmError::Table {
            path: path.to_path_buf(),
            message: format!("no column {name:?}"),
        })?;
        let same = match (c.data_type(), ty) {
            (DataType::Timestamp(a, _), DataType::Timestamp(b, _)) => a == b,
            (a, b) => a == b,
        };
        if !same {
            return Err(LlmError::Table {
                path: path.to_path_buf(),
                message: format!("column {name:?} is {}, expected {ty}", c.data_type()),
            });
        }
        Ok(c)
    };
    let s = |name: &str| col(name, &DataType::Utf8).map(|c| c.as_string::<i32>());
    let (call_id, session, purpose, model, endpoint) = (
        s("call_id")?,
        s("session")?,
        s("purpose")?,
        s("model")?,
        s("endpoint")?,
    );
    let (request_hash, prompt_hash, request_json) =
        (s("request_hash")?, s("prompt_hash")?, s("request_json")?);
    let (response_json, content, status, error) = (
        s("response_json")?,
        s("content")?,
        s("status")?,
        s("error")?,
    );
    let attempt = col("attempt", &DataType::Int32)?.as_primitive::<Int32Type>();
    let seed = col("seed", &DataType::UInt64)?.as_primitive::<UInt64Type>();
    let http = col("http_status", &DataType::Int32)?.as_primitive::<Int32Type>();
    let tin = col("tokens_in", &DataType::Int64)?.as_primitive::<Int64Type>();
    let tout = col("tokens_out", &DataType::Int64)?.as_primitive::<Int64Type>();
    let est = col("usage_estimated", &DataType::Boolean)?.as_boolean();
    let lat = col("latency_ms", &DataType::Float64)?.as_primitive::<Float64Type>();
    let rep = col("replayed", &DataType::Boolean)?.as_boolean();
    let at = col(
        "started_at",
        &DataType::Timestamp(TimeUnit::Millisecond, None),
    )?
    .as_primitive::<TimestampMillisecondType>();
    let os = |a: &StringArray, i: usize| (!a.is_null(i)).then(|| a.value(i).to_string());
    for i in 0..b.num_rows() {
        out.push(CallRecord {
            call_id: call_id.value(i).into(),
            session: session.value(i).into(),
            attempt: attempt.value(i),
            purpose: purpose.value(i).into(),
            model: model.value(i).into(),
            endpoint: endpoint.value(i).into(),
            request_hash: request_hash.value(i).into(),
            prompt_hash: prompt_hash.value(i).into(),
            seed: (!seed.is_null(i)).then(|| seed.value(i)),
            request_json: request_json.value(i).into(),
            response_json: os(response_json, i),
            content: os(content, i),
            status: status.value(i).into(),
            http_status: (!http.is_null(i)).then(|| http.value(i)),
            error: os(error, i),
            tokens_in: tin.value(i),
            tokens_out: tout.value(i),
            usage_estimated: est.value(i),
            latency_ms: lat.value(i),
            replayed: rep.value(i),
            started_at_ms: at.value(i),
        });
    }
    Ok(())
}

/// Milliseconds since the Unix epoch.
pub(crate) fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// Buffers rows and appends them to a run's `llm_calls` as new files.
#[derive(Debug)]
pub(crate) struct CallLog {
    dir: PathBuf,
    session: String,
    state: Mutex<LogState>,
}

#[derive(Debug, Default)]
struct LogState {
    rows: Vec<CallRecord>,
    files: u32,
    /// When the oldest buffered row arrived.
    oldest: Option<std::time::Instant>,
}

impl CallLog {
    pub fn new(run: &RunDir, session: &str) -> Self {
        CallLog {
            dir: run.partition_dir(TABLE, None),
            session: session.to_string(),
            state: Mutex::new(LogState::default()),
        }
    }

    /// Adds a row; writes a file when the buffer is full or its oldest row is [`FLUSH_AFTER`] old.
    pub fn push(&self, row: CallRecord) -> Result<(), LlmError> {
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        st.rows.push(row);
        let oldest = *st.oldest.get_or_insert_with(std::time::Instant::now);
        if st.rows.len() >= FLUSH_EVERY || oldest.elapsed() >= FLUSH_AFTER {
            self.write(&mut st)?;
        }
        Ok(())
    }

    /// Writes buffered rows when the oldest is at least `age` old (the client's watch thread calls
    /// this every fraction of a second, so a row never waits for the next call to be written).
    pub fn flush_older_than(&self, age: std::time::Duration) -> Result<(), LlmError> {
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        match st.oldest {
            Some(t) if t.elapsed() >= age => self.write(&mut st),
            _ => Ok(()),
        }
    }

    /// Writes buffered rows, if any.
    pub fn flush(&self) -> Result<(), LlmError> {
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        self.write(&mut st)
    }

    fn write(&self, st: &mut LogState) -> Result<(), LlmError> {
        if st.rows.is_empty() {
            return Ok(());
        }
        let name = shard_file_name(
            &format!("llm-{}", self.session),
            &format!("{:05}", st.files),
        );
        let path = self.dir.join(name);
        let b = batch(&st.rows).map_err(|e| LlmError::Table {
            path: path.clone(),
            message: e.to_string(),
        })?;
        let mut sink = ParquetSink::create(&path, schema())?;
        sink.write(&b)?;
        sink.commit()?;
        st.files += 1;
        st.rows.clear();
        st.oldest = None;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(i: i64) -> CallRecord {
        CallRecord {
            call_id: format!("s-{i}"),
            session: "s".into(),
            attempt: 1,
            purpose: "test".into(),
            model: "m".into(),
            endpoint: "http://h/v1/chat/completions".into(),
            request_hash: format!("h{i}"),
            prompt_hash: "p".into(),
            seed: if i % 2 == 0 { Some(i as u64) } else { None },
            request_json: "{}".into(),
            response_json: Some("{\"choices\":[]}".into()),
            content: Some(format!("answer {i}")),
            status: status::OK.into(),
            http_status: Some(200),
            error: None,
            tokens_in: 10,
            tokens_out: i,
            usage_estimated: i % 3 == 0,
            latency_ms: 1.5,
            replayed: false,
            started_at_ms: 1_000 + i,
        }
    }

    #[test]
    fn rows_order_by_time_then_call_number() {
        let mut a = row(0);
        let mut b = row(1);
        (a.call_id, a.started_at_ms) = ("s-10".into(), 5);
        (b.call_id, b.started_at_ms) = ("s-9".into(), 5);
        assert!(order_key(&b) < order_key(&a));
    }

    #[test]
    fn rows_round_trip_through_flushed_files() {
        let dir = tempfile::tempdir().unwrap();
        let run = RunDir::new(dir.path());
        let log = CallLog::new(&run, "s");
        for i in 0..(FLUSH_EVERY as i64 + 3) {
            log.push(row(i)).unwrap();
        }
        // One file written by the full buffer, the rest still buffered.
        assert_eq!(run.table(TABLE).unwrap().files.len(), 1);
        log.flush().unwrap();
        assert_eq!(run.table(TABLE).unwrap().files.len(), 2);
        let back = read_calls(&run).unwrap();
        let want: Vec<_> = (0..(FLUSH_EVERY as i64 + 3)).map(row).collect();
        assert_eq!(back, want);
    }
}
