//! The images of a stored trace that a vision-language model is shown: the initial scene and keyframes
//! spread evenly over the rollout, drawn by each environment's renderer (billiards on the built-in 7-ft
//! table, I-PHYRE with its game's blocks when the game is one of the 40 built-in ones, PHYRE on its
//! task's scene, which must be one of the built-in ball-tier tasks).
//!
//! **Does not:** choose what to show when (the summarisers and choosers do).

use crate::bench::feedback::Image;
use crate::envs::iphyre::Games;
use crate::envs::iphyre::render as iphyre_render;
use crate::envs::phyre::TaskSet;
use crate::envs::phyre::render as phyre_render;
use crate::envs::pool::PoolConfig;
use crate::envs::pool::render as pool_render;
use crate::envs::{EnvError, phyre};
use crate::trace::{Env, Trace};

use super::SummaryError;

/// Draws frames of stored traces at one size.
#[derive(Debug)]
pub struct TraceImages {
    size: u32,
    games: Games,
    pool: PoolConfig,
}

impl TraceImages {
    /// A renderer of `size` px square images (the paper used 512).
    pub fn new(size: u32) -> Result<Self, EnvError> {
        Ok(TraceImages {
            size,
            games: Games::default_games()?,
            pool: PoolConfig::default_7ft(),
        })
    }

    /// The image at `t` seconds (the nearest timestep).
    fn frame(&self, trace: &Trace, t: f64) -> Result<Vec<u8>, EnvError> {
        match trace.env {
            Env::Pooltool => pool_render::render_png(
                trace,
                &self.pool,
                t,
                &pool_render::RenderOptions { size: self.size },
            ),
            Env::Iphyre => iphyre_render::render_png(
                trace,
                self.games.get(&trace.task_id).ok(),
                t,
                &iphyre_render::RenderOptions {
                    size: self.size,
                    block_indices: false,
                    time_label: true,
                },
            ),
            Env::Phyre => {
                let task: phyre::Task = TaskSet::default_tasks()?.get(&trace.task_id)?;
                phyre_render::render_png(
                    trace,
                    &task,
                    t,
                    &phyre_render::RenderOptions {
                        size: self.size,
                        grid: false,
                    },
                )
            }
        }
    }

    /// The first timestep.
    pub fn initial(&self, trace: &Trace) -> Result<Image, SummaryError> {
        let t0 = trace.timesteps.first().map_or(0.0, |s| s.t);
        Ok(Image {
            caption: "initial scene".into(),
            png: self.frame(trace, t0).map_err(|e| render_error(trace, e))?,
        })
    }

    /// `k` frames spread evenly from the first to the last timestep.
    pub fn keyframes(&self, trace: &Trace, k: usize) -> Result<Vec<Image>, SummaryError> {
        pool_render::strip_times(trace, k)
            .into_iter()
            .map(|t| {
                Ok(Image {
                    caption: format!("t = {t:.2} s"),
                    png: self.frame(trace, t).map_err(|e| render_error(trace, e))?,
                })
            })
            .collect()
    }
}

fn render_error(trace: &Trace, source: EnvError) -> SummaryError {
    SummaryError::Render {
        trace: trace.trace_id.clone(),
        source,
    }
}
