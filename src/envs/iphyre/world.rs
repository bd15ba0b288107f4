//! [`World`]: one I-PHYRE game as rapier2d bodies, colliders and joints, stepped at a fixed `dt`.
//!
//! **Owns:** the game's rapier bodies, colliders and joints (held and stepped by
//! [`crate::envs::rapier::Physics`]), the mapping between rapier handles and the game's stable object
//! indices, object removal, and contact begin/end changes reported by rapier's collision events.
//! **Does not:** decide when to remove a block (`action.rs`, `step.rs`), judge success (`success.rs`)
//! or build traces (`to_trace.rs`).
//!
//! The mapping follows docs/envs/iphyre.md §R2 and §R9: screen pixels with y down (gravity `+y`), blocks as
//! fixed or dynamic bodies at the segment midpoint carrying `capsule_from_endpoints(a, b, 10)`, balls
//! as `ball(r)`; masses and inertias are set explicitly (collider density 0 plus additional mass
//! properties) so that balls weigh 1 with inertia r²/2 and dynamic blocks weigh 1 with inertia 66.67
//! whatever their length. Chipmunk multiplies the two shapes' friction and elasticity, so every
//! collider uses rapier's `Multiply` combine rule with the per-shape values 0.5 and 0.1 (effective
//! 0.25 and 0.01). Pin joints are rigid rods between body centres: a generic joint with coupled
//! linear axes whose distance limits are both the initial centre distance (a rope joint would only
//! hold in tension). Springs are rapier spring joints with the force-based model. Nothing sleeps
//! (Chipmunk's default space has no sleeping).

use std::collections::HashMap;

use rapier2d::prelude::*;

use crate::envs::rapier::Physics;

use super::error::Result;
use super::game::{Game, GameObject, ObjectKind};
use super::params::PhysicsParams;

/// A contact change between two objects during one step (from rapier's collision events).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ContactChange {
    /// True when the two objects started touching, false when they stopped.
    pub began: bool,
    /// The two object indices, smaller first.
    pub objects: [usize; 2],
}

/// The state of one present object, in the game's coordinates (px, y down, radians).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectState {
    /// Original object index.
    pub index: usize,
    /// Current first end (a ball: its centre), rotated with the body.
    pub p1: [f64; 2],
    /// Current second end (a ball: its centre).
    pub p2: [f64; 2],
    /// Body centre.
    pub centre: [f64; 2],
    /// Body angle (rad).
    pub angle: f64,
    /// Centre velocity (px/s).
    pub velocity: [f64; 2],
    /// Angular velocity (rad/s).
    pub angular_velocity: f64,
}

/// A game's rigid bodies in rapier2d.
pub struct World {
    objects: Vec<GameObject>,
    bodies_of: Vec<Option<RigidBodyHandle>>,
    object_of_collider: HashMap<ColliderHandle, usize>,
    physics: Physics,
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("World")
            .field("objects", &self.objects.len())
            .field("present", &self.present().count())
            .finish_non_exhaustive()
    }
}

fn v(p: [f64; 2]) -> Vector {
    Vector::new(p[0] as f32, p[1] as f32)
}

