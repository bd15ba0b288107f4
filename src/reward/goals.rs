//! Goal files (`data/goals/<env>.toml`): natural-language goals with their reward program and a
//! hand-written verification rule ([`super::verify`]).
//!
//! ```toml
//! [goals]
//! env = "pooltool"
//! library = "data/libraries/pooltool"   # labels the programs are checked against
//! labels = ["falling object"]           # used instead when the library folder does not exist
//!
//! [[goal]]
//! id = "curve-pot-8"
//! sentence = "Make a ball curve around another ball, then pot the eight ball."
//! program = '''AND(...)'''
//! verify = "SEQ(CURVE(\"cue\"), FIRST_HIT(\"8\"), POCKET(\"8\"))"
//! source = "paper appendix G, goal 1"   # optional
//! ```
//!
//! A goal file is read from disk or from the built-in data ([`GoalSet::open`]); its relative `library`
//! is resolved against the project folder, then among the built-in libraries
//! ([`crate::builtin::Location::library`]).

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::error::RewardError;
use super::schema::{LabelInfo, Schema};
use super::verify::Rule;
use crate::builtin::Location;
use crate::detect::Library;
use crate::trace::Env;

/// One goal.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Goal {
    /// Short id, unique in the file.
    pub id: String,
    /// The goal in natural language.
    pub sentence: String,
    /// The reward program (DSL).
    pub program: String,
    /// The verification rule.
    pub verify: String,
    /// Where the goal comes from.
    #[serde(default)]
    pub source: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Header {
    env: String,
    #[serde(default)]
    library: Option<String>,
    #[serde(default)]
    labels: Vec<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    goals: Header,
    #[serde(default)]
    goal: Vec<Goal>,
}

/// A loaded goal file.
#[derive(Debug, Clone)]
pub struct GoalSet {
    /// The file (`(built-in) data/goals/<env>.toml` for a built-in one).
    pub path: PathBuf,
    /// The environment.
    pub env: Env,
    /// The library the programs are written for, when it exists.
    pub library: Option<Location>,
    /// The schema the programs were checked against.
    pub schema: Schema,
    /// The goals in file order.
    pub goals: Vec<Goal>,
}

/// Why a goal file could not be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GoalError {
    /// Reading failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The TOML is malformed or has unknown fields.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A goal's program or rule does not check.
    #[error("{path}: goal {id:?}, {field}: {error}")]
    Goal {
        /// The file.
        path: PathBuf,
        /// The goal.
        id: String,
        /// `program` or `verify`.
        field: &'static str,
        /// The error.
        error: RewardError,
    },
}

impl GoalSet {
    /// Loads and checks `path`; a relative `library` is resolved against `project` (and then the
    /// built-in libraries).
    pub fn load(path: &Path, project: &Path) -> Result<GoalSet, GoalError> {
        GoalSet::open(&Location::Disk(path.to_path_buf()), project)
    }

    /// Like [`GoalSet::load`], for a goal file on disk or a built-in one.
    pub fn open(at: &Location, project: &Path) -> Result<GoalSet, GoalError> {
        let path = &at.path();
        let text = at.read_to_string().map_err(|source| GoalError::Io {
            path: path.into(),
            source,
        })?;
        let fmt = |message: String| GoalError::Format {
            path: path.into(),
            message,
        };
        let file: File = toml::from_str(&text).map_err(|e| fmt(e.to_string()))?;
        let env: Env = file
            .goals
            .env
            .parse()
            .map_err(|e: crate::trace::UnknownEnv| fmt(format!("goals.env: {e}")))?;
        let library = file
            .goals
            .library
            .as_ref()
            .map(|l| Location::library(project, Path::new(l)))
            .filter(Location::is_library);
        let schema = match &library {
            Some(dir) => {
                let lib = Library::open(dir).map_err(|e| fmt(format!("goals.library: {e}")))?;
                Schema::from_library(&lib)
            }
            None if !file.goals.labels.is_empty() => Schema {
                env,
                library: format!("{env} labels of {}", path.display()),
                labels: file
                    .goals
                    .labels
                    .iter()
                    .map(|l| LabelInfo {
                        label: l.clone(),
                        aliases: Vec::new(),
                        keys: None,
                    })
                    .collect(),
            },
            None => {
                return Err(fmt(
                    "goals: give a `library` folder that exists or a list of `labels`".into(),
                ));
            }
        };
        let mut seen = std::collections::BTreeSet::new();
        for g in &file.goal {
            if !seen.insert(g.id.clone()) {
                return Err(fmt(format!("goal id {:?} appears twice", g.id)));
            }
            let bad = |field, error| GoalError::Goal {
                path: path.into(),
                id: g.id.clone(),
                field,
                error,
            };
            super::compile(&g.program, &schema).map_err(|e| bad("program", e))?;
            Rule::parse(&g.verify).map_err(|e| bad("verify", e))?;
        }
        Ok(GoalSet {
            path: path.into(),
            env,
            library,
            schema,
            goals: file.goal,
        })
    }

    /// The goal with this id.
    pub fn get(&self, id: &str) -> Option<&Goal> {
        self.goals.iter().find(|g| g.id == id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_builtin_goal_file_opens_from_an_empty_project_like_its_file_in_the_repository() {
        let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
        let empty = tempfile::tempdir().unwrap();
        for env in Env::ALL {
            let rel = format!("data/goals/{env}.toml");
            let at = Location::file(empty.path(), Path::new(&rel));
            assert!(at.is_builtin(), "{rel}");
            let built = GoalSet::open(&at, empty.path()).unwrap();
            let disk = GoalSet::load(&repo.join(&rel), repo).unwrap();
            assert_eq!(built.env, env);
            assert_eq!(built.goals, disk.goals, "{rel}");
            assert_eq!(built.schema.labels.len(), disk.schema.labels.len(), "{rel}");
            // The goal file's library is the built-in one, found without the repository.
            let lib = built.library.as_ref().expect("a library");
            assert!(lib.is_builtin(), "{rel}: {lib}");
            assert_eq!(built.path, Path::new(&format!("(built-in) {rel}")));
        }
    }
}
