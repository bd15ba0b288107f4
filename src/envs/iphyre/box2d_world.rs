//! [`Box2dWorld`]: one I-PHYRE game in Box2D (the `box2d-rs` crate, a Rust port of Box2D 2.4.1), set up
//! to behave like the original's Chipmunk 7 space (`engine = "box2d"`).
//!
//! **Owns:** the Box2D world of one episode, the mapping from Box2D bodies to the game's object indices
//! (user data), pymunk's damped springs (applied as impulses before each step), object removal, and
//! contact begin/end per object pair from Box2D's contact listener.
//! **Does not:** choose the engine or compute object ends (`world.rs`), decide when to remove a block
//! (`action.rs`, `step.rs`), judge success (`success.rs`) or build traces (`to_trace.rs`).
//!
//! Why Box2D: Chipmunk and Box2D 2.x solve contacts the same way — hard contacts, sequential impulses on
//! accumulated (clamped) impulses, warm starting from the previous step's impulses, friction before the
//! normal impulse in each iteration, contact points that persist by feature id — where rapier's
//! contacts are soft springs (`docs/fidelity.md`, "Where trajectories part: I-PHYRE"). The mapping onto
//! Chipmunk's semantics (docs/envs/iphyre.md §R2):
//!
//! * **Units.** Pixels are divided by `box2d_pixels_per_metre` (20), y stays down (gravity +y). Box2D's
//!   tolerances are fixed in metres; at 20 px per metre its linear slop (0.005 m) is Chipmunk's collision
//!   slop, 0.1 px.
//! * **Shapes.** A ball is a circle. A block (pymunk `Segment` of radius 10, a capsule) is three fixtures:
//!   a box of the segment's length and the capsule's thickness (its polygon radius, Box2D's skin, is
//!   `box2d_polygon_skin`, taken off the box) and a disc of radius 10 at each end. Box2D's polygon
//!   collision extends a contact face by the polygon radius, flat: a capsule made as one thin box with
//!   a 10 px radius supports a bar up to 10 px past its end, where Chipmunk's rounded end lets it tip.
//! * **Materials.** Chipmunk multiplies the two shapes' coefficients; Box2D mixes friction as √(f₁f₂)
//!   and restitution as max(e₁, e₂). Every I-PHYRE shape has the same 0.5 / 0.1, so each fixture gets the
//!   product itself (0.25 / 0.01) and Box2D's mixing returns it. Chipmunk applies restitution at any
//!   approach speed: the restitution threshold is 0.
//! * **Mass.** Set explicitly: balls mass 1 with inertia r²/2, dynamic blocks mass 1 with inertia 66.67,
//!   all about the body origin (the segment midpoint or the ball centre).
//! * **Step.** One step of `1/fps` with `box2d_velocity_iterations` (10, Chipmunk's) and
//!   `box2d_position_iterations`; no continuous collision and no sleeping (Chipmunk's default space has
//!   neither). Box2D moves positions after solving velocities, Chipmunk before; Box2D's state after step
//!   k is Chipmunk's after step k + 1 (the same shift as rapier with one substep).
//! * **Constraints.** A pin joint is a rigid distance joint between the body centres (both limits at the
//!   initial distance) whose bodies still collide (Chipmunk's `collideBodies` is true). A damped spring
//!   is Chipmunk's: before each step the spring force `k·(rest − d)` acts for `dt` along the centre
//!   line, and the relative normal velocity is damped by `1 − exp(−c·dt·(1/m₁ + 1/m₂))`.

use std::cell::RefCell;
use std::rc::Rc;

use box2d_rs::b2_body::{B2body, B2bodyDef, B2bodyType, BodyPtr};
use box2d_rs::b2_fixture::B2fixtureDef;
use box2d_rs::b2_joint::B2JointDefEnum;
use box2d_rs::b2_math::B2vec2;
use box2d_rs::b2_shape::B2massData;
use box2d_rs::b2_world::{B2world, B2worldPtr};
use box2d_rs::b2rs_common::UserDataType;
use box2d_rs::joints::b2_distance_joint::B2distanceJointDef;
use box2d_rs::shapes::b2_circle_shape::B2circleShape;
use box2d_rs::shapes::b2_polygon_shape::B2polygonShape;

use super::error::Result;
use super::game::{Game, ObjectKind};
use super::params::PhysicsParams;
use crate::envs::box2d_contacts::PairContacts;

use super::world::{ContactChange, Pose};

/// The user data Box2D carries: every body and fixture holds its object index.
#[derive(Debug, Default, Clone)]
struct Iphyre;

impl UserDataType for Iphyre {
    type Fixture = usize;
    type Body = usize;
    type Joint = ();
}

/// A damped spring between two body centres (pymunk `DampedSpring` with zero anchors).
#[derive(Debug, Clone, Copy)]
struct Spring {
    objects: [usize; 2],
    rest: f32,
    stiffness: f32,
    damping: f32,
}

