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
    /// A number unique to the shape in its space, mixed into contact hashes.
    pub(crate) hash_id: u64,
    /// World-space cache, refreshed after every position update.
    pub(crate) cache: Cached,
    /// The box Chipmunk's dynamic tree keeps for the shape: its bounding box grown by a tenth of its size
    /// (or its velocity over a tenth of a time unit, if larger) when last re-inserted.
    pub(crate) leaf_bb: Bb,
    /// Whether the shape left its `leaf_bb` in this step's position update (and was re-inserted).
    pub(crate) reinserted: bool,
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

/// An axis-aligned box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Bb {
    l: f64,
    b: f64,
    r: f64,
    t: f64,
}

impl Bb {
    /// Whether `o` lies inside this box.
    pub(crate) fn contains(&self, o: &Bb) -> bool {
        self.l <= o.l && self.r >= o.r && self.b <= o.b && self.t >= o.t
    }

    /// The box a spatial tree keeps for a shape with this box moving at `v`.
    pub(crate) fn grown(&self, v: Vect) -> Bb {
        let x = (self.r - self.l) * 0.1;
        let y = (self.t - self.b) * 0.1;
        let v = v * 0.1;
        Bb {
            l: self.l + (-x).min(v.x),
            b: self.b + (-y).min(v.y),
            r: self.r + x.max(v.x),
            t: self.t + y.max(v.y),
        }
    }

    /// Whether two boxes touch or overlap.
    pub(crate) fn intersects(&self, o: &Bb) -> bool {
        self.l <= o.r && o.l <= self.r && self.b <= o.t && o.b <= self.t
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
            Cached::Segment { a, b, r, .. } => Bb {
                l: a.x.min(b.x) - r,
                b: a.y.min(b.y) - r,
                r: a.x.max(b.x) + r,
                t: a.y.max(b.y) + r,
            },
        }
    }
}
