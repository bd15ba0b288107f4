//! The stage kinds a pipeline can use, listed in one slice as ripgrep lists its flags.
//!
//! A kind lives in `pipeline/stages/<kind>.rs` with its parameters, docs, constructor and tests; adding
//! one means adding it to [`STAGE_KINDS`]. `annotrace stages` prints this list.

use super::params::ParamsOf;
use super::spec::{PipelineSpec, StageDef};
use super::stage::Stage;
use super::stages;

/// Why a stage could not be built from its parameters.
#[derive(Debug, Clone)]
pub struct BuildError {
    /// The parameter at fault, if one is (its line is reported).
    pub param: Option<&'static str>,
    /// What is wrong.
    pub message: String,
}

impl BuildError {
    /// A fault in one parameter.
    pub fn param(param: &'static str, message: impl Into<String>) -> Self {
        BuildError {
            param: Some(param),
            message: message.into(),
        }
    }
}

/// Builds a stage of one kind from its validated definition in a pipeline.
pub type BuildStage = fn(&StageDef, &PipelineSpec) -> Result<Box<dyn Stage>, BuildError>;

/// A kind of stage: its name, docs, parameters and constructor.
#[derive(Debug)]
pub struct StageKind {
    /// The `kind = "…"` value.
    pub name: &'static str,
    /// One line for listings.
    pub summary: &'static str,
    /// A paragraph for `annotrace stages`.
    pub doc: &'static str,
    /// The tables (or files) it writes.
    pub writes: &'static str,
    /// Its parameters: the kind's typed parameter struct.
    pub params: ParamsOf,
    /// Builds the stage from validated parameters; also called once during validation.
    pub build: BuildStage,
}

/// Every stage kind, in the order `annotrace stages` lists them.
pub static STAGE_KINDS: &[&StageKind] = &[
    &stages::import::KIND,
    &stages::simulate::KIND,
    &stages::annotate::KIND,
    &stages::accuracy::KIND,
    &stages::optimise::KIND,
    &stages::evolve::KIND,
    &stages::sql::KIND,
    &stages::export::KIND,
];

/// The kind with this name.
pub fn find_kind(name: &str) -> Option<&'static StageKind> {
    STAGE_KINDS.iter().copied().find(|k| k.name == name)
}

/// The names of all kinds.
pub fn kind_names() -> Vec<&'static str> {
    STAGE_KINDS.iter().map(|k| k.name).collect()
}
