//! [`RapierWorld`]: one PHYRE task plus the red user ball as rapier2d bodies, stepped at 60 Hz (the
//! `engine = "rapier"` backend of [`World`](super::world::World)).
//!
//! **Owns:** the task's rapier bodies and colliders (held and stepped by [`crate::envs::rapier::Physics`]),
//! the mapping between rapier handles and PHYRE body indices (scene bodies `0..n`, the user ball `n`), contact begin/end per body pair from rapier's collision events, and PHYRE's
//! "touching" test for the goal.
//! **Does not:** decide validity (`action.rs`), run the episode loop (`episode.rs`), build traces or
//! choose the engine (`world.rs`).
//!
//! Mapping (docs/envs/phyre.md §R5, §R7): the world is in metres, 6 px per metre, gravity −9.8 m/s², like PHYRE's
//! Box2D world. Each body keeps PHYRE's origin and angle; every polygon or circle becomes one collider on
//! it (a jar is three convex colliders on one body). Dynamic shapes have density 0.25 kg/m², static ones
//! none; every shape has friction 0.5 (rapier's `Average` rule gives Box2D's √(f₁f₂) = 0.5) and
//! restitution 0.2 (`Max`, as Box2D). Bodies get angular damping 0.01 and may sleep with Box2D's
//! rest time (0.5 s) and rapier's 0.05 m/s threshold (`PhysicsParams::sleep_linear`).

use std::collections::HashMap;

use rapier2d::prelude::*;

use crate::envs::rapier::Physics;

use super::error::{PhyreError, Result};
use super::params::{PIXELS_PER_METRE, PhysicsParams};
use super::task::{Shape, Task};
use super::world::{BodySpec, BodyState, ContactChange};

/// Box2D's `b2_angularSleepTolerance` (2°/s in rad/s).
const SLEEP_ANGULAR: f32 = 2.0 * std::f32::consts::PI / 180.0;

/// A task's bodies in rapier2d.
pub struct RapierWorld {
    bodies_of: Vec<RigidBodyHandle>,
    colliders_of: Vec<Vec<ColliderHandle>>,
    dynamic: Vec<usize>,
    /// The exact initial poses (f64, as given), reported for step 0.
    initial: Vec<BodyState>,
    goal: [usize; 2],
    /// Goal radii in metres when both goal bodies are single circles (PHYRE's ball–ball rule).
    two_ball: Option<(f32, f32)>,
    ball_threshold: f32,
    touch_distance: f32,
    active_pairs: HashMap<[usize; 2], u32>,
    bounce: BounceThreshold,
    physics: Physics,
}

/// Box2D's restitution rule: a contact bounces only when its bodies approach faster than the
/// threshold (`b2_velocityThreshold`, 1 m/s); slower contacts are inelastic. rapier bounces every new
/// contact, so this hook zeroes the restitution of slow ones.
struct BounceThreshold {
    threshold: f32,
}

impl PhysicsHooks for BounceThreshold {
    fn modify_solver_contacts(&self, context: &mut ContactModificationContext) {
        let (b1, b2) = (context.rigid_body1, context.rigid_body2);
        let bodies = context.bodies;
        let Some(m) = context.rigid_mut() else {
            return;
        };
        let n = *m.normal;
        let velocity_at = |h: Option<RigidBodyHandle>, p: Vector| {
            h.and_then(|h| bodies.get(h))
                .map_or(Vector::ZERO, |b| b.velocity_at_point(p))
        };
        let fastest = m
            .solver_contacts
            .iter()
            .map(|c| (velocity_at(b1, c.anchor1) - velocity_at(b2, c.anchor2)).dot(n))
            .fold(f32::NEG_INFINITY, f32::max);
        if fastest < self.threshold {
            *m.restitution = 0.0;
        }
    }
}

impl std::fmt::Debug for RapierWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RapierWorld")
            .field("bodies", &self.bodies_of.len())
            .field("goal", &self.goal)
            .finish_non_exhaustive()
    }
}

fn m(px: f64) -> f32 {
    (px / PIXELS_PER_METRE) as f32
}

