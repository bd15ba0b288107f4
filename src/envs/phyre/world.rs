//! [`World`]: one PHYRE task plus the red user ball in the physics engine that
//! [`PhysicsParams::engine`] selects: Box2D (`box2d_world.rs`, PHYRE's own engine) or rapier2d
//! (`rapier_world.rs`). Both speak in PHYRE body indices (scene bodies `0..n`, the user ball `n`).
//!
//! **Owns:** the engine choice, the body list both backends build from, and the types they report
//! ([`BodyState`], [`ContactChange`]).
//! **Does not:** simulate (the backends do), decide validity (`action.rs`), run the episode loop
//! (`episode.rs`) or build traces.

use super::action::UserBall;
use super::box2d_world::Box2dWorld;
use super::error::Result;
use super::params::{Engine, PhysicsParams};
use super::rapier_world::RapierWorld;
use super::task::{Shape, Task};

/// What a backend needs of one body: index, dynamic, origin (px), angle, shapes.
pub(super) type BodySpec<'a> = (usize, bool, [f64; 2], f64, &'a [Shape]);

/// A contact change between two bodies during one step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ContactChange {
    /// True when the two bodies started touching, false when they stopped.
    pub began: bool,
    /// The two body indices, smaller first.
    pub objects: [usize; 2],
}

/// One body's state in scene units (px, px/s, rad, rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyState {
    /// Body index (the user ball is the last).
    pub index: usize,
    /// Body origin x (px).
    pub x: f64,
    /// Body origin y (px, up).
    pub y: f64,
    /// Angle (rad, CCW).
    pub angle: f64,
    /// Velocity x (px/s).
    pub vx: f64,
    /// Velocity y (px/s).
    pub vy: f64,
    /// Angular velocity (rad/s).
    pub angular_velocity: f64,
}

/// A task's bodies in the selected engine.
#[derive(Debug)]
pub struct World {
    backend: Backend,
}

#[derive(Debug)]
enum Backend {
    Box2d(Box2dWorld),
    Rapier(Box<RapierWorld>),
}

/// Calls the same method on whichever backend the world runs.
macro_rules! dispatch {
    ($self:ident, $w:ident => $e:expr) => {
        match &$self.backend {
            Backend::Box2d($w) => $e,
            Backend::Rapier($w) => $e,
        }
    };
}

impl World {
    /// Builds `task`'s bodies and, when given, the red user ball (body index `task.bodies.len()`) in
    /// `params.engine`.
    pub fn new(task: &Task, user: Option<&UserBall>, params: &PhysicsParams) -> Result<World> {
        params.validate()?;
        let user_shapes;
        let mut specs: Vec<BodySpec<'_>> = task
            .bodies
            .iter()
            .map(|b| (b.id, b.dynamic, b.position, b.angle, b.shapes.as_slice()))
            .collect();
        if let Some(u) = user {
            user_shapes = [Shape::Circle { radius: u.radius }];
            specs.push((task.bodies.len(), true, [u.x, u.y], 0.0, &user_shapes));
        }
        let backend = match params.engine {
            Engine::Box2d => Backend::Box2d(Box2dWorld::new(task, specs, params)?),
            Engine::Rapier => Backend::Rapier(Box::new(RapierWorld::new(task, specs, params)?)),
        };
        Ok(World { backend })
    }

    /// Number of bodies (the user ball included).
    pub fn len(&self) -> usize {
        dispatch!(self, w => w.len())
    }

    /// True when the world has no bodies.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Advances one step (1/60 s) and appends the body-pair contact changes of that step to `out`. A jar
    /// touching a ball with two of its parts is one contact: it begins with the first part and ends with
    /// the last.
    pub fn step(&mut self, out: &mut Vec<ContactChange>) {
        match &mut self.backend {
            Backend::Box2d(w) => w.step(out),
            Backend::Rapier(w) => w.step(out),
        }
    }

    /// PHYRE's goal test after a step: the two goal balls' centres closer than r₁ + r₂ + 0.1 px, or else
    /// the goal bodies touching.
    pub fn goal_holds(&self) -> bool {
        dispatch!(self, w => w.goal_holds())
    }

    /// Whether bodies `a` and `b` touch (Box2D: a touching contact between them; rapier: a contact
    /// point closer than `touch_distance`).
    pub fn touching(&self, a: usize, b: usize) -> bool {
        dispatch!(self, w => w.touching(a, b))
    }

    /// Whether every dynamic body sleeps (then nothing moves until the episode ends).
    pub fn all_asleep(&self) -> bool {
        dispatch!(self, w => w.all_asleep())
    }

    /// The indices of the dynamic bodies.
    pub fn dynamic_bodies(&self) -> &[usize] {
        dispatch!(self, w => w.dynamic_bodies())
    }

    /// The state of body `index` in scene units.
    pub fn state(&self, index: usize) -> Option<BodyState> {
        dispatch!(self, w => w.state(index))
    }

    /// The bodies' exact initial states (as given to [`World::new`]).
    pub fn initial_states(&self) -> &[BodyState] {
        dispatch!(self, w => w.initial_states())
    }

    /// Appends the state of every body in index order to `out`.
    pub fn states_into(&self, out: &mut Vec<BodyState>) {
        out.extend((0..self.len()).filter_map(|i| self.state(i)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::phyre::tasks::TaskSet;

    #[test]
    fn a_ball_falls_at_g_and_comes_to_rest_on_the_floor() {
        for engine in [Engine::Box2d, Engine::Rapier] {
            falls_and_rests(engine);
        }
    }

    fn falls_and_rests(engine: Engine) {
        let task = TaskSet::default_tasks().unwrap().get("00000:000").unwrap();
        let params = PhysicsParams {
            engine,
            ..PhysicsParams::default()
        };
        let user = UserBall {
            x: 40.0,
            y: 200.0,
            radius: 10.0,
        };
        let mut world = World::new(&task, Some(&user), &params).unwrap();
        let u = task.bodies.len();
        let mut changes = Vec::new();
        for _ in 0..30 {
            world.step(&mut changes);
        }
        // After 0.5 s of free fall: v = -g·t = -4.9 m/s = -29.4 px/s.
        let s = world.state(u).unwrap();
        assert!((s.vy + 29.4).abs() < 0.1, "{engine:?} {s:?}");
        for _ in 0..300 {
            world.step(&mut changes);
        }
        let s = world.state(u).unwrap();
        assert!((s.y - 10.0).abs() < 0.3, "{engine:?} resting centre {s:?}");
        // The floor is wall 0.
        assert!(
            changes.iter().any(|c| c.began && c.objects == [0, u]),
            "{changes:?}"
        );
        assert!(world.touching(0, u));
        assert!(!world.goal_holds());
    }
}
