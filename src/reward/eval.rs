//! The interpreter: a [`Program`] on an [`AnnotatedTrace`] gives a boolean success and a dense reward
//! in [0, 1].
//!
//! Partial credit, as in the paper (section 3.4): a top-level `AND` scores the mean of its clauses; a
//! clause (or a whole program that is not an `AND`) scores 1/0 by its truth, except the quantitative
//! primitives, which score their distance to satisfaction with an inverse-log shaping clamped to
//! [0, 1] ([`shape`]): `NEARBY_AT` the distance beyond the threshold radius (as a multiple of it),
//! `NEAR` the smallest gap between two objects' outlines beyond its radius (the same way),
//! `COUNT`/`GT`/`LT`/`PATTERN_COUNT` the number of occurrences missing or in excess. Success is the
//! truth of the whole expression, so a program scores 1 exactly when it succeeds.

use serde_json::Value;

use super::error::RewardError;
use super::facts::{AnnotatedTrace, Occurrence, nearby_scale};
use super::program::{Cmp, Filter, Node, NodeKind, ObjRef, PatternRef, Program};

/// The inverse-log shaping of a deviation `d >= 0` (0 = satisfied): `1 / (1 + ln(1 + d))`, in (0, 1].
/// It falls fastest near 0, so improvements close to the target are weighted most.
pub fn shape(d: f64) -> f64 {
    if d.is_nan() {
        return 0.0;
    }
    (1.0 / (1.0 + d.max(0.0).ln_1p())).clamp(0.0, 1.0)
}

/// The value of one top-level clause.
#[derive(Debug, Clone, PartialEq)]
pub struct ClauseValue {
    /// The clause's source text.
    pub text: String,
    /// Whether it holds.
    pub truth: bool,
    /// Its score in [0, 1].
    pub score: f64,
}

/// The result of a program on a trace.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// Whether the whole expression holds.
    pub success: bool,
    /// The dense reward in [0, 1].
    pub score: f64,
    /// The top-level clauses (the operands of a top-level AND, or the expression itself).
    pub clauses: Vec<ClauseValue>,
}

/// Evaluates `program` on `trace`.
pub fn evaluate(program: &Program, trace: &AnnotatedTrace<'_>) -> Result<Evaluation, RewardError> {
    let ev = Eval { trace, program };
    let clauses: Vec<&Node> = match &program.root.kind {
        NodeKind::And(xs) => xs.iter().collect(),
        _ => vec![&program.root],
    };
    let mut out = Vec::with_capacity(clauses.len());
    for c in &clauses {
        let truth = ev.truth(c)?;
        let score = if truth {
            1.0
        } else if c.kind.is_quantitative() {
            ev.graded(c)?
        } else {
            0.0
        };
        out.push(ClauseValue {
            text: program
                .source
                .get(c.span.0..c.span.1)
                .unwrap_or("")
                .to_string(),
            truth,
            score,
        });
    }
    let success = out.iter().all(|c| c.truth);
    let score = if success {
        1.0
    } else {
        out.iter().map(|c| c.score).sum::<f64>() / out.len().max(1) as f64
    };
    Ok(Evaluation {
        success,
        score,
        clauses: out,
    })
}

struct Eval<'a, 'b> {
    trace: &'a AnnotatedTrace<'b>,
    program: &'a Program,
}

fn num(v: &Value) -> Option<f64> {
    match v {
        Value::Number(n) => n.as_f64(),
        Value::String(s) => s.trim().parse().ok(),
        _ => None,
    }
}

/// Whether a pattern's parameter value `have` matches the wanted `want`: strings ignoring case,
/// numbers by value (a numeric string matches its number), lists element by element in any order.
pub fn value_matches(want: &Value, have: &Value) -> bool {
    match (want, have) {
        (Value::Null, Value::Null) => true,
        (Value::Bool(a), Value::Bool(b)) => a == b,
        (Value::Array(w), Value::Array(h)) => {
            w.len() == h.len() && w.iter().all(|x| h.iter().any(|y| value_matches(x, y)))
        }
        (Value::String(a), Value::String(b)) if a.trim().eq_ignore_ascii_case(b.trim()) => true,
        (Value::Number(_) | Value::String(_), Value::Number(_) | Value::String(_)) => {
            match (num(want), num(have)) {
                (Some(a), Some(b)) => (a - b).abs() <= 1e-9 * a.abs().max(1.0),
                _ => false,
            }
        }
        _ => false,
    }
}

