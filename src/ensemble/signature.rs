//! Behaviour signatures: each pooled candidate runs over one fixed set of held-out traces in the worker
//! pool, and its signature is the concatenation of its activation histograms there — the histograms
//! the annotation distance d_p compares (`fitness::histogram`: b time bins, smoothed fractions). K-means
//! then groups candidates whose annotations behave alike on the same traces.
//!
//! **Owns:** turning candidates into signatures and member patterns into histograms. **Does not:**
//! define the histogram (`fitness::histogram`) or run Python in-process (`detect::WorkerPool`).

use crate::detect::{Annotation, CandidateStatus, Detector, WorkerPool};
use crate::fitness::histogram::{activation, histogram};
use crate::trace::Trace;

/// The patterns of `detectors` over `traces` (one pool call), and for each detector whether every call
/// succeeded.
pub fn run(
    pool: &WorkerPool,
    detectors: &[Detector],
    traces: &[Trace],
) -> (Vec<Annotation>, Vec<bool>) {
    let mut ok = vec![true; detectors.len()];
    if detectors.is_empty() || traces.is_empty() {
        return (Vec::new(), ok);
    }
    let batch = pool.run(detectors, traces);
    let mut out = Vec::new();
    for r in batch.results {
        if r.status != CandidateStatus::Ok {
            ok[r.detector] = false;
            continue;
        }
        let det = &detectors[r.detector];
        for (seq, p) in r.patterns.into_iter().enumerate() {
            out.push(Annotation::new(det, &traces[r.trace], seq, p));
        }
    }
    (out, ok)
}

/// The histogram of the annotations `anns` of one detector (or ensemble) id on `trace`.
pub fn trace_histogram(trace: &Trace, anns: &[&Annotation], bins: usize) -> Vec<f64> {
    let steps: Vec<i64> = trace.timesteps.iter().map(|t| t.index).collect();
    let ranges = anns
        .iter()
        .filter(|a| a.trace_id == trace.trace_id)
        .map(|a| (a.start_step, a.end_step));
    histogram(&activation(&steps, ranges), bins)
}

/// Per detector, its histogram on each trace (trace order), from the patterns `anns`.
pub fn histograms(
    detectors: &[Detector],
    traces: &[Trace],
    anns: &[Annotation],
    bins: usize,
) -> Vec<Vec<Vec<f64>>> {
    detectors
        .iter()
        .map(|d| {
            let mine: Vec<&Annotation> = anns.iter().filter(|a| a.detector_id == d.id).collect();
            traces
                .iter()
                .map(|t| trace_histogram(t, &mine, bins))
                .collect()
        })
        .collect()
}

/// The signature of one detector: its per-trace histograms, concatenated.
pub fn signature(hists: &[Vec<f64>]) -> Vec<f64> {
    hists.iter().flatten().copied().collect()
}
