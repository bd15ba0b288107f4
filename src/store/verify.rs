//! Verified reading: a run's files checked against the sizes and SHA-256 sums its manifest records.
//!
//! **Owns:** the checks of one output file ([`check_size`], cheap, done by every reader as it lists a
//! table; [`check_file`], which adds the checksum, done by `annotrace verify` and by `run` before it
//! skips a stage as cached), the SHA-256 of a file ([`sha256_file`]) and the whole-run check
//! ([`verify_run`]): every published file, every journal file, and every file in a table folder that no
//! stage lists (foreign). **Does not:** repair anything (the runner reruns a damaged stage), or decide
//! which files are published (`store::manifest`).

use std::collections::HashSet;
use std::fs::{self, File};
use std::io::{self, Read};
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use super::manifest::{Manifest, OutputFile, StageStatus};
use super::{JOURNAL_TABLES, RESERVED, RunDir, StoreError};
use crate::digest::hex;

/// What is wrong with a file the manifest lists.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Problem {
    /// The file is not there.
    Missing,
    /// Its size differs from the recorded one (`expected` is `None` when the manifest records no size
    /// and the file is empty).
    Size {
        /// The recorded size.
        expected: Option<u64>,
        /// The size on disk.
        found: u64,
    },
    /// Its SHA-256 differs from the recorded one.
    Checksum {
        /// The recorded SHA-256.
        expected: String,
        /// The SHA-256 of the file on disk.
        found: String,
    },
    /// It could not be read, or is not a Parquet file.
    Unreadable(String),
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Problem::Missing => write!(f, "missing (manifest.json lists it)"),
            Problem::Size {
                expected: Some(e),
                found: 0,
            } => write!(f, "is empty (0 bytes), manifest.json records {e} bytes"),
            Problem::Size {
                expected: Some(e),
                found,
            } if found < e => write!(
                f,
                "is truncated: {found} bytes, manifest.json records {e} bytes"
            ),
            Problem::Size {
                expected: Some(e),
                found,
            } => write!(f, "is {found} bytes, manifest.json records {e} bytes"),
            Problem::Size {
                expected: None,
                found,
            } => write!(f, "is {found} bytes (an empty Parquet file)"),
            Problem::Checksum { expected, found } => write!(
                f,
                "SHA-256 {} differs from the {} recorded in manifest.json (contents changed)",
                short(found),
                short(expected)
            ),
            Problem::Unreadable(e) => write!(f, "cannot be read: {e}"),
        }
    }
}

fn short(sha: &str) -> &str {
    &sha[..sha.len().min(12)]
}

/// Checks that an output file exists with the size the manifest records (a stat; an empty Parquet
/// file when no size is recorded) and returns its metadata.
pub fn check_size(path: &Path, output: &OutputFile) -> Result<fs::Metadata, Problem> {
    let meta = match fs::metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Err(Problem::Missing),
        Err(e) => return Err(Problem::Unreadable(e.to_string())),
    };
    match output.bytes {
        Some(expected) if meta.len() != expected => Err(Problem::Size {
            expected: Some(expected),
            found: meta.len(),
        }),
        None if meta.len() == 0 && output.path.ends_with(".parquet") => Err(Problem::Size {
            expected: None,
            found: 0,
        }),
        _ => Ok(meta),
    }
}

/// The size and SHA-256 (hex) of a file, read in 1 MiB blocks.
pub fn sha256_file(path: &Path) -> io::Result<(u64, String)> {
    let mut f = File::open(path)?;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut n = 0u64;
    loop {
        let k = f.read(&mut buf)?;
        if k == 0 {
            break;
        }
        h.update(&buf[..k]);
        n += k as u64;
    }
    Ok((n, hex(&h.finalize())))
}

/// Checks an output file's size and, when `checksum` is set and the manifest records one, its SHA-256.
pub fn check_file(path: &Path, output: &OutputFile, checksum: bool) -> Result<(), Problem> {
    check_size(path, output)?;
    if let (true, Some(expected)) = (checksum, &output.sha256) {
        let (_, found) = sha256_file(path).map_err(|e| Problem::Unreadable(e.to_string()))?;
        if &found != expected {
            return Err(Problem::Checksum {
                expected: expected.clone(),
                found,
            });
        }
    }
    Ok(())
}

/// A damaged file of a run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Damaged {
    /// Its path relative to the run folder.
    pub path: String,
    /// The stage that lists it (`-` for a journal table's file).
    pub stage: String,
    /// What is wrong.
    pub problem: Problem,
}

/// The outcome of [`verify_run`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VerifyReport {
    /// Published files checked (size and checksum).
    pub checked: usize,
    /// Their total size in bytes.
    pub bytes: u64,
    /// Journal files checked (readable Parquet).
    pub journal: usize,
    /// Missing, resized, changed or unreadable files.
    pub damaged: Vec<Damaged>,
    /// Files in table folders that no stage lists: readers ignore them.
    pub foreign: Vec<String>,
    /// Files of a stage that is not finished (an interrupted commit; `run` finishes it), with the stage.
    pub unpublished: Vec<(String, String)>,
    /// Published files without a recorded checksum (a format 1 manifest), checked for size only.
    pub unverified: Vec<String>,
}

