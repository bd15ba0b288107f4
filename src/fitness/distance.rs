//! Trace distance d_x (section 3.1 of the paper) and the pairwise D_x matrix of a training set.
//!
//! **Alignment.** Traces of different lengths are compared on normalised time: each trace is resampled
//! once to `samples` frames at u = k/(samples−1) of its duration (linear interpolation between the two
//! surrounding timesteps by their `t`), so a 2 s shot and a 9 s shot are compared beginning to
//! beginning, middle to middle, end to end. **Matched objects** are the intersection of the two traces'
//! object ids; an object missing from one side at a sampled frame (it appears later or vanishes) is left
//! out of that frame. d_x is the mean, over sampled frames, of the mean Euclidean distance of the
//! matched objects' planar centres ([`crate::trace::Body::centre`]) — "normalised by the length of the
//! trace" is this mean over frames. **Units.** Centres are divided by the environment's scene size
//! ([`scene_scale`]) first, so d_x is a fraction of the scene in every environment (pooltool metres,
//! PHYRE's 256-unit scene, I-PHYRE's 600-pixel scene) and figures compare across environments.
//! A pair with no matched object (or an empty trace) has no distance (`NaN`) and is left out of ρ.

use std::collections::BTreeMap;

use rayon::prelude::*;

use crate::trace::{Env, Trace};

/// Default number of normalised-time samples per trace.
pub const DEFAULT_SAMPLES: usize = 64;

/// The length that positions of `env` are divided by: the long side of pooltool's default 7-ft table
/// (1.9812 m), PHYRE's 256-unit scene, I-PHYRE's 600-pixel scene.
pub fn scene_scale(env: Env) -> f64 {
    crate::envs::facts(env).scene_scale
}

/// A trace resampled on normalised time: object ids (sorted) and their scaled centres per sample
/// (`NaN` where the object is absent).
#[derive(Clone, Debug, PartialEq)]
pub struct Resampled {
    /// The trace id.
    pub trace_id: String,
    /// Object ids, sorted.
    pub objects: Vec<String>,
    /// `samples × objects` centres `(x, y)`, row-major by sample.
    pub centres: Vec<[f64; 2]>,
    /// Number of samples (0 for a trace without timesteps).
    pub samples: usize,
}

/// Resamples `trace` to `samples` frames on normalised time (see the module docs).
pub fn resample(trace: &Trace, samples: usize) -> Resampled {
    let scale = scene_scale(trace.env);
    let mut ids: Vec<String> = trace
        .timesteps
        .iter()
        .flat_map(|ts| ts.objects.iter().map(|o| o.object_id()))
        .collect();
    ids.sort();
    ids.dedup();
    let col: BTreeMap<&str, usize> = ids
        .iter()
        .enumerate()
        .map(|(i, s)| (s.as_str(), i))
        .collect();
    let m = ids.len();
    let n = trace.timesteps.len();
    if n == 0 || samples == 0 {
        return Resampled {
            trace_id: trace.trace_id.clone(),
            objects: ids,
            centres: Vec::new(),
            samples: 0,
        };
    }
    // Dense per-timestep centres, NaN where absent.
    let mut dense = vec![[f64::NAN; 2]; n * m];
    for (i, ts) in trace.timesteps.iter().enumerate() {
        for o in &ts.objects {
            let id = o.object_id();
            let (x, y) = o.body.centre();
            dense[i * m + col[id.as_str()]] = [x / scale, y / scale];
        }
    }
    let t0 = trace.timesteps[0].t;
    let t1 = trace.timesteps[n - 1].t;
    let mut centres = vec![[f64::NAN; 2]; samples * m];
    let mut hi = 0usize;
    for k in 0..samples {
        let u = if samples == 1 {
            0.0
        } else {
            k as f64 / (samples - 1) as f64
        };
        let t = t0 + u * (t1 - t0);
        while hi + 1 < n && trace.timesteps[hi].t < t {
            hi += 1;
        }
        let lo = hi.saturating_sub(1);
        let (ta, tb) = (trace.timesteps[lo].t, trace.timesteps[hi].t);
        let w = if tb > ta && t.is_finite() {
            ((t - ta) / (tb - ta)).clamp(0.0, 1.0)
        } else {
            1.0
        };
        for j in 0..m {
            let (a, b) = (dense[lo * m + j], dense[hi * m + j]);
            centres[k * m + j] = match (a[0].is_nan(), b[0].is_nan()) {
                (false, false) => [a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1])],
                (true, false) => b,
                (false, true) => a,
                (true, true) => [f64::NAN; 2],
            };
        }
    }
    Resampled {
        trace_id: trace.trace_id.clone(),
        objects: ids,
        centres,
        samples,
    }
}

