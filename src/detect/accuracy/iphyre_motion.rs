//! I-PHYRE ground truth for the motion labels: falling object, support contact, sliding contact,
//! bounce, spring pull towards, spring resist movement, swinging object, lever launch and chain movement.
//! Owns these rules (stated in `docs/accuracy.md`, thresholds below); the tracks and contact episodes they read are
//! `kin.rs`. Not the scoring (`mod.rs`), not collision / removal (`iphyre.rs`) nor airborne motion
//! (`airborne.rs`).
//!
//! Each rule reads the simulator's state (recorded positions, velocities, angles; joints and springs
//! from the scene) and its contacts (the contact log, or for logless 60 Hz traces the capsules'
//! touching frames). An episode label (a run of frames) is timed at the run's middle; an instant label
//! at its instant. Screen y grows downwards.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use super::TruthEvent;
use super::kin::{
    Episode, P, Sample, Track, dot, episodes, frame_at, nearest_on, norm, runs, sub, tracks,
};
use crate::trace::{Env, Trace};

/// falling object: downward speed (px/s), shortest fall (s), least drop (px).
pub const FALL: (f64, f64, f64) = (30.0, 0.2, 10.0);
/// support contact: shortest contact (s), largest tilt of the contact normal from vertical (deg).
pub const SUPPORT: (f64, f64) = (0.3, 60.0);
/// sliding contact: tangential relative speed (px/s), shortest slide (s).
pub const SLIDE: (f64, f64) = (15.0, 0.1);
/// bounce: approach speed (px/s), rebound as a fraction of it, least rebound (px/s), window after (s).
pub const BOUNCE: (f64, f64, f64, f64) = (20.0, 0.2, 5.0, 0.15);
/// spring pull towards / resist movement: distance rate (px/s), shortest run (s), least closing (px),
/// least deceleration of the separation (px/s²).
pub const SPRING: (f64, f64, f64, f64) = (10.0, 0.1, 3.0, 5.0);
/// swinging object: rod turning rate (rad/s), shortest swing (s), bridged slow spell (s), least total
/// swing (deg).
pub const SWING: (f64, f64, f64, f64) = (0.2, 0.3, 0.4, 10.0);
/// lever launch: lever turning rate (rad/s), object's upward speed (px/s).
pub const LEVER: (f64, f64) = (0.3, 40.0);

/// chain movement: moving speed (px/s), resting speed (px/s), time for a struck or pulled body to start
/// (s), for a released one (s), longest wait between two links (s).
pub const CHAIN: (f64, f64, f64, f64, f64) = (15.0, 2.0, 0.2, 0.5, 2.0);

/// I-PHYRE's screen side (px).
const SCREEN: f64 = 600.0;

/// Unit contact normal from capsule `a` towards capsule `b`: along the nearest points of their
/// segments, or centre to centre when the segments cross or touch.
fn normal(a: &Sample, b: &Sample) -> P {
    let [a0, a1] = a.ends;
    let [b0, b1] = b.ends;
    let cands = [
        (a0, nearest_on(a0, b0, b1)),
        (a1, nearest_on(a1, b0, b1)),
        (nearest_on(b0, a0, a1), b0),
        (nearest_on(b1, a0, a1), b1),
    ];
    let (p, q) = cands
        .into_iter()
        .min_by(|x, y| {
            norm(sub(x.1, x.0))
                .partial_cmp(&norm(sub(y.1, y.0)))
                .unwrap_or(std::cmp::Ordering::Equal)
        })
        .expect("four candidates");
    let mut d = sub(q, p);
    if norm(d) < 1e-6 {
        d = sub(b.c, a.c);
    }
    let n = norm(d);
    if n < 1e-9 {
        [0.0, -1.0]
    } else {
        [d[0] / n, d[1] / n]
    }
}

fn on_screen(s: &Sample) -> bool {
    let r = s.radius;
    (-r..=SCREEN + r).contains(&s.c[0]) && (-r..=SCREEN + r).contains(&s.c[1])
}

fn event(label: &'static str, t: f64, ids: &[&String]) -> TruthEvent {
    let mut balls: Vec<String> = ids.iter().map(|s| s.to_string()).collect();
    balls.sort();
    balls.dedup();
    TruthEvent { label, t, balls }
}

