//! Runs on object storage (`--run-dir s3://bucket/prefix`, cargo feature `s3`): the commit protocol
//! for a store that has neither rename nor locks (`docs/pipelines.md`, "Runs on object storage").
//!
//! **Owns:** running a pipeline (whole, `--finalize`, or one `--shard i/n`) on a local copy of a
//! remote run and publishing what it commits: each stage's files as immutable, content-addressed
//! objects first, then the manifest with a conditional put (`If-Match` on the ETag it was read with,
//! `If-None-Match: *` for a new run), so that the manifest write is the single commit point and two
//! writers cannot both commit on the same version. **Does not:** compute stages or decide what is
//! cached (the runner's steps, reused as they are), or talk to the store (`store::remote`).
//!
//! - A whole run (also `--finalize` and one-stage commands such as `annotate`): the run is pulled
//!   into a local mirror (manifest and published files), the ordinary runner runs there, and after
//!   each stage's commit its files are uploaded and the mirror's manifest is put with `If-Match` on the
//!   previous ETag. A concurrent writer makes that put fail: the process stops with
//!   [`StoreError::Conflict`] and nothing of it is published.
//! - A shard (`--shard i/n`): the stages are those of a local sharded run; a shardable stage's slice is
//!   computed in the mirror and uploaded under `.staging/<stage>/<fp16>/parts/`, then the slice's
//!   record `_slices/<i>-of-<n>.json` is created with `If-None-Match: *` (the slice's commit point: a
//!   second process given the same index loses there, with a clear error). The process that finds
//!   every slice recorded downloads them, runs the runner's commit and merges the stage's record into
//!   the manifest (read, change one stage, put with `If-Match`; retried on a conflict, and left alone
//!   when another process committed the stage first). Stages wait for the earlier ones by polling the
//!   manifest. Unlike a local run, a waiting shard does not compute another shard's slice (a store has
//!   no lock telling whether that shard is alive): all `n` processes must be able to run at once.

use std::cell::RefCell;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::progress::Progress;
use super::runner::{
    Action, Built, RunError, RunOptions, RunReport, Session, StageReport, prepare, run_local,
};
use super::sharded::{POLL, Slice, missing_slices, shard_stages};
use super::spec::PipelineSpec;
use crate::store::StoreError;
use crate::store::manifest::{Manifest, PipelineInfo, StageRecord, StageStatus, now};
use crate::store::remote::{Mirror, RemoteRun, object_name, walk};
use crate::store::verify::sha256_file;

/// How often a merge of one stage's record into the manifest is retried after losing to another
/// writer before giving up.
const MERGE_ATTEMPTS: usize = 200;

/// One file of a committed slice, as its record lists it.
#[derive(Debug, Serialize, Deserialize)]
struct SliceFile {
    /// Its path inside the stage's staging area.
    path: String,
    bytes: u64,
    sha256: String,
}

/// `_slices/<i>-of-<n>.json`: a slice of a stage, committed.
#[derive(Debug, Serialize, Deserialize)]
struct SliceRecord {
    index: usize,
    count: usize,
    fingerprint: String,
    files: Vec<SliceFile>,
}

/// Runs a pipeline on the remote run `url`: whole (`slice` `None`, also `--finalize`) or one slice.
pub(super) fn run(
    spec: &PipelineSpec,
    opts: &RunOptions,
    slice: Option<Slice>,
    progress: &dyn Progress,
    url: &str,
) -> Result<RunReport, RunError> {
    let remote = RemoteRun::open(url)?;
    let mirror = remote.mirror()?;
    let mut local = opts.clone();
    local.run_dir = Some(mirror.path().to_path_buf());
    // Nothing is created remotely before a stage commits.
    local.remove_new_run_on_failure = false;
    let result = match slice {
        Some(slice) => run_slice(spec, &local, slice, progress, &remote, &mirror),
        None => run_whole(spec, &local, progress, &remote, &mirror),
    };
    // LLM calls recorded before a failure are kept, as in a local run.
    let journal = remote.push_journal(mirror.path());
    let mut report = result?;
    journal?;
    report.run_dir = PathBuf::from(remote.url());
    Ok(report)
}

