//! Writing Parquet tables: one set of writer properties and the column builders that the
//! pulse, waveform and photon files share.

use crate::error::{Error, Result};
use crate::fsutil::Pending;
use arrow_array::builder::{Float32Builder, Float64Builder, ListBuilder};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::schema::types::ColumnPath;
use std::path::Path;
use std::sync::Arc;

/// How a Parquet file is encoded. Every file lidarsim writes uses [`ENCODING`]; the others
/// exist to be measured against it (`lidarsim bench`, "Writing waveform parts").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Encoding {
    pub name: &'static str,
    /// Dictionary pages: they pay only for repeated values, which float waveforms rarely have.
    pub dictionary: bool,
    /// Min/max statistics on every column, per page (true) or on `pulse_id` alone, per
    /// column chunk (false): a reader selects pulses by id, never by a bin's value.
    pub all_statistics: bool,
    /// zstd level, or None for no compression.
    pub zstd: Option<i32>,
    /// BYTE_STREAM_SPLIT for the columns (floats compress better with their bytes grouped).
    pub byte_stream_split: bool,
}

/// The encoding of every file lidarsim writes, chosen by measurement (`lidarsim bench`,
/// "Writing waveform parts", sets it against the others): no dictionary, statistics on
/// `pulse_id` only, zstd level 1.
pub const ENCODING: Encoding = Encoding {
    name: "no dictionary, pulse_id statistics, zstd 1",
    dictionary: false,
    all_statistics: false,
    zstd: Some(1),
    byte_stream_split: false,
};

/// The encodings `lidarsim bench` compares, the chosen one among them.
pub const CANDIDATES: [Encoding; 6] = [
    Encoding {
        name: "parquet defaults (dictionary, page statistics), zstd 1",
        dictionary: true,
        all_statistics: true,
        zstd: Some(1),
        byte_stream_split: false,
    },
    Encoding {
        name: "no dictionary, page statistics, zstd 1",
        dictionary: false,
        all_statistics: true,
        zstd: Some(1),
        byte_stream_split: false,
    },
    ENCODING,
    Encoding {
        name: "no dictionary, pulse_id statistics, zstd 3",
        zstd: Some(3),
        ..ENCODING
    },
    Encoding {
        name: "no dictionary, pulse_id statistics, byte stream split, zstd 1",
        byte_stream_split: true,
        ..ENCODING
    },
    Encoding {
        name: "no dictionary, pulse_id statistics, uncompressed",
        zstd: None,
        ..ENCODING
    },
];

/// Rows per row group: a writer holds one row group in memory, so this bounds what writing
/// a long plan or many photons costs (Parquet's default is 1 Mi rows).
pub const ROW_GROUP_ROWS: usize = 1 << 16;

impl Encoding {
    pub fn props(&self) -> WriterProperties {
        let mut b = WriterProperties::builder()
            .set_created_by(format!("lidarsim {}", env!("CARGO_PKG_VERSION")))
            .set_max_row_group_row_count(Some(ROW_GROUP_ROWS))
            .set_dictionary_enabled(self.dictionary)
            .set_compression(match self.zstd {
                Some(level) => Compression::ZSTD(ZstdLevel::try_new(level).unwrap_or_default()),
                None => Compression::UNCOMPRESSED,
            });
        if !self.all_statistics {
            b = b
                .set_statistics_enabled(EnabledStatistics::None)
                .set_column_statistics_enabled(
                    ColumnPath::from("pulse_id"),
                    EnabledStatistics::Chunk,
                );
        }
        if self.byte_stream_split {
            b = b.set_encoding(parquet::basic::Encoding::BYTE_STREAM_SPLIT);
        }
        b.build()
    }
}

pub fn props() -> WriterProperties {
    ENCODING.props()
}