impl Eval<'_, '_> {
    fn id(&self, o: &ObjRef) -> Result<String, RewardError> {
        match o {
            ObjRef::Id(s) => Ok(s.clone()),
            ObjRef::Lookup { color, shape, pos } => self.trace.object_id(color, shape, *pos),
        }
    }

    /// The ids an object reference stands for: an id, or with `OBJECT_ID` every object of that
    /// colour and shape (PHYRE, I-PHYRE; billiards: one ball).
    fn ids(&self, o: &ObjRef) -> Result<Vec<String>, RewardError> {
        match o {
            ObjRef::Id(s) => Ok(vec![s.clone()]),
            ObjRef::Lookup { color, shape, pos } => self.trace.object_ids(color, shape, *pos),
        }
    }

    fn passes(&self, f: &Filter, o: &Occurrence) -> Result<bool, RewardError> {
        let same = |a: &str, b: &str| value_matches(&Value::from(a), &Value::from(b));
        if let Some(b) = &f.ball {
            let ids = self.ids(b)?;
            let subject = o
                .objects
                .first()
                .map(String::as_str)
                .or_else(|| o.params.get("ball").and_then(Value::as_str));
            if !subject.is_some_and(|s| ids.iter().any(|id| same(s, id))) {
                return Ok(false);
            }
        }
        // `contains=[…]`: each reference names a different object of the pattern (two
        // `OBJECT_ID("red", "ball")` need two red balls).
        let mut wanted = Vec::with_capacity(f.contains.len());
        for c in &f.contains {
            wanted.push(self.ids(c)?);
        }
        fn assign(wanted: &[Vec<String>], objects: &[String], used: &mut Vec<bool>) -> bool {
            let Some((first, rest)) = wanted.split_first() else {
                return true;
            };
            for (k, x) in objects.iter().enumerate() {
                if !used[k]
                    && first.iter().any(|id| {
                        value_matches(&Value::from(x.as_str()), &Value::from(id.as_str()))
                    })
                {
                    used[k] = true;
                    if assign(rest, objects, used) {
                        return true;
                    }
                    used[k] = false;
                }
            }
            false
        }
        if !assign(&wanted, &o.objects, &mut vec![false; o.objects.len()]) {
            return Ok(false);
        }
        for (k, want) in &f.params {
            let have = o.params.get(k).or_else(|| {
                o.params
                    .iter()
                    .find(|(hk, _)| hk.eq_ignore_ascii_case(k))
                    .map(|(_, v)| v)
            });
            if !have.is_some_and(|h| value_matches(want, h)) {
                return Ok(false);
            }
        }
        Ok(true)
    }

    fn pattern(&self, p: &PatternRef) -> Result<Vec<Occurrence>, RewardError> {
        let mut out = Vec::new();
        for o in self.trace.occurrences(&p.label) {
            if self.passes(&p.filter, o)? {
                out.push(o.clone());
            }
        }
        Ok(out)
    }

    /// The occurrences of an event node, in start order.
    fn occurrences(&self, n: &Node) -> Result<Vec<Occurrence>, RewardError> {
        Ok(match &n.kind {
            NodeKind::Pattern(p) => self.pattern(p)?,
            NodeKind::PatternCount { pattern, min_count } => {
                let all = self.pattern(pattern)?;
                let k = (*min_count).max(1) as usize;
                all.get(k - 1).cloned().into_iter().collect()
            }
            NodeKind::Pocketed { ball, pocket } => {
                let id = Value::from(self.id(ball)?);
                self.trace
                    .pockets()
                    .iter()
                    .filter(|(b, p, _)| {
                        value_matches(&id, &Value::from(b.as_str()))
                            && pocket
                                .as_ref()
                                .is_none_or(|want| want.eq_ignore_ascii_case(p))
                    })
                    .map(|(_, _, o)| o.clone())
                    .collect()
            }
            NodeKind::CueHit(b) => {
                let id = self.id(b)?;
                match self.trace.cue_hit() {
                    Some((hit, o))
                        if value_matches(&Value::from(hit.as_str()), &Value::from(id)) =>
                    {
                        vec![o.clone()]
                    }
                    _ => Vec::new(),
                }
            }
            NodeKind::After {
                a,
                b,
                min_delta,
                max_delta,
            } => {
                let (xa, xb) = (self.occurrences(a)?, self.occurrences(b)?);
                let lo = min_delta.unwrap_or(0.0);
                let hi = max_delta.unwrap_or(f64::INFINITY);
                xa.into_iter()
                    .filter(|oa| {
                        xb.iter().any(|ob| {
                            let d = oa.t0 - ob.t0;
                            d >= lo - 1e-9 && d <= hi + 1e-9
                        })
                    })
                    .collect()
            }
            NodeKind::Or(xs) => {
                let mut all = Vec::new();
                for x in xs {
                    all.extend(self.occurrences(x)?);
                }
                all.sort_by(|x, y| x.t0.total_cmp(&y.t0));
                all
            }
            _ => Vec::new(),
        })
    }

