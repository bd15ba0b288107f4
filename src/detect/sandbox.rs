//! The sandbox of a detector worker: its limits ([`SandboxLimits`]), how the process is started
//! (scrubbed environment, resource limits set between `fork` and `exec`) and which layers ended up
//! active ([`SandboxLayers`]).
//!
//! Layers, outermost first; each is tested by a hostile detector in `tests/it/sandbox.rs`:
//! 1. **Process**: the interpreter is resolved once to its real executable (no shell shims), started
//!    with `-s -S -B` and an empty environment plus `PYTHONHASHSEED=0` and `LC_ALL=C.UTF-8`; the
//!    worker's first statement drops the working folder from `sys.path`, which is what CPython 3.11's
//!    `-P` does, for every interpreter (PyPy has no `-P`). (`-I` would also ignore `PYTHONHASHSEED`;
//!    with the environment emptied by us, `-s` and that first statement give the rest of `-I`, and a
//!    fixed hash seed makes set iteration, and so detector output, reproducible.) Working folder `/`;
//!    the worker dies with its parent (`PR_SET_PDEATHSIG`).
//! 2. **Resource limits** (`setrlimit` before `exec`): address space, file size 0, no core files,
//!    few file descriptors, no new processes (not enforced by Linux for root; seccomp covers it), and
//!    CPU seconds, which the worker re-arms before every call.
//! 3. **Landlock** (in the worker, after its imports): a ruleset that handles every file-system right,
//!    TCP bind/connect and signal/abstract-socket scoping, with no rule granting any: no file can be
//!    opened, listed or created.
//! 4. **seccomp-BPF** (in the worker, after Landlock): sockets, exec, fork/vfork/non-thread clone,
//!    every `open*`, file-system changes, ptrace, mount, namespaces, io_uring, bpf fail with `EPERM`.
//! 5. **Python**: the source is parsed and refused if it imports, defines classes, touches an attribute
//!    starting with `_` or a frame/code attribute, or names `eval`, `exec`, `open`, `getattr`, `type`,
//!    `globals`…; it runs with a reduced builtins dict (`print` goes to a bounded buffer) on a read-only
//!    trace.
//! 6. **Rust**: a wall-clock timer per call kills the worker; output is size-bounded and validated.

use std::path::PathBuf;
use std::process::Command;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::error::DetectError;

/// The knobs of the sandbox, with defaults for annotating and evolving on a shared 2-core machine.
#[derive(Clone, Debug, PartialEq)]
pub struct SandboxLimits {
    /// Worker processes. Default: the number of cores (`std::thread::available_parallelism`).
    pub workers: usize,
    /// The Python interpreter (a path, or a name looked up on the `PATH`), resolved once to its real
    /// executable (`sys.executable`) so that shims (pyenv) do not run inside the sandbox. Default:
    /// the process-wide interpreter set by [`set_default_python`] (the command line's
    /// `ANNOTRACE_PYTHON`), else `None`, meaning `python3` on the `PATH`. CPython 3.8+ and PyPy 3.9+
    /// run the worker unchanged, with the same sandbox layers (`docs/detectors.md`).
    pub python: Option<PathBuf>,
    /// Wall-clock limit of one call (compiling or running a detector on one trace). Default 10 s: the
    /// paper's detectors take milliseconds per trace; a call past this is an infinite loop.
    pub call_timeout: Duration,
    /// Address-space limit of a worker (`RLIMIT_AS`, bytes). Default 2 GiB: the interpreter (~30 MB),
    /// `trace_cache` cached traces (~10 MB each for a 500-step, 10-ball pool trace) and a detector's
    /// working memory.
    pub memory_bytes: u64,
    /// Open file descriptors (`RLIMIT_NOFILE`). Default 16: the worker needs its three pipes.
    pub max_open_files: u64,
    /// Traces a worker keeps loaded (least recently used is evicted first). Default 16. With 0 a
    /// worker keeps none: each trace is freed right after its detectors have run, while the worker's
    /// CPU caches still hold it (half the cost of freeing it traces later, measured in
    /// `docs/performance.md`, "The workers' floor, replayed"); for callers that run every trace once
    /// with all its detectors, as every stage with a `DetectorSetup` does (`annotate`, `summarise`,
    /// `optimise`, …).
    pub trace_cache: usize,
    /// Most patterns one call may return. Default 10 000.
    pub max_patterns: usize,
    /// Largest output of one call, as JSON (bytes). Default 4 MiB.
    pub max_output_bytes: usize,
    /// Python recursion limit in the worker. Default 2000.
    pub recursion_limit: u32,
    /// Apply the OS layers (Landlock, seccomp). Default true.
    pub os_layers: bool,
    /// Apply the Landlock layer (when `os_layers`). Default true; off only to test seccomp alone.
    pub landlock: bool,
    /// Apply the seccomp layer (when `os_layers`). Default true; off only to test Landlock alone.
    pub seccomp: bool,
    /// Refuse to start when seccomp is unavailable. Default false (then `layers()` says what is active).
    pub require_seccomp: bool,
    /// The Python layer (source check, reduced builtins). Default true. Turn it off only to test the OS
    /// layers on their own, as `tests/it/sandbox.rs` does.
    pub python_guard: bool,
    /// Whether the detectors of one run request share their helpers' results. Default
    /// [`HelperSharing::Off`]. On for the stages that run each trace once with all their detectors
    /// (`DetectorSetup`) and for `ensemble`; off where a call's own time is a measurement
    /// (`evolve`'s time penalty, the search).
    pub share_helpers: HelperSharing,
}

