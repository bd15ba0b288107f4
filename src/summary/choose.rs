//! Choosers for the identification task: given a trace and N summaries, pick the one written about it.
//!
//! * [`LlmChooser`] (the paper's): a vision-language model sees keyframes of the trace as image
//!   content parts and the numbered summaries (`prompts/summary/identify.j2`) and answers
//!   `Answer: <n>`. An answer that cannot be read is a wrong trial with its reason, not an error.
//! * [`OfflineChooser`] (a **baseline**, no model, no images): scores each summary by the overlap of
//!   its words with evidence from the trace's *own annotations* — the words of their labels, the
//!   object ids they name and their start times at 0.01 s and 0.1 s — as `|E ∩ S| / sqrt(|E|·|S|)`,
//!   and picks the best, breaking ties with the trial's seed. It measures how well the annotations tell
//!   traces apart in words, not what a model sees in the images; a library that annotates nothing
//!   scores chance.

use std::collections::BTreeSet;
use std::sync::Arc;

use serde_json::json;

use crate::bench::feedback::Image;
use crate::detect::Annotation;
use crate::llm::{ChatRequest, LlmClient, Prompts, strip_think};
use crate::rng::SplitMix64;
use crate::trace::{Env, Trace};

use super::SummaryError;
use super::images::TraceImages;
use super::llm::with_images;

/// What a chooser answered, and what it cost.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Choice {
    /// The chosen option (0-based), or `None` when the answer could not be read.
    pub index: Option<usize>,
    /// Why the answer could not be read.
    pub reason: Option<String>,
    /// Prompt tokens (0 offline).
    pub tokens_in: u64,
    /// Completion tokens (0 offline).
    pub tokens_out: u64,
    /// Seconds.
    pub seconds: f64,
    /// The `llm_calls` call id (empty offline).
    pub call_id: String,
}

/// What a chooser reads of a trace in a trial, taken beforehand from the trace and its own
/// annotations: the `summarise` stage reads traces a block at a time and keeps these, not the traces,
/// until every summary is written and the trials can start.
#[derive(Clone, Debug, PartialEq)]
pub enum TrialView {
    /// The evidence words of the trace's own annotations (the offline chooser).
    Evidence(BTreeSet<String>),
    /// The trace's environment and its keyframes, drawn (the LLM chooser).
    Keyframes {
        /// The environment (named in the prompt).
        env: Env,
        /// The keyframes, in time order.
        images: Vec<Image>,
    },
}

/// Something that picks the summary of a trace among `options`.
pub trait Chooser: Sync {
    /// Its name in the `identification` table (`offline`, `llm`).
    fn name(&self) -> &str;
    /// The model behind it (empty offline).
    fn model(&self) -> String;
    /// What [`Chooser::choose`] reads of `trace`, whose own annotations are `annotations`.
    fn view(&self, trace: &Trace, annotations: &[Annotation]) -> Result<TrialView, SummaryError>;
    /// The option (0-based) that describes the trace seen as `view`; `seed` is the trial's.
    fn choose(&self, view: &TrialView, options: &[&str], seed: u64)
    -> Result<Choice, SummaryError>;
}

/// The error of a chooser given another chooser's view.
fn wrong_view(chooser: &str, view: &TrialView) -> SummaryError {
    let kind = match view {
        TrialView::Evidence(_) => "evidence words",
        TrialView::Keyframes { .. } => "keyframes",
    };
    SummaryError::Setup(format!("the {chooser} chooser was given {kind}"))
}

/// Lower-case words of `text`: runs of letters, digits, `.` and `-`, with trailing `.` removed.
fn words(text: &str) -> BTreeSet<String> {
    text.split(|c: char| !(c.is_alphanumeric() || c == '.' || c == '-' || c == '_'))
        .map(|w| w.trim_matches(|c| c == '.' || c == '-').to_lowercase())
        .filter(|w| !w.is_empty())
        .collect()
}

