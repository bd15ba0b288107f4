//! annotrace discovers high-level patterns in physics simulation traces.
//!
//! A simulator (or an import) produces **traces**: dense object states plus a sparse event log, stored
//! as Parquet tables in a **run directory**. Pipelines of **stages** read tables and write tables; SQL
//! over a run's tables makes the paper's figures and tables.
//!
//! Modules, bottom to top (each depends only on those above it in this list):
//! - [`rng`]: the seeded SplitMix64 generator every seeded draw comes from (its streams are output format);
//! - [`digest`]: hex and SHA-256 helpers for ids, fingerprints and string-keyed seeds;
//! - [`trace`]: the trace model, its Arrow schemas and the paper's JSON format;
//! - [`store`]: the run directory on disk — atomic files, Parquet datasets, staging and commit;
//! - [`envs`]: simulators behind one `Environment` trait (billiards: pooltool 0.6.0 physics), producing traces;
//! - [`builtin`]: the built-in data compiled into the binary (libraries, goal files), and whether a
//!   path means a file on disk or a built-in;
//! - [`detect`]: sandboxed Python workers that run detector programs over traces, annotations and libraries;
//! - [`llm`]: OpenAI-compatible chat client (retries, budget, `llm_calls` recording and replay), prompt templates;
//! - [`query`]: DataFusion over a run's tables, and result formats (table, CSV, Markdown, LaTeX, JSON);
//! - [`pipeline`]: pipeline files, the stage registry, fingerprints, the runner and its manifest.
#![warn(missing_docs)]

pub mod builtin;
pub mod detect;
pub mod digest;
pub mod envs;
pub mod fitness;
pub mod llm;
pub mod optimise;
pub mod pipeline;
pub mod query;
pub mod reward;
pub mod rng;
pub mod search;
pub mod store;
pub mod trace;

#[doc(hidden)]
pub mod testutil;

/// The crate version recorded in manifests and stage fingerprints.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
