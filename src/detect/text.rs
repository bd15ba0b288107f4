//! Text for language models: an annotated trace as compact lines, and a token count.
//!
//! [`annotated_text`] writes a header (trace, environment, task, length, outcome), the scene (the
//! objects of the first timestep, environment by environment), what the trace records (its event kinds
//! and payload fields, and the optional object fields it has or lacks, so the text never implies a
//! field an imported trace does not hold), then one line per pattern in a stable
//! order (start step, end step, label, detector, position in its output):
//!
//! ```text
//! trace pool-7-000003-000 (pooltool, task pool-7-000003): 41 steps, t 0.00-3.90 s; outcome no_pocket, success false
//! scene: 10 balls: cue (0.84, 0.46); 1 (0.50, 1.49); …
//! records: events physics_ball_ball 3, physics_stick_ball 1, …; payload fields agents, ball, …
//! patterns (steps, time, label: objects; key parameters):
//! 0-0 t0.00 cue strike: cue struck cue ball (0.84,0.46); V0=5.04 phi=140.36
//! 3-4 t0.39 ball collision: cue striking ball (0.42,1.45), 1 struck ball (0.50,1.49); contacts=1
//! ```
//!
//! [`count_tokens`] estimates the tokens of a text for an OpenAI-style BPE (cl100k_base). No vocabulary
//! can be downloaded here, so it is an approximation, and exactly this: the text is split with the
//! cl100k pre-tokenisation rules (contractions; an optional leading space plus a run of letters; runs
//! of 1–3 digits; an optional leading space plus a run of other non-space characters; runs of
//! whitespace, a newline run counting on its own), then each piece counts
//! `ceil(letters / 6)` tokens for a letter run (common words are one token, long words split),
//! one token per digit group, `ceil(chars / 2)` for a punctuation run, and one per whitespace run
//! that is not a single space absorbed by the next piece. It is meant for comparing costs (summaries,
//! benchmarks), not for billing.

use std::fmt::Write as _;

use serde_json::Value;

use super::annotation::Annotation;
use crate::trace::{Body, Trace};

