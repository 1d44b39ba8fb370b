//! Terrestrial laser scanning: each station sweeping azimuth (outer loop) and zenith (inner),
//! the stations (`position`, or `positions` in order) one after the other.
//!
//! Conventions:
//! - Beam directions from [`super::direction_from_angles`]: zenith from +z, azimuth from +x
//!   towards +y, degrees.
//! - Inclusive rule (module [`super`] doc) on both ranges: a0 + i·step up to a1 and z0 + k·step
//!   up to z1, both ends included when the range is a whole number of steps. A full turn of
//!   azimuth (a1 − a0 = 360) does not repeat a0 at a0 + 360.
//! - `scan_angle_deg` column = zenith angle; `line` = the station's index (the points' source
//!   id).
//! - GPS time of pulse k: `gps_start_s` + k / `prf_hz` ([`super::DEFAULT_PRF_HZ`] when absent).

use super::{
    direction_from_angles, inclusive_steps, is_multiple, need, Pulse, DEFAULT_PRF_HZ, TOL,
};
use crate::campaign::{Platform, PlatformKind};
use crate::error::Result;
use glam::DVec3;

pub(crate) struct Tls {
    positions: Vec<DVec3>,
    azimuth: [f64; 2],
    azimuth_step: f64,
    zenith: [f64; 2],
    zenith_step: f64,
    prf: f64,
    gps_start: f64,
}

impl Tls {
    pub(crate) fn new(p: &Platform) -> Result<Tls> {
        let kind = PlatformKind::Tls;
        Ok(Tls {
            positions: match (&p.positions, p.position) {
                (Some(list), _) => list.iter().map(|&q| DVec3::from_array(q)).collect(),
                (None, q) => vec![DVec3::from_array(need(q, kind, "position")?)],
            },
            azimuth: need(p.azimuth_deg, kind, "azimuth_deg")?,
            azimuth_step: need(p.azimuth_step_deg, kind, "azimuth_step_deg")?,
            zenith: need(p.zenith_deg, kind, "zenith_deg")?,
            zenith_step: need(p.zenith_step_deg, kind, "zenith_step_deg")?,
            prf: p.prf_hz.unwrap_or(DEFAULT_PRF_HZ),
            gps_start: p.gps_start_s.unwrap_or(0.0),
        })
    }

    pub(crate) fn azimuths(&self) -> u64 {
        let span = self.azimuth[1] - self.azimuth[0];
        let n = inclusive_steps(span, self.azimuth_step);
        if span >= 360.0 * (1.0 - TOL) && is_multiple(span, self.azimuth_step) {
            n - 1
        } else {
            n
        }
    }

    pub(crate) fn zeniths(&self) -> u64 {
        inclusive_steps(self.zenith[1] - self.zenith[0], self.zenith_step)
    }

    /// Pulses of one station.
    fn per_station(&self) -> u64 {
        self.azimuths().saturating_mul(self.zeniths())
    }

    pub(crate) fn count(&self) -> u64 {
        self.per_station()
            .saturating_mul(self.positions.len() as u64)
    }

    /// The first pulse of pulse `id`'s station.
    pub(crate) fn station_start(&self, id: u64) -> u64 {
        let per = self.per_station().max(1);
        id / per * per
    }

    /// Pulse `id` (< [`Tls::count`]): station-major, then azimuth, then zenith.
    pub(crate) fn pulse(&self, id: u64) -> Pulse {
        let nz = self.zeniths();
        let per = self.per_station().max(1);
        let (station, k) = (id / per, id % per);
        let (ia, iz) = (k / nz, k % nz);
        let az = (self.azimuth[0] + ia as f64 * self.azimuth_step).min(self.azimuth[1]);
        // Clamped because the tolerance may let the last step overshoot by 1e-9.
        let ze = (self.zenith[0] + iz as f64 * self.zenith_step).min(self.zenith[1]);
        Pulse {
            id,
            gps_time_s: self.gps_start + id as f64 / self.prf,
            origin: self.positions[(station as usize).min(self.positions.len() - 1)],
            direction: direction_from_angles(ze, az),
            scan_angle_deg: ze as f32,
            line: station as u32,
            along: DVec3::X,
            up: DVec3::Z,
            recorded: None,
        }
    }
}