/// The frames of episode `ep` in which both objects exist: (frame, sample of x, sample of y).
fn shared<'a>(
    trace: &Trace,
    ep: &Episode,
    x: &'a Track,
    y: &'a Track,
) -> Vec<(usize, &'a Sample, &'a Sample)> {
    let (a, b) = (frame_at(trace, ep.t0), frame_at(trace, ep.t1));
    (a..=b)
        .map_while(|k| Some((k, x.at(k)?, y.at(k)?)))
        .collect()
}

/// The motion ground truth of an I-PHYRE trace (module doc).
pub fn iphyre_motion_truth(trace: &Trace, merge_s: f64) -> Vec<TruthEvent> {
    let tr = tracks(Env::Iphyre, trace);
    let eps = episodes(Env::Iphyre, trace, merge_s);
    let mut out = Vec::new();
    falling(&tr, merge_s, &mut out);
    for (p, list) in &eps {
        let (Some(x), Some(y)) = (tr.get(&p[0]), tr.get(&p[1])) else {
            continue;
        };
        for ep in list {
            let frames = shared(trace, ep, x, y);
            support(trace, p, ep, x, y, &mut out);
            sliding(p, &frames, merge_s, &mut out);
            bounce(trace, p, ep, x, y, &mut out);
            lever(p, &frames, x, y, &mut out);
        }
    }
    springs_and_swings(&tr, merge_s, &mut out);
    chains(trace, &tr, &eps, &mut out);
    out.sort_by(|a, b| a.t.partial_cmp(&b.t).unwrap_or(std::cmp::Ordering::Equal));
    out
}

fn falling(tr: &BTreeMap<String, Track>, merge_s: f64, out: &mut Vec<TruthEvent>) {
    let (v_min, min_s, min_drop) = FALL;
    for (id, track) in tr {
        if !track.dynamic {
            continue;
        }
        let s = &track.samples;
        let times: Vec<f64> = s.iter().map(|x| x.t).collect();
        let flags: Vec<bool> = s.iter().map(|x| x.v[1] >= v_min && on_screen(x)).collect();
        for (i, j) in runs(&times, &flags, merge_s, min_s) {
            if s[j].c[1] - s[i].c[1] >= min_drop {
                out.push(event("falling object", (s[i].t + s[j].t) / 2.0, &[id]));
            }
        }
    }
}

fn support(
    trace: &Trace,
    p: &[String],
    ep: &Episode,
    x: &Track,
    y: &Track,
    out: &mut Vec<TruthEvent>,
) {
    let (min_s, tilt) = SUPPORT;
    if ep.t1 - ep.t0 < min_s {
        return;
    }
    // The geometry a little after the contact began (the impact frame may still overlap).
    let k = frame_at(trace, (ep.t0 + 0.1).min(ep.t1));
    let (Some(sx), Some(sy)) = (x.at(k), y.at(k)) else {
        return;
    };
    let n = normal(sx, sy); // from x towards y
    let cos = (tilt * PI / 180.0).cos();
    let upper = if -n[1] >= cos - 1e-12 {
        y // y lies above x
    } else if n[1] >= cos - 1e-12 {
        x
    } else {
        return;
    };
    if upper.dynamic {
        out.push(event(
            "support contact",
            (ep.t0 + ep.t1) / 2.0,
            &[&p[0], &p[1]],
        ));
    }
}