/// Encodes a table as a whole Parquet file in memory.
pub fn encode(batch: &RecordBatch, props: WriterProperties) -> parquet::errors::Result<Vec<u8>> {
    let mut w = ArrowWriter::try_new(Vec::new(), batch.schema(), Some(props))?;
    w.write(batch)?;
    w.into_inner()
}

pub fn write_batch(path: &Path, batch: RecordBatch) -> Result<()> {
    let mut sink = Sink::create(path, batch.schema())?;
    sink.write(&batch)?;
    sink.finish()
}

/// A Parquet file written a batch at a time (row groups of [`ROW_GROUP_ROWS`]), under its
/// temporary name until [`Sink::finish`].
pub struct Sink {
    writer: ArrowWriter<std::fs::File>,
    pending: Pending,
    path: std::path::PathBuf,
}

impl Sink {
    pub fn create(path: &Path, schema: arrow_schema::SchemaRef) -> Result<Sink> {
        let (pending, file) = Pending::create(path)?;
        let writer = ArrowWriter::try_new(file, schema, Some(props()))
            .map_err(|e| parquet_error(path, e))?;
        Ok(Sink {
            writer,
            pending,
            path: path.to_path_buf(),
        })
    }

    pub fn write(&mut self, batch: &RecordBatch) -> Result<()> {
        self.writer
            .write(batch)
            .map_err(|e| parquet_error(&self.path, e))
    }

    pub fn finish(self) -> Result<()> {
        self.writer
            .close()
            .map_err(|e| parquet_error(&self.path, e))?;
        self.pending.commit()
    }
}

fn parquet_error(path: &Path, e: parquet::errors::ParquetError) -> Error {
    Error::io(path, "cannot write Parquet", e).advise(crate::fsutil::WRITE_ADVICE)
}

/// A float column where NaN, "no meaning for this pulse or run", is stored as null.
pub fn f32_or_null(values: impl Iterator<Item = f32>) -> ArrayRef {
    Arc::new(arrow_array::Float32Array::from_iter(
        values.map(|v| (!v.is_nan()).then_some(v)),
    ))
}

/// A list column from borrowed rows, its buffers sized once: no row is copied but into the
/// column (cloning each row first, and growing the buffer by doubling, costs a measurable
/// share of the wall time of a simulate stage writing long waveforms).
pub fn list_f32<'a>(rows: impl Iterator<Item = &'a [f32]> + Clone) -> ArrayRef {
    let (n, total) = rows.clone().fold((0, 0), |(n, t), r| (n + 1, t + r.len()));
    let mut b = ListBuilder::with_capacity(Float32Builder::with_capacity(total), n)
        .with_field(Field::new("item", DataType::Float32, false));
    for r in rows {
        b.values().append_slice(r);
        b.append(true);
    }
    Arc::new(b.finish())
}

pub fn list_f64<'a>(rows: impl Iterator<Item = &'a [f64]> + Clone) -> ArrayRef {
    let (n, total) = rows.clone().fold((0, 0), |(n, t), r| (n + 1, t + r.len()));
    let mut b = ListBuilder::with_capacity(Float64Builder::with_capacity(total), n)
        .with_field(Field::new("item", DataType::Float64, false));
    for r in rows {
        b.values().append_slice(r);
        b.append(true);
    }
    Arc::new(b.finish())
}

/// A batch whose columns are nullable where they hold a null.
pub fn batch(columns: Vec<(&str, ArrayRef)>) -> RecordBatch {
    let fields: Vec<Field> = columns
        .iter()
        .map(|(n, a)| Field::new(*n, a.data_type().clone(), a.null_count() > 0))
        .collect();
    RecordBatch::try_new(
        Arc::new(Schema::new(fields)),
        columns.into_iter().map(|(_, a)| a).collect(),
    )
    .expect("columns of one batch have equal lengths")
}

