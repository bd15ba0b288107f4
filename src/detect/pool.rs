//! [`WorkerPool`]: long-lived sandboxed workers that run detectors over traces in parallel.
//!
//! [`WorkerPool::run`] hands traces to workers one at a time (one Rust thread drives each worker): the
//! worker loads the trace once (kept in its cache of `trace_cache` traces; with 0, freed as soon as its
//! detectors have run), compiles each detector once (kept for the worker's life), and runs every
//! detector on it. Every call is timed by the worker (wall and CPU time of `find_pattern` itself) and
//! by the pool (the round trip). A call past its time limit kills the worker, a fresh one takes its
//! place, and the detector is marked `timeout` for that trace and `skipped` for the rest of the batch;
//! the other detectors go on.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use serde_json::Value;

use super::detector::Detector;
use super::error::{CandidateStatus, DetectError, DetectorError};
use super::protocol::{self, COMPILE, RUN, WorkerReply};
use super::sandbox::{SandboxLayers, SandboxLimits, resolve_python};
use super::validate::{Pattern, validate};
use super::worker::{Death, Reply, Worker, parse};
use crate::trace::{FramedTrace, Trace};

/// The result of one detector on one trace.
#[derive(Clone, Debug)]
pub struct CallResult {
    /// Index of the detector in the batch.
    pub detector: usize,
    /// Index of the trace in the batch.
    pub trace: usize,
    /// Whether it ran and produced valid output.
    pub status: CandidateStatus,
    /// The validated patterns (empty unless `status` is ok).
    pub patterns: Vec<Pattern>,
    /// Wall time of `find_pattern` in the worker (s); 0 when it did not run to the end.
    pub wall_s: f64,
    /// CPU time of `find_pattern` in the worker (s).
    pub cpu_s: f64,
    /// Wall time of the whole request as seen from Rust (s): the call plus protocol and validation.
    pub round_trip_s: f64,
    /// The first 1000 characters the detector printed.
    pub printed: String,
}

/// Totals of one [`WorkerPool::run`], for overhead accounting.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunStats {
    /// Traces converted to the paper's dict and loaded into a worker (cache misses).
    pub traces_loaded: usize,
    /// Time spent converting traces to JSON in Rust (s, summed over threads).
    pub convert_s: f64,
    /// Time spent loading traces in workers, round trip (s, summed over threads).
    pub load_s: f64,
    /// Of `load_s`, the time the workers spent decoding and building the paper's dicts (s).
    pub build_s: f64,
    /// Time spent compiling detectors, round trip (s).
    pub compile_s: f64,
    /// Detector calls made.
    pub calls: usize,
    /// Sum of the workers' wall time inside `find_pattern` (s).
    pub detector_wall_s: f64,
    /// Sum of the round trips of run requests (s).
    pub round_trip_s: f64,
    /// Workers replaced after a timeout, memory error or crash.
    pub restarts: usize,
    /// Time spent decoding and validating patterns in Rust (s, summed over threads). Not part of
    /// [`RunStats::overhead`]: it overlaps the workers' next calls.
    pub decode_s: f64,
}

impl RunStats {
    /// Adds another run's totals to these.
    pub fn add(&mut self, o: &RunStats) {
        self.traces_loaded += o.traces_loaded;
        self.convert_s += o.convert_s;
        self.load_s += o.load_s;
        self.compile_s += o.compile_s;
        self.calls += o.calls;
        self.detector_wall_s += o.detector_wall_s;
        self.round_trip_s += o.round_trip_s;
        self.restarts += o.restarts;
        self.decode_s += o.decode_s;
        self.build_s += o.build_s;
    }

    /// Protocol, conversion, loading and compilation time as a fraction of detector time.
    pub fn overhead(&self) -> f64 {
        let over = self.convert_s + self.load_s + self.compile_s + self.round_trip_s
            - self.detector_wall_s;
        if self.detector_wall_s > 0.0 {
            over / self.detector_wall_s
        } else {
            0.0
        }
    }
}

/// The results of a batch: one [`CallResult`] per (trace, detector), trace-major.
#[derive(Clone, Debug, Default)]
pub struct BatchResult {
    /// `results[t * n_detectors + d]`.
    pub results: Vec<CallResult>,
    /// Totals.
    pub stats: RunStats,
}

