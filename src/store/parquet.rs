//! Parquet files of a run: an atomic writer and a reader of whole datasets.

use std::fs::File;
use std::path::{Path, PathBuf};

use arrow::array::RecordBatch;
use arrow::datatypes::SchemaRef;
use parquet::arrow::ArrowWriter;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::properties::WriterProperties;

use super::StoreError;
use super::atomic::AtomicFile;

/// Rows per Parquet row group: large enough for good compression and statistics, small enough that
/// readers can skip row groups of other traces.
pub const ROW_GROUP_ROWS: usize = 64 * 1024;

/// A Parquet file being written; it appears at its path only on [`ParquetSink::commit`].
pub struct ParquetSink {
    writer: ArrowWriter<File>,
    atomic: AtomicFile,
    rows: usize,
}

impl ParquetSink {
    /// Starts a file at `target` with `schema` (zstd, dictionary encoding, page statistics).
    pub fn create(target: impl Into<PathBuf>, schema: SchemaRef) -> Result<Self, StoreError> {
        let target = target.into();
        let mut atomic = AtomicFile::create(&target).map_err(|e| StoreError::io(&target, e))?;
        let props = WriterProperties::builder()
            .set_compression(Compression::ZSTD(
                ZstdLevel::try_new(3).expect("level 3 is valid"),
            ))
            .set_max_row_group_row_count(Some(ROW_GROUP_ROWS))
            .set_created_by(format!("annotrace {}", crate::VERSION))
            .build();
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
