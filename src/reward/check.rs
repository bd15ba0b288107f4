//! The checker: a syntax tree to a typed [`Program`], against a [`Schema`]. Every mistake is a
//! [`RewardError`] with its category and the position of the offending token.

use serde_json::{Value, json};

use super::error::{ErrorCategory, Pos, RewardError};
use super::parser::{Arg, Expr, ExprKind, parse};
use super::program::{Cmp, Filter, Node, NodeKind, ObjRef, PatternRef, Program};
use super::schema::Schema;
use crate::trace::Env;

/// The DSL's function names (upper case; calls are matched ignoring case).
pub const FUNCTION_NAMES: &[&str] = &[
    "PATTERN",
    "PATTERN_COUNT",
    "AND",
    "OR",
    "NOT",
    "AFTER",
    "WITHIN",
    "COUNT",
    "GT",
    "LT",
    "NEARBY_AT",
    "NEAR",
    "OBJECT_ID",
    "CUE_HIT",
    "POCKETED",
];

/// Parses and checks `text` against `schema`.
pub fn compile(text: &str, schema: &Schema) -> Result<Program, RewardError> {
    let ast = parse(text)?;
    let root = Checker { schema }.node(&ast)?;
    Ok(Program {
        source: text.to_string(),
        env: schema.env,
        root,
    })
}

struct Checker<'a> {
    schema: &'a Schema,
}

fn err(category: ErrorCategory, pos: Pos, message: impl Into<String>) -> RewardError {
    RewardError::new(category, pos, message)
}

/// Arguments bound to parameter names.
struct Bound<'e> {
    slots: Vec<Option<&'e Expr>>,
    /// Keyword arguments that are not named parameters (pattern filters), in order.
    extra: Vec<(&'e str, Pos, &'e Expr)>,
}

impl<'e> Bound<'e> {
    fn get(&self, i: usize) -> Option<&'e Expr> {
        self.slots[i].filter(|e| e.kind != ExprKind::None)
    }
}

/// Binds `args` to `names` (positional then keyword); the first `required` are mandatory. With
/// `filters`, unknown keywords are kept as pattern filters; otherwise they are arity errors.
fn bind<'e>(
    fname: &str,
    pos: Pos,
    args: &'e [Arg],
    names: &[&str],
    required: usize,
    filters: bool,
) -> Result<Bound<'e>, RewardError> {
    let mut slots: Vec<Option<&Expr>> = vec![None; names.len()];
    let mut extra = Vec::new();
    let mut seen_kw = false;
    let mut n_pos = 0;
    for a in args {
        match &a.name {
            None => {
                if seen_kw {
                    return Err(err(
                        ErrorCategory::Syntax,
                        a.value.pos,
                        format!("{fname}: positional argument after a keyword argument"),
                    ));
                }
                if n_pos >= names.len() {
                    return Err(err(
                        ErrorCategory::Arity,
                        a.value.pos,
                        format!(
                            "{fname} takes at most {} positional argument(s) ({}), found more",
                            names.len(),
                            names.join(", ")
                        ),
                    ));
                }
                slots[n_pos] = Some(&a.value);
                n_pos += 1;
            }
            Some((k, kpos)) => {
                seen_kw = true;
                match names.iter().position(|n| n == k) {
                    Some(i) if slots[i].is_some() => {
                        return Err(err(
                            ErrorCategory::Arity,
                            *kpos,
                            format!("{fname}: argument `{k}` given twice"),
                        ));
                    }
                    Some(i) => slots[i] = Some(&a.value),
                    None if filters => {
                        if extra.iter().any(|(e, _, _)| e == k) {
                            return Err(err(
                                ErrorCategory::Arity,
                                *kpos,
                                format!("{fname}: keyword `{k}` given twice"),
                            ));
                        }
                        extra.push((k.as_str(), *kpos, &a.value));
                    }
                    None => {
                        return Err(err(
                            ErrorCategory::Arity,
                            *kpos,
                            format!(
                                "{fname} has no argument `{k}` (its arguments: {})",
                                names.join(", ")
                            ),
                        ));
                    }
                }
            }
        }
    }
    if let Some(i) = (0..required).find(|&i| slots[i].is_none()) {
        return Err(err(
            ErrorCategory::Arity,
            pos,
            format!(
                "{fname} needs {required} argument(s) ({}); `{}` is missing",
                names[..required].join(", "),
                names[i]
            ),
        ));
    }
    Ok(Bound { slots, extra })
}

