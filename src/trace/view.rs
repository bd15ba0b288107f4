//! Borrowed views of a table's columns, one value per row, in the forms a simulator holds them: a
//! vector per row, a per-object list indexed by each row's object, a per-timestep value repeated
//! over the step's rows, one constant, or nulls. A columnar writer (`store::ColumnSink`) encodes
//! them straight into Parquet pages, so no Arrow array (and no per-row string) is built for the
//! frame tables.
//!
//! **Owns:** [`ColumnView`] and its conversion from Arrow arrays ([`ColumnView::from_array`]; used
//! to re-encode stored tables and by tests).
//! **Does not:** encode anything (`store`), or know which table a view belongs to (the caller lists
//! views in its schema's order: [`super::TraceColumns::tables`]).

use std::borrow::Cow;

use arrow::array::{
    Array, ArrayRef, AsArray, BooleanArray, DictionaryArray, Float64Array, Int32Array, Int64Array,
    StringArray,
};
use arrow::datatypes::{DataType, Int32Type};

/// Keys into a per-object (or per-code) list, one per row.
#[derive(Clone, Debug)]
pub enum Keys<'a> {
    /// Positions in the list.
    U32(Cow<'a, [u32]>),
    /// Codes (a negative or too large code means the list's first entry, as the dictionary
    /// builder of the record batches maps it).
    I32(&'a [i32]),
}

impl Keys<'_> {
    /// Number of rows.
    pub fn len(&self) -> usize {
        match self {
            Keys::U32(k) => k.len(),
            Keys::I32(k) => k.len(),
        }
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The key of row `i`, clamped to `0..n` (out of range keys mean entry 0).
    #[inline]
    pub fn get(&self, i: usize, n: usize) -> usize {
        let k = match self {
            Keys::U32(k) => k[i] as usize,
            Keys::I32(k) => usize::try_from(k[i]).unwrap_or(usize::MAX),
        };
        if k < n { k } else { 0 }
    }
}

/// One column's values for a run of rows.
#[derive(Clone, Debug)]
pub enum ColumnView<'a> {
    /// A float per row.
    F64(Cow<'a, [f64]>),
    /// A 64-bit integer per row.
    I64(Cow<'a, [i64]>),
    /// A 32-bit integer per row.
    I32(Cow<'a, [i32]>),
    /// A boolean per row.
    Bool(Cow<'a, [bool]>),
    /// Row `i` holds `values[keys[i]]` (values may repeat).
    F64Of {
        /// Per object.
        values: Cow<'a, [f64]>,
        /// Per row.
        keys: Keys<'a>,
    },
    /// Row `i` holds `values[keys[i]]`.
    I64Of {
        /// Per object.
        values: Cow<'a, [i64]>,
        /// Per row.
        keys: Keys<'a>,
    },
    /// Row `i` holds `values[keys[i]]`.
    BoolOf {
        /// Per object.
        values: Cow<'a, [bool]>,
        /// Per row.
        keys: Keys<'a>,
    },
    /// Row `i` holds the string `values[keys[i]]` (values may repeat).
    Str {
        /// Per object or code.
        values: Vec<&'a str>,
        /// Per row.
        keys: Keys<'a>,
    },
    /// The same string in every row.
    StrConst(&'a str),
    /// Timestep `s`'s value repeated over its `counts[s]` rows.
    F64Runs {
        /// Per timestep.
        values: &'a [f64],
        /// Rows per timestep.
        counts: &'a [i32],
    },
    /// Timestep `s`'s value repeated over its `counts[s]` rows.
    I64Runs {
        /// Per timestep.
        values: &'a [i64],
        /// Rows per timestep.
        counts: &'a [i32],
    },
    /// `0, 1, …, counts[s] - 1` for each timestep `s` (a row's slot within its timestep).
    Slots(&'a [i32]),
    /// Null in every row.
    Null,
}

impl<'a> ColumnView<'a> {
    /// The view of an Arrow array whose values are all present or all null (`None` for any other
    /// array, or a type the trace tables do not use).
    pub fn from_array(array: &'a ArrayRef) -> Option<Self> {
        if array.null_count() == array.len() && !array.is_empty() {
            return Some(ColumnView::Null);
        }
        if array.null_count() != 0 {
            return None;
        }
        Some(match array.data_type() {
            DataType::Float64 => {
                let a: &Float64Array = array.as_primitive();
                ColumnView::F64(Cow::Borrowed(a.values()))
            }
            DataType::Int64 => {
                let a: &Int64Array = array.as_primitive();
                ColumnView::I64(Cow::Borrowed(a.values()))
            }
            DataType::Int32 => {
                let a: &Int32Array = array.as_primitive();
                ColumnView::I32(Cow::Borrowed(a.values()))
            }
            DataType::Boolean => {
                let a: &BooleanArray = array.as_boolean();
                ColumnView::Bool(Cow::Owned(a.values().iter().collect()))
            }
            DataType::Utf8 => {
                let a: &StringArray = array.as_string();
                ColumnView::Str {
                    values: a.iter().map(|s| s.unwrap_or_default()).collect(),
                    keys: Keys::U32(Cow::Owned((0..a.len() as u32).collect())),
                }
            }
            DataType::Dictionary(k, v) if **k == DataType::Int32 && **v == DataType::Utf8 => {
                let d: &DictionaryArray<Int32Type> = array.as_dictionary();
                let values: &StringArray = d.values().as_string_opt()?;
                if values.null_count() != 0 {
                    return None;
                }
                ColumnView::Str {
                    values: values.iter().map(|s| s.unwrap_or_default()).collect(),
                    keys: Keys::I32(d.keys().values()),
                }
            }
            _ => return None,
        })
    }
}
