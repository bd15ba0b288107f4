//! What the commands that start detector workers share on the command line: the worker limits
//! (`--workers`, `--timeout`, `--memory-mb`, flattened into each command's arguments with their one
//! set of defaults, [`SandboxParams::DEFAULT`]) and [`kebab`], which reads a flag's kebab-case value
//! into a stage's parameter enum.
//!
//! **Owns:** [`WorkerArgs`], [`kebab`]. **Does not:** choose the library or the run (each command's
//! own flags) or start workers (the stages do, `pipeline::stages::detector_setup`).

use annotrace::pipeline::stages::detector_setup::SandboxParams;

use super::CliError;

const D: SandboxParams = SandboxParams::DEFAULT;

/// The limits of the sandboxed detector workers.
#[derive(clap::Args, Debug, Clone)]
pub(crate) struct WorkerArgs {
    /// Python worker processes (0 = one per core).
    #[arg(long, default_value_t = D.workers)]
    pub workers: u64,
    /// Wall-clock limit of one detector call (s).
    #[arg(long, default_value_t = D.timeout)]
    pub timeout: f64,
    /// Address-space limit of a worker (MiB).
    #[arg(long, default_value_t = D.memory_mb)]
    pub memory_mb: u64,
}

/// The value of `--<flag>` as the parameter enum it names, in the kebab-case the stage parameters
/// use (`--agent search`); an unknown value is an input error naming the flag and the accepted
/// values.
pub(crate) fn kebab<T: serde::de::DeserializeOwned>(flag: &str, v: &str) -> Result<T, CliError> {
    serde_json::from_value(serde_json::Value::String(v.to_string()))
        .map_err(|e| CliError::input(anyhow::anyhow!("--{flag}: {e}")))
}