impl World {
    /// Builds the bodies, colliders and constraints of `game` in its initial state.
    pub fn new(game: &Game, params: &PhysicsParams) -> Result<World> {
        params.validate()?;
        let mut integration = IntegrationParameters {
            dt: params.dt() as f32,
            num_solver_iterations: params.solver_iterations,
            num_internal_stabilization_iterations: params.stabilization_iterations,
            num_internal_pgs_iterations: params.pgs_iterations,
            length_unit: params.length_unit as f32,
            ..IntegrationParameters::default()
        };
        if params.contact_frequency > 0.0 {
            let soft = SpringCoefficients::new(
                params.contact_frequency as f32,
                params.contact_damping_ratio as f32,
            );
            integration.contact_softness = soft;
            integration.static_contact_softness = soft;
        }
        if params.max_corrective_velocity > 0.0 {
            integration.normalized_max_corrective_velocity =
                (params.max_corrective_velocity / params.length_unit) as f32;
        }

        let mut bodies = RigidBodySet::new();
        let mut colliders = ColliderSet::new();
        let mut impulse_joints = ImpulseJointSet::new();
        let mut bodies_of = Vec::with_capacity(game.objects.len());
        let mut object_of_collider = HashMap::new();
        for o in &game.objects {
            let centre = o.centre();
            let builder = if o.dynamic {
                RigidBodyBuilder::dynamic()
            } else {
                RigidBodyBuilder::fixed()
            };
            let (mass, inertia) = match o.kind {
                ObjectKind::Ball => (
                    params.ball_mass,
                    params.ball_mass * o.radius * o.radius / 2.0,
                ),
                ObjectKind::Block => (params.block_mass, params.block_inertia),
            };
            let mut builder = builder
                .translation(v(centre))
                .can_sleep(false)
                .user_data(o.index as u128);
            if o.dynamic {
                builder = builder.additional_mass_properties(MassProperties::new(
                    Vector::ZERO,
                    mass as f32,
                    inertia as f32,
                ));
            }
            let handle = bodies.insert(builder.build());
            let shape = match o.kind {
                ObjectKind::Ball => ColliderBuilder::ball(o.radius as f32),
                ObjectKind::Block => ColliderBuilder::capsule_from_endpoints(
                    v([o.p1[0] - centre[0], o.p1[1] - centre[1]]),
                    v([o.p2[0] - centre[0], o.p2[1] - centre[1]]),
                    params.block_radius as f32,
                ),
            };
            // NOTE: Chipmunk multiplies the shapes' coefficients (docs/envs/iphyre.md §R2, §R9); rapier picks the
            // larger of the two colliders' rules, so setting Multiply on every collider gives 0.5·0.5.
            let collider = shape
                .density(0.0)
                .friction(params.friction as f32)
                .restitution(params.restitution as f32)
                .friction_combine_rule(CoefficientCombineRule::Multiply)
                .restitution_combine_rule(CoefficientCombineRule::Multiply)
                .active_events(ActiveEvents::COLLISION_EVENTS)
                .user_data(o.index as u128)
                .build();
            let ch = colliders.insert_with_parent(collider, handle, &mut bodies);
            object_of_collider.insert(ch, o.index);
            bodies_of.push(Some(handle));
        }
        for [a, b] in &game.joints {
            let (pa, pb) = (game.objects[*a].centre(), game.objects[*b].centre());
            let length = ((pa[0] - pb[0]).hypot(pa[1] - pb[1])) as f32;
            // A rigid rod: both distance limits equal the initial centre distance (pymunk PinJoint).
            let rod = GenericJointBuilder::new(JointAxesMask::empty())
                .coupled_axes(JointAxesMask::LIN_AXES)
                .limits(JointAxis::LinX, [length, length])
                .local_anchor1(Vector::ZERO)
                .local_anchor2(Vector::ZERO)
                .build();
            if let (Some(ha), Some(hb)) = (bodies_of[*a], bodies_of[*b]) {
                impulse_joints.insert(ha, hb, rod, true);
            }
        }
        for [a, b] in &game.springs {
            let spring = SpringJointBuilder::new(
                params.spring_rest_length as f32,
                params.spring_stiffness as f32,
                params.spring_damping as f32,
            )
            .spring_model(MotorModel::ForceBased)
            .local_anchor1(Vector::ZERO)
            .local_anchor2(Vector::ZERO)
            .build();
            if let (Some(ha), Some(hb)) = (bodies_of[*a], bodies_of[*b]) {
                impulse_joints.insert(ha, hb, spring, true);
            }
        }
        Ok(World {
            objects: game.objects.clone(),
            bodies_of,
            object_of_collider,
            physics: Physics::new(
                Vector::new(0.0, params.gravity as f32),
                integration,
                bodies,
                colliders,
                impulse_joints,
            ),
        })
    }

    /// Advances the world by one `dt` and returns the contact changes of that step, in rapier's order.
    pub fn step(&mut self) -> Vec<ContactChange> {
        let mut changes = Vec::new();
        let object_of_collider = &self.object_of_collider;
        self.physics.step(|_, event| {
            let (a, b) = (event.collider1(), event.collider2());
            if let (Some(&a), Some(&b)) = (object_of_collider.get(&a), object_of_collider.get(&b)) {
                changes.push(ContactChange {
                    began: event.started(),
                    objects: [a.min(b), a.max(b)],
                });
            }
        });
        changes
    }

    /// Removes object `index` with its collider and every joint or spring attached to it; returns
    /// false when it is unknown or already gone.
    pub fn remove(&mut self, index: usize) -> bool {
        let Some(handle) = self.bodies_of.get_mut(index).and_then(Option::take) else {
            return false;
        };
        self.physics
            .bodies
            .remove(
                handle,
                &mut self.physics.islands,
                &mut self.physics.colliders,
                &mut self.physics.impulse_joints,
                &mut self.physics.multibody_joints,
                &mut self.physics.soft_bodies,
                true,
            )
            .is_some()
    }

    /// Whether object `index` is still in the world.
    pub fn is_present(&self, index: usize) -> bool {
        matches!(self.bodies_of.get(index), Some(Some(_)))
    }

    /// The game objects as loaded (initial state), indexed by object index.
    pub fn objects(&self) -> &[GameObject] {
        &self.objects
    }

