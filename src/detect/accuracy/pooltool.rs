//! Billiards ground truth from pooltool's event log (and, for spin shot, high angle collision, gentle
//! touch and ball curves around ball, the states and pooltool's motion laws). Owns the mapping of event
//! kinds to labels and pooltool's id conventions for `payload.agents`; not the scoring (`mod.rs`).
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

/// pooltool's default rolling-friction coefficient `u_r` (annotrace's default table uses it too).
pub const ROLLING_FRICTION: f64 = 0.01;

/// Standard gravity (m/s²), as pooltool's `g`.
const G: f64 = 9.8;

/// pooltool's default sliding-friction coefficient `u_s`.
pub const SLIDING_FRICTION: f64 = 0.2;

/// pooltool's gravity in its ball parameters (m/s²), which its sliding motion uses.
const G_POOLTOOL: f64 = 9.81;

/// "ball curves around ball": least heading turn over a slide (degrees), how close (in ball radii,
/// centre to centre) another ball must come, and the shortest slide (s): a path, not the few
/// milliseconds between two contacts of a ball in a cluster (the 50 ms every rule here merges within).
pub const CURVE: (f64, f64, f64) = (8.0, 4.0, 0.05);

/// "ball slowing": a rolling ball coming to rest, if it rolled at least this fast (m/s) when its roll
/// began.
pub const SLOWING_MIN_SPEED: f64 = 0.05;

/// "spin shot": a tip offset at least this far from the cue ball's centre (units of R).
pub const SPIN_MIN_OFFSET: f64 = 0.2;

/// "gentle touch": a collision approached slower than this (m/s, along the line of centres).
pub const GENTLE_MAX_SPEED: f64 = 0.3;

/// "high angle collision": a cut angle (between the relative velocity and the line of centres) in
/// this range (degrees).
pub const HIGH_ANGLE_DEG: (f64, f64) = (45.0, 90.0);

fn num(v: Option<&serde_json::Value>, key: &str) -> Option<f64> {
    v?.get(key)?.as_f64()
}

/// The (position, velocity) of ball `id` at time `t`, moved straight on from the last frame at or
/// before `t` (frames are 10 ms apart or less; a contact's own frame already shows its outcome).
fn state_at(trace: &crate::trace::Trace, id: &str, t: f64) -> Option<([f64; 2], [f64; 2])> {
    let k = trace
        .timesteps
        .partition_point(|s| s.t < t)
        .checked_sub(1)?;
    let step = &trace.timesteps[k];
    step.objects.iter().find_map(|o| match &o.body {
        crate::trace::Body::Pool(b) if b.ball_id == id => {
            let dt = t - step.t;
            Some((
                [
                    b.position[0] + b.velocity[0] * dt,
                    b.position[1] + b.velocity[1] * dt,
                ],
                [b.velocity[0], b.velocity[1]],
            ))
        }
        _ => None,
    })
}

