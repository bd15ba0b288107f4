//! Narrow phase: the contact points between two shapes in Chipmunk's form — a normal pointing from the
//! first shape to the second, and for each point the surface point on either shape plus a hash that
//! identifies the point across steps (for warm starting).
//!
//! Circle–circle and circle–segment give one contact on the line between the closest points (hash 0).
//! Segment–segment runs Chipmunk's GJK on the two cores (from the pair's cached closest features when it
//! has them, else from the axis across the two boxes' centres), with its EPA when the cores cross, then
//! clips each capsule's support edge against the other's and keeps up to two points that overlap —
//! the same operations in the same order as `cpCollision.c`, so the same floating-point results.

use crate::shape::{Bb, Cached, fmax, fmin};
use crate::vect::Vect;

/// Chipmunk's hash multiplier.
const HASH_COEF: u64 = 3_344_921_057;

/// Chipmunk's symmetric pair hash.
pub(crate) fn hash_pair(a: u64, b: u64) -> u64 {
    a.wrapping_mul(HASH_COEF) ^ b.wrapping_mul(HASH_COEF)
}

/// One contact point as found: the surface points on shape a and shape b (world coordinates).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RawContact {
    pub p1: Vect,
    pub p2: Vect,
    pub hash: u64,
}

/// The contacts of one shape pair: the normal (from a to b) and up to two points.
#[derive(Debug, Clone, Default)]
pub(crate) struct Manifold {
    pub n: Vect,
    pub points: Vec<RawContact>,
}

/// The contacts between `a` and `b`, whose hash ids are `ha` and `hb`. Circles must come first. `id` is
/// the pair's collision id (the closest features found last step, 0 for none), which segment pairs
/// start their closest-point search from and update.
pub(crate) fn collide(a: &Cached, ha: u64, b: &Cached, hb: u64, id: &mut u32) -> Manifold {
    match (a, b) {
        (&Cached::Circle { c: c1, r: r1 }, &Cached::Circle { c: c2, r: r2 }) => {
            circle_circle(c1, r1, c2, r2)
        }
        (&Cached::Circle { c, r }, &Cached::Segment { a, b, n, r: sr }) => {
            circle_segment(c, r, a, b, n, sr)
        }
        (&Cached::Segment { .. }, &Cached::Circle { .. }) => {
            unreachable!("collide: the circle must be the first shape")
        }
        (s1 @ &Cached::Segment { .. }, s2 @ &Cached::Segment { .. }) => {
            segment_segment(s1, ha, s2, hb, id)
        }
    }
}

fn circle_circle(c1: Vect, r1: f64, c2: Vect, r2: f64) -> Manifold {
    let mindist = r1 + r2;
    let delta = c2 - c1;
    let distsq = delta.length_sq();
    let mut m = Manifold::default();
    if distsq < mindist * mindist {
        let dist = distsq.sqrt();
        let n = if dist != 0.0 {
            delta * (1.0 / dist)
        } else {
            Vect::new(1.0, 0.0)
        };
        m.n = n;
        m.points.push(RawContact {
            p1: c1 + n * r1,
            p2: c2 + n * -r2,
            hash: 0,
        });
    }
    m
}

fn circle_segment(centre: Vect, r: f64, sa: Vect, sb: Vect, sn: Vect, sr: f64) -> Manifold {
    let seg_delta = sb - sa;
    // A zero-length segment gives NaN here, which Chipmunk's clamp maps to 1.
    let t = clamp01(seg_delta.dot(centre - sa) / seg_delta.length_sq());
    let closest = sa + seg_delta * t;
    let mindist = r + sr;
    let delta = closest - centre;
    let distsq = delta.length_sq();
    let mut m = Manifold::default();
    if distsq < mindist * mindist {
        let dist = distsq.sqrt();
        let n = if dist != 0.0 {
            delta * (1.0 / dist)
        } else {
            sn
        };
        m.n = n;
        m.points.push(RawContact {
            p1: centre + n * r,
            p2: closest + n * -sr,
            hash: 0,
        });
    }
    m
}

/// Chipmunk's bounds on the closest-point searches.
const MAX_GJK_ITERATIONS: u32 = 30;
const MAX_EPA_ITERATIONS: u32 = 30;

/// Chipmunk's `cpfclamp`.
fn clamp(f: f64, lo: f64, hi: f64) -> f64 {
    fmin(fmax(f, lo), hi)
}

