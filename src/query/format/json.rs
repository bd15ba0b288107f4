//! JSON output with typed values: numbers stay numbers, nulls stay null, lists become arrays.
//! `json` writes one array of row objects; `ndjson` writes one object per line.

use std::io::{self, Write};

use arrow::array::{Array, ArrayRef, AsArray, RecordBatch};
use arrow::compute::cast;
use arrow::datatypes::SchemaRef;
use arrow::util::display::{ArrayFormatter, FormatOptions};
use serde_json::{Map, Number, Value};

/// One cell as a JSON value.
pub(crate) fn value(col: &ArrayRef, r: usize) -> Value {
    if col.is_null(r) {
        return Value::Null;
    }
    use arrow::datatypes::*;
    macro_rules! int {
        ($t:ty) => {
            Value::from(col.as_primitive::<$t>().value(r))
        };
    }
    match col.data_type() {
        DataType::Boolean => Value::Bool(col.as_boolean().value(r)),
        DataType::Int8 => int!(Int8Type),
        DataType::Int16 => int!(Int16Type),
        DataType::Int32 => int!(Int32Type),
        DataType::Int64 => int!(Int64Type),
        DataType::UInt8 => int!(UInt8Type),
        DataType::UInt16 => int!(UInt16Type),
        DataType::UInt32 => int!(UInt32Type),
        DataType::UInt64 => int!(UInt64Type),
        DataType::Float32 => {
            Number::from_f64(f64::from(col.as_primitive::<Float32Type>().value(r)))
                .map_or(Value::Null, Value::Number)
        }
        DataType::Float64 => Number::from_f64(col.as_primitive::<Float64Type>().value(r))
            .map_or(Value::Null, Value::Number),
        DataType::Utf8 => Value::String(col.as_string::<i32>().value(r).to_string()),
        DataType::LargeUtf8 => Value::String(col.as_string::<i64>().value(r).to_string()),
        DataType::Utf8View => Value::String(col.as_string_view().value(r).to_string()),
        DataType::Dictionary(_, _) => match cast(&col.slice(r, 1), &DataType::Utf8) {
            Ok(s) => value(&s, 0),
            Err(_) => display(col, r),
        },
        DataType::List(_) => {
            let inner = col.as_list::<i32>().value(r);
            Value::Array((0..inner.len()).map(|i| value(&inner, i)).collect())
        }
        DataType::LargeList(_) => {
            let inner = col.as_list::<i64>().value(r);
            Value::Array((0..inner.len()).map(|i| value(&inner, i)).collect())
        }
        _ => display(col, r),
    }
}

fn display(col: &ArrayRef, r: usize) -> Value {
    match ArrayFormatter::try_new(col.as_ref(), &FormatOptions::default()) {
        Ok(f) => Value::String(f.value(r).to_string()),
        Err(_) => Value::Null,
    }
}

pub(super) fn write(
    out: &mut dyn Write,
    schema: &SchemaRef,
    batches: &[RecordBatch],
    lines: bool,
) -> io::Result<()> {
    let names: Vec<&String> = schema.fields().iter().map(|f| f.name()).collect();
    let mut first = true;
    if !lines {
        write!(out, "[")?;
    }
    for batch in batches {
        for r in 0..batch.num_rows() {
            let row: Map<String, Value> = names
                .iter()
                .zip(batch.columns())
                .map(|(n, c)| ((*n).clone(), value(c, r)))
                .collect();
            let text = serde_json::to_string(&Value::Object(row)).map_err(io::Error::other)?;
            if lines {
                writeln!(out, "{text}")?;
            } else {
                write!(out, "{}{text}", if first { "\n  " } else { ",\n  " })?;
            }
            first = false;
        }
    }
    if !lines {
        writeln!(out, "{}]", if first { "" } else { "\n" })?;
    }
    Ok(())
}
