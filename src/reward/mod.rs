//! Reward programs: a small DSL over annotated traces that gives a boolean success and a dense reward
//! in [0, 1] (the paper's section 3.4), the goal files with hand-written verification rules, and
//! the synthesis of programs from natural-language goals.
//!
//! Pipeline of a program: [`lexer`] → [`parser`] (syntax tree, environment-agnostic) → [`check`]
//! (typed [`Program`] against a [`Schema`]: the library's labels, aliases and parameter keys) →
//! [`eval`] on an [`AnnotatedTrace`] (the library's annotations plus built-in facts from the trace).
//! Every error is a [`RewardError`] with a category, line and column; no input makes any stage panic.
//!
//! `AFTER(a, b)` holds when an occurrence of `a` starts no earlier than an occurrence of `b` (the
//! DSL reference's reading: "a occurs after b"); see `docs/reward.md`.
//!
//! **Owns:** the DSL, its checker and interpreter, goal files and verification rules ([`goals`],
//! [`verify`]), synthesis from goal sentences with repair ([`synth`], through `llm::LlmClient`), and
//! the bridge from reward programs to the detector runtime ([`annotate`]): it batches traces through a
//! `detect::WorkerPool` it is given, and [`annotate::probe_schema`] learns a library's parameter keys
//! by simulating eight billiards shots (`envs::pool`) and annotating them.
//! **Does not:** start or own worker pools (`detect/`), implement physics (`envs/`), search actions
//! (`optimise/`), or write tables (the `optimise` stage does).

pub mod annotate;
pub mod check;
pub mod error;
pub mod eval;
pub mod facts;
pub mod goals;
pub mod lexer;
pub mod parser;
pub mod program;
pub mod schema;
pub mod synth;
pub mod verify;

pub use check::compile;
pub use error::{ErrorCategory, Pos, RewardError};
pub use eval::{ClauseValue, Evaluation, evaluate, shape};
pub use facts::{AnnotatedTrace, Occurrence};
pub use program::{Node, NodeKind, Program};
pub use schema::Schema;

/// The labels a program refers to (canonical spellings, in first-use order): only these detectors
/// need to run to evaluate it.
pub fn labels_used(program: &Program) -> Vec<String> {
    fn walk(n: &Node, out: &mut Vec<String>) {
        let mut add = |l: &str| {
            if !out.iter().any(|x| x == l) {
                out.push(l.to_string());
            }
        };
        match &n.kind {
            NodeKind::Pattern(p)
            | NodeKind::PatternCount { pattern: p, .. }
            | NodeKind::Count { pattern: p, .. } => add(&p.label),
            NodeKind::After { a, b, .. } => {
                walk(a, out);
                walk(b, out);
            }
            NodeKind::And(xs) | NodeKind::Or(xs) => xs.iter().for_each(|x| walk(x, out)),
            NodeKind::Not(x) => walk(x, out),
            NodeKind::CueHit(_)
            | NodeKind::Pocketed { .. }
            | NodeKind::NearbyAt { .. }
            | NodeKind::Near { .. } => {}
        }
    }
    let mut out = Vec::new();
    walk(&program.root, &mut out);
    out
}
