//! [`ChipmunkWorld`]: one I-PHYRE game on annotrace's Chipmunk-faithful step (the `chipmunk-step`
//! crate), set up as iphyre 0.2.3 sets up its pymunk space (`engine = "chipmunk"`).
//!
//! **Owns:** the space of one episode (one body per object, in object order, so body ids are object
//! indices), object removal, and contact begin/end per object pair (the pairs touching after a step
//! against those touching after the previous one; pairs ended by a removal are reported at the next
//! step, first).
//! **Does not:** choose the engine or compute object ends (`world.rs`), decide when to remove a block
//! (`action.rs`, `step.rs`), judge success (`success.rs`) or build traces (`to_trace.rs`).
//!
//! The set-up, as iphyre's `IPHYRE.add_all` does it in pymunk: a ball is a dynamic body (mass
//! `ball_mass`, moment `m·r²/2`) with a circle; a block is a body at its segment's midpoint with a
//! segment of radius `block_radius` (static, or dynamic with mass `block_mass` and moment
//! `block_inertia`); every shape has friction `friction` and elasticity `restitution` (the step
//! multiplies a pair's); a pin joint joins two body centres at their initial distance; a damped spring
//! joins two centres with rest length, stiffness and damping from [`PhysicsParams`]. The space keeps
//! Chipmunk's defaults: 10 iterations, slop 0.1 px, bias 0.9⁶⁰ per second, no damping, no sleeping.
//! Unlike the rapier and Box2D worlds its state after step k is the original's after step k (no
//! one-frame shift).

use std::collections::BTreeSet;

use chipmunk_step::{
    Body, Constraint, DampedSpring, Geometry, PinJoint, Space, Vect, default_bias,
};

use super::error::Result;
use super::game::{Game, ObjectKind};
use super::params::PhysicsParams;
use super::world::{ContactChange, Pose};

/// A game's bodies on the Chipmunk-faithful step.
#[derive(Debug)]
pub(super) struct ChipmunkWorld {
    space: Space,
    dt: f64,
    /// Object pairs touching after the last step, smaller index first.
    touching: BTreeSet<[usize; 2]>,
    /// Contact ends caused by removals since the last step.
    removed: Vec<[usize; 2]>,
}

impl ChipmunkWorld {
    /// Builds `game`'s bodies, shapes, pin joints and springs.
    pub(super) fn new(game: &Game, params: &PhysicsParams) -> Result<ChipmunkWorld> {
        let mut space = Space::new(Vect::new(0.0, params.gravity));
        space.iterations = params.chipmunk_iterations;
        for o in &game.objects {
            let c = o.centre();
            let p = Vect::new(c[0], c[1]);
            let (body, geometry) = match o.kind {
                ObjectKind::Ball => (
                    // pymunk's moment_for_circle(m, 0, r), computed as Chipmunk does.
                    Body::dynamic(
                        params.ball_mass,
                        params.ball_mass * (0.5 * (0.0 + o.radius * o.radius)),
                        p,
                    ),
                    Geometry::Circle {
                        offset: Vect::ZERO,
                        r: o.radius,
                    },
                ),
                ObjectKind::Block => {
                    let body = if o.dynamic {
                        Body::dynamic(params.block_mass, params.block_inertia, p)
                    } else {
                        Body::fixed(p)
                    };
                    let geometry = Geometry::Segment {
                        a: Vect::new(o.p1[0] - c[0], o.p1[1] - c[1]),
                        b: Vect::new(o.p2[0] - c[0], o.p2[1] - c[1]),
                        r: params.block_radius,
                    };
                    (body, geometry)
                }
            };
            let id = space.add_body(body);
            debug_assert_eq!(id, o.index);
            space.add_shape(id, geometry, params.friction, params.restitution);
        }
        // pymunk's default error bias for joints (Chipmunk's, with its single-precision 0.9).
        let error_bias = default_bias();
        for &[a, b] in &game.joints {
            let joint = PinJoint::new(space.bodies(), a, b, Vect::ZERO, Vect::ZERO, error_bias);
            space.add_constraint(Constraint::Pin(joint));
        }
        for &[a, b] in &game.springs {
            space.add_constraint(Constraint::Spring(DampedSpring::new(
                a,
                b,
                Vect::ZERO,
                Vect::ZERO,
                params.spring_rest_length,
                params.spring_stiffness,
                params.spring_damping,
            )));
        }
        Ok(ChipmunkWorld {
            space,
            dt: params.dt(),
            touching: BTreeSet::new(),
            removed: Vec::new(),
        })
    }

    /// One step; the contact changes of the step (and of removals since the last step).
    pub(super) fn step(&mut self) -> Vec<ContactChange> {
        self.space.step(self.dt);
        let mut changes: Vec<ContactChange> = std::mem::take(&mut self.removed)
            .into_iter()
            .map(|objects| ContactChange {
                began: false,
                objects,
            })
            .collect();
        let now: BTreeSet<[usize; 2]> = self
            .space
            .touching_bodies()
            .map(|(a, b)| [a.min(b), a.max(b)])
            .collect();
        for &pair in self.touching.difference(&now) {
            changes.push(ContactChange {
                began: false,
                objects: pair,
            });
        }
        for &pair in now.difference(&self.touching) {
            changes.push(ContactChange {
                began: true,
                objects: pair,
            });
        }
        self.touching = now;
        changes
    }

    /// Removes object `index` with its shape, contacts and constraints; returns false when it is
    /// unknown or already gone.
    pub(super) fn remove(&mut self, index: usize) -> bool {
        if !self.space.remove_body(index) {
            return false;
        }
        let ended: Vec<[usize; 2]> = self
            .touching
            .iter()
            .filter(|p| p.contains(&index))
            .copied()
            .collect();
        for pair in ended {
            self.touching.remove(&pair);
            self.removed.push(pair);
        }
        true
    }

    /// The current body centre of object `index` (None once removed).
    pub(super) fn centre(&self, index: usize) -> Option<[f64; 2]> {
        let b = self.space.body(index)?;
        Some([b.p.x, b.p.y])
    }

    /// The current pose and velocities of object `index` (None once removed).
    pub(super) fn pose(&self, index: usize) -> Option<Pose> {
        let b = self.space.body(index)?;
        Some(Pose {
            centre: [b.p.x, b.p.y],
            angle: b.angle,
            velocity: [b.v.x, b.v.y],
            angular_velocity: b.w,
        })
    }
}
