//! [`PhysicsParams`] and [`Engine`]: the physics engine, PHYRE's physics constants and annotrace's tuning
//! knobs for rapier2d (docs/envs/phyre.md §R5).

use super::error::{PhyreError, Result};

/// The physics engine a PHYRE world runs on (`engine = "box2d" | "rapier"` in a pipeline).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    /// Box2D (the `box2d-rs` port of Box2D 2.4.1), PHYRE's own engine: reproduces PHYRE's outcomes
    /// far more often than rapier2d (docs/fidelity.md). The rapier-only fields of [`PhysicsParams`]
    /// do not apply; Box2D runs PHYRE's 15 velocity and 20 position iterations.
    #[default]
    Box2d,
    /// rapier2d with the tuning knobs of [`PhysicsParams`].
    Rapier,
}

impl Engine {
    /// The name used in parameters and reports: `box2d` or `rapier`.
    pub fn name(self) -> &'static str {
        match self {
            Engine::Box2d => "box2d",
            Engine::Rapier => "rapier",
        }
    }

    /// Parses [`name`](Self::name).
    pub fn from_name(name: &str) -> Option<Engine> {
        match name {
            "box2d" => Some(Engine::Box2d),
            "rapier" => Some(Engine::Rapier),
            _ => None,
        }
    }
}

/// PHYRE's physics (Box2D 2.3 in PHYRE 0.2.2): the engine, PHYRE's constants, and rapier2d's settings
/// when the engine is rapier. The world runs in metres with [`PIXELS_PER_METRE`] = 6, like PHYRE's
/// Box2D world; everything the user sees (tasks, actions, traces) stays in scene pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicsParams {
    /// The engine: Box2D (default) or rapier2d.
    pub engine: Engine,
    /// Box2D only: give dynamic bodies the mass data and gravity scale with which box2d-rs (Box2D 2.4.1)
    /// computes what PHYRE's 2018 Box2D computes (polygon mass about the vertex average, `h·g` per
    /// step; `box2d_compat.rs`). On by default; off is plain Box2D 2.4.1.
    pub box2d_phyre_compat: bool,
    /// Gravity (m/s², downwards): 9.8.
    pub gravity: f64,
    /// Density of dynamic bodies (kg/m²): 0.25. Static bodies have none.
    pub density: f64,
    /// Friction of every shape: 0.5 (Box2D mixes √(f₁f₂), which is 0.5 again).
    pub friction: f64,
    /// Restitution of every shape: 0.2 (Box2D mixes max(e₁, e₂), 0.2 again).
    pub restitution: f64,
    /// Angular damping of every body (1/s): 0.01.
    pub angular_damping: f64,
    /// Linear damping (1/s): 0.
    pub linear_damping: f64,
    /// Steps per second: 60 (`dt` = 1/60 s).
    pub fps: f64,
    /// Most steps an episode runs: 1000 (16.7 s).
    pub max_steps: usize,
    /// Consecutive steps the goal relation must hold: 180 (3 s).
    pub steps_for_solution: usize,
    /// Ball–ball goal rule: touching when the centre distance < r₁ + r₂ + this (px): 0.1.
    pub ball_touch_threshold_px: f64,
    /// Contact distance (m) below which two shapes count as touching: 0.02. Box2D gives every polygon
    /// a 0.01 m skin and reports shapes touching when their skins meet (0.02 m apart for two polygons);
    /// rapier keeps no skin, so contacts closer than this count. Tuned against PHYRE (docs/fidelity.md).
    pub touch_distance: f64,
    /// rapier solver iterations per step (Box2D: 15 velocity + 20 position). Tuned (docs/fidelity.md).
    pub solver_iterations: usize,
    /// rapier internal stabilisation iterations per solver iteration.
    pub stabilization_iterations: usize,
    /// rapier projected Gauss–Seidel iterations per solver iteration (substep).
    pub pgs_iterations: usize,
    /// rapier's contact prediction distance (m): contacts are built for shapes closer than this, so
    /// a body moving less than it per step is stopped at the surface instead of sinking in.
    pub prediction_distance: f64,
    /// Whether dynamic bodies use rapier's continuous collision detection (motion clamping).
    pub ccd: bool,
    /// Contact skin of every polygon (m), rapier's `contact_skin`: Box2D's `b2_polygonRadius` is 0.01.
    pub polygon_skin: f64,
    /// Box2D's `b2_velocityThreshold` (m/s): contacts approaching slower than this do not bounce
    /// (restitution 0); 0 turns the rule off (rapier bounces every new contact).
    pub restitution_threshold: f64,
    /// Whether rapier may reuse a pair's contact points while the pair has moved little
    /// (`IntegrationParameters::contact_recycling`).
    pub contact_recycling: bool,
    /// Whether resting bodies may sleep (Box2D's default world allows sleeping).
    pub sleeping: bool,
    /// A body may sleep once its furthest point has moved slower than this (m/s) for `sleep_time`:
    /// 0.05, rapier's default (Box2D's `b2_linearSleepTolerance` is 0.01 m/s, but rapier bodies at rest
    /// jitter more; 0.05 agreed slightly better with PHYRE and freezes episodes sooner, docs/fidelity.md).
    pub sleep_linear: f64,
    /// Seconds of rest before a body sleeps (Box2D's `b2_timeToSleep`: 0.5).
    pub sleep_time: f64,
}

