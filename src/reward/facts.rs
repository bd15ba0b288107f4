//! The annotated trace a reward program reads: the library's pattern occurrences by label, plus the
//! facts the environment knows from the trace itself (billiards: the first ball the cue ball hits),
//! object lookup by colour and shape, and positions at a normalised time.

use std::collections::HashMap;

use serde_json::{Map, Value};

use super::error::{ErrorCategory, Pos, RewardError};
use crate::detect::{Annotation, normalise_label};
use crate::trace::{Body, Env, Event, Trace};

/// One occurrence of a pattern or built-in event.
#[derive(Debug, Clone, PartialEq)]
pub struct Occurrence {
    /// Start time (s): the time of its first timestep.
    pub t0: f64,
    /// End time (s).
    pub t1: f64,
    /// The objects it names; the first is its subject (`ball=`).
    pub objects: Vec<String>,
    /// Its parameters.
    pub params: Map<String, Value>,
}

/// A trace with its annotations, ready for evaluation.
#[derive(Debug)]
pub struct AnnotatedTrace<'a> {
    /// The trace.
    pub trace: &'a Trace,
    by_label: HashMap<String, Vec<Occurrence>>,
    cue_hit: Option<(String, Occurrence)>,
    pockets: Vec<(String, String, Occurrence)>,
}

/// Unit length of `NEARBY_AT` thresholds per environment: `threshold_strength × scale` is the radius.
/// PHYRE scenes are 256 px wide, I-PHYRE screens 600 px; billiards positions are table metres, so a
/// threshold of 0.1 is 10 cm.
pub fn nearby_scale(env: Env) -> f64 {
    crate::envs::facts(env).nearby_scale
}

/// The time of the last timestep at or before `t` (the first timestep's time when `t` is earlier):
/// how the detectors place an instant on the trace's clock.
fn snap(trace: &Trace, t: f64) -> f64 {
    let i = trace.timesteps.partition_point(|s| s.t <= t);
    trace
        .timesteps
        .get(i.saturating_sub(1))
        .map(|s| s.t)
        .unwrap_or(t)
}

