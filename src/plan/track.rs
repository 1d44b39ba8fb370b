//! Profiling along a ground track: nadir pulses every `along_track_step_m`.
//!
//! Conventions:
//! - Whole-step rule (module [`super`] doc): one shot at the start of every whole step along
//!   the track, so a track of length L gives ⌊L/step⌋ shots at start + k·step; a part-step
//!   left at the end gets none. This is the reading that gives the paper's 6929 MABEL shots
//!   for (3, 3) → (101, 101) at 0.02 m (98√2 / 0.02 = 6929.6); firing at both ends would
//!   give 6930. The end itself is therefore never fired.
//! - Origins at `altitude_m`, beams straight down, `scan_angle_deg` 0, `line` 0.
//! - GPS time of shot k: `gps_start_s` + k / `prf_hz`, with [`super::DEFAULT_PRF_HZ`] when
//!   `prf_hz` is absent (the track has no speed, so the times only order the shots).

use super::{need, whole_steps, GroundPath, Pulse, DEFAULT_PRF_HZ};
use crate::campaign::{Platform, PlatformKind};
use crate::error::{Error, Result};
use glam::DVec3;

pub(crate) struct Track {
    path: GroundPath,
    altitude: f64,
    step: f64,
    prf: f64,
    gps_start: f64,
}

impl Track {
    pub(crate) fn new(p: &Platform) -> Result<Track> {
        let kind = PlatformKind::Track;
        let track = p
            .track
            .as_ref()
            .ok_or_else(|| Error::msg("a track platform needs track"))?;
        Ok(Track {
            path: GroundPath::new(track),
            altitude: need(p.altitude_m, kind, "altitude_m")?,
            step: need(p.along_track_step_m, kind, "along_track_step_m")?,
            prf: p.prf_hz.unwrap_or(DEFAULT_PRF_HZ),
            gps_start: p.gps_start_s.unwrap_or(0.0),
        })
    }

    pub(crate) fn count(&self) -> u64 {
        whole_steps(self.path.length, self.step)
    }

    /// Pulse `id` (< [`Track::count`]).
    pub(crate) fn pulse(&self, id: u64) -> Pulse {
        let g = &self.path;
        Pulse {
            id,
            gps_time_s: self.gps_start + id as f64 / self.prf,
            origin: g.start + g.along * (id as f64 * self.step) + DVec3::Z * self.altitude,
            direction: DVec3::NEG_Z,
            scan_angle_deg: 0.0,
            line: 0,
            along: g.along,
            up: DVec3::Z,
            recorded: None,
        }
    }
}
