//! The paper's per-environment JSON trace format: streaming import with precise errors, and export.
//!
//! **Owns:** reading traces from `.json` (one trace or an array) and `.jsonl` files into the model, the
//! validation rules of `docs/trace-format.md`, and writing a [`Trace`](super::Trace) back in the same
//! layout. **Does not:** touch Parquet or the run directory (`store/`, `pipeline/`).
//!
//! ```
//! use annotrace::trace::{json, Env};
//! let text = r#"{"environment": "phyre", "task_id": "00000:000", "timesteps": [],
//!                "events": [], "outcome": {"success": false, "terminal_status": "INVALID_INPUT"}}"#;
//! let traces = json::read_str("example", text, Env::Phyre);
//! let trace = traces[0].as_ref().unwrap();
//! assert_eq!(trace.task_id, "00000:000");
//! let back = json::to_value(trace);
//! assert_eq!(back["outcome"]["terminal_status"], "INVALID_INPUT");
//! ```

mod error;
mod fields;
mod read;
mod write;

pub use error::{Fault, FaultKind, TraceError, TraceLocation};
pub use read::{
    SourceError, SourceKind, TraceConsumer, TraceHeader, default_trace_id, expand_paths,
    read_bytes, read_file, read_path, read_str,
};
pub use write::{
    PaperTrace, timestep_to_value, to_value, write_steps_sharing_repeats, write_trace,
    write_trace_shell,
};
