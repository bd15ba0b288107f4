//! [`run`]: one PHYRE episode, in PHYRE's order (docs/envs/phyre.md §R5): place the red ball (or stop with
//! `INVALID_INPUT`), then up to 1000 times: step the physics → note contact changes → test the goal
//! relation → stop as soon as it has held for 180 consecutive steps. Frames are kept every `stride` steps
//! (step 0, the initial scene with the red ball, always; the last step always).
//!
//! When every dynamic body sleeps, nothing can move again, so the loop stops stepping the engine and
//! replays the frozen state for the remaining steps: the outcome, frames and events are the same as
//! stepping, only faster.

use super::action::{BallAction, Placement, UserBall};
use super::error::{PhyreError, Result};
use super::params::{Engine, PhysicsParams};
use super::task::Task;
use super::world::{BodyState, ContactChange, World};

/// PHYRE's `SimulationStatus`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Status {
    /// The goal held for 180 consecutive steps (code 1).
    Solved,
    /// 1000 steps without that (code −1).
    NotSolved,
    /// The action's ball is outside the scene or overlaps a body; nothing was simulated (code 0).
    InvalidInput,
}

impl Status {
    /// PHYRE's integer code.
    pub fn code(self) -> i64 {
        match self {
            Status::Solved => 1,
            Status::NotSolved => -1,
            Status::InvalidInput => 0,
        }
    }

    /// PHYRE's name (`SOLVED`, `NOT_SOLVED`, `INVALID_INPUT`).
    pub fn name(self) -> &'static str {
        match self {
            Status::Solved => "SOLVED",
            Status::NotSolved => "NOT_SOLVED",
            Status::InvalidInput => "INVALID_INPUT",
        }
    }
}

/// What to record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordOptions {
    /// Keep a frame every this many steps (≥ 1); 0 keeps no frames but the first and last.
    pub stride: usize,
    /// Whether to keep frames and events at all (off: status only, for search and speed checks).
    pub record: bool,
}

/// The default frame stride: 6 steps, i.e. 10 frames per second (docs/envs/phyre.md says why).
pub const DEFAULT_STRIDE: usize = 6;

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            stride: DEFAULT_STRIDE,
            record: true,
        }
    }
}

/// Every body's state after `step` steps.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Physics steps done (0 = the initial scene).
    pub step: usize,
    /// The bodies in index order (the user ball last).
    pub bodies: Vec<BodyState>,
}

/// Something that happened during an episode.
#[derive(Debug, Clone, PartialEq)]
pub enum EpisodeEvent {
    /// The red ball went into the scene (step 0).
    UserBallPlaced {
        /// Its body index.
        index: usize,
        /// The quantised ball.
        ball: UserBall,
    },
    /// The action was refused (`INVALID_INPUT`).
    InvalidInput {
        /// `outside_scene` or `occludes_body`.
        reason: &'static str,
        /// The overlapped body, for `occludes_body`.
        body: Option<usize>,
    },
    /// Two bodies started touching during step `step`.
    ContactBegin {
        /// The step (1-based).
        step: usize,
        /// Body indices, smaller first.
        objects: [usize; 2],
    },
    /// Two bodies stopped touching during step `step`.
    ContactEnd {
        /// The step.
        step: usize,
        /// Body indices, smaller first.
        objects: [usize; 2],
    },
    /// The goal relation started holding after step `step`.
    GoalRelationBegin {
        /// The step.
        step: usize,
    },
    /// The goal relation stopped holding after step `step`, having held `held_steps` steps.
    GoalRelationEnd {
        /// The step.
        step: usize,
        /// Consecutive steps it held.
        held_steps: usize,
    },
    /// The goal held for the 180th consecutive step: solved.
    Success {
        /// The step.
        step: usize,
    },
}

