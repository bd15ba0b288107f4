//! Setting up the model for stages that ask one (`summarise`, `suggest-labels`, `benchmark` with the
//! `llm` agent, `ensemble` with the identification objective): the client, resumable from the run's
//! own recorded calls, and the prompt templates.
//!
//! **Owns:** how a stage's `llm` settings become a client (the seed default, the process environment,
//! replay of this run's `llm_calls` on resume) and where its prompts come from. **Does not:** ask the
//! model (the callers' `summary`/`bench` code does) or decide whether a stage uses one.

use std::path::{Path, PathBuf};

use crate::llm::{LlmClient, LlmConfig, LlmError, LlmSettings, Prompts, ReplayConfig};
use crate::pipeline::stage::StageError;
use crate::store::RunDir;

/// The stage's client: `settings` with `seed` where they name none, resolved against the process
/// environment. Unless the settings replay another run, answers this run already recorded are served
/// again (non-strict replay of its own `llm_calls`), so a resumed stage asks nothing twice.
pub(crate) fn resumable_client(
    settings: &LlmSettings,
    seed: u64,
    run: &RunDir,
) -> Result<LlmClient, StageError> {
    let mut settings = settings.clone();
    settings.seed = Some(settings.seed.unwrap_or(seed));
    let mut config = LlmConfig::resolve(&settings, &|k| std::env::var(k).ok())?;
    if config.replay.is_none() {
        config.replay = Some(ReplayConfig {
            run: run.root().to_path_buf(),
            strict: false,
        });
    }
    Ok(LlmClient::new(config, Some(run))?)
}

/// The prompt templates: the stage's `prompts` folder, else the project's `prompts/` when it exists,
/// else the built-in ones; with the stage's own templates added by `add` (the summary and label
/// templates, `summary::add_templates`, or the agent's, `bench::agent::add_templates`).
pub(crate) fn stage_prompts(
    prompts: Option<&PathBuf>,
    project: &Path,
    add: fn(&mut Prompts) -> Result<(), LlmError>,
) -> Result<Prompts, StageError> {
    let dir = prompts
        .cloned()
        .or_else(|| Some(project.join("prompts")).filter(|d| d.is_dir()));
    let mut prompts = Prompts::load(dir.as_deref())?;
    add(&mut prompts)?;
    Ok(prompts)
}
