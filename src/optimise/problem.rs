//! What an annealing chain searches: an environment's action as a point of a box ([`Problem`]), for
//! billiards ([`PoolProblem`]: the shot V0, φ, θ, a, b), PHYRE ([`PhyreProblem`]: the red ball's
//! x, y, r) and I-PHYRE ([`IphyreProblem`]: one removal time per eliminable block). Each problem turns a
//! point into the environment's action, simulates it through [`Environment`], names its scene, writes
//! the action as JSON for the `optimisation` table, describes the scene in words for reward synthesis
//! and renders a rollout as a frame strip.
//!
//! A sample reaches the chains as [`Simulated`]: billiards hands over its trace's columns, so a
//! sample only its rule checks never has its `Trace` built.
//!
//! **Owns:** the search boxes and point → action maps. **Does not:** simulate (it calls `envs`), score
//! or anneal (`chains`, `anneal`).

use serde_json::{Value, json};

use super::OptimiseError;
use super::anneal::Dim;
use crate::envs::iphyre::action::Click;
use crate::envs::iphyre::{Game, IphyreEnv};
use crate::envs::phyre::{BallAction, PhyreEnv, Task};
use crate::envs::pool::{PoolEnv, Scene, Shot};
use crate::envs::{EnvError, Environment};
use crate::reward::RewardError;
use crate::reward::verify::Rule;
use crate::trace::{Env, Outcome, Trace, TraceColumns};

/// An environment's action space as a box of continuous parameters.
pub trait Problem: Sync {
    /// An initial condition (a billiards scene, a PHYRE task, an I-PHYRE game).
    type Scene: Clone + Send + Sync;

    /// The environment.
    fn env(&self) -> Env;

    /// The search box for `scene` (its dimension may depend on the scene).
    fn dims(&self, scene: &Self::Scene) -> Vec<Dim>;

    /// Simulates point `x` of the box from `scene`.
    fn simulate(&self, scene: &Self::Scene, x: &[f64]) -> Result<Trace, EnvError>;

    /// Simulates point `x` as an annealing sample: by default [`Problem::simulate`]'s trace; an
    /// environment whose rules read its columns (billiards) hands those over, and the trace is built
    /// only for samples the detectors annotate.
    fn sample(&self, scene: &Self::Scene, x: &[f64]) -> Result<Simulated, EnvError> {
        self.simulate(scene, x).map(Simulated::Trace)
    }

    /// The scene's id in the `optimisation` table.
    fn scene_id(&self, scene: &Self::Scene) -> String;

    /// The action of point `x`, as the environment's action JSON.
    fn action_json(&self, scene: &Self::Scene, x: &[f64]) -> Value;

    /// The scene and the action in words, for the reward-synthesis prompt.
    fn describe(&self, scene: &Self::Scene) -> String;

    /// The rollout `trace` as a strip of `k` frames (PNG).
    fn strip(&self, scene: &Self::Scene, trace: &Trace, k: usize) -> Result<Vec<u8>, EnvError>;
}

/// One simulated sample of a chain: its paper-layout trace, or (billiards) the trace's columns.
// Unboxed: a sample is moved a few times per step, and boxing the columns would cost an
// allocation per sample.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum Simulated {
    /// The trace.
    Trace(Trace),
    /// The trace in columns; [`Simulated::into_trace`] builds the trace.
    Columns(TraceColumns),
}

impl Simulated {
    /// Names the sample's trace.
    pub fn set_trace_id(&mut self, id: String) {
        match self {
            Simulated::Trace(t) => t.trace_id = id,
            Simulated::Columns(c) => c.trace_id = id,
        }
    }

    /// How the episode ended.
    pub fn outcome(&self) -> &Outcome {
        match self {
            Simulated::Trace(t) => &t.outcome,
            Simulated::Columns(c) => &c.outcome,
        }
    }

    /// The paper-layout trace (built from the columns when it is not one yet).
    pub fn into_trace(self) -> Trace {
        match self {
            Simulated::Trace(t) => t,
            Simulated::Columns(c) => c.into_trace(),
        }
    }

