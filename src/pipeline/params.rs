//! Typed stage parameters: each stage kind owns one `#[derive(Deserialize, Serialize, JsonSchema)]`
//! struct (or, for kinds whose parameters depend on the environment, an enum tagged by `env`), and this
//! module turns it into everything else a pipeline needs.
//!
//! **Owns:** the description of a kind's parameters read off its struct's JSON schema ([`ParamDocs`]:
//! names, types, defaults and the field docs, for `annotrace stages` and `docs/pipelines.md`), checking a
//! stage table against it (unknown keys with a "did you mean", wrong types, missing required keys, each
//! with the file and line), and the canonical JSON of the parameters with defaults filled in (what the
//! stage's fingerprint hashes). **Does not:** check what a value means beyond its type (a stage's
//! `build` does that, naming the parameter), or parse TOML (`toml_doc`).
//!
//! A parameter is defined once, as a field: its doc comment is its documentation, its serde default is
//! its default, its type is its type. Optional parameters without a default are `Option` fields with
//! `skip_serializing_if = "Option::is_none"`, so an unset one does not enter the fingerprint.

use std::fmt::Debug;
use std::path::Path;

use schemars::JsonSchema;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};

use super::SpecError;
use super::spec::suggest;
use super::toml_doc::{Entry, Node, NodeValue};

/// A stage kind's parameter type: a struct (or an `env`-tagged enum of structs) with serde defaults.
pub trait StageParams:
    Serialize + DeserializeOwned + JsonSchema + Default + Debug + Send + Sync + 'static
{
}

impl<T> StageParams for T where
    T: Serialize + DeserializeOwned + JsonSchema + Default + Debug + Send + Sync + 'static
{
}

/// The type of a parameter, as a pipeline file writes it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ParamType {
    /// A string.
    Str,
    /// One of a fixed set of strings.
    Choice(Vec<String>),
    /// An integer.
    Int,
    /// A non-negative integer, at most `max`.
    Count {
        /// The largest value the field holds.
        max: u64,
    },
    /// A float (integers accepted).
    Float,
    /// A boolean.
    Bool,
    /// An array of strings.
    StrList,
    /// An array of strings, each one of a fixed set.
    ChoiceList(Vec<String>),
    /// A table of anything its struct accepts.
    Table,
}

