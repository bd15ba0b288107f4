//! `manifest.json`: what a run folder holds and how it got there, rewritten atomically after every
//! change — and the **commit point** of every stage.
//!
//! Per stage it records the kind, parameters, inputs, fingerprint, status (`running`, `committing`,
//! `finished`, `failed`), start and end times, rows written per table, output files (relative to the
//! run folder, each with its size in bytes and SHA-256), a stage-specific summary and the error of a
//! failed attempt.
//!
//! **Owns:** the format (version [`FORMAT`]; format 1, written before checksums existed, is still read),
//! loading and atomic saving, and which files are published ([`Manifest::published`]: the outputs of
//! `finished` stages; nothing else in a table folder is part of the run). **Does not:** decide status
//! changes (the runner does, `pipeline::runner`), or check files (`store::verify`).

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::{RunDir, StoreError, write_atomic};

/// The manifest format this version writes: 2 records each output's size and SHA-256. Format 1 (a list
/// of paths) is read, its files checked for presence only until `run` records their checksums.
pub const FORMAT: u32 = 2;

/// One output file of a stage, as recorded in the manifest.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(from = "OutputRepr")]
pub struct OutputFile {
    /// Its path relative to the run folder, with `/` separators.
    pub path: String,
    /// Its size in bytes (absent in format 1 manifests).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bytes: Option<u64>,
    /// SHA-256 of its contents, lower-case hex (absent in format 1 manifests).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sha256: Option<String>,
}

impl OutputFile {
    /// A file with its size and checksum.
    pub fn new(path: String, bytes: u64, sha256: String) -> Self {
        OutputFile {
            path,
            bytes: Some(bytes),
            sha256: Some(sha256),
        }
    }
}

/// Format 1 wrote outputs as bare paths, format 2 as objects.
#[derive(Deserialize)]
#[serde(untagged)]
enum OutputRepr {
    Path(String),
    File {
        path: String,
        #[serde(default)]
        bytes: Option<u64>,
        #[serde(default)]
        sha256: Option<String>,
    },
}

impl From<OutputRepr> for OutputFile {
    fn from(r: OutputRepr) -> Self {
        match r {
            OutputRepr::Path(path) => OutputFile {
                path,
                bytes: None,
                sha256: None,
            },
            OutputRepr::File {
                path,
                bytes,
                sha256,
            } => OutputFile {
                path,
                bytes,
                sha256,
            },
        }
    }
}

/// The status of a stage in a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StageStatus {
    /// Started and not finished: a resumed run reuses its finished shards.
    Running,
    /// All shards done; its files are being moved into place. Readers do not see them yet.
    Committing,
    /// Done; its outputs are in place and published: readers see them.
    Finished,
    /// Stopped with an error; nothing of it is in place.
    Failed,
}

/// The pipeline that last ran in this folder.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PipelineInfo {
    /// Pipeline name.
    pub name: String,
    /// Its file.
    pub file: String,
    /// SHA-256 of the file.
    pub sha256: String,
    /// Its seed.
    pub seed: u64,
}

/// One stage's record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageRecord {
    /// Stage kind.
    pub kind: String,
    /// Status.
    pub status: StageStatus,
    /// Fingerprint of kind, parameters, inputs and version.
    pub fingerprint: String,
    /// Parameters with defaults.
    pub params: Value,
    /// Input stages.
    pub inputs: Vec<String>,
    /// The seed it ran with.
    pub seed: u64,
    /// annotrace version that ran it.
    pub annotrace_version: String,
    /// RFC 3339 start time.
    pub started: Option<String>,
    /// RFC 3339 end time.
    pub finished: Option<String>,
    /// Wall time in seconds.
    pub seconds: Option<f64>,
    /// Rows written per table.
    pub rows: BTreeMap<String, u64>,
    /// Files written, relative to the run folder, with sizes and checksums.
    pub outputs: Vec<OutputFile>,
    /// Stage-specific summary.
    #[serde(default)]
    pub summary: Value,
    /// Why the last attempt failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The manifest of a run folder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Manifest format version.
    pub format: u32,
    /// annotrace version that last wrote it.
    pub annotrace_version: String,
    /// When the run folder was created.
    pub created: String,
    /// When the manifest was last written.
    pub updated: String,
    /// The pipeline that last ran here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pipeline: Option<PipelineInfo>,
    /// Stages by id.
    pub stages: BTreeMap<String, StageRecord>,
}

/// The current time as RFC 3339 with seconds.
pub fn now() -> String {
    humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string()
}

impl Manifest {
    /// An empty manifest.
    pub fn new() -> Self {
        let t = now();
        Manifest {
            format: FORMAT,
            annotrace_version: crate::VERSION.to_string(),
            created: t.clone(),
            updated: t,
            pipeline: None,
            stages: BTreeMap::new(),
        }
    }

    /// Reads the manifest of a run, or `None` when the run has none yet. A manifest of a newer format
    /// than [`FORMAT`] is refused.
    pub fn load(run: &RunDir) -> Result<Option<Self>, StoreError> {
        let path = run.manifest_path();
        let m: Self = match std::fs::read(&path) {
            Ok(bytes) => serde_json::from_slice(&bytes).map_err(|source| StoreError::Json {
                path: path.clone(),
                source,
            })?,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(StoreError::Io { path, source: e }),
        };
        if m.format > FORMAT {
            return Err(StoreError::ManifestFormat {
                path,
                found: m.format,
            });
        }
        Ok(Some(m))
    }

    /// Writes the manifest atomically (in format [`FORMAT`]). The rename of the new manifest over the
    /// old one is the commit point of every status change.
    pub fn save(&mut self, run: &RunDir) -> Result<(), StoreError> {
        let path = run.manifest_path();
        write_atomic(&path, &self.to_bytes())
            .map(|_| ())
            .map_err(|e| StoreError::Io { path, source: e })
    }

    /// The bytes [`Manifest::save`] writes (stamped with the time, [`FORMAT`] and this version).
    pub fn to_bytes(&mut self) -> Vec<u8> {
        self.updated = now();
        self.format = FORMAT;
        self.annotrace_version = crate::VERSION.to_string();
        let text = serde_json::to_string_pretty(self).expect("the manifest serialises");
        format!("{text}\n").into_bytes()
    }

    /// The published files: every output of a `finished` stage, with the stage's id, in stage order.
    /// Files of running, committing or failed stages, and files no stage lists, are not part of the run.
    pub fn published(&self) -> impl Iterator<Item = (&str, &OutputFile)> {
        self.stages
            .iter()
            .filter(|(_, r)| r.status == StageStatus::Finished)
            .flat_map(|(id, r)| r.outputs.iter().map(move |o| (id.as_str(), o)))
    }

    /// The stage that lists `path` (relative, `/`-separated) among its outputs, whatever its status.
    pub fn owner(&self, path: &str) -> Option<(&str, &StageRecord)> {
        self.stages
            .iter()
            .find(|(_, r)| r.outputs.iter().any(|o| o.path == path))
            .map(|(id, r)| (id.as_str(), r))
    }
}

/// The path of an output inside the run folder.
pub fn output_path(run: &RunDir, output: &OutputFile) -> std::path::PathBuf {
    run.root().join(Path::new(&output.path))
}

impl Default for Manifest {
    fn default() -> Self {
        Self::new()
    }
}