/// A pool of sandboxed Python workers.
///
/// ```no_run
/// use annotrace::detect::{Detector, SandboxLimits, WorkerPool};
/// use annotrace::trace::Env;
/// let pool = WorkerPool::new(SandboxLimits::default()).unwrap();
/// println!("sandbox: {}", pool.layers().describe());
/// let d = Detector::new(Env::Pooltool, "cue strike", "def find_pattern(trace):\n    return []\n", "inline");
/// let traces: Vec<annotrace::trace::Trace> = Vec::new();
/// let batch = pool.run(&[d], &traces);
/// assert!(batch.results.is_empty());
/// ```
pub struct WorkerPool {
    limits: SandboxLimits,
    python: PathBuf,
    slots: Vec<Mutex<Option<Worker>>>,
    layers: SandboxLayers,
}

/// What the pool reads of a trace: its id and steps, and the request that loads it into a worker.
trait Loadable: Sync {
    /// The trace; its steps' objects need not be built.
    fn shell(&self) -> &Trace;
    /// The load request for a run of `detectors` detectors.
    fn load_request(&self, key: &str, detectors: usize) -> (u8, Vec<u8>);
}

impl Loadable for Trace {
    fn shell(&self) -> &Trace {
        self
    }

    fn load_request(&self, key: &str, detectors: usize) -> (u8, Vec<u8>) {
        protocol::load_request(key, self, detectors)
    }
}

impl Loadable for FramedTrace {
    fn shell(&self) -> &Trace {
        FramedTrace::shell(self)
    }

    fn load_request(&self, key: &str, detectors: usize) -> (u8, Vec<u8>) {
        protocol::load_request_framed(key, self, detectors)
    }
}

/// The key of a trace in a worker's cache.
fn trace_key(trace: &Trace) -> String {
    format!(
        "{}\u{1}{}\u{1}{}",
        trace.trace_id,
        trace.timesteps.len(),
        trace.timesteps.last().map(|t| t.t).unwrap_or(0.0)
    )
}

impl WorkerPool {
    /// Starts `limits.workers` workers (at least one) and checks the sandbox layers.
    pub fn new(limits: SandboxLimits) -> Result<Self, DetectError> {
        let python = resolve_python(&limits)?;
        let n = limits.workers.max(1);
        let mut slots = Vec::with_capacity(n);
        let mut layers = SandboxLayers::default();
        for _ in 0..n {
            let w = Worker::spawn(&python, &limits)?;
            layers = w.layers.clone();
            slots.push(Mutex::new(Some(w)));
        }
        if limits.require_seccomp && layers.seccomp != "filter" {
            return Err(DetectError::LayerUnavailable { layer: "seccomp" });
        }
        Ok(WorkerPool {
            limits,
            python,
            slots,
            layers,
        })
    }

    /// The sandbox layers the workers reported.
    pub fn layers(&self) -> &SandboxLayers {
        &self.layers
    }

    /// The limits the pool runs with.
    pub fn limits(&self) -> &SandboxLimits {
        &self.limits
    }

    /// Number of workers.
    pub fn workers(&self) -> usize {
        self.slots.len()
    }

    /// Runs every detector on every trace. Never fails as a whole: a detector that fails is a
    /// [`CandidateStatus::Failed`] result, and a worker that cannot be restarted fails its calls as
    /// `crashed`. Each worker first takes the traces it already holds, then the rest in order.
    pub fn run(&self, detectors: &[Detector], traces: &[Trace]) -> BatchResult {
        self.run_any(detectors, traces)
    }

    /// [`WorkerPool::run`] over traces read from a run's tables: a billiards trace whose frame rows
    /// are still columns goes to its worker straight from them, with the same bytes and results.
    pub fn run_framed(&self, detectors: &[Detector], traces: &[FramedTrace]) -> BatchResult {
        self.run_any(detectors, traces)
    }