impl ParamType {
    /// How the type reads in docs and errors.
    pub fn describe(&self) -> String {
        match self {
            ParamType::Str => "a string".into(),
            ParamType::Choice(options) => format!(
                "one of {}",
                options
                    .iter()
                    .map(|o| format!("\"{o}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            ParamType::Int => "an integer".into(),
            ParamType::Count { .. } => "a non-negative integer".into(),
            ParamType::Float => "a number".into(),
            ParamType::Bool => "true or false".into(),
            ParamType::StrList => "an array of strings".into(),
            ParamType::ChoiceList(options) => format!(
                "an array of {}",
                options
                    .iter()
                    .map(|o| format!("\"{o}\""))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            ParamType::Table => "a table".into(),
        }
    }
}

/// One parameter of a stage kind, read off its struct.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamDoc {
    /// Key in the stage table.
    pub name: String,
    /// Its type.
    pub ty: ParamType,
    /// Whether the stage needs it.
    pub required: bool,
    /// Its default, when it has one.
    pub default: Option<Value>,
    /// The field's documentation.
    pub doc: String,
}

impl ParamDoc {
    /// `required`, `default <value>` or `optional`, as listings print it.
    pub fn default_text(&self) -> String {
        match (&self.default, self.required) {
            (_, true) => "required".to_string(),
            (Some(d), false) => format!("default {d}"),
            (None, false) => "optional".to_string(),
        }
    }
}

/// A kind's parameters: one list, or one list per value of a tag key (`env`).
#[derive(Clone, Debug, PartialEq)]
pub enum ParamDocs {
    /// The same parameters whatever the values.
    Flat(Vec<ParamDoc>),
    /// Parameters that depend on the value of `tag`.
    ByTag {
        /// The key that selects the variant (`env`).
        tag: String,
        /// Its value when the stage does not give it.
        default: String,
        /// Each value of the tag with its parameters (the tag itself not included).
        variants: Vec<(String, Vec<ParamDoc>)>,
    },
}

impl ParamDocs {
    /// The parameters that apply when the tag (if any) has value `tag_value` (default: the default
    /// variant).
    pub fn for_tag(&self, tag_value: Option<&str>) -> Option<&[ParamDoc]> {
        match self {
            ParamDocs::Flat(v) => Some(v),
            ParamDocs::ByTag {
                default, variants, ..
            } => {
                let want = tag_value.unwrap_or(default);
                variants
                    .iter()
                    .find(|(v, _)| v == want)
                    .map(|(_, d)| d.as_slice())
            }
        }
    }

    /// Every parameter name of every variant, with the variants (tag values) that have it.
    fn variants_having(&self, key: &str) -> Vec<&str> {
        match self {
            ParamDocs::Flat(_) => Vec::new(),
            ParamDocs::ByTag { variants, .. } => variants
                .iter()
                .filter(|(_, d)| d.iter().any(|p| p.name == key))
                .map(|(v, _)| v.as_str())
                .collect(),
        }
    }
}

/// A kind's parameter struct, erased to what the pipeline needs (a `StageKind` holds one).
#[derive(Clone, Copy)]
pub struct ParamsOf {
    schema: fn() -> schemars::Schema,
    canonical: fn(Value) -> Result<Value, ParamError>,
    defaults: fn() -> Value,
}

impl std::fmt::Debug for ParamsOf {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ParamsOf")
    }
}

/// A value that its parameter's type refused, with the path of the value (`llm.timeout_s`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParamError {
    /// Dotted path of the value at fault (empty for the table as a whole).
    pub path: String,
    /// What is wrong.
    pub message: String,
}

impl ParamsOf {
    /// The erased form of `P`.
    pub const fn of<P: StageParams>() -> Self {
        ParamsOf {
            schema: || schemars::schema_for!(P),
            canonical: canonical_of::<P>,
            defaults: || serde_json::to_value(P::default()).unwrap_or(Value::Null),
        }
    }

    /// The parameters' documentation, read off the struct's schema.
    pub fn docs(&self) -> ParamDocs {
        let schema = (self.schema)();
        let root = schema.as_value();
        let defaults = (self.defaults)();
        match root.get("oneOf").and_then(Value::as_array) {
            Some(variants) if root.get("properties").is_none() => {
                let mut tag = None;
                let mut out = Vec::new();
                for v in variants {
                    let props = v.get("properties").and_then(Value::as_object);
                    let Some((key, value)) = props.and_then(|p| {
                        p.iter().find_map(|(k, s)| {
                            s.get("const").and_then(Value::as_str).map(|c| (k, c))
                        })
                    }) else {
                        continue;
                    };
                    tag = Some(key.clone());
                    let body = resolve_ref(root, v);
                    let docs = object_docs(root, body, Some(key));
                    out.push((value.to_string(), docs));
                }
                let tag = tag.unwrap_or_else(|| "env".to_string());
                let default = defaults
                    .get(&tag)
                    .and_then(Value::as_str)
                    .unwrap_or_default()
                    .to_string();
                ParamDocs::ByTag {
                    tag,
                    default,
                    variants: out,
                }
            }
            _ => ParamDocs::Flat(object_docs(root, root, None)),
        }
    }

