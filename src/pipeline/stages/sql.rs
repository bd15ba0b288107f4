//! `sql`: runs a query over the run's tables and stores the result as a table of the run.
//!
//! The query is a file under the project's `sql/` folder (`query = "trace_summary.sql"`) or inline
//! (`sql = "SELECT …"`). It sees every table finished so far; its result is written to
//! `<output>/<stage>.result.parquet` and is queryable as `<output>` by later stages and by
//! `annotrace query`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::{SqlSource, valid_table_name};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::query::RunQuery;
use crate::trace::schema::TRACE_TABLES;

/// The `sql` stage kind.
pub static KIND: StageKind = StageKind {
    name: "sql",
    summary: "run an SQL query over the run's tables and store the result as a table",
    doc: "Runs one SQL statement (DataFusion dialect) over every table of the run and stores the result as \
          a table named `output` (default: the stage id with `-` replaced by `_`). The SQL is a file under \
          the project's sql/ folder (`query`) or inline (`sql`).",
    writes: "the table named by `output`",
    params: ParamsOf::of::<SqlParams>(),
    build,
};

/// The parameters of an `sql` stage.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default)]
pub struct SqlParams {
    /// SQL file under sql/ (or a path relative to the project folder).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub query: Option<String>,
    /// Inline SQL, instead of `query`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sql: Option<String>,
    /// Name of the result table (default: the stage id).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub output: Option<String>,
}

/// The result table's name for a stage.
pub(crate) fn output_name(def: &StageDef) -> String {
    def.params
        .get("output")
        .and_then(Value::as_str)
        .map(str::to_owned)
        .unwrap_or_else(|| def.id.replace('-', "_"))
}

fn build(def: &StageDef, spec: &PipelineSpec) -> Result<Box<dyn Stage>, BuildError> {
    let p: SqlParams = def.params()?;
    let source = SqlSource::new(
        p.query.as_deref(),
        p.sql.as_deref(),
        &spec.project_dir,
        false,
    )?
    .expect("required above");
    let output = output_name(def);
    if !valid_table_name(&output) {
        return Err(BuildError::param(
            "output",
            format!("table name {output:?} must use lower-case letters, digits and `_`"),
        ));
    }
    if TRACE_TABLES.contains(&output.as_str()) || output == "exports" {
        return Err(BuildError::param(
            "output",
            format!("{output:?} is a reserved table name"),
        ));
    }
    Ok(Box::new(SqlStage { source, output }))
}

/// The `sql` stage.
#[derive(Debug)]
pub struct SqlStage {
    source: SqlSource,
    output: String,
}

impl Stage for SqlStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({"sql": self.source.text()?, "output": self.output}))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let sql = self.source.text()?;
        let query = RunQuery::open(ctx.run())?;
        let result = query.sql(&sql)?;
        let mut sink = ctx
            .staging()
            .sink(&self.output, None, "result", result.schema.clone())?;
        for batch in &result.batches {
            sink.write(batch)?;
        }
        let (_, rows) = sink.commit()?;
        Ok(StageOutput {
            rows: [(self.output.clone(), rows as u64)].into(),
            files: Vec::new(),
            summary: json!({"table": self.output, "rows": rows, "columns": result.schema.fields().iter().map(|f| f.name().clone()).collect::<Vec<_>>()}),
            line: format!("{rows} rows -> table {}", self.output),
        })
    }
}
