//! The runner: the only place that orders stages, compares fingerprints, skips finished work, resumes
//! interrupted stages and writes `manifest.json`.
//!
//! For each stage, in dependency order:
//! 1. its fingerprint is the SHA-256 of its kind, parameters (defaults filled, keys sorted), its inputs'
//!    fingerprints, the annotrace version and what the stage adds ([`Stage::fingerprint_extra`]);
//! 2. a stage whose manifest record is `finished` with the same fingerprint and whose outputs all exist is
//!    skipped (unless `--force` names it or a stage upstream of it);
//! 3. a stage recorded as `running` with the same fingerprint was interrupted: its finished shards are
//!    kept and the rest is redone; any other earlier output of the stage is deleted first;
//! 4. the stage runs, writing into its staging area; then the manifest says `committing` with the list of
//!    files, the files are moved into place, and the manifest says `finished`.
//!
//! NOTE: the manifest is written before and after every state change, so a run killed at any moment
//! resumes with the same command and never reads a partial file.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicUsize;
use std::time::Instant;

use serde_json::{Map, Value};
use sha2::{Digest, Sha256};

use super::SpecError;
use super::manifest::{Manifest, PipelineInfo, StageRecord, StageStatus, now};
use super::progress::Progress;
use super::spec::PipelineSpec;
use super::stage::{FaultPlan, Stage, StageContext, StageError};
use crate::digest::hex;
use crate::store::{RunDir, Staging, StoreError, remove_files};

/// Options of one `annotrace run`.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Run folder (default: the pipeline's).
    pub run_dir: Option<PathBuf>,
    /// Rerun this stage and everything downstream of it even if cached.
    pub force: Option<String>,
    /// Run only this stage and what it depends on.
    pub until: Option<String>,
    /// Stop on purpose at a point (tests of resumption).
    pub fault: Option<FaultPlan>,
    /// Record the pipeline as the run's pipeline in the manifest (off for one-off CLI commands).
    pub record_pipeline: bool,
    /// When the run folder did not exist and no stage finishes, remove it on failure (one-off CLI
    /// commands such as `annotrace import`, which must leave nothing behind when they fail). Pipelines
    /// keep the folder, so the manifest shows the failed stage and its error.
    pub remove_new_run_on_failure: bool,
}

/// A run could not complete.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunError {
    /// The pipeline file is invalid.
    #[error(transparent)]
    Spec(#[from] SpecError),
    /// `--force` or `--until` names no stage.
    #[error("{option} {id:?}: no such stage (stages: {known})")]
    UnknownStage {
        /// `--force` or `--until`.
        option: &'static str,
        /// The id given.
        id: String,
        /// The pipeline's stage ids.
        known: String,
    },
    /// Another process holds the run folder.
    #[error("{}: another annotrace process is using this run folder", run.display())]
    Locked {
        /// The run folder.
        run: PathBuf,
    },
    /// The run folder could not be read or written.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// A stage failed.
    #[error("stage {id} failed")]
    Stage {
        /// The stage.
        id: String,
        /// Why.
        #[source]
        source: StageError,
    },
}

/// What the runner will do with a stage.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Action {
    /// Finished with the same fingerprint: skipped.
    Cached,
    /// Will run, for this reason.
    Run(RunReason),
    /// Not selected (`--until`).
    Skipped,
}

/// Why the runner runs a stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunReason {
    /// `--force` names it or a stage it depends on.
    Forced,
    /// The manifest has no record of it.
    New,
    /// Its fingerprint differs from the recorded one.
    Changed,
    /// It finished, but its outputs are not all there.
    OutputsMissing,
    /// It was interrupted while running or committing: finished shards are kept.
    Resume,
    /// It failed the last time.
    FailedBefore,
}

