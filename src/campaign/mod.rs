//! Campaign files: the YAML a user writes, its defaults and its validation.
//!
//! The keys are a contract (../shared/spec/campaign.md). Every struct denies unknown keys, and
//! every number is checked after parsing, with errors that point at the file, line and key.
//! Units are those the key names say; conversion to SI happens once, in `sensor`.

pub mod frame;
pub mod spectral;
pub mod yaml;

use crate::error::{Error, Result};
pub use frame::Frame;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
pub use yaml::Doc;

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Campaign {
    pub name: String,
    /// Scene file, relative to the campaign file.
    pub scene: String,
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// One wavelength, or several bands traced in one pass.
    pub wavelength_nm: spectral::Wavelengths,
    pub instrument: Instrument,
    pub platform: Platform,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sun: Option<Sun>,
    #[serde(default)]
    pub simulation: Simulation,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub products: Option<Products>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sweep: Option<BTreeMap<String, Vec<serde_yaml::Value>>>,
    /// Georeference of the products; absent = local metres, no CRS.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<Frame>,
    /// A plane-parallel exponential atmosphere; absent = vacuum.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub atmosphere: Option<Atmosphere>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Atmosphere {
    pub layers: Vec<AtmosphereLayer>,
}

/// One exponential layer: extinction per metre (τ / H) e^(-z/H) at height z above z = 0.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct AtmosphereLayer {
    pub scale_height_m: f64,
    /// Vertical optical depth from z = 0 to the top of the atmosphere, per wavelength.
    pub optical_depth: spectral::Spectral,
}

fn default_seed() -> u64 {
    1
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum InstrumentKind {
    #[default]
    Waveform,
    DiscreteReturn,
    PhotonCounting,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Instrument {
    #[serde(default)]
    pub kind: InstrumentKind,
    pub pulse_energy_j: f64,
    pub pulse_fwhm_ns: f64,
    pub footprint_half_angle_mrad: f64,
    /// η: energy at the footprint edge relative to the centre.
    #[serde(default = "default_eta")]
    pub edge_energy_fraction: f64,
    pub fov_half_angle_mrad: f64,
    pub receiver_area_m2: f64,
    #[serde(default = "default_bin_ns")]
    pub bin_ns: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bandwidth_nm: Option<f64>,
    #[serde(default = "default_max_returns")]
    pub max_returns: u32,
    #[serde(default = "default_threshold")]
    pub detection_threshold_photons: f64,
    /// Probability that a gate of noise alone gives a false return, which sets the detection
    /// threshold of records with noise (see [`Instrument::false_alarm_rate`]); absent: 1e-3.
    #[serde(
        default,
        rename = "false_alarm_rate",
        skip_serializing_if = "Option::is_none"
    )]
    pub false_alarm_rate_per_pulse: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quantum_efficiency: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dead_time_ns: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark_count_hz: Option<f64>,
    /// Optional fixed range gate; by default each pulse's gate covers the scene's bounding box.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range_gate: Option<RangeGate>,
    /// Detector noise; absent: the mean waveform is recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<Noise>,
    /// FWHM of the detector's Gaussian impulse response, convolved with the received
    /// waveform; absent: none beyond the pulse's own shape.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub detector_response_fwhm_ns: Option<f64>,
    /// Analogue-to-digital conversion of the recorded waveform; absent: not quantised.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub digitiser: Option<Digitiser>,
    /// The telescope's centre relative to the laser in the platform frame (x along track,
    /// y left, z up), m; absent: [0, 0, 0], mono-static.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub receiver_offset_m: Option<[f64; 3]>,
}

impl Instrument {
    /// Probability per pulse that a record of noise alone yields a return: the configured
    /// `false_alarm_rate`, or 1e-3. It applies to records with noise only (see `noise`).
    pub fn false_alarm_rate(&self) -> f64 {
        self.false_alarm_rate_per_pulse
            .unwrap_or(DEFAULT_FALSE_ALARM_RATE)
    }

    /// |receiver_offset_m|, m: how much longer than 2R a path may be.
    pub fn receiver_offset_length(&self) -> f64 {
        self.receiver_offset_m
            .map_or(0.0, |o| (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt())
    }
}

/// Noise of an analogue detector: the photoelectrons of signal, solar background and dark
/// counts are Poisson (always, when this section is present), plus Gaussian electronic noise.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// Standard deviation of the electronic (thermal, read) noise per bin, photoelectrons.
    #[serde(default)]
    pub electronic_sd_photons: f64,
}

/// counts = round(offset + gain x photoelectrons), clipped to [0, saturation].
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Digitiser {
    /// Counts per photoelectron.
    pub gain: f64,
    /// Counts of zero signal.
    #[serde(default)]
    pub offset: f64,
    /// Signed so that a negative value reads as out of range (1 to 24), not as a type error.
    pub bits: i64,
    /// Highest count recorded; default 2^bits - 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub saturation: Option<f64>,
}

impl Digitiser {
    pub fn saturation(&self) -> f64 {
        self.saturation
            .unwrap_or(((1u64 << self.bits.clamp(0, 32)) - 1) as f64)
    }
}

fn default_eta() -> f64 {
    (-2.0f64).exp()
}
fn default_bin_ns() -> f64 {
    1.0
}
fn default_max_returns() -> u32 {
    4
}
/// The chance that a gate of noise alone gives a false return, unless the campaign says otherwise.
pub const DEFAULT_FALSE_ALARM_RATE: f64 = 1e-3;

