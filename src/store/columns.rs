//! Parquet files written column chunk by column chunk from borrowed column views
//! ([`ColumnView`]), without Arrow arrays and without parquet-rs's `ArrowWriter`.
//!
//! **Owns:** [`ColumnSink`]: the encoding of each column chunk (PLAIN floats and booleans, strings
//! and small-range integers as dictionary pages with RLE / bit-packed indices, definition levels
//! of optional columns as RLE runs), its compression and statistics, and the file around them
//! (schema, Arrow schema metadata and footer through parquet-rs's `SerializedFileWriter`, so the
//! files are the same Parquet any reader reads).
//! **Does not:** decide what is written (the `simulate` stage feeds the trace tables' views), or
//! write tables with nested or partly-null columns (those go through [`super::ParquetSink`]).
//!
//! Why: `ArrowWriter` runs at 5–7 M rows per CPU second on the frame tables even uncompressed
//! (docs/performance.md, "The column writer"): it computes definition levels row by row, interns
//! every integer and string value into its dictionaries and compares every value for statistics.
//! A simulator already knows what those costs recompute: a column is either present or null in
//! every row of an environment, a row's object is a position in a short list, timesteps are runs.
//! Here a dictionary column looks each distinct string up once per trace and maps rows through a
//! small table; integers whose range in a row group is small are dictionary-encoded by offset
//! (`v − min`); floats are copied. The rows a reader sees are the same as `ArrowWriter`'s; the
//! bytes differ (encodings, one data page per column chunk, chunk statistics without a page index).

use std::borrow::Cow;
use std::collections::HashMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;

use arrow::datatypes::{DataType, SchemaRef};
use bytes::Bytes;
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, Encoding, EncodingMask, PageType};
use parquet::column::page::{CompressedPage, Page, PageWriter};
use parquet::column::writer::ColumnCloseResult;
use parquet::data_type::ByteArray;
use parquet::file::metadata::{ColumnChunkMetaData, PageEncodingStats};
use parquet::file::statistics::{Statistics, ValueStatistics};
use parquet::file::writer::{SerializedFileWriter, SerializedPageWriter, TrackedWrite};
use parquet::schema::types::ColumnDescPtr;

use super::StoreError;
use super::atomic::AtomicFile;
use super::parquet::{Codec, ParquetSettings};
use crate::trace::view::{ColumnView, Keys};

/// Integers whose range in a row group is below this are dictionary-encoded by offset.
const INT_DICT_RANGE: i64 = 1 << 16;

/// The physical kind of a column.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    F64,
    I64,
    I32,
    Bool,
    Str,
}

/// A column's values in the current row group.
#[derive(Debug)]
enum Data {
    F64(Vec<f64>),
    /// `Int64` or `Int32` values (by [`Kind`]).
    Int(Vec<i64>),
    Bool(Vec<bool>),
    /// Dictionary strings in order of first appearance and each present row's position.
    Str {
        dict: Vec<String>,
        lookup: HashMap<String, u32>,
        idx: Vec<u32>,
    },
}

/// One column of the file: its kind, options and the current row group's values and levels.
#[derive(Debug)]
struct Column {
    name: String,
    kind: Kind,
    nullable: bool,
    stats: bool,
    descr: ColumnDescPtr,
    data: Data,
    /// Definition levels of an optional column as runs of (present, rows).
    def_runs: Vec<(bool, u32)>,
    nulls: u64,
    /// Whether the column was fed a value per row ([`ColumnView::F64`]): its pages are compressed
    /// with [`ParquetSettings::float_hash_log`] and [`ParquetSettings::float_raw_literals`].
    /// Columns repeated per step (`t`) or per object (radius) keep zstd's own settings: their
    /// matches lie far apart and a smaller table loses them.
    per_row_floats: bool,
}

impl Column {
    fn defined(&mut self, present: bool, n: usize) {
        if !present {
            self.nulls += n as u64;
        }
        if !self.nullable || n == 0 {
            return;
        }
        let n = n as u32;
        match self.def_runs.last_mut() {
            Some((p, c)) if *p == present => *c += n,
            _ => self.def_runs.push((present, n)),
        }
    }

    fn intern(&mut self, s: &str) -> u32 {
        let Data::Str { dict, lookup, .. } = &mut self.data else {
            return 0;
        };
        if let Some(&k) = lookup.get(s) {
            return k;
        }
        let k = dict.len() as u32;
        dict.push(s.to_string());
        lookup.insert(s.to_string(), k);
        k
    }
}

/// Runs `f(step, slot)` for rows `lo..hi` of timesteps with `counts` rows each.
fn for_run_rows(counts: &[i32], lo: usize, hi: usize, mut f: impl FnMut(usize, i32)) {
    let mut start = 0usize;
    let mut row = lo;
    for (s, &c) in counts.iter().enumerate() {
        let c = c.max(0) as usize;
        let end = start + c;
        while row < hi && row < end {
            if row >= start {
                f(s, (row - start) as i32);
            }
            row += 1;
        }
        if row >= hi {
            return;
        }
        start = end;
    }
}

/// zstd options of one column's pages (the defaults: the level's own).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct ZstdPage {
    /// The match finder's hash table, 2^`hash_log` entries (0: the level's own).
    hash_log: u32,
    /// Literals stored as they are, not Huffman-coded.
    raw_literals: bool,
}

/// A page compressor for the file's codec.
enum Compressor {
    /// The compressor and the page options it is set to.
    Zstd(Box<zstd::bulk::Compressor<'static>>, ZstdPage),
    Lz4Raw,
    Snappy(Box<snap::raw::Encoder>),
    None,
}

impl Compressor {
    fn new(codec: Codec) -> std::io::Result<Self> {
        Ok(match codec {
            Codec::Zstd(level) => Compressor::Zstd(
                Box::new(zstd::bulk::Compressor::new(level)?),
                ZstdPage::default(),
            ),
            Codec::Lz4Raw => Compressor::Lz4Raw,
            Codec::Snappy => Compressor::Snappy(Box::new(snap::raw::Encoder::new())),
            Codec::None => Compressor::None,
        })
    }