impl RunReason {
    /// The reason as `run --explain` prints it.
    pub fn as_str(self) -> &'static str {
        match self {
            RunReason::Forced => "forced",
            RunReason::New => "new",
            RunReason::Changed => "changed",
            RunReason::OutputsMissing => "outputs missing",
            RunReason::Resume => "resume",
            RunReason::FailedBefore => "failed before",
        }
    }
}

/// One line of `annotrace run --explain`.
#[derive(Clone, Debug)]
pub struct PlannedStage {
    /// Stage id.
    pub id: String,
    /// Kind.
    pub kind: &'static str,
    /// Fingerprint.
    pub fingerprint: String,
    /// Inputs.
    pub inputs: Vec<String>,
    /// What will happen.
    pub action: Action,
}

impl std::fmt::Display for PlannedStage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let action = match &self.action {
            Action::Cached => "cached".to_string(),
            Action::Run(why) => format!("run ({})", why.as_str()),
            Action::Skipped => "not selected".to_string(),
        };
        write!(
            f,
            "{:<24} {:<8} {}  {:<28}",
            self.id,
            self.kind,
            &self.fingerprint[..12],
            action
        )?;
        if !self.inputs.is_empty() {
            write!(f, " <- {}", self.inputs.join(", "))?;
        }
        Ok(())
    }
}

/// What happened to one stage.
#[derive(Clone, Debug)]
pub struct StageReport {
    /// Stage id.
    pub id: String,
    /// Whether it was skipped as cached.
    pub cached: bool,
    /// Rows written per table (of the run that produced the outputs).
    pub rows: BTreeMap<String, u64>,
    /// The stage's summary.
    pub summary: Value,
    /// Wall time in seconds (0 when cached).
    pub seconds: f64,
}

/// The outcome of a run.
#[derive(Clone, Debug)]
pub struct RunReport {
    /// The run folder.
    pub run_dir: PathBuf,
    /// Stages in the order they were considered.
    pub stages: Vec<StageReport>,
}

/// An error and its causes on one line, as `{:#}` prints them.
pub fn error_chain(e: &dyn std::error::Error) -> String {
    let mut out = e.to_string();
    let mut cur = e.source();
    while let Some(s) = cur {
        out.push_str(": ");
        out.push_str(&s.to_string());
        cur = s.source();
    }
    out
}

/// Sorts object keys recursively so that equal parameters hash equally.
fn canonical(v: &Value) -> Value {
    match v {
        Value::Object(m) => {
            let mut keys: Vec<&String> = m.keys().collect();
            keys.sort();
            Value::Object(
                keys.into_iter()
                    .map(|k| (k.clone(), canonical(&m[k])))
                    .collect::<Map<_, _>>(),
            )
        }
        Value::Array(a) => Value::Array(a.iter().map(canonical).collect()),
        other => other.clone(),
    }
}

struct Built {
    stages: Vec<Box<dyn Stage>>,
    fingerprints: BTreeMap<String, String>,
    order: Vec<usize>,
}

fn build(spec: &PipelineSpec) -> Result<Built, RunError> {
    let order = spec.order()?;
    let mut stages: Vec<Option<Box<dyn Stage>>> = (0..spec.stages.len()).map(|_| None).collect();
    let mut fingerprints = BTreeMap::new();
    for &i in &order {
        let def = &spec.stages[i];
        let stage = (def.kind.build)(def, spec).map_err(|e| SpecError::Invalid {
            file: spec.file.clone(),
            line: e.param.map_or(def.line, |p| def.line_of(p)),
            message: format!("stage \"{}\": {}", def.id, e.message),
        })?;
        let extra = stage
            .fingerprint_extra()
            .map_err(|source| RunError::Stage {
                id: def.id.clone(),
                source,
            })?;
        let material = serde_json::json!({
            "kind": def.kind.name,
            "params": canonical(&Value::Object(def.params.clone())),
            "inputs": def.inputs.iter().map(|i| fingerprints.get(i).cloned().unwrap_or_default()).collect::<Vec<String>>(),
            "version": crate::VERSION,
            "extra": canonical(&extra),
        });
        fingerprints.insert(
            def.id.clone(),
            hex(&Sha256::digest(material.to_string().as_bytes())),
        );
        stages[i] = Some(stage);
    }
    Ok(Built {
        stages: stages
            .into_iter()
            .map(|s| s.expect("every stage is built"))
            .collect(),
        fingerprints,
        order,
    })
}

