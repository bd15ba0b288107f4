//! Contacts from states, for PHYRE and I-PHYRE traces that log none (traces exported from the original
//! simulators record no contact events): a pair touches in a frame when the distance between the two
//! bodies' outlines is within the simulator's contact margin, and a collision begins in the first frame
//! a pair touches after more than `merge_s` apart. Used only for traces that hold every physics step
//! (60 Hz, [`dense`]); between sparser frames a contact can begin and end unseen.
//!
//! Owns the outlines (I-PHYRE capsules from the frame; PHYRE bodies from the task's exact polygons in
//! the embedded task set, not from the trace's diameter) and the distances between them. Does not own
//! the labels built on the contacts (`iphyre.rs`, `phyre.rs`), and shares nothing with the detectors'
//! geometric fallbacks (`data/libraries/*/_contacts.py`).

use std::collections::BTreeMap;

use super::kin::{P, dot, nearest_on, sub};
use crate::envs::phyre::{Shape, Task, TaskSet};
use crate::trace::{Body, Trace};

/// I-PHYRE (pymunk): shapes touch when they overlap; positions are rounded to 6 significant digits, so
/// a gap up to this (px) counts as touching. Resting contacts overlap by up to pymunk's collision slop
/// (0.1 px).
pub const IPHYRE_TOUCH_PX: f64 = 0.01;

/// PHYRE (Box2D): polygons carry a skin (`b2_polygonRadius`), so resting bodies keep a gap of up to
/// 0.09 px between their outlines; a gap up to this (px) counts as touching.
pub const PHYRE_TOUCH_PX: f64 = 0.12;

/// The physics step of both simulators (s).
pub const STEP_S: f64 = 1.0 / 60.0;

/// PHYRE's scene side (px); the four walls bound it.
const SCENE: f64 = 256.0;

/// Whether the trace holds every physics step: at least two frames, none more than one 60 Hz step
/// apart.
pub fn dense(trace: &Trace) -> bool {
    trace.timesteps.len() >= 2
        && trace
            .timesteps
            .windows(2)
            .all(|w| w[1].t - w[0].t <= STEP_S + 1e-6)
}

/// Collision begins `(t, sorted pair)` from per-frame touching pairs: a pair begins when it touches in
/// a frame and did not touch in the previous one nor within `merge_s` before.
fn begins(frames: Vec<(f64, Vec<Vec<String>>)>, merge_s: f64) -> Vec<(f64, Vec<String>)> {
    let mut last: BTreeMap<Vec<String>, (usize, f64)> = BTreeMap::new();
    let mut out = Vec::new();
    for (k, (t, pairs)) in frames.into_iter().enumerate() {
        for p in pairs {
            let new = match last.get(&p) {
                None => true,
                Some(&(kk, tt)) => kk + 1 != k && t - tt > merge_s,
            };
            if new {
                out.push((t, p.clone()));
            }
            last.insert(p, (k, t));
        }
    }
    out
}

fn sorted_pair(a: String, b: String) -> Vec<String> {
    let mut v = vec![a, b];
    v.sort();
    v
}

/// Distance from point `p` to segment `a`–`b`.
fn point_segment(p: P, a: P, b: P) -> f64 {
    let q = sub(nearest_on(p, a, b), p);
    dot(q, q).sqrt()
}

/// Distance between segments `a`–`b` and `c`–`d` (0 when they cross).
fn segment_segment(a: P, b: P, c: P, d: P) -> f64 {
    let r = sub(b, a);
    let s = sub(d, c);
    let den = r[0] * s[1] - r[1] * s[0];
    if den != 0.0 {
        let ca = sub(c, a);
        let u = (ca[0] * s[1] - ca[1] * s[0]) / den;
        let v = (ca[0] * r[1] - ca[1] * r[0]) / den;
        if (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v) {
            return 0.0;
        }
    }
    point_segment(a, c, d)
        .min(point_segment(b, c, d))
        .min(point_segment(c, a, b))
        .min(point_segment(d, a, b))
}

// ------------------------------------------------------------------------------------------ I-PHYRE

/// Collision begins of an I-PHYRE trace from its frames ([`iphyre_touching`]).
pub fn iphyre_contacts(trace: &Trace, merge_s: f64) -> Vec<(f64, Vec<String>)> {
    begins(iphyre_touching(trace), merge_s)
}

