//! Traces held as columns: simulator state goes straight into typed column vectors, without an
//! [`Object`] (and its strings) per body per step; the paper-layout [`Trace`] is built only when a
//! consumer asks for it ([`TraceColumns::into_trace`]).
//!
//! **Owns:** [`TraceColumns`] (a trace's head — id, task, events, outcome, extra — plus its frames in
//! columns), the per-environment frame builders ([`PoolFrames`], [`PhyreFrames`], [`IphyreFrames`])
//! and their conversion into the trace tables' record batches ([`TraceColumns::batches`]).
//! **Does not:** simulate (each environment's `to_trace` fills a builder) or write files (`store/`).
//!
//! Object ids and the per-object strings (shapes, colours, kinds) are given once per trace when the
//! builder is made; a frame row holds the object's position in that list. Dictionary columns are made
//! from those lists with values in order of first appearance, exactly as [`super::TraceBatchBuilder`]
//! builds them from the paper layout, so both paths give the same record batches (tests below and in
//! each environment's `to_trace`).

use std::borrow::Cow;
use std::sync::Arc;

use arrow::array::{
    ArrayRef, BooleanArray, DictionaryArray, Float64Array, Int32Array, Int64Array, RecordBatch,
    StringArray, new_null_array,
};
use arrow::datatypes::{DataType, Int32Type};
use arrow::error::ArrowError;

use super::Env;
use super::batch::{TraceBatches, TraceMeta, constant_dict, events_batch, traces_batch};
use super::model::{
    Body, Event, IphyreObject, JsonMap, Object, Outcome, PhyreObject, PoolBall, Timestep, Trace,
};
use super::pool_steps::BallView;
use super::schema::{FRAMES, TIMESTEPS};
use super::short_str::ShortStr;
use super::view::{ColumnView, Keys};

/// The rows every environment shares: timesteps, and per frame row the object it belongs to and
/// its planar centre.
#[derive(Clone, Debug, Default)]
struct Rows {
    /// Timestep numbers.
    step: Vec<i64>,
    /// Timestep times (s).
    t: Vec<f64>,
    /// Frame rows per timestep.
    count: Vec<i32>,
    /// Per frame row: the object's position in the trace's object list.
    obj: Vec<u32>,
    /// Per frame row: centre x.
    x: Vec<f64>,
    /// Per frame row: centre y.
    y: Vec<f64>,
}

impl Rows {
    fn with_capacity(steps: usize, rows: usize) -> Self {
        Rows {
            step: Vec::with_capacity(steps),
            t: Vec::with_capacity(steps),
            count: Vec::with_capacity(steps),
            obj: Vec::with_capacity(rows),
            x: Vec::with_capacity(rows),
            y: Vec::with_capacity(rows),
        }
    }

    fn begin_step(&mut self, step: i64, t: f64) {
        self.step.push(step);
        self.t.push(t);
        self.count.push(0);
    }

    fn row(&mut self, obj: usize, x: f64, y: f64) {
        self.obj.push(u32::try_from(obj).unwrap_or(u32::MAX));
        self.x.push(x);
        self.y.push(y);
        if let Some(c) = self.count.last_mut() {
            *c += 1;
        }
    }

    /// Per frame row: (timestep position, slot within the timestep).
    fn positions(&self) -> impl Iterator<Item = (usize, i32)> + '_ {
        self.count
            .iter()
            .enumerate()
            .flat_map(|(s, &c)| (0..c).map(move |k| (s, k)))
    }
}

/// A dictionary column from one string per row, given as an index into `values` (which may repeat
/// strings); dictionary values in order of first appearance, as `StringDictionaryBuilder` makes them.
fn dict_column(values: &[&str], keys: impl Iterator<Item = usize>) -> (ArrayRef, usize) {
    // Distinct strings of `values`, then each row's first-appearance key.
    let mut distinct_of: Vec<usize> = Vec::with_capacity(values.len());
    for (i, v) in values.iter().enumerate() {
        let d = values[..i].iter().position(|w| w == v).unwrap_or(i);
        distinct_of.push(d);
    }
    let mut remap: Vec<i32> = vec![-1; values.len()];
    let mut order: Vec<&str> = Vec::new();
    let out: Vec<i32> = keys
        .map(|k| {
            let d = distinct_of.get(k).copied().unwrap_or(0);
            if remap[d] < 0 {
                remap[d] = order.len() as i32;
                order.push(values[d]);
            }
            remap[d]
        })
        .collect();
    let distinct = order.len();
    let array = DictionaryArray::<Int32Type>::try_new(
        Int32Array::from(out),
        Arc::new(StringArray::from(order)),
    )
    .expect("keys index the values");
    (Arc::new(array), distinct)
}

fn floats(v: Vec<f64>) -> ArrayRef {
    Arc::new(Float64Array::from(v))
}

fn nulls(dt: &DataType, n: usize) -> ArrayRef {
    new_null_array(dt, n)
}

/// A per-object value for every row.
fn per_row<T: Copy>(rows: &Rows, of_object: &[T]) -> Vec<T> {
    rows.obj.iter().map(|&o| of_object[o as usize]).collect()
}

