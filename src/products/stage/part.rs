//! What the products stage hands its writers: a part of waveforms, with the discrete returns
//! and photon events made of it once, and the two calls every writer answers.

use crate::campaign::Loaded;
use crate::error::Result;
use crate::plan::Plan;
use crate::products::photons::{count_photons, photon_rows, PhotonRow};
use crate::products::points::{points_on_axis, Point, PointConfig};
use crate::products::report::summary::ProductsSummary;
use crate::products::returns::{decompose, place_on_summits, Component, Decomposition, Receiver};
use crate::rng::SplitMix64;
use crate::scene::SurfaceClass;
use crate::sensor::pulse_sigma_s;
use crate::waveform::record::Recorder;
use crate::waveform::Waveform;
use rayon::prelude::*;
use std::borrow::Cow;

/// What a part's waveforms make once for every writer: its discrete returns and photon
/// events. Made apart from [`Part`] (which borrows it) so that a part's can be made while the
/// writers take the part before.
pub(super) struct Made {
    /// The discrete returns of every row, in pulse order then time (then band); empty when
    /// the campaign asks for no points.
    points: Vec<Point>,
    /// Those of the first band, with several bands (else `points` are).
    first_points: Option<Vec<Point>>,
    /// The photon events of every row; empty when the campaign asks for none.
    photons: Vec<PhotonRow>,
    /// Those of the first band, with several bands.
    first_photons: Option<Vec<PhotonRow>>,
}

impl Made {
    pub fn new(
        loaded: &Loaded,
        plan: &Plan,
        rows: &[Waveform],
        points: bool,
        photons: bool,
    ) -> Made {
        let first_nm = loaded.campaign.wavelength_nm.first();
        let several = loaded.campaign.wavelength_nm.several();
        let points = if points {
            discrete_returns(loaded, plan, rows)
        } else {
            Vec::new()
        };
        let first_points = several.then(|| {
            let of_first = |p: &&Point| p.wavelength_nm.is_none_or(|nm| nm == first_nm as f32);
            points.iter().filter(of_first).cloned().collect()
        });
        let photons = if photons {
            photon_events(loaded, plan, rows)
        } else {
            Vec::new()
        };
        let first_photons = several.then(|| {
            let of_first = |r: &&PhotonRow| r.wavelength_nm.is_none_or(|nm| nm == first_nm);
            photons.iter().filter(of_first).copied().collect()
        });
        Made {
            points,
            first_points,
            photons,
            first_photons,
        }
    }
}

/// One part of the waveforms, as every writer sees it.
pub(super) struct Part<'a> {
    /// The rows of the campaign's first band (every row with one band): the DSM, the mission
    /// files, the figures and the summaries are made of one band.
    pub first: Vec<&'a Waveform>,
    /// The discrete returns of every row, in pulse order then time (then band).
    pub points: &'a [Point],
    /// The photon events of every row.
    pub photons: &'a [PhotonRow],
    made: &'a Made,
}

/// A product made part by part: what it makes of each part, then its files finished.
pub(super) trait Writer {
    fn add(&mut self, part: &Part) -> Result<()>;
    /// Finishes the files, puts the product's figures in the summary, and returns the
    /// files' names (relative to the run folder), in the order the manifest lists them.
    fn finish(self: Box<Self>, summary: &mut ProductsSummary) -> Result<Vec<String>>;
}

impl<'a> Part<'a> {
    /// The part of `rows`, with what was made of them.
    pub fn new(loaded: &Loaded, rows: &'a [Waveform], made: &'a Made) -> Part<'a> {
        Part {
            first: rows.iter().filter(|w| first_band(loaded, w)).collect(),
            points: &made.points,
            photons: &made.photons,
            made,
        }
    }

    pub fn first_points(&self) -> &[Point] {
        self.made.first_points.as_deref().unwrap_or(self.points)
    }

    pub fn first_photons(&self) -> &[PhotonRow] {
        self.made.first_photons.as_deref().unwrap_or(self.photons)
    }
}

