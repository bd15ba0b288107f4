//! [`Space`]: bodies, shapes, constraints and the contact cache, and the step that moves them in
//! Chipmunk 7's order:
//!
//! 1. move every dynamic body by its velocity plus bias velocity;
//! 2. find the touching shape pairs at the new positions (every pair: the scenes are small) and update
//!    their arbiters, matching contact points to last step's by hash; forget arbiters unused for
//!    `collision_persistence` steps;
//! 3. pre-step contacts (effective masses, overlap bias, bounce target) and constraints (a spring
//!    applies its spring impulse here);
//! 4. add gravity to the velocities;
//! 5. re-apply last step's accumulated impulses, scaled by the ratio of the time steps;
//! 6. `iterations` times: every contact, then every constraint.

use std::collections::HashMap;

use crate::arbiter::{Arbiter, ArbiterState};
use crate::body::{Body, BodyKind};
use crate::collide::collide;
use crate::constraint::Constraint;
use crate::shape::{Cached, Geometry, Shape, transform};
use crate::vect::Vect;

/// A body handle.
pub type BodyId = usize;

/// A simulation space.
#[derive(Debug, Clone)]
pub struct Space {
    /// Gravity (acceleration).
    pub gravity: Vect,
    /// Solver iterations per step: 10.
    pub iterations: usize,
    /// Overlap allowed without correction: 0.1.
    pub collision_slop: f64,
    /// Fraction of the overlap left uncorrected after one time unit: 0.9⁶⁰ (10 % per 1/60).
    pub collision_bias: f64,
    /// Steps an unused arbiter is kept for warm starting: 3.
    pub collision_persistence: u64,
    /// Fraction of the velocity kept per time unit: 1 (no damping).
    pub damping: f64,
    bodies: Vec<Body>,
    alive: Vec<bool>,
    shapes: Vec<Shape>,
    shape_alive: Vec<bool>,
    constraints: Vec<Option<Constraint>>,
    /// Arbiters by (first, second) shape index as first found.
    arbiters: HashMap<(usize, usize), Arbiter>,
    /// The pairs touching in the last step, in solver order.
    active: Vec<(usize, usize)>,
    stamp: u64,
    prev_dt: f64,
}

impl Space {
    /// An empty space with Chipmunk's defaults and gravity `gravity`.
    pub fn new(gravity: Vect) -> Space {
        Space {
            gravity,
            iterations: 10,
            collision_slop: 0.1,
            collision_bias: 0.9f64.powi(60),
            collision_persistence: 3,
            damping: 1.0,
            bodies: Vec::new(),
            alive: Vec::new(),
            shapes: Vec::new(),
            shape_alive: Vec::new(),
            constraints: Vec::new(),
            arbiters: HashMap::new(),
            active: Vec::new(),
            stamp: 0,
            prev_dt: 0.0,
        }
    }

    /// Adds a body; returns its handle.
    pub fn add_body(&mut self, body: Body) -> BodyId {
        self.bodies.push(body);
        self.alive.push(true);
        self.bodies.len() - 1
    }

    /// Adds a shape to body `body` with the given friction and elasticity; returns its index.
    pub fn add_shape(
        &mut self,
        body: BodyId,
        geometry: Geometry,
        friction: f64,
        elasticity: f64,
    ) -> usize {
        let b = &self.bodies[body];
        let cache = transform(&geometry, b.p, b.rot);
        let leaf_bb = cache.bb().grown(b.v);
        self.shapes.push(Shape {
            body,
            geometry,
            friction,
            elasticity,
            hash_id: self.shapes.len() as u64,
            cache,
            leaf_bb,
            reinserted: false,
        });
        self.shape_alive.push(true);
        self.shapes.len() - 1
    }

    /// Adds a constraint; returns its index.
    pub fn add_constraint(&mut self, c: Constraint) -> usize {
        self.constraints.push(Some(c));
        self.constraints.len() - 1
    }

    /// The bodies (removed ones included; see [`is_alive`](Self::is_alive)).
    pub fn bodies(&self) -> &[Body] {
        &self.bodies
    }

    /// Body `id`, if it exists and was not removed.
    pub fn body(&self, id: BodyId) -> Option<&Body> {
        self.alive
            .get(id)
            .copied()
            .unwrap_or(false)
            .then(|| &self.bodies[id])
    }

    /// Whether body `id` exists and was not removed.
    pub fn is_alive(&self, id: BodyId) -> bool {
        self.alive.get(id).copied().unwrap_or(false)
    }

    /// Removes body `id` with its shapes, their arbiters and every constraint on it. Returns false when
    /// it is unknown or already removed.
    pub fn remove_body(&mut self, id: BodyId) -> bool {
        if !self.is_alive(id) {
            return false;
        }
        self.alive[id] = false;
        for (s, shape) in self.shapes.iter().enumerate() {
            if shape.body == id {
                self.shape_alive[s] = false;
            }
        }
        let shape_alive = &self.shape_alive;
        self.arbiters
            .retain(|&(a, b), _| shape_alive[a] && shape_alive[b]);
        self.active
            .retain(|&(a, b)| shape_alive[a] && shape_alive[b]);
        for c in &mut self.constraints {
            if c.as_ref().is_some_and(|c| c.bodies().contains(&id)) {
                *c = None;
            }
        }
        true
    }

