//! A run's tables on an Apache DataFusion Ballista cluster (cargo feature `ballista`).
//!
//! **Owns:** the Ballista session of a [`RunQuery`](super::RunQuery) whose engine is
//! `ballista://HOST:PORT` or `ballista:standalone` ([`Remote`]): checking that the scheduler answers,
//! registering every table of the run on it from the run's **published** files, and collecting a
//! query's result in the types the local engine gives it. **Does not:** plan or check SQL (the local
//! session does both first, so the same statements are refused the same way), choose the engine
//! ([`Engine`]), or start a cluster other than the in-process standalone one.
//!
//! Ballista ships the logical plan to its scheduler, which plans and lists files itself, so the local
//! list-files cache (`published`) does not reach it. Tables are therefore registered with an explicit
//! list of file URLs, one per published file: the scheduler reads those files only, never a folder
//! listing, so a cluster query, too, sees whole stages and no foreign file. A table partitioned by
//! `env=` folders is one listing table per environment with its `env` value as a constant column, under
//! a view that unions them (the plan shipped has the view inlined). A trace table the run does not
//! have yet is a listing table of no files with its documented schema.
//!
//! The executors open the files at the paths this process sees (`file:///…`): the run folder must be on
//! a file system the executors share at the same path (NFS, Lustre, …), or the cluster standalone.
//! Ballista reads strings as `Utf8` rather than `Utf8View` (its Arrow Flight transfers refuse large view
//! buffers); [`Remote::collect`] casts the result to the schema the local planner gives the same SQL, so
//! a `sql` stage stores the same column types on either engine.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use arrow::array::{ArrayRef, RecordBatch};
use arrow::compute::{CastOptions, cast_with_options};
use arrow::datatypes::{DataType, Field, Fields, Schema, SchemaRef};
use ballista::extension::{SessionConfigExt, SessionContextExt};
use ballista_core::serde::protobuf::scheduler_grpc_client::SchedulerGrpcClient;
use datafusion::common::Column;
use datafusion::datasource::ViewTable;
use datafusion::datasource::file_format::parquet::ParquetFormat;
use datafusion::datasource::listing::{
    ListingOptions, ListingTable, ListingTableConfig, ListingTableUrl,
};
use datafusion::error::DataFusionError;
use datafusion::execution::SessionStateBuilder;
use datafusion::execution::runtime_env::RuntimeEnv;
use datafusion::logical_expr::{Expr, LogicalPlanBuilder, lit};
use datafusion::prelude::{SessionConfig, SessionContext};

use super::engine::Engine;
use super::{QueryError, read_only};
use crate::pipeline::error_chain;
use crate::store::{TableDir, TableFile};
use crate::trace::schema::ENV_COLUMN;

/// How long opening a session waits for a scheduler to answer.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// A run's tables registered on a Ballista cluster.
pub(crate) struct Remote {
    ctx: SessionContext,
}

impl Remote {
    /// Connects to `engine` (or starts the standalone cluster) and registers each of `tables` — name,
    /// schema as the local session has it, and published files (`None` for a trace table the run does
    /// not have yet) — from its files.
    pub(crate) async fn open(
        engine: &Engine,
        partitions: usize,
        runtime_env: Arc<RuntimeEnv>,
        tables: Vec<(String, SchemaRef, Option<TableDir>)>,
    ) -> Result<Self, QueryError> {
        let config = SessionConfig::new_with_ballista()
            .with_information_schema(true)
            .with_default_catalog_and_schema("annotrace", "run")
            .with_target_partitions(partitions)
            // Sort a partitioned table's union as a whole: with per-branch sorts merged afterwards,
            // Ballista 55 runs each branch as a stage and its merge of them returned rows twice or
            // never finished (measured on the tests' runs).
            .set_bool("datafusion.optimizer.repartition_sorts", false);
        let state = SessionStateBuilder::new()
            .with_default_features()
            .with_config(config)
            .with_runtime_env(runtime_env)
            .build();
        let ctx = match engine {
            Engine::Local => unreachable!("the local engine has no remote session"),
            Engine::Ballista { host, port } => {
                let scheduler = format!("http://{host}:{port}");
                let unavailable = |detail: String| QueryError::EngineUnavailable {
                    engine: engine.to_string(),
                    detail,
                };
                match tokio::time::timeout(CONNECT_TIMEOUT, SchedulerGrpcClient::connect(scheduler))
                    .await
                {
                    Err(_) => {
                        return Err(unavailable(format!(
                            "no answer within {} s",
                            CONNECT_TIMEOUT.as_secs()
                        )));
                    }
                    Ok(Err(e)) => return Err(unavailable(error_chain(&e))),
                    Ok(Ok(_)) => {}
                }
                SessionContext::remote_with_state(&format!("df://{host}:{port}"), state).await?
            }
            Engine::BallistaStandalone => SessionContext::standalone_with_state(state)
                .await
                .map_err(|e| QueryError::EngineUnavailable {
                    engine: engine.to_string(),
                    detail: e.strip_backtrace(),
                })?,
        };
        for (name, schema, dir) in tables {
            register(&ctx, &name, &schema, dir.as_ref())?;
        }
        Ok(Remote { ctx })
    }

    /// Plans `sql` on the cluster's session, checks it only reads, runs it and returns its batches
    /// cast to `expected` (the schema the local session planned for the same SQL).
    pub(crate) async fn collect(
        &self,
        sql: &str,
        expected: &SchemaRef,
    ) -> Result<Vec<RecordBatch>, DataFusionError> {
        let plan = self.ctx.state().create_logical_plan(sql).await?;
        if read_only::check_plan(&plan).is_err() {
            return Err(DataFusionError::Plan(
                "refused: the statement does not only read".into(),
            ));
        }
        let batches = self.ctx.execute_logical_plan(plan).await?.collect().await?;
        batches.iter().map(|b| conform(b, expected)).collect()
    }
}

