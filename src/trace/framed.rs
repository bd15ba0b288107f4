//! A trace read from a run's tables whose billiard balls stay in their `frames` columns until a
//! consumer asks for them as objects.
//!
//! The detector workers take a billiards trace as columns (`detect::protocol`), so building one
//! paper-layout [`Object`](super::Object) per ball per step only to read it back into columns, and
//! dropping it afterwards, was about a third of what `annotate` itself spends per trace
//! (`docs/performance.md`, "Billiard traces handed to the workers as their columns").
//! [`FramedTrace::decode`] reads a trace's rows with the same checks, in the same order, as
//! [`decode_trace`](super::decode_trace); when every frame row is one it would take as it is, the
//! rows are kept as columns and read through [`PoolSteps`], else (another environment, a missing
//! value, unknown fields) the objects are built at once, as `decode_trace` builds them.
//!
//! **Owns:** [`FramedTrace`] and [`PoolRows`]. **Does not:** read files (`store/`, the stages'
//! `trace_files`) or write the workers' requests (`detect::protocol`).

use arrow::array::RecordBatch;

use super::batch::{DecodeError, FrameCols, TraceRows, decode_with};
use super::model::{Timestep, Trace};
use super::pool_steps::{BallView, PoolSteps};

/// A trace whose billiard frame rows may still be columns.
#[derive(Clone, Debug)]
pub struct FramedTrace {
    /// The trace; its timesteps hold their objects unless `rows` holds them.
    trace: Trace,
    /// The trace's frame rows, not built into objects, and each timestep's first row then the
    /// number of rows.
    rows: Option<(RecordBatch, Vec<usize>)>,
}

impl FramedTrace {
    /// Reads a trace from its rows: what [`decode_trace`](super::decode_trace) reads, with the same
    /// errors, keeping a billiards trace's frame rows as columns when they can be read as they are.
    pub fn decode(rows: &TraceRows<'_>) -> Result<Self, DecodeError> {
        let (trace, starts) = decode_with(rows, |frames, timesteps| {
            Ok(match frames.plain_pool_starts(timesteps) {
                Some(starts) => Some(starts),
                None => {
                    frames.fill(timesteps)?;
                    None
                }
            })
        })?;
        Ok(FramedTrace {
            rows: starts.map(|s| (rows.frames.clone(), s)),
            trace,
        })
    }

    /// The trace: its id, steps (index, time, unknown fields), events and outcome; its steps'
    /// objects only when [`FramedTrace::pool_rows`] is `None`.
    pub fn shell(&self) -> &Trace {
        &self.trace
    }

    /// The billiard frame rows kept as columns, if they were.
    pub fn pool_rows(&self) -> Option<PoolRows<'_>> {
        let (batch, starts) = self.rows.as_ref()?;
        let cols = FrameCols::read(batch, self.trace.env, &self.trace.trace_id).ok()?;
        Some(PoolRows {
            cols,
            starts,
            timesteps: &self.trace.timesteps,
        })
    }

    /// Number of objects over all timesteps (frame rows).
    pub fn frame_rows(&self) -> usize {
        match &self.rows {
            Some((batch, _)) => batch.num_rows(),
            None => self.trace.timesteps.iter().map(|s| s.objects.len()).sum(),
        }
    }

    /// Whether the timesteps' objects are still columns.
    pub fn is_columns(&self) -> bool {
        self.rows.is_some()
    }

    /// The whole trace, its objects built: the trace [`decode_trace`](super::decode_trace) gives.
    pub fn into_trace(mut self) -> Result<Trace, DecodeError> {
        if let Some((batch, _)) = self.rows.take() {
            let trace = &mut self.trace;
            FrameCols::read(&batch, trace.env, &trace.trace_id)?.fill(&mut trace.timesteps)?;
        }
        Ok(self.trace)
    }
}

/// A billiards trace's frame rows read as ball states, step by step, without building objects
/// ([`PoolSteps::Rows`]).
pub struct PoolRows<'a> {
    cols: FrameCols<'a>,
    starts: &'a [usize],
    /// The trace's timesteps (their index, time and unknown fields; no objects).
    timesteps: &'a [Timestep],
}

impl std::fmt::Debug for PoolRows<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PoolRows")
            .field("steps", &self.steps_len())
            .field("rows", &self.starts.last().copied().unwrap_or(0))
            .finish()
    }
}

