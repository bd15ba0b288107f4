//! Prompt templates: Jinja files in the repository's `prompts/` folder, rendered with minijinja.
//!
//! Every template is compiled into the binary (`include_str!`), so annotrace works from any folder.
//! [`Prompts::load`] with a folder (the command line's `--prompts DIR`, `ANNOTRACE_PROMPTS`, or
//! `./prompts` when it exists) reads each template from that folder instead when the file is there, so
//! prompts can be edited without rebuilding; [`Prompts::sources`] says which one each template came
//! from. Templates are strict: a variable the caller did not pass is an error, not an empty string.
//!
//! | template | renders | context |
//! |---|---|---|
//! | `system.j2` | the system message of code requests | — |
//! | `evolve.j2` | the code-evolution prompt | [`EvolveContext`] |
//! | `repair.j2` | the repair prompt | [`RepairContext`] |
//! | `suggest_labels.j2` | the label-suggestion prompt | [`LabelsContext`] |
//! | `rules.j2` | the detector contract (macro, shared) | — |
//! | `env/<env>.j2` | an environment's trace layout and advice (macros) | — |
//!
//! Other modules add their own templates with [`Prompts::add_template`] (the same folder-then-built-in
//! rule applies).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use minijinja::syntax::SyntaxConfig;
use minijinja::{Environment, UndefinedBehavior};
use serde::Serialize;

use super::error::LlmError;
use crate::detect::Library;
use crate::fitness::FitnessTerms;
use crate::trace::Env;

/// The built-in templates: (name, text).
const BUILTIN: &[(&str, &str)] = &[
    ("system.j2", include_str!("../../prompts/system.j2")),
    ("rules.j2", include_str!("../../prompts/rules.j2")),
    ("evolve.j2", include_str!("../../prompts/evolve.j2")),
    ("repair.j2", include_str!("../../prompts/repair.j2")),
    (
        "suggest_labels.j2",
        include_str!("../../prompts/suggest_labels.j2"),
    ),
    (
        "env/pooltool.j2",
        include_str!("../../prompts/env/pooltool.j2"),
    ),
    ("env/phyre.j2", include_str!("../../prompts/env/phyre.j2")),
    ("env/iphyre.j2", include_str!("../../prompts/env/iphyre.j2")),
];

/// Where a template's text came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PromptSource {
    /// Compiled into the binary.
    BuiltIn,
    /// Read from this file.
    File(PathBuf),
}

/// The loaded templates.
#[derive(Debug)]
pub struct Prompts {
    env: Environment<'static>,
    dir: Option<PathBuf>,
    sources: BTreeMap<String, PromptSource>,
}

impl Prompts {
    /// The built-in templates only.
    pub fn builtin() -> Self {
        Self::load(None).expect("the built-in templates parse (tested)")
    }

    /// The templates, each read from `dir` when the file exists there and built in otherwise.
    pub fn load(dir: Option<&Path>) -> Result<Self, LlmError> {
        let mut env = Environment::new();
        env.set_undefined_behavior(UndefinedBehavior::Strict);
        env.set_syntax(
            SyntaxConfig::builder()
                .trim_blocks(true)
                .lstrip_blocks(true)
                .build()
                .expect("default delimiters"),
        );
        let mut p = Prompts {
            env,
            dir: dir.map(Path::to_path_buf),
            sources: BTreeMap::new(),
        };
        for (name, text) in BUILTIN {
            p.add_template(name, text)?;
        }
        Ok(p)
    }

    /// Adds template `name` (a path relative to the prompts folder), read from the folder when the file
    /// is there and `builtin` otherwise.
    pub fn add_template(&mut self, name: &str, builtin: &'static str) -> Result<(), LlmError> {
        let file = self
            .dir
            .as_ref()
            .map(|d| d.join(name))
            .filter(|f| f.is_file());
        let (text, source) = match file {
            Some(f) => {
                let text = std::fs::read_to_string(&f).map_err(|e| LlmError::Template {
                    name: f.display().to_string(),
                    message: e.to_string(),
                })?;
                (text, PromptSource::File(f))
            }
            None => (builtin.to_string(), PromptSource::BuiltIn),
        };
        let shown = match &source {
            PromptSource::File(f) => f.display().to_string(),
            PromptSource::BuiltIn => format!("{name} (built in)"),
        };
        self.env
            .add_template_owned(name.to_string(), text)
            .map_err(|e| LlmError::Template {
                name: shown,
                message: template_message(&e),
            })?;
        self.sources.insert(name.to_string(), source);
        Ok(())
    }

    /// Where each template came from.
    pub fn sources(&self) -> &BTreeMap<String, PromptSource> {
        &self.sources
    }

    /// Renders template `name` with `ctx`.
    pub fn render(&self, name: &str, ctx: impl Serialize) -> Result<String, LlmError> {
        let t = self
            .env
            .get_template(name)
            .map_err(|e| LlmError::Template {
                name: name.to_string(),
                message: template_message(&e),
            })?;
        let out = t
            .render(minijinja::Value::from(minijinja::value::Serde(ctx)))
            .map_err(|e| LlmError::Template {
                name: name.to_string(),
                message: template_message(&e),
            })?;
        Ok(tidy(&out))
    }

