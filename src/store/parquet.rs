//! Parquet files of a run: an atomic writer and a reader of whole datasets.

use std::fs::File;
use std::path::{Path, PathBuf};

use arrow::array::RecordBatch;
use arrow::datatypes::DataType;
use arrow::datatypes::SchemaRef;
use parquet::arrow::ArrowWriter;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::schema::types::ColumnPath;

use super::StoreError;
use super::atomic::AtomicFile;

/// Rows per Parquet row group: large enough for good compression and statistics, small enough that
/// readers can skip row groups of other traces.
pub const ROW_GROUP_ROWS: usize = 64 * 1024;

/// The codec of a Parquet file's pages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    /// zstd at a level (1–22).
    Zstd(i32),
    /// Snappy.
    Snappy,
    /// No compression.
    None,
}

/// How statistics are kept.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stats {
    /// Per page and per column chunk (row group).
    Page,
    /// Per column chunk only.
    Chunk,
}

/// The encoding choices of a run's Parquet files (docs/performance.md, "Parquet settings", measured
/// each of them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParquetSettings {
    /// Page codec.
    pub codec: Codec,
    /// Dictionary-encode `Float64` columns (other columns always are: ids, kinds, integers).
    pub float_dictionary: bool,
    /// Statistics of every column.
    pub stats: Stats,
    /// Rows per row group.
    pub row_group_rows: usize,
}

impl Default for ParquetSettings {
    /// What annotrace writes: zstd level 3, dictionaries on every column but the `Float64` ones
    /// (21 % smaller files than with them: simulator states rarely repeat, and a float column's
    /// dictionary only costs until the writer falls back to plain pages), page statistics, row groups
    /// of [`ROW_GROUP_ROWS`].
    fn default() -> Self {
        ParquetSettings {
            codec: Codec::Zstd(3),
            float_dictionary: false,
            stats: Stats::Page,
            row_group_rows: ROW_GROUP_ROWS,
        }
    }
}

impl ParquetSettings {
    /// The writer properties for files of `schema`.
    pub fn properties(&self, schema: &arrow::datatypes::Schema) -> WriterProperties {
        let codec = match self.codec {
            Codec::Zstd(level) => Compression::ZSTD(ZstdLevel::try_new(level).unwrap_or_default()),
            Codec::Snappy => Compression::SNAPPY,
            Codec::None => Compression::UNCOMPRESSED,
        };
        let mut b = WriterProperties::builder()
            .set_compression(codec)
            .set_max_row_group_row_count(Some(self.row_group_rows.max(1)))
            .set_statistics_enabled(match self.stats {
                Stats::Page => EnabledStatistics::Page,
                Stats::Chunk => EnabledStatistics::Chunk,
            })
            .set_created_by(format!("annotrace {}", crate::VERSION));
        if !self.float_dictionary {
            for f in schema.fields() {
                if f.data_type() == &DataType::Float64 {
                    b = b.set_column_dictionary_enabled(ColumnPath::from(f.name().as_str()), false);
                }
            }
        }
        b.build()
    }
}

/// A Parquet file being written; it appears at its path only on [`ParquetSink::commit`].
pub struct ParquetSink {
    writer: ArrowWriter<File>,
    atomic: AtomicFile,
    rows: usize,
}

impl ParquetSink {
    /// Starts a file at `target` with `schema` and the default [`ParquetSettings`].
    pub fn create(target: impl Into<PathBuf>, schema: SchemaRef) -> Result<Self, StoreError> {
        Self::create_with(target, schema, &ParquetSettings::default())
    }

    /// Starts a file at `target` with `schema`, encoded as `settings` say.
    pub fn create_with(
        target: impl Into<PathBuf>,
        schema: SchemaRef,
        settings: &ParquetSettings,
    ) -> Result<Self, StoreError> {
        let target = target.into();
        let mut atomic = AtomicFile::create(&target).map_err(|e| StoreError::io(&target, e))?;
        let props = settings.properties(&schema);
        let writer = ArrowWriter::try_new(atomic.take_file(), schema, Some(props))
            .map_err(|e| StoreError::parquet(&target, e))?;
        Ok(ParquetSink {
            writer,
            atomic,
            rows: 0,
        })
    }

    /// Appends a batch (its schema must be the file's).
    pub fn write(&mut self, batch: &RecordBatch) -> Result<(), StoreError> {
        self.rows += batch.num_rows();
        self.writer
            .write(batch)
            .map_err(|e| StoreError::parquet(self.atomic.target(), e))
    }

    /// Rows written so far.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Writes the footer, syncs and renames the file into place; returns its path and row count.
    pub fn commit(self) -> Result<(PathBuf, usize), StoreError> {
        let target = self.atomic.target().to_path_buf();
        let file = self
            .writer
            .into_inner()
            .map_err(|e| StoreError::parquet(&target, e))?;
        let path = self
            .atomic
            .commit_with(file)
            .map_err(|e| StoreError::io(&target, e))?;
        Ok((path, self.rows))
    }
}

/// Reads a Parquet file batch by batch, without holding the whole file.
pub fn read_batches(
    path: &Path,
) -> Result<impl Iterator<Item = Result<RecordBatch, StoreError>>, StoreError> {
    let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)
        .and_then(|b| b.with_batch_size(ROW_GROUP_ROWS).build())
        .map_err(|e| StoreError::parquet(path, e))?;
    let path = path.to_path_buf();
    Ok(reader.map(move |b| {
        b.map_err(|e| StoreError::parquet(&path, parquet::errors::ParquetError::from(e)))
    }))
}

/// Reads every batch of a Parquet file.
pub fn read_file(path: &Path) -> Result<Vec<RecordBatch>, StoreError> {
    let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)
        .and_then(|b| b.with_batch_size(ROW_GROUP_ROWS).build())
        .map_err(|e| StoreError::parquet(path, e))?;
    reader
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| StoreError::parquet(path, parquet::errors::ParquetError::from(e)))
}
