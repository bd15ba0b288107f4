//! Why a trace was rejected, and where: the file, the trace within it, the JSON path and the category.

use std::fmt;
use std::path::PathBuf;

/// Where a trace sits in its source.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TraceLocation {
    /// The file it was read from.
    pub file: PathBuf,
    /// 0-based position of the trace in the file (line order for JSON Lines, element order for an array).
    pub ordinal: usize,
    /// 1-based line of the trace in a JSON Lines file.
    pub line: Option<usize>,
    /// Whether the file holds an array of traces.
    pub in_array: bool,
}

impl fmt::Display for TraceLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{line}", self.file.display()),
            None => write!(f, "{} (trace #{})", self.file.display(), self.ordinal),
        }
    }
}

/// The category of a fault, stable for tests and the rejected-traces table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaultKind {
    /// Not JSON.
    Syntax,
    /// A value of the wrong JSON type.
    Type,
    /// A required field is absent.
    Missing,
    /// NaN, Infinity or a number out of the f64 range.
    NonFinite,
    /// Two objects with the same id in one timestep.
    DuplicateObject,
    /// `index` or `t` does not increase.
    Order,
    /// `environment` contradicts the environment being imported.
    EnvMismatch,
    /// A field given twice in one object.
    DuplicateField,
    /// The trace id is already taken in the run or the import.
    DuplicateTrace,
}

impl FaultKind {
    /// The category's name in tables and messages.
    pub fn as_str(self) -> &'static str {
        match self {
            FaultKind::Syntax => "syntax",
            FaultKind::Type => "type",
            FaultKind::Missing => "missing",
            FaultKind::NonFinite => "non_finite",
            FaultKind::DuplicateObject => "duplicate_object",
            FaultKind::Order => "order",
            FaultKind::EnvMismatch => "env_mismatch",
            FaultKind::DuplicateField => "duplicate_field",
            FaultKind::DuplicateTrace => "duplicate_trace",
        }
    }
}

/// A fault inside one trace, before it is tied to a file.
#[derive(Clone, Debug, PartialEq)]
pub struct Fault {
    /// JSON path of the faulty value, from the trace's root `$`.
    pub path: String,
    /// Category.
    pub kind: FaultKind,
    /// What was expected and what was found.
    pub message: String,
    /// 1-based line and column in the file, when the JSON parser knows them.
    pub line_col: Option<(usize, usize)>,
}

impl Fault {
    /// A fault at `path`.
    pub fn new(path: impl Into<String>, kind: FaultKind, message: impl Into<String>) -> Self {
        Fault {
            path: path.into(),
            kind,
            message: message.into(),
            line_col: None,
        }
    }
}

/// A rejected trace: its location, its task id when it was read, and the fault.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub struct TraceError {
    /// Where the trace is.
    pub location: TraceLocation,
    /// The trace's `task_id`, when it was read before the fault.
    pub task_id: Option<String>,
    /// What is wrong.
    pub fault: Fault,
}

impl fmt::Display for TraceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.location.line, self.fault.line_col) {
            (_, Some((line, col))) => write!(f, "{}:{line}:{col}", self.location.file.display())?,
            (Some(line), None) => write!(f, "{}:{line}", self.location.file.display())?,
            (None, None) => write!(f, "{}", self.location.file.display())?,
        }
        write!(f, ": trace #{}", self.location.ordinal)?;
        if let Some(task) = &self.task_id {
            write!(f, " (task_id {task:?})")?;
        }
        write!(
            f,
            " at {}: {} [{}]",
            self.fault.path,
            self.fault.message,
            self.fault.kind.as_str()
        )
    }
}
