//! Streaming reader of the paper's JSON trace format: one trace per file, an array of traces, or JSON Lines.
//!
//! The reader never holds a whole trace as JSON values: it walks the top level with serde, reads one
//! timestep at a time straight into the typed model (each object's known fields into the slots of its
//! environment's layout, not into a JSON map) and hands it to a [`TraceConsumer`] at once. A
//! `.json` file of at most 64 MiB is read into memory first (serde parses a slice faster than a
//! stream); larger files and JSON Lines stream. Memory is bounded by that, one timestep of JSON and
//! whatever the consumer keeps.
//!
//! Every fault names the file, the trace (its line in JSON Lines, its position otherwise, and its
//! `task_id` when known) and the JSON path of the faulty value. A syntax error in a JSON Lines file
//! rejects that line only; in a `.json` file it ends the file, since nothing after it can be trusted.

use std::fmt;
use std::fs::File;
use std::io::{self, BufRead, BufReader};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde::de::value::{MapAccessDeserializer, SeqAccessDeserializer};
use serde::de::{DeserializeSeed, Error as _, IgnoredAny, MapAccess, SeqAccess, Visitor};
use serde_json::Value;

use super::error::{Fault, FaultKind, TraceError, TraceLocation};
use super::fields::{Fields, Lookup, ObjectPath, child_path, describe, not_an_object, number};
use crate::trace::Env;
use crate::trace::model::{
    Body, Event, IphyreObject, JsonMap, Object, Outcome, PhyreObject, PoolBall, Timestep, Trace,
};

/// Everything about a trace except its timesteps, which were streamed to the consumer.
#[derive(Clone, Debug, PartialEq)]
pub struct TraceHeader {
    /// The trace's own `trace_id` field, when it has one.
    pub trace_id: Option<String>,
    /// Its environment (equal to the one being imported).
    pub env: Env,
    /// Its `task_id`.
    pub task_id: String,
    /// Its events.
    pub events: Vec<Event>,
    /// Its outcome.
    pub outcome: Outcome,
    /// Its unknown top-level fields.
    pub extra: JsonMap,
    /// How many timesteps were streamed.
    pub n_timesteps: usize,
}

/// Receives traces as they are read.
pub trait TraceConsumer {
    /// A timestep of the trace being read, in order. If the trace is later rejected, [`finish`]
    /// says so and the consumer drops what it kept of it.
    ///
    /// [`finish`]: TraceConsumer::finish
    fn timestep(&mut self, ts: Timestep);

    /// The end of a trace: its header, or why it was rejected. `Break` stops reading.
    fn finish(
        &mut self,
        location: &TraceLocation,
        result: Result<TraceHeader, TraceError>,
    ) -> ControlFlow<()>;
}

/// A file that could not be read at all.
#[derive(Debug, thiserror::Error)]
#[error("{}", path.display())]
pub struct SourceError {
    /// The file or folder.
    pub path: PathBuf,
    /// The I/O error.
    #[source]
    pub source: io::Error,
}

/// How a file holds its traces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SourceKind {
    /// One trace object, or an array of them.
    Json,
    /// One trace object per line.
    JsonLines,
}

impl SourceKind {
    /// Decides by extension: `.jsonl` and `.ndjson` are JSON Lines, anything else plain JSON.
    pub fn of(path: &Path) -> SourceKind {
        match path.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("jsonl") || e.eq_ignore_ascii_case("ndjson") => {
                SourceKind::JsonLines
            }
            _ => SourceKind::Json,
        }
    }
}