/// The pairs touching in each frame of an I-PHYRE trace (capsules, at least one body dynamic).
pub fn iphyre_touching(trace: &Trace) -> Vec<(f64, Vec<Vec<String>>)> {
    trace
        .timesteps
        .iter()
        .map(|s| {
            let objs: Vec<_> = s
                .objects
                .iter()
                .filter_map(|o| match &o.body {
                    Body::Iphyre(b) => Some(b),
                    _ => None,
                })
                .collect();
            let mut pairs = Vec::new();
            for (i, a) in objs.iter().enumerate() {
                for b in &objs[i + 1..] {
                    if a.dynamic == 0.0 && b.dynamic == 0.0 {
                        continue;
                    }
                    let d = segment_segment([a.x1, a.y1], [a.x2, a.y2], [b.x1, b.y1], [b.x2, b.y2]);
                    if d - a.radius - b.radius <= IPHYRE_TOUCH_PX {
                        pairs.push(sorted_pair(a.index.to_string(), b.index.to_string()));
                    }
                }
            }
            (s.t, pairs)
        })
        .collect()
}

// ------------------------------------------------------------------------------------------- PHYRE

/// A body's outline in scene coordinates.
enum Outline {
    Circle(P, f64),
    Polygons(Vec<Vec<P>>),
    /// A wall: the scene side at `coord` along `axis` (0 = x, 1 = y).
    Wall(usize, f64),
}

fn place(shapes: &[Shape], x: f64, y: f64, angle: f64) -> Outline {
    let (s, c) = angle.sin_cos();
    let at = |p: &[f64; 2]| [x + c * p[0] - s * p[1], y + s * p[0] + c * p[1]];
    if let [Shape::Circle { radius }] = shapes {
        return Outline::Circle([x, y], *radius);
    }
    Outline::Polygons(
        shapes
            .iter()
            .map(|sh| match sh {
                Shape::Polygon(v) => v.iter().map(at).collect(),
                // A circle piece of a compound body: its bounding square is close enough for contact.
                Shape::Circle { radius } => {
                    let r = *radius;
                    [[r, r], [-r, r], [-r, -r], [r, -r]]
                        .iter()
                        .map(at)
                        .collect()
                }
            })
            .collect(),
    )
}

fn inside(p: P, poly: &[P]) -> bool {
    let mut sign = 0.0_f64;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        let c = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        if c != 0.0 {
            if sign == 0.0 {
                sign = c.signum();
            } else if c.signum() != sign {
                return false;
            }
        }
    }
    true
}

fn edges(poly: &[P]) -> impl Iterator<Item = (P, P)> + '_ {
    (0..poly.len()).map(move |i| (poly[i], poly[(i + 1) % poly.len()]))
}

/// Gap between two convex polygons: 0 when they overlap (an edge crosses or a vertex is inside).
fn polygon_gap(p: &[P], q: &[P]) -> f64 {
    if p.iter().any(|v| inside(*v, q)) || q.iter().any(|v| inside(*v, p)) {
        return 0.0;
    }
    let mut best = f64::INFINITY;
    for (a, b) in edges(p) {
        for (c, d) in edges(q) {
            best = best.min(segment_segment(a, b, c, d));
        }
    }
    best
}

fn circle_polygon_gap(c: P, r: f64, poly: &[P]) -> f64 {
    if inside(c, poly) {
        return -r;
    }
    edges(poly)
        .map(|(a, b)| point_segment(c, a, b))
        .fold(f64::INFINITY, f64::min)
        - r
}

fn extent(o: &Outline, axis: usize) -> (f64, f64) {
    match o {
        Outline::Circle(c, r) => (c[axis] - r, c[axis] + r),
        Outline::Polygons(ps) => ps
            .iter()
            .flatten()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p[axis]), hi.max(p[axis]))
            }),
        Outline::Wall(_, _) => (f64::NEG_INFINITY, f64::INFINITY),
    }
}

fn gap(a: &Outline, b: &Outline) -> f64 {
    match (a, b) {
        (Outline::Wall(_, _), Outline::Wall(_, _)) => f64::INFINITY,
        (Outline::Wall(axis, at), o) | (o, Outline::Wall(axis, at)) => {
            let (lo, hi) = extent(o, *axis);
            if *at <= 0.0 { lo - at } else { at - hi }
        }
        (Outline::Circle(c, r), Outline::Circle(d, s)) => {
            let v = sub(*c, *d);
            dot(v, v).sqrt() - r - s
        }
        (Outline::Circle(c, r), Outline::Polygons(ps))
        | (Outline::Polygons(ps), Outline::Circle(c, r)) => ps
            .iter()
            .map(|p| circle_polygon_gap(*c, *r, p))
            .fold(f64::INFINITY, f64::min),
        (Outline::Polygons(ps), Outline::Polygons(qs)) => {
            // Bounding boxes first: most pairs are far apart.
            for axis in 0..2 {
                let (a0, a1) = extent(a, axis);
                let (b0, b1) = extent(b, axis);
                if a0 - b1 > 1.0 || b0 - a1 > 1.0 {
                    return f64::INFINITY;
                }
            }
            ps.iter()
                .flat_map(|p| qs.iter().map(move |q| polygon_gap(p, q)))
                .fold(f64::INFINITY, f64::min)
        }
    }
}