/// Chipmunk's `cpfclamp01`.
fn clamp01(f: f64) -> f64 {
    fmax(0.0, fmin(f, 1.0))
}

/// Whether `c` lies on the positive side of the line through `a` and `b` (Chipmunk's robust form).
fn point_greater(a: Vect, b: Vect, c: Vect) -> bool {
    (b.y - a.y) * (a.x + b.x - 2.0 * c.x) > (b.x - a.x) * (a.y + b.y - 2.0 * c.y)
}

/// Whether `p` is no further along `n` than the edge `v0`–`v1`.
fn check_axis(v0: Vect, v1: Vect, p: Vect, n: Vect) -> bool {
    p.dot(n) <= fmax(v0.dot(n), v1.dot(n))
}

/// The parameter in [−1, 1] of the point of segment `a`–`b` closest to the origin.
fn closest_t(a: Vect, b: Vect) -> f64 {
    let delta = b - a;
    let d2 = delta.length_sq();
    if d2 != 0.0 {
        -clamp(delta.dot(a + b) / d2, -1.0, 1.0)
    } else {
        0.0
    }
}

/// `a` at t = −1, `b` at t = 1.
fn lerp_t(a: Vect, b: Vect, t: f64) -> Vect {
    let ht = 0.5 * t;
    a * (0.5 - ht) + b * (0.5 + ht)
}

/// Squared distance from the origin to segment `a`–`b`.
fn closest_dist(a: Vect, b: Vect) -> f64 {
    lerp_t(a, b, closest_t(a, b)).length_sq()
}

/// An end of a segment as a support point: its position and index (0 for `a`, 1 for `b`).
#[derive(Debug, Clone, Copy)]
struct SegmentCore {
    ta: Vect,
    tb: Vect,
}

impl SegmentCore {
    /// The end furthest along `n` (`b` on a tie).
    fn support(&self, n: Vect) -> (Vect, u32) {
        if self.ta.dot(n) > self.tb.dot(n) {
            (self.ta, 0)
        } else {
            (self.tb, 1)
        }
    }

    fn point(&self, i: u32) -> (Vect, u32) {
        if i == 0 { (self.ta, 0) } else { (self.tb, i) }
    }
}

/// A point of the Minkowski difference (shape 2 − shape 1) with the support points it came from.
#[derive(Debug, Clone, Copy)]
struct MinkowskiPoint {
    a: Vect,
    b: Vect,
    ab: Vect,
    id: u32,
}

impl MinkowskiPoint {
    fn new((a, ia): (Vect, u32), (b, ib): (Vect, u32)) -> MinkowskiPoint {
        MinkowskiPoint {
            a,
            b,
            ab: b - a,
            id: ((ia & 0xFF) << 8) | (ib & 0xFF),
        }
    }
}

/// The closest points of two shapes' cores, the separating axis and their signed distance.
#[derive(Debug, Clone, Copy)]
struct ClosestPoints {
    a: Vect,
    b: Vect,
    n: Vect,
    d: f64,
    id: u32,
}

struct Gjk {
    s1: SegmentCore,
    s2: SegmentCore,
}

impl Gjk {
    fn support(&self, n: Vect) -> MinkowskiPoint {
        MinkowskiPoint::new(self.s1.support(-n), self.s2.support(n))
    }

    fn closest_points(v0: MinkowskiPoint, v1: MinkowskiPoint) -> ClosestPoints {
        let t = closest_t(v0.ab, v1.ab);
        let p = lerp_t(v0.ab, v1.ab, t);
        let pa = lerp_t(v0.a, v1.a, t);
        let pb = lerp_t(v0.b, v1.b, t);
        let id = ((v0.id & 0xFFFF) << 16) | (v1.id & 0xFFFF);
        let n = (v1.ab - v0.ab).rperp().normalize();
        let d = n.dot(p);
        if d <= 0.0 || (-1.0 < t && t < 1.0) {
            ClosestPoints {
                a: pa,
                b: pb,
                n,
                d,
                id,
            }
        } else {
            // Vertex against vertex: the axis is the line between them.
            let d2 = p.length();
            ClosestPoints {
                a: pa,
                b: pb,
                n: p * (1.0 / (d2 + f64::MIN_POSITIVE)),
                d: d2,
                id,
            }
        }
    }

