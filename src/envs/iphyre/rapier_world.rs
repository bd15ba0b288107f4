//! [`RapierWorld`]: one I-PHYRE game as rapier2d bodies, colliders and joints, stepped at a fixed `dt`
//! (`engine = "rapier"`).
//!
//! **Owns:** the game's rapier bodies, colliders and joints (held and stepped by
//! [`crate::envs::rapier::Physics`]), the mapping between rapier handles and the game's stable object
//! indices, object removal, and contact begin/end changes reported by rapier's collision events.
//! **Does not:** choose the engine or compute object ends (`world.rs`), decide when to remove a block
//! (`action.rs`, `step.rs`), judge success (`success.rs`) or build traces (`to_trace.rs`).
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
use super::game::{Game, ObjectKind};
use super::params::PhysicsParams;
use super::world::{ContactChange, Pose};

/// A game's rigid bodies in rapier2d.
pub(super) struct RapierWorld {
    bodies_of: Vec<Option<RigidBodyHandle>>,
    object_of_collider: HashMap<ColliderHandle, usize>,
    physics: Physics,
}

impl std::fmt::Debug for RapierWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RapierWorld")
            .field("bodies", &self.physics.bodies.len())
            .finish_non_exhaustive()
    }
}

fn v(p: [f64; 2]) -> Vector {
    Vector::new(p[0] as f32, p[1] as f32)
}

impl RapierWorld {
    /// Builds the bodies, colliders and constraints of `game` in its initial state.
    pub(super) fn new(game: &Game, params: &PhysicsParams) -> Result<RapierWorld> {
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
        Ok(RapierWorld {
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
    pub(super) fn step(&mut self) -> Vec<ContactChange> {
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
    pub(super) fn remove(&mut self, index: usize) -> bool {
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

    /// The current body centre of object `index` (None once removed).
    pub(super) fn centre(&self, index: usize) -> Option<[f64; 2]> {
        let handle = (*self.bodies_of.get(index)?)?;
        let t = self.physics.bodies.get(handle)?.translation();
        Some([t.x as f64, t.y as f64])
    }

    /// The current pose and velocities of object `index` (None once removed).
    pub(super) fn pose(&self, index: usize) -> Option<Pose> {
        let handle = (*self.bodies_of.get(index)?)?;
        let body = self.physics.bodies.get(handle)?;
        let (t, lv) = (body.translation(), body.linvel());
        Some(Pose {
            centre: [t.x as f64, t.y as f64],
            angle: body.rotation().angle() as f64,
            velocity: [lv.x as f64, lv.y as f64],
            angular_velocity: body.angvel() as f64,
        })
    }
}
