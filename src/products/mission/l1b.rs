//! `waveforms_l1b.h5`: GEDI L1B-like, one group per beam, each shot's record and transmitted
//! pulse concatenated as GEDI concatenates them, with the datasets of GEDI01_B that a
//! simulation defines, in GEDI's names and dtypes.

use super::h5::{Field, H5Writer, Kind};
use super::{
    beam_group, beam_name, dataset_identification, epoch, push_shot, root_attrs, shot_number, Geo,
    SunAngles, MISSION_EPOCH_GPS_S,
};
use crate::campaign::Frame;
use crate::error::Result;
use crate::plan::Pulse;
use crate::waveform::record::{transmitted_pulse, Record};
use crate::waveform::Waveform;
use hdf5_pure::AttrValue;
use std::collections::BTreeMap;
use std::path::Path;

/// GEDI's fill value of 32-bit floats.
const FILL_F32: f32 = -9999.0;

/// What the L1B and L2A files are made from, besides the shots.
pub struct Setup<'a> {
    pub campaign: &'a str,
    pub frame: Option<&'a Frame>,
    /// σ of the transmitted pulse, s.
    pub pulse_sigma_s: f64,
    /// The record is digitised (counts), else photoelectrons.
    pub counts: bool,
    pub threshold_photons: f64,
    pub sun: SunAngles,
    /// GPS seconds of the campaign's first pulse, and the run's fingerprint (the creation date
    /// and uuid of `/METADATA`).
    pub first_gps_s: f64,
    pub fingerprint: String,
}

/// GEDI's `stale_return_flag`: no sample of the mean waveform reaches the detection
/// threshold (photons).
pub fn stale(w: &Waveform, threshold_photons: f64) -> bool {
    !w.laser_photons
        .iter()
        .any(|&v| v as f64 >= threshold_photons && threshold_photons > 0.0)
}

/// Per beam: rx and tx samples written so far, shots so far.
#[derive(Clone, Copy, Default)]
struct Beam {
    rx: u64,
    tx: u64,
    shots: u64,
}

/// `waveforms_l1b.h5`, written a pulse at a time.
pub struct L1b {
    h5: H5Writer,
    beams: BTreeMap<u32, Beam>,
    geo: Geo,
    pulse_sigma_s: f64,
    units: &'static str,
    threshold: f64,
    sun: SunAngles,
}

impl L1b {
    pub fn create(path: &Path, setup: &Setup) -> Result<L1b> {
        let mut attrs = root_attrs(setup.campaign, setup.frame, "GEDI_L1B")?;
        attrs.push(("simulated", format!("simulated by lidarsim {}, not a GEDI granule: laid out as GEDI01_B so its readers open it", env!("CARGO_PKG_VERSION"))));
        let mut h5 = H5Writer::create(path, &attrs)?;
        h5.gedi_strings();
        dataset_identification(
            &mut h5,
            "GEDI_L1B",
            super::L1B_FILE,
            "Simulated geolocated waveforms of every shot of every beam, as GEDI01_B holds them.",
            setup.first_gps_s,
            &setup.fingerprint,
        )?;
        Ok(L1b {
            h5,
            beams: BTreeMap::new(),
            geo: Geo::new(setup.frame)?,
            pulse_sigma_s: setup.pulse_sigma_s,
            units: if setup.counts {
                "counts"
            } else {
                "photoelectrons"
            },
            threshold: setup.threshold_photons,
            sun: setup.sun,
        })
    }

