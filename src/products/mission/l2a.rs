//! `waveforms_l2a.h5`: GEDI L2A-like, one group per beam: each shot's ground (the lowest
//! mode) and relative heights RH0-RH100 found in its record by [`super::metrics`], in GEDI's
//! names and dtypes, with the truth beside them (datasets the real product has not):
//! `truth_ground_elev` and `truth_canopy_top` from the scene under the footprint, `truth_rh`
//! the same metrics of the noise-free mean waveform.

use super::h5::{Field, H5Writer, Kind};
use super::l1b::Setup;
use super::metrics::{quality, Metrics, MIN_SENSITIVITY, NOISELESS_FRACTION};
use super::truth::Truth;
use super::{
    beam_group, beam_name, dataset_identification, push_shot, root_attrs, shot_number, Geo,
    SunAngles, MISSION_EPOCH_GPS_S,
};
use crate::error::Result;
use crate::plan::Pulse;
use crate::waveform::Waveform;
use hdf5_pure::AttrValue;
use std::collections::BTreeMap;
use std::path::Path;

/// GEDI's fill value of floats.
const FILL: f64 = -9999.0;

/// One shot's findings: the record's metrics, the mean waveform's, the scene's truth, and
/// whether the mean waveform reaches the detection threshold anywhere.
pub struct Shot<'a> {
    pub pulse: &'a Pulse,
    pub waveform: &'a Waveform,
    pub found: Option<Metrics>,
    pub truth_found: Option<Metrics>,
    pub truth: Truth,
    pub stale: bool,
}

/// `waveforms_l2a.h5`, written a shot at a time.
pub struct L2a {
    h5: H5Writer,
    /// Shots so far per beam.
    beams: BTreeMap<u32, u64>,
    geo: Geo,
    sun: SunAngles,
}

/// The algorithm, as the file states it.
fn algorithm() -> String {
    format!(
        "record less its noise mean, in photoelectrons; filtered by a Gaussian of the return's sigma; threshold: the level a gate of noise alone crosses at the campaign's false_alarm_rate ({NOISELESS_FRACTION} of the filtered peak without noise); signal from the first to the last sample above it; modes: local maxima above it, distinct where a dip deeper than the threshold parts them, the lowest the ground; RH_p: height above the ground where the energy of y over the signal, summed upwards from its end, first reaches p %; sensitivity 1 - A_min / E (A_min: area of the weakest return found); quality_flag: a ground found, sensitivity >= {MIN_SENSITIVITY}, stale_return_flag 0"
    )
}

impl L2a {
    pub fn create(path: &Path, setup: &Setup) -> Result<L2a> {
        let mut attrs = root_attrs(setup.campaign, setup.frame, "GEDI_L2A")?;
        attrs.push(("simulated", format!("simulated by lidarsim {}, not a GEDI granule: laid out as GEDI02_A so its readers open it", env!("CARGO_PKG_VERSION"))));
        attrs.push(("algorithm", algorithm()));
        let mut h5 = H5Writer::create(path, &attrs)?;
        h5.gedi_strings();
        dataset_identification(
            &mut h5,
            "GEDI_L2A",
            super::L2A_FILE,
            "Ground elevation and relative heights of every simulated shot, as GEDI02_A holds them, with the scene's truth beside them.",
            setup.first_gps_s,
            &setup.fingerprint,
        )?;
        Ok(L2a {
            h5,
            beams: BTreeMap::new(),
            geo: Geo::new(setup.frame)?,
            sun: setup.sun,
        })
    }

    fn beam(&mut self, line: u32) -> Result<String> {
        if self.beams.contains_key(&line) {
            return Ok(beam_name(line));
        }
        let name = beam_group(&mut self.h5, line)?;
        let deg = self.geo.angle_units();
        let f = |path: &str, kind, units, description| {
            Field::new(&name, path, kind, units, description)
        };
        let fill64 = || AttrValue::F64(FILL);
        let fill32 = || AttrValue::F32(FILL as f32);
        let sun = self.sun;
        self.h5.datasets(&[
            f("shot_number", Kind::U64, "counts", "GEDI's shot number, as in waveforms_l1b.h5"),
            f("beam", Kind::U16, "counts", "GEDI's beam number"),
            f("channel", Kind::U8, "counts", "GEDI's digitiser channel of the beam"),
            f("delta_time", Kind::F64, "seconds since 2018-01-01", "transmit time of the shot: GPS seconds less 1198800018"),
            f("master_int", Kind::U32, "seconds", "whole seconds of delta_time"),
            f("master_frac", Kind::F64, "seconds", "fraction of a second of delta_time"),
            f("rh", Kind::F64, "m", "relative heights RH0-RH100 above the lowest mode, from the record (see /@algorithm; fill value: no signal)").rows_of(101).fill(fill64()),
            f("elev_lowestmode", Kind::F32, "m", "height of the lowest mode: the ground (fill value: no signal)").fill(fill32()),
            f("elev_highestreturn", Kind::F32, "m", "height of the signal's start (fill value: no signal)").fill(fill32()),
            f("lat_lowestmode", Kind::F64, deg, "latitude of the lowest mode (fill value: no signal)").fill(fill64()),
            f("lon_lowestmode", Kind::F64, deg, "longitude of the lowest mode (fill value: no signal)").fill(fill64()),
            f("lat_highestreturn", Kind::F64, deg, "latitude of the signal's start (fill value: no signal)").fill(fill64()),
            f("lon_highestreturn", Kind::F64, deg, "longitude of the signal's start (fill value: no signal)").fill(fill64()),
            f("num_detectedmodes", Kind::U8, "counts", "modes found in the record"),
            f("sensitivity", Kind::F32, "1", "beam sensitivity: the canopy cover up to which a ground as bright as the canopy is found (fill value: no signal)").fill(fill32()),
            f("quality_flag", Kind::U8, "1", "1: a ground found, sensitivity >= 0.9 and stale_return_flag 0"),
            f("degrade_flag", Kind::U8, "1", "0: no degraded pointing or positioning (a simulation knows both)"),
            f("selected_algorithm", Kind::U8, "1", "1: the one algorithm of /@algorithm"),
            f("solar_elevation", Kind::F32, "degrees", sun.elevation_description()).fill(fill32()),
            f("solar_azimuth", Kind::F32, "degrees", sun.azimuth_description()).fill(fill32()),
            f("truth_ground_elev", Kind::F64, "m", "not in the real product: the scene's ground under the footprint, weighted by the laser's irradiance (fill value: none)").fill(fill64()),
            f("truth_canopy_top", Kind::F64, "m", "not in the real product: the highest scene point within the footprint's edge (fill value: none)").fill(fill64()),
            f("truth_rh", Kind::F64, "m", "not in the real product: RH0-RH100 of the noise-free mean waveform, above its own lowest mode (fill value: no signal)").rows_of(101).fill(fill64()),
        ])?;
        self.beams.insert(line, 0);
        Ok(name)
    }

