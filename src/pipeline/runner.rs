//! The runner: the only place that orders stages, compares fingerprints, skips finished work, resumes
//! interrupted stages and writes `manifest.json`.
//!
//! For each stage, in dependency order:
//! 1. its fingerprint is the SHA-256 of its kind, parameters (defaults filled, keys sorted), its inputs'
//!    fingerprints, the annotrace version and what the stage adds ([`Stage::fingerprint_extra`]);
//! 2. a stage whose manifest record is `finished` with the same fingerprint and whose outputs all exist
//!    with their recorded sizes and SHA-256 sums is skipped (unless `--force` names it or a stage
//!    upstream of it); one whose outputs are missing or damaged runs again, and says why;
//! 3. a stage recorded as `running` with the same fingerprint was interrupted: its finished shards are
//!    kept and the rest is redone; any other earlier output of the stage is first unpublished (the
//!    manifest stops calling it finished), then deleted;
//! 4. the stage runs, writing into its staging area; then it is committed, one durable step at a time
//!    (listed below): the manifest says `committing` with every file's path, size and SHA-256, the
//!    files are renamed into place, the manifest says `finished` — the commit point: readers list files
//!    from the finished stages of the manifest, so they see the whole stage from here on and nothing of
//!    it before — and the staging area is removed. A run killed after any step finishes the commit.
//!
//! The commit steps, as `ANNOTRACE_FAULT=STAGE:commit-step=K` counts them (the fault stops the process
//! after K durable steps), for a stage with `n` staged files: step 1 writes the manifest with status
//! `committing` and every file's size and SHA-256; steps 2 to n + 1 rename one file each into its table
//! folder; step n + 2 writes the manifest with status `finished` (the commit point); step n + 3 removes
//! the staging area.
//!
//! NOTE: the manifest is written before and after every state change, so a run killed at any moment
//! resumes with the same command and never reads a partial file.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicUsize;
use std::time::Instant;

use rayon::prelude::*;
use serde_json::{Map, Value};
use sha2::{Digest, Sha256};

use super::SpecError;
use super::progress::Progress;
use super::spec::PipelineSpec;
use super::stage::{FaultPlan, FaultPoint, Stage, StageContext, StageError};
use crate::digest::hex;
use crate::store::manifest::{
    Manifest, OutputFile, PipelineInfo, StageRecord, StageStatus, now, output_path,
};
use crate::store::verify::{Problem, check_file, check_size, sha256_file};
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
    /// `--finalize` after a sharded run: commit each shardable stage whose slices are all done (an
    /// error names the slices that are not), then run the rest as usual. A shardable stage is never
    /// computed here.
    pub finalize: bool,
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
    /// `--finalize`: a shardable stage's slices are not all done.
    #[error(
        "stage {id}: {missing}; run the missing shards (`annotrace run PIPELINE --shard i/n`), then --finalize again"
    )]
    ShardsUnfinished {
        /// The stage.
        id: String,
        /// Which slices are missing (`slices 1/3, 2/3 not finished`).
        missing: String,
    },
    /// A sharded run waited for an earlier stage that failed.
    #[error("stage {id} cannot run: stage {input} before it failed: {error}")]
    InputFailed {
        /// The waiting stage.
        id: String,
        /// The failed stage.
        input: String,
        /// The input's recorded error.
        error: String,
    },
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
    /// It finished, but an output's size or checksum differs from the manifest's record.
    OutputsDamaged,
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
            RunReason::OutputsDamaged => "outputs damaged",
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
    /// The first missing or damaged output, when that is why it runs again.
    pub damage: Option<String>,
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

