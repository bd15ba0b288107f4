//! `export`: writes a table, or the result of a query, as a file under the run's `exports/` folder.
//!
//! Formats: CSV, Markdown, LaTeX (booktabs), JSON, JSON Lines and Parquet. The file is written
//! atomically; its name defaults to the table (or stage) name with the format's extension. The file
//! is always a plain name under the run's `exports/`; the query only reads (`COPY`, `INSERT`… are
//! refused), runs on one partition so that the same run gives the same bytes, and takes the same
//! `memory_limit` and `timeout_s` as `sql`.

use std::io::Write;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::SqlSource;
use super::sql::StageLimits;
use crate::pipeline::params::ParamsOf;
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
    params: ParamsOf::of::<ExportParams>(),
    build,
};

/// The file formats an `export` stage writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ExportFormat {
    /// RFC 4180 CSV with a header row.
    #[default]
    Csv,
    /// A GitHub-flavoured Markdown table.
    Markdown,
    /// A booktabs LaTeX tabular.
    Latex,
    /// A JSON array of row objects.
    Json,
    /// One JSON object per line.
    Ndjson,
    /// Apache Parquet.
    Parquet,
}

impl From<ExportFormat> for Format {
    fn from(f: ExportFormat) -> Format {
        match f {
            ExportFormat::Csv => Format::Csv,
            ExportFormat::Markdown => Format::Markdown,
            ExportFormat::Latex => Format::Latex,
            ExportFormat::Json => Format::Json,
            ExportFormat::Ndjson => Format::Ndjson,
            ExportFormat::Parquet => Format::Parquet,
        }
    }
}

/// The parameters of an `export` stage.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct ExportParams {
    /// Table to export.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub table: Option<String>,
    /// SQL file under sql/ whose result to export, instead of `table`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub query: Option<String>,
    /// Inline SQL whose result to export, instead of `table`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sql: Option<String>,
    /// File format.
    pub format: ExportFormat,
    /// File name under exports/ (default: `<table or stage id>.<extension>`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// Decimals for floats in Markdown and LaTeX.
    pub precision: u32,
    /// Caption line written above the table (Markdown, LaTeX).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub title: Option<String>,
    /// Memory the query may use (e.g. "512MiB", "8G", "25%"; default: ANNOTRACE_SQL_MEMORY_LIMIT, else
    /// 4 GiB or half the machine's memory, whichever is smaller).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub memory_limit: Option<String>,
    /// Fail the stage if the query runs longer than this many seconds (default:
    /// ANNOTRACE_SQL_TIMEOUT, else no limit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub timeout_s: Option<f64>,
}

impl Default for ExportParams {
    fn default() -> Self {
        ExportParams {
            table: None,
            query: None,
            sql: None,
            format: ExportFormat::Csv,
            file: None,
            precision: 4,
            title: None,
            memory_limit: None,
            timeout_s: None,
        }
    }
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: ExportParams = def.params()?;
    let sql = SqlSource::new(
        p.query.as_deref(),
        p.sql.as_deref(),
        &spec.project_dir,
        true,
    )?;
    let source = match (p.table, sql) {
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
    let format = Format::from(p.format);
    let stem = match &source {
        Source::Table(t) => t.clone(),
        Source::Sql(_) => def.id.clone(),
    };
    let file = p
        .file
        .unwrap_or_else(|| format!("{stem}.{}", format.extension()));
    if file.is_empty() || file.contains(['/', '\\']) || file.starts_with('.') {
        return Err(BuildError::param(
            "file",
            format!("{file:?} must be a plain file name (it is written under exports/)"),
        ));
    }
    let precision = p.precision as usize;
    let title = p.title;
    let limits = StageLimits::from_params(p.memory_limit.as_deref(), p.timeout_s)?;
    Ok(Box::new(ExportStage {
        source,
        format,
        file,
        limits,
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
    limits: StageLimits,
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
        let query = RunQuery::open_with(ctx.run(), self.limits.settings()?)?;
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