/// A billiards trace's strings as the paper layout holds them, made once per trace: each ball's
/// `PoolBall` then copies them (inline, no allocation) instead of building three `String`s.
#[derive(Default)]
struct PoolStrings {
    kind: ShortStr,
    ids: Vec<ShortStr>,
    states: Vec<ShortStr>,
}

impl PoolStrings {
    /// The strings of `frames` (none for the other environments).
    fn of(frames: &Frames) -> Self {
        match frames {
            Frames::Pool(f) => PoolStrings {
                kind: ShortStr::from("ball"),
                ids: f.ids.iter().map(ShortStr::from).collect(),
                states: f.state_names.iter().map(|&s| ShortStr::from(s)).collect(),
            },
            Frames::Phyre(_) | Frames::Iphyre(_) => PoolStrings::default(),
        }
    }
}

/// Billiard balls, pooltool's layout: every column of a `PoolBall`.
#[derive(Clone, Debug)]
pub struct PoolFrames {
    ids: Vec<String>,
    radius: Vec<f64>,
    state_names: &'static [&'static str],
    rows: Rows,
    z: Vec<f64>,
    v: [Vec<f64>; 3],
    w: [Vec<f64>; 3],
    code: Vec<i32>,
}

impl PoolFrames {
    /// Balls `ids` with their radii (m); `state_names[code]` names motion-state code `code`.
    /// `steps` (the expected number of timesteps) only sizes the buffers.
    pub fn new(
        ids: Vec<String>,
        radius: Vec<f64>,
        state_names: &'static [&'static str],
        steps: usize,
    ) -> Self {
        let rows = steps * ids.len();
        let col = || Vec::with_capacity(rows);
        PoolFrames {
            ids,
            radius,
            state_names,
            rows: Rows::with_capacity(steps, rows),
            z: col(),
            v: [col(), col(), col()],
            w: [col(), col(), col()],
            code: Vec::with_capacity(rows),
        }
    }

    /// Starts timestep `step` at time `t`.
    pub fn begin_step(&mut self, step: i64, t: f64) {
        self.rows.begin_step(step, t);
    }

    /// Ball `ball` (its position in the ids) in the current timestep.
    pub fn ball(&mut self, ball: usize, r: &[f64; 3], v: &[f64; 3], w: &[f64; 3], code: u8) {
        self.rows.row(ball, r[0], r[1]);
        self.z.push(r[2]);
        for k in 0..3 {
            self.v[k].push(v[k]);
            self.w[k].push(w[k]);
        }
        self.code.push(i32::from(code));
    }
}

impl PoolFrames {
    /// Each timestep's time (s).
    pub fn times(&self) -> &[f64] {
        &self.rows.t
    }

    /// Each timestep's first frame row, then the number of rows (so step `k` holds rows
    /// `starts[k]..starts[k + 1]`).
    pub fn step_starts(&self) -> Vec<usize> {
        let mut starts = Vec::with_capacity(self.rows.count.len() + 1);
        let mut next = 0usize;
        starts.push(0);
        for &c in &self.rows.count {
            next += usize::try_from(c).unwrap_or(0);
            starts.push(next);
        }
        starts
    }

    /// Frame row `i`'s ball as rules read it: the same values [`Frames::timesteps`] gives its
    /// `PoolBall` (an unknown motion-state code has the empty name there too).
    pub fn ball_state(&self, i: usize) -> BallView<'_> {
        let o = self.rows.obj[i] as usize;
        let c = self.code[i];
        BallView {
            kind: "ball",
            ball_id: &self.ids[o],
            position: [self.rows.x[i], self.rows.y[i], self.z[i]],
            velocity: [self.v[0][i], self.v[1][i], self.v[2][i]],
            angular_velocity: [self.w[0][i], self.w[1][i], self.w[2][i]],
            motion_state_code: i64::from(c),
            motion_state: usize::try_from(c)
                .ok()
                .and_then(|c| self.state_names.get(c))
                .copied()
                .unwrap_or(""),
            radius: self.radius[o],
        }
    }

    /// The paper-layout objects of frame rows `range` (one timestep): what [`Frames::body`] gives
    /// row by row, with the columns sliced once (the per-sample trace of an optimisation chain is
    /// built here, one object per ball per step).
    fn objects(&self, range: std::ops::Range<usize>, s: &PoolStrings) -> Vec<Object> {
        let rows = &self.rows;
        let obj = &rows.obj[range.clone()];
        let n = obj.len();
        let (x, y, z) = (
            &rows.x[range.clone()],
            &rows.y[range.clone()],
            &self.z[range.clone()],
        );
        let [vx, vy, vz] = self.v.each_ref().map(|c| &c[range.clone()]);
        let [wx, wy, wz] = self.w.each_ref().map(|c| &c[range.clone()]);
        let code = &self.code[range.clone()];
        let mut out = Vec::with_capacity(n);
        for k in 0..n {
            let o = obj[k] as usize;
            let c = code[k];
            out.push(Object {
                body: Body::Pool(PoolBall {
                    kind: s.kind.clone(),
                    ball_id: s.ids[o].clone(),
                    position: [x[k], y[k], z[k]],
                    velocity: [vx[k], vy[k], vz[k]],
                    angular_velocity: [wx[k], wy[k], wz[k]],
                    motion_state_code: i64::from(c),
                    motion_state: usize::try_from(c)
                        .ok()
                        .and_then(|c| s.states.get(c))
                        .cloned()
                        .unwrap_or_default(),
                    radius: self.radius[o],
                }),
                extra: JsonMap::new(),
            });
        }
        out
    }
}

