//! Errors of reward programs: every error carries a category, a 1-based line and column, and a message.

use std::fmt;

/// What kind of mistake a reward program makes (what a repair prompt and a test look at).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ErrorCategory {
    /// The text is not a well-formed expression (bad token, missing parenthesis, trailing input).
    Syntax,
    /// A call names a function the DSL does not have.
    UnknownFunction,
    /// A call has too few or too many arguments, or an unknown or repeated keyword.
    Arity,
    /// An argument has the wrong type (a number where a label is expected, a predicate where an event is).
    ArgumentType,
    /// A pattern label is not in the library (nor an alias of one).
    UnknownLabel,
    /// A parameter key no pattern of that label emits.
    UnknownParameter,
    /// Evaluation failed on a trace (no object of that colour and shape, a function the trace's
    /// environment does not support).
    Runtime,
}

impl ErrorCategory {
    /// The category's name in messages and tables (`syntax`, `unknown_function`, …).
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorCategory::Syntax => "syntax",
            ErrorCategory::UnknownFunction => "unknown_function",
            ErrorCategory::Arity => "arity",
            ErrorCategory::ArgumentType => "argument_type",
            ErrorCategory::UnknownLabel => "unknown_label",
            ErrorCategory::UnknownParameter => "unknown_parameter",
            ErrorCategory::Runtime => "runtime",
        }
    }
}

/// A position in the program text: 1-based line and column (columns count characters).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Pos {
    /// Line, from 1.
    pub line: u32,
    /// Column, from 1, in characters.
    pub col: u32,
    /// Byte offset into the text.
    pub offset: usize,
}

/// An error in a reward program, at a position.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct RewardError {
    /// What kind of error.
    pub category: ErrorCategory,
    /// Where.
    pub pos: Pos,
    /// What is wrong, and what was expected.
    pub message: String,
}

impl RewardError {
    /// An error of `category` at `pos`.
    pub fn new(category: ErrorCategory, pos: Pos, message: impl Into<String>) -> Self {
        RewardError {
            category,
            pos,
            message: message.into(),
        }
    }
}

impl fmt::Display for RewardError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "line {}, column {}: {} error: {}",
            self.pos.line,
            self.pos.col,
            self.category.as_str(),
            self.message
        )
    }
}
