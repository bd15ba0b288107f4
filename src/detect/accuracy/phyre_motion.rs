//! PHYRE ground truth for the motion labels: falling object, grid cell transition, tip over, bounce,
//! support relationship, lose support, rolling object, sliding contact, near collision and wedged (its
//! pushes from the exact outlines of `geometry.rs`). Owns these rules (stated in `docs/accuracy.md`, thresholds below); the tracks and contact episodes they read are
//! `kin.rs`. Not the scoring (`mod.rs`), not the hit (`phyre.rs`) nor airborne motion (`airborne.rs`).
//!
//! Each rule reads the simulator's state (positions, velocities, angles, angular velocities; which
//! bodies are dynamic from the task) and its contacts (the contact log, or for logless 60 Hz traces the
//! exact outlines' touching frames). An episode label is timed at its run's middle, an instant label at
//! its instant. Scene y grows upwards.

use std::collections::BTreeMap;

use super::TruthEvent;
use super::geometry::phyre_outlines;
use super::kin::{Episode, P, Track, dot, episodes, frame_at, intervals, norm, runs, sub, tracks};
use crate::trace::{Env, Trace};

/// falling object: downward speed (px/s), shortest fall (s), least drop (px).
pub const FALL: (f64, f64, f64) = (30.0, 0.2, 10.0);
/// grid cell transition: the action grid's cell side (px) and cells per side.
pub const CELL: (f64, i64) = (32.0, 8);
/// tip over: turning rate (rad/s), shortest turn (s), least net turn (rad).
pub const TIP: (f64, f64, f64) = (0.5, 0.2, 0.7);
/// bounce: vertical speed into the contact (px/s), reversed vertical speed after (px/s), window (s).
pub const BOUNCE: (f64, f64, f64) = (20.0, 10.0, 0.2);
/// support relationship: resting speed (px/s), shortest rest (s).
pub const SUPPORT: (f64, f64) = (5.0, 0.5);
/// lose support: resting speed (px/s), shortest rest (s), falling speed (px/s), window after (s).
pub const LOSE: (f64, f64, f64, f64) = (5.0, 0.3, 20.0, 1.0);
/// rolling object / sliding contact: moving speed (px/s), rolling tolerance (fraction of the speed),
/// shortest roll (s), shortest slide (s).
pub const ROLL: (f64, f64, f64, f64) = (10.0, 0.25, 0.3, 0.2);
/// near collision: moving speed (px/s), largest gap (px), smallest gap (px), contact-free margin (s).
pub const NEAR: (f64, f64, f64, f64) = (20.0, 8.0, 1.5, 0.2);
/// wedged: resting speed (px/s), resting spin (rad/s), shortest wedge (s), cosine of the least angle
/// between two pushes (120°), least horizontal part of each push's direction.
pub const WEDGED: (f64, f64, f64, f64, f64) = (2.0, 0.1, 0.5, -0.5, 0.3);

fn event(label: &'static str, t: f64, ids: &[&String]) -> TruthEvent {
    let mut balls: Vec<String> = ids.iter().map(|s| s.to_string()).collect();
    balls.sort();
    balls.dedup();
    TruthEvent { label, t, balls }
}

/// The motion ground truth of a PHYRE trace (module doc).
pub fn phyre_motion_truth(trace: &Trace, merge_s: f64) -> Vec<TruthEvent> {
    let tr = tracks(Env::Phyre, trace);
    let eps = episodes(Env::Phyre, trace, merge_s);
    let touching = intervals(&eps);
    let mut out = Vec::new();
    for (id, track) in &tr {
        if !track.dynamic {
            continue;
        }
        let mine = touching.get(id).map(Vec::as_slice).unwrap_or_default();
        per_body(id, track, mine, merge_s, &mut out);
    }
    for (p, list) in &eps {
        let (Some(x), Some(y)) = (tr.get(&p[0]), tr.get(&p[1])) else {
            continue;
        };
        for ep in list {
            bounce(trace, p, ep, x, y, &mut out);
            support(trace, p, ep, x, y, merge_s, &mut out);
        }
    }
    near(&tr, &eps, merge_s, &mut out);
    wedged(trace, &tr, &eps, merge_s, &mut out);
    out.sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
    out
}

