//! Pipeline files: parsing, validation and the stage graph.
//!
//! ```toml
//! [pipeline]
//! name = "quickstart"        # default: the file stem; the run folder is runs/<name>
//! seed = 7                   # default 0; handed to every stage
//!
//! [[stage]]
//! id = "import_pool"         # letters, digits, `_` and `-`
//! kind = "import"            # see `annotrace stages`
//! env = "pooltool"           # the kind's parameters sit beside id and kind
//! paths = ["data/examples/pooltool_break.json"]
//!
//! [[stage]]
//! id = "summary"
//! kind = "sql"
//! inputs = ["import_pool"]   # stages that must finish first
//! query = "trace_summary.sql"
//! ```
//!
//! Everything is checked before anything runs: unknown keys, unknown stage kinds, parameter types,
//! duplicate ids, inputs that name no stage, and cycles, each reported with the file and line.
//! Relative paths are resolved against the project folder: the folder holding `pipelines/` when the
//! file sits in one, else the file's own folder.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde_json::{Map, Value};
use sha2::{Digest, Sha256};

use super::params::StageParams;
use super::registry::{BuildError, StageKind, find_kind, kind_names};
use super::toml_doc::{self, Entry, Node, NodeValue};
use super::{SpecError, params};
use crate::digest::hex;

/// A validated pipeline.
#[derive(Clone, Debug)]
pub struct PipelineSpec {
    /// The file it was read from.
    pub file: PathBuf,
    /// Its name (the run folder's default name).
    pub name: String,
    /// Its description, if any.
    pub description: Option<String>,
    /// The seed handed to every stage.
    pub seed: u64,
    /// The folder relative paths are resolved against.
    pub project_dir: PathBuf,
    /// `[pipeline] run_dir`, resolved, if given.
    pub run_dir: Option<PathBuf>,
    /// The stages in file order.
    pub stages: Vec<StageDef>,
    /// SHA-256 of the file's text.
    pub sha256: String,
}

/// One stage of a pipeline, validated against its kind.
#[derive(Clone, Debug)]
pub struct StageDef {
    /// Unique id within the pipeline.
    pub id: String,
    /// Its kind.
    pub kind: &'static StageKind,
    /// Stages that must finish before it.
    pub inputs: Vec<String>,
    /// Parameters, defaults filled in.
    pub params: Map<String, Value>,
    /// Free text.
    pub description: Option<String>,
    /// Line of its `[[stage]]` table (of its `id` key).
    pub line: usize,
    /// Line of each parameter (and of `inputs`) given in the file.
    pub param_lines: Vec<(String, usize)>,
}

impl StageDef {
    /// A stage built in code (a one-stage CLI command) from its kind's typed parameters: the same
    /// canonical parameters, and so the same fingerprint, as the equivalent pipeline file would give.
    pub fn new<P: StageParams>(
        id: impl Into<String>,
        kind: &'static StageKind,
        params: &P,
    ) -> Result<Self, SpecError> {
        let id = id.into();
        let invalid = |message: String| SpecError::Invalid {
            file: PathBuf::from(format!("annotrace-{}", kind.name)),
            line: 0,
            message,
        };
        let value =
            serde_json::to_value(params).map_err(|e| invalid(format!("stage \"{id}\": {e}")))?;
        let canonical = kind
            .params
            .canonical(value)
            .map_err(|e| invalid(format!("stage \"{id}\": `{}`: {}", e.path, e.message)))?;
        let Value::Object(params) = canonical else {
            return Err(invalid(format!(
                "stage \"{id}\": parameters are not a table"
            )));
        };
        Ok(StageDef {
            id,
            kind,
            inputs: Vec::new(),
            params,
            description: None,
            line: 0,
            param_lines: Vec::new(),
        })
    }

    /// The stage's parameters as its kind's struct.
    pub fn params<P: StageParams>(&self) -> Result<P, BuildError> {
        serde_json::from_value(Value::Object(self.params.clone())).map_err(|e| BuildError {
            param: None,
            message: format!("parameters do not fit kind {}: {e}", self.kind.name),
        })
    }

