//! [`Episode`]: the one loop that moves an I-PHYRE game forward, in I-PHYRE `simulate()`'s order
//! (docs/envs/iphyre.md §R3): apply the due click → step the physics → advance the time counter → record the
//! frame and events → check success.
//!
//! Quirks kept on purpose, as in iphyre 0.2.3: a click at exactly t = 0 is dropped; at most one click is
//! applied per step, so clicks with equal times land on consecutive steps; the time compared against
//! click times is a float counter that adds `dt` each step, so a click at 1.6 s fires before step 97
//! (1.6167 s) at 60 fps. The loop runs while the counter is below `max_time` (15 s, about 900 steps at
//! 60 fps) and stops at the first step after which every ball is out.

use super::action::{Click, ClickSchedule, Due, hits_block, validate_clicks};
use super::error::Result;
use super::game::Game;
use super::params::{Engine, PhysicsParams};
use super::success::{all_balls_out, ball_out, reward};
use super::world::{ObjectState, World};

/// The state of every present object after `step` physics steps.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Number of physics steps done (0 = the initial state).
    pub step: usize,
    /// The time counter (s).
    pub t: f64,
    /// The present objects, in object order; removed objects are absent.
    pub objects: Vec<ObjectState>,
}

/// Something that happened during an episode.
#[derive(Debug, Clone, PartialEq)]
pub enum EpisodeEvent {
    /// A click in the action list, at its scheduled time (before anything runs).
    ScheduledAction(Click),
    /// A click at exactly t = 0, dropped without effect (I-PHYRE quirk).
    ActionIgnoredT0(Click),
    /// A click applied before step `step + 1`; `block` is the removed block, `None` when it hit nothing.
    ActionApplied {
        /// Steps done when the click was applied.
        step: usize,
        /// The time counter then (s).
        t: f64,
        /// The click.
        click: Click,
        /// The removed block, if the click hit an eliminable block's core.
        block: Option<usize>,
    },
    /// Two objects started touching during step `step`.
    ContactBegin {
        /// The step (1-based: the state after it).
        step: usize,
        /// The time counter after the step (s).
        t: f64,
        /// The two object indices, smaller first.
        objects: [usize; 2],
    },
    /// Two objects stopped touching during step `step` (also when one of them was removed).
    ContactEnd {
        /// The step.
        step: usize,
        /// The time counter after the step (s).
        t: f64,
        /// The two object indices, smaller first.
        objects: [usize; 2],
    },
    /// A ball's centre went below the bottom edge for the first time.
    BallExit {
        /// The step.
        step: usize,
        /// The time counter after the step (s).
        t: f64,
        /// The ball's object index.
        object: usize,
    },
    /// Every ball is out: the game is solved.
    Success {
        /// The step.
        step: usize,
        /// The time counter after the step (s).
        t: f64,
    },
}

/// What an episode produced.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeResult {
    /// The game's name.
    pub game: String,
    /// The clicks as given.
    pub clicks: Vec<Click>,
    /// Frames 0..=steps when recorded, else empty.
    pub frames: Vec<Frame>,
    /// Events in the order they happened (the scheduled actions first).
    pub events: Vec<EpisodeEvent>,
    /// Whether every ball fell out within the episode.
    pub success: bool,
    /// Physics steps done.
    pub steps: usize,
    /// The time counter at the end (s).
    pub time: f64,
    /// Clicks that removed a block.
    pub eliminations: usize,
    /// The episode reward ([`reward`]).
    pub reward: f64,
    /// The frame rate used.
    pub fps: f64,
    /// The engine that ran it.
    pub engine: Engine,
}

/// One game being played: the world, the click schedule and the record so far.
#[derive(Debug)]
pub struct Episode {
    world: World,
    params: PhysicsParams,
    schedule: ClickSchedule,
    time_count: f64,
    steps: usize,
    eliminations: usize,
    success: bool,
    exited: Vec<bool>,
    record_frames: bool,
    result: EpisodeResult,
}

impl Episode {
    /// Starts `game` with `clicks` (validated against `params.max_time`); `record_frames` keeps every
    /// step's object states.
    pub fn new(
        game: &Game,
        clicks: &[Click],
        params: &PhysicsParams,
        record_frames: bool,
    ) -> Result<Episode> {
        validate_clicks(clicks, params.max_time)?;
        let world = World::new(game, params)?;
        let schedule = ClickSchedule::new(clicks);
        let events = schedule
            .clicks()
            .iter()
            .map(|c| EpisodeEvent::ScheduledAction(*c))
            .collect();
        let mut episode = Episode {
            exited: vec![false; game.objects.len()],
            world,
            params: params.clone(),
            schedule,
            time_count: 0.0,
            steps: 0,
            eliminations: 0,
            success: false,
            record_frames,
            result: EpisodeResult {
                game: game.name.clone(),
                clicks: clicks.to_vec(),
                // The loop runs at most ceil(max_time · fps) + 1 steps (float counter); one frame each.
                frames: Vec::with_capacity(if record_frames {
                    (params.max_time * params.fps).ceil() as usize + 2
                } else {
                    0
                }),
                events,
                success: false,
                steps: 0,
                time: 0.0,
                eliminations: 0,
                reward: 0.0,
                fps: params.fps,
                engine: params.engine,
            },
        };
        episode.record_frame();
        Ok(episode)
    }

