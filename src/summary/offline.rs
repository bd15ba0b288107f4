//! The offline summariser: a deterministic account of an annotated trace in plain sentences, written
//! from the annotations alone, with no model. It is the baseline every pipeline can run, and what the
//! identification task measures when no model is configured: how well a library's annotations tell
//! traces apart.
//!
//! The text names the environment, the duration and outcome, then the patterns in time order —
//! consecutive detections of one label on the same objects merge into one clause ("ball rolling (3)
//! from 0.40 s to 1.20 s, 4 times") — at most [`MAX_CLAUSES`] clauses, then a tally per label. It never
//! names the trace or task id, so it carries no more than the annotations and the outcome.

use std::fmt::Write as _;
use std::time::Instant;

use crate::detect::{Annotation, annotated_text, count_tokens};
use crate::trace::{Env, Trace};

use super::{Summariser, Summary, SummaryError};

/// The most pattern clauses a summary lists before "and N more".
pub const MAX_CLAUSES: usize = 12;

/// The deterministic summariser (`offline` in the `summaries` table).
#[derive(Clone, Copy, Debug, Default)]
pub struct OfflineSummariser;

impl Summariser for OfflineSummariser {
    fn name(&self) -> &str {
        "offline"
    }
    fn model(&self) -> String {
        String::new()
    }
    fn summarise(
        &self,
        trace: &Trace,
        annotations: &[Annotation],
    ) -> Result<Summary, SummaryError> {
        let t0 = Instant::now();
        let text = offline_summary(trace, annotations);
        let read = annotated_text(trace, annotations);
        Ok(Summary {
            tokens_in: count_tokens(&read) as u64,
            tokens_out: count_tokens(&text) as u64,
            usage_estimated: true,
            seconds: t0.elapsed().as_secs_f64(),
            images: 0,
            call_id: String::new(),
            text,
        })
    }
}

fn env_name(env: Env) -> &'static str {
    match env {
        Env::Pooltool => "billiards",
        Env::Phyre => "PHYRE",
        Env::Iphyre => "I-PHYRE",
    }
}

/// One clause: a run of detections of one label on the same objects.
struct Clause<'a> {
    label: &'a str,
    objects: &'a [String],
    t_start: f64,
    t_end: f64,
    count: usize,
}

fn seconds(t: f64) -> String {
    if t.is_finite() {
        format!("{t:.2} s")
    } else {
        "an unknown time".into()
    }
}