/// The whole pipeline on a mirror, each commit published with `If-Match` on the last ETag.
fn run_whole(
    spec: &PipelineSpec,
    opts: &RunOptions,
    progress: &dyn Progress,
    remote: &RemoteRun,
    mirror: &Mirror,
) -> Result<RunReport, RunError> {
    let root = mirror.path();
    if opts.finalize {
        commit_finished_slices(spec, opts, progress, remote, root)?;
    }
    let pulled = remote.pull(root)?;
    let pushed: RefCell<BTreeSet<String>> = RefCell::new(
        pulled
            .iter()
            .flat_map(|(m, _)| m.published())
            .map(|(_, o)| o.path.clone())
            .collect(),
    );
    let etag = RefCell::new(pulled.map(|(_, e)| e));
    let publish = |_: &str, manifest: &Manifest| -> Result<(), RunError> {
        for (_, o) in manifest.published() {
            if pushed.borrow_mut().insert(o.path.clone()) {
                remote.push_output(root, o)?;
            }
        }
        remote.push_journal(root)?;
        let path = root.join("manifest.json");
        let bytes = std::fs::read(&path).map_err(|e| StoreError::io(&path, e))?;
        let new = remote.put_manifest(bytes, etag.borrow().as_deref())?;
        *etag.borrow_mut() = Some(new);
        Ok(())
    };
    let report = run_local(spec, opts, progress, Some(&publish))?;
    if opts.finalize {
        // The shards are done: what no manifest names (committed stages' slices, a killed or losing
        // writer's uploads, superseded versions) is removed.
        let orphans = remote.orphans()?;
        if !orphans.is_empty() {
            remote.delete(&orphans)?;
            progress.note(
                "finalize",
                &format!("{} object(s) no manifest names removed", orphans.len()),
            );
        }
    }
    Ok(report)
}

/// `--finalize`: commits every shardable stage whose slices are all recorded and that no shard
/// committed; a stage started by shards with slices missing is an error naming them.
fn commit_finished_slices(
    spec: &PipelineSpec,
    opts: &RunOptions,
    progress: &dyn Progress,
    remote: &RemoteRun,
    root: &Path,
) -> Result<(), RunError> {
    let (built, run) = prepare(spec, opts)?;
    let merge = |id: &str, m: &Manifest| merge_hook(remote, root, spec, opts, id, m);
    let ctx = Remote {
        session: Session {
            spec,
            opts,
            progress,
            built: &built,
            run: &run,
            on_commit: Some(&merge),
        },
        remote,
        root,
    };
    let selected = opts.until.as_ref().map(|u| spec.upstream(u));
    for &i in &built.order {
        let id = &spec.stages[i].id;
        if !built.stages[i].shardable() || selected.as_ref().is_some_and(|s| !s.contains(id)) {
            continue;
        }
        let fp = &built.fingerprints[id];
        let record = remote
            .load_manifest()?
            .and_then(|(m, _, _)| m.stages.get(id).cloned());
        // A stage finished, or never started by a shard (the runner's --finalize check says so), is
        // left as it is.
        let running =
            record.is_some_and(|r| &r.fingerprint == fp && r.status == StageStatus::Running);
        if running && ctx.try_commit(i, fp)?.is_none() {
            let done = ctx.slices_done(id, fp)?;
            return Err(RunError::ShardsUnfinished {
                id: id.clone(),
                missing: missing_slices(&done)
                    .unwrap_or_else(|| "its commit did not complete".into()),
            });
        }
    }
    Ok(())
}

/// The `on_commit` hook of a shard process: merges the stage's record into the remote manifest.
fn merge_hook(
    remote: &RemoteRun,
    root: &Path,
    spec: &PipelineSpec,
    opts: &RunOptions,
    id: &str,
    manifest: &Manifest,
) -> Result<(), RunError> {
    let record = manifest.stages[id].clone();
    if record.status == StageStatus::Finished {
        for o in &record.outputs {
            remote.push_output(root, o)?;
        }
    }
    let fp = record.fingerprint.clone();
    merge_record(remote, spec, opts, id, record, |r| {
        r.fingerprint == fp && r.status == StageStatus::Finished
    })?;
    Ok(())
}

