//! Accuracy of event-grounded labels: detections scored against the simulator's event log.
//!
//! For billiards the ground truth of a label is a kind of simulator event ([`pooltool_truth`]):
//! `cue strike` ↔ `physics_stick_ball`; `ball collision` ↔ `physics_ball_ball` with contacts of the same
//! pair closer than `merge_s` merged into one (pooltool resolves pressed balls as a burst of contacts);
//! `cushion rebound` ↔ `physics_ball_linear_cushion` / `physics_ball_circular_cushion`, merged per ball
//! the same way; `ball pocketed` ↔ `physics_ball_pocket`; `rolling ball` and `sliding ball` ↔
//! `physics_sliding_rolling` (a rolling episode starts and a sliding one ends there); `spinning ball` ↔
//! `physics_rolling_spinning`.
//!
//! For I-PHYRE ([`iphyre_truth`]): `collision` ↔ `contact_begin`, a pair's contact that begins again within
//! `merge_s` of its last `contact_end` being the same collision (rapier reports a ball skidding over a
//! block's joint, or resting on two blocks, as a chatter of end/begin pairs); `object removal` ↔
//! `action_applied` with `effective: true` (the click removed `eliminated_object`).
//!
//! For PHYRE ([`phyre_truth`]): `moving object hits stationary object` ↔ `contact_begin` (merged the
//! same way) of a pair of which, in the last frame before the contact, one body moves and the other is
//! at rest (speeds from the frames' recorded velocities: moving ≥ [`PHYRE_MOVING`], at rest ≤
//! [`PHYRE_AT_REST`] px/s, or a static body such as a wall). Both bodies are named.
//!
//! [`truth`] and [`grounded`] pick the mapping of an environment.
//!
//! A detection matches a truth event when it has the same label and trace, names every ball the event
//! involves among its objects, and its time span `[t_start − tolerance, t_end + tolerance]` holds the
//! event's time. Matching is one-to-one, greedy in time order, each event taking the matching detection
//! whose span holds its time (else is nearest to it), then whose span centre is closest. Unmatched
//! detections are false positives, unmatched events false negatives.

use std::collections::BTreeMap;

use serde::Serialize;

use super::annotation::Annotation;
use super::detector::normalise_label;
use crate::trace::{Env, Trace};

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

/// The event-grounded pooltool labels, in the paper's order.
pub const POOLTOOL_GROUNDED: &[&str] = &[
    "cue strike",
    "ball collision",
    "cushion rebound",
    "ball pocketed",
    "rolling ball",
    "sliding ball",
    "spinning ball",
];

/// The event-grounded I-PHYRE labels.
pub const IPHYRE_GROUNDED: &[&str] = &["collision", "object removal"];

/// The event-grounded PHYRE labels.
pub const PHYRE_GROUNDED: &[&str] = &["moving object hits stationary object"];

/// PHYRE: a body at least this fast (px/s) in the frame before a contact is moving.
pub const PHYRE_MOVING: f64 = 20.0;

/// PHYRE: a body at most this fast (px/s) in the frame before a contact is at rest.
pub const PHYRE_AT_REST: f64 = 5.0;

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
        Env::Pooltool => pooltool_truth(trace, merge_s),
        Env::Iphyre => iphyre_truth(trace, merge_s),
        Env::Phyre => phyre_truth(trace, merge_s),
    }
    .into_iter()
    .filter(|e| env == Env::Pooltool || e.t <= last + 1e-9)
    .collect()
}

/// Whether a trace's event log can ground its labels: a billiards trace with pooltool events; a PHYRE
/// or I-PHYRE trace with contact events or from annotrace's simulator (its `simulator` field), which
/// logs every contact. An imported trace without contact events (such as `data/examples/`) says
/// nothing about its contacts, so scoring it would count every contact a detector infers as false.
pub fn scorable(env: Env, trace: &Trace) -> bool {
    match env {
        Env::Pooltool => trace.events.iter().any(|e| e.kind.starts_with("physics_")),
        Env::Iphyre | Env::Phyre => {
            trace.extra.contains_key("simulator")
                || trace
                    .events
                    .iter()
                    .any(|e| e.kind == "contact_begin" || e.kind == "contact_end")
        }
    }
}

/// The merged contacts of a trace: `(t, pair)` of each `contact_begin` that does not follow the same
/// pair's last `contact_end` (or, without one, its last `contact_begin`) within `merge_s`.
fn merged_contacts(trace: &Trace, merge_s: f64) -> Vec<(f64, Vec<String>)> {
    let mut events: Vec<_> = trace
        .events
        .iter()
        .filter(|e| e.t.is_some() && (e.kind == "contact_begin" || e.kind == "contact_end"))
        .collect();
    // Stable: events of one time keep their order (an end before the begin that follows it).
    events.sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
    let mut last: BTreeMap<Vec<String>, f64> = BTreeMap::new();
    let mut out = Vec::new();
    for e in events {
        let t = e.t.unwrap_or(0.0);
        let Some(p) = pair(e.payload.as_ref()) else {
            continue;
        };
        if e.kind == "contact_end" {
            last.insert(p, t);
            continue;
        }
        let chatter = last.get(&p).is_some_and(|&l| t - l <= merge_s);
        last.insert(p.clone(), t);
        if !chatter {
            out.push((t, p));
        }
    }
    out
}

