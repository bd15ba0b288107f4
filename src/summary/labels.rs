//! Pattern labels suggested from example traces (the paper's "LLM-Labels", section 4.2): a
//! vision-language model is shown example rollouts — each one's initial image and its annotated trace
//! text ([`crate::detect::annotated_text`]) — and asked for K labels, each a name, a one-sentence
//! description and the objects or quantities it concerns. The answer is parsed strictly
//! ([`parse_strict`]); an answer with problems is sent back with the list of problems
//! (`prompts/summary/labels_repair.j2`) up to `max_repairs` times. Every call goes through
//! [`LlmClient`], so it is in `llm_calls` and replays.
//!
//! Without a model, [`offline_labels`] is the baseline: first the labels of the environment's
//! built-in human library that the known library lacks, in the built-in library's order; then labels
//! mined from the example annotations — ordered pairs "A then B" of two different labels where a B
//! pattern starts after an A pattern, within a tenth of the trace's steps of A's end, on an object A
//! also names — ranked by the number of example traces showing the pair, then by occurrences, then by
//! the labels' order. Deterministic: the same examples give the same labels.
//!
//! **Does not:** run detectors (callers pass the annotations), choose the example traces or write
//! tables (the `suggest-labels` stage does), read the process environment.

use std::collections::{BTreeMap, BTreeSet};

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::builtin::Location;
use crate::detect::{Annotation, Library, annotated_text, normalise_label};
use crate::digest::words_u64;
use crate::llm::{
    ChatRequest, LibraryEntry, LlmClient, LlmError, Message, Prompts, Role, fences, strip_think,
};
use crate::trace::{Env, Trace};

use super::SummaryError;
use super::images::TraceImages;
use super::llm::with_images;

/// The templates of label suggestion (name, built-in text); [`super::add_templates`] adds them.
pub const LABEL_TEMPLATES: [(&str, &str); 2] = [
    (
        "summary/labels.j2",
        include_str!("../../prompts/summary/labels.j2"),
    ),
    (
        "summary/labels_repair.j2",
        include_str!("../../prompts/summary/labels_repair.j2"),
    ),
];

/// Words a label may have (the prompt asks for 2 to 7; one or eight are let through).
const LABEL_WORDS: std::ops::RangeInclusive<usize> = 1..=8;

/// One suggested label.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProposedLabel {
    /// A short, scene-agnostic phrase.
    pub label: String,
    /// One sentence on what happens.
    pub description: String,
    /// The kinds of object or quantities it concerns.
    pub objects: Vec<String>,
    /// Why it is useful (may be empty).
    pub reason: String,
    /// Where it came from: `llm`, `builtin` (the built-in human library) or `mined` (a frequent pair
    /// of annotations in the examples).
    pub source: String,
}

/// What to ask for.
#[derive(Clone, Debug)]
pub struct LabelAsk {
    /// The environment.
    pub env: Env,
    /// How many labels.
    pub k: usize,
    /// Labels the suggestions must not repeat (empty: a whole library is proposed).
    pub known: Vec<LibraryEntry>,
    /// What the agent is trying to do, if known.
    pub objective: Option<String>,
    /// An extra instruction.
    pub guidance: Option<String>,
}

/// The labels of one suggestion and what they cost.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Suggested {
    /// The labels, at most `k`, in the model's (or the baseline's) order.
    pub labels: Vec<ProposedLabel>,
    /// The `llm_calls.request_hash` of each call, in order (empty offline): stable across replays,
    /// unlike call ids, which name the session.
    pub calls: Vec<String>,
    /// The problems of each rejected answer (`answer n: …`), in order.
    pub problems: Vec<String>,
    /// Prompt tokens of all calls.
    pub tokens_in: u64,
    /// Completion tokens of all calls.
    pub tokens_out: u64,
    /// Model seconds of all calls.
    pub seconds: f64,
}