    fn run_any<T: Loadable>(&self, detectors: &[Detector], traces: &[T]) -> BatchResult {
        let nd = detectors.len();
        let keys: Vec<String> = traces.iter().map(|t| trace_key(t.shell())).collect();
        let taken: Vec<AtomicBool> = traces.iter().map(|_| AtomicBool::new(false)).collect();
        let next = AtomicUsize::new(0);
        let shared = Shared {
            dead: Mutex::new(HashMap::new()),
        };
        let results: Mutex<Vec<Option<CallResult>>> = Mutex::new(vec![None; nd * traces.len()]);
        let stats = Mutex::new(RunStats::default());
        let claim = |t: usize| {
            taken[t]
                .compare_exchange(false, true, Ordering::SeqCst, Ordering::SeqCst)
                .is_ok()
        };
        std::thread::scope(|s| {
            for slot in &self.slots {
                let (next, shared, results, stats, keys, claim) =
                    (&next, &shared, &results, &stats, &keys, &claim);
                s.spawn(move || {
                    let mut guard = slot.lock().unwrap_or_else(|p| p.into_inner());
                    let mut local = RunStats::default();
                    let store = |(t, out): (usize, Vec<CallResult>)| {
                        let mut r = results.lock().unwrap_or_else(|p| p.into_inner());
                        for (d, res) in out.into_iter().enumerate() {
                            r[t * nd + d] = Some(res);
                        }
                    };
                    // The previous trace's replies, decoded while the worker runs the next trace.
                    let mut unsettled: Option<Unsettled> = None;
                    // Traces this worker holds already (a search runs many candidates over one set).
                    let mut mine: Vec<usize> = match guard.as_ref() {
                        Some(w) => (0..traces.len())
                            .filter(|&t| w.traces.contains(&keys[t]))
                            .collect(),
                        None => Vec::new(),
                    };
                    mine.reverse();
                    loop {
                        let t = match mine.pop() {
                            Some(t) if claim(t) => t,
                            Some(_) => continue,
                            None => {
                                let t = next.fetch_add(1, Ordering::SeqCst);
                                if t >= traces.len() {
                                    break;
                                }
                                if !claim(t) {
                                    continue;
                                }
                                t
                            }
                        };
                        let job = TraceJob {
                            detectors,
                            t,
                            key: &keys[t],
                            trace: &traces[t],
                            shared,
                        };
                        let next =
                            self.run_trace(&mut guard, &job, &mut local, (&mut unsettled, &store));
                        unsettled = Some(next);
                    }
                    if let Some(u) = unsettled.take() {
                        let d0 = Instant::now();
                        store(u.settle(detectors, &self.limits));
                        local.decode_s += d0.elapsed().as_secs_f64();
                    }
                    stats.lock().unwrap_or_else(|p| p.into_inner()).add(&local);
                });
            }
        });
        let results = results
            .into_inner()
            .unwrap_or_else(|p| p.into_inner())
            .into_iter()
            .flatten()
            .collect();
        BatchResult {
            results,
            stats: stats.into_inner().unwrap_or_else(|p| p.into_inner()),
        }
    }

