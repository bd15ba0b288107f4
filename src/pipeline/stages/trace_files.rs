//! Reading a run's traces file by file, for stages that process every trace (`annotate`, `accuracy`),
//! and choosing and reading a few traces by id, for stages that show examples to a model
//! (`summarise`, `suggest-labels`: [`pick_trace_ids`], [`read_traces_by_id`]).
//!
//! Stages that write the trace tables (`import`, `simulate`) write one file per shard with the same name
//! in `traces`, `timesteps`, `frames` and `events` (`<stage>.<shard>.parquet`). Reading such a set once,
//! grouping each table by trace and slicing, rebuilds all of its traces at the cost of one read
//! (`store::read_traces`, for traces chosen by id, also checks every row against the ids asked for).
//! Those stages write each trace's rows together and in order, so a set's rows are checked to be
//! grouped and are then taken as they are; rows in any other order (files from elsewhere) are sorted
//! first.

use arrow::array::{Array, ArrayRef, RecordBatch, StringArray};
use arrow::compute::{SortColumn, concat_batches, lexsort_to_indices, take, take_record_batch};

use crate::digest::words_u64;
use crate::pipeline::stage::StageError;
use crate::rng::SplitMix64;
use crate::store::{
    ReadTraceError, RunDir, Strings, key_order, plain_strings, read_file_whole_as, trace_ids,
};
use crate::trace::batch::DecodeError;
use crate::trace::schema::table_schema;
use crate::trace::{Env, FramedTrace, Trace, TraceRows, decode_trace};

/// One file name shared by the trace tables of one environment.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct TraceFileSet {
    /// The environment partition.
    pub env: Env,
    /// The file name (`simulate_pool.00000.parquet`).
    pub name: String,
}

