//! What the viewer loads for one trace (its scene, pattern timeline and `show` text) and the row of the
//! trace list that points to it.
//!
//! **Owns:** turning a trace, its annotations grouped by library, its optional ground truth and its
//! annotated text into JSON. **Does not:** draw, read the run, or write files (`site`).

use std::collections::BTreeMap;

use serde::Serialize;
use serde_json::{Value, json};

use super::scene::{Scene, r4};
use crate::detect::Annotation;
use crate::detect::accuracy::TruthEvent;
use crate::trace::Trace;

/// The annotations one library made on a trace.
#[derive(Debug, Clone)]
pub struct LibraryAnnotations {
    /// The library's name (the `detectors` table's `library`).
    pub library: String,
    /// Its annotations of the trace.
    pub annotations: Vec<Annotation>,
}

/// Everything the report shows of one trace besides the trace itself.
#[derive(Debug, Clone, Default)]
pub struct TraceViews {
    /// One entry per library, in the order they are offered.
    pub libraries: Vec<LibraryAnnotations>,
    /// The simulator's ground truth (event-grounded labels), when the run was scored.
    pub truth: Option<Vec<TruthEvent>>,
    /// The annotated trace as `annotrace show` prints it (without its token line).
    pub text: String,
    /// Its token estimate (`detect::count_tokens`).
    pub tokens: usize,
}

/// Longest parameter text kept for hovering (characters).
const INFO_CHARS: usize = 400;

fn short(s: String) -> String {
    if s.chars().count() <= INFO_CHARS {
        s
    } else {
        let mut t: String = s.chars().take(INFO_CHARS).collect();
        t.push('…');
        t
    }
}

/// The time of timestep `step` (its index field), else the nearest by position, else 0.
fn step_time(trace: &Trace, step: i64) -> f64 {
    trace
        .timesteps
        .iter()
        .find(|s| s.index == step)
        .or_else(|| {
            usize::try_from(step).ok().and_then(|k| {
                trace
                    .timesteps
                    .get(k.min(trace.timesteps.len().saturating_sub(1)))
            })
        })
        .map_or(0.0, |s| s.t)
}

fn item(t0: f64, t1: f64, objects: &[String], info: String) -> Value {
    json!({"t0": r4(t0), "t1": r4(t1.max(t0)), "objects": objects, "info": short(info)})
}

/// One section of rows: `label → items`, labels in first-seen order.
fn section(name: &str, kind: &str, rows: Vec<(String, Value)>) -> Value {
    let mut order: Vec<String> = Vec::new();
    let mut by: BTreeMap<String, Vec<Value>> = BTreeMap::new();
    for (label, it) in rows {
        if !by.contains_key(&label) {
            order.push(label.clone());
        }
        by.entry(label).or_default().push(it);
    }
    let labels: Vec<Value> = order
        .into_iter()
        .map(|l| {
            let items = by.remove(&l).unwrap_or_default();
            json!({"label": l, "items": items})
        })
        .collect();
    json!({"name": name, "kind": kind, "labels": labels})
}

/// The library section of a trace: one row per label, annotations in time order.
fn library_section(trace: &Trace, lib: &LibraryAnnotations) -> Value {
    let mut anns: Vec<&Annotation> = lib.annotations.iter().collect();
    anns.sort_by(|a, b| {
        (a.start_step, a.end_step, &a.label, a.seq).cmp(&(
            b.start_step,
            b.end_step,
            &b.label,
            b.seq,
        ))
    });
    let mut labels: Vec<&str> = anns.iter().map(|a| a.label.as_str()).collect();
    labels.sort();
    labels.dedup();
    let rows = labels
        .into_iter()
        .flat_map(|l| anns.iter().filter(move |a| a.label == l))
        .map(|a| {
            let t0 = if a.t_start.is_finite() {
                a.t_start
            } else {
                step_time(trace, a.start_step)
            };
            let t1 = if a.t_end.is_finite() {
                a.t_end
            } else {
                step_time(trace, a.end_step)
            };
            let params = serde_json::to_string(&a.parameters).unwrap_or_default();
            let info = format!("steps {}–{}; {params}", a.start_step, a.end_step);
            (a.label.clone(), item(t0, t1, &a.objects, info))
        })
        .collect();
    section(&lib.library, "library", rows)
}

/// What the viewer loads for one trace, serialised in this field order (the scene is written straight
/// from its struct, not through a JSON value tree).
#[derive(Debug, Serialize)]
pub struct TracePayload<'a> {
    index: usize,
    id: &'a str,
    env: &'a str,
    task: &'a str,
    success: bool,
    status: &'a str,
    t0: f64,
    t1: f64,
    scene: &'a Scene,
    sections: Vec<Value>,
    text: &'a str,
    tokens: usize,
}

/// The payload of trace number `index` of the report.
pub fn trace_payload<'a>(
    index: usize,
    trace: &'a Trace,
    scene: &'a Scene,
    views: &'a TraceViews,
) -> TracePayload<'a> {
    let mut sections: Vec<Value> = views
        .libraries
        .iter()
        .map(|l| library_section(trace, l))
        .collect();
    if let Some(truth) = &views.truth {
        let mut t: Vec<&TruthEvent> = truth.iter().collect();
        t.sort_by(|a, b| a.label.cmp(b.label).then(a.t.total_cmp(&b.t)));
        let rows = t
            .into_iter()
            .map(|e| {
                (
                    e.label.to_string(),
                    item(e.t, e.t, &e.balls, format!("t = {:.3} s", e.t)),
                )
            })
            .collect();
        sections.push(section("ground truth", "truth", rows));
    }
    let events: Vec<(String, Value)> = trace
        .events
        .iter()
        .filter_map(|e| {
            let t = e.t?;
            let payload = e
                .payload
                .as_ref()
                .map(|p| serde_json::to_string(p).unwrap_or_default())
                .unwrap_or_default();
            Some((e.kind.clone(), item(t, t, &[], payload)))
        })
        .collect();
    sections.push(section("simulator events", "events", events));
    let (t0, t1) = match (trace.timesteps.first(), trace.timesteps.last()) {
        (Some(a), Some(b)) => (a.t, b.t),
        _ => (0.0, 0.0),
    };
    TracePayload {
        index,
        id: &trace.trace_id,
        env: trace.env.as_str(),
        task: &trace.task_id,
        success: trace.outcome.success,
        status: &trace.outcome.terminal_status,
        t0: r4(t0),
        t1: r4(t1),
        scene,
        sections,
        text: &views.text,
        tokens: views.tokens,
    }
}

/// The trace list's row for trace number `index`: the columns the list filters on.
pub fn index_row(index: usize, trace: &Trace, views: &TraceViews) -> Value {
    let mut labels: Vec<&str> = views
        .libraries
        .iter()
        .flat_map(|l| l.annotations.iter().map(|a| a.label.as_str()))
        .collect();
    labels.sort();
    labels.dedup();
    let annotations: usize = views.libraries.iter().map(|l| l.annotations.len()).sum();
    let duration = match (trace.timesteps.first(), trace.timesteps.last()) {
        (Some(a), Some(b)) => b.t - a.t,
        _ => 0.0,
    };
    json!({
        "index": index,
        "trace_id": trace.trace_id,
        "env": trace.env.as_str(),
        "task_id": trace.task_id,
        "success": trace.outcome.success,
        "terminal_status": trace.outcome.terminal_status,
        "n_steps": trace.timesteps.len(),
        "n_events": trace.events.len(),
        "duration": r4(duration),
        "annotations": annotations,
        "labels": labels,
        "tokens": views.tokens,
    })
}
