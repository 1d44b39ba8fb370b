//! Writing Parquet tables: one set of writer properties and the column builders that the
//! pulse, waveform and photon files share.

use crate::error::{Error, Result};
use crate::fsutil::write_atomic;
use arrow_array::builder::{Float32Builder, Float64Builder, ListBuilder};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::properties::WriterProperties;
use std::path::Path;
use std::sync::Arc;

pub fn props() -> WriterProperties {
    WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::default()))
        .set_created_by(format!("lidarsim {}", env!("CARGO_PKG_VERSION")))
        .build()
}

pub fn write_batch(path: &Path, batch: RecordBatch) -> Result<()> {
    write_atomic(path, |file| {
        let err = |e: parquet::errors::ParquetError| Error::io(path, "cannot write Parquet", e);
        let mut w = ArrowWriter::try_new(file, batch.schema(), Some(props())).map_err(err)?;
        w.write(&batch).map_err(err)?;
        w.close().map_err(err)?;
        Ok(())
    })
}

pub fn list_f32(rows: impl Iterator<Item = Vec<f32>>) -> ArrayRef {
    let mut b = ListBuilder::new(Float32Builder::new()).with_field(Field::new(
        "item",
        DataType::Float32,
        false,
    ));
    for r in rows {
        b.values().append_slice(&r);
        b.append(true);
    }
    Arc::new(b.finish())
}

pub fn list_f64(rows: impl Iterator<Item = Vec<f64>>) -> ArrayRef {
    let mut b = ListBuilder::new(Float64Builder::new()).with_field(Field::new(
        "item",
        DataType::Float64,
        false,
    ));
    for r in rows {
        b.values().append_slice(&r);
        b.append(true);
    }
    Arc::new(b.finish())
}

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