fn default_threshold() -> f64 {
    5.0
}

/// A fixed range gate: bin 0 starts `start_ns` after emission, `bins` bins long.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RangeGate {
    pub start_ns: f64,
    pub bins: u32,
}

/// All platform kinds share one struct so that every key keeps its own line in errors;
/// which keys a kind needs is checked in [`Campaign::validate`].
#[derive(Clone, Debug, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Platform {
    pub kind: PlatformKind,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pulses: Option<Vec<PulseSpec>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub altitude_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed_m_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_speed_m_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prf_hz: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lines: Option<Vec<Segment>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scanner: Option<Scanner>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub track: Option<Segment>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beams: Option<Vec<Beam>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub off_nadir_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub along_track_step_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<[f64; 3]>,
    /// Several TLS stations, scanned in turn (`line` and the points' source id = the index).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub positions: Option<Vec<[f64; 3]>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub azimuth_deg: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub azimuth_step_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zenith_deg: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zenith_step_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gps_start_s: Option<f64>,
    /// A recorded trajectory flown instead of `altitude_m`, `speed_m_s` and `lines` (als).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trajectory: Option<Trajectory>,
    /// Where the scanner sits on the body and how it is turned (als), known to the
    /// georeferencing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mount: Option<Mount>,
    /// Navigation and mounting errors (als): flown, and not corrected by the georeferencing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub errors: Option<NavErrors>,
}

/// `platform.trajectory`: a CSV of epochs (columns by name) and the times that fire.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Trajectory {
    /// Relative to the campaign file.
    pub file: String,
    /// GPS time intervals [t0, t1] that fire pulses; default the whole trajectory.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scan: Option<Vec<[f64; 2]>>,
    /// `file` resolved against the campaign file's folder when the campaign is loaded.
    #[serde(skip)]
    pub resolved: Option<PathBuf>,
    /// The frame's origin (easting, northing, height), subtracted from the file's positions;
    /// zero without a frame. Set with `resolved`.
    #[serde(skip)]
    pub origin: [f64; 3],
}

/// `platform.mount`: the scanner's origin in the body frame and its turn against the body.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Mount {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset_m: Option<[f64; 3]>,
    /// Roll, pitch, heading of the scanner against the body, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub boresight_deg: Option<[f64; 3]>,
}

/// `platform.errors`: first-order Gauss-Markov position and attitude errors of the recorded
/// pose, and an unknown boresight the pulses fly with.
#[derive(Clone, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct NavErrors {
    /// East, north, up, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_sd_m: Option<[f64; 3]>,
    /// 0 (the default): white.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position_correlation_s: Option<f64>,
    /// Roll, pitch, heading, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attitude_sd_deg: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attitude_correlation_s: Option<f64>,
    /// Roll, pitch, heading of an unknown misalignment, degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub boresight_deg: Option<[f64; 3]>,
}

impl Campaign {
    /// Resolves the files the campaign names besides its scene against `doc`'s folder.
    pub fn resolve_files(&mut self, doc: &Doc) {
        let origin = self.frame.as_ref().map_or([0.0; 3], |f| f.origin);
        if let Some(t) = &mut self.platform.trajectory {
            t.resolved = Some(doc.resolve(&t.file));
            t.origin = origin;
        }
    }
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum PlatformKind {
    #[default]
    Static,
    Als,
    Spaceborne,
    Track,
    Tls,
}

/// One explicit pulse: a position and a beam direction, given as a vector or as the beam's
/// zenith (from +z, so 180° is nadir) and azimuth (from +x towards +y) in degrees.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PulseSpec {
    pub position: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zenith_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub azimuth_deg: Option<f64>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    pub start: [f64; 2],
    pub end: [f64; 2],
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Beam {
    #[serde(default)]
    pub cross_track_m: f64,
    /// The beam's pulse energy as a fraction of `instrument.pulse_energy_j` (default 1):
    /// ATLAS's weak beams carry a quarter of its strong ones'.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_energy: Option<f64>,
}

/// How an ALS scanner sweeps its beam across the track.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ScanPattern {
    /// Back and forth between the scan angles (a galvanometer mirror).
    Oscillating,
    /// From one scan angle to the other, then again (a rotating polygon).
    Line,
    /// Around a cone at the largest scan angle (a Palmer scanner).
    Conic,
    /// A spinning mirror polygon: parallel lines, each from min to max, firing in the first
    /// `duty` of each line.
    RotatingPolygon,
    /// Two rotating prisms (Livox-like rosettes), paraxial: the deflections add as vectors.
    Risley,
    /// A spinning multi-channel head (Velodyne-like).
    Multibeam,
}