    /// The paper-layout trace, borrowed, or built from the columns.
    pub fn trace(&self) -> std::borrow::Cow<'_, Trace> {
        match self {
            Simulated::Trace(t) => std::borrow::Cow::Borrowed(t),
            Simulated::Columns(c) => std::borrow::Cow::Owned(c.clone().into_trace()),
        }
    }

    /// Whether `rule` holds on the sample (read from the columns when it is held in columns).
    pub fn holds(&self, rule: &Rule) -> Result<bool, RewardError> {
        match self {
            Simulated::Trace(t) => rule.holds(t),
            Simulated::Columns(c) => rule.holds_on_columns(c),
        }
    }
}

/// `k` evenly spaced times over the trace (first and last timestep included).
pub fn strip_times(trace: &Trace, k: usize) -> Vec<f64> {
    let end = trace.timesteps.last().map(|t| t.t).unwrap_or(0.0);
    let k = k.max(1);
    if k == 1 {
        return vec![0.0];
    }
    (0..k).map(|i| end * i as f64 / (k - 1) as f64).collect()
}

/// Bounds of the shot parameters searched (inside `PoolEnv::action_space()`'s legal ranges).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShotBounds {
    /// Cue speed (m/s).
    pub v0: (f64, f64),
    /// Elevation (degrees).
    pub theta: (f64, f64),
    /// Largest tip offset radius √(a² + b²) (× R); offsets outside are scaled onto it.
    pub max_offset: f64,
}

impl Default for ShotBounds {
    /// V0 in [0.2, 6] m/s, θ in [0°, 45°], offsets within 0.9 R (φ always spans [0°, 360°)).
    fn default() -> Self {
        ShotBounds {
            v0: (0.2, 6.0),
            theta: (0.0, 45.0),
            max_offset: 0.9,
        }
    }
}

impl ShotBounds {
    /// The search box, checked against the environment's legal ranges.
    pub fn dims(&self, env: &PoolEnv) -> Result<Vec<Dim>, OptimiseError> {
        let space = env.action_space();
        let legal = |name: &str| {
            space
                .iter()
                .find(|d| d.name == name)
                .map(|d| (d.low, d.high))
                .unwrap_or((f64::NEG_INFINITY, f64::INFINITY))
        };
        let inside = |name: &str, (lo, hi): (f64, f64)| {
            let (l, h) = legal(name);
            if lo >= l && hi <= h && lo < hi {
                Ok(())
            } else {
                Err(OptimiseError::Bounds(format!(
                    "{name} range [{lo}, {hi}] must be non-empty and inside the legal [{l}, {h}]"
                )))
            }
        };
        inside("V0", self.v0)?;
        inside("theta", self.theta)?;
        if !(self.max_offset > 0.0 && self.max_offset < 1.0) {
            return Err(OptimiseError::Bounds(format!(
                "max_offset must be in (0, 1) (a² + b² < 1), found {}",
                self.max_offset
            )));
        }
        let (plo, phi) = legal("phi");
        let d = |low: f64, high: f64, periodic| Dim {
            low,
            high,
            periodic,
        };
        Ok(vec![
            d(self.v0.0, self.v0.1, false),
            d(plo.max(0.0), phi.min(360.0), true),
            d(self.theta.0, self.theta.1, false),
            d(-self.max_offset, self.max_offset, false),
            d(-self.max_offset, self.max_offset, false),
        ])
    }

    /// The shot of a point of the box (tip offsets scaled into the allowed disc).
    pub fn shot(&self, x: &[f64]) -> Shot {
        let (mut a, mut b) = (x[3], x[4]);
        let r = a.hypot(b);
        if r > self.max_offset {
            a *= self.max_offset / r;
            b *= self.max_offset / r;
        }
        Shot {
            v0: x[0],
            phi: x[1],
            theta: x[2],
            a,
            b,
        }
    }
}

/// Billiards: the five shot parameters.
#[derive(Debug, Clone)]
pub struct PoolProblem {
    /// The environment (its `trace.dt` sets the trace resolution the detectors see).
    pub env: PoolEnv,
    /// The shot box.
    pub bounds: ShotBounds,
    dims: Vec<Dim>,
}

impl PoolProblem {
    /// The problem, with `bounds` checked against the environment's legal ranges.
    pub fn new(env: PoolEnv, bounds: ShotBounds) -> Result<PoolProblem, OptimiseError> {
        let dims = bounds.dims(&env)?;
        Ok(PoolProblem { env, bounds, dims })
    }
}