fn check_stage_option(
    spec: &PipelineSpec,
    option: &'static str,
    id: &Option<String>,
) -> Result<(), RunError> {
    match id {
        Some(id) if spec.stage(id).is_none() => Err(RunError::UnknownStage {
            option,
            id: id.clone(),
            known: spec
                .stages
                .iter()
                .map(|s| s.id.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        }),
        _ => Ok(()),
    }
}

fn plan_with(
    spec: &PipelineSpec,
    opts: &RunOptions,
    built: &Built,
    run: &RunDir,
    manifest: &Manifest,
) -> Vec<PlannedStage> {
    let selected = opts.until.as_ref().map(|u| spec.upstream(u));
    let forced = opts
        .force
        .as_ref()
        .map(|f| spec.downstream(f))
        .unwrap_or_default();
    built
        .order
        .iter()
        .map(|&i| {
            let def = &spec.stages[i];
            let fp = built.fingerprints[&def.id].clone();
            let action = if selected.as_ref().is_some_and(|s| !s.contains(&def.id)) {
                Action::Skipped
            } else if forced.contains(&def.id) {
                Action::Run(RunReason::Forced)
            } else {
                match manifest.stages.get(&def.id) {
                    None => Action::Run(RunReason::New),
                    Some(r) if r.fingerprint != fp => Action::Run(RunReason::Changed),
                    Some(r) => match r.status {
                        StageStatus::Finished if manifest.outputs_present(run, &def.id) => {
                            Action::Cached
                        }
                        StageStatus::Finished => Action::Run(RunReason::OutputsMissing),
                        StageStatus::Running | StageStatus::Committing => {
                            Action::Run(RunReason::Resume)
                        }
                        StageStatus::Failed => Action::Run(RunReason::FailedBefore),
                    },
                }
            };
            PlannedStage {
                id: def.id.clone(),
                kind: def.kind.name,
                fingerprint: fp,
                inputs: def.inputs.clone(),
                action,
            }
        })
        .collect()
}

/// Checks the options, builds every stage with its fingerprint, and finds the run folder.
fn prepare(spec: &PipelineSpec, opts: &RunOptions) -> Result<(Built, RunDir), RunError> {
    check_stage_option(spec, "--force", &opts.force)?;
    check_stage_option(spec, "--until", &opts.until)?;
    let built = build(spec)?;
    let dir = opts
        .run_dir
        .clone()
        .unwrap_or_else(|| spec.default_run_dir());
    Ok((built, RunDir::new(dir)))
}

/// What `run` would do, without doing it.
pub fn explain(
    spec: &PipelineSpec,
    opts: &RunOptions,
) -> Result<(PathBuf, Vec<PlannedStage>), RunError> {
    let (built, run) = prepare(spec, opts)?;
    let manifest = Manifest::load(&run)?.unwrap_or_default();
    let plan = plan_with(spec, opts, &built, &run, &manifest);
    Ok((run.root().to_path_buf(), plan))
}

fn relative(run: &RunDir, path: &Path) -> String {
    path.strip_prefix(run.root())
        .unwrap_or(path)
        .to_string_lossy()
        .replace('\\', "/")
}

/// Runs a pipeline.
pub fn run(
    spec: &PipelineSpec,
    opts: &RunOptions,
    progress: &dyn Progress,
) -> Result<RunReport, RunError> {
    let (built, run) = prepare(spec, opts)?;
    let existed = run.root().exists();
    fs::create_dir_all(run.root()).map_err(|e| StoreError::Io {
        path: run.root().to_path_buf(),
        source: e,
    })?;
    let lock_path = run.root().join(".lock");
    let lock = fs::File::create(&lock_path).map_err(|e| StoreError::Io {
        path: lock_path.clone(),
        source: e,
    })?;
    if lock.try_lock().is_err() {
        return Err(RunError::Locked {
            run: run.root().to_path_buf(),
        });
    }

    let result = run_locked(spec, opts, progress, &built, &run);
    if result.is_err() && !existed && opts.remove_new_run_on_failure {
        // A run folder this invocation created and that holds no finished stage is removed whole, so a
        // failed first import leaves nothing behind.
        let finished = Manifest::load(&run)
            .ok()
            .flatten()
            .is_some_and(|m| m.stages.values().any(|s| s.status == StageStatus::Finished));
        if !finished {
            drop(lock);
            let _ = fs::remove_dir_all(run.root());
        }
    }
    result
}

/// One invocation of the runner over a locked run folder: what every step of a stage needs.
struct Session<'a> {
    spec: &'a PipelineSpec,
    opts: &'a RunOptions,
    progress: &'a dyn Progress,
    built: &'a Built,
    run: &'a RunDir,
}