/// Expands import arguments into files: a file stands for itself, a folder for every `.json`, `.jsonl`
/// and `.ndjson` file below it (recursively), sorted by path so that imports are reproducible.
pub fn expand_paths(paths: &[PathBuf]) -> Result<Vec<PathBuf>, SourceError> {
    let mut out = Vec::new();
    for p in paths {
        let meta = std::fs::metadata(p).map_err(|source| SourceError {
            path: p.clone(),
            source,
        })?;
        if meta.is_dir() {
            let mut found = Vec::new();
            walk(p, &mut found)?;
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> Result<(), SourceError> {
    let entries = std::fs::read_dir(dir).map_err(|source| SourceError {
        path: dir.to_path_buf(),
        source,
    })?;
    for entry in entries {
        let entry = entry.map_err(|source| SourceError {
            path: dir.to_path_buf(),
            source,
        })?;
        let path = entry.path();
        let ft = entry.file_type().map_err(|source| SourceError {
            path: path.clone(),
            source,
        })?;
        if ft.is_dir() {
            walk(&path, out)?;
        } else if matches!(
            path.extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .as_deref(),
            Some("json" | "jsonl" | "ndjson")
        ) {
            out.push(path);
        }
    }
    Ok(())
}

/// Reads every trace of one file into `consumer`, streaming.
pub fn read_file(
    path: &Path,
    env: Env,
    consumer: &mut dyn TraceConsumer,
) -> Result<(), SourceError> {
    let err = |source| SourceError {
        path: path.to_path_buf(),
        source,
    };
    let file = File::open(path).map_err(err)?;
    let size = file.metadata().map_err(err)?.len();
    let mut reader = BufReader::with_capacity(1 << 16, file);
    match SourceKind::of(path) {
        SourceKind::JsonLines => read_lines(path, reader, env, consumer).map_err(err),
        // A file of at most `WHOLE_JSON_BYTES` is parsed from memory (serde's slice reader is
        // faster than its byte-at-a-time reader); a larger one streams, with bounded memory.
        SourceKind::Json if size <= WHOLE_JSON_BYTES => {
            let mut bytes = Vec::with_capacity(usize::try_from(size).unwrap_or(0));
            io::Read::read_to_end(&mut reader, &mut bytes).map_err(err)?;
            let de = serde_json::Deserializer::from_slice(&bytes);
            read_json(path, de, env, consumer, &|n| nth_line(path, n));
            Ok(())
        }
        SourceKind::Json => {
            let de = serde_json::Deserializer::from_reader(reader);
            read_json(path, de, env, consumer, &|n| nth_line(path, n));
            Ok(())
        }
    }
}

/// `.json` files up to this size are read whole and parsed from memory; larger ones stream.
const WHOLE_JSON_BYTES: u64 = 64 << 20;

/// Reads traces from an in-memory JSON text (one trace or an array) into complete [`Trace`] values.
/// `name` stands for the file in error messages; trace ids default to `name` (or `name-N` in arrays).
pub fn read_str(name: &str, text: &str, env: Env) -> Vec<Result<Trace, TraceError>> {
    read_bytes(name, text.as_bytes(), SourceKind::Json, env)
}

/// Reads traces from in-memory bytes laid out as `kind` into complete [`Trace`] values, exactly as
/// [`read_file`] would read a file holding them (any bytes: invalid UTF-8, syntax errors and every
/// other fault end in a [`TraceError`]). `name` stands for the file in error messages; trace ids
/// default to `name` (`name-N` in arrays, `name-L<line>` in JSON Lines).
pub fn read_bytes(
    name: &str,
    bytes: &[u8],
    kind: SourceKind,
    env: Env,
) -> Vec<Result<Trace, TraceError>> {
    let mut collect = Collect::new(name);
    let path = Path::new(name);
    match kind {
        SourceKind::Json => {
            let text_at = |n: usize| {
                let line = bytes.split(|b| *b == b'\n').nth(n.checked_sub(1)?)?;
                Some(String::from_utf8_lossy(line).into_owned())
            };
            let de = serde_json::Deserializer::from_slice(bytes);
            read_json(path, de, env, &mut collect, &text_at);
        }
        // Reading from memory cannot fail.
        SourceKind::JsonLines => {
            let _ = read_lines(path, bytes, env, &mut collect);
        }
    }
    collect.out
}

/// Reads every trace of a file into complete [`Trace`] values (for small inputs and tests).
pub fn read_path(path: &Path, env: Env) -> Result<Vec<Result<Trace, TraceError>>, SourceError> {
    let stem = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("trace")
        .to_string();
    let mut collect = Collect::new(&stem);
    read_file(path, env, &mut collect)?;
    Ok(collect.out)
}

/// The id a trace gets when it has no `trace_id` field: the file stem, with `-L<line>` for JSON Lines
/// or `-<position>` for an array of traces.
pub fn default_trace_id(stem: &str, location: &TraceLocation) -> String {
    match (location.line, location.in_array) {
        (Some(line), _) => format!("{stem}-L{line}"),
        (None, true) => format!("{stem}-{}", location.ordinal),
        (None, false) => stem.to_string(),
    }
}

/// A consumer that keeps whole traces.
struct Collect {
    stem: String,
    steps: Vec<Timestep>,
    out: Vec<Result<Trace, TraceError>>,
}

impl Collect {
    fn new(stem: &str) -> Self {
        Collect {
            stem: stem.to_string(),
            steps: Vec::new(),
            out: Vec::new(),
        }
    }
}

impl TraceConsumer for Collect {
    fn timestep(&mut self, ts: Timestep) {
        self.steps.push(ts);
    }

    fn finish(
        &mut self,
        loc: &TraceLocation,
        result: Result<TraceHeader, TraceError>,
    ) -> ControlFlow<()> {
        let steps = std::mem::take(&mut self.steps);
        self.out.push(result.map(|h| {
            Trace {
                trace_id: h
                    .trace_id
                    .unwrap_or_else(|| default_trace_id(&self.stem, loc)),
                env: h.env,
                task_id: h.task_id,
                timesteps: steps,
                events: h.events,
                outcome: h.outcome,
                extra: h.extra,
            }
        }));
        ControlFlow::Continue(())
    }
}

/// The message serde carries when the consumer asked to stop; never shown to users.
const STOP: &str = "\u{0}annotrace: consumer stopped";

struct FileState<'c> {
    env: Env,
    file: PathBuf,
    consumer: &'c mut dyn TraceConsumer,
    ordinal: usize,
    line: Option<usize>,
    in_array: bool,
    /// Lines before the text being parsed (JSON Lines parse one line at a time).
    line_base: usize,
    /// The trace being read, if any: its task id and the JSON path being parsed (for syntax errors).
    current: Option<(Option<String>, String)>,
    stopped: bool,
}

impl FileState<'_> {
    fn location(&self) -> TraceLocation {
        TraceLocation {
            file: self.file.clone(),
            ordinal: self.ordinal,
            line: self.line,
            in_array: self.in_array,
        }
    }

    /// Hands a finished trace to the consumer; `Err(())` when reading must stop.
    fn deliver(
        &mut self,
        result: Result<TraceHeader, Fault>,
        task_id: Option<String>,
    ) -> Result<(), ()> {
        let loc = self.location();
        let result = result.map_err(|fault| TraceError {
            location: loc.clone(),
            task_id,
            fault,
        });
        self.current = None;
        self.ordinal += 1;
        match self.consumer.finish(&loc, result) {
            ControlFlow::Continue(()) => Ok(()),
            ControlFlow::Break(()) => {
                self.stopped = true;
                Err(())
            }
        }
    }

    /// Reports a syntax error: for the trace being read, or for the position after the last trace.
    fn syntax(&mut self, err: serde_json::Error, text_at: impl FnOnce(usize) -> Option<String>) {
        let (task_id, path) = self.current.take().unwrap_or((None, "$".to_string()));
        let line_col = (err.line() > 0).then(|| (self.line_base + err.line(), err.column()));
        let source_line = text_at(err.line());
        let mut fault = classify_syntax(&err, source_line.as_deref(), path);
        fault.line_col = line_col;
        let _ = self.deliver(Err(fault), task_id);
    }
}

/// Turns a serde_json error into a fault, recognising the non-finite literals some writers emit.
fn classify_syntax(err: &serde_json::Error, source_line: Option<&str>, path: String) -> Fault {
    let msg = strip_position(&err.to_string());
    if msg.contains("number out of range") {
        return Fault::new(path, FaultKind::NonFinite, "number out of the f64 range");
    }
    if let Some(line) = source_line {
        let from = err.column().saturating_sub(1).min(line.len());
        let window = line.get(from.saturating_sub(1)..).unwrap_or("");
        for lit in ["NaN", "-Infinity", "Infinity", "-inf", "inf", "nan"] {
            if window.trim_start().starts_with(lit) {
                return Fault::new(
                    path,
                    FaultKind::NonFinite,
                    format!(
                        "{lit} is not a finite number (JSON has no NaN or Infinity; drop the sample or use null where allowed)"
                    ),
                );
            }
        }
    }
    Fault::new(path, FaultKind::Syntax, format!("invalid JSON: {msg}"))
}

fn strip_position(msg: &str) -> String {
    match msg.rfind(" at line ") {
        Some(i) => msg[..i].to_string(),
        None => msg.to_string(),
    }
}

fn read_lines(
    path: &Path,
    mut reader: impl BufRead,
    env: Env,
    consumer: &mut dyn TraceConsumer,
) -> io::Result<()> {
    let mut st = FileState {
        env,
        file: path.to_path_buf(),
        consumer,
        ordinal: 0,
        line: None,
        in_array: false,
        line_base: 0,
        current: None,
        stopped: false,
    };
    let mut buf = Vec::new();
    let mut line_no = 0usize;
    loop {
        buf.clear();
        if reader.read_until(b'\n', &mut buf)? == 0 {
            return Ok(());
        }
        line_no += 1;
        if buf.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        st.line = Some(line_no);
        st.line_base = line_no - 1;
        // Parse the line without its terminator: an error at its end is then on this line, not on
        // the next (the same line number whether the import stops or skips the record).
        let end = buf.len()
            - buf
                .iter()
                .rev()
                .take_while(|b| matches!(b, b'\n' | b'\r'))
                .count();
        let line = &buf[..end];
        let mut de = serde_json::Deserializer::from_slice(line);
        let res = TraceSeed { st: &mut st }
            .deserialize(&mut de)
            .and_then(|()| de.end());
        if st.stopped {
            return Ok(());
        }
        if let Err(e) = res {
            let text = String::from_utf8_lossy(line).into_owned();
            st.syntax(e, |_| Some(text));
            if st.stopped {
                return Ok(());
            }
        }
    }
}

/// Reads a `.json` text; `text_at(n)` gives its line `n` (1-based) for error messages.
fn read_json<'de, R: serde_json::de::Read<'de>>(
    path: &Path,
    mut de: serde_json::Deserializer<R>,
    env: Env,
    consumer: &mut dyn TraceConsumer,
    text_at: &dyn Fn(usize) -> Option<String>,
) {
    let mut st = FileState {
        env,
        file: path.to_path_buf(),
        consumer,
        ordinal: 0,
        line: None,
        in_array: false,
        line_base: 0,
        current: None,
        stopped: false,
    };
    let res = FileSeed { st: &mut st }
        .deserialize(&mut de)
        .and_then(|()| de.end());
    if st.stopped {
        return;
    }
    if let Err(e) = res {
        st.syntax(e, text_at);
    }
}

/// Line `n` (1-based) of a file, for error messages only.
fn nth_line(path: &Path, n: usize) -> Option<String> {
    let f = File::open(path).ok()?;
    BufReader::new(f).lines().nth(n.checked_sub(1)?)?.ok()
}

/// The top level of a `.json` file: a trace object or an array of them.
struct FileSeed<'s, 'c> {
    st: &'s mut FileState<'c>,
}

impl<'de> DeserializeSeed<'de> for FileSeed<'_, '_> {
    type Value = ();
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for FileSeed<'_, '_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a trace object or an array of trace objects")
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<(), A::Error> {
        TraceSeed { st: self.st }.visit_map(map)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        self.st.in_array = true;
        while seq
            .next_element_seed(TraceSeed { st: &mut *self.st })?
            .is_some()
        {}
        Ok(())
    }
}

/// One trace object.
struct TraceSeed<'s, 'c> {
    st: &'s mut FileState<'c>,
}

impl<'de> DeserializeSeed<'de> for TraceSeed<'_, '_> {
    type Value = ();
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

/// The fields of a trace as they arrive, and the first fault.
#[derive(Default)]
struct Partial {
    trace_id: Option<String>,
    environment: Option<(String, Option<Env>)>,
    task_id: Option<String>,
    timesteps: Option<usize>,
    events: Option<Vec<Event>>,
    outcome: Option<Outcome>,
    extra: JsonMap,
    seen: Vec<String>,
    fault: Option<Fault>,
    last_step: Option<(i64, f64)>,
}

impl Partial {
    fn fail(&mut self, fault: Fault) {
        if self.fault.is_none() {
            self.fault = Some(fault);
        }
    }

    fn set(&mut self, key: String, v: Value, env: Env) {
        if self.fault.is_some() {
            return;
        }
        let res: Result<(), Fault> = (|| {
            match key.as_str() {
                "environment" => {
                    let s = v.as_str().ok_or_else(|| {
                        Fault::new(
                            "$.environment",
                            FaultKind::Type,
                            format!("expected a string, found {}", describe(&v)),
                        )
                    })?;
                    self.environment = Some((s.to_string(), s.parse::<Env>().ok()));
                    if self.environment.as_ref().and_then(|e| e.1) != Some(env) {
                        return Err(env_mismatch(s, env));
                    }
                }
                "task_id" => {
                    self.task_id = Some(v.as_str().map(str::to_owned).ok_or_else(|| {
                        Fault::new(
                            "$.task_id",
                            FaultKind::Type,
                            format!("expected a string, found {}", describe(&v)),
                        )
                    })?)
                }
                "trace_id" => {
                    let id = v.as_str().filter(|s| !s.is_empty()).ok_or_else(|| {
                        Fault::new(
                            "$.trace_id",
                            FaultKind::Type,
                            format!("expected a non-empty string, found {}", describe(&v)),
                        )
                    })?;
                    self.trace_id = Some(id.to_string());
                }
                "events" => self.events = Some(parse_events(&v)?),
                "outcome" => self.outcome = Some(parse_outcome(&v)?),
                _ => {
                    self.extra.insert(key, v);
                }
            }
            Ok(())
        })();
        if let Err(f) = res {
            self.fail(f);
        }
    }

    fn finish(mut self, env: Env) -> Result<TraceHeader, Fault> {
        // A contradicting environment explains every layout fault after it, so it wins.
        if let Some((name, parsed)) = &self.environment
            && *parsed != Some(env)
        {
            return Err(env_mismatch(name, env));
        }
        if let Some(f) = self.fault.take() {
            return Err(f);
        }
        let missing = |key: &str| {
            Fault::new(
                format!("$.{key}"),
                FaultKind::Missing,
                format!("missing required field `{key}`"),
            )
        };
        if self.environment.is_none() {
            return Err(missing("environment"));
        }
        let task_id = self.task_id.ok_or_else(|| missing("task_id"))?;
        let n_timesteps = self.timesteps.ok_or_else(|| missing("timesteps"))?;
        let outcome = self.outcome.ok_or_else(|| missing("outcome"))?;
        Ok(TraceHeader {
            trace_id: self.trace_id,
            env,
            task_id,
            events: self.events.unwrap_or_default(),
            outcome,
            extra: self.extra,
            n_timesteps,
        })
    }
}

fn env_mismatch(found: &str, env: Env) -> Fault {
    Fault::new(
        "$.environment",
        FaultKind::EnvMismatch,
        format!(
            "the trace says environment {found:?} but it is being imported as \"{env}\" (--env {env})"
        ),
    )
}

impl<'de> Visitor<'de> for TraceSeed<'_, '_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a trace object")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let st = self.st;
        st.current = Some((None, "$".to_string()));
        let mut p = Partial::default();
        while let Some(key) = map.next_key::<String>()? {
            if p.seen.contains(&key) {
                map.next_value::<IgnoredAny>()?;
                p.fail(Fault::new(
                    super::fields::child_path("$", &key),
                    FaultKind::DuplicateField,
                    format!("field `{key}` is given twice"),
                ));
                continue;
            }
            p.seen.push(key.clone());
            if key == "timesteps" {
                map.next_value_seed(TimestepsSeed {
                    st: &mut *st,
                    p: &mut p,
                })?;
                p.timesteps.get_or_insert(0);
            } else {
                if let Some(cur) = st.current.as_mut() {
                    cur.1 = super::fields::child_path("$", &key);
                }
                let v: Value = map.next_value()?;
                p.set(key, v, st.env);
                if let (Some(task), Some(cur)) = (&p.task_id, st.current.as_mut()) {
                    cur.0 = Some(task.clone());
                }
            }
        }
        let task_id = p.task_id.clone();
        let result = p.finish(st.env);
        st.deliver(result, task_id)
            .map_err(|()| A::Error::custom(STOP))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        while seq.next_element::<IgnoredAny>()?.is_some() {}
        self.reject("an array")
    }
    fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<(), E> {
        self.reject(&describe(&Value::String(v.into())))
    }
    fn visit_bool<E: serde::de::Error>(self, v: bool) -> Result<(), E> {
        self.reject(&format!("boolean {v}"))
    }
    fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<(), E> {
        self.reject(&format!("number {v}"))
    }
    fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<(), E> {
        self.reject(&format!("number {v}"))
    }
    fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<(), E> {
        self.reject(&format!("number {v}"))
    }
    fn visit_unit<E: serde::de::Error>(self) -> Result<(), E> {
        self.reject("null")
    }
}

