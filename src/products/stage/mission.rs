//! The mission files' writers: `waveforms_l1b.h5` and `waveforms_l2a.h5` from the instrument's
//! records of the first band, `photons_atl03.h5` from its photon events.

use super::part::{Part, Writer};
use crate::error::Result;
use crate::plan::Plan;
use crate::products::figures::mission::{atl03_photons, l2a_waveforms, PhotonDot, ShotFigure};
use crate::products::mission::metrics::{metrics, quality};
use crate::products::mission::track_name;
use crate::products::mission::truth::under_footprint;
use crate::products::mission::{
    stale, Atl03, Gate, L1b, L2a, Shot, ATL03_FILE, L1B_FILE, L2A_FILE,
};
use crate::products::report::summary::{L2aSummary, ProductsSummary};
use crate::scene::Scene;
use crate::waveform::record::Recorder;
use rayon::prelude::*;

/// `waveforms_l1b.h5` and `waveforms_l2a.h5`, from the same records.
pub(super) struct WaveformFilesWriter<'a> {
    pub l1b: L1b,
    pub l2a: L2a,
    pub recorder: Recorder,
    pub plan: &'a Plan,
    pub scene: &'a Scene,
    pub out: &'a std::path::Path,
    /// σ of the transmitted pulse, s; the threshold of `stale_return_flag`, photons.
    pub pulse_sigma_s: f64,
    pub threshold_photons: f64,
    pub false_alarm_rate: f64,
    /// The footprint's edge and the beam's σ, in tan-space.
    pub edge_tan: f64,
    pub sigma_tan: f64,
    /// The frame's origin height (0 without a frame): local z to the files' heights.
    pub height0: f64,
    /// The shots `l2a_waveforms.png` shows (four spread over the campaign), as they come.
    pub figure_ids: Vec<u64>,
    pub figures: Vec<ShotFigure>,
    /// Shots, and per shot of quality 1 with a truth: RH98 less the true top, ground less the
    /// true ground (m), in shot order.
    pub shots: usize,
    pub against_truth: Vec<(f64, f64)>,
}

/// Mean and sample sd of `v` (none for fewer than two).
fn mean_sd(v: impl Iterator<Item = f64> + Clone) -> (Option<f64>, Option<f64>) {
    let n = v.clone().count();
    if n == 0 {
        return (None, None);
    }
    let mean = v.clone().sum::<f64>() / n as f64;
    let sd = (n > 1).then(|| (v.map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt());
    (Some(mean), sd)
}

/// The waveform figure's shots: four pulses spread evenly over the plan.
pub(super) fn figure_ids(pulses: usize) -> Vec<u64> {
    let mut ids: Vec<u64> = (0..4).map(|j| (pulses * (2 * j + 1) / 8) as u64).collect();
    ids.dedup();
    ids
}

impl Writer for WaveformFilesWriter<'_> {
    fn add(&mut self, part: &Part) -> Result<()> {
        let shots: Vec<_> = part
            .first
            .par_iter()
            .map(|w| {
                let record = self.recorder.record(w);
                let pulse = self.plan.pulse(w.pulse_id);
                let floor = self.recorder.noise_floor_photoelectrons(w);
                let gain = self.recorder.digitiser.as_ref().map_or(1.0, |d| d.gain);
                let sigma_r =
                    self.recorder.return_sigma_s(self.pulse_sigma_s) / (w.bin_ns as f64 * 1e-9);
                let y: Vec<f64> = self
                    .recorder
                    .laser_photoelectrons(&record)
                    .iter()
                    .map(|&v| v as f64)
                    .collect();
                let found = metrics(&y, floor.sqrt(), sigma_r, self.false_alarm_rate);
                let (mean, _) = self.recorder.mean_photoelectrons(w);
                let truth_found = metrics(&mean, floor.sqrt(), sigma_r, self.false_alarm_rate);
                let truth = under_footprint(self.scene, &pulse, self.edge_tan, self.sigma_tan);
                let figure = self.figure_ids.contains(&w.pulse_id).then(|| {
                    // the elevation of (fractional) sample k's centre
                    let at = |k: f64| {
                        let t = (w.t0_ns + (k + 0.5) * w.bin_ns as f64) * 1e-9;
                        (pulse.origin + pulse.direction * (crate::C * t / 2.0)).z + self.height0
                    };
                    ShotFigure {
                        pulse_id: w.pulse_id,
                        elevation: (0..y.len()).map(|k| at(k as f64)).collect(),
                        record: y.clone(),
                        mean: mean.clone(),
                        ground: found.as_ref().map(|m| at(m.ground)),
                        rh98: found.as_ref().map(|m| at(m.rh[98])),
                        truth_ground: truth.ground.map(|z| z + self.height0),
                        truth_top: truth.canopy_top.map(|z| z + self.height0),
                    }
                });
                let sd = gain * floor.sqrt();
                // RH98 and the ground against the truth, for a shot of quality 1
                let stale = stale(w, self.threshold_photons);
                let quality = quality(found.as_ref(), stale);
                let compared = match (&found, truth.ground, truth.canopy_top, quality) {
                    (Some(m), Some(g), Some(top), true) => {
                        let at = |k: f64| {
                            let t = (w.t0_ns + (k + 0.5) * w.bin_ns as f64) * 1e-9;
                            (pulse.origin + pulse.direction * (crate::C * t / 2.0)).z
                        };
                        Some((at(m.rh[98]) - top, at(m.ground) - g))
                    }
                    _ => None,
                };
                let shot = (pulse, record, sd, found, truth_found, truth);
                (shot, stale, figure, compared)
            })
            .collect();
        for (w, shot) in part.first.iter().zip(shots) {
            let ((pulse, record, sd, found, truth_found, truth), stale, figure, compared) = shot;
            self.figures.extend(figure);
            self.shots += 1;
            self.against_truth.extend(compared);
            self.l1b.add(&pulse, w, &record, sd)?;
            self.l2a.add(&Shot {
                pulse: &pulse,
                waveform: w,
                found,
                truth_found,
                truth,
                stale,
            })?;
        }
        Ok(())
    }

    fn finish(self: Box<Self>, summary: &mut ProductsSummary) -> Result<Vec<String>> {
        self.l1b.finish()?;
        self.l2a.finish()?;
        let top = mean_sd(self.against_truth.iter().map(|c| c.0));
        let ground = mean_sd(self.against_truth.iter().map(|c| c.1));
        summary.l2a = Some(L2aSummary {
            shots: self.shots,
            quality_shots: self.against_truth.len(),
            rh98_minus_top_mean_m: top.0,
            rh98_minus_top_sd_m: top.1,
            ground_minus_truth_mean_m: ground.0,
            ground_minus_truth_sd_m: ground.1,
        });
        let mut files = vec![L1B_FILE.to_string(), L2A_FILE.to_string()];
        if !self.figures.is_empty() {
            l2a_waveforms(&self.out.join(L2A_FIGURE), &self.figures)?;
            files.push(L2A_FIGURE.to_string());
        }
        Ok(files)
    }
}