    /// `input` compressed (or `None` when the codec is none); zstd with the options of `page`,
    /// which change how, not whether, it compresses.
    fn compress(&mut self, input: &[u8], page: ZstdPage) -> std::io::Result<Option<Vec<u8>>> {
        Ok(Some(match self {
            Compressor::Zstd(c, set) => {
                use zstd::zstd_safe::{CParameter, ParamSwitch};
                if set.hash_log != page.hash_log {
                    c.set_parameter(CParameter::HashLog(page.hash_log))?;
                }
                if set.raw_literals != page.raw_literals {
                    c.set_parameter(CParameter::LiteralCompressionMode(if page.raw_literals {
                        ParamSwitch::Disable
                    } else {
                        ParamSwitch::Auto
                    }))?;
                }
                *set = page;
                let mut out = Vec::with_capacity(zstd::zstd_safe::compress_bound(input.len()));
                c.compress_to_buffer(input, &mut out)?;
                out
            }
            Compressor::Lz4Raw => {
                let mut out = vec![0u8; lz4_flex::block::get_maximum_output_size(input.len())];
                let n = lz4_flex::block::compress_into(input, &mut out)
                    .map_err(std::io::Error::other)?;
                out.truncate(n);
                out
            }
            Compressor::Snappy(e) => {
                let mut out = vec![0u8; snap::raw::max_compress_len(input.len())];
                let n = e.compress(input, &mut out).map_err(std::io::Error::other)?;
                out.truncate(n);
                out
            }
            Compressor::None => return Ok(None),
        }))
    }
}

/// The Parquet codec of `codec` (as [`ParquetSettings::properties`] sets it).
fn compression(codec: Codec) -> Compression {
    match codec {
        Codec::Zstd(level) => {
            Compression::ZSTD(parquet::basic::ZstdLevel::try_new(level).unwrap_or_default())
        }
        Codec::Snappy => Compression::SNAPPY,
        Codec::Lz4Raw => Compression::LZ4_RAW,
        Codec::None => Compression::UNCOMPRESSED,
    }
}

fn varint(mut v: u64, out: &mut Vec<u8>) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Bits needed for values up to `max`.
fn bit_width(max: u64) -> u8 {
    (64 - max.leading_zeros()) as u8
}

/// An RLE run: `count` copies of `value` at `width` bits.
fn rle_run(value: u32, count: usize, width: u8, out: &mut Vec<u8>) {
    varint((count as u64) << 1, out);
    let bytes = (width as usize).div_ceil(8);
    out.extend_from_slice(&value.to_le_bytes()[..bytes]);
}

/// Bit-packed runs of `values` (a multiple of 8 values, except at the very end, where the last
/// group is padded with zeros), at most 63 groups per run header.
fn bit_packed(values: &[u32], width: u8, out: &mut Vec<u8>) {
    for part in values.chunks(63 * 8) {
        let groups = part.len().div_ceil(8);
        varint(((groups as u64) << 1) | 1, out);
        if width <= 8 {
            pack_groups_narrow(part, width, out);
        } else {
            pack_groups(part, width, out);
        }
    }
}

/// Packs `part` in groups of 8 at `width` bits, a value's bits after the previous value's, least
/// significant first; the last group is padded with zeros.
fn pack_groups(part: &[u32], width: u8, out: &mut Vec<u8>) {
    let mut acc: u64 = 0;
    let mut bits = 0u32;
    for k in 0..part.len().div_ceil(8) * 8 {
        let v = part.get(k).copied().unwrap_or(0) as u64;
        acc |= v << bits;
        bits += u32::from(width);
        while bits >= 8 {
            out.push(acc as u8);
            acc >>= 8;
            bits -= 8;
        }
    }
}

/// [`pack_groups`] for widths up to 8 bits, where a group of 8 values is `width` whole bytes: the
/// group is assembled in one `u64` and written at once. (Dictionary indices of the frame tables are
/// 2–4 bits wide; packing them a bit at a time was 5 % of a billiards `simulate`.)
fn pack_groups_narrow(part: &[u32], width: u8, out: &mut Vec<u8>) {
    debug_assert!(width <= 8);
    let w = usize::from(width);
    let group = |g: &[u32]| {
        g.iter()
            .enumerate()
            .fold(0u64, |acc, (k, &v)| acc | (u64::from(v) << (k * w)))
    };
    let mut groups = part.chunks_exact(8);
    for g in &mut groups {
        out.extend_from_slice(&group(g).to_le_bytes()[..w]);
    }
    let rest = groups.remainder();
    if !rest.is_empty() {
        out.extend_from_slice(&group(rest).to_le_bytes()[..w]);
    }
}

/// The RLE / bit-packed hybrid encoding of `values` at `width` bits: runs of at least 8 equal
/// values as RLE runs, the rest bit-packed in groups of 8.
fn hybrid(values: &[u32], width: u8, out: &mut Vec<u8>) {
    let n = values.len();
    let (mut lit, mut i) = (0usize, 0usize);
    while i < n {
        let v = values[i];
        let mut j = i + 1;
        while j < n && values[j] == v {
            j += 1;
        }
        let pad = (8 - (i - lit) % 8) % 8;
        if j - i >= pad + 8 {
            let cut = i + pad;
            bit_packed(&values[lit..cut], width, out);
            rle_run(v, j - cut, width, out);
            lit = j;
        }
        i = j;
    }
    bit_packed(&values[lit..n], width, out);
}

/// Definition levels (`present` runs) in a data page v1: their byte length, then RLE runs.
fn def_levels(runs: &[(bool, u32)], out: &mut Vec<u8>) {
    let at = out.len();
    out.extend_from_slice(&[0; 4]);
    for &(present, n) in runs {
        rle_run(u32::from(present), n as usize, 1, out);
    }
    let len = (out.len() - at - 4) as u32;
    out[at..at + 4].copy_from_slice(&len.to_le_bytes());
}

/// `min` and `max` of floats as Parquet orders them: NaN left out, a zero minimum as −0 and a
/// zero maximum as +0. Eight lanes of compare-and-select (a NaN never compares less or greater,
/// so it never enters), which the compiler turns into vector min/max.
fn float_range(values: &[f64]) -> Option<(f64, f64)> {
    let mut lo = [f64::INFINITY; 8];
    let mut hi = [f64::NEG_INFINITY; 8];
    let chunks = values.chunks_exact(8);
    let tail = chunks.remainder();
    for c in chunks {
        for k in 0..8 {
            lo[k] = if c[k] < lo[k] { c[k] } else { lo[k] };
            hi[k] = if c[k] > hi[k] { c[k] } else { hi[k] };
        }
    }
    for (k, &x) in tail.iter().enumerate() {
        lo[k] = if x < lo[k] { x } else { lo[k] };
        hi[k] = if x > hi[k] { x } else { hi[k] };
    }
    let mut lo = lo
        .iter()
        .fold(f64::INFINITY, |a, &b| if b < a { b } else { a });
    let mut hi = hi
        .iter()
        .fold(f64::NEG_INFINITY, |a, &b| if b > a { b } else { a });
    // Only infinities compare equal to the starting values: a lane that saw one still counts.
    let has = |x: f64| values.contains(&x);
    if lo == f64::INFINITY && !has(f64::INFINITY) {
        return None;
    }
    if hi == f64::NEG_INFINITY && !has(f64::NEG_INFINITY) {
        return None;
    }
    if lo == 0.0 {
        lo = -0.0;
    }
    if hi == 0.0 {
        hi = 0.0;
    }
    Some((lo, hi))
}

/// A column chunk encoded in memory, ready to be appended to a row group.
struct EncodedChunk {
    bytes: Bytes,
    close: ColumnCloseResult,
}

/// A Parquet file written from column views; it appears at its path only on
/// [`ColumnSink::commit`].
pub struct ColumnSink {
    writer: SerializedFileWriter<BufWriter<File>>,
    atomic: AtomicFile,
    columns: Vec<Column>,
    compressor: Compressor,
    compression: Compression,
    /// zstd options of the per-row float columns' pages.
    float_pages: ZstdPage,
    group_cap: usize,
    group_rows: usize,
    rows: usize,
}

impl ColumnSink {
    /// Whether the column writer can write files of `schema` with `settings`: flat columns of
    /// `Float64`, `Int64`, `Int32`, `Boolean`, `Utf8` and `Dictionary(Int32, Utf8)`; floats plain
    /// (no float dictionaries or byte-stream-split); statistics per column chunk.
    pub fn supports(schema: &arrow::datatypes::Schema, settings: &ParquetSettings) -> bool {
        !settings.float_dictionary
            && !settings.float_byte_stream_split
            && schema
                .fields()
                .iter()
                .all(|f| kind_of(f.data_type()).is_some())
    }

