//! Declared stage parameters: their types, defaults and docs, and checking a stage table against them.
//!
//! Every stage kind lists its parameters as [`ParamSpec`]s, as ripgrep lists its flags: the list drives
//! validation (unknown keys, wrong types, missing required keys, each reported with the file and line),
//! the defaults that enter the stage's fingerprint, and the text of `annotrace stages`.

use std::path::Path;

use serde_json::{Map, Value};

use super::SpecError;
use super::toml_doc::{Entry, Node, NodeValue};

/// The type of a parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamType {
    /// A string.
    Str,
    /// One of a fixed set of strings.
    Choice(&'static [&'static str]),
    /// An integer.
    Int,
    /// A non-negative integer.
    Count,
    /// A float (integers accepted).
    Float,
    /// A boolean.
    Bool,
    /// An array of strings.
    StrList,
    /// A table of anything (passed through as JSON).
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
            ParamType::Count => "a non-negative integer".into(),
            ParamType::Float => "a number".into(),
            ParamType::Bool => "true or false".into(),
            ParamType::StrList => "an array of strings".into(),
            ParamType::Table => "a table".into(),
        }
    }
}

/// One declared parameter of a stage kind.
#[derive(Clone, Copy, Debug)]
pub struct ParamSpec {
    /// Key in the stage table.
    pub name: &'static str,
    /// Its type.
    pub ty: ParamType,
    /// Whether the stage needs it.
    pub required: bool,
    /// Default as a JSON literal, for optional parameters that have one.
    pub default: Option<&'static str>,
    /// One line of documentation.
    pub doc: &'static str,
}

impl ParamSpec {
    /// A required parameter.
    pub const fn required(name: &'static str, ty: ParamType, doc: &'static str) -> Self {
        ParamSpec {
            name,
            ty,
            required: true,
            default: None,
            doc,
        }
    }

    /// An optional parameter with a default (a JSON literal).
    pub const fn optional(
        name: &'static str,
        ty: ParamType,
        default: &'static str,
        doc: &'static str,
    ) -> Self {
        ParamSpec {
            name,
            ty,
            required: false,
            default: Some(default),
            doc,
        }
    }

    /// An optional parameter without a default.
    pub const fn maybe(name: &'static str, ty: ParamType, doc: &'static str) -> Self {
        ParamSpec {
            name,
            ty,
            required: false,
            default: None,
            doc,
        }
    }
}

fn check_type(spec: &ParamSpec, node: &Node) -> Result<Value, String> {
    let wrong = || {
        format!(
            "`{}` must be {}, found {}",
            spec.name,
            spec.ty.describe(),
            node.value.type_name()
        )
    };
    Ok(match (&spec.ty, &node.value) {
        (ParamType::Str, NodeValue::Str(s)) => Value::String(s.clone()),
        (ParamType::Choice(options), NodeValue::Str(s)) => {
            if !options.contains(&s.as_str()) {
                return Err(format!(
                    "`{}` must be {}, found \"{s}\"",
                    spec.name,
                    spec.ty.describe()
                ));
            }
            Value::String(s.clone())
        }
        (ParamType::Int, NodeValue::Int(i)) => Value::from(*i),
        (ParamType::Count, NodeValue::Int(i)) if *i >= 0 => Value::from(*i),
        (ParamType::Count, NodeValue::Int(i)) => {
            return Err(format!(
                "`{}` must be {}, found {i}",
                spec.name,
                spec.ty.describe()
            ));
        }
        (ParamType::Float, NodeValue::Int(i)) => Value::from(*i as f64),
        (ParamType::Float, NodeValue::Float(f)) if f.is_finite() => node.to_json(),
        (ParamType::Float, NodeValue::Float(f)) => {
            return Err(format!(
                "`{}` must be a finite number, found {f}",
                spec.name
            ));
        }
        (ParamType::Bool, NodeValue::Bool(b)) => Value::Bool(*b),
        (ParamType::StrList, NodeValue::Array(items)) => {
            let mut out = Vec::with_capacity(items.len());
            for (i, item) in items.iter().enumerate() {
                match &item.value {
                    NodeValue::Str(s) => out.push(Value::String(s.clone())),
                    other => {
                        return Err(format!(
                            "`{}[{i}]` must be a string, found {}",
                            spec.name,
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

/// A stage's parameters with defaults filled in, and the line of each given key.
pub(crate) type Resolved = (Map<String, Value>, Vec<(String, usize)>);

/// Checks a stage's parameter entries against the kind's specs. Returns the parameters with defaults
/// filled in, and the line of each given key.
pub(crate) fn resolve(
    file: &Path,
    stage_id: &str,
    stage_line: usize,
    kind: &str,
    specs: &[ParamSpec],
    entries: &[&Entry],
) -> Result<Resolved, SpecError> {
    let mut out = Map::new();
    let mut lines = Vec::new();
    for e in entries {
        let Some(spec) = specs.iter().find(|s| s.name == e.key) else {
            let mut known: Vec<&str> = vec!["id", "kind", "inputs", "description"];
            known.extend(specs.iter().map(|s| s.name));
            return Err(SpecError::UnknownKey {
                file: file.to_path_buf(),
                line: e.key_line,
                key: e.key.clone(),
                context: format!("stage \"{stage_id}\" (kind {kind})"),
                known: known.join(", "),
            });
        };
        let value = check_type(spec, &e.value).map_err(|message| SpecError::Invalid {
            file: file.to_path_buf(),
            line: e.value.line,
            message: format!("stage \"{stage_id}\": {message}"),
        })?;
        out.insert(spec.name.to_string(), value);
        lines.push((spec.name.to_string(), e.key_line));
    }
    for spec in specs {
        if out.contains_key(spec.name) {
            continue;
        }
        if spec.required {
            return Err(SpecError::Invalid {
                file: file.to_path_buf(),
                line: stage_line,
                message: format!(
                    "stage \"{stage_id}\" (kind {kind}) is missing required parameter `{}` ({}: {})",
                    spec.name,
                    spec.ty.describe(),
                    spec.doc
                ),
            });
        }
        if let Some(default) = spec.default {
            let v: Value =
                serde_json::from_str(default).expect("parameter defaults are valid JSON literals");
            out.insert(spec.name.to_string(), v);
        }
    }
    Ok((out, lines))
}
