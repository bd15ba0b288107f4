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
//!
//! **Variants** ([`Dx`]). `positions` (the paper's d_x, the default) compares matched objects where they
//! are. `invariant` (beyond the paper, which names d_x's lack of translation and rotation invariance as
//! a limitation) first aligns each matched object's trajectory in one trace to its trajectory in the
//! other by a rigid 2-D Procrustes fit — the translation that matches their centroids over the frames
//! where both exist, then the rotation (no reflection, no scaling) that minimises the squared
//! differences, θ = atan2(Σ(x_a y_b − y_a x_b), Σ(x_a x_b + y_a y_b)) on the centred points — and then
//! measures as `positions` does. The same bounce at two places of the table, or in two directions, is
//! then 0 apart; only the shape and timing of each object's motion count. Each object gets its own
//! fit, so the relative placement of objects is not compared either.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use std::collections::BTreeMap;

use rayon::prelude::*;

use crate::trace::{Env, Trace};

/// Which trace distance d_x is (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Dx {
    /// Matched objects' centres where they are (the paper's d_x).
    #[default]
    Positions,
    /// Each matched object's trajectory aligned to its counterpart by a rigid Procrustes fit first
    /// (translation and rotation invariant).
    Invariant,
}

impl Dx {
    /// Every variant, in documentation order.
    pub const ALL: [Dx; 2] = [Dx::Positions, Dx::Invariant];

    /// `positions` or `invariant`.
    pub fn as_str(self) -> &'static str {
        match self {
            Dx::Positions => "positions",
            Dx::Invariant => "invariant",
        }
    }

    /// d_x of two resampled traces under this variant.
    pub fn distance(self, a: &Resampled, b: &Resampled) -> f64 {
        match self {
            Dx::Positions => trace_distance(a, b),
            Dx::Invariant => invariant_distance(a, b),
        }
    }
}

impl std::fmt::Display for Dx {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Dx {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Dx::ALL
            .into_iter()
            .find(|d| d.as_str() == s)
            .ok_or_else(|| format!("unknown d_x {s:?}: expected positions or invariant"))
    }
}

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

/// Matched columns of `a` and `b` (indices into their sorted object lists), by a merge.
fn matched(a: &Resampled, b: &Resampled) -> Vec<(usize, usize)> {
    let (ma, mb) = (a.objects.len(), b.objects.len());
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
    pairs
}