/// The figures' files.
pub const L2A_FIGURE: &str = "l2a_waveforms.png";
pub const ATL03_FIGURE: &str = "atl03_photons.png";

/// Most photons `atl03_photons.png` keeps: past this, every other is dropped and the step
/// doubled, so memory stays fixed whatever the track's length (a dot is a pixel or two).
const FIGURE_PHOTONS: usize = 200_000;

pub(super) struct Atl03Writer<'a> {
    pub file: Atl03,
    pub plan: &'a Plan,
    pub out: &'a std::path::Path,
    /// The frame's origin height (0 without a frame).
    pub height0: f64,
    /// The first track's photons for the figure: every `step`-th, counted in `seen`.
    pub dots: Vec<PhotonDot>,
    pub step: usize,
    pub seen: usize,
}

impl Writer for Atl03Writer<'_> {
    fn add(&mut self, part: &Part) -> Result<()> {
        // the photons come in pulse order, as the waveforms do; a pulse may have none
        let mut photons = part.first_photons();
        for w in &part.first {
            let n = photons
                .iter()
                .position(|r| r.pulse_id != w.pulse_id)
                .unwrap_or(photons.len());
            let (rows, rest) = photons.split_at(n);
            photons = rest;
            if self.plan.pulse(w.pulse_id).line == 0 {
                for r in rows {
                    if self.seen.is_multiple_of(self.step) {
                        self.dots.push(PhotonDot {
                            along: r.along_track_m,
                            height: r.z + self.height0,
                            source: r.source,
                        });
                    }
                    self.seen += 1;
                    if self.dots.len() >= FIGURE_PHOTONS {
                        self.dots = self.dots.iter().step_by(2).copied().collect();
                        self.step *= 2;
                    }
                }
            }
            let gate = Gate {
                start_s: w.t0_ns * 1e-9,
                length_s: w.laser_photons.len() as f64 * w.bin_ns as f64 * 1e-9,
            };
            let shot = self.plan.shot(w.pulse_id);
            self.file
                .add(&self.plan.pulse(w.pulse_id), shot, gate, rows)?;
        }
        Ok(())
    }

    fn finish(self: Box<Self>, _: &mut ProductsSummary) -> Result<Vec<String>> {
        self.file.finish()?;
        let mut files = vec![ATL03_FILE.to_string()];
        if !self.dots.is_empty() {
            atl03_photons(&self.out.join(ATL03_FIGURE), &track_name(0), &self.dots)?;
            files.push(ATL03_FIGURE.to_string());
        }
        Ok(files)
    }
}