impl TraceSeed<'_, '_> {
    fn reject<E: serde::de::Error>(self, found: &str) -> Result<(), E> {
        let fault = Fault::new(
            "$",
            FaultKind::Type,
            format!("expected a trace object, found {found}"),
        );
        self.st
            .deliver(Err(fault), None)
            .map_err(|()| E::custom(STOP))
    }
}

/// The `timesteps` array: each element is parsed, converted and streamed on its own.
struct TimestepsSeed<'s, 'c, 'p> {
    st: &'s mut FileState<'c>,
    p: &'p mut Partial,
}

impl<'de> DeserializeSeed<'de> for TimestepsSeed<'_, '_, '_> {
    type Value = ();
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for TimestepsSeed<'_, '_, '_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an array of timesteps")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let env = self.st.env;
        let mut i = 0usize;
        loop {
            let path = format!("$.timesteps[{i}]");
            if let Some(cur) = self.st.current.as_mut() {
                cur.1.clone_from(&path);
            }
            if self.p.fault.is_some() {
                if seq.next_element::<IgnoredAny>()?.is_none() {
                    break;
                }
            } else {
                let Some(step) = seq.next_element_seed(TimestepSeed { path: &path, env })? else {
                    break;
                };
                match step.and_then(|raw| raw.finish(&path, self.p.last_step)) {
                    Ok(ts) => {
                        self.p.last_step = Some((ts.index, ts.t));
                        self.st.consumer.timestep(ts);
                    }
                    Err(f) => self.p.fail(f),
                }
            }
            i += 1;
        }
        self.p.timesteps = Some(i);
        Ok(())
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        while map.next_entry::<IgnoredAny, IgnoredAny>()?.is_some() {}
        self.p.fail(Fault::new(
            "$.timesteps",
            FaultKind::Type,
            "expected an array of timesteps, found an object",
        ));
        self.p.timesteps = Some(0);
        Ok(())
    }

    fn visit_unit<E: serde::de::Error>(self) -> Result<(), E> {
        self.p.fail(Fault::new(
            "$.timesteps",
            FaultKind::Type,
            "expected an array of timesteps, found null",
        ));
        self.p.timesteps = Some(0);
        Ok(())
    }

    fn visit_str<E: serde::de::Error>(self, _: &str) -> Result<(), E> {
        self.scalar()
    }
    fn visit_bool<E: serde::de::Error>(self, _: bool) -> Result<(), E> {
        self.scalar()
    }
    fn visit_i64<E: serde::de::Error>(self, _: i64) -> Result<(), E> {
        self.scalar()
    }
    fn visit_u64<E: serde::de::Error>(self, _: u64) -> Result<(), E> {
        self.scalar()
    }
    fn visit_f64<E: serde::de::Error>(self, _: f64) -> Result<(), E> {
        self.scalar()
    }
}

