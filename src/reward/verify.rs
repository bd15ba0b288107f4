//! Verification rules: hand-written success tests of a goal that read the simulator's event log and
//! states directly (never detectors), in the same call syntax as the DSL (`docs/reward.md`).
//!
//! Event functions give timed occurrences:
//! - billiards: `FIRST_HIT(b)` (the first ball the cue ball touches is b), `HIT(a, b, state=, min_cut=,
//!   max_speed=)` (a ball–ball contact of a and b, `"*"` for any ball; a's motion state just before,
//!   the cut angle in degrees, the approach speed in m/s), `CUSHION(b)` (contacts of b with cushions,
//!   50 ms bursts merged), `POCKET(b, pocket?)`, `TRANSITION(b, to)` (a motion-state change of b into
//!   `to`), `CURVE(b)` (between two events of b its heading turns by more than 8° while another ball
//!   passes within 4 radii without touching it);
//! - PHYRE / I-PHYRE: `CONTACT(a, b)` (`contact_begin`, `"*"` for any), `EXIT(obj)` (`ball_exit`),
//!   `REMOVE(obj)` (I-PHYRE: an effective `action_applied` that removed the block),
//!   `SUCCESS()` (the task's success), `TURN(obj, degrees)` (the first timestep at which the object's
//!   orientation differs from its first frame's by at least `degrees`: PHYRE's `angle`, an I-PHYRE
//!   block's segment; balls of I-PHYRE have none), `SWING(obj, degrees)` (I-PHYRE: the first timestep
//!   at which the rod from the object's centre to its pin-joint partner's has turned by `degrees`). Objects are ids or words naming roles read off the
//!   first frame (all must hold): colours and shapes (`"green"`, `"red ball"`), `"user"` (PHYRE's
//!   placed ball), PHYRE's `"dynamic"` (red, green, blue, gray) and `"static"` (black, purple),
//!   I-PHYRE's `"ball"`, `"eliminable"`, `"dynamic"`, `"fixed"`, `"block"`.
//!
//! Combinators: `SEQ(e1, e2, …)` (distinct occurrences in time order, each no earlier than the previous),
//! `ALL(…)`, `ANY(…)`, `NOT(c)`, `NONE(e)` (no occurrence), `AT_LEAST(e, n)`. An event used as a
//! condition holds when it occurs.

use serde_json::Value;

use super::error::{ErrorCategory, Pos, RewardError};
use super::facts::cue_ball_in;
use super::parser::{Arg, Expr, ExprKind, parse};
use crate::trace::{
    BallView, Body, Env, Event, Frames, Outcome, PoolSteps, Timestep, Trace, TraceColumns,
};

/// A parsed verification rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Rule {
    /// The rule's text.
    pub source: String,
    root: Expr,
}

const EVENTS: &[&str] = &[
    "FIRST_HIT",
    "HIT",
    "CUSHION",
    "POCKET",
    "TRANSITION",
    "CURVE",
    "CONTACT",
    "EXIT",
    "SUCCESS",
    "TURN",
    "REMOVE",
    "SWING",
    "SEQ",
];
const CONDITIONS: &[&str] = &["ALL", "ANY", "NOT", "NONE", "AT_LEAST"];

fn err(cat: ErrorCategory, pos: Pos, m: impl Into<String>) -> RewardError {
    RewardError::new(cat, pos, m)
}

fn name_of(e: &Expr) -> Option<(String, &[Arg])> {
    match &e.kind {
        ExprKind::Call { name, args } => Some((name.to_ascii_uppercase(), args.as_slice())),
        _ => None,
    }
}

impl Rule {
    /// Parses a rule and checks its function names and argument counts.
    pub fn parse(text: &str) -> Result<Rule, RewardError> {
        let root = parse(text)?;
        check(&root)?;
        Ok(Rule {
            source: text.to_string(),
            root,
        })
    }

    /// Whether the rule holds on `trace`.
    pub fn holds(&self, trace: &Trace) -> Result<bool, RewardError> {
        let v = Verifier::new(trace);
        v.cond(&self.root)
    }

    /// Whether the rule holds on the trace held by `cols`: read from the columns for billiards (no
    /// `Trace` built, the same verdict as [`Rule::holds`] on `cols.into_trace()`); the other
    /// environments' rules read a copy of the trace.
    pub fn holds_on_columns(&self, cols: &TraceColumns) -> Result<bool, RewardError> {
        match &cols.frames {
            Frames::Pool(frames) => {
                let v = Verifier {
                    env: Env::Pooltool,
                    events: &cols.events,
                    outcome: &cols.outcome,
                    steps: PoolSteps::of_frames(frames),
                    timesteps: &[],
                    cue: cue_ball_in(&cols.events),
                    roles: Default::default(),
                };
                v.cond(&self.root)
            }
            Frames::Phyre(_) | Frames::Iphyre(_) => self.holds(&cols.clone().into_trace()),
        }
    }
}