/// An error and its causes on one line, joined by `: ` as `{:#}` joins them, leaving out a cause whose
/// text the line already ends with: several library errors (Parquet's, Arrow's, DataFusion's) print
/// their source in their own message and return it as their source too.
pub fn error_chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut out = e.to_string();
    let mut cur = e.source();
    while let Some(s) = cur {
        let text = s.to_string();
        if !out.ends_with(&text) {
            out.push_str(": ");
            out.push_str(&text);
        }
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

pub(super) struct Built {
    pub(super) stages: Vec<Box<dyn Stage>>,
    pub(super) fingerprints: BTreeMap<String, String>,
    pub(super) order: Vec<usize>,
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

pub(super) fn plan_with(
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
            let mut damage = None;
            let action = if selected.as_ref().is_some_and(|s| !s.contains(&def.id)) {
                Action::Skipped
            } else if forced.contains(&def.id) {
                Action::Run(RunReason::Forced)
            } else {
                match manifest.stages.get(&def.id) {
                    None => Action::Run(RunReason::New),
                    Some(r) if r.fingerprint != fp => Action::Run(RunReason::Changed),
                    Some(r) => match r.status {
                        StageStatus::Finished => match first_damaged(run, r) {
                            None => Action::Cached,
                            Some((path, problem)) => {
                                let why = if problem == Problem::Missing {
                                    RunReason::OutputsMissing
                                } else {
                                    RunReason::OutputsDamaged
                                };
                                damage = Some(format!("{path} {problem}"));
                                Action::Run(why)
                            }
                        },
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
                damage,
            }
        })
        .collect()
}

/// The first output of a finished stage that is missing or whose size or SHA-256 differs from the
/// record: a stage is skipped as cached only when every output checks.
fn first_damaged(run: &RunDir, record: &StageRecord) -> Option<(String, Problem)> {
    record.outputs.iter().find_map(|o| {
        check_file(&output_path(run, o), o, true)
            .err()
            .map(|p| (o.path.clone(), p))
    })
}

/// The manifest entry of a file about to be published: its run-relative path, size and SHA-256.
fn output_record(run: &RunDir, read_from: &Path, target: &Path) -> Result<OutputFile, StoreError> {
    let (bytes, sha) = sha256_file(read_from).map_err(|e| StoreError::Io {
        path: read_from.to_path_buf(),
        source: e,
    })?;
    Ok(OutputFile::new(relative(run, target), bytes, sha))
}

/// Counts the durable steps of a commit and stops the process where a `commit-step` fault says.
struct CommitSteps<'a> {
    fault: Option<&'a FaultPlan>,
    stage: &'a str,
    done: usize,
}

impl CommitSteps<'_> {
    /// Fires when the fault asks to stop after `done` steps.
    fn check(&self) -> Result<(), RunError> {
        match self.fault {
            Some(f) if f.stage == self.stage && f.point == FaultPoint::CommitStep(self.done) => {
                Err(RunError::Stage {
                    id: self.stage.to_string(),
                    source: f.trigger(format!(
                        "stage {} stopped after commit step {}",
                        self.stage, self.done
                    )),
                })
            }
            _ => Ok(()),
        }
    }

    /// One more step is durable.
    fn step(&mut self) -> Result<(), RunError> {
        self.done += 1;
        self.check()
    }
}

/// Records checksums for the outputs of finished stages in a format 1 manifest (written before
/// checksums existed), trusting the files as they are, as format 1 did. Returns how many were recorded.
fn record_missing_checksums(run: &RunDir, manifest: &mut Manifest) -> Result<usize, StoreError> {
    let mut n = 0;
    for r in manifest.stages.values_mut() {
        if r.status != StageStatus::Finished {
            continue;
        }
        for o in r.outputs.iter_mut().filter(|o| o.sha256.is_none()) {
            let path = output_path(run, o);
            // A missing or empty file stays unrecorded: the stage is rerun as damaged.
            if check_size(&path, o).is_err() {
                continue;
            }
            let (bytes, sha) =
                sha256_file(&path).map_err(|e| StoreError::Io { path, source: e })?;
            (o.bytes, o.sha256) = (Some(bytes), Some(sha));
            n += 1;
        }
    }
    Ok(n)
}