impl TimestepsSeed<'_, '_, '_> {
    fn scalar<E>(self) -> Result<(), E> {
        self.p.fail(Fault::new(
            "$.timesteps",
            FaultKind::Type,
            "expected an array of timesteps, found a scalar",
        ));
        self.p.timesteps = Some(0);
        Ok(())
    }
}

const TIMESTEP_KEYS: &[&str] = &["index", "t", "objects"];

/// A visitor's scalar cases, each handed to its `found` method as a JSON value (a field of the
/// wrong JSON type is described in its fault as it was written).
macro_rules! scalars_to_found {
    () => {
        fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
            Ok(self.found(Value::String(v.to_owned())))
        }
        fn visit_bool<E: serde::de::Error>(self, v: bool) -> Result<Self::Value, E> {
            Ok(self.found(Value::Bool(v)))
        }
        fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Self::Value, E> {
            Ok(self.found(Value::from(v)))
        }
        fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Self::Value, E> {
            Ok(self.found(Value::from(v)))
        }
        fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Self::Value, E> {
            Ok(self.found(Value::from(v)))
        }
        fn visit_unit<E: serde::de::Error>(self) -> Result<Self::Value, E> {
            Ok(self.found(Value::Null))
        }
    };
}

/// One element of `timesteps`, parsed straight into the model: the objects' fields go into slots
/// of their environment's layout ([`Slots`]) instead of a JSON map per object, and nothing is
/// checked until the element has been read, so the faults are those (and in the order) of reading
/// the element as a JSON value first and then field by field (`docs/trace-format.md`).
struct TimestepSeed<'a> {
    path: &'a str,
    env: Env,
}

