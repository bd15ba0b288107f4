//! Conversion between the trace model and Arrow record batches of the trace tables.
//!
//! [`TraceBatchBuilder`] turns one trace into one batch per table, timestep by timestep, so an importer
//! can stream a trace into columns without keeping its JSON. [`decode_trace`] does the reverse for
//! export and for building detector input.

use std::sync::Arc;

use arrow::array::{
    Array, ArrayRef, AsArray, BooleanArray, BooleanBuilder, DictionaryArray, Float64Array,
    Float64Builder, Int32Array, Int32Builder, Int64Array, Int64Builder, ListBuilder, RecordBatch,
    StringArray, StringBuilder, StringDictionaryBuilder,
};
use arrow::compute::cast;
use arrow::datatypes::{DataType, Int32Type};
use arrow::error::ArrowError;
use serde_json::Value;

use super::Env;
use super::model::{
    Body, Event, IphyreObject, JsonMap, Object, Outcome, PhyreObject, PoolBall, Timestep, Trace,
};
use super::pool_steps::BallView;
use super::schema::{EVENTS, FRAMES, SCENES, TIMESTEPS, TRACES};

/// One trace as one batch per table.
#[derive(Clone, Debug)]
pub struct TraceBatches {
    /// One row for `traces`.
    pub traces: RecordBatch,
    /// One row per timestep.
    pub timesteps: RecordBatch,
    /// One row per timestep × object.
    pub frames: RecordBatch,
    /// One row per event.
    pub events: RecordBatch,
}

/// What a trace row holds besides the timesteps.
#[derive(Clone, Debug)]
pub struct TraceMeta<'a> {
    /// Trace id.
    pub trace_id: &'a str,
    /// The scene it starts from.
    pub scene_id: &'a str,
    /// Task id.
    pub task_id: &'a str,
    /// The event log.
    pub events: &'a [Event],
    /// The outcome.
    pub outcome: &'a Outcome,
    /// Unknown top-level fields.
    pub extra: &'a JsonMap,
    /// Where it came from (`file:line`, `simulate:<stage>`, …).
    pub source: &'a str,
}

/// A one-row column's JSON text (a trace's outcome or unknown fields); null when the map is empty.
fn json_or_null(map: &JsonMap) -> Option<String> {
    (!map.is_empty()).then(|| serde_json::to_string(map).expect("a JSON map serialises"))
}

/// Appends `value` as compact JSON text (the text `Value::to_string` gives), written through
/// `buf` so that no string is allocated per row; null where there is none.
fn append_json(out: &mut StringBuilder, buf: &mut Vec<u8>, value: Option<&impl serde::Serialize>) {
    match value {
        Some(v) => {
            buf.clear();
            serde_json::to_writer(&mut *buf, v).expect("a JSON value serialises");
            out.append_value(std::str::from_utf8(buf).expect("serde_json writes UTF-8"));
        }
        None => out.append_null(),
    }
}

/// Appends a map of unknown fields as [`append_json`] does; null when it is empty.
fn append_json_map(out: &mut StringBuilder, buf: &mut Vec<u8>, map: &JsonMap) {
    append_json(out, buf, (!map.is_empty()).then_some(map));
}

pub(super) fn constant_dict(value: &str, len: usize) -> ArrayRef {
    let keys = Int32Array::from(vec![0; len]);
    let values = StringArray::from(vec![value]);
    Arc::new(
        DictionaryArray::<Int32Type>::try_new(keys, Arc::new(values)).expect("key 0 is in range"),
    )
}

/// Column builders for the frames of one trace.
#[derive(Default)]
struct FrameColumns {
    step: Int64Builder,
    t: Float64Builder,
    slot: Int32Builder,
    object_id: StringDictionaryBuilder<Int32Type>,
    x: Float64Builder,
    y: Float64Builder,
    z: Float64Builder,
    vx: Float64Builder,
    vy: Float64Builder,
    vz: Float64Builder,
    angle: Float64Builder,
    wx: Float64Builder,
    wy: Float64Builder,
    wz: Float64Builder,
    kind: StringDictionaryBuilder<Int32Type>,
    motion_state_code: Int32Builder,
    motion_state: StringDictionaryBuilder<Int32Type>,
    radius: Float64Builder,
    diameter: Float64Builder,
    shape: StringDictionaryBuilder<Int32Type>,
    color: StringDictionaryBuilder<Int32Type>,
    is_user_input: BooleanBuilder,
    x1: Float64Builder,
    y1: Float64Builder,
    x2: Float64Builder,
    y2: Float64Builder,
    eliminable: Float64Builder,
    dynamic: Float64Builder,
    joint: Int64Builder,
    spring: Int64Builder,
    extra: StringBuilder,
    /// The buffer `extra`'s JSON is written through.
    json: Vec<u8>,
    rows: usize,
}