    /// The indices of the objects still present, in object order.
    pub fn present(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.objects.len()).filter(|&i| self.is_present(i))
    }

    /// The current body centre of object `index` (cheaper than [`state`](Self::state): no angle, no
    /// ends), or `None` when it was removed or does not exist.
    pub fn centre(&self, index: usize) -> Option<[f64; 2]> {
        let handle = (*self.bodies_of.get(index)?)?;
        let t = self.physics.bodies.get(handle)?.translation();
        Some([t.x as f64, t.y as f64])
    }

    /// The current state of object `index`, or `None` when it was removed or does not exist.
    pub fn state(&self, index: usize) -> Option<ObjectState> {
        let handle = (*self.bodies_of.get(index)?)?;
        let body = self.physics.bodies.get(handle)?;
        let o = &self.objects[index];
        let t = body.translation();
        let centre = [t.x as f64, t.y as f64];
        let angle = body.rotation().angle() as f64;
        let (s, c) = angle.sin_cos();
        let c0 = o.centre();
        let place = |p: [f64; 2]| {
            let (dx, dy) = (p[0] - c0[0], p[1] - c0[1]);
            [centre[0] + c * dx - s * dy, centre[1] + s * dx + c * dy]
        };
        let lv = body.linvel();
        Some(ObjectState {
            index,
            p1: place(o.p1),
            p2: place(o.p2),
            centre,
            angle,
            velocity: [lv.x as f64, lv.y as f64],
            angular_velocity: body.angvel() as f64,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::iphyre::game::Games;

    fn one_ball(x: f64, y: f64) -> Game {
        Game {
            name: "free_fall".into(),
            index: 0,
            fold: "basic".into(),
            objects: vec![GameObject {
                index: 0,
                kind: ObjectKind::Ball,
                p1: [x, y],
                p2: [x, y],
                radius: 20.0,
                eliminable: false,
                dynamic: true,
                joint: 0,
                spring: 0,
            }],
            joints: vec![],
            springs: vec![],
        }
    }

    #[test]
    fn ball_in_free_fall_follows_half_g_t_squared() {
        let params = PhysicsParams::default();
        let mut world = World::new(&one_ball(300.0, 50.0), &params).unwrap();
        let dt = params.dt();
        for n in 1..=120 {
            world.step();
            let t = n as f64 * dt;
            let y = world.state(0).unwrap().centre[1];
            let exact = 50.0 + 0.5 * params.gravity * t * t;
            // Semi-implicit Euler runs ahead of the parabola by g·t·dt/2 (1.7 px at t = 2 s); allow that.
            let tol = 0.5 * params.gravity * t * dt + 0.05;
            assert!((y - exact).abs() <= tol, "t = {t}: y = {y}, exact {exact}");
        }
        let s = world.state(0).unwrap();
        assert!(
            (s.velocity[1] - params.gravity * 2.0).abs() < 0.05,
            "{:?}",
            s.velocity
        );
        assert_eq!(s.centre[0], 300.0);
    }

    #[test]
    fn ball_rests_on_a_static_block() {
        let games = Games::default_games().unwrap();
        let mut world =
            World::new(games.get("support").unwrap(), &PhysicsParams::default()).unwrap();
        let mut began = false;
        for _ in 0..120 {
            began |= world.step().iter().any(|c| c.began && c.objects == [0, 2]);
        }
        let ball = world.state(2).unwrap();
        // Ball radius 20 on a capsule of radius 10 whose core is at y = 400: centre near y = 370.
        assert!((ball.centre[1] - 370.0).abs() < 1.5, "{ball:?}");
        assert!(began, "no contact_begin between block 0 and ball 2");
    }

    #[test]
    fn pin_joint_keeps_the_centre_distance() {
        let games = Games::default_games().unwrap();
        let game = games.get("pendulum").unwrap();
        let mut world = World::new(game, &PhysicsParams::default()).unwrap();
        let [a, b] = game.joints[0];
        let d0 = {
            let (pa, pb) = (game.objects[a].centre(), game.objects[b].centre());
            (pa[0] - pb[0]).hypot(pa[1] - pb[1])
        };
        // Remove the blocker under the ball (object 4) so the pendulum swings.
        assert!(world.remove(4));
        for _ in 0..180 {
            world.step();
        }
        let (pa, pb) = (
            world.state(a).unwrap().centre,
            world.state(b).unwrap().centre,
        );
        let d = (pa[0] - pb[0]).hypot(pa[1] - pb[1]);
        assert!((d - d0).abs() < 0.02 * d0, "rod length {d} vs {d0}");
        assert!(!world.is_present(4) && world.state(4).is_none());
        assert!(!world.remove(4));
    }
}