/// The ground truth of an I-PHYRE trace: merged `contact_begin` events (collision) and effective
/// `action_applied` events (object removal).
pub fn iphyre_truth(trace: &Trace, merge_s: f64) -> Vec<TruthEvent> {
    let mut out: Vec<TruthEvent> = merged_contacts(trace, merge_s)
        .into_iter()
        .map(|(t, balls)| TruthEvent {
            label: "collision",
            t,
            balls,
        })
        .collect();
    for e in &trace.events {
        let (Some(t), Some(p)) = (e.t, e.payload.as_ref()) else {
            continue;
        };
        if e.kind != "action_applied" || p.get("effective") != Some(&serde_json::Value::Bool(true))
        {
            continue;
        }
        let Some(obj) = p.get("eliminated_object") else {
            continue;
        };
        let id = obj
            .as_str()
            .map(str::to_string)
            .unwrap_or_else(|| obj.to_string());
        out.push(TruthEvent {
            label: "object removal",
            t,
            balls: vec![id],
        });
    }
    out.sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
    out
}

/// Speeds (px/s) of the PHYRE bodies in the last frame at or before `t`, by id.
fn phyre_speeds(trace: &Trace, t: f64) -> BTreeMap<String, f64> {
    let k = trace.timesteps.partition_point(|s| s.t <= t);
    let mut out = BTreeMap::new();
    if let Some(step) = trace.timesteps.get(k.saturating_sub(1)) {
        for o in &step.objects {
            if let crate::trace::Body::Phyre(p) = &o.body {
                out.insert(p.object_index.to_string(), p.vx.hypot(p.vy));
            }
        }
    }
    out
}

/// The ground truth of a PHYRE trace: merged `contact_begin` events where one body moves and the other
/// is at rest in the frame before the contact.
pub fn phyre_truth(trace: &Trace, merge_s: f64) -> Vec<TruthEvent> {
    merged_contacts(trace, merge_s)
        .into_iter()
        .filter_map(|(t, balls)| {
            // The frame strictly before the contact step (the contact frame already shows the impact).
            let speeds = phyre_speeds(trace, t - 1e-9);
            let v: Vec<f64> = balls
                .iter()
                .map(|b| speeds.get(b).copied().unwrap_or(0.0))
                .collect();
            let (lo, hi) = (v[0].min(v[1]), v[0].max(v[1]));
            (hi >= PHYRE_MOVING && lo <= PHYRE_AT_REST).then_some(TruthEvent {
                label: "moving object hits stationary object",
                t,
                balls,
            })
        })
        .collect()
}

fn payload_ball(p: Option<&serde_json::Value>) -> Option<String> {
    p.and_then(|p| p.get("ball")).map(|b| match b {
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    })
}

fn pair(p: Option<&serde_json::Value>) -> Option<Vec<String>> {
    let agents = p?.get("agents")?.as_array()?;
    let mut v: Vec<String> = agents
        .iter()
        .take(2)
        .map(|a| {
            a.as_str()
                .map(str::to_string)
                .unwrap_or_else(|| a.to_string())
        })
        .collect();
    if v.len() != 2 {
        return None;
    }
    v.sort();
    Some(v)
}

/// The ground truth of a billiards trace, from its event log.
pub fn pooltool_truth(trace: &Trace, merge_s: f64) -> Vec<TruthEvent> {
    let mut out = Vec::new();
    // Merge bursts: key -> index in `out` of the open group, and the time of its last contact.
    let mut open: BTreeMap<(&'static str, Vec<String>), (usize, f64)> = BTreeMap::new();
    let mut events: Vec<_> = trace.events.iter().filter(|e| e.t.is_some()).collect();
    events.sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
    for e in events {
        let t = e.t.unwrap_or(0.0);
        let p = e.payload.as_ref();
        let (labels, balls, merge): (&[&'static str], Vec<String>, bool) = match e.kind.as_str() {
            "physics_stick_ball" => (
                &["cue strike"],
                payload_ball(p).into_iter().collect(),
                false,
            ),
            "physics_ball_ball" => match pair(p) {
                Some(v) => (&["ball collision"], v, true),
                None => continue,
            },
            "physics_ball_linear_cushion" | "physics_ball_circular_cushion" => (
                &["cushion rebound"],
                payload_ball(p).into_iter().collect(),
                true,
            ),
            "physics_ball_pocket" => (
                &["ball pocketed"],
                payload_ball(p).into_iter().collect(),
                false,
            ),
            "physics_sliding_rolling" => (
                &["rolling ball", "sliding ball"],
                payload_ball(p).into_iter().collect(),
                false,
            ),
            "physics_rolling_spinning" => (
                &["spinning ball"],
                payload_ball(p).into_iter().collect(),
                false,
            ),
            _ => continue,
        };
        for &label in labels {
            if merge {
                let key = (label, balls.clone());
                if let Some((_, last)) = open.get_mut(&key)
                    && t - *last <= merge_s
                {
                    *last = t;
                    continue;
                }
                open.insert(key, (out.len(), t));
            }
            out.push(TruthEvent {
                label,
                t,
                balls: balls.clone(),
            });
        }
    }
    out
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
    let mut used = vec![false; annotations.len()];
    for ev in truth {
        let s = scores.get_mut(ev.label).expect("inserted above");
        s.events += 1;
        let want = normalise_label(ev.label);
        let best = annotations
            .iter()
            .enumerate()
            .filter(|(i, a)| {
                !used[*i]
                    && labels[*i] == want
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
            None => s.false_negatives += 1,
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
        }
    }
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

#[cfg(test)]
mod tests {
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
            !scorable(Env::Iphyre, &trace),
            "no contact log, no simulator field"
        );
        assert_eq!(grounded(Env::Iphyre), IPHYRE_GROUNDED);
    }
}
