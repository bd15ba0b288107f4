//! SQL over a run's tables with DataFusion, and the formats results are printed or exported in.
//!
//! **Owns:** registering every table of a run folder in a DataFusion `SessionContext` ([`RunQuery`]),
//! running SQL under the session's limits and collecting results, listing tables with row counts and
//! schemas, and rendering results ([`format`](mod@format)). **Does not:** write tables (stages do that
//! through `store/`), nor let SQL write anything: every statement is checked before it runs
//! ([`read_only`]) and `COPY`, `INSERT`, `CREATE`, `SET` and the like are refused with
//! [`QueryError::NotReadOnly`]. Limits ([`settings`]): a memory pool, an optional time limit, and one
//! partition by default so that results are reproducible to the last bit.
//!
//! The trace tables (`scenes`, `traces`, `timesteps`, `frames`, `events`) are always registered with
//! their documented schemas, empty if the run has none yet, and expose the `env` partition as a column.
//! Every other table of the run (tables written by SQL stages and later stage kinds) is registered
//! under its folder name with the schema its files carry. A table's files are the **published** ones,
//! from the manifest (`store::RunDir::tables`, sizes checked), never a listing of its folder
//! (`published`): a query sees whole stages only, and never a foreign file.
//!
//! A session whose settings name a Ballista engine ([`Engine`], `ballista://HOST:PORT` or
//! `ballista:standalone`; cargo feature `ballista`) registers the same tables on the cluster from the
//! same published files, plans and checks each statement here, and runs it there (`query::ballista`).
//!
//! ```no_run
//! use annotrace::query::RunQuery;
//! use annotrace::store::RunDir;
//! let q = RunQuery::open(&RunDir::new("runs/quickstart")).unwrap();
//! let result = q.sql("SELECT env, count(*) AS n FROM traces GROUP BY env ORDER BY env").unwrap();
//! println!("{} rows", result.num_rows());
//! ```

#[cfg(feature = "ballista")]
mod ballista;
pub mod engine;
pub mod format;
mod published;
pub mod read_only;
pub mod settings;

use std::num::NonZeroUsize;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use arrow::array::{AsArray, RecordBatch};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use datafusion::datasource::MemTable;
use datafusion::datasource::file_format::parquet::ParquetFormat;
use datafusion::datasource::listing::ListingOptions;
use datafusion::error::DataFusionError;
use datafusion::execution::cache::cache_manager::CacheManagerConfig;
use datafusion::execution::memory_pool::{FairSpillPool, TrackConsumersPool};
use datafusion::execution::runtime_env::RuntimeEnvBuilder;
use datafusion::prelude::{SessionConfig, SessionContext};

use crate::store::{RunDir, StoreError};
use crate::trace::schema::{ENV_COLUMN, TRACE_TABLES, table_schema};

pub use engine::{BadEngine, Engine};
pub use format::{Format, RenderOptions, UnknownFormat, render, render_string};
pub use settings::{BadSetting, MemoryLimit, QuerySettings};