/// Whether the detectors of one run request share their helpers' results (`docs/detectors.md`,
/// "Shared helper results"). A prelude helper that every detector of a library carries
/// (`_contacts(trace)`, `_kin(trace)`) and whose result can depend on nothing but its arguments is
/// then computed once per trace, and each detector gets its own copy of the result. The patterns are
/// the same either way; a call's CPU time no longer counts what another call computed for it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HelperSharing {
    /// Every detector computes its own helpers.
    #[default]
    Off,
    /// Helpers that can be shared are, while sharing pays: after its first three results, a helper
    /// that took under 20 µs to compute on average, or whose results took more than 0.8 of that time
    /// to copy, is called by every detector again, and a detector that has called a helper 100
    /// times in ways that cannot be shared calls it directly.
    Measured,
    /// Every helper that can be shared is, whatever it costs (the tests hold sharing to the same
    /// output with it).
    Always,
}

impl HelperSharing {
    /// The worker's spelling (`off`, `measured`, `always`).
    pub fn as_str(self) -> &'static str {
        match self {
            HelperSharing::Off => "off",
            HelperSharing::Measured => "measured",
            HelperSharing::Always => "always",
        }
    }
}

impl Default for SandboxLimits {
    fn default() -> Self {
        SandboxLimits {
            workers: std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1),
            python: DEFAULT_PYTHON.get().cloned(),
            call_timeout: Duration::from_secs(10),
            memory_bytes: 2 << 30,
            max_open_files: 16,
            trace_cache: 16,
            max_patterns: 10_000,
            max_output_bytes: 4 << 20,
            recursion_limit: 2000,
            os_layers: true,
            landlock: true,
            seccomp: true,
            require_seccomp: false,
            python_guard: true,
            share_helpers: HelperSharing::Off,
        }
    }
}

/// The layers a worker reported active (all workers of a pool have the same).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SandboxLayers {
    /// The interpreter's version.
    pub python: String,
    /// Resource limits applied before `exec` (always, on Unix).
    pub rlimits: bool,
    /// `PR_SET_NO_NEW_PRIVS` set.
    pub no_new_privs: bool,
    /// Landlock ABI version in force (`abi7`), or `unavailable`.
    pub landlock: String,
    /// `filter` when the seccomp-BPF filter is in force, or `unavailable`.
    pub seccomp: String,
    /// The Python source check and reduced builtins.
    pub python_guard: bool,
}

impl SandboxLayers {
    /// One line: `rlimits, no_new_privs, landlock abi7, seccomp filter, python guard (Python 3.11.7)`.
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        if self.rlimits {
            parts.push("rlimits".to_string());
        }
        if self.no_new_privs {
            parts.push("no_new_privs".to_string());
        }
        parts.push(format!("landlock {}", self.landlock));
        parts.push(format!("seccomp {}", self.seccomp));
        if self.python_guard {
            parts.push("python guard".to_string());
        }
        format!("{} (Python {})", parts.join(", "), self.python)
    }
}

