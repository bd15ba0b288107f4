//! Pipelines: files that list stages, and the runner that executes them over a run folder.
//!
//! **Owns:** the pipeline file format and its validation ([`PipelineSpec`]), the registry of stage kinds
//! ([`STAGE_KINDS`]), the [`Stage`] trait and its context, fingerprints, the manifest, resumption, and the
//! runner ([`run`]). **Does not:** know how a stage computes its tables (each kind lives in `stages/`),
//! print anything (progress goes through [`Progress`]), or read the command line.
//!
//! Entry point: `PipelineSpec::from_file(path)` then `run(&spec, &RunOptions::default(), &())`.

mod category;
mod params;
mod progress;
mod registry;
#[cfg(feature = "s3")]
mod remote;
mod runner;
mod sharded;
mod spec;
mod stage;
pub mod stages;
mod toml_doc;

use std::path::PathBuf;

pub use crate::store::manifest::{Manifest, OutputFile, PipelineInfo, StageRecord, StageStatus};
pub use category::{Categorize, ErrorCategory};
pub use params::{ParamDoc, ParamDocs, ParamError, ParamType, ParamsOf, StageParams};
pub use progress::Progress;
pub use registry::{BuildError, STAGE_KINDS, StageKind, find_kind, kind_names, params_markdown};
pub use runner::{
    Action, PlannedStage, RunError, RunOptions, RunReason, RunReport, StageReport, error_chain,
    explain, run,
};
pub use sharded::{Slice, run_shard};
pub use spec::{PipelineSpec, StageDef, project_dir_of, valid_id};
pub use stage::{FaultAction, FaultPlan, FaultPoint, Stage, StageContext, StageError, StageOutput};

/// A pipeline file is invalid. Every variant names the file and line.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SpecError {
    /// The file could not be read.
    #[error("{}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// Not valid TOML.
    #[error("{}:{line}: invalid TOML: {message}", file.display())]
    Toml {
        /// The file.
        file: PathBuf,
        /// Line of the fault.
        line: usize,
        /// The parser's message.
        message: String,
    },
    /// A key that means nothing here.
    #[error("{}:{line}: unknown key `{key}` in {context}{} (known: {known})", file.display(), suggestion.as_ref().map(|s| format!("; did you mean `{s}`?")).unwrap_or_default())]
    UnknownKey {
        /// The file.
        file: PathBuf,
        /// Line of the key.
        line: usize,
        /// The key.
        key: String,
        /// Where it appeared.
        context: String,
        /// Keys that would have been understood.
        known: String,
        /// The closest known key, when the key looks like a typo of it.
        suggestion: Option<String>,
    },
    /// A stage kind that does not exist.
    #[error("{}:{line}: unknown stage kind {kind:?}{} (known: {known})", file.display(), suggestion.as_ref().map(|s| format!("; did you mean {s:?}?")).unwrap_or_default())]
    UnknownKind {
        /// The file.
        file: PathBuf,
        /// Line of the `kind` key.
        line: usize,
        /// The kind given.
        kind: String,
        /// Known kinds.
        known: String,
        /// The closest known kind.
        suggestion: Option<String>,
    },
    /// An input that names no stage.
    #[error("{}:{line}: stage \"{stage}\" names input \"{input}\", which is not a stage of this pipeline (stages: {known})", file.display())]
    MissingInput {
        /// The file.
        file: PathBuf,
        /// Line of the `inputs` key.
        line: usize,
        /// The stage.
        stage: String,
        /// The missing input.
        input: String,
        /// The pipeline's stage ids.
        known: String,
    },
    /// Two stages with one id.
    #[error("{}:{line}: stage id \"{id}\" is used twice (first at line {first_line})", file.display())]
    DuplicateId {
        /// The file.
        file: PathBuf,
        /// Line of the second use.
        line: usize,
        /// The id.
        id: String,
        /// Line of the first use.
        first_line: usize,
    },
    /// Inputs that form a cycle.
    #[error("{}:{line}: stages form a cycle: {}", file.display(), cycle.join(" -> "))]
    Cycle {
        /// The file.
        file: PathBuf,
        /// Line of a stage on the cycle.
        line: usize,
        /// The cycle, first stage repeated at the end.
        cycle: Vec<String>,
    },
    /// Any other invalid value.
    #[error("{}:{line}: {message}", file.display())]
    Invalid {
        /// The file.
        file: PathBuf,
        /// Line of the fault.
        line: usize,
        /// What is wrong.
        message: String,
    },
}
