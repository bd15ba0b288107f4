//! The event loop (docs/envs/pool.md §P6; pooltool
//! `evolution/event_based/simulate.py`). This is the only place that orders the loop:
//!
//! 1. next event = earliest of {stick (t = 0 only), cached transition, ball–ball,
//!    ball–jaw, ball–linear-cushion, ball–pocket}; exact ties → (tier, −energy);
//! 2. evolve every ball to the event time (motion state kept, as pooltool does);
//! 3. resolve the event;
//! 4. record it (event with before/after states, every ball's history);
//! 5. update the transition cache of the event's balls and invalidate their cached
//!    collision times.
//!
//! Caps (`max_events`, `t_final`) end the run with a terminal [`Status`].

use std::sync::Arc;

use super::cache::{CollisionCache, Row, RowMin, TransitionCache};
use super::detect::{Trajectory, ball_ball, ball_cushion, ball_pocket, transition};
use super::error::{PoolError, Result};
use super::events::{Agent, Event, EventKind};
use super::evolve::{self, MotionParams};
use super::params::BallParams;
use super::resolve;
use super::shot::Shot;
use super::state::{BallState, MotionState};
use super::system::System;
use super::table::Table;
use super::vec3;

/// Options of a simulation run.
#[derive(Debug, Clone, Copy)]
pub struct SimOptions {
    /// Stop (and stop all balls) once more than this many events happened; 0 = unlimited
    /// (pooltool's `max_events` semantics).
    pub max_events: usize,
    /// Stop after the first event at or beyond this time (pooltool `t_final`).
    pub t_final: Option<f64>,
}

impl Default for SimOptions {
    /// A generous event cap (pooltool's chatter shots reach ~1,300 events).
    fn default() -> Self {
        SimOptions {
            max_events: 100_000,
            t_final: None,
        }
    }
}

/// How the run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// no further event: every ball is at rest or pocketed
    Settled,
    /// `max_events` exceeded; balls were stopped (pooltool `stop_balls`)
    MaxEvents,
    /// `t_final` reached; balls keep their (possibly moving) state
    MaxTime,
}

/// Result of [`simulate`].
#[derive(Debug, Clone)]
pub struct Simulation {
    /// The table the shot was played on
    pub table: Arc<Table>,
    /// Ball ids, in system order
    pub ball_ids: Vec<String>,
    /// Each ball's parameters
    pub ball_params: Vec<BallParams>,
    /// resolved events in order (pooltool's leading/trailing `none` markers omitted)
    pub events: Vec<Event>,
    /// `history[ball]`: state at t = 0, after every event, and a final copy at `t_end`
    /// (pooltool `ball.history`)
    pub history: Vec<Vec<BallState>>,
    /// Every ball's state at `t_end`
    pub final_states: Vec<BallState>,
    /// Why the run ended
    pub status: Status,
    /// time of the last event
    pub t_end: f64,
}

impl Simulation {
    /// pooltool-style id of an agent ("cue_stick", "cue", "12", "8t", "rt", …).
    pub fn agent_id(&self, a: Agent) -> &str {
        match a {
            Agent::Cue => "cue_stick",
            Agent::Ball(i) => &self.ball_ids[i],
            Agent::LinearCushion(i) => &self.table.linear[i].id,
            Agent::CircularCushion(i) => &self.table.circular[i].id,
            Agent::Pocket(i) => &self.table.pockets[i].id,
        }
    }

    /// pooltool's `event.ids`.
    pub fn event_ids(&self, e: &Event) -> Vec<&str> {
        e.agents().iter().map(|a| self.agent_id(*a)).collect()
    }

    /// Index of ball `id`.
    pub fn ball_index(&self, id: &str) -> Option<usize> {
        self.ball_ids.iter().position(|b| b == id)
    }
}

#[derive(Clone, Copy)]
struct Candidate {
    time: f64,
    kind: EventKind,
    agents: [Agent; 2],
    n_agents: u8,
}

impl Candidate {
    fn none() -> Candidate {
        Candidate {
            time: f64::INFINITY,
            kind: EventKind::SlidingRolling,
            agents: [Agent::Cue, Agent::Cue],
            n_agents: 0,
        }
    }
}