/// A timestep as read, before its `index`, `t` and `objects` are checked.
#[derive(Default)]
struct RawTimestep {
    index: Option<Value>,
    t: Option<Value>,
    objects: Option<ObjectsRead>,
    extra: JsonMap,
}

/// What the `objects` field held.
enum ObjectsRead {
    /// An array: its objects up to the first faulty one, or that fault.
    Array(Result<Vec<Object>, Fault>),
    /// Anything else (a type fault).
    Other(Value),
}

impl Lookup for RawTimestep {
    fn field(&self, key: &str) -> Option<&Value> {
        match key {
            "index" => self.index.as_ref(),
            "t" => self.t.as_ref(),
            _ => None,
        }
    }
}

impl RawTimestep {
    /// Checks the timestep in the order the faults are documented: `index`, `t`, their order
    /// against the previous timestep, then `objects`.
    fn finish(self, path: &str, last: Option<(i64, f64)>) -> Result<Timestep, Fault> {
        let f = Fields::new(&self, ObjectPath::Whole(path));
        let index = f.i64("index")?;
        let t = f.f64("t")?;
        increasing(&f, (index, t), last)?;
        let objects = match self.objects {
            None => {
                return Err(Fault::new(
                    child_path(path, "objects"),
                    FaultKind::Missing,
                    "missing required field `objects`",
                ));
            }
            Some(ObjectsRead::Other(other)) => {
                return Err(Fault::new(
                    child_path(path, "objects"),
                    FaultKind::Type,
                    format!("expected an array of objects, found {}", describe(&other)),
                ));
            }
            Some(ObjectsRead::Array(objects)) => objects?,
        };
        Ok(Timestep {
            index,
            t,
            objects,
            extra: self.extra,
        })
    }
}

/// Checks that a timestep's `index` and `t` are above the previous timestep's.
fn increasing<M: Lookup + ?Sized>(
    f: &Fields<'_, M>,
    (index, t): (i64, f64),
    last: Option<(i64, f64)>,
) -> Result<(), Fault> {
    let Some((prev_index, prev_t)) = last else {
        return Ok(());
    };
    if index <= prev_index {
        return Err(Fault::new(
            f.path_of("index"),
            FaultKind::Order,
            format!(
                "timestep index {index} does not increase (previous timestep has index {prev_index})"
            ),
        ));
    }
    if t <= prev_t {
        return Err(Fault::new(
            f.path_of("t"),
            FaultKind::Order,
            format!("time t = {t} does not increase (previous timestep has t = {prev_t})"),
        ));
    }
    Ok(())
}

