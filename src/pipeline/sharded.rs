//! Sharded runs: one pipeline computed by `n` separate processes over one shared run folder
//! (`annotrace run PIPELINE --shard i/n`, then `--finalize`), as a Slurm job array, a Kubernetes
//! Indexed Job or GNU parallel start them.
//!
//! **Owns:** [`Slice`] (which units of a stage's deterministic work list a process computes), the shard
//! runner ([`run_shard`]: starting a stage, computing a slice, waiting for inputs, taking over the
//! slice of a shard that is not running, the commit by the shard that completes a stage) and the
//! check `--finalize` makes ([`check_slices`]). **Does not:** cut a stage's work into units (each
//! shardable stage does, [`Stage::shardable`](super::Stage::shardable)), or commit (the runner's steps,
//! reused as they are).
//!
//! The protocol (`docs/pipelines.md`, "Sharded runs"):
//! - a unit named `NNNNN…` belongs to slice `NNNNN mod n`; its files are named after the unit, so
//!   the union of the slices' files is the unsharded run's files, byte for byte, whatever `n`;
//! - each process holds `<run>/.shards/<i>-of-<n>.lock` while it lives: a second process given the same
//!   index waits for the first; a process waiting for an input stage computes the slices of processes
//!   that do not hold their lock (not started yet, or dead), so `n` larger than the number of processes
//!   that can run at once never deadlocks;
//! - the manifest is written only under the run's `.lock`, held for one short step at a time: the first
//!   shard to reach a stage records it `running` (unpublishing an older version of it), the shard that
//!   finds every slice of it done commits it (the runner's commit steps; a second committer finds it
//!   `finished` and does nothing), and unshardable stages before a shardable one run whole under the
//!   lock, once (resuming from the finished shards of an attempt that died, as an unsharded run does);
//! - a stage waits until every stage before it in the run order is `finished` (polling the manifest),
//!   so each stage sees the run the single-process run would show it — except sibling stages that
//!   [run beside each other](super::Stage::runs_beside_siblings) (independent `evolve` searches): they
//!   are computed at the same time by the slices that own them, and committed in run order;
//! - stages after the last shardable one (SQL, exports, plots, reports) are left to `--finalize`, an
//!   ordinary run that refuses to compute a shardable stage whose slices are missing.

use std::collections::BTreeSet;
use std::fs;
use std::path::Path;
use std::time::Duration;

use super::progress::Progress;
use super::runner::{
    Action, Built, RunError, RunOptions, RunReason, RunReport, Session, StageReport, prepare,
};
use super::spec::PipelineSpec;
use crate::store::manifest::{Manifest, StageRecord, StageStatus, now};
use crate::store::{RunDir, StoreError};

/// How often a waiting shard reads the manifest again.
pub(super) const POLL: Duration = Duration::from_millis(500);

/// Slice `index` of `count`: the units of a stage's work list whose index is `index` modulo `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Slice {
    /// 0-based index, below `count`.
    pub index: usize,
    /// How many slices the work is cut into.
    pub count: usize,
}

impl Slice {
    /// Slice `index` of `count`; an error unless `count` ≥ 1 and `index` < `count`.
    pub fn new(index: usize, count: usize) -> Result<Self, String> {
        if count == 0 {
            return Err("the shard count must be at least 1".into());
        }
        if index >= count {
            return Err(format!(
                "shard index {index} is out of range for {count} shard(s) (0 to {})",
                count - 1
            ));
        }
        Ok(Slice { index, count })
    }

    /// Whether the unit named `unit` belongs to this slice: its leading decimal number modulo
    /// `count` is `index`. A name without one (`detectors`) belongs to no slice.
    pub fn owns(&self, unit: &str) -> bool {
        unit_index(unit).is_some_and(|u| u % self.count as u64 == self.index as u64)
    }
}

impl std::fmt::Display for Slice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl std::str::FromStr for Slice {
    type Err = String;

    /// `i/n`, 0-based.
    fn from_str(s: &str) -> Result<Self, String> {
        let usage = || format!("bad shard {s:?}: expected i/n with 0 <= i < n, e.g. 0/4");
        let (i, n) = s.split_once('/').ok_or_else(usage)?;
        let i: usize = i.trim().parse().map_err(|_| usage())?;
        let n: usize = n.trim().parse().map_err(|_| usage())?;
        Slice::new(i, n)
    }
}

/// The unit index of a unit name: its leading decimal digits (`00042` → 42, `00003-00001` → 3).
fn unit_index(unit: &str) -> Option<u64> {
    let digits: &str = &unit[..unit
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(unit.len())];
    digits.parse().ok()
}