    /// A live worker in the slot (starting one if needed).
    fn ensure_worker<'w>(
        &self,
        slot: &'w mut Option<Worker>,
        stats: &mut RunStats,
    ) -> Result<&'w mut Worker, DetectorError> {
        if slot.is_none() {
            stats.restarts += 1;
            let w =
                Worker::spawn(&self.python, &self.limits).map_err(|e| DetectorError::Crashed {
                    message: format!("could not start a replacement worker: {e}"),
                })?;
            *slot = Some(w);
        }
        Ok(slot.as_mut().expect("just filled"))
    }

    /// What a dead worker means for the call that was running.
    fn death_error(&self, death: &Death) -> DetectorError {
        match death.signal {
            // SIGXCPU: the RLIMIT_CPU backstop ended the call.
            Some(24) => DetectorError::Timeout {
                seconds: self.limits.call_timeout.as_secs_f64(),
            },
            _ => DetectorError::Crashed {
                message: death.message.clone(),
            },
        }
    }

    /// Loads the trace into the worker (once), compiles the detectors it lacks (once), then runs
    /// them all with one request. The worker gathers the replies and writes them together (at least
    /// every [`BATCH_FLUSH`] before starting a call, so every wait has the call deadline plus that);
    /// their patterns are decoded and validated later ([`Unsettled`]), while the worker runs the next
    /// trace: `prev`, the previous trace's replies, is settled (and stored) as soon as this trace's run
    /// request is on its way. When a call kills the worker, the detectors after it go to a fresh worker;
    /// if the worker dies with more than one reply missing, which call did it is unknown (the earlier
    /// ones may have finished, their replies unwritten), so the missing ones run again, each reply
    /// written as its call ends.
    fn run_trace(
        &self,
        slot: &mut Option<Worker>,
        job: &TraceJob<'_>,
        stats: &mut RunStats,
        (prev, store): (&mut Option<Unsettled>, &Store),
    ) -> Unsettled {
        let detectors = job.detectors;
        let mut decode_s = 0.0;
        let mut settle_prev = || {
            if let Some(p) = prev.take() {
                let d0 = Instant::now();
                store(p.settle(detectors, &self.limits));
                decode_s += d0.elapsed().as_secs_f64();
            }
        };
        let mut turn = Turn {
            out: (0..detectors.len()).map(|d| job.blank(d)).collect(),
            frames: Vec::new(),
            one_by_one: false,
            steps: job
                .trace
                .shell()
                .timesteps
                .first()
                .zip(job.trace.shell().timesteps.last())
                .map(|(a, b)| (a.index, b.index)),
        };
        let mut pending: Vec<usize> = (0..detectors.len()).collect();
        // Each pass either finishes `pending` or loses its worker and retries the rest on a new one;
        // every pass settles at least one detector, so this ends.
        while !pending.is_empty() {
            pending.retain(|&d| match job.shared.dead_error(detectors[d].id.as_str()) {
                Some(e) => {
                    turn.fail(d, e);
                    false
                }
                None => true,
            });
            if pending.is_empty() {
                break;
            }
            if let Err(e) = self.ensure_loaded(slot, job, stats) {
                for &d in &pending {
                    turn.fail(d, e.clone());
                }
                break;
            }
            let Some(ready) = self.compile_missing(slot, job, &pending, &mut turn, stats) else {
                // The worker died while compiling: start over with what is not settled yet.
                pending.retain(|&d| turn.out[d].status == CandidateStatus::Ok);
                continue;
            };
            if ready.is_empty() {
                // Every pending detector failed to compile: no run request (the worker would send no
                // reply to an empty one, and waiting for it killed the worker at the deadline).
                break;
            }
            let Some(settled) =
                self.run_ready(slot, job, &ready, &mut turn, stats, &mut settle_prev)
            else {
                break;
            };
            pending = ready[settled..].to_vec();
        }
        if self.limits.trace_cache == 0 {
            // Keep no trace: free this one now, while the worker's cache still holds its objects
            // (about half the cost of freeing it cold, and the next load reuses warm memory).
            if let Some(w) = slot.as_mut()
                && let Some(at) = w.traces.iter().position(|k| k == job.key)
            {
                w.traces.remove(at);
                w.evict.push(job.key.to_string());
                if w.send_evictions().is_err() {
                    *slot = None;
                }
            }
        }
        settle_prev();
        stats.decode_s += decode_s;
        Unsettled {
            trace: job.t,
            steps: turn.steps,
            out: turn.out,
            frames: turn.frames,
        }
    }

    /// A live worker in the slot that holds the job's trace; a worker that fails to load it is
    /// dropped.
    fn ensure_loaded(
        &self,
        slot: &mut Option<Worker>,
        job: &TraceJob<'_>,
        stats: &mut RunStats,
    ) -> Result<(), DetectorError> {
        let worker = self.ensure_worker(slot, stats)?;
        if let Err(e) = self.load(worker, job.key, job.trace, job.detectors.len(), stats) {
            *slot = None;
            return Err(e);
        }
        Ok(())
    }

    /// Compiles the `pending` detectors the worker lacks (once per worker). Returns those ready to
    /// run, or `None` when the worker died on the way; a detector that fails to compile is settled
    /// in `turn` (and marked dead for the batch when its error is fatal).
    fn compile_missing(
        &self,
        slot: &mut Option<Worker>,
        job: &TraceJob<'_>,
        pending: &[usize],
        turn: &mut Turn,
        stats: &mut RunStats,
    ) -> Option<Vec<usize>> {
        let mut ready = Vec::with_capacity(pending.len());
        for &d in pending {
            let det = &job.detectors[d];
            let worker = slot.as_mut()?;
            if worker.detectors.contains(det.id.as_str()) {
                ready.push(d);
                continue;
            }
            let c0 = Instant::now();
            let reply = worker.request(
                COMPILE,
                &protocol::compile_body(det.id.as_str(), &det.code),
                self.limits.call_timeout,
            );
            stats.compile_s += c0.elapsed().as_secs_f64();
            let e = match self.interpret(reply, slot) {
                Ok(WorkerReply::Done { .. }) => {
                    if let Some(w) = slot.as_mut() {
                        w.detectors.insert(det.id.0.clone());
                    }
                    ready.push(d);
                    continue;
                }
                Ok(WorkerReply::Failed { error, .. }) => {
                    if error.ends_worker() {
                        *slot = None;
                    }
                    error.to_detector_error(self.limits.memory_bytes)
                }
                Err(e) => e,
            };
            job.shared.kill(det.id.as_str(), &e);
            turn.fail(d, e);
        }
        slot.is_some().then_some(ready)
    }

    /// Sends one run request for the `ready` detectors, settles the previous trace
    /// (`settle_prev`) while the worker works, and takes the replies in order. Returns how many
    /// of `ready` got a reply (the rest run again), or `None` when there is no worker to ask.
    fn run_ready(
        &self,
        slot: &mut Option<Worker>,
        job: &TraceJob<'_>,
        ready: &[usize],
        turn: &mut Turn,
        stats: &mut RunStats,
        settle_prev: &mut dyn FnMut(),
    ) -> Option<usize> {
        let worker = slot.as_mut()?;
        let ids: Vec<&str> = ready
            .iter()
            .map(|&d| job.detectors[d].id.as_str())
            .collect();
        let batched = ready.len() > 1 && !turn.one_by_one;
        let flush = if batched { BATCH_FLUSH } else { Duration::ZERO };
        let wait = self.limits.call_timeout + flush;
        let mut started = Instant::now();
        let sent = worker
            .send(RUN, &protocol::run_body(&ids, job.key, flush.as_secs_f64()))
            .and_then(|()| worker.send_evictions());
        // The worker is busy with this trace: decode the previous one's replies meanwhile.
        settle_prev();
        let mut first = Some(match sent {
            Ok(()) => slot.as_mut().map_or(Reply::Timeout, |w| w.wait(wait)),
            Err(death) => Reply::Died(death),
        });
        let mut settled = 0;
        for (pos, &d) in ready.iter().enumerate() {
            let reply = match first.take() {
                Some(r) => r,
                None => match slot.as_mut() {
                    Some(w) => w.wait(wait),
                    None => break,
                },
            };
            if batched && ready.len() - pos > 1 && !matches!(reply, Reply::Frame(_)) {
                // Timed out or died with several replies missing: run those again one by one.
                if let Reply::Died(_) | Reply::Timeout = reply {
                    *slot = None;
                }
                turn.one_by_one = true;
                break;
            }
            let res = &mut turn.out[d];
            res.round_trip_s = started.elapsed().as_secs_f64();
            started = Instant::now();
            stats.calls += 1;
            stats.round_trip_s += res.round_trip_s;
            settled = pos + 1;
            if !self.take_reply(slot, job, d, reply, turn, stats) {
                break;
            }
        }
        Some(settled)
    }

    /// Takes detector `d`'s run reply into `turn`: a marshal reply's timing now and its patterns
    /// later ([`Unsettled`]), a JSON reply or a dead worker's error at once. Returns whether the
    /// worker is still there for the next reply.
    fn take_reply(
        &self,
        slot: &mut Option<Worker>,
        job: &TraceJob<'_>,
        d: usize,
        reply: Reply,
        turn: &mut Turn,
        stats: &mut RunStats,
    ) -> bool {
        let det = &job.detectors[d];
        let res = &mut turn.out[d];
        // Patterns in marshal format: decoded later; only the timing is read now.
        if let Reply::Frame(f) = &reply
            && let Some((wall, cpu)) = protocol::marshal_times(f)
        {
            res.wall_s = wall;
            res.cpu_s = cpu;
            stats.detector_wall_s += wall;
            if let Reply::Frame(f) = reply {
                turn.frames.push((d, f));
            }
            return true;
        }
        let parsed = self.interpret(reply, slot);
        let worker_gone = parsed.is_err();
        match parsed {
            Ok(reply) => {
                (res.wall_s, res.cpu_s) = reply.times();
                stats.detector_wall_s += res.wall_s;
                match reply {
                    WorkerReply::Done {
                        printed, patterns, ..
                    } => accept(res, printed, patterns, det, turn.steps),
                    WorkerReply::Failed { error, .. } => {
                        let e = error.to_detector_error(self.limits.memory_bytes);
                        if error.ends_worker() {
                            // The worker exits after a fatal error; its remaining replies never come.
                            *slot = None;
                            job.shared.kill(det.id.as_str(), &e);
                        }
                        res.status = CandidateStatus::Failed(e);
                    }
                }
            }
            Err(e) => {
                job.shared.kill(det.id.as_str(), &e);
                res.status = CandidateStatus::Failed(e);
            }
        }
        !(worker_gone || slot.is_none())
    }

    /// Makes sure the worker holds the trace, evicting its least recently used one beyond the cache size.
    fn load(
        &self,
        worker: &mut Worker,
        key: &str,
        trace: &dyn Loadable,
        detectors: usize,
        stats: &mut RunStats,
    ) -> Result<(), DetectorError> {
        if worker.traces.iter().any(|k| k == key) {
            worker.traces.retain(|k| k != key);
            worker.traces.push_back(key.to_string());
            return Ok(());
        }
        let c0 = Instant::now();
        let (kind, body) = trace.load_request(key, detectors);
        stats.convert_s += c0.elapsed().as_secs_f64();
        let l0 = Instant::now();
        let wait = self
            .limits
            .call_timeout
            .max(std::time::Duration::from_secs(30));
        match worker.request(kind, &body, wait) {
            Reply::Frame(f) => match parse(&f, 0) {
                Ok(WorkerReply::Done { build, .. }) => {
                    stats.build_s += build;
                }
                // The worker's only failure while loading is running out of memory.
                _ => {
                    return Err(DetectorError::Memory {
                        limit_bytes: self.limits.memory_bytes,
                    });
                }
            },
            Reply::Timeout => {
                return Err(DetectorError::Crashed {
                    message: "loading the trace timed out".into(),
                });
            }
            Reply::Died(death) => {
                return Err(DetectorError::Crashed {
                    message: format!("while loading the trace: {}", death.message),
                });
            }
        }
        stats.traces_loaded += 1;
        worker.traces.push_back(key.to_string());
        // The least recently used trace beyond the cache is dropped after the next run request
        // (`send_evictions`), so that freeing it overlaps the Rust side's work instead of delaying it.
        while worker.traces.len() > self.limits.trace_cache.max(1) {
            if let Some(old) = worker.traces.pop_front() {
                worker.evict.push(old);
            }
        }
        // Loads without runs in between (every detector failed to compile) must not pile up traces.
        if worker.evict.len() > 4 && worker.send_evictions().is_err() {
            return Err(DetectorError::Crashed {
                message: "the worker died while dropping traces".into(),
            });
        }
        stats.load_s += l0.elapsed().as_secs_f64();
        Ok(())
    }

    /// Parses a reply, or turns it into the error of a killed or dead worker (which is then dropped).
    fn interpret(
        &self,
        reply: Reply,
        slot: &mut Option<Worker>,
    ) -> Result<WorkerReply, DetectorError> {
        match reply {
            Reply::Frame(f) => parse(&f, self.limits.max_output_bytes).map_err(|e| {
                *slot = None;
                DetectorError::Crashed {
                    message: e.to_string(),
                }
            }),
            Reply::Timeout => {
                *slot = None;
                Err(DetectorError::Timeout {
                    seconds: self.limits.call_timeout.as_secs_f64(),
                })
            }
            Reply::Died(death) => {
                *slot = None;
                Err(self.death_error(&death))
            }
        }
    }
}

