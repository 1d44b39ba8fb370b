//! Checks of a campaign's `platform:` block ([`platform`]), after `Campaign::validate`.
//!
//! It lives here, beside the planners, because the checks that matter most (a line too
//! short for one scan line, a step larger than its range, a plan too big) need the same
//! derived quantities the planners compute.

use super::{als::Als, kind_phrase, ScanPattern, MAX_PULSES};
use crate::campaign::{Check, Doc, Platform, PlatformKind, Segment};
use crate::error::Result;

/// Flight lines, scan intervals or stations past this would share LAS's last point source id
/// (16 bits: lines and intervals from 1, stations from 0).
const MAX_SOURCES: usize = 65535;

/// Checks a campaign's `platform:` block: the keys its kind takes, the static pulses, the
/// numbers and the size of the plan.
pub fn platform(doc: &Doc, p: &Platform) -> Result<()> {
    let c = &Check { doc };
    keys(doc, p)?;
    if p.kind == PlatformKind::Static {
        let pulses = p.pulses.as_ref().ok_or_else(|| {
            doc.error(
                "platform",
                "a static platform needs `pulses:`, a list of { position, direction }",
            )
        })?;
        if pulses.is_empty() {
            return Err(doc.error("platform.pulses", "the list of pulses is empty"));
        }
        for (k, pulse) in pulses.iter().enumerate() {
            c.coordinates(&format!("platform.pulses[{k}].position"), &pulse.position)?;
            match (&pulse.direction, pulse.zenith_deg, pulse.azimuth_deg) {
                (Some(d), None, None) => {
                    let key = format!("platform.pulses[{k}].direction");
                    c.vec_finite(&key, d)?;
                    if (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() < 1e-12 {
                        return Err(doc.error(&key, "must not be the zero vector"));
                    }
                }
                (None, z, a) => {
                    if let Some(z) = z {
                        c.finite(&format!("platform.pulses[{k}].zenith_deg"), z)?;
                    }
                    if let Some(a) = a {
                        c.finite(&format!("platform.pulses[{k}].azimuth_deg"), a)?;
                    }
                }
                (Some(_), _, _) => {
                    return Err(doc.error(
                        &format!("platform.pulses[{k}].direction"),
                        "give either `direction` or `zenith_deg`/`azimuth_deg`, not both",
                    ))
                }
            }
        }
    }
    numbers(doc, p)?;
    size(doc, p)
}

/// Every platform key and whether this platform gives it.
fn given(p: &Platform) -> [(&'static str, bool); 21] {
    [
        ("pulses", p.pulses.is_some()),
        ("altitude_m", p.altitude_m.is_some()),
        ("speed_m_s", p.speed_m_s.is_some()),
        ("ground_speed_m_s", p.ground_speed_m_s.is_some()),
        ("prf_hz", p.prf_hz.is_some()),
        ("lines", p.lines.is_some()),
        ("scanner", p.scanner.is_some()),
        ("track", p.track.is_some()),
        ("beams", p.beams.is_some()),
        ("off_nadir_deg", p.off_nadir_deg.is_some()),
        ("along_track_step_m", p.along_track_step_m.is_some()),
        ("position", p.position.is_some()),
        ("positions", p.positions.is_some()),
        ("azimuth_deg", p.azimuth_deg.is_some()),
        ("azimuth_step_deg", p.azimuth_step_deg.is_some()),
        ("zenith_deg", p.zenith_deg.is_some()),
        ("zenith_step_deg", p.zenith_step_deg.is_some()),
        ("gps_start_s", p.gps_start_s.is_some()),
        ("trajectory", p.trajectory.is_some()),
        ("mount", p.mount.is_some()),
        ("errors", p.errors.is_some()),
    ]
}

/// (keys the kind needs, keys it may also take). `prf_hz` is conditionally needed by als
/// (checked in `als`); static's `pulses` is checked with its own message by the caller.
fn keys_of(p: &Platform) -> (&'static [&'static str], &'static [&'static str]) {
    match p.kind {
        PlatformKind::Static => (&[], &["pulses", "gps_start_s"]),
        PlatformKind::Als if p.trajectory.is_some() => {
            (&["trajectory", "scanner"], &["prf_hz", "mount", "errors"])
        }
        PlatformKind::Als => (
            &["altitude_m", "speed_m_s", "lines", "scanner"],
            &["prf_hz", "gps_start_s", "mount", "errors"],
        ),
        PlatformKind::Spaceborne => (
            &["altitude_m", "ground_speed_m_s", "prf_hz", "track"],
            &["beams", "off_nadir_deg", "gps_start_s"],
        ),
        PlatformKind::Track => (
            &["altitude_m", "track", "along_track_step_m"],
            &["prf_hz", "gps_start_s"],
        ),
        PlatformKind::Tls => (
            &[
                "azimuth_deg",
                "azimuth_step_deg",
                "zenith_deg",
                "zenith_step_deg",
            ],
            &["position", "positions", "prf_hz", "gps_start_s"],
        ),
    }
}