impl<'a> PoolRows<'a> {
    /// The timesteps, to be read as [`PoolSteps`].
    pub fn steps(&'a self) -> PoolSteps<'a> {
        PoolSteps::Rows(self)
    }

    /// The timesteps, without their objects (those are the rows).
    pub(super) fn timesteps(&self) -> &'a [Timestep] {
        self.timesteps
    }

    /// Timestep `k`'s rows.
    pub(super) fn step_rows(&self, k: usize) -> (usize, usize) {
        (self.starts[k], self.starts[k + 1])
    }

    /// Number of timesteps.
    pub(super) fn steps_len(&self) -> usize {
        self.starts.len().saturating_sub(1)
    }

    /// Frame row `i`'s ball.
    pub(super) fn ball(&self, i: usize) -> BallView<'_> {
        self.cols.ball_view(i)
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use arrow::array::{Array, ArrayRef, Float64Array, Int32Array, Int64Array, StringArray};
    use arrow::compute::cast;
    use arrow::datatypes::DataType;

    use super::*;
    use crate::trace::{Env, PoolSteps, TraceBatchBuilder, TraceBatches, decode_trace};

    fn shot(seed: u64) -> Trace {
        let config = crate::envs::pool::PoolConfig::default_7ft();
        let opts = crate::envs::pool::TraceOptions { dt: 0.05 };
        crate::envs::pool::dataset_trace(&config, seed, 0, &opts).unwrap()
    }

