//! SQL over a run's tables with DataFusion, and the formats results are printed or exported in.
//!
//! **Owns:** registering every table of a run folder in a DataFusion `SessionContext` ([`RunQuery`]),
//! running SQL and collecting results, listing tables with row counts and schemas, and rendering results
//! ([`format`](mod@format)). **Does not:** write tables (stages do that through `store/`).
//!
//! The trace tables (`scenes`, `traces`, `timesteps`, `frames`, `events`) are always registered with
//! their documented schemas, empty if the run has none yet, and expose the `env` partition as a column.
//! Every other folder of Parquet files in the run (tables written by SQL stages and later stage kinds)
//! is registered under its folder name with the schema its files carry.
//!
//! ```no_run
//! use annotrace::query::RunQuery;
//! use annotrace::store::RunDir;
//! let q = RunQuery::open(&RunDir::new("runs/quickstart")).unwrap();
//! let result = q.sql("SELECT env, count(*) AS n FROM traces GROUP BY env ORDER BY env").unwrap();
//! println!("{} rows", result.num_rows());
//! ```

pub mod format;

use std::sync::Arc;

use arrow::array::{AsArray, RecordBatch};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use datafusion::datasource::MemTable;
use datafusion::datasource::file_format::parquet::ParquetFormat;
use datafusion::datasource::listing::ListingOptions;
use datafusion::error::DataFusionError;
use datafusion::prelude::{SessionConfig, SessionContext};

use crate::store::{RunDir, StoreError};
use crate::trace::schema::{ENV_COLUMN, TRACE_TABLES, table_schema};

pub use format::{Format, RenderOptions, UnknownFormat, render, render_string};

/// A failure to register or query a run's tables.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum QueryError {
    /// DataFusion rejected or failed the query; the message is DataFusion's own.
    #[error("{0}")]
    DataFusion(DataFusionError),
    /// The run's files could not be listed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The async runtime could not start.
    #[error("could not start the query runtime: {0}")]
    Runtime(std::io::Error),
}

impl From<DataFusionError> for QueryError {
    // Not a `#[source]`: DataFusion's message already carries its causes, and printing the chain would
    // repeat them.
    fn from(e: DataFusionError) -> Self {
        QueryError::DataFusion(e)
    }
}

/// The result of a query: its schema and batches.
#[derive(Clone, Debug)]
pub struct QueryResult {
    /// Output schema.
    pub schema: SchemaRef,
    /// Output rows.
    pub batches: Vec<RecordBatch>,
}

impl QueryResult {
    /// Total rows.
    pub fn num_rows(&self) -> usize {
        self.batches.iter().map(RecordBatch::num_rows).sum()
    }
}

/// A table's name, row count and schema, as `annotrace tables` lists them.
#[derive(Clone, Debug)]
pub struct TableSummary {
    /// Table name.
    pub name: String,
    /// Number of rows.
    pub rows: u64,
    /// Number of Parquet files.
    pub files: usize,
    /// Schema (with the `env` column for partitioned tables).
    pub schema: SchemaRef,
}

/// A DataFusion session with every table of one run registered.
pub struct RunQuery {
    ctx: SessionContext,
    runtime: tokio::runtime::Runtime,
    tables: Vec<(String, usize)>,
}

fn with_env(schema: &Schema) -> SchemaRef {
    let mut fields: Vec<Field> = schema.fields().iter().map(|f| f.as_ref().clone()).collect();
    fields.push(Field::new(ENV_COLUMN, DataType::Utf8, false));
    Arc::new(Schema::new(fields))
}

impl RunQuery {
    /// Registers the tables of `run`.
    pub fn open(run: &RunDir) -> Result<Self, QueryError> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(std::thread::available_parallelism().map_or(2, |n| n.get()))
            .thread_name("annotrace-query")
            .enable_all()
            .build()
            .map_err(QueryError::Runtime)?;
        let config = SessionConfig::new()
            .with_information_schema(true)
            .with_default_catalog_and_schema("annotrace", "run");
        let ctx = SessionContext::new_with_config(config);
        let mut tables = Vec::new();
        let found = run.tables()?;
        for name in TRACE_TABLES {
            let dir = found.iter().find(|t| t.name == name);
            let schema = table_schema(name).expect("trace tables have schemas");
            match dir {
                Some(t) if !t.files.is_empty() => {
                    runtime.block_on(register_dir(&ctx, run, name, t.partitioned, Some(schema)))?;
                    tables.push((name.to_string(), t.files.len()));
                }
                _ => {
                    let empty = MemTable::try_new(with_env(&schema), vec![vec![]])?;
                    ctx.register_table(name, Arc::new(empty))?;
                    tables.push((name.to_string(), 0));
                }
            }
        }
        for t in found
            .iter()
            .filter(|t| !TRACE_TABLES.contains(&t.name.as_str()) && !t.files.is_empty())
        {
            runtime.block_on(register_dir(&ctx, run, &t.name, t.partitioned, None))?;
            tables.push((t.name.clone(), t.files.len()));
        }
        tables.sort();
        Ok(RunQuery {
            ctx,
            runtime,
            tables,
        })
    }

    /// Runs one SQL statement and collects its result.
    pub fn sql(&self, sql: &str) -> Result<QueryResult, QueryError> {
        self.runtime.block_on(async {
            let df = self.ctx.sql(sql).await?;
            let schema: SchemaRef = Arc::new(df.schema().as_arrow().clone());
            let batches = df.collect().await?;
            Ok(QueryResult { schema, batches })
        })
    }

    /// The registered tables with row counts and schemas, sorted by name.
    pub fn tables(&self) -> Result<Vec<TableSummary>, QueryError> {
        let mut out = Vec::new();
        for (name, files) in &self.tables {
            let provider = self
                .runtime
                .block_on(self.ctx.table_provider(name.as_str()))?;
            let counted = self.sql(&format!("SELECT count(*) FROM \"{name}\""))?;
            let rows = counted
                .batches
                .first()
                .map(|b| {
                    b.column(0)
                        .as_primitive::<arrow::datatypes::Int64Type>()
                        .value(0)
                })
                .unwrap_or(0);
            out.push(TableSummary {
                name: name.clone(),
                rows: rows as u64,
                files: *files,
                schema: provider.schema(),
            });
        }
        Ok(out)
    }

    /// Whether a table of this name is registered.
    pub fn has_table(&self, name: &str) -> bool {
        self.tables.iter().any(|(n, _)| n == name)
    }
}

async fn register_dir(
    ctx: &SessionContext,
    run: &RunDir,
    name: &str,
    partitioned: bool,
    schema: Option<SchemaRef>,
) -> Result<(), QueryError> {
    let dir = run.partition_dir(name, None);
    let abs = std::path::absolute(&dir).map_err(|e| StoreError::Io {
        path: dir.clone(),
        source: e,
    })?;
    let mut url = abs.to_string_lossy().into_owned();
    if !url.ends_with('/') {
        url.push('/');
    }
    let mut options =
        ListingOptions::new(Arc::new(ParquetFormat::default())).with_file_extension(".parquet");
    if partitioned {
        options = options.with_table_partition_cols(vec![(ENV_COLUMN.to_string(), DataType::Utf8)]);
    }
    ctx.register_listing_table(name, url, options, schema, None)
        .await?;
    Ok(())
}