/// A pointer to the key the user probably meant.
fn hint(p: &Platform, key: &str) -> &'static str {
    use PlatformKind::*;
    if p.kind == Als
        && p.trajectory.is_some()
        && ["altitude_m", "speed_m_s", "lines", "gps_start_s"].contains(&key)
    {
        return " (with a trajectory, its file gives the times, positions and attitudes)";
    }
    match (p.kind, key) {
        (Als, "along_track_step_m") => " (an als along-track step goes under `scanner:`)",
        (Als, "ground_speed_m_s") => " (an als platform takes speed_m_s)",
        (Spaceborne, "speed_m_s") => " (a spaceborne platform takes ground_speed_m_s)",
        (Als, "track") => " (an als platform takes `lines: [{ start, end }]`)",
        (Spaceborne | Track, "lines") => " (this kind takes one `track: { start, end }`)",
        (Track, "speed_m_s" | "ground_speed_m_s") => " (a track platform is timed by prf_hz alone)",
        _ => "",
    }
}

/// Keys that do not belong to the kind, and keys it needs but lacks.
pub fn keys(doc: &Doc, p: &Platform) -> Result<()> {
    let (required, optional) = keys_of(p);
    let phrase = kind_phrase(p.kind);
    let given = given(p);
    for (key, here) in given {
        if here && !required.contains(&key) && !optional.contains(&key) {
            return Err(doc.error(
                &format!("platform.{key}"),
                format!("not used by {phrase} platform{}", hint(p, key)),
            ));
        }
    }
    for key in required {
        if !given.iter().any(|(k, here)| k == key && *here) {
            return Err(doc.error("platform", format!("{phrase} platform needs {key}")));
        }
    }
    Ok(())
}

/// The scanner keys each pattern takes: a key of another pattern is an error naming it, and a
/// key a pattern needs, missing, is one too.
fn pattern_keys(c: &Check, s: &crate::campaign::Scanner) -> Result<()> {
    use ScanPattern::*;
    let given = [
        ("scan_angle_deg", s.scan_angle_deg.is_some()),
        ("scan_frequency_hz", s.scan_frequency_hz.is_some()),
        ("look_angle_step_deg", s.look_angle_step_deg.is_some()),
        ("along_track_step_m", s.along_track_step_m.is_some()),
        ("facets", s.facets.is_some()),
        ("duty", s.duty.is_some()),
        ("prism_rates_hz", s.prism_rates_hz.is_some()),
        ("deviation_deg", s.deviation_deg.is_some()),
        ("phase_deg", s.phase_deg.is_some()),
        ("channels_deg", s.channels_deg.is_some()),
        ("rotation_hz", s.rotation_hz.is_some()),
        ("head_tilt_deg", s.head_tilt_deg.is_some()),
    ];
    let grid: &[&str] = &[
        "scan_angle_deg",
        "scan_frequency_hz",
        "look_angle_step_deg",
        "along_track_step_m",
    ];
    let (needs, takes): (&[&str], Vec<&str>) = match s.pattern {
        Line | Oscillating | Conic => (&["scan_angle_deg"], grid.to_vec()),
        RotatingPolygon => (&["scan_angle_deg"], [grid, &["facets", "duty"]].concat()),
        Risley => (
            &["prism_rates_hz", "deviation_deg"],
            vec!["prism_rates_hz", "deviation_deg", "phase_deg"],
        ),
        Multibeam => (
            &["channels_deg", "rotation_hz"],
            vec!["channels_deg", "rotation_hz", "head_tilt_deg"],
        ),
    };
    let name = serde_yaml::to_value(s.pattern)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default();
    for (key, here) in given {
        if here && !takes.contains(&key) {
            return Err(c.doc.error(
                &format!("platform.scanner.{key}"),
                format!("not used by the {name} pattern"),
            ));
        }
    }
    for key in needs {
        if !given.iter().any(|(k, here)| k == key && *here) {
            return Err(c.doc.error(
                "platform.scanner",
                format!("the {name} pattern needs {key}"),
            ));
        }
    }
    Ok(())
}