/// The trace file sets of `env` in the run, sorted by name.
pub(crate) fn trace_file_sets(run: &RunDir, env: Env) -> Result<Vec<TraceFileSet>, StageError> {
    let mut out: Vec<TraceFileSet> = run
        .table("traces")?
        .files
        .into_iter()
        .filter(|f| f.env == Some(env))
        .filter_map(|f| {
            f.path.file_name().map(|n| TraceFileSet {
                env,
                name: n.to_string_lossy().into_owned(),
            })
        })
        .collect();
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

/// All rows of `table` in the set's file (an empty batch when no such file is published), grouped
/// by `trace_id` and ordered by `sort_by` within each trace, with the trace ids as plain strings
/// alongside. String columns come plain, not as dictionaries ([`Strings::Plain`]: the file is read
/// as one batch across its row groups, each with its own dictionary). Rows a stage wrote are
/// already so (one trace after another, in table order), and are then taken as they are; others
/// are sorted by `trace_id` then `sort_by`.
fn sorted_rows(
    run: &RunDir,
    set: &TraceFileSet,
    table: &str,
    sort_by: &[&str],
) -> Result<(RecordBatch, StringArray), StageError> {
    let schema = plain_strings(
        &table_schema(table)
            .ok_or_else(|| StageError::Internal(format!("no schema for table {table}")))?,
    );
    // The set's file of this table, if it is published (a stage writes no file for an empty table).
    let published = run.table(table)?.files.into_iter().find(|f| {
        f.env == Some(set.env) && f.path.file_name().is_some_and(|n| n == set.name.as_str())
    });
    let batches = match published {
        Some(f) => read_file_whole_as(&f.path, Strings::Plain)?,
        None => Vec::new(),
    };
    let all = concat_batches(&schema, &batches)?;
    // Plain strings already (the reader's schema), so no cast.
    let ids = all
        .column_by_name("trace_id")
        .ok_or_else(|| StageError::Internal(format!("{table}: no trace_id column")))?
        .clone();
    if all.num_rows() == 0 {
        return Ok((all, StringArray::from(Vec::<String>::new())));
    }
    let keys = sort_by
        .iter()
        .map(|c| {
            all.column_by_name(c)
                .ok_or_else(|| StageError::Internal(format!("{table}: no {c} column")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let plain = ids
        .as_any()
        .downcast_ref::<StringArray>()
        .ok_or_else(|| StageError::Internal("trace ids are not strings".into()))?;
    if grouped_order(plain, &keys) == Some(true) {
        return Ok((all, plain.clone()));
    }
    let mut columns = vec![SortColumn {
        values: ids.clone(),
        options: None,
    }];
    for k in keys {
        columns.push(SortColumn {
            values: k.clone(),
            options: None,
        });
    }
    let idx = lexsort_to_indices(&columns, None)?;
    let sorted = take_record_batch(&all, &idx)?;
    let ids = take(&ids, &idx, None)?;
    let ids = ids
        .as_any()
        .downcast_ref::<StringArray>()
        .cloned()
        .ok_or_else(|| StageError::Internal("trace ids are not strings".into()))?;
    Ok((sorted, ids))
}

/// Whether rows are already grouped by trace id (each id one contiguous run) and ordered by the
/// integer `keys` within each run, with no nulls: `Some(true)` if so, `Some(false)` if not, `None`
/// when a key is not a 32- or 64-bit integer column (so the caller sorts).
fn grouped_order(ids: &StringArray, keys: &[&ArrayRef]) -> Option<bool> {
    let order = key_order(keys)?;
    if ids.null_count() > 0 {
        return Some(false);
    }
    let mut seen = std::collections::HashSet::new();
    let mut start = 0;
    for i in 1..=ids.len() {
        if i < ids.len() && ids.value(i) == ids.value(start) {
            if order(i - 1, i) == std::cmp::Ordering::Greater {
                return Some(false);
            }
            continue;
        }
        if !seen.insert(ids.value(start)) {
            // The trace's rows come in two runs.
            return Some(false);
        }
        start = i;
    }
    Some(true)
}

/// The row range of each trace id in rows sorted by trace id.
fn ranges(ids: &StringArray) -> std::collections::HashMap<String, (usize, usize)> {
    let mut out = std::collections::HashMap::new();
    let mut start = 0;
    for i in 1..=ids.len() {
        if i == ids.len() || ids.value(i) != ids.value(start) {
            out.insert(ids.value(start).to_string(), (start, i - start));
            start = i;
        }
    }
    out
}

/// The trace ids of a file set, in the order of its `traces` file (only that file is read).
pub(crate) fn set_trace_ids(run: &RunDir, set: &TraceFileSet) -> Result<Vec<String>, StageError> {
    let path = run.partition_dir("traces", Some(set.env)).join(&set.name);
    Ok(crate::store::file_trace_ids(&path)?)
}

/// Reads every trace of a file set, in the order of the `traces` file.
pub(crate) fn read_traces(run: &RunDir, set: &TraceFileSet) -> Result<Vec<Trace>, StageError> {
    read_set(run, set, decode_trace)
}

/// Reads every trace of a file set as [`read_traces`] does, with each billiards trace's frame rows
/// left as columns where they can be (for the detector workers, which take them as columns).
pub(crate) fn read_framed_traces(
    run: &RunDir,
    set: &TraceFileSet,
) -> Result<Vec<FramedTrace>, StageError> {
    read_set(run, set, FramedTrace::decode)
}

/// Every trace of a file set, each decoded from its rows by `decode`.
fn read_set<T>(
    run: &RunDir,
    set: &TraceFileSet,
    decode: impl Fn(&TraceRows<'_>) -> Result<T, DecodeError>,
) -> Result<Vec<T>, StageError> {
    let schema = plain_strings(
        &table_schema("traces")
            .ok_or_else(|| StageError::Internal("no schema for traces".into()))?,
    );
    let path = run.partition_dir("traces", Some(set.env)).join(&set.name);
    let traces = concat_batches(&schema, &read_file_whole_as(&path, Strings::Plain)?)?;
    let (steps, step_ids) = sorted_rows(run, set, "timesteps", &["step"])?;
    let (frames, frame_ids) = sorted_rows(run, set, "frames", &["step", "slot"])?;
    let (events, event_ids) = sorted_rows(run, set, "events", &["seq"])?;
    let (rs, rf, re) = (ranges(&step_ids), ranges(&frame_ids), ranges(&event_ids));
    let ids = traces
        .column_by_name("trace_id")
        .and_then(|c| c.as_any().downcast_ref::<StringArray>())
        .ok_or_else(|| StageError::Internal("traces: trace_id is not a string column".into()))?;
    let slice = |b: &RecordBatch, r: Option<&(usize, usize)>| match r {
        Some(&(o, n)) => b.slice(o, n),
        None => b.slice(0, 0),
    };
    let mut out = Vec::with_capacity(ids.len());
    for i in 0..ids.len() {
        let id = ids.value(i);
        let trace = decode(&TraceRows {
            env: set.env,
            trace: &traces.slice(i, 1),
            timesteps: &slice(&steps, rs.get(id)),
            frames: &slice(&frames, rf.get(id)),
            events: &slice(&events, re.get(id)),
        })
        .map_err(|source| StageError::BadTraceRows {
            path: path.clone(),
            trace_id: id.to_string(),
            source: Box::new(source),
        })?;
        out.push(trace);
    }
    Ok(out)
}

/// The ids of the traces a stage works on: `given` (each checked to be a trace of `env` in the run),
/// or `count` of the run's traces of `env` drawn with `seed` (a Fisher–Yates shuffle of the sorted
/// ids, keyed by `seed` and the stage's `salt`, then truncated), in drawn order.
pub(crate) fn pick_trace_ids(
    run: &RunDir,
    env: Env,
    given: Option<&[String]>,
    count: usize,
    seed: u64,
    salt: u64,
) -> Result<Vec<String>, StageError> {
    let mut all = env_trace_ids(run, env)?;
    if let Some(ids) = given {
        if let Some(bad) = ids.iter().find(|i| all.binary_search(i).is_err()) {
            return Err(StageError::Input(format!(
                "`trace_ids`: the run has no {env} trace {bad:?}"
            )));
        }
        return Ok(ids.to_vec());
    }
    let mut rng = SplitMix64::new(words_u64(&[seed, salt]));
    for i in (1..all.len()).rev() {
        all.swap(i, rng.below(i + 1));
    }
    all.truncate(count);
    Ok(all)
}

/// The ids of the run's traces of `env`, sorted, each once (read from the `traces` table alone).
pub(crate) fn env_trace_ids(run: &RunDir, env: Env) -> Result<Vec<String>, StageError> {
    let mut all: Vec<String> = trace_ids(run)?
        .into_iter()
        .filter(|(e, _)| *e == env)
        .map(|(_, id)| id)
        .collect();
    all.sort();
    all.dedup();
    Ok(all)
}

/// How [`split_ids`] divides a run's traces into kept and set-aside ones.
#[derive(Clone, Copy, Debug)]
pub(crate) struct HashSplit {
    /// Seed of the order and of the draw.
    pub seed: u64,
    /// Mixed into the seed of the draw (so the draw is not the order).
    pub salt: u64,
    /// Share of the traces set aside (0: none).
    pub aside: f64,
    /// Kept traces at most.
    pub max_kept: usize,
    /// Set-aside traces at most.
    pub max_aside: usize,
}

/// Splits `ids` into (kept, set aside): each side ordered by the hash of (seed, id), then by id; an
/// id is set aside when the hash of (seed ^ salt, id) falls in the first `aside` share of the hash
/// range; each side is then cut to its maximum. Depends only on the ids, so a stage picks its traces
/// from the `traces` table and reads only those (`evolve`'s training and held-out traces,
/// `ensemble`'s calibration and test traces).
pub(crate) fn split_ids(mut ids: Vec<String>, s: HashSplit) -> (Vec<String>, Vec<String>) {
    let hash =
        |seed: u64, id: &str| crate::digest::sha256_u64(&[&seed.to_le_bytes(), id.as_bytes()]);
    ids.sort_by_cached_key(|id| (hash(s.seed, id), id.clone()));
    let cut = (s.aside * u64::MAX as f64) as u64;
    let (mut aside, mut kept): (Vec<String>, Vec<String>) = ids
        .into_iter()
        .partition(|id| s.aside > 0.0 && hash(s.seed ^ s.salt, id) < cut);
    kept.truncate(s.max_kept);
    aside.truncate(s.max_aside);
    (kept, aside)
}

/// Reads the two sides of a [`split_ids`] in one pass over the run's tables.
pub(crate) fn read_split(
    run: &RunDir,
    (kept, aside): (Vec<String>, Vec<String>),
) -> Result<(Vec<Trace>, Vec<Trace>), StageError> {
    let n = kept.len();
    let mut kept = read_traces_by_id(run, &[kept, aside].concat())?;
    let aside = kept.split_off(n);
    Ok((kept, aside))
}

/// Reads the traces `ids` from the run (`store::read_traces`: each row group once for all of them);
/// a missing or damaged trace is an input error naming it.
pub(crate) fn read_traces_by_id(run: &RunDir, ids: &[String]) -> Result<Vec<Trace>, StageError> {
    crate::store::read_traces(run, ids).map_err(|e| match e {
        ReadTraceError::Store(e) => StageError::Store(e),
        other => StageError::Input(other.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow::array::{Int32Array, Int64Array};
    use std::sync::Arc;

    fn order(ids: &[&str], steps: &[i64], slots: &[i32]) -> Option<bool> {
        let ids = StringArray::from(ids.to_vec());
        let steps: ArrayRef = Arc::new(Int64Array::from(steps.to_vec()));
        let slots: ArrayRef = Arc::new(Int32Array::from(slots.to_vec()));
        grouped_order(&ids, &[&steps, &slots])
    }

    #[test]
    fn rows_as_a_stage_writes_them_are_taken_as_they_are_and_others_are_sorted() {
        // One trace after another (in any order of ids), steps then slots rising within each.
        assert_eq!(
            order(
                &["b", "b", "b", "a", "a"],
                &[0, 0, 1, 0, 1],
                &[0, 1, 0, 0, 0]
            ),
            Some(true)
        );
        // A slot out of order within a step.
        assert_eq!(order(&["b", "b", "a"], &[0, 0, 0], &[1, 0, 0]), Some(false));
        // A step out of order, whatever the slots.
        assert_eq!(order(&["a", "a", "b"], &[1, 0, 0], &[0, 5, 0]), Some(false));
        // A trace's rows in two runs.
        assert_eq!(order(&["a", "b", "a"], &[0, 0, 1], &[0, 0, 0]), Some(false));
        assert_eq!(order(&[], &[], &[]), Some(true));
        // A key that is not an integer column: the caller sorts.
        let ids = StringArray::from(vec!["a"]);
        let t: ArrayRef = Arc::new(arrow::array::Float64Array::from(vec![0.0]));
        assert_eq!(grouped_order(&ids, &[&t]), None);
    }

    #[test]
    fn a_split_depends_on_the_ids_alone_and_keeps_each_side_in_hash_order() {
        let ids: Vec<String> = (0..40).map(|i| format!("t{i:02}")).collect();
        let s = HashSplit {
            seed: 7,
            salt: 0x401D,
            aside: 0.3,
            max_kept: 100,
            max_aside: 100,
        };
        let (kept, aside) = split_ids(ids.clone(), s);
        // Every id once, on one side; the input's order does not matter.
        let mut all: Vec<String> = kept.iter().chain(&aside).cloned().collect();
        all.sort();
        assert_eq!(all, ids);
        let mut reversed = ids.clone();
        reversed.reverse();
        assert_eq!(split_ids(reversed, s), (kept.clone(), aside.clone()));
        // Each side in the order of the seeded hash.
        let h = |id: &String| crate::digest::sha256_u64(&[&7u64.to_le_bytes(), id.as_bytes()]);
        for side in [&kept, &aside] {
            assert!(side.windows(2).all(|w| h(&w[0]) <= h(&w[1])));
        }
        // About the share asked for.
        assert!((8..=16).contains(&aside.len()), "{} set aside", aside.len());
        // The cuts take the first of each side; nothing is set aside at 0.
        let cut = split_ids(
            ids.clone(),
            HashSplit {
                max_kept: 5,
                max_aside: 2,
                ..s
            },
        );
        assert_eq!(cut, (kept[..5].to_vec(), aside[..2].to_vec()));
        let (none_aside, empty) = split_ids(ids.clone(), HashSplit { aside: 0.0, ..s });
        assert!(empty.is_empty());
        assert_eq!(none_aside.len(), 40);
        // Pinned: a changed split would change every evolve and ensemble result.
        assert_eq!(kept[..3], ["t09", "t02", "t23"]);
        assert_eq!(aside[..2], ["t01", "t35"]);
    }
}
