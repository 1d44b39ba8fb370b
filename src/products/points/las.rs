//! points.las: LAS 1.4, point format 6, millimetre precision, with two extra dimensions (three
//! in a run of several bands: `wavelength_nm` too).

use crate::error::{Error, Result};
use crate::fsutil::{write_atomic, WRITE_ADVICE};
use crate::products::points::Point;
use las::point::Classification;
use las::{Builder, Reader, Transform, Vector, Version, Vlr, Writer};
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::Path;

/// The coarsest coordinate step, used when the points span more than i32 steps of [`FINE`]
/// (214 km); the finest otherwise, so that a coordinate's rounding stays far below the
/// millimetre a user compares points at.
pub const SCALE: f64 = 0.001;
pub const FINE: f64 = 0.0001;

/// Extra bytes per point: `apparent_reflectance` f32 then `pulse_id` u64, little-endian.
const EXTRA: [(&str, u8, usize, &str); 2] = [
    (
        "apparent_reflectance",
        9,
        4,
        "(pi / solid angle) (Q_i / Q_e)",
    ),
    ("pulse_id", 7, 8, "pulse index in pulses.parquet"),
];

/// The extra dimension of a run of several bands, after the others: the point's band.
const BAND: (&str, u8, usize, &str) = ("wavelength_nm", 9, 4, "band of the return, nm");

/// LAS 1.4 data types: 1 u8, 2 i8, 3 u16, 4 i16, 5 u32, 6 i32, 7 u64, 8 i64, 9 f32, 10 f64.
fn type_size(t: u8) -> Option<usize> {
    match t {
        1 | 2 => Some(1),
        3 | 4 => Some(2),
        5 | 6 | 9 => Some(4),
        7 | 8 | 10 => Some(8),
        _ => None,
    }
}

/// The Extra Bytes VLR (LAS 1.4 R15, table 24): one 192-byte descriptor per field, options
/// 0 (no no-data, min, max, scale or offset).
fn extra_bytes_vlr(bands: bool) -> Vlr {
    let mut data = Vec::with_capacity(192 * (EXTRA.len() + 1));
    let band = bands.then_some(BAND);
    for (name, data_type, _, description) in EXTRA.into_iter().chain(band) {
        let mut d = [0u8; 192];
        d[2] = data_type;
        d[4..4 + name.len()].copy_from_slice(name.as_bytes());
        d[160..160 + description.len()].copy_from_slice(description.as_bytes());
        data.extend_from_slice(&d);
    }
    Vlr {
        user_id: "LASF_Spec".to_string(),
        record_id: 4,
        description: "Extra bytes".to_string(),
        data,
    }
}

fn extra_len(bands: bool) -> u16 {
    (EXTRA.iter().map(|e| e.2).sum::<usize>() + if bands { BAND.2 } else { 0 }) as u16
}

/// Writes the points (in the given order) to a LAS 1.4 point format 6 file. The offset is
/// the floor of each coordinate's minimum, so every coordinate is a whole number of steps
/// (0.1 mm, or 1 mm past 214 km) from it and fits i32 for extents up to 2000 km.
pub fn write_las(path: &Path, points: &[Point]) -> Result<()> {
    let mut extent = Extent::default();
    extent.add(path, points)?;
    let offset = extent.offset(path, [0.0; 3])?;
    let layout = Layout {
        gps_offset_s: extent.gps_offset_s(),
        ..Layout::local(offset, extent.scale(offset, [0.0; 3]))
    };
    let mut chunks = Some(points);
    write_las_chunks(path, &layout, |each| match chunks.take() {
        Some(c) => each(c),
        None => Ok(()),
    })
}

/// How the points are written: the LAS offsets, the shift from the scene's local metres to
/// the file's coordinates (the frame's origin, else 0), the CRS as OGC WKT, and LAZ or not.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    pub offset: [f64; 3],
    /// The coordinates' step: [`FINE`] or [`SCALE`] ([`Extent::scale`]).
    pub scale: f64,
    pub shift: [f64; 3],
    pub wkt: Option<&'static str>,
    pub laz: bool,
    /// A run of several bands: each point's `wavelength_nm` is written too.
    pub bands: bool,
    /// Subtracted from every GPS time as it is written ([`Extent::gps_offset_s`]): 0 for
    /// GPS week time (the header's GPS time type bit clear), [`STANDARD_GPS_OFFSET_S`] for
    /// adjusted standard GPS time (the bit set).
    pub gps_offset_s: f64,
}

