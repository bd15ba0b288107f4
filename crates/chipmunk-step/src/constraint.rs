//! Constraints solved in the same iterations as the contacts: [`PinJoint`] (a rigid rod between two
//! anchors, warm-started from its last accumulated impulse) and [`DampedSpring`] (a spring impulse once
//! per step, then velocity damping along the spring in every iteration).

use crate::arbiter::pair_mut;
use crate::body::Body;
use crate::vect::Vect;

/// A constraint between bodies `a` and `b`.
#[derive(Debug, Clone)]
pub enum Constraint {
    /// Keeps the two anchors at their initial distance.
    Pin(PinJoint),
    /// Pulls the two anchors towards a rest length, with damping.
    Spring(DampedSpring),
}

impl Constraint {
    /// The two bodies.
    pub fn bodies(&self) -> [usize; 2] {
        match self {
            Constraint::Pin(j) => [j.a, j.b],
            Constraint::Spring(s) => [s.a, s.b],
        }
    }
}

/// A pin joint (Chipmunk `cpPinJoint`) with unlimited force and bias.
#[derive(Debug, Clone)]
pub struct PinJoint {
    pub(crate) a: usize,
    pub(crate) b: usize,
    anchor_a: Vect,
    anchor_b: Vect,
    dist: f64,
    /// Fraction of the length error left after one second (Chipmunk's `errorBias`).
    error_bias: f64,
    r1: Vect,
    r2: Vect,
    n: Vect,
    n_mass: f64,
    bias: f64,
    jn_acc: f64,
}

/// A damped spring (Chipmunk `cpDampedSpring` with the default linear force).
#[derive(Debug, Clone)]
pub struct DampedSpring {
    pub(crate) a: usize,
    pub(crate) b: usize,
    anchor_a: Vect,
    anchor_b: Vect,
    rest_length: f64,
    stiffness: f64,
    damping: f64,
    r1: Vect,
    r2: Vect,
    n: Vect,
    n_mass: f64,
    target_vrn: f64,
    v_coef: f64,
    /// The impulse applied this step (spring plus damping), which Chipmunk accumulates: each damping
    /// impulse is applied as the change of this sum, which can differ from the impulse in the last bit.
    j_acc: f64,
}

/// The anchors' world offsets, the unit vector from anchor a to anchor b and their distance.
fn geometry(a: &Body, b: &Body, anchor_a: Vect, anchor_b: Vect) -> (Vect, Vect, Vect, f64) {
    let r1 = anchor_a.rotate(a.rot);
    let r2 = anchor_b.rotate(b.rot);
    let delta = (b.p + r2) - (a.p + r1);
    let dist = delta.length();
    let n = delta * (1.0 / if dist != 0.0 { dist } else { f64::INFINITY });
    (r1, r2, n, dist)
}

impl PinJoint {
    /// A pin joint between anchors `anchor_a` on `a` and `anchor_b` on `b` (body coordinates), keeping
    /// their present distance.
    pub fn new(
        bodies: &[Body],
        a: usize,
        b: usize,
        anchor_a: Vect,
        anchor_b: Vect,
        error_bias: f64,
    ) -> PinJoint {
        let (ba, bb) = (&bodies[a], &bodies[b]);
        let pa = ba.p + anchor_a.rotate(ba.rot);
        let pb = bb.p + anchor_b.rotate(bb.rot);
        PinJoint {
            a,
            b,
            anchor_a,
            anchor_b,
            dist: (pb - pa).length(),
            error_bias,
            r1: Vect::ZERO,
            r2: Vect::ZERO,
            n: Vect::ZERO,
            n_mass: 0.0,
            bias: 0.0,
            jn_acc: 0.0,
        }
    }

    /// The distance the joint keeps.
    pub fn distance(&self) -> f64 {
        self.dist
    }
}

