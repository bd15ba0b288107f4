//! The run directory on disk: where every table, export and the manifest of a run live.
//!
//! **Owns:** the layout of a run folder, atomic files ([`AtomicFile`]), Parquet files
//! ([`ParquetSink`]), and the staging area through which a stage publishes its tables all at once
//! ([`Staging`]). **Does not:** decide what a stage computes or when it runs (`pipeline/`), or query
//! tables (`query/`).
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
//! shard done; when every shard is done the files are renamed into the table folders. A killed run
//! therefore leaves finished shards to reuse and never a partial file where readers look, and a stage's
//! tables become visible together.

mod atomic;
mod parquet;
mod traces;

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

pub use self::atomic::{AtomicFile, is_temp_name, sync_dir, write_atomic};
pub use self::parquet::{ParquetSink, ROW_GROUP_ROWS, read_batches, read_file};
pub use self::traces::{ReadTraceError, read_trace, trace_ids};
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

/// Folder names in a run that are not tables.
const RESERVED: &[&str] = &["exports"];

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

    /// Every table in the run: folders (other than `exports` and hidden ones) that hold Parquet files
    /// directly or in `env=` folders.
    pub fn tables(&self) -> Result<Vec<TableDir>, StoreError> {
        let mut out = Vec::new();
        let entries = match fs::read_dir(&self.root) {
            Ok(e) => e,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(out),
            Err(e) => return Err(StoreError::io(&self.root, e)),
        };
        for entry in entries {
            let entry = entry.map_err(|e| StoreError::io(&self.root, e))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with('.')
                || name.starts_with('_')
                || RESERVED.contains(&name.as_str())
                || !entry.path().is_dir()
            {
                continue;
            }
            let table = self.table(&name)?;
            if !table.files.is_empty() || table.partitioned {
                out.push(table);
            }
        }
        out.sort_by(|a, b| a.name.cmp(&b.name));
        Ok(out)
    }

    /// The files of one table (empty when the table has none).
    pub fn table(&self, name: &str) -> Result<TableDir, StoreError> {
        let dir = self.root.join(name);
        let mut files = Vec::new();
        let mut partitioned = false;
        let entries = match fs::read_dir(&dir) {
            Ok(e) => e,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                return Ok(TableDir {
                    name: name.to_string(),
                    partitioned: false,
                    files,
                });
            }
            Err(e) => return Err(StoreError::io(&dir, e)),
        };
        for entry in entries {
            let entry = entry.map_err(|e| StoreError::io(&dir, e))?;
            let path = entry.path();
            let fname = entry.file_name().to_string_lossy().into_owned();
            if let Some(env) = fname.strip_prefix("env=") {
                let Ok(env) = env.parse::<Env>() else {
                    continue;
                };
                partitioned = true;
                for f in parquet_files(&path)? {
                    files.push(TableFile {
                        env: Some(env),
                        path: f,
                    });
                }
            } else if is_parquet(&fname) {
                files.push(TableFile { env: None, path });
            }
        }
        files.sort_by(|a, b| a.path.cmp(&b.path));
        Ok(TableDir {
            name: name.to_string(),
            partitioned,
            files,
        })
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

    /// The run paths the staged files will have once committed.
    pub fn pending(&self) -> Result<Vec<PathBuf>, StoreError> {
        Ok(self
            .staged_files()?
            .into_iter()
            .map(|(_, target)| target)
            .collect())
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
            if self.shard_record(shard)?.is_none() {
                fs::remove_file(&staged).map_err(|e| StoreError::io(&staged, e))?;
                removed += 1;
            }
        }
        // Spilled rows of a trace that was being read.
        let _ = fs::remove_dir_all(self.scratch_dir());
        // Temporary files of a killed writer.
        let mut stack = vec![self.dir.clone()];
        while let Some(dir) = stack.pop() {
            let Ok(entries) = fs::read_dir(&dir) else {
                continue;
            };
            for entry in entries.flatten() {
                let path = entry.path();
                if path.is_dir() {
                    stack.push(path);
                } else if is_temp_name(&entry.file_name().to_string_lossy()) {
                    let _ = fs::remove_file(&path);
                }
            }
        }
        Ok(removed)
    }

    /// Moves every staged file into the run's table folders and removes the staging area. Returns the
    /// final paths. Safe to call again after a crash in the middle: files already moved are skipped.
    pub fn commit(&self) -> Result<Vec<PathBuf>, StoreError> {
        let mut out = Vec::new();
        for (staged, target) in self.staged_files()? {
            let parent = target.parent().expect("a table file has a folder");
            fs::create_dir_all(parent).map_err(|e| StoreError::io(parent, e))?;
            fs::rename(&staged, &target).map_err(|e| StoreError::io(&staged, e))?;
            sync_dir(Some(parent)).map_err(|e| StoreError::io(parent, e))?;
            out.push(target);
        }
        self.remove()?;
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
