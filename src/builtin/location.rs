//! Where a file or library folder that a user names is read from: the disk, or the built-in data
//! ([`super`]). It does not parse what it reads (that is `detect::Library` and `reward::goals`).
//!
//! The rules, the same for every command and stage:
//! - A relative path in a pipeline or goal file (resolved against the project folder) is read from disk
//!   when something exists there. Otherwise, when it is the repository path of built-in data
//!   (`data/libraries/pooltool`, `data/goals/pooltool.toml`), the built-in copy is read. Otherwise it
//!   stays a disk path, so the error names the path that is missing.
//! - With no library given, `<project>/data/libraries/<env>` is used when it has a `library.toml`
//!   (running from a clone uses its files), else the built-in library of the environment. The CLI's
//!   project folder is the current folder.
//! - Paths given on the command line are made absolute by the CLI, so they are always read from disk.
//!
//! Built-in data is read from memory; nothing is unpacked to disk (detectors run from their code in
//! memory, so no command needs a library as a folder).

use std::fmt;
use std::io;
use std::path::{Path, PathBuf};

use crate::trace::Env;

/// A file or folder to read: on disk, or built in (by its repository path).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Location {
    /// A path on disk.
    Disk(PathBuf),
    /// The repository path of built-in data, e.g. `data/libraries/pooltool`.
    Builtin(String),
}

impl Location {
    /// `rel` under `base`: on disk when it exists there, else the built-in at repository path `rel`
    /// when there is one, else on disk.
    pub fn file(base: &Path, rel: &Path) -> Location {
        Self::resolve(base, rel, |p| super::get(p).is_some())
    }

    /// Like [`Location::file`], for a library folder (a built-in library has a `library.toml`).
    pub fn library(base: &Path, rel: &Path) -> Location {
        Self::resolve(base, rel, super::is_library)
    }

    /// The library a stage or command uses when none is given: `base/data/libraries/<env>` when it has
    /// a `library.toml`, else the built-in library of `env`.
    pub fn default_library(base: &Path, env: Env) -> Location {
        let path = super::library_path(env);
        let local = base.join(&path);
        if local.join("library.toml").is_file() {
            Location::Disk(local)
        } else {
            Location::Builtin(path)
        }
    }

    fn resolve(base: &Path, rel: &Path, builtin: impl Fn(&str) -> bool) -> Location {
        let disk = base.join(rel);
        if disk.exists() || rel.is_absolute() {
            return Location::Disk(disk);
        }
        match rel.to_str().and_then(super::normalise) {
            Some(p) if builtin(&p) => Location::Builtin(p),
            _ => Location::Disk(disk),
        }
    }

    /// The file or folder `name` inside this folder.
    pub fn join(&self, name: &str) -> Location {
        match self {
            Location::Disk(p) => Location::Disk(p.join(name)),
            Location::Builtin(p) => Location::Builtin(format!("{p}/{name}")),
        }
    }

    /// Whether this is built-in data.
    pub fn is_builtin(&self) -> bool {
        matches!(self, Location::Builtin(_))
    }

    /// Whether this is a library folder: it has a `library.toml`.
    pub fn is_library(&self) -> bool {
        match self {
            Location::Disk(p) => p.join("library.toml").is_file(),
            Location::Builtin(p) => super::is_library(p),
        }
    }

    /// The file's text; a built-in that does not exist is an [`io::ErrorKind::NotFound`] error.
    pub fn read_to_string(&self) -> io::Result<String> {
        match self {
            Location::Disk(p) => std::fs::read_to_string(p),
            Location::Builtin(p) => super::text(p)
                .map(str::to_string)
                .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "no such built-in file")),
        }
    }

    /// The path to show in messages: the disk path, or `(built-in) <repository path>`.
    pub fn path(&self) -> PathBuf {
        match self {
            Location::Disk(p) => p.clone(),
            Location::Builtin(_) => PathBuf::from(self.to_string()),
        }
    }

    /// This location as a path parameter relative to a project folder, which [`Location::library`] or
    /// [`Location::file`] resolves back to it: the disk path, or the built-in's repository path.
    pub fn as_param(&self) -> String {
        match self {
            Location::Disk(p) => p.to_string_lossy().into_owned(),
            Location::Builtin(p) => p.clone(),
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Disk(p) => write!(f, "{}", p.display()),
            Location::Builtin(p) => write!(f, "(built-in) {p}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_disk_wins_then_the_builtin_then_the_disk_path_for_the_error() {
        let tmp = tempfile::tempdir().unwrap();
        let base = tmp.path();
        let goals = Path::new("data/goals/pooltool.toml");
        assert_eq!(
            Location::file(base, goals),
            Location::Builtin("data/goals/pooltool.toml".into())
        );
        std::fs::create_dir_all(base.join("data/goals")).unwrap();
        std::fs::write(base.join(goals), "mine").unwrap();
        let mine = Location::file(base, goals);
        assert_eq!(mine, Location::Disk(base.join(goals)));
        assert_eq!(mine.read_to_string().unwrap(), "mine");
        let missing = Location::file(base, Path::new("data/goals/nope.toml"));
        assert_eq!(missing, Location::Disk(base.join("data/goals/nope.toml")));
        assert!(missing.read_to_string().is_err());
        // An absolute path is never a built-in, even when it ends like one.
        let abs = base.join("elsewhere/data/libraries/pooltool");
        assert_eq!(Location::library(base, &abs), Location::Disk(abs.clone()));
    }

    #[test]
    fn libraries_resolve_to_the_builtin_unless_the_project_has_its_own() {
        let tmp = tempfile::tempdir().unwrap();
        let base = tmp.path();
        let lib = Location::library(base, Path::new("./data/libraries/phyre/"));
        assert_eq!(lib, Location::Builtin("data/libraries/phyre".into()));
        assert!(lib.is_library());
        assert!(
            lib.join("library.toml")
                .read_to_string()
                .unwrap()
                .contains("[library]")
        );
        assert_eq!(lib.to_string(), "(built-in) data/libraries/phyre");
        assert_eq!(Location::library(base, Path::new(&lib.as_param())), lib);
        // A folder that is not a built-in library stays on disk.
        assert!(!Location::library(base, Path::new("data/goals")).is_builtin());
        assert_eq!(
            Location::default_library(base, Env::Iphyre),
            Location::Builtin("data/libraries/iphyre".into())
        );
        let own = base.join("data/libraries/iphyre");
        std::fs::create_dir_all(&own).unwrap();
        // A folder without a manifest is not a library, so the default stays the built-in one…
        assert!(Location::default_library(base, Env::Iphyre).is_builtin());
        // …but a path naming it explicitly means that folder.
        assert_eq!(
            Location::library(base, Path::new("data/libraries/iphyre")),
            Location::Disk(own.clone())
        );
        std::fs::write(own.join("library.toml"), "").unwrap();
        assert_eq!(
            Location::default_library(base, Env::Iphyre),
            Location::Disk(own)
        );
    }
}