/// The optional `threshold_strength` argument of `NEAR` and `NEARBY_AT` (`what`): above 0, default 0.1.
fn threshold_strength(f: &str, what: &str, arg: Option<&Expr>) -> Result<f64, RewardError> {
    let Some(x) = arg else { return Ok(0.1) };
    let v = number(f, "threshold_strength", x)?;
    if v <= 0.0 {
        return Err(err(
            ErrorCategory::ArgumentType,
            x.pos,
            format!("{what}: `threshold_strength` must be > 0, found {v}"),
        ));
    }
    Ok(v)
}

fn number(fname: &str, what: &str, e: &Expr) -> Result<f64, RewardError> {
    match e.kind {
        ExprKind::Num(n) => Ok(n),
        _ => Err(err(
            ErrorCategory::ArgumentType,
            e.pos,
            format!(
                "{fname}: `{what}` must be a number, found {}",
                e.type_name()
            ),
        )),
    }
}

fn count(fname: &str, what: &str, e: &Expr) -> Result<u64, RewardError> {
    let n = number(fname, what, e)?;
    if n < 0.0 || n.fract() != 0.0 || n > 1e9 {
        return Err(err(
            ErrorCategory::ArgumentType,
            e.pos,
            format!("{fname}: `{what}` must be a whole number >= 0, found {n}"),
        ));
    }
    Ok(n as u64)
}

/// A JSON value from a literal (strings, numbers, booleans and lists of them).
fn literal(fname: &str, e: &Expr) -> Result<Value, RewardError> {
    Ok(match &e.kind {
        ExprKind::Str(s) => json!(s),
        ExprKind::Num(n) => json!(n),
        ExprKind::Bool(b) => json!(b),
        ExprKind::None => Value::Null,
        ExprKind::List(xs) => Value::Array(
            xs.iter()
                .map(|x| literal(fname, x))
                .collect::<Result<_, _>>()?,
        ),
        _ => {
            return Err(err(
                ErrorCategory::ArgumentType,
                e.pos,
                format!(
                    "{fname}: a parameter value must be a string, number, boolean or list, found {}",
                    e.type_name()
                ),
            ));
        }
    })
}

fn id_text(n: f64) -> String {
    if n.fract() == 0.0 && n.abs() < 1e15 {
        format!("{}", n as i64)
    } else {
        n.to_string()
    }
}