fn sliding(
    p: &[String],
    frames: &[(usize, &Sample, &Sample)],
    merge_s: f64,
    out: &mut Vec<TruthEvent>,
) {
    let (v_min, min_s) = SLIDE;
    let times: Vec<f64> = frames.iter().map(|f| f.1.t).collect();
    let flags: Vec<bool> = frames
        .iter()
        .map(|(_, a, b)| {
            let n = normal(b, a);
            let rel = sub(a.v, b.v);
            (rel[1] * n[0] - rel[0] * n[1]).abs() >= v_min
        })
        .collect();
    for (i, j) in runs(&times, &flags, merge_s, min_s) {
        out.push(event(
            "sliding contact",
            (times[i] + times[j]) / 2.0,
            &[&p[0], &p[1]],
        ));
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
    let (approach_min, frac, rebound_min, window) = BOUNCE;
    let c = frame_at(trace, ep.t0);
    let pre = c.saturating_sub(1);
    for (me, other) in [(x, y), (y, x)] {
        if !me.dynamic {
            continue;
        }
        let (Some(m), Some(o), Some(m0), Some(o0)) =
            (me.at(c), other.at(c), me.at(pre), other.at(pre))
        else {
            continue;
        };
        let n = normal(o, m); // from the other towards me
        let approach = -dot(sub(m0.v, o0.v), n);
        if approach < approach_min {
            continue;
        }
        let t_c = trace.timesteps[c].t;
        let rebound = (c..trace.timesteps.len())
            .take_while(|&k| trace.timesteps[k].t <= t_c + window + 1e-9)
            .map_while(|k| Some(dot(sub(me.at(k)?.v, other.at(k)?.v), n)))
            .fold(0.0_f64, f64::max);
        if rebound >= rebound_min && rebound >= frac * approach {
            out.push(event("bounce", ep.t0, &[&p[0], &p[1]]));
        }
    }
}

fn lever(
    p: &[String],
    frames: &[(usize, &Sample, &Sample)],
    x: &Track,
    y: &Track,
    out: &mut Vec<TruthEvent>,
) {
    let (omega, up) = LEVER;
    for (lever_is_x, (lv, ob)) in [(true, (x, y)), (false, (y, x))] {
        if !lv.dynamic || lv.shape == "ball" || !ob.dynamic {
            continue;
        }
        let hit = frames.iter().find(|(_, a, b)| {
            let (l, o) = if lever_is_x { (a, b) } else { (b, a) };
            l.w.abs() >= omega && o.v[1] <= -up
        });
        if let Some((_, a, _)) = hit {
            out.push(event("lever launch", a.t, &[&p[0], &p[1]]));
        }
    }
}

/// The frames two tracks share: (t, sample of a, sample of b).
/// One link of a chain: (time, the body passing the motion on, the body set moving).
type Link = (f64, String, String);

/// chain movement: motion passed along at least three bodies, each set moving by the one before.
/// A link is a collision (a contact episode begins while, in the frame strictly before, one body
/// moves at ≥ 15 px/s and the other, dynamic, rests at ≤ 2 px/s and then reaches 15 px/s within
/// 0.2 s), a pull (two bodies sharing a joint or spring group: one starts moving — its first frame at
/// ≥ 15 px/s after one at ≤ 2 px/s — within 0.2 s after the other did), or a release (an effective
/// removal of a block a resting dynamic body is in contact with, that body reaching 15 px/s within
/// 0.5 s). Links in time order chain when the body one sets moving passes the motion on within 2 s,
/// no body twice. Timed at the middle of the first and last link; names every body of the chain.
fn chains(
    trace: &Trace,
    tr: &BTreeMap<String, Track>,
    eps: &BTreeMap<Vec<String>, Vec<Episode>>,
    out: &mut Vec<TruthEvent>,
) {
    let (moving, rest, start_s, release_s, gap_s) = CHAIN;
    if trace.timesteps.is_empty() {
        return;
    }
    let speed = |id: &str, k: usize| tr.get(id).and_then(|t| t.at(k)).map(|s| norm(s.v));
    let starts_by = |id: &str, from: usize, until: f64| {
        tr.get(id).is_some_and(|t| {
            t.samples
                .iter()
                .any(|s| s.k >= from && s.t <= until + 1e-9 && norm(s.v) >= moving)
        })
    };
    let mut links: Vec<Link> = Vec::new();
    for (p, list) in eps {
        for ep in list {
            let pre = frame_at(trace, ep.t0 - 1e-6);
            if trace.timesteps.get(pre).is_none_or(|s| s.t >= ep.t0) {
                continue;
            }
            for (a, b) in [(&p[0], &p[1]), (&p[1], &p[0])] {
                if !tr.get(b).is_some_and(|t| t.dynamic) {
                    continue;
                }
                let (Some(va), Some(vb)) = (speed(a.as_str(), pre), speed(b.as_str(), pre)) else {
                    continue;
                };
                if va >= moving && vb <= rest && starts_by(b.as_str(), pre + 1, ep.t0 + start_s) {
                    links.push((ep.t0, a.clone(), b.clone()));
                }
            }
        }
    }
    // Motion onsets, for pulls through joints and springs.
    let onsets: BTreeMap<&String, Vec<f64>> = tr
        .iter()
        .map(|(id, t)| {
            let mut at_rest = false;
            let mut v = Vec::new();
            for s in &t.samples {
                let sp = norm(s.v);
                if sp <= rest {
                    at_rest = true;
                } else if at_rest && sp >= moving {
                    v.push(s.t);
                    at_rest = false;
                }
            }
            (id, v)
        })
        .collect();
    let mut groups: BTreeMap<(bool, i64), Vec<&String>> = BTreeMap::new();
    for (id, t) in tr {
        if t.spring != 0 {
            groups.entry((true, t.spring)).or_default().push(id);
        }
        if t.joint != 0 {
            groups.entry((false, t.joint)).or_default().push(id);
        }
    }
    for ids in groups.values() {
        let [a, b] = ids[..] else { continue };
        for (x, y) in [(a, b), (b, a)] {
            for &ty in &onsets[y] {
                if onsets[x]
                    .iter()
                    .any(|&tx| ty - tx > 0.0 && ty - tx <= start_s + 1e-9)
                {
                    links.push((ty, x.clone(), y.clone()));
                }
            }
        }
    }
    // Releases: an effective removal of a block a resting body touches.
    for e in &trace.events {
        let (Some(t), Some(p)) = (e.t, e.payload.as_ref()) else {
            continue;
        };
        if e.kind != "action_applied" || p.get("effective") != Some(&serde_json::Value::Bool(true))
        {
            continue;
        }
        let Some(gone) = p.get("eliminated_object").map(|o| {
            o.as_str()
                .map(str::to_string)
                .unwrap_or_else(|| o.to_string())
        }) else {
            continue;
        };
        let pre = frame_at(trace, t - 1e-6);
        for (pair, list) in eps {
            if !pair.contains(&gone) {
                continue;
            }
            let other = if pair[0] == gone { &pair[1] } else { &pair[0] };
            let at = trace.timesteps[pre].t;
            let touching = list
                .iter()
                .any(|ep| (ep.t0 - 1e-9..=ep.t1 + 1e-9).contains(&at));
            if touching
                && tr.get(other).is_some_and(|t| t.dynamic)
                && speed(other.as_str(), pre).is_some_and(|v| v <= rest)
                && starts_by(other.as_str(), pre, t + release_s)
            {
                links.push((t, gone.clone(), other.clone()));
            }
        }
    }
    links.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    let mut used = vec![false; links.len()];
    for (i, first) in links.iter().enumerate() {
        if used[i] {
            continue;
        }
        used[i] = true;
        let mut chain = vec![i];
        for (j, (t, from, to)) in links.iter().enumerate().skip(i + 1) {
            let (tl, _, last) = &links[*chain.last().expect("one link")];
            if !used[j]
                && from == last
                && *t - tl > 0.0
                && *t - tl <= gap_s + 1e-9
                && chain.iter().all(|&c| &links[c].1 != to)
            {
                used[j] = true;
                chain.push(j);
            }
        }
        if chain.len() < 2 {
            continue;
        }
        let last = &links[*chain.last().expect("two links")];
        let mut ids: Vec<&String> = vec![&first.1];
        ids.extend(chain.iter().map(|&c| &links[c].2));
        out.push(event("chain movement", (first.0 + last.0) / 2.0, &ids));
    }
}

fn together<'a>(a: &'a Track, b: &'a Track) -> Vec<(f64, &'a Sample, &'a Sample)> {
    a.samples
        .iter()
        .filter_map(|s| Some((s.t, s, b.at(s.k)?)))
        .collect()
}