/// Sets stage `id`'s record in the remote manifest to `record` unless the record there already
/// satisfies `keep` (another process got there first): read the manifest with its ETag, change the one
/// stage, put it with `If-Match` (`If-None-Match: *` when there is none), and start over when another
/// writer won. Returns the record the manifest holds afterwards.
fn merge_record(
    remote: &RemoteRun,
    spec: &PipelineSpec,
    opts: &RunOptions,
    id: &str,
    record: StageRecord,
    keep: impl Fn(&StageRecord) -> bool,
) -> Result<StageRecord, RunError> {
    for attempt in 0..MERGE_ATTEMPTS {
        let (mut m, etag) = match remote.load_manifest()? {
            Some((m, _, e)) => (m, Some(e)),
            None => (Manifest::new(), None),
        };
        if let Some(r) = m.stages.get(id).filter(|r| keep(r)) {
            return Ok(r.clone());
        }
        if opts.record_pipeline && m.pipeline.is_none() {
            m.pipeline = Some(PipelineInfo {
                name: spec.name.clone(),
                file: spec.file.to_string_lossy().into_owned(),
                sha256: spec.sha256.clone(),
                seed: spec.seed,
            });
        }
        m.stages.insert(id.to_string(), record.clone());
        match remote.put_manifest(m.to_bytes(), etag.as_deref()) {
            Ok(_) => return Ok(record),
            Err(StoreError::Conflict { .. }) => {
                // Another writer committed in between: read its manifest and try again.
                std::thread::sleep(std::time::Duration::from_millis(
                    20 + 10 * attempt as u64 % 200,
                ));
            }
            Err(e) => return Err(e.into()),
        }
    }
    Err(StoreError::Conflict {
        location: remote.url().to_string(),
        message: format!(
            "stage {id}: the manifest changed under every one of {MERGE_ATTEMPTS} attempts to record it"
        ),
    }
    .into())
}

/// What the shard steps share.
struct Remote<'a> {
    session: Session<'a>,
    remote: &'a RemoteRun,
    root: &'a Path,
}

/// The key prefix of a stage's slices: `.staging/<stage>/<first 16 hex digits of the fingerprint>/`.
fn slices_prefix(id: &str, fp: &str) -> String {
    format!(".staging/{id}/{}/", &fp[..16.min(fp.len())])
}

/// `<i>-of-<n>.json` → (i, n).
fn parse_slice_name(name: &str) -> Option<(usize, usize)> {
    let (i, n) = name.strip_suffix(".json")?.split_once("-of-")?;
    Some((i.parse().ok()?, n.parse().ok()?))
}

/// One `--shard i/n` process on a remote run.
fn run_slice(
    spec: &PipelineSpec,
    opts: &RunOptions,
    slice: Slice,
    progress: &dyn Progress,
    remote: &RemoteRun,
    mirror: &Mirror,
) -> Result<RunReport, RunError> {
    let root = mirror.path();
    let (built, run) = prepare(spec, opts)?;
    let merge = |id: &str, m: &Manifest| merge_hook(remote, root, spec, opts, id, m);
    let ctx = Remote {
        session: Session {
            spec,
            opts,
            progress,
            built: &built,
            run: &run,
            on_commit: Some(&merge),
        },
        remote,
        root,
    };
    let stages = shard_stages(spec, opts, &built);
    let mut reports = Vec::new();
    for (k, &i) in stages.iter().enumerate() {
        ctx.wait_for(i, &stages[..k], slice)?;
        remote.pull(root)?;
        let report = if built.stages[i].shardable() {
            ctx.slice_stage(i, slice)?
        } else {
            ctx.whole_stage(i)?
        };
        reports.push(report);
    }
    Ok(RunReport {
        run_dir: root.to_path_buf(),
        stages: reports,
    })
}