    /// Starts a file at `target` with `schema` (see [`ColumnSink::supports`]), encoded as
    /// `settings` say (codec, label statistics, row-group size; one data page per column chunk).
    pub fn create(
        target: impl Into<PathBuf>,
        schema: SchemaRef,
        settings: &ParquetSettings,
    ) -> Result<Self, StoreError> {
        let target = target.into();
        if !Self::supports(&schema, settings) {
            return Err(StoreError::Schema {
                path: target,
                message: "the column writer cannot write this schema with these settings".into(),
            });
        }
        let mut atomic = AtomicFile::create(&target).map_err(|e| StoreError::io(&target, e))?;
        let props = settings.properties(&schema);
        // The Arrow writer only sets the file up (Parquet schema from the Arrow one, the encoded
        // Arrow schema in the key-value metadata); no batch goes through it.
        let (writer, _) = ArrowWriter::try_new(atomic.take_buffered(), schema.clone(), Some(props))
            .and_then(|w| w.into_serialized_writer())
            .map_err(|e| StoreError::parquet(&target, e))?;
        let descrs: Vec<ColumnDescPtr> = writer.schema_descr().columns().to_vec();
        let columns = schema
            .fields()
            .iter()
            .zip(descrs)
            .map(|(f, descr)| {
                let kind = kind_of(f.data_type()).unwrap_or(Kind::F64);
                let label = matches!(f.data_type(), DataType::Dictionary(..));
                Column {
                    name: f.name().clone(),
                    kind,
                    nullable: f.is_nullable(),
                    stats: !label || settings.label_stats || f.name() == "trace_id",
                    descr,
                    data: empty_data(kind),
                    def_runs: Vec::new(),
                    nulls: 0,
                    per_row_floats: false,
                }
            })
            .collect();
        let compressor = Compressor::new(settings.codec).map_err(|e| StoreError::io(&target, e))?;
        Ok(ColumnSink {
            writer,
            atomic,
            columns,
            compressor,
            compression: compression(settings.codec),
            float_pages: ZstdPage {
                hash_log: settings.float_hash_log,
                raw_literals: settings.float_raw_literals,
            },
            group_cap: settings.row_group_rows.max(1),
            group_rows: 0,
            rows: 0,
        })
    }

    /// Rows written so far.
    pub fn rows(&self) -> usize {
        self.rows
    }

    fn schema_error(&self, message: String) -> StoreError {
        StoreError::Schema {
            path: self.atomic.target().to_path_buf(),
            message,
        }
    }