fn per_body(
    id: &String,
    tr: &Track,
    touching: &[(f64, f64)],
    merge_s: f64,
    out: &mut Vec<TruthEvent>,
) {
    let s = &tr.samples;
    let times: Vec<f64> = s.iter().map(|x| x.t).collect();
    // falling object
    let (v_fall, min_fall, drop) = FALL;
    let flags: Vec<bool> = s.iter().map(|x| x.v[1] <= -v_fall).collect();
    for (i, j) in runs(&times, &flags, merge_s, min_fall) {
        if s[i].c[1] - s[j].c[1] >= drop {
            out.push(event("falling object", (times[i] + times[j]) / 2.0, &[id]));
        }
    }
    // grid cell transition: the centre's cell changes between two frames; timed between them.
    let (side, n) = CELL;
    let cell = |c: f64| ((c / side).floor() as i64).clamp(0, n - 1);
    for w in s.windows(2) {
        if (cell(w[0].c[0]), cell(w[0].c[1])) != (cell(w[1].c[0]), cell(w[1].c[1])) {
            out.push(event(
                "grid cell transition",
                (w[0].t + w[1].t) / 2.0,
                &[id],
            ));
        }
    }
    // tip over: a non-ball body turning fast for long enough, and far enough net.
    if tr.shape != "ball" && tr.shape != "wall" {
        let (omega, min_s, turn) = TIP;
        let flags: Vec<bool> = s.iter().map(|x| x.w.abs() >= omega).collect();
        for (i, j) in runs(&times, &flags, merge_s, min_s) {
            if (s[j].angle - s[i].angle).abs() >= turn {
                out.push(event("tip over", (times[i] + times[j]) / 2.0, &[id]));
            }
        }
    }
    // rolling object / sliding contact: moving while touching, spin matching speed or not.
    let (v_move, tol, min_roll, min_slide) = ROLL;
    let in_contact = |t: f64| {
        touching
            .iter()
            .any(|&(a, b)| a - 1e-9 <= t && t <= b + 1e-9)
    };
    let ball = tr.shape == "ball";
    let (mut roll, mut slide) = (Vec::new(), Vec::new());
    for x in s {
        let sp = norm(x.v);
        let moving = sp >= v_move && in_contact(x.t);
        let rolls = ball && (x.w.abs() * x.radius - sp).abs() <= tol * sp;
        roll.push(moving && rolls);
        slide.push(moving && !rolls);
    }
    for (i, j) in runs(&times, &roll, merge_s, min_roll) {
        out.push(event("rolling object", (times[i] + times[j]) / 2.0, &[id]));
    }
    for (i, j) in runs(&times, &slide, merge_s, min_slide) {
        out.push(event("sliding contact", (times[i] + times[j]) / 2.0, &[id]));
    }
}

fn bounce(
    trace: &Trace,
    p: &[String],
    ep: &Episode,
    x: &Track,
    y: &Track,
    out: &mut Vec<TruthEvent>,
) {
    let (v_in, v_out, window) = BOUNCE;
    // The frame strictly before the contact.
    let pre = frame_at(trace, ep.t0 - 1e-6);
    for me in [x, y] {
        if !me.dynamic {
            continue;
        }
        let Some(before) = me.at(pre) else { continue };
        let v0 = before.v[1];
        if v0.abs() < v_in {
            continue;
        }
        let reversed = me.samples.iter().any(|s| {
            s.k > pre && s.t <= ep.t0 + window + 1e-9 && s.v[1] * v0 < 0.0 && s.v[1].abs() >= v_out
        });
        if reversed {
            out.push(event("bounce", ep.t0, &[&p[0], &p[1]]));
        }
    }
}

