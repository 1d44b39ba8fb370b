//! Pulse planning: a platform expands into the list of pulses to simulate.
//!
//! The frame is flat and local: x, y in metres across the scene, z up, no Earth curvature.
//! Platform heights (`altitude_m`) are measured from z = 0.
//!
//! Sampling a range by a step. Two rules are used, each where the paper's counts or the
//! contract ask for it:
//! - *whole steps* ([`whole_steps`]): one sample at the start of every whole step that fits
//!   in the range, so a leftover part-step at the end gets no sample. ALS scan lines and look
//!   angles and the `track` profiler use it: a scan line or a shot "owns" its step, which is
//!   what the paper's counts imply (⌊98/0.3⌋ = 326 scan lines, ⌊22.18°/0.045°⌋ = 492 look
//!   angles, 326 × 492 = 160,392 pulses; ⌊98√2/0.02⌋ = ⌊6929.6⌋ = 6929 MABEL shots).
//! - *inclusive* ([`inclusive_steps`]): every sample start + k·step that lies in the range,
//!   both ends included when the range is a whole number of steps. TLS angles and
//!   spaceborne shots use it.
//!
//! "A whole number of steps" is judged with a relative tolerance of 1e-9 (capped at a
//! millionth of a step), so that 100/0.1 counts as 1000 steps despite rounding.

mod als;
mod nav;
mod pulses_file;
mod spaceborne;
mod tls;
mod track;
mod trajectory;
pub mod validate;

#[cfg(test)]
mod tests;

pub use crate::campaign::ScanPattern;

pub use pulses_file::write_pulses;

use crate::campaign::{Campaign, Doc, Loaded, Platform, PlatformKind, Segment};
use crate::error::{Error, Result};
use glam::{DVec2, DVec3};

/// Plans larger than this are refused: at 100 bytes a pulse the plan alone would pass 50 GB.
pub const MAX_PULSES: u64 = 500_000_000;

pub use crate::campaign::DEFAULT_PRF_HZ;

const TOL: f64 = 1e-9;

/// One planned pulse, in emission order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pulse {
    pub id: u64,
    pub gps_time_s: f64,
    pub origin: DVec3,
    /// Unit beam direction.
    pub direction: DVec3,
    /// Angle between the beam and nadir, degrees (signed for scanners).
    pub scan_angle_deg: f32,
    pub line: u32,
    /// The platform (body) frame's x axis: the direction of travel, horizontal but for a
    /// trajectory's pitch; +x for static and terrestrial platforms, whose frame is the scene's.
    pub along: DVec3,
    /// The body frame's z axis: +z but for a trajectory's roll and pitch.
    pub up: DVec3,
    /// The pose the points are georeferenced from (origin, unit direction) when it differs
    /// from the flown one: a campaign with `errors`. `None`: the flown pose.
    pub recorded: Option<(DVec3, DVec3)>,
}

impl Pulse {
    /// A point given in the platform frame (x along track, y left, z up), in the scene.
    pub fn platform_to_scene(&self, v: [f64; 3]) -> DVec3 {
        let left = self.up.cross(self.along);
        self.along * v[0] + left * v[1] + self.up * v[2]
    }

    /// The origin the points are georeferenced from: the recorded one.
    pub fn rec_origin(&self) -> DVec3 {
        self.recorded.map_or(self.origin, |r| r.0)
    }

    /// The beam direction the points are georeferenced along: the recorded one.
    pub fn rec_direction(&self) -> DVec3 {
        self.recorded.map_or(self.direction, |r| r.1)
    }
}

