//! `manifest.json`: what a run folder holds and how it got there, rewritten atomically after every change.
//!
//! Per stage it records the kind, parameters, inputs, fingerprint, status (`running`, `committing`,
//! `finished`, `failed`), start and end times, rows written per table, output files (relative to the
//! run folder), a stage-specific summary and the error of a failed attempt.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::store::{RunDir, StoreError, write_atomic};

/// The status of a stage in a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StageStatus {
    /// Started and not finished: a resumed run reuses its finished shards.
    Running,
    /// All shards done; its files are being moved into place.
    Committing,
    /// Done; its outputs are in place.
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
    /// Files written, relative to the run folder.
    pub outputs: Vec<String>,
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
            format: 1,
            annotrace_version: crate::VERSION.to_string(),
            created: t.clone(),
            updated: t,
            pipeline: None,
            stages: BTreeMap::new(),
        }
    }

    /// Reads the manifest of a run, or `None` when the run has none yet.
    pub fn load(run: &RunDir) -> Result<Option<Self>, StoreError> {
        let path = run.manifest_path();
        match std::fs::read(&path) {
            Ok(bytes) => serde_json::from_slice(&bytes)
                .map(Some)
                .map_err(|source| StoreError::Json { path, source }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(StoreError::Io { path, source: e }),
        }
    }

    /// Writes the manifest atomically.
    pub fn save(&mut self, run: &RunDir) -> Result<(), StoreError> {
        self.updated = now();
        self.annotrace_version = crate::VERSION.to_string();
        let path = run.manifest_path();
        let text = serde_json::to_string_pretty(self).expect("the manifest serialises");
        write_atomic(&path, format!("{text}\n").as_bytes())
            .map(|_| ())
            .map_err(|e| StoreError::Io { path, source: e })
    }

    /// Whether every output of a finished stage still exists.
    pub fn outputs_present(&self, run: &RunDir, id: &str) -> bool {
        self.stages.get(id).is_some_and(|r| {
            r.outputs
                .iter()
                .all(|o| run.root().join(Path::new(o)).exists())
        })
    }
}

impl Default for Manifest {
    fn default() -> Self {
        Self::new()
    }
}
