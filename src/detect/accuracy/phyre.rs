//! PHYRE ground truth: "moving object hits stationary object". Owns the label rule; the chatter
//! merging of logged contacts is `contacts.rs`, contacts from exact outlines for traces without a
//! contact log `geometry.rs`. Not the scoring (`mod.rs`).

use std::collections::BTreeMap;

use super::TruthEvent;
use super::contacts::{has_contact_log, merged_contacts};
use super::geometry::phyre_contacts;
use crate::trace::Trace;

/// PHYRE: a body whose mean speed (px/s) over [`PHYRE_WINDOW_S`] before a contact is at least this
/// moves.
pub const PHYRE_MOVING: f64 = 20.0;

/// PHYRE: a body whose mean speed (px/s) over [`PHYRE_WINDOW_S`] before a contact is at most this is
/// at rest.
pub const PHYRE_AT_REST: f64 = 5.0;

/// PHYRE: the window (s) before the last frame ahead of a contact over which a body's mean speed is
/// measured, from its positions.
pub const PHYRE_WINDOW_S: f64 = 0.1;

/// Mean speeds (px/s) of the PHYRE bodies from their displacement between the last frame strictly
/// before `t` and the frame [`PHYRE_WINDOW_S`] before that (or the trace's first frame), by id. Not the
/// velocity fields the detectors read: positions only. Implicit walls (absent) count as at rest.
fn phyre_mean_speeds(trace: &Trace, t: f64) -> BTreeMap<String, f64> {
    let steps = &trace.timesteps;
    let k = steps.partition_point(|s| s.t < t).saturating_sub(1);
    let mut out = BTreeMap::new();
    let Some(last) = steps.get(k) else {
        return out;
    };
    let j = steps.partition_point(|s| s.t <= last.t - PHYRE_WINDOW_S + 1e-9);
    let first = &steps[j.saturating_sub(1).min(k)];
    let dt = last.t - first.t;
    let pos = |s: &crate::trace::Timestep| -> BTreeMap<String, [f64; 2]> {
        s.objects
            .iter()
            .filter_map(|o| match &o.body {
                crate::trace::Body::Phyre(p) => Some((p.object_index.to_string(), [p.x, p.y])),
                _ => None,
            })
            .collect()
    };
    let (a, b) = (pos(first), pos(last));
    for (id, q) in b {
        let speed = match a.get(&id) {
            Some(p) if dt > 0.0 => (q[0] - p[0]).hypot(q[1] - p[1]) / dt,
            _ => 0.0,
        };
        out.insert(id, speed);
    }
    out
}

/// The ground truth of a PHYRE trace: merged contacts where one body moves and the other is at rest,
/// by their mean speeds from positions over the window before the contact.
pub fn phyre_truth(trace: &Trace, merge_s: f64) -> Vec<TruthEvent> {
    let contacts = if has_contact_log(trace) {
        merged_contacts(trace, merge_s)
    } else {
        phyre_contacts(trace, merge_s)
    };
    contacts
        .into_iter()
        .filter_map(|(t, balls)| {
            // Up to the frame strictly before the contact (the contact frame already shows the impact).
            let speeds = phyre_mean_speeds(trace, t);
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