/// One `frames` row: the shared core plus the environment columns, `None` where the environment has
/// no such field.
#[derive(Default)]
struct FrameRow<'a> {
    object_id: String,
    x: f64,
    y: f64,
    z: Option<f64>,
    vx: Option<f64>,
    vy: Option<f64>,
    vz: Option<f64>,
    angle: Option<f64>,
    wx: Option<f64>,
    wy: Option<f64>,
    wz: Option<f64>,
    kind: Option<&'a str>,
    motion_state_code: Option<i32>,
    motion_state: Option<&'a str>,
    radius: Option<f64>,
    diameter: Option<f64>,
    shape: Option<&'a str>,
    color: Option<&'a str>,
    is_user_input: Option<bool>,
    x1: Option<f64>,
    y1: Option<f64>,
    x2: Option<f64>,
    y2: Option<f64>,
    eliminable: Option<f64>,
    dynamic: Option<f64>,
    joint: Option<i64>,
    spring: Option<i64>,
}

impl<'a> FrameRow<'a> {
    fn of(body: &'a Body) -> Self {
        match body {
            Body::Pool(b) => FrameRow {
                object_id: b.ball_id.to_string(),
                x: b.position[0],
                y: b.position[1],
                z: Some(b.position[2]),
                vx: Some(b.velocity[0]),
                vy: Some(b.velocity[1]),
                vz: Some(b.velocity[2]),
                wx: Some(b.angular_velocity[0]),
                wy: Some(b.angular_velocity[1]),
                wz: Some(b.angular_velocity[2]),
                kind: Some(&b.kind),
                // Motion-state codes are 0..=4; the import rejects nothing here, so a foreign
                // producer's out-of-range code saturates rather than wrapping.
                motion_state_code: Some(i32::try_from(b.motion_state_code).unwrap_or(i32::MAX)),
                motion_state: Some(&b.motion_state),
                radius: Some(b.radius),
                ..FrameRow::default()
            },
            Body::Phyre(o) => FrameRow {
                object_id: o.object_index.to_string(),
                x: o.x,
                y: o.y,
                vx: Some(o.vx),
                vy: Some(o.vy),
                angle: Some(o.angle),
                wz: Some(o.angular_velocity),
                diameter: Some(o.diameter),
                shape: Some(&o.shape),
                color: Some(&o.color),
                is_user_input: Some(o.is_user_input),
                ..FrameRow::default()
            },
            Body::Iphyre(o) => FrameRow {
                object_id: o.index.to_string(),
                x: (o.x1 + o.x2) / 2.0,
                y: (o.y1 + o.y2) / 2.0,
                vx: o.vx,
                vy: o.vy,
                angle: o.angle,
                wz: o.angular_velocity,
                radius: Some(o.radius),
                x1: Some(o.x1),
                y1: Some(o.y1),
                x2: Some(o.x2),
                y2: Some(o.y2),
                eliminable: Some(o.eliminable),
                dynamic: Some(o.dynamic),
                joint: Some(o.joint),
                spring: Some(o.spring),
                ..FrameRow::default()
            },
        }
    }
}

impl FrameColumns {
    fn push(&mut self, step: i64, t: f64, slot: i32, obj: &Object) {
        let r = FrameRow::of(&obj.body);
        self.rows += 1;
        self.step.append_value(step);
        self.t.append_value(t);
        self.slot.append_value(slot);
        self.object_id.append_value(&r.object_id);
        self.x.append_value(r.x);
        self.y.append_value(r.y);
        self.z.append_option(r.z);
        self.vx.append_option(r.vx);
        self.vy.append_option(r.vy);
        self.vz.append_option(r.vz);
        self.angle.append_option(r.angle);
        self.wx.append_option(r.wx);
        self.wy.append_option(r.wy);
        self.wz.append_option(r.wz);
        self.kind.append_option(r.kind);
        self.motion_state_code.append_option(r.motion_state_code);
        self.motion_state.append_option(r.motion_state);
        self.radius.append_option(r.radius);
        self.diameter.append_option(r.diameter);
        self.shape.append_option(r.shape);
        self.color.append_option(r.color);
        self.is_user_input.append_option(r.is_user_input);
        self.x1.append_option(r.x1);
        self.y1.append_option(r.y1);
        self.x2.append_option(r.x2);
        self.y2.append_option(r.y2);
        self.eliminable.append_option(r.eliminable);
        self.dynamic.append_option(r.dynamic);
        self.joint.append_option(r.joint);
        self.spring.append_option(r.spring);
        append_json_map(&mut self.extra, &mut self.json, &obj.extra);
    }

    fn finish(&mut self, trace_id: &str) -> Result<RecordBatch, ArrowError> {
        let rows = std::mem::take(&mut self.rows);
        let cols: Vec<ArrayRef> = vec![
            constant_dict(trace_id, rows),
            Arc::new(self.step.finish()),
            Arc::new(self.t.finish()),
            Arc::new(self.slot.finish()),
            Arc::new(self.object_id.finish()),
            Arc::new(self.x.finish()),
            Arc::new(self.y.finish()),
            Arc::new(self.z.finish()),
            Arc::new(self.vx.finish()),
            Arc::new(self.vy.finish()),
            Arc::new(self.vz.finish()),
            Arc::new(self.angle.finish()),
            Arc::new(self.wx.finish()),
            Arc::new(self.wy.finish()),
            Arc::new(self.wz.finish()),
            Arc::new(self.kind.finish()),
            Arc::new(self.motion_state_code.finish()),
            Arc::new(self.motion_state.finish()),
            Arc::new(self.radius.finish()),
            Arc::new(self.diameter.finish()),
            Arc::new(self.shape.finish()),
            Arc::new(self.color.finish()),
            Arc::new(self.is_user_input.finish()),
            Arc::new(self.x1.finish()),
            Arc::new(self.y1.finish()),
            Arc::new(self.x2.finish()),
            Arc::new(self.y2.finish()),
            Arc::new(self.eliminable.finish()),
            Arc::new(self.dynamic.finish()),
            Arc::new(self.joint.finish()),
            Arc::new(self.spring.finish()),
            Arc::new(self.extra.finish()),
        ];
        RecordBatch::try_new(FRAMES.clone(), cols)
    }
}