    fn beam(&mut self, line: u32) -> Result<String> {
        if self.beams.contains_key(&line) {
            return Ok(beam_name(line));
        }
        let name = beam_group(&mut self.h5, line)?;
        epoch(
            &mut self.h5,
            &format!("{name}/ancillary"),
            "master_time_epoch",
        )?;
        self.h5.group(&format!("{name}/geolocation"), &[])?;
        let u = self.units;
        let deg = self.geo.angle_units();
        let f = |path: &str, kind, units, description| {
            Field::new(&name, path, kind, units, description)
        };
        let sun = self.sun;
        self.h5.datasets(&[
            f("rxwaveform", Kind::F32, u, "received waveforms of all shots, concatenated: the instrument's record (noise and digitiser as configured)"),
            f("rx_sample_count", Kind::U16, "counts", "samples of each shot's received waveform"),
            f("rx_sample_start_index", Kind::U64, "counts", "index of each shot's first sample in rxwaveform, counted from 1"),
            f("txwaveform", Kind::F32, "1", "transmitted pulse of each shot, concatenated: the fraction of the pulse energy per sample"),
            f("tx_sample_count", Kind::U16, "counts", "samples of each shot's transmitted waveform"),
            f("tx_sample_start_index", Kind::U64, "counts", "index of each shot's first sample in txwaveform, counted from 1"),
            f("shot_number", Kind::U64, "counts", "GEDI's shot number OOOOOBBRRGNNNNNNNN: orbit 0 (none), beam, reserved 0, granule (from 1, 10^8 shots each) and the shot's index in its beam, from 1"),
            f("beam", Kind::U16, "counts", "GEDI's beam number: the decimal value of the group's binary name"),
            f("channel", Kind::U8, "counts", "GEDI's digitiser channel of the beam"),
            f("delta_time", Kind::F64, "seconds since 2018-01-01", "transmit time of the shot: the pulse's GPS seconds less ancillary/master_time_epoch"),
            f("master_int", Kind::U32, "seconds", "whole seconds of delta_time"),
            f("master_frac", Kind::F64, "seconds", "fraction of a second of delta_time"),
            f("noise_mean_corrected", Kind::F64, u, "mean of a sample without laser signal: solar background and dark counts"),
            f("noise_stddev_corrected", Kind::F64, u, "standard deviation of a sample without laser signal: shot noise of the background, electronic noise and the digitiser's rounding"),
            f("all_samples_sum", Kind::U32, "counts", "sum of the shot's rxwaveform samples, rounded"),
            f("rx_energy", Kind::F64, u, "sum of the shot's rxwaveform less noise_mean_corrected per sample"),
            f("stale_return_flag", Kind::U8, "1", "1: no sample of the mean waveform reaches the detection threshold"),
            f("nsemean_even", Kind::F32, u, "noise mean of the even samples: noise_mean_corrected (the digitiser has one)"),
            f("nsemean_odd", Kind::F32, u, "noise mean of the odd samples: noise_mean_corrected (the digitiser has one)"),
            f("tx_gloc", Kind::F32, "counts", "centre of the transmitted pulse's Gaussian in txwaveform, in samples counted from 1"),
            f("tx_egsigma", Kind::F32, "counts", "sigma of the transmitted pulse's Gaussian, in samples"),
            f("tx_egamplitude", Kind::F32, "1", "summit of the transmitted pulse's Gaussian, in txwaveform's units"),
            f("tx_egbias", Kind::F32, "1", "bias under the transmitted pulse: 0 (txwaveform is the pulse alone)"),
            f("tx_eggamma", Kind::F32, "1", "skew of the transmitted pulse's extended Gaussian: 0 (the simulated pulse is a Gaussian)"),
            f("tx_egflag", Kind::U8, "1", "1: the transmitted pulse's Gaussian is known (it is the simulated pulse)"),
            f("tx_pulseflag", Kind::U8, "1", "1: a transmitted pulse"),
            f("geolocation/shot_number", Kind::U64, "counts", "as shot_number"),
            f("geolocation/delta_time", Kind::F64, "seconds since 2018-01-01", "as delta_time"),
            f("geolocation/degrade", Kind::I8, "1", "0: no degraded geolocation (a simulation knows its pointing and position)"),
            f("geolocation/bounce_time_offset_bin0", Kind::F64, "seconds", "time light takes from the instrument to the centre of the first sample, one way"),
            f("geolocation/bounce_time_offset_lastbin", Kind::F64, "seconds", "time light takes from the instrument to the centre of the last sample, one way"),
            f("geolocation/elevation_bin0", Kind::F64, "m", "height of the centre of the first sample, on the beam axis"),
            f("geolocation/elevation_lastbin", Kind::F64, "m", "height of the centre of the last sample, on the beam axis"),
            f("geolocation/latitude_bin0", Kind::F64, deg, "latitude of the centre of the first sample (local y without a frame: see /@coordinates)"),
            f("geolocation/longitude_bin0", Kind::F64, deg, "longitude of the centre of the first sample (local x without a frame: see /@coordinates)"),
            f("geolocation/latitude_lastbin", Kind::F64, deg, "latitude of the centre of the last sample (local y without a frame: see /@coordinates)"),
            f("geolocation/longitude_lastbin", Kind::F64, deg, "longitude of the centre of the last sample (local x without a frame: see /@coordinates)"),
            f("geolocation/latitude_instrument", Kind::F64, deg, "latitude of the instrument at the shot"),
            f("geolocation/longitude_instrument", Kind::F64, deg, "longitude of the instrument at the shot"),
            f("geolocation/altitude_instrument", Kind::F64, "m", "height of the instrument at the shot"),
            f("geolocation/local_beam_elevation", Kind::F32, "radians", "elevation above the local horizontal of the beam's axis, from the footprint towards the instrument"),
            f("geolocation/local_beam_azimuth", Kind::F32, "radians", "azimuth of the beam's axis from the footprint towards the instrument, from grid north towards east"),
            f("geolocation/solar_elevation", Kind::F32, "degrees", sun.elevation_description()).fill(AttrValue::F32(FILL_F32)),
            f("geolocation/solar_azimuth", Kind::F32, "degrees", sun.azimuth_description()).fill(AttrValue::F32(FILL_F32)),
        ])?;
        self.beams.insert(line, Beam::default());
        Ok(name)
    }

