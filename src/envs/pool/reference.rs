//! Reading pooltool reference traces (`pooltool-trace/1`, docs/envs/pool.md
//! §P10, written by `tools/pooltool/gen_traces.py`) and comparing a simulation with them:
//! the ordered list of ball–ball / cushion / pocket events and the final positions.

use std::sync::Arc;

use serde_json::Value;

use super::error::{PoolError, Result};
use super::events::EventKind;
use super::params::{BallParams, CueSpecs};
use super::shot::Shot;
use super::simulate::Simulation;
use super::state::{Ball, BallState, MotionState};
use super::system::System;
use super::table::Table;

/// One reference event: kind, time, ids, and (ball id, after-state position) pairs.
#[derive(Debug, Clone)]
pub struct RefEvent {
    /// Event kind
    pub kind: EventKind,
    /// Time (s)
    pub time: f64,
    /// pooltool ids of the agents
    pub ids: Vec<String>,
}

/// A parsed reference trace.
#[derive(Debug, Clone)]
pub struct RefTrace {
    /// The system before the shot (positions from `initial`)
    pub system: System,
    /// The shot (`meta.cue`)
    pub shot: Shot,
    /// The events, `none` markers dropped
    pub events: Vec<RefEvent>,
    /// final state of every ball (last history entry), in `system.balls` order
    pub final_states: Vec<BallState>,
    /// Time of the last event (s)
    pub t_final: f64,
}

fn f(v: &Value) -> Result<f64> {
    v.as_f64()
        .ok_or_else(|| PoolError::Data(format!("expected number, got {v}")))
}

fn v3(v: &Value) -> Result<[f64; 3]> {
    let a = v
        .as_array()
        .ok_or_else(|| PoolError::Data("expected [x,y,z]".into()))?;
    if a.len() != 3 {
        return Err(PoolError::Data("expected 3 components".into()));
    }
    Ok([f(&a[0])?, f(&a[1])?, f(&a[2])?])
}

fn state(v: &Value) -> Result<BallState> {
    let s = v["s"]
        .as_i64()
        .and_then(MotionState::from_int)
        .ok_or_else(|| PoolError::Data("bad motion state".into()))?;
    Ok(BallState {
        r: v3(&v["pos"])?,
        v: v3(&v["vel"])?,
        w: v3(&v["avel"])?,
        s,
        t: v["t"].as_f64().unwrap_or(0.0),
    })
}

impl RefTrace {
    /// Parses a `pooltool-trace/1` document.
    pub fn from_json_str(s: &str) -> Result<RefTrace> {
        let v: Value = serde_json::from_str(s)?;
        Self::from_value(&v)
    }

    /// Reads an already-parsed `pooltool-trace/1` document.
    pub fn from_value(v: &Value) -> Result<RefTrace> {
        if v["format"] != "pooltool-trace/1" {
            return Err(PoolError::Data("not a pooltool-trace/1 document".into()));
        }
        let table = Arc::new(Table::from_json_value(&v["table"])?);
        let params: BallParams = serde_json::from_value(v["meta"]["ball_params"].clone())?;
        let cue = &v["meta"]["cue"];
        let specs = CueSpecs {
            mass: f(&cue["specs"]["M"])?,
            length: 0.0,
            tip_radius: cue["specs"]["tip_radius"].as_f64().unwrap_or(0.0),
            end_mass: f(&cue["specs"]["end_mass"])?,
        };
        let shot = Shot {
            v0: f(&cue["V0"])?,
            phi: f(&cue["phi"])?,
            theta: f(&cue["theta"])?,
            a: f(&cue["a"])?,
            b: f(&cue["b"])?,
        };
        let ids: Vec<String> = v["ball_ids"]
            .as_array()
            .ok_or_else(|| PoolError::Data("ball_ids".into()))?
            .iter()
            .map(|x| x.as_str().unwrap_or_default().to_string())
            .collect();
        let mut balls = Vec::new();
        let mut final_states = Vec::new();
        for id in &ids {
            let st = state(&v["initial"][id])?;
            balls.push(Ball {
                id: id.clone(),
                params,
                state: st,
            });
            let hist = v["history"][id]
                .as_array()
                .ok_or_else(|| PoolError::Data("history".into()))?;
            final_states.push(state(
                hist.last()
                    .ok_or_else(|| PoolError::Data("empty history".into()))?,
            )?);
        }
        let mut system = System::new(table, balls, specs);
        system.cue_ball_id = cue["cue_ball_id"].as_str().unwrap_or("cue").to_string();
        let mut events = Vec::new();
        for e in v["events"]
            .as_array()
            .ok_or_else(|| PoolError::Data("events".into()))?
        {
            let ty = e["type"].as_str().unwrap_or("none");
            if let Some(kind) = EventKind::from_name(ty) {
                let ids = e["ids"]
                    .as_array()
                    .map(|a| {
                        a.iter()
                            .map(|x| x.as_str().unwrap_or_default().to_string())
                            .collect()
                    })
                    .unwrap_or_default();
                events.push(RefEvent {
                    kind,
                    time: f(&e["time"])?,
                    ids,
                });
            }
        }
        let t_final = v["meta"]["t_final"].as_f64().unwrap_or(f64::NAN);
        Ok(RefTrace {
            system,
            shot,
            events,
            final_states,
            t_final,
        })
    }
}