    /// The line of a parameter, or of the stage when the parameter was defaulted.
    pub fn line_of(&self, param: &str) -> usize {
        self.param_lines
            .iter()
            .find(|(k, _)| k == param)
            .map_or(self.line, |(_, l)| *l)
    }
}

/// Checks a stage id: letters, digits, `_` and `-`, starting with a letter or digit.
pub fn valid_id(id: &str) -> bool {
    !id.is_empty()
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        && id.starts_with(|c: char| c.is_ascii_alphanumeric())
}

/// Where relative paths of a pipeline file are resolved.
pub fn project_dir_of(file: &Path) -> PathBuf {
    let dir = file
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if dir.file_name().is_some_and(|n| n == "pipelines") {
        dir.parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
            .to_path_buf()
    } else {
        dir.to_path_buf()
    }
}

struct Ctx<'a> {
    file: &'a Path,
}

impl Ctx<'_> {
    fn invalid(&self, line: usize, message: impl Into<String>) -> SpecError {
        SpecError::Invalid {
            file: self.file.to_path_buf(),
            line,
            message: message.into(),
        }
    }

    fn unknown_key(&self, e: &Entry, context: &str, known: &[&str]) -> SpecError {
        SpecError::UnknownKey {
            file: self.file.to_path_buf(),
            line: e.key_line,
            key: e.key.clone(),
            context: context.to_string(),
            known: known.join(", "),
            suggestion: suggest(&e.key, known),
        }
    }

    fn string(&self, node: &Node, what: &str) -> Result<String, SpecError> {
        match &node.value {
            NodeValue::Str(s) => Ok(s.clone()),
            other => Err(self.invalid(
                node.line,
                format!("{what} must be a string, found {}", other.type_name()),
            )),
        }
    }
}

/// The `[pipeline]` table's settings.
struct Header {
    name: String,
    description: Option<String>,
    seed: u64,
    run_dir: Option<PathBuf>,
}

