//! Billiards ground truth from pooltool's event log. Owns the mapping of event kinds to labels and
//! pooltool's id conventions for `payload.agents`; not the scoring (`mod.rs`).
//!
//! The balls of an event come from `payload.agents`, the one field pooltool itself records, read by
//! the position pooltool gives each id for the event's kind — never by what an id looks like (cushion
//! segments are named `"1"` … `"18"`, like balls): `stick_ball` (cue stick, ball), `ball_ball` (ball,
//! ball), `ball_linear_cushion` / `ball_circular_cushion` (ball, cushion or jaw `"1t"` …),
//! `ball_pocket` (ball, pocket `lb` … `rt`), motion transitions (ball). annotrace's extra `ball` field
//! is read only when `agents` is missing.

use std::collections::BTreeMap;

use super::TruthEvent;
use super::contacts::pair;

/// The ball ids a pooltool event of `kind` involves, by pooltool's id conventions (module doc).
pub fn event_balls(kind: &str, p: Option<&serde_json::Value>) -> Vec<String> {
    let agents: Vec<String> = p
        .and_then(|p| p.get("agents"))
        .and_then(|a| a.as_array())
        .map(|a| a.iter().map(id_string).collect())
        .unwrap_or_default();
    let balls: Vec<String> = match kind {
        "physics_stick_ball" => agents
            .get(1)
            .or(agents.first())
            .cloned()
            .into_iter()
            .collect(),
        "physics_ball_ball" => agents.into_iter().take(2).collect(),
        _ => agents.into_iter().take(1).collect(),
    };
    if !balls.is_empty() {
        return balls;
    }
    p.and_then(|p| p.get("ball"))
        .map(id_string)
        .into_iter()
        .collect()
}

fn id_string(v: &serde_json::Value) -> String {
    v.as_str()
        .map(str::to_string)
        .unwrap_or_else(|| v.to_string())
}

/// The ground truth of a billiards trace, from its event log.
///
/// `cue strike` ↔ `physics_stick_ball`; `ball collision` ↔ `physics_ball_ball`, contacts of the same
/// pair closer than `merge_s` merged into one; `cushion rebound` ↔ `physics_ball_linear_cushion` /
/// `physics_ball_circular_cushion`, merged per ball the same way; `ball pocketed` ↔
/// `physics_ball_pocket`; `rolling ball` and `sliding ball` ↔ `physics_sliding_rolling`; `spinning
/// ball` ↔ `physics_rolling_spinning`.
pub fn pooltool_truth(trace: &crate::trace::Trace, merge_s: f64) -> Vec<TruthEvent> {
    let mut out = Vec::new();
    // Merge bursts: key -> index in `out` of the open group, and the time of its last contact.
    let mut open: BTreeMap<(&'static str, Vec<String>), (usize, f64)> = BTreeMap::new();
    let mut events: Vec<_> = trace.events.iter().filter(|e| e.t.is_some()).collect();
    events.sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
    for e in events {
        let t = e.t.unwrap_or(0.0);
        let p = e.payload.as_ref();
        let kind = e.kind.as_str();
        let (labels, merge): (&[&'static str], bool) = match kind {
            "physics_stick_ball" => (&["cue strike"], false),
            "physics_ball_ball" => (&["ball collision"], true),
            "physics_ball_linear_cushion" | "physics_ball_circular_cushion" => {
                (&["cushion rebound"], true)
            }
            "physics_ball_pocket" => (&["ball pocketed"], false),
            "physics_sliding_rolling" => (&["rolling ball", "sliding ball"], false),
            "physics_rolling_spinning" => (&["spinning ball"], false),
            _ => continue,
        };
        let balls = if kind == "physics_ball_ball" {
            match pair(p) {
                Some(v) => v,
                None => continue,
            }
        } else {
            event_balls(kind, p)
        };
        if balls.is_empty() {
            continue;
        }
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