fn check(e: &Expr) -> Result<(), RewardError> {
    let Some((name, args)) = name_of(e) else {
        return Err(err(
            ErrorCategory::ArgumentType,
            e.pos,
            format!("expected a rule function call, found {}", e.type_name()),
        ));
    };
    let n = args.len();
    let (lo, hi) = match name.as_str() {
        "FIRST_HIT" | "CUSHION" | "CURVE" | "EXIT" | "REMOVE" | "NOT" | "NONE" => (1, 1),
        "POCKET" => (1, 2),
        "TRANSITION" | "AT_LEAST" | "CONTACT" | "TURN" | "SWING" => (2, 2),
        "HIT" => (2, 5),
        "SUCCESS" => (0, 0),
        "SEQ" | "ALL" | "ANY" => (1, usize::MAX),
        _ => {
            return Err(err(
                ErrorCategory::UnknownFunction,
                e.pos,
                format!(
                    "unknown verification function `{name}` (events: {}; conditions: {})",
                    EVENTS.join(", "),
                    CONDITIONS.join(", ")
                ),
            ));
        }
    };
    if n < lo || n > hi {
        return Err(err(
            ErrorCategory::Arity,
            e.pos,
            format!("{name} takes {lo}..{hi} arguments, found {n}"),
        ));
    }
    for a in args {
        if matches!(a.value.kind, ExprKind::Call { .. }) {
            check(&a.value)?;
        }
        if let Some((k, p)) = &a.name
            && !(name == "HIT" && ["state", "min_cut", "max_speed"].contains(&k.as_str()))
        {
            return Err(err(
                ErrorCategory::Arity,
                *p,
                format!("{name} has no keyword `{k}`"),
            ));
        }
    }
    Ok(())
}

/// An event instance: time and (for SEQ) its identity.
type Hit = (f64, usize);

/// What a rule reads of one trace.
struct Verifier<'a> {
    env: Env,
    events: &'a [Event],
    outcome: &'a Outcome,
    /// Billiard-ball states by step.
    steps: PoolSteps<'a>,
    /// The paper-layout steps (PHYRE / I-PHYRE bodies; empty when read from billiards columns).
    timesteps: &'a [Timestep],
    cue: String,
    roles: std::collections::HashMap<String, Vec<String>>,
}

fn text(e: &Expr) -> Result<String, RewardError> {
    match &e.kind {
        ExprKind::Str(s) => Ok(s.clone()),
        ExprKind::Num(n) if n.fract() == 0.0 => Ok(format!("{}", *n as i64)),
        _ => Err(err(
            ErrorCategory::ArgumentType,
            e.pos,
            format!("expected an object id, found {}", e.type_name()),
        )),
    }
}

fn number(e: &Expr) -> Result<f64, RewardError> {
    match e.kind {
        ExprKind::Num(n) => Ok(n),
        _ => Err(err(
            ErrorCategory::ArgumentType,
            e.pos,
            format!("expected a number, found {}", e.type_name()),
        )),
    }
}

fn agents(p: &Option<Value>) -> Vec<String> {
    p.as_ref()
        .and_then(|p| p.get("agents"))
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(|x| match x {
                    Value::String(s) => Some(s.clone()),
                    Value::Number(n) => Some(n.to_string()),
                    _ => None,
                })
                .collect()
        })
        .unwrap_or_default()
}

fn is(id: &str, want: &str) -> bool {
    want == "*" || id.eq_ignore_ascii_case(want)
}

/// The roles of every object of a PHYRE / I-PHYRE trace's first frame, by id: its colour and shape or
/// kind (PHYRE: `red`, `green`, `blue`, `purple`, `gray`, `black`, `ball`, `bar`, `jar`, …, `user` for
/// the placed ball, `dynamic`/`static`; I-PHYRE: `ball`/`red`, `eliminable`/`gray`,
/// `dynamic`/`blue`, `fixed`/`black`, `block`).
fn roles(timesteps: &[Timestep]) -> std::collections::HashMap<String, Vec<String>> {
    let mut out = std::collections::HashMap::new();
    let Some(first) = timesteps.first() else {
        return out;
    };
    for o in &first.objects {
        let (id, r): (i64, Vec<&str>) = match &o.body {
            Body::Phyre(p) => {
                let mut r = vec![p.color.as_str(), p.shape.as_str()];
                if p.is_user_input {
                    r.push("user");
                }
                // PHYRE's colours are its body types: black and purple bodies are static.
                r.push(
                    if ["black", "purple"].contains(&p.color.to_ascii_lowercase().as_str()) {
                        "static"
                    } else {
                        "dynamic"
                    },
                );
                (p.object_index, r)
            }
            Body::Iphyre(b) => {
                let ball = b.x1 == b.x2 && b.y1 == b.y2;
                let r = if ball {
                    vec!["ball", "red"]
                } else if b.eliminable > 0.5 {
                    vec!["block", "eliminable", "gray"]
                } else if b.dynamic > 0.5 {
                    vec!["block", "dynamic", "blue"]
                } else {
                    vec!["block", "fixed", "black"]
                };
                (b.index, r)
            }
            _ => continue,
        };
        out.insert(
            id.to_string(),
            r.into_iter().map(str::to_ascii_lowercase).collect(),
        );
    }
    out
}

