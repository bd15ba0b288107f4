//! Result formats: a terminal table, CSV, Markdown, LaTeX (booktabs), JSON and JSON Lines.
//!
//! Every format reads the same cells: `Cells` renders each value once, with floats at a chosen
//! precision for the human formats (table, Markdown, LaTeX) and in full, round-trip precision for the
//! machine formats (CSV, JSON). Each format lives in its own file, as ripgrep keeps one printer per file.

mod csv;
mod json;
mod latex;
mod markdown;
mod table;

use std::fmt;
use std::io::{self, Write};
use std::str::FromStr;

use arrow::array::{Array, ArrayRef, AsArray, RecordBatch};
use arrow::datatypes::{DataType, Float32Type, Float64Type, SchemaRef};
use arrow::util::display::{ArrayFormatter, FormatOptions};

/// An output format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Aligned text for a terminal.
    Table,
    /// RFC 4180 CSV with a header row.
    Csv,
    /// A JSON array of row objects.
    Json,
    /// One JSON object per line.
    Ndjson,
    /// A GitHub-flavoured Markdown table.
    Markdown,
    /// A LaTeX `tabular` with booktabs rules, ready to `\input` into a paper.
    Latex,
    /// Apache Parquet (exports only).
    Parquet,
}

impl Format {
    /// Every format's name, for help and errors.
    pub const NAMES: &'static [&'static str] = &[
        "table", "csv", "json", "ndjson", "markdown", "latex", "parquet",
    ];

    /// The usual file extension.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Table => "txt",
            Format::Csv => "csv",
            Format::Json => "json",
            Format::Ndjson => "jsonl",
            Format::Markdown => "md",
            Format::Latex => "tex",
            Format::Parquet => "parquet",
        }
    }

    /// The format a file name asks for, by extension.
    pub fn from_extension(name: &str) -> Option<Format> {
        let ext = name.rsplit_once('.')?.1.to_ascii_lowercase();
        Some(match ext.as_str() {
            "csv" => Format::Csv,
            "json" => Format::Json,
            "jsonl" | "ndjson" => Format::Ndjson,
            "md" | "markdown" => Format::Markdown,
            "tex" | "latex" => Format::Latex,
            "parquet" => Format::Parquet,
            "txt" => Format::Table,
            _ => return None,
        })
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(Format::NAMES[*self as usize])
    }
}

/// A name that is not a format.
#[derive(Debug, Clone, thiserror::Error)]
#[error("unknown format {0:?} (expected one of: {names})", names = Format::NAMES.join(", "))]
pub struct UnknownFormat(pub String);

impl FromStr for Format {
    type Err = UnknownFormat;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(match s.to_ascii_lowercase().as_str() {
            "table" => Format::Table,
            "csv" => Format::Csv,
            "json" => Format::Json,
            "ndjson" | "jsonl" => Format::Ndjson,
            "markdown" | "md" => Format::Markdown,
            "latex" | "tex" => Format::Latex,
            "parquet" => Format::Parquet,
            _ => return Err(UnknownFormat(s.to_string())),
        })
    }
}

/// Options shared by the text formats.
#[derive(Clone, Debug)]
pub struct RenderOptions {
    /// Digits after the decimal point for floats in table, Markdown and LaTeX (CSV and JSON always
    /// keep full precision). `None` prints the shortest exact form.
    pub precision: Option<usize>,
    /// A caption line for LaTeX (as a comment above the tabular) and Markdown (as a heading line).
    pub title: Option<String>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            precision: Some(4),
            title: None,
        }
    }
}

/// Writes a query result in a text format. Parquet is written by `store::ParquetSink` instead.
pub fn render(
    out: &mut dyn Write,
    schema: &SchemaRef,
    batches: &[RecordBatch],
    format: Format,
    opts: &RenderOptions,
) -> io::Result<()> {
    match format {
        Format::Table => table::write(out, &Cells::new(schema, batches, opts.precision)),
        Format::Csv => csv::write(out, &Cells::new(schema, batches, None)),
        Format::Markdown => {
            markdown::write(out, &Cells::new(schema, batches, opts.precision), opts)
        }
        Format::Latex => latex::write(out, &Cells::new(schema, batches, opts.precision), opts),
        Format::Json => json::write(out, schema, batches, false),
        Format::Ndjson => json::write(out, schema, batches, true),
        Format::Parquet => Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            "Parquet is a binary format; write it with an export",
        )),
    }
}

/// Renders to a string (for tests and small results).
pub fn render_string(
    schema: &SchemaRef,
    batches: &[RecordBatch],
    format: Format,
    opts: &RenderOptions,
) -> String {
    let mut buf = Vec::new();
    render(&mut buf, schema, batches, format, opts).expect("writing to memory cannot fail");
    String::from_utf8(buf).expect("formats write UTF-8")
}

/// A result rendered to strings, cell by cell, with nulls as `None`.
pub(crate) struct Cells {
    pub headers: Vec<String>,
    /// Whether each column holds numbers (right-aligned in tables).
    pub numeric: Vec<bool>,
    pub rows: Vec<Vec<Option<String>>>,
}