impl DampedSpring {
    /// A damped spring between anchors on `a` and `b`.
    pub fn new(
        a: usize,
        b: usize,
        anchor_a: Vect,
        anchor_b: Vect,
        rest_length: f64,
        stiffness: f64,
        damping: f64,
    ) -> DampedSpring {
        DampedSpring {
            a,
            b,
            anchor_a,
            anchor_b,
            rest_length,
            stiffness,
            damping,
            r1: Vect::ZERO,
            r2: Vect::ZERO,
            n: Vect::ZERO,
            n_mass: 0.0,
            target_vrn: 0.0,
            v_coef: 0.0,
            j_acc: 0.0,
        }
    }
}

impl Constraint {
    /// Per-step set-up; the spring applies its spring impulse here.
    pub(crate) fn pre_step(&mut self, bodies: &mut [Body], dt: f64) {
        match self {
            Constraint::Pin(j) => {
                let (a, b) = (&bodies[j.a], &bodies[j.b]);
                let (r1, r2, n, dist) = geometry(a, b, j.anchor_a, j.anchor_b);
                j.r1 = r1;
                j.r2 = r2;
                j.n = n;
                j.n_mass = 1.0 / (a.k_scalar(r1, n) + b.k_scalar(r2, n));
                let bias_coef = 1.0 - j.error_bias.powf(dt);
                j.bias = -bias_coef * (dist - j.dist) / dt;
            }
            Constraint::Spring(s) => {
                let (a, b) = (&bodies[s.a], &bodies[s.b]);
                let (r1, r2, n, dist) = geometry(a, b, s.anchor_a, s.anchor_b);
                let k = a.k_scalar(r1, n) + b.k_scalar(r2, n);
                s.r1 = r1;
                s.r2 = r2;
                s.n = n;
                s.n_mass = 1.0 / k;
                s.target_vrn = 0.0;
                s.v_coef = 1.0 - (-s.damping * dt * k).exp();
                let f_spring = (s.rest_length - dist) * s.stiffness;
                s.j_acc = f_spring * dt;
                let j = n * s.j_acc;
                let (a, b) = pair_mut(bodies, s.a, s.b);
                a.apply_impulse(-j, r1);
                b.apply_impulse(j, r2);
            }
        }
    }

    /// Re-applies the joint's last impulse scaled by `dt_coef` (springs keep none).
    pub(crate) fn apply_cached_impulse(&self, bodies: &mut [Body], dt_coef: f64) {
        if let Constraint::Pin(j) = self {
            let (a, b) = pair_mut(bodies, j.a, j.b);
            let imp = j.n * (j.jn_acc * dt_coef);
            a.apply_impulse(-imp, j.r1);
            b.apply_impulse(imp, j.r2);
        }
    }

    /// One solver iteration.
    pub(crate) fn apply_impulse(&mut self, bodies: &mut [Body]) {
        match self {
            Constraint::Pin(j) => {
                let (a, b) = pair_mut(bodies, j.a, j.b);
                let vrn = (b.velocity_at(j.r2) - a.velocity_at(j.r1)).dot(j.n);
                let jn = (j.bias - vrn) * j.n_mass;
                let jn_old = j.jn_acc;
                j.jn_acc = jn_old + jn;
                let imp = j.n * (j.jn_acc - jn_old);
                a.apply_impulse(-imp, j.r1);
                b.apply_impulse(imp, j.r2);
            }
            Constraint::Spring(s) => {
                let (a, b) = pair_mut(bodies, s.a, s.b);
                let vrn = (b.velocity_at(s.r2) - a.velocity_at(s.r1)).dot(s.n);
                let v_damp = (s.target_vrn - vrn) * s.v_coef;
                s.target_vrn = vrn + v_damp;
                let j_damp = (s.j_acc + v_damp * s.n_mass) - s.j_acc;
                s.j_acc += j_damp;
                let j = s.n * j_damp;
                a.apply_impulse(-j, s.r1);
                b.apply_impulse(j, s.r2);
            }
        }
    }
}