fn run_locked(
    spec: &PipelineSpec,
    opts: &RunOptions,
    progress: &dyn Progress,
    built: &Built,
    run: &RunDir,
) -> Result<RunReport, RunError> {
    let mut manifest = Manifest::load(run)?.unwrap_or_default();
    if opts.record_pipeline {
        manifest.pipeline = Some(PipelineInfo {
            name: spec.name.clone(),
            file: spec.file.to_string_lossy().into_owned(),
            sha256: spec.sha256.clone(),
            seed: spec.seed,
        });
    }
    let session = Session {
        spec,
        opts,
        progress,
        built,
        run,
    };
    let plan = plan_with(spec, opts, built, run, &manifest);
    let mut reports = Vec::new();
    for (planned, &i) in plan.iter().zip(&built.order) {
        let def = &spec.stages[i];
        match planned.action {
            Action::Skipped => continue,
            Action::Cached => {
                progress.stage_cached(&def.id);
                let r = &manifest.stages[&def.id];
                reports.push(StageReport {
                    id: def.id.clone(),
                    cached: true,
                    rows: r.rows.clone(),
                    summary: r.summary.clone(),
                    seconds: 0.0,
                });
                continue;
            }
            Action::Run(_) => {}
        }
        let staging = run.staging(&def.id);
        let previous = manifest.stages.get(&def.id).cloned();
        let resuming = previous.as_ref().is_some_and(|p| {
            p.fingerprint == planned.fingerprint && planned.action == Action::Run(RunReason::Resume)
        });
        if let Some(prev) = previous
            .as_ref()
            .filter(|p| resuming && p.status == StageStatus::Committing)
        {
            reports.push(session.finish_commit(&mut manifest, &staging, &def.id, prev)?);
            continue;
        }
        session.reset_staging(&staging, &def.id, previous.as_ref(), resuming)?;
        reports.push(session.execute(&mut manifest, planned, i, staging)?);
    }
    Ok(RunReport {
        run_dir: run.root().to_path_buf(),
        stages: reports,
    })
}

