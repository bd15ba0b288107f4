//! Typed access to the fields of one JSON object (a JSON map, or the slots the streaming reader filled
//! for a known layout), with errors that carry the JSON path of the fault. A path is made into text
//! only for a fault. Does not own the layouts or the reading itself (`read`).

use std::borrow::Cow;

use serde_json::Value;

use super::error::{Fault, FaultKind};
use crate::trace::model::JsonMap;

/// Where an object's fields are looked up: a whole JSON map, or the fields of a known layout that the
/// streaming reader kept (`read::Slots`) without building a map.
pub(crate) trait Lookup {
    /// The value of field `key`, if the object has it.
    fn field(&self, key: &str) -> Option<&Value>;
}

impl Lookup for JsonMap {
    fn field(&self, key: &str) -> Option<&Value> {
        self.get(key)
    }
}

/// The JSON path of an object, made into text only when a fault needs it: the reader walks about
/// ten thousand objects per billiard shot and names none of them unless one is faulty.
#[derive(Clone, Copy)]
pub(crate) enum ObjectPath<'a> {
    /// A path given whole (`$.outcome`).
    Whole(&'a str),
    /// Element `.1` of the array at path `.0` (`$.timesteps[3].objects` and 1).
    Item(&'a str, usize),
}

impl<'a> ObjectPath<'a> {
    /// The path as text.
    pub(crate) fn text(self) -> Cow<'a, str> {
        match self {
            ObjectPath::Whole(p) => Cow::Borrowed(p),
            ObjectPath::Item(p, i) => Cow::Owned(format!("{p}[{i}]")),
        }
    }
}

/// A JSON object being read field by field; `path` is its JSON path (`$.timesteps[3].objects[1]`).
pub(crate) struct Fields<'a, M: Lookup + ?Sized = JsonMap> {
    obj: &'a M,
    path: ObjectPath<'a>,
}

/// A short, printable description of a JSON value for error messages.
pub(crate) fn describe(v: &Value) -> String {
    let text = match v {
        Value::Null => return "null".into(),
        Value::Bool(b) => return format!("boolean {b}"),
        Value::Number(n) => return format!("number {n}"),
        Value::String(s) => format!("string {s:?}"),
        Value::Array(a) => return format!("an array of {} items", a.len()),
        Value::Object(o) => return format!("an object with {} keys", o.len()),
    };
    if text.len() > 60 {
        let mut cut = 57;
        while !text.is_char_boundary(cut) {
            cut -= 1;
        }
        format!("{}...", &text[..cut])
    } else {
        text
    }
}

impl<'a> Fields<'a> {
    /// Reads `value` as an object, or fails with a type fault at `path`.
    pub(crate) fn of(value: &'a Value, path: &'a str, what: &str) -> Result<Self, Fault> {
        match value {
            Value::Object(obj) => Ok(Fields {
                obj,
                path: ObjectPath::Whole(path),
            }),
            other => Err(not_an_object(path, what, other)),
        }
    }

    /// The fields whose names are not in `known`, in input order.
    pub(crate) fn rest(&self, known: &[&str]) -> JsonMap {
        self.obj
            .iter()
            .filter(|(k, _)| !known.contains(&k.as_str()))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect()
    }
}

/// The fault for a value that should have been an object (`what` names it: "a timestep").
pub(crate) fn not_an_object(path: &str, what: &str, found: &Value) -> Fault {
    Fault::new(
        path,
        FaultKind::Type,
        format!("expected {what} (a JSON object), found {}", describe(found)),
    )
}

impl<'a, M: Lookup + ?Sized> Fields<'a, M> {
    /// Reads the fields of `obj`, an object at `path`.
    pub(crate) fn new(obj: &'a M, path: ObjectPath<'a>) -> Self {
        Fields { obj, path }
    }

    /// The JSON path of `key` inside this object.
    pub(crate) fn path_of(&self, key: &str) -> String {
        child_path(&self.path.text(), key)
    }

