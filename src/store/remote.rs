//! Run folders on object storage (`s3://bucket/prefix`, cargo feature `s3`): the objects of a run on
//! an S3-compatible store (AWS, MinIO, Ceph) and the local copy the runner and the query engine work
//! on.
//!
//! **Owns:** the connection ([`RemoteRun::open`]: credentials, region and endpoint from the usual
//! `AWS_*` variables, `AWS_ENDPOINT_URL` and `AWS_ALLOW_HTTP` for a local store), the object layout
//! (below), the conditional writes (immutable objects with `If-None-Match: *`, the manifest with
//! `If-Match` on the ETag it was read with), pulling a run into a local [`Mirror`] (through a
//! content-addressed download cache) and publishing files. **Does not:** decide when a stage commits
//! or which records go into the manifest (`pipeline::remote`), or query (`query/`, which reads the
//! mirror).
//!
//! ```text
//! s3://bucket/prefix/
//! ├── manifest.json                                   the run's manifest, byte for byte the local format;
//! │                                                   replaced only with If-Match on its ETag
//! ├── traces/env=pooltool/sim.00000.<sha16>.parquet   a published file: its manifest path with the first
//! │                                                   16 hex digits of its SHA-256 before the extension,
//! │                                                   written once (If-None-Match: *), never replaced
//! ├── llm_calls/…                                     the journal table, file by file, written once
//! └── .staging/<stage>/<fp16>/                        a sharded stage's slices before its commit:
//!     ├── parts/<path in the staging area, sha16>     each slice's files, written once
//!     └── _slices/<i>-of-<n>.json                     a slice's record (its files, its units' records),
//!                                                     written once: the commit point of the slice
//! ```
//!
//! Readers resolve a table's files only through the manifest (its outputs carry path, size and
//! SHA-256, from which the object key follows), so an object no manifest names — of a killed writer,
//! a losing writer, or an older version of a stage — is invisible and harmless.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use futures::TryStreamExt;
use object_store::aws::AmazonS3Builder;
use object_store::path::Path as Key;
use object_store::{ObjectStore, ObjectStoreExt, PutMode, PutOptions, PutPayload, UpdateVersion};
use sha2::Digest;

use super::manifest::{FORMAT, Manifest, OutputFile, StageStatus};
use super::{JOURNAL_TABLES, StoreError, is_temp_name, write_atomic};
use crate::digest::hex;

/// The manifest's ETag as the store returned it: the version a conditional replace must match.
pub type ETag = String;

/// One run on an object store.
pub struct RemoteRun {
    url: String,
    bucket: String,
    prefix: String,
    store: Arc<dyn ObjectStore>,
    runtime: tokio::runtime::Runtime,
    cache: PathBuf,
}

impl std::fmt::Debug for RemoteRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RemoteRun").field("url", &self.url).finish()
    }
}

/// The key of a published file: its manifest path with the first 16 hex digits of its SHA-256 before
/// the extension (`traces/env=pooltool/sim.00000.parquet` → `…/sim.00000.0123456789abcdef.parquet`);
/// the path itself for a file recorded without a checksum (manifest format 1).
pub fn object_name(path: &str, sha256: Option<&str>) -> String {
    let Some(sha) = sha256.filter(|s| s.len() >= 16) else {
        return path.to_string();
    };
    let (dir, file) = path.rsplit_once('/').map_or(("", path), |(d, f)| (d, f));
    let named = match file.rsplit_once('.') {
        Some((stem, ext)) => format!("{stem}.{}.{ext}", &sha[..16]),
        None => format!("{file}.{}", &sha[..16]),
    };
    if dir.is_empty() {
        named
    } else {
        format!("{dir}/{named}")
    }
}