impl RapierWorld {
    /// Builds the rapier world of `specs` (scene bodies in index order, the user ball last when present).
    pub(super) fn new(
        task: &Task,
        specs: Vec<BodySpec<'_>>,
        params: &PhysicsParams,
    ) -> Result<RapierWorld> {
        let integration = IntegrationParameters {
            dt: params.dt() as f32,
            num_solver_iterations: params.solver_iterations,
            num_internal_stabilization_iterations: params.stabilization_iterations,
            num_internal_pgs_iterations: params.pgs_iterations,
            contact_recycling: params.contact_recycling,
            normalized_prediction_distance: params.prediction_distance as f32,
            length_unit: 1.0,
            ..IntegrationParameters::default()
        };
        let mut bodies = RigidBodySet::new();
        let mut colliders = ColliderSet::new();
        let n = specs.len();
        let mut bodies_of = Vec::with_capacity(n);
        let mut colliders_of = Vec::with_capacity(n);
        let mut dynamic = Vec::new();
        let mut initial = Vec::with_capacity(n);
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
            let builder = if is_dynamic {
                dynamic.push(index);
                RigidBodyBuilder::dynamic()
            } else {
                RigidBodyBuilder::fixed()
            };
            let mut body = builder
                .translation(Vector::new(m(position[0]), m(position[1])))
                .rotation(angle as f32)
                .angular_damping(params.angular_damping as f32)
                .linear_damping(params.linear_damping as f32)
                .can_sleep(params.sleeping)
                .ccd_enabled(params.ccd && is_dynamic)
                .user_data(index as u128)
                .build();
            let a = body.activation_mut();
            a.normalized_linear_threshold = params.sleep_linear as f32;
            a.angular_threshold = SLEEP_ANGULAR;
            a.time_until_sleep = params.sleep_time as f32;
            let handle = bodies.insert(body);
            let mut mine = Vec::with_capacity(shapes.len());
            for (k, shape) in shapes.iter().enumerate() {
                let builder = match shape {
                    Shape::Circle { radius } => ColliderBuilder::ball(m(*radius)),
                    Shape::Polygon(vs) => {
                        let pts: Vec<Vector> =
                            vs.iter().map(|v| Vector::new(m(v[0]), m(v[1]))).collect();
                        ColliderBuilder::convex_polyline(pts.clone())
                            .or_else(|| ColliderBuilder::convex_hull(&pts))
                            .ok_or_else(|| PhyreError::InvalidTask {
                                field: format!("{} bodies[{index}].shapes[{k}]", task.task_id),
                                message: "degenerate polygon".into(),
                            })?
                    }
                };
                let builder = match shape {
                    Shape::Polygon(_) if params.polygon_skin > 0.0 => {
                        builder.contact_skin(params.polygon_skin as f32)
                    }
                    _ => builder,
                };
                let hooks = if params.restitution_threshold > 0.0 {
                    ActiveHooks::MODIFY_SOLVER_CONTACTS
                } else {
                    ActiveHooks::empty()
                };
                let collider = builder
                    .active_hooks(hooks)
                    .density(if is_dynamic {
                        params.density as f32
                    } else {
                        0.0
                    })
                    .friction(params.friction as f32)
                    .restitution(params.restitution as f32)
                    .friction_combine_rule(CoefficientCombineRule::Average)
                    .restitution_combine_rule(CoefficientCombineRule::Max)
                    .active_events(ActiveEvents::COLLISION_EVENTS)
                    .user_data(index as u128)
                    .build();
                mine.push(colliders.insert_with_parent(collider, handle, &mut bodies));
            }
            bodies_of.push(handle);
            colliders_of.push(mine);
        }
        let two_ball = task.two_ball_goal().then(|| {
            let r = |i: usize| match task.bodies[i].shapes[0] {
                Shape::Circle { radius } => m(radius),
                Shape::Polygon(_) => 0.0,
            };
            (r(task.body1), r(task.body2))
        });
        Ok(RapierWorld {
            bodies_of,
            colliders_of,
            dynamic,
            initial,
            goal: [task.body1, task.body2],
            two_ball,
            ball_threshold: m(params.ball_touch_threshold_px),
            touch_distance: params.touch_distance as f32,
            active_pairs: HashMap::new(),
            bounce: BounceThreshold {
                threshold: params.restitution_threshold as f32,
            },
            physics: Physics::new(
                Vector::new(0.0, -params.gravity as f32),
                integration,
                bodies,
                colliders,
                ImpulseJointSet::new(),
            ),
        })
    }

    /// Number of bodies (the user ball included).
    pub fn len(&self) -> usize {
        self.bodies_of.len()
    }

    /// Advances one step and appends the body-pair contact changes of that step to `out`. A jar touching
    /// a ball with two of its parts is one contact: it begins with the first part and ends with the last.
    pub fn step(&mut self, out: &mut Vec<ContactChange>) {
        let active_pairs = &mut self.active_pairs;
        self.physics
            .step_with_hooks(&self.bounce, |colliders, event| {
                let index = |h: ColliderHandle| colliders.get(h).map(|c| c.user_data as usize);
                let (Some(a), Some(b)) = (index(event.collider1()), index(event.collider2()))
                else {
                    return;
                };
                if a == b {
                    return;
                }
                let key = [a.min(b), a.max(b)];
                let count = active_pairs.entry(key).or_insert(0);
                if event.started() {
                    *count += 1;
                    if *count == 1 {
                        out.push(ContactChange {
                            began: true,
                            objects: key,
                        });
                    }
                } else if *count > 0 {
                    *count -= 1;
                    if *count == 0 {
                        out.push(ContactChange {
                            began: false,
                            objects: key,
                        });
                    }
                }
            });
    }

    /// PHYRE's goal test: the two goal balls' centres closer than r₁ + r₂ + 0.1 px, or else a contact
    /// between the goal bodies closer than `touch_distance`.
    pub fn goal_holds(&self) -> bool {
        let [g1, g2] = self.goal;
        if let Some((r1, r2)) = self.two_ball {
            let p1 = self.physics.bodies[self.bodies_of[g1]].translation();
            let p2 = self.physics.bodies[self.bodies_of[g2]].translation();
            return (p1 - p2).length() < r1 + r2 + self.ball_threshold;
        }
        self.touching(g1, g2)
    }

    /// Whether bodies `a` and `b` touch: some contact point between their colliders is closer than
    /// `touch_distance` (negative distances are penetrations).
    pub fn touching(&self, a: usize, b: usize) -> bool {
        let (Some(ca), Some(cb)) = (self.colliders_of.get(a), self.colliders_of.get(b)) else {
            return false;
        };
        ca.iter().any(|&h1| {
            cb.iter().any(|&h2| {
                self.physics
                    .narrow_phase
                    .contact_pair(h1, h2)
                    .is_some_and(|pair| {
                        pair.manifolds()
                            .iter()
                            .any(|mf| mf.points.iter().any(|p| p.dist <= self.touch_distance))
                    })
            })
        })
    }

    /// Whether every dynamic body sleeps (then nothing moves until the episode ends).
    pub fn all_asleep(&self) -> bool {
        self.dynamic
            .iter()
            .all(|&i| self.physics.bodies[self.bodies_of[i]].is_sleeping())
    }

    /// The indices of the dynamic bodies.
    pub fn dynamic_bodies(&self) -> &[usize] {
        &self.dynamic
    }

    /// The state of body `index` in scene units.
    pub fn state(&self, index: usize) -> Option<BodyState> {
        let body = self.physics.bodies.get(*self.bodies_of.get(index)?)?;
        let t = body.translation();
        let v = body.linvel();
        let k = PIXELS_PER_METRE;
        Some(BodyState {
            index,
            x: t.x as f64 * k,
            y: t.y as f64 * k,
            angle: body.rotation().angle() as f64,
            vx: v.x as f64 * k,
            vy: v.y as f64 * k,
            angular_velocity: body.angvel() as f64,
        })
    }

    /// The bodies' exact initial states (as given).
    pub fn initial_states(&self) -> &[BodyState] {
        &self.initial
    }
}
