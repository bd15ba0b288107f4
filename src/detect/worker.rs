//! One sandboxed worker process: start it, send requests, wait for replies with a deadline, kill it.
//!
//! Replies are read straight from the worker's standard output by the thread that waits for them:
//! `poll(2)` gives the wait its deadline, then whatever the pipe holds is read into a buffer and cut
//! into frames ([`FrameReader`]). No thread sits between the pipe and the caller, so a reply costs one
//! wake-up, not two (on a virtual machine each is tens of microseconds, as much as a short detector
//! call; `docs/performance.md`). A thread drains standard error into a bounded buffer (the last 8 KiB),
//! quoted when the worker dies. The worker remembers which traces and detectors it holds, so that the
//! pool sends each only once.

use std::collections::{HashSet, VecDeque};
use std::io::Read;
use std::path::Path;
use std::process::{Child, ChildStdin, ChildStdout, Stdio};
use std::sync::mpsc::channel;
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use super::error::DetectError;
use super::protocol::{self, WorkerReply, write_frame};
use super::sandbox::{SandboxLayers, SandboxLimits, worker_command};

/// The worker's Python source, embedded at build time.
pub(crate) const WORKER_PY: &str = include_str!("worker.py");

/// How long a worker may take to start and lock itself down.
const START_TIMEOUT: Duration = Duration::from_secs(30);
/// Bytes of standard error kept.
const STDERR_KEEP: usize = 8 << 10;

/// What came back for a request.
#[derive(Debug)]
pub(crate) enum Reply {
    /// A reply frame (raw JSON bytes).
    Frame(Vec<u8>),
    /// No reply within the deadline; the worker has been killed.
    Timeout,
    /// The worker died; how.
    Died(Death),
}

/// How a worker died.
#[derive(Debug)]
pub(crate) struct Death {
    /// The signal that ended it, if one did.
    pub signal: Option<i32>,
    /// Exit status, or signal, and the end of standard error.
    pub message: String,
}

type SpawnRequest = (
    std::process::Command,
    std::sync::mpsc::Sender<std::io::Result<Child>>,
);

/// Starts `cmd` from one thread that lives as long as the process. The sandbox sets
/// `PR_SET_PDEATHSIG`, which the kernel fires when the *thread* that forked the child exits: a
/// replacement worker started from a batch's scoped thread (after a timeout or crash) was killed with
/// SIGKILL as soon as that batch ended, so the next batch found it dead.
fn spawn_from_long_lived_thread(cmd: std::process::Command) -> std::io::Result<Child> {
    static SPAWNER: std::sync::OnceLock<Mutex<std::sync::mpsc::Sender<SpawnRequest>>> =
        std::sync::OnceLock::new();
    let spawner = SPAWNER.get_or_init(|| {
        let (tx, rx) = channel::<SpawnRequest>();
        let started = thread::Builder::new()
            .name("detect-spawner".into())
            .spawn(move || {
                for (mut cmd, reply) in rx {
                    let _ = reply.send(cmd.spawn());
                }
            });
        if let Err(e) = started {
            tracing::warn!("could not start the worker spawner thread: {e}");
        }
        Mutex::new(tx)
    });
    let (reply_tx, reply_rx) = channel();
    let sent = spawner
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .send((cmd, reply_tx));
    match sent {
        Ok(()) => reply_rx
            .recv()
            .unwrap_or_else(|_| Err(std::io::Error::other("the worker spawner thread stopped"))),
        // No spawner thread: start from this thread (the old behaviour).
        Err(std::sync::mpsc::SendError((mut cmd, _))) => cmd.spawn(),
    }
}

/// A running worker.
pub(crate) struct Worker {
    child: Child,
    stdin: Option<ChildStdin>,
    replies: FrameReader,
    stderr: Arc<Mutex<VecDeque<u8>>>,
    /// Trace keys loaded, least recently used first.
    pub traces: VecDeque<String>,
    /// Trace keys to drop with the next [`Worker::send_evictions`] (no longer in `traces`).
    pub evict: Vec<String>,
    /// Detector ids compiled.
    pub detectors: HashSet<String>,
    /// The layers it reported.
    pub layers: SandboxLayers,
}

