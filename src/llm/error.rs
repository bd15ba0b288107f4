//! Errors of the LLM client: configuration, transport, the endpoint's answers, the budget, replay, the
//! `llm_calls` table and prompt templates. Every variant names what the reader needs to act (the URL,
//! the HTTP status and an excerpt of the body, the request hash, the template).

use std::path::PathBuf;

use crate::store::StoreError;

/// A failure of [`LlmClient`](super::LlmClient) or of the prompt and extraction helpers.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LlmError {
    /// The configuration is incomplete or contradictory (no endpoint, no model, a bad number).
    #[error("LLM configuration: {0}")]
    Config(String),
    /// The endpoint answered with an HTTP error status (after retries for 408/429/5xx).
    #[error("{url}: HTTP {status} after {attempts} attempt(s): {body_excerpt}")]
    Status {
        /// The HTTP status code.
        status: u16,
        /// The endpoint (without credentials or query).
        url: String,
        /// The start of the response body.
        body_excerpt: String,
        /// How many requests were sent.
        attempts: u32,
    },
    /// No complete answer arrived within the timeout (after retries).
    #[error("{url}: no answer within {seconds} s, {attempts} attempt(s)")]
    Timeout {
        /// The endpoint.
        url: String,
        /// The per-request timeout (s).
        seconds: f64,
        /// How many requests were sent.
        attempts: u32,
    },
    /// The endpoint could not be reached (refused, reset, DNS) after retries.
    #[error("{url}: cannot reach the endpoint after {attempts} attempt(s): {message}")]
    Connection {
        /// The endpoint.
        url: String,
        /// What the transport said.
        message: String,
        /// How many requests were sent.
        attempts: u32,
    },
    /// A retryable failure (408/429/5xx, timeout, connection) whose next attempt would not fit in the
    /// call's time limit (`call_timeout_s`), or whose server asked for a `Retry-After` beyond it: the
    /// call ends at once instead of waiting.
    #[error(
        "{url}: gave up after {attempts} attempt(s) in {elapsed_s:.1} s: {reason}; the last attempt: {last}"
    )]
    GaveUp {
        /// The endpoint.
        url: String,
        /// How many requests were sent.
        attempts: u32,
        /// Time the call took (s).
        elapsed_s: f64,
        /// Why no further attempt was made (the limit, or the server's `Retry-After`).
        reason: String,
        /// What the last attempt got.
        last: String,
    },
    /// The endpoint answered 200 but not with a chat completion.
    #[error("{url}: the answer is not a chat completion: {message}")]
    BadResponse {
        /// The endpoint.
        url: String,
        /// What is wrong, with an excerpt of the body.
        message: String,
    },
    /// The call or token budget is used up; no request was sent.
    #[error("LLM budget exhausted: {what}")]
    BudgetExhausted {
        /// Which cap was reached, with the figures.
        what: String,
    },
    /// Strict replay found no recorded answer for a request.
    #[error(
        "replay: no recorded answer for request {request_hash} ({purpose}) in {}; \
         the prompt, model or sampling parameters differ from the recorded run (strict replay)",
        source_dir.display()
    )]
    ReplayMiss {
        /// The request's hash (`llm_calls.request_hash`).
        request_hash: String,
        /// The caller's purpose tag.
        purpose: String,
        /// The run folder replayed from.
        source_dir: PathBuf,
    },
    /// A file of the run could not be read or written.
    #[error("llm_calls: {0}")]
    Store(#[from] StoreError),
    /// A file of the `llm_calls` table does not have the expected columns.
    #[error("{}: {message}", path.display())]
    Table {
        /// The Parquet file.
        path: PathBuf,
        /// What is missing or mistyped.
        message: String,
    },
    /// A prompt template could not be read, parsed or rendered.
    #[error("prompt template {name}: {message}")]
    Template {
        /// The template name (`evolve.j2`) or file.
        name: String,
        /// The template engine's message (with line) or the I/O error.
        message: String,
    },
}

impl LlmError {
    /// True when the budget stopped the call (the caller should end its search cleanly).
    pub fn is_budget(&self) -> bool {
        matches!(self, LlmError::BudgetExhausted { .. })
    }

    /// True for failures of the endpoint itself (unreachable, timing out, refusing service), as
    /// opposed to a bad answer, configuration or replay.
    pub fn is_unavailable(&self) -> bool {
        matches!(
            self,
            LlmError::Status { .. }
                | LlmError::Timeout { .. }
                | LlmError::Connection { .. }
                | LlmError::GaveUp { .. }
        )
    }

    /// True when the request itself is refused, whatever the endpoint's health: the configuration
    /// (no model, a template, a replay that does not hold the call) or a 4xx other than 408 and 429
    /// (credentials, a wrong URL or model name, a prompt too long for the model). Retrying cannot help.
    pub fn is_refusal(&self) -> bool {
        match self {
            LlmError::Config(_) | LlmError::ReplayMiss { .. } | LlmError::Template { .. } => true,
            LlmError::Status { status, .. } => {
                (400..500).contains(status) && !matches!(status, 408 | 429)
            }
            _ => false,
        }
    }
}
