//! I-PHYRE ground truth: collisions and object removals. Owns the label rules; the chatter merging
//! of logged contacts is `contacts.rs`. Not the scoring (`mod.rs`).
//!
//! * `collision` ↔ a merged `contact_begin` (annotrace's simulator logs every contact); for a trace
//!   without a contact log that holds every physics step (exported from iphyre itself), a contact
//!   begin found from the capsules of the frames (`geometry.rs`).
//! * `object removal` ↔ `action_applied` with `effective: true`; the removed block is
//!   `eliminated_object` (annotrace's simulator and the reference exporter of iphyre 0.2.3 both write it).

use super::TruthEvent;
use super::contacts::{has_contact_log, merged_contacts};
use super::geometry::iphyre_contacts;
use crate::trace::Trace;

/// The ground truth of an I-PHYRE trace: merged `contact_begin` events (collision) and effective
/// `action_applied` events (object removal).
pub fn iphyre_truth(trace: &Trace, merge_s: f64) -> Vec<TruthEvent> {
    let contacts = if has_contact_log(trace) {
        merged_contacts(trace, merge_s)
    } else {
        iphyre_contacts(trace, merge_s)
    };
    let mut out: Vec<TruthEvent> = contacts
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