impl<'a> Verifier<'a> {
    fn new(trace: &'a Trace) -> Self {
        Verifier {
            env: trace.env,
            events: &trace.events,
            outcome: &trace.outcome,
            steps: PoolSteps::of_trace(trace),
            timesteps: &trace.timesteps,
            cue: cue_ball_in(&trace.events),
            roles: roles(&trace.timesteps),
        }
    }

    /// Whether object `id` is `want`: `*`, its id, or (PHYRE / I-PHYRE) words that all name roles
    /// of it (`"green"`, `"red ball"`, `"user"`, `"eliminable"`).
    fn matches(&self, id: &str, want: &str) -> bool {
        if is(id, want) {
            return true;
        }
        let Some(r) = self.roles.get(id) else {
            return false;
        };
        let words: Vec<String> = want
            .split_whitespace()
            .map(str::to_ascii_lowercase)
            .collect();
        !words.is_empty() && words.iter().all(|w| r.contains(w))
    }

    fn require_env(&self, e: &Expr, name: &str, pool: bool) -> Result<(), RewardError> {
        if (self.env == Env::Pooltool) != pool {
            return Err(err(
                ErrorCategory::Runtime,
                e.pos,
                format!("{name} does not apply to {} traces", self.env),
            ));
        }
        Ok(())
    }

    /// Events of `kind` (several kinds allowed) as (index, time, agents).
    fn events(&self, kinds: &[&str]) -> Vec<(usize, f64, Vec<String>, Option<&Value>)> {
        self.events
            .iter()
            .enumerate()
            .filter(|(_, e)| kinds.contains(&e.kind.as_str()))
            .filter_map(|(i, e)| Some((i, e.t?, agents(&e.payload), e.payload.as_ref())))
            .collect()
    }