fn num(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e9 {
        format!("{v:.0}")
    } else if v.abs() >= 100.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

fn value_text(v: &Value) -> Option<String> {
    match v {
        Value::Number(n) => n.as_f64().map(num),
        Value::String(s) if s.len() <= 40 => Some(s.clone()),
        Value::Bool(b) => Some(b.to_string()),
        Value::Array(a) if a.len() <= 4 && a.iter().all(Value::is_number) => Some(format!(
            "({})",
            a.iter()
                .filter_map(|x| x.as_f64().map(num))
                .collect::<Vec<_>>()
                .join(",")
        )),
        _ => None,
    }
}

/// The scene line: the objects of the first timestep.
fn scene(trace: &Trace) -> String {
    let Some(first) = trace.timesteps.first() else {
        return "scene: no timesteps".into();
    };
    let parts: Vec<String> = first
        .objects
        .iter()
        .map(|o| match &o.body {
            Body::Pool(b) => format!(
                "{} ({}, {})",
                b.ball_id,
                num(b.position[0]),
                num(b.position[1])
            ),
            Body::Phyre(p) => format!(
                "{} {} {}{} d{} at ({}, {})",
                p.object_index,
                p.color,
                p.shape,
                if p.is_user_input { " (placed)" } else { "" },
                num(p.diameter),
                num(p.x),
                num(p.y)
            ),
            Body::Iphyre(p) => format!(
                "{} ({},{})-({},{}) r{}{}{}",
                p.index,
                num(p.x1),
                num(p.y1),
                num(p.x2),
                num(p.y2),
                num(p.radius),
                if p.dynamic != 0.0 {
                    " dynamic"
                } else {
                    " static"
                },
                if p.eliminable != 0.0 {
                    " eliminable"
                } else {
                    ""
                }
            ),
        })
        .collect();
    let noun = match trace.env {
        crate::trace::Env::Pooltool => "balls",
        _ => "objects",
    };
    format!("scene: {} {noun}: {}", parts.len(), parts.join("; "))
}

/// One pattern's objects: `id role (x,y)` for each `object_details` entry.
fn objects(a: &Annotation) -> String {
    let Some(Value::Object(details)) = a.parameters.get("object_details") else {
        return a.objects.join(", ");
    };
    details
        .iter()
        .map(|(key, d)| {
            let id = ["ball_id", "object_id", "object_index", "index", "id"]
                .iter()
                .find_map(|k| d.get(k).and_then(value_text))
                .unwrap_or_else(|| key.clone());
            let mut s = id;
            if let Some(role) = d.get("role").and_then(Value::as_str) {
                s.push(' ');
                s.push_str(role);
            }
            if let Some(p) = ["start_position", "position"]
                .iter()
                .find_map(|k| d.get(k).and_then(value_text))
            {
                s.push(' ');
                s.push_str(&p.replace(' ', ""));
            }
            s
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Up to four scalar parameters (not `object_details`), in their order.
fn key_parameters(a: &Annotation) -> String {
    a.parameters
        .iter()
        .filter(|(k, _)| k.as_str() != "object_details")
        .filter_map(|(k, v)| value_text(v).map(|t| format!("{k}={t}")))
        .take(4)
        .collect::<Vec<_>>()
        .join(" ")
}

/// What the trace records beyond the format's required fields: its event kinds with counts (or none),
/// the payload fields its events carry, whether a PHYRE / I-PHYRE trace logs contacts, and the optional
/// object fields present or missing.
fn records(trace: &Trace) -> String {
    use std::collections::BTreeMap;
    let mut kinds: BTreeMap<&str, usize> = BTreeMap::new();
    let mut fields: std::collections::BTreeSet<&str> = Default::default();
    for e in &trace.events {
        *kinds.entry(e.kind.as_str()).or_default() += 1;
        if let Some(Value::Object(p)) = &e.payload {
            fields.extend(p.keys().map(String::as_str));
        }
    }
    let mut parts = Vec::new();
    if kinds.is_empty() {
        parts.push("no events".to_string());
    } else {
        let list: Vec<String> = kinds.iter().map(|(k, n)| format!("{k} {n}")).collect();
        parts.push(format!("events {}", list.join(", ")));
        if !fields.is_empty() {
            let f: Vec<&str> = fields.into_iter().collect();
            parts.push(format!("payload fields {}", f.join(", ")));
        }
    }
    let first = trace
        .timesteps
        .first()
        .map(|s| s.objects.as_slice())
        .unwrap_or_default();
    match trace.env {
        crate::trace::Env::Pooltool => {
            if trace.extra.contains_key("shot") {
                parts.push("top-level shot".into());
            }
        }
        crate::trace::Env::Phyre | crate::trace::Env::Iphyre => {
            if !kinds.contains_key("contact_begin") {
                parts.push("no contact log".into());
            }
        }
    }
    match trace.env {
        crate::trace::Env::Iphyre => {
            let has = first
                .iter()
                .any(|o| matches!(&o.body, Body::Iphyre(b) if b.vx.is_some()));
            parts.push(if has {
                "objects with angle, vx, vy, angular_velocity".into()
            } else {
                "objects without angle, vx, vy, angular_velocity".into()
            });
        }
        crate::trace::Env::Phyre => {
            let walls = first
                .iter()
                .any(|o| matches!(&o.body, Body::Phyre(p) if p.shape == "wall"));
            if !walls {
                parts.push("walls not listed".into());
            }
            if let Some(Value::String(src)) = trace.extra.get("velocity_source")
                && src.starts_with("estimated")
            {
                parts.push("velocities estimated from positions".into());
            }
        }
        crate::trace::Env::Pooltool => {}
    }
    format!("records: {}", parts.join("; "))
}

/// The annotated trace as text for a language model (see the module docs for the layout).
pub fn annotated_text(trace: &Trace, annotations: &[Annotation]) -> String {
    let mut out = String::new();
    let (t0, t1) = (
        trace.timesteps.first().map_or(0.0, |t| t.t),
        trace.timesteps.last().map_or(0.0, |t| t.t),
    );
    let _ = writeln!(
        out,
        "trace {} ({}, task {}): {} steps, t {:.2}-{:.2} s; outcome {}, success {}",
        trace.trace_id,
        trace.env,
        trace.task_id,
        trace.timesteps.len(),
        t0,
        t1,
        trace.outcome.terminal_status,
        trace.outcome.success
    );
    let _ = writeln!(out, "{}", scene(trace));
    let _ = writeln!(out, "{}", records(trace));
    let mut sorted: Vec<&Annotation> = annotations
        .iter()
        .filter(|a| a.trace_id == trace.trace_id)
        .collect();
    sorted.sort_by(|a, b| {
        (a.start_step, a.end_step, &a.label, &a.detector_id, a.seq).cmp(&(
            b.start_step,
            b.end_step,
            &b.label,
            &b.detector_id,
            b.seq,
        ))
    });
    if sorted.is_empty() {
        out.push_str("patterns: none\n");
        return out;
    }
    out.push_str("patterns (steps, time, label: objects; key parameters):\n");
    for a in sorted {
        let steps = if a.start_step == a.end_step {
            a.start_step.to_string()
        } else {
            format!("{}-{}", a.start_step, a.end_step)
        };
        let time = if a.t_start.is_finite() {
            format!(" t{:.2}", a.t_start)
        } else {
            String::new()
        };
        let params = key_parameters(a);
        // An ensemble annotation (ensemble libraries) says how strongly its members agreed.
        let ensemble = a
            .metadata
            .as_ref()
            .and_then(|m| m.get("ensemble"))
            .map(|e| {
                let n = e["members"].as_array().map_or(0, Vec::len);
                format!(" [ensemble a={:.2}, {n} member(s)]", a.activation)
            })
            .unwrap_or_default();
        let _ = writeln!(
            out,
            "{steps}{time} {}{ensemble}: {}{}",
            a.label,
            objects(a),
            if params.is_empty() {
                String::new()
            } else {
                format!("; {params}")
            }
        );
    }
    out
}

#[derive(Clone, Copy, PartialEq)]
enum Class {
    Letter,
    Digit,
    Space,
    Newline,
    Other,
}

fn class(c: char) -> Class {
    if c.is_alphabetic() {
        Class::Letter
    } else if c.is_numeric() {
        Class::Digit
    } else if c == '\n' || c == '\r' {
        Class::Newline
    } else if c.is_whitespace() {
        Class::Space
    } else {
        Class::Other
    }
}

/// Estimated tokens of `text` for a cl100k-style BPE (see the module docs for exactly how).
///
/// ```
/// use annotrace::detect::count_tokens;
/// assert_eq!(count_tokens(""), 0);
/// assert_eq!(count_tokens("hello world"), 2);
/// assert_eq!(count_tokens("12345"), 2); // "123" "45"
/// ```
pub fn count_tokens(text: &str) -> usize {
    let chars: Vec<char> = text.chars().collect();
    let mut i = 0;
    let mut tokens = 0;
    while i < chars.len() {
        let c = chars[i];
        // Contractions: 's 't 're 've 'm 'll 'd.
        if c == '\'' && i + 1 < chars.len() {
            let rest: String = chars[i + 1..chars.len().min(i + 3)].iter().collect();
            let lower = rest.to_lowercase();
            if ["ll", "re", "ve"].iter().any(|s| lower.starts_with(s)) {
                tokens += 1;
                i += 3;
                continue;
            }
            if ["s", "t", "m", "d"].iter().any(|s| lower.starts_with(s))
                && chars.get(i + 2).is_none_or(|n| !n.is_alphabetic())
            {
                tokens += 1;
                i += 2;
                continue;
            }
        }
        // A single space before a letter or punctuation run belongs to that run.
        let start = if c == ' '
            && chars
                .get(i + 1)
                .is_some_and(|n| matches!(class(*n), Class::Letter | Class::Other))
        {
            i + 1
        } else {
            i
        };
        let k = class(chars[start]);
        let mut j = start + 1;
        while j < chars.len() && class(chars[j]) == k {
            if k == Class::Digit && j - start == 3 {
                break;
            }
            j += 1;
        }
        let n = j - start;
        tokens += match k {
            Class::Letter => n.div_ceil(6),
            Class::Digit => 1,
            Class::Other => n.div_ceil(2),
            Class::Space | Class::Newline => 1,
        };
        i = j;
    }
    tokens
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;
    use crate::detect::DetectorId;
    use crate::trace::Env;

    #[test]
    fn token_estimates_follow_the_pre_tokeniser() {
        assert_eq!(count_tokens("The cue ball's path"), 5);
        assert_eq!(count_tokens("a,b"), 3);
        assert_eq!(count_tokens("line one\nline two\n"), 6);
        assert_eq!(count_tokens("3.14159"), 4); // "3" "." "141" "59"
        assert_eq!(count_tokens("  x"), 2);
        assert_eq!(count_tokens("internationalization"), 4);
    }

    #[test]
    fn annotated_text_is_stable_and_compact() {
        let trace = crate::testutil::synthetic_trace(Env::Pooltool, 0, 5, 2);
        let ann = |label: &str, s: i64, seq: usize| {
            Annotation {
            detector_id: DetectorId("d".into()),
            trace_id: trace.trace_id.clone(),
            label: label.into(),
            seq,
            start_step: s,
            end_step: s + 1,
            t_start: s as f64 * 0.01,
            t_end: (s + 1) as f64 * 0.01,
            objects: vec!["0".into()],
            parameters: json!({"object_details": {"0": {"role": "struck", "ball_id": "0", "start_position": [0.5, 1.25]}}, "speed": 2.5, "note": {"nested": 1}})
                .as_object()
                .unwrap()
                .clone(),
            provenance: None,
            metadata: None,
            activation: 1.0,
        }
        };
        let a = [ann("ball collision", 3, 0), ann("cue strike", 0, 0)];
        let text = annotated_text(&trace, &a);
        let b = [a[1].clone(), a[0].clone()];
        assert_eq!(
            text,
            annotated_text(&trace, &b),
            "order does not depend on input order"
        );
        let lines: Vec<&str> = text.lines().collect();
        assert!(
            lines[0].starts_with("trace pooltool-000000 (pooltool, task task-000): 5 steps"),
            "{text}"
        );
        assert!(lines[1].starts_with("scene: 2 balls: "), "{text}");
        assert!(lines[2].starts_with("records: "), "{text}");
        assert_eq!(
            lines[4],
            "0-1 t0.00 cue strike: 0 struck (0.50,1.25); speed=2.50"
        );
        assert!(lines[5].starts_with("3-4 t0.03 ball collision"));
        assert!(count_tokens(&text) > 20);
    }
}
