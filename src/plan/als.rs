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

use super::nav::Errors;
use super::trajectory::Trajectory;
use super::{need, whole_steps, GroundPath, Pulse};
use crate::campaign::{Platform, PlatformKind, ScanPattern};
use crate::error::{Error, Result};
use glam::{DMat3, DVec3};

/// A flight line, or a scan interval of a trajectory, with what its pulses need: where its
/// pulses start in the plan and when its first scan line starts.
struct Flight {
    /// The straight line flown (`lines`); `None` on a trajectory.
    path: Option<GroundPath>,
    first_id: u64,
    scan_lines: u64,
    /// `lines`: seconds from the campaign's first pulse; a trajectory: GPS seconds.
    start_s: f64,
}

/// What the platform flies.
enum Route {
    /// Straight level lines at a constant height and speed.
    Lines {
        altitude: f64,
    },
    Trajectory(Box<Trajectory>),
}

/// The scanner's axes in the scene: forward, right and down.
struct Axes {
    along: DVec3,
    right: DVec3,
    down: DVec3,
}

impl Axes {
    /// A level scanner flying along `g`, as the straight lines have always been computed.
    fn level(g: &GroundPath) -> Axes {
        Axes {
            along: g.along,
            right: g.right,
            down: DVec3::NEG_Z,
        }
    }

    /// A scanner whose x, y, z (forward, left, up) are the columns of `m`.
    fn of(m: &DMat3) -> Axes {
        Axes {
            along: m.x_axis,
            right: -m.y_axis,
            down: -m.z_axis,
        }
    }
}

/// The rotation of a body (or a scanner against it) turned by roll, pitch and heading
/// (degrees), with the spec's R = Rz(90° − h)·Ry(−p)·Rx(r) less the 90° that puts heading 0
/// on grid north: B = Rz(−h)·Ry(−p)·Rx(r), a heading clockwise seen from above.
fn turned(rph: [f64; 3]) -> DMat3 {
    DMat3::from_rotation_z(-rph[2].to_radians())
        * DMat3::from_rotation_y(-rph[1].to_radians())
        * DMat3::from_rotation_x(rph[0].to_radians())
}

/// `m` = Rz(ψ)·Ry(θ)·Rx(φ) (ψ = 90° − h, θ = −p, φ = r) with roll, pitch and heading errors
/// (degrees) added to r, p and h.
fn with_attitude_error(m: &DMat3, e: [f64; 3]) -> DMat3 {
    let theta = (-m.x_axis.z).clamp(-1.0, 1.0).asin();
    let phi = m.y_axis.z.atan2(m.z_axis.z);
    let psi = m.x_axis.y.atan2(m.x_axis.x);
    DMat3::from_rotation_z(psi - e[2].to_radians())
        * DMat3::from_rotation_y(theta - e[1].to_radians())
        * DMat3::from_rotation_x(phi + e[0].to_radians())
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
    route: Route,
    pattern: ScanPattern,
    sweep: Sweep,
    lines_per_s: f64,
    /// d: along-track distance between scan lines, m (`lines`; 0 on a trajectory).
    pub(crate) line_step_m: f64,
    /// δ: angle between pulses in a scan line, degrees (azimuth for conic).
    pub(crate) look_step_deg: f64,
    pub(crate) per_line: u64,
    gps_start: f64,
    /// The mount's offset (body frame), its boresight, and the unknown boresight flown.
    offset: DVec3,
    mount: DMat3,
    unknown: DMat3,
    /// Straight lines with neither mount nor unknown boresight: the level frame, computed as
    /// it always was, so such campaigns keep their bytes.
    plain: bool,
    /// Whether the pulses carry a recorded pose (`errors` given), and its navigation errors.
    recorded: bool,
    errors: Option<Errors>,
}

