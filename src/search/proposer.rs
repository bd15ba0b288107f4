//! The proposer interface: where the search gets new detector programs from.
//!
//! A [`Proposer`] turns a [`ProposalRequest`] (the label being learned, a few parents from one island
//! with their scores, the labels already in the library, a seed) into Python source for a child
//! detector. Two kinds implement it: the offline `mutate` proposer (syntax-tree edits, `search::mutate`)
//! and the LLM proposer (`search::llm_proposer`). The search validates and scores whatever comes back;
//! a proposer never runs candidate code.
//!
//! **Owns:** the trait and its request/response/error types. **Does not:** validate, evaluate or
//! persist candidates (`search::run`), nor talk HTTP (`llm/`).

use crate::detect::DetectorError;
use crate::fitness::FitnessTerms;
use crate::trace::Env;

/// One parent program shown to the proposer.
#[derive(Clone, Debug, PartialEq)]
pub struct Parent {
    /// The parent's Python source (defines `find_pattern(trace)`).
    pub code: String,
    /// Its fitness terms, `None` for a seed program that has not been scored yet.
    pub fitness: Option<FitnessTerms>,
    /// Its number of non-blank source lines.
    pub lines: usize,
}

/// What the search asks a proposer for: one child program for `label`.
#[derive(Clone, Debug, PartialEq)]
pub struct ProposalRequest {
    /// The environment the traces come from (decides the trace layout a prompt describes).
    pub env: Env,
    /// The pattern label being learned (normalised, e.g. `ball_collision`).
    pub label: String,
    /// The parents sampled from one island, best first (at most the prompt size `s`, at least one).
    pub parents: Vec<Parent>,
    /// Labels already in the library (the child should add something they do not say).
    pub library_labels: Vec<String>,
    /// The seed for this request: derived from the run seed, label, island and step, so the same
    /// search asks the same questions. Deterministic proposers must depend only on it and the parents.
    pub seed: u64,
    /// The island the parents come from.
    pub island: usize,
    /// The search step (0-based, counts every proposal of this label's search).
    pub step: u64,
}

/// A proposed child program and what it cost.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Proposal {
    /// The child's Python source (the proposer strips prose and code fences).
    pub code: String,
    /// Prompt tokens spent (0 for offline proposers).
    pub tokens_in: u64,
    /// Completion tokens spent (0 for offline proposers).
    pub tokens_out: u64,
    /// Calls made to the backend (0 for offline proposers).
    pub calls: u32,
}

/// Why a proposer produced nothing. The search records the failed step and goes on, except for
/// [`ProposeError::BudgetExhausted`] (ends the label's search), [`ProposeError::Unavailable`] (ends
/// the run with an error after retries inside the proposer) and [`ProposeError::Refused`] (ends the
/// run as a configuration error).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ProposeError {
    /// The backend cannot be reached or refuses service (after the proposer's own retries).
    #[error("proposer unavailable: {0}")]
    Unavailable(String),
    /// The backend refuses the request itself (credentials, a wrong URL or model name, a replay that
    /// does not hold the call): the configuration's fault, and retrying cannot help. Ends the run like
    /// [`ProposeError::Unavailable`].
    #[error("proposer refused: {0}")]
    Refused(String),
    /// The token or call budget is used up.
    #[error("proposer budget exhausted: {0}")]
    BudgetExhausted(String),
    /// The backend answered, but with nothing usable (no code in the reply, a parse failure of the
    /// parents for syntax-tree edits, …). The step counts as a failed candidate.
    #[error("{0}")]
    Other(String),
}

/// A source of child programs. Object-safe: the search holds a `&dyn Proposer` and may call it from
/// several threads at once.
pub trait Proposer: Send + Sync {
    /// The proposer's name as recorded in the `candidates` table (`mutate`, `llm:<model>`, …).
    fn name(&self) -> &str;

    /// A new child program for `req.label` from `req.parents`.
    fn propose(&self, req: &ProposalRequest) -> Result<Proposal, ProposeError>;

    /// A repaired version of `code` given the validator's or the runtime's error (category, message,
    /// line and column are in `error`), or `Ok(None)` if this proposer does not repair. `attempt`
    /// counts from 1. The search calls this up to `repair_attempts` times (default 2) when a child
    /// fails with a syntax, forbidden, no-`find_pattern`, runtime or invalid-output error.
    fn repair(
        &self,
        req: &ProposalRequest,
        code: &str,
        error: &DetectorError,
        attempt: u32,
    ) -> Result<Option<Proposal>, ProposeError>;
}

/// Count the non-blank, non-comment source lines of a program (the `lines` of λ and of the tables).
pub fn count_lines(code: &str) -> usize {
    code.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Echo;
    impl Proposer for Echo {
        fn name(&self) -> &str {
            "echo"
        }
        fn propose(&self, req: &ProposalRequest) -> Result<Proposal, ProposeError> {
            Ok(Proposal {
                code: req.parents[0].code.clone(),
                ..Proposal::default()
            })
        }
        fn repair(
            &self,
            _: &ProposalRequest,
            _: &str,
            _: &DetectorError,
            _: u32,
        ) -> Result<Option<Proposal>, ProposeError> {
            Ok(None)
        }
    }

    #[test]
    fn the_trait_is_object_safe_and_lines_skip_blanks_and_comments() {
        let p: Box<dyn Proposer> = Box::new(Echo);
        let req = ProposalRequest {
            env: Env::Pooltool,
            label: "x".into(),
            parents: vec![Parent {
                code: "def find_pattern(trace):\n\n    # c\n    return []\n".into(),
                fitness: None,
                lines: 2,
            }],
            library_labels: vec![],
            seed: 1,
            island: 0,
            step: 0,
        };
        let out = p.propose(&req).unwrap();
        assert_eq!(count_lines(&out.code), 2);
        assert_eq!(p.name(), "echo");
    }
}