/// An exclusive lock on a file, held until dropped (released by the OS if the process dies).
struct FileLock {
    _file: fs::File,
}

impl FileLock {
    /// Opens (creating) `path` and locks it; `wait` blocks until it is free, otherwise `None` when
    /// another process holds it.
    fn acquire(path: &Path, wait: bool) -> Result<Option<Self>, StoreError> {
        if let Some(dir) = path.parent() {
            fs::create_dir_all(dir).map_err(|e| StoreError::io(dir, e))?;
        }
        let file = fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(path)
            .map_err(|e| StoreError::io(path, e))?;
        if wait {
            file.lock().map_err(|e| StoreError::io(path, e))?;
            Ok(Some(FileLock { _file: file }))
        } else {
            match file.try_lock() {
                Ok(()) => Ok(Some(FileLock { _file: file })),
                Err(fs::TryLockError::WouldBlock) => Ok(None),
                Err(fs::TryLockError::Error(e)) => Err(StoreError::io(path, e)),
            }
        }
    }
}

fn slice_lock_path(run: &RunDir, slice: Slice) -> std::path::PathBuf {
    run.root()
        .join(".shards")
        .join(format!("{}-of-{}.lock", slice.index, slice.count))
}

/// `--finalize`: fails unless the shardable stage `id` (fingerprint `fp`, manifest record `record`)
/// is finished, being committed, or `running` with every slice of some count done.
pub(super) fn check_slices(
    run: &RunDir,
    id: &str,
    fp: &str,
    record: Option<&StageRecord>,
) -> Result<(), RunError> {
    let same = record.filter(|r| r.fingerprint == fp);
    match same.map(|r| r.status) {
        Some(StageStatus::Finished | StageStatus::Committing) => return Ok(()),
        Some(StageStatus::Running) => {}
        _ => {
            return Err(RunError::ShardsUnfinished {
                id: id.to_string(),
                missing: "no shard has started it".into(),
            });
        }
    }
    let done = run.staging(id).slices_done(fp)?;
    match missing_slices(&done) {
        None => Ok(()),
        Some(missing) => Err(RunError::ShardsUnfinished {
            id: id.to_string(),
            missing,
        }),
    }
}

/// `None` when the slices done (index, count) cover every index of some count; otherwise which are
/// missing, for the count with the most done.
pub(super) fn missing_slices(done: &[(usize, usize)]) -> Option<String> {
    let counts: BTreeSet<usize> = done.iter().map(|&(_, n)| n).collect();
    let mut best: Option<(usize, Vec<usize>)> = None;
    for n in counts {
        let have: BTreeSet<usize> = done
            .iter()
            .filter(|&&(_, c)| c == n)
            .map(|&(i, _)| i)
            .collect();
        let missing: Vec<usize> = (0..n).filter(|i| !have.contains(i)).collect();
        if missing.is_empty() {
            return None;
        }
        if best.as_ref().is_none_or(|(_, m)| missing.len() < m.len()) {
            best = Some((n, missing));
        }
    }
    Some(match best {
        None => "no slice is finished".into(),
        Some((n, missing)) => format!(
            "slice(s) {} not finished",
            missing
                .iter()
                .map(|i| format!("{i}/{n}"))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    })
}

/// The stages a shard process runs, in run order: every selected stage up to the last selected
/// shardable one (unshardable ones run whole, once, by whichever shard gets there first). The rest is
/// left to `--finalize`.
pub(super) fn shard_stages(spec: &PipelineSpec, opts: &RunOptions, built: &Built) -> Vec<usize> {
    let selected = opts.until.as_ref().map(|u| spec.upstream(u));
    let in_run: Vec<usize> = built
        .order
        .iter()
        .copied()
        .filter(|&i| {
            selected
                .as_ref()
                .is_none_or(|s| s.contains(&spec.stages[i].id))
        })
        .collect();
    let last = in_run.iter().rposition(|&i| built.stages[i].shardable());
    match last {
        Some(last) => in_run[..=last].to_vec(),
        None => Vec::new(),
    }
}

/// One shard process.
struct Shard<'a> {
    session: Session<'a>,
    slice: Slice,
    /// The stages it runs, in run order ([`shard_stages`]).
    stages: Vec<usize>,
    /// Whether this process wrote the "waiting" note for the current stage.
    waiting_noted: std::cell::Cell<bool>,
}

