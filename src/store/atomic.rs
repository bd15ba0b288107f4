//! Atomic files: written under a temporary name in the target's folder, synced, then renamed.
//!
//! A reader (or a resumed run) therefore sees either the old file, or the complete new one, never a
//! partial write. A file dropped without [`AtomicFile::commit`] is removed; one left behind by a killed
//! process has a name that starts with `.` and ends in `.tmp`, which no reader lists.

use std::fs::{self, File};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// True for the temporary names this module creates.
pub fn is_temp_name(name: &str) -> bool {
    name.starts_with('.') && name.ends_with(".tmp")
}

/// A file being written; it appears at its final path only on commit.
#[derive(Debug)]
pub struct AtomicFile {
    file: Option<File>,
    temp: PathBuf,
    target: PathBuf,
    committed: bool,
}

impl AtomicFile {
    /// Starts writing `target`, creating its folder if needed.
    pub fn create(target: impl Into<PathBuf>) -> io::Result<Self> {
        let target = target.into();
        let dir = target
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        fs::create_dir_all(dir)?;
        let name = target
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("file");
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let temp = dir.join(format!(".{name}.{}-{n}.tmp", std::process::id()));
        let file = File::create(&temp)?;
        Ok(AtomicFile {
            file: Some(file),
            temp,
            target,
            committed: false,
        })
    }

    /// The path the file will have once committed.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Syncs the data, renames the file into place and syncs the folder.
    pub fn commit(mut self) -> io::Result<PathBuf> {
        let file = self
            .file
            .take()
            .expect("an uncommitted AtomicFile holds its file");
        file.sync_all()?;
        drop(file);
        fs::rename(&self.temp, &self.target)?;
        self.committed = true;
        sync_dir(self.target.parent())?;
        Ok(self.target.clone())
    }

    /// Commits a file whose handle was passed to another writer and came back.
    fn commit_with(mut self, file: File) -> io::Result<PathBuf> {
        self.file = Some(file);
        self.commit()
    }

    /// The open handle, for a writer that needs ownership of it (through [`AtomicFile::take_buffered`]).
    fn take_file(&mut self) -> File {
        self.file.take().expect("the file handle is taken once")
    }

    /// The open handle behind a buffer of `WRITE_BUFFER` bytes (1 MiB), for a writer that needs
    /// ownership (the Parquet writers); hand it back to [`AtomicFile::commit_buffered`].
    pub fn take_buffered(&mut self) -> BufWriter<File> {
        BufWriter::with_capacity(WRITE_BUFFER, self.take_file())
    }

    /// Writes out what the buffer holds, then commits as [`AtomicFile::commit`] does.
    pub fn commit_buffered(self, buffered: BufWriter<File>) -> io::Result<PathBuf> {
        let file = buffered
            .into_inner()
            .map_err(io::IntoInnerError::into_error)?;
        self.commit_with(file)
    }
}

/// Bytes a buffered file ([`AtomicFile::take_buffered`]) gathers before writing. The Parquet writers
/// hand their output over in pieces of at most 8 KiB (parquet-rs's own buffer), a system call each
/// without this one: about 18,000 per 2,000 billiard traces.
pub const WRITE_BUFFER: usize = 1 << 20;

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.file
            .as_mut()
            .expect("file is open while writing")
            .write(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.file
            .as_mut()
            .expect("file is open while writing")
            .flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.committed {
            let _ = fs::remove_file(&self.temp);
        }
    }
}

/// Syncs a folder so that a rename inside it survives a crash.
pub fn sync_dir(dir: Option<&Path>) -> io::Result<()> {
    let dir = dir
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    match File::open(dir) {
        Ok(d) => d.sync_all().or(Ok(())),
        Err(_) => Ok(()),
    }
}

/// Replaces the folder `target` by `tmp` (a finished folder beside it) so that a reader sees the old
/// folder or the new one, never none or half of one: the old folder is renamed aside, the new one
/// renamed into place, the parent synced, then the old one removed.
pub fn swap_dir(tmp: &Path, target: &Path) -> io::Result<()> {
    let parent = target.parent().unwrap_or(Path::new(".")).to_path_buf();
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let old = parent.join(format!(".{name}.old-{}", std::process::id()));
    let had_old = target.exists();
    if had_old {
        std::fs::rename(target, &old)?;
    }
    std::fs::rename(tmp, target)?;
    sync_dir(Some(&parent))?;
    if had_old {
        std::fs::remove_dir_all(&old)?;
    }
    Ok(())
}

/// Writes the folder `target` atomically: `fill` writes its files into a fresh temporary folder beside
/// it (`.<name>.tmp-<pid>`), which [`swap_dir`] then puts in place; when `fill` fails, the temporary
/// folder is removed and `target` is left as it was.
pub fn write_dir_atomic(
    target: &Path,
    fill: impl FnOnce(&Path) -> io::Result<()>,
) -> io::Result<()> {
    let parent = target.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent)?;
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = parent.join(format!(".{name}.tmp-{}", std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp)?;
    }
    std::fs::create_dir_all(&tmp)?;
    if let Err(e) = fill(&tmp) {
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(e);
    }
    swap_dir(&tmp, target)
}

/// Writes `bytes` to `target` atomically.
pub fn write_atomic(target: impl Into<PathBuf>, bytes: &[u8]) -> io::Result<PathBuf> {
    let mut f = AtomicFile::create(target)?;
    f.write_all(bytes)?;
    f.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_uncommitted_file_leaves_nothing_behind() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("a.json");
        {
            let mut f = AtomicFile::create(&target).unwrap();
            f.write_all(b"partial").unwrap();
        }
        assert!(!target.exists());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn commit_replaces_the_old_file_whole() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("a.json");
        write_atomic(&target, b"old").unwrap();
        let mut f = AtomicFile::create(&target).unwrap();
        f.write_all(b"new contents").unwrap();
        assert_eq!(fs::read(&target).unwrap(), b"old");
        f.commit().unwrap();
        assert_eq!(fs::read(&target).unwrap(), b"new contents");
        let names: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1);
    }
}
