//! Parquet files of a run: an atomic writer and a reader of whole datasets.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use arrow::array::RecordBatch;
use arrow::datatypes::DataType;
use arrow::datatypes::SchemaRef;
use parquet::arrow::ArrowWriter;
use parquet::arrow::arrow_reader::{
    ArrowReaderMetadata, ArrowReaderOptions, ParquetRecordBatchReader,
    ParquetRecordBatchReaderBuilder,
};
use parquet::basic::{Compression, Encoding, ZstdLevel};
use parquet::file::metadata::ParquetMetaData;
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::schema::types::ColumnPath;

use super::StoreError;
use super::atomic::AtomicFile;
use crate::trace::Env;

/// Rows per Parquet row group: large enough for good compression and statistics, small enough that
/// readers can skip row groups of other traces.
pub const ROW_GROUP_ROWS: usize = 64 * 1024;

/// Rows per data page at most: a whole row group's column chunk (the Parquet writer's own default,
/// 20,000, made files 2–8 % larger and cost a compression call per page).
pub const PAGE_ROWS: usize = ROW_GROUP_ROWS;

/// The codec of a Parquet file's pages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Codec {
    /// zstd at a level (1–22; the column writer also takes zstd's fast levels below 1, which the
    /// Arrow writer replaces by 1).
    Zstd(i32),
    /// Snappy.
    Snappy,
    /// LZ4 (the raw block format, Parquet's `LZ4_RAW`).
    Lz4Raw,
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
/// each of them). None of them changes the rows, values or Arrow schema a reader sees, only the bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParquetSettings {
    /// Page codec.
    pub codec: Codec,
    /// Dictionary-encode `Float64` columns (other columns always are: ids, kinds, integers).
    pub float_dictionary: bool,
    /// Encode `Float64` columns that are not dictionary-encoded as `BYTE_STREAM_SPLIT` (each byte of
    /// the eight in its own stream) instead of `PLAIN`.
    pub float_byte_stream_split: bool,
    /// Statistics of every column.
    pub stats: Stats,
    /// Statistics on the dictionary-encoded string columns other than `trace_id` (the labels: object
    /// ids, kinds, states, shapes, colours): without them the writer compares no strings per row;
    /// `trace_id`, plain strings, integers and floats keep theirs.
    pub label_stats: bool,
    /// Rows per row group.
    pub row_group_rows: usize,
    /// Rows per data page at most.
    pub page_rows: usize,
    /// zstd's match-finder hash table, as a power of two, for the pages of floats the column
    /// writer ([`super::ColumnSink`]) is given a value per row of (positions, velocities, spins);
    /// 0 keeps the level's own (2^13 entries at level 1 for pages over 256 KiB). It changes how
    /// zstd finds matches, not what a reader reads. See [`ParquetSettings::for_frames`].
    pub float_hash_log: u32,
    /// Whether zstd stores the literals of those pages (the bytes no match covers) as they are
    /// instead of Huffman-coding them; a standard zstd frame either way.
    pub float_raw_literals: bool,
}

impl Default for ParquetSettings {
    /// What annotrace writes (docs/performance.md, "Parquet settings", measured each choice): zstd
    /// level 1 (within 1 % of level 3's size, a quarter less CPU); dictionaries on every column but
    /// the `Float64` ones (simulator states rarely repeat, and a float column's dictionary only costs
    /// until the writer falls back to plain pages); statistics per page, except on the label strings
    /// (no string comparisons per row: a row group of many traces spans every label anyway); pages
    /// of up to a row group's rows (one compression call per column chunk; 2–8 % smaller files);
    /// row groups of [`ROW_GROUP_ROWS`].
    fn default() -> Self {
        ParquetSettings {
            codec: Codec::Zstd(1),
            float_dictionary: false,
            float_byte_stream_split: false,
            stats: Stats::Page,
            label_stats: false,
            row_group_rows: ROW_GROUP_ROWS,
            page_rows: PAGE_ROWS,
            float_hash_log: 0,
            float_raw_literals: false,
        }
    }
}

