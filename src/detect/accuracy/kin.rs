//! Simulator state for the motion ground truths of PHYRE and I-PHYRE: per-object tracks (centre,
//! velocity, angle, angular velocity, from the recorded state, or by central differences of the
//! positions when a trace records none), per-pair contact episodes (from the contact log, or from the
//! frames' touching pairs of `geometry.rs` for traces that log none) and runs of frames in which a
//! condition holds. Owns no label rule (`airborne.rs`, `iphyre_motion.rs`, `phyre_motion.rs`) and shares
//! nothing with the detectors' preludes (`data/libraries/*/_common.py`, `_contacts.py`, `_motion.py`).

use std::collections::BTreeMap;

use super::contacts::{contact_events, has_contact_log, pair};
use super::geometry::{dense, iphyre_touching, phyre_dynamic, phyre_touching};
use crate::trace::{Body, Env, Trace};

/// A point or vector in scene pixels.
pub type P = [f64; 2];

/// One object in one frame.
#[derive(Clone, Debug)]
pub struct Sample {
    /// Position of the frame in the trace's timestep list.
    pub k: usize,
    /// Time (s).
    pub t: f64,
    /// Centre (I-PHYRE: the capsule's midpoint; PHYRE: the body's origin).
    pub c: P,
    /// Velocity (px/s): recorded, else central differences of the centre.
    pub v: P,
    /// Angle (rad): recorded, else (I-PHYRE) the capsule's direction.
    pub angle: f64,
    /// Angular velocity (rad/s): recorded, else differences of the unwrapped angle.
    pub w: f64,
    /// I-PHYRE: the capsule's two end points (both the centre for a ball).
    pub ends: [P; 2],
    /// I-PHYRE: the capsule's radius; PHYRE: half the diameter.
    pub radius: f64,
}

/// One object over the trace.
#[derive(Clone, Debug, Default)]
pub struct Track {
    /// Moved by the simulator (I-PHYRE `dynamic`; PHYRE: the user's ball or a dynamic task body).
    pub dynamic: bool,
    /// I-PHYRE joint / spring group (0 = none).
    pub joint: i64,
    /// I-PHYRE spring group (0 = none).
    pub spring: i64,
    /// PHYRE shape (`ball`, `bar`, `jar`, `standingsticks`, `wall`); I-PHYRE `ball` or `bar`.
    pub shape: String,
    /// Its frames, in time order (a removed I-PHYRE block stops).
    pub samples: Vec<Sample>,
}

impl Track {
    /// The sample in frame `k`, if the object is there.
    pub fn at(&self, k: usize) -> Option<&Sample> {
        self.samples
            .binary_search_by(|s| s.k.cmp(&k))
            .ok()
            .map(|i| &self.samples[i])
    }
}

/// The scene walls a PHYRE trace exported from phyre omits, with the centre annotrace gives them.
const IMPLICIT_WALLS: [(&str, P); 4] = [
    ("-4", [128.0, -2.5]),
    ("-3", [-2.5, 128.0]),
    ("-2", [128.0, 258.5]),
    ("-1", [258.5, 128.0]),
];