    pub fn add(&mut self, s: &Shot) -> Result<()> {
        let (pulse, w) = (s.pulse, s.waveform);
        let b = self.beam(pulse.line)?;
        let shots = self.beams.get(&pulse.line).copied().unwrap_or_default() + 1;
        // the point of (fractional) sample k's centre: t0 + (k + ½) Δt after emission
        let at = |k: f64| {
            let t = (w.t0_ns + (k + 0.5) * w.bin_ns as f64) * 1e-9;
            self.geo
                .of(pulse.origin + pulse.direction * (crate::C * t / 2.0))
        };
        let rh_of = |m: &Option<Metrics>| -> Vec<f64> {
            match m {
                Some(m) => {
                    let ground = at(m.ground).2;
                    m.rh.iter().map(|&k| at(k).2 - ground).collect()
                }
                None => vec![FILL; 101],
            }
        };
        let (ground, top) = match &s.found {
            Some(m) => (at(m.ground), at(m.top)),
            None => ((FILL, FILL, FILL), (FILL, FILL, FILL)),
        };
        let quality = quality(s.found.as_ref(), s.stale);
        let delta_time = pulse.gps_time_s - MISSION_EPOCH_GPS_S;
        let height = |z: Option<f64>| z.map_or(FILL, |z| self.geo.of(pulse.origin.with_z(z)).2);
        let (truth_ground, truth_top) = (height(s.truth.ground), height(s.truth.canopy_top));
        let rh = rh_of(&s.found);
        let truth_rh = rh_of(&s.truth_found);
        let h = &mut self.h5;
        let shot = shot_number(pulse.line, shots);
        push_shot(h, &b, pulse.line, shot, delta_time)?;
        h.push_f64(&format!("{b}/rh"), &rh)?;
        h.push_f32(&format!("{b}/elev_lowestmode"), &[ground.2 as f32])?;
        h.push_f32(&format!("{b}/elev_highestreturn"), &[top.2 as f32])?;
        h.push_f64(&format!("{b}/lat_lowestmode"), &[ground.0])?;
        h.push_f64(&format!("{b}/lon_lowestmode"), &[ground.1])?;
        h.push_f64(&format!("{b}/lat_highestreturn"), &[top.0])?;
        h.push_f64(&format!("{b}/lon_highestreturn"), &[top.1])?;
        h.push_u8(
            &format!("{b}/num_detectedmodes"),
            &[s.found.as_ref().map_or(0, |m| m.modes)],
        )?;
        h.push_f32(
            &format!("{b}/sensitivity"),
            &[s.found.as_ref().map_or(FILL, |m| m.sensitivity) as f32],
        )?;
        h.push_u8(&format!("{b}/quality_flag"), &[u8::from(quality)])?;
        h.push_u8(&format!("{b}/degrade_flag"), &[0])?;
        h.push_u8(&format!("{b}/selected_algorithm"), &[1])?;
        h.push_f32(
            &format!("{b}/solar_elevation"),
            &[self.sun.elevation_or(FILL as f32)],
        )?;
        h.push_f32(
            &format!("{b}/solar_azimuth"),
            &[self.sun.azimuth_or(FILL as f32)],
        )?;
        h.push_f64(&format!("{b}/truth_ground_elev"), &[truth_ground])?;
        h.push_f64(&format!("{b}/truth_canopy_top"), &[truth_top])?;
        h.push_f64(&format!("{b}/truth_rh"), &truth_rh)?;
        self.beams.insert(pulse.line, shots);
        Ok(())
    }

    pub fn finish(self) -> Result<()> {
        self.h5.finish()
    }
}
