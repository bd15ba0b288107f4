//! The evolutionary search for detector programs (section 3.2, Algorithms 1–2 and appendix F of the
//! paper): for each label, evolve programs whose annotations vary with the traces as the traces vary
//! and that add something the library does not already say; accept the best if ν > δ and its ρ on
//! held-out traces is positive.
//!
//! - [`proposer`]: the interface proposers implement ([`Proposer`]); [`mutate`]: the offline proposer;
//!   [`llm_proposer`]: the LLM proposer (prompts and answers through `llm/`);
//! - [`islands`]: the program database (FunSearch islands, hill-climb, best-of-n);
//! - [`evaluator`]: cheap checks (probe set, behaviour signatures) and Evaluate in the worker pool;
//! - [`run`]: one label's search in rounds, checkpointed and resumable; [`discover`]: Algorithm 2;
//! - [`candidate`]: the `candidates` table; [`library_out`]: the grown library as a folder;
//!   [`tables`]: the other evolution tables; [`tally`]: proposals by outcome (every one failed is an
//!   error).
//!
//! **Owns:** everything above. **Does not:** run candidate code in this process (`detect/` workers do),
//! compute distances (`fitness/`), make HTTP requests (`llm/` does, and records each call in the run's
//! `llm_calls` table), or decide where its tables go (the `evolve` stage writes them and names the folder
//! [`library_out`] writes the grown library into).

pub mod candidate;
pub mod discover;
pub mod evaluator;
pub mod islands;
pub mod library_out;
pub mod llm_proposer;
pub mod mutate;
pub mod proposer;
pub mod run;
pub mod skeleton;
pub mod tables;
pub mod tally;

pub use self::candidate::{CandidateRecord, code_hash};
pub use self::discover::{
    Acceptance, AccuracyGuard, ConvergenceRow, Discovery, GuardCheck, LabelResult, SampleRow,
};
pub use self::evaluator::{EvalSettings, Evaluation, Evaluator};
pub use self::islands::{Database, Program, Strategy, Temperatures};
pub use self::llm_proposer::LlmProposer;
pub use self::mutate::MutateProposer;
pub use self::proposer::{Parent, Proposal, ProposalRequest, ProposeError, Proposer, count_lines};
pub use self::run::{
    Checkpoint, LabelOutcome, LabelSearch, MemoryCheckpoint, SearchConfig, SearchError,
};
pub use self::tally::ProposalTally;