/// `s3://bucket/prefix` split into bucket and prefix (without slashes at either end).
fn parse_url(url: &str) -> Result<(String, String), String> {
    let rest = url
        .strip_prefix("s3://")
        .ok_or_else(|| format!("{url:?}: expected s3://bucket/prefix"))?;
    let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
    if bucket.is_empty() {
        return Err(format!("{url:?}: no bucket (expected s3://bucket/prefix)"));
    }
    let prefix = prefix.trim_matches('/');
    if prefix.split('/').any(|p| p == "." || p == "..")
        || prefix.contains("//")
        || prefix.contains('\\')
    {
        return Err(format!(
            "{url:?}: the prefix must be a plain path (no `.`, `..`, `//` or `\\`)"
        ));
    }
    Ok((bucket.to_string(), prefix.to_string()))
}

/// The download cache: `ANNOTRACE_S3_CACHE`, else `$XDG_CACHE_HOME/annotrace/s3`, else
/// `$HOME/.cache/annotrace/s3`, else the temporary folder.
fn cache_root() -> PathBuf {
    let var = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    if let Some(p) = var("ANNOTRACE_S3_CACHE") {
        return p;
    }
    var("XDG_CACHE_HOME")
        .or_else(|| var("HOME").map(|h| h.join(".cache")))
        .map(|c| c.join("annotrace").join("s3"))
        .unwrap_or_else(|| std::env::temp_dir().join("annotrace-s3"))
}

impl RemoteRun {
    /// Connects to the run at `url` (`s3://bucket/prefix`). Credentials, region and endpoint come from
    /// the environment as for the AWS tools: `AWS_ACCESS_KEY_ID`, `AWS_SECRET_ACCESS_KEY`,
    /// `AWS_SESSION_TOKEN`, `AWS_REGION`, `AWS_ENDPOINT_URL` (MinIO, Ceph, a local server) and
    /// `AWS_ALLOW_HTTP=true` for a plain-HTTP endpoint. Nothing is read until asked.
    pub fn open(url: &str) -> Result<Self, StoreError> {
        Self::open_with(url, &[])
    }

