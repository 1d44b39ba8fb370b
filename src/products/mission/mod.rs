//! Files shaped like the missions' own, so code written for them runs on a simulation:
//! `waveforms_l1b.h5` (GEDI L1B-like: one group per beam), `waveforms_l2a.h5` (GEDI L2A-like:
//! ground and relative heights per shot, with the truth beside them) and `photons_atl03.h5`
//! (ICESat-2 ATL03-like: one group per ground track). Names, dtypes, shapes and indexing follow
//! the real products (`rx_sample_start_index` counts from 1, `signal_conf_ph` is N x 5); what
//! a simulation cannot define is left out; the values are as docs/outputs.md says.
//!
//! Coordinates: with a `frame`, `latitude*`/`lat_ph` and `longitude*`/`lon_ph` are degrees
//! on WGS 84, the inverse projection of the frame's CRS at local + origin (as the real
//! products hold them), and heights are local z + the origin's height (ellipsoidal, as the
//! frame's origin is); without one, local y, x and z in metres, which the root attribute
//! `coordinates` says. Each file names the CRS in its root attributes.

mod atl03;
pub mod h5;
mod l1b;
mod l2a;
pub mod metrics;
pub mod truth;

pub use atl03::{signal_confidence, Atl03, Gate};
pub use l1b::{stale, L1b, Setup};
pub use l2a::{L2a, Shot};

/// The mission-shaped files (campaign.md, "Keys of the third wave").
pub const L1B_FILE: &str = "waveforms_l1b.h5";
pub const L2A_FILE: &str = "waveforms_l2a.h5";
pub const ATL03_FILE: &str = "photons_atl03.h5";

use crate::campaign::frame::ToWgs84;
use crate::campaign::{Frame, Sun};
use crate::error::{Error, Result};
use glam::DVec3;
use h5::{Field, H5Writer, Kind};

/// The root attributes both files carry: what made them and in which coordinates.
fn root_attrs(
    campaign: &str,
    frame: Option<&Frame>,
    product: &str,
) -> Result<Vec<(&'static str, String)>> {
    let mut attrs = vec![
        ("short_name", product.to_string()),
        ("campaign", campaign.to_string()),
        (
            "producer",
            format!("lidarsim {}", env!("CARGO_PKG_VERSION")),
        ),
    ];
    match frame {
        Some(f) => {
            let (_, wkt) = f.resolve().map_err(Error::msg)?;
            attrs.push(("crs", f.crs.clone()));
            attrs.push(("crs_wkt", wkt.to_string()));
            attrs.push((
                "coordinates",
                format!(
                    "latitude and longitude in degrees on WGS 84 (the inverse projection of {}); heights in metres above the WGS 84 ellipsoid",
                    f.crs
                ),
            ));
        }
        None => attrs.push((
            "coordinates",
            "local scene metres, no frame set: latitude = y, longitude = x (metres, not degrees), heights = z".into(),
        )),
    }
    Ok(attrs)
}

/// The one-element dataset `group/name` holding [`MISSION_EPOCH_GPS_S`], as both missions'
/// files hold their epoch.
fn epoch(h5: &mut H5Writer, group: &str, name: &str) -> Result<()> {
    h5.group(group, &[])?;
    h5.datasets(&[Field::new(
        group,
        name,
        Kind::F64,
        "seconds",
        "GPS seconds (since 1980-01-06T00:00:00Z) of 2018-01-01T00:00:00Z: delta_time is GPS time less this",
    )])?;
    h5.push_f64(&format!("{group}/{name}"), &[MISSION_EPOCH_GPS_S])
}

/// How a local point becomes a file's latitude, longitude and height (see the module's
/// comment).
pub(crate) enum Geo {
    Local,
    Frame { to: Box<ToWgs84>, height: f64 },
}

impl Geo {
    pub(crate) fn new(frame: Option<&Frame>) -> Result<Geo> {
        Ok(match frame {
            None => Geo::Local,
            Some(f) => Geo::Frame {
                to: Box::new(ToWgs84::new(f).map_err(Error::msg)?),
                height: f.origin[2],
            },
        })
    }

