//! `export`: writes a table, or the result of a query, as a file under the run's `exports/` folder.
//!
//! Formats: CSV, Markdown, LaTeX (booktabs), JSON, JSON Lines and Parquet. The file is written
//! atomically; its name defaults to the table (or stage) name with the format's extension.

use std::io::Write;

use serde_json::{Value, json};

use super::SqlSource;
use crate::pipeline::params::{ParamSpec, ParamType};
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::query::{Format, RenderOptions, RunQuery, render};
use crate::store::{AtomicFile, ParquetSink, StoreError};

/// The `export` stage kind.
pub static KIND: StageKind = StageKind {
    name: "export",
    summary: "write a table or query result to exports/ as CSV, Markdown, LaTeX, JSON or Parquet",
    doc: "Writes a table of the run (`table`) or the result of a query (`query` file or inline `sql`) to \
          exports/<file>. LaTeX output is a booktabs tabular ready for \\input; floats in the text formats \
          for people (Markdown, LaTeX) are printed with `precision` decimals, CSV and JSON keep them exact.",
    writes: "exports/<file>",
    params: &[
        ParamSpec::maybe("table", ParamType::Str, "table to export"),
        ParamSpec::maybe(
            "query",
            ParamType::Str,
            "SQL file under sql/ whose result to export, instead of `table`",
        ),
        ParamSpec::maybe(
            "sql",
            ParamType::Str,
            "inline SQL whose result to export, instead of `table`",
        ),
        ParamSpec::optional(
            "format",
            ParamType::Choice(&["csv", "markdown", "latex", "json", "ndjson", "parquet"]),
            "\"csv\"",
            "file format",
        ),
        ParamSpec::maybe(
            "file",
            ParamType::Str,
            "file name under exports/ (default: <table or stage id>.<extension>)",
        ),
        ParamSpec::optional(
            "precision",
            ParamType::Count,
            "4",
            "decimals for floats in Markdown and LaTeX",
        ),
        ParamSpec::maybe(
            "title",
            ParamType::Str,
            "caption line written above the table (Markdown, LaTeX)",
        ),
    ],
    build,
};

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let sql = SqlSource::from_params(&def.params, &spec.project_dir, true)?;
    let table = def
        .params
        .get("table")
        .and_then(Value::as_str)
        .map(str::to_owned);
    let source = match (table, sql) {
        (Some(_), Some(_)) => {
            return Err(BuildError::param(
                "table",
                "give `table` or a query (`query`/`sql`), not both",
            ));
        }
        (Some(t), None) => Source::Table(t),
        (None, Some(q)) => Source::Sql(q),
        (None, None) => {
            return Err(BuildError {
                param: None,
                message: "needs `table`, `query` or `sql`".into(),
            });
        }
    };
    let format: Format = def.params["format"]
        .as_str()
        .unwrap_or("csv")
        .parse()
        .map_err(|e: crate::query::UnknownFormat| BuildError::param("format", e.to_string()))?;
    let stem = match &source {
        Source::Table(t) => t.clone(),
        Source::Sql(_) => def.id.clone(),
    };
    let file = def
        .params
        .get("file")
        .and_then(Value::as_str)
        .map(str::to_owned)
        .unwrap_or_else(|| format!("{stem}.{}", format.extension()));
    if file.is_empty() || file.contains(['/', '\\']) || file.starts_with('.') {
        return Err(BuildError::param(
            "file",
            format!("{file:?} must be a plain file name (it is written under exports/)"),
        ));
    }
    let precision = def.params["precision"].as_u64().unwrap_or(4) as usize;
    let title = def
        .params
        .get("title")
        .and_then(Value::as_str)
        .map(str::to_owned);
    Ok(Box::new(ExportStage {
        source,
        format,
        file,
        opts: RenderOptions {
            precision: Some(precision),
            title,
        },
    }))
}

#[derive(Debug)]
enum Source {
    Table(String),
    Sql(SqlSource),
}

/// The `export` stage.
#[derive(Debug)]
pub struct ExportStage {
    source: Source,
    format: Format,
    file: String,
    opts: RenderOptions,
}

impl Stage for ExportStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(match &self.source {
            Source::Table(t) => json!({"table": t}),
            Source::Sql(q) => json!({"sql": q.text()?}),
        })
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let query = RunQuery::open(ctx.run())?;
        let sql = match &self.source {
            Source::Table(t) => {
                if !query.has_table(t) {
                    return Err(StageError::Input(format!(
                        "no table {t:?} in run {}",
                        ctx.run().root().display()
                    )));
                }
                format!("SELECT * FROM \"{t}\"")
            }
            Source::Sql(q) => q.text()?,
        };
        let result = query.sql(&sql)?;
        let path = ctx.run().exports_dir().join(&self.file);
        if self.format == Format::Parquet {
            let mut sink = ParquetSink::create(&path, result.schema.clone())?;
            for b in &result.batches {
                sink.write(b)?;
            }
            sink.commit()?;
        } else {
            let io = |e| StoreError::Io {
                path: path.clone(),
                source: e,
            };
            let mut file = AtomicFile::create(&path).map_err(io)?;
            let mut buf = std::io::BufWriter::new(&mut file);
            render(
                &mut buf,
                &result.schema,
                &result.batches,
                self.format,
                &self.opts,
            )
            .map_err(io)?;
            buf.flush().map_err(io)?;
            drop(buf);
            file.commit().map_err(io)?;
        }
        let rows = result.num_rows();
        Ok(StageOutput {
            rows: Default::default(),
            files: vec![path.clone()],
            summary: json!({"file": format!("exports/{}", self.file), "format": self.format.to_string(), "rows": rows}),
            line: format!("{rows} rows -> exports/{}", self.file),
        })
    }
}
