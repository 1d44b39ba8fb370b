//! The photons writer: `photons.parquet` written a part at a time, and its counts by source.

use super::part::{Part, Writer};
use crate::error::Result;
use crate::parquet_io::Sink;
use crate::products::photons::{photon_table, PhotonRow};
use crate::products::report::summary::{PhotonCounts, ProductsSummary};
use std::path::PathBuf;

pub(super) const PHOTONS_FILE: &str = "photons.parquet";

pub(super) struct PhotonsWriter {
    path: PathBuf,
    /// With several bands the table has a `wavelength_nm` column.
    bands: bool,
    pulses: usize,
    sink: Option<Sink>,
    /// Rows by source: laser, solar, dark.
    by_source: [usize; 3],
    total: usize,
}

impl PhotonsWriter {
    pub fn new(path: PathBuf, bands: bool, pulses: usize) -> PhotonsWriter {
        PhotonsWriter {
            path,
            bands,
            pulses,
            sink: None,
            by_source: [0; 3],
            total: 0,
        }
    }

    fn write(&mut self, rows: &[PhotonRow]) -> Result<()> {
        let table = photon_table(rows, self.bands);
        let sink = match &mut self.sink {
            Some(s) => s,
            None => self.sink.insert(Sink::create(&self.path, table.schema())?),
        };
        sink.write(&table)?;
        for r in rows {
            if let Some(n) = self.by_source.get_mut(r.source as usize) {
                *n += 1;
            }
        }
        self.total += rows.len();
        Ok(())
    }
}

impl Writer for PhotonsWriter {
    fn add(&mut self, part: &Part) -> Result<()> {
        self.write(part.photons)
    }

    fn finish(mut self: Box<Self>, summary: &mut ProductsSummary) -> Result<Vec<String>> {
        if self.sink.is_none() {
            self.write(&[])?;
        }
        if let Some(s) = self.sink.take() {
            s.finish()?;
        }
        let [laser, solar, dark] = self.by_source;
        summary.photons = Some(PhotonCounts {
            total: self.total,
            laser,
            solar,
            dark,
            laser_per_shot: laser as f64 / self.pulses.max(1) as f64,
        });
        Ok(vec![PHOTONS_FILE.to_string()])
    }
}