    /// (latitude, longitude, height) of the local point `p`.
    pub(crate) fn of(&self, p: DVec3) -> (f64, f64, f64) {
        match self {
            Geo::Local => (p.y, p.x, p.z),
            Geo::Frame { to, height } => {
                let (lat, lon) = to.degrees(p.x, p.y);
                (lat, lon, p.z + height)
            }
        }
    }

    /// The units attribute of latitudes and longitudes.
    fn angle_units(&self) -> &'static str {
        match self {
            Geo::Local => "m",
            Geo::Frame { .. } => "degrees",
        }
    }

    /// Latitude's and longitude's units as ATL03 gives them (CF's names), or metres without
    /// a frame.
    fn lat_lon_units(&self) -> (&'static str, &'static str) {
        match self {
            Geo::Local => ("m", "m"),
            Geo::Frame { .. } => ("degrees_north", "degrees_east"),
        }
    }
}

/// GPS seconds (since 1980-01-06) of 2018-01-01T00:00:00 UTC, the GEDI and ATLAS epoch: the
/// mission files' `delta_time` is GPS time less this (ATL03's
/// `/ancillary_data/atlas_sdp_gps_epoch`, GEDI's `ancillary/master_time_epoch`).
pub const MISSION_EPOCH_GPS_S: f64 = 1_198_800_018.0;

/// GEDI's eight beams as its files name them, in the order of a campaign's beams.
const GEDI_BEAMS: [&str; 8] = [
    "BEAM0000", "BEAM0001", "BEAM0010", "BEAM0011", "BEAM0101", "BEAM0110", "BEAM1000", "BEAM1011",
];

/// The L1B group of the campaign's beam `line`: GEDI's names for the first eight, then the
/// binary digits (four while they last) of the beam numbers GEDI leaves unused, 4, 7, 9, 10,
/// 12, 13, ... (see [`beam_number`]): a name no GEDI beam has, its digits its `beam` number, so
/// `shot_number` stays unique across the file, and BEAM followed by digits keeps readers
/// that match `BEAM\d+` working.
pub fn beam_name(line: u32) -> String {
    GEDI_BEAMS.get(line as usize).map_or_else(
        || format!("BEAM{:04b}", beam_number(line)),
        |s| s.to_string(),
    )
}

/// GEDI's beam numbers (the `beam` dataset: the decimal value of the name's binary digits)
/// for the campaign's beam `line`, and its digitiser channel as GEDI's files give it. A beam
/// past the eighth takes the next number GEDI does not use.
pub fn beam_number(line: u32) -> u16 {
    const NUMBERS: [u16; 8] = [0, 1, 2, 3, 5, 6, 8, 11];
    if let Some(&n) = NUMBERS.get(line as usize) {
        return n;
    }
    let extra = (line - 8) as usize;
    (0..u16::MAX)
        .filter(|n| !NUMBERS.contains(n))
        .nth(extra)
        .unwrap_or(u16::MAX)
}

pub fn channel(line: u32) -> u8 {
    const CHANNELS: [u8; 8] = [0, 0, 1, 1, 2, 3, 4, 5];
    CHANNELS
        .get(line as usize)
        .copied()
        .unwrap_or(line.saturating_sub(2).min(255) as u8)
}

/// GEDI's shot number, OOOOOBBRRGNNNNNNNN in decimal digits: orbit O (0: a simulation flies
/// none), beam number B, reserved R (0), sub-orbit granule G and shot index N. A simulation's
/// shots are counted from 1 per beam; each 10^8 shots of a beam make a granule, from 1.
pub fn shot_number(line: u32, index: u64) -> u64 {
    let granule = 1 + index / 100_000_000;
    u64::from(beam_number(line)) * 100_000_000_000 + granule * 100_000_000 + index % 100_000_000
}

/// The sun's elevation and azimuth as the mission files give them (degrees; azimuth from
/// grid north towards east), or none when the campaign has no sun: a simulated night.
#[derive(Clone, Copy, Debug, Default)]
pub struct SunAngles(Option<(f64, f64)>);