/// The evidence words of a trace's annotations.
pub(crate) fn evidence(trace: &Trace, annotations: &[Annotation]) -> BTreeSet<String> {
    let mut e = BTreeSet::new();
    for a in annotations.iter().filter(|a| a.trace_id == trace.trace_id) {
        e.extend(words(&a.label).into_iter().filter(|w| w.len() > 2));
        e.extend(a.objects.iter().map(|o| o.to_lowercase()));
        if a.t_start.is_finite() {
            e.insert(format!("{:.2}", a.t_start));
            e.insert(format!("{:.1}", a.t_start));
        }
    }
    e
}

/// The annotation-overlap baseline (`offline`).
#[derive(Clone, Copy, Debug, Default)]
pub struct OfflineChooser;

impl Chooser for OfflineChooser {
    fn name(&self) -> &str {
        "offline"
    }
    fn model(&self) -> String {
        String::new()
    }
    fn view(&self, trace: &Trace, annotations: &[Annotation]) -> Result<TrialView, SummaryError> {
        Ok(TrialView::Evidence(evidence(trace, annotations)))
    }
    fn choose(
        &self,
        view: &TrialView,
        options: &[&str],
        seed: u64,
    ) -> Result<Choice, SummaryError> {
        let t0 = std::time::Instant::now();
        let TrialView::Evidence(e) = view else {
            return Err(wrong_view(self.name(), view));
        };
        let scores: Vec<f64> = options
            .iter()
            .map(|o| {
                let s = words(o);
                if e.is_empty() || s.is_empty() {
                    0.0
                } else {
                    e.intersection(&s).count() as f64 / ((e.len() * s.len()) as f64).sqrt()
                }
            })
            .collect();
        let best = scores.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let tied: Vec<usize> = (0..options.len()).filter(|&i| scores[i] == best).collect();
        let index = match tied.len() {
            0 => None,
            n => Some(tied[SplitMix64::new(seed).below(n)]),
        };
        Ok(Choice {
            index,
            reason: index.is_none().then(|| "no options".to_string()),
            seconds: t0.elapsed().as_secs_f64(),
            ..Choice::default()
        })
    }
}

/// Reads `Answer: <n>` (the last one) or a bare number from a chooser's answer, for `n` options;
/// the 0-based index, or why not.
pub fn parse_choice(answer: &str, n: usize) -> Result<usize, String> {
    let text = strip_think(answer);
    let lower = text.to_lowercase();
    let number = match lower.rfind("answer") {
        Some(at) => {
            let rest = lower[at + "answer".len()..].trim_start_matches([':', ' ', '*', '#', '\t']);
            let rest = rest.trim_start_matches("summary").trim_start();
            let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
            if digits.is_empty() {
                return Err(format!(
                    "unparsable: no number after \"answer\" in {:?}",
                    excerpt(&text)
                ));
            }
            digits
        }
        None => {
            let t = text.trim().trim_end_matches('.');
            if !t.is_empty() && t.chars().all(|c| c.is_ascii_digit()) {
                t.to_string()
            } else {
                return Err(format!(
                    "unparsable: no \"Answer: <n>\" line in {:?}",
                    excerpt(&text)
                ));
            }
        }
    };
    match number.parse::<usize>() {
        Ok(k) if (1..=n).contains(&k) => Ok(k - 1),
        _ => Err(format!("out of range: {number} is not in 1..={n}")),
    }
}

fn excerpt(text: &str) -> String {
    let t = text.trim();
    match t.char_indices().nth(80) {
        Some((i, _)) => format!("{}…", &t[..i]),
        None => t.to_string(),
    }
}

/// A vision-language model choosing from keyframes (`llm`).
#[derive(Debug)]
pub struct LlmChooser {
    /// The client (records and replays calls).
    pub client: Arc<LlmClient>,
    /// Templates, with the summary templates added.
    pub prompts: Arc<Prompts>,
    /// The renderer.
    pub images: Arc<TraceImages>,
    /// Keyframes shown.
    pub keyframes: usize,
}

