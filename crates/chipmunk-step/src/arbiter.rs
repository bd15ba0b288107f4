//! [`Arbiter`]: the persistent contact state of one shape pair — its contact points with their
//! accumulated impulses (kept across steps by contact hash for warm starting) — and the contact
//! solver: bias velocities for overlap and velocity impulses with restitution and Coulomb friction,
//! solved together in each iteration.

use crate::body::Body;
use crate::collide::Manifold;
use crate::vect::Vect;

/// Where an arbiter is in its life.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ArbiterState {
    /// Touching this step for the first time (or again after a gap): no warm start applied.
    FirstCollision,
    /// Touching this step and the previous one.
    Normal,
    /// Not touching this step; kept a few steps so a returning contact finds its impulses.
    Cached,
}

/// One contact point of an arbiter.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Contact {
    /// Offset of the point on shape a from body a's centre.
    r1: Vect,
    /// Offset of the point on shape b from body b's centre.
    r2: Vect,
    n_mass: f64,
    t_mass: f64,
    bounce: f64,
    bias: f64,
    /// Accumulated normal, tangent and bias impulses.
    jn_acc: f64,
    jt_acc: f64,
    j_bias: f64,
    hash: u64,
}

/// The contact state of one pair of shapes.
#[derive(Debug, Clone)]
pub(crate) struct Arbiter {
    /// Shape indices (a: the first shape in the collision's order; the normal points from a to b).
    pub shape_a: usize,
    pub shape_b: usize,
    pub body_a: usize,
    pub body_b: usize,
    pub state: ArbiterState,
    /// The step at which the pair last touched.
    pub stamp: u64,
    contacts: Vec<Contact>,
    n: Vect,
    /// Combined restitution and friction (products of the shapes').
    e: f64,
    u: f64,
}

/// Two distinct bodies out of a slice, mutably.
pub(crate) fn pair_mut(bodies: &mut [Body], a: usize, b: usize) -> (&mut Body, &mut Body) {
    assert_ne!(a, b, "a constraint or contact on one body");
    if a < b {
        let (lo, hi) = bodies.split_at_mut(b);
        (&mut lo[a], &mut hi[0])
    } else {
        let (lo, hi) = bodies.split_at_mut(a);
        (&mut hi[0], &mut lo[b])
    }
}

impl Arbiter {
    /// A new arbiter for shapes `a` and `b` on bodies `body_a` and `body_b`.
    pub(crate) fn new(shape_a: usize, shape_b: usize, body_a: usize, body_b: usize) -> Arbiter {
        Arbiter {
            shape_a,
            shape_b,
            body_a,
            body_b,
            state: ArbiterState::FirstCollision,
            stamp: 0,
            contacts: Vec::new(),
            n: Vect::ZERO,
            e: 0.0,
            u: 0.0,
        }
    }

    /// The number of contact points.
    pub(crate) fn len(&self) -> usize {
        self.contacts.len()
    }

    /// The contact points' offsets from body a's and body b's centres.
    pub(crate) fn points(&self) -> impl Iterator<Item = (Vect, Vect)> + '_ {
        self.contacts.iter().map(|c| (c.r1, c.r2))
    }

    /// The normal, from shape a to shape b.
    pub(crate) fn normal(&self) -> Vect {
        self.n
    }

    /// Takes this step's contacts, keeping the accumulated impulses of points whose hash matches one of
    /// the previous contacts.
    pub(crate) fn update(&mut self, m: Manifold, pa: Vect, pb: Vect, e: f64, u: f64) {
        let contacts = m
            .points
            .iter()
            .map(|c| {
                let mut con = Contact {
                    r1: c.p1 - pa,
                    r2: c.p2 - pb,
                    n_mass: 0.0,
                    t_mass: 0.0,
                    bounce: 0.0,
                    bias: 0.0,
                    jn_acc: 0.0,
                    jt_acc: 0.0,
                    j_bias: 0.0,
                    hash: c.hash,
                };
                for old in &self.contacts {
                    if old.hash == c.hash {
                        con.jn_acc = old.jn_acc;
                        con.jt_acc = old.jt_acc;
                    }
                }
                con
            })
            .collect();
        self.contacts = contacts;
        self.n = m.n;
        self.e = e;
        self.u = u;
        if self.state == ArbiterState::Cached {
            self.state = ArbiterState::FirstCollision;
        }
    }

    /// Effective masses, the bias velocity that removes the overlap beyond `slop` (fraction `bias` of it
    /// this step) and the bounce target, from the velocities before gravity is added.
    pub(crate) fn pre_step(&mut self, bodies: &[Body], dt: f64, slop: f64, bias: f64) {
        let (a, b) = (&bodies[self.body_a], &bodies[self.body_b]);
        let n = self.n;
        let body_delta = b.p - a.p;
        for con in &mut self.contacts {
            con.n_mass = 1.0 / (a.k_scalar(con.r1, n) + b.k_scalar(con.r2, n));
            con.t_mass = 1.0 / (a.k_scalar(con.r1, n.perp()) + b.k_scalar(con.r2, n.perp()));
            let dist = (con.r2 - con.r1 + body_delta).dot(n);
            con.bias = -bias * (dist + slop).min(0.0) / dt;
            con.j_bias = 0.0;
            let vr = b.velocity_at(con.r2) - a.velocity_at(con.r1);
            con.bounce = vr.dot(n) * self.e;
        }
    }

    /// Re-applies last step's impulses scaled by `dt_coef` (not on a first collision).
    pub(crate) fn apply_cached_impulse(&self, bodies: &mut [Body], dt_coef: f64) {
        if self.state == ArbiterState::FirstCollision {
            return;
        }
        let (a, b) = pair_mut(bodies, self.body_a, self.body_b);
        for con in &self.contacts {
            let j = self.n.rotate(Vect::new(con.jn_acc, con.jt_acc)) * dt_coef;
            a.apply_impulse(-j, con.r1);
            b.apply_impulse(j, con.r2);
        }
    }

    /// One solver iteration over the contact points.
    pub(crate) fn apply_impulse(&mut self, bodies: &mut [Body]) {
        let (a, b) = pair_mut(bodies, self.body_a, self.body_b);
        let n = self.n;
        let friction = self.u;
        for con in &mut self.contacts {
            let (r1, r2) = (con.r1, con.r2);
            let vb1 = a.bias_velocity_at(r1);
            let vb2 = b.bias_velocity_at(r2);
            let vr = b.velocity_at(r2) - a.velocity_at(r1);
            let vbn = (vb2 - vb1).dot(n);
            let vrn = vr.dot(n);
            let vrt = vr.dot(n.perp());

            let jbn = (con.bias - vbn) * con.n_mass;
            let jbn_old = con.j_bias;
            con.j_bias = (jbn_old + jbn).max(0.0);

            let jn = -(con.bounce + vrn) * con.n_mass;
            let jn_old = con.jn_acc;
            con.jn_acc = (jn_old + jn).max(0.0);

            let jt_max = friction * con.jn_acc;
            let jt = -vrt * con.t_mass;
            let jt_old = con.jt_acc;
            con.jt_acc = (jt_old + jt).max(-jt_max).min(jt_max);

            let jb = n * (con.j_bias - jbn_old);
            a.apply_bias_impulse(-jb, r1);
            b.apply_bias_impulse(jb, r2);
            let j = n.rotate(Vect::new(con.jn_acc - jn_old, con.jt_acc - jt_old));
            a.apply_impulse(-j, r1);
            b.apply_impulse(j, r2);
        }
    }
}
