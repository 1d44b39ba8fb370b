//! The mission files' writers: `waveforms_l1b.h5` from the instrument's records of the first
//! band, `photons_atl03.h5` from its photon events.

use super::part::{Part, Writer};
use crate::error::Result;
use crate::plan::Plan;
use crate::products::mission::{Atl03, L1b, ATL03_FILE, L1B_FILE};
use crate::products::report::summary::ProductsSummary;
use crate::waveform::record::Recorder;
use rayon::prelude::*;

pub(super) struct L1bWriter<'a> {
    pub file: L1b,
    pub recorder: Recorder,
    pub plan: &'a Plan,
}

impl Writer for L1bWriter<'_> {
    fn add(&mut self, part: &Part) -> Result<()> {
        let records: Vec<_> = part
            .first
            .par_iter()
            .map(|w| self.recorder.record(w))
            .collect();
        for (w, r) in part.first.iter().zip(&records) {
            self.file.add(&self.plan.pulse(w.pulse_id), w, r)?;
        }
        Ok(())
    }

    fn finish(self: Box<Self>, _: &mut ProductsSummary) -> Result<Vec<String>> {
        self.file.finish()?;
        Ok(vec![L1B_FILE.to_string()])
    }
}

pub(super) struct Atl03Writer<'a> {
    pub file: Atl03,
    pub plan: &'a Plan,
}

impl Writer for Atl03Writer<'_> {
    fn add(&mut self, part: &Part) -> Result<()> {
        for rows in part
            .first_photons()
            .chunk_by(|a, b| a.pulse_id == b.pulse_id)
        {
            self.file.add(&self.plan.pulse(rows[0].pulse_id), rows)?;
        }
        Ok(())
    }

    fn finish(self: Box<Self>, _: &mut ProductsSummary) -> Result<Vec<String>> {
        self.file.finish()?;
        Ok(vec![ATL03_FILE.to_string()])
    }
}