impl Problem for PoolProblem {
    type Scene = Scene;

    fn env(&self) -> Env {
        Env::Pooltool
    }

    fn dims(&self, _: &Scene) -> Vec<Dim> {
        self.dims.clone()
    }

    fn simulate(&self, scene: &Scene, x: &[f64]) -> Result<Trace, EnvError> {
        self.env.simulate(scene, &self.bounds.shot(x))
    }

    fn sample(&self, scene: &Scene, x: &[f64]) -> Result<Simulated, EnvError> {
        self.env
            .simulate_columns(scene, &self.bounds.shot(x))
            .map(Simulated::Columns)
    }

    fn scene_id(&self, scene: &Scene) -> String {
        scene.scene_id.clone()
    }

    fn action_json(&self, _: &Scene, x: &[f64]) -> Value {
        let s = self.bounds.shot(x);
        json!({"V0": s.v0, "phi": s.phi, "theta": s.theta, "a": s.a, "b": s.b})
    }

    fn describe(&self, scene: &Scene) -> String {
        let t = &self.env.config.table;
        let balls: Vec<String> = scene
            .balls
            .iter()
            .map(|b| format!("{} ({:.3}, {:.3})", b.id, b.x, b.y))
            .collect();
        format!(
            "A billiards table {:.3} m wide (x) by {:.3} m long (y), origin at the bottom-left corner; \
             pockets lb, lc, lt on the left (x = 0: bottom, centre, top) and rb, rc, rt on the right.\n\
             The cue strikes ball {:?}. Balls at rest (id, x, y in metres): {}.\n\
             The action is one shot: speed V0 (m/s), aim angle phi (degrees from +x), elevation theta \
             (degrees), tip offsets a, b (ball radii).",
            t.w,
            t.l,
            scene.cue_ball,
            balls.join(", ")
        )
    }

    fn strip(&self, _: &Scene, trace: &Trace, k: usize) -> Result<Vec<u8>, EnvError> {
        crate::envs::pool::render::render_strip_png(
            trace,
            &self.env.config,
            &strip_times(trace, k),
            &crate::envs::pool::render::RenderOptions::default(),
        )
    }
}

/// PHYRE: where and how big the red ball is, (x, y, r) ∈ [0, 1]³. A ball that does not fit the scene
/// gives an `INVALID_INPUT` trace, which no goal's rule or program rewards.
#[derive(Debug, Clone, Default)]
pub struct PhyreProblem {
    /// The environment.
    pub env: PhyreEnv,
}

impl Problem for PhyreProblem {
    type Scene = Task;

    fn env(&self) -> Env {
        Env::Phyre
    }

    fn dims(&self, _: &Task) -> Vec<Dim> {
        self.env
            .action_space()
            .iter()
            .map(|d| Dim {
                low: d.low,
                high: d.high,
                periodic: false,
            })
            .collect()
    }

    fn simulate(&self, scene: &Task, x: &[f64]) -> Result<Trace, EnvError> {
        let a = BallAction {
            x: x[0],
            y: x[1],
            r: x[2],
        };
        self.env.simulate(scene, &a)
    }

    fn scene_id(&self, scene: &Task) -> String {
        scene.task_id.clone()
    }

    fn action_json(&self, _: &Task, x: &[f64]) -> Value {
        json!({"x": x[0], "y": x[1], "r": x[2]})
    }

    fn describe(&self, scene: &Task) -> String {
        let bodies: Vec<String> = scene
            .bodies
            .iter()
            .filter(|b| !b.is_wall)
            .map(|b| {
                format!(
                    "id {} {} {} at ({:.0}, {:.0}) px, size {:.0} px, {}",
                    b.id,
                    b.color.name(),
                    b.shape_type,
                    b.position[0],
                    b.position[1],
                    b.diameter,
                    if b.dynamic { "dynamic" } else { "static" }
                )
            })
            .collect();
        format!(
            "PHYRE task {} ({}): a {:.0}×{:.0} px scene, origin at the bottom-left, y up, gravity down; \
             bodies 0-3 are the walls. Objects: {}.\n\
             The action places one red ball (id {}, shape \"ball\", colour \"red\") before the scene runs: \
             centre x = 255·x px, y = 255·y px, radius 2 + 30·r px, (x, y, r) in [0, 1]; a ball that \
             overlaps an object is invalid.",
            scene.task_id,
            scene.description,
            scene.width,
            scene.height,
            bodies.join("; "),
            scene.bodies.len()
        )
    }