/// What an episode produced.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeResult {
    /// The action as given.
    pub action: BallAction,
    /// Where its ball went, or why it could not.
    pub placement: Placement,
    /// PHYRE's status.
    pub status: Status,
    /// Physics steps done (0 for `INVALID_INPUT`).
    pub steps: usize,
    /// Of those, the steps the engine actually computed (the rest replayed a state where everything
    /// slept).
    pub computed_steps: usize,
    /// The step at which the goal relation started its final (winning) run, when solved.
    pub goal_first_step: Option<usize>,
    /// Frames (empty when not recording).
    pub frames: Vec<Frame>,
    /// Events in order (empty when not recording).
    pub events: Vec<EpisodeEvent>,
    /// The time step (s).
    pub dt: f64,
    /// The frame stride used.
    pub stride: usize,
    /// The physics engine that ran the episode.
    pub engine: Engine,
}

impl EpisodeResult {
    /// Whether the task was solved.
    pub fn solved(&self) -> bool {
        self.status == Status::Solved
    }
}

fn snapshot(world: &World, step: usize) -> Frame {
    if step == 0 {
        return Frame {
            step,
            bodies: world.initial_states().to_vec(),
        };
    }
    let mut bodies = Vec::with_capacity(world.len());
    world.states_into(&mut bodies);
    Frame { step, bodies }
}

/// An action whose ball does not fit: the scene as it stands and why the action is invalid.
fn record_invalid(
    task: &Task,
    placement: Placement,
    params: &PhysicsParams,
    result: &mut EpisodeResult,
) -> Result<()> {
    let world = World::new(task, None, params)?;
    result.frames.push(snapshot(&world, 0));
    let (reason, body) = match placement {
        Placement::Occludes { body } => ("occludes_body", Some(body)),
        _ => ("outside_scene", None),
    };
    result
        .events
        .push(EpisodeEvent::InvalidInput { reason, body });
    Ok(())
}

/// Steps the world to `step`, recording its contact changes and (every `stride` steps) a frame
/// when recording; returns whether the goal relation holds.
fn advance(
    world: &mut World,
    step: usize,
    changes: &mut Vec<ContactChange>,
    opts: &RecordOptions,
    result: &mut EpisodeResult,
) -> bool {
    changes.clear();
    world.step(changes);
    result.computed_steps += 1;
    if opts.record {
        for c in changes.iter() {
            result.events.push(if c.began {
                EpisodeEvent::ContactBegin {
                    step,
                    objects: c.objects,
                }
            } else {
                EpisodeEvent::ContactEnd {
                    step,
                    objects: c.objects,
                }
            });
        }
        if opts.stride > 0 && step.is_multiple_of(opts.stride) {
            result.frames.push(snapshot(world, step));
        }
    }
    world.goal_holds()
}

/// Counts the run of steps in which the goal holds (`run_len`) and records where a run begins
/// (also the first goal step) and ends; `prev` is whether it held the step before.
fn track_goal(
    holds: bool,
    prev: bool,
    run_len: &mut usize,
    step: usize,
    opts: &RecordOptions,
    result: &mut EpisodeResult,
) {
    if holds {
        *run_len += 1;
        if !prev {
            result.goal_first_step = Some(step);
            if opts.record {
                result.events.push(EpisodeEvent::GoalRelationBegin { step });
            }
        }
    } else {
        if prev && opts.record {
            result.events.push(EpisodeEvent::GoalRelationEnd {
                step,
                held_steps: *run_len,
            });
        }
        *run_len = 0;
    }
}