    /// Like [`RemoteRun::open`], with client settings (`aws_endpoint`, `aws_region`, …: object_store's
    /// `AmazonS3ConfigKey` names) over the environment's.
    pub fn open_with(url: &str, config: &[(String, String)]) -> Result<Self, StoreError> {
        let (bucket, prefix) = parse_url(url).map_err(|message| StoreError::Remote {
            location: url.to_string(),
            message,
        })?;
        let mut builder = AmazonS3Builder::from_env();
        for (k, v) in config {
            let key = k.parse().map_err(|e| StoreError::Remote {
                location: url.to_string(),
                message: format!("client setting {k:?}: {e}"),
            })?;
            builder = builder.with_config(key, v);
        }
        let store = builder
            .with_bucket_name(&bucket)
            .build()
            .map_err(|e| StoreError::Remote {
                location: url.to_string(),
                message: format!("cannot configure the S3 client: {e}"),
            })?;
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| StoreError::io(Path::new(url), e))?;
        Ok(RemoteRun {
            url: format!(
                "s3://{bucket}{}{prefix}",
                if prefix.is_empty() { "" } else { "/" }
            ),
            bucket,
            prefix,
            store: Arc::new(store),
            runtime,
            cache: cache_root(),
        })
    }

    /// `s3://bucket/prefix`.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// The bucket.
    pub fn bucket(&self) -> &str {
        &self.bucket
    }

    fn key(&self, rel: &str) -> Key {
        if self.prefix.is_empty() {
            Key::from(rel)
        } else {
            Key::from(format!("{}/{rel}", self.prefix))
        }
    }

    fn err(&self, rel: &str, e: object_store::Error) -> StoreError {
        StoreError::Remote {
            location: format!("{}/{rel}", self.url),
            message: e.to_string(),
        }
    }

    /// The manifest and its ETag, or `None` when the run has none.
    pub fn load_manifest(&self) -> Result<Option<(Manifest, Vec<u8>, ETag)>, StoreError> {
        let rel = "manifest.json";
        let got = self.runtime.block_on(async {
            let r = self.store.get(&self.key(rel)).await?;
            let etag = r.meta.e_tag.clone();
            Ok::<_, object_store::Error>((r.bytes().await?, etag))
        });
        let (bytes, etag) = match got {
            Ok(x) => x,
            Err(object_store::Error::NotFound { .. }) => return Ok(None),
            Err(e) => return Err(self.err(rel, e)),
        };
        let path = PathBuf::from(format!("{}/{rel}", self.url));
        let m: Manifest = serde_json::from_slice(&bytes).map_err(|source| StoreError::Json {
            path: path.clone(),
            source,
        })?;
        if m.format > FORMAT {
            return Err(StoreError::ManifestFormat {
                path,
                found: m.format,
            });
        }
        let etag = etag.ok_or_else(|| StoreError::Remote {
            location: format!("{}/{rel}", self.url),
            message: "the store returned no ETag; conditional writes need one".into(),
        })?;
        Ok(Some((m, bytes.to_vec(), etag)))
    }

    /// Writes the manifest: created when `base` is `None` (refused if one exists), else replaced only
    /// if the stored one still has ETag `base`. Returns the new ETag; [`StoreError::Conflict`] when
    /// another writer got there first (nothing was written).
    pub fn put_manifest(&self, bytes: Vec<u8>, base: Option<&str>) -> Result<ETag, StoreError> {
        let rel = "manifest.json";
        let mode = match base {
            None => PutMode::Create,
            Some(e) => PutMode::Update(UpdateVersion {
                e_tag: Some(e.to_string()),
                version: None,
            }),
        };
        let put = self.runtime.block_on(self.store.put_opts(
            &self.key(rel),
            PutPayload::from(bytes),
            PutOptions::from(mode),
        ));
        match put {
            Ok(r) => r.e_tag.ok_or_else(|| StoreError::Remote {
                location: format!("{}/{rel}", self.url),
                message: "the store returned no ETag; conditional writes need one".into(),
            }),
            Err(object_store::Error::AlreadyExists { .. } | object_store::Error::Precondition { .. }) => {
                Err(StoreError::Conflict {
                    location: self.url.clone(),
                    message: "another writer replaced manifest.json since this process read it; \
                              nothing of this commit was published (its files are unreferenced and harmless)"
                        .into(),
                })
            }
            Err(e) => Err(self.err(rel, e)),
        }
    }

    /// Writes `bytes` at `rel` unless an object is there: true when written, false when it existed.
    pub fn put_new(&self, rel: &str, bytes: Vec<u8>) -> Result<bool, StoreError> {
        let put = self.runtime.block_on(self.store.put_opts(
            &self.key(rel),
            PutPayload::from(bytes),
            PutOptions::from(PutMode::Create),
        ));
        match put {
            Ok(_) => Ok(true),
            Err(
                object_store::Error::AlreadyExists { .. }
                | object_store::Error::Precondition { .. },
            ) => Ok(false),
            Err(e) => Err(self.err(rel, e)),
        }
    }

    /// Uploads the local file `local` to `rel` (content-addressed keys: an object already there holds
    /// the same bytes and is kept).
    pub fn upload(&self, local: &Path, rel: &str) -> Result<(), StoreError> {
        let exists = match self.runtime.block_on(self.store.head(&self.key(rel))) {
            Ok(_) => true,
            Err(object_store::Error::NotFound { .. }) => false,
            Err(e) => return Err(self.err(rel, e)),
        };
        if !exists {
            let bytes = std::fs::read(local).map_err(|e| StoreError::io(local, e))?;
            self.put_new(rel, bytes)?;
        }
        Ok(())
    }

    /// The object at `rel`, or `None`.
    pub fn get(&self, rel: &str) -> Result<Option<Vec<u8>>, StoreError> {
        let got = self.runtime.block_on(async {
            let r = self.store.get(&self.key(rel)).await?;
            r.bytes().await
        });
        match got {
            Ok(b) => Ok(Some(b.to_vec())),
            Err(object_store::Error::NotFound { .. }) => Ok(None),
            Err(e) => Err(self.err(rel, e)),
        }
    }

    /// Every key under `rel_prefix` (relative to the run, sorted).
    pub fn list(&self, rel_prefix: &str) -> Result<Vec<String>, StoreError> {
        let prefix = self.key(rel_prefix.trim_end_matches('/'));
        let metas: Vec<object_store::ObjectMeta> = self
            .runtime
            .block_on(self.store.list(Some(&prefix)).try_collect())
            .map_err(|e| self.err(rel_prefix, e))?;
        let strip = if self.prefix.is_empty() {
            String::new()
        } else {
            format!("{}/", self.prefix)
        };
        let mut out: Vec<String> = metas
            .into_iter()
            .filter_map(|m| m.location.as_ref().strip_prefix(&strip).map(str::to_string))
            .collect();
        out.sort();
        Ok(out)
    }

    /// Downloads the object `rel` whose contents have SHA-256 `sha256` (and `bytes` bytes) to `dest`,
    /// through the download cache: a file fetched once is linked from the cache afterwards. A download
    /// whose size or checksum differs is refused ([`StoreError::Damaged`]).
    pub fn fetch(
        &self,
        rel: &str,
        sha256: Option<&str>,
        bytes: Option<u64>,
        dest: &Path,
    ) -> Result<(), StoreError> {
        if let Some(parent) = dest.parent() {
            std::fs::create_dir_all(parent).map_err(|e| StoreError::io(parent, e))?;
        }
        let _ = std::fs::remove_file(dest);
        let cached = sha256.map(|s| {
            self.cache
                .join("objects")
                .join(&s[..2.min(s.len())])
                .join(s)
        });
        if let Some(c) = cached.as_ref().filter(|c| c.is_file()) {
            return link_or_copy(c, dest);
        }
        let data = self.get(rel)?.ok_or_else(|| StoreError::Remote {
            location: format!("{}/{rel}", self.url),
            message: "the manifest names this object but the store has none; the run is damaged"
                .into(),
        })?;
        let found_sha = hex(&sha2::Sha256::digest(&data));
        let problem = if let Some(expected) = bytes.filter(|&b| b != data.len() as u64) {
            Some(super::Problem::Size {
                expected: Some(expected),
                found: data.len() as u64,
            })
        } else {
            sha256
                .filter(|&s| s != found_sha)
                .map(|expected| super::Problem::Checksum {
                    expected: expected.to_string(),
                    found: found_sha,
                })
        };
        if let Some(problem) = problem {
            return Err(StoreError::Damaged {
                path: PathBuf::from(format!("{}/{rel}", self.url)),
                stage: "-".into(),
                run: PathBuf::from(&self.url),
                problem,
            });
        }
        match cached {
            Some(c) => {
                write_atomic(&c, &data).map_err(|e| StoreError::io(&c, e))?;
                link_or_copy(&c, dest)
            }
            None => write_atomic(dest, &data)
                .map(|_| ())
                .map_err(|e| StoreError::io(dest, e)),
        }
    }

    /// Pulls the run into `mirror`: its manifest, every published file (the outputs of finished
    /// stages) and the journal tables' files. Returns the manifest and its ETag (`None` for a run
    /// without a manifest: a new run). Files of unfinished stages are not fetched.
    pub fn pull(&self, mirror: &Path) -> Result<Option<(Manifest, ETag)>, StoreError> {
        std::fs::create_dir_all(mirror).map_err(|e| StoreError::io(mirror, e))?;
        let loaded = self.load_manifest()?;
        let local_manifest = mirror.join("manifest.json");
        let Some((manifest, bytes, etag)) = loaded else {
            let _ = std::fs::remove_file(&local_manifest);
            return Ok(None);
        };
        for (_, o) in manifest.published() {
            let dest = mirror.join(&o.path);
            if o.sha256.is_some() && is_unchanged(&dest, o) {
                continue;
            }
            self.fetch(
                &object_name(&o.path, o.sha256.as_deref()),
                o.sha256.as_deref(),
                o.bytes,
                &dest,
            )?;
        }
        for table in JOURNAL_TABLES {
            for rel in self.list(table)? {
                let dest = mirror.join(&rel);
                if !dest.is_file() {
                    self.fetch(&rel, None, None, &dest)?;
                }
            }
        }
        write_atomic(&local_manifest, &bytes).map_err(|e| StoreError::io(&local_manifest, e))?;
        Ok(Some((manifest, etag)))
    }

    /// Uploads the outputs of the finished stages of `manifest` (found in `mirror`) that the store
    /// does not hold yet, and the journal tables' files.
    pub fn push_outputs(&self, mirror: &Path, manifest: &Manifest) -> Result<(), StoreError> {
        for (_, o) in manifest.published() {
            self.push_output(mirror, o)?;
        }
        self.push_journal(mirror)
    }

    /// Uploads one output file from `mirror`.
    pub fn push_output(&self, mirror: &Path, o: &OutputFile) -> Result<(), StoreError> {
        self.upload(
            &mirror.join(&o.path),
            &object_name(&o.path, o.sha256.as_deref()),
        )
    }

    /// Uploads the journal tables' files of `mirror` the store does not hold.
    pub fn push_journal(&self, mirror: &Path) -> Result<(), StoreError> {
        for table in JOURNAL_TABLES {
            for file in walk(&mirror.join(table))? {
                let rel = file
                    .strip_prefix(mirror)
                    .expect("walked below the mirror")
                    .to_string_lossy()
                    .replace('\\', "/");
                self.upload(&file, &rel)?;
            }
        }
        Ok(())
    }

    /// The published outputs no stage of the current manifest names, and staged slices of stages
    /// that are not running: what a killed, losing or superseded writer left. Safe to delete while no
    /// writer runs (a running writer's uploads may look unreferenced until it commits).
    pub fn orphans(&self) -> Result<Vec<String>, StoreError> {
        let manifest = self.load_manifest()?.map(|(m, _, _)| m);
        let mut named = std::collections::BTreeSet::new();
        let mut staging_live = Vec::new();
        if let Some(m) = &manifest {
            for (id, r) in &m.stages {
                for o in &r.outputs {
                    named.insert(object_name(&o.path, o.sha256.as_deref()));
                }
                if r.status == StageStatus::Running {
                    staging_live.push(format!(
                        ".staging/{id}/{}/",
                        &r.fingerprint[..16.min(r.fingerprint.len())]
                    ));
                }
            }
        }
        let mut out = Vec::new();
        for key in self.list("")? {
            let journal = JOURNAL_TABLES
                .iter()
                .any(|t| key.starts_with(&format!("{t}/")));
            let live = staging_live.iter().any(|p| key.starts_with(p));
            if key == "manifest.json" || journal || live || named.contains(&key) {
                continue;
            }
            out.push(key);
        }
        Ok(out)
    }

    /// Deletes the objects `keys` (relative to the run).
    pub fn delete(&self, keys: &[String]) -> Result<(), StoreError> {
        for k in keys {
            match self.runtime.block_on(self.store.delete(&self.key(k))) {
                Ok(()) | Err(object_store::Error::NotFound { .. }) => {}
                Err(e) => return Err(self.err(k, e)),
            }
        }
        Ok(())
    }

    /// A fresh local folder to pull this run into.
    pub fn mirror(&self) -> Result<Mirror, StoreError> {
        Mirror::new(&self.cache.join("work"))
    }
}