impl Session<'_> {
    /// A stage killed while moving its files into place: finishes the move and records it finished.
    fn finish_commit(
        &self,
        manifest: &mut Manifest,
        staging: &Staging,
        id: &str,
        prev: &StageRecord,
    ) -> Result<StageReport, RunError> {
        let (run, progress) = (self.run, self.progress);
        // Killed while moving files into place: finish the move.
        staging.commit()?;
        let mut rec = prev.clone();
        rec.status = StageStatus::Finished;
        rec.finished = Some(now());
        manifest.stages.insert(id.to_string(), rec.clone());
        manifest.save(run)?;
        progress.stage_finished(id, "resumed commit");
        Ok(StageReport {
            id: id.to_string(),
            cached: false,
            rows: rec.rows,
            summary: rec.summary,
            seconds: 0.0,
        })
    }

    /// Prepares the staging folder: a resumed stage keeps its finished shards, any other starts empty
    /// (its previous outputs removed).
    fn reset_staging(
        &self,
        staging: &Staging,
        id: &str,
        previous: Option<&StageRecord>,
        resuming: bool,
    ) -> Result<(), RunError> {
        let (run, progress) = (self.run, self.progress);
        if resuming {
            let dropped = staging.discard_unfinished()?;
            progress.note(
                id,
                &format!("resuming: finished shards kept, {dropped} partial file(s) dropped"),
            );
        } else {
            if let Some(prev) = previous {
                let files: Vec<PathBuf> = prev.outputs.iter().map(|o| run.root().join(o)).collect();
                remove_files(&files)?;
            }
            staging.remove()?;
        }
        Ok(())
    }

    /// Runs stage number `i` and commits its outputs, recording each step in the manifest.
    fn execute(
        &self,
        manifest: &mut Manifest,
        planned: &PlannedStage,
        i: usize,
        staging: Staging,
    ) -> Result<StageReport, RunError> {
        let Session {
            spec,
            opts,
            progress,
            built,
            run,
        } = *self;
        let def = &spec.stages[i];
        let started = Instant::now();
        let mut record = StageRecord {
            kind: def.kind.name.to_string(),
            status: StageStatus::Running,
            fingerprint: planned.fingerprint.clone(),
            params: Value::Object(def.params.clone()),
            inputs: def.inputs.clone(),
            seed: spec.seed,
            annotrace_version: crate::VERSION.to_string(),
            started: Some(now()),
            finished: None,
            seconds: None,
            rows: BTreeMap::new(),
            outputs: Vec::new(),
            summary: Value::Null,
            error: None,
        };
        manifest.stages.insert(def.id.clone(), record.clone());
        manifest.save(run)?;

        let ctx = StageContext {
            run,
            stage_id: &def.id,
            seed: spec.seed,
            project_dir: &spec.project_dir,
            staging: staging.clone(),
            progress,
            fault: opts.fault.as_ref(),
            shards_finished: AtomicUsize::new(0),
            shards_started: AtomicUsize::new(0),
        };
        progress.stage_started(&def.id, def.kind.name, None);
        let output = match built.stages[i].run(&ctx) {
            Ok(out) => out,
            Err(source) => {
                staging.remove()?;
                record.status = StageStatus::Failed;
                record.error = Some(error_chain(&source));
                record.finished = Some(now());
                manifest.stages.insert(def.id.clone(), record);
                manifest.save(run)?;
                return Err(RunError::Stage {
                    id: def.id.clone(),
                    source,
                });
            }
        };

        // NOTE: the file list is recorded before the move, so that a crash during the move can finish it.
        let mut outputs: Vec<String> = staging
            .pending()?
            .iter()
            .map(|p| relative(run, p))
            .collect();
        outputs.extend(output.files.iter().map(|p| relative(run, p)));
        record.status = StageStatus::Committing;
        record.outputs = outputs;
        record.rows = output.rows.clone();
        record.summary = output.summary.clone();
        manifest.stages.insert(def.id.clone(), record.clone());
        manifest.save(run)?;
        staging.commit()?;
        let seconds = started.elapsed().as_secs_f64();
        record.status = StageStatus::Finished;
        record.finished = Some(now());
        record.seconds = Some(seconds);
        manifest.stages.insert(def.id.clone(), record);
        manifest.save(run)?;
        progress.stage_finished(&def.id, &output.line);
        Ok(StageReport {
            id: def.id.clone(),
            cached: false,
            rows: output.rows,
            summary: output.summary,
            seconds,
        })
    }
}