/// Where settled results go: (trace, results by detector).
type Store<'a> = dyn Fn((usize, Vec<CallResult>)) + 'a;

/// How long a worker may hold finished replies before writing them (checked before each call starts).
const BATCH_FLUSH: Duration = Duration::from_millis(20);

/// The results of one trace whose marshalled patterns are not decoded yet.
struct Unsettled {
    trace: usize,
    steps: Option<(i64, i64)>,
    out: Vec<CallResult>,
    /// (detector, reply frame) of the calls that returned patterns.
    frames: Vec<(usize, Vec<u8>)>,
}

impl Unsettled {
    /// Decodes and validates the patterns: (trace, results by detector).
    fn settle(
        mut self,
        detectors: &[Detector],
        limits: &SandboxLimits,
    ) -> (usize, Vec<CallResult>) {
        for (d, frame) in self.frames {
            let res = &mut self.out[d];
            match protocol::parse_reply(&frame, limits.max_output_bytes) {
                Ok(WorkerReply::Done {
                    printed, patterns, ..
                }) => accept(res, printed, patterns, &detectors[d], self.steps),
                Ok(WorkerReply::Failed { error, .. }) => {
                    res.status =
                        CandidateStatus::Failed(error.to_detector_error(limits.memory_bytes))
                }
                Err(message) => {
                    res.status = CandidateStatus::Failed(DetectorError::Crashed { message })
                }
            }
        }
        (self.trace, self.out)
    }
}

