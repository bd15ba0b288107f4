//! What the commands that start detector workers share on the command line: the worker limits
//! (`--workers`, `--timeout`, `--memory-mb`, flattened into each command's arguments with their one
//! set of defaults, [`SandboxParams::DEFAULT`]).
//!
//! **Owns:** [`WorkerArgs`]. **Does not:** choose the library or the run (each command's own flags)
//! or start workers (the stages do, `pipeline::stages::detector_setup`).

use annotrace::pipeline::stages::detector_setup::SandboxParams;

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