/// Why no labels came out.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LabelsError {
    /// A call failed.
    #[error(transparent)]
    Llm(#[from] LlmError),
    /// An example could not be drawn.
    #[error(transparent)]
    Render(#[from] SummaryError),
    /// No usable label after every repair.
    #[error(
        "no usable label in {answers} answer(s) of the model; the last answer's problems: {}",
        last.join("; ")
    )]
    NoLabels {
        /// Answers received.
        answers: usize,
        /// The problems of the last one.
        last: Vec<String>,
    },
}

fn known_set(known: &[LibraryEntry]) -> BTreeSet<String> {
    known
        .iter()
        .flat_map(|e| std::iter::once(&e.label).chain(&e.aliases))
        .map(|l| normalise_label(l))
        .collect()
}

/// The JSON array of an answer: the last fenced block whose body is one, else the whole answer
/// (without `<think>` sections) when it is one.
fn answer_array(answer: &str) -> Result<Vec<Value>, String> {
    let text = strip_think(answer);
    for f in fences(&text).into_iter().rev() {
        if let Ok(Value::Array(a)) = serde_json::from_str::<Value>(f.body.trim()) {
            return Ok(a);
        }
    }
    match serde_json::from_str::<Value>(text.trim()) {
        Ok(Value::Array(a)) => Ok(a),
        Ok(_) => Err("the answer is JSON but not an array of patterns".into()),
        Err(_) => Err("no JSON array of patterns found (expected one in a ```json block)".into()),
    }
}

/// Parses an answer strictly: one JSON array of exactly `k` objects, each with a non-empty `label` of
/// 1–8 words, a non-empty `description`, an `objects` list of strings and an optional `reason`; no label
/// twice, none in `known`. Returns the usable labels (in order, at most `k`) and the problems found
/// (empty when the answer is fine).
pub fn parse_strict(
    answer: &str,
    k: usize,
    known: &[LibraryEntry],
) -> (Vec<ProposedLabel>, Vec<String>) {
    let items = match answer_array(answer) {
        Ok(a) => a,
        Err(p) => return (Vec::new(), vec![p]),
    };
    let known = known_set(known);
    let mut seen = BTreeSet::new();
    let (mut labels, mut problems) = (Vec::new(), Vec::new());
    for (i, it) in items.iter().enumerate() {
        let n = i + 1;
        let Value::Object(o) = it else {
            problems.push(format!("item {n} is not an object"));
            continue;
        };
        let text = |key: &str| o.get(key).and_then(Value::as_str).map(str::trim);
        let label = match text("label") {
            Some(l) if !l.is_empty() => l.to_string(),
            _ => {
                problems.push(format!("item {n} has no \"label\" string"));
                continue;
            }
        };
        let words = label.split_whitespace().count();
        let mut bad = Vec::new();
        if !LABEL_WORDS.contains(&words) || label.chars().count() > 80 {
            bad.push(format!("has {words} words (2 to 7 asked)"));
        }
        let description = text("description").unwrap_or_default().to_string();
        if description.is_empty() {
            bad.push("has no \"description\" sentence".to_string());
        }
        let objects = match o.get("objects") {
            Some(Value::Array(a)) if a.iter().all(Value::is_string) => a
                .iter()
                .filter_map(Value::as_str)
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty())
                .collect(),
            _ => {
                bad.push("has no \"objects\" list of strings".to_string());
                Vec::new()
            }
        };
        let norm = normalise_label(&label);
        if known.contains(&norm) {
            bad.push("is already in the library".to_string());
        } else if !seen.insert(norm) {
            bad.push("is proposed twice".to_string());
        }
        if !bad.is_empty() {
            problems.push(format!("item {n} ({label:?}) {}", bad.join(", ")));
            continue;
        }
        if labels.len() < k {
            labels.push(ProposedLabel {
                label,
                description,
                objects,
                reason: text("reason").unwrap_or_default().to_string(),
                source: "llm".into(),
            });
        }
    }
    if items.len() != k {
        problems.push(format!(
            "the array has {} item(s); exactly {k} were asked for",
            items.len()
        ));
    }
    (labels, problems)
}