impl LlmChooser {
    /// The request of one trial on the trace seen as `view` (the keyframes [`Chooser::view`] drew).
    pub fn request(
        &self,
        view: &TrialView,
        options: &[&str],
        seed: u64,
    ) -> Result<ChatRequest, SummaryError> {
        let TrialView::Keyframes { env, images } = view else {
            return Err(wrong_view(self.name(), view));
        };
        let text = self.prompts.render(
            "summary/identify.j2",
            json!({
                "env": env.as_str(),
                "images": images.iter().map(|i| i.caption.clone()).collect::<Vec<_>>(),
                "options": options,
            }),
        )?;
        Ok(ChatRequest::new("identify")
            .message(with_images(text, images))
            .seed(seed))
    }
}

impl Chooser for LlmChooser {
    fn name(&self) -> &str {
        "llm"
    }
    fn model(&self) -> String {
        self.client.model().to_string()
    }
    fn view(&self, trace: &Trace, _annotations: &[Annotation]) -> Result<TrialView, SummaryError> {
        Ok(TrialView::Keyframes {
            env: trace.env,
            images: self.images.keyframes(trace, self.keyframes)?,
        })
    }
    fn choose(
        &self,
        view: &TrialView,
        options: &[&str],
        seed: u64,
    ) -> Result<Choice, SummaryError> {
        let reply = self.client.chat(&self.request(view, options, seed)?)?;
        let (index, reason) = match parse_choice(&reply.content, options.len()) {
            Ok(i) => (Some(i), None),
            Err(why) => (None, Some(why)),
        };
        Ok(Choice {
            index,
            reason,
            tokens_in: reply.tokens_in,
            tokens_out: reply.tokens_out,
            seconds: reply.latency.as_secs_f64(),
            call_id: reply.call_id,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::summary::offline::tests::{ann, trace};

    #[test]
    fn answers_parse_strictly() {
        assert_eq!(parse_choice("Answer: 3", 8), Ok(2));
        assert_eq!(parse_choice("I think 2 fits.\n**Answer:** 5", 8), Ok(4));
        assert_eq!(parse_choice("answer: summary 8", 8), Ok(7));
        assert_eq!(parse_choice("<think>Answer: 1</think>4", 8), Ok(3));
        assert_eq!(parse_choice(" 6.\n", 8), Ok(5));
        assert!(
            parse_choice("Answer: 9", 8)
                .unwrap_err()
                .starts_with("out of range")
        );
        assert!(
            parse_choice("Answer: 0", 8)
                .unwrap_err()
                .starts_with("out of range")
        );
        assert!(
            parse_choice("the third one", 8)
                .unwrap_err()
                .starts_with("unparsable")
        );
        assert!(
            parse_choice("Answer: none", 8)
                .unwrap_err()
                .starts_with("unparsable")
        );
        assert!(parse_choice("", 8).is_err());
    }

    #[test]
    fn offline_chooser_prefers_overlap_and_breaks_ties_by_seed() {
        let t = trace("t1");
        let anns = vec![ann("t1", "cushion rebound", &["cue"], 30, 1.5)];
        let options = [
            "The 3 ball is pocketed at 0.20 s.",
            "A cushion rebound of the cue ball at 1.50 s.",
            "Nothing happens.",
        ];
        let view = OfflineChooser.view(&t, &anns).unwrap();
        let c = OfflineChooser.choose(&view, &options, 1).unwrap();
        assert_eq!(c.index, Some(1));
        // Without annotations every option ties: the seed decides, and different seeds differ.
        let bare = OfflineChooser.view(&t, &[]).unwrap();
        let picks: BTreeSet<usize> = (0..40)
            .map(|s| {
                OfflineChooser
                    .choose(&bare, &options, s)
                    .unwrap()
                    .index
                    .unwrap()
            })
            .collect();
        assert_eq!(picks.len(), 3, "{picks:?}");
        let pick = |s| OfflineChooser.choose(&bare, &options, s).unwrap().index;
        assert_eq!(pick(9), pick(9));
        // Another chooser's view is refused, naming both.
        let keyframes = TrialView::Keyframes {
            env: t.env,
            images: Vec::new(),
        };
        let e = OfflineChooser.choose(&keyframes, &options, 1).unwrap_err();
        assert_eq!(
            e.to_string(),
            "identification: the offline chooser was given keyframes"
        );
    }
}