impl SunAngles {
    pub fn new(sun: Option<&Sun>) -> SunAngles {
        SunAngles(sun.map(|s| {
            // a negative zenith puts the sun at azimuth + 180° (campaign.md)
            let az = s.azimuth_deg + if s.zenith_deg < 0.0 { 180.0 } else { 0.0 };
            (90.0 - s.zenith_deg.abs(), (90.0 - az).rem_euclid(360.0))
        }))
    }

    pub fn elevation_or(&self, fill: f32) -> f32 {
        self.0.map_or(fill, |s| s.0 as f32)
    }

    pub fn azimuth_or(&self, fill: f32) -> f32 {
        self.0.map_or(fill, |s| s.1 as f32)
    }

    pub fn elevation_description(&self) -> &'static str {
        match self.0 {
            Some(_) => "elevation of the sun above the horizon (the campaign's sun)",
            None => "elevation of the sun: the campaign has no sun (a night), so the fill value",
        }
    }

    pub fn azimuth_description(&self) -> &'static str {
        match self.0 {
            Some(_) => "azimuth of the sun, from grid north towards east (the campaign's sun)",
            None => "azimuth of the sun: the campaign has no sun (a night), so the fill value",
        }
    }
}

/// GEDI's `/METADATA/DatasetIdentification`: what the file is, where from, and when. The
/// creation date is the first shot's (the simulated acquisition), not the wall clock, so a
/// run writes the same bytes every time.
fn dataset_identification(
    h5: &mut H5Writer,
    short_name: &str,
    file_name: &str,
    purpose: &str,
    first_gps_s: f64,
    fingerprint: &str,
) -> Result<()> {
    h5.group("METADATA", &[])?;
    let id = fingerprint.get(..32).unwrap_or(fingerprint);
    let uuid = if id.len() == 32 {
        format!(
            "{}-{}-{}-{}-{}",
            &id[..8],
            &id[8..12],
            &id[12..16],
            &id[16..20],
            &id[20..]
        )
    } else {
        id.to_string()
    };
    h5.group(
        "METADATA/DatasetIdentification",
        &[
            ("shortName", short_name.to_string()),
            ("fileName", file_name.to_string()),
            ("purpose", purpose.to_string()),
            ("abstract", format!("Simulated by lidarsim {}: a physically based simulation of the instrument's records over a 3D scene, not mission data.", env!("CARGO_PKG_VERSION"))),
            ("creationDate", gps_to_utc_iso(first_gps_s)),
            ("originatorOrganizationName", "lidarsim (simulation)".to_string()),
            ("PGEVersion", env!("CARGO_PKG_VERSION").to_string()),
            ("VersionID", "simulated".to_string()),
            ("characterSet", "utf8".to_string()),
            ("language", "eng".to_string()),
            ("spatialRepresentationType", "along-track".to_string()),
            ("status", "simulated".to_string()),
            ("topicCategory", "geoscientificInformation".to_string()),
            ("uuid", uuid),
        ],
    )
}

/// GPS seconds as a UTC date (ISO 8601), leap seconds since 1980 counted (18 since 2017).
pub fn gps_to_utc_iso(gps_s: f64) -> String {
    // (GPS second at which the offset starts, GPS - UTC after it)
    const LEAPS: [(f64, f64); 18] = [
        (46_828_800.0, 1.0),
        (78_364_801.0, 2.0),
        (109_900_802.0, 3.0),
        (173_059_203.0, 4.0),
        (252_028_804.0, 5.0),
        (315_187_205.0, 6.0),
        (346_723_206.0, 7.0),
        (393_984_007.0, 8.0),
        (425_520_008.0, 9.0),
        (457_056_009.0, 10.0),
        (504_489_610.0, 11.0),
        (551_750_411.0, 12.0),
        (599_184_012.0, 13.0),
        (820_108_813.0, 14.0),
        (914_803_214.0, 15.0),
        (1_025_136_015.0, 16.0),
        (1_119_744_016.0, 17.0),
        (1_167_264_017.0, 18.0),
    ];
    let offset = LEAPS
        .iter()
        .rev()
        .find(|l| gps_s >= l.0)
        .map_or(0.0, |l| l.1);
    // 1980-01-06 is day 3,657 of the Unix epoch
    let unix = gps_s - offset + 3_657.0 * 86_400.0;
    let days = (unix / 86_400.0).floor();
    let secs = unix - days * 86_400.0;
    // civil date from days since 1970-01-01 (Howard Hinnant's algorithm)
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    let (h, mi) = ((secs / 3600.0).floor(), ((secs % 3600.0) / 60.0).floor());
    let s = secs - h * 3600.0 - mi * 60.0;
    format!("{y:04}-{m:02}-{d:02}T{h:02}:{mi:02}:{s:09.6}Z")
}