/// Takes a successful reply's printed text and validated patterns into `res`.
fn accept(
    res: &mut CallResult,
    printed: String,
    patterns: Value,
    det: &Detector,
    steps: Option<(i64, i64)>,
) {
    res.printed = printed;
    match validate(patterns, det, steps) {
        Ok(p) => res.patterns = p,
        Err(e) => res.status = CandidateStatus::Failed(e),
    }
}

/// One trace's turn on a worker: the batch's detectors and the trace, as [`WorkerPool::run_trace`]
/// and its steps read them.
struct TraceJob<'j> {
    detectors: &'j [Detector],
    /// The trace's index in the batch.
    t: usize,
    /// Its key in the workers' caches.
    key: &'j str,
    trace: &'j dyn Loadable,
    shared: &'j Shared,
}

impl TraceJob<'_> {
    /// Detector `d`'s result before it runs: ok, no patterns, no time.
    fn blank(&self, d: usize) -> CallResult {
        CallResult {
            detector: d,
            trace: self.t,
            status: CandidateStatus::Ok,
            patterns: Vec::new(),
            wall_s: 0.0,
            cpu_s: 0.0,
            round_trip_s: 0.0,
            printed: String::new(),
        }
    }
}

/// What a trace's turn has gathered so far.
struct Turn {
    /// Results by detector; `Ok` until settled otherwise.
    out: Vec<CallResult>,
    /// (detector, reply frame) of the calls whose marshalled patterns are decoded later.
    frames: Vec<(usize, Vec<u8>)>,
    /// Whether a batched run lost its worker with several replies missing, so the rest run one
    /// reply at a time.
    one_by_one: bool,
    /// The trace's first and last step, for validating patterns.
    steps: Option<(i64, i64)>,
}

