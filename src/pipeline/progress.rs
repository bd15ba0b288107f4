//! How the runner and stages report progress, without printing: the CLI decides how to show it.
//!
//! `()` implements [`Progress`] and shows nothing (tests, library use); the CLI has a terminal
//! implementation (progress bars) and a plain one (one log line per event) for non-terminals.

/// Receives progress events. Every method has a no-op default.
pub trait Progress: Send + Sync {
    /// A stage starts; `total` units of work are expected when known.
    fn stage_started(&self, _stage: &str, _kind: &str, _total: Option<u64>) {}
    /// The expected total of the running stage became known or changed.
    fn set_total(&self, _stage: &str, _total: u64) {}
    /// `n` more units of the running stage are done.
    fn advance(&self, _stage: &str, _n: u64) {}
    /// A note worth a line (resumed shards, skipped inputs).
    fn note(&self, _stage: &str, _message: &str) {}
    /// A stage finished; `summary` is a short human line.
    fn stage_finished(&self, _stage: &str, _summary: &str) {}
    /// A stage was skipped because its fingerprint is unchanged.
    fn stage_cached(&self, _stage: &str) {}
}

impl Progress for () {}