/// A column of a [`Table`], borrowed from the rows that hold it.
pub enum Column<'a> {
    U64(Vec<u64>),
    U32(Vec<u32>),
    F64(Vec<f64>),
    F32(Vec<f32>),
    /// NaN, "no meaning for this row", stored as null; the column is always nullable so that
    /// every part of a run has the same schema.
    F32OrNull(Vec<f32>),
    ListF32(Vec<&'a [f32]>),
    ListF64(Vec<&'a [f64]>),
}

impl Column<'_> {
    fn len(&self) -> usize {
        match self {
            Column::U64(v) => v.len(),
            Column::U32(v) => v.len(),
            Column::F64(v) => v.len(),
            Column::F32(v) | Column::F32OrNull(v) => v.len(),
            Column::ListF32(v) => v.len(),
            Column::ListF64(v) => v.len(),
        }
    }

    fn to_arrow(&self) -> ArrayRef {
        use arrow_array::{Float32Array, Float64Array, UInt32Array, UInt64Array};
        match self {
            Column::U64(v) => Arc::new(UInt64Array::from(v.clone())),
            Column::U32(v) => Arc::new(UInt32Array::from(v.clone())),
            Column::F64(v) => Arc::new(Float64Array::from(v.clone())),
            Column::F32(v) => Arc::new(Float32Array::from(v.clone())),
            Column::F32OrNull(v) => f32_or_null(v.iter().copied()),
            Column::ListF32(v) => list_f32(v.iter().copied()),
            Column::ListF64(v) => list_f64(v.iter().copied()),
        }
    }

    /// Writes rows `rows` through Parquet's column writer: values straight from their
    /// slices, where Arrow's writer would first list every value's index (8 bytes per bin),
    /// then gather the values by index (together a large share of a simulate stage's CPU on
    /// long gates).
    /// Lists concatenate into `buf` with their levels, so the writer splits pages where
    /// Arrow's does and the bytes are the same ([`Table::encode_with_arrow`]).
    fn write(
        &self,
        rows: std::ops::Range<usize>,
        col: &mut parquet::file::writer::SerializedColumnWriter<'_>,
        buf: &mut ListBuffers,
        batch: usize,
    ) -> parquet::errors::Result<()> {
        use parquet::data_type::{DoubleType, FloatType, Int32Type, Int64Type};
        match self {
            // unsigned integers are stored as their bits, as Arrow's writer stores them
            Column::U64(v) => {
                let bits: Vec<i64> = v[rows].iter().map(|&x| x as i64).collect();
                col.typed::<Int64Type>().write_batch(&bits, None, None)?;
            }
            Column::U32(v) => {
                let bits: Vec<i32> = v[rows].iter().map(|&x| x as i32).collect();
                col.typed::<Int32Type>().write_batch(&bits, None, None)?;
            }
            Column::F64(v) => {
                col.typed::<DoubleType>()
                    .write_batch(&v[rows], None, None)?;
            }
            Column::F32(v) => {
                col.typed::<FloatType>().write_batch(&v[rows], None, None)?;
            }
            Column::F32OrNull(v) => {
                let v = &v[rows];
                let def: Vec<i16> = v.iter().map(|x| i16::from(!x.is_nan())).collect();
                let present: Vec<f32> = v.iter().copied().filter(|x| !x.is_nan()).collect();
                col.typed::<FloatType>()
                    .write_batch(&present, Some(&def), None)?;
            }
            Column::ListF32(v) => {
                let ListBuffers { f32, def, rep, .. } = buf;
                write_list(col.typed::<FloatType>(), &v[rows], batch, f32, def, rep)?;
            }
            Column::ListF64(v) => {
                let ListBuffers { f64, def, rep, .. } = buf;
                write_list(col.typed::<DoubleType>(), &v[rows], batch, f64, def, rep)?;
            }
        }
        Ok(())
    }
}

/// The values and levels of a list column's rows, reused from column to column.
#[derive(Default)]
struct ListBuffers {
    f32: Vec<f32>,
    f64: Vec<f64>,
    def: Vec<i16>,
    rep: Vec<i16>,
}