/// Adjusted standard GPS time is GPS seconds less 10⁹ (LAS 1.4, global encoding bit 0).
pub const STANDARD_GPS_OFFSET_S: f64 = 1e9;

/// A GPS week, s: the range of GPS week time.
const GPS_WEEK_S: f64 = 604_800.0;

impl Layout {
    /// Local metres, no CRS, LAS.
    pub fn local(offset: [f64; 3], scale: f64) -> Layout {
        Layout {
            offset,
            scale,
            shift: [0.0; 3],
            wkt: None,
            laz: false,
            bands: false,
            gps_offset_s: 0.0,
        }
    }
}

/// What the LAS offsets need of the points, gathered as they stream by: each coordinate's
/// minimum, and the points farthest from it.
#[derive(Clone, Debug, Default)]
pub struct Extent {
    min: Option<[f64; 3]>,
    /// Per axis, the point with the largest coordinate.
    max: [Option<Point>; 3],
    /// The earliest and latest GPS times.
    gps: Option<(f64, f64)>,
}

impl Extent {
    /// Takes in more points; a point with a non-finite coordinate is an error.
    pub fn add(&mut self, path: &Path, points: &[Point]) -> Result<()> {
        for p in points {
            let v = [p.x, p.y, p.z];
            if !v.iter().all(|c| c.is_finite()) {
                return Err(Error::file(
                    path,
                    format!("point of pulse {} has a non-finite coordinate", p.pulse_id),
                ));
            }
            let (lo, hi) = self.gps.get_or_insert((p.gps_time, p.gps_time));
            (*lo, *hi) = (lo.min(p.gps_time), hi.max(p.gps_time));
            let min = self.min.get_or_insert(v);
            for axis in 0..3 {
                min[axis] = min[axis].min(v[axis]);
                if self.max[axis]
                    .as_ref()
                    .is_none_or(|m| v[axis] > [m.x, m.y, m.z][axis])
                {
                    self.max[axis] = Some(p.clone());
                }
            }
        }
        Ok(())
    }

    /// The offsets: the floor of each minimum (0 without points), once every coordinate is
    /// known to be a whole number of millimetres from it within i32; checked here, before
    /// any point is written, because the las crate panics when a writer that failed a point
    /// is dropped.
    /// `shift` is added to every coordinate as it is written (a frame's origin): rounding is
    /// monotonic, so the shifted minimum is the minimum of the shifted coordinates.
    pub fn offset(&self, path: &Path, shift: [f64; 3]) -> Result<[f64; 3]> {
        let offset = self
            .min
            .map_or([0.0; 3], |m| [0, 1, 2].map(|a| (m[a] + shift[a]).floor()));
        for (axis, p) in self.max.iter().enumerate() {
            let Some(p) = p else { continue };
            if ([p.x, p.y, p.z][axis] + shift[axis] - offset[axis]) / SCALE >= i32::MAX as f64 {
                return Err(Error::file(
                    path,
                    format!(
                        "point of pulse {} at ({}, {}, {}) m lies more than 2000 km from the others: LAS cannot hold it",
                        p.pulse_id, p.x, p.y, p.z
                    ),
                ));
            }
        }
        Ok(offset)
    }

    /// How the GPS times are written ([`Layout::gps_offset_s`]). Times within GPS week 0
    /// (a campaign's default `gps_start_s` of 0) are the same numbers as GPS week time, and
    /// are written as they are; any later time is not a time of the week, and LAS 1.4 asks
    /// for adjusted standard GPS time, exact for the times of any real acquisition (from
    /// 1995 on, where the subtraction of 10⁹ is exact).
    pub fn gps_offset_s(&self) -> f64 {
        match self.gps {
            Some((lo, hi)) if !(lo >= 0.0 && hi < GPS_WEEK_S) => STANDARD_GPS_OFFSET_S,
            _ => 0.0,
        }
    }