    /// Deserializes a stage's given parameters into the struct and back: the canonical JSON with every
    /// default filled in.
    pub fn canonical(&self, given: Value) -> Result<Value, ParamError> {
        (self.canonical)(given)
    }
}

fn canonical_of<P: StageParams>(given: Value) -> Result<Value, ParamError> {
    let typed: P = serde_path_to_error::deserialize(given).map_err(|e| ParamError {
        path: e.path().to_string().trim_start_matches('.').to_string(),
        message: e.into_inner().to_string(),
    })?;
    serde_json::to_value(&typed).map_err(|e| ParamError {
        path: String::new(),
        message: e.to_string(),
    })
}

/// The schema `s` points to (`$ref` into `$defs`), or `s` itself.
fn resolve_ref<'a>(root: &'a Value, s: &'a Value) -> &'a Value {
    match s.get("$ref").and_then(Value::as_str) {
        Some(r) => r
            .strip_prefix("#/$defs/")
            .and_then(|name| root.get("$defs").and_then(|d| d.get(name)))
            .unwrap_or(s),
        None => s,
    }
}

/// The parameters of an object schema, in field order, leaving out `skip` (the tag).
fn object_docs(root: &Value, object: &Value, skip: Option<&str>) -> Vec<ParamDoc> {
    let required: Vec<&str> = object
        .get("required")
        .and_then(Value::as_array)
        .map(|r| r.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default();
    let Some(props) = object.get("properties").and_then(Value::as_object) else {
        return Vec::new();
    };
    props
        .iter()
        .filter(|(k, _)| Some(k.as_str()) != skip)
        .map(|(name, s)| ParamDoc {
            name: name.clone(),
            ty: type_of(root, s),
            required: required.contains(&name.as_str()),
            default: s.get("default").filter(|d| !d.is_null()).cloned(),
            doc: s
                .get("description")
                .and_then(Value::as_str)
                .unwrap_or_default()
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" "),
        })
        .collect()
}

/// The parameter type of a property schema (`Option` is read through: absence is the `None`).
fn type_of(root: &Value, s: &Value) -> ParamType {
    let s = resolve_ref(root, s);
    if let Some(inner) = s.get("anyOf").and_then(Value::as_array).and_then(|any| {
        any.iter()
            .find(|a| a.get("type").and_then(Value::as_str) != Some("null"))
    }) {
        return type_of(root, inner);
    }
    let choices = choices_of(s);
    if !choices.is_empty() {
        return ParamType::Choice(choices);
    }
    let types: Vec<&str> = match s.get("type") {
        Some(Value::String(t)) => vec![t.as_str()],
        Some(Value::Array(ts)) => ts.iter().filter_map(Value::as_str).collect(),
        _ => Vec::new(),
    };
    let ty = types.into_iter().find(|t| *t != "null").unwrap_or("object");
    match ty {
        "string" => ParamType::Str,
        "boolean" => ParamType::Bool,
        "number" => ParamType::Float,
        "integer" => {
            if s.get("minimum").and_then(Value::as_f64) == Some(0.0) {
                let max = match s.get("format").and_then(Value::as_str) {
                    Some("uint8") => u8::MAX as u64,
                    Some("uint16") => u16::MAX as u64,
                    Some("uint32") => u32::MAX as u64,
                    _ => i64::MAX as u64,
                };
                ParamType::Count { max }
            } else {
                ParamType::Int
            }
        }
        "array" => {
            let items = s.get("items").map(|i| resolve_ref(root, i));
            match items.map(choices_of).filter(|c| !c.is_empty()) {
                Some(choices) => ParamType::ChoiceList(choices),
                None => ParamType::StrList,
            }
        }
        _ => ParamType::Table,
    }
}

/// The values of a string enum schema (`enum`, or `oneOf` of `const`s), in the order written.
fn choices_of(s: &Value) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    if let Some(e) = s.get("enum").and_then(Value::as_array) {
        out.extend(e.iter().filter_map(Value::as_str).map(str::to_string));
    }
    if let Some(c) = s.get("const").and_then(Value::as_str) {
        out.push(c.to_string());
    }
    for alt in s
        .get("oneOf")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
    {
        out.extend(choices_of(alt));
    }
    out
}