impl ParquetSettings {
    /// What the column writer writes an environment's `timesteps` and `frames` with: the default,
    /// and for billiards' per-row float pages a zstd hash table of 2^10 entries (4 KiB rather than
    /// the 32 KiB of a core's whole L1 data cache) and raw literals. Measured (docs/performance.md,
    /// "zstd's hash table and literals for billiards' float pages"): the column writer takes a fifth
    /// less CPU for frames of the same size. For PHYRE and I-PHYRE either change made the frames
    /// 5–18 % larger for little or no time saved, so they keep zstd's own settings.
    pub fn for_frames(env: Option<Env>) -> Self {
        let pool = env == Some(Env::Pooltool);
        ParquetSettings {
            float_hash_log: if pool { 10 } else { 0 },
            float_raw_literals: pool,
            ..ParquetSettings::default()
        }
    }

    /// The writer properties for files of `schema`.
    pub fn properties(&self, schema: &arrow::datatypes::Schema) -> WriterProperties {
        let codec = match self.codec {
            Codec::Zstd(level) => Compression::ZSTD(ZstdLevel::try_new(level).unwrap_or_default()),
            Codec::Snappy => Compression::SNAPPY,
            Codec::Lz4Raw => Compression::LZ4_RAW,
            Codec::None => Compression::UNCOMPRESSED,
        };
        let mut b = WriterProperties::builder()
            .set_compression(codec)
            .set_max_row_group_row_count(Some(self.row_group_rows.max(1)))
            .set_statistics_enabled(match self.stats {
                Stats::Page => EnabledStatistics::Page,
                Stats::Chunk => EnabledStatistics::Chunk,
            })
            .set_data_page_row_count_limit(self.page_rows.max(1))
            .set_created_by(format!("annotrace {}", crate::VERSION));
        for f in schema.fields() {
            let col = || ColumnPath::from(f.name().as_str());
            match f.data_type() {
                DataType::Float64 if !self.float_dictionary => {
                    b = b.set_column_dictionary_enabled(col(), false);
                    if self.float_byte_stream_split {
                        b = b.set_column_encoding(col(), Encoding::BYTE_STREAM_SPLIT);
                    }
                }
                DataType::Dictionary(..) if !self.label_stats && f.name() != "trace_id" => {
                    b = b.set_column_statistics_enabled(col(), EnabledStatistics::None);
                }
                _ => {}
            }
        }
        b.build()
    }
}

/// A Parquet file being written; it appears at its path only on [`ParquetSink::commit`].
pub struct ParquetSink {
    writer: ArrowWriter<BufWriter<File>>,
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
        let writer = ArrowWriter::try_new(atomic.take_buffered(), schema, Some(props))
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
            .commit_buffered(file)
            .map_err(|e| StoreError::io(&target, e))?;
        Ok((path, self.rows))
    }
}

/// How a reader gives the string columns the file's Arrow schema keeps dictionary-encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strings {
    /// As written: `Dictionary` columns stay dictionaries.
    AsWritten,
    /// As plain `Utf8` (`LargeUtf8`, …: the dictionary's value type). For a batch that spans row
    /// groups this is cheaper: each row group has its own dictionary, and a dictionary batch across
    /// them is built by hashing every row's string into a new one, where a plain one copies it.
    Plain,
}

/// `schema` with every dictionary column given as its value type.
pub fn plain_strings(schema: &SchemaRef) -> SchemaRef {
    if !schema
        .fields()
        .iter()
        .any(|f| matches!(f.data_type(), DataType::Dictionary(..)))
    {
        return schema.clone();
    }
    let fields: Vec<arrow::datatypes::FieldRef> = schema
        .fields()
        .iter()
        .map(|f| match f.data_type() {
            DataType::Dictionary(_, value) => {
                std::sync::Arc::new(f.as_ref().clone().with_data_type(value.as_ref().clone()))
            }
            _ => f.clone(),
        })
        .collect();
    std::sync::Arc::new(arrow::datatypes::Schema::new_with_metadata(
        fields,
        schema.metadata().clone(),
    ))
}

