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
//! Several detectors may share a label: in a plain library their patterns are reported side by side
//! (a fixed-weight union). An **ensemble library** (paper section 3.3, written by the `ensemble` stage)
//! adds one `[[ensemble]]` table per label and says where each member came from:
//!
//! ```toml
//! [[ensemble]]
//! label = "cue strike"
//! gamma = 0.5        # a cluster fires when its normalised activation exceeds γ
//! eps_s = 0.005      # spatial tolerance, in the environment's NEARBY_AT unit (pooltool: metres)
//! eps_t = 1          # temporal tolerance, timesteps
//! k = 2              # clusters = members
//!
//! [[detector]]
//! label = "cue strike"
//! file = "cue_strike_c0.py"
//! weight = 1.0       # reliability weight w
//! reward = 0.42      # training reward t (ν)
//! run = "evolve_s1"  # provenance: run folder / stage
//! candidate = "3f9c0a7e51d2b864"   # its candidates.code_hash there
//! cluster = 0
//! ```
//!
//! The detectors of a label with an `[[ensemble]]` table carry a [`Membership`]; the `ensemble`
//! module combines their patterns by activation clustering. Unknown keys are errors, so a typo does
//! not pass silently.
//!
//! A library is read from a folder on disk ([`Library::load`]) or from the built-in data compiled into
//! the binary ([`Library::builtin`]); [`Library::open`] takes either ([`Location`]). Ids, fingerprints
//! and stored code depend on the files' contents and names, never on where they were read from.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use sha2::{Digest, Sha256};

use super::detector::{Detector, DetectorId, EnsembleSettings, Membership};
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
    #[serde(default, rename = "ensemble")]
    ensembles: Vec<EnsembleEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EnsembleEntry {
    label: String,
    gamma: f64,
    eps_s: f64,
    eps_t: f64,
    k: u32,
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
    #[serde(default)]
    reward: Option<f64>,
    #[serde(default)]
    run: Option<String>,
    #[serde(default)]
    candidate: Option<String>,
    #[serde(default)]
    cluster: Option<u32>,
}

fn one() -> f64 {
    1.0
}

/// The ensemble fields of one `[[detector]]` entry: reward, run, candidate, cluster.
type MemberFields = (Option<f64>, Option<String>, Option<String>, Option<u32>);

/// Gives every detector of a label with an `[[ensemble]]` table its [`Membership`], checking the tables
/// (finite tolerances, γ in [0, 1), one table per label, at least one member, k = members).
fn attach_ensembles(
    detectors: Vec<(Detector, MemberFields)>,
    tables: &[EnsembleEntry],
) -> Result<Vec<Detector>, String> {
    let mut settings = Vec::new();
    for (i, t) in tables.iter().enumerate() {
        if tables[..i].iter().any(|u| u.label == t.label) {
            return Err(format!("two [[ensemble]] tables for label {:?}", t.label));
        }
        if !(0.0..1.0).contains(&t.gamma) {
            return Err(format!(
                "[[ensemble]] {:?}: gamma must be in [0, 1), found {}",
                t.label, t.gamma
            ));
        }
        for (name, v) in [("eps_s", t.eps_s), ("eps_t", t.eps_t)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!(
                    "[[ensemble]] {:?}: {name} must be a number ≥ 0, found {v}",
                    t.label
                ));
            }
        }
        let members: Vec<DetectorId> = detectors
            .iter()
            .filter(|(d, _)| d.label == t.label)
            .map(|(d, _)| d.id.clone())
            .collect();
        if members.is_empty() {
            return Err(format!(
                "[[ensemble]] {:?} names a label no [[detector]] has",
                t.label
            ));
        }
        if members.len() != t.k as usize {
            return Err(format!(
                "[[ensemble]] {:?}: k = {} but the label has {} member detector(s)",
                t.label,
                t.k,
                members.len()
            ));
        }
        settings.push(std::sync::Arc::new(EnsembleSettings {
            label: t.label.clone(),
            gamma: t.gamma,
            eps_s: t.eps_s,
            eps_t: t.eps_t,
            k: t.k,
            members,
        }));
    }
    Ok(detectors
        .into_iter()
        .map(|(mut d, (reward, run, candidate, cluster))| {
            if let Some(s) = settings.iter().find(|s| s.label == d.label) {
                d.ensemble = Some(std::sync::Arc::new(Membership {
                    settings: s.clone(),
                    reward: reward.unwrap_or(1.0),
                    run: run.unwrap_or_default(),
                    candidate: candidate.unwrap_or_default(),
                    cluster: cluster.unwrap_or(0),
                }));
            }
            d
        })
        .collect())
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
            let member = [
                e.reward.is_some(),
                e.run.is_some(),
                e.candidate.is_some(),
                e.cluster.is_some(),
            ];
            let is_member = m.ensembles.iter().any(|x| x.label == e.label);
            if !is_member && member.iter().any(|&b| b) {
                return Err(bad(format!(
                    "detector {:?} ({}) has ensemble fields (reward, run, candidate, cluster) but no [[ensemble]] table names its label",
                    e.label, e.file
                )));
            }
            if e.reward.is_some_and(|r| !r.is_finite()) {
                return Err(bad(format!(
                    "detector {:?}: reward must be a finite number",
                    e.label
                )));
            }
            detectors.push((
                Detector {
                    id: DetectorId::of(env, &e.label, &code),
                    label: e.label,
                    aliases: e.aliases,
                    env,
                    source: format!("{}/{}", m.library.name, e.file),
                    code,
                    weight: e.weight,
                    ensemble: None,
                },
                (e.reward, e.run, e.candidate, e.cluster),
            ));
        }
        let detectors = attach_ensembles(detectors, &m.ensembles).map_err(bad)?;
        Ok(Library {
            name: m.library.name,
            env,
            description: m.library.description,
            origin: dir.clone(),
            detectors,
        })
    }

    /// A hash of everything that decides the library's output (ids, labels, aliases, weights and, in
    /// an ensemble library, each member's reward and its label's γ, ε_s, ε_t), for stage fingerprints.
    /// A plain library's fingerprint is what it was before ensembles existed.
    pub fn fingerprint(&self) -> String {
        let mut h = Sha256::new();
        for d in &self.detectors {
            h.update(d.id.as_str().as_bytes());
            h.update(d.aliases.join("\u{1}").as_bytes());
            h.update(d.weight.to_le_bytes());
            h.update(d.source.as_bytes());
            if let Some(m) = &d.ensemble {
                let s = &m.settings;
                for x in [m.reward, s.gamma, s.eps_s, s.eps_t] {
                    h.update(x.to_le_bytes());
                }
            }
        }
        crate::digest::hex(&h.finalize())
    }

    /// Whether any label of the library is an ensemble (has an `[[ensemble]]` table).
    pub fn is_ensemble(&self) -> bool {
        self.detectors.iter().any(|d| d.ensemble.is_some())
    }

    /// The settings of each ensemble label, in manifest order of their first member.
    pub fn ensembles(&self) -> Vec<std::sync::Arc<EnsembleSettings>> {
        let mut out: Vec<std::sync::Arc<EnsembleSettings>> = Vec::new();
        for d in &self.detectors {
            if let Some(m) = &d.ensemble
                && !out.iter().any(|s| std::sync::Arc::ptr_eq(s, &m.settings))
            {
                out.push(m.settings.clone());
            }
        }
        out
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