/// d_x between two resampled traces (same `samples`): the mean over frames of the mean distance of
/// matched objects; `NaN` when no object is matched at any frame.
pub fn trace_distance(a: &Resampled, b: &Resampled) -> f64 {
    if a.samples == 0 || a.samples != b.samples {
        return f64::NAN;
    }
    let (ma, mb) = (a.objects.len(), b.objects.len());
    // Matched columns by a merge of the sorted id lists.
    let mut pairs = Vec::new();
    let (mut i, mut j) = (0, 0);
    while i < ma && j < mb {
        match a.objects[i].cmp(&b.objects[j]) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                pairs.push((i, j));
                i += 1;
                j += 1;
            }
        }
    }
    let (mut sum, mut frames) = (0.0, 0usize);
    for k in 0..a.samples {
        let (mut s, mut c) = (0.0, 0usize);
        for &(i, j) in &pairs {
            let (p, q) = (a.centres[k * ma + i], b.centres[k * mb + j]);
            if p[0].is_nan() || q[0].is_nan() {
                continue;
            }
            s += ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
            c += 1;
        }
        if c > 0 {
            sum += s / c as f64;
            frames += 1;
        }
    }
    if frames == 0 {
        f64::NAN
    } else {
        sum / frames as f64
    }
}

/// The symmetric pairwise D_x matrix of a training set, stored as its upper triangle.
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceMatrix {
    /// Trace ids, in training-set order.
    pub ids: Vec<String>,
    /// `d_x(i, j)` for `i < j`, row by row (length n(n−1)/2).
    pub upper: Vec<f64>,
}

impl DistanceMatrix {
    /// Computes every pair in parallel (rayon): each trace is resampled once, then pairs are independent.
    pub fn compute(traces: &[Trace], samples: usize) -> Self {
        let res: Vec<Resampled> = traces.par_iter().map(|t| resample(t, samples)).collect();
        let n = res.len();
        let upper: Vec<f64> = (0..n)
            .into_par_iter()
            .flat_map_iter(|i| {
                let res = &res;
                (i + 1..n).map(move |j| trace_distance(&res[i], &res[j]))
            })
            .collect();
        DistanceMatrix {
            ids: res.into_iter().map(|r| r.trace_id).collect(),
            upper,
        }
    }

    /// Number of traces.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether it has no traces.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Index into [`DistanceMatrix::upper`] of pair `(i, j)`, `i < j < n`.
    pub fn pair_index(n: usize, i: usize, j: usize) -> usize {
        debug_assert!(i < j && j < n);
        i * n - i * (i + 1) / 2 + (j - i - 1)
    }

    /// d_x of traces `i` and `j` (0 on the diagonal).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        match i.cmp(&j) {
            std::cmp::Ordering::Equal => 0.0,
            std::cmp::Ordering::Less => self.upper[Self::pair_index(self.len(), i, j)],
            std::cmp::Ordering::Greater => self.upper[Self::pair_index(self.len(), j, i)],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::synthetic_trace;

    fn shifted(env: Env, steps: usize, objects: usize, dx: f64) -> Trace {
        let mut t = synthetic_trace(env, 0, steps, objects);
        for ts in &mut t.timesteps {
            for o in &mut ts.objects {
                if let crate::trace::Body::Pool(b) = &mut o.body {
                    b.position[0] += dx;
                }
            }
        }
        t
    }

    #[test]
    fn a_constant_shift_is_its_scaled_length_and_identical_traces_are_zero() {
        let a = shifted(Env::Pooltool, 11, 3, 0.0);
        let b = shifted(Env::Pooltool, 11, 3, 0.19812);
        let (ra, rb) = (resample(&a, 5), resample(&b, 5));
        assert!((trace_distance(&ra, &rb) - 0.1).abs() < 1e-12);
        assert_eq!(trace_distance(&ra, &ra), 0.0);
    }

    #[test]
    fn different_lengths_align_on_normalised_time() {
        // Object k of the synthetic trace sits at x = k + 0.01 s; 11 steps end at x = k + 0.1,
        // 21 steps at x = k + 0.2. At u the gap is 0.1·u (scaled by the table length), mean over
        // u = 0, 0.5, 1 is 0.05.
        let a = synthetic_trace(Env::Pooltool, 0, 11, 2);
        let b = synthetic_trace(Env::Pooltool, 0, 21, 2);
        let d = trace_distance(&resample(&a, 3), &resample(&b, 3));
        assert!((d - 0.05 / 1.9812).abs() < 1e-12, "{d}");
    }

    #[test]
    fn only_matched_objects_count_and_no_match_is_nan() {
        let a = shifted(Env::Pooltool, 5, 2, 0.0);
        let mut b = shifted(Env::Pooltool, 5, 3, 0.0);
        // The third ball exists only in b: it does not change the distance.
        assert_eq!(trace_distance(&resample(&a, 4), &resample(&b, 4)), 0.0);
        for ts in &mut b.timesteps {
            for o in &mut ts.objects {
                if let crate::trace::Body::Pool(p) = &mut o.body {
                    p.ball_id = format!("other-{}", p.ball_id);
                }
            }
        }
        assert!(trace_distance(&resample(&a, 4), &resample(&b, 4)).is_nan());
    }

    #[test]
    fn the_matrix_is_symmetric_and_matches_pairwise_values() {
        let ts: Vec<Trace> = (0..5)
            .map(|i| shifted(Env::Pooltool, 7, 2, i as f64 * 0.1))
            .collect();
        let m = DistanceMatrix::compute(&ts, 8);
        assert_eq!(m.upper.len(), 10);
        for i in 0..5 {
            for j in 0..5 {
                let want = (i as f64 - j as f64).abs() * 0.1 / 1.9812;
                assert!((m.get(i, j) - want).abs() < 1e-12, "{i} {j}");
            }
        }
    }
}