/// Runs slice `slice` of every shardable stage of a pipeline (and the unshardable stages they need)
/// into the shared run folder; see the module documentation for the protocol.
pub fn run_shard(
    spec: &PipelineSpec,
    opts: &RunOptions,
    slice: Slice,
    progress: &dyn Progress,
) -> Result<RunReport, RunError> {
    if let Some(url) = super::runner::remote_location(spec, opts) {
        #[cfg(feature = "s3")]
        return super::remote::run(spec, opts, Some(slice), progress, &url);
        #[cfg(not(feature = "s3"))]
        return Err(StoreError::RemoteUnsupported { location: url }.into());
    }
    let (built, run) = prepare(spec, opts)?;
    fs::create_dir_all(run.root()).map_err(|e| StoreError::io(run.root(), e))?;
    let lock_path = slice_lock_path(&run, slice);
    let _mine = match FileLock::acquire(&lock_path, false)? {
        Some(lock) => lock,
        None => {
            progress.note(
                "shard",
                &format!("shard {slice} is held by another process; waiting for it to end"),
            );
            FileLock::acquire(&lock_path, true)?.expect("a blocking lock is taken")
        }
    };
    let stages = shard_stages(spec, opts, &built);
    let shard = Shard {
        session: Session {
            spec,
            opts,
            progress,
            built: &built,
            run: &run,
            on_commit: None,
        },
        slice,
        stages: stages.clone(),
        waiting_noted: std::cell::Cell::new(false),
    };
    let mut reports = Vec::new();
    for (k, &i) in stages.iter().enumerate() {
        let earlier: Vec<usize> = stages[..k]
            .iter()
            .copied()
            .filter(|&j| !beside(spec, &built, j, i))
            .collect();
        shard.wait_for(i, &earlier)?;
        let report = if built.stages[i].shardable() {
            shard.slice_stage(i)?
        } else {
            shard.whole_stage(i)?
        };
        reports.extend(report);
    }
    Ok(RunReport {
        run_dir: run.root().to_path_buf(),
        stages: reports,
    })
}

/// Whether stage `i` may be computed while the earlier stage `j` is still running: both say they run
/// beside their siblings ([`Stage::runs_beside_siblings`](super::Stage::runs_beside_siblings)), and
/// `j` is not upstream of `i`.
pub(super) fn beside(spec: &PipelineSpec, built: &Built, j: usize, i: usize) -> bool {
    built.stages[i].shardable()
        && built.stages[i].runs_beside_siblings()
        && built.stages[j].shardable()
        && built.stages[j].runs_beside_siblings()
        && !spec
            .upstream(&spec.stages[i].id)
            .contains(&spec.stages[j].id)
}

