//! Accuracy of event-grounded labels: detections scored against ground truth from the simulator's
//! event log and states.
//!
//! This module owns the scoring (one-to-one matching, precision, recall, F1, the Markdown table), the
//! lists of grounded labels and the dispatch by environment; the ground-truth rules live beside it, one
//! file per environment (`pooltool.rs`, `iphyre.rs`, `phyre.rs`), with the merging of logged contacts in
//! `contacts.rs`. It does not run detectors (the `accuracy` stage does) and shares no code with them.
//! Each rule is stated in `docs/accuracy.md`.
//!
//! A detection matches a truth event when it has the same label and trace, names every object the event
//! involves among its objects, and its time span `[t_start − tolerance, t_end + tolerance]` holds the
//! event's time. Matching is one-to-one, greedy in time order, each event taking the matching detection
//! whose span holds its time (else is nearest to it), then whose span centre is closest. Unmatched
//! detections are false positives, unmatched events false negatives.

mod airborne;
mod contacts;
pub mod geometry;
mod iphyre;
mod iphyre_motion;
mod kin;
mod phyre;
mod phyre_motion;
mod pooltool;

use std::collections::BTreeMap;

use serde::Serialize;

use super::annotation::Annotation;
use super::detector::normalise_label;
use crate::trace::{Env, Trace};

pub use iphyre::iphyre_truth;
pub use phyre::{PHYRE_AT_REST, PHYRE_MOVING, PHYRE_WINDOW_S, phyre_truth};
pub use pooltool::{event_balls, pooltool_state_truth, pooltool_truth};

/// One ground-truth occurrence of a label.
#[derive(Clone, Debug, PartialEq)]
pub struct TruthEvent {
    /// The label it grounds.
    pub label: &'static str,
    /// Its time (s): the first contact of a merged burst.
    pub t: f64,
    /// The balls it involves.
    pub balls: Vec<String>,
}

/// Precision, recall and F1 of one label.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LabelScore {
    /// The label.
    pub label: String,
    /// Truth events.
    pub events: u64,
    /// Detections.
    pub detections: u64,
    /// Matched pairs.
    pub true_positives: u64,
    /// Unmatched detections.
    pub false_positives: u64,
    /// Unmatched events.
    pub false_negatives: u64,
}

impl LabelScore {
    /// TP / (TP + FP); 1 when there are no detections and no events, 0 when only events.
    pub fn precision(&self) -> f64 {
        ratio(
            self.true_positives,
            self.true_positives + self.false_positives,
            self.events == 0,
        )
    }

    /// TP / (TP + FN).
    pub fn recall(&self) -> f64 {
        ratio(
            self.true_positives,
            self.true_positives + self.false_negatives,
            self.detections == 0,
        )
    }

    /// Harmonic mean of precision and recall.
    pub fn f1(&self) -> f64 {
        let (p, r) = (self.precision(), self.recall());
        if p + r > 0.0 {
            2.0 * p * r / (p + r)
        } else {
            0.0
        }
    }
}

fn ratio(a: u64, b: u64, empty_is_perfect: bool) -> f64 {
    if b == 0 {
        if empty_is_perfect { 1.0 } else { 0.0 }
    } else {
        a as f64 / b as f64
    }
}

/// The pooltool labels with a ground truth (from events, or from the simulator's inputs and state), in the
/// paper's order.
pub const POOLTOOL_GROUNDED: &[&str] = &[
    "cue strike",
    "ball collision",
    "cushion rebound",
    "ball pocketed",
    "rolling ball",
    "sliding ball",
    "spinning ball",
    "ball slowing",
    "spin shot",
    "ball curves around ball",
    "high angle collision",
    "gentle touch",
];

/// The event-grounded I-PHYRE labels.
pub const IPHYRE_GROUNDED: &[&str] = &[
    "collision",
    "support contact",
    "falling object",
    "swinging object",
    "object removal",
    "sliding contact",
    "airborne motion",
    "bounce",
    "chain movement",
    "spring pull towards",
    "spring resist movement",
    "lever launch",
];

/// The event-grounded PHYRE labels.
pub const PHYRE_GROUNDED: &[&str] = &[
    "moving object hits stationary object",
    "near collision",
    "support relationship",
    "lose support",
    "falling object",
    "rolling object",
    "sliding contact",
    "airborne motion",
    "bounce",
    "grid cell transition",
    "wedged",
    "tip over",
];