    /// The state of ball `id` at the last timestep at or before `t`.
    fn ball_at(&self, id: &str, t: f64) -> Option<BallView<'a>> {
        let i = self.steps.count_until(t).saturating_sub(1);
        if i >= self.steps.len() {
            return None;
        }
        self.steps.ball(i, id)
    }

    /// `HIT(a, b, state=, min_cut=, max_speed=)`: ball–ball events between `a` and `b` (either
    /// order) that pass the keyword filters.
    fn ball_hits(&self, args: &[Arg]) -> Result<Vec<Hit>, RewardError> {
        let (a, b) = (text(&args[0].value)?, text(&args[1].value)?);
        let mut state = None;
        let (mut min_cut, mut max_speed) = (None, None);
        for x in &args[2..] {
            match x.name.as_ref().map(|n| n.0.as_str()) {
                Some("state") => state = Some(text(&x.value)?),
                Some("min_cut") => min_cut = Some(number(&x.value)?),
                Some("max_speed") => max_speed = Some(number(&x.value)?),
                _ => {
                    return Err(err(
                        ErrorCategory::Arity,
                        x.value.pos,
                        "HIT takes two ball ids and the keywords state=, min_cut=, max_speed=",
                    ));
                }
            }
        }
        let mut hits = Vec::new();
        for (i, t, ids, payload) in self.events(&["physics_ball_ball"]) {
            if ids.len() != 2 {
                continue;
            }
            let (x, y) = if is(&ids[0], &a) && is(&ids[1], &b) {
                (&ids[0], &ids[1])
            } else if is(&ids[1], &a) && is(&ids[0], &b) {
                (&ids[1], &ids[0])
            } else {
                continue;
            };
            if let Some(s) = &state
                && !self
                    .ball_at(x, t)
                    .is_some_and(|ba| ba.motion_state.eq_ignore_ascii_case(s))
            {
                continue;
            }
            if let Some(m) = max_speed {
                let v = payload
                    .and_then(|p| p.get("approach_speed"))
                    .and_then(Value::as_f64)
                    .map(f64::abs);
                if !v.is_some_and(|v| v <= m) {
                    continue;
                }
            }
            if let Some(m) = min_cut
                && !self.cut_angle(x, y, t).is_some_and(|c| c >= m)
            {
                continue;
            }
            hits.push((t, i));
        }
        Ok(hits)
    }

    /// `CUSHION(b)`: cushion contacts of `b`, a run of contacts less than 0.05 s apart counting
    /// once.
    fn cushion_hits(&self, b: &str) -> Vec<Hit> {
        let mut last = f64::NEG_INFINITY;
        let mut hits = Vec::new();
        for (i, t, ids, _) in self.events(&[
            "physics_ball_linear_cushion",
            "physics_ball_circular_cushion",
        ]) {
            if ids.first().is_some_and(|x| is(x, b)) {
                if t - last > 0.05 {
                    hits.push((t, i));
                }
                last = t;
            }
        }
        hits
    }

    /// `SUCCESS`: the `success` event, else the end of a successful trace.
    fn success_hits(&self) -> Vec<Hit> {
        let t = self
            .events
            .iter()
            .enumerate()
            .find(|(_, ev)| ev.kind == "success")
            .and_then(|(i, ev)| Some((ev.t?, i)));
        match t {
            Some(h) => vec![h],
            None if self.outcome.success => {
                let n = self.steps.len();
                vec![(if n > 0 { self.steps.t(n - 1) } else { 0.0 }, usize::MAX)]
            }
            None => Vec::new(),
        }
    }

    /// `SEQ(e1, e2, …)`: the last hit of the first chain of distinct occurrences in time order, or
    /// none when the chain breaks.
    fn seq_hits(&self, args: &[Arg]) -> Result<Vec<Hit>, RewardError> {
        let mut prev: Option<Hit> = None;
        let mut used: Vec<(usize, f64, usize)> = Vec::new();
        for (k, a) in args.iter().enumerate() {
            let occ = self.occurrences(&a.value)?;
            let next = occ.into_iter().find(|h| {
                prev.is_none_or(|p| h.0 >= p.0)
                    && !used.iter().any(|(_, t, i)| *i == h.1 && *t == h.0)
            });
            match next {
                Some(h) => {
                    used.push((k, h.0, h.1));
                    prev = Some(h);
                }
                None => return Ok(Vec::new()),
            }
        }
        Ok(prev.into_iter().collect())
    }

    fn occurrences(&self, e: &Expr) -> Result<Vec<Hit>, RewardError> {
        let (name, args) = name_of(e).expect("checked");
        let arg = |i: usize| text(&args[i].value);
        let mut out: Vec<Hit> = match name.as_str() {
            "FIRST_HIT" => {
                self.require_env(e, &name, true)?;
                let b = arg(0)?;
                self.events(&["physics_ball_ball"])
                    .into_iter()
                    .find(|(_, _, ids, _)| ids.contains(&self.cue))
                    .filter(|(_, _, ids, _)| ids.iter().any(|x| *x != self.cue && is(x, &b)))
                    .map(|(i, t, _, _)| (t, i))
                    .into_iter()
                    .collect()
            }
            "HIT" => {
                self.require_env(e, &name, true)?;
                self.ball_hits(args)?
            }
            "CUSHION" => {
                self.require_env(e, &name, true)?;
                self.cushion_hits(&arg(0)?)
            }
            "POCKET" => {
                self.require_env(e, &name, true)?;
                let b = arg(0)?;
                let pocket = if args.len() > 1 { Some(arg(1)?) } else { None };
                self.events(&["physics_ball_pocket"])
                    .into_iter()
                    .filter(|(_, _, ids, _)| {
                        ids.first().is_some_and(|x| is(x, &b))
                            && pocket
                                .as_ref()
                                .is_none_or(|p| ids.get(1).is_some_and(|x| is(x, p)))
                    })
                    .map(|(i, t, _, _)| (t, i))
                    .collect()
            }
            "TRANSITION" => {
                self.require_env(e, &name, true)?;
                let (b, to) = (arg(0)?, arg(1)?);
                self.events
                    .iter()
                    .enumerate()
                    .filter(|(_, ev)| ev.kind.starts_with("physics_"))
                    .filter_map(|(i, ev)| {
                        let p = ev.payload.as_ref()?;
                        let ball = p.get("ball")?.as_str()?;
                        let state = p.get("to")?.as_str()?;
                        (is(ball, &b) && state.eq_ignore_ascii_case(&to)).then_some((ev.t?, i))
                    })
                    .collect()
            }
            "CURVE" => {
                self.require_env(e, &name, true)?;
                self.curves(&arg(0)?)
            }
            "CONTACT" => {
                self.require_env(e, &name, false)?;
                let (a, b) = (arg(0)?, arg(1)?);
                self.events(&["contact_begin"])
                    .into_iter()
                    .filter(|(_, _, ids, _)| {
                        ids.len() == 2
                            && ((self.matches(&ids[0], &a) && self.matches(&ids[1], &b))
                                || (self.matches(&ids[1], &a) && self.matches(&ids[0], &b)))
                    })
                    .map(|(i, t, _, _)| (t, i))
                    .collect()
            }
            "EXIT" => {
                self.require_env(e, &name, false)?;
                let b = arg(0)?;
                self.events(&["ball_exit"])
                    .into_iter()
                    .filter(|(_, _, ids, _)| ids.iter().any(|x| self.matches(x, &b)))
                    .map(|(i, t, _, _)| (t, i))
                    .collect()
            }
            "SUCCESS" => self.success_hits(),
            "SWING" => {
                self.require_env(e, &name, false)?;
                self.swings(&arg(0)?, number(&args[1].value)?)
            }
            "REMOVE" => {
                self.require_env(e, &name, false)?;
                let b = arg(0)?;
                self.events(&["action_applied"])
                    .into_iter()
                    .filter(|(_, _, ids, p)| {
                        p.and_then(|p| p.get("effective"))
                            .and_then(Value::as_bool)
                            .unwrap_or(false)
                            && ids.iter().any(|x| self.matches(x, &b))
                    })
                    .map(|(i, t, _, _)| (t, i))
                    .collect()
            }
            "TURN" => {
                self.require_env(e, &name, false)?;
                self.turns(&arg(0)?, number(&args[1].value)?)
            }
            "SEQ" => self.seq_hits(args)?,
            _ => {
                return Err(err(
                    ErrorCategory::ArgumentType,
                    e.pos,
                    format!("{name} is a condition, not an event"),
                ));
            }
        };
        out.sort_by(|x, y| x.0.total_cmp(&y.0));
        Ok(out)
    }

    fn cond(&self, e: &Expr) -> Result<bool, RewardError> {
        let (name, args) = name_of(e).expect("checked");
        Ok(match name.as_str() {
            "ALL" => {
                for a in args {
                    if !self.cond(&a.value)? {
                        return Ok(false);
                    }
                }
                true
            }
            "ANY" => {
                for a in args {
                    if self.cond(&a.value)? {
                        return Ok(true);
                    }
                }
                false
            }
            "NOT" => !self.cond(&args[0].value)?,
            "NONE" => self.occurrences(&args[0].value)?.is_empty(),
            "AT_LEAST" => {
                let n = number(&args[1].value)?;
                self.occurrences(&args[0].value)?.len() as f64 >= n
            }
            _ => !self.occurrences(e)?.is_empty(),
        })
    }

    /// `TURN(obj, degrees)`: for each object that matches, the first timestep at which its
    /// orientation is at least `degrees` away from its first frame's (angles compared modulo a full
    /// turn; an I-PHYRE block's orientation is its segment's, modulo a half turn).
    fn turns(&self, obj: &str, degrees: f64) -> Vec<Hit> {
        let orientation = |b: &Body| -> Option<(String, f64, f64)> {
            match b {
                Body::Phyre(p) => {
                    Some((p.object_index.to_string(), p.angle, std::f64::consts::TAU))
                }
                Body::Iphyre(p) if !(p.x1 == p.x2 && p.y1 == p.y2) => Some((
                    p.index.to_string(),
                    (p.y2 - p.y1).atan2(p.x2 - p.x1),
                    std::f64::consts::PI,
                )),
                _ => None,
            }
        };
        let mut first: std::collections::HashMap<String, f64> = Default::default();
        let mut out: Vec<Hit> = Vec::new();
        let mut done: std::collections::HashSet<String> = Default::default();
        for (k, step) in self.timesteps.iter().enumerate() {
            for o in &step.objects {
                let Some((id, a, period)) = orientation(&o.body) else {
                    continue;
                };
                if done.contains(&id) || !self.matches(&id, obj) {
                    continue;
                }
                let a0 = *first.entry(id.clone()).or_insert(a);
                let d = (a - a0).rem_euclid(period);
                if d.min(period - d).to_degrees() >= degrees {
                    out.push((step.t, usize::MAX - k));
                    done.insert(id);
                }
            }
        }
        out
    }

    /// `SWING(obj, degrees)`: for each I-PHYRE object that matches and has a pin-joint partner, the
    /// first timestep at which the rod between their centres points at least `degrees` away from its
    /// first frame's direction.
    fn swings(&self, obj: &str, degrees: f64) -> Vec<Hit> {
        let tau = std::f64::consts::TAU;
        let mut first: std::collections::HashMap<String, f64> = Default::default();
        let mut done: std::collections::HashSet<String> = Default::default();
        let mut out: Vec<Hit> = Vec::new();
        for (k, step) in self.timesteps.iter().enumerate() {
            let blocks: Vec<&crate::trace::IphyreObject> = step
                .objects
                .iter()
                .filter_map(|o| match &o.body {
                    Body::Iphyre(b) if b.joint > 0 => Some(b),
                    _ => None,
                })
                .collect();
            for b in &blocks {
                let id = b.index.to_string();
                if done.contains(&id) || !self.matches(&id, obj) {
                    continue;
                }
                let Some(p) = blocks
                    .iter()
                    .find(|p| p.joint == b.joint && p.index != b.index)
                else {
                    continue;
                };
                let c = |o: &crate::trace::IphyreObject| ((o.x1 + o.x2) / 2.0, (o.y1 + o.y2) / 2.0);
                let ((bx, by), (px, py)) = (c(b), c(p));
                let a = (py - by).atan2(px - bx);
                let a0 = *first.entry(id.clone()).or_insert(a);
                let d = (a - a0).rem_euclid(tau);
                if d.min(tau - d).to_degrees() >= degrees {
                    out.push((step.t, usize::MAX / 2 - k));
                    done.insert(id);
                }
            }
        }
        out
    }

    /// The cut angle (degrees) of striker `x` on `y` at contact time `t`: the angle between x's
    /// velocity and the line of centres, with positions extrapolated from the last timestep.
    fn cut_angle(&self, x: &str, y: &str, t: f64) -> Option<f64> {
        let (bx, by) = (self.ball_at(x, t)?, self.ball_at(y, t)?);
        let i = self.steps.count_until(t).saturating_sub(1);
        let dt = t - self.steps.t(i);
        let p = |b: &BallView| {
            [
                b.position[0] + b.velocity[0] * dt,
                b.position[1] + b.velocity[1] * dt,
            ]
        };
        let (px, py) = (p(&bx), p(&by));
        let n = [py[0] - px[0], py[1] - px[1]];
        let v = [
            bx.velocity[0] - by.velocity[0],
            bx.velocity[1] - by.velocity[1],
        ];
        let (nn, vn) = (n[0].hypot(n[1]), v[0].hypot(v[1]));
        if nn == 0.0 || vn == 0.0 {
            return None;
        }
        let c = ((n[0] * v[0] + n[1] * v[1]) / (nn * vn)).clamp(-1.0, 1.0);
        Some(c.acos().to_degrees())
    }

    /// Stretches between consecutive events of `b` where its heading turns by more than 8° while
    /// another ball comes within 4 radii (without a contact in between, as no event splits it).
    fn curves(&self, b: &str) -> Vec<Hit> {
        let mut times: Vec<f64> = self
            .events
            .iter()
            .filter(|e| e.kind.starts_with("physics_"))
            .filter(|e| agents(&e.payload).iter().any(|x| x == b))
            .filter_map(|e| e.t)
            .collect();
        times.sort_by(f64::total_cmp);
        let steps = &self.steps;
        let mut out = Vec::new();
        for w in times.windows(2) {
            let (t0, t1) = (w[0], w[1]);
            let inside: Vec<usize> = (0..steps.len())
                .filter(|&k| steps.t(k) > t0 + 1e-9 && steps.t(k) < t1 - 1e-9)
                .collect();
            if inside.len() < 2 {
                continue;
            }
            let state = |k: usize| steps.ball(k, b);
            let (Some(s0), Some(s1)) = (state(inside[0]), state(*inside.last().expect("len>=2")))
            else {
                continue;
            };
            let h = |p: &BallView| p.velocity[1].atan2(p.velocity[0]);
            if s0.velocity[0].hypot(s0.velocity[1]) < 1e-3
                || s1.velocity[0].hypot(s1.velocity[1]) < 1e-3
            {
                continue;
            }
            let mut turn = (h(&s1) - h(&s0)).to_degrees().abs() % 360.0;
            if turn > 180.0 {
                turn = 360.0 - turn;
            }
            if turn <= 8.0 {
                continue;
            }
            let r = s0.radius.max(1e-6);
            let near = inside.iter().any(|&k| {
                let Some(me) = state(k) else { return false };
                steps.balls(k).any(|p| {
                    p.ball_id != b
                        && p.motion_state != "pocketed"
                        && (p.position[0] - me.position[0]).hypot(p.position[1] - me.position[1])
                            < 4.0 * r
                })
            });
            if near {
                out.push((steps.t(inside[0]), usize::MAX - out.len()));
            }
        }
        out
    }
}

