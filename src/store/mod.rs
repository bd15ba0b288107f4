//! The run directory on disk: where every table, export and the manifest of a run live.
//!
//! **Owns:** the layout of a run folder, the manifest format ([`manifest`]), atomic files
//! ([`AtomicFile`]), Parquet files ([`ParquetSink`]; [`ColumnSink`] writes the frame tables from column
//! views without Arrow arrays), the staging area through which a stage publishes
//! its tables all at once ([`Staging`]), which files readers see ([`RunDir::tables`]: the published
//! files of the manifest) and verified reading ([`verify`]). **Does not:** decide what a stage computes
//! or when it runs and commits (`pipeline/`), or query tables (`query/`).
//!
//! ```text
//! runs/quickstart/
//! ├── manifest.json                       stages, fingerprints, status, outputs (written atomically)
//! ├── traces/env=pooltool/import.00000.parquet
//! ├── frames/env=pooltool/import.00000.parquet
//! ├── summary/summary.result.parquet     a table written by an SQL stage (not partitioned)
//! ├── exports/summary.tex                 files written by export stages
//! └── .staging/<stage>/…                  shards of a running stage, moved into place on commit
//! ```
//!
//! A stage writes each shard's files under `.staging/<stage>/` (each file atomically) and marks the
//! shard done; when every shard is done the runner records the files (with sizes and checksums) in the
//! manifest as `committing`, renames them into the table folders, and then records the stage
//! `finished`. **Readers list a table's files from the manifest** — the outputs of finished stages —
//! never from the folder, so that last manifest write is the one atomic step that publishes a stage: a
//! reader sees all of a stage's tables or none of them, whenever the process was killed, and a file no
//! finished stage lists (a foreign file, one of an interrupted commit) is invisible. Every listed file's
//! size is checked as it is listed (a stat); [`verify`] also checks checksums.
//!
//! With the cargo feature `s3`, `remote` holds the same layout on an object store (`s3://bucket/prefix`)
//! and the local copy a remote run is worked on through (`pipeline::remote` publishes its commits).
//!
//! One exception: [`JOURNAL_TABLES`] (`llm_calls`) are appended to file by file outside any stage (so
//! that calls recorded before a kill survive it) and are listed from their folder; each of their files
//! is written atomically, so none is ever partial.

mod atomic;
mod columns;
pub mod manifest;
mod parquet;
#[cfg(feature = "s3")]
pub mod remote;
mod traces;
pub mod verify;

use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

pub use self::atomic::{
    AtomicFile, is_temp_name, swap_dir, sync_dir, write_atomic, write_dir_atomic,
};
pub use self::columns::ColumnSink;
pub use self::manifest::{Manifest, OutputFile, StageStatus};
pub use self::parquet::{
    Codec, ParquetSettings, ParquetSink, ROW_GROUP_ROWS, Stats, Strings, plain_strings,
    read_batches, read_file, read_file_whole, read_file_whole_as,
};
pub use self::traces::{ReadTraceError, read_trace, read_traces, trace_ids};
pub(crate) use self::traces::{file_trace_ids, key_order, rows_of};
pub use self::verify::Problem;
use crate::trace::Env;

/// A failure to read or write a run's files.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StoreError {
    /// A file-system operation failed.
    #[error("{}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: io::Error,
    },
    /// Parquet encoding or decoding failed.
    #[error("{}", path.display())]
    Parquet {
        /// The file.
        path: PathBuf,
        /// The Parquet error.
        #[source]
        source: ::parquet::errors::ParquetError,
    },
    /// A table file lacks a column (or has another table's schema).
    #[error("{}: {message}", path.display())]
    Schema {
        /// The file.
        path: PathBuf,
        /// What is missing or wrong.
        message: String,
    },
    /// A JSON file of the run is not what annotrace wrote.
    #[error("{}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// The parser error.
        #[source]
        source: serde_json::Error,
    },
    /// A published file is missing or not what the manifest recorded (size or checksum).
    #[error(
        "{}: {problem} (an output of stage {stage}); the run folder is damaged: `annotrace verify --run {}` lists every damaged file, `annotrace run` redoes the stages",
        path.display(), run.display()
    )]
    Damaged {
        /// The file.
        path: PathBuf,
        /// The stage that wrote it (`-` for a journal table's file).
        stage: String,
        /// The run folder.
        run: PathBuf,
        /// What is wrong.
        problem: Problem,
    },
    /// An object store refused or failed a request (a run at `s3://…`), or its location is malformed.
    #[error("{location}: {message}")]
    Remote {
        /// The run or object (`s3://bucket/prefix/key`).
        location: String,
        /// What failed.
        message: String,
    },
    /// A conditional write to an object store lost to another writer: nothing of it was published.
    #[error("{location}: {message}")]
    Conflict {
        /// The run (`s3://bucket/prefix`).
        location: String,
        /// What conflicted.
        message: String,
    },
    /// A run location on object storage given to an annotrace built without the `s3` feature.
    #[error(
        "{location}: this annotrace was built without object-storage support; rebuild with `cargo build --features s3`"
    )]
    RemoteUnsupported {
        /// The location given.
        location: String,
    },
    /// The manifest was written by a newer annotrace.
    #[error(
        "{}: manifest format {found} is newer than this annotrace reads (format {}); use a newer annotrace",
        path.display(), manifest::FORMAT
    )]
    ManifestFormat {
        /// The manifest.
        path: PathBuf,
        /// Its format.
        found: u32,
    },
}