/// The event-grounded labels of `env`, in the paper's order.
pub fn grounded(env: Env) -> &'static [&'static str] {
    match env {
        Env::Pooltool => POOLTOOL_GROUNDED,
        Env::Iphyre => IPHYRE_GROUNDED,
        Env::Phyre => PHYRE_GROUNDED,
    }
}

/// The ground truth of a trace of `env`, from its event log (and, for PHYRE, the frame before each
/// contact).
///
/// PHYRE and I-PHYRE events after the trace's last timestep are left out: no pattern can span them (an
/// imported trace may keep fewer frames than its event log covers).
pub fn truth(env: Env, trace: &Trace, merge_s: f64) -> Vec<TruthEvent> {
    let last = trace.timesteps.last().map_or(f64::NEG_INFINITY, |s| s.t);
    match env {
        Env::Pooltool => {
            let mut v = pooltool_truth(trace, merge_s);
            v.extend(pooltool::pooltool_state_truth(trace, merge_s));
            v
        }
        Env::Iphyre | Env::Phyre => {
            let mut v = if env == Env::Iphyre {
                let mut v = iphyre_truth(trace, merge_s);
                v.extend(iphyre_motion::iphyre_motion_truth(trace, merge_s));
                v
            } else {
                let mut v = phyre_truth(trace, merge_s);
                v.extend(phyre_motion::phyre_motion_truth(trace, merge_s));
                v
            };
            v.extend(airborne::airborne_truth(env, trace, merge_s));
            v
        }
    }
    .into_iter()
    .filter(|e| env == Env::Pooltool || e.t <= last + 1e-9)
    .collect()
}

/// Whether a trace can ground its labels: a billiards trace with pooltool events; a PHYRE or I-PHYRE
/// trace with contact events, from annotrace's simulator (its `simulator` field; it logs every
/// contact), or holding every 60 Hz physics step (traces exported from the original simulators, whose
/// contacts are rebuilt from the frames, `geometry.rs`; for PHYRE only tasks of the embedded task set,
/// whose exact outlines are known). A sparse imported trace without contact events (such as
/// `data/examples/`) says nothing about its contacts, so scoring it would count every contact a detector
/// infers as false.
pub fn scorable(env: Env, trace: &Trace) -> bool {
    match env {
        Env::Pooltool => trace.events.iter().any(|e| e.kind.starts_with("physics_")),
        Env::Iphyre | Env::Phyre => {
            trace.extra.contains_key("simulator")
                || contacts::has_contact_log(trace)
                || (geometry::dense(trace)
                    && (env == Env::Iphyre || geometry::phyre_outlines_known(trace)))
        }
    }
}

/// A disagreement between detections and ground truth: an unmatched truth event (a false negative) or
/// an unmatched detection (a false positive).
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct Miss {
    /// The label.
    pub label: String,
    /// The trace.
    pub trace_id: String,
    /// `"missed"` (a truth event no detection matched) or `"false"` (a detection matching no event).
    pub kind: String,
    /// The truth event's time, or the detection's span start (s).
    pub t_start: f64,
    /// The truth event's time, or the detection's span end (s).
    pub t_end: f64,
    /// The objects the event involves, or the detection names.
    pub objects: Vec<String>,
}

/// Scores the annotations of one trace against its truth events, adding to `scores` (by label) for
/// the `grounded` labels; annotations of other labels are ignored.
pub fn score_trace(
    grounded: &[&str],
    truth: &[TruthEvent],
    annotations: &[&Annotation],
    tolerance: f64,
    scores: &mut BTreeMap<String, LabelScore>,
) {
    score_trace_listing("", grounded, truth, annotations, tolerance, scores);
}