/// The labels pooltool's events ground through the simulator's inputs and state rather than one event
/// kind each (rules in `docs/accuracy.md`):
///
/// * `spin shot` ↔ a `physics_stick_ball` whose tip offset `hypot(a, b)` is at least
///   `SPIN_MIN_OFFSET`; the offsets come from the strike's payload (annotrace) or the trace's top-level
///   `shot` (pooltool exporters); without either the strike grounds nothing.
/// * `ball slowing` ↔ a `physics_rolling_stationary` that ends a roll begun by the same ball's
///   `physics_sliding_rolling` with nothing in between, when the roll lasted long enough to have started
///   at `SLOWING_MIN_SPEED` or more: rolling friction decelerates at `u_r g`, so the start speed is
///   `u_r g (t_stop − t_roll)` — event times only, no frame.
/// * `gentle touch` and `high angle collision` ↔ a merged `ball collision` (as in [`pooltool_truth`])
///   whose approach speed along the line of centres is below `GENTLE_MAX_SPEED`, or whose cut angle is
///   in `HIGH_ANGLE_DEG`; both from the two balls' states moved on to the first contact's time (the
///   approach speed from the first contact's event when it records one, as annotrace's simulator does).
pub fn pooltool_state_truth(trace: &crate::trace::Trace, merge_s: f64) -> Vec<TruthEvent> {
    let mut out = Vec::new();
    let shot = trace.extra.get("shot");
    let mut events: Vec<_> = trace.events.iter().filter(|e| e.t.is_some()).collect();
    events.sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
    // The open roll of each ball: the time of its sliding->rolling transition.
    let mut rolling: BTreeMap<String, f64> = BTreeMap::new();
    for e in &events {
        let t = e.t.unwrap_or(0.0);
        let p = e.payload.as_ref();
        let balls = event_balls(&e.kind, p);
        if e.kind == "physics_stick_ball" {
            let (a, b) = match (num(p, "a"), num(p, "b")) {
                (Some(a), Some(b)) => (Some(a), Some(b)),
                _ => (num(shot, "a"), num(shot, "b")),
            };
            if let (Some(a), Some(b)) = (a, b)
                && a.hypot(b) >= SPIN_MIN_OFFSET
            {
                out.push(TruthEvent {
                    label: "spin shot",
                    t,
                    balls: balls.clone(),
                });
            }
        }
        if !e.kind.starts_with("physics_") {
            continue;
        }
        for b in &balls {
            let start = rolling.remove(b);
            if e.kind == "physics_rolling_stationary"
                && let Some(t0) = start
                && ROLLING_FRICTION * G * (t - t0) >= SLOWING_MIN_SPEED
            {
                out.push(TruthEvent {
                    label: "ball slowing",
                    t,
                    balls: vec![b.clone()],
                });
            }
        }
        if e.kind == "physics_sliding_rolling"
            && let Some(b) = balls.first()
        {
            rolling.insert(b.clone(), t);
        }
    }
    for c in pooltool_truth(trace, merge_s)
        .into_iter()
        .filter(|c| c.label == "ball collision")
    {
        let (Some((pa, va)), Some((pb, vb))) = (
            state_at(trace, &c.balls[0], c.t),
            state_at(trace, &c.balls[1], c.t),
        ) else {
            continue;
        };
        let n = [pb[0] - pa[0], pb[1] - pa[1]];
        let nn = n[0].hypot(n[1]);
        let v = [va[0] - vb[0], va[1] - vb[1]];
        let vn = v[0].hypot(v[1]);
        if nn <= 0.0 {
            continue;
        }
        let approach = (v[0] * n[0] + v[1] * n[1]) / nn;
        // The simulator's own approach speed at the first contact when its event records one.
        let logged = trace
            .events
            .iter()
            .find(|e| e.kind == "physics_ball_ball" && e.t == Some(c.t))
            .and_then(|e| num(e.payload.as_ref(), "approach_speed"));
        if logged.unwrap_or(approach).abs() < GENTLE_MAX_SPEED {
            out.push(TruthEvent {
                label: "gentle touch",
                t: c.t,
                balls: c.balls.clone(),
            });
        }
        if vn > 1e-6 {
            let cut = (approach / vn).clamp(-1.0, 1.0).acos().to_degrees();
            if (HIGH_ANGLE_DEG.0..HIGH_ANGLE_DEG.1).contains(&cut) {
                out.push(TruthEvent {
                    label: "high angle collision",
                    t: c.t,
                    balls: c.balls,
                });
            }
        }
    }
    curves(trace, &events, &mut out);
    out.sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
    out
}

/// One ball in one frame: (t, position, velocity, angular velocity, motion state, radius).
type PoolState<'a> = (f64, [f64; 2], [f64; 2], [f64; 3], &'a str, f64);

