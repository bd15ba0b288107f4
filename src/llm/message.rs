//! The chat-completions wire format: what a caller asks ([`ChatRequest`], [`Message`]), the JSON body
//! sent, and the parsed answer ([`ChatReply`]).
//!
//! Only the common subset of the OpenAI protocol is used, which llama.cpp's server, vLLM, Ollama and
//! hosted APIs all accept: `model`, `messages` (text, or text and `image_url` parts with base64 PNG data
//! URLs for vision models), `temperature`, `max_tokens`, `seed`, `stop`, `stream: false`. `usage` in the
//! answer is optional.

use std::time::Duration;

use serde::{Deserialize, Serialize};
use serde_json::{Map, Value, json};

/// Who speaks a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Instructions that frame the conversation.
    System,
    /// The caller's prompt.
    User,
    /// A model answer (for few-shot or multi-turn prompts).
    Assistant,
}

/// One part of a multi-part message.
#[derive(Clone, Debug, PartialEq)]
pub enum Part {
    /// Text.
    Text(String),
    /// An image as a `data:` or `https:` URL.
    ImageUrl(String),
}

impl Part {
    /// A PNG image as a base64 `data:` URL part.
    pub fn png(bytes: &[u8]) -> Part {
        Part::ImageUrl(format!("data:image/png;base64,{}", base64(bytes)))
    }
}

/// One message of a conversation.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// The speaker.
    pub role: Role,
    /// Text and images, in order (a plain text message is one [`Part::Text`]).
    pub parts: Vec<Part>,
}

impl Message {
    /// A text message.
    pub fn text(role: Role, text: impl Into<String>) -> Self {
        Message {
            role,
            parts: vec![Part::Text(text.into())],
        }
    }
    /// A system message.
    pub fn system(text: impl Into<String>) -> Self {
        Message::text(Role::System, text)
    }
    /// A user message.
    pub fn user(text: impl Into<String>) -> Self {
        Message::text(Role::User, text)
    }
    /// A user message with a PNG image after the text (sent as a base64 data URL).
    pub fn user_with_png(text: impl Into<String>, png: &[u8]) -> Self {
        Message {
            role: Role::User,
            parts: vec![
                Part::Text(text.into()),
                Part::ImageUrl(format!("data:image/png;base64,{}", base64(png))),
            ],
        }
    }
    /// The text of the message (images left out).
    pub fn text_content(&self) -> String {
        let mut out = String::new();
        for p in &self.parts {
            if let Part::Text(t) = p {
                if !out.is_empty() {
                    out.push('\n');
                }
                out.push_str(t);
            }
        }
        out
    }

    fn to_json(&self) -> Value {
        let content = match self.parts.as_slice() {
            [Part::Text(t)] => Value::String(t.clone()),
            parts => Value::Array(
                parts
                    .iter()
                    .map(|p| match p {
                        Part::Text(t) => json!({"type": "text", "text": t}),
                        Part::ImageUrl(u) => json!({"type": "image_url", "image_url": {"url": u}}),
                    })
                    .collect(),
            ),
        };
        json!({"role": self.role, "content": content})
    }
}

/// A request for one completion. The model comes from the client's configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct ChatRequest {
    /// What the call is for (`evolve`, `repair`, `suggest_labels`, `reward_synthesis`, …); recorded in
    /// `llm_calls.purpose`, not sent.
    pub purpose: String,
    /// The conversation.
    pub messages: Vec<Message>,
    /// Sampling temperature (the client's default when `None`).
    pub temperature: Option<f64>,
    /// Completion token cap (the client's default when `None`).
    pub max_tokens: Option<u32>,
    /// The request's seed: sent to the server (which may or may not honour it) and part of the request
    /// hash, so the same search asks the same questions and replays them.
    pub seed: Option<u64>,
    /// Stop sequences.
    pub stop: Vec<String>,
    /// Where the request queues for one of the client's slots when all are taken: lower orders are
    /// admitted first, `None` after every ordered request (`llm::slots`). Neither sent nor hashed.
    pub order: Option<u64>,
}

