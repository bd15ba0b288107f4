//! Helpers shared by the integration tests (and, by path, the `replay` example).

pub mod recording;
