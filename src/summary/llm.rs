//! The LLM summariser: one chat call per trace to an OpenAI-compatible vision-language endpoint,
//! through [`LlmClient`] (so every call is in `llm_calls`, with its seconds and tokens, and replays).
//!
//! Two modes, the paper's two summary inputs: [`LlmMode::Frames`] shows keyframes of the rollout only
//! (the DeepPHY-style baseline), [`LlmMode::Annotations`] shows the initial image and the annotated
//! trace text ([`crate::detect::annotated_text`]). The prompt is `prompts/summary/summarise.j2`.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::detect::{Annotation, annotated_text};
use crate::digest::{sha256_u64, words_u64};
use crate::llm::{ChatRequest, LlmClient, LlmError, Message, Part, Prompts, Role, strip_think};
use crate::trace::Trace;

use super::images::TraceImages;
use super::{Summariser, Summary, SummaryError};

/// The templates this module adds to [`Prompts`] (name, built-in text).
pub const TEMPLATES: [(&str, &str); 2] = [
    (
        "summary/summarise.j2",
        include_str!("../../prompts/summary/summarise.j2"),
    ),
    (
        "summary/identify.j2",
        include_str!("../../prompts/summary/identify.j2"),
    ),
];

/// Adds the summary and label-suggestion templates (a prompts folder's own files win).
pub fn add_templates(prompts: &mut Prompts) -> Result<(), LlmError> {
    for (name, text) in TEMPLATES.into_iter().chain(super::labels::LABEL_TEMPLATES) {
        prompts.add_template(name, text)?;
    }
    Ok(())
}

/// What the model is shown.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum LlmMode {
    /// Keyframes of the rollout only (the baseline).
    Frames,
    /// The initial image and the annotated trace text.
    Annotations,
}

impl LlmMode {
    /// The mode's name (`frames`, `annotations`).
    pub fn as_str(self) -> &'static str {
        match self {
            LlmMode::Frames => "frames",
            LlmMode::Annotations => "annotations",
        }
    }
}

/// A user message: the text, then each image after its caption.
pub(crate) fn with_images(text: String, images: &[crate::bench::feedback::Image]) -> Message {
    let mut parts = vec![Part::Text(text)];
    for im in images {
        parts.push(Part::Text(format!("[{}]", im.caption)));
        parts.push(Part::png(&im.png));
    }
    Message {
        role: Role::User,
        parts,
    }
}

/// The request seed of trace `trace_id` under `seed`.
pub(crate) fn request_seed(seed: u64, trace_id: &str, purpose: u64) -> u64 {
    words_u64(&[seed, sha256_u64(&[trace_id.as_bytes()]), purpose])
}

/// Summaries from a vision-language model.
#[derive(Debug)]
pub struct LlmSummariser {
    /// The client (records and replays calls).
    pub client: Arc<LlmClient>,
    /// Templates, with [`TEMPLATES`] added.
    pub prompts: Arc<Prompts>,
    /// The renderer.
    pub images: Arc<TraceImages>,
    /// What the model is shown.
    pub mode: LlmMode,
    /// Keyframes in frames mode.
    pub keyframes: usize,
    /// The longest summary asked for, in words.
    pub words: usize,
    /// Seed of the requests (mixed with the trace id).
    pub seed: u64,
}

impl LlmSummariser {
    /// The request for `trace`.
    pub fn request(
        &self,
        trace: &Trace,
        annotations: &[Annotation],
    ) -> Result<(ChatRequest, u64), SummaryError> {
        let (images, annotated) = match self.mode {
            LlmMode::Frames => (self.images.keyframes(trace, self.keyframes)?, None),
            LlmMode::Annotations => (
                vec![self.images.initial(trace)?],
                Some(annotated_text(trace, annotations)),
            ),
        };
        let text = self.prompts.render(
            "summary/summarise.j2",
            json!({
                "env": trace.env.as_str(),
                "mode": self.mode.as_str(),
                "images": images.iter().map(|i| i.caption.clone()).collect::<Vec<_>>(),
                "annotated": annotated,
                "words": self.words,
            }),
        )?;
        let req = ChatRequest::new(format!("summarise_{}", self.mode.as_str()))
            .message(with_images(text, &images))
            .seed(request_seed(self.seed, &trace.trace_id, 0));
        Ok((req, images.len() as u64))
    }
}

impl Summariser for LlmSummariser {
    fn name(&self) -> &str {
        self.mode.as_str()
    }
    fn model(&self) -> String {
        self.client.model().to_string()
    }
    fn summarise(
        &self,
        trace: &Trace,
        annotations: &[Annotation],
    ) -> Result<Summary, SummaryError> {
        let (req, images) = self.request(trace, annotations)?;
        let reply = self.client.chat(&req)?;
        Ok(Summary {
            text: strip_think(&reply.content).trim().to_string(),
            tokens_in: reply.tokens_in,
            tokens_out: reply.tokens_out,
            usage_estimated: reply.usage_estimated,
            seconds: reply.latency.as_secs_f64(),
            images,
            call_id: reply.call_id,
        })
    }
}
