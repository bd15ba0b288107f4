//! [`Physics`]: the rapier2d sets, pipeline and event channels that the PHYRE and I-PHYRE worlds share.
//!
//! **Owns:** building the rapier state around given bodies, colliders and joints, one pipeline step (with
//! optional physics hooks supplied by the world), and
//! draining the step's collision events (contact-force and soft-body events are discarded).
//! **Does not:** know environments: what bodies exist, their materials and what a contact means belong to
//! `phyre/rapier_world.rs` and `iphyre/rapier_world.rs`.

use std::sync::mpsc;

use rapier2d::prelude::*;

/// rapier2d's state for one world: gravity, integration parameters, the sets and the event channels.
pub struct Physics {
    /// Gravity (world units per s²).
    pub gravity: Vector,
    /// Step length, solver iterations, tolerances.
    pub integration: IntegrationParameters,
    /// The rigid bodies.
    pub bodies: RigidBodySet,
    /// The colliders.
    pub colliders: ColliderSet,
    /// The impulse joints.
    pub impulse_joints: ImpulseJointSet,
    /// The islands (sleeping and activation).
    pub islands: IslandManager,
    /// Multibody joints (unused, required by the pipeline).
    pub multibody_joints: MultibodyJointSet,
    /// The contact graph (for distance queries between touching colliders).
    pub narrow_phase: NarrowPhase,
    /// Soft bodies (unused, required by the pipeline and body removal).
    pub soft_bodies: SoftBodySet,
    pipeline: PhysicsPipeline,
    broad_phase: BroadPhaseBvh,
    ccd: CCDSolver,
    collision_rx: mpsc::Receiver<CollisionEvent>,
    force_rx: mpsc::Receiver<ContactForceEvent>,
    tear_rx: mpsc::Receiver<SoftBodyTearEvent>,
    events: ChannelEventCollector,
}

impl Physics {
    /// The rapier state around `bodies`, `colliders` and `impulse_joints`.
    pub fn new(
        gravity: Vector,
        integration: IntegrationParameters,
        bodies: RigidBodySet,
        colliders: ColliderSet,
        impulse_joints: ImpulseJointSet,
    ) -> Self {
        let (collision_tx, collision_rx) = mpsc::channel();
        let (force_tx, force_rx) = mpsc::channel();
        let (tear_tx, tear_rx) = mpsc::channel();
        Physics {
            gravity,
            integration,
            bodies,
            colliders,
            impulse_joints,
            islands: IslandManager::new(),
            multibody_joints: MultibodyJointSet::new(),
            pipeline: PhysicsPipeline::new(),
            broad_phase: BroadPhaseBvh::new(),
            narrow_phase: NarrowPhase::new(),
            soft_bodies: SoftBodySet::new(),
            ccd: CCDSolver::new(),
            collision_rx,
            force_rx,
            tear_rx,
            events: ChannelEventCollector::new(collision_tx, force_tx, tear_tx),
        }
    }

    /// Advances one `integration.dt` and passes each collision event of the step, in rapier's order, to
    /// `on_collision` together with the collider set (to map handles to objects).
    pub fn step(&mut self, on_collision: impl FnMut(&ColliderSet, CollisionEvent)) {
        self.step_with_hooks(&(), on_collision);
    }

    /// [`step`](Self::step) with `hooks` called for the colliders that ask for them (`ActiveHooks`).
    pub fn step_with_hooks(
        &mut self,
        hooks: &dyn PhysicsHooks,
        mut on_collision: impl FnMut(&ColliderSet, CollisionEvent),
    ) {
        self.pipeline.step(
            self.gravity,
            &self.integration,
            &mut self.islands,
            &mut self.broad_phase,
            &mut self.narrow_phase,
            &mut self.bodies,
            &mut self.colliders,
            &mut self.impulse_joints,
            &mut self.multibody_joints,
            &mut self.soft_bodies,
            &mut self.ccd,
            hooks,
            &self.events,
        );
        while self.force_rx.try_recv().is_ok() {}
        while self.tear_rx.try_recv().is_ok() {}
        while let Ok(event) = self.collision_rx.try_recv() {
            on_collision(&self.colliders, event);
        }
    }
}