/// Writes a list column's rows. Parquet's writer cuts the levels it is given into
/// mini-batches of `batch` levels, each grown to the end of its last row, and checks the page
/// size after each: the rows are handed over in exactly those mini-batches, a row that fills
/// one alone straight from its slice (a waveform of 1024 bins or more), shorter rows
/// concatenated into `values`, so that pages end where Arrow's writer ends them.
fn write_list<T: parquet::data_type::DataType>(
    w: &mut parquet::column::writer::ColumnWriterImpl<'_, T>,
    rows: &[&[T::T]],
    batch: usize,
    values: &mut Vec<T::T>,
    def: &mut Vec<i16>,
    rep: &mut Vec<i16>,
) -> parquet::errors::Result<()>
where
    T::T: Copy,
{
    let mut start = 0;
    let mut levels = 0;
    for (k, r) in rows.iter().enumerate() {
        levels += r.len().max(1);
        if levels < batch && k + 1 < rows.len() {
            continue;
        }
        let group = &rows[start..=k];
        set_levels(group.iter().map(|r| r.len()), def, rep);
        if let [one] = group {
            w.write_batch(one, Some(def), Some(rep))?;
        } else {
            values.clear();
            for r in group {
                values.extend_from_slice(r);
            }
            w.write_batch(values, Some(def), Some(rep))?;
        }
        (start, levels) = (k + 1, 0);
    }
    Ok(())
}

/// The levels of a required list of required items with rows of `lens` values: a row
/// starts at repetition level 0; an empty row is one level, defined to 0.
fn set_levels(lens: impl Iterator<Item = usize>, def: &mut Vec<i16>, rep: &mut Vec<i16>) {
    def.clear();
    rep.clear();
    for n in lens {
        if n == 0 {
            def.push(0);
            rep.push(0);
        } else {
            def.resize(def.len() + n, 1);
            rep.push(0);
            rep.resize(rep.len() + n - 1, 1);
        }
    }
}

/// A table of named columns: written straight through Parquet's column writers
/// ([`Table::write`]), or made into an Arrow batch for Arrow's writer (the same bytes).
pub struct Table<'a> {
    pub columns: Vec<(&'static str, Column<'a>)>,
}

