//! Annotations: the patterns a library found in a trace, as rows ([`Annotation`]) and as the paper's
//! sparse N×J matrix of a trace ([`AnnotationMatrix`], timestep × detector).

use std::collections::BTreeMap;

use serde_json::{Map, Value};

use super::detector::{Detector, DetectorId};
use super::validate::Pattern;
use crate::trace::Trace;

/// One pattern found by one detector in one trace (a row of the `annotations` table).
#[derive(Clone, Debug, PartialEq)]
pub struct Annotation {
    /// The detector.
    pub detector_id: DetectorId,
    /// The trace.
    pub trace_id: String,
    /// The detector's label (canonical spelling, whatever the detector wrote).
    pub label: String,
    /// Position of the pattern in the detector's output for this trace.
    pub seq: usize,
    /// First timestep index (inclusive).
    pub start_step: i64,
    /// Last timestep index (inclusive).
    pub end_step: i64,
    /// Time of the first timestep (s).
    pub t_start: f64,
    /// Time of the last timestep (s).
    pub t_end: f64,
    /// The object ids it names (from `object_details`).
    pub objects: Vec<String>,
    /// `parameters` (with `object_details`).
    pub parameters: Map<String, Value>,
    /// `provenance`, if the detector gave one.
    pub provenance: Option<Value>,
    /// `metadata`, if the detector gave one.
    pub metadata: Option<Value>,
    /// Its value in the annotation matrix: the detector's weight.
    pub activation: f64,
}

impl Annotation {
    /// The annotation of `pattern`, found by `detector` in `trace` as its `seq`-th pattern.
    pub fn new(detector: &Detector, trace: &Trace, seq: usize, pattern: Pattern) -> Self {
        let time_of = |step: i64| {
            trace
                .timesteps
                .binary_search_by_key(&step, |t| t.index)
                .ok()
                .map(|i| trace.timesteps[i].t)
                .unwrap_or(f64::NAN)
        };
        Annotation {
            detector_id: detector.id.clone(),
            trace_id: trace.trace_id.clone(),
            label: detector.label.clone(),
            seq,
            start_step: pattern.start_step,
            end_step: pattern.end_step,
            t_start: time_of(pattern.start_step),
            t_end: time_of(pattern.end_step),
            objects: pattern.objects(),
            parameters: pattern.parameters,
            provenance: pattern.provenance,
            metadata: pattern.metadata,
            activation: detector.weight,
        }
    }
}

/// The annotations of each of `traces`, in the order of `traces`, each trace's in the order they
/// come in; annotations of traces not in `traces` are dropped, and a trace listed twice gets them at
/// its first place only. One pass over `annotations` (a filter per trace would compare every
/// annotation's trace id once per trace). `A` is an owned [`Annotation`] or a reference to one.
pub fn by_trace<A: std::borrow::Borrow<Annotation>>(
    traces: &[Trace],
    annotations: impl IntoIterator<Item = A>,
) -> Vec<Vec<A>> {
    let index: std::collections::HashMap<&str, usize> = traces
        .iter()
        .enumerate()
        .rev()
        .map(|(i, t)| (t.trace_id.as_str(), i))
        .collect();
    let mut out: Vec<Vec<A>> = traces.iter().map(|_| Vec::new()).collect();
    for a in annotations {
        if let Some(&i) = index.get(a.borrow().trace_id.as_str()) {
            out[i].push(a);
        }
    }
    out
}

/// The sparse N×J annotation matrix of one trace: row n is the trace's n-th timestep, column j the
/// j-th detector; a cell holds the activation of a pattern covering that step (the largest, when
/// patterns of one detector overlap), and absent cells are 0.
#[derive(Clone, Debug, PartialEq)]
pub struct AnnotationMatrix {
    /// Timestep index of each row.
    pub steps: Vec<i64>,
    /// Detector of each column.
    pub columns: Vec<DetectorId>,
    /// Non-zero cells `(row, column) -> activation`, ordered by row then column.
    pub cells: BTreeMap<(usize, usize), f64>,
}