impl Remote<'_> {
    fn built(&self) -> &Built {
        self.session.built
    }

    fn id(&self, i: usize) -> &str {
        &self.session.spec.stages[i].id
    }

    fn local_manifest(&self) -> Result<Manifest, RunError> {
        Ok(Manifest::load(self.session.run)?.unwrap_or_default())
    }

    /// An unshardable stage a shardable one needs: computed here and merged into the manifest unless
    /// another shard committed it first (then the next pull brings its files).
    fn whole_stage(&self, i: usize) -> Result<StageReport, RunError> {
        let s = &self.session;
        let id = self.id(i).to_string();
        let mut manifest = self.local_manifest()?;
        let planned = self.session.planned(&manifest, i);
        if planned.action == Action::Cached {
            return Ok(self.session.cached(&id, &manifest.stages[&id]));
        }
        let staging = s.run.staging(&id);
        s.reset_staging(&mut manifest, &staging, &id, false)?;
        let record = s.begin(&mut manifest, &planned, i)?;
        s.run_and_commit(&mut manifest, record, i, staging)
    }

    /// The slices of stage `id` (fingerprint `fp`) recorded in the store.
    fn slices_done(&self, id: &str, fp: &str) -> Result<Vec<(usize, usize)>, RunError> {
        let dir = format!("{}_slices/", slices_prefix(id, fp));
        let mut out: Vec<(usize, usize)> = self
            .remote
            .list(&dir)?
            .iter()
            .filter_map(|k| parse_slice_name(k.rsplit('/').next().unwrap_or_default()))
            .collect();
        out.sort();
        Ok(out)
    }

    /// Stage `i`: started in the manifest if no shard has, this process's slice computed and
    /// recorded unless it is, committed if that completes it.
    fn slice_stage(&self, i: usize, slice: Slice) -> Result<StageReport, RunError> {
        let s = &self.session;
        let id = self.id(i).to_string();
        let mut manifest = self.local_manifest()?;
        let planned = self.session.planned(&manifest, i);
        if planned.action == Action::Cached {
            return Ok(self.session.cached(&id, &manifest.stages[&id]));
        }
        let fp = planned.fingerprint.clone();
        // Start: record it `running` (unpublishing an older version) unless a shard has.
        let fresh = s.begin(&mut manifest, &planned, i)?;
        let record = merge_record(self.remote, s.spec, s.opts, &id, fresh, |r| {
            r.fingerprint == fp && matches!(r.status, StageStatus::Running | StageStatus::Finished)
        })?;
        if record.status == StageStatus::Finished {
            self.remote.pull(self.root)?;
            return Ok(self.session.cached(&id, &record));
        }
        manifest.stages.insert(id.clone(), record);
        manifest.save(s.run)?;
        if self
            .slices_done(&id, &fp)?
            .contains(&(slice.index, slice.count))
        {
            s.progress
                .note(&id, &format!("slice {slice} is recorded done already"));
        } else {
            self.compute_slice(i, &fp, slice)?;
        }
        let committed = self.try_commit(i, &fp)?;
        Ok(committed.unwrap_or_else(|| StageReport {
            id: id.clone(),
            cached: false,
            rows: Default::default(),
            summary: serde_json::Value::Null,
            seconds: 0.0,
        }))
    }

    /// Computes `slice` of stage `i` in the mirror, uploads its files and creates its record.
    fn compute_slice(&self, i: usize, fp: &str, slice: Slice) -> Result<(), RunError> {
        let s = &self.session;
        let def = &s.spec.stages[i];
        let staging = s.run.staging(&def.id);
        staging.remove()?;
        s.run_slice(i, &staging, slice)?;
        let prefix = slices_prefix(&def.id, fp);
        let mut files = Vec::new();
        for file in walk(staging.dir())? {
            let rel = file
                .strip_prefix(staging.dir())
                .expect("walked below the staging area")
                .to_string_lossy()
                .replace('\\', "/");
            // Scratch files and the local slice records are not part of the slice.
            if rel.starts_with("_spill/") || rel.starts_with("_slices/") {
                continue;
            }
            let (bytes, sha256) = sha256_file(&file).map_err(|e| StoreError::io(&file, e))?;
            self.remote.upload(
                &file,
                &format!("{prefix}parts/{}", object_name(&rel, Some(&sha256))),
            )?;
            files.push(SliceFile {
                path: rel,
                bytes,
                sha256,
            });
        }
        let record = SliceRecord {
            index: slice.index,
            count: slice.count,
            fingerprint: fp.to_string(),
            files,
        };
        let key = format!("{prefix}_slices/{}-of-{}.json", slice.index, slice.count);
        let body = serde_json::to_vec_pretty(&record).expect("a slice record serialises");
        if !self.remote.put_new(&key, body)? {
            return Err(StoreError::Conflict {
                location: self.remote.url().to_string(),
                message: format!(
                    "stage {}: slice {slice} was committed by another process while this one computed it \
                     (the same --shard index given twice?); that process's slice is kept, this one's was not published",
                    def.id
                ),
            }
            .into());
        }
        staging.remove()?;
        s.progress
            .stage_finished(&def.id, &format!("slice {slice} done"));
        Ok(())
    }

    /// Commits stage `i` if every slice of it is recorded and the manifest has it `running` with `fp`:
    /// downloads the slices into the mirror's staging area, runs the runner's commit there and merges
    /// the record (a stage another process committed first is left as it is).
    fn try_commit(&self, i: usize, fp: &str) -> Result<Option<StageReport>, RunError> {
        let s = &self.session;
        let id = self.id(i).to_string();
        let done = self.slices_done(&id, fp)?;
        if missing_slices(&done).is_some() {
            return Ok(None);
        }
        let Some(running) = self
            .remote
            .load_manifest()?
            .and_then(|(m, _, _)| m.stages.get(&id).cloned())
            .filter(|r| r.fingerprint == fp && r.status == StageStatus::Running)
        else {
            return Ok(None);
        };
        // The complete count: each unit's files come from exactly one slice of it.
        let count = done
            .iter()
            .map(|&(_, n)| n)
            .find(|&n| (0..n).all(|k| done.contains(&(k, n))))
            .expect("missing_slices found a complete count");
        self.remote.pull(self.root)?;
        let staging = s.run.staging(&id);
        staging.remove()?;
        if let Err(e) = self.fetch_slices(&id, fp, count, &staging) {
            // Another process committed the stage meanwhile and `--finalize` removed its slices.
            let committed = self
                .remote
                .load_manifest()?
                .and_then(|(m, _, _)| m.stages.get(&id).cloned())
                .is_some_and(|r| r.fingerprint == fp && r.status == StageStatus::Finished);
            return if committed { Ok(None) } else { Err(e) };
        }
        s.progress
            .note(&id, &format!("every slice of {count} is done: committing"));
        let mut manifest = self.local_manifest()?;
        let mut record = running;
        record.started = Some(now());
        manifest.stages.insert(id.clone(), record.clone());
        manifest.save(s.run)?;
        s.run_and_commit(&mut manifest, record, i, staging)
            .map(Some)
    }

    /// Downloads the files of slices 0..`count` of stage `id` into its staging area.
    fn fetch_slices(
        &self,
        id: &str,
        fp: &str,
        count: usize,
        staging: &crate::store::Staging,
    ) -> Result<(), RunError> {
        let prefix = slices_prefix(id, fp);
        for index in 0..count {
            let key = format!("{prefix}_slices/{index}-of-{count}.json");
            let body = self.remote.get(&key)?.ok_or_else(|| StoreError::Remote {
                location: format!("{}/{key}", self.remote.url()),
                message: "listed but not found".into(),
            })?;
            let rec: SliceRecord =
                serde_json::from_slice(&body).map_err(|source| StoreError::Json {
                    path: PathBuf::from(format!("{}/{key}", self.remote.url())),
                    source,
                })?;
            for f in &rec.files {
                self.remote.fetch(
                    &format!("{prefix}parts/{}", object_name(&f.path, Some(&f.sha256))),
                    Some(&f.sha256),
                    Some(f.bytes),
                    &staging.dir().join(&f.path),
                )?;
            }
        }
        Ok(())
    }

    /// Waits until every stage before stage `i` in the run order (`earlier`) is finished in the
    /// remote manifest, committing meanwhile those whose slices are all recorded; fails when one of
    /// them failed.
    fn wait_for(&self, i: usize, earlier: &[usize], slice: Slice) -> Result<(), RunError> {
        let s = &self.session;
        let def = &s.spec.stages[i];
        let mut noted = false;
        loop {
            let manifest = self
                .remote
                .load_manifest()?
                .map(|(m, _, _)| m)
                .unwrap_or_default();
            let pending = s.unfinished(&manifest, i, earlier)?;
            if pending.is_empty() {
                return Ok(());
            }
            let mut progressed = false;
            for &j in &pending {
                if self.built().stages[j].shardable() {
                    let fp = self.built().fingerprints[self.id(j)].clone();
                    progressed |= self.try_commit(j, &fp)?.is_some();
                }
            }
            if !progressed {
                if !noted {
                    noted = true;
                    let names: Vec<&str> = pending.iter().map(|&j| self.id(j)).collect();
                    s.progress.note(
                        &def.id,
                        &format!(
                            "shard {slice}: waiting for stage(s) {} (other shards' slices)",
                            names.join(", ")
                        ),
                    );
                }
                std::thread::sleep(POLL);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slice_names_parse() {
        assert_eq!(parse_slice_name("2-of-3.json"), Some((2, 3)));
        assert_eq!(parse_slice_name("x-of-3.json"), None);
        assert_eq!(parse_slice_name("2-of-3.tmp"), None);
        assert_eq!(
            slices_prefix("sim", "0123456789abcdef0123"),
            ".staging/sim/0123456789abcdef/"
        );
    }
}