impl<'de> DeserializeSeed<'de> for TimestepSeed<'_> {
    type Value = Result<RawTimestep, Fault>;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for TimestepSeed<'_> {
    type Value = Result<RawTimestep, Fault>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a timestep")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let mut step = RawTimestep::default();
        while let Some(key) = map.next_key_seed(KeySeed(TIMESTEP_KEYS))? {
            // Positions in `TIMESTEP_KEYS`: `index`, `t`, `objects`.
            match key {
                Key::Known(0) => step.index = Some(map.next_value()?),
                Key::Known(1) => step.t = Some(map.next_value()?),
                Key::Known(_) => {
                    let objects_path = child_path(self.path, "objects");
                    step.objects = Some(map.next_value_seed(ObjectsSeed {
                        path: &objects_path,
                        env: self.env,
                    })?);
                }
                // A key given twice keeps its last value in its first place, as a JSON map does.
                Key::Other(k) => {
                    step.extra.insert(k, map.next_value()?);
                }
            }
        }
        Ok(Ok(step))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
        Ok(self.found(Value::deserialize(SeqAccessDeserializer::new(seq))?))
    }

    scalars_to_found!();
}

impl TimestepSeed<'_> {
    fn found(self, v: Value) -> Result<RawTimestep, Fault> {
        Err(not_an_object(self.path, "a timestep", &v))
    }
}

/// An object key: its position in a layout's list of known keys, or the key itself.
enum Key {
    Known(usize),
    Other(String),
}

/// Reads a key against a layout's known keys without allocating for a known one.
struct KeySeed(&'static [&'static str]);

impl<'de> DeserializeSeed<'de> for KeySeed {
    type Value = Key;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<Key, D::Error> {
        d.deserialize_str(self)
    }
}

impl<'de> Visitor<'de> for KeySeed {
    type Value = Key;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an object key")
    }

    fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Key, E> {
        Ok(match self.0.iter().position(|k| *k == v) {
            Some(i) => Key::Known(i),
            None => Key::Other(v.to_owned()),
        })
    }
}

/// The `objects` field of a timestep.
struct ObjectsSeed<'a> {
    path: &'a str,
    env: Env,
}

impl<'de> DeserializeSeed<'de> for ObjectsSeed<'_> {
    type Value = ObjectsRead;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<ObjectsRead, D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for ObjectsSeed<'_> {
    type Value = ObjectsRead;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an array of objects")
    }

    /// Converts objects in order and stops converting at the first fault (the rest of the array is
    /// still read, as JSON, so that a syntax error after it is found just the same).
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<ObjectsRead, A::Error> {
        let mut out: Vec<Object> = Vec::with_capacity(seq.size_hint().unwrap_or(16));
        let mut ids: Vec<String> = Vec::with_capacity(out.capacity());
        let mut j = 0usize;
        let mut fault = None;
        loop {
            if fault.is_some() {
                if seq.next_element::<IgnoredAny>()?.is_none() {
                    break;
                }
                continue;
            }
            let seed = ObjectSeed {
                path: ObjectPath::Item(self.path, j),
                env: self.env,
            };
            let Some(obj) = seq.next_element_seed(seed)? else {
                break;
            };
            match obj {
                Ok(obj) => {
                    let id = obj.object_id();
                    if let Some(first) = ids.iter().position(|x| *x == id) {
                        fault = Some(Fault::new(
                            ObjectPath::Item(self.path, j).text(),
                            FaultKind::DuplicateObject,
                            format!(
                                "object id {id:?} appears twice in this timestep (also at objects[{first}])"
                            ),
                        ));
                    } else {
                        ids.push(id);
                        out.push(obj);
                    }
                }
                Err(f) => fault = Some(f),
            }
            j += 1;
        }
        Ok(ObjectsRead::Array(match fault {
            Some(f) => Err(f),
            None => Ok(out),
        }))
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<ObjectsRead, A::Error> {
        Ok(self.found(Value::deserialize(MapAccessDeserializer::new(map))?))
    }

    scalars_to_found!();
}

impl ObjectsSeed<'_> {
    fn found(self, v: Value) -> ObjectsRead {
        ObjectsRead::Other(v)
    }
}

/// The fields of one object in the layout of its environment: each known field's value in its
/// slot, the others (in input order) for the object's `extra`.
struct Slots {
    keys: &'static [&'static str],
    values: [Option<Value>; MAX_OBJECT_KEYS],
    extra: JsonMap,
}

/// The most fields a layout names (I-PHYRE's).
const MAX_OBJECT_KEYS: usize = IPHYRE_KEYS.len();

impl Lookup for Slots {
    fn field(&self, key: &str) -> Option<&Value> {
        let i = self.keys.iter().position(|k| *k == key)?;
        self.values[i].as_ref()
    }
}

/// One object of a timestep.
struct ObjectSeed<'a> {
    path: ObjectPath<'a>,
    env: Env,
}

impl ObjectSeed<'_> {
    fn found(self, v: Value) -> Result<Object, Fault> {
        Err(not_an_object(&self.path.text(), "an object", &v))
    }
}

impl<'de> DeserializeSeed<'de> for ObjectSeed<'_> {
    type Value = Result<Object, Fault>;
    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for ObjectSeed<'_> {
    type Value = Result<Object, Fault>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an object")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
        let mut slots = Slots {
            keys: layout_keys(self.env),
            values: Default::default(),
            extra: JsonMap::new(),
        };
        while let Some(key) = map.next_key_seed(KeySeed(slots.keys))? {
            match key {
                Key::Known(i) => slots.values[i] = Some(map.next_value()?),
                Key::Other(k) => {
                    slots.extra.insert(k, map.next_value()?);
                }
            }
        }
        Ok(
            object_of(&Fields::new(&slots, self.path), self.env).map(|body| Object {
                body,
                extra: slots.extra,
            }),
        )
    }

    fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
        Ok(self.found(Value::deserialize(SeqAccessDeserializer::new(seq))?))
    }

    scalars_to_found!();
}