/// Builds the batches of one trace at a time, timestep by timestep.
#[derive(Default)]
pub struct TraceBatchBuilder {
    frames: FrameColumns,
    step: Int64Builder,
    t: Float64Builder,
    n_objects: Int32Builder,
    step_extra: StringBuilder,
    /// The buffer `step_extra`'s JSON is written through.
    json: Vec<u8>,
    steps: usize,
    distinct_objects: std::collections::BTreeSet<String>,
    t_range: Option<(f64, f64)>,
    /// Frame rows of the current trace already handed out by [`TraceBatchBuilder::take_frames`].
    taken_frames: usize,
}

impl TraceBatchBuilder {
    /// An empty builder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the next timestep of the current trace.
    pub fn push_timestep(&mut self, ts: &Timestep) {
        self.steps += 1;
        self.step.append_value(ts.index);
        self.t.append_value(ts.t);
        self.n_objects
            .append_value(i32::try_from(ts.objects.len()).unwrap_or(i32::MAX));
        append_json_map(&mut self.step_extra, &mut self.json, &ts.extra);
        for (slot, obj) in ts.objects.iter().enumerate() {
            self.frames
                .push(ts.index, ts.t, i32::try_from(slot).unwrap_or(i32::MAX), obj);
            if !self
                .distinct_objects
                .contains(obj.body.object_id().as_str())
            {
                self.distinct_objects.insert(obj.object_id());
            }
        }
        self.t_range = Some(match self.t_range {
            None => (ts.t, ts.t),
            Some((a, _)) => (a, ts.t),
        });
    }

    /// Frame rows of the current trace held in memory.
    pub fn buffered_frames(&self) -> usize {
        self.frames.rows
    }

    /// Hands out the frame rows buffered so far (with `trace_id` as a placeholder id, see
    /// [`with_trace_id`]) so that a very long trace need not be held in memory; the trace's summary
    /// counts still include them.
    pub fn take_frames(&mut self, trace_id: &str) -> Result<RecordBatch, ArrowError> {
        self.taken_frames += self.frames.rows;
        self.frames.finish(trace_id)
    }

    /// Drops the timesteps pushed so far (the trace was rejected).
    pub fn discard(&mut self) {
        let _ = self.finish_columns("");
    }

    fn finish_columns(&mut self, trace_id: &str) -> Result<(RecordBatch, RecordBatch), ArrowError> {
        let steps = std::mem::take(&mut self.steps);
        self.taken_frames = 0;
        self.distinct_objects.clear();
        self.t_range = None;
        let timesteps = RecordBatch::try_new(
            TIMESTEPS.clone(),
            vec![
                constant_dict(trace_id, steps),
                Arc::new(self.step.finish()),
                Arc::new(self.t.finish()),
                Arc::new(self.n_objects.finish()),
                Arc::new(self.step_extra.finish()),
            ],
        )?;
        let frames = self.frames.finish(trace_id)?;
        Ok((timesteps, frames))
    }

    /// Finishes the current trace and resets the builder for the next one.
    pub fn finish(&mut self, meta: &TraceMeta<'_>) -> Result<TraceBatches, ArrowError> {
        let n_objects = self.distinct_objects.len();
        let t_range = self.t_range;
        let taken = self.taken_frames;
        let (timesteps, frames) = self.finish_columns(meta.trace_id)?;
        let traces = traces_batch(
            meta,
            timesteps.num_rows(),
            n_objects,
            taken + frames.num_rows(),
            t_range,
        )?;
        let events = events_batch(meta.trace_id, meta.events)?;
        Ok(TraceBatches {
            traces,
            timesteps,
            frames,
            events,
        })
    }

    /// Converts a whole in-memory trace.
    pub fn from_trace(
        trace: &Trace,
        scene_id: &str,
        source: &str,
    ) -> Result<TraceBatches, ArrowError> {
        TraceBatchBuilder::new().push_trace(trace, scene_id, source)
    }

    /// Converts a whole in-memory trace with this builder (whose buffers a writer of many traces
    /// keeps): every timestep, then the trace's row and events.
    pub fn push_trace(
        &mut self,
        trace: &Trace,
        scene_id: &str,
        source: &str,
    ) -> Result<TraceBatches, ArrowError> {
        for ts in &trace.timesteps {
            self.push_timestep(ts);
        }
        self.finish(&TraceMeta {
            trace_id: &trace.trace_id,
            scene_id,
            task_id: &trace.task_id,
            events: &trace.events,
            outcome: &trace.outcome,
            extra: &trace.extra,
            source,
        })
    }
}