/// The text of the first request: `examples` are `{image, annotated}` (the image's caption and the
/// example's annotated trace).
pub fn prompt_text(
    prompts: &Prompts,
    ask: &LabelAsk,
    examples: &[Value],
) -> Result<String, LlmError> {
    prompts.render(
        "summary/labels.j2",
        json!({
            "env": ask.env.as_str(),
            "k": ask.k,
            "known": ask.known,
            "examples": examples,
            "objective": ask.objective,
            "guidance": ask.guidance,
        }),
    )
}

/// The text of a repair request listing `problems`.
pub fn repair_text(prompts: &Prompts, k: usize, problems: &[String]) -> Result<String, LlmError> {
    prompts.render(
        "summary/labels_repair.j2",
        json!({"k": k, "problems": problems}),
    )
}

/// Suggestions from a vision-language model with a repair loop.
#[derive(Debug)]
pub struct LlmLabeller<'a> {
    /// The client (records and replays calls).
    pub client: &'a LlmClient,
    /// Templates, with [`LABEL_TEMPLATES`] added.
    pub prompts: &'a Prompts,
    /// The renderer of the initial images.
    pub images: &'a TraceImages,
    /// Repair rounds after the first answer.
    pub max_repairs: usize,
    /// Seed of the requests.
    pub seed: u64,
    /// Sampling temperature (the client's default when `None`).
    pub temperature: Option<f64>,
}

impl LlmLabeller<'_> {
    /// The first request: the prompt with every example's annotated text, then each example's initial
    /// image after its caption.
    pub fn request(
        &self,
        ask: &LabelAsk,
        traces: &[Trace],
        annotations: &[Annotation],
    ) -> Result<ChatRequest, LabelsError> {
        let mut images = Vec::with_capacity(traces.len());
        let mut examples = Vec::with_capacity(traces.len());
        for (i, t) in traces.iter().enumerate() {
            let mut im = self.images.initial(t)?;
            im.caption = format!("example {}: initial scene", i + 1);
            examples.push(json!({
                "image": im.caption,
                "annotated": annotated_text(t, annotations),
            }));
            images.push(im);
        }
        let text = prompt_text(self.prompts, ask, &examples)?;
        let mut req = ChatRequest::new("suggest_labels_examples")
            .message(with_images(text, &images))
            .seed(words_u64(&[self.seed, 0x1AB]));
        req.temperature = self.temperature;
        Ok(req)
    }

    /// Asks, parses, and repairs up to `max_repairs` times. The last answer's usable labels are kept
    /// when every repair still had problems (they are listed in [`Suggested::problems`]); none at all
    /// is [`LabelsError::NoLabels`].
    pub fn suggest(
        &self,
        ask: &LabelAsk,
        traces: &[Trace],
        annotations: &[Annotation],
    ) -> Result<Suggested, LabelsError> {
        let mut req = self.request(ask, traces, annotations)?;
        let mut out = Suggested::default();
        let mut answers = 0;
        loop {
            let reply = self.client.chat(&req)?;
            answers += 1;
            out.calls.push(reply.request_hash.clone());
            out.tokens_in += reply.tokens_in;
            out.tokens_out += reply.tokens_out;
            // Microseconds: a replayed latency comes back from the recorded milliseconds.
            out.seconds += (reply.latency.as_secs_f64() * 1e6).round() / 1e6;
            let (labels, problems) = parse_strict(&reply.content, ask.k, &ask.known);
            if problems.is_empty() || answers > self.max_repairs {
                if labels.is_empty() {
                    return Err(LabelsError::NoLabels {
                        answers,
                        last: problems,
                    });
                }
                out.problems
                    .extend(problems.iter().map(|p| format!("answer {answers}: {p}")));
                out.labels = labels;
                return Ok(out);
            }
            out.problems
                .extend(problems.iter().map(|p| format!("answer {answers}: {p}")));
            let repair = repair_text(self.prompts, ask.k, &problems)?;
            req = req
                .message(Message::text(Role::Assistant, reply.content))
                .message(Message::user(repair));
            req.seed = Some(words_u64(&[self.seed, 0x1AB, answers as u64]));
        }
    }
}

