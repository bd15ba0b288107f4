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

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::error::RewardError;
use super::schema::{LabelInfo, Schema};
use super::verify::Rule;
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
    /// The file.
    pub path: PathBuf,
    /// The environment.
    pub env: Env,
    /// The library folder the programs are written for, when it exists.
    pub library: Option<PathBuf>,
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
    /// crate's own folder).
    pub fn load(path: &Path, project: &Path) -> Result<GoalSet, GoalError> {
        let text = std::fs::read_to_string(path).map_err(|source| GoalError::Io {
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
        let library = file.goals.library.as_ref().and_then(|l| {
            [
                project.join(l),
                Path::new(env!("CARGO_MANIFEST_DIR")).join(l),
            ]
            .into_iter()
            .find(|p| p.join("library.toml").is_file())
        });
        let schema = match &library {
            Some(dir) => {
                let lib = Library::load(dir).map_err(|e| fmt(format!("goals.library: {e}")))?;
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