impl Ctx<'_> {
    /// Reads the `[pipeline]` table `e` into `h`.
    fn header(&self, e: &Entry, project_dir: &Path, h: &mut Header) -> Result<(), SpecError> {
        let cx = self;
        let NodeValue::Table(entries) = &e.value.value else {
            return Err(cx.invalid(e.key_line, "`pipeline` must be a table: [pipeline]"));
        };
        for p in entries {
            match p.key.as_str() {
                "name" => {
                    h.name = cx.string(&p.value, "`name`")?;
                    if !valid_id(&h.name) {
                        return Err(cx.invalid(
                            p.value.line,
                            format!(
                                "pipeline name {:?} must use letters, digits, `_` and `-` only",
                                h.name
                            ),
                        ));
                    }
                }
                "description" => h.description = Some(cx.string(&p.value, "`description`")?),
                "seed" => match p.value.value {
                    NodeValue::Int(s) if s >= 0 => h.seed = s as u64,
                    ref other => {
                        return Err(cx.invalid(
                            p.value.line,
                            format!(
                                "`seed` must be a non-negative integer, found {}",
                                other.type_name()
                            ),
                        ));
                    }
                },
                "run_dir" => {
                    let dir = cx.string(&p.value, "`run_dir`")?;
                    // An object-store location (`s3://…`) is kept as written.
                    h.run_dir = Some(if dir.starts_with("s3://") {
                        PathBuf::from(dir)
                    } else {
                        project_dir.join(dir)
                    });
                }
                _ => {
                    return Err(cx.unknown_key(
                        p,
                        "[pipeline]",
                        &["name", "description", "seed", "run_dir"],
                    ));
                }
            }
        }
        Ok(())
    }

    /// Reads one `[[stage]]` table; `earlier` are the stages before it (for duplicate ids).
    fn stage(&self, node: &Node, earlier: &[StageDef]) -> Result<StageDef, SpecError> {
        let (cx, file) = (self, self.file);
        let NodeValue::Table(entries) = &node.value else {
            return Err(cx.invalid(node.line, "each stage must be a table"));
        };
        let get = |key: &str| entries.iter().find(|e| e.key == key);
        let line = get("id").map_or(node.line, |e| e.key_line);
        let id = match get("id") {
            Some(e) => cx.string(&e.value, "`id`")?,
            None => {
                return Err(cx.invalid(
                    entries.first().map_or(node.line, |e| e.key_line),
                    "stage has no `id`",
                ));
            }
        };
        if !valid_id(&id) {
            return Err(cx.invalid(line, format!("stage id {id:?} must use letters, digits, `_` and `-` only, starting with a letter or digit")));
        }
        if let Some(first) = earlier.iter().find(|s| s.id == id) {
            return Err(SpecError::DuplicateId {
                file: file.to_path_buf(),
                line,
                id,
                first_line: first.line,
            });
        }
        let kind_entry = get("kind").ok_or_else(|| {
            cx.invalid(
                line,
                format!(
                    "stage \"{id}\" has no `kind` (known: {})",
                    kind_names().join(", ")
                ),
            )
        })?;
        let kind_name = cx.string(&kind_entry.value, "`kind`")?;
        let kind = find_kind(&kind_name).ok_or_else(|| SpecError::UnknownKind {
            file: file.to_path_buf(),
            line: kind_entry.key_line,
            kind: kind_name.clone(),
            known: kind_names().join(", "),
            suggestion: suggest(&kind_name, &kind_names()),
        })?;
        let mut inputs = Vec::new();
        if let Some(e) = get("inputs") {
            let NodeValue::Array(items) = &e.value.value else {
                return Err(cx.invalid(
                    e.value.line,
                    format!("stage \"{id}\": `inputs` must be an array of stage ids"),
                ));
            };
            for item in items {
                inputs.push(cx.string(item, "each input")?);
            }
        }
        let description = get("description")
            .map(|e| cx.string(&e.value, "`description`"))
            .transpose()?;
        let param_entries: Vec<&Entry> = entries
            .iter()
            .filter(|e| !matches!(e.key.as_str(), "id" | "kind" | "inputs" | "description"))
            .collect();
        let (params, mut param_lines) =
            params::resolve(file, &id, line, kind.name, &kind.params, &param_entries)?;
        if let Some(e) = get("inputs") {
            param_lines.push(("inputs".to_string(), e.key_line));
        }
        Ok(StageDef {
            id,
            kind,
            inputs,
            params,
            description,
            line,
            param_lines,
        })
    }
}

impl PipelineSpec {
    /// Reads and validates a pipeline file.
    pub fn from_file(path: &Path) -> Result<Self, SpecError> {
        let text = std::fs::read_to_string(path).map_err(|source| SpecError::Io {
            file: path.to_path_buf(),
            source,
        })?;
        Self::from_toml(path, &text)
    }

    /// Validates a pipeline given as text; `file` names it in errors and anchors relative paths.
    ///
    /// ```
    /// use annotrace::pipeline::PipelineSpec;
    /// let text = "[[stage]]\nid = \"summary\"\nkind = \"sql\"\nsql = \"SELECT 1 AS one\"\n";
    /// let spec = PipelineSpec::from_toml(std::path::Path::new("pipelines/demo.toml"), text).unwrap();
    /// assert_eq!(spec.name, "demo");
    /// assert_eq!(spec.stages[0].kind.name, "sql");
    /// ```
    pub fn from_toml(file: &Path, text: &str) -> Result<Self, SpecError> {
        let cx = Ctx { file };
        let doc = toml_doc::parse(file, text)?;
        let project_dir = project_dir_of(file);
        let mut header = Header {
            name: file
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or("pipeline")
                .to_string(),
            description: None,
            seed: 0,
            run_dir: None,
        };
        let mut stage_nodes: Vec<&Node> = Vec::new();
        for e in &doc {
            match e.key.as_str() {
                "pipeline" => cx.header(e, &project_dir, &mut header)?,
                "stage" => {
                    let NodeValue::Array(items) = &e.value.value else {
                        return Err(
                            cx.invalid(e.key_line, "stages are written as [[stage]] tables")
                        );
                    };
                    stage_nodes.extend(items.iter());
                }
                _ => return Err(cx.unknown_key(e, "the top level", &["pipeline", "stage"])),
            }
        }
        if stage_nodes.is_empty() {
            return Err(cx.invalid(1, "the pipeline has no [[stage]] tables"));
        }
        let mut stages: Vec<StageDef> = Vec::new();
        for node in stage_nodes {
            let def = cx.stage(node, &stages)?;
            stages.push(def);
        }
        let spec = PipelineSpec {
            file: file.to_path_buf(),
            name: header.name,
            description: header.description,
            seed: header.seed,
            project_dir,
            run_dir: header.run_dir,
            stages,
            sha256: hex(&Sha256::digest(text.as_bytes())),
        };
        spec.check_graph()?;
        Ok(spec)
    }