/// The summary text of `trace` from its `annotations` (rows of other traces are ignored).
pub fn offline_summary(trace: &Trace, annotations: &[Annotation]) -> String {
    let mut own: Vec<&Annotation> = annotations
        .iter()
        .filter(|a| a.trace_id == trace.trace_id)
        .collect();
    own.sort_by(|a, b| {
        (a.start_step, a.end_step, &a.label, &a.detector_id, a.seq).cmp(&(
            b.start_step,
            b.end_step,
            &b.label,
            &b.detector_id,
            b.seq,
        ))
    });
    let (t0, t1) = (
        trace.timesteps.first().map_or(0.0, |t| t.t),
        trace.timesteps.last().map_or(0.0, |t| t.t),
    );
    let mut out = String::new();
    let _ = write!(
        out,
        "A {} rollout of {:.1} s that ends {} ({}).",
        env_name(trace.env),
        t1 - t0,
        trace
            .outcome
            .terminal_status
            .replace('_', " ")
            .to_lowercase(),
        if trace.outcome.success {
            "solved"
        } else {
            "not solved"
        }
    );
    if own.is_empty() {
        out.push_str(" No pattern of the library was detected.");
        return out;
    }
    // Merge consecutive detections of one label on the same objects.
    let mut clauses: Vec<Clause<'_>> = Vec::new();
    for a in &own {
        if let Some(c) = clauses
            .last_mut()
            .filter(|c| c.label == a.label && c.objects == a.objects.as_slice())
        {
            c.count += 1;
            c.t_end = c.t_end.max(a.t_end);
            continue;
        }
        clauses.push(Clause {
            label: &a.label,
            objects: &a.objects,
            t_start: a.t_start,
            t_end: a.t_end,
            count: 1,
        });
    }
    let kinds: std::collections::BTreeMap<&str, usize> =
        own.iter().fold(Default::default(), |mut m, a| {
            *m.entry(a.label.as_str()).or_default() += 1;
            m
        });
    let _ = write!(
        out,
        " The library detected {} pattern{} of {} kind{}. In order:",
        own.len(),
        if own.len() == 1 { "" } else { "s" },
        kinds.len(),
        if kinds.len() == 1 { "" } else { "s" },
    );
    for (i, c) in clauses.iter().take(MAX_CLAUSES).enumerate() {
        let who = if c.objects.is_empty() {
            String::new()
        } else {
            format!(" ({})", c.objects.join(", "))
        };
        let when = if c.count == 1 && (c.t_end - c.t_start).abs() < 1e-9 {
            format!("at {}", seconds(c.t_start))
        } else {
            format!("from {} to {}", seconds(c.t_start), seconds(c.t_end))
        };
        let times = if c.count > 1 {
            format!(", {} times", c.count)
        } else {
            String::new()
        };
        let _ = write!(
            out,
            "{} {}{who} {when}{times}",
            if i == 0 { "" } else { ";" },
            c.label
        );
    }
    if clauses.len() > MAX_CLAUSES {
        let _ = write!(out, "; and {} more", clauses.len() - MAX_CLAUSES);
    }
    out.push('.');
    let tally: Vec<String> = kinds.iter().map(|(l, n)| format!("{l} {n}")).collect();
    let _ = write!(out, " Patterns by kind: {}.", tally.join(", "));
    out
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::detect::DetectorId;
    use crate::testutil;

    pub(crate) fn trace(id: &str) -> Trace {
        let mut t = testutil::synthetic_trace(Env::Pooltool, 1, 200, 3);
        t.trace_id = id.into();
        t
    }

    pub(crate) fn ann(trace: &str, label: &str, objects: &[&str], s: i64, t: f64) -> Annotation {
        Annotation {
            detector_id: DetectorId::of(Env::Pooltool, label, ""),
            trace_id: trace.into(),
            label: label.into(),
            seq: 0,
            start_step: s,
            end_step: s,
            t_start: t,
            t_end: t,
            objects: objects.iter().map(|o| o.to_string()).collect(),
            parameters: Default::default(),
            provenance: None,
            metadata: None,
            activation: 1.0,
        }
    }

    #[test]
    fn clauses_merge_and_are_in_time_order() {
        let trace = trace("t1");
        let anns = vec![
            ann("t1", "cushion rebound", &["cue"], 30, 1.5),
            ann("t1", "ball collision", &["cue", "1"], 10, 0.5),
            ann("t1", "ball collision", &["cue", "1"], 12, 0.6),
            ann("other", "ball pocketed", &["9"], 5, 0.2),
        ];
        let text = offline_summary(&trace, &anns);
        assert!(
            text.contains("3 patterns of 2 kinds. In order: ball collision (cue, 1) from 0.50 s to 0.60 s, 2 times; cushion rebound (cue) at 1.50 s."),
            "{text}"
        );
        assert!(
            text.contains("Patterns by kind: ball collision 2, cushion rebound 1."),
            "{text}"
        );
        assert!(
            !text.contains("pocketed"),
            "another trace's rows leaked: {text}"
        );
        assert!(
            !text.contains("t1"),
            "the trace id must not be named: {text}"
        );
        // Deterministic.
        assert_eq!(text, offline_summary(&trace, &anns));
    }

    #[test]
    fn no_annotations_and_long_lists() {
        let trace = trace("t1");
        let text = offline_summary(&trace, &[]);
        assert!(
            text.ends_with("No pattern of the library was detected."),
            "{text}"
        );
        let many: Vec<Annotation> = (0..20)
            .map(|i| ann("t1", &format!("p{i}"), &[], i, i as f64 * 0.1))
            .collect();
        let text = offline_summary(&trace, &many);
        assert!(text.contains("; and 8 more."), "{text}");
        let s = OfflineSummariser.summarise(&trace, &many).unwrap();
        assert!(s.tokens_in > s.tokens_out && s.tokens_out > 0);
        assert!(s.usage_estimated && s.call_id.is_empty());
    }
}