impl StoreError {
    pub(crate) fn io(path: &Path, source: io::Error) -> Self {
        StoreError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
    pub(crate) fn parquet(path: &Path, source: ::parquet::errors::ParquetError) -> Self {
        StoreError::Parquet {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Whether a run location names an object store (`s3://bucket/prefix`) rather than a local folder.
pub fn remote_url(location: &Path) -> Option<&str> {
    location.to_str().filter(|s| s.starts_with("s3://"))
}

/// Folder names in a run that are not tables.
const RESERVED: &[&str] = &["exports"];

/// Tables appended to file by file outside any stage, each file written atomically, and listed from
/// their folder rather than from the manifest: `llm_calls` (calls recorded before a kill survive it).
pub const JOURNAL_TABLES: &[&str] = &["llm_calls"];

/// The file name of a stage's shard: `<stage>.<shard>.parquet`. Stage ids contain no `.`.
pub fn shard_file_name(stage_id: &str, shard: &str) -> String {
    format!("{stage_id}.{shard}.parquet")
}

/// One Parquet file of a table.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TableFile {
    /// Its `env=` partition, if the table is partitioned.
    pub env: Option<Env>,
    /// Its path.
    pub path: PathBuf,
    /// Its size in bytes (checked against the manifest when listed).
    pub bytes: u64,
    /// When it was last modified.
    pub modified: SystemTime,
}

/// A table found in a run folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TableDir {
    /// Table name (the folder name).
    pub name: String,
    /// Whether its files sit in `env=` folders.
    pub partitioned: bool,
    /// Its files, sorted.
    pub files: Vec<TableFile>,
}

/// A run folder.
#[derive(Clone, Debug)]
pub struct RunDir {
    root: PathBuf,
}

impl RunDir {
    /// The run at `root` (nothing is created until something is written).
    pub fn new(root: impl Into<PathBuf>) -> Self {
        RunDir { root: root.into() }
    }

    /// The run folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `manifest.json`.
    pub fn manifest_path(&self) -> PathBuf {
        self.root.join("manifest.json")
    }

    /// The folder of exported files.
    pub fn exports_dir(&self) -> PathBuf {
        self.root.join("exports")
    }

    /// The folder of a table, and of its partition when `env` is given.
    pub fn partition_dir(&self, table: &str, env: Option<Env>) -> PathBuf {
        let dir = self.root.join(table);
        match env {
            Some(env) => dir.join(format!("env={env}")),
            None => dir,
        }
    }

    /// The staging area of a stage.
    pub fn staging(&self, stage_id: &str) -> Staging {
        Staging {
            run: self.clone(),
            stage_id: stage_id.to_string(),
            dir: self.root.join(".staging").join(stage_id),
        }
    }

    /// Every table in the run with its published files: the Parquet outputs of the manifest's finished
    /// stages (outside `exports/`), grouped by their first folder, plus the [`JOURNAL_TABLES`] listed
    /// from their folders. Each file's size is checked: a missing, empty or truncated file is a
    /// [`StoreError::Damaged`] naming it. Files no finished stage lists are not seen.
    pub fn tables(&self) -> Result<Vec<TableDir>, StoreError> {
        let manifest = Manifest::load(self)?;
        let mut out: Vec<TableDir> = Vec::new();
        let mut names: Vec<String> = manifest
            .iter()
            .flat_map(|m| m.published())
            .filter_map(|(_, o)| table_of(&o.path).map(|(t, _)| t.to_string()))
            .collect();
        names.extend(JOURNAL_TABLES.iter().map(|t| t.to_string()));
        names.sort();
        names.dedup();
        for name in names {
            let t = self.table_in(manifest.as_ref(), &name)?;
            if !t.files.is_empty() {
                out.push(t);
            }
        }
        Ok(out)
    }

    /// The published files of one table (empty when the table has none), checked as in
    /// [`RunDir::tables`].
    pub fn table(&self, name: &str) -> Result<TableDir, StoreError> {
        let manifest = Manifest::load(self)?;
        self.table_in(manifest.as_ref(), name)
    }

    fn table_in(&self, manifest: Option<&Manifest>, name: &str) -> Result<TableDir, StoreError> {
        let mut files = Vec::new();
        let mut partitioned = false;
        if JOURNAL_TABLES.contains(&name) {
            for path in parquet_files_or_none(&self.root.join(name))? {
                let meta = fs::metadata(&path).map_err(|e| StoreError::io(&path, e))?;
                if meta.len() == 0 {
                    return Err(self.damaged(
                        &path,
                        "-",
                        Problem::Size {
                            expected: None,
                            found: 0,
                        },
                    ));
                }
                files.push(TableFile {
                    env: None,
                    modified: meta.modified().unwrap_or(SystemTime::UNIX_EPOCH),
                    bytes: meta.len(),
                    path,
                });
            }
        }
        for (stage, o) in manifest.iter().flat_map(|m| m.published()) {
            let Some((table, rest)) = table_of(&o.path) else {
                continue;
            };
            if table != name {
                continue;
            }
            let env = match rest.split_once('/') {
                Some((part, _)) => match part.strip_prefix("env=").map(str::parse::<Env>) {
                    Some(Ok(env)) => Some(env),
                    _ => continue,
                },
                None => None,
            };
            partitioned |= env.is_some();
            let path = self.root.join(Path::new(&o.path));
            let meta = verify::check_size(&path, o).map_err(|p| self.damaged(&path, stage, p))?;
            files.push(TableFile {
                env,
                path,
                bytes: meta.len(),
                modified: meta.modified().unwrap_or(SystemTime::UNIX_EPOCH),
            });
        }
        files.sort_by(|a, b| a.path.cmp(&b.path));
        Ok(TableDir {
            name: name.to_string(),
            partitioned,
            files,
        })
    }

    /// A [`StoreError::Damaged`] for a file of this run.
    pub fn damaged(&self, path: &Path, stage: &str, problem: Problem) -> StoreError {
        StoreError::Damaged {
            path: path.to_path_buf(),
            stage: stage.to_string(),
            run: self.root.clone(),
            problem,
        }
    }
}

/// The table of a published output path (`traces/env=pool/x.parquet` → `traces`, the rest), or `None`
/// for files that are not table files (exports, non-Parquet files, files at the top of the run).
fn table_of(path: &str) -> Option<(&str, &str)> {
    let (table, rest) = path.split_once('/')?;
    let file = rest.rsplit('/').next().unwrap_or(rest);
    (!table.starts_with('.')
        && !table.starts_with('_')
        && !RESERVED.contains(&table)
        && !JOURNAL_TABLES.contains(&table)
        && is_parquet(file)
        && rest.split('/').count() <= 2)
        .then_some((table, rest))
}

fn parquet_files_or_none(dir: &Path) -> Result<Vec<PathBuf>, StoreError> {
    match fs::metadata(dir) {
        Ok(m) if m.is_dir() => parquet_files(dir),
        Ok(_) => Ok(Vec::new()),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(Vec::new()),
        Err(e) => Err(StoreError::io(dir, e)),
    }
}

fn is_parquet(name: &str) -> bool {
    name.ends_with(".parquet") && !name.starts_with('.')
}

fn parquet_files(dir: &Path) -> Result<Vec<PathBuf>, StoreError> {
    let mut out = Vec::new();
    for entry in fs::read_dir(dir).map_err(|e| StoreError::io(dir, e))? {
        let entry = entry.map_err(|e| StoreError::io(dir, e))?;
        if is_parquet(&entry.file_name().to_string_lossy()) {
            out.push(entry.path());
        }
    }
    out.sort();
    Ok(out)
}

/// The staging area of one stage: `.staging/<stage>/` mirrors the run's table folders.
#[derive(Clone, Debug)]
pub struct Staging {
    run: RunDir,
    stage_id: String,
    dir: PathBuf,
}

impl Staging {
    /// The stage this area belongs to.
    pub fn stage_id(&self) -> &str {
        &self.stage_id
    }

    /// The staging folder (`.staging/<stage>/`).
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn done_dir(&self) -> PathBuf {
        self.dir.join("_done")
    }

    /// The staged files of one table (of shards finished by an earlier attempt, after
    /// [`Staging::discard_unfinished`]).
    pub fn table_files(&self, table: &str) -> Result<Vec<PathBuf>, StoreError> {
        let prefix = self.dir.join(table);
        Ok(self
            .staged_files()?
            .into_iter()
            .map(|(staged, _)| staged)
            .filter(|p| p.starts_with(&prefix))
            .collect())
    }

    /// Starts a staged Parquet file for `table` (and partition), named after the stage and shard.
    pub fn sink(
        &self,
        table: &str,
        env: Option<Env>,
        shard: &str,
        schema: arrow::datatypes::SchemaRef,
    ) -> Result<ParquetSink, StoreError> {
        let mut path = self.dir.join(table);
        if let Some(env) = env {
            path = path.join(format!("env={env}"));
        }
        ParquetSink::create(path.join(shard_file_name(&self.stage_id, shard)), schema)
    }

    /// Starts a staged Parquet file for `table` written by the column writer ([`ColumnSink`]), with
    /// the environment's [`ParquetSettings::for_frames`].
    pub fn column_sink(
        &self,
        table: &str,
        env: Option<Env>,
        shard: &str,
        schema: arrow::datatypes::SchemaRef,
    ) -> Result<ColumnSink, StoreError> {
        let mut path = self.dir.join(table);
        if let Some(env) = env {
            path = path.join(format!("env={env}"));
        }
        ColumnSink::create(
            path.join(shard_file_name(&self.stage_id, shard)),
            schema,
            &ParquetSettings::for_frames(env),
        )
    }

    /// The record of a finished shard, if it finished.
    pub fn shard_record(&self, shard: &str) -> Result<Option<serde_json::Value>, StoreError> {
        let path = self.done_dir().join(format!("{shard}.json"));
        match fs::read(&path) {
            Ok(bytes) => serde_json::from_slice(&bytes)
                .map(Some)
                .map_err(|source| StoreError::Json { path, source }),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(StoreError::io(&path, e)),
        }
    }

    /// A folder for a stage's scratch files (removed with the staging area, never published).
    pub fn scratch_dir(&self) -> PathBuf {
        self.dir.join("_spill")
    }

    /// Marks a shard finished, with a record of what it wrote. Call after its files are committed.
    pub fn mark_done(&self, shard: &str, record: &serde_json::Value) -> Result<(), StoreError> {
        let path = self.done_dir().join(format!("{shard}.json"));
        write_atomic(&path, record.to_string().as_bytes())
            .map(|_| ())
            .map_err(|e| StoreError::io(&path, e))
    }

    /// The staged files, as (path inside the staging area, path it will have in the run), sorted.
    pub fn pending(&self) -> Result<Vec<(PathBuf, PathBuf)>, StoreError> {
        self.staged_files()
    }

    /// Every staged Parquet file, as (path inside the staging area, path inside the run).
    fn staged_files(&self) -> Result<Vec<(PathBuf, PathBuf)>, StoreError> {
        let mut out = Vec::new();
        if !self.dir.exists() {
            return Ok(out);
        }
        let mut stack = vec![self.dir.clone()];
        while let Some(dir) = stack.pop() {
            for entry in fs::read_dir(&dir).map_err(|e| StoreError::io(&dir, e))? {
                let entry = entry.map_err(|e| StoreError::io(&dir, e))?;
                let path = entry.path();
                if path.is_dir() {
                    // `_done` holds shard records and `_spill` spilled rows: neither is a table.
                    if !entry.file_name().to_string_lossy().starts_with('_') {
                        stack.push(path);
                    }
                } else if is_parquet(&entry.file_name().to_string_lossy()) {
                    let rel = path
                        .strip_prefix(&self.dir)
                        .expect("walked below the staging dir")
                        .to_path_buf();
                    out.push((path, self.run.root.join(rel)));
                }
            }
        }
        out.sort();
        Ok(out)
    }

    /// Removes staged files of shards that did not finish (a killed run's leftovers), so that they are
    /// written again from the start.
    pub fn discard_unfinished(&self) -> Result<usize, StoreError> {
        let removed = self.discard_unfinished_where(|_| true)?;
        // Spilled rows of a trace that was being read.
        let _ = fs::remove_dir_all(self.scratch_dir());
        Ok(removed)
    }

    /// Like [`Staging::discard_unfinished`], for the shards `owns` accepts only (a process computing
    /// one slice of a stage while other processes write theirs): their unfinished files and the
    /// temporary files of their killed writers are removed, every other file is left alone.
    pub fn discard_unfinished_where(
        &self,
        owns: impl Fn(&str) -> bool,
    ) -> Result<usize, StoreError> {
        let mut removed = 0;
        for (staged, _) in self.staged_files()? {
            let name = staged
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or_default();
            let shard = name
                .strip_prefix(&format!("{}.", self.stage_id))
                .and_then(|s| s.strip_suffix(".parquet"))
                .unwrap_or_default();
            if owns(shard) && self.shard_record(shard)?.is_none() {
                fs::remove_file(&staged).map_err(|e| StoreError::io(&staged, e))?;
                removed += 1;
            }
        }
        // Temporary files of a killed writer.
        let mut stack = vec![self.dir.clone()];
        while let Some(dir) = stack.pop() {
            let Ok(entries) = fs::read_dir(&dir) else {
                continue;
            };
            for entry in entries.flatten() {
                let path = entry.path();
                let name = entry.file_name().to_string_lossy().into_owned();
                if path.is_dir() {
                    stack.push(path);
                } else if is_temp_name(&name) && owns(&self.shard_of_temp(&name)) {
                    let _ = fs::remove_file(&path);
                }
            }
        }
        Ok(removed)
    }

    /// The shard a temporary file belongs to: `.<stage>.<shard>.parquet.<pid>-<n>.tmp` (a table file)
    /// or `.<shard>.json.<pid>-<n>.tmp` (a shard record); empty when it is neither.
    fn shard_of_temp(&self, name: &str) -> String {
        let target = name
            .strip_prefix('.')
            .and_then(|n| n.strip_suffix(".tmp"))
            .and_then(|n| n.rsplit_once('.'))
            .map_or("", |(target, _)| target);
        target
            .strip_prefix(&format!("{}.", self.stage_id))
            .and_then(|s| s.strip_suffix(".parquet"))
            .or_else(|| target.strip_suffix(".json"))
            .unwrap_or_default()
            .to_string()
    }

    fn slices_dir(&self) -> PathBuf {
        self.dir.join("_slices")
    }

    /// Records that slice `index` of `count` of the stage with `fingerprint` is done (every unit it
    /// owns has its record): `_slices/<index>-of-<count>.json`.
    pub fn mark_slice(
        &self,
        index: usize,
        count: usize,
        fingerprint: &str,
    ) -> Result<(), StoreError> {
        let path = self.slices_dir().join(format!("{index}-of-{count}.json"));
        let record =
            serde_json::json!({"index": index, "count": count, "fingerprint": fingerprint});
        write_atomic(&path, record.to_string().as_bytes())
            .map(|_| ())
            .map_err(|e| StoreError::io(&path, e))
    }

    /// The slices recorded done for `fingerprint`, as (index, count), sorted.
    pub fn slices_done(&self, fingerprint: &str) -> Result<Vec<(usize, usize)>, StoreError> {
        let dir = self.slices_dir();
        let entries = match fs::read_dir(&dir) {
            Ok(e) => e,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(StoreError::io(&dir, e)),
        };
        let mut out = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| StoreError::io(&dir, e))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') || !name.ends_with(".json") {
                continue;
            }
            let path = entry.path();
            let bytes = fs::read(&path).map_err(|e| StoreError::io(&path, e))?;
            let v: serde_json::Value = serde_json::from_slice(&bytes)
                .map_err(|source| StoreError::Json { path, source })?;
            if v["fingerprint"].as_str() == Some(fingerprint)
                && let (Some(i), Some(n)) = (v["index"].as_u64(), v["count"].as_u64())
            {
                out.push((i as usize, n as usize));
            }
        }
        out.sort();
        Ok(out)
    }

    /// Moves every staged file into the run's table folders, one rename (and folder sync) at a time,
    /// calling `step` after each; returns the final paths. The files stay invisible to readers until
    /// the manifest records the stage finished. Safe to call again after a crash in the middle: files
    /// already moved are no longer staged. The staging area itself is left for [`Staging::remove`].
    pub fn move_into_place<E: From<StoreError>>(
        &self,
        mut step: impl FnMut() -> Result<(), E>,
    ) -> Result<Vec<PathBuf>, E> {
        let mut out = Vec::new();
        for (staged, target) in self.staged_files()? {
            let parent = target.parent().expect("a table file has a folder");
            fs::create_dir_all(parent).map_err(|e| StoreError::io(parent, e))?;
            fs::rename(&staged, &target).map_err(|e| StoreError::io(&staged, e))?;
            sync_dir(Some(parent)).map_err(|e| StoreError::io(parent, e))?;
            out.push(target);
            step()?;
        }
        Ok(out)
    }

    /// Deletes the staging area and everything in it.
    pub fn remove(&self) -> Result<(), StoreError> {
        match fs::remove_dir_all(&self.dir) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
            Err(e) => Err(StoreError::io(&self.dir, e)),
        }?;
        // Drop `.staging` itself once no stage uses it.
        if let Some(parent) = self.dir.parent() {
            let _ = fs::remove_dir(parent);
        }
        Ok(())
    }
}

