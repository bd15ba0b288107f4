//! Running one stage as a pipeline: what `simulate`, `import`, `annotate`, `accuracy` and `evolve` do
//! on the command line. The command fills the stage kind's typed parameter struct from its flags
//! ([`kebab`] reads a flag's kebab-case value into one of its enums); the stage then runs through the
//! same runner (manifest, resumption, fingerprints) as in a pipeline file.

use std::path::{Path, PathBuf};

use annotrace::digest::sha256_hex;
use annotrace::pipeline::{
    ErrorCategory, PipelineSpec, RunOptions, SpecError, StageDef, StageKind, StageParams,
    StageReport, run as run_pipeline,
};
use anyhow::Context;

use super::progress::Terminal;
use super::{CliError, fault_from_env, run_error};

/// How a one-stage command runs its stage.
pub(crate) struct OneStage<'a> {
    /// The run folder.
    pub run: &'a Path,
    /// The stage id recorded in the run's manifest.
    pub id: String,
    /// Rerun even when the manifest says the stage finished with the same fingerprint.
    pub force: bool,
    /// Remove the run folder again when it was created by this command and the stage fails.
    pub remove_new_run_on_failure: bool,
}

impl OneStage<'_> {
    /// Builds the stage from `params`, runs it and returns its report. A parameter the stage refuses
    /// is reported as its flag (`--game: unknown I-PHYRE game "nope"`), exit 2.
    pub(crate) fn run<P: StageParams>(
        &self,
        kind: &'static StageKind,
        params: &P,
        quiet: bool,
    ) -> Result<StageReport, CliError> {
        let def = StageDef::new(self.id.clone(), kind, params).map_err(flag_error)?;
        let spec = PipelineSpec::from_stages(
            &format!("annotrace-{}", kind.name),
            PathBuf::from("."),
            0,
            vec![def],
        )
        .map_err(flag_error)?;
        let opts = RunOptions {
            run_dir: Some(self.run.to_path_buf()),
            force: self.force.then(|| self.id.clone()),
            fault: fault_from_env()?,
            remove_new_run_on_failure: self.remove_new_run_on_failure,
            ..RunOptions::default()
        };
        let report = run_pipeline(&spec, &opts, &Terminal::new(quiet)).map_err(run_error)?;
        report.stages.into_iter().next().ok_or_else(|| {
            CliError::new(
                ErrorCategory::Internal,
                anyhow::anyhow!("internal error: the stage did not run"),
            )
        })
    }
}

/// The stage's typed summary (the struct its kind writes into the report). One that does not read
/// back is a bug of annotrace, exit 70.
pub(crate) fn summary<T: serde::de::DeserializeOwned>(
    stage: &StageReport,
    kind: &str,
) -> Result<T, CliError> {
    serde_json::from_value(stage.summary.clone()).map_err(|e| {
        CliError::new(
            ErrorCategory::Internal,
            anyhow::anyhow!("internal error: {kind} summary: {e}"),
        )
    })
}

/// `<kind>-<10 hex digits>` of the canonical parameters: the same command gives the same stage (a
/// rerun is a no-op, an interrupted one resumes), another command another stage.
pub(crate) fn params_id<P: StageParams>(kind: &str, params: &P) -> String {
    let key = serde_json::to_string(params).unwrap_or_default();
    format!("{kind}-{}", &sha256_hex(key.as_bytes())[..10])
}

/// A path as an absolute string (the stage resolves paths against the working folder anyway; absolute
/// ones make the stage id independent of where the command runs).
pub(crate) fn absolute(p: &Path) -> Result<String, CliError> {
    Ok(std::path::absolute(p)
        .with_context(|| format!("resolving {}", p.display()))
        .map_err(CliError::input)?
        .to_string_lossy()
        .into_owned())
}

/// Fails (exit 2) when the run folder does not exist.
pub(crate) fn existing_run(run: &Path) -> Result<(), CliError> {
    super::location::check_exists(run)
}

/// A validation error of the one-stage pipeline, worded for the command line: the internal file, line
/// and stage id are dropped and the parameter is named as its flag (`` `game`: unknown … `` →
/// `--game: unknown …`).
fn flag_error(e: SpecError) -> CliError {
    let SpecError::Invalid { message, .. } = &e else {
        return CliError::input(e);
    };
    let rest = match message.strip_prefix("stage \"") {
        Some(r) => r.split_once("\": ").map_or(message.as_str(), |(_, m)| m),
        None => message.as_str(),
    };
    let text = match rest.strip_prefix('`').and_then(|r| r.split_once("`: ")) {
        Some((key, m)) => format!("--{}: {m}", key.replace('_', "-")),
        None => rest.to_string(),
    };
    CliError::input(anyhow::anyhow!("{text}"))
}

/// The value of `--<flag>` as the parameter enum it names, in the kebab-case the stage parameters
/// use (`--agent search`); an unknown value is an input error naming the flag and the accepted
/// values.
pub(crate) fn kebab<T: serde::de::DeserializeOwned>(flag: &str, v: &str) -> Result<T, CliError> {
    serde_json::from_value(serde_json::Value::String(v.to_string()))
        .map_err(|e| CliError::input(anyhow::anyhow!("--{flag}: {e}")))
}