/// Plays `action` on `task`. Errors only for an action outside [0, 1]³ or non-finite, or bad parameters;
/// a ball that does not fit gives an `INVALID_INPUT` result.
pub fn run(
    task: &Task,
    action: &BallAction,
    params: &PhysicsParams,
    opts: &RecordOptions,
) -> Result<EpisodeResult> {
    params.validate()?;
    let placement = action.place(task)?;
    let mut result = EpisodeResult {
        action: *action,
        placement,
        status: Status::InvalidInput,
        steps: 0,
        computed_steps: 0,
        goal_first_step: None,
        frames: Vec::new(),
        events: Vec::new(),
        dt: params.dt(),
        stride: opts.stride,
        engine: params.engine,
    };
    let ball = match placement {
        Placement::Valid(b) => b,
        Placement::OutsideScene | Placement::Occludes { .. } => {
            if opts.record {
                record_invalid(task, placement, params, &mut result)?;
            }
            return Ok(result);
        }
    };
    let mut world = World::new(task, Some(&ball), params)?;
    if opts.record {
        result.events.push(EpisodeEvent::UserBallPlaced {
            index: task.bodies.len(),
            ball,
        });
        result.frames.push(snapshot(&world, 0));
    }
    let mut changes: Vec<ContactChange> = Vec::new();
    let (mut run_len, mut prev) = (0usize, false);
    let mut status = Status::NotSolved;
    let mut step = 0;
    let mut frozen: Option<Frame> = None;
    while step < params.max_steps {
        step += 1;
        let holds = if let Some(f) = &frozen {
            // Nothing moves any more: the goal test gives what it gave last step.
            if opts.record && opts.stride > 0 && step % opts.stride == 0 {
                result.frames.push(Frame {
                    step,
                    bodies: f.bodies.clone(),
                });
            }
            prev
        } else {
            advance(&mut world, step, &mut changes, opts, &mut result)
        };
        track_goal(holds, prev, &mut run_len, step, opts, &mut result);
        prev = holds;
        if run_len >= params.steps_for_solution {
            status = Status::Solved;
            if opts.record {
                result.events.push(EpisodeEvent::Success { step });
            }
            break;
        }
        if frozen.is_none() && params.sleeping && world.all_asleep() {
            frozen = Some(snapshot(&world, step));
            if !opts.record {
                // Status only: jump to the end of the episode.
                let left = params.max_steps - step;
                if holds && params.steps_for_solution - run_len <= left {
                    step += params.steps_for_solution - run_len;
                    status = Status::Solved;
                } else {
                    step = params.max_steps;
                }
                break;
            }
        }
    }
    if status != Status::Solved {
        result.goal_first_step = None;
    }
    if opts.record && result.frames.last().is_none_or(|f| f.step != step) {
        let mut last = match &frozen {
            Some(f) => f.clone(),
            None => snapshot(&world, step),
        };
        last.step = step;
        result.frames.push(last);
    }
    result.status = status;
    result.steps = step;
    Ok(result)
}

/// PHYRE's status of `action` on `task` without recording anything (the fastest path).
pub fn status(task: &Task, action: &BallAction, params: &PhysicsParams) -> Result<Status> {
    let r = run(
        task,
        action,
        params,
        &RecordOptions {
            stride: 0,
            record: false,
        },
    )?;
    Ok(r.status)
}