impl ScanPattern {
    /// Scan lines per period of `scan_frequency_hz`.
    pub fn lines_per_period(self) -> f64 {
        match self {
            ScanPattern::Oscillating => 2.0,
            ScanPattern::Line
            | ScanPattern::Conic
            | ScanPattern::RotatingPolygon
            | ScanPattern::Risley
            | ScanPattern::Multibeam => 1.0,
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Scanner {
    pub pattern: ScanPattern,
    /// [min, max] of the look angle: every pattern but `risley` and `multibeam`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scan_angle_deg: Option<[f64; 2]>,
    /// `rotating_polygon`: mirror facets (a line per facet; the rotation is
    /// scan_frequency_hz / facets) and the fraction of each line that fires (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub facets: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duty: Option<f64>,
    /// `risley`: the two prisms' rates (turns per second, signed), deflections and phases.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prism_rates_hz: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deviation_deg: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phase_deg: Option<[f64; 2]>,
    /// `multibeam`: the channels' elevations above the head's plane, its turns per second and
    /// its tilt (a roll about the body's x axis, right side down).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub channels_deg: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation_hz: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub head_tilt_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scan_frequency_hz: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub look_angle_step_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub along_track_step_m: Option<f64>,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Sun {
    /// Zenith angle of the direction towards the sun; negative puts it at azimuth + 180°.
    pub zenith_deg: f64,
    /// Azimuth of the direction towards the sun, from +x towards +y.
    pub azimuth_deg: f64,
    /// Spectral irradiance at the top of the scene, W m⁻² µm⁻¹.
    pub irradiance_w_m2_um: f64,
    /// How a sample picks the light its light sub-path starts from: `fixed` with
    /// `selection_probability` for the sun (the paper's 0.5), `power`, in proportion to the
    /// energy each light sends into the part of the scene the receiver sees during the pulse's
    /// range gate, or `auto` (the default; `fixed` when only a probability is given), which
    /// tries both on the pilot pulses and keeps the cheaper for the same laser and solar
    /// errors. Read it through [`Sun::selection`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub selection: Option<SunSelection>,
    /// Probability of the sun with `selection: fixed`; default 0.5.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub selection_probability: Option<f64>,
    /// Share of the samples that trace the sun's light: a number in (0, 1] (default 1) or
    /// `auto`. The others trace the laser's alone (bdpt's receiver sub-path stops where the
    /// laser's joins end, and no light sub-path starts at the sun); the sun's contributions
    /// are divided by the share, so both estimates stay unbiased. Where the solar photons are
    /// a small part of the waveform (a photon-counting track by day), their simulation noise
    /// is a small part of its whole, and a share of 1/16 buys the laser's light for half the
    /// time. `auto` tries 1, 1/4 and 1/16 on the pilot pulses and keeps the cheapest for the
    /// same noise in photons. Read it through [`Sun::share_fraction`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub share: Option<SunShare>,
}

/// `sun.share` as written: a fraction of the samples, or `auto`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SunShare {
    Fraction(f64),
    /// Chosen by the pilot before any pulse is traced.
    Auto,
}

impl Serialize for SunShare {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            SunShare::Fraction(f) => s.serialize_f64(*f),
            SunShare::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for SunShare {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Number(f64),
            Word(String),
        }
        match Raw::deserialize(d) {
            Ok(Raw::Number(f)) => Ok(SunShare::Fraction(f)),
            Ok(Raw::Word(w)) if w == "auto" => Ok(SunShare::Auto),
            _ => Err(serde::de::Error::custom(
                "expected a number in (0, 1] (the share of samples that trace the sun) or auto",
            )),
        }
    }
}

impl Sun {
    /// The selection asked for: as written, else `fixed` when a probability is given, else
    /// `auto`.
    pub fn selection(&self) -> SunSelection {
        match (self.selection, self.selection_probability) {
            (Some(s), _) => s,
            (None, Some(_)) => SunSelection::Fixed,
            (None, None) => SunSelection::Auto,
        }
    }

    /// The share of samples that trace the sun: as written, 1 when not given or still `auto`
    /// (a pilot's trials set it before tracing).
    pub fn share_fraction(&self) -> f64 {
        match self.share {
            Some(SunShare::Fraction(f)) => f,
            _ => 1.0,
        }
    }
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum SunSelection {
    /// The paper's: the sun with a fixed probability, 0.5 unless given. Best where the
    /// receiver sees most of the scene (a GEDI footprint over the orchard): sun sub-paths
    /// land in view and carry much of the solar signal.
    Fixed,
    /// By the energy each light sends into the receiver's view
    /// ([`crate::sensor::SunSource::for_gate`]). Best where it sees a few metres of a large
    /// scene (MABEL): a sun sub-path then almost never lands in view.
    Power,
    /// Chosen between the two by `simulation.method: auto`'s pilot; resolved before any
    /// pulse is traced.
    Auto,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Bidirectional path tracing with every connection strategy.
    Bdpt,
    /// Light paths from the laser, each vertex connected to the receiver.
    Forward,
    /// Receiver paths from the aperture, each vertex connected to the laser.
    Backward,
    /// One of the three, chosen per campaign by a pilot before the simulation (see
    /// `pipeline::simulate::choose_method`): the default, so a campaign that names no method
    /// gets the cheapest for its scene and instrument.
    #[default]
    Auto,
}

/// Which vertices of bdpt's receiver sub-path join the laser's light (its light sub-paths
/// and the laser itself). The sun's light joins every one either way: its light sub-paths
/// rarely land in a narrow view, so the solar signal of every order comes from the receiver
/// sub-path's vertices connected to the sun.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum ReceiverDepth {
    /// Every vertex, up to `max_order`: all of bdpt's strategies.
    Full,
    /// The aperture point and the first surface the receiver sees: each order of laser light
    /// is then made by the laser's light sub-path connected to the aperture or to that
    /// surface (and order 1 also by that surface connected to the laser). Where the laser's
    /// light sub-paths find the receiver's view as well as the receiver's sub-paths find the
    /// beam (MABEL over the orchard), its deeper strategies add connections, not accuracy;
    /// without a sun, the receiver sub-path then stops at that surface.
    First,
    /// Chosen between the two by a pilot for bdpt (`pipeline::simulate`); forward and
    /// backward have one sub-path and take it as `full`.
    #[default]
    Auto,
}

/// How multiple importance sampling weighs the strategies that can make a path.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum MisHeuristic {
    #[default]
    Power,
    Balance,
}