    /// Expands the hull (which holds the origin) towards the difference's edge nearest to the origin.
    fn epa(&self, hull: &[MinkowskiPoint], iteration: u32) -> ClosestPoints {
        let count = hull.len();
        let mut mini = 0;
        let mut min_dist = f64::INFINITY;
        let mut i = count - 1;
        for j in 0..count {
            let d = closest_dist(hull[i].ab, hull[j].ab);
            if d < min_dist {
                min_dist = d;
                mini = i;
            }
            i = j;
        }
        let v0 = hull[mini];
        let v1 = hull[(mini + 1) % count];
        let p = self.support((v1.ab - v0.ab).perp());
        let duplicate = p.id == v0.id || p.id == v1.id;
        if !duplicate && point_greater(v0.ab, v1.ab, p.ab) && iteration < MAX_EPA_ITERATIONS {
            let mut hull2 = Vec::with_capacity(count + 1);
            hull2.push(p);
            for i in 0..count {
                let index = (mini + 1 + i) % count;
                let h0 = hull2[hull2.len() - 1].ab;
                let h1 = hull[index].ab;
                let h2 = if i + 1 < count {
                    hull[(index + 1) % count].ab
                } else {
                    p.ab
                };
                if point_greater(h0, h2, h1) {
                    hull2.push(hull[index]);
                }
            }
            self.epa(&hull2, iteration + 1)
        } else {
            Self::closest_points(v0, v1)
        }
    }

    fn recurse(&self, v0: MinkowskiPoint, v1: MinkowskiPoint, iteration: u32) -> ClosestPoints {
        if iteration > MAX_GJK_ITERATIONS {
            return Self::closest_points(v0, v1);
        }
        if point_greater(v1.ab, v0.ab, Vect::ZERO) {
            // The origin is behind the edge: flip it.
            return self.recurse(v1, v0, iteration);
        }
        let t = closest_t(v0.ab, v1.ab);
        let n = if -1.0 < t && t < 1.0 {
            (v1.ab - v0.ab).perp()
        } else {
            -lerp_t(v0.ab, v1.ab, t)
        };
        let p = self.support(n);
        if point_greater(p.ab, v0.ab, Vect::ZERO) && point_greater(v1.ab, p.ab, Vect::ZERO) {
            // The triangle v0, p, v1 holds the origin: the cores overlap.
            self.epa(&[v0, p, v1], 1)
        } else if check_axis(v0.ab, v1.ab, p.ab, n) {
            Self::closest_points(v0, v1)
        } else if closest_dist(v0.ab, p.ab) < closest_dist(p.ab, v1.ab) {
            self.recurse(v0, p, iteration + 1)
        } else {
            self.recurse(p, v1, iteration + 1)
        }
    }

    /// The closest points, starting from the support points named by `id` (last step's result for this
    /// pair) or, with no id, from the axis across the two boxes' centres; `id` becomes this result's.
    fn run(&self, bb1: Bb, bb2: Bb, id: &mut u32) -> ClosestPoints {
        let (v0, v1) = if *id != 0 {
            (
                MinkowskiPoint::new(
                    self.s1.point((*id >> 24) & 0xFF),
                    self.s2.point((*id >> 16) & 0xFF),
                ),
                MinkowskiPoint::new(self.s1.point((*id >> 8) & 0xFF), self.s2.point(*id & 0xFF)),
            )
        } else {
            let axis = (bb1.center() - bb2.center()).perp();
            (self.support(axis), self.support(-axis))
        };
        let points = self.recurse(v0, v1, 1);
        *id = points.id;
        points
    }
}

/// A capsule's support edge along `n`: its two ends (with their hashes) ordered along its outward normal.
fn support_edge(a: Vect, b: Vect, sn: Vect, hash_id: u64, n: Vect) -> [(Vect, u64); 2] {
    if sn.dot(n) > 0.0 {
        [(a, hash_pair(hash_id, 0)), (b, hash_pair(hash_id, 1))]
    } else {
        [(b, hash_pair(hash_id, 1)), (a, hash_pair(hash_id, 0))]
    }
}