    /// The body pairs whose shapes touched in the last step, in solver order (each pair as
    /// `(body of the first shape, body of the second)`).
    pub fn touching_bodies(&self) -> impl Iterator<Item = (BodyId, BodyId)> + '_ {
        self.active
            .iter()
            .map(|&(a, b)| (self.shapes[a].body, self.shapes[b].body))
    }

    /// Advances the space by `dt`.
    pub fn step(&mut self, dt: f64) {
        if dt == 0.0 {
            return;
        }
        self.stamp += 1;
        let prev_dt = self.prev_dt;
        self.prev_dt = dt;
        for arb_key in self.active.drain(..) {
            if let Some(arb) = self.arbiters.get_mut(&arb_key) {
                arb.state = ArbiterState::Normal;
            }
        }

        // 1. Positions.
        for (b, body) in self.bodies.iter_mut().enumerate() {
            if self.alive[b] && body.kind == BodyKind::Dynamic {
                body.update_position(dt);
            }
        }
        for (s, shape) in self.shapes.iter_mut().enumerate() {
            if self.shape_alive[s] {
                let b = &self.bodies[shape.body];
                shape.cache = transform(&shape.geometry, b.p, b.rot);
                let bb = shape.cache.bb();
                shape.reinserted = b.kind == BodyKind::Dynamic && !shape.leaf_bb.contains(&bb);
                if shape.reinserted {
                    shape.leaf_bb = bb.grown(b.v);
                }
            }
        }

        // 2. Collisions.
        self.collide_all();
        let stamp = self.stamp;
        let persistence = self.collision_persistence;
        self.arbiters.retain(|_, arb| {
            let ticks = stamp - arb.stamp;
            if ticks >= 1 && arb.state != ArbiterState::Cached {
                arb.state = ArbiterState::Cached;
            }
            ticks < persistence
        });

        // 3. Pre-step.
        let slop = self.collision_slop;
        let bias = 1.0 - self.collision_bias.powf(dt);
        for key in &self.active {
            let arb = self.arbiters.get_mut(key).expect("active arbiter");
            arb.pre_step(&self.bodies, dt, slop, bias);
        }
        for c in self.constraints.iter_mut().flatten() {
            c.pre_step(&mut self.bodies, dt);
        }

        // 4. Velocities.
        let damping = self.damping.powf(dt);
        for (b, body) in self.bodies.iter_mut().enumerate() {
            if self.alive[b] && body.kind == BodyKind::Dynamic {
                body.update_velocity(self.gravity, damping, dt);
            }
        }

        // 5. Warm start.
        let dt_coef = if prev_dt == 0.0 { 0.0 } else { dt / prev_dt };
        for key in &self.active {
            self.arbiters[key].apply_cached_impulse(&mut self.bodies, dt_coef);
        }
        for c in self.constraints.iter().flatten() {
            c.apply_cached_impulse(&mut self.bodies, dt_coef);
        }

        // 6. Iterations.
        for _ in 0..self.iterations {
            for key in &self.active {
                let arb = self.arbiters.get_mut(key).expect("active arbiter");
                arb.apply_impulse(&mut self.bodies);
            }
            for c in self.constraints.iter_mut().flatten() {
                c.apply_impulse(&mut self.bodies);
            }
        }
    }

    /// Finds every touching pair of shapes on different bodies (not both static) and updates its
    /// arbiter; the touching pairs become `active`.
    fn collide_all(&mut self) {
        let n = self.shapes.len();
        for i in 0..n {
            if !self.shape_alive[i] {
                continue;
            }
            for j in (i + 1)..n {
                if !self.shape_alive[j] {
                    continue;
                }
                let (si, sj) = (&self.shapes[i], &self.shapes[j]);
                if si.body == sj.body {
                    continue;
                }
                let (bi, bj) = (&self.bodies[si.body], &self.bodies[sj.body]);
                if bi.kind == BodyKind::Static && bj.kind == BodyKind::Static {
                    continue;
                }
                if !si.cache.bb().intersects(&sj.cache.bb()) {
                    continue;
                }
                // Circles first. Between a dynamic and a static shape Chipmunk's tree reports the dynamic
                // one first in a step that re-inserted it, else the static one (from its cached pair).
                let swap = match (&si.cache, &sj.cache) {
                    (Cached::Segment { .. }, Cached::Circle { .. }) => true,
                    (Cached::Circle { .. }, Cached::Segment { .. }) => false,
                    _ => match (bi.kind, bj.kind) {
                        (BodyKind::Static, BodyKind::Dynamic) => sj.reinserted,
                        (BodyKind::Dynamic, BodyKind::Static) => !si.reinserted,
                        _ => false,
                    },
                };
                let (a, b) = if swap { (j, i) } else { (i, j) };
                let (sa, sb) = (&self.shapes[a], &self.shapes[b]);
                let m = collide(&sa.cache, sa.hash_id, &sb.cache, sb.hash_id);
                if m.points.is_empty() {
                    continue;
                }
                let key = (i, j);
                let (pa, pb) = (self.bodies[sa.body].p, self.bodies[sb.body].p);
                let (e, u) = (sa.elasticity * sb.elasticity, sa.friction * sb.friction);
                let (body_a, body_b) = (sa.body, sb.body);
                let arb = self
                    .arbiters
                    .entry(key)
                    .or_insert_with(|| Arbiter::new(a, b, body_a, body_b));
                arb.shape_a = a;
                arb.shape_b = b;
                arb.body_a = body_a;
                arb.body_b = body_b;
                arb.update(m, pa, pb, e, u);
                arb.stamp = self.stamp;
                self.active.push(key);
            }
        }
    }
}