/// Where a ray sample's first dimensions come from (the light's start, the aperture point,
/// the receiver's direction); every later dimension is independent either way.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum Sampler {
    /// Independent uniform draws from the ray's random stream.
    #[default]
    Independent,
    /// Owen-scrambled Sobol' pairs indexed by the ray's index in its pulse (`rng::Sobol2`):
    /// few rays cover the footprint, the aperture and the field of view evenly.
    Sobol,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Simulation {
    #[serde(default)]
    pub method: Method,
    #[serde(default = "default_rays")]
    pub rays_per_pulse: u64,
    /// The highest order of scattering traced, or `auto`: read it through
    /// [`MaxOrder::cap`].
    #[serde(default = "default_max_order")]
    pub max_order: MaxOrder,
    #[serde(default)]
    pub mis: MisHeuristic,
    #[serde(default)]
    pub sampler: Sampler,
    #[serde(default)]
    pub receiver_depth: ReceiverDepth,
}

impl Default for Simulation {
    fn default() -> Self {
        Simulation {
            method: Method::default(),
            rays_per_pulse: default_rays(),
            max_order: default_max_order(),
            mis: MisHeuristic::default(),
            sampler: Sampler::default(),
            receiver_depth: ReceiverDepth::default(),
        }
    }
}

fn default_rays() -> u64 {
    10_000
}
fn default_max_order() -> MaxOrder {
    MaxOrder::Order(MaxOrder::AUTO_CAP)
}

/// `simulation.max_order` as written: a number, or `auto`, which the pilot resolves into the
/// order past which the received energy's tail is below a fraction of a pulse's standard
/// error (`pipeline::simulate::choose_max_order`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaxOrder {
    Order(u32),
    Auto,
}

impl MaxOrder {
    /// The order `auto`'s pilot traces to, and the default.
    pub const AUTO_CAP: u32 = 100;

    /// The highest order traced: `auto` before its pilot is [`MaxOrder::AUTO_CAP`].
    pub fn cap(self) -> u32 {
        match self {
            MaxOrder::Order(n) => n,
            MaxOrder::Auto => MaxOrder::AUTO_CAP,
        }
    }
}

impl std::fmt::Display for MaxOrder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MaxOrder::Order(n) => write!(f, "{n}"),
            MaxOrder::Auto => f.write_str("auto"),
        }
    }
}

impl Serialize for MaxOrder {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            MaxOrder::Order(n) => s.serialize_u32(*n),
            MaxOrder::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for MaxOrder {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Number(u64),
            Word(String),
        }
        match Raw::deserialize(d) {
            Ok(Raw::Number(n)) => Ok(MaxOrder::Order(u32::try_from(n).unwrap_or(u32::MAX))),
            Ok(Raw::Word(w)) if w == "auto" => Ok(MaxOrder::Auto),
            _ => Err(serde::de::Error::custom(
                "expected a whole number of scattering orders (1 to 100000) or auto",
            )),
        }
    }
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Products {
    #[serde(default = "yes")]
    pub waveforms: bool,
    #[serde(default)]
    pub points: bool,
    #[serde(default)]
    pub photons: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dsm: Option<Dsm>,
    #[serde(default)]
    pub points_format: PointsFormat,
}

/// The discrete returns' file: `points.las`, or `points.laz` (LAZ, the same points).
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum PointsFormat {
    #[default]
    Las,
    Laz,
}

impl Campaign {
    /// The products the run makes: `products:` as given, else the kind's defaults (the
    /// points and a 2 m DSM of a discrete-return instrument, the photons of a photon-counting
    /// one; the waveforms always).
    pub fn products(&self) -> Products {
        self.products.clone().unwrap_or_else(|| {
            let kind = self.instrument.kind;
            let discrete = kind == InstrumentKind::DiscreteReturn;
            Products {
                waveforms: true,
                points: discrete,
                photons: kind == InstrumentKind::PhotonCounting,
                dsm: discrete.then_some(Dsm {
                    resolution_m: default_dsm_resolution(),
                }),
                points_format: PointsFormat::Las,
            }
        })
    }