/// The tracks of a PHYRE or I-PHYRE trace, by object id. PHYRE traces without wall objects get the
/// four implicit walls (static, at rest).
pub fn tracks(env: Env, trace: &Trace) -> BTreeMap<String, Track> {
    let dynamic = if env == Env::Phyre {
        phyre_dynamic(trace).unwrap_or_default()
    } else {
        BTreeMap::new()
    };
    let mut out: BTreeMap<String, Track> = BTreeMap::new();
    // Whether velocities / angles / spins were recorded, per object.
    let mut recorded: BTreeMap<String, (bool, bool, bool)> = BTreeMap::new();
    for (k, s) in trace.timesteps.iter().enumerate() {
        for o in &s.objects {
            let (id, sample, rec) = match &o.body {
                Body::Iphyre(b) => {
                    let ends = [[b.x1, b.y1], [b.x2, b.y2]];
                    let c = [(b.x1 + b.x2) / 2.0, (b.y1 + b.y2) / 2.0];
                    let dir = (b.y2 - b.y1).atan2(b.x2 - b.x1);
                    let v = [b.vx.unwrap_or(0.0), b.vy.unwrap_or(0.0)];
                    let id = b.index.to_string();
                    let tr = out.entry(id.clone()).or_default();
                    if tr.samples.is_empty() {
                        tr.dynamic = b.dynamic != 0.0;
                        tr.joint = b.joint;
                        tr.spring = b.spring;
                        tr.shape = if ends[0] == ends[1] { "ball" } else { "bar" }.into();
                    }
                    let sample = Sample {
                        k,
                        t: s.t,
                        c,
                        v,
                        angle: b.angle.unwrap_or(dir),
                        w: b.angular_velocity.unwrap_or(0.0),
                        ends,
                        radius: b.radius,
                    };
                    let rec = (
                        b.vx.is_some() && b.vy.is_some(),
                        b.angle.is_some(),
                        b.angular_velocity.is_some(),
                    );
                    (id, sample, rec)
                }
                Body::Phyre(p) => {
                    let id = p.object_index.to_string();
                    let tr = out.entry(id.clone()).or_default();
                    if tr.samples.is_empty() {
                        tr.dynamic = dynamic.get(&id).copied().unwrap_or(p.is_user_input);
                        tr.shape = p.shape.clone();
                    }
                    let c = [p.x, p.y];
                    let sample = Sample {
                        k,
                        t: s.t,
                        c,
                        v: [p.vx, p.vy],
                        angle: p.angle,
                        w: p.angular_velocity,
                        ends: [c, c],
                        radius: p.diameter / 2.0,
                    };
                    (id, sample, (true, true, true))
                }
                Body::Pool(_) => continue,
            };
            recorded.insert(id.clone(), rec);
            out.entry(id).or_default().samples.push(sample);
        }
    }
    for (id, tr) in &mut out {
        let (v, a, w) = recorded.get(id).copied().unwrap_or((true, true, true));
        unwrap_angles(&mut tr.samples);
        if !v || (!a && !w) {
            differentiate(&mut tr.samples, !v, !w);
        } else if !w {
            differentiate(&mut tr.samples, false, true);
        }
    }
    if env == Env::Phyre
        && !trace.timesteps.first().is_some_and(|s| {
            s.objects
                .iter()
                .any(|o| matches!(&o.body, Body::Phyre(p) if p.shape == "wall"))
        })
    {
        for (id, c) in IMPLICIT_WALLS {
            let samples = trace
                .timesteps
                .iter()
                .enumerate()
                .map(|(k, s)| Sample {
                    k,
                    t: s.t,
                    c,
                    v: [0.0, 0.0],
                    angle: 0.0,
                    w: 0.0,
                    ends: [c, c],
                    radius: 0.0,
                })
                .collect();
            out.insert(
                id.to_string(),
                Track {
                    dynamic: false,
                    shape: "wall".into(),
                    samples,
                    ..Track::default()
                },
            );
        }
    }
    out
}

/// Makes the angles of a track continuous (no 2π jumps between frames).
fn unwrap_angles(samples: &mut [Sample]) {
    use std::f64::consts::{PI, TAU};
    for i in 1..samples.len() {
        let mut d = samples[i].angle - samples[i - 1].angle;
        while d > PI {
            d -= TAU;
        }
        while d < -PI {
            d += TAU;
        }
        samples[i].angle = samples[i - 1].angle + d;
    }
}

/// Central differences (one-sided at the ends) of centre and angle over the real time between frames.
fn differentiate(samples: &mut [Sample], velocity: bool, spin: bool) {
    let n = samples.len();
    if n < 2 {
        return;
    }
    let rates: Vec<(P, f64)> = (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            let dt = samples[b].t - samples[a].t;
            if dt <= 0.0 {
                return ([0.0, 0.0], 0.0);
            }
            let (p, q) = (&samples[a], &samples[b]);
            (
                [(q.c[0] - p.c[0]) / dt, (q.c[1] - p.c[1]) / dt],
                (q.angle - p.angle) / dt,
            )
        })
        .collect();
    for (s, (v, w)) in samples.iter_mut().zip(rates) {
        if velocity {
            s.v = v;
        }
        if spin {
            s.w = w;
        }
    }
}

/// Runs of consecutive items whose flag holds, as `(first, last)` positions; runs whose times are at
/// most `gap` apart are joined, runs lasting less than `min_s` dropped.
pub fn runs(times: &[f64], flags: &[bool], gap: f64, min_s: f64) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    for (i, &f) in flags.iter().enumerate() {
        if !f {
            continue;
        }
        match out.last_mut() {
            Some(r) if i == r.1 + 1 || times[i] - times[r.1] <= gap + 1e-9 => r.1 = i,
            _ => out.push((i, i)),
        }
    }
    out.retain(|&(a, b)| times[b] - times[a] >= min_s - 1e-9);
    out
}

/// One contact of a pair: from its begin to its end (the last frame if it never ends).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Episode {
    /// Begin (s).
    pub t0: f64,
    /// End (s).
    pub t1: f64,
    /// Whether it ended within the trace.
    pub ended: bool,
}

