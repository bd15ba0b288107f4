//! PHYRE ground truth: "moving object hits stationary object". Owns the label rule; the chatter
//! merging of logged contacts is `contacts.rs`, contacts from exact outlines for traces without a
//! contact log `geometry.rs`. Not the scoring (`mod.rs`).

use std::collections::BTreeMap;

use super::TruthEvent;
use super::contacts::{has_contact_log, merged_contacts};
use super::geometry::phyre_contacts;
use crate::trace::Trace;

/// PHYRE: a body at least this fast (px/s) in the frame before a contact is moving.
pub const PHYRE_MOVING: f64 = 20.0;

/// PHYRE: a body at most this fast (px/s) in the frame before a contact is at rest.
pub const PHYRE_AT_REST: f64 = 5.0;

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
    let contacts = if has_contact_log(trace) {
        merged_contacts(trace, merge_s)
    } else {
        phyre_contacts(trace, merge_s)
    };
    contacts
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