    /// A pipeline of stages built in code (what a one-stage CLI command runs), checked as a file would
    /// be: ids, inputs, cycles, and each stage's `build`. `name` stands for the file in errors;
    /// relative paths resolve against `project_dir`.
    pub fn from_stages(
        name: &str,
        project_dir: PathBuf,
        seed: u64,
        stages: Vec<StageDef>,
    ) -> Result<Self, SpecError> {
        let file = PathBuf::from(format!("{name}.toml"));
        let mut text = String::new();
        for s in &stages {
            text.push_str(&format!(
                "{} {} {}\n",
                s.id,
                s.kind.name,
                Value::Object(s.params.clone())
            ));
        }
        let spec = PipelineSpec {
            file,
            name: name.to_string(),
            description: None,
            seed,
            project_dir,
            run_dir: None,
            stages,
            sha256: hex(&Sha256::digest(text.as_bytes())),
        };
        spec.check_graph()?;
        Ok(spec)
    }

    /// Checks that ids are unique, inputs name stages, the graph has no cycle, and every stage builds.
    fn check_graph(&self) -> Result<(), SpecError> {
        let file = &self.file;
        for (i, s) in self.stages.iter().enumerate() {
            if let Some(first) = self.stages[..i].iter().find(|o| o.id == s.id) {
                return Err(SpecError::DuplicateId {
                    file: file.clone(),
                    line: s.line,
                    id: s.id.clone(),
                    first_line: first.line,
                });
            }
            for input in &s.inputs {
                if !self.stages.iter().any(|o| &o.id == input) {
                    return Err(SpecError::MissingInput {
                        file: file.clone(),
                        line: s.line_of("inputs"),
                        stage: s.id.clone(),
                        input: input.clone(),
                        known: self
                            .stages
                            .iter()
                            .map(|o| o.id.clone())
                            .collect::<Vec<_>>()
                            .join(", "),
                    });
                }
            }
        }
        self.order()?;
        for s in &self.stages {
            (s.kind.build)(s, self)
                .map(|_| ())
                .map_err(|e| SpecError::Invalid {
                    file: file.clone(),
                    line: e.param.map_or(s.line, |p| s.line_of(p)),
                    message: format!("stage \"{}\": {}", s.id, e.message),
                })?;
        }
        Ok(())
    }

    /// The stages in an order where every stage comes after its inputs (file order among equals).
    pub fn order(&self) -> Result<Vec<usize>, SpecError> {
        let index: BTreeMap<&str, usize> = self
            .stages
            .iter()
            .enumerate()
            .map(|(i, s)| (s.id.as_str(), i))
            .collect();
        let mut state = vec![0u8; self.stages.len()]; // 0 new, 1 on the path, 2 done
        let mut order = Vec::with_capacity(self.stages.len());
        fn visit(
            i: usize,
            spec: &PipelineSpec,
            index: &BTreeMap<&str, usize>,
            state: &mut [u8],
            path: &mut Vec<usize>,
            order: &mut Vec<usize>,
        ) -> Result<(), SpecError> {
            match state[i] {
                2 => return Ok(()),
                1 => {
                    let from = path.iter().position(|&p| p == i).unwrap_or(0);
                    let mut cycle: Vec<String> = path[from..]
                        .iter()
                        .map(|&p| spec.stages[p].id.clone())
                        .collect();
                    cycle.push(spec.stages[i].id.clone());
                    return Err(SpecError::Cycle {
                        file: spec.file.clone(),
                        line: spec.stages[i].line,
                        cycle,
                    });
                }
                _ => {}
            }
            state[i] = 1;
            path.push(i);
            for input in &spec.stages[i].inputs {
                visit(index[input.as_str()], spec, index, state, path, order)?;
            }
            path.pop();
            state[i] = 2;
            order.push(i);
            Ok(())
        }
        for i in 0..self.stages.len() {
            visit(i, self, &index, &mut state, &mut Vec::new(), &mut order)?;
        }
        Ok(order)
    }