/// The one `traces` row of a trace: its metadata and summary counts.
pub(super) fn traces_batch(
    meta: &TraceMeta<'_>,
    n_steps: usize,
    n_objects: usize,
    n_frames: usize,
    t_range: Option<(f64, f64)>,
) -> Result<RecordBatch, ArrowError> {
    let o = meta.outcome;
    RecordBatch::try_new(
        TRACES.clone(),
        vec![
            Arc::new(StringArray::from(vec![meta.trace_id])),
            Arc::new(StringArray::from(vec![meta.scene_id])),
            Arc::new(StringArray::from(vec![meta.task_id])),
            Arc::new(Int64Array::from(vec![n_steps as i64])),
            Arc::new(Int64Array::from(vec![n_objects as i64])),
            Arc::new(Int64Array::from(vec![n_frames as i64])),
            Arc::new(Int64Array::from(vec![meta.events.len() as i64])),
            Arc::new(Float64Array::from(vec![t_range.map(|r| r.0)])),
            Arc::new(Float64Array::from(vec![t_range.map(|r| r.1)])),
            Arc::new(BooleanArray::from(vec![o.success])),
            Arc::new(StringArray::from(vec![o.terminal_status.as_str()])),
            Arc::new(StringArray::from(vec![
                Value::Object(o.metrics.clone()).to_string(),
            ])),
            Arc::new(StringArray::from(vec![json_or_null(&o.extra)])),
            Arc::new(StringArray::from(vec![json_or_null(meta.extra)])),
            Arc::new(StringArray::from(vec![meta.source])),
        ],
    )
}

/// The same rows with every `trace_id` set to `trace_id` (the column must be the table's first).
pub fn with_trace_id(batch: &RecordBatch, trace_id: &str) -> Result<RecordBatch, ArrowError> {
    let mut cols = batch.columns().to_vec();
    cols[0] = constant_dict(trace_id, batch.num_rows());
    RecordBatch::try_new(batch.schema(), cols)
}

/// The agents an event names: `payload.agents` when it is an array of strings or numbers.
pub fn event_agents(e: &Event) -> Option<Vec<String>> {
    let agents = e.payload.as_ref()?.get("agents")?.as_array()?;
    agents
        .iter()
        .map(|a| match a {
            Value::String(s) => Some(s.clone()),
            Value::Number(n) => Some(n.to_string()),
            _ => None,
        })
        .collect()
}

pub(super) fn events_batch(trace_id: &str, events: &[Event]) -> Result<RecordBatch, ArrowError> {
    let mut seq = Int32Builder::with_capacity(events.len());
    let mut kind = StringDictionaryBuilder::<Int32Type>::new();
    let mut t = Float64Builder::with_capacity(events.len());
    let mut agents = ListBuilder::new(StringBuilder::new());
    let mut payload = StringBuilder::new();
    let mut extra = StringBuilder::new();
    let mut buf = Vec::new();
    for (i, e) in events.iter().enumerate() {
        seq.append_value(i32::try_from(i).unwrap_or(i32::MAX));
        kind.append_value(&e.kind);
        t.append_option(e.t);
        match event_agents(e) {
            Some(list) => {
                for a in list {
                    agents.values().append_value(a);
                }
                agents.append(true);
            }
            None => agents.append(false),
        }
        append_json(&mut payload, &mut buf, e.payload.as_ref());
        append_json_map(&mut extra, &mut buf, &e.extra);
    }
    RecordBatch::try_new(
        EVENTS.clone(),
        vec![
            constant_dict(trace_id, events.len()),
            Arc::new(seq.finish()),
            Arc::new(kind.finish()),
            Arc::new(t.finish()),
            Arc::new(agents.finish()),
            Arc::new(payload.finish()),
            Arc::new(extra.finish()),
        ],
    )
}

/// One row of `scenes`.
pub fn scene_batch(
    scene_id: &str,
    task_id: &str,
    source: &str,
    n_objects: usize,
    spec: &Value,
) -> Result<RecordBatch, ArrowError> {
    RecordBatch::try_new(
        SCENES.clone(),
        vec![
            Arc::new(StringArray::from(vec![scene_id])),
            Arc::new(StringArray::from(vec![task_id])),
            Arc::new(StringArray::from(vec![source])),
            Arc::new(Int64Array::from(vec![n_objects as i64])),
            Arc::new(StringArray::from(vec![spec.to_string()])),
        ],
    )
}

