//! Summaries of annotated traces in natural language, what they cost, and the identification task.
//!
//! **Owns:** the summarisers ([`Summariser`]: [`OfflineSummariser`], a deterministic account written
//! from the annotations with no model; [`LlmSummariser`] in two modes, `frames` — keyframes of the
//! rollout only, the DeepPHY-style baseline — and `annotations` — the initial image plus the annotated
//! trace text, the paper's), the images of a stored trace ([`TraceImages`]), the identification task
//! ([`identification_accuracy`], [`identify`]: a chooser is shown a trace and 8 summaries, one of them
//! the trace's own, and picks one; its accuracy is the objective the ensemble calibration maximises)
//! with its choosers ([`OfflineChooser`], a clearly labelled annotation-overlap baseline, and
//! [`LlmChooser`], images as image content parts), and the `summaries` and `identification` tables
//! ([`table`]), the identification task as the ensemble calibration's objective
//! ([`IdentificationObjective`]), and pattern labels suggested from example traces ([`labels`]: an LLM
//! shown initial images and annotated traces, with strict parsing and repair, or a deterministic offline
//! baseline).
//!
//! **Does not:** run detectors (callers pass the annotations, from the worker pool or the
//! `annotations` table), read the process environment (callers build the [`crate::llm::LlmClient`]),
//! or write run folders (the `summarise` stage does, `pipeline::stages::summarise`).
//!
//! ```
//! use annotrace::summary::{IdentifyParams, OfflineChooser, OfflineSummariser, identification_accuracy};
//! # fn traces() -> (Vec<annotrace::trace::Trace>, Vec<annotrace::detect::Annotation>) { (vec![], vec![]) }
//! let (traces, annotations) = traces();
//! let params = IdentifyParams { options: 8, seed: 7 };
//! // Fewer traces than options is an error, not a silent easier task.
//! assert!(identification_accuracy(&traces, &annotations, &OfflineSummariser, &OfflineChooser, &params).is_err());
//! ```

mod choose;
mod error;
mod identify;
mod images;
pub mod labels;
mod llm;
mod objective;
mod offline;
pub mod table;

pub use self::choose::{Choice, Chooser, LlmChooser, OfflineChooser, TrialView, parse_choice};
pub use self::error::SummaryError;
pub use self::identify::{
    Identification, IdentifyParams, Trial, check as check_trials, identification_accuracy,
    identify, options_for, trial as identify_trial,
};
pub use self::images::TraceImages;
pub use self::labels::{
    LabelAsk, LabelsError, LlmLabeller, ProposedLabel, Suggested, offline_labels,
};
pub use self::llm::{LlmMode, LlmSummariser, TEMPLATES, add_templates};
pub use self::objective::IdentificationObjective;
pub use self::offline::{OfflineSummariser, offline_summary};

use crate::detect::Annotation;
use crate::trace::Trace;

/// One summary and what it cost.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// The summary text.
    pub text: String,
    /// Prompt tokens (the server's count; for the offline summariser, the estimated tokens of the
    /// annotated text it read).
    pub tokens_in: u64,
    /// Completion tokens (the server's count; offline, the estimated tokens of the text).
    pub tokens_out: u64,
    /// True when the counts are `detect::count_tokens` estimates.
    pub usage_estimated: bool,
    /// Seconds it took (the model's latency, or the offline summariser's wall time).
    pub seconds: f64,
    /// Images sent.
    pub images: u64,
    /// The `llm_calls` call id (empty offline).
    pub call_id: String,
}

/// Something that writes a summary of an annotated trace.
pub trait Summariser: Sync {
    /// Its name in the `summaries` table (`offline`, `frames`, `annotations`).
    fn name(&self) -> &str;
    /// The model behind it (empty offline).
    fn model(&self) -> String;
    /// A summary of `trace`; `annotations` are its annotations (other traces' rows are ignored).
    fn summarise(&self, trace: &Trace, annotations: &[Annotation])
    -> Result<Summary, SummaryError>;
}
