//! [`LlmClient`]: one OpenAI-compatible chat-completions endpoint, shared by every thread of a run.
//!
//! A call ([`LlmClient::chat`]) goes: budget check → replay lookup (when replaying) → a free slot of the
//! concurrency limit → one HTTP request → on 408/429/5xx, a timeout or a connection error, a backoff
//! (seeded jitter, at least the server's `Retry-After`) and another request, up to `max_retries` →
//! the answer, with token counts from `usage` or estimated. Every attempt becomes an `llm_calls` row.
//!
//! Time is bounded per call: no attempt outlives `call_timeout` (its request timeout is cut to the time
//! left), and a retry whose wait — the backoff or the server's `Retry-After` — would not leave time for
//! another attempt is not made: the call ends at once with [`LlmError::GaveUp`]. While requests are
//! unanswered, the client's watch thread (`llm::waiting`) reports progress and writes recorded rows.
//!
//! It uses reqwest's **blocking** API: every caller in annotrace is synchronous (search threads, the
//! CLI), and parallelism comes from calling one shared client from several threads. Do not call it
//! from inside an async runtime.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant, SystemTime};

use super::backoff::{delay, parse_retry_after};
use super::budget::{Meter, Usage};
use super::config::{LlmConfig, endpoint_url, redact_url};
use super::error::LlmError;
use super::message::{ChatReply, ChatRequest, excerpt, parse_answer};
use super::record::{CallLog, CallRecord, now_ms, status};
use super::replay::ReplayIndex;
use super::slots::Slots;
use super::waiting::{Board, WaitObserver, Watch};
use crate::detect::count_tokens;
use crate::digest::sha256_hex;
use crate::rng::splitmix64;
use crate::store::RunDir;

/// The least time worth starting another attempt with: a retry that would leave less of the call's
/// limit is not made.
const MIN_ATTEMPT: Duration = Duration::from_secs(1);

/// Keys shorter than this are not scrubbed from recorded text (replacing every `x` would mangle the
/// record, and such a key is no secret).
const MIN_SCRUB_LEN: usize = 8;

static SESSIONS: AtomicU64 = AtomicU64::new(0);

/// A chat-completions client with a concurrency limit, retries, a budget, recording and replay.
///
/// ```no_run
/// use annotrace::llm::{ChatRequest, LlmClient, LlmConfig};
/// use annotrace::store::RunDir;
///
/// let client = LlmClient::new(
///     LlmConfig::new("http://localhost:8080", "qwen2.5-coder-7b-instruct"),
///     Some(&RunDir::new("runs/demo")),
/// )?;
/// let reply = client.chat(&ChatRequest::new("demo").user("Say hello.").seed(1))?;
/// println!("{} ({} + {} tokens)", reply.content, reply.tokens_in, reply.tokens_out);
/// client.flush()?; // also done on drop
/// # Ok::<(), annotrace::llm::LlmError>(())
/// ```
#[derive(Debug)]
pub struct LlmClient {
    config: LlmConfig,
    endpoint: Option<String>,
    shown: String,
    http: Option<reqwest::blocking::Client>,
    slots: Slots,
    meter: Meter,
    log: Option<Arc<CallLog>>,
    board: Option<Arc<Board>>,
    /// Declared after `log` and `board`'s owners above only by convention: it holds them weakly.
    _watch: Option<Watch>,
    replay: Option<ReplayIndex>,
    record_replayed: bool,
    session: String,
    seq: AtomicU64,
}

/// One call of [`LlmClient::chat`]: the request, its id and the body sent on every attempt.
struct Call<'r> {
    req: &'r ChatRequest,
    /// `<session>-<n>`.
    call_id: String,
    body_text: String,
    /// SHA-256 of `body_text`: the replay key.
    request_hash: String,
    /// SHA-256 of the messages alone.
    prompt_hash: String,
}

/// What one HTTP attempt gave.
enum Attempt {
    Ok {
        http_status: u16,
        body: String,
        content: String,
        finish_reason: Option<String>,
        usage: Option<(u64, u64)>,
    },
    Failed {
        status: &'static str,
        http_status: Option<u16>,
        body: Option<String>,
        message: String,
        retry_after: Option<Duration>,
        retryable: bool,
    },
}