/// Pulls the remote run `url` into a fresh local mirror for reading (`query`, `tables`, …).
pub fn open_for_reading(url: &str) -> Result<(Mirror, super::RunDir), StoreError> {
    let remote = RemoteRun::open(url)?;
    let mirror = remote.mirror()?;
    if remote.pull(mirror.path())?.is_none() {
        return Err(StoreError::Remote {
            location: url.to_string(),
            message: "no run here (no manifest.json)".into(),
        });
    }
    let run = super::RunDir::new(mirror.path());
    Ok((mirror, run))
}

/// Whether the local file `dest` already has the output's size and checksum.
fn is_unchanged(dest: &Path, o: &OutputFile) -> bool {
    let Ok(meta) = std::fs::metadata(dest) else {
        return false;
    };
    if o.bytes.is_some_and(|b| b != meta.len()) {
        return false;
    }
    super::verify::sha256_file(dest).is_ok_and(|(_, s)| Some(s) == o.sha256)
}

fn link_or_copy(from: &Path, to: &Path) -> Result<(), StoreError> {
    if std::fs::hard_link(from, to).is_ok() {
        return Ok(());
    }
    let data = std::fs::read(from).map_err(|e| StoreError::io(from, e))?;
    write_atomic(to, &data)
        .map(|_| ())
        .map_err(|e| StoreError::io(to, e))
}