fn support(
    trace: &Trace,
    p: &[String],
    ep: &Episode,
    x: &Track,
    y: &Track,
    merge_s: f64,
    out: &mut Vec<TruthEvent>,
) {
    let k0 = frame_at(trace, ep.t0);
    let k1 = frame_at(trace, ep.t1);
    let (Some(sx), Some(sy)) = (x.at(k0), y.at(k0)) else {
        return;
    };
    let (upper, lower) = if sx.c[1] > sy.c[1] { (x, y) } else { (y, x) };
    if !upper.dynamic || lower.samples.is_empty() {
        return;
    }
    let inside: Vec<_> = upper
        .samples
        .iter()
        .filter(|s| (k0..=k1).contains(&s.k))
        .collect();
    let times: Vec<f64> = inside.iter().map(|s| s.t).collect();
    // support relationship: resting on it for long enough.
    let (rest_v, min_rest) = SUPPORT;
    let rest: Vec<bool> = inside.iter().map(|s| norm(s.v) <= rest_v).collect();
    for (i, j) in runs(&times, &rest, merge_s, min_rest) {
        out.push(event(
            "support relationship",
            (times[i] + times[j]) / 2.0,
            &[&p[0], &p[1]],
        ));
    }
    // lose support: it rested there, the contact ended, and it falls soon after.
    let (lose_v, lose_rest, fall_v, window) = LOSE;
    if !ep.ended {
        return;
    }
    let resting: Vec<f64> = inside
        .iter()
        .filter(|s| norm(s.v) <= lose_v)
        .map(|s| s.t)
        .collect();
    let (Some(&first), Some(&last)) = (resting.first(), resting.last()) else {
        return;
    };
    if last - first < lose_rest - 1e-9 {
        return;
    }
    // Timed at the first falling frame after its last resting one: the moment it loses support.
    let fall = upper
        .samples
        .iter()
        .find(|s| s.t >= last && s.t <= ep.t1 + window + 1e-9 && s.v[1] <= -fall_v);
    if let Some(f) = fall {
        out.push(event("lose support", f.t, &[&p[0], &p[1]]));
    }
}

fn near(
    tr: &BTreeMap<String, Track>,
    eps: &BTreeMap<Vec<String>, Vec<Episode>>,
    merge_s: f64,
    out: &mut Vec<TruthEvent>,
) {
    let (v_move, max_gap, min_gap, margin) = NEAR;
    let balls: Vec<(&String, &Track)> = tr.iter().filter(|(_, t)| t.shape == "ball").collect();
    for (i, (a, ta)) in balls.iter().enumerate() {
        for (b, tb) in &balls[i + 1..] {
            let both: Vec<_> = ta
                .samples
                .iter()
                .filter_map(|s| Some((s, tb.at(s.k)?)))
                .collect();
            let times: Vec<f64> = both.iter().map(|(s, _)| s.t).collect();
            let gaps: Vec<f64> = both
                .iter()
                .map(|(s, q)| norm([q.c[0] - s.c[0], q.c[1] - s.c[1]]) - s.radius - q.radius)
                .collect();
            let flags: Vec<bool> = both
                .iter()
                .zip(&gaps)
                .map(|((s, q), &g)| {
                    g > min_gap && g <= max_gap && norm(s.v).max(norm(q.v)) >= v_move
                })
                .collect();
            let mut key = vec![(*a).clone(), (*b).clone()];
            key.sort();
            let touches = eps.get(&key).map(Vec::as_slice).unwrap_or_default();
            for (x, y) in runs(&times, &flags, merge_s, 0.0) {
                let (t0, t1) = (times[x], times[y]);
                if touches
                    .iter()
                    .any(|e| e.t0 <= t1 + margin && e.t1 >= t0 - margin)
                {
                    continue;
                }
                let closest = (x..=y)
                    .min_by(|&m, &n| {
                        gaps[m]
                            .partial_cmp(&gaps[n])
                            .unwrap_or(std::cmp::Ordering::Equal)
                    })
                    .unwrap_or(x);
                out.push(event("near collision", times[closest], &[a, b]));
            }
        }
    }
}