    /// [`FINE`] when every shifted coordinate is within i32 steps of it from `offset`, else
    /// [`SCALE`].
    pub fn scale(&self, offset: [f64; 3], shift: [f64; 3]) -> f64 {
        let fits = self.max.iter().enumerate().all(|(axis, p)| {
            p.as_ref().is_none_or(|p| {
                ([p.x, p.y, p.z][axis] + shift[axis] - offset[axis]) / FINE < i32::MAX as f64
            })
        });
        if fits {
            FINE
        } else {
            SCALE
        }
    }
}

/// Writes points.las (or .laz) as `layout` says from the points `chunks` hands to its
/// callback, in order.
pub fn write_las_chunks(
    path: &Path,
    layout: &Layout,
    chunks: impl FnOnce(&mut dyn FnMut(&[Point]) -> Result<()>) -> Result<()>,
) -> Result<()> {
    let err = |e: las::Error| {
        Error::io(
            path,
            "cannot write LAS",
            std::io::Error::other(e.to_string()),
        )
        .advise(crate::fsutil::WRITE_ADVICE)
    };
    let offset = layout.offset;
    let mut b = Builder::from((1, 4));
    b.version = Version::new(1, 4);
    b.point_format = las::point::Format::new(6).map_err(err)?;
    b.point_format.extra_bytes = extra_len(layout.bands);
    b.point_format.is_compressed = layout.laz;
    let transform = |offset| Transform {
        scale: layout.scale,
        offset,
    };
    b.transforms = Vector {
        x: transform(offset[0]),
        y: transform(offset[1]),
        z: transform(offset[2]),
    };
    b.generating_software = format!("lidarsim {}", env!("CARGO_PKG_VERSION"));
    if layout.gps_offset_s != 0.0 {
        b.gps_time_type = las::GpsTimeType::Standard;
    }
    b.vlrs.push(extra_bytes_vlr(layout.bands));
    let mut header = b.into_header().map_err(err)?;
    if let Some(wkt) = layout.wkt {
        // LAS 1.4: "The OGC Coordinate System WKT VLR data shall be a null-terminated string"
        let mut bytes = wkt.as_bytes().to_vec();
        bytes.push(0);
        header.set_wkt_crs(bytes).map_err(err)?;
    }
    write_atomic(path, |file| {
        let sink = Sticky {
            inner: BufWriter::new(file),
            error: None,
        };
        let mut w = Writer::new(sink, header).map_err(err)?;
        let mut fix = HeaderFix::default();
        let transforms = *w.header().transforms();
        let written = chunks(&mut |points| {
            for p in points {
                let q = to_las(p, layout);
                fix.add(&q, &transforms)?;
                w.write_point(q).map_err(err)?;
            }
            Ok(())
        });
        let mut sink = w.into_inner().map_err(err)?;
        written?;
        let flushed = sink.inner.flush();
        let patched = flushed.and_then(|()| fix.patch(sink.inner.get_mut(), layout));
        match sink.error.take().map_or(patched, Err) {
            Ok(()) => Ok(()),
            Err(e) => Err(Error::io(path, "cannot write LAS", e).advise(WRITE_ADVICE)),
        }
    })
}

/// What the las crate leaves to be put right in a LAS 1.4 header once the points are
/// written: its bounds round outwards from the unquantised coordinates (a step beyond the
/// stored ones, which readers that check the header against the points report), it fills
/// the legacy point counts, which LAS 1.4 requires to be 0 for point format 6, and it leaves
/// the creation date 0. The date written is the day of the earliest point's GPS time (the
/// UTC day but for the leap seconds' few seconds after midnight): the simulated
/// acquisition's, so that the same run gives the same bytes.
#[derive(Default)]
struct HeaderFix {
    /// Per axis, the least and greatest stored coordinate (in steps from the offset).
    steps: Option<[[i32; 2]; 3]>,
    first_gps_s: Option<f64>,
}