impl<'a> AnnotatedTrace<'a> {
    /// Indexes `annotations` (those of other traces are ignored) and derives the built-in facts.
    pub fn new<'b>(
        trace: &'a Trace,
        annotations: impl IntoIterator<Item = &'b Annotation>,
    ) -> Self {
        let mut by_label: HashMap<String, Vec<Occurrence>> = HashMap::new();
        for a in annotations {
            if a.trace_id != trace.trace_id {
                continue;
            }
            by_label
                .entry(normalise_label(&a.label))
                .or_default()
                .push(Occurrence {
                    t0: a.t_start,
                    t1: a.t_end,
                    objects: a.objects.clone(),
                    params: a.parameters.clone(),
                });
        }
        for v in by_label.values_mut() {
            v.sort_by(|x, y| x.t0.total_cmp(&y.t0));
        }
        let cue_hit = if trace.env == Env::Pooltool {
            first_cue_contact(trace).or_else(|| {
                // No event log: the earliest annotated collision that involves the cue ball.
                let cue = cue_ball(trace);
                by_label.get("ball collision").and_then(|v| {
                    v.iter().find(|o| o.objects.contains(&cue)).and_then(|o| {
                        let other = o.objects.iter().find(|x| **x != cue)?.clone();
                        Some((other, o.clone()))
                    })
                })
            })
        } else {
            None
        };
        let pockets = if trace.env == Env::Pooltool {
            pocket_drops(trace)
        } else {
            Vec::new()
        };
        AnnotatedTrace {
            trace,
            by_label,
            cue_hit,
            pockets,
        }
    }

    /// Occurrences of a (canonical) label, in start order.
    pub fn occurrences(&self, label: &str) -> &[Occurrence] {
        self.by_label
            .get(&normalise_label(label))
            .map(Vec::as_slice)
            .unwrap_or(&[])
    }

    /// The first ball the cue ball touches, and that contact as an occurrence.
    pub fn cue_hit(&self) -> Option<&(String, Occurrence)> {
        self.cue_hit.as_ref()
    }

    /// Balls that dropped, in time order: (ball, pocket, the drop as an occurrence).
    pub fn pockets(&self) -> &[(String, String, Occurrence)] {
        &self.pockets
    }

    /// The id of the object of `color` and `shape` in the trace's first timestep (the first of
    /// [`AnnotatedTrace::object_ids`]).
    pub fn object_id(&self, color: &str, shape: &str, pos: Pos) -> Result<String, RewardError> {
        Ok(self.object_ids(color, shape, pos)?.remove(0))
    }

    /// Every object of `color` and `shape` in the trace's first timestep, in trace order (at least
    /// one, else a runtime error). A shape of `object` (or `any`, `*`) matches every shape; PHYRE and
    /// I-PHYRE colours may list alternatives (`"blue|purple"`). Billiards
    /// gives one ball: the solid of that colour when present, else the stripe.
    pub fn object_ids(
        &self,
        color: &str,
        shape: &str,
        pos: Pos,
    ) -> Result<Vec<String>, RewardError> {
        let color = color.trim().to_lowercase();
        let shape = shape.trim().to_lowercase();
        let first = self.trace.timesteps.first().map(|t| t.objects.as_slice());
        let present = |id: &str| {
            first
                .into_iter()
                .flatten()
                .any(|o| o.body.object_id() == id)
        };
        let found: Vec<String> = match self.trace.env {
            Env::Pooltool => pool_ball_of(&color, &shape)
                .into_iter()
                .find(|id| present(id))
                .map(str::to_string)
                .into_iter()
                .collect(),
            _ => first
                .into_iter()
                .flatten()
                .filter_map(|o| match &o.body {
                    Body::Phyre(p) => (color
                        .split('|')
                        .any(|c| colour_eq(&p.color.to_lowercase(), c.trim()))
                        && shape_matches(&p.shape, &shape))
                    .then(|| o.body.object_id()),
                    Body::Iphyre(p) => {
                        let is_ball = p.x1 == p.x2 && p.y1 == p.y2;
                        let c = if is_ball {
                            "red"
                        } else if p.eliminable > 0.5 {
                            "gray"
                        } else if p.dynamic > 0.5 {
                            "blue"
                        } else {
                            "black"
                        };
                        let s = if is_ball { "ball" } else { "block" };
                        (color.split('|').any(|w| colour_eq(c, w.trim()))
                            && shape_matches(s, &shape))
                        .then(|| o.body.object_id())
                    }
                    Body::Pool(_) => None,
                })
                .collect(),
        };
        if !found.is_empty() {
            return Ok(found);
        }
        Err({
            RewardError::new(
                ErrorCategory::Runtime,
                pos,
                format!(
                    "OBJECT_ID: no {color} {shape} in trace {} ({})",
                    self.trace.trace_id, self.trace.env
                ),
            )
        })
    }

    /// The smallest gap (environment units, 0 when touching or overlapping) between the outlines of
    /// an object of `a` and a different object of `b` over the trace's timesteps ([`outline_gap`]);
    /// infinite when both exist but never as two different objects. A runtime error when the trace
    /// holds no object of `a` or none of `b` with an outline.
    pub fn min_gap(&self, a: &[String], b: &[String], pos: Pos) -> Result<f64, RewardError> {
        let mut best: Option<f64> = None;
        let (mut seen_a, mut seen_b) = (false, false);
        for step in &self.trace.timesteps {
            let find = |ids: &[String]| -> Vec<(String, Capsule)> {
                step.objects
                    .iter()
                    .filter_map(|o| {
                        let id = o.body.object_id();
                        if !ids.contains(&id) {
                            return None;
                        }
                        capsule(&o.body).map(|c| (id, c))
                    })
                    .collect()
            };
            let (xs, ys) = (find(a), find(b));
            seen_a |= !xs.is_empty();
            seen_b |= !ys.is_empty();
            for (ia, ca) in &xs {
                for (ib, cb) in &ys {
                    if ia != ib {
                        let g = outline_gap(ca, cb);
                        best = Some(best.map_or(g, |x: f64| x.min(g)));
                    }
                }
            }
        }
        if best.is_none() && seen_a && seen_b {
            // Both exist, but never as two different objects (one red ball asked to meet a red
            // ball): they never come near.
            return Ok(f64::INFINITY);
        }
        best.ok_or_else(|| {
            RewardError::new(
                ErrorCategory::Runtime,
                pos,
                format!(
                    "NEAR: no object {a:?} or {b:?} with an outline in trace {}",
                    self.trace.trace_id
                ),
            )
        })
    }
}

/// An object's outline as a capsule: the segment from `p` to `q` thickened by `r`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capsule {
    /// One end of the core segment.
    pub p: [f64; 2],
    /// The other end.
    pub q: [f64; 2],
    /// The thickness around it.
    pub r: f64,
}