impl AnnotationMatrix {
    /// Builds the matrix of a trace with timestep indices `steps` (increasing) over `columns`, from its
    /// annotations (annotations of other detectors or traces' steps outside `steps` are ignored).
    pub fn build(steps: &[i64], columns: &[DetectorId], annotations: &[Annotation]) -> Self {
        let mut cells = BTreeMap::new();
        for a in annotations {
            let Some(col) = columns.iter().position(|c| *c == a.detector_id) else {
                continue;
            };
            let lo = steps.partition_point(|&s| s < a.start_step);
            let hi = steps.partition_point(|&s| s <= a.end_step);
            for row in lo..hi {
                let cell = cells.entry((row, col)).or_insert(0.0_f64);
                *cell = cell.max(a.activation);
            }
        }
        AnnotationMatrix {
            steps: steps.to_vec(),
            columns: columns.to_vec(),
            cells,
        }
    }

    /// (rows, columns).
    pub fn shape(&self) -> (usize, usize) {
        (self.steps.len(), self.columns.len())
    }

    /// The value of a cell (0 when absent).
    pub fn get(&self, row: usize, col: usize) -> f64 {
        self.cells.get(&(row, col)).copied().unwrap_or(0.0)
    }

    /// Non-zero cells.
    pub fn nnz(&self) -> usize {
        self.cells.len()
    }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;
    use crate::trace::Env;

    #[test]
    fn the_matrix_covers_each_span_inclusively() {
        let d = Detector::new(Env::Pooltool, "a", "x", "t");
        let e = Detector {
            weight: 0.5,
            ..Detector::new(Env::Pooltool, "b", "y", "t")
        };
        let trace = crate::testutil::synthetic_trace(Env::Pooltool, 0, 6, 2);
        let p = |s, e| Pattern {
            label: "a".into(),
            start_step: s,
            end_step: e,
            parameters: json!({"object_details": {"cue": {"ball_id": "cue"}}})
                .as_object()
                .unwrap()
                .clone(),
            provenance: None,
            metadata: None,
        };
        let anns = vec![
            Annotation::new(&d, &trace, 0, p(1, 2)),
            Annotation::new(&e, &trace, 0, p(2, 4)),
        ];
        assert_eq!(anns[0].objects, vec!["cue".to_string()]);
        let steps: Vec<i64> = trace.timesteps.iter().map(|t| t.index).collect();
        let m = AnnotationMatrix::build(&steps, &[d.id.clone(), e.id.clone()], &anns);
        assert_eq!(m.shape(), (6, 2));
        assert_eq!(m.nnz(), 5);
        assert_eq!(
            (m.get(0, 0), m.get(1, 0), m.get(2, 0), m.get(3, 0)),
            (0.0, 1.0, 1.0, 0.0)
        );
        assert_eq!((m.get(2, 1), m.get(4, 1), m.get(5, 1)), (0.5, 0.5, 0.0));
    }

    #[test]
    fn annotations_are_grouped_by_trace_in_the_traces_order_keeping_their_own_order() {
        let d = Detector::new(Env::Pooltool, "a", "x", "t");
        let traces: Vec<Trace> = (0..3)
            .map(|i| crate::testutil::synthetic_trace(Env::Pooltool, i, 4, 2))
            .collect();
        let p = |s| Pattern {
            label: "a".into(),
            start_step: s,
            end_step: s,
            parameters: Map::new(),
            provenance: None,
            metadata: None,
        };
        let stranger = crate::testutil::synthetic_trace(Env::Pooltool, 9, 4, 2);
        // Interleaved, with a trace that is not asked for.
        let anns = vec![
            Annotation::new(&d, &traces[2], 0, p(3)),
            Annotation::new(&d, &traces[0], 0, p(1)),
            Annotation::new(&d, &stranger, 0, p(0)),
            Annotation::new(&d, &traces[2], 1, p(0)),
            Annotation::new(&d, &traces[0], 1, p(2)),
        ];
        let asked = [
            traces[2].clone(),
            traces[1].clone(),
            traces[0].clone(),
            traces[2].clone(),
        ];
        let grouped = by_trace(&asked, &anns);
        let filtered: Vec<Vec<&Annotation>> = asked
            .iter()
            .map(|t| anns.iter().filter(|a| a.trace_id == t.trace_id).collect())
            .collect();
        assert_eq!(grouped[..3], filtered[..3]);
        assert_eq!(
            grouped[0].iter().map(|a| a.start_step).collect::<Vec<_>>(),
            [3, 0]
        );
        assert!(grouped[1].is_empty() && grouped[3].is_empty());
        // Owned annotations are moved into their groups.
        let owned = by_trace(&traces, anns.clone());
        assert_eq!(owned.iter().map(Vec::len).collect::<Vec<_>>(), [2, 0, 2]);
        assert_eq!(owned[2], [anns[0].clone(), anns[3].clone()]);
    }
}