/// "ball curves around ball" (rule in `docs/accuracy.md`): a ball's slide between two of its events —
/// sliding in the first frame after the first — whose heading, by pooltool's sliding motion (the
/// velocity changes at `u_s g` against the constant direction of the cloth contact point's velocity
/// `v + R ẑ × ω`), turns by more than `CURVE.0` degrees from the first event to the next (or to the
/// slide's end, at least `CURVE.2` s after the first), while another ball its pair never collides with
/// comes within `CURVE.1` radii.
/// Timed at the middle of the two events; names the curving ball and the closest such ball.
fn curves(trace: &crate::trace::Trace, events: &[&crate::trace::Event], out: &mut Vec<TruthEvent>) {
    let (min_turn, radii, min_slide) = CURVE;
    let mut states: BTreeMap<&str, Vec<PoolState>> = BTreeMap::new();
    for s in &trace.timesteps {
        for o in &s.objects {
            if let crate::trace::Body::Pool(b) = &o.body {
                states.entry(b.ball_id.as_str()).or_default().push((
                    s.t,
                    [b.position[0], b.position[1]],
                    [b.velocity[0], b.velocity[1]],
                    b.angular_velocity,
                    b.motion_state.as_str(),
                    b.radius,
                ));
            }
        }
    }
    let mut times: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    let mut collided: std::collections::BTreeSet<Vec<String>> = Default::default();
    for e in events.iter().filter(|e| e.kind.starts_with("physics_")) {
        let balls = event_balls(&e.kind, e.payload.as_ref());
        if e.kind == "physics_ball_ball"
            && let Some(p) = pair(e.payload.as_ref())
        {
            collided.insert(p);
        }
        for b in balls {
            times.entry(b).or_default().push(e.t.unwrap_or(0.0));
        }
    }
    let last = trace.timesteps.last().map_or(0.0, |s| s.t);
    for (id, ts) in &times {
        let Some(mine) = states.get(id.as_str()) else {
            continue;
        };
        let ends = ts.iter().skip(1).copied().chain([last]);
        for (t0, t1) in ts.iter().copied().zip(ends) {
            if t1 <= t0 {
                continue;
            }
            // The first frame after the event: the state the slide starts from.
            let Some(&(ta, _, va, w, state, r)) = mine.iter().find(|x| x.0 > t0 + 1e-12) else {
                continue;
            };
            if state != "sliding" || ta >= t1 {
                continue;
            }
            let u = [va[0] - r * w[1], va[1] + r * w[0]];
            let un = u[0].hypot(u[1]);
            if un <= 1e-9 {
                continue;
            }
            let (ux, uy) = (u[0] / un, u[1] / un);
            let decel = SLIDING_FRICTION * G_POOLTOOL;
            let slide_end = ta + 2.0 * un / (7.0 * decel);
            let at = |t: f64| {
                let dt = t.min(slide_end) - ta;
                [va[0] - decel * dt * ux, va[1] - decel * dt * uy]
            };
            if t1.min(slide_end) - t0 < min_slide - 1e-9 {
                continue;
            }
            let (v0, v1) = (at(t0), at(t1));
            let (n0, n1) = (v0[0].hypot(v0[1]), v1[0].hypot(v1[1]));
            if n0 <= 1e-6 || n1 <= 1e-6 {
                continue;
            }
            let cos = ((v0[0] * v1[0] + v0[1] * v1[1]) / (n0 * n1)).clamp(-1.0, 1.0);
            if cos.acos().to_degrees() <= min_turn {
                continue;
            }
            let mut best: Option<(f64, &str)> = None;
            for (other, theirs) in &states {
                if *other == id.as_str() {
                    continue;
                }
                let mut key = vec![id.clone(), other.to_string()];
                key.sort();
                if collided.contains(&key) {
                    continue;
                }
                for p in mine
                    .iter()
                    .filter(|p| (ta - 1e-12..=t1 + 1e-12).contains(&p.0))
                {
                    let i = theirs.partition_point(|q| q.0 < p.0 - 1e-12);
                    let Some(q) = theirs.get(i).filter(|q| (q.0 - p.0).abs() <= 1e-12) else {
                        continue;
                    };
                    if q.4 == "pocketed" {
                        continue;
                    }
                    let d = (p.1[0] - q.1[0]).hypot(p.1[1] - q.1[1]);
                    if d < radii * r && best.is_none_or(|(bd, _)| d < bd) {
                        best = Some((d, *other));
                    }
                }
            }
            if let Some((_, other)) = best {
                out.push(TruthEvent {
                    label: "ball curves around ball",
                    t: (t0 + t1) / 2.0,
                    balls: vec![id.clone(), other.to_string()],
                });
            }
        }
    }
}