/// Object fields of each environment's layout, in the paper's order.
pub(crate) const POOL_KEYS: &[&str] = &[
    "kind",
    "ball_id",
    "position",
    "velocity",
    "angular_velocity",
    "motion_state_code",
    "motion_state",
    "radius",
];
pub(crate) const PHYRE_KEYS: &[&str] = &[
    "object_index",
    "shape",
    "color",
    "diameter",
    "x",
    "y",
    "angle",
    "vx",
    "vy",
    "angular_velocity",
    "is_user_input",
];
pub(crate) const IPHYRE_KEYS: &[&str] = &[
    "index",
    "x1",
    "y1",
    "x2",
    "y2",
    "radius",
    "eliminable",
    "dynamic",
    "joint",
    "spring",
    "angle",
    "vx",
    "vy",
    "angular_velocity",
];

/// The known fields of each environment's objects.
fn layout_keys(env: Env) -> &'static [&'static str] {
    match env {
        Env::Pooltool => POOL_KEYS,
        Env::Phyre => PHYRE_KEYS,
        Env::Iphyre => IPHYRE_KEYS,
    }
}

/// Converts the fields of one object in the layout of `env`.
fn object_of<M: Lookup + ?Sized>(f: &Fields<'_, M>, env: Env) -> Result<Body, Fault> {
    Ok(match env {
        Env::Pooltool => Body::Pool(PoolBall {
            kind: f.str("kind")?.into(),
            ball_id: f.str("ball_id")?.into(),
            position: f.vec3("position")?,
            velocity: f.vec3("velocity")?,
            angular_velocity: f.vec3("angular_velocity")?,
            motion_state_code: f.i64("motion_state_code")?,
            motion_state: f.str("motion_state")?.into(),
            radius: f.f64("radius")?,
        }),
        Env::Phyre => Body::Phyre(PhyreObject {
            object_index: f.i64("object_index")?,
            shape: f.str("shape")?,
            color: f.str("color")?,
            diameter: f.f64("diameter")?,
            x: f.f64("x")?,
            y: f.f64("y")?,
            angle: f.f64("angle")?,
            vx: f.f64("vx")?,
            vy: f.f64("vy")?,
            angular_velocity: f.f64("angular_velocity")?,
            is_user_input: f.bool("is_user_input")?,
        }),
        Env::Iphyre => Body::Iphyre(IphyreObject {
            index: f.i64("index")?,
            x1: f.f64("x1")?,
            y1: f.f64("y1")?,
            x2: f.f64("x2")?,
            y2: f.f64("y2")?,
            radius: f.f64("radius")?,
            eliminable: f.f64("eliminable")?,
            dynamic: f.f64("dynamic")?,
            joint: f.i64("joint")?,
            spring: f.i64("spring")?,
            angle: f.opt_f64("angle")?,
            vx: f.opt_f64("vx")?,
            vy: f.opt_f64("vy")?,
            angular_velocity: f.opt_f64("angular_velocity")?,
        }),
    })
}

const EVENT_KEYS: &[&str] = &["kind", "t", "payload"];

fn parse_events(v: &Value) -> Result<Vec<Event>, Fault> {
    let items = v.as_array().ok_or_else(|| {
        Fault::new(
            "$.events",
            FaultKind::Type,
            format!("expected an array of events, found {}", describe(v)),
        )
    })?;
    items
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let path = format!("$.events[{i}]");
            let f = Fields::of(e, &path, "an event")?;
            let t = match e.get("t") {
                None | Some(Value::Null) => None,
                Some(t) => Some(number(t, || f.path_of("t"))?),
            };
            Ok(Event {
                kind: f.str("kind")?,
                t,
                payload: e.get("payload").cloned(),
                extra: f.rest(EVENT_KEYS),
            })
        })
        .collect()
}

const OUTCOME_KEYS: &[&str] = &["success", "terminal_status", "metrics"];