/// PHYRE bodies: `object_index, shape, color, diameter, x, y, angle, vx, vy, angular_velocity,
/// is_user_input`.
#[derive(Clone, Debug)]
pub struct PhyreFrames {
    ids: Vec<String>,
    shape: Vec<String>,
    color: Vec<&'static str>,
    diameter: Vec<f64>,
    user: Vec<bool>,
    rows: Rows,
    angle: Vec<f64>,
    vx: Vec<f64>,
    vy: Vec<f64>,
    wz: Vec<f64>,
}

/// What a PHYRE body keeps for the whole episode.
#[derive(Clone, Debug)]
pub struct PhyreBody {
    /// Shape name (`ball`, `bar`, `jar`, `wall`, …).
    pub shape: String,
    /// Colour name.
    pub color: &'static str,
    /// Diameter (px).
    pub diameter: f64,
    /// Whether the action placed it.
    pub is_user_input: bool,
}

impl PhyreFrames {
    /// Bodies `0..bodies.len()` (the object id is the position); `steps` and `rows` size the buffers.
    pub fn new(bodies: Vec<PhyreBody>, steps: usize, rows: usize) -> Self {
        let col = || Vec::with_capacity(rows);
        let mut out = PhyreFrames {
            ids: (0..bodies.len()).map(|i| i.to_string()).collect(),
            shape: Vec::with_capacity(bodies.len()),
            color: Vec::with_capacity(bodies.len()),
            diameter: Vec::with_capacity(bodies.len()),
            user: Vec::with_capacity(bodies.len()),
            rows: Rows::with_capacity(steps, rows),
            angle: col(),
            vx: col(),
            vy: col(),
            wz: col(),
        };
        for b in bodies {
            out.shape.push(b.shape);
            out.color.push(b.color);
            out.diameter.push(b.diameter);
            out.user.push(b.is_user_input);
        }
        out
    }

    /// Starts timestep `step` at time `t`.
    pub fn begin_step(&mut self, step: i64, t: f64) {
        self.rows.begin_step(step, t);
    }

    /// Body `index` in the current timestep. `state` is `[x, y, angle, vx, vy, angular_velocity]`.
    pub fn body(&mut self, index: usize, state: [f64; 6]) {
        self.rows.row(
            index.min(self.ids.len().saturating_sub(1)),
            state[0],
            state[1],
        );
        self.angle.push(state[2]);
        self.vx.push(state[3]);
        self.vy.push(state[4]);
        self.wz.push(state[5]);
    }
}

/// What an I-PHYRE object keeps for the whole episode.
#[derive(Clone, Copy, Debug)]
pub struct IphyreBody {
    /// Radius (px).
    pub radius: f64,
    /// 1 when a click can remove it.
    pub eliminable: f64,
    /// 1 when it moves.
    pub dynamic: f64,
    /// Pin joint (1-based, 0 for none).
    pub joint: i64,
    /// Spring (1-based, 0 for none).
    pub spring: i64,
}

/// I-PHYRE blocks and balls: `index, x1, y1, x2, y2, radius, eliminable, dynamic, joint, spring,
/// angle, vx, vy, angular_velocity`.
#[derive(Clone, Debug)]
pub struct IphyreFrames {
    ids: Vec<String>,
    bodies: Vec<IphyreBody>,
    rows: Rows,
    ends: [Vec<f64>; 4],
    angle: Vec<f64>,
    vx: Vec<f64>,
    vy: Vec<f64>,
    wz: Vec<f64>,
}

impl IphyreFrames {
    /// Objects `0..bodies.len()` (the object id is the position); `steps` and `rows` size the buffers.
    pub fn new(bodies: Vec<IphyreBody>, steps: usize, rows: usize) -> Self {
        let col = || Vec::with_capacity(rows);
        IphyreFrames {
            ids: (0..bodies.len()).map(|i| i.to_string()).collect(),
            bodies,
            rows: Rows::with_capacity(steps, rows),
            ends: [col(), col(), col(), col()],
            angle: col(),
            vx: col(),
            vy: col(),
            wz: col(),
        }
    }

    /// Starts timestep `step` at time `t`.
    pub fn begin_step(&mut self, step: i64, t: f64) {
        self.rows.begin_step(step, t);
    }

    /// Object `index` in the current timestep: its ends, angle, centre velocity and angular velocity.
    pub fn object(
        &mut self,
        index: usize,
        p1: [f64; 2],
        p2: [f64; 2],
        angle: f64,
        v: [f64; 2],
        w: f64,
    ) {
        let index = index.min(self.ids.len().saturating_sub(1));
        self.rows
            .row(index, (p1[0] + p2[0]) / 2.0, (p1[1] + p2[1]) / 2.0);
        self.ends[0].push(p1[0]);
        self.ends[1].push(p1[1]);
        self.ends[2].push(p2[0]);
        self.ends[3].push(p2[1]);
        self.angle.push(angle);
        self.vx.push(v[0]);
        self.vy.push(v[1]);
        self.wz.push(w);
    }
}