/// Unit vector of a beam with zenith angle θ from +z and azimuth φ from +x towards +y.
pub fn direction_from_angles(zenith_deg: f64, azimuth_deg: f64) -> DVec3 {
    let (t, p) = (zenith_deg.to_radians(), azimuth_deg.to_radians());
    DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

/// Angle between a beam and nadir, in degrees.
pub fn off_nadir_deg(direction: DVec3) -> f64 {
    (-direction.z).clamp(-1.0, 1.0).acos().to_degrees()
}

/// `extent / step`, snapped to the nearest whole number when within the tolerance.
///
/// The tolerance is relative (1e-9 of the ratio) but capped at a millionth of a step, so
/// that a very long range cannot gain a whole step from it; the ratio's own rounding error
/// stays far below the cap up to [`MAX_PULSES`] steps.
fn snapped_ratio(extent: f64, step: f64) -> (f64, bool) {
    let r = extent / step;
    let near = r.round();
    if (r - near).abs() <= (TOL * r.abs().max(1.0)).min(1e-6) {
        (near, true)
    } else {
        (r, false)
    }
}

/// Number of samples at the start of each whole `step` in `extent` (see the module doc).
pub fn whole_steps(extent: f64, step: f64) -> u64 {
    // `as` saturates, so absurd ratios become u64::MAX and fail the size check.
    snapped_ratio(extent, step).0.floor().max(0.0) as u64
}

/// Number of samples start + k·step within `extent`, both ends included (module doc).
pub fn inclusive_steps(extent: f64, step: f64) -> u64 {
    whole_steps(extent, step).saturating_add(1)
}

/// Whether `extent` is a whole number of `step`s, within the tolerance.
pub fn is_multiple(extent: f64, step: f64) -> bool {
    snapped_ratio(extent, step).1
}

/// Reads a campaign file and checks all of it: its own keys, its platform, its scene file.
pub fn read_campaign(path: &std::path::Path) -> Result<Loaded> {
    load_campaign(Doc::read(path)?, &[])
}

/// Checks a campaign's text (a file read, or a host's mapping written as YAML) with
/// `overrides` (dotted keys, as in a sweep) applied before validation. An error at an
/// overridden key names the override.
pub fn load_campaign(doc: Doc, overrides: &[(String, serde_yaml::Value)]) -> Result<Loaded> {
    if overrides.is_empty() {
        let mut campaign: Campaign = doc.parse()?;
        campaign.resolve_files(&doc);
        check_campaign(&doc, &campaign)?;
        return Loaded::new(doc, campaign);
    }
    let mut tree: serde_yaml::Value = doc.parse()?;
    let named = |k: &str, v: &serde_yaml::Value, m: &dyn std::fmt::Display| {
        Error::at(
            &doc.path,
            None,
            k,
            format!("override {}: {m}", crate::campaign::yaml::inline(v)),
        )
    };
    for (k, v) in overrides {
        crate::campaign::yaml::set_path(&mut tree, k, v.clone()).map_err(|m| named(k, v, &m))?;
    }
    let mut campaign: Campaign = serde_path_to_error::deserialize(tree).map_err(|e| {
        let at = e.path().to_string();
        let message = crate::campaign::yaml::plain_words(&e.into_inner().to_string());
        match overrides.iter().find(|(k, _)| {
            at == *k
                || at.starts_with(&format!("{k}."))
                || message.contains(&format!("`{}`", k.rsplit('.').next().unwrap_or(k)))
        }) {
            Some((k, v)) => named(k, v, &message),
            None => doc.error(&at, format!("with the overrides: {message}")),
        }
    })?;
    campaign.resolve_files(&doc);
    check_campaign(&doc, &campaign).map_err(|e| {
        let ek = e.key.clone().unwrap_or_default();
        match overrides
            .iter()
            .find(|(k, _)| ek == *k || ek.starts_with(&format!("{k}.")))
        {
            Some((k, v)) => named(k, v, &e.message),
            None => e,
        }
    })?;
    Loaded::new(doc, campaign)
}

/// A one-pulse static campaign over a scene, given as the sections of a campaign file
/// (YAML values), and its pulse 0. A single pulse simulated in memory is defined as this
/// campaign's pulse (spec: python.md), and the bench traces its pulses so.
#[derive(Clone, Debug)]
pub struct OnePulse {
    pub instrument: serde_yaml::Value,
    pub origin: [f64; 3],
    pub direction: [f64; 3],
    pub wavelength_nm: serde_yaml::Value,
    /// The `simulation:` section (method, rays_per_pulse, max_order, ...).
    pub simulation: serde_yaml::Value,
    pub seed: u64,
    pub sun: Option<serde_yaml::Value>,
    pub atmosphere: Option<serde_yaml::Value>,
}

impl OnePulse {
    /// The campaign, checked as a file is; `label` names it in error messages.
    pub fn campaign(&self, scene: &std::path::Path, label: &str) -> Result<(Loaded, Pulse)> {
        use serde_yaml::Value;
        let scene = std::path::absolute(scene)
            .map_err(|e| Error::io(scene, "cannot resolve the scene's path", e))?;
        let xyz = |v: [f64; 3]| Value::Sequence(v.iter().map(|&x| Value::from(x)).collect());
        let mut pulse = serde_yaml::Mapping::new();
        pulse.insert("position".into(), xyz(self.origin));
        pulse.insert("direction".into(), xyz(self.direction));
        let mut platform = serde_yaml::Mapping::new();
        platform.insert("kind".into(), "static".into());
        platform.insert(
            "pulses".into(),
            Value::Sequence(vec![Value::Mapping(pulse)]),
        );
        let mut m = serde_yaml::Mapping::new();
        m.insert("name".into(), "pulse".into());
        m.insert("scene".into(), scene.display().to_string().into());
        m.insert("seed".into(), self.seed.into());
        m.insert("wavelength_nm".into(), self.wavelength_nm.clone());
        m.insert("instrument".into(), self.instrument.clone());
        m.insert("platform".into(), Value::Mapping(platform));
        m.insert("simulation".into(), self.simulation.clone());
        if let Some(sun) = &self.sun {
            m.insert("sun".into(), sun.clone());
        }
        if let Some(a) = &self.atmosphere {
            m.insert("atmosphere".into(), a.clone());
        }
        let text = serde_yaml::to_string(&Value::Mapping(m))
            .map_err(|e| Error::msg(format!("{label}: {e}")))?;
        let doc = Doc {
            path: std::path::PathBuf::from(label),
            text,
        };
        let loaded = load_campaign(doc, &[])?;
        let pulse = Plan::new(&loaded.campaign)?.pulse(0);
        Ok((loaded, pulse))
    }
}

/// Checks a campaign's own keys, then its platform.
pub fn check_campaign(doc: &Doc, campaign: &Campaign) -> Result<()> {
    campaign.validate(doc)?;
    validate::platform(doc, &campaign.platform)
}

/// A campaign's pulses, made on demand: any pulse, or any range of them, is computed from
/// its id alone, so no stage holds the whole plan in memory whatever the campaign's length.
pub struct Plan {
    len: u64,
    platform: Source,
}

/// The platform that makes the pulses.
enum Source {
    /// `static`: the campaign file lists its pulses.
    Listed(Vec<Pulse>),
    Als(Box<als::Als>),
    Spaceborne(spaceborne::Spaceborne),
    Track(track::Track),
    Tls(tls::Tls),
}

impl Plan {
    /// The plan of a campaign; refused when over [`MAX_PULSES`].
    pub fn new(campaign: &Campaign) -> Result<Plan> {
        let p = &campaign.platform;
        let platform = match p.kind {
            PlatformKind::Static => Source::Listed(static_pulses(p)),
            PlatformKind::Als => {
                Source::Als(Box::new(als::Als::new(p)?.with_errors(p, campaign.seed)))
            }
            PlatformKind::Spaceborne => Source::Spaceborne(spaceborne::Spaceborne::new(p)?),
            PlatformKind::Track => Source::Track(track::Track::new(p)?),
            PlatformKind::Tls => Source::Tls(tls::Tls::new(p)?),
        };
        let len = match &platform {
            Source::Listed(v) => v.len() as u64,
            Source::Als(a) => a.count(),
            Source::Spaceborne(s) => s.count(),
            Source::Track(t) => t.count(),
            Source::Tls(t) => t.count(),
        };
        if len > MAX_PULSES {
            return Err(Error::msg(too_many(len)));
        }
        Ok(Plan { len, platform })
    }

    /// Number of pulses.
    pub fn len(&self) -> usize {
        self.len as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Pulse `id`, which must be below [`Plan::len`].
    pub fn pulse(&self, id: u64) -> Pulse {
        debug_assert!(id < self.len);
        match &self.platform {
            Source::Listed(v) => v[id as usize],
            Source::Als(a) => a.pulse(id),
            Source::Spaceborne(s) => s.pulse(id),
            Source::Track(t) => t.pulse(id),
            Source::Tls(t) => t.pulse(id),
        }
    }

    /// The first pulse of pulse `id`'s line (flight line or scan interval, spaceborne beam,
    /// station): where along-track distances on that line count from.
    pub fn line_start(&self, id: u64) -> u64 {
        match &self.platform {
            Source::Listed(v) => {
                let line = v[id as usize].line;
                v.iter().position(|p| p.line == line).unwrap_or(0) as u64
            }
            Source::Als(a) => a.line_start(id),
            Source::Spaceborne(s) => s.line_start(id),
            Source::Track(_) => 0,
            Source::Tls(t) => t.station_start(id),
        }
    }

    /// The shot pulse `id` belongs to: the index of the laser's firing, which the beams of a
    /// spaceborne platform share; every other platform fires one pulse a shot.
    pub fn shot(&self, id: u64) -> u64 {
        match &self.platform {
            Source::Spaceborne(s) => s.shot(id),
            _ => id,
        }
    }

    /// The scan angle LAS records for pulse `p`: the beam's angle from the scene's nadir
    /// ("down in the data coordinate system is the 0.0 position"). An airborne pulse's is its
    /// look angle, or across track with the roll in it ([`als`]); a TLS station's, 180° less
    /// its zenith angle (it has no direction of travel to sign it by: 0 to 180°).
    pub fn las_scan_angle(&self, p: &Pulse) -> f32 {
        match &self.platform {
            Source::Als(a) => a.las_angle(p),
            Source::Tls(_) => (-p.rec_direction().z).clamp(-1.0, 1.0).acos().to_degrees() as f32,
            _ => p.scan_angle_deg,
        }
    }

    /// The recorded trajectory flown, as `check` reports it: its epochs, times and scan
    /// intervals; `None` for every other platform.
    pub fn trajectory_note(&self) -> Option<String> {
        match &self.platform {
            Source::Als(a) => a.trajectory_note(),
            _ => None,
        }
    }

    /// Whether the pulses carry a recorded pose apart from the flown one (`errors` given):
    /// pulses.parquet then has its columns.
    pub fn records_pose(&self) -> bool {
        matches!(&self.platform, Source::Als(a) if a.records_pose())
    }

    /// LAS's scan direction and edge-of-flight-line flags of pulse `id`: the look angle
    /// growing (left to right: a positive angle is right of the track), and the last pulse of a
    /// scan line. Only the across-track sweeps (`line`, `oscillating`, `rotating_polygon`) have
    /// them; every other pulse has neither.
    pub fn scan_flags(&self, id: u64) -> (bool, bool) {
        match &self.platform {
            Source::Als(a) => a.scan_flags(id),
            _ => (false, false),
        }
    }

    /// `n` pulses spread over the plan for a sample of it (a pilot, a probe): one from each of
    /// `n` equal strata, at an offset hashed from `seed` and the stratum. Not the first of
    /// each stratum: a fixed stride aliases with a scan whose period divides it (the town
    /// survey's eighths are whole scan periods, so their first pulses all look 15° aside).
    pub fn spread(&self, n: usize, seed: u64) -> Vec<Pulse> {
        let n = (n as u64).min(self.len);
        (0..n)
            .map(|k| {
                let (lo, hi) = (k * self.len / n, (k + 1) * self.len / n);
                let h = crate::rng::splitmix64(seed ^ crate::rng::splitmix64(k ^ 0x7069_6c6f_7400));
                self.pulse(lo + h % (hi - lo).max(1))
            })
            .collect()
    }

    /// The pulses whose ids lie in `range` (clipped to the plan), in emission order.
    pub fn pulses(&self, range: std::ops::Range<usize>) -> Vec<Pulse> {
        let end = range.end.min(self.len());
        (range.start.min(end)..end)
            .map(|id| self.pulse(id as u64))
            .collect()
    }
}

/// Every pulse of a campaign, in emission order (`id` = index): for tests and small plans;
/// the pipeline takes them a part at a time from [`Plan`].
pub fn plan(campaign: &Campaign) -> Result<Vec<Pulse>> {
    let plan = Plan::new(campaign)?;
    Ok(plan.pulses(0..plan.len()))
}

/// How many pulses `plan` would make, without making them (saturating on overflow).
pub fn count(p: &Platform) -> Result<u64> {
    Ok(match p.kind {
        PlatformKind::Static => p.pulses.as_ref().map_or(0, |v| v.len() as u64),
        PlatformKind::Als => als::Als::new(p)?.count(),
        PlatformKind::Spaceborne => spaceborne::Spaceborne::new(p)?.count(),
        PlatformKind::Track => track::Track::new(p)?.count(),
        PlatformKind::Tls => tls::Tls::new(p)?.count(),
    })
}

pub(crate) fn too_many(n: u64) -> String {
    format!(
        "the platform plans {n} pulses, more than the limit of {MAX_PULSES}; \
         use larger steps, a lower prf_hz or shorter lines, or split the campaign"
    )
}

fn static_pulses(p: &Platform) -> Vec<Pulse> {
    let specs = p.pulses.as_deref().unwrap_or(&[]);
    let t0 = p.gps_start_s.unwrap_or(0.0);
    specs
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let direction = match s.direction {
                Some(d) => DVec3::from_array(d).normalize(),
                None => direction_from_angles(
                    s.zenith_deg.unwrap_or(180.0),
                    s.azimuth_deg.unwrap_or(0.0),
                ),
            };
            Pulse {
                id: i as u64,
                gps_time_s: t0,
                origin: DVec3::from_array(s.position),
                direction,
                scan_angle_deg: off_nadir_deg(direction) as f32,
                line: 0,
                along: DVec3::X,
                up: DVec3::Z,
                recorded: None,
            }
        })
        .collect()
}