struct Engine<'a> {
    sys: &'a System,
    states: Vec<BallState>,
    params: Vec<BallParams>,
    cc: CollisionCache,
    tc: TransitionCache,
    traj: Vec<Trajectory>,
    traj_valid: Vec<bool>,
    t: f64,
}

impl<'a> Engine<'a> {
    fn trajectory(&mut self, i: usize) -> Trajectory {
        if !self.traj_valid[i] {
            self.traj[i] = Trajectory::of(&self.states[i], &self.params[i]);
            self.traj_valid[i] = true;
        }
        self.traj[i]
    }

    fn horizon(&self, i: usize) -> f64 {
        self.tc.time_of(i) - self.t
    }

    fn energy(&self, i: usize) -> f64 {
        self.states[i].energy(&self.params[i])
    }

    /// The earliest ball–ball, jaw, linear-cushion and pocket candidates, after recomputing the
    /// cached times that the last event made stale.
    fn refresh_and_pick(&mut self) -> [Candidate; 4] {
        let bb = self.refresh_ball_ball();
        self.refresh_rows();
        [
            bb,
            self.pick_row(Row::Circular),
            self.pick_row(Row::Linear),
            self.pick_row(Row::Pocket),
        ]
    }

    /// Recomputes the stale ball–ball times and returns the earliest pair (ties: the earlier
    /// computed, as in pooltool's dict order).
    fn refresh_ball_ball(&mut self) -> Candidate {
        let n = self.states.len();
        let mut bb = Candidate::none();
        let mut bb_seq = u64::MAX;
        for i in 0..n {
            for j in (i + 1)..n {
                let k = self.cc.bb_index(i, j);
                if CollisionCache::is_stale(self.cc.ball_ball[k]) {
                    let (si, sj) = (self.states[i], self.states[j]);
                    let dt = if !si.s.is_on_table()
                        || !sj.s.is_on_table()
                        || (si.s.is_nontranslating() && sj.s.is_nontranslating())
                    {
                        f64::INFINITY
                    } else {
                        let (ti, tj) = (self.trajectory(i), self.trajectory(j));
                        let h = self.horizon(i).min(self.horizon(j));
                        ball_ball::collision_time(
                            &si,
                            &self.params[i],
                            &ti,
                            &sj,
                            &self.params[j],
                            &tj,
                            h,
                        )
                    };
                    self.cc.ball_ball[k] = self.t + dt;
                    self.cc.ball_ball_seq[k] = self.cc.next_seq();
                }
                let t = self.cc.ball_ball[k];
                let q = self.cc.ball_ball_seq[k];
                if t < bb.time || (t == bb.time && q < bb_seq) {
                    bb_seq = q;
                    bb = Candidate {
                        time: t,
                        kind: EventKind::BallBall,
                        agents: [Agent::Ball(i), Agent::Ball(j)],
                        n_agents: 2,
                    };
                }
            }
        }
        bb
    }

    /// Recomputes the jaw, linear-cushion and pocket rows of every ball whose rows are stale, in
    /// pooltool's candidate order (circular, linear, pocket). A ball's rows are invalidated whole,
    /// so each is recomputed whole and its minimum kept.
    fn refresh_rows(&mut self) {
        let table = self.sys.table.clone();
        for i in 0..self.states.len() {
            if self.cc.row_fresh[i] {
                continue;
            }
            let st = self.states[i];
            let moving = !st.s.is_nontranslating();
            let h = self.horizon(i);
            let tr = if moving {
                self.trajectory(i)
            } else {
                Trajectory::default()
            };
            let p = self.params[i];
            let t0 = self.t;
            // A resting ball's row is all ∞ (no time is computed for it).
            let circular = table.circular.iter().map(|jaw| {
                if moving {
                    ball_cushion::circular_time(&st, &p, &tr, jaw, h)
                } else {
                    f64::INFINITY
                }
            });
            self.cc.store_row(Row::Circular, i, t0, circular);
            let linear = table.linear.iter().map(|seg| {
                if moving {
                    ball_cushion::linear_time(&st, &p, &tr, seg, h)
                } else {
                    f64::INFINITY
                }
            });
            self.cc.store_row(Row::Linear, i, t0, linear);
            let pockets = table.pockets.iter().map(|pk| {
                if moving {
                    ball_pocket::pocket_time(&st, &p, &tr, pk, h)
                } else {
                    f64::INFINITY
                }
            });
            self.cc.store_row(Row::Pocket, i, t0, pockets);
            self.cc.row_fresh[i] = true;
        }
    }