impl Table<'_> {
    pub fn rows(&self) -> usize {
        self.columns.first().map_or(0, |(_, c)| c.len())
    }

    pub fn batch(&self) -> RecordBatch {
        let arrays = self.columns.iter().map(|(_, c)| c.to_arrow()).collect();
        RecordBatch::try_new(self.batch_schema(), arrays)
            .expect("columns of one table have equal lengths")
    }

    /// Encodes the table into `sink` as Arrow's writer would (its schema, its metadata, row
    /// groups of [`ROW_GROUP_ROWS`]), without building Arrow arrays.
    pub fn encode<W: std::io::Write + Send>(
        &self,
        sink: W,
        mut props: WriterProperties,
    ) -> parquet::errors::Result<W> {
        let schema = self.batch_schema();
        let descr = parquet::arrow::ArrowSchemaConverter::new()
            .with_coerce_types(props.coerce_types())
            .convert(&schema)?;
        parquet::arrow::add_encoded_arrow_schema_to_metadata(&schema, &mut props);
        let group_rows = props.max_row_group_row_count().unwrap_or(usize::MAX).max(1);
        let batch = props.write_batch_size();
        let mut file = parquet::file::writer::SerializedFileWriter::new(
            sink,
            descr.root_schema_ptr(),
            Arc::new(props),
        )?;
        let mut buf = ListBuffers::default();
        let mut start = 0;
        while start < self.rows() {
            let end = self.rows().min(start.saturating_add(group_rows));
            let mut group = file.next_row_group()?;
            for (name, c) in &self.columns {
                let mut col = group.next_column()?.ok_or_else(|| {
                    parquet::errors::ParquetError::General(format!("no column for {name}"))
                })?;
                c.write(start..end, &mut col, &mut buf, batch)?;
                col.close()?;
            }
            group.close()?;
            start = end;
        }
        file.into_inner()
    }

    /// The same table through Arrow's writer: what [`Table::encode`] must equal, byte for
    /// byte, and the encodings `lidarsim bench` compares.
    pub fn encode_with_arrow(&self, props: WriterProperties) -> parquet::errors::Result<Vec<u8>> {
        encode(&self.batch(), props)
    }

    /// Writes the table as a Parquet file with lidarsim's encoding, under its temporary name
    /// until it is whole.
    pub fn write(&self, path: &Path) -> Result<()> {
        self.write_pending(path)?.commit()
    }

    /// [`Table::write`] but for the commit, which is the caller's.
    pub fn write_pending(&self, path: &Path) -> Result<Pending> {
        let (pending, file) = Pending::create(path)?;
        self.encode(file, props())
            .map_err(|e| parquet_error(path, e))?;
        Ok(pending)
    }

    fn batch_schema(&self) -> arrow_schema::SchemaRef {
        let item = |t: DataType| DataType::List(Arc::new(Field::new("item", t, false)));
        let fields: Vec<Field> = self
            .columns
            .iter()
            .map(|(n, c)| {
                let (t, nullable) = match c {
                    Column::U64(_) => (DataType::UInt64, false),
                    Column::U32(_) => (DataType::UInt32, false),
                    Column::F64(_) => (DataType::Float64, false),
                    Column::F32(_) => (DataType::Float32, false),
                    Column::F32OrNull(_) => (DataType::Float32, true),
                    Column::ListF32(_) => (item(DataType::Float32), false),
                    Column::ListF64(_) => (item(DataType::Float64), false),
                };
                Field::new(*n, t, nullable)
            })
            .collect();
        Arc::new(Schema::new(fields))
    }
}

/// The leaf of column `name` when it is a list of floats laid out as [`Table`] writes it (a
/// required list of required items: definition and repetition levels at most 1), else None.
pub fn f32_list_leaf(
    schema: &parquet::schema::types::SchemaDescriptor,
    name: &str,
) -> Option<usize> {
    schema.columns().iter().position(|c| {
        c.path().parts().first().map(String::as_str) == Some(name)
            && c.physical_type() == parquet::basic::Type::FLOAT
            && c.max_def_level() == 1
            && c.max_rep_level() == 1
    })
}