impl HeaderFix {
    fn add(&mut self, p: &las::Point, t: &Vector<Transform>) -> Result<()> {
        let q = [p.x, p.y, p.z]
            .into_iter()
            .zip([t.x, t.y, t.z])
            .map(|(v, t)| t.inverse(v))
            .collect::<std::result::Result<Vec<i32>, _>>()
            .map_err(|e| Error::msg(format!("cannot write LAS: {e}")))?;
        let s = self.steps.get_or_insert([[q[0]; 2], [q[1]; 2], [q[2]; 2]]);
        for (axis, v) in q.into_iter().enumerate() {
            s[axis][0] = s[axis][0].min(v);
            s[axis][1] = s[axis][1].max(v);
        }
        if let Some(t) = p.gps_time {
            self.first_gps_s = Some(self.first_gps_s.map_or(t, |f| f.min(t)));
        }
        Ok(())
    }

    fn patch(&self, file: &mut std::fs::File, layout: &Layout) -> std::io::Result<()> {
        if let Some(t) = self.first_gps_s {
            let (year, day) = gps_year_and_day(t + layout.gps_offset_s);
            let mut date = [0u8; 4];
            date[..2].copy_from_slice(&day.to_le_bytes());
            date[2..].copy_from_slice(&year.to_le_bytes());
            file.seek(SeekFrom::Start(90))?;
            file.write_all(&date)?;
        }
        // legacy number of point records and by return (offsets 107-130)
        file.seek(SeekFrom::Start(107))?;
        file.write_all(&[0u8; 24])?;
        if let Some(s) = self.steps {
            // max x, min x, max y, min y, max z, min z (offsets 179-226)
            let mut b = Vec::with_capacity(48);
            for (axis, [lo, hi]) in s.into_iter().enumerate() {
                let at = |k: i32| layout.offset[axis] + layout.scale * k as f64;
                b.extend_from_slice(&at(hi).to_le_bytes());
                b.extend_from_slice(&at(lo).to_le_bytes());
            }
            file.seek(SeekFrom::Start(179))?;
            file.write_all(&b)?;
        }
        file.seek(SeekFrom::End(0))?;
        Ok(())
    }
}

/// The year and day of the year (from 1) of a GPS time in seconds since 1980-01-06, on
/// GPS's clock; clamped to the years a LAS header can hold.
fn gps_year_and_day(gps_s: f64) -> (u16, u16) {
    // days from 1970-01-01 (the civil-from-days algorithm's epoch) to 1980-01-06: 3657
    let days = (gps_s / 86_400.0).floor().clamp(-3e6, 3e7) as i64 + 3657;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy_march = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy_march + 2) / 153;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
    // day of the year from the March-based day: January and February close the year before
    let day = if month <= 2 {
        doy_march - 306
    } else {
        doy_march + 59 + i64::from(leap)
    } + 1;
    (year.clamp(0, 65_535) as u16, day.clamp(1, 366) as u16)
}

/// A writer that never fails: it keeps the first error and drops what follows. The las
/// crate panics when a writer whose stream failed (a full disk) is dropped, so its stream
/// must not fail; the error is returned once the writer is done.
#[derive(Debug)]
struct Sticky<W> {
    inner: W,
    error: Option<std::io::Error>,
}

impl<W: Write> Write for Sticky<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.error.is_none() {
            if let Err(e) = self.inner.write_all(buf) {
                self.error = Some(e);
            }
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if self.error.is_none() {
            if let Err(e) = self.inner.flush() {
                self.error = Some(e);
            }
        }
        Ok(())
    }
}

impl<W: Seek> Seek for Sticky<W> {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        if self.error.is_none() {
            match self.inner.seek(pos) {
                Ok(at) => return Ok(at),
                Err(e) => self.error = Some(e),
            }
        }
        Ok(0)
    }
}

