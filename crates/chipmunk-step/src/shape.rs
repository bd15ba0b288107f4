//! [`Shape`]: the collision shapes (circles and capsule segments), their world-space cache and their
//! bounding boxes.

use crate::vect::Vect;

/// The geometry of a shape, in its body's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Geometry {
    /// A disc of radius `r` centred at `offset`.
    Circle {
        /// Centre in body coordinates.
        offset: Vect,
        /// Radius.
        r: f64,
    },
    /// A capsule: all points within `r` of the segment `a`–`b`.
    Segment {
        /// First end in body coordinates.
        a: Vect,
        /// Second end in body coordinates.
        b: Vect,
        /// Radius.
        r: f64,
    },
}

/// A shape attached to a body, with its material and its world-space cache.
#[derive(Debug, Clone)]
pub struct Shape {
    /// The body index.
    pub body: usize,
    /// The geometry in body coordinates.
    pub geometry: Geometry,
    /// Friction coefficient (multiplied with the other shape's).
    pub friction: f64,
    /// Elasticity (multiplied with the other shape's).
    pub elasticity: f64,
    /// The shape's number in its space (Chipmunk's `hashid`: the count of shapes added before it),
    /// mixed into contact hashes and deciding where the spatial index keeps it.
    pub(crate) hash_id: u64,
    /// Whether the shape sits in the static index (its body was static when it was added).
    pub(crate) is_static: bool,
    /// World-space cache, refreshed after every position update.
    pub(crate) cache: Cached,
}

/// A shape in world coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Cached {
    Circle {
        c: Vect,
        r: f64,
    },
    Segment {
        a: Vect,
        b: Vect,
        /// Unit normal (the segment direction turned by −90°).
        n: Vect,
        r: f64,
    },
}

/// 0.1 as Chipmunk writes it (`0.1f`, a single-precision literal): 0.100000001490116…
pub(crate) const TENTH_F32: f64 = 0.1f32 as f64;

/// Chipmunk's `cpfmin`: `a` when `a < b`, else `b`.
pub(crate) fn fmin(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
}

/// Chipmunk's `cpfmax`: `a` when `a > b`, else `b`.
pub(crate) fn fmax(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// An axis-aligned box (left, bottom, right, top).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Bb {
    pub l: f64,
    pub b: f64,
    pub r: f64,
    pub t: f64,
}

impl Bb {
    /// Whether `o` lies inside this box.
    pub(crate) fn contains(&self, o: &Bb) -> bool {
        self.l <= o.l && self.r >= o.r && self.b <= o.b && self.t >= o.t
    }

    /// The box a Chipmunk tree keeps for a shape with this box moving at `v`: grown on every side by a
    /// tenth (`0.1f`) of its size, or on the side it moves to by its velocity over a tenth of a time unit if that
    /// is more.
    pub(crate) fn grown(&self, v: Vect) -> Bb {
        let x = (self.r - self.l) * TENTH_F32;
        let y = (self.t - self.b) * TENTH_F32;
        let v = v * TENTH_F32;
        Bb {
            l: self.l + fmin(-x, v.x),
            b: self.b + fmin(-y, v.y),
            r: self.r + fmax(x, v.x),
            t: self.t + fmax(y, v.y),
        }
    }

    /// Whether two boxes touch or overlap.
    pub(crate) fn intersects(&self, o: &Bb) -> bool {
        self.l <= o.r && o.l <= self.r && self.b <= o.t && o.b <= self.t
    }

    /// The smallest box holding both.
    pub(crate) fn merge(&self, o: &Bb) -> Bb {
        Bb {
            l: fmin(self.l, o.l),
            b: fmin(self.b, o.b),
            r: fmax(self.r, o.r),
            t: fmax(self.t, o.t),
        }
    }

    /// The area.
    pub(crate) fn area(&self) -> f64 {
        (self.r - self.l) * (self.t - self.b)
    }

    /// The area of [`merge`](Self::merge)`(o)`.
    pub(crate) fn merged_area(&self, o: &Bb) -> f64 {
        (fmax(self.r, o.r) - fmin(self.l, o.l)) * (fmax(self.t, o.t) - fmin(self.b, o.b))
    }

    /// Twice the Manhattan distance between the centres.
    pub(crate) fn proximity(&self, o: &Bb) -> f64 {
        (self.l + self.r - o.l - o.r).abs() + (self.b + self.t - o.b - o.t).abs()
    }

    /// The centre (as Chipmunk computes it: a lerp of the corners at one half).
    pub(crate) fn center(&self) -> Vect {
        Vect::new(self.l, self.b).lerp(Vect::new(self.r, self.t), 0.5)
    }
}

/// The world-space cache of `geometry` on a body at `p` with rotation `rot`.
pub(crate) fn transform(geometry: &Geometry, p: Vect, rot: Vect) -> Cached {
    match *geometry {
        Geometry::Circle { offset, r } => Cached::Circle {
            c: p + offset.rotate(rot),
            r,
        },
        Geometry::Segment { a, b, r } => {
            let n = (b - a).normalize().rperp();
            Cached::Segment {
                a: p + a.rotate(rot),
                b: p + b.rotate(rot),
                n: n.rotate(rot),
                r,
            }
        }
    }
}

impl Cached {
    /// The bounding box.
    pub(crate) fn bb(&self) -> Bb {
        match *self {
            Cached::Circle { c, r } => Bb {
                l: c.x - r,
                b: c.y - r,
                r: c.x + r,
                t: c.y + r,
            },
            Cached::Segment { a, b, r, .. } => {
                let (l, rr) = if a.x < b.x { (a.x, b.x) } else { (b.x, a.x) };
                let (bo, t) = if a.y < b.y { (a.y, b.y) } else { (b.y, a.y) };
                Bb {
                    l: l - r,
                    b: bo - r,
                    r: rr + r,
                    t: t + r,
                }
            }
        }
    }
}