    fn strip(&self, scene: &Task, trace: &Trace, k: usize) -> Result<Vec<u8>, EnvError> {
        crate::envs::phyre::render::render_strip_png(
            trace,
            scene,
            &strip_times(trace, k),
            &crate::envs::phyre::render::RenderOptions::default(),
        )
    }
}

/// I-PHYRE: one time per eliminable block, in [0, `horizon`·(1 + `never`)]; a time past `horizon`
/// means the block is never removed, so "remove nothing" and "remove only block k" are in the box.
#[derive(Debug, Clone)]
pub struct IphyreProblem {
    /// The environment.
    pub env: IphyreEnv,
    /// Latest removal time (s), at most the episode's `max_time`.
    pub horizon: f64,
    /// The share of each range past `horizon` that means "never".
    pub never: f64,
}

impl IphyreProblem {
    /// The clicks of point `x` on `game`: block k at time `x[k]` when `x[k] ≤ horizon`.
    pub fn clicks(&self, game: &Game, x: &[f64]) -> Vec<Click> {
        game.eliminable()
            .zip(x)
            .filter(|(_, t)| **t <= self.horizon)
            .map(|(o, &t)| {
                let [cx, cy] = o.centre();
                Click {
                    x: cx,
                    y: cy,
                    t: t.max(1e-3),
                }
            })
            .collect()
    }
}

impl Problem for IphyreProblem {
    type Scene = Game;

    fn env(&self) -> Env {
        Env::Iphyre
    }

    fn dims(&self, game: &Game) -> Vec<Dim> {
        game.eliminable()
            .map(|_| Dim {
                low: 0.0,
                high: self.horizon * (1.0 + self.never),
                periodic: false,
            })
            .collect()
    }

    fn simulate(&self, game: &Game, x: &[f64]) -> Result<Trace, EnvError> {
        self.env.simulate(game, &self.clicks(game, x))
    }

    fn scene_id(&self, game: &Game) -> String {
        game.name.clone()
    }

    fn action_json(&self, game: &Game, x: &[f64]) -> Value {
        let blocks: Vec<Value> = game
            .eliminable()
            .zip(x)
            .map(|(o, &t)| {
                json!({"block": o.index, "t": if t <= self.horizon { Value::from(t) } else { Value::Null }})
            })
            .collect();
        json!({"removals": blocks})
    }

    fn describe(&self, game: &Game) -> String {
        let objects: Vec<String> = game
            .objects
            .iter()
            .map(|o| {
                let what = match (o.kind, o.eliminable, o.dynamic) {
                    (crate::envs::iphyre::ObjectKind::Ball, _, _) => {
                        return format!(
                            "id {} red ball at ({:.0}, {:.0}) px, radius {:.0}",
                            o.index, o.p1[0], o.p1[1], o.radius
                        );
                    }
                    (_, true, _) => "gray eliminable block",
                    (_, _, true) => "blue dynamic block",
                    _ => "black fixed block",
                };
                format!(
                    "id {} {what} from ({:.0}, {:.0}) to ({:.0}, {:.0}) px, radius {:.0}",
                    o.index, o.p1[0], o.p1[1], o.p2[0], o.p2[1], o.radius
                )
            })
            .collect();
        format!(
            "I-PHYRE game {:?}: a 600×600 px screen, origin at the top-left, y down, gravity down; the \
             episode lasts up to {:.0} s and succeeds (and stops) when every ball has left through the bottom edge. Objects: {}.\n\
             The action removes gray eliminable blocks: one removal time per block (seconds, up to \
             {:.1} s), or never.",
            game.name,
            self.env.params.max_time,
            objects.join("; "),
            self.horizon
        )
    }

    fn strip(&self, game: &Game, trace: &Trace, k: usize) -> Result<Vec<u8>, EnvError> {
        crate::envs::iphyre::render::render_strip_png(
            trace,
            Some(game),
            &strip_times(trace, k),
            &crate::envs::iphyre::render::RenderOptions::default(),
        )
    }
}
