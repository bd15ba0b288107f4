//! A detector library on disk: a folder with a `library.toml` manifest and one `.py` file per detector,
//! which people can read and edit.
//!
//! ```toml
//! [library]
//! name = "pooltool-human"
//! env = "pooltool"
//! description = "Hand-written detectors for the paper's 12 PoolTool human labels"
//!
//! [[detector]]
//! label = "cue strike"          # the label its patterns carry
//! file = "cue_strike.py"        # defines find_pattern(trace)
//! aliases = ["stick strike"]    # optional: other spellings the validator accepts
//! weight = 1.0                  # optional: its value in the annotation matrix
//! prelude = ["_contacts.py"]     # optional: helper files prepended to this detector only
//! ```
//!
//! `[library] prelude = [...]` lists helper files prepended to every detector. Detectors cannot import,
//! so shared helpers live in prelude files; the loaded code (library preludes, then the detector's, then
//! its file) is what runs, is hashed into the detector id and is stored, so every detector stays
//! self-contained. Line numbers in its errors count from the top of that combined code.
//!
//! Several detectors may share a label (an ensemble). Unknown keys are errors, so a typo does not pass
//! silently.
//!
//! A library is read from a folder on disk ([`Library::load`]) or from the built-in data compiled into
//! the binary ([`Library::builtin`]); [`Library::open`] takes either ([`Location`]). Ids, fingerprints
//! and stored code depend on the files' contents and names, never on where they were read from.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use sha2::{Digest, Sha256};

use super::detector::{Detector, DetectorId};
use crate::builtin::Location;
use crate::trace::Env;

/// A library could not be loaded; every variant names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LibraryError {
    /// A file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The manifest is not valid.
    #[error("{}: {message}", path.display())]
    Manifest {
        /// The manifest.
        path: PathBuf,
        /// What is wrong (from the TOML parser, with line and column).
        message: String,
    },
}