    /// Whether the episode is over (solved, or the time counter reached `max_time`).
    pub fn done(&self) -> bool {
        self.success || self.time_count >= self.params.max_time
    }

    /// The world as it is now.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// One iteration of I-PHYRE's loop; does nothing once [`done`](Self::done).
    pub fn step(&mut self) {
        if self.done() {
            return;
        }
        match self.schedule.due(self.time_count) {
            Due::Nothing => {}
            Due::DroppedAtZero(click) => self
                .result
                .events
                .push(EpisodeEvent::ActionIgnoredT0(click)),
            Due::Apply(click) => {
                let block = self.eliminate(click);
                self.result.events.push(EpisodeEvent::ActionApplied {
                    step: self.steps,
                    t: self.time_count,
                    click,
                    block,
                });
            }
        }
        let changes = self.world.step();
        self.steps += 1;
        self.time_count += self.params.dt();
        let (step, t) = (self.steps, self.time_count);
        for c in changes {
            self.result.events.push(if c.began {
                EpisodeEvent::ContactBegin {
                    step,
                    t,
                    objects: c.objects,
                }
            } else {
                EpisodeEvent::ContactEnd {
                    step,
                    t,
                    objects: c.objects,
                }
            });
        }
        self.record_frame();
        for o in self
            .world
            .objects()
            .iter()
            .filter(|o| o.kind == super::game::ObjectKind::Ball)
        {
            if self.exited[o.index] {
                continue;
            }
            if let Some(c) = self.world.centre(o.index)
                && ball_out(c[1])
            {
                self.exited[o.index] = true;
                self.result.events.push(EpisodeEvent::BallExit {
                    step,
                    t,
                    object: o.index,
                });
            }
        }
        if all_balls_out(&self.world) {
            self.success = true;
            self.result.events.push(EpisodeEvent::Success { step, t });
        }
    }

    /// Runs to the end and returns the record.
    pub fn run(mut self) -> EpisodeResult {
        while !self.done() {
            self.step();
        }
        self.finish()
    }

    /// The record so far, with the outcome fields filled in.
    pub fn finish(mut self) -> EpisodeResult {
        let r = &mut self.result;
        r.success = self.success;
        r.steps = self.steps;
        r.time = self.time_count;
        r.eliminations = self.eliminations;
        r.reward = reward(self.steps, self.params.fps, self.eliminations, self.success);
        self.result
    }

    /// Removes the first present eliminable block (in object order) whose core contains the click.
    fn eliminate(&mut self, click: Click) -> Option<usize> {
        let hit = self
            .world
            .objects()
            .iter()
            .filter(|o| o.eliminable)
            .find_map(|o| {
                let state = self.world.state(o.index)?;
                hits_block(
                    o,
                    state.centre,
                    self.params.block_radius,
                    [click.x, click.y],
                )
                .then_some(o.index)
            })?;
        self.world.remove(hit);
        self.eliminations += 1;
        Some(hit)
    }

    fn record_frame(&mut self) {
        if !self.record_frames {
            return;
        }
        let objects = self
            .world
            .present()
            .filter_map(|i| self.world.state(i))
            .collect();
        self.result.frames.push(Frame {
            step: self.steps,
            t: self.time_count,
            objects,
        });
    }
}