    /// The earliest entry of row `row` over all balls (ties: the lower sequence number).
    fn pick_row(&self, row: Row) -> Candidate {
        let (kind, obstacle): (EventKind, fn(usize) -> Agent) = match row {
            Row::Circular => (EventKind::BallCircularCushion, Agent::CircularCushion),
            Row::Linear => (EventKind::BallLinearCushion, Agent::LinearCushion),
            Row::Pocket => (EventKind::BallPocket, Agent::Pocket),
        };
        let mut best = Candidate::none();
        let mut m: RowMin = (f64::INFINITY, u64::MAX, 0);
        for (i, &r) in self.cc.row_min(row).iter().enumerate() {
            if r.0 < f64::INFINITY && (r.0 < m.0 || (r.0 == m.0 && r.1 < m.1)) {
                m = r;
                best = Candidate {
                    time: r.0,
                    kind,
                    agents: [Agent::Ball(i), obstacle(r.2)],
                    n_agents: 2,
                };
            }
        }
        best
    }

    /// The engine at t = 0: every ball's state with t = 0, first transitions cached, no
    /// collision time known yet.
    fn new(sys: &'a System) -> Self {
        let n = sys.balls.len();
        let table = &sys.table;
        let states: Vec<BallState> = sys
            .balls
            .iter()
            .map(|b| BallState { t: 0.0, ..b.state })
            .collect();
        let params: Vec<BallParams> = sys.balls.iter().map(|b| b.params).collect();
        let tc = TransitionCache {
            next: states
                .iter()
                .zip(params.iter())
                .map(|(s, p)| transition::next_transition(s, p))
                .collect(),
        };
        Engine {
            sys,
            states,
            params,
            cc: CollisionCache::new(
                n,
                table.linear.len(),
                table.circular.len(),
                table.pockets.len(),
            ),
            tc,
            traj: vec![Trajectory::default(); n],
            traj_valid: vec![false; n],
            t: 0.0,
        }
    }

    /// Step 1: the earliest of {stick (t = 0 only), cached transition, ball–ball, circular,
    /// linear, pocket}; exact ties go to the lower tier, then the higher energy, then the
    /// earlier candidate. `None` when nothing will happen (settled).
    fn next_event(&mut self, shot: &Shot, cue_idx: usize) -> Option<Candidate> {
        let mut cands: Vec<Candidate> = Vec::with_capacity(6);
        if self.t == 0.0 {
            let has_energy = (0..self.states.len()).any(|i| self.energy(i) != 0.0);
            let time = if !has_energy && shot.v0 > 0.0 {
                0.0
            } else {
                f64::INFINITY
            };
            cands.push(Candidate {
                time,
                kind: EventKind::StickBall,
                agents: [Agent::Cue, Agent::Ball(cue_idx)],
                n_agents: 2,
            });
        }
        match self.tc.earliest() {
            Some((i, time, kind)) => cands.push(Candidate {
                time,
                kind,
                agents: [Agent::Ball(i), Agent::Cue],
                n_agents: 1,
            }),
            None => cands.push(Candidate::none()),
        }
        cands.extend(self.refresh_and_pick());
        let min_time = cands.iter().map(|c| c.time).fold(f64::INFINITY, f64::min);
        if min_time == f64::INFINITY || min_time.is_nan() {
            return None;
        }
        let simultaneous: Vec<&Candidate> = cands.iter().filter(|c| c.time == min_time).collect();
        let mut best = simultaneous[0];
        if simultaneous.len() > 1 {
            let mut bk = self.priority(best, shot);
            for c in &simultaneous[1..] {
                let k = self.priority(c, shot);
                if k.0 < bk.0 || (k.0 == bk.0 && -k.1 < -bk.1) {
                    best = c;
                    bk = k;
                }
            }
        }
        Some(*best)
    }