/// Checks the options, builds every stage with its fingerprint, and finds the run folder.
pub(super) fn prepare(spec: &PipelineSpec, opts: &RunOptions) -> Result<(Built, RunDir), RunError> {
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

/// Called after the manifest records a stage `finished` or `failed` (with the stage's id and the
/// manifest as saved): how a run on object storage publishes each commit (`pipeline::remote`).
pub(super) type OnCommit<'a> = dyn Fn(&str, &Manifest) -> Result<(), RunError> + 'a;

/// Runs a pipeline. A run location `s3://bucket/prefix` runs on a local copy published to the object
/// store stage by stage (feature `s3`, `pipeline::remote`).
pub fn run(
    spec: &PipelineSpec,
    opts: &RunOptions,
    progress: &dyn Progress,
) -> Result<RunReport, RunError> {
    if let Some(url) = remote_location(spec, opts) {
        #[cfg(feature = "s3")]
        return super::remote::run(spec, opts, None, progress, &url);
        #[cfg(not(feature = "s3"))]
        return Err(StoreError::RemoteUnsupported { location: url }.into());
    }
    run_local(spec, opts, progress, None)
}

/// The run location when it is on object storage (`s3://…`).
pub(super) fn remote_location(spec: &PipelineSpec, opts: &RunOptions) -> Option<String> {
    let dir = opts.run_dir.clone().or_else(|| spec.run_dir.clone())?;
    crate::store::remote_url(&dir).map(str::to_string)
}

/// Runs a pipeline in a local run folder, calling `on_commit` after each stage's commit.
pub(super) fn run_local(
    spec: &PipelineSpec,
    opts: &RunOptions,
    progress: &dyn Progress,
    on_commit: Option<&OnCommit<'_>>,
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

    let result = run_locked(spec, opts, progress, &built, &run, on_commit);
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
pub(super) struct Session<'a> {
    pub(super) spec: &'a PipelineSpec,
    pub(super) opts: &'a RunOptions,
    pub(super) progress: &'a dyn Progress,
    pub(super) built: &'a Built,
    pub(super) run: &'a RunDir,
    /// Called after each stage's commit (`None` for a local run).
    pub(super) on_commit: Option<&'a OnCommit<'a>>,
}

fn run_locked(
    spec: &PipelineSpec,
    opts: &RunOptions,
    progress: &dyn Progress,
    built: &Built,
    run: &RunDir,
    on_commit: Option<&OnCommit<'_>>,
) -> Result<RunReport, RunError> {
    let mut manifest = Manifest::load(run)?.unwrap_or_default();
    let format = manifest.format;
    if format < crate::store::manifest::FORMAT && !manifest.stages.is_empty() {
        let n = record_missing_checksums(run, &mut manifest)?;
        manifest.save(run)?;
        progress.note(
            "manifest",
            &format!(
                "format {format} upgraded to {}: sizes and SHA-256 of {n} existing file(s) recorded",
                crate::store::manifest::FORMAT
            ),
        );
    }
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
        on_commit,
    };
    let plan = plan_with(spec, opts, built, run, &manifest);
    let mut reports = Vec::new();
    for (planned, &i) in plan.iter().zip(&built.order) {
        let def = &spec.stages[i];
        match planned.action {
            Action::Skipped => continue,
            Action::Cached => {
                // A run killed after the commit point, before the staging area was removed.
                run.staging(&def.id).remove()?;
                reports.push(session.cached(&def.id, &manifest.stages[&def.id]));
                continue;
            }
            Action::Run(_) => {}
        }
        if let Some(damage) = &planned.damage {
            progress.note(&def.id, &format!("{damage}: running the stage again"));
        }
        let staging = run.staging(&def.id);
        let previous = manifest.stages.get(&def.id).cloned();
        if opts.finalize && built.stages[i].shardable() {
            super::sharded::check_slices(run, &def.id, &planned.fingerprint, previous.as_ref())?;
        }
        let mut resuming = previous.as_ref().is_some_and(|p| {
            p.fingerprint == planned.fingerprint && planned.action == Action::Run(RunReason::Resume)
        });
        if let Some(prev) = previous
            .as_ref()
            .filter(|p| resuming && p.status == StageStatus::Committing)
        {
            match session.finish_commit(&mut manifest, &staging, &def.id, prev)? {
                Some(report) => {
                    reports.push(report);
                    continue;
                }
                // Its files are not all there: the stage runs again from the start.
                None => resuming = false,
            }
        }
        session.reset_staging(&mut manifest, &staging, &def.id, resuming)?;
        reports.push(session.execute(&mut manifest, planned, i, staging)?);
    }
    Ok(RunReport {
        run_dir: run.root().to_path_buf(),
        stages: reports,
    })
}