/// "an als", "a track", ...: the kind with its article, for messages.
pub(crate) fn kind_phrase(kind: PlatformKind) -> &'static str {
    match kind {
        PlatformKind::Static => "a static",
        PlatformKind::Als => "an als",
        PlatformKind::Spaceborne => "a spaceborne",
        PlatformKind::Track => "a track",
        PlatformKind::Tls => "a tls",
    }
}

/// A required key, for callers that plan without validating first.
fn need<T: Copy>(v: Option<T>, kind: PlatformKind, key: &str) -> Result<T> {
    v.ok_or_else(|| Error::msg(format!("{} platform needs {key}", kind_phrase(kind))))
}

/// A straight ground path in scene x/y with its horizontal frame.
#[derive(Clone, Copy, Debug)]
struct GroundPath {
    start: DVec3,
    end: DVec3,
    /// Unit vector along the path (z = 0).
    along: DVec3,
    /// Unit vector to the right of the direction of travel (z = 0): along × up.
    right: DVec3,
    length: f64,
}

impl GroundPath {
    fn new(s: &Segment) -> GroundPath {
        let (a, b) = (DVec2::from_array(s.start), DVec2::from_array(s.end));
        let length = (b - a).length();
        let u = if length > 0.0 {
            (b - a) / length
        } else {
            DVec2::X
        };
        GroundPath {
            start: a.extend(0.0),
            end: b.extend(0.0),
            along: u.extend(0.0),
            right: DVec3::new(u.y, -u.x, 0.0),
            length,
        }
    }
}