/// A reader of the Parquet file at `path`, in batches of the rows `batch_rows` gives for its metadata.
fn reader(
    path: &Path,
    batch_rows: impl FnOnce(&ParquetMetaData) -> usize,
) -> Result<ParquetRecordBatchReader, StoreError> {
    reader_of(path, Strings::AsWritten, batch_rows)
}

/// [`reader`], with the string columns given as `strings` says.
fn reader_of(
    path: &Path,
    strings: Strings,
    batch_rows: impl FnOnce(&ParquetMetaData) -> usize,
) -> Result<ParquetRecordBatchReader, StoreError> {
    let file = File::open(path).map_err(|e| StoreError::io(path, e))?;
    let meta = ArrowReaderMetadata::load(&file, ArrowReaderOptions::new())
        .map_err(|e| StoreError::parquet(path, e))?;
    let plain = match strings {
        Strings::Plain => Some(plain_strings(meta.schema())),
        Strings::AsWritten => None,
    };
    let meta = match plain {
        // A schema without dictionaries is its own plain form (the same `Arc`).
        Some(plain) if !std::sync::Arc::ptr_eq(&plain, meta.schema()) => {
            ArrowReaderMetadata::try_new(
                meta.metadata().clone(),
                ArrowReaderOptions::new().with_schema(plain),
            )
            .map_err(|e| StoreError::parquet(path, e))?
        }
        _ => meta,
    };
    let builder = ParquetRecordBatchReaderBuilder::new_with_metadata(file, meta);
    let rows = batch_rows(builder.metadata());
    builder
        .with_batch_size(rows)
        .build()
        .map_err(|e| StoreError::parquet(path, e))
}

/// A reader's failure on a batch of the file at `path`.
fn batch_error(path: &Path, e: arrow::error::ArrowError) -> StoreError {
    StoreError::parquet(path, parquet::errors::ParquetError::from(e))
}

/// Every batch a reader of the file at `path` gives.
fn collect(path: &Path, reader: ParquetRecordBatchReader) -> Result<Vec<RecordBatch>, StoreError> {
    reader
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| batch_error(path, e))
}

/// Reads a Parquet file batch by batch, without holding the whole file.
pub fn read_batches(
    path: &Path,
) -> Result<impl Iterator<Item = Result<RecordBatch, StoreError>>, StoreError> {
    let reader = reader(path, |_| ROW_GROUP_ROWS)?;
    let path = path.to_path_buf();
    Ok(reader.map(move |b| b.map_err(|e| batch_error(&path, e))))
}

/// The most rows [`read_file_whole`] reads as one batch. The reader reserves a batch's worth of each
/// column up front from the row counts the footer claims, so a damaged or forged footer must not be
/// able to ask for more than this (a few tens of megabytes per column).
const WHOLE_FILE_MAX_ROWS: usize = 1 << 22;

/// Reads a whole Parquet file as one record batch (none for an empty file, several for a file of more
/// than `WHOLE_FILE_MAX_ROWS` rows), so that a reader which needs every row together
/// (`concat_batches` of one batch slices, it does not copy) pays no second copy of the rows.
pub fn read_file_whole(path: &Path) -> Result<Vec<RecordBatch>, StoreError> {
    read_file_whole_as(path, Strings::AsWritten)
}

/// [`read_file_whole`], with the string columns given as `strings` says.
pub fn read_file_whole_as(path: &Path, strings: Strings) -> Result<Vec<RecordBatch>, StoreError> {
    let whole = |meta: &ParquetMetaData| {
        meta.row_groups()
            .iter()
            .map(|g| usize::try_from(g.num_rows()).unwrap_or(0))
            .fold(0usize, usize::saturating_add)
            .clamp(1, WHOLE_FILE_MAX_ROWS)
    };
    collect(path, reader_of(path, strings, whole)?)
}

