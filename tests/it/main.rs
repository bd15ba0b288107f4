//! Integration tests: one binary, one file per command users type (ripgrep's and uv's layout).

mod common;

mod annotate;
mod anywhere;
mod ballista;
mod bench;
mod benchmark;
mod ensemble;
mod evolve;
mod exit_codes;
mod export;
mod import;
mod iphyre;
mod lazy_steps;
mod libraries;
mod llm;
mod llm_time;
mod optimise;
mod originals;
mod phyre;
mod publish;
mod query;
mod render;
mod report;
mod reward;
mod run;
#[cfg(feature = "s3")]
mod s3;
mod sandbox;
mod shard;
mod shared_helpers;
mod simulate;
mod snapshots_cli;
mod sql_guard;
mod suggest_labels;
mod summarise;
mod survey;
mod tools;
