//! The evolutionary search for detector programs (section 3.2, Algorithms 1–2 of the paper).
//!
//! **Owns:** the proposer interface ([`Proposer`]).
//! **Does not:** run candidate code (`detect/` workers do), compute fitness (`fitness/`), talk to LLMs
//! (`llm/`).

pub mod proposer;

pub use self::proposer::{Parent, Proposal, ProposalRequest, ProposeError, Proposer, count_lines};
