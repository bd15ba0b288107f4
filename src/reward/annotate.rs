//! Annotating traces for reward programs through the detector runtime: the detectors a program
//! needs, one batched worker-pool call for many traces, and a schema whose parameter keys are learned
//! by annotating a few simulated shots.

use crate::detect::{Annotation, CandidateStatus, Detector, Library, WorkerPool, normalise_label};
use crate::envs::Environment;
use crate::envs::pool::{PoolEnv, Shot};
use crate::trace::{Env, Trace};

use super::schema::Schema;

/// The detectors of `library` whose labels are in `labels` (all of them when `labels` is empty).
pub fn detectors_for(library: &Library, labels: &[String]) -> Vec<Detector> {
    let wanted: Vec<String> = labels.iter().map(|l| normalise_label(l)).collect();
    library
        .detectors
        .iter()
        .filter(|d| wanted.is_empty() || wanted.contains(&normalise_label(&d.label)))
        .cloned()
        .collect()
}

/// Runs `detectors` over `traces` in one pool call; returns the annotations of the successful calls
/// and the number of failed calls. Members of an ensemble library's labels are combined into the
/// label's ensemble annotations (`ensemble::activation`), so reward programs read ensemble libraries
/// as they read plain ones.
pub fn annotate(
    pool: &WorkerPool,
    detectors: &[Detector],
    traces: &[Trace],
) -> (Vec<Annotation>, usize) {
    if detectors.is_empty() || traces.is_empty() {
        return (Vec::new(), 0);
    }
    let batch = pool.run(detectors, traces);
    let mut out = Vec::new();
    let mut failed = 0;
    for r in batch.results {
        if r.status != CandidateStatus::Ok {
            failed += 1;
            continue;
        }
        let det = &detectors[r.detector];
        for (seq, p) in r.patterns.into_iter().enumerate() {
            out.push(Annotation::new(det, &traces[r.trace], seq, p));
        }
    }
    (
        crate::ensemble::activation::combine(detectors, traces, out),
        failed,
    )
}

/// Shots of the probe: straight, cut, soft, follow, draw, side spin, masse and a bank, so that every
/// built-in billiards label fires at least once.
const PROBE_SHOTS: [Shot; 8] = [
    Shot {
        v0: 2.5,
        phi: 90.0,
        theta: 0.0,
        a: 0.0,
        b: 0.0,
    },
    Shot {
        v0: 4.0,
        phi: 80.0,
        theta: 0.0,
        a: 0.0,
        b: 0.4,
    },
    Shot {
        v0: 0.6,
        phi: 95.0,
        theta: 0.0,
        a: 0.0,
        b: 0.0,
    },
    Shot {
        v0: 3.0,
        phi: 100.0,
        theta: 5.0,
        a: 0.3,
        b: -0.4,
    },
    Shot {
        v0: 5.0,
        phi: 30.0,
        theta: 0.0,
        a: -0.4,
        b: 0.2,
    },
    Shot {
        v0: 3.0,
        phi: 92.0,
        theta: 45.0,
        a: 0.5,
        b: 0.0,
    },
    Shot {
        v0: 6.0,
        phi: 200.0,
        theta: 0.0,
        a: 0.0,
        b: 0.0,
    },
    Shot {
        v0: 2.0,
        phi: 85.0,
        theta: 10.0,
        a: 0.0,
        b: 0.5,
    },
];

/// The schema of `library` with parameter keys learned from annotating eight simulated billiards
/// shots (for other environments, the labels only: no simulator input is at hand for them here).
pub fn probe_schema(library: &Library, pool: &WorkerPool) -> Schema {
    let mut schema = Schema::from_library(library);
    if library.env != Env::Pooltool {
        return schema;
    }
    let env = PoolEnv::default();
    let traces: Vec<Trace> = env
        .scenes(PROBE_SHOTS.len(), 20_260_101)
        .unwrap_or_default()
        .iter()
        .zip(PROBE_SHOTS.iter())
        .filter_map(|(scene, shot)| env.simulate(scene, shot).ok())
        .collect();
    let (anns, _) = annotate(pool, &library.detectors, &traces);
    schema.learn_keys(&anns);
    schema
}