    /// The campaign with the defaults the run applies written out, where leaving them out
    /// would hide them from a reader of `campaign.resolved.yaml`: the products, the GPS start,
    /// the receiver's offset, the false-alarm rate, and the scanner's duty (rotating polygon)
    /// or prism phases (Risley). The run itself reads the same values either way.
    ///
    /// Only defaults that change nothing when written out: a `mount:` or a `beams:` list the
    /// campaign left out stays out (a mount, even of zeros, turns the beam through the body's
    /// axes, with other round-off), their keys are filled where they stand.
    pub fn with_defaults(&self) -> Campaign {
        let mut c = self.clone();
        c.products = Some(self.products());
        let p = &mut c.platform;
        if p.trajectory.is_none() {
            // a trajectory's file gives the times, and refuses the key
            p.gps_start_s.get_or_insert(0.0);
        }
        match p.kind {
            PlatformKind::Track | PlatformKind::Tls => {
                p.prf_hz.get_or_insert(DEFAULT_PRF_HZ);
            }
            PlatformKind::Spaceborne => {
                p.off_nadir_deg.get_or_insert(0.0);
                for b in p.beams.iter_mut().flatten() {
                    b.relative_energy.get_or_insert(1.0);
                }
            }
            _ => {}
        }
        if let Some(m) = &mut p.mount {
            m.offset_m.get_or_insert([0.0; 3]);
            m.boresight_deg.get_or_insert([0.0; 3]);
        }
        if let Some(e) = &mut p.errors {
            e.position_correlation_s.get_or_insert(0.0);
            e.attitude_correlation_s.get_or_insert(0.0);
        }
        if let Some(scan) = &mut p.scanner {
            match scan.pattern {
                ScanPattern::RotatingPolygon => {
                    scan.duty.get_or_insert(1.0);
                }
                ScanPattern::Risley => {
                    scan.phase_deg.get_or_insert([0.0; 2]);
                }
                ScanPattern::Multibeam => {
                    scan.head_tilt_deg.get_or_insert(0.0);
                }
                _ => {}
            }
        }
        let i = &mut c.instrument;
        i.receiver_offset_m.get_or_insert([0.0; 3]);
        i.false_alarm_rate_per_pulse = Some(self.instrument.false_alarm_rate());
        // the detector's: a photon's chance to count, and counts without one
        i.quantum_efficiency.get_or_insert(1.0);
        i.dark_count_hz.get_or_insert(0.0);
        if i.kind == InstrumentKind::PhotonCounting {
            i.dead_time_ns.get_or_insert(0.0);
        }
        if let Some(d) = &mut i.digitiser {
            d.saturation = Some(d.saturation());
        }
        if let Some(s) = &mut c.sun {
            s.share.get_or_insert(SunShare::Fraction(1.0));
            if s.selection() == SunSelection::Fixed {
                s.selection_probability.get_or_insert(0.5);
            }
        }
        c
    }

    /// The pulse energy of beam `line`, J: the instrument's, times the beam's
    /// `relative_energy`.
    pub fn pulse_energy_j(&self, line: u32) -> f64 {
        let beam = self
            .platform
            .beams
            .as_ref()
            .and_then(|b| b.get(line as usize));
        self.instrument.pulse_energy_j * beam.and_then(|b| b.relative_energy).unwrap_or(1.0)
    }

    /// What is valid but likely not what the user wants, one sentence each, for `check` and
    /// the run log.
    pub fn warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.sun.is_some() && self.simulation.method == Method::Forward {
            out.push(
                "with simulation.method forward the sun is found only where sun-lit points \
                 fall in the narrow field of view, so its background converges very slowly \
                 (often 0 at tens of rays per pulse); bdpt or backward estimate it through \
                 the receiver's paths"
                    .to_string(),
            );
        }
        let i = &self.instrument;
        if i.kind == InstrumentKind::PhotonCounting
            && (i.noise.is_some() || i.digitiser.is_some() || i.detector_response_fwhm_ns.is_some())
        {
            out.push(
                "instrument.noise, detector_response_fwhm_ns and digitiser model an analogue \
                 detector and change nothing for a photon_counting instrument, whose events \
                 are already Poisson counts with dead time"
                    .to_string(),
            );
        }
        let missions = i.kind == InstrumentKind::Waveform || self.products().photons;
        if let Some(off) = self.frame.as_ref().and_then(Frame::degrees_off) {
            if missions {
                out.push(off);
            }
        }
        out
    }

    /// The discrete returns' file format (`products.points_format`, LAS by default).
    pub fn points_format(&self) -> PointsFormat {
        self.products
            .as_ref()
            .map_or(PointsFormat::Las, |p| p.points_format)
    }
}

impl PointsFormat {
    pub fn file_name(self) -> &'static str {
        match self {
            PointsFormat::Las => "points.las",
            PointsFormat::Laz => "points.laz",
        }
    }
}

