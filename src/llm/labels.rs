//! Label suggestion: ask the model for K new pattern labels for an environment, given its trace layout
//! and the current library, and parse the answer (a JSON array, or failing that a bullet list).
//!
//! Entry point: [`suggest_labels`]; the parser alone is [`parse_labels`].

use serde::Serialize;
use serde_json::Value;

use super::client::LlmClient;
use super::error::LlmError;
use super::extract::{fences, strip_think};
use super::message::{ChatReply, ChatRequest};
use super::prompt::{LabelsContext, LibraryEntry, Prompts};
use crate::detect::{Library, normalise_label};
use crate::trace::Env;

/// One proposed label.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct SuggestedLabel {
    /// A short, scene-agnostic phrase.
    pub label: String,
    /// One sentence on what happens (may be empty for a bare bullet).
    pub description: String,
    /// Why it is useful (may be empty).
    pub reason: String,
}

/// Why label suggestion produced nothing.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LabelsError {
    /// The call failed.
    #[error(transparent)]
    Llm(#[from] LlmError),
    /// The answer held neither a JSON list nor a bullet list of labels.
    #[error(
        "no labels in the answer (expected a JSON array or a bullet list); it starts: {excerpt}"
    )]
    Unparsable {
        /// The start of the answer.
        excerpt: String,
    },
}

/// What to ask for.
#[derive(Clone, Debug)]
pub struct SuggestParams {
    /// The environment.
    pub env: Env,
    /// How many labels.
    pub k: usize,
    /// What the agent is trying to do, if known.
    pub objective: Option<String>,
    /// Extra instructions.
    pub guidance: Option<String>,
    /// The request seed.
    pub seed: u64,
    /// Sampling temperature (the client's default when `None`).
    pub temperature: Option<f64>,
}

/// The parsed suggestions and the call behind them.
#[derive(Clone, Debug)]
pub struct Suggestions {
    /// New labels, at most `k`, in the model's order.
    pub labels: Vec<SuggestedLabel>,
    /// Proposed labels dropped because the library (or an earlier suggestion) already has them.
    pub duplicates: Vec<String>,
    /// The call.
    pub reply: ChatReply,
}

/// Renders `suggest_labels.j2` for `library`, asks `client`, parses and filters the answer.
pub fn suggest_labels(
    client: &LlmClient,
    prompts: &Prompts,
    library: &Library,
    params: &SuggestParams,
) -> Result<Suggestions, LabelsError> {
    let entries = LibraryEntry::of(library);
    let prompt = prompts.render(
        "suggest_labels.j2",
        LabelsContext {
            env: params.env,
            k: params.k,
            library: entries.clone(),
            objective: params.objective.clone(),
            guidance: params.guidance.clone(),
        },
    )?;
    let mut req = ChatRequest::new("suggest_labels")
        .user(prompt)
        .seed(params.seed);
    req.temperature = params.temperature;
    let reply = client.chat(&req)?;
    let parsed = parse_labels(&reply.content)?;
    let mut known: Vec<String> = entries
        .iter()
        .flat_map(|e| std::iter::once(&e.label).chain(&e.aliases))
        .map(|l| normalise_label(l))
        .collect();
    let mut labels = Vec::new();
    let mut duplicates = Vec::new();
    for s in parsed {
        let n = normalise_label(&s.label);
        if known.contains(&n) {
            duplicates.push(s.label);
        } else if labels.len() < params.k {
            known.push(n);
            labels.push(s);
        }
    }
    Ok(Suggestions {
        labels,
        duplicates,
        reply,
    })
}

