//! Client configuration: where the endpoint is, which model, the key, timeouts, retries, concurrency,
//! the budget and replay.
//!
//! [`LlmSettings`] is what a pipeline file (`[llm]` table) or the command line gives; [`LlmConfig`] is
//! the resolved configuration the client runs with. [`LlmConfig::resolve`] merges settings over the
//! `ANNOTRACE_LLM_*` variables, which the caller passes in as a lookup function (the library never reads
//! the process environment itself). The API key is only ever taken from a variable, never from a file,
//! and [`ApiKey`] prints as `[redacted]`.

use std::fmt;
use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;

use super::error::LlmError;

/// Environment variable: the endpoint (`http://localhost:8080`, `http://host:8000/v1`, or the full
/// `…/chat/completions` URL).
pub const ENV_BASE_URL: &str = "ANNOTRACE_LLM_BASE_URL";
/// Environment variable: the model name sent in every request.
pub const ENV_MODEL: &str = "ANNOTRACE_LLM_MODEL";
/// Environment variable: the bearer token (optional; local servers need none).
pub const ENV_API_KEY: &str = "ANNOTRACE_LLM_API_KEY";

/// Default whole-request timeout of one attempt: local models writing a long answer are slow.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(300);
/// Default limit of one call, attempts and waits included: a hung or refusing endpoint ends a call
/// after at most five minutes (exit code 3), instead of `max_retries + 1` full timeouts.
pub const DEFAULT_CALL_TIMEOUT: Duration = Duration::from_secs(300);
/// Default interval of the "still waiting" notices.
pub const DEFAULT_WAIT_NOTICE: Duration = Duration::from_secs(15);

/// A secret bearer token. Its `Debug` and `Display` print `[redacted]`; the only way to the text is
/// [`ApiKey::expose`], used for the `Authorization` header and to scrub recorded text.
#[derive(Clone, PartialEq, Eq)]
pub struct ApiKey(String);

impl ApiKey {
    /// Wraps a key.
    pub fn new(key: impl Into<String>) -> Self {
        ApiKey(key.into())
    }
    /// The key itself.
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for ApiKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("ApiKey([redacted])")
    }
}

impl fmt::Display for ApiKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("[redacted]")
    }
}

/// Caps on what a client may spend. A call is refused with
/// [`LlmError::BudgetExhausted`] once either cap is reached; calls already in flight finish (so the
/// token total can pass `max_tokens` by at most the calls in flight).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Budget {
    /// Most logical calls (retries of one call count once). Replayed calls count too, so a replayed
    /// run stops where the recorded one stopped.
    pub max_calls: Option<u64>,
    /// Most tokens (prompt + completion, as reported or estimated).
    pub max_tokens: Option<u64>,
}

/// Where recorded answers come from, and what a request without one does.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReplayConfig {
    /// The run folder whose `llm_calls` table answers requests.
    pub run: PathBuf,
    /// When true a request with no recorded answer is an error ([`LlmError::ReplayMiss`]); when false
    /// it goes to the endpoint (which must then be configured).
    pub strict: bool,
}

/// Settings as a pipeline file's `[llm]` table or command-line flags give them; every field is
/// optional and overrides the matching `ANNOTRACE_LLM_*` variable. There is deliberately no key field:
/// keys come from `ANNOTRACE_LLM_API_KEY` (or the variable named by `api_key_env`).
///
/// ```toml
/// [llm]
/// base_url = "http://localhost:8080"
/// model = "qwen2.5-coder-7b-instruct"
/// parallel = 4            # the server's parallel slots
/// timeout_s = 300       # one request
/// call_timeout_s = 300  # one call, retries and waits included
/// max_retries = 4
/// max_calls = 500
/// temperature = 0.8
/// ```
#[derive(Clone, Debug, Default, PartialEq, Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LlmSettings {
    /// Endpoint URL (see [`ENV_BASE_URL`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_url: Option<String>,
    /// Model name.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// Name of the environment variable holding the key (default `ANNOTRACE_LLM_API_KEY`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub api_key_env: Option<String>,
    /// Whole-request timeout (s) of one HTTP attempt; default 300 (local models are slow).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub timeout_s: Option<f64>,
    /// The longest one call may take (s), every attempt and wait between attempts included; default
    /// 300. A retry (or a server's `Retry-After`) that does not fit in what is left ends the call at
    /// once instead.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub call_timeout_s: Option<f64>,
    /// While a request is unanswered, a "still waiting" notice every this many seconds (s); default 15.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wait_notice_s: Option<f64>,
    /// Connection timeout (s); default 10.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub connect_timeout_s: Option<f64>,
    /// Retries after the first attempt on 408/429/5xx, timeouts and connection errors; default 4.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_retries: Option<u32>,
    /// First backoff delay (s), doubled per retry; default 1.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backoff_base_s: Option<f64>,
    /// Longest backoff delay (s) of the client's own doubling; default 60. (A server's `Retry-After` is
    /// honoured when it fits in the call's time left, see `call_timeout_s`.)
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backoff_max_s: Option<f64>,
    /// Requests in flight at once (the endpoint's parallel slots); default 4.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parallel: Option<usize>,
    /// Call cap.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_calls: Option<u64>,
    /// Token cap.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_tokens: Option<u64>,
    /// Sampling temperature sent when a request does not set one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temperature: Option<f64>,
    /// `max_tokens` sent when a request does not set one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_output_tokens: Option<u32>,
    /// Seed of the retry jitter (request seeds come from the callers).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Replay answers from this run folder's `llm_calls`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub replay: Option<PathBuf>,
    /// With `replay`: a request with no recorded answer is an error (default true).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub strict_replay: Option<bool>,
}