impl Cells {
    pub(crate) fn new(
        schema: &SchemaRef,
        batches: &[RecordBatch],
        precision: Option<usize>,
    ) -> Self {
        let headers = schema.fields().iter().map(|f| f.name().clone()).collect();
        let numeric = schema
            .fields()
            .iter()
            .map(|f| f.data_type().is_numeric())
            .collect();
        let mut rows = Vec::new();
        let opts = FormatOptions::default().with_null("");
        for batch in batches {
            let cols: Vec<Box<dyn Fn(usize) -> Option<String>>> = batch
                .columns()
                .iter()
                .map(|c| cell_fn(c.clone(), precision, &opts))
                .collect();
            for r in 0..batch.num_rows() {
                rows.push(cols.iter().map(|f| f(r)).collect());
            }
        }
        Cells {
            headers,
            numeric,
            rows,
        }
    }
}

fn cell_fn(
    col: ArrayRef,
    precision: Option<usize>,
    opts: &FormatOptions<'static>,
) -> Box<dyn Fn(usize) -> Option<String>> {
    match (col.data_type(), precision) {
        (DataType::Float64, Some(p)) => Box::new(move |r| {
            (!col.is_null(r)).then(|| float(col.as_primitive::<Float64Type>().value(r), p))
        }),
        (DataType::Float32, Some(p)) => Box::new(move |r| {
            (!col.is_null(r))
                .then(|| float(f64::from(col.as_primitive::<Float32Type>().value(r)), p))
        }),
        _ => {
            // The formatter borrows the array; keep both alive together.
            let owned = col.clone();
            let opts = opts.clone();
            Box::new(move |r| {
                if owned.is_null(r) {
                    return None;
                }
                ArrayFormatter::try_new(owned.as_ref(), &opts)
                    .ok()
                    .map(|f| f.value(r).to_string())
            })
        }
    }
}

fn float(v: f64, precision: usize) -> String {
    if v.is_finite() {
        format!("{v:.precision$}")
    } else {
        v.to_string()
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use arrow::array::{Float64Array, Int64Array, StringArray};
    use arrow::datatypes::{Field, Schema};

    use super::*;

    pub(super) fn sample() -> (SchemaRef, Vec<RecordBatch>) {
        let schema = Arc::new(Schema::new(vec![
            Field::new("label", DataType::Utf8, true),
            Field::new("n", DataType::Int64, false),
            Field::new("mean_speed", DataType::Float64, true),
        ]));
        let batch = RecordBatch::try_new(
            schema.clone(),
            vec![
                Arc::new(StringArray::from(vec![
                    Some("cushion_rebound"),
                    Some("a, \"quoted\" & 50%"),
                    None,
                ])),
                Arc::new(Int64Array::from(vec![12, 3, 0])),
                Arc::new(Float64Array::from(vec![Some(1.23456789), Some(0.5), None])),
            ],
        )
        .unwrap();
        (schema, vec![batch])
    }

    #[test]
    fn table_aligns_and_rounds() {
        let (schema, batches) = sample();
        let out = render_string(&schema, &batches, Format::Table, &RenderOptions::default());
        insta::assert_snapshot!(out, @r#"
        +-------------------+----+------------+
        | label             | n  | mean_speed |
        +-------------------+----+------------+
        | cushion_rebound   | 12 |     1.2346 |
        | a, "quoted" & 50% |  3 |     0.5000 |
        |                   |  0 |            |
        +-------------------+----+------------+
        3 rows
        "#);
    }

    #[test]
    fn csv_quotes_and_keeps_full_precision() {
        let (schema, batches) = sample();
        let out = render_string(&schema, &batches, Format::Csv, &RenderOptions::default());
        assert_eq!(
            out,
            "label,n,mean_speed\ncushion_rebound,12,1.23456789\n\"a, \"\"quoted\"\" & 50%\",3,0.5\n,0,\n"
        );
    }

    #[test]
    fn markdown_right_aligns_numbers_and_escapes_pipes() {
        let (schema, batches) = sample();
        let out = render_string(
            &schema,
            &batches,
            Format::Markdown,
            &RenderOptions::default(),
        );
        insta::assert_snapshot!(out, @r#"
        | label | n | mean_speed |
        | :--- | ---: | ---: |
        | cushion_rebound | 12 | 1.2346 |
        | a, "quoted" & 50% | 3 | 0.5000 |
        |  | 0 |  |
        "#);
    }

    #[test]
    fn latex_is_booktabs_with_escapes() {
        let (schema, batches) = sample();
        let opts = RenderOptions {
            precision: Some(2),
            title: None,
        };
        let out = render_string(&schema, &batches, Format::Latex, &opts);
        insta::assert_snapshot!(out, @r#"
        % requires \usepackage{booktabs}
        \begin{tabular}{lrr}
        \toprule
        label & n & mean\_speed \\
        \midrule
        cushion\_rebound & 12 & 1.23 \\
        a, "quoted" \& 50\% & 3 & 0.50 \\
         & 0 &  \\
        \bottomrule
        \end{tabular}
        "#);
    }

    #[test]
    fn json_keeps_types_and_nulls() {
        let (schema, batches) = sample();
        let out = render_string(&schema, &batches, Format::Json, &RenderOptions::default());
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(v[0]["n"], 12);
        assert_eq!(v[0]["mean_speed"], 1.23456789);
        assert!(v[2]["label"].is_null());
        let lines = render_string(&schema, &batches, Format::Ndjson, &RenderOptions::default());
        assert_eq!(lines.lines().count(), 3);
    }

    #[test]
    fn format_names_round_trip() {
        for name in Format::NAMES {
            assert_eq!(name.parse::<Format>().unwrap().to_string(), *name);
        }
        assert_eq!(Format::from_extension("t.tex"), Some(Format::Latex));
        assert!("xlsx".parse::<Format>().is_err());
    }
}