impl ChatRequest {
    /// An empty request for `purpose`.
    pub fn new(purpose: impl Into<String>) -> Self {
        ChatRequest {
            purpose: purpose.into(),
            messages: Vec::new(),
            temperature: None,
            max_tokens: None,
            seed: None,
            stop: Vec::new(),
            order: None,
        }
    }
    /// Adds a message.
    pub fn message(mut self, m: Message) -> Self {
        self.messages.push(m);
        self
    }
    /// Adds a system message.
    pub fn system(self, text: impl Into<String>) -> Self {
        self.message(Message::system(text))
    }
    /// Adds a user message.
    pub fn user(self, text: impl Into<String>) -> Self {
        self.message(Message::user(text))
    }
    /// Sets the seed.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = Some(seed);
        self
    }
    /// Sets the order in which the request is admitted to a slot when it has to wait for one.
    pub fn order(mut self, order: u64) -> Self {
        self.order = Some(order);
        self
    }
    /// Sets the temperature.
    pub fn temperature(mut self, t: f64) -> Self {
        self.temperature = Some(t);
        self
    }
    /// Sets the completion token cap.
    pub fn max_tokens(mut self, n: u32) -> Self {
        self.max_tokens = Some(n);
        self
    }

    /// The JSON body sent for `model`, with the client's defaults filled in. Keys are in a fixed order
    /// so equal requests serialise (and hash) equally.
    pub(crate) fn body(
        &self,
        model: &str,
        default_temperature: Option<f64>,
        default_max_tokens: Option<u32>,
    ) -> Value {
        let mut m = Map::new();
        m.insert("model".into(), Value::String(model.to_string()));
        m.insert(
            "messages".into(),
            Value::Array(self.messages.iter().map(Message::to_json).collect()),
        );
        if let Some(t) = self.temperature.or(default_temperature) {
            m.insert("temperature".into(), json!(t));
        }
        if let Some(n) = self.max_tokens.or(default_max_tokens) {
            m.insert("max_tokens".into(), json!(n));
        }
        if let Some(s) = self.seed {
            m.insert("seed".into(), json!(s));
        }
        if !self.stop.is_empty() {
            m.insert("stop".into(), json!(self.stop));
        }
        m.insert("stream".into(), Value::Bool(false));
        Value::Object(m)
    }
}

/// A completion and what it cost.
#[derive(Clone, Debug, PartialEq)]
pub struct ChatReply {
    /// The assistant's text (empty if it sent none).
    pub content: String,
    /// `finish_reason` of the first choice (`stop`, `length`, …), if given.
    pub finish_reason: Option<String>,
    /// Prompt tokens (from `usage`, or estimated).
    pub tokens_in: u64,
    /// Completion tokens (from `usage`, or estimated).
    pub tokens_out: u64,
    /// True when the server gave no `usage` and the counts are `detect::count_tokens` estimates.
    pub usage_estimated: bool,
    /// Wall time of the successful attempt (as recorded, for a replayed answer).
    pub latency: Duration,
    /// Requests sent for this call (0 when replayed).
    pub attempts: u32,
    /// True when the answer came from a recorded `llm_calls` table.
    pub replayed: bool,
    /// The request's hash (`llm_calls.request_hash`).
    pub request_hash: String,
    /// The call's id (`llm_calls.call_id`).
    pub call_id: String,
}

/// What a 200 answer parsed to.
#[derive(Debug)]
pub(crate) struct ParsedAnswer {
    pub content: String,
    pub finish_reason: Option<String>,
    pub usage: Option<(u64, u64)>,
}

#[derive(Deserialize)]
struct RawAnswer {
    choices: Vec<RawChoice>,
    #[serde(default)]
    usage: Option<RawUsage>,
}

#[derive(Deserialize)]
struct RawChoice {
    #[serde(default)]
    message: Option<RawMessage>,
    /// Legacy completions answer.
    #[serde(default)]
    text: Option<String>,
    #[serde(default)]
    finish_reason: Option<String>,
}

#[derive(Deserialize)]
struct RawMessage {
    #[serde(default)]
    content: Option<Value>,
}