impl Checker<'_> {
    fn node(&self, e: &Expr) -> Result<Node, RewardError> {
        let ExprKind::Call { name, args } = &e.kind else {
            return Err(err(
                ErrorCategory::ArgumentType,
                e.pos,
                format!(
                    "expected a predicate such as PATTERN(\"label\") or AND(...), found {}",
                    e.type_name()
                ),
            ));
        };
        let upper = name.to_ascii_uppercase();
        let f = upper.as_str();
        let kind = match f {
            "AND" | "OR" => self.junction(f, e.pos, args)?,
            "NOT" => {
                let b = bind(f, e.pos, args, &["expr"], 1, false)?;
                NodeKind::Not(Box::new(self.node(b.slots[0].expect("required"))?))
            }
            "PATTERN" => {
                let b = bind(f, e.pos, args, &["label", "params"], 1, true)?;
                NodeKind::Pattern(self.pattern(f, &b, 0, Some(1))?)
            }
            "PATTERN_COUNT" => {
                let b = bind(f, e.pos, args, &["label", "params", "min_count"], 1, true)?;
                let min_count = match b.get(2) {
                    Some(x) => count(f, "min_count", x)?,
                    None => 1,
                };
                NodeKind::PatternCount {
                    pattern: self.pattern(f, &b, 0, Some(1))?,
                    min_count,
                }
            }
            "COUNT" | "GT" | "LT" => {
                let b = bind(f, e.pos, args, &["label", "count", "params"], 2, true)?;
                let n = count(f, "count", b.slots[1].expect("required"))?;
                let cmp = match f {
                    "COUNT" => Cmp::Eq,
                    "GT" => Cmp::Gt,
                    _ => Cmp::Lt,
                };
                NodeKind::Count {
                    pattern: self.pattern(f, &b, 0, Some(2))?,
                    n,
                    cmp,
                }
            }
            "CUE_HIT" | "POCKETED" => self.billiards_fact(f, e.pos, args)?,
            "AFTER" | "WITHIN" => self.after(f, e.pos, args)?,
            "NEARBY_AT" => self.nearby_at(f, e.pos, args)?,
            "NEAR" => self.near(f, e.pos, args)?,
            "OBJECT_ID" => {
                return Err(err(
                    ErrorCategory::ArgumentType,
                    e.pos,
                    "OBJECT_ID returns an object id, not a predicate: use it as an argument of NEARBY_AT, \
                     NEAR, CUE_HIT or a ball= filter",
                ));
            }
            _ => {
                return Err(err(
                    ErrorCategory::UnknownFunction,
                    e.pos,
                    format!(
                        "unknown function `{name}` (the DSL has {})",
                        FUNCTION_NAMES.join(", ")
                    ),
                ));
            }
        };
        Ok(Node {
            kind,
            pos: e.pos,
            span: e.span,
        })
    }

    /// `AND(...)` and `OR(...)`: one or more expressions, no keywords.
    fn junction(&self, f: &str, pos: Pos, args: &[Arg]) -> Result<NodeKind, RewardError> {
        if let Some(a) = args.iter().find(|a| a.name.is_some()) {
            let (k, p) = a.name.as_ref().expect("checked");
            return Err(err(
                ErrorCategory::Arity,
                *p,
                format!("{f} takes expressions only, not the keyword `{k}`"),
            ));
        }
        if args.is_empty() {
            return Err(err(
                ErrorCategory::Arity,
                pos,
                format!("{f} needs at least one expression"),
            ));
        }
        let xs = args
            .iter()
            .map(|a| self.node(&a.value))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(if f == "AND" {
            NodeKind::And(xs)
        } else {
            NodeKind::Or(xs)
        })
    }

    /// `CUE_HIT(ball)` and `POCKETED(ball, pocket)`: billiards facts, unknown in other environments.
    fn billiards_fact(&self, f: &str, pos: Pos, args: &[Arg]) -> Result<NodeKind, RewardError> {
        if self.schema.env != Env::Pooltool {
            return Err(err(
                ErrorCategory::UnknownFunction,
                pos,
                format!(
                    "{f} is a billiards fact; it does not exist for {}",
                    self.schema.env
                ),
            ));
        }
        if f == "POCKETED" {
            let b = bind(f, pos, args, &["ball", "pocket"], 1, false)?;
            let pocket = match b.get(1) {
                None => None,
                Some(x) => match &x.kind {
                    ExprKind::Str(s) => Some(s.clone()),
                    _ => {
                        return Err(err(
                            ErrorCategory::ArgumentType,
                            x.pos,
                            format!(
                                "POCKETED: `pocket` is a pocket id string (lb, lc, lt, rb, rc, rt), found {}",
                                x.type_name()
                            ),
                        ));
                    }
                },
            };
            Ok(NodeKind::Pocketed {
                ball: self.obj(f, b.slots[0].expect("required"))?,
                pocket,
            })
        } else {
            let b = bind(f, pos, args, &["ball"], 1, false)?;
            Ok(NodeKind::CueHit(
                self.obj(f, b.slots[0].expect("required"))?,
            ))
        }
    }

    /// `NEAR(a, b, threshold_strength)`: two objects, the threshold above 0 (default 0.1).
    fn near(&self, f: &str, pos: Pos, args: &[Arg]) -> Result<NodeKind, RewardError> {
        let b = bind(f, pos, args, &["a", "b", "threshold_strength"], 2, false)?;
        let threshold = threshold_strength(f, "NEAR", b.get(2))?;
        Ok(NodeKind::Near {
            a: self.obj(f, b.slots[0].expect("required"))?,
            b: self.obj(f, b.slots[1].expect("required"))?,
            threshold,
        })
    }

    /// `NEARBY_AT(obj_id, x, y, t, threshold_strength)`: `t` in [0, 1], the threshold above 0
    /// (default 0.1).
    fn nearby_at(&self, f: &str, pos: Pos, args: &[Arg]) -> Result<NodeKind, RewardError> {
        let b = bind(
            f,
            pos,
            args,
            &["obj_id", "x", "y", "t", "threshold_strength"],
            4,
            false,
        )?;
        let x = number(f, "x", b.slots[1].expect("required"))?;
        let y = number(f, "y", b.slots[2].expect("required"))?;
        let te = b.slots[3].expect("required");
        let t = number(f, "t", te)?;
        if !(0.0..=1.0).contains(&t) {
            return Err(err(
                ErrorCategory::ArgumentType,
                te.pos,
                format!("NEARBY_AT: `t` is normalised time in [0, 1], found {t}"),
            ));
        }
        let threshold = threshold_strength(f, "NEARBY_AT", b.get(4))?;
        Ok(NodeKind::NearbyAt {
            obj: self.obj(f, b.slots[0].expect("required"))?,
            x,
            y,
            t,
            threshold,
        })
    }

    /// `AFTER(a, b, min_delta, max_delta, first_params, second_params)` and
    /// `WITHIN(a, b, window, event_params, reference_params)`.
    fn after(&self, f: &str, pos: Pos, args: &[Arg]) -> Result<NodeKind, RewardError> {
        let within = f == "WITHIN";
        let names: &[&str] = if within {
            &["a", "b", "window", "event_params", "reference_params"]
        } else {
            &[
                "a",
                "b",
                "min_delta",
                "max_delta",
                "first_params",
                "second_params",
            ]
        };
        let b = bind(f, pos, args, names, if within { 3 } else { 2 }, false)?;
        let delta = |i: usize| -> Result<Option<f64>, RewardError> {
            b.get(i).map(|x| number(f, names[i], x)).transpose()
        };
        let (min_delta, max_delta, p1, p2) = if within {
            (Some(0.0), delta(2)?, 3, 4)
        } else {
            (delta(2)?, delta(3)?, 4, 5)
        };
        if let (Some(lo), Some(hi)) = (min_delta, max_delta)
            && lo > hi
        {
            return Err(err(
                ErrorCategory::ArgumentType,
                pos,
                format!("{f}: the smallest delay {lo} is larger than the largest {hi}"),
            ));
        }
        let a = self.event_arg(f, b.slots[0].expect("required"), b.get(p1), names[p1])?;
        let bb = self.event_arg(f, b.slots[1].expect("required"), b.get(p2), names[p2])?;
        Ok(NodeKind::After {
            a: Box::new(a),
            b: Box::new(bb),
            min_delta,
            max_delta,
        })
    }

    /// An argument of AFTER/WITHIN: a label (with optional params) or an event expression.
    fn event_arg(
        &self,
        f: &str,
        e: &Expr,
        params: Option<&Expr>,
        pname: &str,
    ) -> Result<Node, RewardError> {
        match &e.kind {
            ExprKind::Str(label) => {
                let info = self.label(label, e.pos)?;
                let mut filter = Filter::default();
                if let Some(p) = params {
                    self.params_map(f, &info.label, p, &mut filter)?;
                }
                Ok(Node {
                    kind: NodeKind::Pattern(PatternRef {
                        label: info.label.clone(),
                        filter,
                    }),
                    pos: e.pos,
                    span: e.span,
                })
            }
            ExprKind::Call { .. } => {
                let mut n = self.node(e)?;
                if !n.kind.is_event() {
                    return Err(err(
                        ErrorCategory::ArgumentType,
                        e.pos,
                        format!(
                            "{f} orders events in time: this argument must be a label, PATTERN, PATTERN_COUNT, \
                             CUE_HIT, POCKETED, AFTER, WITHIN or an OR of those, found `{}`",
                            match &e.kind {
                                ExprKind::Call { name, .. } => name.as_str(),
                                _ => "?",
                            }
                        ),
                    ));
                }
                if let Some(p) = params {
                    match &mut n.kind {
                        NodeKind::Pattern(pr) | NodeKind::PatternCount { pattern: pr, .. } => {
                            let label = pr.label.clone();
                            self.params_map(f, &label, p, &mut pr.filter)?;
                        }
                        _ => {
                            return Err(err(
                                ErrorCategory::ArgumentType,
                                p.pos,
                                format!(
                                    "{f}: `{pname}` filters a label or PATTERN argument, not this expression"
                                ),
                            ));
                        }
                    }
                }
                Ok(n)
            }
            _ => Err(err(
                ErrorCategory::ArgumentType,
                e.pos,
                format!(
                    "{f}: expected a label string or an event expression, found {}",
                    e.type_name()
                ),
            )),
        }
    }

    fn label(&self, name: &str, pos: Pos) -> Result<&super::schema::LabelInfo, RewardError> {
        self.schema.resolve(name).ok_or_else(|| {
            err(
                ErrorCategory::UnknownLabel,
                pos,
                format!(
                    "unknown pattern label {name:?}; the library {} has: {}",
                    self.schema.library,
                    self.schema
                        .labels
                        .iter()
                        .map(|l| format!("{:?}", l.label))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )
        })
    }

    /// The label in slot `li` and the filters: the map in slot `pi` plus the extra keywords.
    fn pattern(
        &self,
        f: &str,
        b: &Bound<'_>,
        li: usize,
        pi: Option<usize>,
    ) -> Result<PatternRef, RewardError> {
        let le = b.slots[li].expect("required");
        let ExprKind::Str(name) = &le.kind else {
            return Err(err(
                ErrorCategory::ArgumentType,
                le.pos,
                format!(
                    "{f}: the first argument must be a pattern label string, found {}",
                    le.type_name()
                ),
            ));
        };
        let info = self.label(name, le.pos)?;
        let label = info.label.clone();
        let mut filter = Filter::default();
        if let Some(p) = pi.and_then(|i| b.get(i)) {
            self.params_map(f, &label, p, &mut filter)?;
        }
        for (k, kpos, v) in &b.extra {
            self.filter_entry(f, &label, k, *kpos, v, &mut filter)?;
        }
        Ok(PatternRef { label, filter })
    }

    fn params_map(
        &self,
        f: &str,
        label: &str,
        e: &Expr,
        filter: &mut Filter,
    ) -> Result<(), RewardError> {
        let ExprKind::Map(items) = &e.kind else {
            return Err(err(
                ErrorCategory::ArgumentType,
                e.pos,
                format!(
                    "{f}: parameters must be a map like {{\"key\": value}}, found {}",
                    e.type_name()
                ),
            ));
        };
        for (k, kpos, v) in items {
            self.filter_entry(f, label, k, *kpos, v, filter)?;
        }
        Ok(())
    }

    fn filter_entry(
        &self,
        f: &str,
        label: &str,
        key: &str,
        kpos: Pos,
        v: &Expr,
        filter: &mut Filter,
    ) -> Result<(), RewardError> {
        match key {
            "ball" => filter.ball = Some(self.obj(f, v)?),
            "contains" => {
                let items: Vec<&Expr> = match &v.kind {
                    ExprKind::List(xs) => xs.iter().collect(),
                    _ => vec![v],
                };
                for x in items {
                    filter.contains.push(self.obj(f, x)?);
                }
            }
            _ => {
                let info = self.schema.resolve(label).expect("resolved before");
                if !self.schema.key_known(info, key) {
                    let known: Vec<String> = info
                        .keys
                        .iter()
                        .flatten()
                        .cloned()
                        .chain(super::schema::BUILTIN_KEYS.iter().map(|s| s.to_string()))
                        .collect();
                    return Err(err(
                        ErrorCategory::UnknownParameter,
                        kpos,
                        format!(
                            "{f}: patterns of {label:?} have no parameter `{key}` (they have: {})",
                            known.join(", ")
                        ),
                    ));
                }
                filter.params.push((key.to_string(), literal(f, v)?));
            }
        }
        Ok(())
    }

    fn obj(&self, f: &str, e: &Expr) -> Result<ObjRef, RewardError> {
        match &e.kind {
            ExprKind::Str(s) => Ok(ObjRef::Id(s.clone())),
            ExprKind::Num(n) => Ok(ObjRef::Id(id_text(*n))),
            ExprKind::Call { name, args } if name.eq_ignore_ascii_case("OBJECT_ID") => {
                let b = bind("OBJECT_ID", e.pos, args, &["color", "shape"], 2, false)?;
                let s = |i: usize| -> Result<String, RewardError> {
                    let x = b.slots[i].expect("required");
                    match &x.kind {
                        ExprKind::Str(s) => Ok(s.to_lowercase()),
                        _ => Err(err(
                            ErrorCategory::ArgumentType,
                            x.pos,
                            format!("OBJECT_ID: expected a string, found {}", x.type_name()),
                        )),
                    }
                };
                Ok(ObjRef::Lookup {
                    color: s(0)?,
                    shape: s(1)?,
                    pos: e.pos,
                })
            }
            ExprKind::Call { name, .. }
                if !FUNCTION_NAMES.contains(&name.to_ascii_uppercase().as_str()) =>
            {
                Err(err(
                    ErrorCategory::UnknownFunction,
                    e.pos,
                    format!("unknown function `{name}`"),
                ))
            }
            _ => Err(err(
                ErrorCategory::ArgumentType,
                e.pos,
                format!(
                    "{f}: expected an object id (a string such as \"cue\", a number, or OBJECT_ID(color, shape)), found {}",
                    e.type_name()
                ),
            )),
        }
    }
}