/// The resolved client configuration.
#[derive(Clone, Debug)]
pub struct LlmConfig {
    /// The endpoint as given (`None`: only replay can answer).
    pub base_url: Option<String>,
    /// Model name sent in every request.
    pub model: String,
    /// Bearer token, if any.
    pub api_key: Option<ApiKey>,
    /// Whole-request timeout of one attempt.
    pub timeout: Duration,
    /// The longest one call may take, attempts and waits included.
    pub call_timeout: Duration,
    /// Interval of the "still waiting" notices while a request is unanswered.
    pub wait_notice: Duration,
    /// Connection timeout.
    pub connect_timeout: Duration,
    /// Retries after the first attempt.
    pub max_retries: u32,
    /// First backoff delay.
    pub backoff_base: Duration,
    /// Longest backoff delay of the client's own doubling.
    pub backoff_max: Duration,
    /// Requests in flight at once.
    pub parallel: usize,
    /// Spending caps.
    pub budget: Budget,
    /// Default temperature.
    pub temperature: Option<f64>,
    /// Default `max_tokens`.
    pub max_output_tokens: Option<u32>,
    /// Seed of the retry jitter.
    pub seed: u64,
    /// Replay source, if any.
    pub replay: Option<ReplayConfig>,
}

impl Default for LlmConfig {
    fn default() -> Self {
        LlmConfig {
            base_url: None,
            model: String::new(),
            api_key: None,
            timeout: DEFAULT_TIMEOUT,
            call_timeout: DEFAULT_CALL_TIMEOUT,
            wait_notice: DEFAULT_WAIT_NOTICE,
            connect_timeout: Duration::from_secs(10),
            max_retries: 4,
            backoff_base: Duration::from_secs(1),
            backoff_max: Duration::from_secs(60),
            parallel: 4,
            budget: Budget::default(),
            temperature: None,
            max_output_tokens: None,
            seed: 0,
            replay: None,
        }
    }
}

fn secs(field: &str, v: f64) -> Result<Duration, LlmError> {
    if v.is_finite() && v > 0.0 && v < 1e7 {
        Ok(Duration::from_secs_f64(v))
    } else {
        Err(LlmError::Config(format!(
            "{field} must be a positive number of seconds, got {v}"
        )))
    }
}

impl LlmConfig {
    /// A configuration for `base_url` and `model` with the defaults above.
    pub fn new(base_url: impl Into<String>, model: impl Into<String>) -> Self {
        LlmConfig {
            base_url: Some(base_url.into()),
            model: model.into(),
            ..LlmConfig::default()
        }
    }

