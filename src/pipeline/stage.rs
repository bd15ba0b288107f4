//! The [`Stage`] trait every stage kind implements, the context a stage runs in, and what it returns.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use serde_json::Value;

use super::progress::Progress;
use crate::query::QueryError;
use crate::store::{RunDir, Staging, StoreError};
use crate::trace::json::{SourceError, TraceError};

/// A stage of a pipeline, built from its validated parameters.
pub trait Stage: Send + Sync {
    /// Material beyond kind, parameters and inputs that decides whether cached output is still valid
    /// (input files' sizes and times, the text of an SQL file). Default: nothing.
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(Value::Null)
    }

    /// Does the work: writes tables through `ctx.staging()` (committed by the runner) or files under
    /// `exports/` (listed in the output).
    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError>;

    /// Whether the stage can run as slices in separate processes (`annotrace run --shard i/n`): its
    /// work is a deterministic list of units named `NNNNN…` (the leading number is the unit's index),
    /// each written to its own files and recorded with [`StageContext::finish_shard`], and
    /// [`StageContext::owns`] is asked before a unit is computed. The run without a slice (the commit)
    /// finds every unit done, computes the units without a leading number and sums the records.
    /// A stage may also be one unit whose shards carry other names (`evolve`: its rounds), computed
    /// whole by the slice that owns it and replayed from its records by the commit. Default: no.
    fn shardable(&self) -> bool {
        false
    }

    /// Whether, in a sharded run, the stage may be computed while an earlier stage that also says so
    /// and is not upstream of it is still running (sibling `evolve` searches): it reads nothing such
    /// a sibling writes except a cache whose use its commit decides, and stages are still committed
    /// in run order. Only meaningful for a [`Stage::shardable`] stage. Default: no.
    fn runs_beside_siblings(&self) -> bool {
        false
    }
}

/// What a finished stage reports.
#[derive(Clone, Debug, Default)]
pub struct StageOutput {
    /// Rows written per table.
    pub rows: BTreeMap<String, u64>,
    /// Files written outside the table folders (exports), as absolute or run-relative paths.
    pub files: Vec<PathBuf>,
    /// Stage-specific details for the manifest.
    pub summary: Value,
    /// One human line for the terminal.
    pub line: String,
}

/// A stage failed. Every variant keeps its cause; [`Categorize`](super::Categorize) says what kind of
/// failure it is (bad input, an unavailable service, a disk error, a bug).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StageError {
    /// An input trace is invalid (and `skip_invalid` is off).
    #[error("{0}")]
    InvalidTrace(Box<TraceError>),
    /// An input file could not be read.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// The rows of a trace in the run's tables do not form a valid trace.
    #[error("{}: trace {trace_id}", path.display())]
    BadTraceRows {
        /// The `traces` file.
        path: PathBuf,
        /// The trace.
        trace_id: String,
        /// What is wrong.
        #[source]
        source: Box<crate::trace::batch::DecodeError>,
    },
    /// Reading or writing the run failed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// Reading or writing a file outside the run's tables failed (an export, an SQL file).
    #[error("{}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A query failed.
    #[error(transparent)]
    Query(#[from] QueryError),
    /// The detector worker pool could not start or failed as a whole.
    #[error(transparent)]
    Workers(#[from] crate::detect::DetectError),
    /// A detector library could not be read.
    #[error(transparent)]
    Library(#[from] crate::detect::LibraryError),
    /// The LLM client failed (configuration, an unreachable endpoint, its `llm_calls` table).
    #[error("llm: {0}")]
    Llm(Box<crate::llm::LlmError>),
    /// An evolutionary search could not go on.
    #[error(transparent)]
    Search(Box<crate::search::SearchError>),
    /// A proposer could not be set up.
    #[error(transparent)]
    Proposer(#[from] crate::search::ProposeError),
    /// A goal's reward program or verification rule does not compile.
    #[error("goal {id:?}: {part}")]
    Goal {
        /// The goal.
        id: String,
        /// `program` or `verify`.
        part: &'static str,
        /// The compiler's error.
        #[source]
        source: Box<crate::reward::RewardError>,
    },
    /// The optimisation experiment could not run.
    #[error(transparent)]
    Optimise(Box<crate::optimise::OptimiseError>),
    /// The run holds too few traces for the stage.
    #[error("{stage} needs at least {needed} {what} (found {found}){hint}")]
    TooFewTraces {
        /// The stage kind.
        stage: &'static str,
        /// Which traces (`pooltool traces in the run`, `training traces after the held-out split`).
        what: String,
        /// The minimum.
        needed: usize,
        /// How many there are.
        found: usize,
        /// What to do about it (empty, or `: add …`).
        hint: &'static str,
    },
    /// Building a batch failed (an annotrace bug if it happens).
    #[error("internal error, please report it: {0}")]
    Internal(String),
    /// Bad input data that the message explains, for the rare case no typed variant fits. Prefer a
    /// typed variant that keeps its cause: this one is always categorised as the user's input.
    #[error("{0}")]
    Input(String),
    /// An environment refused to simulate one item (a scene, task or episode), with its cause.
    #[error("{item}: {source}")]
    Simulation {
        /// The item (`scene pool-7-000003`, `trace …`, `task 00004:063`).
        item: String,
        /// The environment's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A simulator produced a state that is not finite (NaN or infinite).
    #[error(
        "trace {trace}: the simulation produced a non-finite {field} (timestep {step}, object #{object}); \
         the trace was not written"
    )]
    NonFinite {
        /// The trace.
        trace: String,
        /// Its timestep index.
        step: i64,
        /// The object's position in the timestep.
        object: usize,
        /// The field.
        field: &'static str,
    },
    /// A fault injected for testing.
    #[error("injected fault: {0}")]
    Injected(String),
    /// Label suggestion gave no usable label (a model's answers after every repair, or the offline
    /// baseline on these examples).
    #[error("suggest-labels: {0}")]
    Labels(String),
}

impl From<crate::llm::LlmError> for StageError {
    fn from(e: crate::llm::LlmError) -> Self {
        StageError::Llm(Box::new(e))
    }
}

impl From<crate::search::SearchError> for StageError {
    fn from(e: crate::search::SearchError) -> Self {
        StageError::Search(Box::new(e))
    }
}

impl From<crate::optimise::OptimiseError> for StageError {
    fn from(e: crate::optimise::OptimiseError) -> Self {
        StageError::Optimise(Box::new(e))
    }
}

impl StageError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        StageError::Io {
            path: path.into(),
            source,
        }
    }
}

