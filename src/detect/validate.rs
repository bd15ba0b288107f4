//! Validation of a detector's output against the paper's pattern contract, in Rust (the worker is not
//! trusted to have done it).
//!
//! The output must be a list of objects, each with `label` (the detector's label, compared
//! case-insensitively, or an alias), integer `start_timestep` ≤ `end_timestep`, both between the trace's
//! first and last timestep index, and `parameters` holding an `object_details` object. `provenance` and
//! `metadata` are optional; other keys are ignored. Every fault names its JSON path (`$[2].end_timestep`).

use serde_json::{Map, Value};

use super::detector::Detector;
use super::error::DetectorError;

/// One validated pattern.
#[derive(Clone, Debug, PartialEq)]
pub struct Pattern {
    /// The label as the detector wrote it.
    pub label: String,
    /// First timestep index (inclusive).
    pub start_step: i64,
    /// Last timestep index (inclusive).
    pub end_step: i64,
    /// `parameters`, verbatim (holds `object_details`).
    pub parameters: Map<String, Value>,
    /// `provenance`, if given.
    pub provenance: Option<Value>,
    /// `metadata`, if given.
    pub metadata: Option<Value>,
}

impl Pattern {
    /// `parameters.object_details`.
    pub fn object_details(&self) -> Option<&Map<String, Value>> {
        self.parameters.get("object_details")?.as_object()
    }

    /// The object ids the pattern names: the `object_details` keys, or where an entry gives an id
    /// (`ball_id`, `object_index`, `index`, `id`, `object_id`), that id.
    pub fn objects(&self) -> Vec<String> {
        let mut out = Vec::new();
        for (key, entry) in self.object_details().into_iter().flatten() {
            let id = ["ball_id", "object_id", "object_index", "index", "id"]
                .iter()
                .find_map(|k| match entry.get(k) {
                    Some(Value::String(s)) => Some(s.clone()),
                    Some(Value::Number(n)) => Some(n.to_string()),
                    _ => None,
                })
                .unwrap_or_else(|| key.clone());
            if !out.contains(&id) {
                out.push(id);
            }
        }
        out
    }
}

fn invalid(path: String, message: impl Into<String>) -> DetectorError {
    DetectorError::InvalidOutput {
        path,
        message: message.into(),
    }
}

fn step(item: &Map<String, Value>, key: &str, path: &str) -> Result<i64, DetectorError> {
    match item.get(key) {
        None => Err(invalid(format!("{path}.{key}"), format!("missing `{key}`"))),
        Some(Value::Number(n)) => match n.as_i64() {
            Some(i) => Ok(i),
            None => match n.as_f64() {
                Some(f) if f.fract() == 0.0 && f.abs() < 1e15 => Ok(f as i64),
                _ => Err(invalid(
                    format!("{path}.{key}"),
                    format!("`{key}` must be an integer timestep index, found {n}"),
                )),
            },
        },
        Some(other) => Err(invalid(
            format!("{path}.{key}"),
            format!(
                "`{key}` must be an integer timestep index, found {}",
                type_name(other)
            ),
        )),
    }
}

fn type_name(v: &Value) -> &'static str {
    match v {
        Value::Null => "None",
        Value::Bool(_) => "a bool",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "a list",
        Value::Object(_) => "a dict",
    }
}