impl Worker {
    /// Starts a worker and waits for its ready message.
    pub fn spawn(python: &Path, limits: &SandboxLimits) -> Result<Worker, DetectError> {
        let mut cmd = worker_command(&python.to_path_buf(), limits, WORKER_PY);
        cmd.stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = spawn_from_long_lived_thread(cmd).map_err(|e| DetectError::Spawn {
            message: format!("{}: {e}", python.display()),
        })?;
        let stdin = child.stdin.take();
        let stdout = child.stdout.take().expect("piped");
        let mut err = child.stderr.take().expect("piped");
        let replies = FrameReader::new(stdout, limits.max_output_bytes + (64 << 10));
        let stderr = Arc::new(Mutex::new(VecDeque::new()));
        let sink = stderr.clone();
        thread::Builder::new()
            .name("detect-stderr".into())
            .spawn(move || {
                let mut buf = [0u8; 4096];
                while let Ok(n) = err.read(&mut buf) {
                    if n == 0 {
                        break;
                    }
                    let mut q = sink.lock().unwrap_or_else(|p| p.into_inner());
                    q.extend(&buf[..n]);
                    let excess = q.len().saturating_sub(STDERR_KEEP);
                    q.drain(..excess);
                }
            })
            .map_err(|e| DetectError::Spawn {
                message: format!("stderr thread: {e}"),
            })?;
        let mut w = Worker {
            child,
            stdin,
            replies,
            stderr,
            traces: VecDeque::new(),
            evict: Vec::new(),
            detectors: HashSet::new(),
            layers: SandboxLayers::default(),
        };
        let ready = match w.wait_reply(START_TIMEOUT) {
            Reply::Frame(f) => {
                protocol::parse_json(&f).map_err(|m| DetectError::Spawn { message: m })?
            }
            Reply::Timeout => {
                return Err(DetectError::Spawn {
                    message: "no ready message within 30 s".into(),
                });
            }
            Reply::Died(d) => return Err(DetectError::Spawn { message: d.message }),
        };
        let layers = &ready["layers"];
        w.layers = SandboxLayers {
            python: ready["python"].as_str().unwrap_or_default().to_string(),
            rlimits: cfg!(unix),
            no_new_privs: layers["no_new_privs"].as_bool().unwrap_or(false),
            landlock: layers["landlock"]
                .as_str()
                .unwrap_or("unavailable")
                .to_string(),
            seccomp: layers["seccomp"]
                .as_str()
                .unwrap_or("unavailable")
                .to_string(),
            python_guard: layers["python_guard"].as_bool().unwrap_or(false),
        };
        Ok(w)
    }

    /// Sends a request and waits up to `timeout` for its reply. On timeout the worker is killed.
    pub fn request(&mut self, kind: u8, body: &[u8], timeout: Duration) -> Reply {
        match self.send(kind, body) {
            Ok(()) => self.wait_reply(timeout),
            Err(death) => Reply::Died(death),
        }
    }

    /// Tells the worker to drop the traces in `evict` (a request without a reply).
    pub fn send_evictions(&mut self) -> Result<(), Death> {
        if self.evict.is_empty() {
            return Ok(());
        }
        let body = protocol::evict_body(&self.evict);
        self.evict.clear();
        self.send(protocol::EVICT, &body)
    }

    /// Sends a request without waiting for its reply (collect it with [`Worker::wait`]).
    pub fn send(&mut self, kind: u8, body: &[u8]) -> Result<(), Death> {
        let sent = match self.stdin.as_mut() {
            Some(stdin) => write_frame(stdin, kind, body),
            None => Err(std::io::Error::other("worker stdin closed")),
        };
        sent.map_err(|_| self.reap())
    }