    /// The system message for code requests.
    pub fn system(&self) -> Result<String, LlmError> {
        self.render("system.j2", serde_json::json!({}))
    }
}

/// The error with its template line and the chain of causes.
fn template_message(e: &minijinja::Error) -> String {
    let mut msg = e.to_string();
    let mut src = std::error::Error::source(e);
    while let Some(s) = src {
        msg.push_str(": ");
        msg.push_str(&s.to_string());
        src = s.source();
    }
    msg
}

/// Collapses runs of blank lines left by template blocks to one, and trims the ends.
fn tidy(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut blank = 0;
    for line in s.lines() {
        let line = line.trim_end();
        if line.is_empty() {
            blank += 1;
            if blank > 1 {
                continue;
            }
        } else {
            blank = 0;
        }
        out.push_str(line);
        out.push('\n');
    }
    out.trim().to_string() + "\n"
}

/// One parent shown in the evolution prompt.
#[derive(Clone, Debug, Serialize)]
pub struct ParentView {
    /// Its source.
    pub code: String,
    /// Its non-blank lines.
    pub lines: usize,
    /// Whether it has fitness terms (a seed program may not).
    pub scored: bool,
    /// ν.
    pub nu: f64,
    /// ρ.
    pub rho: f64,
    /// η.
    pub eta: f64,
    /// λ.
    pub lambda: f64,
    /// ψ.
    pub psi: f64,
}

impl ParentView {
    /// A parent with its terms, if scored.
    pub fn new(code: &str, lines: usize, fitness: Option<&FitnessTerms>) -> Self {
        let f = fitness.copied().unwrap_or_default();
        ParentView {
            code: code.to_string(),
            lines,
            scored: fitness.is_some(),
            nu: f.nu,
            rho: f.rho,
            eta: f.eta,
            lambda: f.lambda,
            psi: f.psi,
        }
    }
}

/// Context of `evolve.j2`.
#[derive(Clone, Debug, Serialize)]
pub struct EvolveContext {
    /// The environment (`pooltool`, `phyre`, `iphyre`).
    pub env: Env,
    /// The label being learned.
    pub label: String,
    /// The search step.
    pub step: u64,
    /// The island.
    pub island: usize,
    /// The parents, best first.
    pub parents: Vec<ParentView>,
    /// Labels already in the library.
    pub library_labels: Vec<String>,
}

/// Context of `repair.j2`.
#[derive(Clone, Debug, Serialize)]
pub struct RepairContext {
    /// The environment.
    pub env: Env,
    /// The label being learned.
    pub label: String,
    /// The rejected code.
    pub code: String,
    /// The validator's category (`syntax`, `forbidden`, `runtime`, `invalid_output`, …).
    pub error_category: String,
    /// Its message.
    pub error_message: String,
    /// 1-based line, if known.
    pub error_line: Option<u32>,
    /// 1-based column, if known.
    pub error_column: Option<u32>,
    /// Which repair this is (from 1).
    pub attempt: u32,
}

/// One library entry shown in the label-suggestion prompt.
#[derive(Clone, Debug, Serialize)]
pub struct LibraryEntry {
    /// The label.
    pub label: String,
    /// Other names for it.
    pub aliases: Vec<String>,
}

/// Context of `suggest_labels.j2`.
#[derive(Clone, Debug, Serialize)]
pub struct LabelsContext {
    /// The environment.
    pub env: Env,
    /// How many labels to propose.
    pub k: usize,
    /// The library's labels (one entry per distinct label).
    pub library: Vec<LibraryEntry>,
    /// What the agent is trying to do, if the user says.
    pub objective: Option<String>,
    /// Extra instructions, if the user gives any.
    pub guidance: Option<String>,
}

