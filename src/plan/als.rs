//! Airborne laser scanning: straight flight lines and a scanner sweeping across track.
//!
//! Conventions:
//! - The scan angle θ is measured in the vertical plane perpendicular to the flight
//!   direction, from nadir, **positive to the right of the flight direction** (seen from
//!   above, flying along +x, right is −y). The beam is `right·sin θ − z·cos θ`, so it has no
//!   along-track component: the scanner is not tilted forward.
//! - `line` sweeps min → max, then jumps back to min; `oscillating` sweeps min → max on even
//!   scan lines and max → min on odd ones (a scan line is one sweep, so one period of
//!   `scan_frequency_hz` holds two scan lines); `conic` turns the beam once per scan line on a
//!   cone about nadir whose half-angle is max(|min|, |max|) of `scan_angle_deg`, starting
//!   straight ahead and turning towards the right. For `conic`, `look_angle_step_deg` is the
//!   azimuth step around the cone, and the `scan_angle_deg` column is the cone half-angle
//!   (an off-nadir angle, not signed); for `line` and `oscillating` it is the signed θ.
//! - The pattern is a grid: scan lines every d metres along track (`along_track_step_m`, else
//!   speed / scan lines per second), pulses every δ within a scan line (`look_angle_step_deg`,
//!   else the angle a scan line covers × scan lines per second / `prf_hz`). Both counts use
//!   whole steps (module [`super`] doc): a flight line of length L holds ⌊L/d⌋ scan lines, a
//!   sweep over a range R holds ⌊R/δ⌋ pulses at min + iδ (max − iδ going back). A sawtooth or
//!   triangle wave sampled at a fixed rate gives exactly this grid.
//! - Time: the platform flies at `speed_m_s`, so a scan line lasts d / speed and its pulses are
//!   evenly spaced in it; the effective pulse rate is (pulses per scan line) × speed / d. When
//!   both steps are given (the paper's case) that rate follows from them and `prf_hz` is not
//!   used; when δ derives from `prf_hz` the rate is `prf_hz` when `prf_hz` / (scan lines per
//!   second) is whole, otherwise a little less (a part-step left at the end of a sweep is not
//!   fired). When `along_track_step_m` is given, `scan_frequency_hz` is not used either.
//! - Origins move with the platform: a pulse's origin is where the platform is at its GPS
//!   time, so scan lines on the ground are slightly slanted, as with a real scanner. Every
//!   origin lies on its flight line. Flight lines are flown in order; between two, the
//!   platform flies straight from one end to the next start at the same speed, so GPS times
//!   keep increasing with emission order. `line` = index of the flight line.

use super::{need, whole_steps, GroundPath, Pulse};
use crate::campaign::{Platform, PlatformKind, ScanPattern};
use crate::error::{Error, Result};
use glam::DVec3;

/// A flight line with what its pulses need: where its pulses start in the plan and when the
/// platform reaches its start.
struct Flight {
    path: GroundPath,
    first_id: u64,
    scan_lines: u64,
    t_start: f64,
}

pub(crate) struct Als {
    flights: Vec<Flight>,
    altitude: f64,
    speed: f64,
    pattern: ScanPattern,
    min_deg: f64,
    max_deg: f64,
    cone_deg: f64,
    /// d: along-track distance between scan lines, m.
    pub(crate) line_step_m: f64,
    /// δ: angle between pulses in a scan line, degrees (azimuth for conic).
    pub(crate) look_step_deg: f64,
    pub(crate) per_line: u64,
    gps_start: f64,
}