/// Number checks of the non-static kinds (static is checked by the caller).
///
/// A flat list of located checks, one per key of each platform kind.
pub fn numbers(doc: &Doc, p: &Platform) -> Result<()> {
    let c = Check { doc };
    if let Some(t) = p.gps_start_s {
        // GPS seconds since 1980-01-06: 10^10 is the year 2296
        c.within(
            "platform.gps_start_s",
            t,
            0.0,
            1e10,
            "GPS seconds since 1980-01-06, from 0 to 10^10",
        )?;
    }
    c.opt_positive("platform.altitude_m", p.altitude_m)?;
    if let Some(h) = p.altitude_m {
        c.within(
            "platform.altitude_m",
            h,
            0.0,
            crate::campaign::MAX_PLATFORM_COORDINATE_M,
            "metres up to 10^8 (100,000 km)",
        )?;
    }
    c.opt_positive("platform.prf_hz", p.prf_hz)?;
    match p.kind {
        PlatformKind::Static => Ok(()),
        PlatformKind::Als => als(&c, p),
        PlatformKind::Spaceborne => {
            c.opt_positive("platform.ground_speed_m_s", p.ground_speed_m_s)?;
            if let Some(t) = &p.track {
                segment(&c, "platform.track", t)?;
            }
            if let Some(beams) = &p.beams {
                if beams.is_empty() {
                    return Err(doc.error(
                        "platform.beams",
                        "the list of beams is empty (leave `beams` out for one nadir beam)",
                    ));
                }
                for (b, beam) in beams.iter().enumerate() {
                    c.within(
                        &format!("platform.beams[{b}].cross_track_m"),
                        beam.cross_track_m,
                        -1e6,
                        1e6,
                        "metres within ±1000 km",
                    )?;
                    c.opt_positive(
                        &format!("platform.beams[{b}].relative_energy"),
                        beam.relative_energy,
                    )?;
                }
            }
            if let Some(a) = p.off_nadir_deg {
                c.open_deg("platform.off_nadir_deg", a, -90.0, 90.0)?;
            }
            Ok(())
        }
        PlatformKind::Track => {
            if let Some(t) = &p.track {
                segment(&c, "platform.track", t)?;
            }
            c.opt_positive("platform.along_track_step_m", p.along_track_step_m)?;
            if let (Some(t), Some(step)) = (&p.track, p.along_track_step_m) {
                let length = super::GroundPath::new(t).length;
                if super::whole_steps(length, step) == 0 {
                    return Err(doc.error(
                        "platform.along_track_step_m",
                        format!("{step} m is longer than the track ({length} m): no pulse fits"),
                    ));
                }
            }
            Ok(())
        }
        PlatformKind::Tls => {
            match (&p.position, &p.positions) {
                (Some(pos), None) => c.coordinates("platform.position", pos)?,
                (None, Some(list)) if list.len() > MAX_SOURCES + 1 => {
                    return Err(doc.error(
                        "platform.positions",
                        format!(
                            "{} positions: LAS numbers a point's station in 16 bits, 65536 at most (0 to 65535)",
                            list.len()
                        ),
                    ))
                }
                (None, Some(list)) if !list.is_empty() => {
                    for (k, pos) in list.iter().enumerate() {
                        c.coordinates(&format!("platform.positions[{k}]"), pos)?;
                    }
                }
                (None, Some(_)) => {
                    return Err(doc.error(
                        "platform.positions",
                        "the list of scan positions is empty (give at least one [x, y, z])",
                    ))
                }
                (Some(_), Some(_)) => {
                    return Err(doc.error(
                        "platform.positions",
                        "give either `position` (one station) or `positions` (several), not both",
                    ))
                }
                (None, None) => {
                    return Err(doc.error(
                        "platform",
                        "a tls platform needs position (one station) or positions (several)",
                    ))
                }
            }
            if let Some([a0, a1]) = p.azimuth_deg {
                let key = "platform.azimuth_deg";
                c.finite(key, a0)?;
                c.finite(key, a1)?;
                if a1 < a0 || a1 - a0 > 360.0 * (1.0 + super::TOL) {
                    return Err(doc.error(
                        key,
                        format!(
                            "must be [from, to] with from <= to <= from + 360, found [{a0}, {a1}]"
                        ),
                    ));
                }
            }
            c.opt_positive("platform.azimuth_step_deg", p.azimuth_step_deg)?;
            if let Some([z0, z1]) = p.zenith_deg {
                let key = "platform.zenith_deg";
                for z in [z0, z1] {
                    c.finite(key, z)?;
                    if !(0.0..=180.0).contains(&z) {
                        return Err(doc.error(
                            key,
                            format!(
                                "zenith angles must lie within [0, 180] degrees, found {}",
                                crate::campaign::shown(z)
                            ),
                        ));
                    }
                }
                if z1 < z0 {
                    return Err(doc.error(
                        key,
                        format!("must be [from, to] with from <= to, found [{z0}, {z1}]"),
                    ));
                }
            }
            c.opt_positive("platform.zenith_step_deg", p.zenith_step_deg)
        }
    }
}