/// The baseline without a model (see the module doc): built-in labels the known set lacks, then
/// frequent ordered pairs of the examples' annotations; at most `k`, each new and distinct.
pub fn offline_labels(
    ask: &LabelAsk,
    traces: &[Trace],
    annotations: &[Annotation],
) -> Result<Vec<ProposedLabel>, crate::detect::LibraryError> {
    let mut known = known_set(&ask.known);
    let mut out = Vec::new();
    let builtin = Library::open(&Location::Builtin(crate::builtin::library_path(ask.env)))?;
    let mut order: Vec<String> = Vec::new();
    for d in &builtin.detectors {
        if !order.contains(&d.label) {
            order.push(d.label.clone());
        }
    }
    for d in &builtin.detectors {
        if out.len() >= ask.k {
            return Ok(out);
        }
        if known.insert(normalise_label(&d.label)) {
            out.push(ProposedLabel {
                label: d.label.clone(),
                description: format!(
                    "the \"{}\" pattern of the built-in human library ({})",
                    d.label, builtin.name
                ),
                objects: Vec::new(),
                reason: "a label of the built-in human library that the library lacks".into(),
                source: "builtin".into(),
            });
        }
    }
    for p in mined_pairs(traces, annotations, &order) {
        if out.len() >= ask.k {
            break;
        }
        let label = format!("{} then {}", p.first, p.second);
        if known.insert(normalise_label(&label)) {
            out.push(ProposedLabel {
                description: format!(
                    "a \"{}\" pattern followed soon after by a \"{}\" pattern on an object the first one names",
                    p.first, p.second
                ),
                label,
                objects: p.objects,
                reason: format!(
                    "seen in {} of the {} example trace(s), {} time(s) in all",
                    p.traces,
                    traces.len(),
                    p.count
                ),
                source: "mined".into(),
            });
        }
    }
    Ok(out)
}

/// One mined pair.
#[derive(Clone, Debug, PartialEq)]
struct Pair {
    first: String,
    second: String,
    traces: usize,
    count: usize,
    /// The object ids the pair shared most often (at most 3).
    objects: Vec<String>,
}