/// One environment's frames in columns.
#[derive(Clone, Debug)]
pub enum Frames {
    /// Billiards.
    Pool(PoolFrames),
    /// PHYRE.
    Phyre(PhyreFrames),
    /// I-PHYRE.
    Iphyre(IphyreFrames),
}

impl From<PoolFrames> for Frames {
    fn from(f: PoolFrames) -> Self {
        Frames::Pool(f)
    }
}

impl From<PhyreFrames> for Frames {
    fn from(f: PhyreFrames) -> Self {
        Frames::Phyre(f)
    }
}

impl From<IphyreFrames> for Frames {
    fn from(f: IphyreFrames) -> Self {
        Frames::Iphyre(f)
    }
}

/// Whether, at every row, the sum of the `K` columns' values (added in column order, as
/// [`Frames::first_non_finite`] adds them) is finite; false also when the columns' lengths differ.
/// `s * 0.0` is ±0 for a finite `s` and NaN otherwise, and a NaN stays in its lane's total.
fn finite_sums<const K: usize>(cols: [&[f64]; K]) -> bool {
    const LANES: usize = 8;
    let n = cols.first().map_or(0, |c| c.len());
    if cols.iter().any(|c| c.len() != n) {
        return false;
    }
    let sum = |i: usize| cols.iter().fold(0.0, |s, c| s + c[i]);
    let mut acc = [0.0f64; LANES];
    let full = n - n % LANES;
    for at in (0..full).step_by(LANES) {
        let blocks: [&[f64; LANES]; K] = std::array::from_fn(|k| {
            cols[k][at..at + LANES]
                .try_into()
                .expect("a block of LANES values")
        });
        for (l, a) in acc.iter_mut().enumerate() {
            let s = blocks.iter().fold(0.0, |s, b| s + b[l]);
            *a += s * 0.0;
        }
    }
    let tail = (full..n).fold(0.0, |t, i| t + sum(i) * 0.0);
    tail == 0.0 && acc.iter().all(|a| *a == 0.0)
}

impl Frames {
    fn rows(&self) -> &Rows {
        match self {
            Frames::Pool(f) => &f.rows,
            Frames::Phyre(f) => &f.rows,
            Frames::Iphyre(f) => &f.rows,
        }
    }

    fn ids(&self) -> &[String] {
        match self {
            Frames::Pool(f) => &f.ids,
            Frames::Phyre(f) => &f.ids,
            Frames::Iphyre(f) => &f.ids,
        }
    }

    /// The environment.
    pub fn env(&self) -> Env {
        match self {
            Frames::Pool(_) => Env::Pooltool,
            Frames::Phyre(_) => Env::Phyre,
            Frames::Iphyre(_) => Env::Iphyre,
        }
    }

    /// Number of timesteps.
    pub fn steps(&self) -> usize {
        self.rows().step.len()
    }

    /// Number of frame rows.
    pub fn len(&self) -> usize {
        self.rows().obj.len()
    }

    /// Whether there are no frame rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The first object state that is not finite, as [`Trace::first_non_finite`] reports it:
    /// (timestep index, object position in the step, field).
    pub fn first_non_finite(&self) -> Option<(i64, usize, &'static str)> {
        let rows = self.rows();
        // Whole columns first, in blocks the compiler vectorises: when every sum the row-by-row
        // search checks is finite, it would find nothing.
        let finite = match self {
            Frames::Pool(f) => {
                finite_sums([&rows.x, &rows.y, &f.z])
                    && finite_sums([&f.v[0], &f.v[1], &f.v[2]])
                    && finite_sums([&f.w[0], &f.w[1], &f.w[2]])
            }
            Frames::Phyre(f) => [&rows.x, &rows.y, &f.angle]
                .iter()
                .all(|c| finite_sums([c.as_slice()])),
            Frames::Iphyre(f) => f.ends.iter().all(|c| finite_sums([c.as_slice()])),
        };
        if finite {
            return None;
        }
        let bad = |i: usize| -> Option<&'static str> {
            let check = |fields: &[(&'static str, f64)]| {
                fields.iter().find(|(_, v)| !v.is_finite()).map(|(n, _)| *n)
            };
            match self {
                Frames::Pool(f) => check(&[
                    ("position", rows.x[i] + rows.y[i] + f.z[i]),
                    ("velocity", f.v[0][i] + f.v[1][i] + f.v[2][i]),
                    ("angular_velocity", f.w[0][i] + f.w[1][i] + f.w[2][i]),
                ]),
                Frames::Phyre(f) => {
                    check(&[("x", rows.x[i]), ("y", rows.y[i]), ("angle", f.angle[i])])
                }
                Frames::Iphyre(f) => check(&[
                    ("x1", f.ends[0][i]),
                    ("y1", f.ends[1][i]),
                    ("x2", f.ends[2][i]),
                    ("y2", f.ends[3][i]),
                ]),
            }
        };
        rows.positions()
            .enumerate()
            .find_map(|(i, (s, k))| bad(i).map(|field| (rows.step[s], k as usize, field)))
    }