impl Als {
    pub(crate) fn new(p: &Platform) -> Result<Als> {
        let kind = PlatformKind::Als;
        let s = p
            .scanner
            .as_ref()
            .ok_or_else(|| Error::msg("an als platform needs scanner"))?;
        let pattern = s.pattern;
        let speed = need(p.speed_m_s, kind, "speed_m_s")?;
        let [min_deg, max_deg] = s.scan_angle_deg;
        let lines_per_s = match s.along_track_step_m {
            Some(d) => speed / d,
            None => {
                need(s.scan_frequency_hz, kind, "scanner.scan_frequency_hz")?
                    * pattern.lines_per_period()
            }
        };
        let line_step_m = s.along_track_step_m.unwrap_or(speed / lines_per_s);
        let sweep_deg = match pattern {
            ScanPattern::Conic => 360.0,
            ScanPattern::Line | ScanPattern::Oscillating => max_deg - min_deg,
        };
        let look_step_deg = match s.look_angle_step_deg {
            Some(a) => a,
            None => sweep_deg * lines_per_s / need(p.prf_hz, kind, "prf_hz")?,
        };
        let per_line = whole_steps(sweep_deg, look_step_deg);
        // Flights in order; between two, the platform flies straight from one end to the next
        // start. Summed in flight order, so every pulse's time is the same however it is found.
        let (mut flights, mut first_id, mut t_line) = (Vec::new(), 0u64, 0.0);
        let mut previous_end: Option<DVec3> = None;
        for seg in p.lines.as_deref().unwrap_or(&[]) {
            let path = GroundPath::new(seg);
            if let Some(e) = previous_end {
                t_line += (path.start - e).length() / speed;
            }
            let scan_lines = whole_steps(path.length, line_step_m);
            flights.push(Flight {
                path,
                first_id,
                scan_lines,
                t_start: t_line,
            });
            first_id = first_id.saturating_add(scan_lines.saturating_mul(per_line));
            t_line += path.length / speed;
            previous_end = Some(path.end);
        }
        Ok(Als {
            flights,
            altitude: need(p.altitude_m, kind, "altitude_m")?,
            speed,
            pattern,
            min_deg,
            max_deg,
            cone_deg: min_deg.abs().max(max_deg.abs()),
            line_step_m,
            look_step_deg,
            per_line,
            gps_start: p.gps_start_s.unwrap_or(0.0),
        })
    }

    /// Scan lines of each flight line, in order.
    pub(crate) fn scan_lines(&self) -> impl Iterator<Item = u64> + '_ {
        self.flights.iter().map(|f| f.scan_lines)
    }

    pub(crate) fn count(&self) -> u64 {
        self.flights.last().map_or(0, |f| {
            f.first_id
                .saturating_add(f.scan_lines.saturating_mul(self.per_line))
        })
    }

    /// Beam direction and scan-angle column of pulse `i` of scan line `j`.
    fn beam(&self, g: &GroundPath, j: u64, i: u64) -> (DVec3, f64) {
        let step = i as f64 * self.look_step_deg;
        let down = DVec3::NEG_Z;
        match self.pattern {
            ScanPattern::Line | ScanPattern::Oscillating => {
                // Clamped because whole_steps tolerates a last step overshooting by 1e-9.
                let theta = if self.pattern == ScanPattern::Oscillating && j % 2 == 1 {
                    (self.max_deg - step).max(self.min_deg)
                } else {
                    (self.min_deg + step).min(self.max_deg)
                };
                let (s, c) = theta.to_radians().sin_cos();
                (g.right * s + down * c, theta)
            }
            ScanPattern::Conic => {
                let (s, c) = self.cone_deg.to_radians().sin_cos();
                let (sa, ca) = step.to_radians().sin_cos();
                ((g.along * ca + g.right * sa) * s + down * c, self.cone_deg)
            }
        }
    }

    /// Pulse `id` (< [`Als::count`]).
    pub(crate) fn pulse(&self, id: u64) -> Pulse {
        let index = self.flights.partition_point(|f| f.first_id <= id) - 1;
        let f = &self.flights[index];
        let n = self.per_line;
        let (j, i) = ((id - f.first_id) / n, (id - f.first_id) % n);
        let lines_per_s = self.speed / self.line_step_m;
        // Scan lines flown since the start of this flight line, fractional.
        let s = j as f64 + i as f64 / n as f64;
        let (direction, angle) = self.beam(&f.path, j, i);
        Pulse {
            id,
            gps_time_s: self.gps_start + f.t_start + s / lines_per_s,
            origin: f.path.start + f.path.along * (s * self.line_step_m) + DVec3::Z * self.altitude,
            direction,
            scan_angle_deg: angle as f32,
            line: index as u32,
            along: f.path.along,
        }
    }
}