fn to_las(p: &Point, layout: &Layout) -> las::Point {
    let shift = layout.shift;
    let mut extra = Vec::with_capacity(extra_len(layout.bands) as usize);
    extra.extend_from_slice(&p.apparent_reflectance.to_le_bytes());
    extra.extend_from_slice(&p.pulse_id.to_le_bytes());
    if layout.bands {
        extra.extend_from_slice(&p.wavelength_nm.unwrap_or(f32::NAN).to_le_bytes());
    }
    // Code 12 (overlap) is a flag in LAS 1.4, not a class: such a point is unclassified.
    let classification =
        Classification::new(p.classification).unwrap_or(Classification::Unclassified);
    las::Point {
        x: p.x + shift[0],
        y: p.y + shift[1],
        z: p.z + shift[2],
        intensity: p.intensity,
        return_number: p.return_number.min(15),
        number_of_returns: p.number_of_returns.min(15),
        classification,
        scan_angle: scan_angle_for_las(p.scan_angle_deg),
        scan_direction: if p.left_to_right {
            las::point::ScanDirection::LeftToRight
        } else {
            las::point::ScanDirection::RightToLeft
        },
        is_edge_of_flight_line: p.edge_of_line,
        point_source_id: p.point_source_id,
        gps_time: Some(p.gps_time - layout.gps_offset_s),
        extra_bytes: extra,
        ..Default::default()
    }
}

/// Format 6 stores the scan angle in 0.006° steps and the crate truncates towards zero:
/// hand it the middle of the nearest step so the stored value is the rounded one.
fn scan_angle_for_las(deg: f32) -> f32 {
    let k = (deg as f64 / 0.006).round().clamp(-30_000.0, 30_000.0);
    if !k.is_finite() {
        return 0.0;
    }
    ((k + 0.5f64.copysign(k)) * 0.006) as f32
}

/// Reads a LAS file written by [`write_las`] (or any file with the same two extra
/// dimensions, found by name in its Extra Bytes VLR).
pub fn read_las(path: &Path) -> Result<Vec<Point>> {
    let err = |e: las::Error| Error::data(path, format!("cannot read LAS: {e}"));
    let mut reader = Reader::from_path(path).map_err(err)?;
    // the pulses' GPS seconds again, from adjusted standard GPS time when the header says so
    let gps_offset_s = if reader.header().gps_time_type().is_standard() {
        STANDARD_GPS_OFFSET_S
    } else {
        0.0
    };
    let offsets = {
        let vlr = reader
            .header()
            .all_vlrs()
            .find(|v| v.user_id == "LASF_Spec" && v.record_id == 4)
            .ok_or_else(|| Error::data(path, "no Extra Bytes VLR"))?;
        let mut at = 0usize;
        let mut found = [None; 2];
        let mut band = None;
        for d in vlr.data.chunks_exact(192) {
            let name_end = d[4..36].iter().position(|&c| c == 0).unwrap_or(32);
            let name = std::str::from_utf8(&d[4..4 + name_end]).unwrap_or("");
            let size = if d[2] == 0 {
                d[3] as usize // undocumented bytes: options holds the length
            } else {
                type_size(d[2]).ok_or_else(|| Error::data(path, "unknown extra bytes type"))?
            };
            for (k, e) in EXTRA.iter().enumerate() {
                if e.0 == name && e.1 == d[2] {
                    found[k] = Some(at);
                }
            }
            if BAND.0 == name && BAND.1 == d[2] {
                band = Some(at);
            }
            at += size;
        }
        match found {
            [Some(a), Some(b)] => (a, b, band),
            _ => {
                return Err(Error::data(
                    path,
                    "missing apparent_reflectance or pulse_id",
                ))
            }
        }
    };
    // a chunk at a time, not `read_all`: that reserves what the header claims, and a damaged
    // count (10^9 points) aborted the process on a failed allocation
    const CHUNK: u64 = 1 << 16;
    let claimed = reader.header().number_of_points();
    let mut data = las::PointDataBuilder::new()
        .for_header(reader.header())
        .build();
    let mut out = Vec::new();
    let short = |held: usize| {
        move |e: las::Error| {
            Error::data(
                path,
                format!(
                    "cannot read LAS: the header gives {claimed} points, {held} read before: {e}"
                ),
            )
        }
    };
    while reader
        .fill_points(CHUNK, &mut data)
        .map_err(short(out.len()))?
        > 0
    {
        for p in data.points() {
            out.push(las_point(path, p.map_err(err)?, offsets, gps_offset_s)?);
        }
    }
    if out.len() as u64 != claimed {
        return Err(Error::data(
            path,
            format!(
                "the header gives {claimed} points, the file holds {}",
                out.len()
            ),
        ));
    }
    Ok(out)
}