    /// Step 2: evolves every ball to `time` in closed form, keeping its motion state (as
    /// pooltool does), and forgets the cached trajectories.
    fn evolve_to(&mut self, time: f64) {
        let dt = time - self.t;
        let t_evolved = self.t + dt;
        for i in 0..self.states.len() {
            let s = self.states[i];
            let (rvw, _) = evolve::evolve_rvw(
                s.s,
                &[s.r, s.v, s.w],
                &MotionParams::from(&self.params[i]),
                dt,
            );
            self.states[i] = BallState {
                r: rvw[0],
                v: rvw[1],
                w: rvw[2],
                s: s.s,
                t: t_evolved,
            };
        }
        self.traj_valid.iter_mut().for_each(|v| *v = false);
    }

    /// Step 3: applies event `ev` to its balls (`ball_agents`, in agent order). Collisions set
    /// the balls' time to the event time; transitions keep the evolved time.
    fn resolve(&mut self, ev: &Candidate, ball_agents: &[usize], shot: &Shot, cue_idx: usize) {
        let (time, agents) = (ev.time, ev.agents);
        let system = self.sys;
        let table = &system.table;
        let models = &system.models;
        match ev.kind {
            EventKind::StickBall => {
                let i = cue_idx;
                resolve::stick_ball::resolve(
                    &mut self.states[i],
                    &self.params[i],
                    &system.cue,
                    models,
                    shot,
                );
                self.states[i].t = time;
            }
            EventKind::BallBall => {
                let (i, j) = (ball_agents[0], ball_agents[1]);
                let (mut a, mut b) = (self.states[i], self.states[j]);
                resolve::ball_ball::resolve(
                    &mut a,
                    &self.params[i],
                    &mut b,
                    &self.params[j],
                    models,
                );
                a.t = time;
                b.t = time;
                self.states[i] = a;
                self.states[j] = b;
            }
            EventKind::BallLinearCushion => {
                let i = ball_agents[0];
                if let Agent::LinearCushion(c) = agents[1] {
                    resolve::ball_cushion::resolve_linear(
                        &mut self.states[i],
                        &self.params[i],
                        models,
                        &table.linear[c],
                    );
                }
                self.states[i].t = time;
            }
            EventKind::BallCircularCushion => {
                let i = ball_agents[0];
                if let Agent::CircularCushion(c) = agents[1] {
                    resolve::ball_cushion::resolve_circular(
                        &mut self.states[i],
                        &self.params[i],
                        models,
                        &table.circular[c],
                    );
                }
                self.states[i].t = time;
            }
            EventKind::BallPocket => {
                let i = ball_agents[0];
                if let Agent::Pocket(c) = agents[1] {
                    resolve::ball_pocket::resolve(&mut self.states[i], &table.pockets[c]);
                }
                self.states[i].t = time;
            }
            k => {
                let i = ball_agents[0];
                resolve::transition::resolve(&mut self.states[i], k);
            }
        }
    }

    /// Step 4: moves the clock to the event, appends every ball's state to `history`, and
    /// returns the event with its balls' states before and after (both stamped at its time).
    fn record(
        &mut self,
        ev: &Candidate,
        ball_agents: &[usize],
        before: &[BallState],
        after: &[BallState],
        history: &mut [Vec<BallState>],
    ) -> Event {
        let time = ev.time;
        self.t = time;
        for (i, s) in self.states.iter_mut().enumerate() {
            s.t = time;
            history[i].push(*s);
        }
        let balls = ball_agents
            .iter()
            .zip(before.iter().zip(after.iter()))
            .map(|(&i, (b, a))| (i, BallState { t: time, ..*b }, BallState { t: time, ..*a }))
            .collect();
        Event {
            kind: ev.kind,
            time,
            agents: ev.agents,
            n_agents: ev.n_agents,
            balls,
        }
    }