    /// One shot: its pulse, mean waveform, record and the record's noise sd.
    pub fn add(
        &mut self,
        pulse: &Pulse,
        w: &Waveform,
        record: &Record,
        noise_sd: f64,
    ) -> Result<()> {
        let b = self.beam(pulse.line)?;
        let tx = transmitted_pulse(self.pulse_sigma_s, w.bin_ns as f64 * 1e-9);
        let beam = self.beams.get(&pulse.line).copied().unwrap_or_default();
        let n = record.samples.len();
        // a gate the scene's ranges sized (none given) may pass what the count holds
        if n > usize::from(u16::MAX) {
            return Err(crate::error::Error::msg(format!(
                "pulse {}: a waveform of {n} samples, more than the 65535 that waveforms_l1b.h5 \
                 gives a shot (GEDI's rx_sample_count is 16 bits): use wider bins \
                 (instrument.bin_ns) or a range_gate",
                pulse.id
            ))
            .for_key("instrument.bin_ns"));
        }
        // centre of sample k: t0 + (k + ½) Δt after emission, at range c t / 2
        let at = |k: usize| {
            let t = (w.t0_ns + (k as f64 + 0.5) * w.bin_ns as f64) * 1e-9;
            self.geo
                .of(pulse.origin + pulse.direction * (crate::C * t / 2.0))
        };
        let (first, last) = (at(0), at(n.saturating_sub(1)));
        let instrument = self.geo.of(pulse.origin);
        let stale = stale(w, self.threshold);
        let shot = shot_number(pulse.line, beam.shots + 1);
        let delta_time = pulse.gps_time_s - MISSION_EPOCH_GPS_S;
        let sum: f64 = record.samples.iter().map(|&v| v as f64).sum();
        let up = -pulse.direction;
        let h = &mut self.h5;
        h.push_f32(&format!("{b}/rxwaveform"), &record.samples)?;
        h.push_u16(&format!("{b}/rx_sample_count"), &[n as u16])?;
        h.push_u64(&format!("{b}/rx_sample_start_index"), &[beam.rx + 1])?;
        h.push_f32(&format!("{b}/txwaveform"), &tx)?;
        h.push_u16(
            &format!("{b}/tx_sample_count"),
            &[tx.len().min(65_535) as u16],
        )?;
        h.push_u64(&format!("{b}/tx_sample_start_index"), &[beam.tx + 1])?;
        push_shot(h, &b, pulse.line, shot, delta_time)?;
        h.push_f64(&format!("{b}/noise_mean_corrected"), &[record.background])?;
        h.push_f64(&format!("{b}/noise_stddev_corrected"), &[noise_sd])?;
        h.push_u32(
            &format!("{b}/all_samples_sum"),
            &[sum.round().clamp(0.0, u32::MAX as f64) as u32],
        )?;
        h.push_f64(
            &format!("{b}/rx_energy"),
            &[sum - record.background * n as f64],
        )?;
        h.push_u8(&format!("{b}/stale_return_flag"), &[u8::from(stale)])?;
        // the transmitted pulse: a Gaussian of σ_tx samples centred in its ±4σ window
        let sigma_tx = self.pulse_sigma_s / (w.bin_ns as f64 * 1e-9);
        let summit = tx.iter().cloned().fold(0.0f32, f32::max);
        let noise = record.background as f32;
        h.push_f32(&format!("{b}/nsemean_even"), &[noise])?;
        h.push_f32(&format!("{b}/nsemean_odd"), &[noise])?;
        h.push_f32(
            &format!("{b}/tx_gloc"),
            &[(tx.len() as f64 + 1.0) as f32 / 2.0],
        )?;
        h.push_f32(&format!("{b}/tx_egsigma"), &[sigma_tx as f32])?;
        h.push_f32(&format!("{b}/tx_egamplitude"), &[summit])?;
        h.push_f32(&format!("{b}/tx_egbias"), &[0.0])?;
        h.push_f32(&format!("{b}/tx_eggamma"), &[0.0])?;
        h.push_u8(&format!("{b}/tx_egflag"), &[1])?;
        h.push_u8(&format!("{b}/tx_pulseflag"), &[1])?;
        let g = format!("{b}/geolocation");
        let one_way = |k: usize| (w.t0_ns + (k as f64 + 0.5) * w.bin_ns as f64) * 1e-9 / 2.0;
        h.push_f64(&format!("{g}/bounce_time_offset_bin0"), &[one_way(0)])?;
        h.push_f64(
            &format!("{g}/bounce_time_offset_lastbin"),
            &[one_way(n.saturating_sub(1))],
        )?;
        h.push_u64(&format!("{g}/shot_number"), &[shot])?;
        h.push_f64(&format!("{g}/delta_time"), &[delta_time])?;
        h.push_i8(&format!("{g}/degrade"), &[0])?;
        h.push_f64(&format!("{g}/elevation_bin0"), &[first.2])?;
        h.push_f64(&format!("{g}/elevation_lastbin"), &[last.2])?;
        h.push_f64(&format!("{g}/latitude_bin0"), &[first.0])?;
        h.push_f64(&format!("{g}/longitude_bin0"), &[first.1])?;
        h.push_f64(&format!("{g}/latitude_lastbin"), &[last.0])?;
        h.push_f64(&format!("{g}/longitude_lastbin"), &[last.1])?;
        h.push_f64(&format!("{g}/latitude_instrument"), &[instrument.0])?;
        h.push_f64(&format!("{g}/longitude_instrument"), &[instrument.1])?;
        h.push_f64(&format!("{g}/altitude_instrument"), &[instrument.2])?;
        h.push_f32(
            &format!("{g}/local_beam_elevation"),
            &[up.z.clamp(-1.0, 1.0).asin() as f32],
        )?;
        h.push_f32(
            &format!("{g}/local_beam_azimuth"),
            &[up.x.atan2(up.y) as f32],
        )?;
        h.push_f32(
            &format!("{g}/solar_elevation"),
            &[self.sun.elevation_or(FILL_F32)],
        )?;
        h.push_f32(
            &format!("{g}/solar_azimuth"),
            &[self.sun.azimuth_or(FILL_F32)],
        )?;
        self.beams.insert(
            pulse.line,
            Beam {
                rx: beam.rx + n as u64,
                tx: beam.tx + tx.len() as u64,
                shots: beam.shots + 1,
            },
        );
        Ok(())
    }

    pub fn finish(self) -> Result<()> {
        self.h5.finish()
    }
}