/// The ALS platform's checks: scanner, lines and pulse rate, one located check per key.
fn als(c: &Check, p: &Platform) -> Result<()> {
    let doc = c.doc;
    c.opt_positive("platform.speed_m_s", p.speed_m_s)?;
    let Some(s) = &p.scanner else { return Ok(()) };
    let pattern = s.pattern;
    pattern_keys(c, s)?;
    let (mut lo, mut hi) = (0.0, 0.0);
    match pattern {
        ScanPattern::Risley => {
            let key = "platform.scanner.prism_rates_hz";
            for r in s.prism_rates_hz.unwrap_or_default() {
                c.finite(key, r)?;
            }
            for d in s.deviation_deg.unwrap_or_default() {
                c.open_deg("platform.scanner.deviation_deg", d, 0.0, 45.0)?;
            }
            for ph in s.phase_deg.unwrap_or_default() {
                c.finite("platform.scanner.phase_deg", ph)?;
            }
            if p.prf_hz.is_none() {
                return Err(doc.error("platform", "a risley scanner needs platform.prf_hz"));
            }
        }
        ScanPattern::Multibeam => {
            let key = "platform.scanner.channels_deg";
            let channels = s.channels_deg.as_deref().unwrap_or(&[]);
            if channels.is_empty() {
                return Err(doc.error(key, "the list of channels is empty"));
            }
            for &e in channels {
                c.open_deg(key, e, -90.0, 90.0)?;
            }
            c.opt_positive("platform.scanner.rotation_hz", s.rotation_hz)?;
            if let Some(t) = s.head_tilt_deg {
                // ±90: the head's axis level, its channels sweeping a vertical plane
                let key = "platform.scanner.head_tilt_deg";
                c.finite(key, t)?;
                if t.abs() > 90.0 {
                    return Err(doc.error(
                        key,
                        format!(
                            "must lie between -90 and 90 degrees, found {}",
                            crate::campaign::shown(t)
                        ),
                    ));
                }
            }
            if p.prf_hz.is_none() {
                return Err(doc.error("platform", "a multibeam scanner needs platform.prf_hz"));
            }
        }
        _ => {
            let key = "platform.scanner.scan_angle_deg";
            [lo, hi] = s.scan_angle_deg.unwrap_or_default();
            // a polygon fires only the first `duty` of its sweep: the angles fired must look
            // below the horizon, the sweep's end may lie past it (±30° at duty 0.5 is
            // [-30, 90])
            // the duty first: the angles' range depends on it
            if let Some(d) = s.duty {
                if !(d > 0.0 && d <= 1.0) {
                    return Err(doc.error(
                        "platform.scanner.duty",
                        format!("must be in (0, 1], found {}", crate::campaign::shown(d)),
                    ));
                }
            }
            let fired = match (pattern, s.duty) {
                (ScanPattern::RotatingPolygon, Some(d)) if d > 0.0 && d < 1.0 => d,
                _ => 1.0,
            };
            c.open_deg(key, lo, -90.0, 90.0)?;
            if fired < 1.0 {
                c.finite(key, hi)?;
                let end = lo + fired * (hi - lo);
                if end >= 90.0 {
                    return Err(doc.error(
                        key,
                        format!(
                            "the angles fired at duty {fired} reach {} degrees: they must stay below 90",
                            if end < 1e6 { format!("{end:.2}") } else { format!("{end:.3e}") }
                        ),
                    ));
                }
            } else {
                c.open_deg(key, hi, -90.0, 90.0)?;
            }
            if lo >= hi {
                return Err(doc.error(
                    key,
                    format!("must be [min, max] with min < max, found [{lo}, {hi}]"),
                ));
            }
            c.opt_positive("platform.scanner.scan_frequency_hz", s.scan_frequency_hz)?;
            c.opt_positive(
                "platform.scanner.look_angle_step_deg",
                s.look_angle_step_deg,
            )?;
            c.opt_positive("platform.scanner.along_track_step_m", s.along_track_step_m)?;
            if let Some(0) = s.facets {
                return Err(doc.error("platform.scanner.facets", "must be at least 1"));
            }
            if s.along_track_step_m.is_none() && s.scan_frequency_hz.is_none() {
                return Err(doc.error(
                    "platform.scanner",
                    "an als scanner needs scan_frequency_hz unless along_track_step_m is given",
                ));
            }
            if s.look_angle_step_deg.is_none() && p.prf_hz.is_none() {
                return Err(doc.error(
                    "platform",
                    "an als platform needs prf_hz unless scanner.look_angle_step_deg is given",
                ));
            }
        }
    }
    mount_and_errors(c, p)?;
    if let Some(t) = &p.trajectory {
        return trajectory(c, p, t);
    }
    let lines = p.lines.as_deref().unwrap_or(&[]);
    if lines.is_empty() {
        return Err(doc.error("platform.lines", "the list of flight lines is empty"));
    }
    if lines.len() > MAX_SOURCES {
        return Err(doc.error(
            "platform.lines",
            format!(
                "{} flight lines: LAS numbers a point's line in 16 bits, 65535 at most (1 to 65535)",
                lines.len()
            ),
        ));
    }
    for (i, l) in lines.iter().enumerate() {
        segment(c, &format!("platform.lines[{i}]"), l)?;
    }
    // Every key is present and sane here, so the planner's derived quantities exist.
    let a = Als::new(p).map_err(|e| doc.error("platform", e))?;
    if a.per_line == 0 {
        let (key, what) = match s.look_angle_step_deg {
            Some(_) => (
                "platform.scanner.look_angle_step_deg",
                "the look angle step is",
            ),
            None => (
                "platform.prf_hz",
                "prf_hz is too low: the derived look angle step is",
            ),
        };
        let sweep = if pattern == ScanPattern::Conic {
            "a turn (360°)".to_string()
        } else {
            format!("the scan range ({}°)", hi - lo)
        };
        return Err(doc.error(
            key,
            format!(
                "{what} {}°, wider than {sweep}: no pulse fits in a scan line",
                a.look_step_deg
            ),
        ));
    }
    for (i, (l, n)) in lines.iter().zip(a.scan_lines()).enumerate() {
        if n == 0 {
            return Err(doc.error(
                &format!("platform.lines[{i}]"),
                format!(
                    "is {} m long, shorter than one along-track step ({} m): no scan line fits",
                    super::GroundPath::new(l).length,
                    a.line_step_m
                ),
            ));
        }
    }
    Ok(())
}

