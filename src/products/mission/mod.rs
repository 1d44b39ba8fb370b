//! Files shaped like the missions' own, so code written for them runs on a simulation:
//! `waveforms_l1b.h5` (GEDI L1B-like: one group per beam) and `photons_atl03.h5` (ICESat-2
//! ATL03-like: one group per ground track). Names, shapes and indexing follow the real
//! products (`rx_sample_start_index` counts from 1, `signal_conf_ph` is N x 5); the
//! simulation defines the values as the output contract (docs/outputs.md) says.
//!
//! Coordinates: with a `frame`, `latitude*`/`lat_ph` and `longitude*`/`lon_ph` are degrees
//! on WGS 84, the inverse projection of the frame's CRS at local + origin (as the real
//! products hold them), and heights are local z + the origin's height (ellipsoidal, as the
//! frame's origin is); without one, local y, x and z in metres, which the root attribute
//! `coordinates` says. Each file names the CRS in its root attributes.

pub mod h5;

/// The mission-shaped files (campaign.md, "Files of the next wave").
pub const L1B_FILE: &str = "waveforms_l1b.h5";
pub const ATL03_FILE: &str = "photons_atl03.h5";

use crate::campaign::frame::ToWgs84;
use crate::campaign::Frame;
use crate::error::{Error, Result};
use crate::plan::Pulse;
use crate::products::photons::PhotonRow;
use crate::waveform::record::{transmitted_pulse, Record};
use crate::waveform::Waveform;
use glam::DVec3;
use h5::{Field, H5Writer, Kind};
use std::collections::BTreeMap;
use std::path::Path;

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

/// ATL03's `/orbit_info`: `sc_orient` 0 (backward), under which ATLAS's left beams (gt1l, gt2l,
/// gt3l) are the strong ones, as the campaign's first beam (gt1l) is; `rgt` and
/// `cycle_number`, which a simulation has not, hold 0 and say so.
fn orbit_info(h5: &mut H5Writer) -> Result<()> {
    h5.group("orbit_info", &[])?;
    h5.datasets(&[
        Field::new("orbit_info", "sc_orient", Kind::I8, "1", "spacecraft orientation: 0 backward (the left beams gt1l, gt2l, gt3l strong), 1 forward, 2 transition; 0 here"),
        Field::new("orbit_info", "rgt", Kind::I16, "1", "reference ground track: none in a simulation (0, outside ATLAS's 1-1387)"),
        Field::new("orbit_info", "cycle_number", Kind::I8, "1", "91-day cycle: none in a simulation (0)"),
    ])?;
    h5.push_i8("orbit_info/sc_orient", &[0])?;
    h5.push_i16("orbit_info/rgt", &[0])?;
    h5.push_i8("orbit_info/cycle_number", &[0])
}

/// How a local point becomes a file's latitude, longitude and height (see the module's
/// comment).
enum Geo {
    Local,
    Frame { to: Box<ToWgs84>, height: f64 },
}

impl Geo {
    fn new(frame: Option<&Frame>) -> Result<Geo> {
        Ok(match frame {
            None => Geo::Local,
            Some(f) => Geo::Frame {
                to: Box::new(ToWgs84::new(f).map_err(Error::msg)?),
                height: f.origin[2],
            },
        })
    }

