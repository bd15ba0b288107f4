//! [`Space`]: bodies, shapes, constraints and the contact cache, and the step that moves them in
//! Chipmunk 7's order:
//!
//! 1. move every dynamic body by its velocity plus bias velocity;
//! 2. find the touching shape pairs at the new positions, in the order Chipmunk's spatial index reports
//!    them ([`Index`](crate::bbtree::Index)), and update their arbiters in that order (which is the
//!    solver's), matching contact points to last step's by hash; forget arbiters unused for
//!    `collision_persistence` steps;
//! 3. pre-step contacts (effective masses, overlap bias, bounce target) and constraints (a spring
//!    applies its spring impulse here);
//! 4. add gravity to the velocities;
//! 5. re-apply last step's accumulated impulses, scaled by the ratio of the time steps;
//! 6. `iterations` times: every contact, then every constraint.

use std::collections::HashMap;

use crate::arbiter::{Arbiter, ArbiterState};
use crate::bbtree::{Index, Query};
use crate::body::{Body, BodyKind};
use crate::collide::collide;
use crate::constraint::Constraint;
use crate::shape::{Cached, Geometry, Shape, TENTH_F32, transform};
use crate::vect::Vect;

/// Chipmunk's default `collisionBias` and constraint `errorBias`, `pow(1.0f - 0.1f, 60)`: the base is
/// the single-precision 0.9 (0.899999976158…), so the value is 0.0017970074436…, not 0.9⁶⁰ =
/// 0.0017970102999….
pub fn default_bias() -> f64 {
    ((1.0f32 - 0.1f32) as f64).powf(60.0)
}

/// One touching shape pair of a step, as [`Space::contact_points`] reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactReport {
    /// The body of the first shape.
    pub body_a: BodyId,
    /// The body of the second shape.
    pub body_b: BodyId,
    /// The normal, from the first shape to the second.
    pub normal: Vect,
    /// Each contact point on the first and on the second shape, in world coordinates.
    pub points: Vec<(Vect, Vect)>,
}

/// A body handle.
pub type BodyId = usize;

/// A simulation space.
#[derive(Debug, Clone)]
pub struct Space {
    /// Gravity (acceleration).
    pub gravity: Vect,
    /// Solver iterations per step: 10.
    pub iterations: usize,
    /// Overlap allowed without correction: Chipmunk's `0.1f` (0.100000001490116…).
    pub collision_slop: f64,
    /// Fraction of the overlap left uncorrected after one time unit: [`default_bias`] (10 % corrected
    /// per 1/60).
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
    /// Arbiters by shape pair (smaller shape index first).
    arbiters: HashMap<(usize, usize), Arbiter>,
    /// The static and dynamic shape trees, which decide the order of the touching pairs.
    index: Index,
    /// The broad phase's candidate pairs of the current step (kept to reuse the allocation).
    queries: Vec<Query>,
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
            collision_slop: TENTH_F32,
            collision_bias: default_bias(),
            collision_persistence: 3,
            damping: 1.0,
            bodies: Vec::new(),
            alive: Vec::new(),
            shapes: Vec::new(),
            shape_alive: Vec::new(),
            constraints: Vec::new(),
            arbiters: HashMap::new(),
            index: Index::new(),
            queries: Vec::new(),
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
        let s = self.shapes.len();
        // Chipmunk numbers shapes in the order they are added (`shapeIDCounter`).
        let hash_id = s as u64;
        let is_static = b.kind == BodyKind::Static;
        if is_static {
            self.index.insert_static(s, cache.bb());
        } else {
            self.index.insert_dynamic(s, hash_id, cache.bb().grown(b.v));
        }
        self.shapes.push(Shape {
            body,
            geometry,
            friction,
            elasticity,
            hash_id,
            is_static,
            cache,
        });
        self.shape_alive.push(true);
        s
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
            if shape.body == id && self.shape_alive[s] {
                self.shape_alive[s] = false;
                self.index.remove(s, shape.hash_id, shape.is_static);
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

    /// The contacts of the last step in solver order: the bodies of the first and second shape of each
    /// touching pair and its number of contact points.
    pub fn contacts(&self) -> impl Iterator<Item = (BodyId, BodyId, usize)> + '_ {
        self.active.iter().map(|k| {
            let arb = &self.arbiters[k];
            (arb.body_a, arb.body_b, arb.len())
        })
    }

    /// The contacts of the last step in solver order, in detail (as Chipmunk's contact point sets give
    /// them, for comparing with a recording of the original).
    pub fn contact_points(&self) -> Vec<ContactReport> {
        self.active
            .iter()
            .map(|k| {
                let arb = &self.arbiters[k];
                let (pa, pb) = (self.bodies[arb.body_a].p, self.bodies[arb.body_b].p);
                ContactReport {
                    body_a: arb.body_a,
                    body_b: arb.body_b,
                    normal: arb.normal(),
                    points: arb.points().map(|(r1, r2)| (pa + r1, pb + r2)).collect(),
                }
            })
            .collect()
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
            if self.shape_alive[s] && !shape.is_static {
                let b = &self.bodies[shape.body];
                shape.cache = transform(&shape.geometry, b.p, b.rot);
            }
        }

        // 2. Collisions, in the spatial index's order.
        let mut queries = std::mem::take(&mut self.queries);
        queries.clear();
        let (shapes, bodies) = (&self.shapes, &self.bodies);
        self.index.reindex_query(
            |s| {
                let bb = shapes[s].cache.bb();
                (bb, bb.grown(bodies[shapes[s].body].v))
            },
            &mut queries,
        );
        for q in &queries {
            let id = self.collide_shapes(q);
            if let Some(pair) = q.pair {
                self.index.set_pair_id(pair, id);
            }
        }
        self.queries = queries;
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

    /// Tests the candidate pair `q` and, when its shapes touch, updates its arbiter and appends it to the
    /// solver's list (Chipmunk's `cpSpaceCollideShapes`). Returns the collision id to keep for the pair.
    fn collide_shapes(&mut self, q: &Query) -> u32 {
        let (sa, sb) = (&self.shapes[q.a], &self.shapes[q.b]);
        if sa.body == sb.body || !sa.cache.bb().intersects(&sb.cache.bb()) {
            return q.id;
        }
        // The narrow phase puts a circle first.
        let (a, b) = match (&sa.cache, &sb.cache) {
            (Cached::Segment { .. }, Cached::Circle { .. }) => (q.b, q.a),
            _ => (q.a, q.b),
        };
        let (sa, sb) = (&self.shapes[a], &self.shapes[b]);
        let mut id = q.id;
        let m = collide(&sa.cache, sa.hash_id, &sb.cache, sb.hash_id, &mut id);
        if m.points.is_empty() {
            return id;
        }
        let (body_a, body_b) = (sa.body, sb.body);
        if self.bodies[body_a].kind == BodyKind::Static
            && self.bodies[body_b].kind == BodyKind::Static
        {
            return id;
        }
        let (pa, pb) = (self.bodies[body_a].p, self.bodies[body_b].p);
        let (e, u) = (sa.elasticity * sb.elasticity, sa.friction * sb.friction);
        let key = (a.min(b), a.max(b));
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
        id
    }
}
