//! The event loop (reference/pooltool-physics.md §2.6; pooltool
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

use super::cache::{CollisionCache, TransitionCache};
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

    fn refresh_and_pick(&mut self) -> [Candidate; 4] {
        let n = self.states.len();
        let table = self.sys.table.clone();
        // ball–ball
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
        // circular, linear, pocket (pooltool's candidate order). A ball's rows are
        // invalidated whole, so each is recomputed whole and its minimum kept.
        let (nl, nc, np) = (
            table.linear.len(),
            table.circular.len(),
            table.pockets.len(),
        );
        #[inline]
        fn better(t: f64, q: u64, best: (f64, u64, usize)) -> bool {
            t < best.0 || (t == best.0 && q < best.1)
        }
        for i in 0..n {
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
            let mut m = (f64::INFINITY, u64::MAX, 0usize);
            for (c, jaw) in table.circular.iter().enumerate() {
                let dt = if moving {
                    ball_cushion::circular_time(&st, &p, &tr, jaw, h)
                } else {
                    f64::INFINITY
                };
                let (t, q) = (self.t + dt, self.cc.next_seq());
                self.cc.circular[i * nc + c] = t;
                self.cc.circular_seq[i * nc + c] = q;
                if better(t, q, m) {
                    m = (t, q, c);
                }
            }
            self.cc.row_min_circular[i] = m;
            let mut m = (f64::INFINITY, u64::MAX, 0usize);
            for (c, seg) in table.linear.iter().enumerate() {
                let dt = if moving {
                    ball_cushion::linear_time(&st, &p, &tr, seg, h)
                } else {
                    f64::INFINITY
                };
                let (t, q) = (self.t + dt, self.cc.next_seq());
                self.cc.linear[i * nl + c] = t;
                self.cc.linear_seq[i * nl + c] = q;
                if better(t, q, m) {
                    m = (t, q, c);
                }
            }
            self.cc.row_min_linear[i] = m;
            let mut m = (f64::INFINITY, u64::MAX, 0usize);
            for (c, pk) in table.pockets.iter().enumerate() {
                let dt = if moving {
                    ball_pocket::pocket_time(&st, &p, &tr, pk, h)
                } else {
                    f64::INFINITY
                };
                let (t, q) = (self.t + dt, self.cc.next_seq());
                self.cc.pocket[i * np + c] = t;
                self.cc.pocket_seq[i * np + c] = q;
                if better(t, q, m) {
                    m = (t, q, c);
                }
            }
            self.cc.row_min_pocket[i] = m;
            self.cc.row_fresh[i] = true;
        }
        let mut circ = Candidate::none();
        let mut lin = Candidate::none();
        let mut pock = Candidate::none();
        let (mut cm, mut lm, mut pm) = (
            (f64::INFINITY, u64::MAX, 0usize),
            (f64::INFINITY, u64::MAX, 0usize),
            (f64::INFINITY, u64::MAX, 0usize),
        );
        for i in 0..n {
            let r = self.cc.row_min_circular[i];
            if r.0 < f64::INFINITY && better(r.0, r.1, cm) {
                cm = r;
                circ = Candidate {
                    time: r.0,
                    kind: EventKind::BallCircularCushion,
                    agents: [Agent::Ball(i), Agent::CircularCushion(r.2)],
                    n_agents: 2,
                };
            }
            let r = self.cc.row_min_linear[i];
            if r.0 < f64::INFINITY && better(r.0, r.1, lm) {
                lm = r;
                lin = Candidate {
                    time: r.0,
                    kind: EventKind::BallLinearCushion,
                    agents: [Agent::Ball(i), Agent::LinearCushion(r.2)],
                    n_agents: 2,
                };
            }
            let r = self.cc.row_min_pocket[i];
            if r.0 < f64::INFINITY && better(r.0, r.1, pm) {
                pm = r;
                pock = Candidate {
                    time: r.0,
                    kind: EventKind::BallPocket,
                    agents: [Agent::Ball(i), Agent::Pocket(r.2)],
                    n_agents: 2,
                };
            }
        }
        [bb, circ, lin, pock]
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

/// Simulate `shot` on `system` until every ball rests (or a cap is hit).
pub fn simulate(system: &System, shot: &Shot, opts: &SimOptions) -> Result<Simulation> {
    shot.validate()?;
    let cue_idx = system.validate()?;
    if let Some(tf) = opts.t_final
        && !tf.is_finite()
    {
        return Err(PoolError::InvalidShot("t_final must be finite".into()));
    }
    let n = system.balls.len();
    let table = system.table.clone();
    let mut states: Vec<BallState> = system
        .balls
        .iter()
        .map(|b| BallState { t: 0.0, ..b.state })
        .collect();
    for s in states.iter_mut() {
        s.t = 0.0;
    }
    let params: Vec<BallParams> = system.balls.iter().map(|b| b.params).collect();
    let tc = TransitionCache {
        next: states
            .iter()
            .zip(params.iter())
            .map(|(s, p)| transition::next_transition(s, p))
            .collect(),
    };
    let mut eng = Engine {
        sys: system,
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
    };
    let mut history: Vec<Vec<BallState>> = eng.states.iter().map(|s| vec![*s]).collect();
    let mut events: Vec<Event> = Vec::new();
    let mut num_events = 0usize;
    let status;

    loop {
        // ---- 1. next event
        let mut cands: Vec<Candidate> = Vec::with_capacity(6);
        if eng.t == 0.0 {
            let has_energy = (0..n).any(|i| eng.energy(i) != 0.0);
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
        match eng.tc.earliest() {
            Some((i, time, kind)) => cands.push(Candidate {
                time,
                kind,
                agents: [Agent::Ball(i), Agent::Cue],
                n_agents: 1,
            }),
            None => cands.push(Candidate::none()),
        }
        let [bb, circ, lin, pock] = eng.refresh_and_pick();
        cands.push(bb);
        cands.push(circ);
        cands.push(lin);
        cands.push(pock);
        let min_time = cands.iter().map(|c| c.time).fold(f64::INFINITY, f64::min);
        if min_time == f64::INFINITY || min_time.is_nan() {
            status = Status::Settled;
            break;
        }
        let simultaneous: Vec<&Candidate> = cands.iter().filter(|c| c.time == min_time).collect();
        let ev = if simultaneous.len() == 1 {
            simultaneous[0]
        } else {
            let mut best = simultaneous[0];
            let mut bk = eng.priority(best, shot);
            for c in &simultaneous[1..] {
                let k = eng.priority(c, shot);
                if k.0 < bk.0 || (k.0 == bk.0 && -k.1 < -bk.1) {
                    best = c;
                    bk = k;
                }
            }
            best
        };
        let (kind, time, agents, n_agents) = (ev.kind, ev.time, ev.agents, ev.n_agents);

        // ---- 2. evolve every ball (motion state kept, like pooltool)
        let dt = time - eng.t;
        let t_evolved = eng.t + dt;
        for i in 0..n {
            let s = eng.states[i];
            let (rvw, _) = evolve::evolve_rvw(
                s.s,
                &[s.r, s.v, s.w],
                &MotionParams::from(&eng.params[i]),
                dt,
            );
            eng.states[i] = BallState {
                r: rvw[0],
                v: rvw[1],
                w: rvw[2],
                s: s.s,
                t: t_evolved,
            };
        }
        eng.traj_valid.iter_mut().for_each(|v| *v = false);

        // ---- 3. resolve
        let ball_agents: Vec<usize> = agents[..n_agents as usize]
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
        let models = &system.models;
        match kind {
            EventKind::StickBall => {
                let i = cue_idx;
                resolve::stick_ball::resolve(
                    &mut eng.states[i],
                    &eng.params[i],
                    &system.cue,
                    models,
                    shot,
                );
                eng.states[i].t = time;
            }
            EventKind::BallBall => {
                let (i, j) = (ball_agents[0], ball_agents[1]);
                let (mut a, mut b) = (eng.states[i], eng.states[j]);
                resolve::ball_ball::resolve(&mut a, &eng.params[i], &mut b, &eng.params[j], models);
                a.t = time;
                b.t = time;
                eng.states[i] = a;
                eng.states[j] = b;
            }
            EventKind::BallLinearCushion => {
                let i = ball_agents[0];
                if let Agent::LinearCushion(c) = agents[1] {
                    resolve::ball_cushion::resolve_linear(
                        &mut eng.states[i],
                        &eng.params[i],
                        models,
                        &table.linear[c],
                    );
                }
                eng.states[i].t = time;
            }
            EventKind::BallCircularCushion => {
                let i = ball_agents[0];
                if let Agent::CircularCushion(c) = agents[1] {
                    resolve::ball_cushion::resolve_circular(
                        &mut eng.states[i],
                        &eng.params[i],
                        models,
                        &table.circular[c],
                    );
                }
                eng.states[i].t = time;
            }
            EventKind::BallPocket => {
                let i = ball_agents[0];
                if let Agent::Pocket(c) = agents[1] {
                    resolve::ball_pocket::resolve(&mut eng.states[i], &table.pockets[c]);
                }
                eng.states[i].t = time;
            }
            k => {
                let i = ball_agents[0];
                resolve::transition::resolve(&mut eng.states[i], k);
            }
        }
        let after: Vec<BallState> = ball_agents.iter().map(|&i| eng.states[i]).collect();

        // ---- 5a. transition cache uses the resolved ("final") states, whose t is the
        // event time for collisions and the evolved time for transitions (pooltool)
        for &i in &ball_agents {
            eng.tc.next[i] = transition::next_transition(&eng.states[i], &eng.params[i]);
        }

        // ---- 4. record
        eng.t = time;
        for (i, s) in eng.states.iter_mut().enumerate() {
            s.t = time;
            history[i].push(*s);
        }
        let balls = ball_agents
            .iter()
            .zip(before.iter().zip(after.iter()))
            .map(|(&i, (b, a))| (i, BallState { t: time, ..*b }, BallState { t: time, ..*a }))
            .collect();
        events.push(Event {
            kind,
            time,
            agents,
            n_agents,
            balls,
        });

        if let Some(tf) = opts.t_final
            && eng.t >= tf
        {
            status = Status::MaxTime;
            break;
        }
        if opts.max_events > 0 && num_events > opts.max_events {
            for s in eng.states.iter_mut() {
                if s.s != MotionState::Pocketed {
                    s.s = MotionState::Stationary;
                }
                s.v = [0.0; 3];
                s.w = [0.0; 3];
            }
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
        table,
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
    /// carries (1+e)/2 of the cue ball's normal speed (§2.8 (b)).
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