    fn required(&self, key: &str) -> Result<&'a Value, Fault> {
        self.obj.field(key).ok_or_else(|| {
            Fault::new(
                self.path_of(key),
                FaultKind::Missing,
                format!("missing required field `{key}`"),
            )
        })
    }

    /// A required finite number.
    pub(crate) fn f64(&self, key: &str) -> Result<f64, Fault> {
        number(self.required(key)?, || self.path_of(key))
    }

    /// An optional finite number (absent or null gives `None`).
    pub(crate) fn opt_f64(&self, key: &str) -> Result<Option<f64>, Fault> {
        match self.obj.field(key) {
            None | Some(Value::Null) => Ok(None),
            Some(v) => number(v, || self.path_of(key)).map(Some),
        }
    }

    /// A required integer.
    pub(crate) fn i64(&self, key: &str) -> Result<i64, Fault> {
        let v = self.required(key)?;
        v.as_i64().ok_or_else(|| {
            Fault::new(
                self.path_of(key),
                FaultKind::Type,
                format!("expected an integer, found {}", describe(v)),
            )
        })
    }

    /// A required string.
    pub(crate) fn str(&self, key: &str) -> Result<String, Fault> {
        let v = self.required(key)?;
        v.as_str().map(str::to_owned).ok_or_else(|| {
            Fault::new(
                self.path_of(key),
                FaultKind::Type,
                format!("expected a string, found {}", describe(v)),
            )
        })
    }

    /// A required boolean.
    pub(crate) fn bool(&self, key: &str) -> Result<bool, Fault> {
        let v = self.required(key)?;
        v.as_bool().ok_or_else(|| {
            Fault::new(
                self.path_of(key),
                FaultKind::Type,
                format!("expected true or false, found {}", describe(v)),
            )
        })
    }

    /// A required array of exactly three finite numbers.
    pub(crate) fn vec3(&self, key: &str) -> Result<[f64; 3], Fault> {
        let v = self.required(key)?;
        let items = v.as_array().filter(|a| a.len() == 3).ok_or_else(|| {
            Fault::new(
                self.path_of(key),
                FaultKind::Type,
                format!("expected an array of 3 numbers, found {}", describe(v)),
            )
        })?;
        let mut out = [0.0; 3];
        for (i, item) in items.iter().enumerate() {
            out[i] = number(item, || format!("{}[{i}]", self.path_of(key)))?;
        }
        Ok(out)
    }

    /// An optional JSON object (absent gives `None`).
    pub(crate) fn opt_object(&self, key: &str) -> Result<Option<JsonMap>, Fault> {
        match self.obj.field(key) {
            None => Ok(None),
            Some(Value::Object(m)) => Ok(Some(m.clone())),
            Some(v) => Err(Fault::new(
                self.path_of(key),
                FaultKind::Type,
                format!("expected a JSON object, found {}", describe(v)),
            )),
        }
    }
}

/// Reads a finite number; integers are accepted where a float is expected. `path` makes the
/// value's JSON path, only for a fault.
pub(crate) fn number(v: &Value, path: impl FnOnce() -> String) -> Result<f64, Fault> {
    match v.as_f64() {
        Some(x) if x.is_finite() => Ok(x),
        Some(x) => Err(Fault::new(
            path(),
            FaultKind::NonFinite,
            format!("expected a finite number, found {x}"),
        )),
        None => Err(Fault::new(
            path(),
            FaultKind::Type,
            format!("expected a number, found {}", describe(v)),
        )),
    }
}

/// `parent.key`, quoting the key when it is not a plain identifier.
pub(crate) fn child_path(parent: &str, key: &str) -> String {
    let plain = !key.is_empty()
        && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !key.starts_with(|c: char| c.is_ascii_digit());
    if plain {
        format!("{parent}.{key}")
    } else {
        format!("{parent}[{key:?}]")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn errors_name_the_path_and_what_was_found() {
        let v = json!({"x": "abc", "p": [1, 2], "n": 3.5});
        let f = Fields::of(&v, "$.timesteps[2].objects[0]", "an object").unwrap();
        let e = f.f64("x").unwrap_err();
        assert_eq!(e.path, "$.timesteps[2].objects[0].x");
        assert!(e.message.contains("string \"abc\""), "{}", e.message);
        let e = f.vec3("p").unwrap_err();
        assert_eq!(e.kind, FaultKind::Type);
        let e = f.i64("n").unwrap_err();
        assert!(e.message.contains("integer"));
        let e = f.str("missing").unwrap_err();
        assert_eq!(e.kind, FaultKind::Missing);
        assert_eq!(e.path, "$.timesteps[2].objects[0].missing");
    }

    #[test]
    fn odd_keys_are_quoted_in_paths() {
        assert_eq!(child_path("$", "a b"), "$[\"a b\"]");
        assert_eq!(child_path("$", "9ball"), "$[\"9ball\"]");
        assert_eq!(child_path("$", "ball_id"), "$.ball_id");
    }
}
