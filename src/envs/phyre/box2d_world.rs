//! [`Box2dWorld`]: one PHYRE task plus the red user ball in Box2D (the `box2d-rs` crate, a Rust port of
//! Box2D 2.4.1), built and stepped the way PHYRE 0.2.2 builds and steps its Box2D world.
//!
//! **Owns:** the Box2D world of one episode, the mapping from fixtures to PHYRE body indices (user data),
//! contact begin/end per body pair from Box2D's contact listener, and PHYRE's goal test on Box2D's
//! contact graph (`IsTouching`, and the ball–ball distance rule).
//! **Does not:** decide validity (`action.rs`), run the episode loop (`episode.rs`) or choose the engine
//! (`world.rs`).
//!
//! Construction follows PHYRE's `thrift_box2d_conversion.cpp` (docs/envs/phyre.md §R5): bodies are created
//! in scene order and the user ball last; every length goes to `f32` first and is then divided by
//! `PIXELS_IN_METER` in `f32` (`p2m`); each polygon or circle is one fixture with density 0.25 on dynamic
//! bodies (0 on static ones), friction 0.5 and restitution 0.2; bodies get angular damping 0.01. The world
//! steps with `dt = 1/60` (f32), 15 velocity and 20 position iterations, sleeping, warm starting and
//! continuous collision on (Box2D's defaults, which PHYRE keeps). With `box2d_phyre_compat` (default)
//! dynamic bodies get the mass data and gravity scale that make 2.4.1 compute what PHYRE's 2018 Box2D
//! computes (`box2d_compat.rs`).

use std::cell::RefCell;
use std::rc::Rc;

use box2d_phyre::Phyre;
use box2d_rs::b2_body::{B2bodyDef, B2bodyType, BodyPtr};
use box2d_rs::b2_fixture::B2fixtureDef;
use box2d_rs::b2_math::B2vec2;
use box2d_rs::b2_world::B2worldPtr;
use box2d_rs::shapes::b2_circle_shape::B2circleShape;
use box2d_rs::shapes::b2_polygon_shape::B2polygonShape;

use super::box2d_compat::{Fixture, legacy_gravity_scale, legacy_mass_data};
use super::error::{PhyreError, Result};
use super::params::{PIXELS_PER_METRE, PhysicsParams};
use super::task::{Shape, Task};
use crate::envs::box2d_contacts::PairContacts;

use super::world::{BodySpec, BodyState, ContactChange};

/// PHYRE's velocity and position iterations (`kVelocityIterations`, `kPositionIterations`).
const VELOCITY_ITERATIONS: i32 = 15;
const POSITION_ITERATIONS: i32 = 20;

/// Box2D's `b2_maxPolygonVertices`.
const MAX_POLYGON_VERTICES: usize = 8;

/// PHYRE's `p2m`: pixels (a double in PHYRE's scene) to metres, in `f32` as PHYRE computes it.
fn p2m(px: f64) -> f32 {
    px as f32 / PIXELS_PER_METRE as f32
}

/// A task's bodies in Box2D.
pub struct Box2dWorld {
    world: B2worldPtr<Phyre>,
    bodies_of: Vec<BodyPtr<Phyre>>,
    dynamic: Vec<usize>,
    initial: Vec<BodyState>,
    goal: [usize; 2],
    /// Goal radii in metres when both goal bodies are single circles (PHYRE's ball–ball rule).
    two_ball: Option<(f32, f32)>,
    ball_threshold: f32,
    listener: Rc<RefCell<PairContacts>>,
    dt: f32,
}

impl std::fmt::Debug for Box2dWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Box2dWorld")
            .field("bodies", &self.bodies_of.len())
            .field("goal", &self.goal)
            .finish_non_exhaustive()
    }
}

impl Drop for Box2dWorld {
    fn drop(&mut self) {
        // box2d-rs links bodies, contacts and the world through reference-counted lists: destroy the
        // bodies (which removes their contacts) so nothing is kept alive by a cycle.
        for body in self.bodies_of.drain(..) {
            box2d_phyre::destroy_body(&self.world, body);
        }
    }
}