/// Checks one given value against its parameter's type; returns it as JSON.
fn check_type(doc: &ParamDoc, node: &Node) -> Result<Value, String> {
    let wrong = || {
        format!(
            "`{}` must be {}, found {}",
            doc.name,
            doc.ty.describe(),
            node.value.type_name()
        )
    };
    Ok(match (&doc.ty, &node.value) {
        (ParamType::Str, NodeValue::Str(s)) => Value::String(s.clone()),
        (ParamType::Choice(options), NodeValue::Str(s)) => {
            if !options.contains(s) {
                return Err(format!(
                    "`{}` must be {}, found \"{s}\"",
                    doc.name,
                    doc.ty.describe()
                ));
            }
            Value::String(s.clone())
        }
        (ParamType::Int, NodeValue::Int(i)) => Value::from(*i),
        (ParamType::Count { max }, NodeValue::Int(i)) if *i >= 0 => {
            if *i as u64 > *max {
                return Err(format!("`{}` must be at most {max}, found {i}", doc.name));
            }
            Value::from(*i)
        }
        (ParamType::Count { .. }, NodeValue::Int(i)) => {
            return Err(format!(
                "`{}` must be {}, found {i}",
                doc.name,
                doc.ty.describe()
            ));
        }
        (ParamType::Float, NodeValue::Int(i)) => Value::from(*i as f64),
        (ParamType::Float, NodeValue::Float(f)) if f.is_finite() => node.to_json(),
        (ParamType::Float, NodeValue::Float(f)) => {
            return Err(format!("`{}` must be a finite number, found {f}", doc.name));
        }
        (ParamType::Bool, NodeValue::Bool(b)) => Value::Bool(*b),
        (ParamType::ChoiceList(options), NodeValue::Array(items)) => {
            let mut out = Vec::with_capacity(items.len());
            for (i, item) in items.iter().enumerate() {
                match &item.value {
                    NodeValue::Str(s) if options.contains(s) => out.push(Value::String(s.clone())),
                    other => {
                        return Err(format!(
                            "`{}[{i}]` must be one of {}, found {}",
                            doc.name,
                            options
                                .iter()
                                .map(|o| format!("\"{o}\""))
                                .collect::<Vec<_>>()
                                .join(", "),
                            match other {
                                NodeValue::Str(s) => format!("\"{s}\""),
                                o => o.type_name().to_string(),
                            }
                        ));
                    }
                }
            }
            Value::Array(out)
        }
        (ParamType::StrList, NodeValue::Array(items)) => {
            let mut out = Vec::with_capacity(items.len());
            for (i, item) in items.iter().enumerate() {
                match &item.value {
                    NodeValue::Str(s) => out.push(Value::String(s.clone())),
                    other => {
                        return Err(format!(
                            "`{}[{i}]` must be a string, found {}",
                            doc.name,
                            other.type_name()
                        ));
                    }
                }
            }
            Value::Array(out)
        }
        (ParamType::Table, NodeValue::Table(_)) => node.to_json(),
        _ => return Err(wrong()),
    })
}

/// The tag key and its value (given, or the default) of a kind whose parameters depend on it, or
/// `(None, None)` for a kind with one parameter list; a value naming no variant is an error at its line.
fn chosen_variant(
    all: &ParamDocs,
    entries: &[&Entry],
    stage_id: &str,
) -> Result<(Option<String>, Option<String>), (usize, String)> {
    let ParamDocs::ByTag {
        tag,
        default,
        variants,
    } = all
    else {
        return Ok((None, None));
    };
    let value = match entries.iter().find(|e| &e.key == tag) {
        None => default.clone(),
        Some(e) => match &e.value.value {
            NodeValue::Str(s) if variants.iter().any(|(v, _)| v == s) => s.clone(),
            other => {
                let choices = ParamType::Choice(variants.iter().map(|(v, _)| v.clone()).collect());
                let found = match other {
                    NodeValue::Str(s) => format!("\"{s}\""),
                    o => o.type_name().to_string(),
                };
                return Err((
                    e.value.line,
                    format!(
                        "stage \"{stage_id}\": `{tag}` must be {}, found {found}",
                        choices.describe()
                    ),
                ));
            }
        },
    };
    Ok((Some(tag.clone()), Some(value)))
}