impl From<arrow::error::ArrowError> for StageError {
    fn from(e: arrow::error::ArrowError) -> Self {
        StageError::Internal(e.to_string())
    }
}

/// Where to stop a run on purpose, to test resumption: after a stage has finished `n` shards (in this
/// process), in the middle of writing its shard number `n`, or after step `n` of its commit.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FaultPlan {
    /// The stage to stop in.
    pub stage: String,
    /// When to stop.
    pub point: FaultPoint,
    /// How to stop.
    pub action: FaultAction,
}

/// When a [`FaultPlan`] fires.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultPoint {
    /// After this many shards were finished by this process.
    AfterShards(usize),
    /// Half-way through writing the shard with this index (0-based, counting shards this process starts).
    MidShard(usize),
    /// After this many durable steps of the stage's commit (0: before the first; the steps are listed
    /// in the runner's module documentation and `docs/pipelines.md`).
    CommitStep(usize),
}

/// What a [`FaultPlan`] does when it fires.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultAction {
    /// `abort()` the process: no destructor runs, as with `kill -9`.
    Abort,
    /// Return an error from the stage.
    Fail,
}

impl std::str::FromStr for FaultPlan {
    type Err = String;

    /// `STAGE:after-shards=N`, `STAGE:mid-shard=N` or `STAGE:commit-step=N`, optionally followed by
    /// `:fail` (default: abort).
    fn from_str(s: &str) -> Result<Self, String> {
        let usage = || {
            format!(
                "bad fault plan {s:?}: expected STAGE:after-shards=N, STAGE:mid-shard=N or STAGE:commit-step=N, optionally :fail"
            )
        };
        let mut parts = s.split(':');
        let stage = parts
            .next()
            .filter(|p| !p.is_empty())
            .ok_or_else(usage)?
            .to_string();
        let (key, n) = parts
            .next()
            .and_then(|p| p.split_once('='))
            .ok_or_else(usage)?;
        let n: usize = n.parse().map_err(|_| usage())?;
        let point = match key {
            "after-shards" => FaultPoint::AfterShards(n),
            "mid-shard" => FaultPoint::MidShard(n),
            "commit-step" => FaultPoint::CommitStep(n),
            _ => return Err(usage()),
        };
        let action = match parts.next() {
            None | Some("abort") => FaultAction::Abort,
            Some("fail") => FaultAction::Fail,
            Some(_) => return Err(usage()),
        };
        Ok(FaultPlan {
            stage,
            point,
            action,
        })
    }
}