/// LAS class of a component: the surface class with the most impulse energy within two
/// sigmas of its centre.
fn class_of(w: &Waveform, centre: f64, sigma: f64) -> u8 {
    let lo = (centre - 2.0 * sigma).floor().max(0.0) as usize;
    let hi = ((centre + 2.0 * sigma).ceil() as usize).min(w.laser_photons.len());
    let mut best = (0.0f64, SurfaceClass::Other.las_code());
    for class in SurfaceClass::ALL {
        let code = class.las_code();
        let e = w.class_energy_sum(class.index(), lo, hi);
        if e > best.0 {
            best = (e, code);
        }
    }
    best.1
}

/// The decomposition of one waveform as the campaign asks for it: of the instrument's
/// record (noise, detector response, digitiser) when it has one, else of the mean photons.
/// The components as fitted (the figures draw them).
pub(super) fn components(loaded: &Loaded, w: &Waveform) -> Vec<Component> {
    decomposed(loaded, w).0
}

/// [`components`], with the samples they were fitted to and the return's sigma in bins.
///
/// A record is decomposed in photoelectrons, the detector's own units, where the laser's
/// shot noise is Poisson (variance = mean) and the electronic and background noise adds its
/// floor: the fit's likelihood, its test for an extra component and every significance test
/// then weigh the noise the record has. The components' areas are then given back in photons
/// at the detector (divided by the quantum efficiency q), as the mean waveform's are.
fn decomposed<'w>(loaded: &Loaded, w: &'w Waveform) -> (Vec<Component>, Cow<'w, [f32]>, f64) {
    let c = &loaded.campaign;
    let inst = &c.instrument;
    let hv = crate::photon_energy_j(band_of(loaded, w));
    let band = c.wavelength_nm.index_of(w.wavelength_nm);
    let recorder = Recorder::new(inst, SplitMix64::band_seed(c.seed, band));
    let recorded = recorder.changes_returns();
    // photons (photoelectrons for a record) per bin of the gate from energies over the span
    // of bins the light reached, as the waveform holds them (zero outside)
    let q = if recorded {
        recorder.quantum_efficiency
    } else {
        1.0
    };
    let photons_of = |energies: &[f32], v: &mut Vec<f32>| {
        v.clear();
        v.resize(w.laser_photons.len(), 0.0);
        let span = w.span_first_bin.min(v.len())..v.len();
        for (m, &e) in v[span].iter_mut().zip(energies) {
            *m = (q * e as f64 / hv) as f32;
        }
    };
    let (samples, sigma_s, receiver_noise) = if recorded {
        let pe = recorder.laser_photoelectrons(&recorder.record(w));
        (
            Cow::Owned(pe),
            recorder.return_sigma_s(pulse_sigma_s(inst)),
            recorder.noise_floor_photoelectrons(w),
        )
    } else {
        (
            Cow::Borrowed(w.laser_photons.as_slice()),
            pulse_sigma_s(inst),
            0.0,
        )
    };
    let sigma_bins = sigma_s / (inst.bin_ns * 1e-9);
    let receiver = Receiver {
        sigma_bins,
        footprint_edge_sigmas: Some(crate::sensor::footprint_edge_sigmas(inst)),
        noise_floor: receiver_noise,
        false_alarm_rate: recorder
            .electronic_sd
            .is_some()
            .then(|| inst.false_alarm_rate()),
    };
    // the two gates of photons in a thread's buffers, kept from waveform to waveform: a gate
    // of a few hundred bins is more than the allocator's per-thread cache holds, and two such
    // allocations a waveform were a measurable share of the stage
    let mut comps = GATES.with_borrow_mut(|(mc_se, leaves)| {
        photons_of(&w.impulse_energy_se_j, mc_se);
        photons_of(&w.class_energy_j[SurfaceClass::Vegetation.index()], leaves);
        decompose(
            &samples,
            mc_se,
            leaves,
            q * inst.detection_threshold_photons,
            inst.max_returns as usize,
            Decomposition::Gaussian,
            &receiver,
        )
    });
    for k in &mut comps {
        k.area_photons /= q;
        k.amplitude /= q;
    }
    (comps, samples, sigma_bins)
}

