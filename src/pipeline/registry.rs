//! The stage kinds a pipeline can use, listed in one slice as ripgrep lists its flags.
//!
//! A kind lives in `pipeline/stages/<kind>.rs` with its parameters, docs, constructor and tests; adding
//! one means adding it to [`STAGE_KINDS`]. `annotrace stages` prints this list.

use super::params::ParamsOf;
use super::spec::{PipelineSpec, StageDef};
use super::stage::Stage;
use super::stages;

/// Why a stage could not be built from its parameters.
#[derive(Debug, Clone)]
pub struct BuildError {
    /// The parameter at fault, if one is (its line is reported).
    pub param: Option<&'static str>,
    /// What is wrong.
    pub message: String,
}

impl BuildError {
    /// A fault in one parameter.
    pub fn param(param: &'static str, message: impl Into<String>) -> Self {
        BuildError {
            param: Some(param),
            message: message.into(),
        }
    }
}

/// Builds a stage of one kind from its validated definition in a pipeline.
pub type BuildStage = fn(&StageDef, &PipelineSpec) -> Result<Box<dyn Stage>, BuildError>;

/// A kind of stage: its name, docs, parameters and constructor.
#[derive(Debug)]
pub struct StageKind {
    /// The `kind = "…"` value.
    pub name: &'static str,
    /// One line for listings.
    pub summary: &'static str,
    /// A paragraph for `annotrace stages`.
    pub doc: &'static str,
    /// The tables (or files) it writes.
    pub writes: &'static str,
    /// Its parameters: the kind's typed parameter struct.
    pub params: ParamsOf,
    /// Builds the stage from validated parameters; also called once during validation.
    pub build: BuildStage,
}

/// Every stage kind, in the order `annotrace stages` lists them.
pub static STAGE_KINDS: &[&StageKind] = &[
    &stages::import::KIND,
    &stages::simulate::KIND,
    &stages::annotate::KIND,
    &stages::accuracy::KIND,
    &stages::synthesise::KIND,
    &stages::optimise::KIND,
    &stages::benchmark::KIND,
    &stages::summarise::KIND,
    &stages::suggest_labels::KIND,
    &stages::evolve::KIND,
    &stages::ensemble::KIND,
    &stages::sql::KIND,
    &stages::export::KIND,
    &stages::report::KIND,
    &stages::plot::KIND,
    &stages::survey::KIND,
    &stages::import_survey::KIND,
];

/// The kind with this name.
pub fn find_kind(name: &str) -> Option<&'static StageKind> {
    STAGE_KINDS.iter().copied().find(|k| k.name == name)
}

/// The names of all kinds.
pub fn kind_names() -> Vec<&'static str> {
    STAGE_KINDS.iter().map(|k| k.name).collect()
}

/// The parameter reference of every kind as Markdown (one table per kind, per environment where the
/// parameters depend on it): the section of `docs/pipelines.md` between its `params` markers, which a
/// test keeps equal to this text.
pub fn params_markdown() -> String {
    use super::params::{ParamDoc, ParamDocs};
    fn table(out: &mut String, docs: &[ParamDoc]) {
        out.push_str("| parameter | type | default | meaning |\n|---|---|---|---|\n");
        for p in docs {
            let default = match (&p.default, p.required) {
                (_, true) => "required".to_string(),
                (Some(d), false) => format!("`{d}`"),
                (None, false) => "–".to_string(),
            };
            out.push_str(&format!(
                "| `{}` | {} | {} | {} |\n",
                p.name,
                p.ty.describe(),
                default,
                p.doc.replace('|', "\\|")
            ));
        }
        out.push('\n');
    }
    let mut out = String::new();
    for kind in STAGE_KINDS {
        match kind.params.docs() {
            ParamDocs::Flat(docs) => {
                out.push_str(&format!("### `{}`\n\n", kind.name));
                table(&mut out, &docs);
            }
            ParamDocs::ByTag {
                tag,
                default,
                variants,
            } => {
                for (value, docs) in variants {
                    let d = if value == default {
                        " (the default)"
                    } else {
                        ""
                    };
                    out.push_str(&format!(
                        "### `{}` with `{tag} = \"{value}\"`{d}\n\n",
                        kind.name
                    ));
                    table(&mut out, &docs);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `docs/pipelines.md` lists every parameter as the structs define it. To refresh the section after
    /// changing a parameter: `ANNOTRACE_UPDATE_DOCS=1 cargo test --lib params_reference`.
    #[test]
    fn params_reference_in_the_docs_matches_the_structs() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/pipelines.md");
        let text = std::fs::read_to_string(&path).unwrap();
        let (begin, end) = ("<!-- params:begin -->\n", "<!-- params:end -->");
        let a = text.find(begin).expect("begin marker") + begin.len();
        let b = text.find(end).expect("end marker");
        let want = params_markdown();
        if std::env::var_os("ANNOTRACE_UPDATE_DOCS").is_some() {
            let new = format!("{}{want}{}", &text[..a], &text[b..]);
            std::fs::write(&path, new).unwrap();
            return;
        }
        assert_eq!(
            &text[a..b],
            want,
            "docs/pipelines.md is out of step with the parameter structs: \
             rerun with ANNOTRACE_UPDATE_DOCS=1"
        );
    }
}