/// Ordered pairs of different labels: B starts after A starts, within a tenth of the trace's steps
/// (at least one step) of A's end, and names an object A names (or one of them names none).
fn mined_pairs(traces: &[Trace], annotations: &[Annotation], order: &[String]) -> Vec<Pair> {
    #[derive(Default)]
    struct Tally {
        traces: BTreeSet<String>,
        count: usize,
        objects: BTreeMap<String, usize>,
    }
    let mut tally: BTreeMap<(String, String), Tally> = BTreeMap::new();
    for (t, mut anns) in traces
        .iter()
        .zip(crate::detect::by_trace(traces, annotations))
    {
        anns.sort_by(|a, b| {
            (a.start_step, a.end_step, &a.label, a.seq).cmp(&(
                b.start_step,
                b.end_step,
                &b.label,
                b.seq,
            ))
        });
        let window = (t.timesteps.len() as i64 / 10).max(1);
        for (i, a) in anns.iter().enumerate() {
            for b in &anns[i + 1..] {
                if b.label == a.label || b.start_step <= a.start_step {
                    continue;
                }
                if b.start_step - a.end_step > window {
                    continue;
                }
                let shared: Vec<&String> =
                    b.objects.iter().filter(|o| a.objects.contains(o)).collect();
                if shared.is_empty() && !a.objects.is_empty() && !b.objects.is_empty() {
                    continue;
                }
                let e = tally.entry((a.label.clone(), b.label.clone())).or_default();
                e.traces.insert(t.trace_id.clone());
                e.count += 1;
                for o in shared {
                    *e.objects.entry(o.clone()).or_default() += 1;
                }
            }
        }
    }
    let rank = |l: &str| order.iter().position(|o| o == l).unwrap_or(usize::MAX);
    let mut pairs: Vec<Pair> = tally
        .into_iter()
        .map(|((first, second), t)| {
            let mut objs: Vec<(String, usize)> = t.objects.into_iter().collect();
            objs.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
            Pair {
                first,
                second,
                traces: t.traces.len(),
                count: t.count,
                objects: objs.into_iter().take(3).map(|(o, _)| o).collect(),
            }
        })
        .collect();
    pairs.sort_by(|a, b| {
        b.traces
            .cmp(&a.traces)
            .then(b.count.cmp(&a.count))
            .then(rank(&a.first).cmp(&rank(&b.first)))
            .then(rank(&a.second).cmp(&rank(&b.second)))
            .then(a.first.cmp(&b.first))
            .then(a.second.cmp(&b.second))
    });
    pairs
}

#[cfg(test)]
mod tests {
    use super::*;

    fn known() -> Vec<LibraryEntry> {
        vec![LibraryEntry {
            label: "cushion rebound".into(),
            aliases: vec!["bank".into()],
        }]
    }

    /// The prompts as a model sees them: billiards with the library's labels taken, PHYRE proposing
    /// a whole library with an objective, and a repair.
    #[test]
    fn prompts_render_per_environment() {
        let mut prompts = Prompts::builtin();
        super::super::add_templates(&mut prompts).unwrap();
        for (env, known) in [(Env::Pooltool, known()), (Env::Phyre, Vec::new())] {
            let trace = crate::testutil::synthetic_trace(env, 0, 12, 2);
            let anns = vec![ann(&trace.trace_id, "bounce", 3, 5, &["1"])];
            let ask = LabelAsk {
                env,
                k: 12,
                known,
                objective: (env == Env::Phyre)
                    .then(|| "the green object touches the blue one".into()),
                guidance: None,
            };
            let examples = vec![json!({
                "image": "example 1: initial scene",
                "annotated": annotated_text(&trace, &anns),
            })];
            let text = prompt_text(&prompts, &ask, &examples).unwrap();
            insta::assert_snapshot!(format!("labels_{env}"), text);
        }
        let problems = vec![
            "item 2 (\"spin\") has no \"description\" sentence".to_string(),
            "the array has 11 item(s); exactly 12 were asked for".to_string(),
        ];
        insta::assert_snapshot!(
            "labels_repair",
            repair_text(&prompts, 12, &problems).unwrap()
        );
    }

    #[test]
    fn a_good_answer_parses_with_no_problem() {
        let a = "<think>[\"x\"]</think>Here:\n```json\n[{\"label\": \"Long rail run\", \"description\": \"A ball rolls along a cushion.\", \"objects\": [\"ball\", \"cushion\"], \"reason\": \"r\"},\n {\"label\": \"double kiss\", \"description\": \"Two balls touch twice.\", \"objects\": []}]\n```";
        let (l, p) = parse_strict(a, 2, &known());
        assert!(p.is_empty(), "{p:?}");
        assert_eq!(l.len(), 2);
        assert_eq!(l[0].objects, ["ball", "cushion"]);
        assert_eq!((l[0].reason.as_str(), l[1].reason.as_str()), ("r", ""));
    }