impl Session<'_> {
    /// A stage killed during its commit: finishes moving its files into place, checks that every
    /// output has its recorded size, and records it finished. `None` when an output is missing or
    /// damaged (the stage must run again).
    pub(super) fn finish_commit(
        &self,
        manifest: &mut Manifest,
        staging: &Staging,
        id: &str,
        prev: &StageRecord,
    ) -> Result<Option<StageReport>, RunError> {
        let (run, progress) = (self.run, self.progress);
        let mut steps = CommitSteps {
            fault: None,
            stage: id,
            done: 0,
        };
        staging.move_into_place(|| steps.step())?;
        if let Some((path, problem)) = prev.outputs.iter().find_map(|o| {
            check_size(&output_path(run, o), o)
                .err()
                .map(|p| (&o.path, p))
        }) {
            progress.note(
                id,
                &format!("interrupted commit cannot be finished: {path} {problem}; running the stage again"),
            );
            return Ok(None);
        }
        let mut rec = prev.clone();
        rec.status = StageStatus::Finished;
        rec.finished = Some(now());
        manifest.stages.insert(id.to_string(), rec.clone());
        manifest.save(run)?;
        self.committed(id, manifest)?;
        staging.remove()?;
        progress.stage_finished(id, "resumed commit");
        Ok(Some(StageReport {
            id: id.to_string(),
            cached: false,
            rows: rec.rows,
            summary: rec.summary,
            seconds: 0.0,
        }))
    }

    /// Tells the `on_commit` hook that stage `id` is recorded finished or failed in `manifest`.
    fn committed(&self, id: &str, manifest: &Manifest) -> Result<(), RunError> {
        match self.on_commit {
            Some(hook) => hook(id, manifest),
            None => Ok(()),
        }
    }

    /// Prepares the staging folder: a resumed stage keeps its finished shards, any other starts empty.
    /// Outputs of an earlier attempt are unpublished first (the manifest records the stage `running`,
    /// still listing them), then deleted, so a reader never sees a finished stage with files missing.
    pub(super) fn reset_staging(
        &self,
        manifest: &mut Manifest,
        staging: &Staging,
        id: &str,
        resuming: bool,
    ) -> Result<(), RunError> {
        let (run, progress) = (self.run, self.progress);
        if let Some(prev) = manifest
            .stages
            .get_mut(id)
            .filter(|p| !p.outputs.is_empty())
        {
            if prev.status != StageStatus::Running {
                prev.status = StageStatus::Running;
                manifest.save(run)?;
            }
            let prev = &manifest.stages[id];
            let files: Vec<PathBuf> = prev.outputs.iter().map(|o| output_path(run, o)).collect();
            remove_files(&files)?;
        }
        if resuming {
            let dropped = staging.discard_unfinished()?;
            progress.note(
                id,
                &format!("resuming: finished shards kept, {dropped} partial file(s) dropped"),
            );
        } else {
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
        let record = self.begin(manifest, planned, i)?;
        self.run_and_commit(manifest, record, i, staging)
    }

    /// Records stage number `i` `running` with its fingerprint (a fresh record) and returns it.
    pub(super) fn begin(
        &self,
        manifest: &mut Manifest,
        planned: &PlannedStage,
        i: usize,
    ) -> Result<StageRecord, RunError> {
        let def = &self.spec.stages[i];
        let record = StageRecord {
            kind: def.kind.name.to_string(),
            status: StageStatus::Running,
            fingerprint: planned.fingerprint.clone(),
            params: Value::Object(def.params.clone()),
            inputs: def.inputs.clone(),
            seed: self.spec.seed,
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
        manifest.save(self.run)?;
        Ok(record)
    }

    /// The context stage number `i` runs in; `slice` when this process computes one slice of it.
    pub(super) fn context(
        &self,
        i: usize,
        staging: Staging,
        slice: Option<super::sharded::Slice>,
    ) -> StageContext<'_> {
        let def = &self.spec.stages[i];
        StageContext {
            run: self.run,
            stage_id: &def.id,
            seed: self.spec.seed,
            project_dir: &self.spec.project_dir,
            staging,
            progress: self.progress,
            fault: self.opts.fault.as_ref(),
            shards_finished: AtomicUsize::new(0),
            shards_started: AtomicUsize::new(0),
            slice,
        }
    }

    /// Which of the stages `earlier` (indices) a sharded stage `i` still waits for in `manifest`:
    /// those not finished under their current fingerprint; an error when one of them failed.
    pub(super) fn unfinished(
        &self,
        manifest: &Manifest,
        i: usize,
        earlier: &[usize],
    ) -> Result<Vec<usize>, RunError> {
        let mut pending = Vec::new();
        for &e in earlier {
            let input = &self.spec.stages[e].id;
            let fp = &self.built.fingerprints[input];
            match manifest.stages.get(input) {
                Some(r) if &r.fingerprint == fp && r.status == StageStatus::Finished => {}
                Some(r) if &r.fingerprint == fp && r.status == StageStatus::Failed => {
                    return Err(RunError::InputFailed {
                        id: self.spec.stages[i].id.clone(),
                        input: input.clone(),
                        error: r.error.clone().unwrap_or_default(),
                    });
                }
                _ => pending.push(e),
            }
        }
        Ok(pending)
    }

    /// The report of a stage found finished in the manifest (`record`), announced as cached.
    pub(super) fn cached(&self, id: &str, record: &StageRecord) -> StageReport {
        self.progress.stage_cached(id);
        StageReport {
            id: id.to_string(),
            cached: true,
            rows: record.rows.clone(),
            summary: record.summary.clone(),
            seconds: 0.0,
        }
    }

    /// The plan line of stage number `i` against `manifest`.
    pub(super) fn planned(&self, manifest: &Manifest, i: usize) -> PlannedStage {
        let pos = self
            .built
            .order
            .iter()
            .position(|&j| j == i)
            .expect("every stage is in the order");
        plan_with(self.spec, self.opts, self.built, self.run, manifest)
            .into_iter()
            .nth(pos)
            .expect("one plan line per stage")
    }

    /// Computes `slice` of stage number `i` into `staging` (a shard's share of a shardable stage),
    /// announcing it on the progress display; the caller records the slice done.
    pub(super) fn run_slice(
        &self,
        i: usize,
        staging: &Staging,
        slice: super::sharded::Slice,
    ) -> Result<(), RunError> {
        let def = &self.spec.stages[i];
        self.progress
            .note(&def.id, &format!("computing slice {slice}"));
        self.progress.stage_started(&def.id, def.kind.name, None);
        let ctx = self.context(i, staging.clone(), Some(slice));
        self.built.stages[i]
            .run(&ctx)
            .map(drop)
            .map_err(|source| RunError::Stage {
                id: def.id.clone(),
                source,
            })
    }

    /// Runs stage number `i` (recorded `running` as `record`) over its whole work list and commits its
    /// outputs, recording each step in the manifest. A stage whose units were computed by shards only
    /// computes what no slice owns and sums the shards' records here.
    pub(super) fn run_and_commit(
        &self,
        manifest: &mut Manifest,
        mut record: StageRecord,
        i: usize,
        staging: Staging,
    ) -> Result<StageReport, RunError> {
        let Session {
            spec,
            opts,
            progress,
            built,
            run,
            ..
        } = *self;
        let def = &spec.stages[i];
        let started = Instant::now();
        let ctx = self.context(i, staging.clone(), None);
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
                self.committed(&def.id, manifest)?;
                return Err(RunError::Stage {
                    id: def.id.clone(),
                    source,
                });
            }
        };

        // The commit (its steps are listed in the module doc). NOTE: the file list, with sizes and
        // checksums, is recorded before the move, so that a crash during the move can finish it; the
        // stage is published only by the manifest that says `finished`.
        let mut steps = CommitSteps {
            fault: opts.fault.as_ref(),
            stage: &def.id,
            done: 0,
        };
        steps.check()?;
        // Sizes and checksums of the staged files, read on every core (a billiards stage of 2,000
        // traces stages 100 files, 142 MB): in file order, so the manifest is the same.
        let mut outputs = staging
            .pending()?
            .par_iter()
            .map(|(staged, target)| output_record(run, staged, target))
            .collect::<Result<Vec<_>, _>>()?;
        for f in &output.files {
            let f = if f.is_absolute() || f.starts_with(run.root()) {
                f.clone()
            } else {
                run.root().join(f)
            };
            outputs.push(output_record(run, &f, &f)?);
        }
        record.status = StageStatus::Committing;
        record.outputs = outputs;
        record.rows = output.rows.clone();
        record.summary = output.summary.clone();
        manifest.stages.insert(def.id.clone(), record.clone());
        manifest.save(run)?;
        steps.step()?;
        staging.move_into_place(|| steps.step())?;
        let seconds = started.elapsed().as_secs_f64();
        record.status = StageStatus::Finished;
        record.finished = Some(now());
        record.seconds = Some(seconds);
        manifest.stages.insert(def.id.clone(), record);
        manifest.save(run)?;
        self.committed(&def.id, manifest)?;
        steps.step()?;
        staging.remove()?;
        steps.step()?;
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
