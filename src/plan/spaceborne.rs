//! Spaceborne (or any fast nadir-ish) profiler: shots along a ground track, one pulse per
//! beam per shot.
//!
//! Conventions:
//! - Shots every `ground_speed_m_s` / `prf_hz` metres along the track, from its start, while
//!   they stay on it (inclusive rule: the end gets a shot when the track is a whole number of
//!   shot spacings). Shot k is fired at `gps_start_s` + k / `prf_hz`, all beams together.
//! - Beam b's footprint centre is on the ground track shifted `cross_track_m` to the right of
//!   the direction of travel (z = 0). `off_nadir_deg` tilts every beam across track, positive
//!   towards the right; the origin is moved left by altitude·tan(off-nadir) so that the
//!   footprint centre stays on that offset track whatever the tilt. Origins are at
//!   `altitude_m`.
//! - Pulse ids run shot-major, beam-minor; `line` = beam index; the `scan_angle_deg` column is
//!   the signed off-nadir tilt.

use super::{inclusive_steps, need, GroundPath, Pulse};
use crate::campaign::{Platform, PlatformKind};
use crate::error::{Error, Result};
use glam::DVec3;

pub(crate) struct Spaceborne {
    path: GroundPath,
    altitude: f64,
    prf: f64,
    pub(crate) shot_step_m: f64,
    /// Cross-track offsets of the beams, m; `None` = one beam on the track.
    beams: Option<Vec<f64>>,
    off_nadir_deg: f64,
    gps_start: f64,
}

impl Spaceborne {
    pub(crate) fn new(p: &Platform) -> Result<Spaceborne> {
        let kind = PlatformKind::Spaceborne;
        let track = p
            .track
            .as_ref()
            .ok_or_else(|| Error::msg("a spaceborne platform needs track"))?;
        let prf = need(p.prf_hz, kind, "prf_hz")?;
        Ok(Spaceborne {
            path: GroundPath::new(track),
            altitude: need(p.altitude_m, kind, "altitude_m")?,
            prf,
            shot_step_m: need(p.ground_speed_m_s, kind, "ground_speed_m_s")? / prf,
            beams: p
                .beams
                .as_ref()
                .map(|b| b.iter().map(|b| b.cross_track_m).collect()),
            off_nadir_deg: p.off_nadir_deg.unwrap_or(0.0),
            gps_start: p.gps_start_s.unwrap_or(0.0),
        })
    }

    fn beam_count(&self) -> u64 {
        self.beams.as_ref().map_or(1, |b| b.len() as u64)
    }

    pub(crate) fn shots(&self) -> u64 {
        inclusive_steps(self.path.length, self.shot_step_m)
    }

    /// The shot pulse `id` belongs to: every beam fires at once.
    pub(crate) fn shot(&self, id: u64) -> u64 {
        id / self.beam_count()
    }

    /// The first shot's pulse of pulse `id`'s beam.
    pub(crate) fn line_start(&self, id: u64) -> u64 {
        id % self.beam_count()
    }

    pub(crate) fn count(&self) -> u64 {
        self.shots().saturating_mul(self.beam_count())
    }

    /// Pulse `id` (< [`Spaceborne::count`]): shot-major, beam-minor.
    pub(crate) fn pulse(&self, id: u64) -> Pulse {
        let g = &self.path;
        let (s, c) = self.off_nadir_deg.to_radians().sin_cos();
        let direction = g.right * s - DVec3::Z * c;
        // From the footprint centre back up the beam to the platform's height.
        let lift = DVec3::Z * self.altitude - g.right * (self.altitude * s / c);
        let beams = self.beam_count();
        let (k, b) = (id / beams, id % beams);
        let cross = self.beams.as_ref().map_or(0.0, |v| v[b as usize]);
        let ground = g.start + g.along * (k as f64 * self.shot_step_m).min(g.length);
        Pulse {
            id,
            gps_time_s: self.gps_start + k as f64 / self.prf,
            origin: ground + g.right * cross + lift,
            direction,
            scan_angle_deg: self.off_nadir_deg as f32,
            line: b as u32,
            along: g.along,
            up: DVec3::Z,
            recorded: None,
        }
    }
}