/// A game's bodies in Box2D.
pub(super) struct Box2dWorld {
    world: B2worldPtr<Iphyre>,
    bodies_of: Vec<Option<BodyPtr<Iphyre>>>,
    springs: Vec<Spring>,
    listener: Rc<RefCell<PairContacts>>,
    dt: f32,
    velocity_iterations: i32,
    position_iterations: i32,
    /// Pixels per Box2D metre.
    scale: f64,
}

impl std::fmt::Debug for Box2dWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Box2dWorld")
            .field("bodies", &self.bodies_of.iter().flatten().count())
            .field("springs", &self.springs.len())
            .finish_non_exhaustive()
    }
}

impl Drop for Box2dWorld {
    fn drop(&mut self) {
        // box2d-rs links bodies, contacts and the world through reference-counted lists: destroy the
        // bodies (which removes their contacts and joints) so nothing is kept alive by a cycle.
        let mut world = self.world.borrow_mut();
        for body in self.bodies_of.drain(..).flatten() {
            world.destroy_body(body);
        }
    }
}

impl Box2dWorld {
    /// Builds `game`'s bodies, fixtures, pin joints and springs.
    pub(super) fn new(game: &Game, params: &PhysicsParams) -> Result<Box2dWorld> {
        let scale = params.box2d_pixels_per_metre;
        let m = |px: f64| (px / scale) as f32;
        let world = B2world::<Iphyre>::new(B2vec2::new(0.0, m(params.gravity)));
        let listener = Rc::new(RefCell::new(PairContacts::default()));
        {
            let mut w = world.borrow_mut();
            w.set_contact_listener(listener.clone());
            w.set_allow_sleeping(false);
            w.set_continuous_physics(false);
            w.set_warm_starting(true);
        }
        let mut bodies_of = Vec::with_capacity(game.objects.len());
        for o in &game.objects {
            let c = o.centre();
            let def = B2bodyDef::<Iphyre> {
                body_type: if o.dynamic {
                    B2bodyType::B2DynamicBody
                } else {
                    B2bodyType::B2StaticBody
                },
                position: B2vec2::new(m(c[0]), m(c[1])),
                allow_sleep: false,
                user_data: Some(o.index),
                ..B2bodyDef::default()
            };
            let body = B2world::create_body(world.clone(), &def);
            let mut shapes: Vec<Rc<RefCell<dyn box2d_rs::b2_shape::B2shapeDynTrait>>> = Vec::new();
            let circle = |centre: [f64; 2], radius: f64| {
                let mut s = B2circleShape::default();
                s.base.m_radius = m(radius);
                s.m_p = B2vec2::new(m(centre[0]), m(centre[1]));
                Rc::new(RefCell::new(s))
            };
            match o.kind {
                ObjectKind::Ball => shapes.push(circle([0.0, 0.0], o.radius)),
                ObjectKind::Block => {
                    let (dx, dy) = (o.p2[0] - o.p1[0], o.p2[1] - o.p1[1]);
                    let half = 0.5 * dx.hypot(dy);
                    let skin = params.box2d_polygon_skin;
                    // The capsule as the union of a box and two end discs: Box2D's rounded polygons
                    // extend their contact faces by the radius (no rounded ends), so the radius stays a
                    // skin and the ends are circles.
                    if half > 0.0 {
                        let mut b = B2polygonShape::default();
                        b.set_as_box_angle(
                            m(half),
                            m(params.block_radius - skin),
                            B2vec2::zero(),
                            dy.atan2(dx) as f32,
                        );
                        b.base.m_radius = m(skin);
                        shapes.push(Rc::new(RefCell::new(b)));
                    }
                    let c = o.centre();
                    for p in [o.p1, o.p2] {
                        shapes.push(circle([p[0] - c[0], p[1] - c[1]], params.block_radius));
                        if half == 0.0 {
                            break;
                        }
                    }
                }
            }
            for shape in shapes {
                let fixture = B2fixtureDef::<Iphyre> {
                    shape: Some(shape),
                    density: 0.0,
                    friction: (params.friction * params.friction) as f32,
                    restitution: (params.restitution * params.restitution) as f32,
                    restitution_threshold: 0.0,
                    user_data: Some(o.index),
                    ..B2fixtureDef::default()
                };
                B2body::create_fixture(body.clone(), &fixture);
            }
            if o.dynamic {
                let (mass, inertia) = match o.kind {
                    ObjectKind::Ball => (
                        params.ball_mass,
                        params.ball_mass * o.radius * o.radius / 2.0,
                    ),
                    ObjectKind::Block => (params.block_mass, params.block_inertia),
                };
                body.borrow_mut().set_mass_data(&B2massData {
                    mass: mass as f32,
                    center: B2vec2::zero(),
                    i: (inertia / (scale * scale)) as f32,
                });
            }
            bodies_of.push(Some(body));
        }
        for &[a, b] in &game.joints {
            let (Some(Some(ba)), Some(Some(bb))) = (bodies_of.get(a), bodies_of.get(b)) else {
                continue;
            };
            let (pa, pb) = (game.objects[a].centre(), game.objects[b].centre());
            let mut def = B2distanceJointDef::<Iphyre>::default();
            def.initialize(
                ba.clone(),
                bb.clone(),
                B2vec2::new(m(pa[0]), m(pa[1])),
                B2vec2::new(m(pb[0]), m(pb[1])),
            );
            def.base.collide_connected = true;
            world
                .borrow_mut()
                .create_joint(&B2JointDefEnum::DistanceJoint(def));
        }
        let springs = game
            .springs
            .iter()
            .map(|&objects| Spring {
                objects,
                rest: m(params.spring_rest_length),
                // Force per metre of stretch: k px-units of force per px, in Box2D's units.
                stiffness: params.spring_stiffness as f32,
                damping: params.spring_damping as f32,
            })
            .collect();
        Ok(Box2dWorld {
            world,
            bodies_of,
            springs,
            listener,
            dt: params.dt() as f32,
            velocity_iterations: params.box2d_velocity_iterations.min(i32::MAX as usize) as i32,
            position_iterations: params.box2d_position_iterations.min(i32::MAX as usize) as i32,
            scale,
        })
    }