/// Reads every batch of a Parquet file.
pub fn read_file(path: &Path) -> Result<Vec<RecordBatch>, StoreError> {
    collect(path, reader(path, |_| ROW_GROUP_ROWS)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow::array::{Array, DictionaryArray, Float64Array, StringArray};
    use arrow::datatypes::{Field, Int32Type, Schema};
    use std::sync::Arc;

    #[test]
    fn a_whole_file_is_one_batch_across_row_groups_and_their_dictionaries() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.parquet");
        let schema = Arc::new(Schema::new(vec![
            Field::new(
                "label",
                DataType::Dictionary(Box::new(DataType::Int32), Box::new(DataType::Utf8)),
                false,
            ),
            Field::new("x", DataType::Float64, false),
        ]));
        // More rows than `read_file` puts in a batch, in row groups of 1,000 rows, each with its own
        // dictionary of labels.
        let n = ROW_GROUP_ROWS + 10;
        let labels: Vec<String> = (0..n).map(|i| format!("l{}", i / 700)).collect();
        let batch = RecordBatch::try_new(
            schema.clone(),
            vec![
                Arc::new(
                    labels
                        .iter()
                        .map(String::as_str)
                        .collect::<DictionaryArray<Int32Type>>(),
                ),
                Arc::new(Float64Array::from_iter_values((0..n).map(|i| i as f64))),
            ],
        )
        .unwrap();
        let props = WriterProperties::builder()
            .set_max_row_group_row_count(Some(1000))
            .build();
        let mut w = ArrowWriter::try_new(File::create(&path).unwrap(), schema.clone(), Some(props))
            .unwrap();
        w.write(&batch).unwrap();
        w.close().unwrap();

        let whole = read_file_whole(&path).unwrap();
        assert_eq!(whole.len(), 1);
        assert_eq!(whole[0].num_rows(), n);
        let got = arrow::compute::cast(whole[0].column(0), &DataType::Utf8).unwrap();
        let got = got.as_any().downcast_ref::<StringArray>().unwrap();
        assert_eq!(got.iter().flatten().collect::<Vec<_>>(), labels);
        assert_eq!(whole[0].column(1).as_ref(), batch.column(1).as_ref());
        assert!(read_file(&path).unwrap().len() > 1);

        // Read with plain strings: the same rows, the label column as Utf8, the floats untouched, and
        // the schema `plain_strings` gives.
        let plain = read_file_whole_as(&path, Strings::Plain).unwrap();
        assert_eq!(plain.len(), 1);
        assert_eq!(plain[0].schema(), plain_strings(&schema));
        assert_eq!(plain[0].schema().field(0).data_type(), &DataType::Utf8);
        let got = plain[0]
            .column(0)
            .as_any()
            .downcast_ref::<StringArray>()
            .unwrap();
        assert_eq!(got.iter().flatten().collect::<Vec<_>>(), labels);
        assert_eq!(plain[0].column(1).as_ref(), batch.column(1).as_ref());
        // A schema without dictionaries is its own plain form.
        let floats = Arc::new(Schema::new(vec![Field::new("x", DataType::Float64, false)]));
        assert!(Arc::ptr_eq(&plain_strings(&floats), &floats));
    }

    #[test]
    fn trace_ids_keep_statistics_and_floats_lose_dictionaries() {
        let schema = crate::trace::schema::FRAMES.clone();
        let props = ParquetSettings::default().properties(&schema);
        let col = |name: &str| ColumnPath::from(name);
        // `read_trace` skips row groups by the `trace_id` statistics.
        assert_eq!(
            props.statistics_enabled(&col("trace_id")),
            EnabledStatistics::Page
        );
        assert_eq!(props.statistics_enabled(&col("x")), EnabledStatistics::Page);
        assert_eq!(
            props.statistics_enabled(&col("object_id")),
            EnabledStatistics::None
        );
        assert!(!props.dictionary_enabled(&col("x")));
        assert!(props.dictionary_enabled(&col("object_id")));
        assert!(props.dictionary_enabled(&col("step")));
        let with_labels = ParquetSettings {
            label_stats: true,
            float_byte_stream_split: true,
            ..ParquetSettings::default()
        }
        .properties(&schema);
        assert_eq!(
            with_labels.statistics_enabled(&col("object_id")),
            EnabledStatistics::Page
        );
        assert_eq!(
            with_labels.encoding(&col("vx")),
            Some(parquet::basic::Encoding::BYTE_STREAM_SPLIT)
        );
    }
}