/// A trace table's rows could not be turned back into a trace.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    /// A column the decoder needs is missing or has another type.
    #[error("table {table}: column `{column}` is missing or is not {expected}")]
    Column {
        /// Table name.
        table: &'static str,
        /// Column name.
        column: String,
        /// Expected Arrow type.
        expected: &'static str,
    },
    /// A value that the format requires is null.
    #[error(
        "table {table}: column `{column}` is null in row {row} of trace {trace_id:?}, but {env} traces require it"
    )]
    Null {
        /// Table name.
        table: &'static str,
        /// Column name.
        column: String,
        /// Row within the trace's rows.
        row: usize,
        /// The trace.
        trace_id: String,
        /// Its environment.
        env: Env,
    },
    /// A JSON column does not hold JSON.
    #[error("table {table}: column `{column}` of trace {trace_id:?} holds invalid JSON: {source}")]
    Json {
        /// Table name.
        table: &'static str,
        /// Column name.
        column: &'static str,
        /// The trace.
        trace_id: String,
        /// Parser error.
        source: serde_json::Error,
    },
    /// The `traces` table has no row for the trace.
    #[error("no trace {0:?} in the traces table")]
    NotFound(String),
    /// An Arrow kernel failed.
    #[error(transparent)]
    Arrow(#[from] ArrowError),
}

/// Reads named columns of one batch, converting dictionary strings to plain strings.
struct Cols<'a> {
    table: &'static str,
    batch: &'a RecordBatch,
}

impl<'a> Cols<'a> {
    fn col(&self, name: &str) -> Option<&'a ArrayRef> {
        self.batch.column_by_name(name)
    }

    fn err(&self, column: &str, expected: &'static str) -> DecodeError {
        DecodeError::Column {
            table: self.table,
            column: column.to_string(),
            expected,
        }
    }

    fn f64(&self, name: &str) -> Result<&'a Float64Array, DecodeError> {
        self.col(name)
            .and_then(|c| c.as_primitive_opt())
            .ok_or_else(|| self.err(name, "Float64"))
    }

    fn i64(&self, name: &str) -> Result<&'a Int64Array, DecodeError> {
        self.col(name)
            .and_then(|c| c.as_primitive_opt())
            .ok_or_else(|| self.err(name, "Int64"))
    }

    fn i32(&self, name: &str) -> Result<&'a Int32Array, DecodeError> {
        self.col(name)
            .and_then(|c| c.as_primitive_opt())
            .ok_or_else(|| self.err(name, "Int32"))
    }

    fn bool(&self, name: &str) -> Result<&'a BooleanArray, DecodeError> {
        self.col(name)
            .and_then(|c| c.as_boolean_opt())
            .ok_or_else(|| self.err(name, "Boolean"))
    }

    /// A string column, plain or dictionary-encoded.
    fn str(&self, name: &str) -> Result<StrCol, DecodeError> {
        let c = self.col(name).ok_or_else(|| self.err(name, "Utf8"))?;
        Ok(match c.data_type() {
            DataType::Utf8 => StrCol::Plain(c.as_string::<i32>().clone()),
            DataType::Dictionary(k, v) if **k == DataType::Int32 && **v == DataType::Utf8 => {
                let d = c.as_dictionary::<Int32Type>();
                StrCol::Dict {
                    keys: d.keys().clone(),
                    values: d.values().as_string::<i32>().clone(),
                }
            }
            DataType::Dictionary(_, v) if **v == DataType::Utf8 => {
                StrCol::Plain(cast(c, &DataType::Utf8)?.as_string::<i32>().clone())
            }
            _ => return Err(self.err(name, "Utf8")),
        })
    }
}

/// A string column as it was read: plain, or dictionary-encoded with `Int32` keys (the trace tables'
/// labels), whose rows are looked up in the dictionary rather than cast to plain strings first (a
/// cast copies every row's string, and the frames' labels repeat on every row).
enum StrCol {
    Plain(StringArray),
    Dict {
        keys: Int32Array,
        values: StringArray,
    },
}

impl StrCol {
    fn len(&self) -> usize {
        match self {
            StrCol::Plain(a) => a.len(),
            StrCol::Dict { keys, .. } => keys.len(),
        }
    }

    /// Rows that are null (a key outside the dictionary is not counted).
    fn null_count(&self) -> usize {
        match self {
            StrCol::Plain(a) => a.null_count(),
            StrCol::Dict { keys, .. } => keys.null_count(),
        }
    }

    /// Row `i` (the empty string where it is null).
    fn value(&self, i: usize) -> &str {
        self.get(i).unwrap_or("")
    }

    /// Row `i`, `None` where it is null (or, in a damaged file, its key is outside the dictionary).
    fn get(&self, i: usize) -> Option<&str> {
        match self {
            StrCol::Plain(a) => (!a.is_null(i)).then(|| a.value(i)),
            StrCol::Dict { keys, values } => {
                let k = usize::try_from(keys.value(i)).ok()?;
                (!keys.is_null(i) && k < values.len() && !values.is_null(k))
                    .then(|| values.value(k))
            }
        }
    }
}

fn opt<A: Array + ?Sized, T>(a: &A, i: usize, get: impl Fn(usize) -> T) -> Option<T> {
    (!a.is_null(i)).then(|| get(i))
}

fn parse_map(
    text: Option<&str>,
    table: &'static str,
    column: &'static str,
    trace_id: &str,
) -> Result<JsonMap, DecodeError> {
    match text {
        None => Ok(JsonMap::new()),
        Some(s) => serde_json::from_str(s).map_err(|source| DecodeError::Json {
            table,
            column,
            trace_id: trace_id.to_string(),
            source,
        }),
    }
}

