//! What the client does while it waits for an endpoint: the board of requests in flight, the "still
//! waiting" notices, and the periodic flush of the call log.
//!
//! Each client with an endpoint or a call log has one background thread (its *watch*) that wakes every
//! [`TICK`]. It writes the log's buffered rows once the oldest is [`FLUSH_AFTER`] old — so an attempt
//! recorded just before a long wait (a hung request, a `Retry-After`) is on disk within about a second
//! and survives a kill — and, while a request has been unanswered for the notice interval, it reports a
//! [`WaitNotice`] once per interval to the client's observer (by default a `WARN` log line, which the
//! command line prints on stderr). The thread ends when the client is dropped.
//!
//! **Owns:** the in-flight board, the notice schedule and the watch thread. **Does not:** send
//! requests or decide retries (`client`), or format rows (`record`).

use std::collections::BTreeMap;
use std::fmt;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, Weak};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::record::{CallLog, FLUSH_AFTER};

/// How often the watch wakes.
pub const TICK: Duration = Duration::from_millis(250);

/// A report that requests to an endpoint are still unanswered.
#[derive(Clone, Debug, PartialEq)]
pub struct WaitNotice {
    /// The endpoint (without credentials or query).
    pub endpoint: String,
    /// Requests sent and not answered yet.
    pub in_flight: usize,
    /// The purpose tag of the call waiting longest.
    pub purpose: String,
    /// Its attempt number (1-based).
    pub attempt: u32,
    /// The most attempts a call makes (`max_retries + 1`).
    pub max_attempts: u32,
    /// How long that call has taken so far, earlier attempts and waits included.
    pub waited: Duration,
    /// The call's time limit (`call_timeout_s`).
    pub limit: Duration,
}

impl fmt::Display for WaitNotice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "waiting for {} (attempt {}/{}, {:.0} s; a call gives up after {:.0} s)",
            self.endpoint,
            self.attempt,
            self.max_attempts,
            self.waited.as_secs_f64(),
            self.limit.as_secs_f64()
        )?;
        if self.in_flight > 1 {
            write!(f, "; {} requests unanswered", self.in_flight)?;
        }
        write!(f, " [{}]", self.purpose)
    }
}

/// Receives the client's [`WaitNotice`]s (from the watch thread).
pub type WaitObserver = Arc<dyn Fn(&WaitNotice) + Send + Sync>;

#[derive(Debug)]
struct Pending {
    purpose: String,
    attempt: u32,
    call_started: Instant,
}

/// The requests of one client in flight, and when the last notice went out.
pub(crate) struct Board {
    endpoint: String,
    max_attempts: u32,
    limit: Duration,
    every: Duration,
    next: AtomicU64,
    pending: Mutex<BTreeMap<u64, Pending>>,
    last_notice: Mutex<Option<Instant>>,
    observer: Mutex<Option<WaitObserver>>,
}

impl fmt::Debug for Board {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Board")
            .field("endpoint", &self.endpoint)
            .field("every", &self.every)
            .finish_non_exhaustive()
    }
}

/// Removes its request from the board when dropped.
pub(crate) struct InFlight<'a> {
    board: &'a Board,
    key: u64,
}

impl Drop for InFlight<'_> {
    fn drop(&mut self) {
        lock(&self.board.pending).remove(&self.key);
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Whether a notice is due: the oldest request has waited `every`, and the last notice (if any) is
/// `every` old.
fn due(oldest_waited: Duration, since_last: Option<Duration>, every: Duration) -> bool {
    oldest_waited >= every && since_last.is_none_or(|d| d >= every)
}

impl Board {
    pub fn new(endpoint: String, max_attempts: u32, limit: Duration, every: Duration) -> Self {
        Board {
            endpoint,
            max_attempts,
            limit,
            every,
            next: AtomicU64::new(0),
            pending: Mutex::new(BTreeMap::new()),
            last_notice: Mutex::new(None),
            observer: Mutex::new(None),
        }
    }

    /// Puts attempt `attempt` of a call started at `call_started` on the board until the guard drops.
    pub fn enter(&self, purpose: &str, attempt: u32, call_started: Instant) -> InFlight<'_> {
        let key = self.next.fetch_add(1, Ordering::Relaxed);
        lock(&self.pending).insert(
            key,
            Pending {
                purpose: purpose.to_string(),
                attempt,
                call_started,
            },
        );
        InFlight { board: self, key }
    }

    pub fn set_observer(&self, observer: Option<WaitObserver>) {
        *lock(&self.observer) = observer;
    }

    /// The notice due at `now`, if any (and marks it sent).
    fn notice(&self, now: Instant) -> Option<WaitNotice> {
        let pending = lock(&self.pending);
        let oldest = pending.values().min_by_key(|p| p.call_started)?;
        let waited = now.saturating_duration_since(oldest.call_started);
        let mut last = lock(&self.last_notice);
        if !due(
            waited,
            last.map(|t| now.saturating_duration_since(t)),
            self.every,
        ) {
            return None;
        }
        *last = Some(now);
        Some(WaitNotice {
            endpoint: self.endpoint.clone(),
            in_flight: pending.len(),
            purpose: oldest.purpose.clone(),
            attempt: oldest.attempt,
            max_attempts: self.max_attempts,
            waited,
            limit: self.limit,
        })
    }

    fn tick(&self) {
        let Some(n) = self.notice(Instant::now()) else {
            return;
        };
        let observer = lock(&self.observer).clone();
        match observer {
            Some(f) => f(&n),
            None => tracing::warn!("{n}"),
        }
    }
}

