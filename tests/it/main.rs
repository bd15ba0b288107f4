//! Integration tests: one binary, one file per command users type (ripgrep's and uv's layout).

mod common;

mod annotate;
mod export;
mod import;
mod query;
mod render;
mod run;
mod sandbox;
mod simulate;