/// Box2D's polygon for PHYRE's vertices (px, counter-clockwise), or `None` when Box2D would refuse it
/// (more than 8 vertices, or fewer than 3 after welding: `b2PolygonShape::Set` asserts on those).
fn polygon(vs: &[[f64; 2]]) -> Option<B2polygonShape> {
    if vs.len() < 3 || vs.len() > MAX_POLYGON_VERTICES {
        return None;
    }
    let pts: Vec<B2vec2> = vs
        .iter()
        .map(|v| B2vec2::new(p2m(v[0]), p2m(v[1])))
        .collect();
    // Box2D welds vertices closer than half a linear slop and needs three left in convex position:
    // check the area so `set` cannot assert.
    let mut area2 = 0.0f64;
    for i in 0..pts.len() {
        let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
        area2 += f64::from(a.x) * f64::from(b.y) - f64::from(b.x) * f64::from(a.y);
    }
    if area2.is_nan() || area2.abs() <= 1e-6 {
        return None;
    }
    let mut shape = B2polygonShape::default();
    shape.set(&pts);
    Some(shape)
}

impl Box2dWorld {
    /// Builds the Box2D world of `specs` (scene bodies in index order, the user ball last when present).
    pub(super) fn new(
        task: &Task,
        specs: Vec<BodySpec<'_>>,
        params: &PhysicsParams,
    ) -> Result<Box2dWorld> {
        let (dt, gravity) = (params.dt() as f32, -(params.gravity as f32));
        let world = box2d_phyre::new_world(B2vec2::new(0.0, gravity));
        let listener = Rc::new(RefCell::new(PairContacts::default()));
        {
            let mut w = world.borrow_mut();
            w.set_contact_listener(listener.clone());
            w.set_allow_sleeping(params.sleeping);
        }
        let mut bodies_of = Vec::with_capacity(specs.len());
        let mut dynamic = Vec::new();
        let mut initial = Vec::with_capacity(specs.len());
        for (index, is_dynamic, position, angle, shapes) in specs {
            initial.push(BodyState {
                index,
                x: position[0],
                y: position[1],
                angle,
                vx: 0.0,
                vy: 0.0,
                angular_velocity: 0.0,
            });
            if is_dynamic {
                dynamic.push(index);
            }
            let def = B2bodyDef::<Phyre> {
                body_type: if is_dynamic {
                    B2bodyType::B2DynamicBody
                } else {
                    B2bodyType::B2StaticBody
                },
                position: B2vec2::new(p2m(position[0]), p2m(position[1])),
                angle: angle as f32,
                angular_damping: params.angular_damping as f32,
                linear_damping: params.linear_damping as f32,
                allow_sleep: params.sleeping,
                user_data: Some(index),
                ..B2bodyDef::default()
            };
            let body = box2d_phyre::create_body(&world, &def);
            let mut fixtures = Vec::with_capacity(shapes.len());
            for (k, shape) in shapes.iter().enumerate() {
                let shape: Rc<RefCell<dyn box2d_rs::b2_shape::B2shapeDynTrait>> = match shape {
                    Shape::Circle { radius } => {
                        let mut c = B2circleShape::default();
                        c.base.m_radius = p2m(*radius);
                        fixtures.push(Fixture::Circle(c.base.m_radius));
                        Rc::new(RefCell::new(c))
                    }
                    Shape::Polygon(vs) => {
                        let p = polygon(vs).ok_or_else(|| PhyreError::InvalidTask {
                            field: format!("{} bodies[{index}].shapes[{k}]", task.task_id),
                            message: "not a convex polygon of 3 to 8 vertices".into(),
                        })?;
                        fixtures.push(Fixture::Polygon(p.m_vertices[..p.m_count].to_vec()));
                        Rc::new(RefCell::new(p))
                    }
                };
                let fixture = B2fixtureDef::<Phyre> {
                    shape: Some(shape),
                    density: if is_dynamic {
                        params.density as f32
                    } else {
                        0.0
                    },
                    friction: params.friction as f32,
                    restitution: params.restitution as f32,
                    user_data: Some(index),
                    ..B2fixtureDef::default()
                };
                box2d_phyre::create_fixture(&body, &fixture);
            }
            if is_dynamic && params.box2d_phyre_compat {
                let mut b = body.borrow_mut();
                b.set_mass_data(&legacy_mass_data(&fixtures, params.density as f32));
                let scale = legacy_gravity_scale(b.get_mass(), dt, gravity);
                b.set_gravity_scale(scale);
            }
            bodies_of.push(body);
        }
        let two_ball = task.two_ball_goal().then(|| {
            let r = |i: usize| match task.bodies[i].shapes[0] {
                Shape::Circle { radius } => p2m(radius),
                Shape::Polygon(_) => 0.0,
            };
            (r(task.body1), r(task.body2))
        });
        Ok(Box2dWorld {
            world,
            bodies_of,
            dynamic,
            initial,
            goal: [task.body1, task.body2],
            two_ball,
            ball_threshold: p2m(params.ball_touch_threshold_px),
            listener,
            dt,
        })
    }