fn segment_segment(s1: &Cached, h1: u64, s2: &Cached, h2: u64, id: &mut u32) -> Manifold {
    let (
        &Cached::Segment {
            a: a1,
            b: b1,
            n: n1,
            r: r1,
        },
        &Cached::Segment {
            a: a2,
            b: b2,
            n: n2,
            r: r2,
        },
    ) = (s1, s2)
    else {
        unreachable!("segment_segment on non-segments")
    };
    let gjk = Gjk {
        s1: SegmentCore { ta: a1, tb: b1 },
        s2: SegmentCore { ta: a2, tb: b2 },
    };
    let points = gjk.run(s1.bb(), s2.bb(), id);
    let n = points.n;
    let mut m = Manifold::default();
    // Chipmunk rejects a contact at a segment's end against the segment's end tangent; I-PHYRE's
    // segments have zero tangents, which reject nothing unless the axis is not finite.
    let z = n.dot(Vect::ZERO);
    let tangents_pass = z == 0.0;
    let at_end_1 = points.a == a1 || points.a == b1;
    let at_end_2 = points.b == a2 || points.b == b2;
    if !(points.d <= r1 + r2 && (!at_end_1 || tangents_pass) && (!at_end_2 || tangents_pass)) {
        return m;
    }
    let e1 = support_edge(a1, b1, n1, h1, n);
    let e2 = support_edge(a2, b2, n2, h2, -n);
    m.n = n;
    let (d1a, d1b) = (e1[0].0.cross(n), e1[1].0.cross(n));
    let (d2a, d2b) = (e2[0].0.cross(n), e2[1].0.cross(n));
    let den1 = 1.0 / (d1b - d1a + f64::MIN_POSITIVE);
    let den2 = 1.0 / (d2b - d2a + f64::MIN_POSITIVE);
    // Each end of one edge projected onto the other, clamped to it; kept where the surfaces overlap.
    let candidates = [
        (
            clamp01((d2b - d1a) * den1),
            clamp01((d1a - d2a) * den2),
            hash_pair(e1[0].1, e2[1].1),
        ),
        (
            clamp01((d2a - d1a) * den1),
            clamp01((d1b - d2a) * den2),
            hash_pair(e1[1].1, e2[0].1),
        ),
    ];
    for (t1, t2, hash) in candidates {
        let p1 = n * r1 + e1[0].0.lerp(e1[1].0, t1);
        let p2 = n * -r2 + e2[0].0.lerp(e2[1].0, t2);
        if (p2 - p1).dot(n) <= 0.0 {
            m.points.push(RawContact { p1, p2, hash });
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(a: Vect, b: Vect, r: f64) -> Cached {
        Cached::Segment {
            a,
            b,
            n: (b - a).normalize().rperp(),
            r,
        }
    }

    #[test]
    fn a_bar_on_a_bar_touches_at_both_overlapping_ends() {
        let lower = seg(Vect::new(0.0, 0.0), Vect::new(100.0, 0.0), 10.0);
        let upper = seg(Vect::new(50.0, -19.0), Vect::new(150.0, -19.0), 10.0);
        let m = collide(&upper, 1, &lower, 2, &mut 0);
        assert_eq!(m.points.len(), 2);
        assert!((m.n.y - 1.0).abs() < 1e-12, "{:?}", m.n);
        let mut xs: Vec<f64> = m.points.iter().map(|c| c.p1.x).collect();
        xs.sort_by(f64::total_cmp);
        assert!(
            (xs[0] - 50.0).abs() < 1e-9 && (xs[1] - 100.0).abs() < 1e-9,
            "{xs:?}"
        );
        for c in &m.points {
            assert!(((c.p2 - c.p1).dot(m.n) + 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn crossing_cores_are_pushed_apart_along_the_shorter_axis() {
        let a = seg(Vect::new(0.0, 0.0), Vect::new(100.0, 0.0), 10.0);
        let b = seg(Vect::new(50.0, -2.0), Vect::new(50.0, 40.0), 10.0);
        let m = collide(&a, 1, &b, 2, &mut 0);
        assert!(!m.points.is_empty());
        // Moving b by 2 px + radii down... the least penetration is along +y (2 px to clear the core).
        assert!((m.n.y - 1.0).abs() < 1e-12, "{:?}", m.n);
    }

    #[test]
    fn a_ball_touches_a_segment_end_from_the_side() {
        let s = seg(Vect::new(0.0, 0.0), Vect::new(100.0, 0.0), 10.0);
        let c = Cached::Circle {
            c: Vect::new(115.0, 0.0),
            r: 10.0,
        };
        let m = collide(&c, 1, &s, 2, &mut 0);
        assert_eq!(m.points.len(), 1);
        assert!((m.n.x + 1.0).abs() < 1e-12);
        let far = Cached::Circle {
            c: Vect::new(121.0, 0.0),
            r: 10.0,
        };
        assert!(collide(&far, 1, &s, 2, &mut 0).points.is_empty());
    }
}