    /// The stage with this id.
    pub fn stage(&self, id: &str) -> Option<&StageDef> {
        self.stages.iter().find(|s| s.id == id)
    }

    /// `id` and every stage it depends on, directly or not.
    pub fn upstream(&self, id: &str) -> BTreeSet<String> {
        let mut out = BTreeSet::new();
        let mut todo = vec![id.to_string()];
        while let Some(cur) = todo.pop() {
            if out.insert(cur.clone())
                && let Some(s) = self.stage(&cur)
            {
                todo.extend(s.inputs.iter().cloned());
            }
        }
        out
    }

    /// `id` and every stage that depends on it, directly or not.
    pub fn downstream(&self, id: &str) -> BTreeSet<String> {
        let mut out = BTreeSet::new();
        let mut todo = vec![id.to_string()];
        while let Some(cur) = todo.pop() {
            if out.insert(cur.clone()) {
                todo.extend(
                    self.stages
                        .iter()
                        .filter(|s| s.inputs.contains(&cur))
                        .map(|s| s.id.clone()),
                );
            }
        }
        out
    }

    /// The run folder: `--run-dir`, else `[pipeline] run_dir`, else `<project>/runs/<name>`.
    pub fn default_run_dir(&self) -> PathBuf {
        self.run_dir
            .clone()
            .unwrap_or_else(|| self.project_dir.join("runs").join(&self.name))
    }
}

