//! A small rigid-body step with Chipmunk2D 7's semantics, for scenes of tens of bodies made of circles
//! and capsule segments joined by pin joints and damped springs (annotrace's I-PHYRE worlds, whose
//! original runs on pymunk).
//!
//! What makes it Chipmunk's rather than another impulse solver's: positions move first, with the
//! velocity plus a bias velocity; overlap beyond the collision slop is removed by bias impulses solved in
//! the same iterations as the velocity impulses (no separate position pass); contacts come from
//! Chipmunk's circle and segment tests and keep their accumulated impulses across steps by contact
//! hash; friction and elasticity are the products of the two shapes'; pin joints and springs are solved
//! in the same loop as the contacts. The algorithm was studied from Chipmunk's sources and written anew.
//!
//! **Owns:** the space, its bodies, shapes, constraints and contact cache, and the step.
//! **Does not:** know about games, pixels or clicks (the I-PHYRE world in annotrace does), sleeping,
//! polygons, sensors or collision callbacks. Its spatial index (`bbtree`) is there for the order in
//! which it reports touching pairs, which is the contact solver's order and shows in trajectories.

mod arbiter;
mod bbtree;
mod body;
mod collide;
mod constraint;
mod shape;
mod space;
mod vect;

pub use body::{Body, BodyKind};
pub use constraint::{Constraint, DampedSpring, PinJoint};
pub use shape::Geometry;
pub use space::{BodyId, ContactReport, Space, default_bias};
pub use vect::Vect;