/// Checks that file `name` of a library stays inside the library folder: a relative path of plain
/// components (no `..`, no root), and on disk, after symbolic links are followed, still under the
/// folder. A manifest naming `../../etc/passwd` or `/etc/hostname` is refused, never read.
fn inside(dir: &Location, name: &str) -> Result<(), String> {
    use std::path::Component;
    let rel = Path::new(name);
    if name.is_empty() || !rel.components().all(|c| matches!(c, Component::Normal(_))) {
        return Err(format!(
            "file {name:?} must be a relative path inside the library folder (no `..`, no leading `/`)"
        ));
    }
    if let Location::Disk(root) = dir {
        let file = root.join(rel);
        if let (Ok(root), Ok(file)) = (root.canonicalize(), file.canonicalize())
            && !file.starts_with(&root)
        {
            return Err(format!(
                "file {name:?} leads outside the library folder (to {})",
                file.display()
            ));
        }
    }
    Ok(())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Manifest {
    library: Header,
    #[serde(default, rename = "detector")]
    detectors: Vec<Entry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Header {
    name: String,
    env: String,
    #[serde(default)]
    description: String,
    #[serde(default)]
    prelude: Vec<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Entry {
    label: String,
    file: String,
    #[serde(default)]
    aliases: Vec<String>,
    #[serde(default = "one")]
    weight: f64,
    #[serde(default)]
    prelude: Vec<String>,
}

fn one() -> f64 {
    1.0
}

/// A loaded library.
#[derive(Clone, Debug)]
pub struct Library {
    /// Its name.
    pub name: String,
    /// The environment its detectors read.
    pub env: Env,
    /// One paragraph on what it is.
    pub description: String,
    /// Where it was read from: a folder on disk, or built in.
    pub origin: Location,
    /// Its detectors, in manifest order.
    pub detectors: Vec<Detector>,
}

impl Library {
    /// Reads `dir/library.toml` and the detector files it lists.
    pub fn load(dir: &Path) -> Result<Library, LibraryError> {
        Library::open(&Location::Disk(dir.to_path_buf()))
    }

    /// The built-in library of `env` (`data/libraries/<env>`, compiled into the binary).
    pub fn builtin(env: Env) -> Result<Library, LibraryError> {
        Library::open(&Location::Builtin(crate::builtin::library_path(env)))
    }

    /// Reads `library.toml` and the detector files it lists from a folder on disk or a built-in one.
    pub fn open(dir: &Location) -> Result<Library, LibraryError> {
        let path = dir.join("library.toml").path();
        let read = |name: &str| {
            inside(dir, name).map_err(|message| LibraryError::Manifest {
                path: path.clone(),
                message,
            })?;
            let file = dir.join(name);
            file.read_to_string().map_err(|source| LibraryError::Io {
                path: file.path(),
                source,
            })
        };
        let text = read("library.toml")?;
        let bad = |message: String| LibraryError::Manifest {
            path: path.clone(),
            message,
        };
        let m: Manifest = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
        let env: Env = m
            .library
            .env
            .parse()
            .map_err(|e: crate::trace::UnknownEnv| bad(e.to_string()))?;
        if m.detectors.is_empty() {
            return Err(bad("the library lists no [[detector]]".into()));
        }
        let mut shared = String::new();
        for name in &m.library.prelude {
            shared.push_str(&read(name)?);
            shared.push_str("\n\n");
        }
        let mut detectors = Vec::with_capacity(m.detectors.len());
        for e in m.detectors {
            if e.label.trim().is_empty() {
                return Err(bad(format!(
                    "detector file {:?} has an empty label",
                    e.file
                )));
            }
            if !(e.weight.is_finite()) {
                return Err(bad(format!(
                    "detector {:?}: weight must be a finite number",
                    e.label
                )));
            }
            let mut code = shared.clone();
            for name in &e.prelude {
                code.push_str(&read(name)?);
                code.push_str("\n\n");
            }
            code.push_str(&read(&e.file)?);
            detectors.push(Detector {
                id: DetectorId::of(env, &e.label, &code),
                label: e.label,
                aliases: e.aliases,
                env,
                source: format!("{}/{}", m.library.name, e.file),
                code,
                weight: e.weight,
            });
        }
        Ok(Library {
            name: m.library.name,
            env,
            description: m.library.description,
            origin: dir.clone(),
            detectors,
        })
    }

    /// A hash of everything that decides the library's output (ids, labels, aliases, weights), for
    /// stage fingerprints.
    pub fn fingerprint(&self) -> String {
        let mut h = Sha256::new();
        for d in &self.detectors {
            h.update(d.id.as_str().as_bytes());
            h.update(d.aliases.join("\u{1}").as_bytes());
            h.update(d.weight.to_le_bytes());
            h.update(d.source.as_bytes());
        }
        crate::digest::hex(&h.finalize())
    }

    /// The distinct labels, in manifest order.
    pub fn labels(&self) -> Vec<&str> {
        let mut out: Vec<&str> = Vec::new();
        for d in &self.detectors {
            if !out.contains(&d.label.as_str()) {
                out.push(&d.label);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_pooltool_library_loads() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/libraries/pooltool");
        let lib = Library::load(&dir).unwrap();
        assert_eq!(lib.env, Env::Pooltool);
        assert_eq!(lib.labels().len(), 12);
        assert!(
            lib.detectors
                .iter()
                .all(|d| d.code.contains("def find_pattern(trace)"))
        );
        assert_eq!(
            lib.fingerprint(),
            Library::load(&dir).unwrap().fingerprint()
        );
    }

    #[test]
    fn each_builtin_library_is_its_folder_byte_for_byte() {
        for env in Env::ALL {
            let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(crate::builtin::library_path(env));
            let disk = Library::load(&dir).unwrap();
            let built = Library::builtin(env).unwrap();
            assert!(built.origin.is_builtin() && !disk.origin.is_builtin());
            assert_eq!(built.fingerprint(), disk.fingerprint(), "{env}");
            assert_eq!((&built.name, built.env), (&disk.name, disk.env));
            let code = |l: &Library| -> Vec<(String, String)> {
                l.detectors
                    .iter()
                    .map(|d| (d.source.clone(), d.code.clone()))
                    .collect()
            };
            assert_eq!(code(&built), code(&disk), "{env}");
        }
    }

    #[test]
    fn manifest_errors_name_the_file_and_the_fault() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::write(
            tmp.path().join("library.toml"),
            "[library]\nname = \"x\"\nenv = \"pooltool\"\n[[detector]]\nlabel = \"a\"\nfile = \"a.py\"\ncolour = 1\n",
        )
        .unwrap();
        let e = Library::load(tmp.path()).unwrap_err().to_string();
        assert!(e.contains("library.toml") && e.contains("colour"), "{e}");
        std::fs::write(
            tmp.path().join("library.toml"),
            "[library]\nname = \"x\"\nenv = \"pooltool\"\n[[detector]]\nlabel = \"a\"\nfile = \"a.py\"\n",
        )
        .unwrap();
        let e = Library::load(tmp.path()).unwrap_err().to_string();
        assert!(e.contains("a.py"), "{e}");
    }

    #[test]
    fn files_outside_the_library_folder_are_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let lib = tmp.path().join("lib");
        std::fs::create_dir(&lib).unwrap();
        std::fs::write(tmp.path().join("secret.py"), "x = 1\n").unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink(tmp.path().join("secret.py"), lib.join("link.py")).unwrap();
        for (file, message) in [
            (
                "../secret.py",
                "must be a relative path inside the library folder",
            ),
            (
                "/etc/hostname",
                "must be a relative path inside the library folder",
            ),
            ("link.py", "leads outside the library folder"),
        ] {
            std::fs::write(
                lib.join("library.toml"),
                format!("[library]\nname = \"x\"\nenv = \"pooltool\"\n[[detector]]\nlabel = \"a\"\nfile = \"{file}\"\n"),
            )
            .unwrap();
            let e = Library::load(&lib).unwrap_err().to_string();
            assert!(e.contains(message), "{file}: {e}");
            assert!(e.contains("library.toml"), "{e}");
        }
    }
}
