//! The `trace_distances` table: a training set's pairwise D_x matrix, computed once and reused by every
//! search over that set (one row per pair `i < j`, `set_id` naming the set: a hash of its trace ids, the
//! sample count and the scaling convention).

use std::sync::Arc;

use arrow::array::{Array, AsArray, Float64Array, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Float64Type, Schema, SchemaRef};
use arrow::error::ArrowError;
use sha2::{Digest, Sha256};

use super::distance::{DistanceMatrix, Dx};

/// Version of the d_x convention (alignment, scaling), part of every `set_id`.
pub const DX_VERSION: u32 = 1;

/// The schema of `trace_distances`.
pub fn distances_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new("set_id", DataType::Utf8, false),
        Field::new("trace_a", DataType::Utf8, false),
        Field::new("trace_b", DataType::Utf8, false),
        Field::new("d_x", DataType::Float64, true),
    ]))
}

/// The id of a training set: a hash of its trace ids (in order), `samples` and [`DX_VERSION`].
pub fn set_id(ids: &[String], samples: usize) -> String {
    set_id_with(ids, samples, Dx::Positions)
}

/// [`set_id`] of a set whose D_x is computed under `dx`; `positions` gives the same id as
/// [`set_id`] (ids of earlier runs stay valid), another variant adds its name to the hash.
pub fn set_id_with(ids: &[String], samples: usize, dx: Dx) -> String {
    let mut h = Sha256::new();
    h.update(DX_VERSION.to_le_bytes());
    h.update((samples as u64).to_le_bytes());
    if dx != Dx::Positions {
        h.update(dx.as_str().as_bytes());
        h.update([0xff]);
    }
    for id in ids {
        h.update(id.as_bytes());
        h.update([0]);
    }
    crate::digest::hex(&h.finalize()[..8])
}

/// The rows of `m` (NaN distances as nulls).
pub fn distances_batch(set: &str, m: &DistanceMatrix) -> Result<RecordBatch, ArrowError> {
    let n = m.len();
    let (mut a, mut b) = (
        Vec::with_capacity(m.upper.len()),
        Vec::with_capacity(m.upper.len()),
    );
    for i in 0..n {
        for j in i + 1..n {
            a.push(m.ids[i].as_str());
            b.push(m.ids[j].as_str());
        }
    }
    let d: Float64Array = m
        .upper
        .iter()
        .map(|&v| v.is_finite().then_some(v))
        .collect();
    RecordBatch::try_new(
        distances_schema(),
        vec![
            Arc::new(StringArray::from(vec![set; m.upper.len()])),
            Arc::new(StringArray::from(a)),
            Arc::new(StringArray::from(b)),
            Arc::new(d),
        ],
    )
}

/// Rebuilds the matrix of set `set` over `ids` from rows of the table; `None` unless every pair is there.
pub fn matrix_from_batches(
    set: &str,
    ids: &[String],
    batches: &[RecordBatch],
) -> Option<DistanceMatrix> {
    let n = ids.len();
    let pos: std::collections::HashMap<&str, usize> = ids
        .iter()
        .enumerate()
        .map(|(i, s)| (s.as_str(), i))
        .collect();
    let mut upper = vec![f64::NAN; n * n.saturating_sub(1) / 2];
    let mut seen = vec![false; upper.len()];
    for b in batches {
        let sid = b.column_by_name("set_id")?.as_string::<i32>();
        let ta = b.column_by_name("trace_a")?.as_string::<i32>();
        let tb = b.column_by_name("trace_b")?.as_string::<i32>();
        let d = b.column_by_name("d_x")?.as_primitive::<Float64Type>();
        for r in 0..b.num_rows() {
            if sid.value(r) != set {
                continue;
            }
            let (Some(&i), Some(&j)) = (pos.get(ta.value(r)), pos.get(tb.value(r))) else {
                continue;
            };
            let (i, j) = if i < j { (i, j) } else { (j, i) };
            if i == j {
                continue;
            }
            let k = DistanceMatrix::pair_index(n, i, j);
            upper[k] = if d.is_null(r) { f64::NAN } else { d.value(r) };
            seen[k] = true;
        }
    }
    seen.iter().all(|&s| s).then(|| DistanceMatrix {
        ids: ids.to_vec(),
        upper,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_matrix_round_trips_through_its_rows() {
        let m = DistanceMatrix {
            ids: vec!["a".into(), "b".into(), "c".into()],
            upper: vec![1.0, f64::NAN, 2.0],
        };
        let id = set_id(&m.ids, 64);
        assert_ne!(id, set_id(&m.ids, 32));
        let b = distances_batch(&id, &m).unwrap();
        assert_eq!(b.num_rows(), 3);
        let back = matrix_from_batches(&id, &m.ids, std::slice::from_ref(&b)).unwrap();
        assert_eq!(back.upper[0], 1.0);
        assert!(back.upper[1].is_nan());
        assert_eq!(back.upper[2], 2.0);
        assert!(matrix_from_batches("other", &m.ids, &[b]).is_none());
    }
}