    #[test]
    fn every_kind_of_problem_is_named() {
        let (l, p) = parse_strict("- a bullet list\n- is not accepted", 3, &known());
        assert!(l.is_empty());
        assert!(p[0].contains("no JSON array"), "{p:?}");
        let a = r#"[{"label": "Bank", "description": "d", "objects": []},
                    {"label": "spin", "objects": ["ball"]},
                    {"label": "spin", "description": "d", "objects": "ball"},
                    7,
                    {"description": "d"},
                    {"label": "a b c d e f g h i j", "description": "d", "objects": []},
                    {"label": "ok one", "description": "d", "objects": ["ball"]}]"#;
        let (l, p) = parse_strict(a, 3, &known());
        assert_eq!(l.len(), 1, "{l:?}");
        assert_eq!(l[0].label, "ok one");
        let all = p.join("\n");
        for needle in [
            "item 1 (\"Bank\") is already in the library",
            "item 2 (\"spin\") has no \"description\"",
            "item 3 (\"spin\") has no \"objects\" list of strings, is proposed twice",
            "item 4 is not an object",
            "item 5 has no \"label\"",
            "item 6 (\"a b c d e f g h i j\") has 10 words",
            "the array has 7 item(s); exactly 3",
        ] {
            assert!(all.contains(needle), "{needle}\n{all}");
        }
    }

    fn ann(trace: &str, label: &str, s: i64, e: i64, objects: &[&str]) -> Annotation {
        Annotation {
            detector_id: crate::detect::DetectorId(format!("d-{label}")),
            trace_id: trace.into(),
            label: label.into(),
            seq: 0,
            start_step: s,
            end_step: e,
            t_start: s as f64 * 0.1,
            t_end: e as f64 * 0.1,
            objects: objects.iter().map(|o| o.to_string()).collect(),
            parameters: Default::default(),
            provenance: None,
            metadata: None,
            activation: 1.0,
        }
    }

    #[test]
    fn the_offline_baseline_fills_from_the_builtin_library_then_mined_pairs() {
        let traces: Vec<Trace> = (0..2)
            .map(|i| crate::testutil::synthetic_trace(Env::Pooltool, i, 40, 3))
            .collect();
        let (a, b) = (&traces[0].trace_id, &traces[1].trace_id);
        let anns = vec![
            ann(a, "ball collision", 3, 4, &["cue", "3"]),
            ann(a, "cushion rebound", 6, 7, &["3"]),
            ann(a, "ball pocketed", 30, 31, &["3"]),
            ann(b, "ball collision", 10, 11, &["cue", "5"]),
            ann(b, "cushion rebound", 12, 13, &["5"]),
            ann(b, "ball pocketed", 14, 14, &["9"]),
        ];
        // Every built-in label known: only mined pairs.
        let lib = Library::open(&Location::Builtin("data/libraries/pooltool".into())).unwrap();
        let ask = LabelAsk {
            env: Env::Pooltool,
            k: 12,
            known: LibraryEntry::of(&lib),
            objective: None,
            guidance: None,
        };
        let l = offline_labels(&ask, &traces, &anns).unwrap();
        let names: Vec<&str> = l.iter().map(|x| x.label.as_str()).collect();
        // Collision → rebound shares an object in both traces; rebound → pocketed is too late in the
        // first and on another ball in the second.
        assert_eq!(names, ["ball collision then cushion rebound"], "{l:?}");
        assert_eq!(l[0].objects, ["3", "5"]);
        assert_eq!(l[0].source, "mined");
        assert_eq!(offline_labels(&ask, &traces, &anns).unwrap(), l);
        // Nothing known: the built-in labels come first, in the library's order.
        let ask = LabelAsk {
            known: Vec::new(),
            k: 3,
            ..ask
        };
        let l = offline_labels(&ask, &traces, &anns).unwrap();
        assert_eq!(
            l.iter().map(|x| x.label.as_str()).collect::<Vec<_>>(),
            ["cue strike", "ball collision", "cushion rebound"]
        );
        assert!(l.iter().all(|x| x.source == "builtin"));
    }
}
