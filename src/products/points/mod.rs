//! Discrete-return points from a pulse's decomposed waveform.

pub mod accuracy;
pub mod las;
pub mod spill;
pub mod strips;

use crate::plan::Pulse;
use crate::products::returns::Component;
use crate::waveform::Waveform;
use crate::C;

/// LAS 1.4 return numbers are 4 bits.
pub const MAX_LAS_RETURNS: usize = 15;
/// Intensity of a return whose energy equals that of a white Lambertian target at nadir at
/// the reference range (see [`PointConfig::reference_range_m`]).
pub const INTENSITY_AT_WHITE_REFERENCE: f64 = 10_000.0;

/// One discrete return, with everything points.las stores.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    /// Emission time of the pulse, s.
    pub gps_time: f64,
    pub intensity: u16,
    /// 1-based, by time.
    pub return_number: u8,
    pub number_of_returns: u8,
    pub scan_angle_deg: f32,
    /// Flight line + 1 (0 means "no source" in LAS).
    pub point_source_id: u16,
    /// ASPRS code: 2 ground, 5 vegetation, 6 building, 1 unclassified.
    pub classification: u8,
    pub apparent_reflectance: f32,
    pub pulse_id: u64,
    /// The band of the waveform it came from, in a run of several bands.
    pub wavelength_nm: Option<f32>,
    /// LAS's scan direction flag (the look angle growing: left to right) and edge of flight
    /// line (the last pulse of a scan line), from [`crate::plan::Plan::scan_flags`].
    pub left_to_right: bool,
    pub edge_of_line: bool,
}

/// Sensor constants the points need.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointConfig {
    /// Q_e, J.
    pub emitted_energy_j: f64,
    /// hν, J.
    pub photon_energy_j: f64,
    /// A_tel, m².
    pub telescope_area_m2: f64,
    /// Range at which a white (ρ = 1) Lambertian target at nadir gets intensity 10 000;
    /// the platform's nominal range (altitude for nadir sensors) keeps intensities of one
    /// campaign in the u16 range whatever its energy, aperture and altitude.
    pub reference_range_m: f64,
    /// The LAS point source id of `line` 0: 1 for flight lines and beams (ASPRS's custom),
    /// 0 for TLS stations (the station's index, as the campaign's `positions` count them).
    pub first_source_id: u32,
}

impl PointConfig {
    /// Intensity = min(65535, round(10 000 · (Q_i / Q_e) · π R_ref² / A_tel)): the return's
    /// energy, scaled so that 10 000 is a white Lambertian plate at the reference range.
    /// Unlike ρ_i it is not range-corrected, as LAS intensity is not.
    pub fn intensity(&self, energy_ratio: f64) -> u16 {
        let scale =
            INTENSITY_AT_WHITE_REFERENCE * std::f64::consts::PI * self.reference_range_m.powi(2)
                / self.telescope_area_m2;
        let v = (energy_ratio * scale).round();
        if v.is_finite() {
            v.clamp(0.0, 65535.0) as u16
        } else {
            0
        }
    }
}

/// Range of a component, m: R = c t / 2 with t = t0 + centre·Δt (f64 throughout: at
/// 419 km a float nanosecond would be metres off).
pub fn range_m(t0_ns: f64, bin_ns: f64, centre_bin: f64) -> f64 {
    let t_ns = t0_ns + centre_bin * bin_ns;
    C * t_ns * 1e-9 / 2.0
}

/// The points of one pulse, one per component, in time order. `classes[i]` is the LAS class
/// of component i (the surface class that contributed most energy to it); missing entries
/// are 1 (unclassified). Components with a non-positive or non-finite range are skipped, and
/// at most 15 returns are kept, the LAS limit.
pub fn points(
    pulse: &Pulse,
    waveform: &Waveform,
    components: &[Component],
    classes: &[u8],
    config: &PointConfig,
) -> Vec<Point> {
    points_on_axis(
        pulse,
        waveform.t0_ns,
        waveform.bin_ns as f64,
        components,
        classes,
        config,
    )
}