/// The mean over frames of the mean distance of the matched objects' centres `ca`/`cb`
/// (`samples × pairs`, row-major; `NaN` where absent); `NaN` when no frame has a matched object.
fn mean_frame_distance(ca: &[[f64; 2]], cb: &[[f64; 2]], samples: usize, pairs: usize) -> f64 {
    let (mut sum, mut frames) = (0.0, 0usize);
    for k in 0..samples {
        let (mut s, mut c) = (0.0, 0usize);
        for m in 0..pairs {
            let (p, q) = (ca[k * pairs + m], cb[k * pairs + m]);
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

/// The matched objects' centres of `a` and `b` side by side (`samples × pairs`, row-major).
fn matched_centres(a: &Resampled, b: &Resampled) -> (Vec<[f64; 2]>, Vec<[f64; 2]>, usize) {
    let pairs = matched(a, b);
    let (ma, mb) = (a.objects.len(), b.objects.len());
    let mut ca = Vec::with_capacity(a.samples * pairs.len());
    let mut cb = Vec::with_capacity(a.samples * pairs.len());
    for k in 0..a.samples {
        for &(i, j) in &pairs {
            ca.push(a.centres[k * ma + i]);
            cb.push(b.centres[k * mb + j]);
        }
    }
    (ca, cb, pairs.len())
}

/// d_x between two resampled traces (same `samples`): the mean over frames of the mean distance of
/// matched objects; `NaN` when no object is matched at any frame.
pub fn trace_distance(a: &Resampled, b: &Resampled) -> f64 {
    if a.samples == 0 || a.samples != b.samples {
        return f64::NAN;
    }
    let (ca, cb, n) = matched_centres(a, b);
    mean_frame_distance(&ca, &cb, a.samples, n)
}

/// Rigidly aligns the points `p` onto `q` (same length; pairs with a `NaN` on either side are ignored
/// by the fit and stay `NaN`): `p` is centred, rotated by the Procrustes angle and moved to `q`'s
/// centroid. Returns `p` unchanged when no pair is complete.
pub fn procrustes_align(p: &[[f64; 2]], q: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let both = |k: usize| !p[k][0].is_nan() && !q[k][0].is_nan();
    let n = (0..p.len()).filter(|&k| both(k)).count();
    if n == 0 {
        return p.to_vec();
    }
    let (mut pc, mut qc) = ([0.0; 2], [0.0; 2]);
    for k in (0..p.len()).filter(|&k| both(k)) {
        for d in 0..2 {
            pc[d] += p[k][d] / n as f64;
            qc[d] += q[k][d] / n as f64;
        }
    }
    let (mut dot, mut cross) = (0.0, 0.0);
    for k in (0..p.len()).filter(|&k| both(k)) {
        let (px, py) = (p[k][0] - pc[0], p[k][1] - pc[1]);
        let (qx, qy) = (q[k][0] - qc[0], q[k][1] - qc[1]);
        dot += px * qx + py * qy;
        cross += px * qy - py * qx;
    }
    // A degenerate fit (a stationary object on either side) has no preferred angle: rotate by 0.
    let theta = if dot == 0.0 && cross == 0.0 {
        0.0
    } else {
        cross.atan2(dot)
    };
    let (s, c) = theta.sin_cos();
    p.iter()
        .map(|v| {
            if v[0].is_nan() {
                return [f64::NAN; 2];
            }
            let (x, y) = (v[0] - pc[0], v[1] - pc[1]);
            [c * x - s * y + qc[0], s * x + c * y + qc[1]]
        })
        .collect()
}

/// The `invariant` d_x: each matched object's trajectory in `a` aligned to its trajectory in `b` by
/// [`procrustes_align`], then measured as [`trace_distance`]. Symmetric up to rounding (the optimal
/// rigid fit of a onto b and of b onto a leave the same residuals).
pub fn invariant_distance(a: &Resampled, b: &Resampled) -> f64 {
    if a.samples == 0 || a.samples != b.samples {
        return f64::NAN;
    }
    let (mut ca, cb, n) = matched_centres(a, b);
    for m in 0..n {
        let p: Vec<[f64; 2]> = (0..a.samples).map(|k| ca[k * n + m]).collect();
        let q: Vec<[f64; 2]> = (0..a.samples).map(|k| cb[k * n + m]).collect();
        for (k, v) in procrustes_align(&p, &q).into_iter().enumerate() {
            ca[k * n + m] = v;
        }
    }
    mean_frame_distance(&ca, &cb, a.samples, n)
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
        Self::compute_with(traces, samples, Dx::Positions)
    }

    /// [`DistanceMatrix::compute`] under the d_x variant `dx`.
    pub fn compute_with(traces: &[Trace], samples: usize, dx: Dx) -> Self {
        let res: Vec<Resampled> = traces.par_iter().map(|t| resample(t, samples)).collect();
        let n = res.len();
        let upper: Vec<f64> = (0..n)
            .into_par_iter()
            .flat_map_iter(|i| {
                let res = &res;
                (i + 1..n).map(move |j| dx.distance(&res[i], &res[j]))
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
                    p.ball_id = format!("other-{}", p.ball_id).into();
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

    fn one_object(points: &[[f64; 2]]) -> Resampled {
        Resampled {
            trace_id: "t".into(),
            objects: vec!["o".into()],
            centres: points.to_vec(),
            samples: points.len(),
        }
    }

    #[test]
    fn invariant_dx_ignores_a_rigid_motion_that_positions_counts() {
        let path = [[0.0, 0.0], [0.1, 0.0], [0.2, 0.05], [0.25, 0.15]];
        // Rotated by 90° and moved to another place.
        let moved: Vec<[f64; 2]> = path.iter().map(|p| [0.5 - p[1], 0.3 + p[0]]).collect();
        let (a, b) = (one_object(&path), one_object(&moved));
        assert!(invariant_distance(&a, &b).abs() < 1e-12);
        assert!(trace_distance(&a, &b) > 0.2);
        assert!(Dx::Invariant.distance(&a, &a).abs() < 1e-12);
    }

    #[test]
    fn invariant_dx_hand_values() {
        // A moving object against a stationary one: no rotation is preferred, so only the centroids
        // are matched: distances 1, 0, 1 → 2/3.
        let a = one_object(&[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]);
        let b = one_object(&[[5.0, 5.0], [5.0, 5.0], [5.0, 5.0]]);
        assert!((invariant_distance(&a, &b) - 2.0 / 3.0).abs() < 1e-12);
        // An L and its mirror image: no reflection, so the best rotation (−90°) leaves residuals
        // √2/3, 2√2/3, √2/3 → 4√2/9.
        let l = one_object(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]);
        let m = one_object(&[[0.0, 0.0], [1.0, 0.0], [1.0, -1.0]]);
        let want = 4.0 * 2f64.sqrt() / 9.0;
        assert!((invariant_distance(&l, &m) - want).abs() < 1e-12);
        assert!((invariant_distance(&m, &l) - want).abs() < 1e-12);
        // Frames where one side is absent take no part in the fit or the mean.
        let mut gap = l.clone();
        gap.centres.push([f64::NAN; 2]);
        gap.samples = 4;
        let mut m4 = m.clone();
        m4.centres.push([9.0, 9.0]);
        m4.samples = 4;
        assert!((invariant_distance(&gap, &m4) - want).abs() < 1e-12);
    }

    #[test]
    fn the_invariant_matrix_of_shifted_copies_is_zero() {
        let ts: Vec<Trace> = (0..4)
            .map(|i| shifted(Env::Pooltool, 7, 2, i as f64 * 0.1))
            .collect();
        let m = DistanceMatrix::compute_with(&ts, 8, Dx::Invariant);
        assert!(m.upper.iter().all(|d| d.abs() < 1e-12), "{:?}", m.upper);
        assert_eq!(
            DistanceMatrix::compute(&ts, 8),
            DistanceMatrix::compute_with(&ts, 8, Dx::Positions)
        );
    }
}