/// PHYRE's `PIXELS_IN_METER`.
pub const PIXELS_PER_METRE: f64 = 6.0;

impl Default for PhysicsParams {
    fn default() -> Self {
        PhysicsParams {
            engine: Engine::default(),
            box2d_phyre_compat: true,
            gravity: 9.8,
            density: 0.25,
            friction: 0.5,
            restitution: 0.2,
            angular_damping: 0.01,
            linear_damping: 0.0,
            fps: 60.0,
            max_steps: 1000,
            steps_for_solution: 180,
            ball_touch_threshold_px: 0.1,
            touch_distance: 0.02,
            solver_iterations: 4,
            stabilization_iterations: 1,
            pgs_iterations: 1,
            prediction_distance: 0.02,
            ccd: false,
            polygon_skin: 0.0,
            restitution_threshold: 0.0,
            contact_recycling: true,
            sleeping: true,
            sleep_linear: 0.05,
            sleep_time: 0.5,
        }
    }
}

impl PhysicsParams {
    /// The time step `1 / fps` (s).
    pub fn dt(&self) -> f64 {
        1.0 / self.fps
    }

    /// Checks every value is finite and in range.
    pub fn validate(&self) -> Result<()> {
        let non_negative = [
            ("gravity", self.gravity),
            ("density", self.density),
            ("friction", self.friction),
            ("restitution", self.restitution),
            ("angular_damping", self.angular_damping),
            ("linear_damping", self.linear_damping),
            ("ball_touch_threshold_px", self.ball_touch_threshold_px),
            ("touch_distance", self.touch_distance),
            ("prediction_distance", self.prediction_distance),
            ("polygon_skin", self.polygon_skin),
            ("restitution_threshold", self.restitution_threshold),
            ("sleep_linear", self.sleep_linear),
            ("sleep_time", self.sleep_time),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(PhyreError::InvalidParams {
                    field,
                    message: format!("{v} is not a finite non-negative number"),
                });
            }
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(PhyreError::InvalidParams {
                field: "fps",
                message: format!("{} is not a positive number", self.fps),
            });
        }
        for (field, v) in [
            ("max_steps", self.max_steps),
            ("steps_for_solution", self.steps_for_solution),
            ("solver_iterations", self.solver_iterations),
            ("pgs_iterations", self.pgs_iterations),
        ] {
            if v == 0 {
                return Err(PhyreError::InvalidParams {
                    field,
                    message: "must be at least 1".into(),
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_phyres_and_bad_values_are_named() {
        let p = PhysicsParams::default();
        p.validate().unwrap();
        assert_eq!((p.max_steps, p.steps_for_solution), (1000, 180));
        assert!((p.dt() - 1.0 / 60.0).abs() < 1e-15);
        let bad = PhysicsParams {
            fps: f64::NAN,
            ..PhysicsParams::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("fps"));
        let bad = PhysicsParams {
            solver_iterations: 0,
            ..PhysicsParams::default()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("solver_iterations")
        );
    }
}