/// A failure to register or query a run's tables.
///
/// [`is_users`](QueryError::is_users) tells the query's own faults (refused, too big, too slow, bad
/// SQL) from the machine's (files, runtime).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum QueryError {
    /// DataFusion rejected or failed the query; the message is DataFusion's own.
    #[error("{0}")]
    DataFusion(DataFusionError),
    /// The statement would write files or change the session; queries only read the run.
    #[error(
        "refused: {statement} — SQL over a run is read-only (no COPY, INSERT, CREATE, DROP, SET…); \
         write a result with `annotrace query … --out FILE` or an `export` stage"
    )]
    NotReadOnly {
        /// What was refused, in SQL words (`COPY … TO '/tmp/f.csv'`, `INSERT INTO traces`).
        statement: String,
    },
    /// The query needed more memory than the session's pool holds.
    #[error(
        "the query needs more memory than the SQL memory limit of {limit} (raise it with --memory-limit, \
         the `memory_limit` stage parameter or ANNOTRACE_SQL_MEMORY_LIMIT): {detail}"
    )]
    MemoryLimit {
        /// The limit.
        limit: MemoryLimit,
        /// DataFusion's account of who asked for what.
        detail: String,
    },
    /// The query did not finish within its time limit.
    #[error(
        "the query did not finish within its time limit of {} s (--timeout, the `timeout_s` stage \
         parameter or ANNOTRACE_SQL_TIMEOUT)", limit.as_secs_f64()
    )]
    Timeout {
        /// The limit.
        limit: Duration,
    },
    /// A result file would land inside the run's folders (only `exports/` takes files).
    #[error(
        "{}: refused to write a query result inside run folder {} (a file there could be read as part of a \
         table); write it under {}/exports/ or outside the run",
        path.display(), run.display(), run.display()
    )]
    OutputInRun {
        /// The file asked for.
        path: PathBuf,
        /// The run folder.
        run: PathBuf,
    },
    /// A limit given in a variable or parameter does not parse.
    #[error(transparent)]
    BadSetting(#[from] BadSetting),
    /// The run's files could not be listed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The async runtime could not start.
    #[error("could not start the query runtime: {0}")]
    Runtime(std::io::Error),
    /// The engine named cannot be used by this build (a Ballista engine without the `ballista` feature).
    #[error(transparent)]
    BadEngine(#[from] BadEngine),
    /// The SQL engine did not answer (a Ballista scheduler down or unreachable).
    #[error("the SQL engine {engine} is unavailable: {detail}")]
    EngineUnavailable {
        /// The engine, as given.
        engine: String,
        /// What went wrong, with its causes.
        detail: String,
    },
}

impl From<DataFusionError> for QueryError {
    // Not a `#[source]`: DataFusion's message already carries its causes, and printing the chain would
    // repeat them.
    fn from(e: DataFusionError) -> Self {
        QueryError::DataFusion(e)
    }
}

impl QueryError {
    /// Whether the query itself is at fault (bad or refused SQL, over its memory or time limit, a
    /// result path inside the run, a bad limit) rather than the run's files or the machine.
    pub fn is_users(&self) -> bool {
        match self {
            QueryError::DataFusion(e) => !matches!(
                e.find_root(),
                DataFusionError::IoError(_)
                    | DataFusionError::ObjectStore(_)
                    | DataFusionError::ParquetError(_)
                    | DataFusionError::Internal(_)
            ),
            QueryError::Store(_)
            | QueryError::Runtime(_)
            | QueryError::EngineUnavailable { .. } => false,
            QueryError::NotReadOnly { .. }
            | QueryError::BadEngine(_)
            | QueryError::MemoryLimit { .. }
            | QueryError::Timeout { .. }
            | QueryError::OutputInRun { .. }
            | QueryError::BadSetting(_) => true,
        }
    }

    /// DataFusion's error, as [`QueryError::MemoryLimit`] when the memory pool ran out.
    fn from_execution(e: DataFusionError, limit: MemoryLimit) -> Self {
        match e.find_root() {
            DataFusionError::ResourcesExhausted(detail) => QueryError::MemoryLimit {
                limit,
                detail: detail.clone(),
            },
            // The spill cap is an I/O error in DataFusion 55 (disk_manager.rs); only its text tells.
            _ if e
                .to_string()
                .contains("during the spilling process has exceeded") =>
            {
                QueryError::MemoryLimit {
                    limit,
                    detail: format!(
                        "its spill files outgrew {} in the temporary folder ({} × the memory limit)",
                        settings::human_bytes(limit.bytes().saturating_mul(settings::SPILL_FACTOR)),
                        settings::SPILL_FACTOR
                    ),
                }
            }
            _ => QueryError::DataFusion(e),
        }
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

/// A DataFusion session with every table of one run registered, under the limits of its
/// [`QuerySettings`].
pub struct RunQuery {
    ctx: SessionContext,
    /// The same tables on a Ballista cluster, when the settings name one: statements are planned and
    /// checked by `ctx`, then run there.
    #[cfg(feature = "ballista")]
    remote: Option<ballista::Remote>,
    runtime: tokio::runtime::Runtime,
    tables: Vec<(String, usize)>,
    settings: QuerySettings,
}

fn with_env(schema: &Schema) -> SchemaRef {
    let mut fields: Vec<Field> = schema.fields().iter().map(|f| f.as_ref().clone()).collect();
    fields.push(Field::new(ENV_COLUMN, DataType::Utf8, false));
    Arc::new(Schema::new(fields))
}

impl RunQuery {
    /// Registers the tables of `run` with the default [`QuerySettings`].
    pub fn open(run: &RunDir) -> Result<Self, QueryError> {
        Self::open_with(run, QuerySettings::default())
    }

    /// Registers the tables of `run`; every statement runs under `settings`.
    pub fn open_with(run: &RunDir, settings: QuerySettings) -> Result<Self, QueryError> {
        settings.engine.check_built()?;
        let partitions = settings.partitions.max(1);
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(
                std::thread::available_parallelism()
                    .map_or(2, |n| n.get())
                    .min(partitions.max(2)),
            )
            .thread_name("annotrace-query")
            .enable_all()
            .build()
            .map_err(QueryError::Runtime)?;
        let config = SessionConfig::new()
            .with_information_schema(true)
            .with_default_catalog_and_schema("annotrace", "run")
            .with_target_partitions(partitions);
        let limit = settings.memory_limit.bytes();
        let pool = TrackConsumersPool::new(
            FairSpillPool::new(usize::try_from(limit).unwrap_or(usize::MAX)),
            NonZeroUsize::new(3).expect("non-zero"),
        );
        let found = run.tables()?;
        let folders: Vec<_> = found
            .iter()
            .map(|t| (run.partition_dir(&t.name, None), t))
            .collect();
        let listing = published::PublishedFiles::new(&folders)?;
        let env = RuntimeEnvBuilder::new()
            .with_cache_manager(
                CacheManagerConfig::default()
                    .with_list_files_cache(Some(published::shared(listing))),
            )
            .with_memory_pool(Arc::new(pool))
            .with_max_temp_directory_size(limit.saturating_mul(settings::SPILL_FACTOR))
            .build_arc()?;
        let ctx = SessionContext::new_with_config_rt(config, env);
        let mut tables = Vec::new();
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
        #[cfg(feature = "ballista")]
        let remote = if settings.engine.is_local() {
            None
        } else {
            let mut remote_tables = Vec::with_capacity(tables.len());
            for (name, _) in &tables {
                let schema = runtime
                    .block_on(ctx.table_provider(name.as_str()))?
                    .schema();
                let dir = found.iter().find(|t| &t.name == name).cloned();
                remote_tables.push((name.clone(), schema, dir));
            }
            // The cluster's session gets a memory pool of its own (used by the standalone executor)
            // and no published-files cache: its tables list their files explicitly.
            let remote_env = RuntimeEnvBuilder::new()
                .with_memory_pool(Arc::new(FairSpillPool::new(
                    usize::try_from(limit).unwrap_or(usize::MAX),
                )))
                .with_max_temp_directory_size(limit.saturating_mul(settings::SPILL_FACTOR))
                .build_arc()?;
            Some(runtime.block_on(ballista::Remote::open(
                &settings.engine,
                partitions,
                remote_env,
                remote_tables,
            ))?)
        };
        Ok(RunQuery {
            ctx,
            #[cfg(feature = "ballista")]
            remote,
            runtime,
            tables,
            settings,
        })
    }

    /// The settings this session runs under.
    pub fn settings(&self) -> &QuerySettings {
        &self.settings
    }

    /// Runs one SQL statement and collects its result. The statement must only read
    /// ([`QueryError::NotReadOnly`] otherwise, checked before anything runs) and finish within the
    /// session's memory pool and time limit.
    pub fn sql(&self, sql: &str) -> Result<QueryResult, QueryError> {
        let limit = self.settings.memory_limit;
        let run = async {
            let plan = self.ctx.state().create_logical_plan(sql).await?;
            read_only::check_plan(&plan)?;
            #[cfg(feature = "ballista")]
            if let Some(remote) = &self.remote {
                let schema: SchemaRef = Arc::new(plan.schema().as_arrow().clone());
                let batches = remote
                    .collect(sql, &schema)
                    .await
                    .map_err(|e| QueryError::from_execution(e, limit))?;
                return Ok(QueryResult { schema, batches });
            }
            let df = self.ctx.execute_logical_plan(plan).await?;
            let schema: SchemaRef = Arc::new(df.schema().as_arrow().clone());
            let batches = df
                .collect()
                .await
                .map_err(|e| QueryError::from_execution(e, limit))?;
            Ok(QueryResult { schema, batches })
        };
        self.runtime.block_on(async {
            match self.settings.timeout {
                // DataFusion's operators yield to the runtime between batches, so the timer fires
                // even in a query that never waits for input; dropping the future cancels the query.
                Some(t) => tokio::time::timeout(t, run)
                    .await
                    .unwrap_or(Err(QueryError::Timeout { limit: t })),
                None => run.await,
            }
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
    let url = published::folder_url(&dir).map_err(|e| StoreError::Io {
        path: dir.clone(),
        source: e,
    })?;
    let mut options =
        ListingOptions::new(Arc::new(ParquetFormat::default())).with_file_extension(".parquet");
    if partitioned {
        options = options.with_table_partition_cols(vec![(ENV_COLUMN.to_string(), DataType::Utf8)]);
    }
    ctx.register_listing_table(name, url, options, schema, None)
        .await?;
    Ok(())
}
