//! [`PhysicsParams`]: I-PHYRE's physics constants as one knob struct (docs/envs/iphyre.md §R2).

use super::error::{IphyreError, Result};

/// The physics engine an I-PHYRE world runs on (`engine = "rapier" | "box2d" | "chipmunk"` in a
/// pipeline's `simulate` stage, `--engine` on `annotrace simulate --env iphyre`).
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
    /// Box2D (the `box2d-rs` port of Box2D 2.4.1), set up with Chipmunk's semantics: hard contacts
    /// solved by sequential impulses with accumulated impulses and warm starting, no continuous
    /// collision, no sleeping (`box2d_world.rs`). The rapier-only fields of [`PhysicsParams`] do not
    /// apply; the `box2d_*` ones do. Measured against the original it is not better than rapier2d
    /// overall (docs/fidelity.md, "I-PHYRE on Box2D").
    Box2d,
    /// annotrace's Chipmunk-faithful step (the `chipmunk-step` crate, `chipmunk_world.rs`), the default:
    /// Chipmunk 7's step, narrow phase and contact order (its bounding-box tree's), which reproduces the
    /// original bit for bit on every episode of the balanced sets. Only `chipmunk_iterations` of the
    /// engine-specific fields applies (docs/fidelity.md, "I-PHYRE on a Chipmunk-faithful step").
    #[default]
    Chipmunk,
    /// rapier2d with the tuning knobs of [`PhysicsParams`] (`rapier_world.rs`); the default until the
    /// Chipmunk step reproduced the original (runs made before the `engine` field existed used it).
    Rapier,
}

impl Engine {
    /// The name used in parameters and reports: `box2d`, `chipmunk` or `rapier`.
    pub fn name(self) -> &'static str {
        match self {
            Engine::Box2d => "box2d",
            Engine::Chipmunk => "chipmunk",
            Engine::Rapier => "rapier",
        }
    }

    /// What a trace's `simulator.engine` says: the library behind the engine.
    pub fn description(self) -> &'static str {
        match self {
            Engine::Box2d => "box2d-rs 0.0.4 (Box2D 2.4.1)",
            Engine::Chipmunk => "chipmunk-step (Chipmunk 7.0.3 as pymunk 6.11.1 builds it)",
            Engine::Rapier => "rapier2d",
        }
    }

    /// Parses [`name`](Self::name).
    pub fn from_name(name: &str) -> Option<Engine> {
        match name {
            "box2d" => Some(Engine::Box2d),
            "chipmunk" => Some(Engine::Chipmunk),
            "rapier" => Some(Engine::Rapier),
            _ => None,
        }
    }
}

/// I-PHYRE's physics constants. [`Default`] gives iphyre 0.2.3's values (pymunk 6.11.1 / Chipmunk 7.0.3),
/// in screen pixels (600×600, y down) and seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct PhysicsParams {
    /// The engine: the Chipmunk-faithful step (default), rapier2d, or Box2D with Chipmunk's semantics.
    pub engine: Engine,
    /// Downward gravity (px/s²): 100.
    pub gravity: f64,
    /// Physics steps per second; one step per frame, no substeps: 60 (the gym wrappers and DeepPHY use 10).
    pub fps: f64,
    /// Episode length (s): 15.
    pub max_time: f64,
    /// Per-shape friction coefficient: 0.5. Chipmunk multiplies the two shapes' values, so the effective
    /// contact friction is 0.25; the world sets rapier's `Multiply` combine rule to match.
    pub friction: f64,
    /// Per-shape elasticity: 0.1 (effective restitution 0.01 by the same product rule).
    pub restitution: f64,
    /// Block capsule radius (px): 10.
    pub block_radius: f64,
    /// Mass of every ball, whatever its radius: 1 (inertia r²/2).
    pub ball_mass: f64,
    /// Mass of a dynamic block: 1.
    pub block_mass: f64,
    /// Rotational inertia of a dynamic block: `moment_for_segment(1, (0,0), (0,0), 10)` = 66.67,
    /// independent of its length (an I-PHYRE quirk kept on purpose, docs/envs/iphyre.md §R2).
    pub block_inertia: f64,
    /// Spring rest length (px): 20.
    pub spring_rest_length: f64,
    /// Spring stiffness (force per px): 1.
    pub spring_stiffness: f64,
    /// Spring damping (force per px/s): 0.3.
    pub spring_damping: f64,
    /// rapier solver iterations, i.e. substeps, per step: 1. Chipmunk takes one step per frame (positions
    /// from the previous velocities, then 10 velocity iterations); rapier's substeps integrate gravity in
    /// pieces, so with 3 a falling body already differs from Chipmunk's after one step and lags its
    /// one-frame-shifted trajectory by a third of a step. With one substep a free fall is Chipmunk's,
    /// one frame earlier (`docs/fidelity.md`, "I-PHYRE: where trajectories part").
    pub solver_iterations: usize,
    /// rapier's unbiased (relaxation) passes per solver iteration, which remove the velocity added to
    /// push penetrations apart: 0 (rapier's default is 1). Without them friction is solved in the biased
    /// pass; measured against the original this agrees better (`docs/fidelity.md`) and saves about a
    /// third of the solver's work.
    pub stabilization_iterations: usize,
    /// rapier projected Gauss–Seidel iterations per substep: 10, Chipmunk's default `Space.iterations`.
    /// With one substep this is Chipmunk's step structure; it raised the balanced held-out agreement
    /// from 91.5 % to 92.8 % at both 60 and 10 fps (`docs/fidelity.md`).
    pub pgs_iterations: usize,
    /// Contact softness (rapier `SpringCoefficients`) for every contact, static or not: natural
    /// frequency (Hz); 0 keeps rapier's defaults (30 Hz between dynamic bodies, 60 Hz against fixed ones).
    pub contact_frequency: f64,
    /// Contact softness damping ratio (rapier's default: 10), used when `contact_frequency` > 0.
    pub contact_damping_ratio: f64,
    /// Largest velocity (px/s) rapier may use to push a penetration apart; 0 keeps rapier's default
    /// (3 · `length_unit`).
    pub max_corrective_velocity: f64,
    /// rapier's `length_unit`, which scales its tolerances (allowed penetration 0.001·unit, prediction
    /// distance 0.002·unit, maximum corrective velocity 10·unit per s): 1, i.e. tolerances in pixels.
    /// Chosen by measurement against the original (`docs/fidelity.md`): outcome agreement on 640
    /// held-out pairs is 96.6 % (60 fps) and 92.5 % (10 fps) with 1, against 93.4 % and 90.3 % with
    /// 100 (the "metre-sized objects" reading of docs/envs/iphyre.md §R9); 0.1 breaks contacts (78 %).
    pub length_unit: f64,
    /// Box2D: screen pixels per Box2D metre, 20. Box2D's tolerances are fixed in metres (linear slop
    /// 0.005 m, largest position correction 0.2 m, largest move 2 m per step); at 20 px per metre the
    /// slop is Chipmunk's collision slop, 0.1 px.
    pub box2d_pixels_per_metre: f64,
    /// Box2D velocity iterations per step: 10, Chipmunk's `Space.iterations`.
    pub box2d_velocity_iterations: usize,
    /// Box2D position (overlap correction) iterations per step: 3.
    pub box2d_position_iterations: usize,
    /// Box2D: the polygon radius (px) of the box in a block's capsule (a box plus two end discs): 0.2,
    /// Box2D's own `b2_polygonRadius` (0.01 m) at 20 px per metre. The box is made thinner by it.
    pub box2d_polygon_skin: f64,
    /// Chipmunk step: solver iterations per step, 10 (pymunk's default `Space.iterations`).
    pub chipmunk_iterations: usize,
}