    /// Number of bodies (the user ball included).
    pub fn len(&self) -> usize {
        self.bodies_of.len()
    }

    /// One Box2D step; appends the step's body-pair contact changes to `out`.
    pub fn step(&mut self, out: &mut Vec<ContactChange>) {
        box2d_phyre::step(
            &self.world,
            self.dt,
            VELOCITY_ITERATIONS,
            POSITION_ITERATIONS,
        );
        out.extend(
            self.listener
                .borrow_mut()
                .changes
                .drain(..)
                .map(|(began, objects)| ContactChange { began, objects }),
        );
    }

    /// PHYRE's goal test (`isTaskInSolvedState`): for two goal balls, centre distance < r₁ + r₂ + 0.1 px
    /// (in `f32`); otherwise a contact between the goal bodies that Box2D reports as touching.
    pub fn goal_holds(&self) -> bool {
        let [g1, g2] = self.goal;
        if let Some((r1, r2)) = self.two_ball {
            let p1 = self.bodies_of[g1].borrow().get_position();
            let p2 = self.bodies_of[g2].borrow().get_position();
            let (dx, dy) = (p1.x - p2.x, p1.y - p2.y);
            return (dx * dx + dy * dy).sqrt() < r1 + r2 + self.ball_threshold;
        }
        self.touching(g1, g2)
    }

    /// PHYRE's `isTouching`: some contact in `a`'s contact list has `b` as its other body and is
    /// touching (PHYRE's goal bodies are scene bodies, never the user ball).
    pub fn touching(&self, a: usize, b: usize) -> bool {
        let (Some(body_a), Some(body_b)) = (self.bodies_of.get(a), self.bodies_of.get(b)) else {
            return false;
        };
        let body = body_a.borrow();
        body.get_contact_list().iter().any(|edge| {
            let edge = edge.borrow();
            let other_is_b = edge.other.upgrade().is_some_and(|o| Rc::ptr_eq(&o, body_b));
            other_is_b
                && edge
                    .contact
                    .upgrade()
                    .is_some_and(|c| c.borrow().get_base().is_touching())
        })
    }

    /// Whether every dynamic body sleeps.
    pub fn all_asleep(&self) -> bool {
        self.dynamic
            .iter()
            .all(|&i| !self.bodies_of[i].borrow().is_awake())
    }

    /// The indices of the dynamic bodies.
    pub fn dynamic_bodies(&self) -> &[usize] {
        &self.dynamic
    }

    /// The state of body `index` in scene units.
    pub fn state(&self, index: usize) -> Option<BodyState> {
        let body = self.bodies_of.get(index)?.borrow();
        let p = body.get_position();
        let v = body.get_linear_velocity();
        // PHYRE's `m2p`, in f32 as PHYRE reports positions.
        let m2p = |m: f32| f64::from(m * PIXELS_PER_METRE as f32);
        Some(BodyState {
            index,
            x: m2p(p.x),
            y: m2p(p.y),
            angle: f64::from(body.get_angle()),
            vx: m2p(v.x),
            vy: m2p(v.y),
            angular_velocity: f64::from(body.get_angular_velocity()),
        })
    }

    /// The bodies' exact initial states.
    pub fn initial_states(&self) -> &[BodyState] {
        &self.initial
    }
}