    /// The body of frame row `i`, in the paper's layout. `pool` holds a billiards trace's strings,
    /// made once per trace ([`PoolStrings`]).
    fn body(&self, i: usize, pool: &PoolStrings) -> Body {
        let rows = self.rows();
        let o = rows.obj[i] as usize;
        match self {
            Frames::Pool(f) => Body::Pool(PoolBall {
                kind: pool.kind.clone(),
                ball_id: pool.ids[o].clone(),
                position: [rows.x[i], rows.y[i], f.z[i]],
                velocity: [f.v[0][i], f.v[1][i], f.v[2][i]],
                angular_velocity: [f.w[0][i], f.w[1][i], f.w[2][i]],
                motion_state_code: i64::from(f.code[i]),
                motion_state: usize::try_from(f.code[i])
                    .ok()
                    .and_then(|c| pool.states.get(c))
                    .cloned()
                    .unwrap_or_default(),
                radius: f.radius[o],
            }),
            Frames::Phyre(f) => Body::Phyre(PhyreObject {
                object_index: o as i64,
                shape: f.shape[o].clone(),
                color: f.color[o].to_string(),
                diameter: f.diameter[o],
                x: rows.x[i],
                y: rows.y[i],
                angle: f.angle[i],
                vx: f.vx[i],
                vy: f.vy[i],
                angular_velocity: f.wz[i],
                is_user_input: f.user[o],
            }),
            Frames::Iphyre(f) => {
                let b = &f.bodies[o];
                Body::Iphyre(IphyreObject {
                    index: o as i64,
                    x1: f.ends[0][i],
                    y1: f.ends[1][i],
                    x2: f.ends[2][i],
                    y2: f.ends[3][i],
                    radius: b.radius,
                    eliminable: b.eliminable,
                    dynamic: b.dynamic,
                    joint: b.joint,
                    spring: b.spring,
                    angle: Some(f.angle[i]),
                    vx: Some(f.vx[i]),
                    vy: Some(f.vy[i]),
                    angular_velocity: Some(f.wz[i]),
                })
            }
        }
    }

    /// The paper-layout timesteps.
    pub fn timesteps(&self) -> Vec<Timestep> {
        let rows = self.rows();
        let pool = PoolStrings::of(self);
        let mut next = 0usize;
        rows.step
            .iter()
            .zip(&rows.t)
            .zip(&rows.count)
            .map(|((&index, &t), &count)| {
                let range = next..next + count as usize;
                let objects = match self {
                    Frames::Pool(f) => f.objects(range, &pool),
                    _ => range
                        .map(|i| Object {
                            body: self.body(i, &pool),
                            extra: JsonMap::new(),
                        })
                        .collect(),
                };
                next += count as usize;
                Timestep {
                    index,
                    t,
                    objects,
                    extra: JsonMap::new(),
                }
            })
            .collect()
    }

    /// The number of distinct object ids among the frame rows (as the `frames` batch's
    /// `object_id` dictionary counts them).
    fn distinct_objects(&self) -> usize {
        let ids = self.ids();
        let mut used = vec![false; ids.len()];
        for &o in &self.rows().obj {
            if let Some(u) = used.get_mut(o as usize) {
                *u = true;
            }
        }
        let mut seen: Vec<&str> = Vec::new();
        for (id, _) in ids.iter().zip(&used).filter(|(_, u)| **u) {
            if !seen.contains(&id.as_str()) {
                seen.push(id);
            }
        }
        seen.len()
    }

    /// The `timesteps` rows of trace `trace_id` as column views, in the schema's order.
    fn timestep_views<'a>(&'a self, trace_id: &'a str) -> Vec<ColumnView<'a>> {
        let rows = self.rows();
        vec![
            ColumnView::StrConst(trace_id),
            ColumnView::I64(Cow::Borrowed(&rows.step)),
            ColumnView::F64(Cow::Borrowed(&rows.t)),
            ColumnView::I32(Cow::Borrowed(&rows.count)),
            ColumnView::Null,
        ]
    }