    fn rows_of(b: &TraceBatches, env: Env) -> TraceRows<'_> {
        TraceRows {
            env,
            trace: &b.traces,
            timesteps: &b.timesteps,
            frames: &b.frames,
            events: &b.events,
        }
    }

    /// `batch` with column `name` replaced by `f` of it.
    fn with_column(
        batch: &RecordBatch,
        name: &str,
        f: impl FnOnce(&ArrayRef) -> ArrayRef,
    ) -> RecordBatch {
        let i = batch.schema().index_of(name).unwrap();
        let mut cols = batch.columns().to_vec();
        cols[i] = f(&cols[i]);
        RecordBatch::try_new(batch.schema(), cols).unwrap()
    }

    /// A float column with row `at` null.
    fn null_f64(at: usize) -> impl FnOnce(&ArrayRef) -> ArrayRef {
        move |c| {
            let a = c.as_any().downcast_ref::<Float64Array>().unwrap();
            let v: Float64Array = (0..a.len())
                .map(|i| (i != at).then(|| a.value(i)))
                .collect();
            Arc::new(v)
        }
    }

    /// A string column (plain or dictionary) with row `at` null, kept in its type.
    fn null_str(at: usize) -> impl FnOnce(&ArrayRef) -> ArrayRef {
        move |c| {
            let plain = cast(c, &DataType::Utf8).unwrap();
            let a = plain.as_any().downcast_ref::<StringArray>().unwrap();
            let v: StringArray = (0..a.len())
                .map(|i| (i != at && !a.is_null(i)).then(|| a.value(i)))
                .collect();
            cast(&v, c.data_type()).unwrap()
        }
    }

    /// What both decoders make of the same rows: equal traces, or equal errors.
    fn both(b: &TraceBatches, env: Env) -> (Result<FramedTrace, String>, Result<Trace, String>) {
        let rows = rows_of(b, env);
        let framed = FramedTrace::decode(&rows).map_err(|e| e.to_string());
        let whole = decode_trace(&rows).map_err(|e| e.to_string());
        let built = framed
            .clone()
            .and_then(|f| f.into_trace().map_err(|e| e.to_string()));
        assert_eq!(built, whole);
        (framed, whole)
    }

    #[test]
    fn a_billiards_trace_kept_as_columns_reads_as_the_trace_decode_trace_gives() {
        for seed in 1..4 {
            let trace = shot(seed);
            let b = TraceBatchBuilder::from_trace(&trace, "scene", "test").unwrap();
            let (framed, whole) = both(&b, Env::Pooltool);
            let (framed, whole) = (framed.unwrap(), whole.unwrap());
            assert_eq!(whole, trace);
            assert!(framed.is_columns());
            assert_eq!(framed.frame_rows(), b.frames.num_rows());
            // Without its objects, the rest of the trace is there already.
            let shell = framed.shell();
            assert!(shell.timesteps.iter().all(|s| s.objects.is_empty()));
            assert_eq!(shell.timesteps.len(), trace.timesteps.len());
            assert_eq!(
                (shell.trace_id.as_str(), &shell.events, &shell.outcome),
                (trace.trace_id.as_str(), &trace.events, &trace.outcome)
            );
            // Ball by ball, step by step, the columns read as the objects do.
            let rows = framed.pool_rows().unwrap();
            let (a, o) = (rows.steps(), PoolSteps::of_trace(&trace));
            assert_eq!(a.len(), o.len());
            for k in 0..a.len() {
                assert_eq!(a.t(k), o.t(k));
                assert!(a.balls(k).eq(o.balls(k)), "step {k}");
            }
        }
    }

    #[test]
    fn rows_it_cannot_take_as_they_are_give_decode_trace_s_objects_or_its_error() {
        let trace = shot(2);
        let b = TraceBatchBuilder::from_trace(&trace, "scene", "test").unwrap();
        let n = b.frames.num_rows();
        let frames = |f: &dyn Fn(&RecordBatch) -> RecordBatch| TraceBatches {
            frames: f(&b.frames),
            ..b.clone()
        };
        // A value a ball needs is missing: the same error, naming the row.
        for col in ["vz", "wx", "radius", "z"] {
            let (framed, _) = both(
                &frames(&|f| with_column(f, col, null_f64(n / 2))),
                Env::Pooltool,
            );
            let e = framed.unwrap_err();
            assert!(e.contains(col) && e.contains(&(n / 2).to_string()), "{e}");
        }
        for col in ["kind", "motion_state"] {
            let (framed, _) = both(
                &frames(&|f| with_column(f, col, null_str(7))),
                Env::Pooltool,
            );
            assert!(framed.unwrap_err().contains(col));
        }
        let (framed, _) = both(
            &frames(&|f| {
                with_column(f, "motion_state_code", |c| {
                    let a = c.as_any().downcast_ref::<Int32Array>().unwrap();
                    Arc::new(
                        (0..a.len())
                            .map(|i| (i != 3).then(|| a.value(i)))
                            .collect::<Int32Array>(),
                    )
                })
            }),
            Env::Pooltool,
        );
        assert!(framed.unwrap_err().contains("motion_state_code"));
        // A row before the first step, and one past the last.
        for (row, step) in [(0, -1), (n - 1, 1_000_000)] {
            let (framed, _) = both(
                &frames(&|f| {
                    with_column(f, "step", |c| {
                        let a = c.as_any().downcast_ref::<Int64Array>().unwrap();
                        let v: Int64Array = (0..a.len())
                            .map(|i| if i == row { step } else { a.value(i) })
                            .collect();
                        Arc::new(v)
                    })
                }),
                Env::Pooltool,
            );
            assert!(framed.unwrap_err().contains("step"));
        }
        // Unknown fields on a ball: built at once, the same objects.
        let mut extra = trace.clone();
        extra.timesteps[3].objects[1]
            .extra
            .insert("note".into(), serde_json::json!(1));
        let be = TraceBatchBuilder::from_trace(&extra, "scene", "test").unwrap();
        let (framed, whole) = both(&be, Env::Pooltool);
        assert!(!framed.unwrap().is_columns());
        assert_eq!(whole.unwrap(), extra);
        // A repeated step index: its rows go to the first of the two steps, in both.
        let mut twice = trace.clone();
        twice.timesteps[5].index = twice.timesteps[4].index;
        let bt = TraceBatchBuilder::from_trace(&twice, "scene", "test").unwrap();
        let (framed, whole) = both(&bt, Env::Pooltool);
        let (framed, whole) = (framed.unwrap(), whole.unwrap());
        assert!(framed.is_columns());
        assert!(whole.timesteps[5].objects.is_empty());
        assert_eq!(
            whole.timesteps[4].objects.len(),
            2 * trace.timesteps[4].objects.len()
        );
        // Other environments are built at once.
        let phyre = crate::testutil::synthetic_trace(Env::Phyre, 0, 6, 3);
        let bp = TraceBatchBuilder::from_trace(&phyre, "scene", "test").unwrap();
        let (framed, whole) = both(&bp, Env::Phyre);
        assert!(!framed.unwrap().is_columns());
        assert_eq!(whole.unwrap(), phyre);
    }
}