impl LlmClient {
    /// A client for `config`, recording every call into `record`'s `llm_calls` table when given.
    /// Opens the replay source when the configuration has one.
    pub fn new(config: LlmConfig, record: Option<&RunDir>) -> Result<Self, LlmError> {
        config.validate()?;
        let endpoint = config.base_url.as_deref().map(endpoint_url).transpose()?;
        let shown = endpoint.as_deref().map(redact_url).unwrap_or_default();
        let http = match &endpoint {
            Some(url) => {
                let mut b = reqwest::blocking::Client::builder()
                    .timeout(config.timeout)
                    .connect_timeout(config.connect_timeout)
                    .user_agent(format!("annotrace/{}", crate::VERSION));
                // A server on this machine is reached directly even when HTTP(S)_PROXY is set
                // without a NO_PROXY for it (other hosts follow the proxy variables).
                if is_loopback(url) {
                    b = b.no_proxy();
                }
                Some(
                    b.build()
                        .map_err(|e| LlmError::Config(format!("HTTP client: {e}")))?,
                )
            }
            None => None,
        };
        let replay = config
            .replay
            .as_ref()
            .map(|r| ReplayIndex::open(&r.run))
            .transpose()?;
        let record_replayed = match (record, &config.replay) {
            (Some(rec), Some(rep)) => !same_dir(rec.root(), &rep.run),
            _ => false,
        };
        let session = format!(
            "{}-{}-{}",
            now_ms(),
            std::process::id(),
            SESSIONS.fetch_add(1, Ordering::Relaxed)
        );
        let log = record.map(|r| Arc::new(CallLog::new(r, &session)));
        let board = endpoint.is_some().then(|| {
            Arc::new(Board::new(
                shown.clone(),
                config.max_retries.saturating_add(1),
                config.call_timeout,
                config.wait_notice,
            ))
        });
        let watch = (log.is_some() || board.is_some()).then(|| {
            Watch::start(
                board.as_ref().map(Arc::downgrade),
                log.as_ref().map(Arc::downgrade),
            )
        });
        Ok(LlmClient {
            slots: Slots::new(config.parallel),
            meter: Meter::new(config.budget),
            log,
            board,
            _watch: watch,
            endpoint,
            shown,
            http,
            replay,
            record_replayed,
            session,
            seq: AtomicU64::new(0),
            config,
        })
    }

    /// The configuration in use (its `Debug` hides the key).
    pub fn config(&self) -> &LlmConfig {
        &self.config
    }

    /// The model name sent.
    pub fn model(&self) -> &str {
        &self.config.model
    }

    /// This client's session id (`llm_calls.session`).
    pub fn session(&self) -> &str {
        &self.session
    }

    /// What has been spent so far.
    pub fn usage(&self) -> Usage {
        self.meter.usage()
    }

    /// Sends the "still waiting" notices ([`WaitNotice`](super::WaitNotice)) to `observer` instead of
    /// the log (`WARN` lines). Notices come from the client's watch thread.
    pub fn set_wait_observer(&self, observer: WaitObserver) {
        if let Some(b) = &self.board {
            b.set_observer(Some(observer));
        }
    }

    /// Sends the notices to the log again (and drops the observer set before).
    pub fn clear_wait_observer(&self) {
        if let Some(b) = &self.board {
            b.set_observer(None);
        }
    }

    /// Writes buffered `llm_calls` rows now (also done every few calls, within about a second of a
    /// row's arrival, and on drop).
    pub fn flush(&self) -> Result<(), LlmError> {
        match &self.log {
            Some(log) => log.flush(),
            None => Ok(()),
        }
    }

    /// The SHA-256 of the body this client would send for `req` (the replay key).
    pub fn request_hash(&self, req: &ChatRequest) -> String {
        sha256_hex(self.body(req).to_string().as_bytes())
    }

    fn body(&self, req: &ChatRequest) -> serde_json::Value {
        req.body(
            &self.config.model,
            self.config.temperature,
            self.config.max_output_tokens,
        )
    }

    /// `s` with the API key replaced by `[redacted]`: applied to everything the client logs, records or
    /// returns (an endpoint may echo the key in headers, error bodies or answers).
    fn scrub(&self, s: &str) -> String {
        match &self.config.api_key {
            Some(k) if k.expose().len() >= MIN_SCRUB_LEN => s.replace(k.expose(), "[redacted]"),
            _ => s.to_string(),
        }
    }

    fn record(&self, row: CallRecord) -> Result<(), LlmError> {
        match &self.log {
            Some(log) => log.push(CallRecord {
                request_json: self.scrub(&row.request_json),
                response_json: row.response_json.as_deref().map(|s| self.scrub(s)),
                content: row.content.as_deref().map(|s| self.scrub(s)),
                error: row.error.as_deref().map(|s| self.scrub(s)),
                ..row
            }),
            None => Ok(()),
        }
    }