/// PHYRE bars are 5.12 px thick (`docs/envs/phyre.md`).
const PHYRE_BAR_THICKNESS: f64 = 5.12;

/// The outline of a body as a capsule: billiards balls and PHYRE balls are circles, I-PHYRE blocks
/// and balls are capsules already (balls have equal ends), a PHYRE bar is its segment of length
/// √(diameter² − 5.12²) thickened by half its 5.12 px; a PHYRE jar is approximated by the circle of
/// its diameter around its position. PHYRE walls (and any other shape) have none.
pub fn capsule(body: &Body) -> Option<Capsule> {
    match body {
        Body::Pool(b) => {
            let c = [b.position[0], b.position[1]];
            Some(Capsule {
                p: c,
                q: c,
                r: b.radius,
            })
        }
        Body::Phyre(o) => {
            let c = [o.x, o.y];
            match o.shape.to_ascii_lowercase().as_str() {
                "ball" | "jar" => Some(Capsule {
                    p: c,
                    q: c,
                    r: o.diameter / 2.0,
                }),
                "bar" => {
                    let half = (o.diameter.powi(2) - PHYRE_BAR_THICKNESS.powi(2))
                        .max(0.0)
                        .sqrt()
                        / 2.0;
                    let (s, k) = o.angle.sin_cos();
                    Some(Capsule {
                        p: [c[0] - half * k, c[1] - half * s],
                        q: [c[0] + half * k, c[1] + half * s],
                        r: PHYRE_BAR_THICKNESS / 2.0,
                    })
                }
                _ => None,
            }
        }
        Body::Iphyre(o) => Some(Capsule {
            p: [o.x1, o.y1],
            q: [o.x2, o.y2],
            r: o.radius,
        }),
    }
}

/// The gap between two capsules: the distance between their core segments less both thicknesses,
/// 0 when they touch or overlap.
pub fn outline_gap(a: &Capsule, b: &Capsule) -> f64 {
    (segment_distance(a.p, a.q, b.p, b.q) - a.r - b.r).max(0.0)
}

fn point_segment(x: [f64; 2], p: [f64; 2], q: [f64; 2]) -> f64 {
    let d = [q[0] - p[0], q[1] - p[1]];
    let l2 = d[0] * d[0] + d[1] * d[1];
    let u = if l2 <= 0.0 {
        0.0
    } else {
        (((x[0] - p[0]) * d[0] + (x[1] - p[1]) * d[1]) / l2).clamp(0.0, 1.0)
    };
    (p[0] + u * d[0] - x[0]).hypot(p[1] + u * d[1] - x[1])
}

fn segment_distance(p1: [f64; 2], q1: [f64; 2], p2: [f64; 2], q2: [f64; 2]) -> f64 {
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let (d1, d2) = (cross(p2, q2, p1), cross(p2, q2, q1));
    let (d3, d4) = (cross(p1, q1, p2), cross(p1, q1, q2));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return 0.0;
    }
    point_segment(p1, p2, q2)
        .min(point_segment(q1, p2, q2))
        .min(point_segment(p2, p1, q1))
        .min(point_segment(q2, p1, q1))
}

impl AnnotatedTrace<'_> {
    /// The planar position of object `id` at normalised time `t` in [0, 1] (the last timestep at or
    /// before that instant).
    pub fn position_at(&self, id: &str, t: f64, pos: Pos) -> Result<(f64, f64), RewardError> {
        let steps = &self.trace.timesteps;
        let missing = || {
            RewardError::new(
                ErrorCategory::Runtime,
                pos,
                format!(
                    "NEARBY_AT: no object {id:?} in trace {}",
                    self.trace.trace_id
                ),
            )
        };
        let (Some(a), Some(b)) = (steps.first(), steps.last()) else {
            return Err(missing());
        };
        let at = a.t + t.clamp(0.0, 1.0) * (b.t - a.t);
        let i = steps
            .partition_point(|s| s.t <= at + 1e-9)
            .saturating_sub(1);
        steps[i]
            .objects
            .iter()
            .find(|o| o.body.object_id() == id)
            .map(|o| o.body.centre())
            .ok_or_else(missing)
    }
}

fn colour_eq(a: &str, b: &str) -> bool {
    let n = |s: &str| {
        if s == "grey" {
            "gray".to_string()
        } else {
            s.to_string()
        }
    };
    n(a) == n(b)
}