/// The rows of one trace, read from the tables, each sorted in table order (`timesteps` by step,
/// `frames` by step then slot, `events` by seq).
pub struct TraceRows<'a> {
    /// The environment (from the `env=` partition).
    pub env: Env,
    /// The trace's single `traces` row.
    pub trace: &'a RecordBatch,
    /// Its `timesteps` rows.
    pub timesteps: &'a RecordBatch,
    /// Its `frames` rows.
    pub frames: &'a RecordBatch,
    /// Its `events` rows.
    pub events: &'a RecordBatch,
}

/// Rebuilds a trace from its rows: the inverse of [`TraceBatchBuilder`]. Reads the `traces` row,
/// the timesteps, the frames into their timesteps and the events, in that order.
pub fn decode_trace(rows: &TraceRows<'_>) -> Result<Trace, DecodeError> {
    decode_with(rows, |frames, timesteps| frames.fill(timesteps)).map(|(trace, ())| trace)
}

/// Rebuilds a trace from its rows as [`decode_trace`] does, in the same order of reads (and so of
/// errors), with `frames` deciding what becomes of the frame rows: `decode_trace` fills them into
/// their timesteps; [`FramedTrace`](super::FramedTrace) may keep them as columns.
pub(super) fn decode_with<T>(
    rows: &TraceRows<'_>,
    frames: impl FnOnce(&FrameCols<'_>, &mut Vec<Timestep>) -> Result<T, DecodeError>,
) -> Result<(Trace, T), DecodeError> {
    let env = rows.env;
    let tr = Cols {
        table: "traces",
        batch: rows.trace,
    };
    if rows.trace.num_rows() == 0 {
        return Err(DecodeError::NotFound(String::new()));
    }
    let trace_id = tr.str("trace_id")?.value(0).to_string();
    let (outcome, top_extra) = decode_outcome(&tr, &trace_id)?;
    let mut timesteps = decode_timesteps(rows.timesteps, &trace_id)?;
    let cols = FrameCols::read(rows.frames, env, &trace_id)?;
    let kept = frames(&cols, &mut timesteps)?;
    let events = decode_events(rows.events, &trace_id)?;
    let trace = Trace {
        trace_id,
        env,
        task_id: tr.str("task_id")?.value(0).to_string(),
        timesteps,
        events,
        outcome,
        extra: top_extra,
    };
    Ok((trace, kept))
}

/// The outcome and the unknown top-level fields of a trace's `traces` row.
fn decode_outcome(tr: &Cols<'_>, trace_id: &str) -> Result<(Outcome, JsonMap), DecodeError> {
    let outcome_extra = tr.str("outcome_extra")?;
    let extra = tr.str("extra")?;
    let outcome = Outcome {
        success: tr.bool("success")?.value(0),
        terminal_status: tr.str("terminal_status")?.value(0).to_string(),
        metrics: parse_map(
            Some(tr.str("metrics")?.value(0)),
            "traces",
            "metrics",
            trace_id,
        )?,
        extra: parse_map(outcome_extra.get(0), "traces", "outcome_extra", trace_id)?,
    };
    let top_extra = parse_map(extra.get(0), "traces", "extra", trace_id)?;
    Ok((outcome, top_extra))
}

/// The trace's timesteps, without their objects (see [`FrameCols::fill`]).
fn decode_timesteps(batch: &RecordBatch, trace_id: &str) -> Result<Vec<Timestep>, DecodeError> {
    let ts = Cols {
        table: "timesteps",
        batch,
    };
    let (steps, times, step_extra) = (ts.i64("step")?, ts.f64("t")?, ts.str("extra")?);
    let mut timesteps: Vec<Timestep> = Vec::with_capacity(steps.len());
    for i in 0..steps.len() {
        timesteps.push(Timestep {
            index: steps.value(i),
            t: times.value(i),
            objects: Vec::new(),
            extra: parse_map(step_extra.get(i), "timesteps", "extra", trace_id)?,
        });
    }
    Ok(timesteps)
}

/// The trace's events, in table order.
fn decode_events(batch: &RecordBatch, trace_id: &str) -> Result<Vec<Event>, DecodeError> {
    let ev = Cols {
        table: "events",
        batch,
    };
    let (ekind, et, payload, eextra) = (
        ev.str("kind")?,
        ev.f64("t")?,
        ev.str("payload")?,
        ev.str("extra")?,
    );
    let mut events = Vec::with_capacity(ekind.len());
    for i in 0..ekind.len() {
        let payload = match payload.get(i) {
            None => None,
            Some(s) => Some(serde_json::from_str(s).map_err(|source| DecodeError::Json {
                table: "events",
                column: "payload",
                trace_id: trace_id.to_string(),
                source,
            })?),
        };
        events.push(Event {
            kind: ekind.value(i).to_string(),
            t: opt(et, i, |i| et.value(i)),
            payload,
            extra: parse_map(eextra.get(i), "events", "extra", trace_id)?,
        });
    }
    Ok(events)
}

/// The columns of a trace's `frames` rows, read once; a row becomes an object of its
/// environment's kind, and a value that kind needs but the row lacks is [`DecodeError::Null`].
pub(super) struct FrameCols<'a> {
    env: Env,
    trace_id: &'a str,
    step: &'a Int64Array,
    oid: StrCol,
    x: &'a Float64Array,
    y: &'a Float64Array,
    z: &'a Float64Array,
    vx: &'a Float64Array,
    vy: &'a Float64Array,
    vz: &'a Float64Array,
    angle: &'a Float64Array,
    wx: &'a Float64Array,
    wy: &'a Float64Array,
    wz: &'a Float64Array,
    kind: StrCol,
    msc: &'a Int32Array,
    ms: StrCol,
    radius: &'a Float64Array,
    diameter: &'a Float64Array,
    shape: StrCol,
    color: StrCol,
    user: &'a BooleanArray,
    x1: &'a Float64Array,
    y1: &'a Float64Array,
    x2: &'a Float64Array,
    y2: &'a Float64Array,
    elim: &'a Float64Array,
    dynamic: &'a Float64Array,
    joint: &'a Int64Array,
    spring: &'a Int64Array,
    extra: StrCol,
}