    /// Waits up to `timeout` for the next reply (of a request that has several). On timeout the worker
    /// is killed.
    pub fn wait(&mut self, timeout: Duration) -> Reply {
        self.wait_reply(timeout)
    }

    fn wait_reply(&mut self, timeout: Duration) -> Reply {
        match self.replies.next(Instant::now() + timeout) {
            Ok(frame) => Reply::Frame(frame),
            Err(Wait::Closed) => Reply::Died(self.reap()),
            Err(Wait::Timeout) => {
                self.kill();
                Reply::Timeout
            }
        }
    }

    /// Kills the worker (SIGKILL) and waits for it.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        self.stdin = None;
    }

    /// Waits for a worker that stopped on its own and says how it ended.
    fn reap(&mut self) -> Death {
        self.stdin = None;
        // The process may still be exiting; give it a moment, then make sure.
        let deadline = Instant::now() + Duration::from_secs(2);
        let status = loop {
            match self.child.try_wait() {
                Ok(Some(s)) => break Some(s),
                Ok(None) if Instant::now() < deadline => thread::sleep(Duration::from_millis(5)),
                _ => {
                    let _ = self.child.kill();
                    break self.child.wait().ok();
                }
            }
        };
        // Let the stderr thread catch up with the last words.
        thread::sleep(Duration::from_millis(10));
        let tail = {
            let q = self.stderr.lock().unwrap_or_else(|p| p.into_inner());
            String::from_utf8_lossy(&q.iter().copied().collect::<Vec<u8>>()).into_owned()
        };
        #[cfg(unix)]
        let signal = {
            use std::os::unix::process::ExitStatusExt;
            status.and_then(|s| s.signal())
        };
        #[cfg(not(unix))]
        let signal = None;
        let how = match (status.and_then(|s| s.code()), signal) {
            (Some(c), _) => format!("exit status {c}"),
            (None, Some(s)) => format!("signal {s}"),
            _ => "unknown status".into(),
        };
        let tail = tail.trim();
        Death {
            signal,
            message: if tail.is_empty() {
                how
            } else {
                let start = tail
                    .char_indices()
                    .rev()
                    .nth(1999)
                    .map(|(i, _)| i)
                    .unwrap_or(0);
                format!("{how}; stderr: {}", &tail[start..])
            },
        }
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Why no frame came.
#[derive(Debug, PartialEq)]
enum Wait {
    /// Nothing complete before the deadline.
    Timeout,
    /// The pipe closed, failed, or announced a frame over the bound: the worker is gone or broken.
    Closed,
}

/// Cuts the worker's standard output into frames (4-byte little-endian length, then the bytes).
struct FrameReader {
    out: ChildStdout,
    buf: Vec<u8>,
    /// Bytes of `buf` already handed out.
    start: usize,
    /// Largest frame accepted.
    max: usize,
}

impl FrameReader {
    fn new(out: ChildStdout, max: usize) -> Self {
        FrameReader {
            out,
            buf: Vec::with_capacity(64 << 10),
            start: 0,
            max,
        }
    }

    /// The next frame, waiting until `deadline` at most.
    fn next(&mut self, deadline: Instant) -> Result<Vec<u8>, Wait> {
        loop {
            let have = &self.buf[self.start..];
            let mut want = 64 << 10;
            if have.len() >= 4 {
                let n = u32::from_le_bytes([have[0], have[1], have[2], have[3]]) as usize;
                if n > self.max {
                    return Err(Wait::Closed);
                }
                if have.len() >= 4 + n {
                    let frame = have[4..4 + n].to_vec();
                    self.start += 4 + n;
                    if self.start == self.buf.len() {
                        self.buf.clear();
                        self.start = 0;
                    }
                    return Ok(frame);
                }
                want = want.max(4 + n - have.len());
            }
            if self.start > 0 {
                self.buf.drain(..self.start);
                self.start = 0;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if !readable(&self.out, left)? {
                return Err(Wait::Timeout);
            }
            let old = self.buf.len();
            self.buf.resize(old + want.min(1 << 20), 0);
            match self.out.read(&mut self.buf[old..]) {
                Ok(0) => {
                    self.buf.truncate(old);
                    return Err(Wait::Closed);
                }
                Ok(k) => self.buf.truncate(old + k),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => self.buf.truncate(old),
                Err(_) => {
                    self.buf.truncate(old);
                    return Err(Wait::Closed);
                }
            }
        }
    }
}

/// Waits up to `left` for the pipe to have data (or be closed); `false` when the time ran out.
#[cfg(unix)]
fn readable(out: &ChildStdout, left: Duration) -> Result<bool, Wait> {
    use std::os::fd::AsRawFd;
    let mut fd = libc::pollfd {
        fd: out.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    let deadline = Instant::now() + left;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        // Whole milliseconds, rounded up, so that a wait never ends early.
        let ms = i32::try_from(left.as_micros().div_ceil(1000)).unwrap_or(i32::MAX);
        // SAFETY: one valid pollfd, owned by this frame, for the duration of the call.
        let r = unsafe { libc::poll(&mut fd, 1, ms) };
        match r {
            1.. => return Ok(true),
            0 if Instant::now() >= deadline => return Ok(false),
            0 => continue,
            _ if std::io::Error::last_os_error().kind() == std::io::ErrorKind::Interrupted => {
                continue;
            }
            _ => return Err(Wait::Closed),
        }
    }
}

/// Without `poll(2)` the read blocks; the worker itself (`resource`, `fcntl`) needs a Unix system anyway.
#[cfg(not(unix))]
fn readable(_out: &ChildStdout, _left: Duration) -> Result<bool, Wait> {
    Ok(true)
}

/// Parses a reply frame; marshalled patterns are decoded under a budget of `max_output_bytes`.
pub(crate) fn parse(frame: &[u8], max_output_bytes: usize) -> Result<WorkerReply, DetectError> {
    protocol::parse_reply(frame, max_output_bytes).map_err(DetectError::Internal)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reader over what `sh` prints: frames split or joined however the pipe delivers them.
    fn reader(script: &str, max: usize) -> (Child, FrameReader) {
        let mut child = std::process::Command::new("sh")
            .arg("-c")
            .arg(script)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let out = child.stdout.take().unwrap();
        (child, FrameReader::new(out, max))
    }

    #[test]
    fn frames_are_cut_from_the_pipe_and_a_closed_pipe_is_reported() {
        // Two frames in one write, then a third in pieces with a pause between them.
        let (mut c, mut r) = reader(
            r"printf '\002\000\000\000ab\001\000\000\000c'; sleep 0.2; printf '\003\000'; sleep 0.1; printf '\000\000xyz'",
            16,
        );
        let far = Instant::now() + Duration::from_secs(10);
        assert_eq!(r.next(far).unwrap(), b"ab");
        assert_eq!(r.next(far).unwrap(), b"c");
        assert_eq!(r.next(far).unwrap(), b"xyz");
        assert_eq!(r.next(far), Err(Wait::Closed));
        c.wait().unwrap();
    }

    #[test]
    fn a_silent_worker_times_out_and_an_oversized_frame_is_refused() {
        let (mut c, mut r) = reader("sleep 5", 16);
        let t0 = Instant::now();
        assert_eq!(
            r.next(Instant::now() + Duration::from_millis(150)),
            Err(Wait::Timeout)
        );
        assert!(t0.elapsed() >= Duration::from_millis(150));
        let _ = c.kill();
        let _ = c.wait();
        let (mut c, mut r) = reader(r"printf '\377\377\000\000'", 16);
        assert_eq!(
            r.next(Instant::now() + Duration::from_secs(10)),
            Err(Wait::Closed)
        );
        c.wait().unwrap();
    }
}
