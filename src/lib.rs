//! annotrace discovers high-level patterns in physics simulation traces.
//!
//! A simulator (or an import) produces **traces**: dense object states plus a sparse event log, stored
//! as Parquet tables in a **run directory**. Pipelines of **stages** read tables and write tables; SQL
//! over a run's tables makes the paper's figures and tables.
//!
//! Modules, bottom to top (each uses only modules above it in this list; `docs/architecture.md` has the
//! data path, what each module may not touch, and how to add a stage kind or an environment):
//! - [`rng`]: the seeded SplitMix64 generator every seeded draw comes from (its streams are output format);
//! - [`digest`]: hex and SHA-256 helpers for ids, fingerprints and string-keyed seeds;
//! - [`trace`]: the trace model, its Arrow schemas and the paper's JSON format;
//! - [`store`]: the run directory on disk — atomic files, Parquet datasets, staging and commit;
//! - [`envs`]: simulators behind one `Environment` trait (billiards after pooltool 0.6.0, PHYRE and
//!   I-PHYRE on a Chipmunk-faithful step), producing traces;
//! - [`builtin`]: the built-in data compiled into the binary (libraries, goal files), and whether a
//!   path means a file on disk or a built-in;
//! - [`detect`]: sandboxed Python workers that run detector programs over traces, annotations and libraries;
//! - [`fitness`]: trace and annotation distances and the Evaluate function (ν = ρ + η − λ − ψ);
//! - [`llm`]: OpenAI-compatible chat client (retries, budget, `llm_calls` recording and replay), prompt templates;
//! - [`query`]: DataFusion over a run's tables, and result formats (table, CSV, Markdown, LaTeX, JSON);
//! - [`plot`]: figures as SVG and PNG (axes, bands, bars), the plot kinds of a run and the
//!   annotation-examples figure;
//! - [`search`]: the evolutionary search for detectors (proposers, islands, rounds, Algorithm 2);
//! - [`reward`]: the reward-program DSL over annotated traces, goal files, verification rules, synthesis;
//! - [`optimise`]: simulated annealing of actions for reward programs and the billiards experiment;
//! - [`report`]: the static web report of a run (trace player, pattern timeline, annotated text);
//! - [`survey`]: the survey kit (rollout animations beside summaries rated 1–7, seeded per-participant
//!   shuffle, response CSVs and their tables);
//! - [`pipeline`]: pipeline files, the stage registry and every stage kind, fingerprints, the runner and
//!   its manifest.
//!
//! The `annotrace` binary (`src/main.rs`, `src/cli/`) turns command lines into calls to these modules.
#![deny(missing_docs)]
// `pipeline::SpecError` carries the file, line, key and suggestion a user needs to fix a pipeline file;
// it is built once per failed run, never on a hot path, so its size is not worth boxing.
#![allow(clippy::result_large_err)]

pub mod bench;
pub mod builtin;
pub mod detect;
pub mod digest;
pub mod ensemble;
pub mod envs;
pub mod fitness;
pub mod llm;
pub mod optimise;
pub mod pipeline;
pub mod plot;
pub mod query;
pub mod report;
pub mod reward;
pub mod rng;
pub mod search;
pub mod store;
pub mod summary;
pub mod survey;
pub mod trace;

#[doc(hidden)]
pub mod testutil;

/// The crate version recorded in manifests and stage fingerprints.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
