//! Billiard-ball states by timestep, read the same way from a paper-layout [`Trace`], from a
//! simulated trace's columns ([`PoolFrames`]) or from its rows in a run's tables ([`PoolRows`]).
//! The verification rules read a shot through it, so an optimisation sample checked only by its
//! rule (a sparse chain's) never has its `Trace` built: that build, one [`Object`](super::Object)
//! per ball per step, costs more than the rule. The detector workers' load requests read it too
//! (`detect::protocol`), so `annotate` hands a billiards trace to a worker straight from its rows.
//!
//! **Owns:** [`PoolSteps`], [`BallView`] and the iterator over a step's balls.
//! **Does not:** build traces or columns (`frames`, the environments' `to_trace`), or know any rule
//! (`reward::verify`).

use super::framed::PoolRows;
use super::frames::PoolFrames;
use super::model::{Body, Timestep, Trace};

/// One ball's state at one timestep, borrowed: every field of a [`PoolBall`](super::PoolBall), as
/// rules and the detector workers' load requests read it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BallView<'a> {
    /// Object kind, `"ball"` for balls.
    pub kind: &'a str,
    /// Ball id: `"cue"`, `"1"` … `"15"`.
    pub ball_id: &'a str,
    /// Centre position (m).
    pub position: [f64; 3],
    /// Centre velocity (m/s).
    pub velocity: [f64; 3],
    /// Angular velocity (rad/s).
    pub angular_velocity: [f64; 3],
    /// pooltool's motion-state integer.
    pub motion_state_code: i64,
    /// The motion state's name (`stationary`, `spinning`, `sliding`, `rolling`, `pocketed`).
    pub motion_state: &'a str,
    /// Ball radius (m).
    pub radius: f64,
}

impl<'a> BallView<'a> {
    /// A paper-layout ball's view.
    pub fn of(b: &'a super::PoolBall) -> Self {
        BallView {
            kind: b.kind.as_str(),
            ball_id: b.ball_id.as_str(),
            position: b.position,
            velocity: b.velocity,
            angular_velocity: b.angular_velocity,
            motion_state_code: b.motion_state_code,
            motion_state: b.motion_state.as_str(),
            radius: b.radius,
        }
    }
}

/// The timesteps of a billiards trace: its paper-layout steps, or its columns with each step's
/// first frame row.
#[derive(Clone, Debug)]
pub enum PoolSteps<'a> {
    /// A paper-layout trace's timesteps (objects that are not balls are skipped).
    Trace(&'a [Timestep]),
    /// Columns: step `k` holds frame rows `starts[k]..starts[k + 1]`.
    Columns {
        /// The frames.
        frames: &'a PoolFrames,
        /// Each step's first row, then the number of rows.
        starts: Vec<usize>,
    },
    /// A trace's `frames` rows as read from the run's tables.
    Rows(&'a PoolRows<'a>),
}

impl<'a> PoolSteps<'a> {
    /// The steps of `trace`.
    pub fn of_trace(trace: &'a Trace) -> Self {
        PoolSteps::Trace(&trace.timesteps)
    }

    /// The steps of billiards columns.
    pub fn of_frames(frames: &'a PoolFrames) -> Self {
        PoolSteps::Columns {
            frames,
            starts: frames.step_starts(),
        }
    }

    /// Number of timesteps.
    pub fn len(&self) -> usize {
        match self {
            PoolSteps::Trace(s) => s.len(),
            PoolSteps::Columns { starts, .. } => starts.len().saturating_sub(1),
            PoolSteps::Rows(r) => r.steps_len(),
        }
    }

    /// Whether there are no timesteps.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The time of step `k` (s).
    pub fn t(&self, k: usize) -> f64 {
        match self {
            PoolSteps::Trace(s) => s[k].t,
            PoolSteps::Columns { frames, .. } => frames.times()[k],
            PoolSteps::Rows(r) => r.timesteps()[k].t,
        }
    }

    /// The number of steps at or before `t` (steps are in increasing time).
    pub fn count_until(&self, t: f64) -> usize {
        match self {
            PoolSteps::Trace(s) => s.partition_point(|s| s.t <= t),
            PoolSteps::Columns { frames, .. } => frames.times().partition_point(|&s| s <= t),
            PoolSteps::Rows(r) => r.timesteps().partition_point(|s| s.t <= t),
        }
    }

    /// The balls of step `k`, in the step's order.
    pub fn balls(&self, k: usize) -> Balls<'_, 'a> {
        let (row, end) = match self {
            PoolSteps::Trace(s) => (0, s[k].objects.len()),
            PoolSteps::Columns { starts, .. } => (starts[k], starts[k + 1]),
            PoolSteps::Rows(r) => r.step_rows(k),
        };
        Balls {
            steps: self,
            k,
            row,
            end,
        }
    }

    /// Ball `id` at step `k` (the first with that id).
    pub fn ball(&self, k: usize, id: &str) -> Option<BallView<'a>> {
        self.balls(k).find(|b| b.ball_id == id)
    }
}

/// The balls of one step ([`PoolSteps::balls`]).
#[derive(Debug)]
pub struct Balls<'s, 'a> {
    steps: &'s PoolSteps<'a>,
    k: usize,
    row: usize,
    end: usize,
}

impl<'a> Iterator for Balls<'_, 'a> {
    type Item = BallView<'a>;

    fn next(&mut self) -> Option<BallView<'a>> {
        while self.row < self.end {
            let i = self.row;
            self.row += 1;
            match self.steps {
                PoolSteps::Trace(s) => {
                    if let Body::Pool(b) = &s[self.k].objects[i].body {
                        return Some(BallView::of(b));
                    }
                }
                PoolSteps::Columns { frames, .. } => return Some(frames.ball_state(i)),
                PoolSteps::Rows(r) => return Some(r.ball(i)),
            }
        }
        None
    }
}