/// The PHYRE task a trace plays, from the embedded ball-tier task set; `None` for other tasks.
fn phyre_task(trace: &Trace) -> Option<Task> {
    TaskSet::default_tasks().ok()?.get(&trace.task_id).ok()
}

/// Whether the trace's PHYRE bodies can be given exact outlines (its task is in the embedded task set).
pub fn phyre_outlines_known(trace: &Trace) -> bool {
    phyre_task(trace).is_some()
}

/// Per-frame touching pairs of a PHYRE trace, with the task's exact outlines (at least one body
/// dynamic). Object ids are the trace's `object_index`; a trace that omits the four walls numbers its
/// bodies from PHYRE's body 4 (the exporters' `body index − 4`), and its walls are the implicit ids
/// `-4` (floor), `-3` (left), `-2` (ceiling), `-1` (right).
pub fn phyre_contacts(trace: &Trace, merge_s: f64) -> Vec<(f64, Vec<String>)> {
    begins(phyre_touching(trace), merge_s)
}

/// The pairs touching in each frame of a PHYRE trace, as [`phyre_contacts`] finds them (empty for a
/// task outside the embedded set).
pub fn phyre_touching(trace: &Trace) -> Vec<(f64, Vec<Vec<String>>)> {
    phyre_outlines(trace)
        .into_iter()
        .map(|(t, bodies)| {
            let mut pairs = Vec::new();
            for (i, a) in bodies.iter().enumerate() {
                for b in &bodies[i + 1..] {
                    if (a.dynamic || b.dynamic) && gap(&a.outline, &b.outline) <= PHYRE_TOUCH_PX {
                        pairs.push(sorted_pair(a.id.clone(), b.id.clone()));
                    }
                }
            }
            (t, pairs)
        })
        .collect()
}

/// One PHYRE body in one frame: its id, whether it is dynamic, its exact outline.
pub struct Placed {
    /// The trace's `object_index` (or an implicit wall's id).
    pub id: String,
    /// Moved by the simulator.
    pub dynamic: bool,
    outline: Outline,
}

impl Placed {
    /// The point of this body's outline nearest to `p` (`None` when `p` is inside it): for a wall,
    /// `p` moved onto the wall's line.
    pub fn nearest_to(&self, p: P) -> Option<P> {
        match &self.outline {
            Outline::Circle(c, r) => {
                let d = sub(p, *c);
                let n = dot(d, d).sqrt();
                (n > *r).then_some([c[0] + d[0] * r / n, c[1] + d[1] * r / n])
            }
            Outline::Wall(axis, at) => {
                let mut q = p;
                q[*axis] = *at;
                Some(q)
            }
            Outline::Polygons(ps) => {
                if ps.iter().any(|poly| inside(p, poly)) {
                    return None;
                }
                ps.iter()
                    .flat_map(|poly| edges(poly).map(|(a, b)| nearest_on(p, a, b)))
                    .min_by(|a, b| {
                        let (da, db) = (sub(*a, p), sub(*b, p));
                        dot(da, da)
                            .partial_cmp(&dot(db, db))
                            .unwrap_or(std::cmp::Ordering::Equal)
                    })
            }
        }
    }
}

