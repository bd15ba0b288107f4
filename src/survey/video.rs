//! A trace's rollout as an animation: frames drawn by the environment's renderer (the one behind
//! `annotrace render`, the report's colours and the summarisers' keyframes), played in real time.
//!
//! **Owns:** which instants become frames (`fps` per simulated second, evenly over the trace, at most
//! `max_frames`; the delay between frames is the time between them, so the animation lasts as long as
//! the rollout) and turning the rendered PNGs into RGBA for [`super::Animation`]. **Does not:** draw
//! (`envs::*::render`) or encode (`super::apng`).

use rayon::prelude::*;

use super::SurveyError;
use super::apng::Animation;
use crate::envs::EnvError;
use crate::envs::iphyre::Games;
use crate::envs::iphyre::render as iphyre_render;
use crate::envs::phyre::render as phyre_render;
use crate::envs::phyre::{Task, TaskSet};
use crate::envs::pool::PoolConfig;
use crate::envs::pool::render as pool_render;
use crate::trace::{Env, Trace};

/// How a rollout becomes an animation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VideoOptions {
    /// Width and height of a frame (px).
    pub size: u32,
    /// Frames per simulated second.
    pub fps: f64,
    /// At most this many frames (longer rollouts get fewer frames per second, still in real time).
    pub max_frames: usize,
}

impl Default for VideoOptions {
    fn default() -> Self {
        VideoOptions {
            size: 320,
            fps: 10.0,
            max_frames: 150,
        }
    }
}

/// The instants drawn and the delay between frames (ms) for a trace spanning `t0..=t1`.
pub fn frame_times(t0: f64, t1: f64, opts: &VideoOptions) -> (Vec<f64>, u16) {
    let span = (t1 - t0).max(0.0);
    let wanted = (span * opts.fps).floor() as usize + 1;
    let n = wanted.clamp(1, opts.max_frames.max(1));
    if n == 1 {
        return (vec![t0], 1000);
    }
    let step = span / (n - 1) as f64;
    let delay = (step * 1000.0).round().clamp(10.0, 65_535.0) as u16;
    ((0..n).map(|i| t0 + step * i as f64).collect(), delay)
}

/// Draws frames of stored traces (the renderers' data loaded once).
#[derive(Debug)]
pub struct Videos {
    opts: VideoOptions,
    pool: PoolConfig,
    games: Games,
}

impl Videos {
    /// A frame maker with these options.
    pub fn new(opts: VideoOptions) -> Result<Self, EnvError> {
        Ok(Videos {
            opts,
            pool: PoolConfig::default_7ft(),
            games: Games::default_games()?,
        })
    }

    fn task(trace: &Trace) -> Result<Task, EnvError> {
        let tasks = TaskSet::default_tasks().map_err(|e| EnvError::Render(e.to_string()))?;
        tasks
            .get(&trace.task_id)
            .map_err(|e| EnvError::Render(e.to_string()))
    }

    /// The rollout of `trace` as an animation.
    pub fn animation(&mut self, trace: &Trace) -> Result<Animation, SurveyError> {
        let err = |source: EnvError| SurveyError::Render {
            trace: trace.trace_id.clone(),
            source,
        };
        let (t0, t1) = match (trace.timesteps.first(), trace.timesteps.last()) {
            (Some(a), Some(b)) => (a.t, b.t),
            _ => {
                return Err(err(EnvError::Render("the trace has no timesteps".into())));
            }
        };
        let (times, delay_ms) = frame_times(t0, t1, &self.opts);
        let size = self.opts.size;
        let task = match trace.env {
            Env::Phyre => Some(Self::task(trace).map_err(err)?),
            _ => None,
        };
        let game = self.games.get(&trace.task_id).ok();
        let pool = &self.pool;
        let png = |t: f64| -> Result<Vec<u8>, EnvError> {
            match trace.env {
                Env::Pooltool => {
                    pool_render::render_png(trace, pool, t, &pool_render::RenderOptions { size })
                }
                Env::Iphyre => iphyre_render::render_png(
                    trace,
                    game,
                    t,
                    &iphyre_render::RenderOptions {
                        size,
                        block_indices: false,
                        time_label: true,
                    },
                ),
                Env::Phyre => phyre_render::render_png(
                    trace,
                    task.as_ref().expect("set for PHYRE"),
                    t,
                    &phyre_render::RenderOptions { size, grid: false },
                ),
            }
        };
        let frames = times
            .par_iter()
            .map(|&t| {
                let bytes = png(t)?;
                let pixmap = tiny_skia::Pixmap::decode_png(&bytes)
                    .map_err(|e| EnvError::Render(format!("decoding a frame: {e}")))?;
                if (pixmap.width(), pixmap.height()) != (size, size) {
                    return Err(EnvError::Render(format!(
                        "a frame is {}×{} px, expected {size}×{size}",
                        pixmap.width(),
                        pixmap.height()
                    )));
                }
                // Frames are opaque, so premultiplied RGBA is RGBA.
                Ok(pixmap.take())
            })
            .collect::<Result<Vec<_>, EnvError>>()
            .map_err(err)?;
        Ok(Animation {
            width: size,
            height: size,
            delay_ms,
            frames,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_follow_the_rollout_in_real_time() {
        let o = VideoOptions {
            size: 64,
            fps: 10.0,
            max_frames: 150,
        };
        let (t, d) = frame_times(0.0, 2.0, &o);
        assert_eq!(t.len(), 21);
        assert_eq!(d, 100);
        assert!((t[20] - 2.0).abs() < 1e-12);
        // Capped: fewer frames, longer delays, same duration.
        let (t, d) = frame_times(1.0, 31.0, &o);
        assert_eq!(t.len(), 150);
        assert_eq!(d, (30_000.0f64 / 149.0).round() as u16);
        // A single instant is one frame.
        assert_eq!(frame_times(3.0, 3.0, &o).0, [3.0]);
    }

    #[test]
    fn a_billiards_shot_becomes_an_animation_of_its_frames() {
        let trace = crate::testutil::synthetic_trace(Env::Pooltool, 0, 12, 3);
        let mut v = Videos::new(VideoOptions {
            size: 64,
            fps: 10.0,
            max_frames: 8,
        })
        .unwrap();
        let a = v.animation(&trace).unwrap();
        assert_eq!((a.width, a.height), (64, 64));
        assert!(a.frames.len() > 1 && a.frames.len() <= 8);
        assert!(a.frames.iter().all(|f| f.len() == 64 * 64 * 4));
        // The first frame is what `render` draws at the first timestep.
        let png = pool_render::render_png(
            &trace,
            &PoolConfig::default_7ft(),
            trace.timesteps[0].t,
            &pool_render::RenderOptions { size: 64 },
        )
        .unwrap();
        let first = tiny_skia::Pixmap::decode_png(&png).unwrap();
        assert_eq!(first.data(), &a.frames[0][..]);
    }
}
