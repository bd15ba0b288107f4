//! What every stage that runs detectors shares: the sandbox parameters (`env`, `library`, `workers`,
//! `timeout`, `memory_mb`), the library they load, and the worker pool they start.
//!
//! **Owns:** [`SandboxParams`] (flattened into the parameter structs of `annotate`, `accuracy`, `evolve`
//! and `optimise`) and `DetectorSetup`. **Does not:** run detectors (`detect::WorkerPool`) or write
//! tables (each stage does, through [`StageContext::write_batch`](crate::pipeline::StageContext)).

use std::path::Path;
use std::time::Duration;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::builtin::Location;
use crate::detect::{HelperSharing, Library, SandboxLimits, WorkerPool};
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
    /// Library folder, relative to the project folder (default: the project's `data/libraries/<env>`
    /// when it has one, else the built-in library).
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
        let dir = match &p.library {
            Some(l) => Location::library(&spec.project_dir, Path::new(l)),
            None => Location::default_library(&spec.project_dir, env),
        };
        let library =
            Library::open(&dir).map_err(|e| BuildError::param("library", e.to_string()))?;
        if library.env != env {
            return Err(BuildError::param(
                "library",
                format!("library {dir} is for {}, not {env}", library.env),
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

    /// Starts the worker pool. Every stage that takes its detectors from a `DetectorSetup` runs
    /// each trace once, with all the detectors it needs in one call (`annotate`, `accuracy`,
    /// `summarise`, `benchmark`, `optimise`, `synthesise`, `suggest_labels`), so its workers keep no
    /// trace after its run (`SandboxLimits::trace_cache` 0) and each is freed while it is still in
    /// the CPU's caches. The stages that run many detectors over the same traces in turn (`evolve`,
    /// `ensemble`) start their own pools with a cache that holds their trace sets. The detectors of
    /// a run request share their helpers' results (`HelperSharing::Measured`): these stages use the
    /// patterns, not a call's own time.
    pub(crate) fn pool(&self) -> Result<WorkerPool, StageError> {
        WorkerPool::new(SandboxLimits {
            trace_cache: 0,
            share_helpers: HelperSharing::Measured,
            ..self.limits.clone()
        })
        .map_err(StageError::Workers)
    }
}
