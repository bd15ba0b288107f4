//! The report: a static web site of a run's traces that opens from the file system with no server.
//!
//! `report/index.html` lists the traces (filters by environment, outcome and label, and a small
//! SQL-like `WHERE` over the list's columns); choosing one loads its script and shows the **trace
//! player** (the scene on a canvas in the colours of `annotrace render`, play/pause/scrub/speed, object
//! ids on hover), the **pattern timeline** beneath it (a section per library, one row per label, bars
//! for annotations, the ground truth and the simulator's events as ticks; a shared playhead; clicking a
//! bar seeks the player; hovering one highlights its objects in the scene), and the annotated trace
//! exactly as `annotrace show` prints it, with its token estimate. Two libraries can be chosen to be
//! shown one above the other on the same time axis.
//!
//! **Owns:** the scene geometry for the canvas (`scene`), the per-trace payload (`payload`), writing
//! the folder atomically (`site`) and the page's hand-written HTML, CSS and JavaScript (`assets/`, no
//! framework, no third-party code). **Does not:** read run folders or choose traces (the `report` stage
//! does), simulate, or run detectors.

mod payload;
pub mod scene;
mod site;

use std::path::PathBuf;

pub use payload::{LibraryAnnotations, TracePayload, TraceViews, index_row, trace_payload};
pub use scene::{Scene, SceneError, SceneObject, scene};
pub(crate) use site::swap_in;
pub use site::{SiteWriter, trace_file};

/// The page's script (part of the `report` stage's fingerprint: a new viewer rewrites reports).
pub const VIEWER_JS: &str = include_str!("assets/viewer.js");

/// Writing a report failed.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file or folder of the report could not be written.
    #[error("{}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The target is not a folder path (`/`, `..`).
    #[error("{}: not a usable report folder", .0.display())]
    Target(PathBuf),
    /// A trace cannot be drawn.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// Serialising the payload failed (an annotrace bug).
    #[error("internal error, please report it: {0}")]
    Internal(String),
}