    /// The `frames` rows of trace `trace_id` as column views, in the schema's order: the same
    /// values as [`Frames::batches`]' columns, without building them.
    fn frame_views<'a>(&'a self, trace_id: &'a str) -> Vec<ColumnView<'a>> {
        use ColumnView::{F64, Null};
        let rows = self.rows();
        let obj = || Keys::U32(Cow::Borrowed(&rows.obj));
        let f = |v: &'a [f64]| F64(Cow::Borrowed(v));
        let mut cols = vec![
            ColumnView::StrConst(trace_id),
            ColumnView::I64Runs {
                values: &rows.step,
                counts: &rows.count,
            },
            ColumnView::F64Runs {
                values: &rows.t,
                counts: &rows.count,
            },
            ColumnView::Slots(&rows.count),
            ColumnView::Str {
                values: self.ids().iter().map(String::as_str).collect(),
                keys: obj(),
            },
            f(&rows.x),
            f(&rows.y),
        ];
        // Columns in `FRAMES` order from `z` to `spring`.
        let env: Vec<ColumnView<'a>> = match self {
            Frames::Pool(p) => vec![
                f(&p.z),
                f(&p.v[0]),
                f(&p.v[1]),
                f(&p.v[2]),
                Null,
                f(&p.w[0]),
                f(&p.w[1]),
                f(&p.w[2]),
                ColumnView::StrConst("ball"),
                ColumnView::I32(Cow::Borrowed(&p.code)),
                ColumnView::Str {
                    values: p.state_names.to_vec(),
                    keys: Keys::I32(&p.code),
                },
                ColumnView::F64Of {
                    values: Cow::Borrowed(&p.radius),
                    keys: obj(),
                },
                Null,
                Null,
                Null,
                Null,
                Null,
                Null,
                Null,
                Null,
                Null,
                Null,
                Null,
                Null,
            ],
            Frames::Phyre(p) => vec![
                Null,
                f(&p.vx),
                f(&p.vy),
                Null,
                f(&p.angle),
                Null,
                Null,
                f(&p.wz),
                Null,
                Null,
                Null,
                Null,
                ColumnView::F64Of {
                    values: Cow::Borrowed(&p.diameter),
                    keys: obj(),
                },
                ColumnView::Str {
                    values: p.shape.iter().map(String::as_str).collect(),
                    keys: obj(),
                },
                ColumnView::Str {
                    values: p.color.clone(),
                    keys: obj(),
                },
                ColumnView::BoolOf {
                    values: Cow::Borrowed(&p.user),
                    keys: obj(),
                },
                Null,
                Null,
                Null,
                Null,
                Null,
                Null,
                Null,
                Null,
            ],
            Frames::Iphyre(p) => {
                let of = |get: fn(&IphyreBody) -> f64| ColumnView::F64Of {
                    values: Cow::Owned(p.bodies.iter().map(get).collect()),
                    keys: obj(),
                };
                let ofi = |get: fn(&IphyreBody) -> i64| ColumnView::I64Of {
                    values: Cow::Owned(p.bodies.iter().map(get).collect()),
                    keys: obj(),
                };
                vec![
                    Null,
                    f(&p.vx),
                    f(&p.vy),
                    Null,
                    f(&p.angle),
                    Null,
                    Null,
                    f(&p.wz),
                    Null,
                    Null,
                    Null,
                    of(|b| b.radius),
                    Null,
                    Null,
                    Null,
                    Null,
                    f(&p.ends[0]),
                    f(&p.ends[1]),
                    f(&p.ends[2]),
                    f(&p.ends[3]),
                    of(|b| b.eliminable),
                    of(|b| b.dynamic),
                    ofi(|b| b.joint),
                    ofi(|b| b.spring),
                ]
            }
        };
        cols.extend(env);
        cols.push(Null);
        cols
    }

    fn take_rows(&mut self) -> Rows {
        std::mem::take(match self {
            Frames::Pool(f) => &mut f.rows,
            Frames::Phyre(f) => &mut f.rows,
            Frames::Iphyre(f) => &mut f.rows,
        })
    }

    /// The `timesteps` and `frames` batches of trace `trace_id`, and the number of distinct objects.
    fn batches(mut self, trace_id: &str) -> Result<(RecordBatch, RecordBatch, usize), ArrowError> {
        let rows = self.take_rows();
        let n = rows.obj.len();
        let steps = rows.step.len();
        let mut frame_step = Vec::with_capacity(n);
        let mut frame_t = Vec::with_capacity(n);
        let mut slot = Vec::with_capacity(n);
        for (s, k) in rows.positions() {
            frame_step.push(rows.step[s]);
            frame_t.push(rows.t[s]);
            slot.push(k);
        }
        let keys = || rows.obj.iter().map(|&o| o as usize);
        let ids: Vec<&str> = self.ids().iter().map(String::as_str).collect();
        let (object_id, distinct) = dict_column(&ids, keys());
        let f64n = || nulls(&DataType::Float64, n);
        let dictn = || nulls(&super::schema::dict_utf8(), n);
        let i64n = || nulls(&DataType::Int64, n);
        // Columns in `FRAMES` order from `z` to `spring`.
        let env_cols: Vec<ArrayRef> = match self {
            Frames::Pool(f) => {
                let PoolFrames {
                    radius,
                    state_names,
                    z,
                    v: [vx, vy, vz],
                    w: [wx, wy, wz],
                    code,
                    ..
                } = f;
                let balls = vec!["ball"; radius.len()];
                let (kind, _) = dict_column(&balls, keys());
                let (state, _) = dict_column(
                    state_names,
                    code.iter().map(|&c| usize::try_from(c).unwrap_or(0)),
                );
                let radius = per_row(&rows, &radius);
                vec![
                    floats(z),
                    floats(vx),
                    floats(vy),
                    floats(vz),
                    f64n(),
                    floats(wx),
                    floats(wy),
                    floats(wz),
                    kind,
                    Arc::new(Int32Array::from(code)),
                    state,
                    floats(radius),
                    f64n(),
                    dictn(),
                    dictn(),
                    nulls(&DataType::Boolean, n),
                    f64n(),
                    f64n(),
                    f64n(),
                    f64n(),
                    f64n(),
                    f64n(),
                    i64n(),
                    i64n(),
                ]
            }
            Frames::Phyre(f) => {
                let shapes: Vec<&str> = f.shape.iter().map(String::as_str).collect();
                let (shape, _) = dict_column(&shapes, keys());
                let (color, _) = dict_column(&f.color, keys());
                let diameter = per_row(&rows, &f.diameter);
                let user = per_row(&rows, &f.user);
                vec![
                    f64n(),
                    floats(f.vx),
                    floats(f.vy),
                    f64n(),
                    floats(f.angle),
                    f64n(),
                    f64n(),
                    floats(f.wz),
                    dictn(),
                    nulls(&DataType::Int32, n),
                    dictn(),
                    f64n(),
                    floats(diameter),
                    shape,
                    color,
                    Arc::new(BooleanArray::from(user)),
                    f64n(),
                    f64n(),
                    f64n(),
                    f64n(),
                    f64n(),
                    f64n(),
                    i64n(),
                    i64n(),
                ]
            }
            Frames::Iphyre(f) => {
                let of = |get: fn(&IphyreBody) -> f64| -> ArrayRef {
                    floats(keys().map(|o| get(&f.bodies[o])).collect())
                };
                let ofi = |get: fn(&IphyreBody) -> i64| -> ArrayRef {
                    Arc::new(Int64Array::from(
                        keys().map(|o| get(&f.bodies[o])).collect::<Vec<_>>(),
                    ))
                };
                let (radius, elim, dynamic) =
                    (of(|b| b.radius), of(|b| b.eliminable), of(|b| b.dynamic));
                let (joint, spring) = (ofi(|b| b.joint), ofi(|b| b.spring));
                let [x1, y1, x2, y2] = f.ends;
                vec![
                    f64n(),
                    floats(f.vx),
                    floats(f.vy),
                    f64n(),
                    floats(f.angle),
                    f64n(),
                    f64n(),
                    floats(f.wz),
                    dictn(),
                    nulls(&DataType::Int32, n),
                    dictn(),
                    radius,
                    f64n(),
                    dictn(),
                    dictn(),
                    nulls(&DataType::Boolean, n),
                    floats(x1),
                    floats(y1),
                    floats(x2),
                    floats(y2),
                    elim,
                    dynamic,
                    joint,
                    spring,
                ]
            }
        };
        let timesteps = RecordBatch::try_new(
            TIMESTEPS.clone(),
            vec![
                constant_dict(trace_id, steps),
                Arc::new(Int64Array::from(rows.step)),
                floats(rows.t),
                Arc::new(Int32Array::from(rows.count)),
                nulls(&DataType::Utf8, steps),
            ],
        )?;
        let mut cols: Vec<ArrayRef> = Vec::with_capacity(FRAMES.fields().len());
        cols.push(constant_dict(trace_id, n));
        cols.push(Arc::new(Int64Array::from(frame_step)));
        cols.push(floats(frame_t));
        cols.push(Arc::new(Int32Array::from(slot)));
        cols.push(object_id);
        cols.push(floats(rows.x));
        cols.push(floats(rows.y));
        cols.extend(env_cols);
        cols.push(nulls(&DataType::Utf8, n));
        let frames = RecordBatch::try_new(FRAMES.clone(), cols)?;
        Ok((timesteps, frames, distinct))
    }
}

