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

/// The encoding of every file lidarsim writes, chosen by measurement (README, "Writing
/// waveform parts"): no dictionary, statistics on `pulse_id` only, zstd level 1.
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
/// column (cloning each row first, and growing the buffer by doubling, cost 7 % of the wall
/// time of a simulate stage writing 3152-bin waveforms).
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

pub fn batch(columns: Vec<(&str, ArrayRef)>) -> RecordBatch {
    batch_nullable(columns, &[])
}

/// A batch whose `nullable` columns are declared nullable whether or not this batch holds a
/// null, so every part of a run has the same schema.
pub fn batch_nullable(columns: Vec<(&str, ArrayRef)>, nullable: &[&str]) -> RecordBatch {
    let fields: Vec<Field> = columns
        .iter()
        .map(|(n, a)| {
            Field::new(
                *n,
                a.data_type().clone(),
                a.null_count() > 0 || nullable.contains(n),
            )
        })
        .collect();
    RecordBatch::try_new(
        Arc::new(Schema::new(fields)),
        columns.into_iter().map(|(_, a)| a).collect(),
    )
    .expect("columns of one batch have equal lengths")
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
}