    /// Merges `settings` over the `ANNOTRACE_LLM_*` variables read through `env` (pass
    /// `|k| std::env::var(k).ok()` from the command line). Settings win over variables; the key comes
    /// from a variable only. Fails when neither an endpoint nor a replay source is given, or when no
    /// model is named.
    pub fn resolve(
        settings: &LlmSettings,
        env: &dyn Fn(&str) -> Option<String>,
    ) -> Result<LlmConfig, LlmError> {
        let var = |k: &str| {
            env(k)
                .map(|v| v.trim().to_string())
                .filter(|v| !v.is_empty())
        };
        let key_var = settings.api_key_env.as_deref().unwrap_or(ENV_API_KEY);
        let d = LlmConfig::default();
        let mut c = LlmConfig {
            base_url: settings.base_url.clone().or_else(|| var(ENV_BASE_URL)),
            model: settings
                .model
                .clone()
                .or_else(|| var(ENV_MODEL))
                .unwrap_or_default(),
            api_key: var(key_var).map(ApiKey::new),
            max_retries: settings.max_retries.unwrap_or(d.max_retries),
            parallel: settings.parallel.unwrap_or(d.parallel),
            budget: Budget {
                max_calls: settings.max_calls,
                max_tokens: settings.max_tokens,
            },
            temperature: settings.temperature,
            max_output_tokens: settings.max_output_tokens,
            seed: settings.seed.unwrap_or(0),
            replay: settings.replay.clone().map(|run| ReplayConfig {
                run,
                strict: settings.strict_replay.unwrap_or(true),
            }),
            ..d
        };
        if let Some(v) = settings.timeout_s {
            c.timeout = secs("timeout_s", v)?;
        }
        if let Some(v) = settings.call_timeout_s {
            c.call_timeout = secs("call_timeout_s", v)?;
        }
        if let Some(v) = settings.wait_notice_s {
            c.wait_notice = secs("wait_notice_s", v)?;
        }
        if let Some(v) = settings.connect_timeout_s {
            c.connect_timeout = secs("connect_timeout_s", v)?;
        }
        if let Some(v) = settings.backoff_base_s {
            c.backoff_base = secs("backoff_base_s", v)?;
        }
        if let Some(v) = settings.backoff_max_s {
            c.backoff_max = secs("backoff_max_s", v)?;
        }
        c.validate()?;
        Ok(c)
    }

    /// Checks the configuration: a model, an endpoint or a replay source, sane numbers.
    pub fn validate(&self) -> Result<(), LlmError> {
        if self.model.trim().is_empty() {
            return Err(LlmError::Config(format!(
                "no model: set {ENV_MODEL} or `model` in the [llm] settings"
            )));
        }
        match (&self.base_url, &self.replay) {
            (None, None) => {
                return Err(LlmError::Config(format!(
                    "no endpoint: set {ENV_BASE_URL} (e.g. http://localhost:8080 for a llama.cpp server) \
                     or replay a recorded run"
                )));
            }
            (None, Some(r)) if !r.strict => {
                return Err(LlmError::Config(format!(
                    "non-strict replay sends unrecorded requests to the endpoint, but {ENV_BASE_URL} is not set"
                )));
            }
            _ => {}
        }
        if let Some(url) = &self.base_url {
            endpoint_url(url)?;
        }
        if self.parallel == 0 {
            return Err(LlmError::Config("parallel must be at least 1".into()));
        }
        if let Some(t) = self.temperature
            && !(t.is_finite() && (0.0..=2.0).contains(&t))
        {
            return Err(LlmError::Config(format!(
                "temperature must be within [0, 2], got {t}"
            )));
        }
        Ok(())
    }
}

/// The chat-completions URL for a base URL: a URL ending in `/chat/completions` is kept; one ending
/// in `/v1` (OpenAI's convention, Ollama's `…:11434/v1`) gets `/chat/completions`; anything else
/// (`http://localhost:8080`, llama.cpp's and vLLM's root) gets `/v1/chat/completions`.
pub fn endpoint_url(base: &str) -> Result<String, LlmError> {
    let base = base.trim();
    if !(base.starts_with("http://") || base.starts_with("https://")) {
        return Err(LlmError::Config(format!(
            "{ENV_BASE_URL} must start with http:// or https://, got {:?}",
            redact_url(base)
        )));
    }
    let trimmed = base.trim_end_matches('/');
    let (path_part, query) = match trimmed.split_once('?') {
        Some((p, q)) => (p.trim_end_matches('/'), Some(q)),
        None => (trimmed, None),
    };
    let mut url = if path_part.ends_with("/chat/completions") {
        path_part.to_string()
    } else if path_part.ends_with("/v1") {
        format!("{path_part}/chat/completions")
    } else {
        format!("{path_part}/v1/chat/completions")
    };
    if let Some(q) = query {
        url.push('?');
        url.push_str(q);
    }
    Ok(url)
}