impl Shard<'_> {
    /// Whether every stage before stage `i` in this shard's run order is finished (stages are
    /// committed in run order, also when siblings were computed side by side).
    fn earlier_finished(&self, i: usize) -> Result<bool, RunError> {
        let s = &self.session;
        let Some(pos) = self.stages.iter().position(|&j| j == i) else {
            return Ok(true);
        };
        let manifest = Manifest::load(s.run)?.unwrap_or_default();
        Ok(self.stages[..pos].iter().all(|&j| {
            let id = &s.spec.stages[j].id;
            manifest.stages.get(id).is_some_and(|r| {
                r.fingerprint == s.built.fingerprints[id] && r.status == StageStatus::Finished
            })
        }))
    }

    /// Runs `f` holding the run folder's lock (waiting for it), with the manifest as it is now.
    fn locked<T>(
        &self,
        f: impl FnOnce(&mut Manifest) -> Result<T, RunError>,
    ) -> Result<T, RunError> {
        let run = self.session.run;
        let _lock = FileLock::acquire(&run.root().join(".lock"), true)?;
        let mut manifest = Manifest::load(run)?.unwrap_or_default();
        if self.session.opts.record_pipeline && manifest.pipeline.is_none() {
            let spec = self.session.spec;
            manifest.pipeline = Some(crate::store::manifest::PipelineInfo {
                name: spec.name.clone(),
                file: spec.file.to_string_lossy().into_owned(),
                sha256: spec.sha256.clone(),
                seed: spec.seed,
            });
        }
        f(&mut manifest)
    }

    /// An unshardable stage a shardable one needs: run whole, under the run lock, by the first shard
    /// that gets there; the others find it finished.
    fn whole_stage(&self, i: usize) -> Result<Option<StageReport>, RunError> {
        let s = &self.session;
        let id = &s.spec.stages[i].id;
        self.locked(|manifest| {
            let planned = self.session.planned(manifest, i);
            if planned.action == Action::Cached {
                s.run.staging(id).remove()?;
                return Ok(Some(self.session.cached(id, &manifest.stages[id])));
            }
            let staging = s.run.staging(id);
            let previous = manifest.stages.get(id).cloned();
            let mut resuming = previous.as_ref().is_some_and(|p| {
                p.fingerprint == planned.fingerprint
                    && planned.action == Action::Run(RunReason::Resume)
            });
            if let Some(prev) = previous
                .as_ref()
                .filter(|p| resuming && p.status == StageStatus::Committing)
            {
                match s.finish_commit(manifest, &staging, id, prev)? {
                    Some(report) => return Ok(Some(report)),
                    // Its files are not all there: the stage runs again from the start.
                    None => resuming = false,
                }
            }
            // A stage whose earlier attempt died (its process held the run lock, so no other one
            // writes its staging area) keeps its finished shards, as in an unsharded run: an
            // `evolve` goes on from its saved rounds.
            s.reset_staging(manifest, &staging, id, resuming)?;
            let record = s.begin(manifest, &planned, i)?;
            s.run_and_commit(manifest, record, i, staging).map(Some)
        })
    }

    /// Starts stage `i` if no shard has (under the run lock): `None` when it is finished already
    /// (its report), else the fingerprint its slices are computed for.
    fn start(&self, i: usize) -> Result<Result<String, StageReport>, RunError> {
        let s = &self.session;
        let id = &s.spec.stages[i].id;
        self.locked(|manifest| {
            let planned = self.session.planned(manifest, i);
            let staging = s.run.staging(id);
            match (&planned.action, manifest.stages.get(id).cloned()) {
                (Action::Cached, Some(r)) => return Ok(Err(self.session.cached(id, &r))),
                (Action::Run(RunReason::Resume), Some(r)) if r.status == StageStatus::Running => {
                    return Ok(Ok(planned.fingerprint));
                }
                (Action::Run(RunReason::Resume), Some(r))
                    if r.status == StageStatus::Committing =>
                {
                    if let Some(report) = s.finish_commit(manifest, &staging, id, &r)? {
                        return Ok(Err(report));
                    }
                }
                _ => {}
            }
            if let Some(damage) = &planned.damage {
                s.progress
                    .note(id, &format!("{damage}: running the stage again"));
            }
            s.reset_staging(manifest, &staging, id, false)?;
            s.begin(manifest, &planned, i)?;
            Ok(Ok(planned.fingerprint))
        })
    }

    /// Computes `slice` of stage `i` (recorded `running` with `fp`) unless it is done, and records it
    /// done. The caller holds the slice's lock.
    fn compute_slice(&self, i: usize, fp: &str, slice: Slice) -> Result<bool, RunError> {
        let s = &self.session;
        let def = &s.spec.stages[i];
        let staging = s.run.staging(&def.id);
        if staging
            .slices_done(fp)?
            .contains(&(slice.index, slice.count))
        {
            return Ok(false);
        }
        let dropped = staging.discard_unfinished_where(|unit| slice.owns(unit))?;
        if dropped > 0 {
            s.progress.note(
                &def.id,
                &format!("slice {slice}: {dropped} partial file(s) of an earlier attempt dropped"),
            );
        }
        s.run_slice(i, &staging, slice)?;
        staging.mark_slice(slice.index, slice.count, fp)?;
        s.progress
            .stage_finished(&def.id, &format!("slice {slice} done"));
        Ok(true)
    }

    /// Commits stage `i` if every slice of it is done and no shard has yet (under the run lock).
    fn try_commit(&self, i: usize, fp: &str) -> Result<Option<StageReport>, RunError> {
        let s = &self.session;
        let id = &s.spec.stages[i].id;
        let staging = s.run.staging(id);
        if missing_slices(&staging.slices_done(fp)?).is_some() || !self.earlier_finished(i)? {
            return Ok(None);
        }
        self.locked(|manifest| {
            let record = match manifest.stages.get(id) {
                Some(r) if r.fingerprint == fp && r.status == StageStatus::Running => r.clone(),
                Some(r) if r.fingerprint == fp && r.status == StageStatus::Committing => {
                    let r = r.clone();
                    return s.finish_commit(manifest, &staging, id, &r);
                }
                // Committed by another shard, or restarted with another fingerprint.
                _ => return Ok(None),
            };
            let mut record = record;
            record.started = Some(now());
            s.run_and_commit(manifest, record, i, staging).map(Some)
        })
    }

    /// Stage `i`: started if need be, this process's slice computed, committed if that completes it.
    fn slice_stage(&self, i: usize) -> Result<Option<StageReport>, RunError> {
        let fp = match self.start(i)? {
            Ok(fp) => fp,
            Err(report) => return Ok(Some(report)),
        };
        self.compute_slice(i, &fp, self.slice)?;
        let committed = self.try_commit(i, &fp)?;
        let id = &self.session.spec.stages[i].id;
        Ok(Some(committed.unwrap_or_else(|| StageReport {
            id: id.clone(),
            cached: false,
            rows: Default::default(),
            summary: serde_json::Value::Null,
            seconds: 0.0,
        })))
    }

    /// Waits until every stage before stage `i` in the run order (`earlier`) is finished — not only
    /// its inputs: a stage reading "every trace of the run" must see what the single-process run, which
    /// goes in this order, would show it, and every shard must cut the same work list. Meanwhile,
    /// computes the slices of those stages whose shard process is not running (its lock is free) and
    /// commits one whose slices are all done; fails when one of them failed.
    fn wait_for(&self, i: usize, earlier: &[usize]) -> Result<(), RunError> {
        let s = &self.session;
        let def = &s.spec.stages[i];
        self.waiting_noted.set(false);
        loop {
            let manifest = Manifest::load(s.run)?.unwrap_or_default();
            let pending = s.unfinished(&manifest, i, earlier)?;
            if pending.is_empty() {
                return Ok(());
            }
            let mut progressed = false;
            for &j in &pending {
                if !s.built.stages[j].shardable() {
                    continue;
                }
                let fp = &s.built.fingerprints[&s.spec.stages[j].id];
                progressed |= self.take_over(j, fp)?;
                progressed |= self.try_commit(j, fp)?.is_some();
            }
            if !progressed {
                if !self.waiting_noted.replace(true) {
                    s.progress.note(
                        &def.id,
                        &format!(
                            "shard {}: waiting for stage(s) {} (other shards' slices)",
                            self.slice,
                            pending
                                .iter()
                                .map(|&j| s.spec.stages[j].id.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    );
                }
                std::thread::sleep(POLL);
            }
        }
    }

    /// Computes every unfinished slice of stage `j` whose process does not hold its lock (not started
    /// yet, or dead). True when one was computed.
    fn take_over(&self, j: usize, fp: &str) -> Result<bool, RunError> {
        let s = &self.session;
        let id = &s.spec.stages[j].id;
        let running = Manifest::load(s.run)?
            .and_then(|m| m.stages.get(id).cloned())
            .is_some_and(|r| r.fingerprint == fp && r.status == StageStatus::Running);
        if !running {
            return Ok(false);
        }
        let done = s.run.staging(id).slices_done(fp)?;
        let n = self.slice.count;
        let mut any = false;
        for index in 0..n {
            if done.contains(&(index, n)) {
                continue;
            }
            let other = Slice::new(index, n).expect("index below count");
            let Some(_lock) = FileLock::acquire(&slice_lock_path(s.run, other), false)? else {
                continue;
            };
            s.progress.note(
                id,
                &format!(
                    "shard {}: slice {other} has no running process; computing it here",
                    self.slice
                ),
            );
            any |= self.compute_slice(j, fp, other)?;
        }
        Ok(any)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slices_own_units_by_leading_number() {
        let s: Slice = "1/3".parse().unwrap();
        assert!(s.owns("00001") && s.owns("00004") && s.owns("00007-00002"));
        assert!(!s.owns("00000") && !s.owns("00002") && !s.owns("detectors"));
        let all: Vec<usize> = (0..10)
            .filter(|u| (0..3).any(|i| Slice::new(i, 3).unwrap().owns(&format!("{u:05}"))))
            .collect();
        assert_eq!(all, (0..10).collect::<Vec<_>>(), "every unit has a slice");
        assert!("3/3".parse::<Slice>().is_err());
        assert!("0/0".parse::<Slice>().is_err());
        assert!("x".parse::<Slice>().is_err());
    }

    #[test]
    fn missing_slices_names_them() {
        assert_eq!(missing_slices(&[(0, 2), (1, 2)]), None);
        assert_eq!(
            missing_slices(&[(0, 3)]).unwrap(),
            "slice(s) 1/3, 2/3 not finished"
        );
        // A complete set of another count is enough (units do not depend on the count).
        assert_eq!(missing_slices(&[(0, 3), (0, 1)]), None);
        assert_eq!(missing_slices(&[]).unwrap(), "no slice is finished");
    }
}