impl<'a> FrameCols<'a> {
    /// Every column of `batch` (the `frames` rows of trace `trace_id` of `env`).
    pub(super) fn read(
        batch: &'a RecordBatch,
        env: Env,
        trace_id: &'a str,
    ) -> Result<Self, DecodeError> {
        let fr = Cols {
            table: "frames",
            batch,
        };
        Ok(FrameCols {
            env,
            trace_id,
            step: fr.i64("step")?,
            oid: fr.str("object_id")?,
            x: fr.f64("x")?,
            y: fr.f64("y")?,
            z: fr.f64("z")?,
            vx: fr.f64("vx")?,
            vy: fr.f64("vy")?,
            vz: fr.f64("vz")?,
            angle: fr.f64("angle")?,
            wx: fr.f64("wx")?,
            wy: fr.f64("wy")?,
            wz: fr.f64("wz")?,
            kind: fr.str("kind")?,
            msc: fr.i32("motion_state_code")?,
            ms: fr.str("motion_state")?,
            radius: fr.f64("radius")?,
            diameter: fr.f64("diameter")?,
            shape: fr.str("shape")?,
            color: fr.str("color")?,
            user: fr.bool("is_user_input")?,
            x1: fr.f64("x1")?,
            y1: fr.f64("y1")?,
            x2: fr.f64("x2")?,
            y2: fr.f64("y2")?,
            elim: fr.f64("eliminable")?,
            dynamic: fr.f64("dynamic")?,
            joint: fr.i64("joint")?,
            spring: fr.i64("spring")?,
            extra: fr.str("extra")?,
        })
    }

    /// Appends every row's object to its timestep. Rows arrive sorted by (step, slot), so they
    /// are walked alongside the timesteps; a row whose step has no timestep is an error.
    pub(super) fn fill(&self, timesteps: &mut [Timestep]) -> Result<(), DecodeError> {
        let mut cursor = 0usize;
        for i in 0..self.step.len() {
            let step = self.step.value(i);
            while cursor < timesteps.len() && timesteps[cursor].index < step {
                cursor += 1;
            }
            let Some(target) = timesteps.get_mut(cursor).filter(|t| t.index == step) else {
                return Err(self.null("step", i));
            };
            if target.objects.is_empty() {
                // The step's rows are together: room for all of them at once, not grown by doubling.
                let run = (i..self.step.len())
                    .take_while(|&j| self.step.value(j) == step)
                    .count();
                target.objects.reserve_exact(run);
            }
            let body = match self.env {
                Env::Pooltool => Body::Pool(self.pool_ball(i)?),
                Env::Phyre => Body::Phyre(self.phyre_object(i)?),
                Env::Iphyre => Body::Iphyre(self.iphyre_object(i)?),
            };
            let extra = parse_map(self.extra.get(i), "frames", "extra", self.trace_id)?;
            target.objects.push(Object { body, extra });
        }
        Ok(())
    }

    /// For a billiards trace whose every row [`FrameCols::fill`] would take as it is (each row's
    /// step a timestep's, every value a ball needs present, no unknown fields), each timestep's first
    /// row and then the number of rows; `None` when any row is otherwise (`fill` then builds the
    /// objects, or names the row that is wrong).
    pub(super) fn plain_pool_starts(&self, timesteps: &[Timestep]) -> Option<Vec<usize>> {
        if self.env != Env::Pooltool || self.extra.len() != self.extra.null_count() {
            return None;
        }
        let floats = [
            self.z,
            self.vx,
            self.vy,
            self.vz,
            self.wx,
            self.wy,
            self.wz,
            self.radius,
        ];
        if floats.iter().any(|a| a.null_count() > 0) || self.msc.null_count() > 0 {
            return None;
        }
        let n = self.step.len();
        if !(0..n).all(|i| self.kind.get(i).is_some() && self.ms.get(i).is_some()) {
            return None;
        }
        // Rows to timesteps as `fill` walks them: each run of rows of one step to the first
        // timestep of that index at or after the previous run's (a repeated index gets none: its
        // rows went to the first). A row that would go back is one `fill` rejects.
        let mut starts = Vec::with_capacity(timesteps.len() + 1);
        let mut i = 0usize;
        for ts in timesteps {
            starts.push(i);
            while i < n && self.step.value(i) == ts.index {
                i += 1;
            }
            if i < n && self.step.value(i) < ts.index {
                return None;
            }
        }
        starts.push(i);
        (i == n).then_some(starts)
    }

