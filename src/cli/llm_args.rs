//! The LLM flags every command that calls a model shares (`#[command(flatten)]`), and the one place
//! the CLI reads the `ANNOTRACE_LLM_*` and `ANNOTRACE_PROMPTS` variables.

use std::path::PathBuf;

use annotrace::llm::{LlmConfig, LlmError, LlmSettings, Prompts};
use anyhow::anyhow;

use super::CliError;

/// The LLM flags shared by commands that call a model.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct LlmArgs {
    /// Endpoint URL (overrides ANNOTRACE_LLM_BASE_URL), e.g. http://localhost:8080.
    #[arg(long)]
    pub llm_base_url: Option<String>,
    /// Model name (overrides ANNOTRACE_LLM_MODEL).
    #[arg(long)]
    pub llm_model: Option<String>,
    /// Timeout of one HTTP request in seconds (default 300).
    #[arg(long)]
    pub llm_timeout: Option<f64>,
    /// The longest one LLM call may take in seconds, retries and waits included (default 300); an
    /// endpoint that hangs or keeps refusing fails the command after this long (exit 3).
    #[arg(long)]
    pub llm_call_timeout: Option<f64>,
    /// Retries on 408/429/5xx, timeouts and connection errors (default 4).
    #[arg(long)]
    pub llm_retries: Option<u32>,
    /// Requests in flight at once: the endpoint's parallel slots (default 4).
    #[arg(long)]
    pub llm_parallel: Option<usize>,
    /// Stop after this many LLM calls.
    #[arg(long)]
    pub llm_max_calls: Option<u64>,
    /// Stop after this many tokens (prompt + completion).
    #[arg(long)]
    pub llm_max_tokens: Option<u64>,
    /// Answer from this run's recorded llm_calls instead of the endpoint.
    #[arg(long, value_name = "RUN")]
    pub replay: Option<PathBuf>,
    /// With --replay: send requests that have no recorded answer to the endpoint instead of failing.
    #[arg(long, requires = "replay")]
    pub replay_fallback: bool,
    /// Folder of prompt templates overriding the built-in ones file by file (default: ANNOTRACE_PROMPTS,
    /// else ./prompts when it exists).
    #[arg(long, value_name = "DIR")]
    pub prompts: Option<PathBuf>,
}

impl LlmArgs {
    /// The settings these flags give.
    pub fn settings(&self) -> LlmSettings {
        LlmSettings {
            base_url: self.llm_base_url.clone(),
            model: self.llm_model.clone(),
            timeout_s: self.llm_timeout,
            call_timeout_s: self.llm_call_timeout,
            max_retries: self.llm_retries,
            parallel: self.llm_parallel,
            max_calls: self.llm_max_calls,
            max_tokens: self.llm_max_tokens,
            replay: self.replay.clone(),
            strict_replay: self.replay.as_ref().map(|_| !self.replay_fallback),
            ..LlmSettings::default()
        }
    }

    /// The resolved configuration: flags over `ANNOTRACE_LLM_*` (exit 2 when incomplete).
    pub fn config(&self, seed: u64) -> Result<LlmConfig, CliError> {
        let mut s = self.settings();
        s.seed = Some(seed);
        if let Some(r) = &self.replay
            && !r.is_dir()
        {
            return Err(CliError::input(anyhow!(
                "--replay {}: no such run folder",
                r.display()
            )));
        }
        LlmConfig::resolve(&s, &|k| std::env::var(k).ok()).map_err(CliError::input)
    }

    /// The prompt templates: `--prompts`, else `ANNOTRACE_PROMPTS`, else `./prompts` if it exists,
    /// else the built-in ones.
    pub fn prompts(&self) -> Result<Prompts, CliError> {
        let dir = self
            .prompts
            .clone()
            .or_else(|| std::env::var_os("ANNOTRACE_PROMPTS").map(PathBuf::from))
            .or_else(|| Some(PathBuf::from("prompts")).filter(|p| p.is_dir()));
        if let Some(d) = &dir
            && !d.is_dir()
        {
            return Err(CliError::input(anyhow!(
                "prompts folder {}: not found",
                d.display()
            )));
        }
        Prompts::load(dir.as_deref()).map_err(CliError::input)
    }
}

/// A client error, with its category: configuration and replay misses are the user's (2), an
/// unreachable or failing endpoint is a service failure (3), a bad answer or the budget a run-time
/// failure (1).
pub fn llm_error(e: LlmError) -> CliError {
    CliError::of(e)
}
