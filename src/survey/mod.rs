//! The survey kit (the paper's appendix D): a static page on which people rate summaries of rollouts on
//! a 1–7 Likert scale, each rollout shown as an animation beside ONE summary, the condition (which
//! summariser wrote it) and the order of items shuffled per participant with a seed; the answers are
//! kept in the browser and exported as CSV, which `import-survey` checks and turns into a table.
//!
//! **Owns:** the animation of a rollout (`video`: frames from the environments' renderers, the
//! colours of `annotrace render` and the report; `apng`: the APNG encoding), the per-participant
//! shuffle ([`assignment`], computed identically by the page's JavaScript), the page folder (`site`,
//! swapped in whole like the report's) with its hand-written HTML/CSS/JS (`assets/`), and the
//! `survey_items` and `survey_responses` tables with the response CSV ([`responses`]).
//! **Does not:** read or write run folders or choose traces (the `survey` and `import-survey` stages
//! do), or write summaries (`crate::summary`).

mod apng;
mod assign;
pub mod responses;
mod site;
mod video;

use std::path::PathBuf;

pub use apng::{Animation, ApngError};
pub use assign::{MAX_PARTICIPANT, Shown, assignment, fnv1a64, valid_participant};
pub use responses::{
    CSV_COLUMNS, Design, Item, Response, SURVEY_ITEMS, SURVEY_RESPONSES, SummaryRef, Survey,
    parse_csv,
};
pub use site::{PageText, SurveyWriter, survey_id};
pub use video::{VideoOptions, Videos, frame_times};

/// The page's script (part of the `survey` stage's fingerprint: a new page rewrites surveys).
pub const SURVEY_JS: &str = include_str!("assets/survey.js");

/// Making a survey or reading its answers failed.
#[derive(Debug, thiserror::Error)]
pub enum SurveyError {
    /// A trace could not be drawn.
    #[error("trace {trace}: {source}")]
    Render {
        /// The trace.
        trace: String,
        /// The renderer's error.
        #[source]
        source: crate::envs::EnvError,
    },
    /// An animation could not be encoded.
    #[error(transparent)]
    Apng(#[from] ApngError),
    /// A file or folder could not be read or written.
    #[error("{}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A response CSV is malformed or does not match its survey.
    #[error("{}:{line}: {}{message}", file.display(), field.map(|f| format!("field `{f}`: ")).unwrap_or_default())]
    Csv {
        /// The file.
        file: PathBuf,
        /// Its line (1-based, the header is 1).
        line: u64,
        /// The column at fault, when one is.
        field: Option<&'static str>,
        /// What is wrong and what was expected.
        message: String,
    },
    /// The run's `survey_items` table is damaged.
    #[error("{}: {message}", path.display())]
    Items {
        /// The table file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The target is not a folder path (`/`, `..`).
    #[error("{}: not a usable survey folder", .0.display())]
    Target(PathBuf),
    /// An annotrace bug.
    #[error("internal error, please report it: {0}")]
    Internal(String),
}

impl From<crate::report::ReportError> for SurveyError {
    fn from(e: crate::report::ReportError) -> Self {
        match e {
            crate::report::ReportError::Io { path, source } => SurveyError::Io { path, source },
            crate::report::ReportError::Target(p) => SurveyError::Target(p),
            other => SurveyError::Internal(other.to_string()),
        }
    }
}
