//! Simulation environments that produce traces: one module per environment behind [`Environment`].
//!
//! **Owns:** the [`Environment`] trait (scenes, action validation, simulate → [`Trace`], success,
//! rendering) and its implementations: [`pool`] (billiards, pooltool 0.6.0 physics) and [`iphyre`]
//! (I-PHYRE on the Chipmunk-faithful step by default, or rapier2d or Box2D) and [`phyre`] (PHYRE's ball tier on Box2D by default, or rapier2d), which share the rapier state of
//! [`rapier`]. Their renderers share the pixmap, PNG and strip plumbing of the private `draw` module; PHYRE's and
//! I-PHYRE's Box2D worlds share the contact listener of the private `box2d_contacts` module.
//! **Does not:** write run folders or order stages (`pipeline/`), parse command lines (`cli/`). It uses
//! only [`crate::trace`], [`crate::rng`] and [`crate::digest`] below it. The physics each simulator
//! follows is written out in `docs/envs/{pool,phyre,iphyre}.md`.
//!
//! **Entry point:** [`pool::PoolEnv`]:
//!
//! ```
//! use annotrace::envs::{Environment, pool::{PoolEnv, Shot}};
//! let env = PoolEnv::default();
//! let scene = &env.scenes(1, 42).unwrap()[0];
//! let trace = env.simulate(scene, &Shot { v0: 4.0, phi: 80.0, theta: 0.0, a: 0.0, b: 0.2 }).unwrap();
//! assert_eq!(trace.events[1].kind, "physics_stick_ball");
//! ```

mod box2d_contacts;
mod draw;
pub mod iphyre;
pub mod phyre;
pub mod pool;
pub mod rapier;

use crate::trace::{Env, Trace};

/// The facts about an environment that code outside `envs/` needs (trace distances, reward programs,
/// prompts), one constant per environment module, found through [`facts`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnvFacts {
    /// The environment.
    pub env: Env,
    /// The length positions are divided by for trace distances: the scene's long side in its units.
    pub scene_scale: f64,
    /// The unit length of `NEARBY_AT` thresholds in reward programs (radius = threshold × this).
    pub nearby_scale: f64,
    /// How positions are measured, in words for the reward DSL reference given to models.
    pub units: &'static str,
}

/// Every environment's facts: adding an environment adds its module's constant here.
pub static ENVIRONMENTS: [&EnvFacts; 3] = [&pool::FACTS, &phyre::FACTS, &iphyre::FACTS];

/// The facts of `env`.
pub fn facts(env: Env) -> &'static EnvFacts {
    ENVIRONMENTS
        .iter()
        .copied()
        .find(|f| f.env == env)
        .expect("every Env has its facts in ENVIRONMENTS")
}

/// One dimension of an environment's continuous action space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActionDim {
    /// Name as it appears in action JSON (`V0`, `phi`, …).
    pub name: &'static str,
    /// Unit (`m/s`, `deg`, `R`).
    pub unit: &'static str,
    /// Smallest allowed value.
    pub low: f64,
    /// Largest allowed value (exclusive where the doc says so).
    pub high: f64,
    /// What it means.
    pub doc: &'static str,
}

/// Why an environment could not do what was asked.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EnvError {
    /// The environment does not offer this operation.
    #[error("{env} does not support {what}")]
    Unsupported {
        /// The environment.
        env: Env,
        /// The operation (`rendering`, …).
        what: &'static str,
    },
    /// A billiards scene, shot or simulation failed.
    #[error(transparent)]
    Pool(#[from] pool::PoolError),
    /// An I-PHYRE game, click list or simulation failed.
    #[error(transparent)]
    Iphyre(#[from] iphyre::IphyreError),
    /// A PHYRE task, action or simulation failed.
    #[error(transparent)]
    Phyre(#[from] phyre::PhyreError),
    /// Rendering failed.
    #[error("rendering: {0}")]
    Render(String),
}

/// A simulator that turns (scene, action) into a [`Trace`]; what `TableProvider` is to DataFusion.
pub trait Environment: Send + Sync {
    /// An initial condition.
    type Scene;
    /// What an agent chooses.
    type Action;

    /// The environment's name in traces and run folders.
    fn env(&self) -> Env;

    /// `n` generated scenes; scene `i` depends only on (`seed`, `i`).
    fn scenes(&self, n: usize, seed: u64) -> Result<Vec<Self::Scene>, EnvError>;

    /// The continuous action space, one entry per parameter.
    fn action_space(&self) -> Vec<ActionDim>;

    /// Checks an action against a scene without simulating; the error names the bad field.
    fn validate(&self, scene: &Self::Scene, action: &Self::Action) -> Result<(), EnvError>;

    /// Simulates `action` from `scene` into a trace.
    fn simulate(&self, scene: &Self::Scene, action: &Self::Action) -> Result<Trace, EnvError>;

    /// Whether a trace met its scene's success rule (by default, what its outcome says).
    fn success(&self, trace: &Trace) -> bool {
        trace.outcome.success
    }

    /// A PNG image of `trace` at time `t` (seconds). Default: not supported.
    fn render(&self, trace: &Trace, t: f64) -> Result<Vec<u8>, EnvError> {
        let _ = (trace, t);
        Err(EnvError::Unsupported {
            env: self.env(),
            what: "rendering",
        })
    }
}
