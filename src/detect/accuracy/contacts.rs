//! Contacts from a PHYRE or I-PHYRE event log: `contact_begin` / `contact_end` pairs merged into
//! collisions. Owns the chatter rule (a pair's contact that begins again within `merge_s` of its end is
//! the same collision); not the labels built on it (`iphyre.rs`, `phyre.rs`) nor contacts from geometry
//! (`geometry.rs`).

use std::collections::BTreeMap;

use crate::trace::Trace;

/// Whether the trace logs its contacts (`contact_begin` / `contact_end`).
pub fn has_contact_log(trace: &Trace) -> bool {
    trace
        .events
        .iter()
        .any(|e| e.kind == "contact_begin" || e.kind == "contact_end")
}

/// A trace's timed `contact_begin` and `contact_end` events in time order; events of one time keep
/// their order (stable sort: an end before the begin that follows it).
pub(super) fn contact_events(trace: &Trace) -> Vec<&crate::trace::Event> {
    let mut events: Vec<_> = trace
        .events
        .iter()
        .filter(|e| e.t.is_some() && (e.kind == "contact_begin" || e.kind == "contact_end"))
        .collect();
    events.sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
    events
}

/// The merged contacts of a trace: `(t, pair)` of each `contact_begin` that does not follow the same
/// pair's last `contact_end` (or, without one, its last `contact_begin`) within `merge_s`.
pub fn merged_contacts(trace: &Trace, merge_s: f64) -> Vec<(f64, Vec<String>)> {
    let events = contact_events(trace);
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

/// The two ids of `payload.agents`, sorted.
pub fn pair(p: Option<&serde_json::Value>) -> Option<Vec<String>> {
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