/// A URL fit for logs and tables: user information and the query (where some services put keys) are
/// dropped.
pub fn redact_url(url: &str) -> String {
    let (scheme, rest) = match url.split_once("://") {
        Some((s, r)) => (Some(s), r),
        None => (None, url),
    };
    let rest = rest.split(['?', '#']).next().unwrap_or("");
    let rest = match rest.split_once('/') {
        Some((auth, path)) => {
            let host = auth.rsplit('@').next().unwrap_or(auth);
            format!("{host}/{path}")
        }
        None => rest.rsplit('@').next().unwrap_or(rest).to_string(),
    };
    match scheme {
        Some(s) => format!("{s}://{rest}"),
        None => rest,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let pairs: Vec<(String, String)> = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        move |k| pairs.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone())
    }

    #[test]
    fn endpoint_urls_follow_the_common_base_url_conventions() {
        let e = |s| endpoint_url(s).unwrap();
        assert_eq!(
            e("http://localhost:8080"),
            "http://localhost:8080/v1/chat/completions"
        );
        assert_eq!(
            e("http://localhost:8080/"),
            "http://localhost:8080/v1/chat/completions"
        );
        assert_eq!(e("http://h:11434/v1"), "http://h:11434/v1/chat/completions");
        assert_eq!(
            e("https://api.x.com/openai/v1/"),
            "https://api.x.com/openai/v1/chat/completions"
        );
        assert_eq!(
            e("http://h/v1/chat/completions"),
            "http://h/v1/chat/completions"
        );
        assert_eq!(
            e("http://h/v1?api-version=2"),
            "http://h/v1/chat/completions?api-version=2"
        );
        assert!(endpoint_url("localhost:8080").is_err());
    }

    #[test]
    fn redacted_urls_lose_user_info_and_query() {
        assert_eq!(
            redact_url("https://u:secret@h:1/v1?key=abc"),
            "https://h:1/v1"
        );
        assert_eq!(redact_url("http://h:8080"), "http://h:8080");
    }

    #[test]
    fn settings_win_over_variables_and_the_key_comes_from_a_variable() {
        let env = vars(&[
            (ENV_BASE_URL, "http://a:1"),
            (ENV_MODEL, "m-env"),
            (ENV_API_KEY, "sk-secret"),
        ]);
        let s = LlmSettings {
            model: Some("m-file".into()),
            parallel: Some(2),
            max_calls: Some(5),
            ..LlmSettings::default()
        };
        let c = LlmConfig::resolve(&s, &env).unwrap();
        assert_eq!(c.base_url.as_deref(), Some("http://a:1"));
        assert_eq!(c.model, "m-file");
        assert_eq!(c.parallel, 2);
        assert_eq!(c.budget.max_calls, Some(5));
        assert_eq!(c.api_key.as_ref().unwrap().expose(), "sk-secret");
        assert!(!format!("{c:?}").contains("sk-secret"));
    }

    #[test]
    fn settings_read_from_a_toml_table_and_reject_unknown_keys() {
        let s: LlmSettings = toml::from_str(
            "base_url = \"http://localhost:8080\"\nmodel = \"m\"\nparallel = 2\ntimeout_s = 60\nmax_calls = 10",
        )
        .unwrap();
        assert_eq!(s.parallel, Some(2));
        assert_eq!(s.max_calls, Some(10));
        let c = LlmConfig::resolve(&s, &|_| None).unwrap();
        assert_eq!(c.timeout, Duration::from_secs(60));
        let e = toml::from_str::<LlmSettings>("api_key = \"sk-x\"").unwrap_err();
        assert!(e.to_string().contains("unknown field"), "{e}");
    }

    #[test]
    fn missing_endpoint_or_model_is_a_configuration_error() {
        let e =
            LlmConfig::resolve(&LlmSettings::default(), &vars(&[(ENV_MODEL, "m")])).unwrap_err();
        assert!(e.to_string().contains(ENV_BASE_URL), "{e}");
        let e = LlmConfig::resolve(
            &LlmSettings::default(),
            &vars(&[(ENV_BASE_URL, "http://h")]),
        )
        .unwrap_err();
        assert!(e.to_string().contains(ENV_MODEL), "{e}");
        // Strict replay needs no endpoint.
        let s = LlmSettings {
            replay: Some("runs/x".into()),
            ..LlmSettings::default()
        };
        assert!(LlmConfig::resolve(&s, &vars(&[(ENV_MODEL, "m")])).is_ok());
        let bad = LlmSettings {
            timeout_s: Some(-1.0),
            ..LlmSettings::default()
        };
        assert!(
            LlmConfig::resolve(&bad, &vars(&[(ENV_MODEL, "m"), (ENV_BASE_URL, "http://h")]))
                .is_err()
        );
    }
}