impl Default for PhysicsParams {
    fn default() -> Self {
        PhysicsParams {
            engine: Engine::Chipmunk,
            gravity: 100.0,
            fps: 60.0,
            max_time: 15.0,
            friction: 0.5,
            restitution: 0.1,
            block_radius: 10.0,
            ball_mass: 1.0,
            block_mass: 1.0,
            block_inertia: 1.0 * 10.0 * 10.0 * 2.0 / 3.0,
            spring_rest_length: 20.0,
            spring_stiffness: 1.0,
            spring_damping: 0.3,
            solver_iterations: 1,
            stabilization_iterations: 0,
            pgs_iterations: 10,
            contact_frequency: 0.0,
            contact_damping_ratio: 10.0,
            max_corrective_velocity: 0.0,
            length_unit: 1.0,
            box2d_pixels_per_metre: 20.0,
            box2d_velocity_iterations: 10,
            box2d_position_iterations: 3,
            box2d_polygon_skin: 0.2,
            chipmunk_iterations: 10,
        }
    }
}

impl PhysicsParams {
    /// The defaults at another frame rate (the gym wrappers' and DeepPHY's 10 fps, for instance).
    pub fn with_fps(fps: f64) -> Self {
        PhysicsParams {
            fps,
            ..PhysicsParams::default()
        }
    }

    /// The time step `1 / fps` (s).
    pub fn dt(&self) -> f64 {
        1.0 / self.fps
    }

    /// Checks every value is finite and in range.
    pub fn validate(&self) -> Result<()> {
        let positive = [
            ("fps", self.fps),
            ("max_time", self.max_time),
            ("block_radius", self.block_radius),
            ("ball_mass", self.ball_mass),
            ("block_mass", self.block_mass),
            ("block_inertia", self.block_inertia),
            ("length_unit", self.length_unit),
            ("box2d_pixels_per_metre", self.box2d_pixels_per_metre),
        ];
        let non_negative = [
            ("gravity", self.gravity.abs()),
            ("friction", self.friction),
            ("restitution", self.restitution),
            ("spring_rest_length", self.spring_rest_length),
            ("spring_stiffness", self.spring_stiffness),
            ("spring_damping", self.spring_damping),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(IphyreError::InvalidParams {
                    field,
                    message: format!("{v} is not a positive number"),
                });
            }
        }
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(IphyreError::InvalidParams {
                    field,
                    message: format!("{v} is not a finite non-negative number"),
                });
            }
        }
        for (field, v) in [
            ("solver_iterations", self.solver_iterations),
            ("pgs_iterations", self.pgs_iterations),
            ("box2d_velocity_iterations", self.box2d_velocity_iterations),
            ("chipmunk_iterations", self.chipmunk_iterations),
        ] {
            if v == 0 {
                return Err(IphyreError::InvalidParams {
                    field,
                    message: "must be at least 1".into(),
                });
            }
        }
        if !(self.box2d_polygon_skin >= 0.0 && self.box2d_polygon_skin < self.block_radius) {
            return Err(IphyreError::InvalidParams {
                field: "box2d_polygon_skin",
                message: format!(
                    "{} is not in [0, block_radius {})",
                    self.box2d_polygon_skin, self.block_radius
                ),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_iphyres() {
        let p = PhysicsParams::default();
        assert!((p.block_inertia - 66.67).abs() < 0.01);
        assert!((p.dt() - 1.0 / 60.0).abs() < 1e-15);
        assert!((p.friction * p.friction - 0.25).abs() < 1e-12);
        assert!((p.restitution * p.restitution - 0.01).abs() < 1e-12);
        p.validate().unwrap();
        assert!(PhysicsParams::with_fps(0.0).validate().is_err());
        assert!(PhysicsParams::with_fps(f64::NAN).validate().is_err());
    }
}