/// One point of [`read_las`], its extra bytes at `offsets` (reflectance, pulse id, band).
fn las_point(
    path: &Path,
    p: las::Point,
    offsets: (usize, usize, Option<usize>),
    gps_offset_s: f64,
) -> Result<Point> {
    let e = &p.extra_bytes;
    if e.len() < offsets.0 + 4 || e.len() < offsets.1 + 8 {
        return Err(Error::data(path, "point too short for its extra bytes"));
    }
    let rho = f32::from_le_bytes(e[offsets.0..offsets.0 + 4].try_into().expect("4 bytes"));
    let id = u64::from_le_bytes(e[offsets.1..offsets.1 + 8].try_into().expect("8 bytes"));
    let wavelength_nm = match offsets.2 {
        Some(at) => {
            let b = e
                .get(at..at + 4)
                .ok_or_else(|| Error::data(path, "point too short for its wavelength_nm"))?;
            Some(f32::from_le_bytes(b.try_into().expect("4 bytes")))
        }
        None => None,
    };
    Ok(Point {
        x: p.x,
        y: p.y,
        z: p.z,
        gps_time: p.gps_time.unwrap_or(0.0) + gps_offset_s,
        intensity: p.intensity,
        return_number: p.return_number,
        number_of_returns: p.number_of_returns,
        scan_angle_deg: p.scan_angle,
        point_source_id: p.point_source_id,
        classification: u8::from(p.classification),
        apparent_reflectance: rho,
        pulse_id: id,
        wavelength_nm,
        left_to_right: p.scan_direction == las::point::ScanDirection::LeftToRight,
        edge_of_line: p.is_edge_of_flight_line,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn sample(n: usize) -> Vec<Point> {
        let mut r = SplitMix64::new(11);
        (0..n)
            .map(|i| {
                let nr = 1 + (i % 4) as u8;
                Point {
                    x: 651_234.0 + 98.0 * r.uniform(),
                    y: 5_432_100.0 + 98.0 * r.uniform(),
                    z: -3.0 + 30.0 * r.uniform(),
                    gps_time: 1.0e5 + i as f64 * 1e-5,
                    intensity: (r.next_u64() % 65536) as u16,
                    return_number: 1 + (i as u8 % nr),
                    number_of_returns: nr,
                    // Format 6 stores the angle in 0.006° steps.
                    scan_angle_deg: ((r.uniform() * 22.2 - 11.1) / 0.006).round() as f32 * 0.006,
                    point_source_id: 1 + (i % 3) as u16,
                    classification: [1, 2, 5, 6][i % 4],
                    apparent_reflectance: r.uniform() as f32,
                    pulse_id: (1u64 << 40) + i as u64,
                    wavelength_nm: None,
                    left_to_right: i % 2 == 0,
                    edge_of_line: i % 7 == 0,
                }
            })
            .collect()
    }

    /// A file `name` in a folder of its own, removed with the folder.
    fn tmp(name: &str) -> (crate::testdata::TempDir, std::path::PathBuf) {
        let d = crate::testdata::TempDir::new(&format!("las-{name}"));
        let p = d.join(name);
        (d, p)
    }

    /// The header's bounds are the stored coordinates' (not a step beyond), its legacy point
    /// counts 0 (point format 6), its creation date the earliest point's UTC day, and GPS
    /// times past week 0 in adjusted standard GPS time (GPS seconds less 10⁹, the global
    /// encoding's bit 0 set), read back as the GPS seconds they were.
    #[test]
    fn header_bounds_counts_date_and_gps_time() {
        let mut pts = sample(500);
        // 2019-10-21T10:30:00Z, the GPS time of the bundled ICESat-2-like campaign
        for (i, p) in pts.iter_mut().enumerate() {
            p.gps_time = 1_255_689_018.0 + i as f64;
        }
        for laz in [false, true] {
            let (_dir, path) = tmp(if laz { "header.laz" } else { "header.las" });
            let mut extent = Extent::default();
            extent.add(&path, &pts).unwrap();
            assert_eq!(extent.gps_offset_s(), STANDARD_GPS_OFFSET_S);
            let layout = Layout {
                laz,
                gps_offset_s: extent.gps_offset_s(),
                ..Layout::local([651_000.0, 5_432_000.0, -4.0], FINE)
            };
            let mut chunks = Some(&pts[..]);
            write_las_chunks(&path, &layout, |each| match chunks.take() {
                Some(c) => each(c),
                None => Ok(()),
            })
            .unwrap();
            let raw = std::fs::read(&path).unwrap();
            let u16_at = |k: usize| u16::from_le_bytes([raw[k], raw[k + 1]]);
            let f64_at = |k: usize| f64::from_le_bytes(raw[k..k + 8].try_into().unwrap());
            assert_eq!(
                (u16_at(92), u16_at(90)),
                (2019, 294),
                "2019-10-21 is day 294"
            );
            assert!(raw[107..131].iter().all(|&b| b == 0), "legacy counts");
            assert_eq!(u16_at(6) & 1, 1, "GPS time type: adjusted standard");
            let data = Reader::from_path(&path).unwrap().read_all().unwrap();
            let stored: Vec<f64> = data
                .points()
                .map(|p| p.unwrap().gps_time.unwrap())
                .collect();
            assert_eq!(stored[7], 255_689_025.0);
            let back = read_las(&path).unwrap();
            for (a, b) in pts.iter().zip(&back) {
                assert_eq!(a.gps_time, b.gps_time);
            }
            for (axis, k) in [(0usize, 179usize), (1, 195), (2, 211)] {
                let v: Vec<f64> = back.iter().map(|p| [p.x, p.y, p.z][axis]).collect();
                let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
                assert_eq!(
                    (f64_at(k), f64_at(k + 8)),
                    (hi, lo),
                    "axis {axis}, laz {laz}"
                );
            }
            let h = Reader::from_path(&path).unwrap().header().clone();
            assert_eq!(h.number_of_points(), 500);
        }
        // within GPS week 0 (the default `gps_start_s` of 0), GPS week time: the same numbers
        let mut extent = Extent::default();
        extent.add(Path::new("week"), &sample(3)).unwrap();
        assert_eq!(extent.gps_offset_s(), 0.0);
        let (_dir, path) = tmp("week.las");
        write_las(&path, &sample(3)).unwrap();
        assert!(!Reader::from_path(&path)
            .unwrap()
            .header()
            .gps_time_type()
            .is_standard());
        assert_eq!(gps_year_and_day(0.0), (1980, 6));
        assert_eq!(gps_year_and_day(1_198_800_018.0), (2018, 1));
        // 2020-12-31T12:00:00Z, the 366th day of a leap year (GPS time 18 s ahead of UTC)
        assert_eq!(gps_year_and_day(1_293_451_218.0), (2020, 366));
        assert_eq!(gps_year_and_day(1_235_433_618.0), (2019, 60), "2019-03-01");
    }

    /// Points 300 km apart do not fit i32 steps of 0.1 mm: the file falls back to 1 mm.
    #[test]
    fn a_wide_extent_takes_millimetre_steps() {
        let mut pts = sample(4);
        pts[3].x += 300_000.0;
        let (_dir, path) = tmp("wide.las");
        write_las(&path, &pts).unwrap();
        let h = Reader::from_path(&path).unwrap().header().clone();
        assert_eq!(h.transforms().x.scale, SCALE);
        for (a, b) in pts.iter().zip(read_las(&path).unwrap()) {
            assert!((a.x - b.x).abs() <= 0.0005 + 1e-9, "{} {}", a.x, b.x);
        }
    }

    #[test]
    fn write_then_read_back() {
        let pts = sample(1000);
        let (_dir, path) = tmp("roundtrip.las");
        write_las(&path, &pts).unwrap();
        let back = read_las(&path).unwrap();
        assert_eq!(back.len(), pts.len());
        for (a, b) in pts.iter().zip(&back) {
            assert!((a.x - b.x).abs() <= 0.00005 + 1e-9, "{} {}", a.x, b.x);
            assert!((a.y - b.y).abs() <= 0.00005 + 1e-9);
            assert!((a.z - b.z).abs() <= 0.00005 + 1e-9);
            assert_eq!(a.gps_time, b.gps_time);
            assert_eq!(
                (
                    a.intensity,
                    a.return_number,
                    a.number_of_returns,
                    a.point_source_id
                ),
                (
                    b.intensity,
                    b.return_number,
                    b.number_of_returns,
                    b.point_source_id
                )
            );
            assert!((a.scan_angle_deg - b.scan_angle_deg).abs() < 1e-4);
            assert_eq!(a.classification, b.classification);
            assert_eq!(a.apparent_reflectance, b.apparent_reflectance);
            assert_eq!(a.pulse_id, b.pulse_id);
        }
        let h = Reader::from_path(&path).unwrap().header().clone();
        assert_eq!(h.version(), Version::new(1, 4));
        assert_eq!(h.point_format().to_u8().unwrap(), 6);
        assert_eq!(h.transforms().x.scale, FINE);
        assert_eq!(h.transforms().z.offset, -3.0);
        // Nothing left under a temporary name.
        let names: Vec<_> = std::fs::read_dir(path.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert!(names.iter().all(|n| !n.to_string_lossy().contains(".tmp-")));
    }

    #[test]
    fn empty_and_bad_points() {
        let (_dir, path) = tmp("empty.las");
        write_las(&path, &[]).unwrap();
        assert!(read_las(&path).unwrap().is_empty());
        let mut p = sample(2);
        p[1].z = f64::NAN;
        let (_bad_dir, bad) = tmp("bad.las");
        assert!(write_las(&bad, &p).is_err());
        assert!(!bad.exists());
        let (_missing_dir, missing) = tmp("missing.las");
        assert!(read_las(&missing).is_err());
    }

    /// A header whose point count is damaged (10^9 for 3 points) is a data error naming the
    /// count: the reader reserves nothing the file does not hold.
    #[test]
    fn a_damaged_point_count_is_a_data_error() {
        let (_dir, path) = tmp("count.las");
        write_las(&path, &sample(3)).unwrap();
        let whole = std::fs::read(&path).unwrap();
        for claimed in [1_000_000_000u64, 4] {
            let mut bytes = whole.clone();
            // LAS 1.4's number of point records (u64 at 247)
            bytes[247..255].copy_from_slice(&claimed.to_le_bytes());
            std::fs::write(&path, &bytes).unwrap();
            let e = read_las(&path).unwrap_err();
            assert_eq!(e.kind, crate::error::Kind::Data, "{e}");
            assert!(e.to_string().contains(&format!("{claimed} points")), "{e}");
        }
    }

    #[test]
    fn laspy_reads_the_file() {
        let ok = std::process::Command::new("python3")
            .args(["-c", "import laspy"])
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false);
        if !ok {
            crate::testdata::skip_tool("python3 with laspy is not available (pip install laspy)");
            return;
        }
        let pts = sample(257);
        let (_dir, path) = tmp("laspy.las");
        write_las(&path, &pts).unwrap();
        let returns: Vec<String> = pts.iter().map(|p| p.return_number.to_string()).collect();
        let script = format!(
            r#"
import sys, laspy, numpy as np
f = laspy.read(sys.argv[1])
assert f.header.version.major == 1 and f.header.version.minor == 4, f.header.version
assert f.header.point_format.id == 6, f.header.point_format.id
assert len(f.points) == {n}, len(f.points)
assert list(f.header.scales) == [0.0001, 0.0001, 0.0001], f.header.scales
names = list(f.point_format.extra_dimension_names)
assert names == ["apparent_reflectance", "pulse_id"], names
assert f["pulse_id"].dtype == np.uint64 and f["apparent_reflectance"].dtype == np.float32
assert list(f.return_number) == [{returns}]
assert int(f["pulse_id"][3]) == {id3}, f["pulse_id"][3]
assert abs(float(f["apparent_reflectance"][5]) - {rho5}) < 1e-6
assert abs(float(f.x[7]) - {x7}) < 0.0006
print("laspy ok")
"#,
            n = pts.len(),
            returns = returns.join(","),
            id3 = pts[3].pulse_id,
            rho5 = pts[5].apparent_reflectance,
            x7 = pts[7].x,
        );
        let out = std::process::Command::new("python3")
            .arg("-c")
            .arg(script)
            .arg(&path)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "laspy check failed: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}