#[cfg(test)]
mod goal_rule_tests {
    //! The verification rules of the PHYRE and I-PHYRE goal files on hand-made traces: for each goal,
    //! one event log where the goal holds and one where it does not.

    use serde_json::json;

    use super::Rule;
    use crate::reward::goals::GoalSet;
    use crate::testutil::synthetic_trace;
    use crate::trace::{Body, Env, Event, JsonMap, Trace};

    /// (contacts or exits as (kind, t, agents), success).
    type Log = (
        &'static [(&'static str, f64, &'static [&'static str])],
        bool,
    );

    fn trace(env: Env, log: &Log) -> Trace {
        let mut t = synthetic_trace(env, 0, 4, 5);
        for ts in &mut t.timesteps {
            for (k, o) in ts.objects.iter_mut().enumerate() {
                match &mut o.body {
                    // 0 black bar (static), 1 green ball, 2 blue bar, 3 black wall, 4 the red user ball.
                    Body::Phyre(p) => {
                        let (color, shape) = [
                            ("black", "bar"),
                            ("green", "ball"),
                            ("blue", "bar"),
                            ("black", "undefined"),
                            ("red", "ball"),
                        ][k];
                        p.object_index = k as i64;
                        p.color = color.into();
                        p.shape = shape.into();
                        p.is_user_input = k == 4;
                    }
                    // 0 eliminable (gray), 1 dynamic (blue), 2 fixed (black), 3 and 4 balls.
                    Body::Iphyre(b) => {
                        b.index = k as i64;
                        let ball = k >= 3;
                        (b.x1, b.y1) = (100.0 * k as f64, 300.0);
                        (b.x2, b.y2) = if ball {
                            (b.x1, b.y1)
                        } else {
                            (b.x1 + 50.0, 300.0)
                        };
                        b.eliminable = if k == 0 { 1.0 } else { 0.0 };
                        b.dynamic = if k == 1 || ball { 1.0 } else { 0.0 };
                    }
                    _ => unreachable!(),
                }
            }
        }
        // `("turn", t, [id, degrees])` is no event: from time t on, object id is turned by that much
        // (PHYRE: its angle; I-PHYRE: its segment about its centre).
        for (_, at, agents) in log.0.iter().filter(|e| e.0 == "turn") {
            let deg: f64 = agents[1].parse().unwrap();
            for ts in t.timesteps.iter_mut().filter(|s| s.t >= *at) {
                for o in &mut ts.objects {
                    match &mut o.body {
                        Body::Phyre(p) if p.object_index.to_string() == agents[0] => {
                            p.angle = deg.to_radians();
                        }
                        Body::Iphyre(b) if b.index.to_string() == agents[0] => {
                            let (cx, cy) = ((b.x1 + b.x2) / 2.0, (b.y1 + b.y2) / 2.0);
                            let h = (b.x2 - b.x1).hypot(b.y2 - b.y1) / 2.0;
                            let (sn, cs) = deg.to_radians().sin_cos();
                            (b.x1, b.y1, b.x2, b.y2) =
                                (cx - h * cs, cy - h * sn, cx + h * cs, cy + h * sn);
                        }
                        _ => {}
                    }
                }
            }
        }
        // `("swing", t, [a, b, degrees])`: a and b share pin joint 1, and from time t on a has swung
        // about b's centre by that much.
        for (_, at, agents) in log.0.iter().filter(|e| e.0 == "swing") {
            let deg: f64 = agents[2].parse().unwrap();
            let (sn, cs) = deg.to_radians().sin_cos();
            for ts in &mut t.timesteps {
                let centre = ts.objects.iter().find_map(|o| match &o.body {
                    Body::Iphyre(b) if b.index.to_string() == agents[1] => {
                        Some(((b.x1 + b.x2) / 2.0, (b.y1 + b.y2) / 2.0))
                    }
                    _ => None,
                });
                let (cx, cy) = centre.unwrap();
                let moved = ts.t >= *at;
                for o in &mut ts.objects {
                    let Body::Iphyre(b) = &mut o.body else {
                        continue;
                    };
                    let id = b.index.to_string();
                    if id == agents[0] || id == agents[1] {
                        b.joint = 1;
                    }
                    if id == agents[0] && moved {
                        let r = |x: f64, y: f64| {
                            (
                                cx + (x - cx) * cs - (y - cy) * sn,
                                cy + (x - cx) * sn + (y - cy) * cs,
                            )
                        };
                        ((b.x1, b.y1), (b.x2, b.y2)) = (r(b.x1, b.y1), r(b.x2, b.y2));
                    }
                }
            }
        }
        // `action_applied` removed its agent; `click_missed` is an `action_applied` that removed
        // nothing.
        t.events = log
            .0
            .iter()
            .filter(|e| e.0 != "turn" && e.0 != "swing")
            .map(|(kind, at, agents)| {
                let (kind, payload) = match *kind {
                    "action_applied" => (*kind, json!({ "agents": agents, "effective": true })),
                    "click_missed" => (
                        "action_applied",
                        json!({ "agents": [], "effective": false }),
                    ),
                    _ => (*kind, json!({ "agents": agents })),
                };
                Event {
                    kind: kind.to_string(),
                    t: Some(*at),
                    payload: Some(payload),
                    extra: JsonMap::new(),
                }
            })
            .collect();
        t.outcome.success = log.1;
        t
    }

    fn check(env: Env, cases: &[(&str, Log, Log)]) {
        let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let set = GoalSet::load(&repo.join(format!("data/goals/{env}.toml")), repo).unwrap();
        assert_eq!(set.goals.len(), 10, "{env}: ten goals");
        for g in &set.goals {
            let (_, yes, no) = cases
                .iter()
                .find(|c| c.0 == g.id)
                .unwrap_or_else(|| panic!("{env}: no hand-made traces for goal {}", g.id));
            let rule = Rule::parse(&g.verify).unwrap();
            assert!(
                rule.holds(&trace(env, yes)).unwrap(),
                "{}: should hold",
                g.id
            );
            assert!(
                !rule.holds(&trace(env, no)).unwrap(),
                "{}: should not hold",
                g.id
            );
        }
    }

    const C: &str = "contact_begin";
    const TURN: &str = "turn";

    /// The hand-made traces of each PHYRE goal: (goal, where it holds, where it does not). Objects:
    /// 0 black bar, 1 green ball, 2 blue bar, 3 black wall, 4 the red user ball. The "does not"
    /// traces include the ones that fooled the first drafts of the rules (session 9): a success
    /// with two contacts the red ball took no part in, a single contact counted as knocking
    /// something over, two contacts with static bodies as "roll, then hit a dynamic object".
    #[test]
    fn phyre_goal_rules_hold_exactly_on_their_traces() {
        check(
            Env::Phyre,
            &[
                (
                    "red-touches-green",
                    (&[(C, 0.1, &["4", "1"])], false),
                    (&[(C, 0.1, &["4", "2"])], false),
                ),
                (
                    "bounce-then-solve",
                    (&[(C, 0.01, &["4", "0"]), (C, 0.02, &["1", "2"])], true),
                    // Fooled the first rule (success and two contacts, none of the red ball).
                    (&[(C, 0.1, &["1", "0"]), (C, 0.2, &["1", "2"])], true),
                ),
                (
                    "tip-over",
                    (
                        &[(C, 0.005, &["4", "2"]), (TURN, 0.02, &["2", "60"])],
                        false,
                    ),
                    // Fooled the first rule (any contact), and a turn before the red ball came.
                    (
                        &[(C, 0.005, &["4", "2"]), (TURN, 0.02, &["2", "20"])],
                        false,
                    ),
                ),
                (
                    "green-touches-goal",
                    (&[(C, 0.1, &["1", "2"])], false),
                    (&[(C, 0.1, &["1", "0"])], false),
                ),
                (
                    "bounce-off-then-green",
                    (&[(C, 0.1, &["4", "3"]), (C, 0.2, &["4", "1"])], false),
                    (&[(C, 0.1, &["4", "1"]), (C, 0.2, &["4", "3"])], false),
                ),
                (
                    "roll-then-hit",
                    (&[(C, 0.1, &["4", "0"]), (C, 0.2, &["4", "2"])], false),
                    // Fooled the first rule (two contacts of the red ball, both with static bodies).
                    (&[(C, 0.1, &["4", "0"]), (C, 0.2, &["4", "3"])], false),
                ),
                (
                    "solve-without-red-on-green",
                    (&[(C, 0.1, &["4", "2"]), (C, 0.2, &["1", "2"])], true),
                    (&[(C, 0.1, &["4", "1"]), (C, 0.2, &["1", "2"])], true),
                ),
                (
                    "hit-goal",
                    (&[(C, 0.1, &["2", "4"])], false),
                    (&[(C, 0.1, &["1", "4"])], false),
                ),
                (
                    "knock-green-down",
                    (&[(C, 0.1, &["4", "1"]), (C, 0.2, &["1", "0"])], false),
                    (&[(C, 0.1, &["1", "0"]), (C, 0.2, &["4", "1"])], false),
                ),
                (
                    "solve-without-black",
                    (&[(C, 0.1, &["4", "2"]), (C, 0.2, &["1", "2"])], true),
                    (&[(C, 0.1, &["4", "2"]), (C, 0.2, &["4", "3"])], true),
                ),
            ],
        );
    }

    /// The same for I-PHYRE. Objects: 0 eliminable (gray), 1 dynamic (blue), 2 fixed (black), 3
    /// and 4 balls. The "does not" traces include the ones that fooled the first drafts: an exit of
    /// anything with no block removed, keeping the balls on screen by doing nothing, an exit with a
    /// contact of a blue block but nothing swinging.
    #[test]
    fn iphyre_goal_rules_hold_exactly_on_their_traces() {
        const X: &str = "ball_exit";
        const R: &str = "action_applied";
        check(
            Env::Iphyre,
            &[
                (
                    "remove-then-fall",
                    (&[(R, 0.5, &["0"]), (X, 1.0, &["3"])], false),
                    // Fooled the first rule (an exit without a removal).
                    (&[("click_missed", 0.5, &[]), (X, 1.0, &["3"])], false),
                ),
                (
                    "solve-without-black",
                    (&[(C, 0.5, &["3", "0"]), (X, 1.0, &["3"])], true),
                    (&[(C, 0.5, &["3", "2"]), (X, 1.0, &["3"])], true),
                ),
                (
                    "slide-then-exit",
                    (&[(C, 0.5, &["3", "2"]), (X, 1.0, &["3"])], false),
                    // Fooled the first rule (the ball's resting contact with its gray support).
                    (&[(C, 0.5, &["3", "0"]), (X, 1.0, &["3"])], false),
                ),
                (
                    "ball-hits-blue",
                    (&[(C, 0.5, &["1", "3"])], false),
                    (&[(C, 0.5, &["2", "3"])], false),
                ),
                (
                    "keep-balls-on-screen",
                    (&[(R, 0.5, &["0"]), (C, 0.6, &["3", "2"])], false),
                    // Fooled the first rule (nothing removed, the balls resting where they were).
                    (&[(C, 0.0, &["3", "0"])], false),
                ),
                (
                    "two-balls-collide",
                    (&[(C, 0.5, &["3", "4"])], false),
                    (&[(C, 0.5, &["3", "1"])], false),
                ),
                (
                    "blue-then-exit",
                    (&[(C, 0.5, &["3", "1"]), (X, 1.0, &["3"])], false),
                    (&[(C, 0.5, &["3", "2"]), (X, 1.0, &["3"])], false),
                ),
                (
                    "fall-onto-black",
                    (&[(R, 0.2, &["0"]), (C, 0.5, &["3", "2"])], false),
                    (&[(C, 0.1, &["3", "2"]), (R, 0.2, &["0"])], false),
                ),
                (
                    "swing-then-exit",
                    (
                        &[("swing", 0.02, &["3", "1", "40"]), (X, 1.0, &["3"])],
                        false,
                    ),
                    // Fooled the first rule (a blue block touched, nothing swinging); a block that
                    // turns in place is no swing either.
                    (
                        &[
                            (C, 0.5, &["3", "1"]),
                            (TURN, 0.02, &["1", "40"]),
                            (X, 1.0, &["3"]),
                        ],
                        false,
                    ),
                ),
                (
                    "exit-alone",
                    (&[(X, 1.0, &["3"])], false),
                    (&[(C, 0.5, &["3", "4"]), (X, 1.0, &["3"])], false),
                ),
            ],
        );
    }
}