/// Removes files a stage published earlier (listed in the manifest), and folders left empty.
pub fn remove_files(files: &[PathBuf]) -> Result<(), StoreError> {
    for f in files {
        match fs::remove_file(f) {
            Ok(()) => {
                if let Some(parent) = f.parent() {
                    let _ = fs::remove_dir(parent);
                    if let Some(grand) = parent.parent().filter(|g| g.file_name().is_some())
                        && parent
                            .file_name()
                            .is_some_and(|n| n.to_string_lossy().starts_with("env="))
                    {
                        let _ = fs::remove_dir(grand);
                    }
                }
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(StoreError::io(f, e)),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_slice_discards_only_its_own_unfinished_files() {
        let dir = tempfile::tempdir().unwrap();
        let run = RunDir::new(dir.path());
        let staging = run.staging("sim");
        let part = |unit: &str| {
            staging
                .dir
                .join("traces/env=pooltool")
                .join(shard_file_name("sim", unit))
        };
        let temp = |unit: &str| {
            staging
                .dir
                .join("frames/env=pooltool")
                .join(format!(".sim.{unit}.parquet.4242-0.tmp"))
        };
        for unit in ["00000", "00001", "00002", "00003"] {
            for p in [part(unit), temp(unit)] {
                fs::create_dir_all(p.parent().unwrap()).unwrap();
                fs::write(&p, b"x").unwrap();
            }
        }
        staging.mark_done("00001", &serde_json::json!({})).unwrap();
        // Slice 1 of 2 owns units 1 and 3: 3 is unfinished, 1 is done.
        let owns = |u: &str| u.parse::<u64>().is_ok_and(|n| n % 2 == 1);
        assert_eq!(staging.discard_unfinished_where(owns).unwrap(), 1);
        assert!(part("00000").exists() && part("00001").exists() && part("00002").exists());
        assert!(!part("00003").exists());
        assert!(temp("00000").exists() && temp("00002").exists());
        assert!(!temp("00001").exists() && !temp("00003").exists());
        assert_eq!(staging.shard_of_temp(".00007.json.1-2.tmp"), "00007");
        assert_eq!(staging.shard_of_temp(".sim.00007.parquet.1-2.tmp"), "00007");
        assert_eq!(staging.shard_of_temp(".other.tmp"), "");
    }

    #[test]
    fn slices_are_recorded_per_fingerprint() {
        let dir = tempfile::tempdir().unwrap();
        let staging = RunDir::new(dir.path()).staging("sim");
        staging.mark_slice(1, 3, "aaa").unwrap();
        staging.mark_slice(0, 3, "aaa").unwrap();
        staging.mark_slice(2, 3, "bbb").unwrap();
        assert_eq!(staging.slices_done("aaa").unwrap(), vec![(0, 3), (1, 3)]);
        assert_eq!(staging.slices_done("bbb").unwrap(), vec![(2, 3)]);
        assert!(staging.slices_done("ccc").unwrap().is_empty());
    }
}