thread_local! {
    /// [`decomposed`]'s Monte Carlo errors and leaves' photons over the gate.
    static GATES: std::cell::RefCell<(Vec<f32>, Vec<f32>)> = std::cell::RefCell::default();
}

/// The wavelength of a waveform row, nm: its band's, or the campaign's.
fn band_of(loaded: &Loaded, w: &Waveform) -> f64 {
    w.wavelength_nm
        .unwrap_or(loaded.campaign.wavelength_nm.first())
}

/// Whether a waveform row is of the campaign's first band.
fn first_band(loaded: &Loaded, w: &Waveform) -> bool {
    w.wavelength_nm
        .is_none_or(|nm| nm == loaded.campaign.wavelength_nm.first())
}

/// Discrete returns of every pulse, in pulse order then time (then band).
fn discrete_returns(loaded: &Loaded, plan: &Plan, waveforms: &[Waveform]) -> Vec<Point> {
    let c = &loaded.campaign;
    let inst = &c.instrument;
    let reference_range = if plan.is_empty() {
        1.0
    } else {
        plan.pulse(0).origin.z.abs().max(1.0)
    };
    let by_pulse: Vec<Vec<Point>> = waveforms
        .par_iter()
        .map(|w| {
            let pulse = &plan.pulse(w.pulse_id);
            let config = PointConfig {
                // the pulse's own beam's energy (a weak beam's is a fraction of it)
                emitted_energy_j: c.pulse_energy_j(pulse.line),
                photon_energy_j: crate::photon_energy_j(band_of(loaded, w)),
                telescope_area_m2: inst.receiver_area_m2,
                reference_range_m: reference_range,
                first_source_id: u32::from(c.platform.kind != crate::campaign::PlatformKind::Tls),
            };
            // the points where a detector puts the returns: wide ones at their summits
            let (mut comps, photons, sigma_bins) = decomposed(loaded, w);
            place_on_summits(&mut comps, &photons, sigma_bins);
            let classes: Vec<u8> = comps
                .iter()
                .map(|k| class_of(w, k.centre_bin, k.sigma_bins))
                .collect();
            let mut points =
                points_on_axis(pulse, w.t0_ns, w.bin_ns as f64, &comps, &classes, &config);
            let (left_to_right, edge_of_line) = plan.scan_flags(pulse.id);
            let scan_angle_deg = plan.las_scan_angle(pulse);
            for p in &mut points {
                p.scan_angle_deg = scan_angle_deg;
                p.wavelength_nm = w.wavelength_nm.map(|nm| nm as f32);
                p.left_to_right = left_to_right;
                p.edge_of_line = edge_of_line;
            }
            points
        })
        .collect();
    by_pulse.into_iter().flatten().collect()
}

/// Photon events of every pulse (photon counting), deterministic per (seed, pulse).
fn photon_events(loaded: &Loaded, plan: &Plan, waveforms: &[Waveform]) -> Vec<PhotonRow> {
    let c = &loaded.campaign;
    let inst = &c.instrument;
    let by_pulse: Vec<Vec<PhotonRow>> = waveforms
        .par_iter()
        .map(|w| {
            let pulse = &plan.pulse(w.pulse_id);
            let events = count_photons(
                &w.laser_photons,
                w.solar_photons_per_bin as f64,
                w.bin_ns as f64 * 1e-9,
                inst.quantum_efficiency.unwrap_or(1.0),
                inst.dark_count_hz.unwrap_or(0.0),
                inst.dead_time_ns.unwrap_or(0.0) * 1e-9,
                SplitMix64::band_seed(c.seed, c.wavelength_nm.index_of(w.wavelength_nm)),
                w.pulse_id,
            );
            // from the first pulse of the pulse's own line: a spaceborne platform's beams
            // each count from their own first shot, not from the first beam's
            let first = plan.pulse(plan.line_start(w.pulse_id)).origin;
            let along = (pulse.origin - first).truncate().length();
            let mut rows = photon_rows(pulse, w.t0_ns, &events, along);
            for r in &mut rows {
                r.wavelength_nm = w.wavelength_nm;
            }
            rows
        })
        .collect();
    by_pulse.into_iter().flatten().collect()
}