/// Contact episodes of each sorted pair. From a log: a pair's contact from its `contact_begin` to its
/// `contact_end`, a re-begin within `merge_s` of the end continuing it. From frames (traces that hold
/// every physics step): a pair's runs of touching frames, gaps up to `merge_s` bridged, ending at the
/// last touching frame.
pub fn episodes(env: Env, trace: &Trace, merge_s: f64) -> BTreeMap<Vec<String>, Vec<Episode>> {
    let last = trace.timesteps.last().map_or(0.0, |s| s.t);
    let mut by_pair: BTreeMap<Vec<String>, Vec<Episode>> = BTreeMap::new();
    if has_contact_log(trace) {
        let mut open: BTreeMap<Vec<String>, bool> = BTreeMap::new();
        for e in contact_events(trace) {
            let t = e.t.unwrap_or(0.0);
            let Some(p) = pair(e.payload.as_ref()) else {
                continue;
            };
            let list = by_pair.entry(p.clone()).or_default();
            let is_open = open.get(&p).copied().unwrap_or(false);
            if e.kind == "contact_begin" {
                if is_open {
                    continue;
                }
                match list.last_mut() {
                    Some(ep) if t - ep.t1 <= merge_s => {
                        ep.t1 = last;
                        ep.ended = false;
                    }
                    _ => list.push(Episode {
                        t0: t,
                        t1: last,
                        ended: false,
                    }),
                }
                open.insert(p, true);
            } else if is_open {
                if let Some(ep) = list.last_mut() {
                    ep.t1 = t;
                    ep.ended = true;
                }
                open.insert(p, false);
            }
        }
    } else if dense(trace) {
        let frames = if env == Env::Iphyre {
            iphyre_touching(trace)
        } else {
            phyre_touching(trace)
        };
        for (t, pairs) in frames {
            for p in pairs {
                let list = by_pair.entry(p).or_default();
                match list.last_mut() {
                    Some(ep) if t - ep.t1 <= merge_s + 1e-9 => ep.t1 = t,
                    _ => list.push(Episode {
                        t0: t,
                        t1: t,
                        ended: true,
                    }),
                }
            }
        }
        for list in by_pair.values_mut() {
            if let Some(ep) = list.last_mut() {
                ep.ended = ep.t1 < last - 1e-9;
            }
        }
    }
    by_pair
}

/// Contact intervals of each object (the episodes of every pair it belongs to).
pub fn intervals(
    episodes: &BTreeMap<Vec<String>, Vec<Episode>>,
) -> BTreeMap<String, Vec<(f64, f64)>> {
    let mut out: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    for (p, list) in episodes {
        for id in p {
            out.entry(id.clone())
                .or_default()
                .extend(list.iter().map(|e| (e.t0, e.t1)));
        }
    }
    out
}

/// Position in the timestep list of the last frame at or before `t` (0 before the first).
pub fn frame_at(trace: &Trace, t: f64) -> usize {
    trace
        .timesteps
        .partition_point(|s| s.t <= t + 1e-9)
        .saturating_sub(1)
}

/// Speed (px/s).
pub fn norm(v: P) -> f64 {
    v[0].hypot(v[1])
}

/// `a − b`.
pub fn sub(a: P, b: P) -> P {
    [a[0] - b[0], a[1] - b[1]]
}

/// The dot product of `a` and `b`.
pub fn dot(a: P, b: P) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// The point of segment `a`–`b` nearest to `p`.
pub fn nearest_on(p: P, a: P, b: P) -> P {
    let d = sub(b, a);
    let l2 = dot(d, d);
    let u = if l2 > 0.0 {
        (dot(sub(p, a), d) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    [a[0] + u * d[0], a[1] + u * d[1]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_join_short_gaps_and_drop_short_runs() {
        let t: Vec<f64> = (0..10).map(|i| i as f64 * 0.1).collect();
        let f = [
            true, true, false, true, true, false, false, false, true, false,
        ];
        assert_eq!(runs(&t, &f, 0.2, 0.2), [(0, 4)]);
        assert_eq!(runs(&t, &f, 0.0, 0.0), [(0, 1), (3, 4), (8, 8)]);
    }

    #[test]
    fn velocities_and_spins_from_positions_when_not_recorded() {
        let mut trace = crate::testutil::synthetic_trace(Env::Iphyre, 0, 5, 1);
        for (k, s) in trace.timesteps.iter_mut().enumerate() {
            s.t = k as f64 * 0.1;
            if let Body::Iphyre(b) = &mut s.objects[0].body {
                b.vx = None;
                b.vy = None;
                b.angle = None;
                b.angular_velocity = None;
                b.x1 = 10.0 + 3.0 * k as f64;
                b.x2 = b.x1 + 10.0;
                b.y1 = 50.0;
                b.y2 = 50.0;
            }
        }
        let tr = tracks(Env::Iphyre, &trace);
        let s = &tr.values().next().unwrap().samples[2];
        assert!((s.v[0] - 30.0).abs() < 1e-9 && s.v[1].abs() < 1e-9, "{s:?}");
        assert!(s.w.abs() < 1e-9);
    }
}
