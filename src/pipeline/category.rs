//! What a user can do about an error: [`ErrorCategory`], and [`Categorize`], the one place that decides
//! the category of every library error a command or a stage can return.
//!
//! The command line turns a category into an exit code (one table, in `cli/mod.rs`); everything else in
//! the library only builds typed errors and lets this module classify them, so that "bad input" means
//! the user's input and nothing else.

use std::io;

use super::{RunError, SpecError, StageError};
use crate::detect::{DetectError, LibraryError};
use crate::llm::LlmError;
use crate::optimise::OptimiseError;
use crate::query::QueryError;
use crate::search::{ProposeError, SearchError};
use crate::store::{ReadTraceError, StoreError};

/// What kind of failure an error is, from the point of view of the person who has to act on it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ErrorCategory {
    /// The user's input or configuration is wrong (a malformed file, an unknown option value, an
    /// invalid pipeline, a run with too few traces, a file that does not exist): fix it and retry.
    Input,
    /// The command ran but did not succeed (items failed, a stage failed at run time, an answer that
    /// could not be used).
    Failed,
    /// An external service is unavailable: the LLM endpoint is unreachable or keeps failing after
    /// retries, or the detector workers cannot start (no Python, a missing sandbox layer). Retry later
    /// or fix the machine; the input is fine.
    Service,
    /// Reading or writing the run folder or an output failed (disk full, permission denied, a
    /// read-only file system).
    Io,
    /// Another annotrace process holds the run folder.
    Locked,
    /// A bug in annotrace: please report it.
    Internal,
}

impl ErrorCategory {
    /// The category's name (`input`, `failed`, `service`, `io`, `locked`, `internal`).
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorCategory::Input => "input",
            ErrorCategory::Failed => "failed",
            ErrorCategory::Service => "service",
            ErrorCategory::Io => "io",
            ErrorCategory::Locked => "locked",
            ErrorCategory::Internal => "internal",
        }
    }
}

/// An error that knows its [`ErrorCategory`].
pub trait Categorize {
    /// What kind of failure this is.
    fn category(&self) -> ErrorCategory;
}

/// A file-system error: a missing file is the user's (they named it), anything else is the disk's.
fn io_category(e: &io::Error) -> ErrorCategory {
    match e.kind() {
        io::ErrorKind::NotFound => ErrorCategory::Input,
        _ => ErrorCategory::Io,
    }
}

impl Categorize for io::Error {
    fn category(&self) -> ErrorCategory {
        io_category(self)
    }
}

impl Categorize for RunError {
    fn category(&self) -> ErrorCategory {
        match self {
            RunError::Spec(e) => e.category(),
            RunError::UnknownStage { .. } => ErrorCategory::Input,
            RunError::Locked { .. } => ErrorCategory::Locked,
            RunError::Store(e) => e.category(),
            RunError::Stage { source, .. } => source.category(),
            RunError::ShardsUnfinished { .. } | RunError::InputFailed { .. } => {
                ErrorCategory::Failed
            }
        }
    }
}

impl Categorize for SpecError {
    fn category(&self) -> ErrorCategory {
        match self {
            // The user named the file: missing, a folder or unreadable is theirs to fix; a disk
            // error while reading it is not.
            SpecError::Io { source, .. } => match source.kind() {
                io::ErrorKind::NotFound
                | io::ErrorKind::PermissionDenied
                | io::ErrorKind::IsADirectory => ErrorCategory::Input,
                _ => ErrorCategory::Io,
            },
            _ => ErrorCategory::Input,
        }
    }
}

