//! `photons_atl03.h5`: ICESat-2 ATL03-like, one group per ground track (gt1l, gt1r, gt2l, ...)
//! with `heights/` (a row per photon event), `geolocation/` (a row per 20 m along-track
//! segment) and `bckgrd_atlas/` (a row per 50 shots), laid out, typed and indexed as the real
//! product.

use super::h5::{Field, H5Writer, Kind};
use super::{epoch, root_attrs, track_name, Geo, SunAngles, MISSION_EPOCH_GPS_S};
use crate::campaign::Frame;
use crate::error::Result;
use crate::plan::Pulse;
use crate::products::photons::PhotonRow;
use glam::DVec3;
use hdf5_pure::AttrValue;
use std::collections::BTreeMap;
use std::path::Path;

/// ATL03's along-track segment length, m.
const SEGMENT_M: f64 = 20.0;
/// Shots per row of `bckgrd_atlas/` (ATLAS sums its background over 50 shots, at 200 Hz).
const BACKGROUND_SHOTS: u64 = 50;
/// ICESat-2's fill values of 64- and 32-bit floats.
const FILL_F64: f64 = f64::MAX;
const FILL_F32: f32 = f32::MAX;

/// ATL03's `/orbit_info`: `sc_orient` 0 (backward), under which ATLAS's left beams (gt1l, gt2l,
/// gt3l) are the strong ones, as the campaign's even beams (gt1l, ...) are; `rgt` and
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
    /// Its first photon's latitude, longitude and the shot's delta_time (fill values without
    /// photons).
    reference: (f64, f64, f64),
}

impl Segment {
    fn empty(k: i64) -> Segment {
        Segment {
            k,
            photons: 0,
            first: 0,
            reference: (FILL_F64, FILL_F64, FILL_F64),
        }
    }
}

/// The background of the 50 shots so far of a track (a row of `bckgrd_atlas/`).
#[derive(Clone, Copy, Default)]
struct Background {
    shots: u64,
    /// Photon events, and those of them that are noise (solar and dark, by the truth).
    events: u64,
    noise: u64,
    /// The first shot's delta_time and major frame, the range window's top and height (m).
    delta_time: f64,
    frame: i64,
    top: f64,
    height: f64,
}

/// Per ground track: photons so far, the first pulse's origin (where along-track distance
/// starts), the segment and the background row being filled.
struct Track {
    name: String,
    first: DVec3,
    photons: u64,
    /// The 20 m segment the last pulse fell in, not yet written.
    segment: Option<Segment>,
    background: Background,
}

/// `photons_atl03.h5`, written a pulse at a time.
pub struct Atl03 {
    h5: H5Writer,
    tracks: BTreeMap<u32, Track>,
    geo: Geo,
    sun: SunAngles,
}

/// Appends one row of `track`'s `geolocation/`.
fn write_segment(h5: &mut H5Writer, track: &str, seg: &Segment, sun: &SunAngles) -> Result<()> {
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
    h5.push_i32(
        &format!("{g}/reference_photon_index"),
        &[i32::from(seg.photons > 0)],
    )?;
    h5.push_f64(&format!("{g}/reference_photon_lat"), &[seg.reference.0])?;
    h5.push_f64(&format!("{g}/reference_photon_lon"), &[seg.reference.1])?;
    h5.push_f64(&format!("{g}/delta_time"), &[seg.reference.2])?;
    h5.push_f32(
        &format!("{g}/solar_elevation"),
        &[sun.elevation_or(FILL_F32)],
    )?;
    h5.push_f32(&format!("{g}/solar_azimuth"), &[sun.azimuth_or(FILL_F32)])
}

