//! [`Body`]: a rigid body's state and its two integration steps (positions with velocity plus bias
//! velocity, then velocities with gravity), as Chipmunk's default body functions do them.

use crate::vect::Vect;

/// Whether a body moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BodyKind {
    /// Moved by the step: finite mass and moment.
    Dynamic,
    /// Never moves: infinite mass and moment.
    Static,
}

/// One rigid body. Its position is its centre of gravity.
#[derive(Debug, Clone)]
pub struct Body {
    /// Dynamic or static.
    pub kind: BodyKind,
    /// Position (centre of gravity).
    pub p: Vect,
    /// Velocity.
    pub v: Vect,
    /// Angle (rad).
    pub angle: f64,
    /// Angular velocity (rad per time unit).
    pub w: f64,
    /// Inverse mass (0 for static bodies).
    pub m_inv: f64,
    /// Inverse moment of inertia (0 for static bodies).
    pub i_inv: f64,
    /// `(cos angle, sin angle)`.
    pub(crate) rot: Vect,
    /// Bias velocity that pushes overlapping shapes apart; used by the next position update only.
    pub(crate) v_bias: Vect,
    /// Angular bias velocity.
    pub(crate) w_bias: f64,
}

impl Body {
    /// A dynamic body of mass `mass` and moment `moment` at `p`, at rest.
    pub fn dynamic(mass: f64, moment: f64, p: Vect) -> Body {
        Body {
            kind: BodyKind::Dynamic,
            m_inv: 1.0 / mass,
            i_inv: 1.0 / moment,
            ..Body::fixed(p)
        }
    }

    /// A static body at `p`.
    pub fn fixed(p: Vect) -> Body {
        Body {
            kind: BodyKind::Static,
            p,
            v: Vect::ZERO,
            angle: 0.0,
            w: 0.0,
            m_inv: 0.0,
            i_inv: 0.0,
            rot: Vect::new(1.0, 0.0),
            v_bias: Vect::ZERO,
            w_bias: 0.0,
        }
    }

    /// `(cos angle, sin angle)`.
    pub fn rotation(&self) -> Vect {
        self.rot
    }

    /// Moves the body by its velocity plus its bias velocity, then clears the bias velocity.
    pub(crate) fn update_position(&mut self, dt: f64) {
        self.p = self.p + (self.v + self.v_bias) * dt;
        self.angle += (self.w + self.w_bias) * dt;
        self.rot = Vect::new(self.angle.cos(), self.angle.sin());
        self.v_bias = Vect::ZERO;
        self.w_bias = 0.0;
    }

    /// Adds gravity for `dt` to the velocity, after damping it by `damping`.
    pub(crate) fn update_velocity(&mut self, gravity: Vect, damping: f64, dt: f64) {
        self.v = self.v * damping + gravity * dt;
        self.w *= damping;
    }

    /// Applies impulse `j` at offset `r` from the centre.
    pub(crate) fn apply_impulse(&mut self, j: Vect, r: Vect) {
        self.v = self.v + j * self.m_inv;
        self.w += self.i_inv * r.cross(j);
    }

    /// Applies bias impulse `j` at offset `r`.
    pub(crate) fn apply_bias_impulse(&mut self, j: Vect, r: Vect) {
        self.v_bias = self.v_bias + j * self.m_inv;
        self.w_bias += self.i_inv * r.cross(j);
    }

    /// Velocity of the point at offset `r`.
    pub(crate) fn velocity_at(&self, r: Vect) -> Vect {
        self.v + r.perp() * self.w
    }

    /// Bias velocity of the point at offset `r`.
    pub(crate) fn bias_velocity_at(&self, r: Vect) -> Vect {
        self.v_bias + r.perp() * self.w_bias
    }

    /// The effective inverse mass along `n` at offset `r`.
    pub(crate) fn k_scalar(&self, r: Vect, n: Vect) -> f64 {
        let rcn = r.cross(n);
        self.m_inv + self.i_inv * rcn * rcn
    }
}