    fn count(&self, p: &PatternRef) -> Result<u64, RewardError> {
        Ok(self.pattern(p)?.len() as u64)
    }

    /// How far a count is from satisfying its comparison (0 = satisfied).
    fn count_deviation(c: u64, n: u64, cmp: Cmp) -> f64 {
        let (c, n) = (c as f64, n as f64);
        match cmp {
            Cmp::Eq => (c - n).abs(),
            Cmp::Gt => (n + 1.0 - c).max(0.0),
            Cmp::Lt => (c - (n - 1.0)).max(0.0),
            Cmp::AtLeast => (n - c).max(0.0),
        }
    }

    fn nearby_deviation(
        &self,
        n: &Node,
        obj: &ObjRef,
        x: f64,
        y: f64,
        t: f64,
        threshold: f64,
    ) -> Result<f64, RewardError> {
        let id = self.id(obj)?;
        let (px, py) = self.trace.position_at(&id, t, n.pos)?;
        let r = threshold * nearby_scale(self.program.env);
        let d = ((px - x).powi(2) + (py - y).powi(2)).sqrt();
        Ok(if d <= r { 0.0 } else { d / r - 1.0 })
    }

    /// How far two objects stay from touching, in threshold radii beyond the radius (0 = within it).
    fn near_deviation(
        &self,
        n: &Node,
        a: &ObjRef,
        b: &ObjRef,
        threshold: f64,
    ) -> Result<f64, RewardError> {
        let gap = self.trace.min_gap(&self.ids(a)?, &self.ids(b)?, n.pos)?;
        let r = threshold * nearby_scale(self.program.env);
        Ok(if gap <= r { 0.0 } else { gap / r - 1.0 })
    }

    fn truth(&self, n: &Node) -> Result<bool, RewardError> {
        Ok(match &n.kind {
            NodeKind::Pattern(_)
            | NodeKind::CueHit(_)
            | NodeKind::Pocketed { .. }
            | NodeKind::After { .. }
            | NodeKind::PatternCount { .. } => !self.occurrences(n)?.is_empty(),
            NodeKind::Count { pattern, n: k, cmp } => {
                Self::count_deviation(self.count(pattern)?, *k, *cmp) == 0.0
            }
            NodeKind::And(xs) => {
                for x in xs {
                    if !self.truth(x)? {
                        return Ok(false);
                    }
                }
                true
            }
            NodeKind::Or(xs) => {
                for x in xs {
                    if self.truth(x)? {
                        return Ok(true);
                    }
                }
                false
            }
            NodeKind::Not(x) => !self.truth(x)?,
            NodeKind::NearbyAt {
                obj,
                x,
                y,
                t,
                threshold,
            } => self.nearby_deviation(n, obj, *x, *y, *t, *threshold)? == 0.0,
            NodeKind::Near { a, b, threshold } => self.near_deviation(n, a, b, *threshold)? == 0.0,
        })
    }

    /// The graded score of a quantitative node.
    fn graded(&self, n: &Node) -> Result<f64, RewardError> {
        Ok(match &n.kind {
            NodeKind::Count { pattern, n: k, cmp } => {
                shape(Self::count_deviation(self.count(pattern)?, *k, *cmp))
            }
            NodeKind::PatternCount { pattern, min_count } => shape(Self::count_deviation(
                self.count(pattern)?,
                *min_count,
                Cmp::AtLeast,
            )),
            NodeKind::NearbyAt {
                obj,
                x,
                y,
                t,
                threshold,
            } => shape(self.nearby_deviation(n, obj, *x, *y, *t, *threshold)?),
            NodeKind::Near { a, b, threshold } => shape(self.near_deviation(n, a, b, *threshold)?),
            _ => {
                if self.truth(n)? {
                    1.0
                } else {
                    0.0
                }
            }
        })
    }
}