    /// Frame row `i`'s ball, borrowed: the values [`FrameCols::pool_ball`] copies, for a row
    /// [`FrameCols::plain_pool_starts`] has checked (a missing string reads as empty here).
    pub(super) fn ball_view(&self, i: usize) -> BallView<'_> {
        BallView {
            kind: self.kind.value(i),
            ball_id: self.oid.value(i),
            position: [self.x.value(i), self.y.value(i), self.z.value(i)],
            velocity: [self.vx.value(i), self.vy.value(i), self.vz.value(i)],
            angular_velocity: [self.wx.value(i), self.wy.value(i), self.wz.value(i)],
            motion_state_code: i64::from(self.msc.value(i)),
            motion_state: self.ms.value(i),
            radius: self.radius.value(i),
        }
    }

    fn null(&self, col: &str, i: usize) -> DecodeError {
        DecodeError::Null {
            table: "frames",
            column: col.into(),
            row: i,
            trace_id: self.trace_id.to_string(),
            env: self.env,
        }
    }

    /// Row `i` of a float column the object needs.
    fn need_f(&self, a: &Float64Array, col: &str, i: usize) -> Result<f64, DecodeError> {
        if a.is_null(i) {
            Err(self.null(col, i))
        } else {
            Ok(a.value(i))
        }
    }

    /// Row `i` of a string column the object needs.
    fn need_s<'s>(&self, a: &'s StrCol, col: &str, i: usize) -> Result<&'s str, DecodeError> {
        a.get(i).ok_or_else(|| self.null(col, i))
    }

    fn pool_ball(&self, i: usize) -> Result<PoolBall, DecodeError> {
        let msc = self.msc;
        Ok(PoolBall {
            kind: self.need_s(&self.kind, "kind", i)?.into(),
            ball_id: self.oid.value(i).into(),
            position: [
                self.x.value(i),
                self.y.value(i),
                self.need_f(self.z, "z", i)?,
            ],
            velocity: [
                self.need_f(self.vx, "vx", i)?,
                self.need_f(self.vy, "vy", i)?,
                self.need_f(self.vz, "vz", i)?,
            ],
            angular_velocity: [
                self.need_f(self.wx, "wx", i)?,
                self.need_f(self.wy, "wy", i)?,
                self.need_f(self.wz, "wz", i)?,
            ],
            motion_state_code: opt(msc, i, |i| msc.value(i) as i64)
                .ok_or_else(|| self.null("motion_state_code", i))?,
            motion_state: self.need_s(&self.ms, "motion_state", i)?.into(),
            radius: self.need_f(self.radius, "radius", i)?,
        })
    }

    fn phyre_object(&self, i: usize) -> Result<PhyreObject, DecodeError> {
        let user = self.user;
        Ok(PhyreObject {
            object_index: self
                .oid
                .value(i)
                .parse()
                .map_err(|_| self.null("object_id", i))?,
            shape: self.need_s(&self.shape, "shape", i)?.to_string(),
            color: self.need_s(&self.color, "color", i)?.to_string(),
            diameter: self.need_f(self.diameter, "diameter", i)?,
            x: self.x.value(i),
            y: self.y.value(i),
            angle: self.need_f(self.angle, "angle", i)?,
            vx: self.need_f(self.vx, "vx", i)?,
            vy: self.need_f(self.vy, "vy", i)?,
            angular_velocity: self.need_f(self.wz, "wz", i)?,
            is_user_input: opt(user, i, |i| user.value(i))
                .ok_or_else(|| self.null("is_user_input", i))?,
        })
    }

    fn iphyre_object(&self, i: usize) -> Result<IphyreObject, DecodeError> {
        let (joint, spring) = (self.joint, self.spring);
        let (angle, vx, vy, wz) = (self.angle, self.vx, self.vy, self.wz);
        Ok(IphyreObject {
            index: self
                .oid
                .value(i)
                .parse()
                .map_err(|_| self.null("object_id", i))?,
            x1: self.need_f(self.x1, "x1", i)?,
            y1: self.need_f(self.y1, "y1", i)?,
            x2: self.need_f(self.x2, "x2", i)?,
            y2: self.need_f(self.y2, "y2", i)?,
            radius: self.need_f(self.radius, "radius", i)?,
            eliminable: self.need_f(self.elim, "eliminable", i)?,
            dynamic: self.need_f(self.dynamic, "dynamic", i)?,
            joint: opt(joint, i, |i| joint.value(i)).ok_or_else(|| self.null("joint", i))?,
            spring: opt(spring, i, |i| spring.value(i)).ok_or_else(|| self.null("spring", i))?,
            angle: opt(angle, i, |i| angle.value(i)),
            vx: opt(vx, i, |i| vx.value(i)),
            vy: opt(vy, i, |i| vy.value(i)),
            angular_velocity: opt(wz, i, |i| wz.value(i)),
        })
    }
}