/// Creates the GEDI group of the campaign's beam `line`; returns its name.
fn beam_group(h5: &mut H5Writer, line: u32) -> Result<String> {
    let name = beam_name(line);
    h5.group(
        &name,
        &[("description", format!("beam {line} of the campaign"))],
    )?;
    Ok(name)
}

/// A GEDI shot's identity and time in beam group `b`: `shot_number`, `beam`, `channel`,
/// `delta_time` and its whole seconds and fraction (`master_int`, `master_frac`; 0 and the
/// time's fraction before the epoch, where u32 has no place for it).
fn push_shot(h: &mut H5Writer, b: &str, line: u32, shot: u64, delta_time: f64) -> Result<()> {
    h.push_u64(&format!("{b}/shot_number"), &[shot])?;
    h.push_u16(&format!("{b}/beam"), &[beam_number(line)])?;
    h.push_u8(&format!("{b}/channel"), &[channel(line)])?;
    h.push_f64(&format!("{b}/delta_time"), &[delta_time])?;
    h.push_u32(
        &format!("{b}/master_int"),
        &[delta_time.floor().clamp(0.0, u32::MAX as f64) as u32],
    )?;
    h.push_f64(
        &format!("{b}/master_frac"),
        &[delta_time - delta_time.floor()],
    )
}

/// ICESat-2's ground tracks gt1l, gt1r, gt2l, ... for beams 0, 1, 2, ...
pub fn track_name(line: u32) -> String {
    format!(
        "gt{}{}",
        line / 2 + 1,
        if line.is_multiple_of(2) { 'l' } else { 'r' }
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The epoch is 2018-01-01T00:00:00Z, 18 leap seconds after GPS time began.
    #[test]
    fn gps_seconds_become_utc_dates() {
        assert_eq!(
            gps_to_utc_iso(MISSION_EPOCH_GPS_S),
            "2018-01-01T00:00:00.000000Z"
        );
        assert_eq!(gps_to_utc_iso(0.0), "1980-01-06T00:00:00.000000Z");
        // GEDI's granule of 2019-04-18 08:03:38 (orbit 1964): its delta_time 40810919.52
        let t = gps_to_utc_iso(MISSION_EPOCH_GPS_S + 40_810_919.52);
        assert!(t.starts_with("2019-04-18T08:21:59.52"), "{t}");
    }

    /// GEDI's shot numbers: the real file's beam 5 is 5 x 10^11 plus granule and index.
    #[test]
    fn shot_numbers_carry_beam_granule_and_index() {
        assert_eq!(shot_number(4, 1), 500_100_000_001);
        assert_eq!(shot_number(0, 100_000_000), 200_000_000);
        assert_eq!(beam_number(7), 11);
        assert_eq!(channel(4), 2);
    }

    /// The campaign's beams take GEDI's eight names in order (not their binary indexes: the
    /// fifth is BEAM0101, not BEAM0100), and the next ones the numbers GEDI leaves unused:
    /// every name and every number once.
    #[test]
    fn beams_take_gedis_names() {
        let names: Vec<String> = (0..11).map(beam_name).collect();
        assert_eq!(
            names,
            [
                "BEAM0000", "BEAM0001", "BEAM0010", "BEAM0011", "BEAM0101", "BEAM0110", "BEAM1000",
                "BEAM1011", "BEAM0100", "BEAM0111", "BEAM1001"
            ]
        );
        let numbers: Vec<u16> = (0..20).map(beam_number).collect();
        for (k, n) in numbers.iter().enumerate() {
            assert!(!numbers[..k].contains(n), "beam number {n} twice");
            let name = beam_name(k as u32);
            assert_eq!(u16::from_str_radix(&name[4..], 2).unwrap(), *n, "{name}");
        }
    }
}
