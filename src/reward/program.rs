//! A checked reward program: the typed tree the checker builds and the interpreter evaluates.

use serde_json::Value;

use super::error::Pos;
use crate::trace::Env;

/// A checked program with its source text.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// The program text.
    pub source: String,
    /// The environment it was checked for.
    pub env: Env,
    /// The root expression.
    pub root: Node,
}

/// A checked expression with its position and source span.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// What it computes.
    pub kind: NodeKind,
    /// Where it starts.
    pub pos: Pos,
    /// Byte span in the source.
    pub span: (usize, usize),
}

/// How a count is compared with its target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cmp {
    /// `COUNT`: exactly n.
    Eq,
    /// `GT`: more than n.
    Gt,
    /// `LT`: fewer than n.
    Lt,
    /// `PATTERN_COUNT`: at least n.
    AtLeast,
}

/// The checked forms of the DSL's functions.
#[derive(Debug, Clone, PartialEq)]
pub enum NodeKind {
    /// `PATTERN(label, {params}, ball=, contains=, key=value…)`: the pattern occurs (an event).
    Pattern(PatternRef),
    /// `PATTERN_COUNT(label, …, min_count=n)`: at least n occurrences; as an event, it happens when
    /// the n-th occurrence starts.
    PatternCount {
        /// The pattern.
        pattern: PatternRef,
        /// The minimum.
        min_count: u64,
    },
    /// `COUNT` / `GT` / `LT`: the number of occurrences compared with `n`.
    Count {
        /// The pattern.
        pattern: PatternRef,
        /// The target.
        n: u64,
        /// The comparison.
        cmp: Cmp,
    },
    /// `CUE_HIT(ball)`: the first ball the cue ball touches is `ball` (an event at that contact).
    CueHit(ObjRef),
    /// `POCKETED(ball, pocket?)`: billiards, `ball` drops (into `pocket`), from the trace's
    /// `physics_ball_pocket` events (an event at the drop).
    Pocketed {
        /// The ball.
        ball: ObjRef,
        /// The pocket id (`lb`, `lc`, `lt`, `rb`, `rc`, `rt`), any when absent.
        pocket: Option<String>,
    },
    /// `AFTER(a, b, …)` / `WITHIN(a, b, window, …)`: an occurrence of `a` starts no earlier than one of
    /// `b`, with `min_delta <= t_a - t_b <= max_delta`; as an event, the qualifying occurrences of `a`.
    After {
        /// The later event.
        a: Box<Node>,
        /// The earlier event.
        b: Box<Node>,
        /// Smallest allowed delay (s); 0 when absent.
        min_delta: Option<f64>,
        /// Largest allowed delay (s).
        max_delta: Option<f64>,
    },
    /// `AND(…)`.
    And(Vec<Node>),
    /// `OR(…)`; an event when every operand is one (the union of their occurrences).
    Or(Vec<Node>),
    /// `NOT(x)`.
    Not(Box<Node>),
    /// `NEARBY_AT(obj, x, y, t, threshold_strength)`.
    NearbyAt {
        /// The object.
        obj: ObjRef,
        /// Target x (environment units).
        x: f64,
        /// Target y (environment units).
        y: f64,
        /// Normalised time in [0, 1] (0 = first timestep, 1 = last).
        t: f64,
        /// Threshold as a fraction of the environment's scale.
        threshold: f64,
    },
    /// `NEAR(a, b, threshold_strength)`: at some timestep the outlines of an object `a` and a
    /// different object `b` are within `threshold_strength × scale` of each other.
    Near {
        /// One object (with `OBJECT_ID`, PHYRE / I-PHYRE: any object of that colour and shape).
        a: ObjRef,
        /// The other.
        b: ObjRef,
        /// Threshold as a fraction of the environment's scale.
        threshold: f64,
    },
}

impl NodeKind {
    /// Whether the node has occurrences in time (can be an argument of `AFTER`/`WITHIN`).
    pub fn is_event(&self) -> bool {
        match self {
            NodeKind::Pattern(_)
            | NodeKind::PatternCount { .. }
            | NodeKind::CueHit(_)
            | NodeKind::Pocketed { .. }
            | NodeKind::After { .. } => true,
            NodeKind::Or(xs) => xs.iter().all(|x| x.kind.is_event()),
            _ => false,
        }
    }

    /// Whether the node scores by distance to satisfaction rather than 0/1 (counts, `NEARBY_AT` and
    /// `NEAR`).
    pub fn is_quantitative(&self) -> bool {
        matches!(
            self,
            NodeKind::PatternCount { .. }
                | NodeKind::Count { .. }
                | NodeKind::NearbyAt { .. }
                | NodeKind::Near { .. }
        )
    }
}

/// A pattern label with the filters its occurrences must pass.
#[derive(Debug, Clone, PartialEq)]
pub struct PatternRef {
    /// The library's canonical label.
    pub label: String,
    /// The filters.
    pub filter: Filter,
}

/// Filters on a pattern's occurrences; all must hold.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Filter {
    /// `ball=`: the pattern's subject (its first object).
    pub ball: Option<ObjRef>,
    /// `contains=[…]`: objects it must name.
    pub contains: Vec<ObjRef>,
    /// Other keys: the pattern's parameter must equal the value (strings ignoring case, numbers by value).
    pub params: Vec<(String, Value)>,
}

/// An object named by id or looked up by colour and shape.
#[derive(Debug, Clone, PartialEq)]
pub enum ObjRef {
    /// An object id (`"cue"`, `"8"`, `"3"`).
    Id(String),
    /// `OBJECT_ID(color, shape)`, resolved against the trace's first timestep.
    Lookup {
        /// The colour.
        color: String,
        /// The shape.
        shape: String,
        /// Where the call is (for runtime errors).
        pos: Pos,
    },
}