/// [`points`] with the waveform's time axis given directly.
pub fn points_on_axis(
    pulse: &Pulse,
    t0_ns: f64,
    bin_ns: f64,
    components: &[Component],
    classes: &[u8],
    config: &PointConfig,
) -> Vec<Point> {
    let mut order: Vec<(usize, f64)> = components
        .iter()
        .enumerate()
        .map(|(i, c)| (i, range_m(t0_ns, bin_ns, c.centre_bin)))
        .filter(|(i, r)| r.is_finite() && *r > 0.0 && components[*i].area_photons.is_finite())
        .collect();
    order.sort_by(|a, b| a.1.total_cmp(&b.1));
    order.truncate(MAX_LAS_RETURNS);
    let n = order.len() as u8;
    order
        .iter()
        .enumerate()
        .map(|(k, &(i, r))| {
            let c = &components[i];
            // georeferenced from the recorded pose, as a survey is
            let p = pulse.rec_origin() + pulse.rec_direction() * r;
            let energy_ratio = c.area_photons * config.photon_energy_j / config.emitted_energy_j;
            // ρ_i = (π / ΔΩ_i)(Q_i / Q_e), ΔΩ_i = A_tel / R².
            let rho = std::f64::consts::PI * r * r / config.telescope_area_m2 * energy_ratio;
            Point {
                x: p.x,
                y: p.y,
                z: p.z,
                gps_time: pulse.gps_time_s,
                intensity: config.intensity(energy_ratio),
                return_number: k as u8 + 1,
                number_of_returns: n,
                scan_angle_deg: pulse.scan_angle_deg,
                point_source_id: pulse
                    .line
                    .saturating_add(config.first_source_id)
                    .min(u16::MAX as u32) as u16,
                classification: classes.get(i).copied().unwrap_or(1),
                apparent_reflectance: rho as f32,
                pulse_id: pulse.id,
                wavelength_nm: None,
                left_to_right: false,
                edge_of_line: false,
            }
        })
        .collect()
}