fn parse_outcome(v: &Value) -> Result<Outcome, Fault> {
    let f = Fields::of(v, "$.outcome", "the outcome")?;
    Ok(Outcome {
        success: f.bool("success")?,
        terminal_status: f.str("terminal_status")?,
        metrics: f.opt_object("metrics")?.unwrap_or_default(),
        extra: f.rest(OUTCOME_KEYS),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The reference: a timestep parsed as a JSON value first and then read field by field, as the
    /// reader did before it read timesteps straight into the model.
    fn by_value(
        v: &Value,
        path: &str,
        env: Env,
        last: Option<(i64, f64)>,
    ) -> Result<Timestep, Fault> {
        let f = Fields::of(v, path, "a timestep")?;
        let index = f.i64("index")?;
        let t = f.f64("t")?;
        increasing(&f, (index, t), last)?;
        let objects_path = f.path_of("objects");
        let objects = match v.get("objects") {
            None => {
                return Err(Fault::new(
                    &objects_path,
                    FaultKind::Missing,
                    "missing required field `objects`",
                ));
            }
            Some(Value::Array(items)) => items,
            Some(other) => {
                return Err(Fault::new(
                    &objects_path,
                    FaultKind::Type,
                    format!("expected an array of objects, found {}", describe(other)),
                ));
            }
        };
        let mut out = Vec::new();
        let mut ids: Vec<String> = Vec::new();
        for (j, o) in objects.iter().enumerate() {
            let opath = format!("{objects_path}[{j}]");
            let of = Fields::of(o, &opath, "an object")?;
            let obj = Object {
                body: object_of(&of, env)?,
                extra: of.rest(layout_keys(env)),
            };
            let id = obj.object_id();
            if let Some(first) = ids.iter().position(|x| *x == id) {
                return Err(Fault::new(
                    opath,
                    FaultKind::DuplicateObject,
                    format!(
                        "object id {id:?} appears twice in this timestep (also at objects[{first}])"
                    ),
                ));
            }
            ids.push(id);
            out.push(obj);
        }
        Ok(Timestep {
            index,
            t,
            objects: out,
            extra: f.rest(TIMESTEP_KEYS),
        })
    }

    /// The reader's own way: the element read straight into the model, then checked.
    fn streamed(
        text: &str,
        path: &str,
        env: Env,
        last: Option<(i64, f64)>,
    ) -> Result<Timestep, Fault> {
        let mut de = serde_json::Deserializer::from_str(text);
        let raw = TimestepSeed { path, env }.deserialize(&mut de).unwrap();
        de.end().unwrap();
        raw.and_then(|r| r.finish(path, last))
    }

    /// A value of a field in each JSON type and some edge cases, as JSON text.
    fn any_value(rng: &mut SplitMix64) -> String {
        let pick = [
            "\"ball\"",
            "\"1\"",
            "\"cue\"",
            "\"\"",
            "0",
            "1",
            "-0",
            "-0.0",
            "2.5",
            "-3",
            "1e300",
            "18446744073709551615",
            "9223372036854775808",
            "100000000000000000000",
            "true",
            "false",
            "null",
            "[]",
            "[1, 2]",
            "[1, 2, 3]",
            "[1, \"2\", 3]",
            "[1, 2, 3, 4]",
            "[null, 0, 0]",
            "{}",
            "{\"a\": 1}",
        ];
        pick[rng.below(pick.len())].to_string()
    }

    /// A valid value of a known field.
    fn good_value(key: &str, j: usize, rng: &mut SplitMix64) -> String {
        match key {
            "kind" => "\"ball\"".into(),
            "ball_id" => format!("\"{}\"", j % 3),
            "shape" => "\"ball\"".into(),
            "color" => "\"red\"".into(),
            "motion_state" => "\"rolling\"".into(),
            "position" | "velocity" | "angular_velocity" => {
                format!("[{}, {}, 0]", rng.below(10) as i64 - 5, rng.next_f64())
            }
            "is_user_input" => "false".into(),
            "object_index" | "index" => format!("{}", j % 3),
            "motion_state_code" | "joint" | "spring" => format!("{}", rng.below(4)),
            _ => format!("{}", rng.next_f64() * 10.0),
        }
    }

    /// An object's fields as JSON text: the layout's, some dropped, doubled, mistyped, reordered
    /// or joined by unknown ones.
    fn object_text(keys: &[&str], j: usize, rng: &mut SplitMix64) -> String {
        if rng.below(150) == 0 {
            return any_value(rng);
        }
        let mut fields: Vec<(String, String)> = Vec::new();
        for k in keys {
            if rng.below(150) == 0 {
                continue;
            }
            let v = if rng.below(120) == 0 {
                any_value(rng)
            } else {
                good_value(k, j, rng)
            };
            fields.push((k.to_string(), v));
            if rng.below(150) == 0 {
                fields.push((k.to_string(), any_value(rng)));
            }
        }
        if rng.below(5) == 0 {
            let n = 1 + rng.below(3);
            for e in 0..n {
                fields.push((format!("extra{}", e % 2), any_value(rng)));
            }
        }
        if rng.below(4) == 0 {
            let a = rng.below(fields.len().max(1));
            let b = rng.below(fields.len().max(1));
            if a < fields.len() && b < fields.len() {
                fields.swap(a, b);
            }
        }
        let body: Vec<String> = fields
            .iter()
            .map(|(k, v)| format!("{}: {v}", Value::String(k.clone())))
            .collect();
        format!("{{{}}}", body.join(", "))
    }

    fn timestep_text(env: Env, rng: &mut SplitMix64) -> String {
        let keys = layout_keys(env);
        let n = rng.below(5);
        let objects: Vec<String> = (0..n).map(|j| object_text(keys, j, rng)).collect();
        let mut fields = vec![
            ("index".to_string(), format!("{}", rng.below(4))),
            ("t".to_string(), format!("{}", rng.next_f64())),
            ("objects".to_string(), format!("[{}]", objects.join(", "))),
        ];
        for f in fields.iter_mut() {
            if rng.below(20) == 0 {
                f.1 = any_value(rng);
            }
        }
        if rng.below(20) == 0 {
            let i = rng.below(fields.len());
            fields.remove(i);
        }
        if rng.below(10) == 0 {
            let i = rng.below(fields.len());
            let dup = (fields[i].0.clone(), any_value(rng));
            fields.push(dup);
        }
        if rng.below(6) == 0 {
            fields.push(("note".into(), any_value(rng)));
            fields.reverse();
        }
        if rng.below(60) == 0 {
            return any_value(rng);
        }
        let body: Vec<String> = fields
            .iter()
            .map(|(k, v)| format!("\"{k}\": {v}"))
            .collect();
        format!("{{{}}}", body.join(", "))
    }

    #[test]
    fn a_timestep_read_straight_into_the_model_gives_what_reading_it_as_a_value_gave() {
        let mut rng = SplitMix64::new(7);
        let mut faults = std::collections::BTreeMap::<&str, usize>::new();
        for case in 0..6000 {
            let env = [Env::Pooltool, Env::Phyre, Env::Iphyre][case % 3];
            let text = timestep_text(env, &mut rng);
            let last = match rng.below(3) {
                0 => None,
                1 => Some((1, 0.5)),
                _ => Some((-1, -1.0)),
            };
            let path = "$.timesteps[4]";
            let value: Value = serde_json::from_str(&text).unwrap();
            let want = by_value(&value, path, env, last);
            let got = streamed(&text, path, env, last);
            assert_eq!(got, want, "case {case}: {text}");
            *faults
                .entry(got.as_ref().err().map_or("ok", |f| f.kind.as_str()))
                .or_default() += 1;
        }
        // The cases reach every outcome the rules have.
        for kind in ["ok", "type", "missing", "duplicate_object", "order"] {
            assert!(faults.get(kind).copied().unwrap_or(0) >= 50, "{faults:?}");
        }
    }
}