/// The closest known name, if it is close enough to be a typo.
pub(crate) fn suggest(given: &str, known: &[&str]) -> Option<String> {
    fn distance(a: &str, b: &str) -> usize {
        let b: Vec<char> = b.chars().collect();
        let mut prev: Vec<usize> = (0..=b.len()).collect();
        for (i, ca) in a.chars().enumerate() {
            let mut cur = vec![i + 1];
            for (j, cb) in b.iter().enumerate() {
                cur.push(
                    (prev[j] + usize::from(ca != *cb))
                        .min(prev[j + 1] + 1)
                        .min(cur[j] + 1),
                );
            }
            prev = cur;
        }
        prev[b.len()]
    }
    known
        .iter()
        .map(|k| (distance(given, k), *k))
        .filter(|(d, k)| *d <= 2.max(k.len() / 3))
        .min()
        .map(|(_, k)| k.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<PipelineSpec, SpecError> {
        PipelineSpec::from_toml(Path::new("pipelines/t.toml"), text)
    }

    const SQL: &str = "kind = \"sql\"\nsql = \"SELECT 1\"\n";

    #[test]
    fn orders_stages_after_their_inputs() {
        let text =
            format!("[[stage]]\nid = \"b\"\ninputs = [\"a\"]\n{SQL}\n[[stage]]\nid = \"a\"\n{SQL}");
        let spec = parse(&text).unwrap();
        let order: Vec<&str> = spec
            .order()
            .unwrap()
            .iter()
            .map(|&i| spec.stages[i].id.as_str())
            .collect();
        assert_eq!(order, ["a", "b"]);
        assert_eq!(spec.project_dir, PathBuf::from("."));
        assert_eq!(
            spec.downstream("a").into_iter().collect::<Vec<_>>(),
            ["a", "b"]
        );
    }

    #[test]
    fn errors_name_file_line_and_key() {
        let e = parse(&format!("[[stage]]\nid = \"a\"\n{SQL}colour = 3\n")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "pipelines/t.toml:5: unknown key `colour` in stage \"a\" (kind sql) (known: id, kind, inputs, description, query, sql, output, memory_limit, timeout_s, engine)"
        );
        let e = parse("[[stage]]\nid = \"a\"\nkind = \"anotate\"\n").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("pipelines/t.toml:3: unknown stage kind \"anotate\""),
            "{e}"
        );
        let e = parse(&format!("[[stage]]\nid = \"a\"\ninputs = [\"zz\"]\n{SQL}")).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("pipelines/t.toml:3: stage \"a\" names input \"zz\""),
            "{e}"
        );
        let e = parse(&format!(
            "[[stage]]\nid = \"a\"\n{SQL}\n[[stage]]\nid = \"a\"\n{SQL}"
        ))
        .unwrap_err();
        assert!(
            matches!(
                e,
                SpecError::DuplicateId {
                    line: 7,
                    first_line: 2,
                    ..
                }
            ),
            "{e:?}"
        );
        let e = parse(&format!(
            "[[stage]]\nid = \"a\"\n{SQL}\nprecision = \"x\"\n"
        ))
        .unwrap_err();
        assert!(e.to_string().contains("unknown key `precision`"), "{e}");
    }

    #[test]
    fn typed_parameters_name_the_line_and_the_fix() {
        let e =
            parse("[[stage]]\nid = \"s\"\nkind = \"simulate\"\nenv = \"phyre\"\ngames = \"all\"\n")
                .unwrap_err();
        assert_eq!(
            e.to_string(),
            "pipelines/t.toml:5: `games` is not a parameter of stage \"s\" (kind simulate, env = \"phyre\"): it applies with env = \"iphyre\" only"
        );
        let e = parse("[[stage]]\nid = \"s\"\nkind = \"simulate\"\nscenez = 3\n").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("pipelines/t.toml:4: unknown key `scenez` in stage \"s\" (kind simulate, env = \"pooltool\"); did you mean `scenes`?"),
            "{e}"
        );
        let e = parse("[[stage]]\nid = \"s\"\nkind = \"simulate\"\nenv = \"pool\"\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "pipelines/t.toml:4: stage \"s\": `env` must be one of \"pooltool\", \"phyre\", \"iphyre\", found \"pool\""
        );
        let e = parse("[[stage]]\nid = \"i\"\nkind = \"import\"\nenv = \"phyre\"\n").unwrap_err();
        assert!(
            e.to_string().contains("missing required parameter `paths`"),
            "{e}"
        );
        let e =
            parse("[[stage]]\nid = \"e\"\nkind = \"evolve\"\nbudget = 3\nllm = { modl = \"x\" }\n")
                .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("pipelines/t.toml:5: stage \"e\": `llm.modl`: unknown field `modl`"),
            "{e}"
        );
        let e =
            parse("[[stage]]\nid = \"e\"\nkind = \"evolve\"\nstrategy = \"greedy\"\n").unwrap_err();
        assert!(
            e.to_string()
                .contains("`strategy` must be one of \"island\", \"hill-climb\", \"best-of-n\""),
            "{e}"
        );
    }

    #[test]
    fn defaults_enter_the_canonical_parameters() {
        let spec =
            parse("[[stage]]\nid = \"s\"\nkind = \"simulate\"\nenv = \"iphyre\"\nshots = 2\n")
                .unwrap();
        let p = Value::Object(spec.stages[0].params.clone());
        assert_eq!(
            p,
            serde_json::json!({"env": "iphyre", "shots": 2, "scenes_per_shard": 100})
        );
    }

    #[test]
    fn cycles_are_reported_with_their_path() {
        let text = format!(
            "[[stage]]\nid = \"a\"\ninputs = [\"c\"]\n{SQL}\n[[stage]]\nid = \"b\"\ninputs = [\"a\"]\n{SQL}\n[[stage]]\nid = \"c\"\ninputs = [\"b\"]\n{SQL}"
        );
        let e = parse(&text).unwrap_err();
        let SpecError::Cycle { cycle, .. } = &e else {
            panic!("{e:?}")
        };
        assert_eq!(cycle.first(), cycle.last());
        assert_eq!(cycle.len(), 4);
    }

    #[test]
    fn suggests_close_kind_names() {
        assert_eq!(
            suggest("imprt", &["import", "sql", "export"]).as_deref(),
            Some("import")
        );
        assert_eq!(suggest("zzzzzz", &["import", "sql"]), None);
    }
}
