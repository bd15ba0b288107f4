//! [`Vect`]: the 2-D vector arithmetic the step uses (f64, like Chipmunk's `cpFloat` in pymunk builds).

use std::ops::{Add, Mul, Neg, Sub};

/// A 2-D vector.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vect {
    /// x component.
    pub x: f64,
    /// y component.
    pub y: f64,
}

impl Vect {
    /// The zero vector.
    pub const ZERO: Vect = Vect { x: 0.0, y: 0.0 };

    /// `(x, y)`.
    pub const fn new(x: f64, y: f64) -> Vect {
        Vect { x, y }
    }

    /// Dot product.
    pub fn dot(self, o: Vect) -> f64 {
        self.x * o.x + self.y * o.y
    }

    /// The z component of the 3-D cross product.
    pub fn cross(self, o: Vect) -> f64 {
        self.x * o.y - self.y * o.x
    }

    /// Rotated by +90° (`(-y, x)`).
    pub fn perp(self) -> Vect {
        Vect::new(-self.y, self.x)
    }

    /// Rotated by −90° (`(y, -x)`).
    pub fn rperp(self) -> Vect {
        Vect::new(self.y, -self.x)
    }

    /// Squared length.
    pub fn length_sq(self) -> f64 {
        self.dot(self)
    }

    /// Length.
    pub fn length(self) -> f64 {
        self.length_sq().sqrt()
    }

    /// Unit vector (divided by its length plus the smallest positive normal float, as Chipmunk does, so
    /// the zero vector stays zero).
    pub fn normalize(self) -> Vect {
        self * (1.0 / (self.length() + f64::MIN_POSITIVE))
    }

    /// Complex multiplication by the unit vector `rot` (a rotation).
    pub fn rotate(self, rot: Vect) -> Vect {
        Vect::new(
            self.x * rot.x - self.y * rot.y,
            self.x * rot.y + self.y * rot.x,
        )
    }

    /// `self + (o − self)·t`.
    pub fn lerp(self, o: Vect, t: f64) -> Vect {
        self * (1.0 - t) + o * t
    }
}

impl Add for Vect {
    type Output = Vect;
    fn add(self, o: Vect) -> Vect {
        Vect::new(self.x + o.x, self.y + o.y)
    }
}

impl Sub for Vect {
    type Output = Vect;
    fn sub(self, o: Vect) -> Vect {
        Vect::new(self.x - o.x, self.y - o.y)
    }
}

impl Mul<f64> for Vect {
    type Output = Vect;
    fn mul(self, s: f64) -> Vect {
        Vect::new(self.x * s, self.y * s)
    }
}

impl Neg for Vect {
    type Output = Vect;
    fn neg(self) -> Vect {
        Vect::new(-self.x, -self.y)
    }
}