fn yes() -> bool {
    true
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Dsm {
    #[serde(default = "default_dsm_resolution")]
    pub resolution_m: f64,
}

fn default_dsm_resolution() -> f64 {
    2.0
}

/// A campaign with the file it came from, validated.
#[derive(Clone, Debug)]
pub struct Loaded {
    pub campaign: Campaign,
    pub doc: Doc,
    pub scene_path: PathBuf,
    /// Why the campaign's `simulation.method` is what it is, when `auto` chose it.
    pub method_note: Option<String>,
}

impl Loaded {
    /// A parsed campaign and its file, once its scene file is found. The campaign's own keys
    /// are checked by [`Campaign::validate`], its platform by `plan::validate` (which needs
    /// the planners' geometry): `plan::read_campaign` does all three.
    pub fn new(doc: Doc, campaign: Campaign) -> Result<Loaded> {
        let scene_path = doc.resolve(&campaign.scene);
        if !scene_path.is_file() {
            return Err(doc.error(
                "scene",
                format!(
                    "scene file {} {}",
                    scene_path.display(),
                    crate::error::not_a_file(&scene_path)
                ),
            ));
        }
        Ok(Loaded {
            campaign,
            doc,
            scene_path,
            method_note: None,
        })
    }

    /// The campaign with every default filled in and its scene as the campaign file names it
    /// (relative to that file): the same text from whatever folder the campaign is run. Less
    /// its `products:`, which neither the plan nor the simulation reads: a campaign edited
    /// there alone keeps its waveforms on `--resume`.
    pub fn campaign_yaml_but_products(&self) -> String {
        let mut c = self.campaign.with_defaults();
        c.products = None;
        serde_yaml::to_string(&c).expect("a campaign always serialises")
    }

    /// The products the run makes ([`Campaign::products`]), as YAML.
    pub fn products_yaml(&self) -> String {
        serde_yaml::to_string(&self.campaign.products()).expect("products always serialise")
    }

    pub fn resolved_yaml(&self) -> String {
        // absolute: the file is read from the run folder, where a path relative to the
        // working folder the run started in would name nothing
        let absolute = |p: &std::path::Path| {
            std::path::absolute(p)
                .unwrap_or_else(|_| p.to_path_buf())
                .display()
                .to_string()
        };
        let mut c = self.campaign.with_defaults();
        c.scene = absolute(&self.scene_path);
        if let Some(t) = &mut c.platform.trajectory {
            if let Some(r) = &t.resolved {
                t.file = absolute(r);
            }
        }
        let yaml = serde_yaml::to_string(&c).expect("a campaign always serialises");
        match &self.method_note {
            Some(note) => format!("# {note}\n{yaml}"),
            None => yaml,
        }
    }
}

/// Checks that a number is finite and within a range, with a located error otherwise (the
/// campaign's and the platform planner's checks alike).
pub(crate) struct Check<'a> {
    pub doc: &'a Doc,
}

/// A number as a message shows it: 1e300 as 1e300, not as its 301 digits.
pub(crate) fn shown(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e7).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

impl Check<'_> {
    pub(crate) fn finite(&self, key: &str, v: f64) -> Result<()> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(self
                .doc
                .error(key, format!("must be a finite number, found {}", shown(v))))
        }
    }
    pub(crate) fn positive(&self, key: &str, v: f64) -> Result<()> {
        self.finite(key, v)?;
        if v > 0.0 {
            Ok(())
        } else {
            Err(self
                .doc
                .error(key, format!("must be positive, found {}", shown(v))))
        }
    }
    pub(crate) fn non_negative(&self, key: &str, v: f64) -> Result<()> {
        self.finite(key, v)?;
        if v >= 0.0 {
            Ok(())
        } else {
            Err(self
                .doc
                .error(key, format!("must not be negative, found {}", shown(v))))
        }
    }
    pub(crate) fn within(&self, key: &str, v: f64, lo: f64, hi: f64, what: &str) -> Result<()> {
        self.finite(key, v)?;
        if v >= lo && v <= hi {
            Ok(())
        } else {
            Err(self
                .doc
                .error(key, format!("must be {what}, found {}", shown(v))))
        }
    }
    pub(crate) fn opt_positive(&self, key: &str, v: Option<f64>) -> Result<()> {
        v.map_or(Ok(()), |v| self.positive(key, v))
    }
    pub(crate) fn opt_non_negative(&self, key: &str, v: Option<f64>) -> Result<()> {
        v.map_or(Ok(()), |v| self.non_negative(key, v))
    }
    /// Strictly between `lo` and `hi` degrees.
    pub(crate) fn open_deg(&self, key: &str, v: f64, lo: f64, hi: f64) -> Result<()> {
        self.finite(key, v)?;
        if v > lo && v < hi {
            Ok(())
        } else {
            Err(self.doc.error(
                key,
                format!(
                    "must lie strictly between {lo} and {hi} degrees, found {}",
                    shown(v)
                ),
            ))
        }
    }
    pub(crate) fn vec_finite(&self, key: &str, v: &[f64]) -> Result<()> {
        v.iter().try_for_each(|x| self.finite(key, *x))
    }
    /// Coordinates in metres within ±[`MAX_PLATFORM_COORDINATE_M`] (a position past it
    /// made ranges and times of infinity).
    pub(crate) fn coordinates(&self, key: &str, v: &[f64]) -> Result<()> {
        v.iter().try_for_each(|x| {
            self.within(
                key,
                *x,
                -MAX_PLATFORM_COORDINATE_M,
                MAX_PLATFORM_COORDINATE_M,
                "a coordinate in metres within 100,000 km",
            )
        })
    }
}

/// Pulse rate used for GPS times by `track` and `tls` platforms that give no `prf_hz`.
pub const DEFAULT_PRF_HZ: f64 = 1000.0;

/// How far a platform's positions may lie from the scene's origin, m: 100,000 km, past the
/// geostationary orbit, as `frame.origin`.
pub const MAX_PLATFORM_COORDINATE_M: f64 = 1e8;