impl VerifyReport {
    /// Whether nothing is damaged and no foreign file lies in a table folder.
    pub fn is_clean(&self) -> bool {
        self.damaged.is_empty() && self.foreign.is_empty()
    }
}

/// Checks a whole run folder: the size and SHA-256 of every published file, that every journal file is
/// a readable Parquet file, and which files in table folders no stage lists. Hidden files (temporary
/// files, `.staging/`) and `exports/` files that no stage lists (written by `--out`) are not reported.
pub fn verify_run(run: &RunDir) -> Result<VerifyReport, StoreError> {
    let manifest = Manifest::load(run)?.unwrap_or_default();
    let mut report = VerifyReport::default();
    let mut published = HashSet::new();
    for (stage, o) in manifest.published() {
        published.insert(o.path.as_str());
        let path = run.root().join(Path::new(&o.path));
        report.checked += 1;
        match check_file(&path, o, true) {
            Ok(()) => {
                report.bytes += o.bytes.unwrap_or(0);
                if o.sha256.is_none() {
                    report.unverified.push(o.path.clone());
                }
            }
            Err(problem) => report.damaged.push(Damaged {
                path: o.path.clone(),
                stage: stage.to_string(),
                problem,
            }),
        }
    }
    for table in JOURNAL_TABLES {
        for path in super::parquet_files_or_none(&run.root().join(table))? {
            report.journal += 1;
            if let Err(problem) = readable_parquet(&path) {
                report.damaged.push(Damaged {
                    path: relative(run, &path),
                    stage: "-".into(),
                    problem,
                });
            }
        }
    }
    for path in table_folder_files(run)? {
        let rel = relative(run, &path);
        if published.contains(rel.as_str()) {
            continue;
        }
        match manifest.owner(&rel) {
            Some((stage, r)) if r.status != StageStatus::Finished => {
                report.unpublished.push((rel, stage.to_string()))
            }
            _ => report.foreign.push(rel),
        }
    }
    report.foreign.sort();
    Ok(report)
}

/// Opens a Parquet file's footer.
fn readable_parquet(path: &Path) -> Result<(), Problem> {
    let f = File::open(path).map_err(|e| Problem::Unreadable(e.to_string()))?;
    if f.metadata().map(|m| m.len()).unwrap_or(0) == 0 {
        return Err(Problem::Size {
            expected: None,
            found: 0,
        });
    }
    parquet::file::reader::SerializedFileReader::new(f)
        .map(|_| ())
        .map_err(|e| Problem::Unreadable(e.to_string()))
}

fn relative(run: &RunDir, path: &Path) -> String {
    path.strip_prefix(run.root())
        .unwrap_or(path)
        .to_string_lossy()
        .replace('\\', "/")
}