/// Plays `game` with `clicks` to the end (every frame recorded).
pub fn play(game: &Game, clicks: &[Click], params: &PhysicsParams) -> Result<EpisodeResult> {
    Ok(Episode::new(game, clicks, params, true)?.run())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::iphyre::action::click_block;
    use crate::envs::iphyre::game::Games;

    fn support() -> Game {
        Games::default_games()
            .unwrap()
            .get("support")
            .unwrap()
            .clone()
    }

    #[test]
    fn removing_both_supports_lets_the_ball_fall_out() {
        let g = support();
        let clicks = [
            click_block(&g, 0, 1.0).unwrap(),
            click_block(&g, 1, 1.0).unwrap(),
        ];
        let r = play(&g, &clicks, &PhysicsParams::default()).unwrap();
        assert!(r.success, "{:?}", r.events);
        assert_eq!(r.eliminations, 2);
        // The ball falls from y = 340 to 600 (260 px at g = 100: about 2.3 s) after the clicks at 1 s.
        assert!((3.0..4.0).contains(&r.time), "solved at {} s", r.time);
        assert_eq!(r.frames.len(), r.steps + 1);
        let applied: Vec<_> = r
            .events
            .iter()
            .filter_map(|e| match e {
                EpisodeEvent::ActionApplied { step, block, .. } => Some((*step, *block)),
                _ => None,
            })
            .collect();
        // Equal times: one click per step, on consecutive steps; 1.0 s is reached after 60 steps.
        assert_eq!(applied, vec![(60, Some(0)), (61, Some(1))]);
        assert!(matches!(
            r.events.last(),
            Some(EpisodeEvent::Success { .. })
        ));
        assert!(
            r.events
                .iter()
                .any(|e| matches!(e, EpisodeEvent::BallExit { object: 2, .. }))
        );
        assert!((r.reward - (1000.0 - r.steps as f64 / 60.0 - 20.0)).abs() < 1e-9);
        // Removed blocks disappear from the frames after their removal.
        assert_eq!(r.frames.last().unwrap().objects.len(), 1);
    }

    #[test]
    fn without_clicks_the_ball_stays_and_the_episode_times_out() {
        let g = support();
        let r = play(&g, &[], &PhysicsParams::with_fps(10.0)).unwrap();
        assert!(!r.success);
        assert!((150..=151).contains(&r.steps), "{} steps", r.steps);
        assert!((r.reward + r.steps as f64 / 10.0).abs() < 1e-9);
    }

    #[test]
    fn clicks_at_t0_are_dropped_and_clicks_off_blocks_do_nothing() {
        let g = support();
        let at_zero = click_block(&g, 0, 0.0).unwrap();
        let nowhere = Click {
            x: 5.0,
            y: 5.0,
            t: 0.5,
        };
        let r = play(&g, &[at_zero, nowhere], &PhysicsParams::with_fps(10.0)).unwrap();
        assert_eq!(r.eliminations, 0);
        assert!(!r.success);
        assert!(r.events.contains(&EpisodeEvent::ActionIgnoredT0(at_zero)));
        assert!(
            r.events
                .iter()
                .any(|e| matches!(e, EpisodeEvent::ActionApplied { block: None, .. }))
        );
        assert_eq!(r.frames.last().unwrap().objects.len(), 3);
    }

    #[test]
    fn float_time_counter_fires_late() {
        // 1.6 s at 60 fps: the accumulated counter first reaches 1.6 after 97 steps (docs/envs/iphyre.md §R3).
        let g = support();
        let click = Click {
            t: 1.6,
            ..click_block(&g, 0, 1.0).unwrap()
        };
        let mut e = Episode::new(&g, &[click], &PhysicsParams::default(), false).unwrap();
        for _ in 0..100 {
            e.step();
        }
        let r = e.finish();
        let step = r.events.iter().find_map(|e| match e {
            EpisodeEvent::ActionApplied { step, .. } => Some(*step),
            _ => None,
        });
        assert_eq!(step, Some(97));
    }

    #[test]
    fn every_game_plays_to_the_end_with_finite_states() {
        // Robustness, not fidelity: each game, every eliminable block clicked (0.5 s apart from 0.5 s),
        // at the gym wrappers' 10 fps. Every frame must stay finite and the record must be consistent.
        let games = Games::default_games().unwrap();
        let params = PhysicsParams::with_fps(10.0);
        for g in games.all() {
            let clicks: Vec<Click> = (0..g.eliminable().count())
                .map(|k| click_block(g, k, 0.5 * (k + 1) as f64).unwrap())
                .collect();
            let r = play(g, &clicks, &params).unwrap();
            assert_eq!(r.frames.len(), r.steps + 1, "{}", g.name);
            assert!(r.steps <= 151, "{}: {} steps", g.name, r.steps);
            assert!(r.eliminations <= clicks.len(), "{}", g.name);
            for f in &r.frames {
                for o in &f.objects {
                    let values = [
                        o.p1[0],
                        o.p1[1],
                        o.p2[0],
                        o.p2[1],
                        o.angle,
                        o.velocity[0],
                        o.velocity[1],
                    ];
                    assert!(
                        values.iter().all(|v| v.is_finite()),
                        "{} step {}: {o:?}",
                        g.name,
                        f.step
                    );
                }
            }
            assert_eq!(
                r.success,
                matches!(r.events.last(), Some(EpisodeEvent::Success { .. })),
                "{}",
                g.name
            );
        }
    }

    #[test]
    fn bad_clicks_are_errors_not_panics() {
        let g = support();
        let err = play(
            &g,
            &[Click {
                x: 1.0,
                y: 1.0,
                t: 16.0,
            }],
            &PhysicsParams::default(),
        )
        .unwrap_err();
        assert!(err.to_string().contains("after the episode"), "{err}");
    }
}