impl Categorize for StageError {
    fn category(&self) -> ErrorCategory {
        match self {
            StageError::InvalidTrace(_) | StageError::Source(_) => ErrorCategory::Input,
            StageError::BadTraceRows { .. } => ErrorCategory::Input,
            StageError::Store(e) => e.category(),
            StageError::Query(e) => e.category(),
            StageError::Workers(e) => e.category(),
            StageError::Llm(e) => e.category(),
            StageError::Search(e) => e.category(),
            StageError::Proposer(e) => e.category(),
            StageError::Library(e) => e.category(),
            StageError::Io { source, .. } => io_category(source),
            StageError::Goal { .. } => ErrorCategory::Input,
            StageError::Optimise(e) => match e.as_ref() {
                OptimiseError::Internal(_) => ErrorCategory::Internal,
                _ => ErrorCategory::Input,
            },
            StageError::TooFewTraces { .. } | StageError::Input(_) => ErrorCategory::Input,
            StageError::Internal(_) => ErrorCategory::Internal,
            // A simulator that blew up on valid input: the run failed, the input was not wrong.
            StageError::NonFinite { .. } => ErrorCategory::Failed,
            // A scene, task or click list the environment refuses: the input's fault.
            StageError::Simulation { .. } => ErrorCategory::Input,
            StageError::Injected(_) => ErrorCategory::Failed,
            StageError::Labels(_) => ErrorCategory::Failed,
        }
    }
}

impl Categorize for StoreError {
    fn category(&self) -> ErrorCategory {
        match self {
            StoreError::Io { source, .. } => io_category(source),
            StoreError::Parquet { source, .. } => match source {
                ::parquet::errors::ParquetError::External(e) => e
                    .downcast_ref::<io::Error>()
                    .map_or(ErrorCategory::Input, io_category),
                // A damaged or foreign file in the run folder: the data is wrong, not the disk.
                _ => ErrorCategory::Input,
            },
            StoreError::Schema { .. } | StoreError::Json { .. } => ErrorCategory::Input,
            // A published file missing, resized or changed: the run folder's data is wrong.
            StoreError::Damaged { .. } | StoreError::ManifestFormat { .. } => ErrorCategory::Input,
            // The object store is unreachable or refused the request (credentials, endpoint).
            StoreError::Remote { .. } => ErrorCategory::Service,
            // Another writer committed first: as with a run folder another process holds.
            StoreError::Conflict { .. } => ErrorCategory::Locked,
            StoreError::RemoteUnsupported { .. } => ErrorCategory::Input,
        }
    }
}

impl Categorize for ReadTraceError {
    fn category(&self) -> ErrorCategory {
        match self {
            ReadTraceError::NotFound { .. } | ReadTraceError::Decode(_) => ErrorCategory::Input,
            ReadTraceError::Store(e) => e.category(),
        }
    }
}

impl Categorize for QueryError {
    fn category(&self) -> ErrorCategory {
        match self {
            // DataFusion's errors are nearly always the query's (a bad column, a syntax error).
            QueryError::DataFusion(_) => ErrorCategory::Input,
            // Refused writes, limits hit and bad limit settings are the query's or its settings'.
            QueryError::NotReadOnly { .. }
            | QueryError::MemoryLimit { .. }
            | QueryError::Timeout { .. }
            | QueryError::OutputInRun { .. }
            | QueryError::BadSetting(_) => ErrorCategory::Input,
            // A Ballista engine in a build without the feature is a configuration error; a cluster
            // that does not answer is an unavailable service.
            QueryError::BadEngine(_) => ErrorCategory::Input,
            QueryError::EngineUnavailable { .. } => ErrorCategory::Service,
            QueryError::Store(e) => e.category(),
            QueryError::Runtime(_) => ErrorCategory::Internal,
        }
    }
}

impl Categorize for DetectError {
    fn category(&self) -> ErrorCategory {
        match self {
            DetectError::NoPython { .. }
            | DetectError::Spawn { .. }
            | DetectError::LayerUnavailable { .. } => ErrorCategory::Service,
            DetectError::Internal(_) => ErrorCategory::Internal,
        }
    }
}

impl Categorize for LibraryError {
    fn category(&self) -> ErrorCategory {
        match self {
            LibraryError::Io { source, .. } => match source.kind() {
                io::ErrorKind::NotFound | io::ErrorKind::IsADirectory => ErrorCategory::Input,
                _ => ErrorCategory::Io,
            },
            _ => ErrorCategory::Input,
        }
    }
}