/// The interpreter [`SandboxLimits::default`] uses, set once per process (the command line sets it
/// from `ANNOTRACE_PYTHON`).
static DEFAULT_PYTHON: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();

/// Sets the interpreter every later [`SandboxLimits::default`] names (a path, or a name such as
/// `pypy3` looked up on the `PATH`). A machine setting, like which `python3` is on the `PATH`: it is
/// not part of any stage's fingerprint, since the worker's output does not depend on it. Only the
/// first call counts; returns whether this one did.
pub fn set_default_python(python: PathBuf) -> bool {
    DEFAULT_PYTHON.set(python).is_ok()
}

/// Resolves the interpreter: the configured one (else `python3` on the `PATH`) asked for its real
/// executable.
pub(crate) fn resolve_python(limits: &SandboxLimits) -> Result<PathBuf, DetectError> {
    let program = limits
        .python
        .clone()
        .unwrap_or_else(|| PathBuf::from("python3"));
    let tried = match &limits.python {
        Some(p) => p.display().to_string(),
        None => "python3 on the PATH".into(),
    };
    let out = Command::new(&program)
        .args(["-c", "import sys; print(sys.executable)"])
        .output()
        .map_err(|e| DetectError::NoPython {
            tried: tried.clone(),
            message: e.to_string(),
        })?;
    let path = String::from_utf8_lossy(&out.stdout).trim().to_string();
    if !out.status.success() || path.is_empty() {
        return Err(DetectError::NoPython {
            tried,
            message: String::from_utf8_lossy(&out.stderr).into_owned(),
        });
    }
    Ok(PathBuf::from(path))
}

/// The worker's command line and environment, with resource limits applied in the child before
/// `exec`.
pub(crate) fn worker_command(python: &PathBuf, limits: &SandboxLimits, script: &str) -> Command {
    let config = serde_json::json!({
        "max_patterns": limits.max_patterns,
        "max_output_bytes": limits.max_output_bytes,
        "python_guard": limits.python_guard,
        "os_layers": limits.os_layers,
        "landlock": limits.landlock,
        "seccomp": limits.seccomp,
        "recursion_limit": limits.recursion_limit,
        "cpu_seconds": limits.call_timeout.as_secs_f64().ceil() + 1.0,
        "share_helpers": limits.share_helpers.as_str(),
    });
    let mut cmd = Command::new(python);
    // No `-P` (CPython 3.11+ only; PyPy 3.9 refuses it): the worker drops the working folder's entry
    // from `sys.path` as its first statement, which is what `-P` does.
    cmd.args(["-s", "-S", "-B", "-c", script])
        .arg(config.to_string())
        .env_clear()
        .env("PYTHONHASHSEED", "0")
        .env("LC_ALL", "C.UTF-8")
        .current_dir("/");
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        let memory = limits.memory_bytes;
        let files = limits.max_open_files;
        let cpu = limits.call_timeout.as_secs() + 1;
        // SAFETY: the closure runs in the forked child before exec and only calls async-signal-safe
        // functions (setrlimit, prctl), with no allocation.
        unsafe {
            cmd.pre_exec(move || {
                set_limit(libc::RLIMIT_AS, memory, memory)?;
                set_limit(libc::RLIMIT_FSIZE, 0, 0)?;
                set_limit(libc::RLIMIT_CORE, 0, 0)?;
                set_limit(libc::RLIMIT_NOFILE, files, files)?;
                set_limit(libc::RLIMIT_NPROC, 0, 0)?;
                set_limit(libc::RLIMIT_CPU, cpu, libc::RLIM_INFINITY)?;
                #[cfg(target_os = "linux")]
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL, 0, 0, 0);
                Ok(())
            });
        }
    }
    cmd
}

#[cfg(unix)]
fn set_limit(resource: libc::__rlimit_resource_t, soft: u64, hard: u64) -> std::io::Result<()> {
    let lim = libc::rlimit {
        rlim_cur: soft as libc::rlim_t,
        rlim_max: hard as libc::rlim_t,
    };
    // SAFETY: setrlimit reads the struct we pass.
    if unsafe { libc::setrlimit(resource, &lim) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}