impl Als {
    pub(crate) fn new(p: &Platform) -> Result<Als> {
        let kind = PlatformKind::Als;
        let s = p
            .scanner
            .as_ref()
            .ok_or_else(|| Error::msg("an als platform needs scanner"))?;
        let pattern = s.pattern;
        let trajectory = p.trajectory.as_ref().map(Trajectory::open).transpose()?;
        // a trajectory has no speed: its scan lines are timed by the scanner alone
        let speed = match &trajectory {
            Some(_) => {
                if s.along_track_step_m.is_some() {
                    return Err(Error::msg(
                        "scanner.along_track_step_m is not used with a trajectory \
                         (it has no constant speed): give scan_frequency_hz",
                    ));
                }
                None
            }
            None => Some(need(p.speed_m_s, kind, "speed_m_s")?),
        };
        let grid_angles = || need(s.scan_angle_deg, kind, "scanner.scan_angle_deg");
        let (sweep, lines_per_s, look_step_deg, per_line) = match pattern {
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
                (sweep, prf, 0.0, per_line)
            }
            _ => {
                let [min_deg, max_deg] = grid_angles()?;
                let lines_per_s = match (s.along_track_step_m, speed) {
                    (Some(d), Some(speed)) => speed / d,
                    _ => {
                        need(s.scan_frequency_hz, kind, "scanner.scan_frequency_hz")?
                            * pattern.lines_per_period()
                    }
                };
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
                (sweep, lines_per_s, look_step_deg, per_line)
            }
        };
        let (mut flights, mut first_id) = (Vec::new(), 0u64);
        let (route, line_step_m, lines_per_s, gps_start) = match (trajectory, speed) {
            (Some(t), _) => {
                let span = t.span();
                let intervals = p
                    .trajectory
                    .as_ref()
                    .and_then(|t| t.scan.clone())
                    .unwrap_or_else(|| vec![span]);
                for [t0, t1] in &intervals {
                    // GPS seconds near 1.3e9 resolve only 0.24 µs: a length short of whole
                    // lines by its ends' rounding alone is those whole lines
                    let slack = 2.0 * f64::EPSILON * t0.abs().max(t1.abs());
                    let scan_lines = whole_steps(t1 - t0 + slack, 1.0 / lines_per_s);
                    flights.push(Flight {
                        path: None,
                        first_id,
                        scan_lines,
                        start_s: *t0,
                    });
                    first_id = first_id.saturating_add(scan_lines.saturating_mul(per_line));
                }
                let gps_start = intervals.first().map_or(span[0], |i| i[0]);
                (Route::Trajectory(Box::new(t)), 0.0, lines_per_s, gps_start)
            }
            (None, speed) => {
                let speed = speed.unwrap_or(1.0);
                let line_step_m = match pattern {
                    ScanPattern::Risley | ScanPattern::Multibeam => speed / lines_per_s,
                    _ => s.along_track_step_m.unwrap_or(speed / lines_per_s),
                };
                // Flights in order; between two, the platform flies straight from one end to
                // the next start. Summed in flight order, so every pulse's time is the same
                // however it is found.
                let (mut t_line, mut previous_end) = (0.0, None::<DVec3>);
                for seg in p.lines.as_deref().unwrap_or(&[]) {
                    let path = GroundPath::new(seg);
                    if let Some(e) = previous_end {
                        t_line += (path.start - e).length() / speed;
                    }
                    let scan_lines = whole_steps(path.length, line_step_m);
                    flights.push(Flight {
                        path: Some(path),
                        first_id,
                        scan_lines,
                        start_s: t_line,
                    });
                    first_id = first_id.saturating_add(scan_lines.saturating_mul(per_line));
                    t_line += path.length / speed;
                    previous_end = Some(path.end);
                }
                let altitude = need(p.altitude_m, kind, "altitude_m")?;
                (
                    Route::Lines { altitude },
                    line_step_m,
                    speed / line_step_m,
                    p.gps_start_s.unwrap_or(0.0),
                )
            }
        };
        let mount = p.mount.clone().unwrap_or_default();
        let unknown = p.errors.as_ref().and_then(|e| e.boresight_deg);
        let plain = matches!(route, Route::Lines { .. })
            && p.mount.is_none()
            && unknown.is_none_or(|b| b == [0.0; 3]);
        Ok(Als {
            flights,
            route,
            pattern,
            sweep,
            lines_per_s,
            line_step_m,
            look_step_deg,
            per_line,
            gps_start,
            offset: DVec3::from_array(mount.offset_m.unwrap_or([0.0; 3])),
            mount: turned(mount.boresight_deg.unwrap_or([0.0; 3])),
            unknown: turned(unknown.unwrap_or([0.0; 3])),
            plain,
            recorded: p.errors.is_some(),
            errors: None,
        })
    }

    /// The navigation errors of `p.errors`, drawn from `seed`.
    pub(crate) fn with_errors(mut self, p: &Platform, seed: u64) -> Als {
        if let Some(e) = &p.errors {
            let n = self.count();
            self.errors = Errors::new(e, seed, n, &|id| self.time(id).1);
        }
        self
    }

    pub(crate) fn trajectory_note(&self) -> Option<String> {
        let Route::Trajectory(t) = &self.route else {
            return None;
        };
        let [t0, t1] = t.span();
        let scanned: f64 = self
            .flights
            .iter()
            .map(|f| f.scan_lines as f64 / self.lines_per_s)
            .sum();
        Some(format!(
            "{} epochs from {t0} to {t1} s (GPS), {} scan interval{} firing over {scanned:.3} s",
            t.epochs(),
            self.flights.len(),
            if self.flights.len() == 1 { "" } else { "s" }
        ))
    }

    pub(crate) fn records_pose(&self) -> bool {
        self.recorded
    }

    /// Scan lines of each flight line (or scan interval), in order.
    pub(crate) fn scan_lines(&self) -> impl Iterator<Item = u64> + '_ {
        self.flights.iter().map(|f| f.scan_lines)
    }

    pub(crate) fn count(&self) -> u64 {
        self.flights.last().map_or(0, |f| {
            f.first_id
                .saturating_add(f.scan_lines.saturating_mul(self.per_line))
        })
    }

    /// The first pulse of pulse `id`'s flight line (or scan interval).
    pub(crate) fn line_start(&self, id: u64) -> u64 {
        self.flights[self.locate(id).0].first_id
    }

    /// Flight, scan line j in it and pulse i in that, of pulse `id`.
    fn locate(&self, id: u64) -> (usize, u64, u64) {
        let index = self.flights.partition_point(|f| f.first_id <= id) - 1;
        let f = &self.flights[index];
        let n = self.per_line;
        (index, (id - f.first_id) / n, (id - f.first_id) % n)
    }

    /// Scan lines flown since the start of the flight, fractional: a grid spreads a line's
    /// pulses over its period, a multibeam head fires its channels at once.
    fn lines_flown(&self, j: u64, i: u64) -> f64 {
        let frac = match &self.sweep {
            Sweep::Grid { per_period, .. } => i as f64 / per_period,
            Sweep::Risley { .. } | Sweep::Multibeam { .. } => 0.0,
        };
        j as f64 + frac
    }

    /// (GPS time, seconds since the campaign's first scan line began) of a pulse `dt` seconds
    /// into flight `f`.
    fn times(&self, f: &Flight, dt: f64) -> (f64, f64) {
        match self.route {
            Route::Lines { .. } => {
                let t = f.start_s + dt;
                (self.gps_start + t, t)
            }
            Route::Trajectory(_) => (f.start_s + dt, (f.start_s - self.gps_start) + dt),
        }
    }

    /// (GPS time, seconds since the first scan line began) of pulse `id`.
    fn time(&self, id: u64) -> (f64, f64) {
        let (index, j, i) = self.locate(id);
        let f = &self.flights[index];
        self.times(f, self.lines_flown(j, i) / self.lines_per_s)
    }

    /// Beam direction and scan-angle column of pulse `i` of scan line `j`, fired `t` seconds
    /// after the campaign's first pulse, from a scanner whose axes are `a`.
    fn beam(&self, a: &Axes, j: u64, i: u64, t: f64) -> (DVec3, f64) {
        let down = a.down;
        let left = -a.right;
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
                        ((a.along * ca + a.right * sa) * s + down * c, *cone_deg)
                    }
                    _ => {
                        // Clamped because whole_steps tolerates a last step overshooting by 1e-9.
                        let theta = if self.pattern == ScanPattern::Oscillating && j % 2 == 1 {
                            (max_deg - step).max(*min_deg)
                        } else {
                            (min_deg + step).min(*max_deg)
                        };
                        let (s, c) = theta.to_radians().sin_cos();
                        (a.right * s + down * c, theta)
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
                ((a.along * az.cos() + left * az.sin()) * s + down * c, off)
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
                    a.along * b.x + left * b.y - down * b.z,
                    channels_deg[i as usize],
                )
            }
        }
    }

    /// The scan angle LAS records of pulse `p` (its `scan_angle_deg` is the scanner's look
    /// angle): the recorded beam's angle from the scene's nadir in the plane across the
    /// body's heading, positive to the right (counter-clockwise seen from behind), so a
    /// roll is in it, as LAS defines it ("with respect to the vertical of the coordinate
    /// system of the data"; ±180° is up). A cone's or a rosette's look angle is unsigned
    /// and off nadir, a multibeam channel's an elevation: each is projected so. A sweep
    /// across track on straight level lines keeps its look angle, which is that angle there.
    pub(crate) fn las_angle(&self, p: &Pulse) -> f32 {
        let sweep = matches!(
            self.pattern,
            ScanPattern::Line | ScanPattern::Oscillating | ScanPattern::RotatingPolygon
        );
        if self.plain && sweep {
            return p.scan_angle_deg;
        }
        let (x, d) = (p.along, p.rec_direction());
        let right = DVec3::new(x.y, -x.x, 0.0)
            .try_normalize()
            .unwrap_or_else(|| {
                (-p.up.cross(p.along))
                    .with_z(0.0)
                    .try_normalize()
                    .unwrap_or(DVec3::X)
            });
        d.dot(right).atan2(-d.z).to_degrees() as f32
    }

    /// (left to right, edge of the scan line) of pulse `id`: see [`super::Plan::scan_flags`].
    pub(crate) fn scan_flags(&self, id: u64) -> (bool, bool) {
        let (_, j, i) = self.locate(id);
        let edge = i + 1 == self.per_line;
        match self.pattern {
            ScanPattern::Line | ScanPattern::RotatingPolygon => (true, edge),
            // a line's first pulse is the turn itself, at the swath's edge: the last point
            // before the mirror changes direction, as LAS defines the flag (not the one a step
            // before it); the flight's first pulse turns nothing
            ScanPattern::Oscillating => (j % 2 == 0, i == 0 && j > 0),
            _ => (false, false),
        }
    }

    /// Pulse `id` (< [`Als::count`]).
    pub(crate) fn pulse(&self, id: u64) -> Pulse {
        let (index, j, i) = self.locate(id);
        let f = &self.flights[index];
        let s = self.lines_flown(j, i);
        let dt = s / self.lines_per_s;
        let (gps_time_s, t) = self.times(f, dt);
        // the body's position and axes (columns: forward, left, up)
        let (position, body) = match (&self.route, &f.path) {
            (Route::Trajectory(tr), _) => {
                let (p, q) = tr.pose(f.start_s, dt);
                (p, DMat3::from_quat(q))
            }
            (Route::Lines { altitude }, Some(g)) => (
                g.start + g.along * (s * self.line_step_m) + DVec3::Z * *altitude,
                DMat3::from_cols(g.along, -g.right, DVec3::Z),
            ),
            (Route::Lines { .. }, None) => unreachable!("a flight line has its path"),
        };
        let (origin, direction, angle) = match (&f.path, self.plain) {
            (Some(g), true) => {
                let (d, a) = self.beam(&Axes::level(g), j, i, t);
                (position, d, a)
            }
            _ => {
                let flown = body * self.mount * self.unknown;
                let (d, a) = self.beam(&Axes::of(&flown), j, i, t);
                (position + body * self.offset, d, a)
            }
        };
        let recorded = self.recorded.then(|| match &self.errors {
            None if self.unknown == DMat3::IDENTITY => (origin, direction),
            None => {
                let (d, _) = self.beam(&Axes::of(&(body * self.mount)), j, i, t);
                (origin, d)
            }
            Some(e) => {
                let (dp, da) = e.at(id, &|k| self.time(k).1);
                let rec = with_attitude_error(&body, da);
                let (d, _) = self.beam(&Axes::of(&(rec * self.mount)), j, i, t);
                (position + DVec3::from_array(dp) + rec * self.offset, d)
            }
        });
        Pulse {
            id,
            gps_time_s,
            origin,
            direction,
            scan_angle_deg: angle as f32,
            line: index as u32,
            along: body.x_axis,
            up: body.z_axis,
            recorded,
        }
    }
}
