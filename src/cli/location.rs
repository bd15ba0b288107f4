//! Run locations on the command line: a local folder, or `s3://bucket/prefix` (feature `s3`), which
//! reading commands (`query`, `tables`, `show`, `export`, `verify`, `annotate`'s summary) see through a
//! pulled local copy.

use std::path::{Path, PathBuf};

use super::CliError;

/// A run ready to read: its local folder (a pulled copy for a remote run, removed when dropped).
pub(crate) struct LocalRun {
    path: PathBuf,
    #[cfg(feature = "s3")]
    _mirror: Option<annotrace::store::remote::Mirror>,
}

impl LocalRun {
    /// The local folder.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }
}

/// Opens the run at `location` for reading: a local folder that must exist, or a remote run pulled
/// into a local copy.
pub(crate) fn local_run(location: &Path) -> Result<LocalRun, CliError> {
    if let Some(url) = annotrace::store::remote_url(location) {
        #[cfg(feature = "s3")]
        {
            let (mirror, run) = annotrace::store::remote::open_for_reading(url)?;
            return Ok(LocalRun {
                path: run.root().to_path_buf(),
                _mirror: Some(mirror),
            });
        }
        #[cfg(not(feature = "s3"))]
        return Err(CliError::of(
            annotrace::store::StoreError::RemoteUnsupported {
                location: url.to_string(),
            },
        ));
    }
    if !location.is_dir() {
        return Err(CliError::input(anyhow::anyhow!(
            "{}: no such run folder",
            location.display()
        )));
    }
    Ok(LocalRun {
        path: location.to_path_buf(),
        #[cfg(feature = "s3")]
        _mirror: None,
    })
}

/// Checks that a run a command adds a stage to exists: a local folder, or a remote run with a manifest.
pub(crate) fn check_exists(location: &Path) -> Result<(), CliError> {
    if let Some(url) = annotrace::store::remote_url(location) {
        #[cfg(feature = "s3")]
        {
            let remote = annotrace::store::remote::RemoteRun::open(url)?;
            if remote.load_manifest()?.is_none() {
                return Err(CliError::input(anyhow::anyhow!(
                    "{url}: no run here (no manifest.json)"
                )));
            }
            return Ok(());
        }
        #[cfg(not(feature = "s3"))]
        return Err(CliError::of(
            annotrace::store::StoreError::RemoteUnsupported {
                location: url.to_string(),
            },
        ));
    }
    local_run(location).map(|_| ())
}