/// A trace's rows for a columnar writer ([`TraceColumns::tables`]).
#[derive(Debug)]
pub struct TraceTables<'a> {
    /// Its `traces` row.
    pub traces: RecordBatch,
    /// Its `events` rows.
    pub events: RecordBatch,
    /// Rows of `timesteps`.
    pub timestep_rows: usize,
    /// Its `timesteps` columns.
    pub timesteps: Vec<ColumnView<'a>>,
    /// Rows of `frames`.
    pub frame_rows: usize,
    /// Its `frames` columns.
    pub frames: Vec<ColumnView<'a>>,
}

/// One trace with its frames in columns: what a simulator hands to the tables.
#[derive(Clone, Debug)]
pub struct TraceColumns {
    /// Unique id of the trace within a run.
    pub trace_id: String,
    /// The task or scene family.
    pub task_id: String,
    /// The frames.
    pub frames: Frames,
    /// The sparse event log.
    pub events: Vec<Event>,
    /// How the episode ended.
    pub outcome: Outcome,
    /// Top-level fields of the trace.
    pub extra: JsonMap,
}

impl TraceColumns {
    /// The environment.
    pub fn env(&self) -> Env {
        self.frames.env()
    }

    /// The paper-layout trace (for consumers that need one).
    pub fn into_trace(self) -> Trace {
        Trace {
            env: self.frames.env(),
            timesteps: self.frames.timesteps(),
            trace_id: self.trace_id,
            task_id: self.task_id,
            events: self.events,
            outcome: self.outcome,
            extra: self.extra,
        }
    }