/// Every row of the list columns at `leaves` (see [`f32_list_leaf`]) of a Parquet file, given
/// to `each` as (index into `leaves`, row, values), column after column, straight from the
/// pages: Arrow's reader grows each batch's buffers by doubling, then each row is copied out
/// of them again (most of a products stage reading long waveforms).
pub fn read_f32_lists(
    file: &std::fs::File,
    leaves: &[usize],
    mut each: impl FnMut(usize, usize, &[f32]),
) -> parquet::errors::Result<()> {
    use parquet::file::reader::FileReader;
    let reader = parquet::file::reader::SerializedFileReader::new(file.try_clone()?)?;
    let (mut def, mut rep, mut values) = (Vec::new(), Vec::new(), Vec::<f32>::new());
    // rows of the row groups before
    let mut done = 0usize;
    for g in 0..reader.num_row_groups() {
        let group = reader.get_row_group(g)?;
        let rows = usize::try_from(group.metadata().num_rows()).unwrap_or(0);
        for (k, &leaf) in leaves.iter().enumerate() {
            if leaf >= group.metadata().num_columns() {
                return Err(parquet::errors::ParquetError::General(format!(
                    "row group {g} has no column {leaf}"
                )));
            }
            // a reservation, not a promise: a damaged footer must not ask for the moon
            let levels = usize::try_from(group.metadata().column(leaf).num_values())
                .unwrap_or(0)
                .min(1 << 26);
            for levels_or_values in [&mut def, &mut rep] {
                levels_or_values.clear();
                levels_or_values.reserve(levels);
            }
            values.clear();
            values.reserve(levels);
            let mut column = parquet::column::reader::get_typed_column_reader::<
                parquet::data_type::FloatType,
            >(group.get_column_reader(leaf)?);
            let mut read = 0;
            while read < rows {
                let (records, _, _) = column.read_records(
                    rows - read,
                    Some(&mut def),
                    Some(&mut rep),
                    &mut values,
                )?;
                if records == 0 {
                    break;
                }
                read += records;
            }
            if read != rows || def.len() != rep.len() {
                return Err(parquet::errors::ParquetError::General(format!(
                    "column {leaf} holds {read} of its {rows} rows"
                )));
            }
            // a row starts at repetition level 0 and holds a value per level, or is empty:
            // one level, defined to 0 (the items are required, so no other level is null)
            let (mut at, mut k_level, mut row) = (0, 0, done);
            while k_level < rep.len() {
                let end = k_level
                    + 1
                    + rep[k_level + 1..]
                        .iter()
                        .position(|&r| r == 0)
                        .unwrap_or(rep.len() - k_level - 1);
                let n = if def[k_level] == 1 { end - k_level } else { 0 };
                let values = values.get(at..at + n).ok_or_else(|| {
                    parquet::errors::ParquetError::General(format!("column {leaf} ends early"))
                })?;
                each(k, row, values);
                (at, k_level, row) = (at + n, end, row + 1);
            }
        }
        done += rows;
    }
    Ok(())
}

/// Picks the rows of a batch to keep (None: all of them).
pub type RowFilter<'a> = dyn Fn(&RecordBatch) -> Option<arrow_array::BooleanArray> + 'a;

/// Every row of a Parquet file as Arrow batches, with the schema (the whole file: tables the
/// user asks for, not the stages' streaming reads). `keep` picks rows from each batch when
/// given.
pub fn read_batches(
    path: &Path,
    keep: Option<&RowFilter>,
) -> Result<(arrow_schema::SchemaRef, Vec<RecordBatch>)> {
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let bad = |e: &dyn std::fmt::Display| {
        Error::data(path, format!("not a readable Parquet file: {e}"))
            .advise("run the stage that writes it again")
    };
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, "cannot open", e))?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)
        .map_err(|e| bad(&e))?
        .with_batch_size(65_536)
        .build()
        .map_err(|e| bad(&e))?;
    let schema = arrow_array::RecordBatchReader::schema(&reader);
    let mut batches = Vec::new();
    for b in reader {
        let b = b.map_err(|e| bad(&e))?;
        let b = match keep.and_then(|k| k(&b)) {
            Some(mask) => {
                arrow_select::filter::filter_record_batch(&b, &mask).map_err(|e| bad(&e))?
            }
            None => b,
        };
        if b.num_rows() > 0 {
            batches.push(b);
        }
    }
    Ok((schema, batches))
}

#[cfg(test)]
mod tests {
    use super::*;
    use parquet::file::reader::{FileReader, SerializedFileReader};