    /// Chipmunk's damped springs for one step: the spring impulse `k·(rest − d)·dt` and the damping
    /// impulse along the centre line, before Box2D integrates gravity and solves contacts.
    fn apply_springs(&self) {
        let dt = self.dt;
        for s in &self.springs {
            let [a, b] = s.objects;
            let (Some(Some(ba)), Some(Some(bb))) = (self.bodies_of.get(a), self.bodies_of.get(b))
            else {
                continue;
            };
            let (pa, va, ima) = {
                let body = ba.borrow();
                (
                    body.get_position(),
                    body.get_linear_velocity(),
                    inv_mass(&body),
                )
            };
            let (pb, vb, imb) = {
                let body = bb.borrow();
                (
                    body.get_position(),
                    body.get_linear_velocity(),
                    inv_mass(&body),
                )
            };
            let k = ima + imb;
            if k == 0.0 {
                continue;
            }
            let delta = pb - pa;
            let dist = delta.length();
            let n = if dist > 0.0 {
                B2vec2::new(delta.x / dist, delta.y / dist)
            } else {
                B2vec2::new(0.0, 0.0)
            };
            let f_spring = (s.rest - dist) * s.stiffness;
            let vrn = (vb.x - va.x) * n.x + (vb.y - va.y) * n.y;
            let v_coef = 1.0 - (-s.damping * dt * k).exp();
            let j = f_spring * dt - vrn * v_coef / k;
            let impulse = B2vec2::new(n.x * j, n.y * j);
            ba.borrow_mut()
                .apply_linear_impulse_to_center(B2vec2::new(-impulse.x, -impulse.y), true);
            bb.borrow_mut()
                .apply_linear_impulse_to_center(impulse, true);
        }
    }

    /// One Box2D step; the contact changes of the step (and of removals since the last step).
    pub(super) fn step(&mut self) -> Vec<ContactChange> {
        self.apply_springs();
        self.world
            .borrow_mut()
            .step(self.dt, self.velocity_iterations, self.position_iterations);
        let changes = std::mem::take(&mut self.listener.borrow_mut().changes);
        changes
            .into_iter()
            .map(|(began, objects)| ContactChange { began, objects })
            .collect()
    }

    /// Removes object `index` with its fixture, contacts and joints (its springs stop acting); returns
    /// false when it is unknown or already gone.
    pub(super) fn remove(&mut self, index: usize) -> bool {
        let Some(body) = self.bodies_of.get_mut(index).and_then(Option::take) else {
            return false;
        };
        self.world.borrow_mut().destroy_body(body);
        true
    }

    /// The current body centre of object `index` (None once removed).
    pub(super) fn centre(&self, index: usize) -> Option<[f64; 2]> {
        let body = self.bodies_of.get(index)?.as_ref()?.borrow();
        let p = body.get_position();
        Some([f64::from(p.x) * self.scale, f64::from(p.y) * self.scale])
    }

    /// The current pose and velocities of object `index` (None once removed).
    pub(super) fn pose(&self, index: usize) -> Option<Pose> {
        let body = self.bodies_of.get(index)?.as_ref()?.borrow();
        let (p, v) = (body.get_position(), body.get_linear_velocity());
        Some(Pose {
            centre: [f64::from(p.x) * self.scale, f64::from(p.y) * self.scale],
            angle: f64::from(body.get_angle()),
            velocity: [f64::from(v.x) * self.scale, f64::from(v.y) * self.scale],
            angular_velocity: f64::from(body.get_angular_velocity()),
        })
    }
}

/// A body's inverse mass (0 for static bodies).
fn inv_mass(body: &B2body<Iphyre>) -> f32 {
    let mass = body.get_mass();
    if mass > 0.0 { 1.0 / mass } else { 0.0 }
}