/// `mount` and `errors`: finite numbers, angles below 90°, standard deviations and
/// correlation times not negative.
fn mount_and_errors(c: &Check, p: &Platform) -> Result<()> {
    let angles = |key: &str, v: [f64; 3]| -> Result<()> {
        for a in v {
            c.open_deg(key, a, -90.0, 90.0)?;
        }
        Ok(())
    };
    if let Some(m) = &p.mount {
        if let Some(o) = &m.offset_m {
            for v in o {
                c.within(
                    "platform.mount.offset_m",
                    *v,
                    -1000.0,
                    1000.0,
                    "metres between -1000 and 1000",
                )?;
            }
        }
        if let Some(b) = m.boresight_deg {
            angles("platform.mount.boresight_deg", b)?;
        }
    }
    if let Some(e) = &p.errors {
        for (key, sd) in [
            ("platform.errors.position_sd_m", e.position_sd_m),
            ("platform.errors.attitude_sd_deg", e.attitude_sd_deg),
        ] {
            for v in sd.unwrap_or_default() {
                c.within(key, v, 0.0, 1e4, "from 0 to 10^4")?;
            }
        }
        for (key, tau) in [
            (
                "platform.errors.position_correlation_s",
                e.position_correlation_s,
            ),
            (
                "platform.errors.attitude_correlation_s",
                e.attitude_correlation_s,
            ),
        ] {
            if let Some(t) = tau {
                c.non_negative(key, t)?;
            }
        }
        if let Some(b) = e.boresight_deg {
            angles("platform.errors.boresight_deg", b)?;
        }
    }
    Ok(())
}