/// [`score_trace`] of trace `trace_id`, also returning every disagreement (unmatched events and
/// detections of grounded labels) by label and time.
pub fn score_trace_listing(
    trace_id: &str,
    grounded: &[&str],
    truth: &[TruthEvent],
    annotations: &[&Annotation],
    tolerance: f64,
    scores: &mut BTreeMap<String, LabelScore>,
) -> Vec<Miss> {
    let mut misses = Vec::new();
    for label in grounded
        .iter()
        .copied()
        .chain(truth.iter().map(|e| e.label))
    {
        scores
            .entry(label.to_string())
            .or_insert_with(|| LabelScore {
                label: label.to_string(),
                ..LabelScore::default()
            });
    }
    let grounded: Vec<(String, String)> = scores
        .keys()
        .map(|k| (normalise_label(k), k.clone()))
        .collect();
    let labels: Vec<String> = annotations
        .iter()
        .map(|a| normalise_label(&a.label))
        .collect();
    // Each label's annotations, in order: an event looks only at its own label's.
    let mut of_label: std::collections::HashMap<&str, Vec<usize>> = Default::default();
    for (i, l) in labels.iter().enumerate() {
        of_label.entry(l.as_str()).or_default().push(i);
    }
    let mut used = vec![false; annotations.len()];
    for ev in truth {
        let s = scores.get_mut(ev.label).expect("inserted above");
        s.events += 1;
        let want = normalise_label(ev.label);
        let candidates = of_label.get(want.as_str()).map_or(&[][..], Vec::as_slice);
        let best = candidates
            .iter()
            .map(|&i| (i, annotations[i]))
            .filter(|(i, a)| {
                !used[*i]
                    && a.t_start - tolerance <= ev.t
                    && ev.t <= a.t_end + tolerance
                    && ev.balls.iter().all(|b| a.objects.contains(b))
            })
            .min_by(|(_, a), (_, b)| {
                let key = |a: &Annotation| {
                    let outside = (a.t_start - ev.t).max(ev.t - a.t_end).max(0.0);
                    (outside, ((a.t_start + a.t_end) / 2.0 - ev.t).abs())
                };
                key(a)
                    .partial_cmp(&key(b))
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
            .map(|(i, _)| i);
        match best {
            Some(i) => {
                used[i] = true;
                s.true_positives += 1;
            }
            None => {
                s.false_negatives += 1;
                misses.push(Miss {
                    label: ev.label.to_string(),
                    trace_id: trace_id.to_string(),
                    kind: "missed".into(),
                    t_start: ev.t,
                    t_end: ev.t,
                    objects: ev.balls.clone(),
                });
            }
        }
    }
    for (i, label) in labels.iter().enumerate() {
        let Some((_, key)) = grounded.iter().find(|(g, _)| g == label) else {
            continue;
        };
        let s = scores.get_mut(key).expect("a grounded label");
        s.detections += 1;
        if !used[i] {
            s.false_positives += 1;
            let a = annotations[i];
            misses.push(Miss {
                label: key.clone(),
                trace_id: a.trace_id.clone(),
                kind: "false".into(),
                t_start: a.t_start,
                t_end: a.t_end,
                objects: a.objects.clone(),
            });
        }
    }
    misses.sort_by(|a, b| {
        (a.label.as_str(), a.t_start)
            .partial_cmp(&(b.label.as_str(), b.t_start))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    misses
}

/// A Markdown table of scores (label, events, detections, precision, recall, F1).
pub fn markdown(scores: &[LabelScore]) -> String {
    let mut out = String::from(
        "| label | events | detections | TP | FP | FN | precision | recall | F1 |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for s in scores {
        out.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {:.3} | {:.3} | {:.3} |\n",
            s.label,
            s.events,
            s.detections,
            s.true_positives,
            s.false_positives,
            s.false_negatives,
            s.precision(),
            s.recall(),
            s.f1()
        ));
    }
    out
}

/// A hash of the ground-truth rules' source (this module's files, compiled in): the `accuracy` stage's
/// fingerprint includes it, so a changed rule rescores instead of serving a cached table.
pub fn rules_fingerprint() -> String {
    const SOURCES: [&str; 10] = [
        include_str!("mod.rs"),
        include_str!("airborne.rs"),
        include_str!("contacts.rs"),
        include_str!("geometry.rs"),
        include_str!("iphyre.rs"),
        include_str!("iphyre_motion.rs"),
        include_str!("kin.rs"),
        include_str!("phyre.rs"),
        include_str!("phyre_motion.rs"),
        include_str!("pooltool.rs"),
    ];
    crate::digest::sha256_hex(SOURCES.concat().as_bytes())[..16].to_string()
}

#[cfg(test)]
mod tests {

    #[test]
    fn the_rules_fingerprint_covers_every_file_of_the_module() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/detect/accuracy");
        let n = std::fs::read_dir(dir)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .path()
                    .extension()
                    .is_some_and(|x| x == "rs")
            })
            .count();
        assert_eq!(n, 10, "add the new file to rules_fingerprint's SOURCES");
        assert_eq!(super::rules_fingerprint().len(), 16);
    }

    use serde_json::json;

    use super::*;
    use crate::detect::DetectorId;
    use crate::trace::{Event, JsonMap};

    fn ev(kind: &str, t: f64, payload: serde_json::Value) -> Event {
        Event {
            kind: kind.into(),
            t: Some(t),
            payload: Some(payload),
            extra: JsonMap::new(),
        }
    }

    fn ann(label: &str, t0: f64, t1: f64, objects: &[&str]) -> Annotation {
        Annotation {
            detector_id: DetectorId("d".into()),
            trace_id: "t".into(),
            label: label.into(),
            seq: 0,
            start_step: 0,
            end_step: 0,
            t_start: t0,
            t_end: t1,
            objects: objects.iter().map(|s| s.to_string()).collect(),
            parameters: Default::default(),
            provenance: None,
            metadata: None,
            activation: 1.0,
        }
    }

    #[test]
    fn chatter_merges_and_matches_are_one_to_one() {
        let mut trace = crate::testutil::synthetic_trace(Env::Pooltool, 0, 3, 1);
        trace.events = vec![
            ev(
                "physics_stick_ball",
                0.0,
                json!({"agents": ["cue_stick", "cue"], "ball": "cue"}),
            ),
            ev("physics_ball_ball", 0.50, json!({"agents": ["cue", "1"]})),
            ev("physics_ball_ball", 0.52, json!({"agents": ["1", "cue"]})),
            ev("physics_ball_ball", 0.90, json!({"agents": ["cue", "1"]})),
        ];
        let truth = pooltool_truth(&trace, 0.05);
        assert_eq!(truth.len(), 3, "{truth:?}");
        let anns = [
            ann("cue strike", 0.0, 0.01, &["cue"]),
            ann("Ball Collision", 0.49, 0.53, &["cue", "1"]),
            ann("ball collision", 0.49, 0.53, &["cue", "1"]),
            ann("ball collision", 0.89, 0.91, &["cue", "2"]),
        ];
        let refs: Vec<&Annotation> = anns.iter().collect();
        let mut scores = BTreeMap::new();
        score_trace(POOLTOOL_GROUNDED, &truth, &refs, 0.05, &mut scores);
        let c = &scores["ball collision"];
        assert_eq!(
            (
                c.events,
                c.detections,
                c.true_positives,
                c.false_positives,
                c.false_negatives
            ),
            (2, 3, 1, 2, 1)
        );
        let s = &scores["cue strike"];
        assert_eq!((s.precision(), s.recall(), s.f1()), (1.0, 1.0, 1.0));
        assert!(
            markdown(&scores.values().cloned().collect::<Vec<_>>())
                .contains("| cue strike | 1 | 1 |")
        );
    }

    #[test]
    fn pooltool_truth_reads_balls_from_agents_by_kind_as_pooltool_records_them() {
        // pooltool itself records only `agents`; cushion "9" and ball "9" share an id.
        let mut trace = crate::testutil::synthetic_trace(Env::Pooltool, 0, 3, 1);
        let a = |kind: &str, t: f64, ids: &[&str]| ev(kind, t, json!({ "agents": ids }));
        trace.events = vec![
            a("physics_stick_ball", 0.0, &["cue_stick", "cue"]),
            a("physics_ball_linear_cushion", 0.3, &["1", "9"]),
            a("physics_ball_circular_cushion", 0.32, &["1", "9t"]), // same rebound
            a("physics_ball_pocket", 0.8, &["9", "rt"]),
            a("physics_sliding_rolling", 0.9, &["cue"]),
            a("physics_rolling_spinning", 1.0, &["2"]),
        ];
        let got: Vec<(&str, Vec<String>)> = pooltool_truth(&trace, 0.05)
            .into_iter()
            .map(|e| (e.label, e.balls))
            .collect();
        let v = |s: &str| vec![s.to_string()];
        assert_eq!(
            got,
            [
                ("cue strike", v("cue")),
                ("cushion rebound", v("1")),
                ("ball pocketed", v("9")),
                ("rolling ball", v("cue")),
                ("sliding ball", v("cue")),
                ("spinning ball", v("2")),
            ]
        );
        // annotrace's extra `ball` field only when agents are missing.
        assert_eq!(
            event_balls("physics_ball_pocket", Some(&json!({"ball": "3"}))),
            v("3")
        );
    }

    #[test]
    fn pooltool_state_truth_spin_from_the_shot_and_slowing_from_the_roll_time() {
        let mut trace = crate::testutil::synthetic_trace(Env::Pooltool, 0, 3, 1);
        let a = |kind: &str, t: f64, ids: &[&str]| ev(kind, t, json!({ "agents": ids }));
        trace.events = vec![
            a("physics_stick_ball", 0.0, &["cue_stick", "cue"]),
            a("physics_sliding_rolling", 0.2, &["cue"]),
            a("physics_rolling_stationary", 1.0, &["cue"]), // 0.8 s of roll: 0.078 m/s at its start
            a("physics_sliding_rolling", 0.3, &["1"]),
            a("physics_rolling_stationary", 0.6, &["1"]), // 0.3 s: 0.029 m/s, too slow
        ];
        trace
            .extra
            .insert("shot".into(), json!({"V0": 1.0, "a": 0.15, "b": -0.15}));
        let got: Vec<(&str, f64)> = pooltool_state_truth(&trace, 0.05)
            .iter()
            .map(|e| (e.label, e.t))
            .collect();
        assert_eq!(got, [("spin shot", 0.0), ("ball slowing", 1.0)]);
        // The strike's own offsets win over the top-level shot: a centre-ball hit.
        trace.events[0] = ev(
            "physics_stick_ball",
            0.0,
            json!({"agents": ["cue_stick", "cue"], "a": 0.0, "b": 0.1}),
        );
        assert!(
            pooltool_state_truth(&trace, 0.05)
                .iter()
                .all(|e| e.label != "spin shot")
        );
    }

    #[test]
    fn iphyre_truth_merges_chatter_after_an_end_and_keeps_effective_removals() {
        let mut trace = crate::testutil::synthetic_trace(Env::Iphyre, 0, 3, 1);
        let c = |kind: &str, t: f64| ev(kind, t, json!({"agents": ["3", "1"]}));
        trace.events = vec![
            c("contact_begin", 0.50),
            c("contact_end", 0.60),
            c("contact_begin", 0.64), // 40 ms after its end: the same collision
            c("contact_end", 0.90),
            c("contact_begin", 1.00), // 100 ms after: a new one
            ev(
                "action_applied",
                1.2,
                json!({"agents": ["4"], "eliminated_object": 4, "effective": true}),
            ),
            ev(
                "action_applied",
                1.5,
                json!({"agents": [], "eliminated_object": null, "effective": false}),
            ),
        ];
        let truth = iphyre_truth(&trace, 0.05);
        let got: Vec<(&str, f64, Vec<String>)> = truth
            .iter()
            .map(|e| (e.label, e.t, e.balls.clone()))
            .collect();
        let pair = vec!["1".to_string(), "3".to_string()];
        assert_eq!(
            got,
            [
                ("collision", 0.50, pair.clone()),
                ("collision", 1.00, pair),
                ("object removal", 1.2, vec!["4".to_string()]),
            ]
        );
        // The synthetic trace's 3 steps end at 0.02 s: no pattern could span these events.
        assert!(super::truth(Env::Iphyre, &trace, 0.05).is_empty());
        assert!(scorable(Env::Iphyre, &trace));
        trace.events.retain(|e| e.kind == "action_applied");
        assert!(
            scorable(Env::Iphyre, &trace),
            "no contact log, but every 60 Hz step: contacts from the frames"
        );
        for (k, s) in trace.timesteps.iter_mut().enumerate() {
            s.t = k as f64 * 0.1;
        }
        assert!(
            !scorable(Env::Iphyre, &trace),
            "no contact log, no simulator field, frames too sparse"
        );
        assert_eq!(grounded(Env::Iphyre), IPHYRE_GROUNDED);
    }
}