/// Ball–ball, cushion and pocket events as comparable (kind name, ids) keys.
pub fn collision_keys_ref(t: &RefTrace) -> Vec<(EventKind, Vec<String>, f64)> {
    t.events
        .iter()
        .filter(|e| e.kind.is_collision() || e.kind == EventKind::BallPocket)
        .map(|e| (e.kind, e.ids.clone(), e.time))
        .collect()
}

/// Ball–ball, cushion and pocket events of a simulation as (kind, ids, time).
pub fn collision_keys_sim(s: &Simulation) -> Vec<(EventKind, Vec<String>, f64)> {
    s.events
        .iter()
        .filter(|e| e.kind.is_collision() || e.kind == EventKind::BallPocket)
        .map(|e| {
            (
                e.kind,
                s.event_ids(e).into_iter().map(|x| x.to_string()).collect(),
                e.time,
            )
        })
        .collect()
}

/// Outcome of comparing one simulation with its reference trace.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// Collision/pocket events in the reference
    pub n_ref: usize,
    /// Collision/pocket events in the simulation
    pub n_sim: usize,
    /// length of the common prefix of the collision/pocket event sequences
    pub common_prefix: usize,
    /// the event sequences are identical (kinds and ids, in order)
    pub sequence_equal: bool,
    /// max |Δt| over the common prefix
    pub max_dt: f64,
    /// max planar distance between final positions (pocketed balls compare pocket spots)
    pub max_final_dist: f64,
    /// time of the first differing event (reference time), if any
    pub diverge_time: Option<f64>,
    /// total event count difference (all kinds, incl. transitions)
    pub n_all_ref: usize,
    /// Events of all kinds in the simulation
    pub n_all_sim: usize,
    /// every event (transitions included) has the same kind and ids, in order
    pub all_sequence_equal: bool,
}

impl Comparison {
    /// Agreement: same ordered collision/pocket events and final positions within `tol` m.
    pub fn agrees(&self, tol: f64) -> bool {
        self.sequence_equal && self.max_final_dist <= tol
    }
}

/// Compares a simulation of `r`'s system and shot with `r`.
pub fn compare(r: &RefTrace, s: &Simulation) -> Comparison {
    let a = collision_keys_ref(r);
    let b = collision_keys_sim(s);
    let mut k = 0;
    let mut max_dt: f64 = 0.0;
    while k < a.len() && k < b.len() && a[k].0 == b[k].0 && a[k].1 == b[k].1 {
        max_dt = max_dt.max((a[k].2 - b[k].2).abs());
        k += 1;
    }
    let sequence_equal = k == a.len() && k == b.len();
    let diverge_time = if sequence_equal {
        None
    } else {
        Some(
            a.get(k)
                .map(|x| x.2)
                .unwrap_or_else(|| b.get(k).map(|x| x.2).unwrap_or(f64::NAN)),
        )
    };
    let mut max_final: f64 = 0.0;
    for (i, id) in s.ball_ids.iter().enumerate() {
        if let Some(j) = r.system.balls.iter().position(|b| &b.id == id) {
            let (p, q) = (s.final_states[i].r, r.final_states[j].r);
            max_final = max_final.max(((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt());
        }
    }
    let all_sequence_equal = r.events.len() == s.events.len()
        && r.events
            .iter()
            .zip(s.events.iter())
            .all(|(x, y)| x.kind == y.kind && x.ids.iter().map(|q| q.as_str()).eq(s.event_ids(y)));
    Comparison {
        all_sequence_equal,
        n_ref: a.len(),
        n_sim: b.len(),
        common_prefix: k,
        sequence_equal,
        max_dt,
        max_final_dist: max_final,
        diverge_time,
        n_all_ref: r.events.len(),
        n_all_sim: s.events.len(),
    }
}