impl FaultPlan {
    /// Fires the fault: aborts the process (as `kill -9` would stop it: no destructor runs) or returns
    /// the error to fail with.
    pub(crate) fn trigger(&self, what: String) -> StageError {
        match self.action {
            FaultAction::Abort => {
                eprintln!("annotrace: injected fault: {what}; aborting");
                std::process::abort();
            }
            FaultAction::Fail => StageError::Injected(what),
        }
    }
}

/// Everything a stage may use while it runs.
pub struct StageContext<'a> {
    pub(crate) run: &'a RunDir,
    pub(crate) stage_id: &'a str,
    pub(crate) seed: u64,
    pub(crate) project_dir: &'a Path,
    pub(crate) staging: Staging,
    pub(crate) progress: &'a dyn Progress,
    pub(crate) fault: Option<&'a FaultPlan>,
    pub(crate) shards_finished: AtomicUsize,
    pub(crate) shards_started: AtomicUsize,
    /// The slice of the work this process computes (`--shard i/n`); `None`: all of it.
    pub(crate) slice: Option<super::sharded::Slice>,
}

impl<'a> StageContext<'a> {
    /// The run folder.
    pub fn run(&self) -> &RunDir {
        self.run
    }

    /// This stage's id.
    pub fn stage_id(&self) -> &str {
        self.stage_id
    }

    /// The pipeline's seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The folder relative paths were resolved against.
    pub fn project_dir(&self) -> &Path {
        self.project_dir
    }

    /// The stage's staging area: tables written here appear in the run when the stage finishes.
    pub fn staging(&self) -> &Staging {
        &self.staging
    }

    /// Writes one batch as a staged file of `table` (partition `env`, file named after `shard`) and
    /// returns its row count.
    pub fn write_batch(
        &self,
        table: &str,
        env: crate::trace::Env,
        shard: &str,
        batch: &arrow::array::RecordBatch,
    ) -> Result<u64, StageError> {
        let mut sink = self.staging.sink(table, Some(env), shard, batch.schema())?;
        sink.write(batch)?;
        let (_, n) = sink.commit()?;
        Ok(n as u64)
    }

    /// Whether this process computes the unit named `shard` (a [`Stage::shardable`] stage asks before
    /// computing a unit): always, unless the process runs one slice of the stage (`--shard i/n`); then
    /// only units whose leading number is `i` modulo `n`. A unit name without a leading number belongs
    /// to no slice: the commit computes it.
    pub fn owns(&self, shard: &str) -> bool {
        self.slice.is_none_or(|s| s.owns(shard))
    }

    /// The slice this process computes, if it runs one (`--shard i/n`).
    pub fn slice(&self) -> Option<super::sharded::Slice> {
        self.slice
    }

    /// Progress reporting.
    pub fn progress(&self) -> &dyn Progress {
        self.progress
    }

    /// The record of a shard finished by an earlier, interrupted attempt, if any.
    pub fn finished_shard(&self, shard: &str) -> Result<Option<Value>, StageError> {
        Ok(self.staging.shard_record(shard)?)
    }

    fn fire(&self, what: String) -> Result<(), StageError> {
        match self.fault {
            Some(f) => Err(f.trigger(what)),
            None => Err(StageError::Injected(what)),
        }
    }

    /// Call when a shard starts writing; returns the shard's ordinal in this process.
    pub fn shard_started(&self) -> usize {
        self.shards_started.fetch_add(1, Ordering::SeqCst)
    }

    /// Call half-way through writing a shard (after some of its files are open and written): the
    /// `mid-shard` fault fires here.
    pub fn checkpoint_mid_shard(&self, ordinal: usize) -> Result<(), StageError> {
        match self.fault {
            Some(f) if f.stage == self.stage_id && f.point == FaultPoint::MidShard(ordinal) => self
                .fire(format!(
                    "stage {} stopped in the middle of shard #{ordinal}",
                    self.stage_id
                )),
            _ => Ok(()),
        }
    }

    /// Marks a shard finished after its files were committed to staging; a later attempt skips it.
    pub fn finish_shard(&self, shard: &str, record: &Value) -> Result<(), StageError> {
        self.staging.mark_done(shard, record)?;
        let n = self.shards_finished.fetch_add(1, Ordering::SeqCst) + 1;
        match self.fault {
            Some(f) if f.stage == self.stage_id && f.point == FaultPoint::AfterShards(n) => {
                self.fire(format!("stage {} stopped after {n} shards", self.stage_id))
            }
            _ => Ok(()),
        }
    }
}
