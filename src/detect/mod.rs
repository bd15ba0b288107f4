//! The detector runtime: sandboxed Python workers that run detector programs over traces.
//!
//! A **detector** ([`Detector`]) is Python source defining `find_pattern(trace)`, which returns a list of
//! patterns `{label, start_timestep, end_timestep, parameters: {object_details: {...}}, provenance?,
//! metadata?}` (the paper's contract). Detectors are written by people and, mostly, by LLMs, so they run
//! in a [`WorkerPool`] of long-lived, sandboxed CPython processes (layers in [`SandboxLimits`]' module
//! docs), and every output is checked in Rust ([`validate`]). A failing detector is data
//! ([`CandidateStatus`], [`DetectorError`] with line, column or JSON path), never an `Err` of the batch.
//!
//! **Owns:** the worker processes and their protocol, the sandbox limits, output validation, library
//! folders ([`Library`]), annotations and the N×J annotation matrix ([`AnnotationMatrix`]), and the Arrow
//! schemas of the `detectors`, `detector_calls` and `annotations` tables ([`tables`]), and annotated
//! traces as text for language models with a token estimate ([`annotated_text`], [`count_tokens`]).
//! **Does not:** write tables to a run (the `annotate` stage does; [`tables::read_annotations`] reads
//! them back through `store/`), choose detectors (`search/`) or score them (`fitness/`).
//!
//! Entry point: [`WorkerPool::new`] then [`WorkerPool::run`]`(&detectors, &traces)`.

pub mod accuracy;
mod annotation;
mod detector;
mod error;
mod library;
mod marshal;
mod pool;
pub(crate) mod protocol;
mod sandbox;
pub mod tables;
mod text;
mod validate;
mod worker;

pub use self::annotation::{Annotation, AnnotationMatrix, by_trace};
pub use self::detector::{Detector, DetectorId, EnsembleSettings, Membership, normalise_label};
pub use self::error::{CandidateStatus, DetectError, DetectorError};
pub use self::library::{Library, LibraryError};
pub use self::pool::{BatchResult, CallResult, RunStats, WorkerPool};
pub use self::sandbox::{HelperSharing, SandboxLayers, SandboxLimits, set_default_python};
pub use self::text::{annotated_text, count_tokens};
pub use self::validate::{Pattern, validate};

/// A hash of the worker's source, so that stages rerun when the sandbox changes.
pub fn worker_fingerprint() -> String {
    use sha2::{Digest, Sha256};
    crate::digest::hex(&Sha256::digest(worker::WORKER_PY.as_bytes())[..8])
}