/// A `file://` URL of one file, never read as a glob (run paths may contain `[`, `*` or `?`).
fn file_url(file: &TableFile) -> Result<ListingTableUrl, DataFusionError> {
    let abs =
        std::path::absolute(&file.path).map_err(|e| DataFusionError::External(Box::new(e)))?;
    let url = url::Url::from_file_path(&abs).map_err(|()| {
        DataFusionError::Plan(format!("{}: not a file path for a URL", abs.display()))
    })?;
    ListingTableUrl::try_new(url, None)
}

/// A listing table over exactly `files` (none: an empty table) with the given file schema.
fn listing(files: &[&TableFile], schema: SchemaRef) -> Result<ListingTable, DataFusionError> {
    let urls = files
        .iter()
        .map(|f| file_url(f))
        .collect::<Result<Vec<_>, _>>()?;
    let options =
        ListingOptions::new(Arc::new(ParquetFormat::default())).with_file_extension(".parquet");
    ListingTable::try_new(
        ListingTableConfig::new_with_multi_paths(urls)
            .with_listing_options(options)
            .with_schema(schema),
    )
}

/// Registers one table under `name`; `schema` is the local session's (with `env` last for a
/// partitioned table).
fn register(
    ctx: &SessionContext,
    name: &str,
    schema: &SchemaRef,
    dir: Option<&TableDir>,
) -> Result<(), DataFusionError> {
    let schema = without_views(schema);
    let Some(dir) = dir.filter(|d| d.partitioned) else {
        let files: Vec<&TableFile> = dir.map(|d| d.files.iter().collect()).unwrap_or_default();
        ctx.register_table(name, Arc::new(listing(&files, schema)?))?;
        return Ok(());
    };
    // `env=` partitions: the file schema is the table's without its last column, `env`.
    let (env_index, _) = schema
        .column_with_name(ENV_COLUMN)
        .ok_or_else(|| DataFusionError::Plan(format!("table {name} has no {ENV_COLUMN} column")))?;
    let file_fields: Vec<Field> = schema
        .fields()
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != env_index)
        .map(|(_, f)| f.as_ref().clone())
        .collect();
    let file_schema = Arc::new(Schema::new(file_fields));
    let mut by_env: BTreeMap<String, Vec<&TableFile>> = BTreeMap::new();
    for f in &dir.files {
        let env = f.env.map(|e| e.to_string()).ok_or_else(|| {
            DataFusionError::Plan(format!(
                "{}: a file of partitioned table {name} outside an env= folder",
                f.path.display()
            ))
        })?;
        by_env.entry(env).or_default().push(f);
    }
    let mut union: Option<LogicalPlanBuilder> = None;
    for (env, files) in by_env {
        let table = listing(&files, file_schema.clone())?;
        let columns = schema
            .fields()
            .iter()
            .map(|f| {
                if f.name() == ENV_COLUMN {
                    lit(env.clone()).alias(ENV_COLUMN)
                } else {
                    Expr::Column(Column::new_unqualified(f.name()))
                }
            })
            .collect::<Vec<_>>();
        let branch = LogicalPlanBuilder::scan(
            format!("{name}__env_{env}"),
            datafusion::datasource::provider_as_source(Arc::new(table)),
            None,
        )?
        .project(columns)?
        .build()?;
        union = Some(match union {
            None => LogicalPlanBuilder::from(branch),
            Some(u) => u.union(branch)?,
        });
    }
    let plan = union
        .ok_or_else(|| DataFusionError::Plan(format!("partitioned table {name} has no files")))?
        .build()?;
    ctx.register_table(name, Arc::new(ViewTable::new(plan, None)))?;
    Ok(())
}

/// `schema` with string and binary views as plain strings and binaries (at any depth), the types
/// Ballista reads Parquet as.
fn without_views(schema: &SchemaRef) -> SchemaRef {
    fn plain(t: &DataType) -> DataType {
        match t {
            DataType::Utf8View => DataType::Utf8,
            DataType::BinaryView => DataType::Binary,
            DataType::List(f) => DataType::List(Arc::new(field(f))),
            DataType::LargeList(f) => DataType::LargeList(Arc::new(field(f))),
            DataType::FixedSizeList(f, n) => DataType::FixedSizeList(Arc::new(field(f)), *n),
            DataType::Struct(fs) => {
                DataType::Struct(fs.iter().map(|f| field(f)).collect::<Fields>())
            }
            other => other.clone(),
        }
    }
    fn field(f: &Field) -> Field {
        f.clone().with_data_type(plain(f.data_type()))
    }
    Arc::new(Schema::new_with_metadata(
        schema.fields().iter().map(|f| field(f)).collect::<Fields>(),
        schema.metadata().clone(),
    ))
}

/// `batch` with each column cast to `expected`'s type (only view/plain string differences arise).
fn conform(batch: &RecordBatch, expected: &SchemaRef) -> Result<RecordBatch, DataFusionError> {
    if batch.num_columns() != expected.fields().len() {
        return Err(DataFusionError::Internal(format!(
            "the cluster returned {} columns where the local plan has {}",
            batch.num_columns(),
            expected.fields().len()
        )));
    }
    let columns = batch
        .columns()
        .iter()
        .zip(expected.fields())
        .map(|(c, f)| -> Result<ArrayRef, DataFusionError> {
            if c.data_type() == f.data_type() {
                Ok(c.clone())
            } else {
                Ok(cast_with_options(
                    c,
                    f.data_type(),
                    &CastOptions::default(),
                )?)
            }
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(RecordBatch::try_new(expected.clone(), columns)?)
}
