//! Replay: answers recorded in a run's `llm_calls`, served to identical requests.
//!
//! Requests are matched by `request_hash` (the SHA-256 of the body: model, messages, sampling
//! parameters and seed). When a run asked the same request several times, the recorded answers are
//! served in their recorded order, and the last one again once they run out.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use super::error::LlmError;
use super::record::{CallRecord, read_calls, status};
use crate::store::RunDir;

/// A recorded answer.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Recorded {
    pub content: String,
    pub response_json: Option<String>,
    pub tokens_in: u64,
    pub tokens_out: u64,
    pub usage_estimated: bool,
    pub latency_ms: f64,
}

#[derive(Debug)]
struct Queue {
    answers: Vec<Recorded>,
    next: usize,
}

/// The recorded answers of one run, by request hash.
#[derive(Debug)]
pub(crate) struct ReplayIndex {
    run: PathBuf,
    queues: Mutex<HashMap<String, Queue>>,
}

impl ReplayIndex {
    /// Reads the `ok` rows of `run`'s `llm_calls`. A run without the table replays nothing (every
    /// request misses).
    pub fn open(run: &Path) -> Result<Self, LlmError> {
        let rows = read_calls(&RunDir::new(run))?;
        Ok(Self::from_rows(run, rows))
    }

    pub fn from_rows(run: &Path, rows: Vec<CallRecord>) -> Self {
        let mut queues: HashMap<String, Queue> = HashMap::new();
        for r in rows {
            if r.status != status::OK {
                continue;
            }
            let Some(content) = r.content else { continue };
            queues
                .entry(r.request_hash)
                .or_insert_with(|| Queue {
                    answers: Vec::new(),
                    next: 0,
                })
                .answers
                .push(Recorded {
                    content,
                    response_json: r.response_json,
                    tokens_in: r.tokens_in.max(0) as u64,
                    tokens_out: r.tokens_out.max(0) as u64,
                    usage_estimated: r.usage_estimated,
                    latency_ms: r.latency_ms,
                });
        }
        ReplayIndex {
            run: run.to_path_buf(),
            queues: Mutex::new(queues),
        }
    }

    /// The run replayed from.
    pub fn run(&self) -> &Path {
        &self.run
    }

    /// The next recorded answer to `request_hash`, if any.
    pub fn take(&self, request_hash: &str) -> Option<Recorded> {
        let mut q = self.queues.lock().unwrap_or_else(|p| p.into_inner());
        let queue = q.get_mut(request_hash)?;
        let i = queue.next.min(queue.answers.len() - 1);
        queue.next += 1;
        Some(queue.answers[i].clone())
    }
}
