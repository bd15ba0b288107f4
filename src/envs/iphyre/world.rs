//! [`World`]: one I-PHYRE game in the physics engine that [`PhysicsParams::engine`] selects: Box2D with
//! Chipmunk's semantics (`box2d_world.rs`), the Chipmunk-faithful step (`chipmunk_world.rs`) or rapier2d
//! (`rapier_world.rs`). All speak in the game's object indices.
//!
//! **Owns:** the engine choice, the game objects as loaded, and the object states reported outward
//! ([`ObjectState`]: ends rotated with the body) and the contact changes ([`ContactChange`]).
//! **Does not:** simulate (the backends do), decide when to remove a block (`action.rs`, `step.rs`),
//! judge success (`success.rs`) or build traces (`to_trace.rs`).

use super::box2d_world::Box2dWorld;
use super::chipmunk_world::ChipmunkWorld;
use super::error::Result;
use super::game::{Game, GameObject};
use super::params::{Engine, PhysicsParams};
use super::rapier_world::RapierWorld;

/// A contact change between two objects during one step (from the engine's contact events).
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

/// What a backend reports of one body: centre (px), angle, velocities.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Pose {
    pub centre: [f64; 2],
    pub angle: f64,
    pub velocity: [f64; 2],
    pub angular_velocity: f64,
}

/// A game's bodies in the selected engine.
pub struct World {
    objects: Vec<GameObject>,
    backend: Backend,
}

#[derive(Debug)]
enum Backend {
    Box2d(Box2dWorld),
    Chipmunk(Box<ChipmunkWorld>),
    Rapier(Box<RapierWorld>),
}

/// Calls the same method on whichever backend the world runs.
macro_rules! dispatch {
    ($self:expr, $w:ident => $e:expr) => {
        match $self {
            Backend::Box2d($w) => $e,
            Backend::Chipmunk($w) => $e,
            Backend::Rapier($w) => $e,
        }
    };
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("World")
            .field("objects", &self.objects.len())
            .field("present", &self.present().count())
            .field("backend", &self.backend)
            .finish()
    }
}

impl World {
    /// Builds the bodies, colliders and constraints of `game` in its initial state.
    pub fn new(game: &Game, params: &PhysicsParams) -> Result<World> {
        params.validate()?;
        let backend = match params.engine {
            Engine::Box2d => Backend::Box2d(Box2dWorld::new(game, params)?),
            Engine::Chipmunk => Backend::Chipmunk(Box::new(ChipmunkWorld::new(game, params)?)),
            Engine::Rapier => Backend::Rapier(Box::new(RapierWorld::new(game, params)?)),
        };
        Ok(World {
            objects: game.objects.clone(),
            backend,
        })
    }

    /// Advances the world by one `dt` and returns the contact changes of that step, in the engine's
    /// order (Box2D: contacts ended by a removal come first).
    pub fn step(&mut self) -> Vec<ContactChange> {
        dispatch!(&mut self.backend, w => w.step())
    }

    /// Removes object `index` with its collider and every joint or spring attached to it; returns
    /// false when it is unknown or already gone.
    pub fn remove(&mut self, index: usize) -> bool {
        dispatch!(&mut self.backend, w => w.remove(index))
    }

    /// Whether object `index` is still in the world.
    pub fn is_present(&self, index: usize) -> bool {
        self.centre(index).is_some()
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
        dispatch!(&self.backend, w => w.centre(index))
    }