impl Campaign {
    /// Checks every campaign key a value can make wrong, in the file's order. A flat list of
    /// independent checks, each naming its key: long because the campaign has many keys.
    pub fn validate(&self, doc: &Doc) -> Result<()> {
        let c = Check { doc };
        let name = self.name.trim();
        // YAML's null (`~`, `null`), which serde reads as that text
        if name.is_empty()
            || name == "."
            || name == ".."
            || ["~", "null", "Null", "NULL"].contains(&name)
            || self.name.contains(['/', '\\'])
            || self.name.chars().any(char::is_control)
        {
            return Err(doc.error(
                "name",
                "must be a non-empty name without slashes or control characters (line breaks, \
                 tabs), other than . and .. and YAML's null (~, null): it names the run folder",
            ));
        }
        // a folder's name: file systems hold 255 bytes in one
        if self.name.len() > 255 {
            return Err(doc.error(
                "name",
                format!(
                    "is {} bytes long: it names the run folder, which holds 255 at most",
                    self.name.len()
                ),
            ));
        }
        for (k, &w) in self.wavelength_nm.all().iter().enumerate() {
            let key = if self.wavelength_nm.several() {
                format!("wavelength_nm[{k}]")
            } else {
                "wavelength_nm".to_string()
            };
            c.within(
                &key,
                w,
                100.0,
                20_000.0,
                "a wavelength in nm between 100 and 20000",
            )?;
        }
        let i = &self.instrument;
        c.positive("instrument.pulse_energy_j", i.pulse_energy_j)?;
        // bounds far beyond any instrument, where photon counts and times stay finite
        c.within(
            "instrument.pulse_energy_j",
            i.pulse_energy_j,
            0.0,
            1e3,
            "a pulse energy in J above 0 and at most 1000",
        )?;
        c.non_negative("instrument.pulse_fwhm_ns", i.pulse_fwhm_ns)?;
        c.within(
            "instrument.footprint_half_angle_mrad",
            i.footprint_half_angle_mrad,
            1e-9,
            1500.0,
            "an angle in mrad above 0 and below 1500 (86°)",
        )?;
        c.within(
            "instrument.fov_half_angle_mrad",
            i.fov_half_angle_mrad,
            1e-9,
            1500.0,
            "an angle in mrad above 0 and below 1500 (86°)",
        )?;
        if !(i.edge_energy_fraction > 0.0 && i.edge_energy_fraction < 1.0) {
            return Err(doc.error(
                "instrument.edge_energy_fraction",
                format!(
                    "must lie strictly between 0 and 1 (default e^-2 = 0.1353), found {}",
                    i.edge_energy_fraction
                ),
            ));
        }
        c.positive("instrument.receiver_area_m2", i.receiver_area_m2)?;
        c.positive("instrument.bin_ns", i.bin_ns)?;
        c.within(
            "instrument.bin_ns",
            i.bin_ns,
            0.0,
            1e6,
            "a bin width in ns above 0 and at most 10^6 (1 ms)",
        )?;
        if i.max_returns == 0 {
            return Err(doc.error(
                "instrument.max_returns",
                "must be at least 1 (returns kept per pulse; default 4)",
            ));
        }
        c.opt_positive("instrument.bandwidth_nm", i.bandwidth_nm)?;
        c.non_negative(
            "instrument.detection_threshold_photons",
            i.detection_threshold_photons,
        )?;
        if let Some(a) = i.false_alarm_rate_per_pulse {
            c.finite("instrument.false_alarm_rate", a)?;
            if !(a > 0.0 && a < 1.0) {
                return Err(doc.error(
                    "instrument.false_alarm_rate",
                    format!(
                        "must lie strictly between 0 and 1 (the chance of a false return in a \
                         gate of noise alone; default 0.001), found {}",
                        shown(a)
                    ),
                ));
            }
        }
        if let Some(q) = i.quantum_efficiency {
            c.within(
                "instrument.quantum_efficiency",
                q,
                0.0,
                1.0,
                "between 0 and 1",
            )?;
        }
        c.opt_non_negative("instrument.dead_time_ns", i.dead_time_ns)?;
        c.opt_non_negative("instrument.dark_count_hz", i.dark_count_hz)?;
        if let Some(d) = i.dark_count_hz {
            c.within(
                "instrument.dark_count_hz",
                d,
                0.0,
                1e10,
                "a rate in Hz from 0 to 10^10 (a detector's dark counts are far fewer)",
            )?;
        }
        if let Some(n) = &i.noise {
            // the record is kept in f32: a noise of 1e39 photons filled it with infinities
            c.within(
                "instrument.noise.electronic_sd_photons",
                n.electronic_sd_photons,
                0.0,
                1e12,
                "photons from 0 to 10^12 (a detector's noise is a few photons)",
            )?;
        }
        if let Some(v) = i.detector_response_fwhm_ns {
            // its kernel and the matched filter span it in bins: a response of 10^9 ns asked
            // for 20 GB; a detector's is nanoseconds
            c.within(
                "instrument.detector_response_fwhm_ns",
                v,
                0.0,
                1e4,
                "nanoseconds from 0 to 10^4 (a detector responds within nanoseconds)",
            )?;
        }
        if let Some(o) = i.receiver_offset_m {
            for (k, v) in o.iter().enumerate() {
                c.within(
                    &format!("instrument.receiver_offset_m[{k}]"),
                    *v,
                    -1000.0,
                    1000.0,
                    "metres between -1000 and 1000",
                )?;
            }
        }
        if let Some(d) = &i.digitiser {
            c.positive("instrument.digitiser.gain", d.gain)?;
            c.finite("instrument.digitiser.offset", d.offset)?;
            if !(1..=24).contains(&d.bits) {
                return Err(doc.error(
                    "instrument.digitiser.bits",
                    format!("must be between 1 and 24, found {}", d.bits),
                ));
            }
            let full = ((1u64 << d.bits) - 1) as f64;
            if let Some(s) = d.saturation {
                c.within(
                    "instrument.digitiser.saturation",
                    s,
                    0.0,
                    full,
                    &format!("counts between 0 and 2^bits - 1 = {full}"),
                )?;
            }
        }
        if let Some(g) = &i.range_gate {
            c.finite("instrument.range_gate.start_ns", g.start_ns)?;
            if g.bins == 0 || g.bins > 10_000_000 {
                return Err(doc.error(
                    "instrument.range_gate.bins",
                    "must be between 1 and 10000000",
                ));
            }
            // GEDI's rx_sample_count, which waveforms_l1b.h5 keeps, is 16 bits
            if i.kind == InstrumentKind::Waveform && g.bins > u32::from(u16::MAX) {
                return Err(doc.error(
                    "instrument.range_gate.bins",
                    format!(
                        "a waveform instrument's gate holds at most 65535 bins (the 16 bits of \
                         rx_sample_count in waveforms_l1b.h5, as GEDI's), found {}: use wider \
                         bins (instrument.bin_ns)",
                        g.bins
                    ),
                ));
            }
        }
        if let Some(a) = &self.atmosphere {
            for (k, layer) in a.layers.iter().enumerate() {
                c.positive(
                    &format!("atmosphere.layers[{k}].scale_height_m"),
                    layer.scale_height_m,
                )?;
                let key = format!("atmosphere.layers[{k}].optical_depth");
                for &w in self.wavelength_nm.all() {
                    let tau = layer
                        .optical_depth
                        .at(w)
                        .map_err(|why| doc.error(&key, why))?;
                    c.non_negative(&key, tau)?;
                }
            }
        }
        if let Some(s) = &self.sun {
            if i.bandwidth_nm.is_none() {
                return Err(doc.error(
                    "instrument",
                    "the sun needs `instrument.bandwidth_nm`, the receiver's band, for the solar signal",
                ));
            }
            if let Some(q) = s.selection_probability {
                if s.selection() != SunSelection::Fixed {
                    return Err(doc.error(
                        "sun.selection_probability",
                        "applies to `selection: fixed` only: write that, or remove the probability to select by power or automatically",
                    ));
                }
                if !(q > 0.0 && q < 1.0) {
                    return Err(doc.error(
                        "sun.selection_probability",
                        format!("must lie strictly between 0 and 1, found {}", shown(q)),
                    ));
                }
            }
            if let Some(SunShare::Fraction(f)) = s.share {
                if !(f > 0.0 && f <= 1.0) {
                    return Err(doc.error(
                        "sun.share",
                        format!(
                            "must lie in (0, 1], the share of samples that trace the sun, found {}",
                            shown(f)
                        ),
                    ));
                }
            }
            c.within(
                "sun.zenith_deg",
                s.zenith_deg,
                -90.0,
                90.0,
                "between -90 and 90",
            )?;
            c.finite("sun.azimuth_deg", s.azimuth_deg)?;
            c.non_negative("sun.irradiance_w_m2_um", s.irradiance_w_m2_um)?;
            c.within(
                "sun.irradiance_w_m2_um",
                s.irradiance_w_m2_um,
                0.0,
                1e8,
                "an irradiance in W m⁻² µm⁻¹ from 0 to 10^8 (the sun gives about 2000 at most)",
            )?;
        }
        let s = &self.simulation;
        if s.rays_per_pulse == 0 || s.rays_per_pulse > u64::from(u32::MAX) {
            // the waveforms' `rays` column is a u32
            return Err(doc.error(
                "simulation.rays_per_pulse",
                format!("must be from 1 to {}, found {}", u32::MAX, s.rays_per_pulse),
            ));
        }
        if s.max_order.cap() == 0 || s.max_order.cap() > 100_000 {
            return Err(doc.error("simulation.max_order", "must be between 1 and 100000"));
        }
        if let Some(p) = &self.products {
            if let Some(d) = &p.dsm {
                c.positive("products.dsm.resolution_m", d.resolution_m)?;
                c.within(
                    "products.dsm.resolution_m",
                    d.resolution_m,
                    0.0,
                    1e5,
                    "a cell size in metres up to 100 km",
                )?;
            }
        }
        if let Some(f) = &self.frame {
            f.resolve().map_err(|e| doc.error("frame.crs", e))?;
            for (k, v) in f.origin.iter().enumerate() {
                c.within(
                    &format!("frame.origin[{k}]"),
                    *v,
                    -1e8,
                    1e8,
                    "a coordinate in metres within 100,000 km",
                )?;
            }
            // the mission files (a waveform instrument's GEDI files, photons' ATL03) give
            // degrees, which some CRSs cannot give in this build: said before any pulse
            let missions =
                self.instrument.kind == InstrumentKind::Waveform || self.products().photons;
            if let Some(why) = f.degrees_unavailable().filter(|_| missions) {
                return Err(doc.error("frame.crs", why));
            }
        }
        Ok(())
    }
}

/// Error for a bad campaign path given on the command line.
pub fn missing_campaign(path: &Path) -> Error {
    Error::file(
        path,
        format!("campaign file {}", crate::error::not_a_file(path)),
    )
}