    /// The `max_events` cap: every ball on the table stops where it is (pooltool `stop_balls`).
    fn stop_balls(&mut self) {
        for s in self.states.iter_mut() {
            if s.s != MotionState::Pocketed {
                s.s = MotionState::Stationary;
            }
            s.v = [0.0; 3];
            s.w = [0.0; 3];
        }
    }

    fn priority(&self, c: &Candidate, shot: &Shot) -> (u8, f64) {
        let e = match c.kind {
            EventKind::StickBall => shot.v0 * shot.v0,
            EventKind::BallBall => {
                if let (Agent::Ball(i), Agent::Ball(j)) = (c.agents[0], c.agents[1]) {
                    vec3::norm2(vec3::sub(self.states[i].v, self.states[j].v))
                } else {
                    0.0
                }
            }
            _ => match c.agents[0] {
                Agent::Ball(i) => self.energy(i),
                _ => 0.0,
            },
        };
        (c.kind.tier(), e)
    }
}

/// Simulate `shot` on `system` until every ball rests (or a cap is hit). One loop turn is one
/// event, in the steps of the module doc: `next_event`, `evolve_to`, `resolve`, the transition
/// cache, `record`, the caps, the collision cache.
pub fn simulate(system: &System, shot: &Shot, opts: &SimOptions) -> Result<Simulation> {
    shot.validate()?;
    let cue_idx = system.validate()?;
    if let Some(tf) = opts.t_final
        && !tf.is_finite()
    {
        return Err(PoolError::InvalidShot("t_final must be finite".into()));
    }
    let mut eng = Engine::new(system);
    let mut history: Vec<Vec<BallState>> = eng.states.iter().map(|s| vec![*s]).collect();
    let mut events: Vec<Event> = Vec::new();
    let mut num_events = 0usize;
    let status;

    loop {
        // ---- 1. next event
        let Some(ev) = eng.next_event(shot, cue_idx) else {
            status = Status::Settled;
            break;
        };

        // ---- 2. evolve every ball (motion state kept, like pooltool)
        eng.evolve_to(ev.time);

        // ---- 3. resolve
        let ball_agents: Vec<usize> = ev.agents[..ev.n_agents as usize]
            .iter()
            .filter_map(|a| {
                if let Agent::Ball(i) = a {
                    Some(*i)
                } else {
                    None
                }
            })
            .collect();
        let before: Vec<BallState> = ball_agents.iter().map(|&i| eng.states[i]).collect();
        eng.resolve(&ev, &ball_agents, shot, cue_idx);
        let after: Vec<BallState> = ball_agents.iter().map(|&i| eng.states[i]).collect();

        // ---- 5a. transition cache uses the resolved ("final") states, whose t is the
        // event time for collisions and the evolved time for transitions (pooltool)
        for &i in &ball_agents {
            eng.tc.next[i] = transition::next_transition(&eng.states[i], &eng.params[i]);
        }

        // ---- 4. record
        events.push(eng.record(&ev, &ball_agents, &before, &after, &mut history));

        if let Some(tf) = opts.t_final
            && eng.t >= tf
        {
            status = Status::MaxTime;
            break;
        }
        if opts.max_events > 0 && num_events > opts.max_events {
            eng.stop_balls();
            status = Status::MaxEvents;
            break;
        }
        num_events += 1;

        // ---- 5b. invalidate cached collision times of the event's balls
        for &i in &ball_agents {
            eng.cc.invalidate_ball(i);
        }
    }

    let t_end = eng.t;
    for (i, s) in eng.states.iter().enumerate() {
        history[i].push(BallState { t: t_end, ..*s });
    }
    Ok(Simulation {
        table: system.table.clone(),
        ball_ids: system.balls.iter().map(|b| b.id.clone()).collect(),
        ball_params: eng.params,
        events,
        history,
        final_states: eng.states,
        status,
        t_end,
    })
}