/// Every non-hidden file below the run's table folders (not `exports/`, the journal tables, hidden or
/// `_` folders).
fn table_folder_files(run: &RunDir) -> Result<Vec<PathBuf>, StoreError> {
    let mut out = Vec::new();
    let root = run.root();
    let entries = match fs::read_dir(root) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(out),
        Err(e) => return Err(StoreError::io(root, e)),
    };
    let mut stack = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| StoreError::io(root, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if entry.path().is_dir()
            && !name.starts_with('.')
            && !name.starts_with('_')
            && !RESERVED.contains(&name.as_str())
            && !JOURNAL_TABLES.contains(&name.as_str())
        {
            stack.push(entry.path());
        }
    }
    while let Some(dir) = stack.pop() {
        for entry in fs::read_dir(&dir).map_err(|e| StoreError::io(&dir, e))? {
            let entry = entry.map_err(|e| StoreError::io(&dir, e))?;
            if entry.file_name().to_string_lossy().starts_with('.') {
                continue;
            }
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.push(path);
            }
        }
    }
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use arrow::array::{Int64Array, RecordBatch};
    use arrow::datatypes::{DataType, Field, Schema};

    use super::*;
    use crate::store::ParquetSink;
    use crate::store::manifest::StageRecord;

    fn parquet(path: &Path, n: i64) {
        let schema = Arc::new(Schema::new(vec![Field::new("x", DataType::Int64, false)]));
        let batch = RecordBatch::try_new(
            schema.clone(),
            vec![Arc::new(Int64Array::from_iter_values(0..n))],
        )
        .unwrap();
        let mut sink = ParquetSink::create(path, schema).unwrap();
        sink.write(&batch).unwrap();
        sink.commit().unwrap();
    }

    fn record(status: StageStatus, outputs: Vec<OutputFile>) -> StageRecord {
        StageRecord {
            kind: "import".into(),
            status,
            fingerprint: "f".into(),
            params: serde_json::Value::Null,
            inputs: Vec::new(),
            seed: 0,
            annotrace_version: crate::VERSION.into(),
            started: None,
            finished: None,
            seconds: None,
            rows: Default::default(),
            outputs,
            summary: serde_json::Value::Null,
            error: None,
        }
    }

    fn output(run: &RunDir, rel: &str) -> OutputFile {
        let (bytes, sha) = sha256_file(&run.root().join(rel)).unwrap();
        OutputFile::new(rel.into(), bytes, sha)
    }

    /// Only the outputs of finished stages are listed: a committing stage's files and a foreign file
    /// in the same folder are not, and become visible only with the manifest that says finished.
    #[test]
    fn readers_see_finished_stages_only() {
        let dir = tempfile::tempdir().unwrap();
        let run = RunDir::new(dir.path());
        parquet(&dir.path().join("traces/env=pooltool/a.0.parquet"), 10);
        parquet(&dir.path().join("traces/env=pooltool/foreign.parquet"), 3);
        let out = output(&run, "traces/env=pooltool/a.0.parquet");
        let mut m = Manifest::new();
        m.stages.insert(
            "a".into(),
            record(StageStatus::Committing, vec![out.clone()]),
        );
        m.save(&run).unwrap();
        assert!(run.tables().unwrap().is_empty());
        assert!(run.table("traces").unwrap().files.is_empty());
        let report = verify_run(&run).unwrap();
        assert_eq!(report.foreign, ["traces/env=pooltool/foreign.parquet"]);
        assert_eq!(report.unpublished.len(), 1);

        m.stages.get_mut("a").unwrap().status = StageStatus::Finished;
        m.save(&run).unwrap();
        let t = run.table("traces").unwrap();
        assert!(t.partitioned);
        assert_eq!(t.files.len(), 1);
        assert!(t.files[0].path.ends_with("a.0.parquet"));
        assert_eq!(Some(t.files[0].bytes), out.bytes);
        let report = verify_run(&run).unwrap();
        assert_eq!((report.checked, report.damaged.len()), (1, 0));
        assert!(!report.is_clean(), "the foreign file is reported");
    }

    /// Sizes are checked as files are listed; checksums by `verify_run`.
    #[test]
    fn damaged_files_are_named_with_what_is_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let run = RunDir::new(dir.path());
        let rel = ["t/a.parquet", "t/b.parquet", "t/c.parquet"];
        for r in rel {
            parquet(&dir.path().join(r), 100);
        }
        let mut m = Manifest::new();
        m.stages.insert(
            "s".into(),
            record(
                StageStatus::Finished,
                rel.iter().map(|r| output(&run, r)).collect(),
            ),
        );
        m.save(&run).unwrap();
        assert_eq!(run.table("t").unwrap().files.len(), 3);

        // c: same size, one byte changed: listed (sizes match), caught by the checksum.
        let c = dir.path().join(rel[2]);
        let mut bytes = fs::read(&c).unwrap();
        bytes[10] ^= 1;
        fs::write(&c, &bytes).unwrap();
        assert_eq!(run.table("t").unwrap().files.len(), 3);
        // b: truncated; a: missing.
        let b = dir.path().join(rel[1]);
        let len = fs::metadata(&b).unwrap().len();
        File::options()
            .write(true)
            .open(&b)
            .unwrap()
            .set_len(len / 2)
            .unwrap();
        let err = run.table("t").unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("t/b.parquet") && msg.contains("is truncated"),
            "{msg}"
        );
        assert!(matches!(err, StoreError::Damaged { .. }));
        fs::remove_file(dir.path().join(rel[0])).unwrap();

        let report = verify_run(&run).unwrap();
        let problems: Vec<(&str, &Problem)> = report
            .damaged
            .iter()
            .map(|d| (d.path.as_str(), &d.problem))
            .collect();
        assert_eq!(problems.len(), 3);
        assert_eq!(problems[0], ("t/a.parquet", &Problem::Missing));
        assert!(matches!(problems[1].1, Problem::Size { found, .. } if *found == len / 2));
        assert!(matches!(problems[2].1, Problem::Checksum { .. }));
        assert!(problems[2].1.to_string().contains("differs from the"));
    }

    /// Format 1 listed outputs as bare paths; they are read with no size or checksum.
    #[test]
    fn format_1_outputs_are_bare_paths() {
        let o: OutputFile = serde_json::from_str("\"traces/x.parquet\"").unwrap();
        assert_eq!(
            (o.path.as_str(), o.bytes, o.sha256),
            ("traces/x.parquet", None, None)
        );
        let o: OutputFile =
            serde_json::from_str(r#"{"path": "t/x.parquet", "bytes": 4, "sha256": "ab"}"#).unwrap();
        assert_eq!(o, OutputFile::new("t/x.parquet".into(), 4, "ab".into()));
        assert_eq!(
            serde_json::to_string(&o).unwrap(),
            r#"{"path":"t/x.parquet","bytes":4,"sha256":"ab"}"#
        );
    }
}