/// Labels from an answer: the last JSON array of objects with a `label` (or `name`) field, or of
/// strings, in the last fence that has one, or else anywhere in the text; failing that, the items of a bullet or numbered list, split into label
/// and description at the first ` — `, ` – `, ` - ` or `: `.
pub fn parse_labels(answer: &str) -> Result<Vec<SuggestedLabel>, LabelsError> {
    let text = strip_think(answer);
    let mut candidates: Vec<&str> = fences(&text).into_iter().map(|f| f.body).collect();
    candidates.reverse();
    candidates.push(&text);
    for c in candidates {
        if let Some(labels) = labels_in_json(c) {
            return Ok(labels);
        }
    }
    let bullets = labels_of_bullets(&text);
    if !bullets.is_empty() {
        return Ok(bullets);
    }
    Err(LabelsError::Unparsable {
        excerpt: text.trim().chars().take(120).collect(),
    })
}

/// Most `[` positions tried when looking for a JSON array in prose. A failed try stops at the first
/// invalid token (and nesting deeper than 128 fails), so this bounds the work on bracket-heavy answers
/// (code) to well under a second.
const MAX_ARRAY_STARTS: usize = 50_000;

/// The labels of the last JSON array in `s` that holds labels: each `[` is tried as the start of one
/// JSON value (parsing stops at the value's end, or early at the first invalid token); a found array is
/// skipped over whole, so arrays nested inside it are not taken instead.
fn labels_in_json(s: &str) -> Option<Vec<SuggestedLabel>> {
    let mut found = None;
    let mut pos = 0;
    let mut tries = 0;
    while let Some(i) = s[pos..].find('[') {
        let start = pos + i;
        tries += 1;
        if tries > MAX_ARRAY_STARTS {
            break;
        }
        let mut stream = serde_json::Deserializer::from_str(&s[start..]).into_iter::<Value>();
        match stream.next() {
            Some(Ok(v)) => {
                let end = start + stream.byte_offset();
                if let Some(labels) = labels_of_json(&v) {
                    found = Some(labels);
                }
                pos = end.max(start + 1);
            }
            _ => pos = start + 1,
        }
    }
    found
}

fn labels_of_json(v: &Value) -> Option<Vec<SuggestedLabel>> {
    let items = v.as_array()?;
    let mut out = Vec::new();
    for it in items {
        let s = |k: &str| {
            it.get(k)
                .and_then(Value::as_str)
                .map(str::trim)
                .unwrap_or("")
        };
        let label = match it {
            Value::String(l) => l.trim().to_string(),
            Value::Object(_) => {
                let l = if s("label").is_empty() {
                    s("name")
                } else {
                    s("label")
                };
                l.to_string()
            }
            _ => continue,
        };
        if label.is_empty() {
            continue;
        }
        out.push(SuggestedLabel {
            label,
            description: s("description").to_string(),
            reason: s("reason").to_string(),
        });
    }
    (!out.is_empty()).then_some(out)
}