    /// Asks for one completion. See the module docs for the order of checks, retries and recording.
    pub fn chat(&self, req: &ChatRequest) -> Result<ChatReply, LlmError> {
        let call = self.prepare(req)?;
        if let Some(reply) = self.replayed(&call)? {
            return Ok(reply);
        }
        let (Some(http), Some(endpoint)) = (&self.http, &self.endpoint) else {
            return Err(LlmError::Config(
                "no endpoint configured (ANNOTRACE_LLM_BASE_URL)".into(),
            ));
        };
        self.send_with_retries(&call, http, endpoint)
    }

    /// Checks the request, reserves a call from the budget and names the call.
    fn prepare<'r>(&self, req: &'r ChatRequest) -> Result<Call<'r>, LlmError> {
        if req.messages.is_empty() {
            return Err(LlmError::Config(format!(
                "request {:?} has no messages",
                req.purpose
            )));
        }
        let body = self.body(req);
        let body_text = body.to_string();
        let request_hash = sha256_hex(body_text.as_bytes());
        let prompt_hash = sha256_hex(body["messages"].to_string().as_bytes());
        self.meter.reserve()?;
        let call_id = format!(
            "{}-{}",
            self.session,
            self.seq.fetch_add(1, Ordering::Relaxed)
        );
        Ok(Call {
            req,
            call_id,
            body_text,
            request_hash,
            prompt_hash,
        })
    }

    /// The `llm_calls` row of attempt `attempt` (0: replayed) of `call`, started at
    /// `started_at_ms`, before its outcome is filled in.
    fn row(&self, call: &Call<'_>, attempt: i32, started_at_ms: i64) -> CallRecord {
        CallRecord {
            call_id: call.call_id.clone(),
            session: self.session.clone(),
            attempt,
            purpose: call.req.purpose.clone(),
            model: self.config.model.clone(),
            endpoint: self.shown.clone(),
            request_hash: call.request_hash.clone(),
            prompt_hash: call.prompt_hash.clone(),
            seed: call.req.seed,
            request_json: call.body_text.clone(),
            response_json: None,
            content: None,
            status: status::OK.into(),
            http_status: None,
            error: None,
            tokens_in: 0,
            tokens_out: 0,
            usage_estimated: false,
            latency_ms: 0.0,
            replayed: false,
            started_at_ms,
        }
    }

    /// The recorded answer to `call` when replaying (recorded again as a replayed row when the
    /// configuration asks); a miss is an error under strict replay, else `None`.
    fn replayed(&self, call: &Call<'_>) -> Result<Option<ChatReply>, LlmError> {
        let Some(replay) = &self.replay else {
            return Ok(None);
        };
        if let Some(ans) = replay.take(&call.request_hash) {
            self.meter.add_tokens(ans.tokens_in, ans.tokens_out, true);
            if self.record_replayed {
                self.record(CallRecord {
                    response_json: ans.response_json.clone(),
                    content: Some(ans.content.clone()),
                    tokens_in: ans.tokens_in as i64,
                    tokens_out: ans.tokens_out as i64,
                    usage_estimated: ans.usage_estimated,
                    latency_ms: ans.latency_ms,
                    replayed: true,
                    ..self.row(call, 0, now_ms())
                })?;
            }
            return Ok(Some(ChatReply {
                content: ans.content,
                finish_reason: None,
                tokens_in: ans.tokens_in,
                tokens_out: ans.tokens_out,
                usage_estimated: ans.usage_estimated,
                latency: Duration::from_secs_f64(ans.latency_ms.max(0.0) / 1e3),
                attempts: 0,
                replayed: true,
                request_hash: call.request_hash.clone(),
                call_id: call.call_id.clone(),
            }));
        }
        if self.config.replay.as_ref().is_some_and(|r| r.strict) {
            return Err(LlmError::ReplayMiss {
                request_hash: call.request_hash.clone(),
                purpose: call.req.purpose.clone(),
                source_dir: replay.run().to_path_buf(),
            });
        }
        Ok(None)
    }

    /// Sends `call` until it succeeds, fails for good or runs out of retries, recording every
    /// attempt; waits between attempts with seeded jitter.
    fn send_with_retries(
        &self,
        call: &Call<'_>,
        http: &reqwest::blocking::Client,
        endpoint: &str,
    ) -> Result<ChatReply, LlmError> {
        let jitter_seed = splitmix64(
            self.config.seed
                ^ call.req.seed.unwrap_or_else(|| {
                    u64::from_str_radix(&call.request_hash[..16], 16).unwrap_or(0)
                }),
        );
        // The call's clock starts when its first attempt has a slot: waiting for a slot is the run's
        // own queue (more proposals than the endpoint's parallel slots), not the endpoint's delay.
        let mut clock: Option<(Instant, Instant)> = None;
        let mut attempt: u32 = 0;
        loop {
            attempt += 1;
            let started_at_ms = now_ms();
            let t0 = Instant::now();
            let (timeout, call_started, deadline);
            let outcome = {
                let _slot = self.slots.acquire(call.req.order);
                (call_started, deadline) = *clock.get_or_insert_with(|| {
                    let now = Instant::now();
                    (now, now + self.config.call_timeout)
                });
                timeout = self.config.timeout.min(
                    deadline
                        .saturating_duration_since(Instant::now())
                        .max(MIN_ATTEMPT),
                );
                let _waiting = self
                    .board
                    .as_ref()
                    .map(|b| b.enter(&call.req.purpose, attempt, call_started));
                self.meter.add_request();
                self.send_once(http, endpoint, &call.body_text, timeout)
            };
            let latency = t0.elapsed();
            let latency_ms = latency.as_secs_f64() * 1e3;
            let row = self.row(call, attempt as i32, started_at_ms);
            match outcome {
                Attempt::Ok {
                    http_status,
                    body,
                    content,
                    finish_reason,
                    usage,
                } => {
                    let (tokens_in, tokens_out, usage_estimated) = match usage {
                        Some((i, o)) => (i, o, false),
                        None => (
                            estimate_prompt(call.req),
                            count_tokens(&content) as u64,
                            true,
                        ),
                    };
                    self.meter.add_tokens(tokens_in, tokens_out, false);
                    self.record(CallRecord {
                        response_json: Some(body),
                        content: Some(content.clone()),
                        http_status: Some(i32::from(http_status)),
                        tokens_in: tokens_in as i64,
                        tokens_out: tokens_out as i64,
                        usage_estimated,
                        latency_ms,
                        ..row
                    })?;
                    return Ok(ChatReply {
                        content: self.scrub(&content),
                        finish_reason,
                        tokens_in,
                        tokens_out,
                        usage_estimated,
                        latency,
                        attempts: attempt,
                        replayed: false,
                        request_hash: call.request_hash.clone(),
                        call_id: call.call_id.clone(),
                    });
                }
                Attempt::Failed {
                    status: st,
                    http_status,
                    body,
                    message,
                    retry_after,
                    retryable,
                } => {
                    self.record(CallRecord {
                        response_json: body.clone(),
                        status: st.into(),
                        http_status: http_status.map(i32::from),
                        error: Some(message.clone()),
                        latency_ms,
                        ..row
                    })?;
                    if retryable && attempt <= self.config.max_retries {
                        let wait = delay(
                            self.config.backoff_base,
                            self.config.backoff_max,
                            attempt,
                            jitter_seed,
                            retry_after,
                        );
                        let left = deadline.saturating_duration_since(Instant::now());
                        if wait.saturating_add(MIN_ATTEMPT) > left {
                            return Err(self.gave_up(
                                attempt,
                                call_started,
                                retry_after.filter(|ra| *ra >= wait),
                                left,
                                &message,
                            ));
                        }
                        tracing::warn!(
                            "{}: {}; retry {attempt} of {} in {:.1} s",
                            self.shown,
                            self.scrub(&message),
                            self.config.max_retries,
                            wait.as_secs_f64()
                        );
                        std::thread::sleep(wait);
                        continue;
                    }
                    return Err(self.final_error(st, http_status, body, message, attempt, timeout));
                }
            }
        }
    }

    /// The error of a call that stops retrying because the next attempt would not fit in its time limit
    /// (`retry_after`: the server's wait, when that is what did not fit).
    fn gave_up(
        &self,
        attempts: u32,
        call_started: Instant,
        retry_after: Option<Duration>,
        left: Duration,
        last: &str,
    ) -> LlmError {
        let limit = self.config.call_timeout.as_secs_f64();
        let reason = match retry_after {
            Some(ra) => format!(
                "the endpoint asks to retry after {:.0} s, more than the {:.0} s left of the call's \
                 {limit:.0} s limit (call_timeout_s)",
                ra.as_secs_f64(),
                left.as_secs_f64()
            ),
            None => format!("the call's time limit of {limit:.0} s (call_timeout_s) is used up"),
        };
        LlmError::GaveUp {
            url: self.shown.clone(),
            attempts,
            elapsed_s: call_started.elapsed().as_secs_f64(),
            reason,
            last: self.scrub(last),
        }
    }

    /// The error of a call whose last attempt failed with `st` (after `attempts` attempts).
    fn final_error(
        &self,
        st: &'static str,
        http_status: Option<u16>,
        body: Option<String>,
        message: String,
        attempts: u32,
        timeout: Duration,
    ) -> LlmError {
        let url = self.shown.clone();
        match (st, http_status) {
            (status::HTTP_ERROR, Some(code)) => LlmError::Status {
                status: code,
                url,
                body_excerpt: self.scrub(&excerpt(body.as_deref().unwrap_or(""), 300)),
                attempts,
            },
            (status::TIMEOUT, _) => LlmError::Timeout {
                url,
                seconds: timeout.as_secs_f64(),
                attempts,
            },
            (status::BAD_RESPONSE, _) => LlmError::BadResponse {
                url,
                message: self.scrub(&message),
            },
            _ => LlmError::Connection {
                url,
                message: self.scrub(&message),
                attempts,
            },
        }
    }

    fn send_once(
        &self,
        http: &reqwest::blocking::Client,
        endpoint: &str,
        body: &str,
        timeout: Duration,
    ) -> Attempt {
        let mut rb = http
            .post(endpoint)
            .timeout(timeout)
            .header(reqwest::header::CONTENT_TYPE, "application/json")
            .body(body.to_string());
        if let Some(k) = &self.config.api_key {
            rb = rb.bearer_auth(k.expose());
        }
        let transport = |e: reqwest::Error| {
            let timed_out = e.is_timeout();
            let e = e.without_url();
            let mut message = e.to_string();
            let mut src = std::error::Error::source(&e);
            while let Some(s) = src {
                message.push_str(": ");
                message.push_str(&s.to_string());
                src = s.source();
            }
            if timed_out {
                Attempt::Failed {
                    status: status::TIMEOUT,
                    http_status: None,
                    body: None,
                    message: format!("no answer within {:.1} s", timeout.as_secs_f64()),
                    retry_after: None,
                    retryable: true,
                }
            } else {
                Attempt::Failed {
                    status: status::CONNECTION,
                    http_status: None,
                    body: None,
                    message,
                    retry_after: None,
                    retryable: true,
                }
            }
        };
        let resp = match rb.send() {
            Ok(r) => r,
            Err(e) => return transport(e),
        };
        let code = resp.status().as_u16();
        let retry_after = resp
            .headers()
            .get(reqwest::header::RETRY_AFTER)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| parse_retry_after(v, SystemTime::now()));
        let text = match resp.text() {
            Ok(t) => t,
            Err(e) => return transport(e),
        };
        if (200..300).contains(&code) {
            return match parse_answer(&text) {
                Ok(a) => Attempt::Ok {
                    http_status: code,
                    body: text,
                    content: a.content,
                    finish_reason: a.finish_reason,
                    usage: a.usage,
                },
                Err(message) => Attempt::Failed {
                    status: status::BAD_RESPONSE,
                    http_status: Some(code),
                    body: Some(text),
                    message,
                    retry_after: None,
                    retryable: false,
                },
            };
        }
        Attempt::Failed {
            status: status::HTTP_ERROR,
            http_status: Some(code),
            message: format!("HTTP {code}: {}", excerpt(&text, 300)),
            body: Some(text),
            retry_after,
            retryable: code == 408 || code == 429 || code >= 500,
        }
    }
}