impl LibraryEntry {
    /// One entry per distinct label of `library`, with the aliases of its detectors.
    pub fn of(library: &Library) -> Vec<LibraryEntry> {
        let mut out: Vec<LibraryEntry> = Vec::new();
        for d in &library.detectors {
            match out.iter_mut().find(|e| e.label == d.label) {
                Some(e) => {
                    for a in &d.aliases {
                        if !e.aliases.contains(a) {
                            e.aliases.push(a.clone());
                        }
                    }
                }
                None => out.push(LibraryEntry {
                    label: d.label.clone(),
                    aliases: d.aliases.clone(),
                }),
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn evolve_ctx(env: Env, scored: bool, n: usize) -> EvolveContext {
        let f = FitnessTerms::new(0.61, 0.2, 0.3, 0.0);
        EvolveContext {
            env,
            label: "cushion rebound".into(),
            step: 12,
            island: 3,
            parents: (0..n)
                .map(|i| {
                    ParentView::new(
                        &format!("def find_pattern(trace):\n    return []  # v{i}\n"),
                        2,
                        scored.then_some(&f),
                    )
                })
                .collect(),
            library_labels: vec!["cue strike".into(), "ball collision".into()],
        }
    }

    #[test]
    fn every_environment_renders_the_evolution_prompt() {
        let p = Prompts::builtin();
        for env in Env::ALL {
            let text = p.render("evolve.j2", evolve_ctx(env, true, 2)).unwrap();
            assert!(
                text.contains("Pattern to detect: cushion rebound"),
                "{text}"
            );
            assert!(text.contains("score 0.5100"), "{text}");
            assert!(text.contains("# v1"), "{text}");
            assert!(text.contains("Do not import"), "{text}");
            assert!(text.contains("cue strike, ball collision"), "{text}");
            assert!(!text.contains("\n\n\n"), "{text}");
            let layout_word = match env {
                Env::Pooltool => "motion_state_code",
                Env::Phyre => "is_user_input",
                Env::Iphyre => "eliminable",
            };
            assert!(text.contains(layout_word), "{env}: {text}");
        }
        let unscored = p
            .render("evolve.j2", evolve_ctx(Env::Pooltool, false, 1))
            .unwrap();
        assert!(unscored.contains("not scored yet"), "{unscored}");
        assert!(
            unscored.contains("Here is the current detector."),
            "{unscored}"
        );
    }

    #[test]
    fn the_repair_prompt_carries_the_validator_error() {
        let p = Prompts::builtin();
        let text = p
            .render(
                "repair.j2",
                RepairContext {
                    env: Env::Phyre,
                    label: "ball falls".into(),
                    code: "def find_pattern(trace)\n    return []\n".into(),
                    error_category: "syntax".into(),
                    error_message: "expected ':'".into(),
                    error_line: Some(1),
                    error_column: None,
                    attempt: 1,
                },
            )
            .unwrap();
        assert!(text.contains("- category: syntax"), "{text}");
        assert!(text.contains("- message: expected ':'"), "{text}");
        assert!(text.contains("- line: 1\n"), "{text}");
        assert!(text.contains("- column: unknown"), "{text}");
        assert!(
            text.contains("def find_pattern(trace)\n    return []"),
            "{text}"
        );
    }

    #[test]
    fn the_label_prompt_lists_the_library_and_asks_for_k() {
        let p = Prompts::builtin();
        let text = p
            .render(
                "suggest_labels.j2",
                LabelsContext {
                    env: Env::Iphyre,
                    k: 4,
                    library: vec![LibraryEntry {
                        label: "block removed".into(),
                        aliases: vec!["click".into()],
                    }],
                    objective: Some("make every ball leave the scene".into()),
                    guidance: None,
                },
            )
            .unwrap();
        assert!(text.contains("Propose 4 new patterns."), "{text}");
        assert!(text.contains("- block removed (also: click)"), "{text}");
        assert!(text.contains("make every ball leave the scene"), "{text}");
    }

    /// The rendered prompts as a person reads them: a change to a template is a reviewed diff.
    #[test]
    fn rendered_prompts_snapshot() {
        let p = Prompts::builtin();
        insta::assert_snapshot!(
            "evolve_pooltool",
            p.render("evolve.j2", evolve_ctx(Env::Pooltool, true, 2))
                .unwrap()
        );
        insta::assert_snapshot!(
            "repair_iphyre",
            p.render(
                "repair.j2",
                RepairContext {
                    env: Env::Iphyre,
                    label: "ball rolls off block".into(),
                    code:
                        "def find_pattern(trace):\n    return [x for x in trace[\"timesteps\"]]\n"
                            .into(),
                    error_category: "invalid_output".into(),
                    error_message: "at $[0]: the pattern has no `label`".into(),
                    error_line: None,
                    error_column: None,
                    attempt: 2,
                },
            )
            .unwrap()
        );
        insta::assert_snapshot!(
            "suggest_labels_phyre",
            p.render(
                "suggest_labels.j2",
                LabelsContext {
                    env: Env::Phyre,
                    k: 5,
                    library: vec![],
                    objective: None,
                    guidance: Some("Prefer patterns about the green object.".into()),
                },
            )
            .unwrap()
        );
    }

    #[test]
    fn a_missing_variable_is_an_error_and_files_override_built_ins() {
        let p = Prompts::builtin();
        let e = p
            .render("repair.j2", serde_json::json!({"env": "pooltool"}))
            .unwrap_err();
        assert!(e.to_string().contains("repair.j2"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("system.j2"), "Custom {{ 1 + 1 }}").unwrap();
        let p = Prompts::load(Some(dir.path())).unwrap();
        assert_eq!(p.system().unwrap(), "Custom 2\n");
        assert_eq!(
            p.sources()["system.j2"],
            PromptSource::File(dir.path().join("system.j2"))
        );
        assert_eq!(p.sources()["evolve.j2"], PromptSource::BuiltIn);
        std::fs::write(dir.path().join("evolve.j2"), "{% if %}").unwrap();
        let e = Prompts::load(Some(dir.path())).unwrap_err();
        assert!(e.to_string().contains("evolve.j2"), "{e}");
    }
}