    /// The current state of object `index`, or `None` when it was removed or does not exist.
    pub fn state(&self, index: usize) -> Option<ObjectState> {
        let pose = dispatch!(&self.backend, w => w.pose(index))?;
        let o = &self.objects[index];
        let (s, c) = pose.angle.sin_cos();
        let c0 = o.centre();
        let centre = pose.centre;
        let place = |p: [f64; 2]| {
            let (dx, dy) = (p[0] - c0[0], p[1] - c0[1]);
            [centre[0] + c * dx - s * dy, centre[1] + s * dx + c * dy]
        };
        Some(ObjectState {
            index,
            p1: place(o.p1),
            p2: place(o.p2),
            centre,
            angle: pose.angle,
            velocity: pose.velocity,
            angular_velocity: pose.angular_velocity,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::iphyre::game::Games;
    use crate::envs::iphyre::game::ObjectKind;

    /// The default parameters on each engine.
    fn engines() -> [PhysicsParams; 3] {
        [Engine::Rapier, Engine::Box2d, Engine::Chipmunk].map(|engine| PhysicsParams {
            engine,
            ..PhysicsParams::default()
        })
    }

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
        for params in engines() {
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
    }

    #[test]
    fn chipmunk_free_fall_moves_positions_first_like_the_original() {
        // pymunk moves positions with the previous step's velocity: y_k = y_0 + g·dt²·k(k−1)/2, to the
        // last bits (the recorded original matches this to 1e-12 px).
        let params = PhysicsParams {
            engine: Engine::Chipmunk,
            ..PhysicsParams::default()
        };
        let mut world = World::new(&one_ball(300.0, 50.0), &params).unwrap();
        let dt = params.dt();
        for k in 1..=120u32 {
            world.step();
            let y = world.state(0).unwrap().centre[1];
            let exact = 50.0 + params.gravity * dt * dt * f64::from(k * (k - 1)) / 2.0;
            assert!((y - exact).abs() < 1e-9, "step {k}: y = {y}, exact {exact}");
        }
    }

    #[test]
    fn ball_rests_on_a_static_block() {
        let games = Games::default_games().unwrap();
        for params in engines() {
            let mut world = World::new(games.get("support").unwrap(), &params).unwrap();
            let mut began = false;
            for _ in 0..120 {
                began |= world.step().iter().any(|c| c.began && c.objects == [0, 2]);
            }
            let ball = world.state(2).unwrap();
            // Ball radius 20 on a capsule of radius 10 whose core is at y = 400: centre near y = 370.
            assert!((ball.centre[1] - 370.0).abs() < 1.5, "{ball:?}");
            assert!(began, "no contact_begin between block 0 and ball 2");
        }
    }

    #[test]
    fn pin_joint_keeps_the_centre_distance() {
        let games = Games::default_games().unwrap();
        let game = games.get("pendulum").unwrap();
        for params in engines() {
            let mut world = World::new(game, &params).unwrap();
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

    #[test]
    fn a_spring_pulls_its_bodies_towards_the_rest_length() {
        // impulse_spring: a spring joins a dynamic block and a ball 240 px apart (rest length 20).
        let games = Games::default_games().unwrap();
        let game = games.get("impulse_spring").unwrap();
        let [a, b] = game.springs[0];
        let dist = |w: &World| {
            let (pa, pb) = (w.centre(a).unwrap(), w.centre(b).unwrap());
            (pa[0] - pb[0]).hypot(pa[1] - pb[1])
        };
        for params in engines() {
            let mut world = World::new(game, &params).unwrap();
            let d0 = dist(&world);
            for _ in 0..30 {
                world.step();
            }
            assert!(
                dist(&world) < d0 - 5.0,
                "{:?}: {} vs {d0}",
                params.engine,
                dist(&world)
            );
        }
    }

    #[test]
    fn box2d_blocks_are_capsules_with_round_ends() {
        // A ball dropped just past a static block's end rolls off its rounded end (a flat box end
        // extended by the radius would hold it): it must leave the block's top sideways.
        let mut game = one_ball(245.0, 300.0);
        game.objects[0].index = 1;
        game.objects[0].radius = 10.0;
        game.objects.insert(
            0,
            GameObject {
                index: 0,
                kind: ObjectKind::Block,
                p1: [100.0, 350.0],
                p2: [240.0, 350.0],
                radius: 10.0,
                eliminable: false,
                dynamic: false,
                joint: 0,
                spring: 0,
            },
        );
        let params = PhysicsParams {
            engine: Engine::Box2d,
            ..PhysicsParams::default()
        };
        let mut world = World::new(&game, &params).unwrap();
        for _ in 0..240 {
            world.step();
        }
        let ball = world.state(1).unwrap();
        assert!(ball.centre[1] > 400.0 && ball.centre[0] > 250.0, "{ball:?}");
    }
}