    /// The trace's rows for a columnar writer: the one-row `traces` batch and the `events` batch
    /// (as [`TraceColumns::batches`] makes them), and the `timesteps` and `frames` rows as column
    /// views in their schemas' order (the same values as those batches, no array built).
    pub fn tables<'a>(
        &'a self,
        scene_id: &str,
        source: &str,
    ) -> Result<TraceTables<'a>, ArrowError> {
        let rows = self.frames.rows();
        let t_range = match (rows.t.first(), rows.t.last()) {
            (Some(&a), Some(&b)) => Some((a, b)),
            _ => None,
        };
        let meta = TraceMeta {
            trace_id: &self.trace_id,
            scene_id,
            task_id: &self.task_id,
            events: &self.events,
            outcome: &self.outcome,
            extra: &self.extra,
            source,
        };
        let traces = traces_batch(
            &meta,
            rows.step.len(),
            self.frames.distinct_objects(),
            rows.obj.len(),
            t_range,
        )?;
        Ok(TraceTables {
            traces,
            events: events_batch(&self.trace_id, &self.events)?,
            timestep_rows: rows.step.len(),
            timesteps: self.frames.timestep_views(&self.trace_id),
            frame_rows: rows.obj.len(),
            frames: self.frames.frame_views(&self.trace_id),
        })
    }

    /// The trace's rows of the `traces`, `timesteps`, `frames` and `events` tables: the same
    /// batches [`super::TraceBatchBuilder::from_trace`] makes of [`TraceColumns::into_trace`].
    pub fn batches(self, scene_id: &str, source: &str) -> Result<TraceBatches, ArrowError> {
        let TraceColumns {
            trace_id,
            task_id,
            frames,
            events,
            outcome,
            extra,
        } = self;
        let t_range = match (frames.rows().t.first(), frames.rows().t.last()) {
            (Some(&a), Some(&b)) => Some((a, b)),
            _ => None,
        };
        let (timesteps, frames, distinct) = frames.batches(&trace_id)?;
        let meta = TraceMeta {
            trace_id: &trace_id,
            scene_id,
            task_id: &task_id,
            events: &events,
            outcome: &outcome,
            extra: &extra,
            source,
        };
        let traces = traces_batch(
            &meta,
            timesteps.num_rows(),
            distinct,
            frames.num_rows(),
            t_range,
        )?;
        let events = events_batch(&trace_id, &events)?;
        Ok(TraceBatches {
            traces,
            timesteps,
            frames,
            events,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::TraceBatchBuilder;

    fn outcome() -> Outcome {
        Outcome {
            success: false,
            terminal_status: "timeout".into(),
            metrics: JsonMap::new(),
            extra: JsonMap::new(),
        }
    }

    fn pool(nan_at: Option<(usize, usize)>) -> TraceColumns {
        let ids = vec!["cue".to_string(), "1".to_string(), "9".to_string()];
        let mut f = PoolFrames::new(ids, vec![0.028; 3], &["a", "b", "c", "d", "e"], 4);
        for step in 0..4 {
            f.begin_step(step as i64, step as f64 * 0.1);
            for b in 0..3 {
                let mut v = [b as f64, 0.5, 0.0];
                if nan_at == Some((step, b)) {
                    v[1] = f64::NAN;
                }
                f.ball(
                    b,
                    &[0.1 * b as f64, 0.2, 0.028],
                    &v,
                    &[0.0; 3],
                    ((step + b) % 5) as u8,
                );
            }
        }
        TraceColumns {
            trace_id: "t".into(),
            task_id: "task".into(),
            frames: f.into(),
            events: vec![Event::at("e", 0.0, serde_json::json!({"agents": ["cue"]}))],
            outcome: outcome(),
            extra: JsonMap::new(),
        }
    }

    #[test]
    fn non_finite_states_are_found_where_the_trace_finds_them() {
        assert_eq!(pool(None).frames.first_non_finite(), None);
        let bad = pool(Some((2, 1)));
        let want = bad.clone().into_trace().first_non_finite();
        assert_eq!(bad.frames.first_non_finite(), want);
        assert_eq!(want, Some((2, 1, "velocity")));
    }

    #[test]
    fn column_sums_are_checked_in_blocks_and_in_the_tail() {
        let ok: Vec<f64> = (0..21).map(|i| i as f64 - 10.0).collect();
        assert!(finite_sums([ok.as_slice()]));
        assert!(finite_sums([ok.as_slice(), &ok, &ok]));
        assert!(finite_sums::<1>([&[]]));
        for (at, bad) in [(3, f64::NAN), (13, f64::INFINITY), (20, f64::NEG_INFINITY)] {
            // Inside the first block, the second, and the tail.
            let mut c = ok.clone();
            c[at] = bad;
            assert!(!finite_sums([c.as_slice()]), "{at}");
            assert!(!finite_sums([ok.as_slice(), &c]), "{at}");
        }
        // Finite values whose sum is not, as the row-by-row search adds them.
        let big = vec![1e308; 9];
        assert!(finite_sums([big.as_slice()]));
        assert!(!finite_sums([big.as_slice(), &big]));
        assert!(!finite_sums([big.as_slice(), &big[..8]]));
    }

    #[test]
    fn batches_equal_the_builder_of_the_paper_layout() {
        let cols = pool(None);
        let trace = cols.clone().into_trace();
        let want = TraceBatchBuilder::from_trace(&trace, "scene", "src").unwrap();
        let got = cols.batches("scene", "src").unwrap();
        assert_eq!(got.traces, want.traces);
        assert_eq!(got.timesteps, want.timesteps);
        assert_eq!(got.frames, want.frames);
        assert_eq!(got.events, want.events);
    }

    #[test]
    fn dictionaries_follow_first_appearance() {
        let (col, distinct) = dict_column(&["x", "y", "x", "z"], [3, 2, 0, 1, 3].into_iter());
        let d = col
            .as_any()
            .downcast_ref::<DictionaryArray<Int32Type>>()
            .unwrap();
        let values = d.values().as_any().downcast_ref::<StringArray>().unwrap();
        assert_eq!(values.iter().flatten().collect::<Vec<_>>(), ["z", "x", "y"]);
        assert_eq!(d.keys().values().to_vec(), [0, 1, 1, 2, 0]);
        assert_eq!(distinct, 3);
    }
}