fn labels_of_bullets(text: &str) -> Vec<SuggestedLabel> {
    let mut out = Vec::new();
    for line in text.lines() {
        let l = line.trim();
        let item = if let Some(r) = l
            .strip_prefix("- ")
            .or(l.strip_prefix("* "))
            .or(l.strip_prefix("• "))
        {
            r
        } else {
            let digits = l.chars().take_while(char::is_ascii_digit).count();
            if digits == 0 {
                continue;
            }
            match l[digits..]
                .strip_prefix(". ")
                .or(l[digits..].strip_prefix(") "))
            {
                Some(r) => r,
                None => continue,
            }
        };
        let item = item.replace("**", "").replace('`', "");
        let item = item.trim();
        let (label, desc) = ["\u{2014}", "\u{2013}", " - ", ": "]
            .iter()
            .filter_map(|sep| item.split_once(sep))
            .min_by_key(|(l, _)| l.len())
            .unwrap_or((item, ""));
        let label = label.trim().trim_matches('"').trim();
        if label.is_empty() || label.split_whitespace().count() > 10 {
            continue;
        }
        out.push(SuggestedLabel {
            label: label.to_string(),
            description: desc.trim().to_string(),
            reason: String::new(),
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_json_array_in_a_fence_after_thinking_is_parsed() {
        let a = "<think>hmm [not json]</think>Let me think: e.g. [1] is not it.\n```json\n[\n {\"reason\": \"r1\", \"description\": \"d1\", \"label\": \"Ball grazes cushion\"},\n {\"label\": \"double kiss\", \"description\": \"d2\"}\n]\n```";
        let l = parse_labels(a).unwrap();
        assert_eq!(l.len(), 2);
        assert_eq!(l[0].label, "Ball grazes cushion");
        assert_eq!(
            (l[0].description.as_str(), l[0].reason.as_str()),
            ("d1", "r1")
        );
        assert_eq!(l[1].label, "double kiss");
    }

    #[test]
    fn a_bare_array_of_strings_is_parsed() {
        let l = parse_labels("Here: [\"slow roll\", \"jump shot\"] done").unwrap();
        assert_eq!(
            l.iter().map(|s| s.label.as_str()).collect::<Vec<_>>(),
            ["slow roll", "jump shot"]
        );
    }

    #[test]
    fn bullet_and_numbered_lists_are_parsed() {
        let a = "Suggestions:\n- **Cue ball scratch** — the cue ball drops into a pocket.\n* Long rail run: a ball travels the length of the table.\n1. Cluster break - several balls move at once\n2) Stop shot\nThat is all.";
        let l = parse_labels(a).unwrap();
        let names: Vec<_> = l.iter().map(|s| s.label.as_str()).collect();
        assert_eq!(
            names,
            [
                "Cue ball scratch",
                "Long rail run",
                "Cluster break",
                "Stop shot"
            ]
        );
        assert_eq!(l[0].description, "the cue ball drops into a pocket.");
    }

    /// Seeded random answers stitched from the pieces models emit (fences, think tags, brackets,
    /// bullets, multi-byte text): the parsers return values or typed errors and never panic.
    #[test]
    fn random_answers_never_panic_the_parsers() {
        const PIECES: &[&str] = &[
            "```",
            "```python\n",
            "```json\n",
            "```py",
            "\n",
            "  ",
            "<think>",
            "</think>",
            "def find_pattern(trace):\n",
            "    return []\n",
            "def helper(x):",
            "X = 1\n",
            "[",
            "]",
            "{",
            "}",
            "\"label\": ",
            "\"name\"",
            ",",
            ":",
            "- ",
            "* ",
            "1. ",
            "2) ",
            "— ",
            "–",
            "é",
            "日本",
            "🎱",
            "**",
            "`",
            "\"",
            "null",
            "42",
            "Sure! ",
            "# c\n",
            "else:\n",
            "\r\n",
            "\u{0}",
        ];
        let mut state = 0x5eed_u64;
        let mut next = || {
            state = crate::rng::splitmix64(state);
            state
        };
        for _ in 0..3000 {
            let n = (next() % 24) as usize;
            let text: String = (0..n)
                .map(|_| PIECES[(next() % PIECES.len() as u64) as usize])
                .collect();
            let _ = crate::llm::extract_code(&text);
            let _ = parse_labels(&text);
            let _ = fences(&text);
            let _ = strip_think(&text);
        }
    }

    #[test]
    fn the_outer_array_wins_and_bracket_heavy_answers_stay_cheap() {
        let a = "[{\"label\": \"outer one\", \"description\": \"[\\\"x\\\"]\"}, {\"label\": \"outer two\"}]";
        let l = parse_labels(a).unwrap();
        assert_eq!(l.len(), 2);
        assert_eq!(l[0].description, "[\"x\"]");
        let noisy = format!("{}\n[\"real label\"]", "x[[[[ ]] ".repeat(5_000));
        assert_eq!(parse_labels(&noisy).unwrap()[0].label, "real label");
    }

    #[test]
    fn nothing_usable_is_an_error() {
        assert!(matches!(
            parse_labels("I would rather not."),
            Err(LabelsError::Unparsable { .. })
        ));
        assert!(matches!(
            parse_labels("[]"),
            Err(LabelsError::Unparsable { .. })
        ));
    }
}
