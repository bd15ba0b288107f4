//! Narrow phase: the contact points between two shapes in Chipmunk's form — a normal pointing from the
//! first shape to the second, and for each point the surface point on either shape plus a hash that
//! identifies the point across steps (for warm starting).
//!
//! Circle–circle and circle–segment give one contact on the line between the closest points (hash 0).
//! Segment–segment finds the two cores' closest points (or, when the cores cross, the least-penetration
//! axis among the two segments' normals, which is where an expanding-polytope search on the Minkowski
//! difference of two segments ends), then clips each capsule's support edge against the other's and
//! keeps up to two points that overlap.

use crate::shape::Cached;
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

/// The contacts between `a` and `b`, whose hash ids are `ha` and `hb`. Circles must come first.
pub(crate) fn collide(a: &Cached, ha: u64, b: &Cached, hb: u64) -> Manifold {
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
            segment_segment(s1, ha, s2, hb)
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
    let t = (seg_delta.dot(centre - sa) / seg_delta.length_sq()).clamp(0.0, 1.0);
    // A zero-length segment gives NaN above; Chipmunk's clamp maps it to its lower bound.
    let t = if t.is_nan() { 0.0 } else { t };
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

/// The closest point to the origin on segment `a`–`b`, parametrised over [−1, 1] (Chipmunk's form).
fn closest_t(a: Vect, b: Vect) -> f64 {
    let delta = b - a;
    -(delta.dot(a + b) / (delta.length_sq() + f64::MIN_POSITIVE)).clamp(-1.0, 1.0)
}

/// `a` at t = −1, `b` at t = 1.
fn lerp_t(a: Vect, b: Vect, t: f64) -> Vect {
    let ht = 0.5 * t;
    a * (0.5 - ht) + b * (0.5 + ht)
}

/// The separating axis (from segment 1 towards segment 2) and the signed distance between the two
/// segments' cores (negative when they cross).
fn core_axis(a1: Vect, b1: Vect, n1: Vect, a2: Vect, b2: Vect, n2: Vect) -> (Vect, f64) {
    // The Minkowski difference (segment 2 − segment 1) is a parallelogram with corners q[i].
    let q = [a2 - a1, a2 - b1, b2 - b1, b2 - a1];
    let edges = [(q[0], q[1]), (q[1], q[2]), (q[2], q[3]), (q[3], q[0])];
    let inside = {
        // The origin is inside when it is on the same side of every edge.
        let s: Vec<f64> = edges.iter().map(|(u, v)| (*v - *u).cross(-*u)).collect();
        s.iter().all(|&x| x > 0.0) || s.iter().all(|&x| x < 0.0)
    };
    if !inside {
        // The closest point of the parallelogram to the origin lies on one of its edges.
        let mut best: Option<(f64, Vect, Vect, f64)> = None;
        for (u, v) in edges {
            let t = closest_t(u, v);
            let p = lerp_t(u, v, t);
            let d2 = p.length_sq();
            if best.is_none_or(|b| d2 < b.0) {
                best = Some((d2, u, v, t));
            }
        }
        let (_, u, v, t) = best.expect("four edges");
        let p = lerp_t(u, v, t);
        if -1.0 < t && t < 1.0 {
            // Vertex against edge: the axis is the edge's normal.
            let mut n = (v - u).rperp().normalize();
            if n.dot(p) < 0.0 {
                n = -n;
            }
            (n, n.dot(p))
        } else {
            let d = p.length();
            (p * (1.0 / (d + f64::MIN_POSITIVE)), d)
        }
    } else {
        // The cores cross: the least-penetration axis among ±n1, ±n2; the normal points against it.
        let mut best = (f64::INFINITY, n1);
        for u in [n1, -n1, n2, -n2] {
            let h = q.iter().map(|c| c.dot(u)).fold(f64::NEG_INFINITY, f64::max);
            if h < best.0 {
                best = (h, u);
            }
        }
        (-best.1, -best.0)
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

fn segment_segment(s1: &Cached, h1: u64, s2: &Cached, h2: u64) -> Manifold {
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
    let (n, d) = core_axis(a1, b1, n1, a2, b2, n2);
    let mut m = Manifold::default();
    if d > r1 + r2 {
        return m;
    }
    let e1 = support_edge(a1, b1, n1, h1, n);
    let e2 = support_edge(a2, b2, n2, h2, -n);
    m.n = n;
    let (d1a, d1b) = (e1[0].0.cross(n), e1[1].0.cross(n));
    let (d2a, d2b) = (e2[0].0.cross(n), e2[1].0.cross(n));
    let den1 = 1.0 / (d1b - d1a + f64::MIN_POSITIVE);
    let den2 = 1.0 / (d2b - d2a + f64::MIN_POSITIVE);
    let clamp01 = |x: f64| x.clamp(0.0, 1.0);
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
        let m = collide(&upper, 1, &lower, 2);
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
        let m = collide(&a, 1, &b, 2);
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
        let m = collide(&c, 1, &s, 2);
        assert_eq!(m.points.len(), 1);
        assert!((m.n.x + 1.0).abs() < 1e-12);
        let far = Cached::Circle {
            c: Vect::new(121.0, 0.0),
            r: 10.0,
        };
        assert!(collide(&far, 1, &s, 2).points.is_empty());
    }
}
