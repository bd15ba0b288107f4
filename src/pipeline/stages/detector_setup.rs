//! What every stage that runs detectors shares: the sandbox parameters (`env`, `library`, `workers`,
//! `timeout`, `memory_mb`), the library they load, and the worker pool they start.
//!
//! **Owns:** [`SandboxParams`] (flattened into the parameter structs of `annotate`, `accuracy`, `evolve`
//! and `optimise`) and [`DetectorSetup`]. **Does not:** run detectors (`detect::WorkerPool`) or write
//! tables (each stage does, through [`StageContext::write_batch`](crate::pipeline::StageContext)).

use std::path::{Path, PathBuf};
use std::time::Duration;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::detect::{Library, SandboxLimits, WorkerPool};
use crate::pipeline::registry::BuildError;
use crate::pipeline::spec::PipelineSpec;
use crate::pipeline::stage::StageError;
use crate::trace::Env;

/// The parameters of a stage that runs detectors in the sandboxed worker pool.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct SandboxParams {
    /// Environment whose traces are used.
    pub env: Env,
    /// Library folder, relative to the project folder (default: data/libraries/<env>).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub library: Option<String>,
    /// Python worker processes (0 = one per core).
    pub workers: u64,
    /// Wall-clock limit of one detector call (s); a call past it is killed and marked timeout.
    pub timeout: f64,
    /// Address-space limit of a worker (MiB); a call past it is marked memory.
    pub memory_mb: u64,
}

impl SandboxParams {
    /// The defaults.
    pub const DEFAULT: SandboxParams = SandboxParams {
        env: Env::Pooltool,
        library: None,
        workers: 0,
        timeout: 10.0,
        memory_mb: 2048,
    };
}

impl Default for SandboxParams {
    fn default() -> Self {
        SandboxParams::DEFAULT
    }
}

/// The library and sandbox settings of a stage that runs detectors.
#[derive(Debug)]
pub(crate) struct DetectorSetup {
    pub env: Env,
    pub library: Library,
    pub limits: SandboxLimits,
}

impl DetectorSetup {
    /// Loads the library and checks the limits.
    pub(crate) fn new(p: &SandboxParams, spec: &PipelineSpec) -> Result<Self, BuildError> {
        let env = p.env;
        let dir: PathBuf = match &p.library {
            Some(l) => spec.project_dir.join(l),
            None => default_library_dir(&spec.project_dir, env),
        };
        let library =
            Library::load(&dir).map_err(|e| BuildError::param("library", e.to_string()))?;
        if library.env != env {
            return Err(BuildError::param(
                "library",
                format!(
                    "library {} is for {}, not {env}",
                    dir.display(),
                    library.env
                ),
            ));
        }
        if !(p.timeout > 0.0 && p.timeout.is_finite()) {
            return Err(BuildError::param(
                "timeout",
                format!("timeout must be > 0, found {}", p.timeout),
            ));
        }
        let mut limits = SandboxLimits::default();
        if p.workers > 0 {
            limits.workers = p.workers as usize;
        }
        limits.call_timeout = Duration::from_secs_f64(p.timeout);
        limits.memory_bytes = p.memory_mb.clamp(64, 1 << 40) << 20;
        Ok(DetectorSetup {
            env,
            library,
            limits,
        })
    }

    /// Starts the worker pool.
    pub(crate) fn pool(&self) -> Result<WorkerPool, StageError> {
        WorkerPool::new(self.limits.clone()).map_err(StageError::Workers)
    }
}

/// `data/libraries/<env>` under the project folder, or the crate's own copy when the project has none.
pub(crate) fn default_library_dir(project: &Path, env: Env) -> PathBuf {
    let local = project.join("data/libraries").join(env.as_str());
    if local.join("library.toml").is_file() {
        local
    } else {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("data/libraries")
            .join(env.as_str())
    }
}
