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
//! - `rotating_polygon` draws parallel lines like `line`, but a line lasts a full period of
//!   the polygon's facet (1 / `scan_frequency_hz`) and only its first `duty` fires: pulse i of a
//!   line is at u = i / P of it (P = `prf_hz` / `scan_frequency_hz` pulses per period), at the
//!   look angle min + (max − min) u, for every i with u < duty. The `scan_angle_deg` column is
//!   the signed angle.
//! - `risley` and `multibeam` fire at `prf_hz` from the first pulse on, t = k / `prf_hz`; a
//!   "scan line" is one firing, d = speed / `prf_hz` apart. Risley (paraxial): prism i deflects
//!   by d_i (cos p_i, sin p_i), p_i = 360° rate_i t + phase_i, and the beam leaves at off-nadir
//!   |d_1 + d_2| towards the body azimuth of d_1 + d_2 (0 = body x, forward; counter-clockwise
//!   seen from above, so 90° = left); the column is the off-nadir angle. Multibeam: every
//!   channel fires at once, at azimuth φ = 360° `rotation_hz` t (counter-clockwise from body
//!   x seen from above) and its elevation e above the head's plane, the head rolled by
//!   `head_tilt_deg` about the body's x axis (right side down, as a positive roll); the column
//!   is the channel's elevation. Body x is along the flight line, y to its left, z up.
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

/// What turns a pulse's place in its scan line, and its time, into a beam.
enum Sweep {
    /// Line, oscillating, conic and rotating polygon: the look angle from the scan line and
    /// the pulse's index in it; pulses per line period (the time a pulse takes, as a fraction
    /// of the line).
    Grid {
        min_deg: f64,
        max_deg: f64,
        cone_deg: f64,
        per_period: f64,
    },
    Risley {
        rates_hz: [f64; 2],
        deviation_deg: [f64; 2],
        phase_deg: [f64; 2],
    },
    Multibeam {
        channels_deg: Vec<f64>,
        rotation_hz: f64,
        tilt_deg: f64,
    },
}