/// Central-difference rate of a series over its times.
fn rate(times: &[f64], xs: &[f64]) -> Vec<f64> {
    let n = xs.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            let dt = times[b] - times[a];
            if dt > 0.0 { (xs[b] - xs[a]) / dt } else { 0.0 }
        })
        .collect()
}

fn springs_and_swings(tr: &BTreeMap<String, Track>, merge_s: f64, out: &mut Vec<TruthEvent>) {
    let mut groups: BTreeMap<(bool, i64), Vec<&String>> = BTreeMap::new();
    for (id, t) in tr {
        if t.spring != 0 {
            groups.entry((true, t.spring)).or_default().push(id);
        }
        if t.joint != 0 {
            groups.entry((false, t.joint)).or_default().push(id);
        }
    }
    for ((is_spring, _), ids) in groups {
        let [a, b] = ids[..] else { continue };
        let both = together(&tr[a], &tr[b]);
        if both.len() < 3 {
            continue;
        }
        let times: Vec<f64> = both.iter().map(|f| f.0).collect();
        if is_spring {
            let (v, min_s, close, decel) = SPRING;
            let d: Vec<f64> = both.iter().map(|(_, p, q)| norm(sub(q.c, p.c))).collect();
            let r = rate(&times, &d);
            let acc = rate(&times, &r);
            let pull: Vec<bool> = r.iter().map(|&x| x <= -v).collect();
            for (i, j) in runs(&times, &pull, merge_s, min_s) {
                if d[i] - d[j] >= close {
                    out.push(event(
                        "spring pull towards",
                        (times[i] + times[j]) / 2.0,
                        &[a, b],
                    ));
                }
            }
            let resist: Vec<bool> = r
                .iter()
                .zip(&acc)
                .map(|(&x, &g)| x >= v && g <= -decel)
                .collect();
            for (i, j) in runs(&times, &resist, merge_s, min_s) {
                out.push(event(
                    "spring resist movement",
                    (times[i] + times[j]) / 2.0,
                    &[a, b],
                ));
            }
        } else {
            let (omega, min_s, bridge, min_deg) = SWING;
            let ang: Vec<f64> = {
                let mut v: Vec<f64> = both
                    .iter()
                    .map(|(_, p, q)| (q.c[1] - p.c[1]).atan2(q.c[0] - p.c[0]))
                    .collect();
                for i in 1..v.len() {
                    let mut d = v[i] - v[i - 1];
                    while d > PI {
                        d -= 2.0 * PI;
                    }
                    while d < -PI {
                        d += 2.0 * PI;
                    }
                    v[i] = v[i - 1] + d;
                }
                v
            };
            // Turning rate over each frame interval (backwards), 0 for the first frame.
            let w: Vec<f64> = (0..ang.len())
                .map(|i| {
                    if i == 0 || times[i] <= times[i - 1] {
                        0.0
                    } else {
                        (ang[i] - ang[i - 1]) / (times[i] - times[i - 1])
                    }
                })
                .collect();
            let flags: Vec<bool> = w.iter().map(|x| x.abs() >= omega).collect();
            for (i, j) in runs(&times, &flags, bridge, min_s) {
                let swung: f64 = (i + 1..=j).map(|n| (ang[n] - ang[n - 1]).abs()).sum();
                if swung * 180.0 / PI >= min_deg {
                    out.push(event(
                        "swinging object",
                        (times[i] + times[j]) / 2.0,
                        &[a, b],
                    ));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Body;

    /// Two balls on spring 1, 100 px apart, closing at 20 px/s for 0.5 s then at rest; frames 10 ms.
    fn spring_trace() -> Trace {
        let mut trace = crate::testutil::synthetic_trace(Env::Iphyre, 0, 101, 2);
        trace.events.clear();
        for s in &mut trace.timesteps {
            let gap = 100.0 - 20.0 * s.t.min(0.5);
            for (k, o) in s.objects.iter_mut().enumerate() {
                if let Body::Iphyre(b) = &mut o.body {
                    let x = if k == 0 { 200.0 } else { 200.0 + gap };
                    (b.x1, b.x2, b.y1, b.y2) = (x, x, 300.0, 300.0);
                    b.spring = 1;
                }
            }
        }
        trace
    }

    #[test]
    fn a_spring_closing_is_one_pull_timed_at_its_middle() {
        let got = iphyre_motion_truth(&spring_trace(), 0.05);
        let pulls: Vec<&TruthEvent> = got
            .iter()
            .filter(|e| e.label == "spring pull towards")
            .collect();
        assert_eq!(pulls.len(), 1, "{got:?}");
        assert!((pulls[0].t - 0.25).abs() < 0.02, "{got:?}");
        assert_eq!(pulls[0].balls, ["0", "1"]);
        // Nothing falls, nothing slides: no contacts, no downward motion.
        assert!(
            got.iter().all(|e| e.label == "spring pull towards"),
            "{got:?}"
        );
    }

    #[test]
    fn the_contact_normal_points_from_one_capsule_to_the_other() {
        let cap = |ends: [P; 2]| Sample {
            k: 0,
            t: 0.0,
            c: [
                (ends[0][0] + ends[1][0]) / 2.0,
                (ends[0][1] + ends[1][1]) / 2.0,
            ],
            v: [0.0, 0.0],
            angle: 0.0,
            w: 0.0,
            ends,
            radius: 10.0,
        };
        let floor = cap([[0.0, 100.0], [200.0, 100.0]]);
        let ball = cap([[50.0, 80.0], [50.0, 80.0]]);
        assert_eq!(normal(&floor, &ball), [0.0, -1.0]); // up the screen
        assert_eq!(normal(&ball, &floor), [0.0, 1.0]);
    }
}
