//! `sql`: runs a query over the run's tables and stores the result as a table of the run.
//!
//! The query is a file under the project's `sql/` folder (`query = "trace_summary.sql"`) or inline
//! (`sql = "SELECT …"`). It sees every table finished so far; its result is written to
//! `<output>/<stage>.result.parquet` and is queryable as `<output>` by later stages and by
//! `annotrace query`.
//!
//! The query only reads (`COPY`, `INSERT`, `CREATE`… are refused) and runs on one partition, so the same
//! run gives the same table bytes; `memory_limit` and `timeout_s` bound it (`StageLimits`, shared with
//! `export`). `engine` runs it on a Ballista cluster instead of in-process (feature `ballista`; without
//! the parameter, `ANNOTRACE_SQL_ENGINE` decides for the whole run, for `export` stages too).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::{SqlSource, valid_table_name};
use crate::pipeline::params::ParamsOf;
use crate::pipeline::registry::{BuildError, StageKind};
use crate::pipeline::spec::{PipelineSpec, StageDef};
use crate::pipeline::stage::{Stage, StageContext, StageError, StageOutput};
use crate::query::settings::timeout_from_secs;
use crate::query::{BadEngine, Engine, MemoryLimit, QueryError, QuerySettings, RunQuery};
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
    /// Memory the query may use (e.g. "512MiB", "8G", "25%"; default: ANNOTRACE_SQL_MEMORY_LIMIT, else
    /// 4 GiB or half the machine's memory, whichever is smaller).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub memory_limit: Option<String>,
    /// Fail the stage if the query runs longer than this many seconds (default:
    /// ANNOTRACE_SQL_TIMEOUT, else no limit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub timeout_s: Option<f64>,
    /// Where the query runs: "local", "ballista://HOST:PORT" (a Ballista cluster whose executors see the
    /// run folder at the same path) or "ballista:standalone" (default: ANNOTRACE_SQL_ENGINE, else local).
    /// Ballista needs a build with `--features ballista`; the result table is the same, though rows of a
    /// query without ORDER BY may come in another order.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub engine: Option<String>,
}

/// The limits an `sql` or `export` stage's parameters set for its query; what they leave out comes from
/// the `ANNOTRACE_SQL_*` variables when the stage runs, then the defaults.
#[derive(Clone, Debug, Default)]
pub(crate) struct StageLimits {
    memory_limit: Option<MemoryLimit>,
    timeout: Option<std::time::Duration>,
    engine: Option<Engine>,
}

impl StageLimits {
    /// From the `memory_limit` and `timeout_s` parameters.
    pub(crate) fn from_params(
        memory_limit: Option<&str>,
        timeout_s: Option<f64>,
    ) -> Result<Self, BuildError> {
        Ok(StageLimits {
            memory_limit: memory_limit.map(str::parse).transpose().map_err(
                |e: crate::query::settings::BadMemoryLimit| {
                    BuildError::param("memory_limit", e.to_string())
                },
            )?,
            timeout: timeout_s
                .map(timeout_from_secs)
                .transpose()
                .map_err(|e| BuildError::param("timeout_s", e))?,
            engine: None,
        })
    }

    /// The same limits, with the query run on `engine` (the `engine` parameter: parsed, and refused
    /// when this build cannot reach it).
    pub(crate) fn with_engine(mut self, engine: Option<&str>) -> Result<Self, BuildError> {
        if let Some(e) = engine {
            let engine: Engine = e
                .parse()
                .map_err(|e: BadEngine| BuildError::param("engine", e.to_string()))?;
            engine
                .check_built()
                .map_err(|e| BuildError::param("engine", e.to_string()))?;
            self.engine = Some(engine);
        }
        Ok(self)
    }

    /// The settings to open the run with: these limits over the variables, on one partition.
    pub(crate) fn settings(&self) -> Result<QuerySettings, QueryError> {
        let mut settings =
            QuerySettings::resolve(self.memory_limit, self.timeout, &|k| std::env::var(k).ok())?;
        if let Some(engine) = &self.engine {
            settings.engine = engine.clone();
        }
        Ok(settings)
    }
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
    let limits = StageLimits::from_params(p.memory_limit.as_deref(), p.timeout_s)?
        .with_engine(p.engine.as_deref())?;
    Ok(Box::new(SqlStage {
        source,
        output,
        limits,
    }))
}

/// The `sql` stage.
#[derive(Debug)]
pub struct SqlStage {
    source: SqlSource,
    output: String,
    limits: StageLimits,
}

impl Stage for SqlStage {
    fn fingerprint_extra(&self) -> Result<Value, StageError> {
        Ok(json!({"sql": self.source.text()?, "output": self.output}))
    }

    fn run(&self, ctx: &StageContext<'_>) -> Result<StageOutput, StageError> {
        let sql = self.source.text()?;
        let query = RunQuery::open_with(ctx.run(), self.limits.settings()?)?;
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