/// Points as an Arrow table, one row each: x, y, z, gps_time (f64), return_number,
/// number_of_returns, classification (u8), intensity (u16), apparent_reflectance (f32),
/// pulse_id (u64), scan_angle_deg (f32), point_source_id (u16), and wavelength_nm (f32)
/// when any point has a band (a run of several).
pub fn points_table(points: &[Point]) -> arrow_array::RecordBatch {
    use arrow_array::{ArrayRef, Float32Array, Float64Array, UInt16Array, UInt64Array, UInt8Array};
    use std::sync::Arc;
    let f64s = |f: fn(&Point) -> f64| -> ArrayRef {
        Arc::new(Float64Array::from_iter_values(points.iter().map(f)))
    };
    let u8s = |f: fn(&Point) -> u8| -> ArrayRef {
        Arc::new(UInt8Array::from_iter_values(points.iter().map(f)))
    };
    let u16s = |f: fn(&Point) -> u16| -> ArrayRef {
        Arc::new(UInt16Array::from_iter_values(points.iter().map(f)))
    };
    let f32s = |f: fn(&Point) -> f32| -> ArrayRef {
        Arc::new(Float32Array::from_iter_values(points.iter().map(f)))
    };
    let mut columns = vec![
        ("x", f64s(|p| p.x)),
        ("y", f64s(|p| p.y)),
        ("z", f64s(|p| p.z)),
        ("gps_time", f64s(|p| p.gps_time)),
        ("return_number", u8s(|p| p.return_number)),
        ("number_of_returns", u8s(|p| p.number_of_returns)),
        ("classification", u8s(|p| p.classification)),
        ("intensity", u16s(|p| p.intensity)),
        ("apparent_reflectance", f32s(|p| p.apparent_reflectance)),
        (
            "pulse_id",
            Arc::new(UInt64Array::from_iter_values(
                points.iter().map(|p| p.pulse_id),
            )) as ArrayRef,
        ),
        ("scan_angle_deg", f32s(|p| p.scan_angle_deg)),
        ("point_source_id", u16s(|p| p.point_source_id)),
    ];
    if points.iter().any(|p| p.wavelength_nm.is_some()) {
        columns.push((
            "wavelength_nm",
            Arc::new(Float32Array::from_iter(
                points.iter().map(|p| p.wavelength_nm),
            )),
        ));
    }
    crate::parquet_io::batch(columns)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    const T0_NS: f64 = 1500.0;
    const BIN_NS: f64 = 0.5;

    #[test]
    fn lambertian_plane_gives_its_reflectance_and_range() {
        let h = 250.0;
        let cfg = PointConfig {
            emitted_energy_j: 1e-6,
            photon_energy_j: crate::photon_energy_j(1064.0),
            telescope_area_m2: 0.1,
            first_source_id: 1,
            reference_range_m: h,
        };
        let pulse = Pulse {
            id: 7,
            gps_time_s: 12.5,
            origin: DVec3::new(10.0, 20.0, h + 5.0),
            direction: DVec3::new(0.0, 0.0, -1.0),
            scan_angle_deg: -3.5,
            line: 2,
            along: DVec3::X,
            up: DVec3::Z,
            recorded: None,
        };
        // A target at range h: t = 2h/c; ρ = 0.4 Lambertian returns Q_e ρ A / (π h²).
        let centre = (2.0 * h / C * 1e9 - T0_NS) / BIN_NS;
        let q = cfg.emitted_energy_j * 0.4 * cfg.telescope_area_m2 / (std::f64::consts::PI * h * h);
        let ground = Component {
            centre_bin: centre,
            sigma_bins: 2.0,
            area_photons: q / cfg.photon_energy_j,
            amplitude: 0.0,
            one_surface: false,
        };
        let canopy = Component {
            centre_bin: centre - 40.0,
            ..ground
        };
        let p = points_on_axis(&pulse, T0_NS, BIN_NS, &[ground, canopy], &[2], &cfg);
        assert_eq!(p.len(), 2);
        let (first, last) = (&p[0], &p[1]);
        assert_eq!((first.return_number, last.return_number), (1, 2));
        assert_eq!((first.number_of_returns, last.number_of_returns), (2, 2));
        assert_eq!((first.classification, last.classification), (1, 2));
        assert!((last.z - 5.0).abs() < 1e-6 && last.x == 10.0 && last.y == 20.0);
        assert!((first.z - (5.0 + 40.0 * 0.5e-9 * C / 2.0)).abs() < 1e-6);
        assert!((last.apparent_reflectance - 0.4).abs() < 1e-6);
        assert_eq!(last.intensity, 4000);
        assert_eq!(
            (last.point_source_id, last.pulse_id, last.gps_time),
            (3, 7, 12.5)
        );
        assert_eq!(last.scan_angle_deg, -3.5);
    }

    #[test]
    fn bad_components_are_skipped_and_intensity_clamps() {
        let cfg = PointConfig {
            emitted_energy_j: 1e-6,
            photon_energy_j: 1e-19,
            telescope_area_m2: 0.1,
            first_source_id: 1,
            reference_range_m: 250.0,
        };
        let pulse = Pulse {
            id: 0,
            gps_time_s: 0.0,
            origin: DVec3::ZERO,
            direction: DVec3::new(0.0, 0.0, -1.0),
            scan_angle_deg: 0.0,
            line: 0,
            along: DVec3::X,
            up: DVec3::Z,
            recorded: None,
        };
        let c = Component {
            centre_bin: f64::NAN,
            sigma_bins: 1.0,
            area_photons: 1.0,
            amplitude: 1.0,
            one_surface: false,
        };
        let bright = Component {
            centre_bin: 10.0,
            area_photons: 1e13,
            ..c
        };
        let p = points_on_axis(&pulse, T0_NS, BIN_NS, &[c, bright], &[], &cfg);
        assert_eq!(p.len(), 1);
        assert_eq!(
            (p[0].intensity, p[0].number_of_returns, p[0].classification),
            (65535, 1, 1)
        );
    }
}