/// Checks a frame stride.
pub fn validate_stride(stride: usize) -> Result<()> {
    if stride == 0 || stride > 1000 {
        return Err(PhyreError::InvalidParams {
            field: "stride",
            message: format!("{stride} is not within 1..=1000 steps"),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::phyre::tasks::TaskSet;

    #[test]
    fn dropping_the_red_ball_on_the_green_one_in_00000_pushes_it_into_the_blue_one() {
        // Task 00000:000: green ball (r 7.5) at x 89.6, blue ball (r 15.5) at x 192 on the floor.
        let task = TaskSet::default_tasks().unwrap().get("00000:000").unwrap();
        let params = PhysicsParams::default();
        // A big ball just left of the green one rolls it to the right.
        let a = BallAction {
            x: 60.0 / 255.0,
            y: 0.5,
            r: 0.8,
        };
        let r = run(&task, &a, &params, &RecordOptions::default()).unwrap();
        assert_eq!(r.frames[0].step, 0);
        assert_eq!(r.frames[0].bodies.len(), task.bodies.len() + 1);
        assert!(r.frames.windows(2).all(|w| w[0].step < w[1].step));
        assert_eq!(r.frames.last().unwrap().step, r.steps);
        assert!(matches!(
            r.events[0],
            EpisodeEvent::UserBallPlaced { index: 6, .. }
        ));
        let contact = r.events.iter().any(|e| {
            matches!(
                e,
                EpisodeEvent::ContactBegin {
                    objects: [0, 6],
                    ..
                }
            )
        });
        assert!(contact, "the red ball never hit the floor");
        // The status-only path gives the same outcome.
        assert_eq!(status(&task, &a, &params).unwrap(), r.status);
        // Doing nothing useful leaves it unsolved after 1000 steps.
        let far = BallAction {
            x: 0.95,
            y: 0.95,
            r: 0.0,
        };
        let r = run(&task, &far, &params, &RecordOptions::default()).unwrap();
        assert_eq!((r.status, r.steps), (Status::NotSolved, 1000));
        assert_eq!(r.frames.len(), 1 + 1000 / DEFAULT_STRIDE + 1);
    }

    #[test]
    fn invalid_actions_are_not_simulated() {
        let task = TaskSet::default_tasks().unwrap().get("00000:000").unwrap();
        let a = BallAction {
            x: 89.6 / 255.0,
            y: 58.7 / 255.0,
            r: 0.2,
        };
        let r = run(
            &task,
            &a,
            &PhysicsParams::default(),
            &RecordOptions::default(),
        )
        .unwrap();
        assert_eq!(
            (r.status, r.steps, r.frames.len()),
            (Status::InvalidInput, 0, 1)
        );
        assert_eq!(r.frames[0].bodies.len(), task.bodies.len());
        assert!(matches!(
            r.events[0],
            EpisodeEvent::InvalidInput {
                reason: "occludes_body",
                body: Some(4)
            }
        ));
        let bad = BallAction {
            x: -0.1,
            y: 0.5,
            r: 0.2,
        };
        assert!(
            run(
                &task,
                &bad,
                &PhysicsParams::default(),
                &RecordOptions::default()
            )
            .is_err()
        );
    }

    #[test]
    fn solved_runs_stop_at_the_180th_touching_step() {
        let set = TaskSet::default_tasks().unwrap();
        let params = PhysicsParams::default();
        // Actions that solve template 00000 in PHYRE 0.2.2 (tests/data/phyre/reference.jsonl); most of
        // them solve it here too, the first that does is checked.
        let solving = [
            (
                "00000:010",
                [0.9446689170495839, 0.5218483217500717, 0.4146619399905236],
            ),
            (
                "00000:010",
                [0.15896958364551972, 0.11037514116430513, 0.6563295894652734],
            ),
            (
                "00000:021",
                [0.8468288014900353, 0.23984775914758616, 0.49376971426872995],
            ),
            (
                "00000:021",
                [0.828845807980693, 0.5747115047081023, 0.6280761983073504],
            ),
            (
                "00000:061",
                [0.25974475274713704, 0.3868898853207624, 0.8320168996345009],
            ),
        ];
        let (task, a) = solving
            .iter()
            .map(|(id, [x, y, r])| {
                (
                    set.get(id).unwrap(),
                    BallAction {
                        x: *x,
                        y: *y,
                        r: *r,
                    },
                )
            })
            .find(|(task, a)| status(task, a, &params).unwrap() == Status::Solved)
            .expect("none of PHYRE's solving actions solves here");
        let r = run(
            &task,
            &a,
            &params,
            &RecordOptions {
                stride: 1,
                record: true,
            },
        )
        .unwrap();
        assert!(r.solved());
        let first = r.goal_first_step.unwrap();
        assert_eq!(r.steps, first + params.steps_for_solution - 1);
        assert!(
            matches!(r.events.last(), Some(EpisodeEvent::Success { step }) if *step == r.steps)
        );
        assert_eq!(r.frames.len(), r.steps + 1);
    }
}