/// Checks `output` (the detector's return value) for `detector` on a trace whose timestep indices run
/// from `first` to `last` (`None` for a trace without timesteps).
pub fn validate(
    output: Value,
    detector: &Detector,
    steps: Option<(i64, i64)>,
) -> Result<Vec<Pattern>, DetectorError> {
    let Value::Array(items) = output else {
        return Err(invalid(
            "$".into(),
            format!(
                "find_pattern must return a list, found {}",
                type_name(&output)
            ),
        ));
    };
    let mut out = Vec::with_capacity(items.len());
    // Labels already accepted in this output (a detector writes the same one on every pattern).
    let mut accepted: Vec<String> = Vec::new();
    for (i, item) in items.into_iter().enumerate() {
        let path = format!("$[{i}]");
        let Value::Object(mut item) = item else {
            return Err(invalid(
                path,
                format!("each pattern must be a dict, found {}", type_name(&item)),
            ));
        };
        let label = match item.get("label") {
            Some(Value::String(s)) => s.clone(),
            Some(other) => {
                return Err(invalid(
                    format!("{path}.label"),
                    format!("`label` must be a string, found {}", type_name(other)),
                ));
            }
            None => return Err(invalid(format!("{path}.label"), "missing `label`")),
        };
        if !accepted.contains(&label) && !detector.accepts_label(&label) {
            return Err(invalid(
                format!("{path}.label"),
                format!(
                    "label {label:?} is not the target label {:?}",
                    detector.label
                ),
            ));
        }
        if accepted.len() < 4 && !accepted.contains(&label) {
            accepted.push(label.clone());
        }
        let start = step(&item, "start_timestep", &path)?;
        let end = step(&item, "end_timestep", &path)?;
        if start > end {
            return Err(invalid(
                format!("{path}.end_timestep"),
                format!("end_timestep {end} is before start_timestep {start}"),
            ));
        }
        match steps {
            None => {
                return Err(invalid(
                    format!("{path}.start_timestep"),
                    "the trace has no timesteps",
                ));
            }
            Some((first, last)) => {
                for (key, v) in [("start_timestep", start), ("end_timestep", end)] {
                    if v < first || v > last {
                        return Err(invalid(
                            format!("{path}.{key}"),
                            format!("{key} {v} is outside the trace's timesteps {first}..={last}"),
                        ));
                    }
                }
            }
        }
        let parameters = match item.remove("parameters") {
            Some(Value::Object(p)) => p,
            Some(other) => {
                return Err(invalid(
                    format!("{path}.parameters"),
                    format!("`parameters` must be a dict, found {}", type_name(&other)),
                ));
            }
            None => {
                return Err(invalid(
                    format!("{path}.parameters"),
                    "missing `parameters`",
                ));
            }
        };
        match parameters.get("object_details") {
            Some(Value::Object(_)) => {}
            Some(other) => {
                return Err(invalid(
                    format!("{path}.parameters.object_details"),
                    format!(
                        "`object_details` must be a dict, found {}",
                        type_name(other)
                    ),
                ));
            }
            None => {
                return Err(invalid(
                    format!("{path}.parameters.object_details"),
                    "missing `object_details` (a dict keyed by object id or role)",
                ));
            }
        }
        out.push(Pattern {
            label,
            start_step: start,
            end_step: end,
            parameters,
            provenance: item.remove("provenance"),
            metadata: item.remove("metadata"),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;
    use crate::trace::Env;

    fn det() -> Detector {
        Detector::new(Env::Pooltool, "cue strike", "", "test")
    }

    fn good() -> Value {
        json!({"label": "Cue Strike", "start_timestep": 1, "end_timestep": 2,
               "parameters": {"object_details": {"cue": {"role": "struck", "ball_id": "cue"}}},
               "metadata": {"speed": 2.0}})
    }

    fn err_path(v: Value) -> (String, String) {
        match validate(v, &det(), Some((0, 10))).unwrap_err() {
            DetectorError::InvalidOutput { path, message } => (path, message),
            e => panic!("{e:?}"),
        }
    }

    #[test]
    fn a_valid_pattern_passes_with_its_objects() {
        let out = validate(json!([good()]), &det(), Some((0, 10))).unwrap();
        assert_eq!(out.len(), 1);
        assert_eq!((out[0].start_step, out[0].end_step), (1, 2));
        assert_eq!(out[0].objects(), vec!["cue".to_string()]);
        assert_eq!(out[0].metadata, Some(json!({"speed": 2.0})));
        assert!(validate(json!([]), &det(), None).unwrap().is_empty());
    }

    #[test]
    fn each_invalid_output_names_its_path() {
        assert_eq!(err_path(json!({"a": 1})).0, "$");
        assert_eq!(err_path(json!([1])).0, "$[0]");
        let mut v = good();
        v["label"] = json!("ball collision");
        assert_eq!(err_path(json!([good(), v])).0, "$[1].label");
        let mut v = good();
        v["label"] = json!(3);
        assert_eq!(err_path(json!([v])).0, "$[0].label");
        let mut v = good();
        v.as_object_mut().unwrap().remove("start_timestep");
        assert_eq!(err_path(json!([v])).0, "$[0].start_timestep");
        let mut v = good();
        v["end_timestep"] = json!("5");
        assert_eq!(err_path(json!([v])).0, "$[0].end_timestep");
        let mut v = good();
        v["end_timestep"] = json!(1.5);
        assert_eq!(err_path(json!([v])).0, "$[0].end_timestep");
        let mut v = good();
        v["start_timestep"] = json!(5);
        let (p, m) = err_path(json!([v]));
        assert_eq!(p, "$[0].end_timestep");
        assert!(m.contains("before"));
        let mut v = good();
        v["end_timestep"] = json!(11);
        let (p, m) = err_path(json!([v]));
        assert_eq!(p, "$[0].end_timestep");
        assert!(m.contains("outside"), "{m}");
        let mut v = good();
        v["start_timestep"] = json!(-1);
        assert_eq!(err_path(json!([v])).0, "$[0].start_timestep");
        let mut v = good();
        v.as_object_mut().unwrap().remove("parameters");
        assert_eq!(err_path(json!([v])).0, "$[0].parameters");
        let mut v = good();
        v["parameters"] = json!({"speed": 1});
        assert_eq!(err_path(json!([v])).0, "$[0].parameters.object_details");
        let mut v = good();
        v["parameters"] = json!({"object_details": []});
        assert_eq!(err_path(json!([v])).0, "$[0].parameters.object_details");
        // Integral floats are accepted as indices.
        let mut v = good();
        v["end_timestep"] = json!(3.0);
        assert_eq!(
            validate(json!([v]), &det(), Some((0, 10))).unwrap()[0].end_step,
            3
        );
    }
}