impl Categorize for LlmError {
    fn category(&self) -> ErrorCategory {
        match self {
            // The request itself is refused (configuration, replay, a 4xx other than 408/429).
            e if e.is_refusal() => ErrorCategory::Input,
            e if e.is_unavailable() => ErrorCategory::Service,
            LlmError::Store(e) => e.category(),
            // A bad answer, an exhausted budget, a damaged `llm_calls` file: the call did not succeed.
            _ => ErrorCategory::Failed,
        }
    }
}

impl Categorize for ProposeError {
    fn category(&self) -> ErrorCategory {
        match self {
            ProposeError::Unavailable(_) => ErrorCategory::Service,
            ProposeError::Refused(_) => ErrorCategory::Input,
            _ => ErrorCategory::Failed,
        }
    }
}

impl Categorize for SearchError {
    fn category(&self) -> ErrorCategory {
        match self {
            SearchError::Proposer { source, .. } => source.category(),
            SearchError::Seed { .. } | SearchError::AllProposalsFailed { .. } => {
                ErrorCategory::Failed
            }
            SearchError::Checkpoint(_) => ErrorCategory::Io,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    #[test]
    fn io_errors_split_between_the_user_and_the_disk() {
        let missing = io::Error::from(io::ErrorKind::NotFound);
        let full = io::Error::from(io::ErrorKind::StorageFull);
        let denied = io::Error::from(io::ErrorKind::PermissionDenied);
        assert_eq!(missing.category(), ErrorCategory::Input);
        assert_eq!(full.category(), ErrorCategory::Io);
        assert_eq!(denied.category(), ErrorCategory::Io);
        let stage = StageError::Io {
            path: PathBuf::from("/x"),
            source: io::Error::from(io::ErrorKind::StorageFull),
        };
        assert_eq!(stage.category(), ErrorCategory::Io);
    }

    #[test]
    fn an_unreachable_endpoint_is_a_service_failure_not_bad_input() {
        let e = LlmError::Connection {
            url: "http://127.0.0.1:9".into(),
            message: "refused".into(),
            attempts: 3,
        };
        assert_eq!(e.category(), ErrorCategory::Service);
        let stage = StageError::from(e);
        assert_eq!(stage.category(), ErrorCategory::Service);
        let run = RunError::Stage {
            id: "evolve".into(),
            source: stage,
        };
        assert_eq!(run.category(), ErrorCategory::Service);
        assert_eq!(
            LlmError::Config("no model".into()).category(),
            ErrorCategory::Input
        );
        let status = |status| LlmError::Status {
            status,
            url: "u".into(),
            body_excerpt: String::new(),
            attempts: 1,
        };
        assert_eq!(status(503).category(), ErrorCategory::Service);
        assert_eq!(status(401).category(), ErrorCategory::Input);
    }

    #[test]
    fn a_proposer_that_cannot_be_reached_is_a_service_failure() {
        let e = SearchError::Proposer {
            label: "x".into(),
            source: ProposeError::Unavailable("refused".into()),
        };
        assert_eq!(StageError::from(e).category(), ErrorCategory::Service);
        let e = SearchError::Proposer {
            label: "x".into(),
            source: ProposeError::Other("garbage".into()),
        };
        assert_eq!(e.category(), ErrorCategory::Failed);
    }

    #[test]
    fn workers_that_cannot_start_are_a_service_failure_and_a_lock_is_its_own() {
        let e = DetectError::NoPython {
            tried: "python3".into(),
            message: "not found".into(),
        };
        assert_eq!(StageError::from(e).category(), ErrorCategory::Service);
        let locked = RunError::Locked { run: "r".into() };
        assert_eq!(locked.category(), ErrorCategory::Locked);
        assert_eq!(
            StageError::Internal("x".into()).category(),
            ErrorCategory::Internal
        );
    }
}