fn shape_matches(have: &str, want: &str) -> bool {
    if matches!(want, "object" | "any" | "*") {
        return true;
    }
    let canon = |s: &str| match s {
        "circle" | "ball" | "disc" => "ball".to_string(),
        "bar" | "block" | "rod" | "stick" | "rectangle" => "block".to_string(),
        other => other.to_string(),
    };
    canon(&have.to_lowercase()) == canon(want)
}

/// Pool ball ids by colour: solids 1–8 (yellow, blue, red, purple, orange, green, brown, black) and
/// stripes 9–15 in the same colour order; the cue ball is white. A shape of `stripe` picks the
/// striped ball, anything else the solid first.
fn pool_ball_of(color: &str, shape: &str) -> Vec<&'static str> {
    const SOLIDS: [(&str, &str, Option<&str>); 8] = [
        ("yellow", "1", Some("9")),
        ("blue", "2", Some("10")),
        ("red", "3", Some("11")),
        ("purple", "4", Some("12")),
        ("orange", "5", Some("13")),
        ("green", "6", Some("14")),
        ("brown", "7", Some("15")),
        ("black", "8", None),
    ];
    let color = match color {
        "maroon" | "burgundy" => "brown",
        "violet" => "purple",
        c => c,
    };
    if color == "white" {
        return vec!["cue"];
    }
    let Some((_, solid, stripe)) = SOLIDS.iter().find(|(c, _, _)| *c == color) else {
        return Vec::new();
    };
    if shape.contains("stripe") {
        stripe.iter().copied().collect()
    } else {
        std::iter::once(*solid).chain(*stripe).collect()
    }
}

/// The cue ball's id (from the `shot_prepared` event; `cue` when absent).
pub fn cue_ball(trace: &Trace) -> String {
    cue_ball_in(&trace.events)
}

/// The cue ball named by the `shot_prepared` event of `events` (`"cue"` without one).
pub fn cue_ball_in(events: &[Event]) -> String {
    events
        .iter()
        .find(|e| e.kind == "shot_prepared")
        .and_then(|e| {
            e.payload
                .as_ref()?
                .get("cue_ball")?
                .as_str()
                .map(str::to_string)
        })
        .unwrap_or_else(|| "cue".to_string())
}

/// The first `physics_ball_ball` event involving the cue ball: the other ball and the contact.
fn first_cue_contact(trace: &Trace) -> Option<(String, Occurrence)> {
    let cue = cue_ball(trace);
    let mut contacts: Vec<(f64, String)> = trace
        .events
        .iter()
        .filter(|e| e.kind == "physics_ball_ball")
        .filter_map(|e| {
            let t = e.t?;
            let agents = e.payload.as_ref()?.get("agents")?.as_array()?;
            let ids: Vec<&str> = agents.iter().filter_map(Value::as_str).collect();
            if ids.len() == 2 && ids.contains(&cue.as_str()) {
                let other = ids.iter().find(|x| **x != cue)?;
                Some((t, other.to_string()))
            } else {
                None
            }
        })
        .collect();
    contacts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (t, other) = contacts.into_iter().next()?;
    let t0 = snap(trace, t);
    let mut params = Map::new();
    params.insert("t".into(), Value::from(t));
    Some((
        other.clone(),
        Occurrence {
            t0,
            t1: t0,
            objects: vec![cue, other],
            params,
        },
    ))
}

/// Every `physics_ball_pocket` event: (ball, pocket, the drop placed on the timestep clock).
fn pocket_drops(trace: &Trace) -> Vec<(String, String, Occurrence)> {
    let mut out: Vec<(String, String, Occurrence)> = trace
        .events
        .iter()
        .filter(|e| e.kind == "physics_ball_pocket")
        .filter_map(|e| {
            let t = e.t?;
            let agents = e.payload.as_ref()?.get("agents")?.as_array()?;
            let ball = agents.first()?.as_str()?.to_string();
            let pocket = agents.get(1)?.as_str()?.to_string();
            let t0 = snap(trace, t);
            let mut params = Map::new();
            params.insert("t".into(), Value::from(t));
            params.insert("pocket".into(), Value::from(pocket.clone()));
            Some((
                ball.clone(),
                pocket.clone(),
                Occurrence {
                    t0,
                    t1: t0,
                    objects: vec![ball, pocket],
                    params,
                },
            ))
        })
        .collect();
    out.sort_by(|a, b| a.2.t0.total_cmp(&b.2.t0));
    out
}