impl Turn {
    fn fail(&mut self, d: usize, e: DetectorError) {
        self.out[d].status = CandidateStatus::Failed(e);
    }
}

/// State shared by the threads of one batch.
struct Shared {
    /// Detectors that failed fatally, with the error later calls report as `skipped`.
    dead: Mutex<HashMap<String, DetectorError>>,
}

impl Shared {
    fn kill(&self, id: &str, e: &DetectorError) {
        if e.is_fatal() {
            self.dead
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .entry(id.to_string())
                .or_insert_with(|| e.clone());
        }
    }

    /// The error a detector's later calls report: compile errors as they were, run-time failures as
    /// `skipped`.
    fn dead_error(&self, id: &str) -> Option<DetectorError> {
        let dead = self.dead.lock().unwrap_or_else(|p| p.into_inner());
        dead.get(id).map(|e| match e {
            DetectorError::Syntax { .. }
            | DetectorError::Forbidden { .. }
            | DetectorError::NoFindPattern { .. } => e.clone(),
            other => DetectorError::Skipped {
                message: other.to_string(),
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::synthetic_trace;
    use crate::trace::Env;

    #[test]
    fn a_batch_whose_only_detector_fails_to_compile_leaves_the_worker_usable() {
        let pool = WorkerPool::new(SandboxLimits {
            workers: 1,
            call_timeout: std::time::Duration::from_secs(5),
            ..SandboxLimits::default()
        })
        .unwrap();
        let traces = vec![synthetic_trace(Env::Pooltool, 0, 5, 2)];
        let bad = Detector::new(Env::Pooltool, "x", "def find_pattern(trace:\n", "t");
        let good = Detector::new(
            Env::Pooltool,
            "x",
            "def find_pattern(trace):\n    return []\n",
            "t",
        );
        let r = pool.run(std::slice::from_ref(&bad), &traces);
        assert_eq!(r.results[0].status.as_str(), "syntax");
        let r = pool.run(std::slice::from_ref(&good), &traces);
        assert_eq!(
            r.results[0].status,
            CandidateStatus::Ok,
            "{:?}",
            r.results[0]
        );
        // The worker was not killed waiting for a reply to an empty run request.
        assert_eq!(r.stats.restarts, 0);
    }

    /// Reports the trace's last step, so a wrong (evicted or stale) trace shows.
    fn last_step_detector() -> Detector {
        Detector::new(
            Env::Pooltool,
            "x",
            "def find_pattern(trace):\n    n = trace['timesteps'][-1]['index']\n    return [{'label': 'x', 'start_timestep': n, 'end_timestep': n, 'parameters': {'object_details': {}}}]\n",
            "t",
        )
    }

    #[test]
    fn a_small_trace_cache_evicts_and_reloads_without_changing_results() {
        let pool = WorkerPool::new(SandboxLimits {
            workers: 1,
            trace_cache: 2,
            ..SandboxLimits::default()
        })
        .unwrap();
        let traces: Vec<Trace> = (0..6)
            .map(|i| synthetic_trace(Env::Pooltool, i, 4 + i, 2))
            .collect();
        let d = last_step_detector();
        let first = pool.run(std::slice::from_ref(&d), &traces);
        let again = pool.run(std::slice::from_ref(&d), &traces);
        for r in [&first, &again] {
            for (res, t) in r.results.iter().zip(&traces) {
                assert_eq!(res.status, CandidateStatus::Ok, "{res:?}");
                assert_eq!(res.patterns[0].end_step, t.timesteps.last().unwrap().index);
            }
        }
        // Two traces stay cached; the other four are loaded again on the second pass.
        assert_eq!(first.stats.traces_loaded, 6);
        assert_eq!(again.stats.traces_loaded, 4);
        assert_eq!(again.stats.restarts, 0);
    }

    #[test]
    fn with_no_trace_cache_each_trace_is_freed_after_its_run_and_results_do_not_change() {
        let pool = WorkerPool::new(SandboxLimits {
            workers: 1,
            trace_cache: 0,
            ..SandboxLimits::default()
        })
        .unwrap();
        let traces: Vec<Trace> = (0..5)
            .map(|i| synthetic_trace(Env::Pooltool, i, 4 + i, 2))
            .collect();
        let raises = Detector::new(
            Env::Pooltool,
            "y",
            "def find_pattern(trace):\n    return [][1]\n",
            "t",
        );
        let bad = Detector::new(Env::Pooltool, "z", "def find_pattern(trace:\n", "t");
        // A trace whose only detector fails to compile is loaded and freed without a run request.
        let r = pool.run(std::slice::from_ref(&bad), &traces[..2]);
        assert!(r.results.iter().all(|c| c.status.as_str() == "syntax"));
        let dets = [last_step_detector(), raises];
        for _ in 0..2 {
            let r = pool.run(&dets, &traces);
            for (t, trace) in traces.iter().enumerate() {
                let res = &r.results[2 * t];
                assert_eq!((res.trace, res.detector), (t, 0));
                assert_eq!(res.status, CandidateStatus::Ok, "{res:?}");
                assert_eq!(
                    res.patterns[0].end_step,
                    trace.timesteps.last().unwrap().index
                );
                assert_eq!(r.results[2 * t + 1].status.as_str(), "runtime");
            }
            // Nothing is kept between runs: every trace is loaded each time, by the same worker.
            assert_eq!(r.stats.traces_loaded, traces.len());
            assert_eq!(r.stats.restarts, 0);
        }
        // Not even the last one (a cache of one trace would keep it).
        let r = pool.run(&dets, &traces[4..]);
        assert_eq!(r.results[0].patterns[0].end_step, 7);
        assert_eq!(r.stats.traces_loaded, 1);
    }
}