    /// (latitude, longitude, height) of the local point `p`.
    fn of(&self, p: DVec3) -> (f64, f64, f64) {
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
/// beam index in five or more binary digits (a ninth beam has no GEDI name; five digits never
/// meet one of GEDI's four, and BEAM followed by digits keeps readers that match `BEAM\d+`
/// working).
pub fn beam_name(line: u32) -> String {
    GEDI_BEAMS
        .get(line as usize)
        .map_or_else(|| format!("BEAM{line:05b}"), |s| s.to_string())
}

/// ICESat-2's ground tracks gt1l, gt1r, gt2l, ... for beams 0, 1, 2, ...
pub fn track_name(line: u32) -> String {
    format!(
        "gt{}{}",
        line / 2 + 1,
        if line.is_multiple_of(2) { 'l' } else { 'r' }
    )
}

/// `waveforms_l1b.h5`, written a pulse at a time.
pub struct L1b {
    h5: H5Writer,
    /// Samples written so far per beam: rx, tx.
    beams: BTreeMap<u32, (u64, u64)>,
    geo: Geo,
    pulse_sigma_s: f64,
    units: &'static str,
    threshold: f64,
}

impl L1b {
    /// `counts`: the record is digitised (else in photoelectrons).
    pub fn create(
        path: &Path,
        campaign: &str,
        frame: Option<&Frame>,
        pulse_sigma_s: f64,
        counts: bool,
        threshold_photons: f64,
    ) -> Result<L1b> {
        let attrs = root_attrs(campaign, frame, "GEDI01_B-like (simulated)")?;
        let mut h5 = H5Writer::create(path, &attrs)?;
        epoch(&mut h5, "ancillary", "master_time_epoch")?;
        Ok(L1b {
            h5,
            beams: BTreeMap::new(),
            geo: Geo::new(frame)?,
            pulse_sigma_s,
            units: if counts { "counts" } else { "photoelectrons" },
            threshold: threshold_photons,
        })
    }

    fn beam(&mut self, line: u32) -> Result<String> {
        let name = beam_name(line);
        if self.beams.contains_key(&line) {
            return Ok(name);
        }
        self.h5.group(
            &name,
            &[("description", format!("beam {line} of the campaign"))],
        )?;
        self.h5.group(&format!("{name}/geolocation"), &[])?;
        let u = self.units;
        let units = self.geo.angle_units();
        let f = |path: &str, kind, units, description| {
            Field::new(&name, path, kind, units, description)
        };
        self.h5.datasets(&[
            f("rxwaveform", Kind::F32, u, "received waveforms of all shots, concatenated: the instrument's record (noise and digitiser as configured)"),
            f("rx_sample_count", Kind::U32, "1", "samples of each shot's received waveform"),
            f("rx_sample_start_index", Kind::U64, "1", "index of each shot's first sample in rxwaveform, counted from 1"),
            f("txwaveform", Kind::F32, "1", "transmitted pulse of each shot, concatenated: the fraction of the pulse energy per sample"),
            f("tx_sample_count", Kind::U32, "1", "samples of each shot's transmitted waveform"),
            f("tx_sample_start_index", Kind::U64, "1", "index of each shot's first sample in txwaveform, counted from 1"),
            f("shot_number", Kind::U64, "1", "the campaign's pulse_id"),
            f("delta_time", Kind::F64, "seconds since 2018-01-01", "transmit time of the shot: the pulse's GPS seconds less ancillary/master_time_epoch"),
            f("noise_mean_corrected", Kind::F64, u, "mean of a sample without laser signal: solar background and dark counts"),
            f("stale_return_flag", Kind::U8, "1", "1: no sample of the mean waveform reaches the detection threshold"),
            f("geolocation/elevation_bin0", Kind::F64, "m", "height of the centre of the first sample, on the beam axis"),
            f("geolocation/elevation_lastbin", Kind::F64, "m", "height of the centre of the last sample, on the beam axis"),
            f("geolocation/latitude_bin0", Kind::F64, units, "latitude of the centre of the first sample (local y without a frame: see /@coordinates)"),
            f("geolocation/longitude_bin0", Kind::F64, units, "longitude of the centre of the first sample (local x without a frame: see /@coordinates)"),
            f("geolocation/latitude_lastbin", Kind::F64, units, "latitude of the centre of the last sample (local y without a frame: see /@coordinates)"),
            f("geolocation/longitude_lastbin", Kind::F64, units, "longitude of the centre of the last sample (local x without a frame: see /@coordinates)"),
        ])?;
        self.beams.insert(line, (0, 0));
        Ok(name)
    }

    pub fn add(&mut self, pulse: &Pulse, w: &Waveform, record: &Record) -> Result<()> {
        let b = self.beam(pulse.line)?;
        let tx = transmitted_pulse(self.pulse_sigma_s, w.bin_ns as f64 * 1e-9);
        let (rx_next, tx_next) = self.beams.get(&pulse.line).copied().unwrap_or_default();
        let n = record.samples.len();
        // centre of sample k: t0 + (k + ½) Δt after emission, at range c t / 2
        let at = |k: usize| {
            let t = (w.t0_ns + (k as f64 + 0.5) * w.bin_ns as f64) * 1e-9;
            self.geo
                .of(pulse.origin + pulse.direction * (crate::C * t / 2.0))
        };
        let (first, last) = (at(0), at(n.saturating_sub(1)));
        let stale = !w
            .laser_photons
            .iter()
            .any(|&v| v as f64 >= self.threshold && self.threshold > 0.0);
        let h = &mut self.h5;
        h.push_f32(&format!("{b}/rxwaveform"), &record.samples)?;
        h.push_u32(&format!("{b}/rx_sample_count"), &[n as u32])?;
        h.push_u64(&format!("{b}/rx_sample_start_index"), &[rx_next + 1])?;
        h.push_f32(&format!("{b}/txwaveform"), &tx)?;
        h.push_u32(&format!("{b}/tx_sample_count"), &[tx.len() as u32])?;
        h.push_u64(&format!("{b}/tx_sample_start_index"), &[tx_next + 1])?;
        h.push_u64(&format!("{b}/shot_number"), &[pulse.id])?;
        h.push_f64(
            &format!("{b}/delta_time"),
            &[pulse.gps_time_s - MISSION_EPOCH_GPS_S],
        )?;
        h.push_f64(&format!("{b}/noise_mean_corrected"), &[record.background])?;
        h.push_u8(&format!("{b}/stale_return_flag"), &[u8::from(stale)])?;
        let g = format!("{b}/geolocation");
        h.push_f64(&format!("{g}/elevation_bin0"), &[first.2])?;
        h.push_f64(&format!("{g}/elevation_lastbin"), &[last.2])?;
        h.push_f64(&format!("{g}/latitude_bin0"), &[first.0])?;
        h.push_f64(&format!("{g}/longitude_bin0"), &[first.1])?;
        h.push_f64(&format!("{g}/latitude_lastbin"), &[last.0])?;
        h.push_f64(&format!("{g}/longitude_lastbin"), &[last.1])?;
        self.beams
            .insert(pulse.line, (rx_next + n as u64, tx_next + tx.len() as u64));
        Ok(())
    }

    pub fn finish(self) -> Result<()> {
        self.h5.finish()
    }
}

/// Per ground track: photons so far, the first pulse's origin (where along-track distance
/// starts) and the sources of the photons, for `signal_conf_ph` at the end.
struct Track {
    name: String,
    first: DVec3,
    sources: Vec<u8>,
    /// The 20 m segment the last pulse fell in, not yet written.
    segment: Option<Segment>,
}

/// ATL03's along-track segment length, m.
const SEGMENT_M: f64 = 20.0;

/// One along-track segment of a ground track (ATL03's `geolocation/`): the photons of the
/// pulses whose nadir point falls in it, which follow each other in the file.
#[derive(Clone, Copy)]
struct Segment {
    /// Segment k spans [20 k, 20 (k + 1)) m of along-track distance from the track's first
    /// pulse.
    k: i64,
    photons: u64,
    /// 1-based index of its first photon in the track's photons (0: none yet, as ATL03 has it).
    first: u64,
    /// Its first photon's latitude, longitude and the shot's delta_time (NaN without photons).
    reference: (f64, f64, f64),
}

/// `photons_atl03.h5`, written a pulse at a time.
pub struct Atl03 {
    h5: H5Writer,
    tracks: BTreeMap<u32, Track>,
    geo: Geo,
}

impl Segment {
    fn empty(k: i64) -> Segment {
        Segment {
            k,
            photons: 0,
            first: 0,
            reference: (f64::NAN, f64::NAN, f64::NAN),
        }
    }
}

/// Appends one row of `track`'s `geolocation/`.
fn write_segment(h5: &mut H5Writer, track: &str, seg: &Segment) -> Result<()> {
    let g = format!("{track}/geolocation");
    h5.push_i32(
        &format!("{g}/segment_id"),
        &[(seg.k + 1).clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32],
    )?;
    h5.push_f64(&format!("{g}/segment_dist_x"), &[SEGMENT_M * seg.k as f64])?;
    h5.push_f64(&format!("{g}/segment_length"), &[SEGMENT_M])?;
    h5.push_i32(
        &format!("{g}/segment_ph_cnt"),
        &[seg.photons.min(i32::MAX as u64) as i32],
    )?;
    h5.push_i64(
        &format!("{g}/ph_index_beg"),
        &[seg.first.min(i64::MAX as u64) as i64],
    )?;
    h5.push_f64(&format!("{g}/reference_photon_lat"), &[seg.reference.0])?;
    h5.push_f64(&format!("{g}/reference_photon_lon"), &[seg.reference.1])?;
    h5.push_f64(&format!("{g}/delta_time"), &[seg.reference.2])
}

/// `signal_conf_ph`: high confidence (4) for laser photons, noise (0) for solar and dark
/// ones, in all five surface-type columns (land, ocean, sea ice, land ice, inland water).
pub fn signal_confidence(source: u8) -> i8 {
    if source == 0 {
        4
    } else {
        0
    }
}

impl Atl03 {
    pub fn create(path: &Path, campaign: &str, frame: Option<&Frame>) -> Result<Atl03> {
        let mut attrs = root_attrs(campaign, frame, "ATL03")?;
        attrs.push((
            "simulated",
            format!(
                "simulated by lidarsim {}, not an ATLAS granule: laid out as ATL03 so its readers open it",
                env!("CARGO_PKG_VERSION")
            ),
        ));
        let mut h5 = H5Writer::create(path, &attrs)?;
        epoch(&mut h5, "ancillary_data", "atlas_sdp_gps_epoch")?;
        orbit_info(&mut h5)?;
        Ok(Atl03 {
            h5,
            tracks: BTreeMap::new(),
            geo: Geo::new(frame)?,
        })
    }

    fn track(&mut self, pulse: &Pulse) -> Result<()> {
        if self.tracks.contains_key(&pulse.line) {
            return Ok(());
        }
        let name = track_name(pulse.line);
        self.h5.group(
            &name,
            &[(
                "description",
                format!("beam {} of the campaign", pulse.line),
            )],
        )?;
        self.h5.group(&format!("{name}/heights"), &[])?;
        let group = format!("{name}/heights");
        let units = self.geo.angle_units();
        let f = |path: &str, kind, units, description| {
            Field::new(&group, path, kind, units, description)
        };
        self.h5.datasets(&[
            f("h_ph", Kind::F64, "m", "height of the photon event"),
            f("lat_ph", Kind::F64, units, "latitude of the photon event (local y without a frame: see /@coordinates)"),
            f("lon_ph", Kind::F64, units, "longitude of the photon event (local x without a frame: see /@coordinates)"),
            f("delta_time", Kind::F64, "seconds since 2018-01-01", "transmit time of the shot the photon belongs to, GPS seconds less atlas_sdp_gps_epoch"),
            f("dist_ph_along", Kind::F64, "m", "along-track distance from the start of the photon's 20 m segment (geolocation/segment_dist_x)"),
            f("dist_ph_across", Kind::F64, "m", "across-track distance from the pulse's nadir point, positive to the left of the track"),
            f("ph_id_pulse", Kind::U8, "1", "the shot within its major frame of 200, counted from 1: pulse_id % 200 + 1"),
            f("pce_mframe_cnt", Kind::U32, "1", "the major frame of 200 shots: pulse_id // 200"),
            f("ph_id_count", Kind::U8, "1", "photon event number within the pulse, counted from 1"),
            f("quality_ph", Kind::I8, "1", "0: nominal (always)"),
            f("truth_source", Kind::U8, "1", "not in the real product: the simulation's truth, 0 laser, 1 solar, 2 dark"),
        ])?;
        let group = format!("{name}/geolocation");
        self.h5.group(&group, &[])?;
        let f = |path: &str, kind, units, description| {
            Field::new(&group, path, kind, units, description)
        };
        self.h5.datasets(&[
            f("segment_id", Kind::I32, "1", "the segment's number along the track, from 1 at the track's first pulse (the real product counts from the equator)"),
            f("segment_dist_x", Kind::F64, "m", "along-track distance of the segment's start from the track's first pulse"),
            f("segment_length", Kind::F64, "m", "the segment's along-track length"),
            f("segment_ph_cnt", Kind::I32, "1", "photon events in the segment: those of the pulses whose nadir point falls in it"),
            f("ph_index_beg", Kind::I64, "1", "index of the segment's first photon in heights/, counted from 1 (0: none)"),
            f("reference_photon_lat", Kind::F64, units, "latitude of the segment's first photon (NaN: none)"),
            f("reference_photon_lon", Kind::F64, units, "longitude of the segment's first photon (NaN: none)"),
            f("delta_time", Kind::F64, "seconds since 2018-01-01", "transmit time of the shot of the segment's first photon (NaN: none)"),
        ])?;
        self.tracks.insert(
            pulse.line,
            Track {
                name,
                first: pulse.origin,
                sources: Vec::new(),
                segment: None,
            },
        );
        Ok(())
    }

    /// One pulse's photon events (its rows of photons.parquet).
    pub fn add(&mut self, pulse: &Pulse, rows: &[PhotonRow]) -> Result<()> {
        self.track(pulse)?;
        let Some(track) = self.tracks.get_mut(&pulse.line) else {
            return Ok(());
        };
        let b = format!("{}/heights", track.name);
        let along = (pulse.origin - track.first).truncate();
        let unit = along.try_normalize();
        // the pulse's segment, by its nadir point's distance along the track; the one before
        // is written once the track leaves it, with any it skipped (no pulse: no photons)
        let k = (along.length() / SEGMENT_M).floor() as i64;
        match track.segment {
            Some(seg) if seg.k == k => {}
            Some(seg) => {
                write_segment(&mut self.h5, &track.name, &seg)?;
                for skipped in seg.k + 1..k {
                    write_segment(&mut self.h5, &track.name, &Segment::empty(skipped))?;
                }
                track.segment = Some(Segment::empty(k));
            }
            None => track.segment = Some(Segment::empty(k)),
        }
        let start = SEGMENT_M * k as f64;
        let n = rows.len();
        let (mut h, mut lat, mut lon, mut time) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        let (mut d_along, mut d_across, mut count) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for (k, r) in rows.iter().enumerate() {
            let p = DVec3::new(r.x, r.y, r.z);
            let (la, lo, z) = self.geo.of(p);
            h.push(z);
            lat.push(la);
            lon.push(lo);
            time.push(pulse.gps_time_s - MISSION_EPOCH_GPS_S);
            let from_first = (p - track.first).truncate();
            let off = (p - pulse.origin).truncate();
            match unit {
                Some(u) => {
                    d_along.push(from_first.dot(u) - start);
                    d_across.push(u.perp_dot(off));
                }
                None => {
                    d_along.push(from_first.length() - start);
                    d_across.push(off.length());
                }
            }
            count.push((k + 1).min(255) as u8);
            track.sources.push(r.source);
        }
        if let (Some(seg), false) = (track.segment.as_mut(), rows.is_empty()) {
            if seg.photons == 0 {
                // the photons before this pulse's, in the track: the one just pushed is last
                seg.first = (track.sources.len() - n) as u64 + 1;
                seg.reference = (lat[0], lon[0], pulse.gps_time_s - MISSION_EPOCH_GPS_S);
            }
            seg.photons += n as u64;
        }
        let sources: Vec<u8> = rows.iter().map(|r| r.source).collect();
        let hw = &mut self.h5;
        hw.push_f64(&format!("{b}/h_ph"), &h)?;
        hw.push_f64(&format!("{b}/lat_ph"), &lat)?;
        hw.push_f64(&format!("{b}/lon_ph"), &lon)?;
        hw.push_f64(&format!("{b}/delta_time"), &time)?;
        hw.push_f64(&format!("{b}/dist_ph_along"), &d_along)?;
        hw.push_f64(&format!("{b}/dist_ph_across"), &d_across)?;
        hw.push_u8(
            &format!("{b}/ph_id_pulse"),
            &vec![(pulse.id % 200 + 1) as u8; n],
        )?;
        hw.push_u32(
            &format!("{b}/pce_mframe_cnt"),
            &vec![(pulse.id / 200).min(u64::from(u32::MAX)) as u32; n],
        )?;
        hw.push_u8(&format!("{b}/ph_id_count"), &count)?;
        hw.push_i8(&format!("{b}/quality_ph"), &vec![0; n])?;
        hw.push_u8(&format!("{b}/truth_source"), &sources)
    }

    /// Writes `signal_conf_ph` of every track (N x 5: the crate appends to rank-1 datasets
    /// only, so this one is written whole, 5 bytes a photon) and closes the file.
    pub fn finish(mut self) -> Result<()> {
        for track in std::mem::take(&mut self.tracks).into_values() {
            if let Some(seg) = &track.segment {
                write_segment(&mut self.h5, &track.name, seg)?;
            }
            let conf: Vec<i8> = track
                .sources
                .iter()
                .flat_map(|&s| [signal_confidence(s); 5])
                .collect();
            let field = Field::new(
                &format!("{}/heights", track.name),
                "signal_conf_ph",
                Kind::I8,
                "1",
                "confidence that the photon is signal, per surface type (land, ocean, sea ice, land ice, inland water): 4 high (laser photons), 0 noise (solar and dark)",
            );
            self.h5.matrix_i8(&field, track.sources.len(), 5, &conf)?;
        }
        self.h5.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The campaign's beams take GEDI's eight names in order (not their binary indexes: the
    /// fifth is BEAM0101, not BEAM0100), and a ninth a name of its own (five digits).
    #[test]
    fn beams_take_gedis_names() {
        let names: Vec<String> = (0..9).map(beam_name).collect();
        assert_eq!(
            names,
            [
                "BEAM0000",
                "BEAM0001",
                "BEAM0010",
                "BEAM0011",
                "BEAM0101",
                "BEAM0110",
                "BEAM1000",
                "BEAM1011",
                "BEAM01000"
            ]
        );
    }
}
