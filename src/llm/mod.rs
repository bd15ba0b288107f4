//! Language models: an OpenAI-compatible chat-completions client, prompt templates, and the parsing of
//! answers into code and labels.
//!
//! **Owns:** the HTTP client ([`LlmClient`]: concurrency limit, timeouts and a time limit per call,
//! retries with seeded backoff, "still waiting" notices ([`WaitNotice`]),
//! budget, recording every attempt in the run's `llm_calls` table, replay from it), its configuration
//! ([`LlmConfig`], from [`LlmSettings`] and the `ANNOTRACE_LLM_*` variables the caller passes in), the
//! prompt templates of `prompts/` ([`Prompts`]), code extraction ([`extract_code`]) and label
//! suggestion ([`suggest_labels`]). **Does not:** read the process environment or argv (`cli/` does and
//! passes an [`LlmConfig`] down), choose or score detectors (`search/`, `fitness/`), or run code
//! (`detect/`). The search's LLM proposer is `search::llm_proposer`.
//!
//! Entry point: [`LlmClient::new`]`(config, Some(&run))`, then [`LlmClient::chat`] with a
//! [`ChatRequest`] from any number of threads.
//!
//! ```no_run
//! use annotrace::llm::{ChatRequest, LlmClient, LlmConfig, LlmSettings, Prompts, extract_code};
//! use annotrace::store::RunDir;
//!
//! let config = LlmConfig::resolve(&LlmSettings::default(), &|k| std::env::var(k).ok())?;
//! let client = LlmClient::new(config, Some(&RunDir::new("runs/demo")))?;
//! let prompts = Prompts::builtin();
//! let req = ChatRequest::new("demo")
//!     .system(prompts.system()?)
//!     .user("Write find_pattern(trace) returning [].")
//!     .seed(7);
//! let reply = client.chat(&req)?;
//! let code = extract_code(&reply.content);
//! # Ok::<(), annotrace::llm::LlmError>(())
//! ```

mod backoff;
mod budget;
mod client;
mod config;
mod error;
mod extract;
mod labels;
mod message;
mod prompt;
pub mod record;
mod replay;
mod slots;
mod waiting;

pub use self::budget::Usage;
pub use self::client::LlmClient;
pub use self::config::{
    ApiKey, Budget, DEFAULT_CALL_TIMEOUT, DEFAULT_TIMEOUT, DEFAULT_WAIT_NOTICE, ENV_API_KEY,
    ENV_BASE_URL, ENV_MODEL, LlmConfig, LlmSettings, ReplayConfig, endpoint_url, redact_url,
};
pub use self::error::LlmError;
pub use self::extract::{ExtractError, Fence, extract_code, fences, strip_think};
pub use self::labels::{
    LabelsError, SuggestParams, SuggestedLabel, Suggestions, parse_labels, suggest_labels,
};
pub(crate) use self::message::base64;
pub use self::message::{ChatReply, ChatRequest, Message, Part, Role};
pub use self::prompt::{
    EvolveContext, LabelsContext, LibraryEntry, ParentView, PromptSource, Prompts, RepairContext,
};
pub use self::record::{CallRecord, read_calls};
pub use self::waiting::{WaitNotice, WaitObserver};