#[derive(Deserialize)]
struct RawUsage {
    #[serde(default)]
    prompt_tokens: Option<u64>,
    #[serde(default)]
    completion_tokens: Option<u64>,
}

/// Parses a chat-completions answer body. `content` may be a string, `null` or an array of text parts.
pub(crate) fn parse_answer(body: &str) -> Result<ParsedAnswer, String> {
    let raw: RawAnswer =
        serde_json::from_str(body).map_err(|e| format!("{e}: {}", excerpt(body, 200)))?;
    let Some(first) = raw.choices.into_iter().next() else {
        return Err(format!("no choices: {}", excerpt(body, 200)));
    };
    let content = match first.message.and_then(|m| m.content) {
        Some(Value::String(s)) => s,
        Some(Value::Array(parts)) => parts
            .iter()
            .filter_map(|p| p.get("text").and_then(Value::as_str))
            .collect::<Vec<_>>()
            .join(""),
        Some(Value::Null) | None => first.text.unwrap_or_default(),
        Some(other) => return Err(format!("message.content is {other}, expected text")),
    };
    let usage = raw
        .usage
        .and_then(|u| match (u.prompt_tokens, u.completion_tokens) {
            (Some(p), Some(c)) => Some((p, c)),
            _ => None,
        });
    Ok(ParsedAnswer {
        content,
        finish_reason: first.finish_reason,
        usage,
    })
}

/// The first `n` characters of `s`, with `…` when cut.
pub(crate) fn excerpt(s: &str, n: usize) -> String {
    let mut out: String = s.chars().take(n).collect();
    if s.chars().nth(n).is_some() {
        out.push('…');
    }
    out
}

/// Standard base64 with padding (for image data URLs).
pub(crate) fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        out.push(A[(n >> 18) as usize & 63] as char);
        out.push(A[(n >> 12) as usize & 63] as char);
        out.push(if chunk.len() > 1 {
            A[(n >> 6) as usize & 63] as char
        } else {
            '='
        });
        out.push(if chunk.len() > 2 {
            A[n as usize & 63] as char
        } else {
            '='
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bodies_are_deterministic_and_fill_defaults() {
        let r = ChatRequest::new("t").system("s").user("u").seed(7);
        let a = r.body("m", Some(0.5), Some(100)).to_string();
        let b = r.body("m", Some(0.5), Some(100)).to_string();
        assert_eq!(a, b);
        assert_eq!(
            a,
            r#"{"model":"m","messages":[{"role":"system","content":"s"},{"role":"user","content":"u"}],"temperature":0.5,"max_tokens":100,"seed":7,"stream":false}"#
        );
        let own = ChatRequest::new("t")
            .user("u")
            .temperature(0.1)
            .body("m", Some(0.5), None);
        assert_eq!(own["temperature"], 0.1);
        assert!(own.get("max_tokens").is_none());
    }

    #[test]
    fn images_go_as_data_url_parts() {
        let m = Message::user_with_png("look", &[1, 2, 3, 4]);
        let j = m.to_json();
        assert_eq!(j["content"][0]["text"], "look");
        assert_eq!(
            j["content"][1]["image_url"]["url"],
            "data:image/png;base64,AQIDBA=="
        );
        assert_eq!(base64(b"Man"), "TWFu");
        assert_eq!(base64(b"Ma"), "TWE=");
    }

    #[test]
    fn answers_parse_with_and_without_usage() {
        let a = parse_answer(
            r#"{"choices":[{"message":{"role":"assistant","content":"hi"},"finish_reason":"stop"}],"usage":{"prompt_tokens":3,"completion_tokens":1}}"#,
        )
        .unwrap();
        assert_eq!((a.content.as_str(), a.usage), ("hi", Some((3, 1))));
        let b = parse_answer(r#"{"choices":[{"message":{"content":[{"type":"text","text":"a"},{"type":"text","text":"b"}]}}]}"#)
            .unwrap();
        assert_eq!((b.content.as_str(), b.usage), ("ab", None));
        assert!(parse_answer(r#"{"choices":[]}"#).is_err());
        assert!(parse_answer("<html>proxy</html>").is_err());
    }
}