/// Appends one row of `track`'s `bckgrd_atlas/`.
fn write_background(h5: &mut H5Writer, track: &str, b: &Background) -> Result<()> {
    let g = format!("{track}/bckgrd_atlas");
    let window_s = b.shots as f64 * 2.0 * b.height / crate::C;
    let rate = if window_s > 0.0 {
        b.noise as f64 / window_s
    } else {
        0.0
    };
    let clamp = |n: u64| n.min(i32::MAX as u64) as i32;
    h5.push_f64(&format!("{g}/delta_time"), &[b.delta_time])?;
    h5.push_i64(&format!("{g}/pce_mframe_cnt"), &[b.frame])?;
    h5.push_i32(&format!("{g}/bckgrd_counts"), &[clamp(b.events)])?;
    h5.push_i32(&format!("{g}/bckgrd_counts_reduced"), &[clamp(b.noise)])?;
    h5.push_f32(&format!("{g}/bckgrd_int_height"), &[b.height as f32])?;
    h5.push_f32(
        &format!("{g}/bckgrd_int_height_reduced"),
        &[b.height as f32],
    )?;
    h5.push_f32(&format!("{g}/bckgrd_hist_top"), &[b.top as f32])?;
    h5.push_f32(&format!("{g}/bckgrd_rate"), &[rate as f32])
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

/// The pulse's range window (its record's gate): start and length after emission, s.
#[derive(Clone, Copy, Debug)]
pub struct Gate {
    pub start_s: f64,
    pub length_s: f64,
}

impl Atl03 {
    pub fn create(
        path: &Path,
        campaign: &str,
        frame: Option<&Frame>,
        sun: SunAngles,
    ) -> Result<Atl03> {
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
            sun,
        })
    }

    fn track(&mut self, pulse: &Pulse) -> Result<()> {
        if self.tracks.contains_key(&pulse.line) {
            return Ok(());
        }
        let name = track_name(pulse.line);
        // under sc_orient 0 the left beams are the strong ones
        let strong = pulse.line.is_multiple_of(2);
        self.h5.group(
            &name,
            &[
                (
                    // ATL03 capitalises its groups' attribute
                    "Description",
                    format!("beam {} of the campaign", pulse.line),
                ),
                ("groundtrack_id", name.clone()),
                (
                    "atlas_beam_type",
                    if strong { "strong" } else { "weak" }.to_string(),
                ),
                ("sc_orientation", "Backward".to_string()),
            ],
        )?;
        let (lat_units, lon_units) = self.geo.lat_lon_units();
        // what locates a group's elements, as the real product's `coordinates` say
        const PHOTON: &str = "delta_time lat_ph lon_ph";
        const SEGMENT: &str = "delta_time reference_photon_lat reference_photon_lon";
        const BACKGROUND: &str = "delta_time";
        let group = format!("{name}/heights");
        self.h5.group(&group, &[])?;
        let f = |path: &str, kind, units, description| {
            Field::new(&group, path, kind, units, description)
        };
        self.h5.datasets(&[
            f("h_ph", Kind::F32, "meters", "height of the photon event").long_name("Photon WGS84 Height").cf("physicalMeasurement", PHOTON),
            f("lat_ph", Kind::F64, lat_units, "latitude of the photon event (local y without a frame: see /@coordinates)").long_name("Latitude").cf("modelResult", "delta_time lon_ph"),
            f("lon_ph", Kind::F64, lon_units, "longitude of the photon event (local x without a frame: see /@coordinates)").long_name("Longitude").cf("modelResult", "delta_time lat_ph"),
            f("delta_time", Kind::F64, "seconds since 2018-01-01", "transmit time of the shot the photon belongs to, GPS seconds less atlas_sdp_gps_epoch").long_name("Elapsed GPS seconds").cf("referenceInformation", "lat_ph lon_ph"),
            f("dist_ph_along", Kind::F32, "meters", "along-track distance from the start of the photon's 20 m segment (geolocation/segment_dist_x)").long_name("Distance from equator crossing.").cf("modelResult", PHOTON),
            f("dist_ph_across", Kind::F32, "meters", "across-track distance from the pulse's nadir point, positive to the left of the track").long_name("Distance off RGT.").cf("modelResult", PHOTON),
            f("ph_id_pulse", Kind::U8, "counts", "the shot within its major frame of 200, counted from 1: shot % 200 + 1 (a shot: one firing, all beams)").long_name("laser pulse counter").cf("referenceInformation", PHOTON),
            f("pce_mframe_cnt", Kind::U32, "counts", "the major frame of 200 shots: shot // 200 (a shot: one firing, all beams)").long_name("PCE Major frame counter").cf("referenceInformation", PHOTON),
            f("ph_id_count", Kind::U8, "counts", "photon event number within the pulse, counted from 1").long_name("photon event counter").cf("referenceInformation", PHOTON),
            f("quality_ph", Kind::I8, "1", "0: nominal (always)").long_name("Photon Quality").cf("qualityInformation", PHOTON),
            f("signal_conf_ph", Kind::I8, "1", "confidence that the photon is signal, per surface type (land, ocean, sea ice, land ice, inland water): 4 high (laser photons), 0 noise (solar and dark)").rows_of(5).long_name("Photon Signal Confidence").cf("qualityInformation", PHOTON),
            f("truth_source", Kind::U8, "1", "not in the real product: the simulation's truth, 0 laser, 1 solar, 2 dark").long_name("Simulated photon source (truth)").cf("referenceInformation", PHOTON),
        ])?;
        let group = format!("{name}/geolocation");
        self.h5.group(&group, &[])?;
        let f = |path: &str, kind, units, description| {
            Field::new(&group, path, kind, units, description)
        };
        self.h5.datasets(&[
            f("segment_id", Kind::I32, "1", "the segment's number along the track, from 1 at the track's first pulse (the real product counts from the equator)").long_name("along-track segment ID number.").cf("referenceInformation", SEGMENT),
            f("segment_dist_x", Kind::F64, "meters", "along-track distance of the segment's start from the track's first pulse").long_name("Segment Distance from EQC").cf("modelResult", SEGMENT),
            f("segment_length", Kind::F64, "meters", "the segment's along-track length").long_name("along-track segment length").cf("modelResult", SEGMENT),
            f("segment_ph_cnt", Kind::I32, "counts", "photon events in the segment: those of the pulses whose nadir point falls in it").long_name("Number of photons").fill(AttrValue::I32(0)).cf("referenceInformation", SEGMENT),
            f("ph_index_beg", Kind::I64, "counts", "index of the segment's first photon in heights/, counted from 1 (0: none)").long_name("Photon Index Begin").fill(AttrValue::I64(0)).cf("referenceInformation", SEGMENT),
            f("reference_photon_index", Kind::I32, "counts", "index of the reference photon within the segment, counted from 1: its first (0: none)").long_name("Reference Photon Index").fill(AttrValue::I32(0)).cf("referenceInformation", SEGMENT),
            f("reference_photon_lat", Kind::F64, lat_units, "latitude of the segment's first photon (fill value: none)").long_name("Segment Latitude").fill(AttrValue::F64(FILL_F64)).cf("modelResult", "delta_time"),
            f("reference_photon_lon", Kind::F64, lon_units, "longitude of the segment's first photon (fill value: none)").long_name("Segment Longitude").fill(AttrValue::F64(FILL_F64)).cf("modelResult", "delta_time"),
            f("delta_time", Kind::F64, "seconds since 2018-01-01", "transmit time of the shot of the segment's first photon (fill value: none)").long_name("Delta Time").fill(AttrValue::F64(FILL_F64)).cf("physicalMeasurement", "reference_photon_lat reference_photon_lon"),
            f("solar_elevation", Kind::F32, "degrees", self.sun.elevation_description()).long_name("solar elevation").fill(AttrValue::F32(FILL_F32)).cf("modelResult", SEGMENT),
            f("solar_azimuth", Kind::F32, "degrees_east", self.sun.azimuth_description()).long_name("solar azimuth").fill(AttrValue::F32(FILL_F32)).cf("modelResult", SEGMENT),
        ])?;
        let group = format!("{name}/bckgrd_atlas");
        self.h5.group(&group, &[])?;
        let f = |path: &str, kind, units, description| {
            Field::new(&group, path, kind, units, description)
        };
        self.h5.datasets(&[
            f("delta_time", Kind::F64, "seconds since 2018-01-01", "transmit time of the first of the 50 shots summed").long_name("Time at the start of ATLAS 50-shot sum").cf("referenceInformation", ""),
            f("pce_mframe_cnt", Kind::I64, "counts", "the major frame of the first of the 50 shots").long_name("PCE Major frame counter").cf("referenceInformation", BACKGROUND),
            f("bckgrd_counts", Kind::I32, "counts", "photon events of the 50 shots within their range windows").long_name("ATLAS 50-shot background count").cf("modelResult", BACKGROUND),
            f("bckgrd_counts_reduced", Kind::I32, "counts", "those of them that are not laser photons (by the simulation's truth, not by a signal finder)").long_name("ATLAS 50-shot background count - reduced").cf("modelResult", BACKGROUND),
            f("bckgrd_int_height", Kind::F32, "meters", "height of the range window: c times the record's gate over 2").long_name("Altimetric range window width").cf("modelResult", BACKGROUND),
            f("bckgrd_int_height_reduced", Kind::F32, "meters", "the same (the truth removes the signal's events, not a height span)").long_name("Altimetric range window height - reduced").cf("modelResult", BACKGROUND),
            f("bckgrd_hist_top", Kind::F32, "meters", "height of the top of the first shot's range window, on its beam axis").long_name("Top of the altimetric range window").cf("modelResult", BACKGROUND),
            f("bckgrd_rate", Kind::F32, "counts / second", "noise photon events per second of range window: bckgrd_counts_reduced / (50 x the gate)").long_name("Background count rate based on the ATLAS 50-shot sum").cf("modelResult", BACKGROUND),
        ])?;
        self.tracks.insert(
            pulse.line,
            Track {
                name,
                first: pulse.origin,
                photons: 0,
                segment: None,
                background: Background::default(),
            },
        );
        Ok(())
    }

    /// One pulse's photon events (its rows of photons.parquet, maybe none) and its gate;
    /// `shot` the laser's firing it belongs to, which counts the major frames (the beams
    /// of one firing share it, as ATLAS's six do).
    pub fn add(&mut self, pulse: &Pulse, shot: u64, gate: Gate, rows: &[PhotonRow]) -> Result<()> {
        self.track(pulse)?;
        let Some(track) = self.tracks.get_mut(&pulse.line) else {
            return Ok(());
        };
        let delta_time = pulse.gps_time_s - MISSION_EPOCH_GPS_S;
        let frame = shot / 200;
        // the background of 50 shots: a row once the 50th is in
        let bg = &mut track.background;
        if bg.shots == 0 {
            let top = pulse.origin + pulse.direction * (crate::C * gate.start_s / 2.0);
            *bg = Background {
                delta_time,
                frame: frame.min(i64::MAX as u64) as i64,
                top: self.geo.of(top).2,
                height: crate::C * gate.length_s / 2.0,
                ..Background::default()
            };
        }
        bg.shots += 1;
        bg.events += rows.len() as u64;
        bg.noise += rows.iter().filter(|r| r.source != 0).count() as u64;
        if bg.shots == BACKGROUND_SHOTS {
            let done = std::mem::take(bg);
            write_background(&mut self.h5, &track.name, &done)?;
        }
        let b = format!("{}/heights", track.name);
        let along = (pulse.origin - track.first).truncate();
        // the direction of travel: the platform's, which the track's first pulse has too (the
        // way from the first pulse is no direction at the first pulse itself)
        let unit = pulse
            .along
            .truncate()
            .try_normalize()
            .or_else(|| along.try_normalize());
        // the pulse's segment, by its nadir point's distance along the track; the one before
        // is written once the track leaves it, with any it skipped (no pulse: no photons)
        let k = (along.length() / SEGMENT_M).floor() as i64;
        match track.segment {
            Some(seg) if seg.k == k => {}
            Some(seg) => {
                write_segment(&mut self.h5, &track.name, &seg, &self.sun)?;
                for skipped in seg.k + 1..k {
                    write_segment(
                        &mut self.h5,
                        &track.name,
                        &Segment::empty(skipped),
                        &self.sun,
                    )?;
                }
                track.segment = Some(Segment::empty(k));
            }
            None => track.segment = Some(Segment::empty(k)),
        }
        if rows.is_empty() {
            return Ok(());
        }
        let start = SEGMENT_M * k as f64;
        let n = rows.len();
        let mut h = Vec::with_capacity(n);
        let (mut lat, mut lon) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let (mut d_along, mut d_across) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let mut count = Vec::with_capacity(n);
        let mut conf = Vec::with_capacity(5 * n);
        for (k, r) in rows.iter().enumerate() {
            let p = DVec3::new(r.x, r.y, r.z);
            let (la, lo, z) = self.geo.of(p);
            h.push(z as f32);
            lat.push(la);
            lon.push(lo);
            let from_first = (p - track.first).truncate();
            let off = (p - pulse.origin).truncate();
            let (a, c) = match unit {
                Some(u) => (from_first.dot(u) - start, u.perp_dot(off)),
                None => (from_first.length() - start, off.length()),
            };
            d_along.push(a as f32);
            d_across.push(c as f32);
            count.push((k + 1).min(255) as u8);
            conf.extend([signal_confidence(r.source); 5]);
        }
        if let Some(seg) = track.segment.as_mut() {
            if seg.photons == 0 {
                seg.first = track.photons + 1;
                seg.reference = (lat[0], lon[0], delta_time);
            }
            seg.photons += n as u64;
        }
        track.photons += n as u64;
        let sources: Vec<u8> = rows.iter().map(|r| r.source).collect();
        let hw = &mut self.h5;
        hw.push_f32(&format!("{b}/h_ph"), &h)?;
        hw.push_f64(&format!("{b}/lat_ph"), &lat)?;
        hw.push_f64(&format!("{b}/lon_ph"), &lon)?;
        hw.push_f64(&format!("{b}/delta_time"), &vec![delta_time; n])?;
        hw.push_f32(&format!("{b}/dist_ph_along"), &d_along)?;
        hw.push_f32(&format!("{b}/dist_ph_across"), &d_across)?;
        hw.push_u8(
            &format!("{b}/ph_id_pulse"),
            &vec![(shot % 200 + 1) as u8; n],
        )?;
        hw.push_u32(
            &format!("{b}/pce_mframe_cnt"),
            &vec![frame.min(u64::from(u32::MAX)) as u32; n],
        )?;
        hw.push_u8(&format!("{b}/ph_id_count"), &count)?;
        hw.push_i8(&format!("{b}/quality_ph"), &vec![0; n])?;
        hw.push_i8(&format!("{b}/signal_conf_ph"), &conf)?;
        hw.push_u8(&format!("{b}/truth_source"), &sources)
    }

    /// Writes each track's last segment and background row (of fewer than 50 shots) and the
    /// file.
    pub fn finish(mut self) -> Result<()> {
        for track in std::mem::take(&mut self.tracks).into_values() {
            if let Some(seg) = &track.segment {
                write_segment(&mut self.h5, &track.name, seg, &self.sun)?;
            }
            if track.background.shots > 0 {
                write_background(&mut self.h5, &track.name, &track.background)?;
            }
        }
        self.h5.finish()
    }
}