/// Exact state of ball `ball` at time `t` (evolved in closed form from the latest
/// recorded state at or before `t`; clamped to [0, t_end]).
pub fn state_at(sim: &Simulation, ball: usize, t: f64) -> Option<BallState> {
    let h = sim.history.get(ball)?;
    if !t.is_finite() {
        return None;
    }
    let t = t.clamp(0.0, sim.t_end);
    // last entry with time <= t
    let k = h.partition_point(|s| s.t <= t);
    let base = if k == 0 { h[0] } else { h[k - 1] };
    let mut out = evolve::evolve_state(&base, &sim.ball_params[ball], t - base.t);
    out.t = t;
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::super::params::CueSpecs;
    use super::super::state::Ball;
    use super::*;

    fn one_ball(x: f64, y: f64) -> System {
        let p = BallParams::pool_default();
        let balls = vec![Ball {
            id: "cue".into(),
            params: p,
            state: BallState::at_rest(x, y, p.r),
        }];
        System::new(
            Arc::new(Table::default_7ft()),
            balls,
            CueSpecs::pool_default(),
        )
    }

    /// Natural-roll strike (b = 0.4, θ = 0) straight up the table: no sliding phase, the
    /// ball rolls v²/(2 μ_r g) and stops (rolling_stationary). Events: stick_ball,
    /// sliding_rolling at t = 0 (zero slip), rolling_stationary at v/(μ_r g). Tol 1e-9 m.
    #[test]
    fn natural_roll_shot_stops_at_closed_form_distance() {
        let sys = one_ball(0.5, 0.3);
        let shot = Shot {
            v0: 0.3,
            phi: 90.0,
            theta: 0.0,
            a: 0.0,
            b: 0.4,
        };
        let sim = simulate(&sys, &shot, &SimOptions::default()).unwrap();
        let kinds: Vec<&str> = sim.events.iter().map(|e| e.kind.name()).collect();
        assert_eq!(
            kinds,
            vec!["stick_ball", "sliding_rolling", "rolling_stationary"]
        );
        assert!(sim.events[1].time < 1e-12, "no sliding phase");
        let v = vec3::norm(sim.events[0].balls[0].2.v);
        let p = BallParams::pool_default();
        let d = v * v / (2.0 * p.u_r * p.g);
        assert!((sim.final_states[0].r[1] - 0.3 - d).abs() < 1e-9);
        assert!((sim.t_end - v / (p.u_r * p.g)).abs() < 1e-9);
        assert_eq!(sim.status, Status::Settled);
        assert_eq!(sim.event_ids(&sim.events[0]), vec!["cue_stick", "cue"]);
        // state_at agrees with the closed form half-way
        let s = state_at(&sim, 0, sim.t_end / 2.0).unwrap();
        assert_eq!(s.s, MotionState::Rolling);
        assert!((vec3::norm(s.v) - v / 2.0).abs() < 1e-9);
    }

    /// Pocket: aim the ball at the "lb" corner pocket; the last collision-type event is
    /// ball_pocket with ids (cue, lb), the ball ends pocketed at the pocket spot.
    #[test]
    fn ball_is_pocketed() {
        let sys = one_ball(0.3, 0.3);
        let pk = sys
            .table
            .pockets
            .iter()
            .find(|p| p.id == "lb")
            .unwrap()
            .clone();
        let phi = (pk.center[1] - 0.3).atan2(pk.center[0] - 0.3).to_degrees();
        let shot = Shot {
            v0: 2.0,
            phi,
            theta: 0.0,
            a: 0.0,
            b: 0.0,
        };
        let sim = simulate(&sys, &shot, &SimOptions::default()).unwrap();
        let last = sim.events.last().unwrap();
        assert_eq!(last.kind, EventKind::BallPocket);
        assert_eq!(sim.event_ids(last), vec!["cue", "lb"]);
        assert_eq!(sim.final_states[0].s, MotionState::Pocketed);
        // the centre was on the pocket circle when the event fired
        let before = last.balls[0].1;
        let d =
            ((before.r[0] - pk.center[0]).powi(2) + (before.r[1] - pk.center[1]).powi(2)).sqrt();
        assert!((d - pk.radius).abs() < 1e-9);
    }

    /// Head-on stun shot into an object ball: one ball_ball event, then the object ball
    /// carries (1+e)/2 of the cue ball's normal speed (§P8 (b)).
    #[test]
    fn head_on_collision_in_the_loop() {
        let p = BallParams::pool_default();
        let mut sys = one_ball(0.5, 0.3);
        sys.balls.push(Ball {
            id: "1".into(),
            params: p,
            state: BallState::at_rest(0.5, 0.6, p.r),
        });
        let shot = Shot {
            v0: 1.0,
            phi: 90.0,
            theta: 0.0,
            a: 0.0,
            b: 0.0,
        };
        let sim = simulate(&sys, &shot, &SimOptions::default()).unwrap();
        let bb: Vec<&Event> = sim
            .events
            .iter()
            .filter(|e| e.kind == EventKind::BallBall)
            .collect();
        assert!(!bb.is_empty());
        let e = bb[0];
        assert_eq!(sim.event_ids(e), vec!["cue", "1"]);
        let (cue_before, obj_after) = (e.balls[0].1, e.balls[1].2);
        assert!(
            (obj_after.v[1] - (1.0 + p.e_b) / 2.0 * cue_before.v[1]).abs() < 1e-3 * cue_before.v[1]
        );
        let gap = vec3::norm(vec3::sub(e.balls[1].2.r, e.balls[0].2.r));
        assert!(
            (gap - 2.0 * p.r - 1e-6).abs() < 1e-9,
            "MIN_DIST kiss gap {gap}"
        );
    }

    /// A cushion hit: straight at the +x rail; one ball_linear_cushion with id "15".
    #[test]
    fn rail_hit_ids() {
        let sys = one_ball(0.5, 0.5);
        let shot = Shot {
            v0: 1.0,
            phi: 0.0,
            theta: 0.0,
            a: 0.0,
            b: 0.2,
        };
        let sim = simulate(&sys, &shot, &SimOptions::default()).unwrap();
        let c: Vec<&Event> = sim
            .events
            .iter()
            .filter(|e| e.kind == EventKind::BallLinearCushion)
            .collect();
        assert_eq!(sim.event_ids(c[0]), vec!["cue", "15"]);
        assert!(c[0].balls[0].2.v[0] < 0.0);
    }

    /// Caps and bad input: max_events gives a terminal status, invalid shots and systems
    /// are errors, V0 = 0 yields no events.
    #[test]
    fn caps_and_errors() {
        let sys = one_ball(0.5, 0.5);
        let shot = Shot {
            v0: 3.0,
            phi: 10.0,
            theta: 0.0,
            a: 0.1,
            b: 0.1,
        };
        let sim = simulate(
            &sys,
            &shot,
            &SimOptions {
                max_events: 2,
                t_final: None,
            },
        )
        .unwrap();
        assert_eq!(sim.status, Status::MaxEvents);
        assert!(sim.final_states.iter().all(|s| s.v == [0.0; 3]));
        let sim = simulate(
            &sys,
            &shot,
            &SimOptions {
                max_events: 0,
                t_final: Some(0.5),
            },
        )
        .unwrap();
        assert_eq!(sim.status, Status::MaxTime);
        assert!(sim.t_end >= 0.5);
        assert!(simulate(&sys, &Shot { v0: -1.0, ..shot }, &SimOptions::default()).is_err());
        assert!(
            simulate(
                &sys,
                &Shot {
                    a: 0.9,
                    b: 0.9,
                    ..shot
                },
                &SimOptions::default()
            )
            .is_err()
        );
        let mut bad = sys.clone();
        bad.cue_ball_id = "nope".into();
        assert!(simulate(&bad, &shot, &SimOptions::default()).is_err());
        let mut bad = sys.clone();
        bad.balls[0].state.r[0] = f64::NAN;
        assert!(simulate(&bad, &shot, &SimOptions::default()).is_err());
        let sim = simulate(&sys, &Shot { v0: 0.0, ..shot }, &SimOptions::default()).unwrap();
        assert!(sim.events.is_empty());
        assert_eq!(sim.status, Status::Settled);
        assert!(state_at(&sim, 5, 0.0).is_none());
    }
}