    /// The files get the chosen encoding: no dictionary page on any column, statistics on
    /// `pulse_id` and nowhere else, zstd.
    #[test]
    fn files_carry_the_chosen_encoding() {
        let ids: ArrayRef = Arc::new(arrow_array::UInt64Array::from(vec![7u64, 8, 9]));
        let rows: Vec<Vec<f32>> = (0..3).map(|k| vec![0.0, k as f32, 0.0, 0.0]).collect();
        let lists = list_f32(rows.iter().map(|r| r.as_slice()));
        let b = batch(vec![("pulse_id", ids), ("laser_photons", lists)]);
        let reader = |bytes: Vec<u8>, name: &str| {
            let path = std::env::temp_dir().join(format!("lidarsim_{}_{name}", std::process::id()));
            std::fs::write(&path, bytes).unwrap();
            let r = SerializedFileReader::new(std::fs::File::open(&path).unwrap()).unwrap();
            let _ = std::fs::remove_file(&path);
            r
        };
        let r = reader(encode(&b, props()).unwrap(), "chosen.parquet");
        let rg = r.metadata().row_group(0);
        for c in rg.columns() {
            let name = c.column_path().string();
            assert!(
                c.dictionary_page_offset().is_none(),
                "{name} has a dictionary"
            );
            assert_eq!(
                c.compression(),
                Compression::ZSTD(ZstdLevel::try_new(1).unwrap())
            );
            assert_eq!(c.statistics().is_some(), name == "pulse_id", "{name}");
        }
        // and Parquet's defaults would have put a dictionary on the list
        let r = reader(
            encode(&b, CANDIDATES[0].props()).unwrap(),
            "defaults.parquet",
        );
        assert!(r
            .metadata()
            .row_group(0)
            .columns()
            .iter()
            .any(|c| c.dictionary_page_offset().is_some()));
    }

    /// The column writer writes the bytes Arrow's writer writes: long rows (written one at a
    /// time), short and empty rows (concatenated), nulls, unsigned integers, several row
    /// groups, and under every candidate encoding.
    #[test]
    fn columns_write_the_bytes_arrow_writes() {
        let mut rng = crate::rng::SplitMix64::new(11);
        let n = ROW_GROUP_ROWS + 300;
        let long: Vec<Vec<f32>> = (0..40)
            .map(|i| {
                let len = 1024 + 97 * i;
                (0..len)
                    .map(|k| {
                        if k % 7 == 0 {
                            rng.uniform() as f32
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
            .collect();
        let short: Vec<Vec<f64>> = (0..n).map(|i| vec![i as f64 * 0.5; i % 6]).collect();
        let mixed: Vec<&[f32]> = (0..n)
            .map(|i| match i % 3 {
                0 if i < 120 => long[i % long.len()].as_slice(),
                1 => &long[i % long.len()][..i % 50],
                _ => &[][..],
            })
            .collect();
        let table = |rows: usize| Table {
            columns: vec![
                (
                    "pulse_id",
                    Column::U64((0..rows as u64).map(|i| u64::MAX - i).collect()),
                ),
                (
                    "t0_ns",
                    Column::F64((0..rows).map(|i| i as f64 * 1e-3).collect()),
                ),
                ("mixed", Column::ListF32(mixed[..rows].to_vec())),
                (
                    "short",
                    Column::ListF64(short[..rows].iter().map(|r| r.as_slice()).collect()),
                ),
                (
                    "brf",
                    Column::F32OrNull(
                        (0..rows)
                            .map(|i| if i % 5 == 0 { f32::NAN } else { i as f32 })
                            .collect(),
                    ),
                ),
                (
                    "rays",
                    Column::U32((0..rows as u32).map(|i| u32::MAX - i).collect()),
                ),
                ("bin_ns", Column::F32(vec![0.5; rows])),
            ],
        };
        let long_only = Table {
            columns: vec![
                ("pulse_id", Column::U64((0..40).collect())),
                (
                    "laser_photons",
                    Column::ListF32(long.iter().map(|r| r.as_slice()).collect()),
                ),
            ],
        };
        for (name, t) in [
            ("long rows", long_only),
            ("mixed rows, two row groups", table(n)),
            ("no rows", table(0)),
        ] {
            for e in CANDIDATES {
                let arrow = t.encode_with_arrow(e.props()).unwrap();
                let ours = t.encode(Vec::new(), e.props()).unwrap();
                assert!(
                    arrow == ours,
                    "{name}, {}: {} bytes against Arrow's {}",
                    e.name,
                    ours.len(),
                    arrow.len()
                );
            }
        }
    }
}
