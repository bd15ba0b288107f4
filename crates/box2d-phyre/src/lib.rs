//! box2d-rs (a Rust port of Box2D 2.4.1) instantiated for annotrace's PHYRE worlds.
//!
//! **Owns:** the user-data type of PHYRE's Box2D worlds ([`Phyre`]: every body and fixture carries its
//! PHYRE body index) and the non-generic entry points annotrace calls: [`new_world`], [`create_body`],
//! [`create_fixture`], [`step`], [`destroy_body`].
//! **Does not:** decide anything about PHYRE (annotrace's `envs::phyre::box2d_world` builds the scenes,
//! listens for contacts and tests the goal).
//!
//! Why a crate of its own: box2d-rs is generic over the user-data type, so its world, island, contact
//! manager and broad phase are compiled (monomorphised) in the crate that names the concrete type. Named
//! in annotrace, they were compiled at annotrace's `opt-level = 0` in debug builds whatever the
//! `[profile.dev.package.box2d-rs]` override said. Here they are compiled with this crate's override
//! (annotrace's `Cargo.toml`), so debug-build PHYRE episodes step optimised code, as rapier's do. The
//! functions are `#[inline(never)]` so no caller re-instantiates them. Release builds optimise
//! everything either way; the arithmetic is the same in both (Rust does not contract or reorder float
//! operations at any optimisation level).

use box2d_rs::b2_body::{B2body, B2bodyDef, BodyPtr};
use box2d_rs::b2_fixture::B2fixtureDef;
use box2d_rs::b2_math::B2vec2;
use box2d_rs::b2_world::{B2world, B2worldPtr};
use box2d_rs::b2rs_common::UserDataType;

/// The user data of PHYRE's Box2D worlds: bodies and fixtures hold their PHYRE body index.
#[derive(Debug, Default, Clone)]
pub struct Phyre;

impl UserDataType for Phyre {
    type Fixture = usize;
    type Body = usize;
    type Joint = ();
}

/// A new empty world with this gravity (m/s²).
#[inline(never)]
pub fn new_world(gravity: B2vec2) -> B2worldPtr<Phyre> {
    B2world::<Phyre>::new(gravity)
}

/// Creates a body in `world`.
#[inline(never)]
pub fn create_body(world: &B2worldPtr<Phyre>, def: &B2bodyDef<Phyre>) -> BodyPtr<Phyre> {
    B2world::create_body(world.clone(), def)
}

/// Adds a fixture to `body` (Box2D recomputes the body's mass from its fixtures).
#[inline(never)]
pub fn create_fixture(body: &BodyPtr<Phyre>, def: &B2fixtureDef<Phyre>) {
    B2body::create_fixture(body.clone(), def);
}

/// One `b2World::Step`.
#[inline(never)]
pub fn step(
    world: &B2worldPtr<Phyre>,
    dt: f32,
    velocity_iterations: i32,
    position_iterations: i32,
) {
    world
        .borrow_mut()
        .step(dt, velocity_iterations, position_iterations);
}

/// Destroys `body` and its contacts (box2d-rs links them through reference-counted lists).
#[inline(never)]
pub fn destroy_body(world: &B2worldPtr<Phyre>, body: BodyPtr<Phyre>) {
    world.borrow_mut().destroy_body(body);
}
