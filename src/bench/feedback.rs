//! What an agent is shown: the images of a task before it acts, and the feedback after a failed
//! attempt in each [`FeedbackMode`].
//!
//! * `none`: only the verdict (the action failed, or was invalid and why).
//! * `image-only` (DeepPHY's baseline): the verdict and keyframes of the failed rollout — PHYRE at
//!   t = 0, 1, 2, 3, 4 s (DeepPHY's first five 60-step frames), I-PHYRE evenly from the last removal to
//!   the end, billiards evenly over the shot — each a PNG.
//! * `annotations` (the paper's): the verdict and the rollout as annotated-trace text from a detector
//!   library ([`crate::detect::annotated_text`], what `annotrace show` prints); the initial image was
//!   already shown with the task.
//!
//! Billiards plays on an evolving table, so after every shot the current table is shown too, whatever the
//! mode. **Does not:** run detectors itself (the caller passes the annotations from the worker pool).

use serde::{Deserialize, Serialize};

use super::task::{Simulators, TaskScene};
use crate::detect::Annotation;
use crate::envs::EnvError;
use crate::envs::iphyre::render as iphyre_render;
use crate::envs::phyre::render as phyre_render;
use crate::envs::pool::render as pool_render;
use crate::trace::{Body, Env, Object, Outcome, PoolBall, Timestep, Trace};

/// What follows a failed attempt.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum FeedbackMode {
    /// The verdict only.
    #[default]
    None,
    /// The verdict and keyframes of the rollout (DeepPHY's baseline).
    ImageOnly,
    /// The verdict and the annotated trace of the rollout as text.
    Annotations,
}

impl FeedbackMode {
    /// The mode's name (`none`, `image-only`, `annotations`).
    pub fn as_str(self) -> &'static str {
        match self {
            FeedbackMode::None => "none",
            FeedbackMode::ImageOnly => "image-only",
            FeedbackMode::Annotations => "annotations",
        }
    }
}

/// A labelled image.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// What it shows (`initial scene`, `t = 2.0 s`).
    pub caption: String,
    /// PNG bytes.
    pub png: Vec<u8>,
}

/// The feedback of one failed attempt.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Feedback {
    /// Annotated-trace text (annotations mode).
    pub text: Option<String>,
    /// Keyframes (image-only mode) and, for billiards, the table now.
    pub images: Vec<Image>,
}

/// The images shown with a task before the first attempt, `size` px square: PHYRE the scene and the
/// scene with the numbered grid, I-PHYRE the game with block indices, billiards the table.
pub fn task_images(
    scene: &TaskScene,
    sims: &Simulators,
    size: u32,
) -> Result<Vec<Image>, EnvError> {
    match scene {
        TaskScene::Phyre(task) => {
            let plain = phyre_render::RenderOptions { size, grid: false };
            let grid = phyre_render::RenderOptions { size, grid: true };
            Ok(vec![
                Image {
                    caption: "initial scene".into(),
                    png: phyre_render::render_task_png(task, &plain)?,
                },
                Image {
                    caption: "initial scene with the numbered 8x8 grid".into(),
                    png: phyre_render::render_task_png(task, &grid)?,
                },
            ])
        }
        TaskScene::Iphyre(game) => Ok(vec![Image {
            caption: "initial scene, removable blocks numbered".into(),
            png: iphyre_render::render_scene_png(
                game,
                &iphyre_render::RenderOptions {
                    size,
                    block_indices: true,
                    time_label: false,
                },
            )?,
        }]),
        TaskScene::Pool(_) => Ok(vec![Image {
            caption: "the table".into(),
            png: pool_table_png(scene, sims, size)?,
        }]),
    }
}

/// The billiards table of `scene` as a PNG (a one-step trace of the balls at rest).
fn pool_table_png(scene: &TaskScene, sims: &Simulators, size: u32) -> Result<Vec<u8>, EnvError> {
    let TaskScene::Pool(s) = scene else {
        return Err(EnvError::Render("not a billiards table".into()));
    };
    let r = sims.pool.config.ball.r;
    let objects = s
        .balls
        .iter()
        .map(|b| Object {
            body: Body::Pool(PoolBall {
                kind: "ball".into(),
                ball_id: b.id.as_str().into(),
                position: [b.x, b.y, r],
                velocity: [0.0; 3],
                angular_velocity: [0.0; 3],
                motion_state_code: 0,
                motion_state: "stationary".into(),
                radius: r,
            }),
            extra: Default::default(),
        })
        .collect();
    let trace = Trace {
        trace_id: s.scene_id.clone(),
        env: Env::Pooltool,
        task_id: s.scene_id.clone(),
        timesteps: vec![Timestep {
            index: 0,
            t: 0.0,
            objects,
            extra: Default::default(),
        }],
        events: Vec::new(),
        outcome: Outcome {
            success: false,
            terminal_status: "at_rest".into(),
            metrics: Default::default(),
            extra: Default::default(),
        },
        extra: Default::default(),
    };
    pool_render::render_png(
        &trace,
        &sims.pool.config,
        0.0,
        &pool_render::RenderOptions { size },
    )
}

/// The instants of the `k` keyframes of a rollout of `scene`.
pub fn keyframe_times(scene: &TaskScene, trace: &Trace, k: usize, last_removal: f64) -> Vec<f64> {
    let end = trace.timesteps.last().map_or(0.0, |s| s.t);
    match scene {
        TaskScene::Phyre(_) => (0..k).map(|i| (i as f64).min(end)).collect(),
        TaskScene::Iphyre(_) => {
            let from = last_removal.min(end);
            if k <= 1 {
                return vec![from; k];
            }
            (0..k)
                .map(|i| from + (end - from) * i as f64 / (k - 1) as f64)
                .collect()
        }
        TaskScene::Pool(_) => pool_render::strip_times(trace, k),
    }
}

/// The feedback of the failed rollout `trace` of `scene` (the state the attempt started from) in
/// `mode`; `next` is the state after it (shown for billiards), `annotations` the rollout's annotations.
#[allow(clippy::too_many_arguments)]
pub fn feedback(
    mode: FeedbackMode,
    sims: &Simulators,
    scene: &TaskScene,
    next: &TaskScene,
    trace: &Trace,
    last_removal: f64,
    annotations: &[Annotation],
    keyframes: usize,
    size: u32,
) -> Result<Feedback, EnvError> {
    let mut out = Feedback::default();
    match mode {
        FeedbackMode::None => {}
        FeedbackMode::Annotations => {
            out.text = Some(crate::detect::annotated_text(trace, annotations));
        }
        FeedbackMode::ImageOnly => {
            for t in keyframe_times(scene, trace, keyframes, last_removal) {
                let png = match scene {
                    TaskScene::Phyre(task) => phyre_render::render_png(
                        trace,
                        task,
                        t,
                        &phyre_render::RenderOptions { size, grid: false },
                    )?,
                    TaskScene::Iphyre(game) => iphyre_render::render_png(
                        trace,
                        Some(game),
                        t,
                        &iphyre_render::RenderOptions {
                            size,
                            block_indices: true,
                            time_label: true,
                        },
                    )?,
                    TaskScene::Pool(_) => pool_render::render_png(
                        trace,
                        &sims.pool.config,
                        t,
                        &pool_render::RenderOptions { size },
                    )?,
                };
                out.images.push(Image {
                    caption: format!("t = {t:.1} s"),
                    png,
                });
            }
        }
    }
    if matches!(next, TaskScene::Pool(_)) {
        out.images.push(Image {
            caption: "the table now".into(),
            png: pool_table_png(next, sims, size)?,
        });
    }
    Ok(out)
}