pub(crate) struct Als {
    flights: Vec<Flight>,
    altitude: f64,
    speed: f64,
    pattern: ScanPattern,
    sweep: Sweep,
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
        let grid_angles = || need(s.scan_angle_deg, kind, "scanner.scan_angle_deg");
        let (sweep, line_step_m, look_step_deg, per_line) = match pattern {
            ScanPattern::Risley | ScanPattern::Multibeam => {
                let prf = need(p.prf_hz, kind, "prf_hz")?;
                let sweep = if pattern == ScanPattern::Risley {
                    Sweep::Risley {
                        rates_hz: need(s.prism_rates_hz, kind, "scanner.prism_rates_hz")?,
                        deviation_deg: need(s.deviation_deg, kind, "scanner.deviation_deg")?,
                        phase_deg: s.phase_deg.unwrap_or([0.0; 2]),
                    }
                } else {
                    Sweep::Multibeam {
                        channels_deg: need(s.channels_deg.as_ref(), kind, "scanner.channels_deg")?
                            .clone(),
                        rotation_hz: need(s.rotation_hz, kind, "scanner.rotation_hz")?,
                        tilt_deg: s.head_tilt_deg.unwrap_or(0.0),
                    }
                };
                let per_line = match &sweep {
                    Sweep::Multibeam { channels_deg, .. } => channels_deg.len() as u64,
                    _ => 1,
                };
                (sweep, speed / prf, 0.0, per_line)
            }
            _ => {
                let [min_deg, max_deg] = grid_angles()?;
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
                    _ => max_deg - min_deg,
                };
                let look_step_deg = match s.look_angle_step_deg {
                    Some(a) => a,
                    None => sweep_deg * lines_per_s / need(p.prf_hz, kind, "prf_hz")?,
                };
                let (per_line, per_period) = if pattern == ScanPattern::RotatingPolygon {
                    // P pulses per period, the first `duty` of them fired: i < duty P
                    let per_period = sweep_deg / look_step_deg;
                    let fired = s.duty.unwrap_or(1.0) * per_period;
                    let n = if (fired - fired.round()).abs() < 1e-9 {
                        fired.round()
                    } else {
                        fired.ceil()
                    };
                    (n as u64, per_period)
                } else {
                    let n = whole_steps(sweep_deg, look_step_deg);
                    (n, n as f64)
                };
                let sweep = Sweep::Grid {
                    min_deg,
                    max_deg,
                    cone_deg: min_deg.abs().max(max_deg.abs()),
                    per_period,
                };
                (sweep, line_step_m, look_step_deg, per_line)
            }
        };
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
            sweep,
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

    /// Beam direction and scan-angle column of pulse `i` of scan line `j`, fired `t` seconds
    /// after the campaign's first pulse.
    fn beam(&self, g: &GroundPath, j: u64, i: u64, t: f64) -> (DVec3, f64) {
        let down = DVec3::NEG_Z;
        let left = -g.right;
        match &self.sweep {
            Sweep::Grid {
                min_deg,
                max_deg,
                cone_deg,
                ..
            } => {
                let step = i as f64 * self.look_step_deg;
                match self.pattern {
                    ScanPattern::Conic => {
                        let (s, c) = cone_deg.to_radians().sin_cos();
                        let (sa, ca) = step.to_radians().sin_cos();
                        ((g.along * ca + g.right * sa) * s + down * c, *cone_deg)
                    }
                    _ => {
                        // Clamped because whole_steps tolerates a last step overshooting by 1e-9.
                        let theta = if self.pattern == ScanPattern::Oscillating && j % 2 == 1 {
                            (max_deg - step).max(*min_deg)
                        } else {
                            (min_deg + step).min(*max_deg)
                        };
                        let (s, c) = theta.to_radians().sin_cos();
                        (g.right * s + down * c, theta)
                    }
                }
            }
            Sweep::Risley {
                rates_hz,
                deviation_deg,
                phase_deg,
            } => {
                let deflection = |k: usize| {
                    let p = (360.0 * rates_hz[k] * t + phase_deg[k]).to_radians();
                    glam::DVec2::new(p.cos(), p.sin()) * deviation_deg[k]
                };
                let d = deflection(0) + deflection(1);
                let off = d.length();
                let az = d.y.atan2(d.x);
                let (s, c) = off.to_radians().sin_cos();
                ((g.along * az.cos() + left * az.sin()) * s + down * c, off)
            }
            Sweep::Multibeam {
                channels_deg,
                rotation_hz,
                tilt_deg,
            } => {
                let e = channels_deg[i as usize].to_radians();
                let phi = (360.0 * rotation_hz * t).to_radians();
                // in the head's frame, then rolled by the tilt about body x
                let h = DVec3::new(e.cos() * phi.cos(), e.cos() * phi.sin(), e.sin());
                let (sr, cr) = tilt_deg.to_radians().sin_cos();
                let b = DVec3::new(h.x, h.y * cr - h.z * sr, h.y * sr + h.z * cr);
                (
                    g.along * b.x + left * b.y + DVec3::Z * b.z,
                    channels_deg[i as usize],
                )
            }
        }
    }

    /// (left to right, edge of the scan line) of pulse `id`: see [`super::Plan::scan_flags`].
    pub(crate) fn scan_flags(&self, id: u64) -> (bool, bool) {
        let index = self.flights.partition_point(|f| f.first_id <= id) - 1;
        let f = &self.flights[index];
        let n = self.per_line;
        let (j, i) = ((id - f.first_id) / n, (id - f.first_id) % n);
        let edge = i + 1 == n;
        match self.pattern {
            ScanPattern::Line | ScanPattern::RotatingPolygon => (true, edge),
            ScanPattern::Oscillating => (j % 2 == 0, edge),
            _ => (false, false),
        }
    }

    /// Pulse `id` (< [`Als::count`]).
    pub(crate) fn pulse(&self, id: u64) -> Pulse {
        let index = self.flights.partition_point(|f| f.first_id <= id) - 1;
        let f = &self.flights[index];
        let n = self.per_line;
        let (j, i) = ((id - f.first_id) / n, (id - f.first_id) % n);
        let lines_per_s = self.speed / self.line_step_m;
        // Scan lines flown since the start of this flight line, fractional: a grid spreads a
        // line's pulses over its period, a multibeam head fires its channels at once
        let frac = match &self.sweep {
            Sweep::Grid { per_period, .. } => i as f64 / per_period,
            Sweep::Risley { .. } | Sweep::Multibeam { .. } => 0.0,
        };
        let s = j as f64 + frac;
        let t = f.t_start + s / lines_per_s;
        let (direction, angle) = self.beam(&f.path, j, i, t);
        Pulse {
            id,
            gps_time_s: self.gps_start + t,
            origin: f.path.start + f.path.along * (s * self.line_step_m) + DVec3::Z * self.altitude,
            direction,
            scan_angle_deg: angle as f32,
            line: index as u32,
            along: f.path.along,
        }
    }
}