    /// Appends `rows` rows given as one view per column of the schema, in order. A view must
    /// cover the rows (a per-row slice of `rows` values, keys for `rows` rows, runs summing to
    /// `rows`), and its kind match the column's.
    pub fn append(&mut self, rows: usize, views: &[ColumnView<'_>]) -> Result<(), StoreError> {
        if views.len() != self.columns.len() {
            return Err(self.schema_error(format!(
                "{} column views for {} columns",
                views.len(),
                self.columns.len()
            )));
        }
        for (c, v) in self.columns.iter().zip(views) {
            if let Some(n) = view_rows(v)
                && n != rows
            {
                return Err(
                    self.schema_error(format!("column {}: {n} values for {rows} rows", c.name))
                );
            }
        }
        let mut at = 0;
        while at < rows {
            let take = (rows - at).min(self.group_cap - self.group_rows);
            let pushed = self
                .columns
                .iter_mut()
                .zip(views)
                .try_for_each(|(c, v)| push(c, v, at, at + take));
            pushed.map_err(|m| self.schema_error(m))?;
            at += take;
            self.group_rows += take;
            self.rows += take;
            if self.group_rows == self.group_cap {
                self.flush_group()?;
            }
        }
        Ok(())
    }

    /// Writes the current row group (if it holds rows).
    fn flush_group(&mut self) -> Result<(), StoreError> {
        if self.group_rows == 0 {
            return Ok(());
        }
        let rows = self.group_rows;
        let target = self.atomic.target().to_path_buf();
        let perr = |e| StoreError::parquet(&target, e);
        let mut chunks = Vec::with_capacity(self.columns.len());
        for c in &mut self.columns {
            chunks.push(
                encode_chunk(
                    c,
                    rows,
                    &mut self.compressor,
                    self.compression,
                    self.float_pages,
                )
                .map_err(|e| StoreError::parquet(&target, e))?,
            );
            c.data = empty_data_like(&mut c.data);
            c.def_runs.clear();
            c.nulls = 0;
        }
        let mut group = self.writer.next_row_group().map_err(perr)?;
        for chunk in chunks {
            group
                .append_column(&chunk.bytes, chunk.close)
                .map_err(|e| StoreError::parquet(&target, e))?;
        }
        group.close().map_err(|e| StoreError::parquet(&target, e))?;
        self.group_rows = 0;
        Ok(())
    }

    /// Writes the last row group and the footer, syncs and renames the file into place; returns
    /// its path and row count.
    pub fn commit(mut self) -> Result<(PathBuf, usize), StoreError> {
        self.flush_group()?;
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

fn kind_of(dt: &DataType) -> Option<Kind> {
    Some(match dt {
        DataType::Float64 => Kind::F64,
        DataType::Int64 => Kind::I64,
        DataType::Int32 => Kind::I32,
        DataType::Boolean => Kind::Bool,
        DataType::Utf8 => Kind::Str,
        DataType::Dictionary(k, v) if **k == DataType::Int32 && **v == DataType::Utf8 => Kind::Str,
        _ => return None,
    })
}

fn empty_data(kind: Kind) -> Data {
    match kind {
        Kind::F64 => Data::F64(Vec::new()),
        Kind::I64 | Kind::I32 => Data::Int(Vec::new()),
        Kind::Bool => Data::Bool(Vec::new()),
        Kind::Str => Data::Str {
            dict: Vec::new(),
            lookup: HashMap::new(),
            idx: Vec::new(),
        },
    }
}

/// A cleared copy of `data` that keeps the row buffers' capacity (a new row group starts a new
/// dictionary).
fn empty_data_like(data: &mut Data) -> Data {
    fn cleared<T>(v: &mut Vec<T>) -> Vec<T> {
        let mut w = std::mem::take(v);
        w.clear();
        w
    }
    match data {
        Data::F64(v) => Data::F64(cleared(v)),
        Data::Int(v) => Data::Int(cleared(v)),
        Data::Bool(v) => Data::Bool(cleared(v)),
        Data::Str { idx, .. } => Data::Str {
            dict: Vec::new(),
            lookup: HashMap::new(),
            idx: cleared(idx),
        },
    }
}

/// Rows a view covers (`None` for views that fit any number: constants and nulls).
fn view_rows(v: &ColumnView<'_>) -> Option<usize> {
    Some(match v {
        ColumnView::F64(s) => s.len(),
        ColumnView::I64(s) => s.len(),
        ColumnView::I32(s) => s.len(),
        ColumnView::Bool(s) => s.len(),
        ColumnView::F64Of { keys, .. }
        | ColumnView::I64Of { keys, .. }
        | ColumnView::BoolOf { keys, .. }
        | ColumnView::Str { keys, .. } => keys.len(),
        ColumnView::F64Runs { counts, .. }
        | ColumnView::I64Runs { counts, .. }
        | ColumnView::Slots(counts) => counts.iter().map(|&c| c.max(0) as usize).sum(),
        ColumnView::StrConst(_) | ColumnView::Null => return None,
    })
}

/// The keys of rows `lo..hi`, each clamped to `0..n`.
fn keyed<'k>(
    keys: &'k Keys<'_>,
    n: usize,
    lo: usize,
    hi: usize,
) -> impl Iterator<Item = usize> + 'k {
    (lo..hi).map(move |i| keys.get(i, n))
}

/// Appends rows `lo..hi` of `view` to `c`.
fn push(c: &mut Column, view: &ColumnView<'_>, lo: usize, hi: usize) -> Result<(), String> {
    let n = hi - lo;
    let mismatch = || {
        format!(
            "column {}: a {:?} view for a {:?} column",
            c.name,
            view_name(view),
            c.kind
        )
    };
    if let ColumnView::Null = view {
        if !c.nullable {
            return Err(format!(
                "column {}: nulls in a column that has none",
                c.name
            ));
        }
        c.defined(false, n);
        return Ok(());
    }
    let of = |values_len: usize, keys| keyed(keys, values_len, lo, hi);
    match (&mut c.data, view) {
        (Data::F64(out), ColumnView::F64(s)) => {
            c.per_row_floats = true;
            out.extend_from_slice(&s[lo..hi])
        }
        (Data::F64(out), ColumnView::F64Of { values, keys }) => {
            out.extend(of(values.len(), keys).map(|k| values[k]))
        }
        (Data::F64(out), ColumnView::F64Runs { values, counts }) => {
            for_run_rows(counts, lo, hi, |s, _| out.push(values[s]))
        }
        (Data::Int(out), ColumnView::I64(s)) if c.kind == Kind::I64 => {
            out.extend_from_slice(&s[lo..hi])
        }
        (Data::Int(out), ColumnView::I64Of { values, keys }) if c.kind == Kind::I64 => {
            out.extend(of(values.len(), keys).map(|k| values[k]))
        }
        (Data::Int(out), ColumnView::I64Runs { values, counts }) if c.kind == Kind::I64 => {
            for_run_rows(counts, lo, hi, |s, _| out.push(values[s]))
        }
        (Data::Int(out), ColumnView::I32(s)) if c.kind == Kind::I32 => {
            out.extend(s[lo..hi].iter().map(|&v| i64::from(v)))
        }
        (Data::Int(out), ColumnView::Slots(counts)) if c.kind == Kind::I32 => {
            for_run_rows(counts, lo, hi, |_, k| out.push(i64::from(k)))
        }
        (Data::Bool(out), ColumnView::Bool(s)) => out.extend_from_slice(&s[lo..hi]),
        (Data::Bool(out), ColumnView::BoolOf { values, keys }) => {
            out.extend(of(values.len(), keys).map(|k| values[k]))
        }
        (Data::Str { .. }, ColumnView::Str { values, keys }) => {
            let remap: Vec<u32> = values.iter().map(|s| c.intern(s)).collect();
            let Data::Str { idx, .. } = &mut c.data else {
                unreachable!("matched above")
            };
            if remap.is_empty() {
                return Err(format!("column {}: row keys into no values", c.name));
            }
            idx.extend(of(remap.len(), keys).map(|k| remap[k]));
        }
        (Data::Str { .. }, ColumnView::StrConst(s)) => {
            let k = c.intern(s);
            let Data::Str { idx, .. } = &mut c.data else {
                unreachable!("matched above")
            };
            idx.resize(idx.len() + n, k);
        }
        _ => return Err(mismatch()),
    }
    c.defined(true, n);
    Ok(())
}

fn view_name(v: &ColumnView<'_>) -> &'static str {
    match v {
        ColumnView::F64(_) => "F64",
        ColumnView::I64(_) => "I64",
        ColumnView::I32(_) => "I32",
        ColumnView::Bool(_) => "Bool",
        ColumnView::F64Of { .. } => "F64Of",
        ColumnView::I64Of { .. } => "I64Of",
        ColumnView::BoolOf { .. } => "BoolOf",
        ColumnView::Str { .. } => "Str",
        ColumnView::StrConst(_) => "StrConst",
        ColumnView::F64Runs { .. } => "F64Runs",
        ColumnView::I64Runs { .. } => "I64Runs",
        ColumnView::Slots(_) => "Slots",
        ColumnView::Null => "Null",
    }
}

/// How a chunk's present values were encoded.
struct Encoded {
    /// The dictionary page's PLAIN values and their count, if dictionary-encoded.
    dict: Option<(Vec<u8>, usize)>,
    statistics: Option<Statistics>,
}

/// Whether `c`'s PLAIN values are left where they are rather than copied into its data page: a
/// non-nullable float column's page has no levels before its values, and on a little-endian machine
/// those values' own bytes are the page ([`page_body`]).
fn values_in_place(c: &Column) -> bool {
    matches!(c.data, Data::F64(_)) && !c.nullable && cfg!(target_endian = "little")
}

/// The data page of `c` as `encode_values` left it: `data` (its levels and values), or, for PLAIN
/// values left in place ([`values_in_place`]; `dict` tells whether they were dictionary-encoded
/// instead), the values' own bytes, which the codec reads where they are instead of from a copy.
fn page_body(c: &Column, dict: bool, data: Vec<u8>) -> Cow<'_, [u8]> {
    match &c.data {
        Data::F64(v) if !dict && values_in_place(c) => {
            use arrow::datatypes::ToByteSlice;
            Cow::Borrowed(v.to_byte_slice())
        }
        _ => Cow::Owned(data),
    }
}

/// Appends `v` as PLAIN little-endian values.
fn plain_f64(v: &[f64], out: &mut Vec<u8>) {
    #[cfg(target_endian = "little")]
    {
        // The values' own bytes are already little-endian: one copy, no zero-fill first.
        use arrow::datatypes::ToByteSlice;
        out.extend_from_slice(v.to_byte_slice());
    }
    #[cfg(not(target_endian = "little"))]
    {
        out.reserve(v.len() * 8);
        for x in v {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
}

/// Appends the data page's values section of `c`'s present values to `values`, except for PLAIN
/// values left in place ([`values_in_place`], read through [`page_body`]).
fn encode_values(c: &Column, values: &mut Vec<u8>) -> Encoded {
    let nulls = Some(c.nulls);
    let stats = c.stats;
    match &c.data {
        Data::F64(v) => {
            // A column holding one value (bit for bit) is a one-entry dictionary and a single RLE
            // run: nothing for the codec to squeeze (billiards' `z` and `vz`, for example).
            let constant = v
                .first()
                .filter(|x| v.iter().all(|y| y.to_bits() == x.to_bits()));
            let dict = match constant {
                Some(x) if v.len() > 1 => {
                    values.push(0);
                    rle_run(0, v.len(), 0, values);
                    Some((x.to_le_bytes().to_vec(), 1))
                }
                _ if values_in_place(c) => None,
                _ => {
                    plain_f64(v, values);
                    None
                }
            };
            let range = float_range(v);
            Encoded {
                dict,
                statistics: stats.then(|| {
                    ValueStatistics::<f64>::new(
                        range.map(|r| r.0),
                        range.map(|r| r.1),
                        None,
                        nulls,
                        false,
                    )
                    .with_backwards_compatible_min_max(true)
                    .into()
                }),
            }
        }
        Data::Int(v) => {
            let range = v
                .iter()
                .fold(None, |acc: Option<(i64, i64)>, &x| match acc {
                    None => Some((x, x)),
                    Some((a, b)) => Some((a.min(x), b.max(x))),
                });
            let wide = c.kind == Kind::I64;
            let plain = |x: i64, out: &mut Vec<u8>| {
                if wide {
                    out.extend_from_slice(&x.to_le_bytes());
                } else {
                    out.extend_from_slice(&(x as i32).to_le_bytes());
                }
            };
            let statistics = stats.then(|| -> Statistics {
                if wide {
                    ValueStatistics::<i64>::new(
                        range.map(|r| r.0),
                        range.map(|r| r.1),
                        None,
                        nulls,
                        false,
                    )
                    .with_backwards_compatible_min_max(true)
                    .into()
                } else {
                    ValueStatistics::<i32>::new(
                        range.map(|r| r.0 as i32),
                        range.map(|r| r.1 as i32),
                        None,
                        nulls,
                        false,
                    )
                    .with_backwards_compatible_min_max(true)
                    .into()
                }
            });
            match range {
                Some((lo, hi))
                    if hi.checked_sub(lo).is_some_and(|r| r < INT_DICT_RANGE)
                        && ((hi - lo) as usize) < v.len() =>
                {
                    let entries = (hi - lo + 1) as usize;
                    let mut dict = Vec::with_capacity(entries * if wide { 8 } else { 4 });
                    for x in lo..=hi {
                        plain(x, &mut dict);
                    }
                    let width = bit_width((hi - lo) as u64);
                    let keys: Vec<u32> = v.iter().map(|&x| (x - lo) as u32).collect();
                    values.push(width);
                    hybrid(&keys, width, values);
                    Encoded {
                        dict: Some((dict, entries)),
                        statistics,
                    }
                }
                _ => {
                    values.reserve(v.len() * if wide { 8 } else { 4 });
                    for &x in v {
                        plain(x, values);
                    }
                    Encoded {
                        dict: None,
                        statistics,
                    }
                }
            }
        }
        Data::Bool(v) => {
            let at = values.len();
            values.resize(at + v.len().div_ceil(8), 0);
            for (i, &b) in v.iter().enumerate() {
                if b {
                    values[at + i / 8] |= 1 << (i % 8);
                }
            }
            let lo = v.iter().all(|&b| b);
            let hi = v.iter().any(|&b| b);
            let some = !v.is_empty();
            Encoded {
                dict: None,
                statistics: stats.then(|| {
                    ValueStatistics::<bool>::new(
                        some.then_some(lo),
                        some.then_some(hi),
                        None,
                        nulls,
                        false,
                    )
                    .into()
                }),
            }
        }
        Data::Str { dict, idx, .. } => {
            if idx.is_empty() {
                return Encoded {
                    dict: None,
                    statistics: stats.then(|| {
                        ValueStatistics::<ByteArray>::new(None, None, None, nulls, false).into()
                    }),
                };
            }
            let mut page = Vec::new();
            for s in dict {
                page.extend_from_slice(&(s.len() as u32).to_le_bytes());
                page.extend_from_slice(s.as_bytes());
            }
            let width = bit_width(dict.len().saturating_sub(1) as u64);
            values.push(width);
            hybrid(idx, width, values);
            let statistics = stats.then(|| {
                let lo = dict.iter().min().map(|s| ByteArray::from(s.as_str()));
                let hi = dict.iter().max().map(|s| ByteArray::from(s.as_str()));
                ValueStatistics::<ByteArray>::new(lo, hi, None, nulls, false).into()
            });
            Encoded {
                dict: Some((page, dict.len())),
                statistics,
            }
        }
    }
}

/// The column chunk of `c`'s current row group (`rows` rows): an optional dictionary page and
/// one data page (v1), compressed, in memory.
fn encode_chunk(
    c: &Column,
    rows: usize,
    compressor: &mut Compressor,
    compression: Compression,
    float_pages: ZstdPage,
) -> parquet::errors::Result<EncodedChunk> {
    // Values left in place need no page buffer (`page_body`).
    let mut data = if values_in_place(c) {
        Vec::new()
    } else {
        Vec::with_capacity(rows * 8 + 64)
    };
    if c.nullable {
        def_levels(&c.def_runs, &mut data);
    }
    let enc = encode_values(c, &mut data);
    let mut sink = TrackedWrite::new(Vec::new());
    let mut encodings = vec![Encoding::RLE];
    let mut page_stats = Vec::new();
    let (mut compressed_total, mut uncompressed_total) = (0u64, 0u64);
    let (mut dict_offset, data_offset);
    let page = if c.per_row_floats {
        float_pages
    } else {
        ZstdPage::default()
    };
    // An uncompressed page is its buffer, moved (or copied, for values read in place).
    let mut compress = |buf: Cow<'_, [u8]>| -> parquet::errors::Result<(Bytes, usize)> {
        let raw = buf.len();
        Ok(match compressor.compress(&buf, page)? {
            Some(z) => (Bytes::from(z), raw),
            None => (Bytes::from(buf.into_owned()), raw),
        })
    };
    {
        let mut pages = SerializedPageWriter::new(&mut sink);
        dict_offset = None;
        let dict_encoded = enc.dict.is_some();
        let data_encoding = if let Some((dict, entries)) = enc.dict {
            let (buf, raw) = compress(Cow::Owned(dict))?;
            let spec = pages.write_page(CompressedPage::new(
                Page::DictionaryPage {
                    buf,
                    num_values: entries as u32,
                    encoding: Encoding::PLAIN,
                    is_sorted: false,
                },
                raw,
            ))?;
            dict_offset = Some(spec.offset as i64);
            compressed_total += spec.compressed_size as u64;
            uncompressed_total += spec.uncompressed_size as u64;
            encodings.push(Encoding::PLAIN);
            page_stats.push(PageEncodingStats {
                page_type: PageType::DICTIONARY_PAGE,
                encoding: Encoding::PLAIN,
                count: 1,
            });
            Encoding::RLE_DICTIONARY
        } else {
            Encoding::PLAIN
        };
        let (buf, raw) = compress(page_body(c, dict_encoded, data))?;
        let spec = pages.write_page(CompressedPage::new(
            Page::DataPage {
                buf,
                num_values: rows as u32,
                encoding: data_encoding,
                def_level_encoding: Encoding::RLE,
                rep_level_encoding: Encoding::RLE,
                statistics: None,
            },
            raw,
        ))?;
        data_offset = spec.offset as i64;
        compressed_total += spec.compressed_size as u64;
        uncompressed_total += spec.uncompressed_size as u64;
        encodings.push(data_encoding);
        page_stats.push(PageEncodingStats {
            page_type: PageType::DATA_PAGE,
            encoding: data_encoding,
            count: 1,
        });
        pages.close()?;
    }
    let bytes = Bytes::from(sink.into_inner()?);
    let mut builder = ColumnChunkMetaData::builder(c.descr.clone())
        .set_compression(compression)
        .set_encodings_mask(EncodingMask::new_from_encodings(encodings.iter()))
        .set_page_encoding_stats(page_stats)
        .set_total_compressed_size(compressed_total as i64)
        .set_total_uncompressed_size(uncompressed_total as i64)
        .set_num_values(rows as i64)
        .set_data_page_offset(data_offset)
        .set_dictionary_page_offset(dict_offset);
    if let Some(s) = enc.statistics {
        builder = builder.set_statistics(s);
    }
    let metadata = builder.build()?;
    Ok(EncodedChunk {
        close: ColumnCloseResult {
            bytes_written: compressed_total,
            rows_written: rows as u64,
            metadata,
            bloom_filter: None,
            column_index: None,
            offset_index: None,
        },
        bytes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::parquet::read_file;
    use crate::trace::frames::{IphyreBody, IphyreFrames, PhyreBody, PhyreFrames, PoolFrames};
    use crate::trace::schema::{FRAMES, TIMESTEPS};
    use crate::trace::{Env, Event, JsonMap, Outcome, TraceColumns};
    use arrow::array::{Array, ArrayRef, RecordBatch};
    use arrow::compute::{cast, concat_batches};

    fn trace(id: &str, frames: crate::trace::Frames) -> TraceColumns {
        TraceColumns {
            trace_id: id.into(),
            task_id: "task".into(),
            frames,
            events: vec![Event::at("e", 0.0, serde_json::json!({"agents": ["cue"]}))],
            outcome: Outcome {
                success: false,
                terminal_status: "timeout".into(),
                metrics: JsonMap::new(),
                extra: JsonMap::new(),
            },
            extra: JsonMap::new(),
        }
    }

    /// Billiards: balls `ids` over `steps` steps; motion codes in long runs for ball 0 and
    /// changing every step for the others, so indices take both RLE and bit-packed runs.
    fn pool(id: &str, ids: &[&str], steps: usize, seed: u32) -> TraceColumns {
        let names = &["stationary", "spinning", "sliding", "rolling", "pocketed"];
        let ids: Vec<String> = ids.iter().map(|s| s.to_string()).collect();
        let n = ids.len();
        let mut f = PoolFrames::new(ids, vec![0.028575; n], names, steps);
        for s in 0..steps {
            f.begin_step(s as i64, s as f64 * 0.01);
            for b in 0..n {
                let x = (s * 7 + b * 3 + seed as usize) as f64 * 0.001;
                let code = if b == 0 {
                    (s / 20 % 5) as u8
                } else {
                    ((s + b) % 5) as u8
                };
                f.ball(b, &[x, -x, 0.028575], &[x, 0.0, -0.0], &[0.0, x, 1.5], code);
            }
        }
        trace(id, f.into())
    }

    fn phyre(id: &str, steps: usize) -> TraceColumns {
        let body = |shape: &str, color, d, user| PhyreBody {
            shape: shape.into(),
            color,
            diameter: d,
            is_user_input: user,
        };
        let bodies = vec![
            body("wall", "black", 256.0, false),
            body("bar", "green", 40.0, false),
            body("wall", "black", 256.0, false),
            body("ball", "red", 20.0, true),
        ];
        let mut f = PhyreFrames::new(bodies, steps, steps * 4);
        for s in 0..steps {
            f.begin_step(s as i64, s as f64 / 60.0);
            // A body leaves after 10 steps: timesteps of different sizes.
            for b in 0..if s > 10 { 3 } else { 4 } {
                let v = (s + b) as f64;
                f.body(b, [v, v * 2.0, 0.1 * v, -v, 0.5, 0.0]);
            }
        }
        trace(id, f.into())
    }

    fn iphyre(id: &str, steps: usize) -> TraceColumns {
        let bodies = vec![
            IphyreBody {
                radius: 10.0,
                eliminable: 0.0,
                dynamic: 1.0,
                joint: 0,
                spring: 2,
            },
            IphyreBody {
                radius: 5.0,
                eliminable: 1.0,
                dynamic: 0.0,
                joint: 1,
                spring: 0,
            },
        ];
        let mut f = IphyreFrames::new(bodies, steps, steps * 2);
        for s in 0..steps {
            f.begin_step(s as i64, s as f64 / 60.0);
            for b in 0..2 {
                let v = (s * 2 + b) as f64;
                f.object(b, [v, 1.0], [v + 1.0, 2.0], 0.25, [v, -v], 0.0);
            }
        }
        trace(id, f.into())
    }

    /// Dictionary columns as plain strings (readers may cut dictionaries differently).
    fn plain(batch: &RecordBatch) -> Vec<ArrayRef> {
        batch
            .columns()
            .iter()
            .map(|c| match c.data_type() {
                DataType::Dictionary(..) => cast(c, &DataType::Utf8).unwrap(),
                _ => c.clone(),
            })
            .collect()
    }

    /// Writes `traces` with the column writer and with the record batches of
    /// [`TraceColumns::batches`]; the rows read back are the same, column by column.
    fn round_trip(traces: &[TraceColumns], settings: &ParquetSettings) {
        let dir = tempfile::tempdir().unwrap();
        let (fp, tp) = (dir.path().join("f.parquet"), dir.path().join("t.parquet"));
        let mut frames = ColumnSink::create(&fp, FRAMES.clone(), settings).unwrap();
        let mut steps = ColumnSink::create(&tp, TIMESTEPS.clone(), settings).unwrap();
        let (mut want_f, mut want_t) = (Vec::new(), Vec::new());
        for t in traces {
            let tables = t.tables("scene", "src").unwrap();
            frames.append(tables.frame_rows, &tables.frames).unwrap();
            steps
                .append(tables.timestep_rows, &tables.timesteps)
                .unwrap();
            let b = t.clone().batches("scene", "src").unwrap();
            assert_eq!(tables.traces, b.traces);
            assert_eq!(tables.events, b.events);
            want_f.push(b.frames);
            want_t.push(b.timesteps);
        }
        for (sink, path, want, schema) in [
            (frames, &fp, want_f, FRAMES.clone()),
            (steps, &tp, want_t, TIMESTEPS.clone()),
        ] {
            let rows = sink.rows();
            let (path2, n) = sink.commit().unwrap();
            assert_eq!((&path2, n), (path, rows));
            let got = read_file(path).unwrap();
            assert!(
                got.iter().all(|b| b.schema() == schema),
                "same Arrow schema"
            );
            let got = concat_batches(&schema, &got).unwrap();
            let want = concat_batches(&schema, &want).unwrap();
            assert_eq!(got.num_rows(), want.num_rows());
            for (i, (g, w)) in plain(&got).iter().zip(plain(&want)).enumerate() {
                assert_eq!(
                    g.as_ref(),
                    w.as_ref(),
                    "column {} of {}",
                    schema.field(i).name(),
                    path.display()
                );
            }
        }
    }

    #[test]
    fn every_environment_reads_back_the_rows_of_its_batches() {
        let small = ParquetSettings {
            row_group_rows: 37,
            ..ParquetSettings::default()
        };
        let pools = vec![
            pool("a", &["cue", "1", "9"], 50, 0),
            pool("b", &["cue", "1", "2", "9"], 30, 5),
            pool("c", &["9"], 3, 1),
        ];
        round_trip(&pools, &ParquetSettings::default());
        round_trip(&pools, &small);
        let phyres = vec![phyre("p1", 25), phyre("p2", 3)];
        round_trip(&phyres, &ParquetSettings::default());
        round_trip(&phyres, &small);
        let iphyres = vec![iphyre("i1", 40), iphyre("i2", 9)];
        round_trip(&iphyres, &ParquetSettings::default());
        round_trip(&iphyres, &small);
        // Each environment's own settings, as `simulate` writes its frames.
        round_trip(&pools, &ParquetSettings::for_frames(Some(Env::Pooltool)));
        round_trip(&phyres, &ParquetSettings::for_frames(Some(Env::Phyre)));
        round_trip(&iphyres, &ParquetSettings::for_frames(Some(Env::Iphyre)));
    }

    /// The compressed size of every column chunk of a frames file written with `settings`.
    fn chunk_sizes(traces: &[TraceColumns], settings: &ParquetSettings) -> Vec<(String, i64)> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.parquet");
        let mut sink = ColumnSink::create(&path, FRAMES.clone(), settings).unwrap();
        for t in traces {
            let tables = t.tables("s", "src").unwrap();
            sink.append(tables.frame_rows, &tables.frames).unwrap();
        }
        sink.commit().unwrap();
        let reader =
            parquet::file::reader::SerializedFileReader::new(File::open(&path).unwrap()).unwrap();
        use parquet::file::reader::FileReader;
        let group = reader.metadata().row_group(0).clone();
        group
            .columns()
            .iter()
            .map(|c| (c.column_path().string(), c.compressed_size()))
            .collect()
    }

    #[test]
    fn float_page_options_change_only_the_per_row_float_pages() {
        let traces = vec![pool("a", &["cue", "1", "2", "3", "9"], 2000, 0)];
        let default = chunk_sizes(&traces, &ParquetSettings::default());
        let billiards = chunk_sizes(&traces, &ParquetSettings::for_frames(Some(Env::Pooltool)));
        assert_eq!(
            ParquetSettings::for_frames(Some(Env::Phyre)),
            ParquetSettings::default()
        );
        assert_eq!(
            ParquetSettings::for_frames(Some(Env::Iphyre)),
            ParquetSettings::default()
        );
        let per_row = ["x", "y", "vx", "vy", "wx", "wy", "wz"];
        let mut changed = Vec::new();
        for ((name, a), (name_b, b)) in default.iter().zip(&billiards) {
            assert_eq!(name, name_b);
            if a != b {
                changed.push(name.as_str());
            }
        }
        assert!(!changed.is_empty(), "the options change some float pages");
        for name in &changed {
            assert!(
                per_row.contains(name),
                "{name} is not a per-row float column"
            );
        }
    }

    #[test]
    fn every_codec_and_label_statistics_read_back() {
        let traces = vec![
            pool("a", &["cue", "1", "9"], 40, 0),
            pool("b", &["cue"], 20, 2),
        ];
        for codec in [
            Codec::Zstd(1),
            Codec::Zstd(3),
            Codec::Lz4Raw,
            Codec::Snappy,
            Codec::None,
        ] {
            for label_stats in [false, true] {
                let settings = ParquetSettings {
                    codec,
                    label_stats,
                    row_group_rows: 64,
                    ..ParquetSettings::default()
                };
                round_trip(&traces, &settings);
            }
        }
    }

    #[test]
    fn trace_ids_have_chunk_statistics_and_labels_none() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.parquet");
        let settings = ParquetSettings {
            row_group_rows: 100,
            ..ParquetSettings::default()
        };
        let mut sink = ColumnSink::create(&path, FRAMES.clone(), &settings).unwrap();
        for (id, steps) in [("t2", 30), ("t1", 30), ("t3", 30)] {
            let t = pool(id, &["cue", "1"], steps, 0);
            let tables = t.tables("s", "src").unwrap();
            sink.append(tables.frame_rows, &tables.frames).unwrap();
        }
        sink.commit().unwrap();
        let reader =
            parquet::file::reader::SerializedFileReader::new(File::open(&path).unwrap()).unwrap();
        use parquet::file::reader::FileReader;
        let meta = reader.metadata();
        assert_eq!(meta.num_row_groups(), 2);
        let col = |g: usize, name: &str| {
            let i = FRAMES.index_of(name).unwrap();
            meta.row_group(g).column(i).statistics().cloned()
        };
        match col(0, "trace_id") {
            Some(Statistics::ByteArray(s)) => {
                assert_eq!(s.min_bytes_opt(), Some(&b"t1"[..]));
                assert_eq!(s.max_bytes_opt(), Some(&b"t2"[..]));
            }
            other => panic!("trace_id statistics: {other:?}"),
        }
        assert!(col(0, "object_id").is_none());
        match col(0, "slot") {
            Some(Statistics::Int32(s)) => {
                assert_eq!((s.min_opt(), s.max_opt()), (Some(&0), Some(&1)));
            }
            other => panic!("slot statistics: {other:?}"),
        }
        match col(0, "diameter") {
            Some(s) => assert_eq!(s.null_count_opt(), Some(100)),
            None => panic!("diameter has statistics"),
        }
    }

    #[test]
    fn views_that_do_not_fit_the_schema_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.parquet");
        let mut sink =
            ColumnSink::create(&path, TIMESTEPS.clone(), &ParquetSettings::default()).unwrap();
        let t = pool("a", &["cue"], 4, 0);
        let tables = t.tables("s", "src").unwrap();
        // Frames' views for the timesteps table: wrong count.
        let err = sink.append(tables.frame_rows, &tables.frames).unwrap_err();
        assert!(err.to_string().contains("column views"), "{err}");
        let mut views = tables.timesteps.clone();
        views[1] = ColumnView::Null;
        let err = sink.append(tables.timestep_rows, &views).unwrap_err();
        assert!(format!("{err}").contains("step"), "{err}");
        views[1] = ColumnView::F64(std::borrow::Cow::Owned(vec![0.0; 4]));
        let err = sink.append(4, &views).unwrap_err();
        assert!(format!("{err}").contains("F64"), "{err}");
        views = tables.timesteps.clone();
        let err = sink.append(3, &views).unwrap_err();
        assert!(format!("{err}").contains("4 values for 3 rows"), "{err}");
    }

    #[test]
    fn float_ranges_leave_nan_out_and_sign_zeros() {
        assert_eq!(float_range(&[]), None);
        assert_eq!(float_range(&[f64::NAN; 11]), None);
        let v: Vec<f64> = (0..21).map(|i| f64::from(i) - 7.5).collect();
        assert_eq!(float_range(&v), Some((-7.5, 12.5)));
        let mut w = v.clone();
        w[3] = f64::NAN;
        w[20] = f64::NAN;
        assert_eq!(float_range(&w), Some((-7.5, 11.5)));
        let (lo, hi) = float_range(&[0.0, 0.0, -0.0]).unwrap();
        assert!(lo == 0.0 && lo.is_sign_negative() && hi.is_sign_positive());
        assert_eq!(
            float_range(&[f64::INFINITY]),
            Some((f64::INFINITY, f64::INFINITY))
        );
        assert_eq!(
            float_range(&[f64::NEG_INFINITY, 1.0]),
            Some((f64::NEG_INFINITY, 1.0))
        );
    }

    #[test]
    fn hybrid_runs_cover_every_value() {
        // Lengths of the encoding for a few patterns: RLE runs of 8+ equal values, bit-packed
        // groups otherwise (decoding is checked by the round trips above).
        let mut out = Vec::new();
        hybrid(&[3; 100], 2, &mut out);
        assert_eq!(out, [200, 1, 3]);
        out.clear();
        hybrid(&[0, 1, 2, 3, 0, 1, 2, 3], 2, &mut out);
        assert_eq!(out, [3, 0b11_10_01_00, 0b11_10_01_00]);
        out.clear();
        hybrid(&[1, 2, 3], 2, &mut out);
        assert_eq!(out, [3, 0b11_10_01, 0]);
    }

    #[test]
    fn narrow_groups_pack_as_bit_by_bit() {
        // Every width the one-word path takes, on group counts with and without a remainder, and
        // values that fill their width; the bit-by-bit packer is the reference.
        let mut rng = crate::rng::SplitMix64::new(7);
        for width in 0..=8u8 {
            for len in [0usize, 1, 7, 8, 9, 63 * 8, 63 * 8 + 5, 1000] {
                let values: Vec<u32> = (0..len).map(|_| rng.below(1 << width) as u32).collect();
                let (mut fast, mut slow) = (Vec::new(), Vec::new());
                pack_groups_narrow(&values, width, &mut fast);
                pack_groups(&values, width, &mut slow);
                assert_eq!(fast, slow, "width {width}, {len} values");
                assert_eq!(fast.len(), len.div_ceil(8) * usize::from(width));
            }
        }
    }
}