/// wedged: a dynamic body other than a jar at rest (speed and spin) for long enough while two bodies
/// it is in contact with push from opposed sides. A push's direction runs from the body's centre to
/// the point of the other body's exact outline nearest to that centre (a wall: straight at it); two
/// pushes are opposed when at least 120° apart and on opposite sides horizontally, each direction's
/// horizontal part at least 0.3. Timed at the resting run's middle; names the wedged body.
fn wedged(
    trace: &Trace,
    tr: &BTreeMap<String, Track>,
    eps: &BTreeMap<Vec<String>, Vec<Episode>>,
    merge_s: f64,
    out: &mut Vec<TruthEvent>,
) {
    let (rest_v, rest_w, min_s, opposed_cos, side) = WEDGED;
    let mut frames = None;
    for (id, track) in tr {
        if !track.dynamic || track.shape == "jar" || track.shape == "wall" {
            continue;
        }
        let mine: Vec<(&String, &Vec<Episode>)> = eps
            .iter()
            .filter(|(p, _)| p.contains(id))
            .map(|(p, l)| (if &p[0] == id { &p[1] } else { &p[0] }, l))
            .collect();
        if mine.len() < 2 {
            continue;
        }
        let frames = frames.get_or_insert_with(|| phyre_outlines(trace));
        if frames.is_empty() {
            return;
        }
        let s = &track.samples;
        let flags: Vec<bool> = s
            .iter()
            .map(|x| {
                if norm(x.v) > rest_v || x.w.abs() > rest_w {
                    return false;
                }
                let bodies = &frames[x.k].1;
                let pushes: Vec<P> = mine
                    .iter()
                    .filter(|(_, l)| l.iter().any(|e| (e.t0 - 1e-9..=e.t1 + 1e-9).contains(&x.t)))
                    .filter_map(|(other, _)| {
                        let q = bodies.iter().find(|b| &b.id == *other)?.nearest_to(x.c)?;
                        let d = sub(q, x.c);
                        let n = dot(d, d).sqrt();
                        (n > 0.0).then_some([d[0] / n, d[1] / n])
                    })
                    .collect();
                pushes.iter().enumerate().any(|(i, a)| {
                    pushes[i + 1..].iter().any(|b| {
                        dot(*a, *b) <= opposed_cos
                            && a[0] * b[0] < 0.0
                            && a[0].abs() >= side
                            && b[0].abs() >= side
                    })
                })
            })
            .collect();
        let times: Vec<f64> = s.iter().map(|x| x.t).collect();
        for (i, j) in runs(&times, &flags, merge_s, min_s) {
            out.push(event("wedged", (times[i] + times[j]) / 2.0, &[id]));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Body;

    /// The user's ball (object 0) falling from y = 200 as y = 200 − 50 t², frames 10 ms, 0.6 s.
    fn drop_trace() -> Trace {
        let mut trace = crate::testutil::synthetic_trace(Env::Phyre, 0, 61, 1);
        trace.events.clear();
        for s in &mut trace.timesteps {
            if let Body::Phyre(p) = &mut s.objects[0].body {
                (p.x, p.y, p.vx, p.vy) = (100.0, 200.0 - 50.0 * s.t * s.t, 0.0, -100.0 * s.t);
            }
        }
        trace
    }

    #[test]
    fn a_drop_falls_once_and_crosses_one_grid_row() {
        let got = phyre_motion_truth(&drop_trace(), 0.05);
        let labels: Vec<&str> = got.iter().map(|e| e.label).collect();
        // Falling from 0.3 s (30 px/s) to 0.6 s, 13.5 px down; y 200 → 182 crosses the 192 row line.
        assert_eq!(
            labels,
            ["grid cell transition", "falling object"],
            "{got:?}"
        );
        assert!((got[1].t - 0.45).abs() < 1e-9, "{got:?}");
        let cross = (8.0_f64 / 50.0).sqrt(); // y = 192 at t = 0.4
        assert!((got[0].t - cross).abs() < 0.01, "{got:?}");
        assert!(got.iter().all(|e| e.balls == ["0"]));
    }
}