/// The watch thread of a client; stops when dropped.
#[derive(Debug)]
pub(crate) struct Watch {
    stop: Arc<(Mutex<bool>, Condvar)>,
    handle: Option<JoinHandle<()>>,
}

impl Watch {
    /// Starts the thread over the client's board and call log (held weakly: the thread never keeps
    /// them alive).
    pub fn start(board: Option<Weak<Board>>, log: Option<Weak<CallLog>>) -> Watch {
        let stop = Arc::new((Mutex::new(false), Condvar::new()));
        let s = stop.clone();
        let handle = std::thread::Builder::new()
            .name("annotrace-llm-watch".into())
            .spawn(move || watch(&s, board, log))
            .map_err(|e| tracing::warn!("cannot start the LLM watch thread: {e}"))
            .ok();
        Watch { stop, handle }
    }
}

fn watch(stop: &(Mutex<bool>, Condvar), board: Option<Weak<Board>>, log: Option<Weak<CallLog>>) {
    let (flag, cv) = stop;
    let mut stopped = lock(flag);
    loop {
        stopped = cv
            .wait_timeout(stopped, TICK)
            .unwrap_or_else(|p| p.into_inner())
            .0;
        if *stopped {
            return;
        }
        if let Some(log) = log.as_ref().and_then(Weak::upgrade)
            && let Err(e) = log.flush_older_than(FLUSH_AFTER)
        {
            tracing::error!("writing llm_calls: {e}");
        }
        if let Some(b) = board.as_ref().and_then(Weak::upgrade) {
            b.tick();
        }
    }
}

impl Drop for Watch {
    fn drop(&mut self) {
        *lock(&self.stop.0) = true;
        self.stop.1.notify_all();
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_notice_is_due_once_per_interval_after_the_first() {
        let s = Duration::from_secs;
        assert!(!due(s(14), None, s(15)));
        assert!(due(s(15), None, s(15)));
        assert!(!due(s(40), Some(s(10)), s(15)));
        assert!(due(s(40), Some(s(15)), s(15)));
    }

    #[test]
    fn the_board_reports_the_oldest_call_and_forgets_answered_ones() {
        let b = Board::new(
            "http://h/v1/chat/completions".into(),
            5,
            Duration::from_secs(300),
            Duration::from_secs(15),
        );
        let t0 = Instant::now();
        assert_eq!(b.notice(t0 + Duration::from_secs(60)), None);
        let first = b.enter("evolve", 2, t0);
        let _second = b.enter("repair", 1, t0 + Duration::from_secs(10));
        assert_eq!(b.notice(t0 + Duration::from_secs(14)), None);
        let n = b.notice(t0 + Duration::from_secs(34)).unwrap();
        assert_eq!(
            (n.in_flight, n.attempt, n.purpose.as_str()),
            (2, 2, "evolve")
        );
        assert_eq!(
            n.to_string(),
            "waiting for http://h/v1/chat/completions (attempt 2/5, 34 s; a call gives up after \
             300 s); 2 requests unanswered [evolve]"
        );
        // Not again within the interval.
        assert_eq!(b.notice(t0 + Duration::from_secs(40)), None);
        drop(first);
        let n = b.notice(t0 + Duration::from_secs(50)).unwrap();
        assert_eq!((n.in_flight, n.purpose.as_str()), (1, "repair"));
    }
}