/// A stage's canonical parameters (defaults filled in) and the line of each given key.
pub(crate) type Resolved = (Map<String, Value>, Vec<(String, usize)>);

/// Keys every stage table has beside its kind's parameters.
pub(crate) const STAGE_KEYS: [&str; 4] = ["id", "kind", "inputs", "description"];

/// Checks a stage's parameter entries against its kind's parameter struct. Returns the canonical
/// parameters (the struct with defaults, as JSON) and the line of each given key.
pub(crate) fn resolve(
    file: &Path,
    stage_id: &str,
    stage_line: usize,
    kind: &str,
    params: &ParamsOf,
    entries: &[&Entry],
) -> Result<Resolved, SpecError> {
    let invalid = |line: usize, message: String| SpecError::Invalid {
        file: file.to_path_buf(),
        line,
        message,
    };
    let all = params.docs();
    let (tag, tag_value) =
        chosen_variant(&all, entries, stage_id).map_err(|(line, m)| invalid(line, m))?;
    let docs = all
        .for_tag(tag_value.as_deref())
        .expect("the tag value was checked against the variants");
    let context = match (&tag, &tag_value) {
        (Some(t), Some(v)) => format!("stage \"{stage_id}\" (kind {kind}, {t} = \"{v}\")"),
        _ => format!("stage \"{stage_id}\" (kind {kind})"),
    };
    let mut given = Map::new();
    let mut lines = Vec::new();
    if let (Some(t), Some(v)) = (&tag, &tag_value) {
        given.insert(t.clone(), Value::String(v.clone()));
    }
    for e in entries {
        if Some(&e.key) == tag.as_ref() {
            lines.push((e.key.clone(), e.key_line));
            continue;
        }
        let Some(doc) = docs.iter().find(|d| d.name == e.key) else {
            let elsewhere = all.variants_having(&e.key);
            if let (Some(t), false) = (&tag, elsewhere.is_empty()) {
                return Err(invalid(
                    e.key_line,
                    format!(
                        "`{}` is not a parameter of {context}: it applies with {t} = {} only",
                        e.key,
                        elsewhere
                            .iter()
                            .map(|w| format!("\"{w}\""))
                            .collect::<Vec<_>>()
                            .join(" or ")
                    ),
                ));
            }
            let mut known: Vec<&str> = STAGE_KEYS.to_vec();
            known.extend(tag.as_deref());
            known.extend(docs.iter().map(|d| d.name.as_str()));
            return Err(SpecError::UnknownKey {
                file: file.to_path_buf(),
                line: e.key_line,
                key: e.key.clone(),
                context,
                known: known.join(", "),
                suggestion: suggest(&e.key, &known),
            });
        };
        let value = check_type(doc, &e.value)
            .map_err(|message| invalid(e.value.line, format!("stage \"{stage_id}\": {message}")))?;
        given.insert(doc.name.clone(), value);
        lines.push((doc.name.clone(), e.key_line));
    }
    for doc in docs {
        if doc.required && !given.contains_key(&doc.name) {
            return Err(invalid(
                stage_line,
                format!(
                    "{context} is missing required parameter `{}` ({}: {})",
                    doc.name,
                    doc.ty.describe(),
                    doc.doc
                ),
            ));
        }
    }
    let canonical = params.canonical(Value::Object(given)).map_err(|e| {
        let key = e.path.split(['.', '[']).next().unwrap_or_default();
        let line = lines
            .iter()
            .find(|(k, _)| k == key)
            .map_or(stage_line, |(_, l)| *l);
        let at = if e.path.is_empty() {
            String::new()
        } else {
            format!("`{}`: ", e.path)
        };
        invalid(line, format!("stage \"{stage_id}\": {at}{}", e.message))
    })?;
    let Value::Object(map) = canonical else {
        return Err(invalid(
            stage_line,
            format!("stage \"{stage_id}\": parameters are not a table"),
        ));
    };
    Ok((map, lines))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    /// A strategy.
    #[derive(Serialize, Deserialize, JsonSchema, Debug, Default, Clone, Copy, PartialEq)]
    #[serde(rename_all = "kebab-case")]
    enum Mode {
        #[default]
        Fast,
        SlowAndSure,
    }

    #[derive(Serialize, Deserialize, JsonSchema, Debug, PartialEq)]
    #[serde(default)]
    struct Demo {
        /// How many.
        count: u32,
        /// A   spacing
        /// over two lines (s).
        dt: f64,
        /// The mode.
        mode: Mode,
        /// Optional seed.
        #[serde(skip_serializing_if = "Option::is_none")]
        seed: Option<u64>,
        /// Names.
        #[serde(skip_serializing_if = "Option::is_none")]
        names: Option<Vec<String>>,
    }

    impl Default for Demo {
        fn default() -> Self {
            Demo {
                count: 3,
                dt: 0.5,
                mode: Mode::Fast,
                seed: None,
                names: None,
            }
        }
    }

    #[derive(Serialize, Deserialize, JsonSchema, Debug, PartialEq, Default)]
    #[serde(default)]
    struct Other {
        /// Which games.
        games: Option<String>,
    }

    #[derive(Serialize, Deserialize, JsonSchema, Debug, PartialEq)]
    #[serde(tag = "env", rename_all = "lowercase")]
    enum Tagged {
        Pooltool(Demo),
        Iphyre(Other),
    }

    impl Default for Tagged {
        fn default() -> Self {
            Tagged::Pooltool(Demo::default())
        }
    }

    #[test]
    fn docs_come_from_the_struct() {
        let ParamDocs::Flat(docs) = ParamsOf::of::<Demo>().docs() else {
            panic!("flat")
        };
        let names: Vec<&str> = docs.iter().map(|d| d.name.as_str()).collect();
        assert_eq!(names, ["count", "dt", "mode", "seed", "names"]);
        assert_eq!(
            docs[0].ty,
            ParamType::Count {
                max: u32::MAX as u64
            }
        );
        assert_eq!(docs[0].default, Some(Value::from(3)));
        assert_eq!(docs[1].doc, "A spacing over two lines (s).");
        assert_eq!(
            docs[2].ty,
            ParamType::Choice(vec!["fast".into(), "slow-and-sure".into()])
        );
        assert_eq!(
            docs[3].ty,
            ParamType::Count {
                max: i64::MAX as u64
            }
        );
        assert_eq!(docs[3].default, None);
        assert_eq!(docs[4].ty, ParamType::StrList);
    }

    #[test]
    fn tagged_docs_list_each_variant() {
        let ParamDocs::ByTag {
            tag,
            default,
            variants,
        } = ParamsOf::of::<Tagged>().docs()
        else {
            panic!("tagged")
        };
        assert_eq!(tag, "env");
        assert_eq!(default, "pooltool");
        assert_eq!(variants.len(), 2);
        assert_eq!(variants[1].0, "iphyre");
        assert_eq!(variants[1].1[0].name, "games");
    }

    #[test]
    fn canonical_fills_defaults_and_leaves_out_unset_options() {
        let c = ParamsOf::of::<Demo>()
            .canonical(serde_json::json!({"count": 5}))
            .unwrap();
        assert_eq!(
            c,
            serde_json::json!({"count": 5, "dt": 0.5, "mode": "fast"})
        );
        let e = ParamsOf::of::<Demo>()
            .canonical(serde_json::json!({"count": 5, "mode": "slow"}))
            .unwrap_err();
        assert_eq!(e.path, "mode");
    }
}