/// Every file below `dir` (none when it does not exist), skipping temporary files.
pub(crate) fn walk(dir: &Path) -> Result<Vec<PathBuf>, StoreError> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let entries = match std::fs::read_dir(&d) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(e) => return Err(StoreError::io(&d, e)),
        };
        for entry in entries {
            let entry = entry.map_err(|e| StoreError::io(&d, e))?;
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if !is_temp_name(&entry.file_name().to_string_lossy()) {
                out.push(path);
            }
        }
    }
    out.sort();
    Ok(out)
}

/// Removes the mirrors of processes that ended without removing theirs (killed): `run-<pid>-<n>`
/// whose process no longer exists.
fn remove_dead_mirrors(parent: &Path) {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = name
            .strip_prefix("run-")
            .and_then(|r| r.split_once('-'))
            .and_then(|(p, _)| p.parse::<libc::pid_t>().ok())
        else {
            continue;
        };
        // SAFETY: kill with signal 0 sends nothing; it only asks whether the process exists.
        let gone = unsafe { libc::kill(pid, 0) } == -1
            && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH);
        if gone {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

static MIRRORS: AtomicU64 = AtomicU64::new(0);

/// A local folder holding a pulled copy of a remote run, removed when dropped.
#[derive(Debug)]
pub struct Mirror {
    dir: PathBuf,
}

impl Mirror {
    fn new(parent: &Path) -> Result<Self, StoreError> {
        std::fs::create_dir_all(parent).map_err(|e| StoreError::io(parent, e))?;
        remove_dead_mirrors(parent);
        let n = MIRRORS.fetch_add(1, Ordering::Relaxed);
        let dir = parent.join(format!("run-{}-{n}", std::process::id()));
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|e| StoreError::io(&dir, e))?;
        }
        std::fs::create_dir_all(&dir).map_err(|e| StoreError::io(&dir, e))?;
        let mut marker =
            std::fs::File::create(dir.join(".mirror")).map_err(|e| StoreError::io(&dir, e))?;
        let _ = writeln!(
            marker,
            "a local copy of a remote run; removed when its process ends"
        );
        Ok(Mirror { dir })
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }
}

impl Drop for Mirror {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn object_names_carry_the_checksum() {
        let sha = "0123456789abcdef0123456789abcdef0123456789abcdef0123456789abcdef";
        assert_eq!(
            object_name("traces/env=pooltool/sim.00000.parquet", Some(sha)),
            "traces/env=pooltool/sim.00000.0123456789abcdef.parquet"
        );
        assert_eq!(
            object_name("exports/a", Some(sha)),
            "exports/a.0123456789abcdef"
        );
        assert_eq!(object_name("x/y.parquet", None), "x/y.parquet");
    }

    #[test]
    fn urls_name_a_bucket_and_a_plain_prefix() {
        assert_eq!(
            parse_url("s3://b/runs/q/").unwrap(),
            ("b".to_string(), "runs/q".to_string())
        );
        assert_eq!(
            parse_url("s3://b").unwrap(),
            ("b".to_string(), String::new())
        );
        assert!(parse_url("s3:///x").is_err());
        assert!(parse_url("s3://b/../x").is_err());
        assert!(parse_url("/local").is_err());
    }
}