/// Every body of each frame of a PHYRE trace placed with the task's exact outline (empty for a task
/// outside the embedded set): the trace's objects, and the implicit walls when it omits them.
pub fn phyre_outlines(trace: &Trace) -> Vec<(f64, Vec<Placed>)> {
    let Some(task) = phyre_task(trace) else {
        return Vec::new();
    };
    let lists_walls = trace.timesteps.first().is_some_and(|s| {
        s.objects
            .iter()
            .any(|o| matches!(&o.body, Body::Phyre(p) if p.shape == "wall"))
    });
    let offset: i64 = if lists_walls { 0 } else { 4 };
    let walls: Vec<(String, bool, Outline)> = if lists_walls {
        Vec::new()
    } else {
        vec![
            ("-4".into(), false, Outline::Wall(1, 0.0)),
            ("-3".into(), false, Outline::Wall(0, 0.0)),
            ("-2".into(), false, Outline::Wall(1, SCENE)),
            ("-1".into(), false, Outline::Wall(0, SCENE)),
        ]
    };
    trace
        .timesteps
        .iter()
        .map(|s| {
            let mut bodies: Vec<Placed> = s
                .objects
                .iter()
                .filter_map(|o| match &o.body {
                    Body::Phyre(p) => Some(p),
                    _ => None,
                })
                .filter_map(|p| {
                    let id = p.object_index.to_string();
                    if p.is_user_input {
                        let circle = [Shape::Circle {
                            radius: p.diameter / 2.0,
                        }];
                        return Some(Placed {
                            id,
                            dynamic: true,
                            outline: place(&circle, p.x, p.y, p.angle),
                        });
                    }
                    let body = usize::try_from(p.object_index + offset)
                        .ok()
                        .and_then(|i| task.bodies.get(i))?;
                    if body.is_wall {
                        let o = match body.id {
                            0 => Outline::Wall(1, 0.0),
                            1 => Outline::Wall(0, 0.0),
                            2 => Outline::Wall(1, SCENE),
                            _ => Outline::Wall(0, SCENE),
                        };
                        return Some(Placed {
                            id,
                            dynamic: false,
                            outline: o,
                        });
                    }
                    Some(Placed {
                        id,
                        dynamic: body.dynamic,
                        outline: place(&body.shapes, p.x, p.y, p.angle),
                    })
                })
                .collect();
            bodies.extend(walls.iter().map(|(id, d, o)| Placed {
                id: id.clone(),
                dynamic: *d,
                outline: copy_wall(o),
            }));
            (s.t, bodies)
        })
        .collect()
}

/// Whether PHYRE object `index` of `trace` is a dynamic body (the user's ball, or a dynamic body of the
/// task); `None` when the task is not in the embedded set.
pub fn phyre_dynamic(trace: &Trace) -> Option<BTreeMap<String, bool>> {
    let task = phyre_task(trace)?;
    let first = trace.timesteps.first()?;
    let lists_walls = first
        .objects
        .iter()
        .any(|o| matches!(&o.body, Body::Phyre(p) if p.shape == "wall"));
    let offset: i64 = if lists_walls { 0 } else { 4 };
    Some(
        first
            .objects
            .iter()
            .filter_map(|o| match &o.body {
                Body::Phyre(p) => Some(p),
                _ => None,
            })
            .map(|p| {
                let dynamic = p.is_user_input
                    || usize::try_from(p.object_index + offset)
                        .ok()
                        .and_then(|i| task.bodies.get(i))
                        .is_some_and(|b| b.dynamic);
                (p.object_index.to_string(), dynamic)
            })
            .collect(),
    )
}

fn copy_wall(o: &Outline) -> Outline {
    match o {
        Outline::Wall(a, at) => Outline::Wall(*a, *at),
        _ => unreachable!("only walls are copied"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_between_outlines() {
        assert_eq!(
            segment_segment([0.0, 0.0], [2.0, 2.0], [0.0, 2.0], [2.0, 0.0]),
            0.0
        );
        assert!(
            (segment_segment([0.0, 0.0], [1.0, 0.0], [0.0, 3.0], [1.0, 3.0]) - 3.0).abs() < 1e-12
        );
        let square = vec![[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]];
        let far = vec![[3.0, 1.0], [2.5, 1.0], [2.5, -1.0], [3.0, -1.0]];
        assert!((polygon_gap(&square, &far) - 1.5).abs() < 1e-12);
        assert!((circle_polygon_gap([0.0, 3.0], 1.5, &square) - 0.5).abs() < 1e-12);
        let ball = Outline::Circle([10.0, 7.55], 7.5);
        assert!((gap(&ball, &Outline::Wall(1, 0.0)) - 0.05).abs() < 1e-12);
        assert!((gap(&Outline::Wall(0, SCENE), &ball) - (SCENE - 17.5)).abs() < 1e-12);
    }

    #[test]
    fn a_pair_begins_once_per_touching_run_and_rebegins_after_merge() {
        let p = || vec!["1".to_string(), "2".to_string()];
        let frames = vec![
            (0.0, vec![]),
            (0.1, vec![p()]),
            (0.2, vec![p()]),
            (0.3, vec![]),
            (0.32, vec![p()]), // 120 ms after 0.2: a new collision with merge 0.05
            (0.33, vec![]),
            (0.35, vec![p()]), // 30 ms after: chatter
        ];
        let got: Vec<f64> = begins(frames, 0.05).into_iter().map(|(t, _)| t).collect();
        assert_eq!(got, [0.1, 0.32]);
    }
}
