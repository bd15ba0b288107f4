//! A TOML document with the line of every key and value, so that pipeline errors can say where.

use std::path::Path;

use serde_json::{Number, Value};
use toml::de::{DeTable, DeValue};

use super::SpecError;

/// A value of the pipeline file and the line it starts on.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Node {
    pub value: NodeValue,
    pub line: usize,
}

/// TOML values, with tables keeping the line of each key.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum NodeValue {
    Str(String),
    Int(i64),
    Float(f64),
    Bool(bool),
    Datetime(String),
    Array(Vec<Node>),
    Table(Vec<Entry>),
}

/// One `key = value` of a table.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Entry {
    pub key: String,
    pub key_line: usize,
    pub value: Node,
}

impl NodeValue {
    /// The TOML type name, for errors.
    pub fn type_name(&self) -> &'static str {
        match self {
            NodeValue::Str(_) => "a string",
            NodeValue::Int(_) => "an integer",
            NodeValue::Float(_) => "a float",
            NodeValue::Bool(_) => "a boolean",
            NodeValue::Datetime(_) => "a datetime",
            NodeValue::Array(_) => "an array",
            NodeValue::Table(_) => "a table",
        }
    }
}

impl Node {
    /// The value as JSON (datetimes become strings).
    pub fn to_json(&self) -> Value {
        match &self.value {
            NodeValue::Str(s) | NodeValue::Datetime(s) => Value::String(s.clone()),
            NodeValue::Int(i) => Value::from(*i),
            NodeValue::Float(f) => Number::from_f64(*f).map_or(Value::Null, Value::Number),
            NodeValue::Bool(b) => Value::Bool(*b),
            NodeValue::Array(items) => Value::Array(items.iter().map(Node::to_json).collect()),
            NodeValue::Table(entries) => Value::Object(
                entries
                    .iter()
                    .map(|e| (e.key.clone(), e.value.to_json()))
                    .collect(),
            ),
        }
    }
}

/// Maps byte offsets to 1-based line numbers.
struct Lines(Vec<usize>);

impl Lines {
    fn new(text: &str) -> Self {
        Lines(text.match_indices('\n').map(|(i, _)| i).collect())
    }
    fn line(&self, offset: usize) -> usize {
        self.0.partition_point(|&nl| nl < offset) + 1
    }
}

/// Parses a pipeline file's text into entries with lines.
pub(crate) fn parse(file: &Path, text: &str) -> Result<Vec<Entry>, SpecError> {
    let lines = Lines::new(text);
    let doc = DeTable::parse(text).map_err(|e| SpecError::Toml {
        file: file.to_path_buf(),
        line: e.span().map_or(1, |s| lines.line(s.start)),
        message: e.message().trim().to_string(),
    })?;
    let table = doc.into_inner();
    convert_table(&table, &lines, file)
}

fn convert_table(t: &DeTable<'_>, lines: &Lines, file: &Path) -> Result<Vec<Entry>, SpecError> {
    let mut entries: Vec<Entry> = t
        .iter()
        .map(|(k, v)| {
            Ok(Entry {
                key: k.get_ref().to_string(),
                key_line: lines.line(k.span().start),
                value: convert(v.get_ref(), lines.line(v.span().start), lines, file)?,
            })
        })
        .collect::<Result<_, SpecError>>()?;
    // The map behind DeTable sorts keys; restore file order so errors come in reading order.
    entries.sort_by_key(|e| e.key_line);
    Ok(entries)
}

fn convert(v: &DeValue<'_>, line: usize, lines: &Lines, file: &Path) -> Result<Node, SpecError> {
    let bad = |what: &str| SpecError::Toml {
        file: file.to_path_buf(),
        line,
        message: format!("{what} is out of range"),
    };
    let value = match v {
        DeValue::String(s) => NodeValue::Str(s.to_string()),
        DeValue::Integer(i) => NodeValue::Int(
            i64::from_str_radix(&i.as_str().replace('_', ""), i.radix())
                .map_err(|_| bad("integer"))?,
        ),
        DeValue::Float(f) => {
            let s = f.as_str().replace('_', "");
            let parsed = match s.trim_start_matches('+') {
                "inf" => f64::INFINITY,
                "-inf" => f64::NEG_INFINITY,
                "nan" | "-nan" => f64::NAN,
                other => other.parse::<f64>().map_err(|_| bad("float"))?,
            };
            NodeValue::Float(parsed)
        }
        DeValue::Boolean(b) => NodeValue::Bool(*b),
        DeValue::Datetime(d) => NodeValue::Datetime(d.to_string()),
        DeValue::Array(items) => NodeValue::Array(
            items
                .iter()
                .map(|item| convert(item.get_ref(), lines.line(item.span().start), lines, file))
                .collect::<Result<_, _>>()?,
        ),
        DeValue::Table(t) => NodeValue::Table(convert_table(t, lines, file)?),
    };
    Ok(Node { value, line })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_lines_of_keys_and_array_tables() {
        let text = "[pipeline]\nname = \"x\"\n\n[[stage]]\nid = \"a\"\nkind = \"sql\"\n\n[[stage]]\nid = \"b\"\nseed = 0x10\n";
        let doc = parse(Path::new("p.toml"), text).unwrap();
        let stages = doc.iter().find(|e| e.key == "stage").unwrap();
        let NodeValue::Array(items) = &stages.value.value else {
            panic!()
        };
        let NodeValue::Table(second) = &items[1].value else {
            panic!()
        };
        assert_eq!(second[0].key, "id");
        assert_eq!(second[0].key_line, 9);
        assert_eq!(second[1].value.value, NodeValue::Int(16));
    }

    #[test]
    fn syntax_errors_carry_the_line() {
        let err = parse(Path::new("p.toml"), "a = 1\nb = = 2\n").unwrap_err();
        assert!(matches!(err, SpecError::Toml { line: 2, .. }), "{err:?}");
    }
}