impl Drop for LlmClient {
    fn drop(&mut self) {
        if let Err(e) = self.flush() {
            tracing::error!("writing llm_calls: {e}");
        }
    }
}

/// Estimated prompt tokens: the messages' text plus a few tokens of chat framing per message.
fn estimate_prompt(req: &ChatRequest) -> u64 {
    req.messages
        .iter()
        .map(|m| count_tokens(&m.text_content()) as u64 + 4)
        .sum::<u64>()
        + 3
}

/// Whether the URL's host is `localhost` or a loopback address.
fn is_loopback(url: &str) -> bool {
    let rest = url.split_once("://").map_or(url, |(_, r)| r);
    let auth = rest.split(['/', '?', '#']).next().unwrap_or("");
    let host = auth.rsplit('@').next().unwrap_or(auth);
    let host = match host.strip_prefix('[') {
        Some(v6) => v6.split(']').next().unwrap_or(""),
        None => host.split(':').next().unwrap_or(""),
    };
    host.eq_ignore_ascii_case("localhost")
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

fn same_dir(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_hosts_are_recognised() {
        for u in [
            "http://localhost:8080/v1/chat/completions",
            "http://127.0.0.1:1/v1",
            "http://u:p@127.0.0.2/x",
            "http://[::1]:8080/v1",
        ] {
            assert!(is_loopback(u), "{u}");
        }
        for u in [
            "https://api.example.com/v1",
            "http://10.0.0.5:8000",
            "http://localhost.evil.com/",
        ] {
            assert!(!is_loopback(u), "{u}");
        }
    }
}
