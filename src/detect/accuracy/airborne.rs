//! "airborne motion" ground truth for PHYRE and I-PHYRE: a free body's flight between contacts. Owns
//! the flight rule; the per-object contact intervals (from the contact log, or from the frames'
//! touching pairs for traces that log none) are `kin.rs`; not the scoring (`mod.rs`).
//!
//! A flight is a maximal run of frames in which a free dynamic body (I-PHYRE: not held by a joint or a
//! spring, centre on screen; PHYRE: a dynamic body of the task or the user's ball) is in no contact,
//! lasting at least [`MIN_FLIGHT_S`] (I-PHYRE 0.15 s, PHYRE 0.2 s) at a mean speed of at least
//! [`MIN_FLIGHT_SPEED`] (path length over duration, from the positions). Its truth time is the middle of
//! the run, so a detection matches it whatever frame it takes as the flight's first or last.

use std::collections::BTreeMap;

use super::TruthEvent;
use super::geometry::phyre_dynamic;
use super::kin::{episodes, intervals};
use crate::trace::{Body, Env, Trace};

/// Shortest flight (s) per environment: I-PHYRE, PHYRE.
pub const MIN_FLIGHT_S: (f64, f64) = (0.15, 0.2);

/// Slowest mean speed (px/s) of a flight.
pub const MIN_FLIGHT_SPEED: f64 = 10.0;

/// I-PHYRE's screen side (px).
const SCREEN: f64 = 600.0;

/// Per frame: (t, centre, free) of each object, by id.
type Track = Vec<(f64, [f64; 2], bool)>;

fn tracks(env: Env, trace: &Trace) -> BTreeMap<String, Track> {
    let dynamic = if env == Env::Phyre {
        phyre_dynamic(trace).unwrap_or_default()
    } else {
        BTreeMap::new()
    };
    let mut out: BTreeMap<String, Track> = BTreeMap::new();
    for s in &trace.timesteps {
        for o in &s.objects {
            let (id, c, free) = match &o.body {
                Body::Iphyre(b) => {
                    let c = [(b.x1 + b.x2) / 2.0, (b.y1 + b.y2) / 2.0];
                    let on_screen = (-b.radius..=SCREEN + b.radius).contains(&c[0])
                        && (-b.radius..=SCREEN + b.radius).contains(&c[1]);
                    let free = b.dynamic != 0.0 && b.joint == 0 && b.spring == 0 && on_screen;
                    (b.index.to_string(), c, free)
                }
                Body::Phyre(p) => {
                    let id = p.object_index.to_string();
                    let free = dynamic.get(&id).copied().unwrap_or(false);
                    (id, [p.x, p.y], free)
                }
                Body::Pool(_) => continue,
            };
            out.entry(id).or_default().push((s.t, c, free));
        }
    }
    out
}

/// The airborne flights of a PHYRE or I-PHYRE trace (module doc).
pub fn airborne_truth(env: Env, trace: &Trace, merge_s: f64) -> Vec<TruthEvent> {
    let min_s = if env == Env::Iphyre {
        MIN_FLIGHT_S.0
    } else {
        MIN_FLIGHT_S.1
    };
    let contacts = intervals(&episodes(env, trace, merge_s));
    let mut out = Vec::new();
    for (id, track) in tracks(env, trace) {
        let mine = contacts.get(&id).map(Vec::as_slice).unwrap_or_default();
        let in_contact = |t: f64| mine.iter().any(|&(a, b)| a - 1e-9 <= t && t <= b + 1e-9);
        let mut run: Vec<(f64, [f64; 2])> = Vec::new();
        let mut flush = |run: &mut Vec<(f64, [f64; 2])>| {
            if let (Some(first), Some(last)) = (run.first(), run.last()) {
                let duration = last.0 - first.0;
                let path: f64 = run
                    .windows(2)
                    .map(|w| (w[1].1[0] - w[0].1[0]).hypot(w[1].1[1] - w[0].1[1]))
                    .sum();
                if duration >= min_s - 1e-9 && path >= MIN_FLIGHT_SPEED * duration {
                    out.push(TruthEvent {
                        label: "airborne motion",
                        t: (first.0 + last.0) / 2.0,
                        balls: vec![id.clone()],
                    });
                }
            }
            run.clear();
        };
        for &(t, c, free) in &track {
            if free && !in_contact(t) {
                run.push((t, c));
            } else {
                flush(&mut run);
            }
        }
        flush(&mut run);
    }
    out
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;
    use crate::trace::{Event, JsonMap};

    /// One capsule dropping as y = 50 t² (px, y down), frames 10 ms apart for 0.6 s.
    fn drop_trace() -> Trace {
        let mut trace = crate::testutil::synthetic_trace(Env::Iphyre, 0, 61, 1);
        for s in &mut trace.timesteps {
            if let Body::Iphyre(b) = &mut s.objects[0].body {
                b.y1 = 100.0 + 50.0 * s.t * s.t;
                b.y2 = b.y1;
            }
        }
        trace.events.clear();
        trace
    }

    #[test]
    fn a_flight_ends_at_its_logged_contact_and_is_timed_at_its_middle() {
        let mut trace = drop_trace();
        trace.events.push(Event {
            kind: "contact_begin".into(),
            t: Some(0.3),
            payload: Some(json!({"agents": ["0", "9"]})),
            extra: JsonMap::new(),
        });
        let got = airborne_truth(Env::Iphyre, &trace, 0.05);
        assert_eq!(got.len(), 1, "{got:?}");
        assert!((got[0].t - 0.145).abs() < 1e-9, "{got:?}");
        assert_eq!(got[0].balls, ["0"]);
        // No log, nothing to touch in the frames: the whole drop is one flight.
        let got = airborne_truth(Env::Iphyre, &drop_trace(), 0.05);
        assert_eq!(got.len(), 1);
        assert!((got[0].t - 0.3).abs() < 1e-9, "{got:?}");
        // Held by a joint: never free.
        let mut held = drop_trace();
        for s in &mut held.timesteps {
            if let Body::Iphyre(b) = &mut s.objects[0].body {
                b.joint = 1;
            }
        }
        assert!(airborne_truth(Env::Iphyre, &held, 0.05).is_empty());
    }
}
