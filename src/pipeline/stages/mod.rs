//! The stage kinds, one file each, in the order of `STAGE_KINDS` (`super::registry`): `import`
//! (paper-format JSON into the trace tables), `simulate` (an environment's simulator into the trace
//! tables; `simulate.rs` with `simulate_phyre.rs` and `simulate_iphyre.rs` for the other environments),
//! `annotate` (a detector library run over the traces), `accuracy` (its event-grounded labels scored
//! against simulator events), `synthesise` (goal sentences to reward programs through an LLM),
//! `optimise` (annealing actions for reward programs), `benchmark` (DeepPHY's agent loop), `summarise`
//! (summaries of traces, their cost and the identification task), `suggest-labels` (pattern labels
//! suggested from example traces, for an evolve stage), `evolve` (the evolutionary search for
//! detectors), `ensemble` (an ensemble library from the candidates of several evolve stages, paper
//! section 3.3), `sql` (a query over the run stored as a table), `export` (a table or query written to
//! `exports/`), `report` (the static web report of the run), `plot` (a figure of the run as SVG/PNG), `survey` (the
//! survey page of rollout animations and summaries rated 1–7) and `import-survey` (its response CSVs
//! into `survey_responses`).
//!
//! Helpers shared by kinds: `detector_setup` (the library, environment and sandbox parameters of every
//! kind that runs detectors), `trace_files` (reading a run's traces file by file for `annotate` and
//! `accuracy`), and `SqlSource` here (the query of `sql` and `export`). Adding a kind:
//! `docs/architecture.md`.

pub mod accuracy;
pub mod annotate;
pub mod benchmark;
pub mod detector_setup;
pub mod ensemble;
pub mod evolve;
pub mod export;
pub mod import;
pub mod import_survey;
mod llm_setup;
pub mod optimise;
pub mod plot;
pub mod report;
pub mod simulate;
pub mod sql;
pub mod suggest_labels;
pub mod summarise;
pub mod survey;
pub mod synthesise;
mod trace_files;

use std::path::{Path, PathBuf};

use super::registry::BuildError;

/// Where a stage's SQL comes from: a file under the project's `sql/` folder, or inline text.
#[derive(Clone, Debug)]
pub(crate) enum SqlSource {
    /// A file (resolved path).
    File(PathBuf),
    /// Inline SQL.
    Inline(String),
}

impl SqlSource {
    /// From a stage's `query` (a file name under `<project>/sql/`, or a path relative to the project)
    /// or `sql` (inline text); exactly one must be given unless `optional` (a `table` stands in).
    pub(crate) fn new(
        query: Option<&str>,
        inline: Option<&str>,
        project: &Path,
        optional: bool,
    ) -> Result<Option<Self>, BuildError> {
        match (query, inline) {
            (Some(_), Some(_)) => Err(BuildError::param(
                "sql",
                "give either `query` (a file in sql/) or `sql` (inline), not both",
            )),
            (Some(q), None) => {
                let candidates = [project.join("sql").join(q), project.join(q)];
                candidates
                    .iter()
                    .find(|p| p.is_file())
                    .map(|p| Some(SqlSource::File(p.clone())))
                    .ok_or_else(|| {
                        BuildError::param(
                            "query",
                            format!(
                                "SQL file {q:?} not found (looked for {})",
                                candidates
                                    .iter()
                                    .map(|c| c.display().to_string())
                                    .collect::<Vec<_>>()
                                    .join(" and ")
                            ),
                        )
                    })
            }
            (None, Some(s)) if s.trim().is_empty() => {
                Err(BuildError::param("sql", "`sql` is empty"))
            }
            (None, Some(s)) => Ok(Some(SqlSource::Inline(s.to_string()))),
            (None, None) if optional => Ok(None),
            (None, None) => Err(BuildError {
                param: None,
                message: "needs `query` (a file in sql/) or `sql` (inline SQL)".into(),
            }),
        }
    }

    /// The SQL text.
    pub(crate) fn text(&self) -> Result<String, super::StageError> {
        match self {
            SqlSource::Inline(s) => Ok(s.clone()),
            SqlSource::File(p) => {
                std::fs::read_to_string(p).map_err(|e| super::StageError::io(p, e))
            }
        }
    }
}

/// Checks a table name given by a user: lower-case letters, digits and `_`, not starting with a digit.
pub(crate) fn valid_table_name(name: &str) -> bool {
    !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        && !name.starts_with(|c: char| c.is_ascii_digit())
}