/// A trajectory platform: its file (errors name the file's line and column), its scan
/// intervals within the file's times, and a scan line in each.
fn trajectory(c: &Check, p: &Platform, t: &crate::campaign::Trajectory) -> Result<()> {
    let doc = c.doc;
    if p.scanner
        .as_ref()
        .is_some_and(|s| s.along_track_step_m.is_some())
    {
        return Err(doc.error(
            "platform.scanner.along_track_step_m",
            "not used with a trajectory (it has no constant speed): give scan_frequency_hz",
        ));
    }
    let path = t.resolved.clone().unwrap_or_else(|| t.file.clone().into());
    if !path.is_file() {
        return Err(doc.error(
            "platform.trajectory.file",
            format!(
                "trajectory file {} {}",
                path.display(),
                crate::error::not_a_file(&path)
            ),
        ));
    }
    let span = super::trajectory::Trajectory::open(t)?.span();
    let key = "platform.trajectory.scan";
    if let Some(intervals) = &t.scan {
        if intervals.is_empty() {
            return Err(doc.error(key, "the list of scan intervals is empty (leave `scan` out to scan the whole trajectory)"));
        }
        if intervals.len() > MAX_SOURCES {
            return Err(doc.error(
                key,
                format!(
                    "{} scan intervals: LAS numbers a point's interval in 16 bits, 65535 at most (1 to 65535)",
                    intervals.len()
                ),
            ));
        }
        let mut previous = f64::NEG_INFINITY;
        for (k, &[t0, t1]) in intervals.iter().enumerate() {
            let key = format!("{key}[{k}]");
            c.finite(&key, t0)?;
            c.finite(&key, t1)?;
            if t1 <= t0 {
                return Err(doc.error(
                    &key,
                    format!("must be [from, to] with from < to, found [{t0}, {t1}]"),
                ));
            }
            if t0 < span[0] || t1 > span[1] {
                return Err(doc.error(
                    &key,
                    format!(
                        "[{t0}, {t1}] is not within the trajectory's times [{}, {}]",
                        span[0], span[1]
                    ),
                ));
            }
            if t0 < previous {
                return Err(doc.error(
                    &key,
                    format!("starts at {t0} s, before the interval before it ends ({previous} s): give the intervals in time order, apart"),
                ));
            }
            previous = t1;
        }
    }
    let a = Als::new(p).map_err(|e| doc.error("platform", e))?;
    if a.per_line == 0 {
        return Err(doc.error(
            "platform.prf_hz",
            format!(
                "prf_hz is too low: the derived look angle step is {}°, wider than the scan: no pulse fits in a scan line",
                a.look_step_deg
            ),
        ));
    }
    for (k, n) in a.scan_lines().enumerate() {
        if n == 0 {
            let which = if t.scan.is_some() {
                format!("{key}[{k}]")
            } else {
                "platform.trajectory".to_string()
            };
            return Err(doc.error(&which, "is shorter than one scan line: no pulse fits"));
        }
    }
    Ok(())
}

/// The plan is neither empty nor over [`MAX_PULSES`].
pub fn size(doc: &Doc, p: &Platform) -> Result<()> {
    let n = super::count(p).map_err(|e| doc.error("platform", e))?;
    if n == 0 {
        return Err(doc.error("platform", "the platform plans no pulse"));
    }
    if n > MAX_PULSES {
        return Err(doc.error("platform", super::too_many(n)));
    }
    Ok(())
}

/// A segment's ends are finite and distinct.
fn segment(c: &Check, key: &str, s: &Segment) -> Result<()> {
    c.coordinates(&format!("{key}.start"), &s.start)?;
    c.coordinates(&format!("{key}.end"), &s.end)?;
    if s.start == s.end {
        return Err(c.doc.error(
            &format!("{key}.end"),
            format!(
                "must differ from start ({:?}): a line needs a direction",
                s.start
            ),
        ));
    }
    Ok(())
}
