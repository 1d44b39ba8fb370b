//! `products.json`: what the products stage made, one typed record written by the stage and
//! read back by the report, `compare` and the bench.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ProductsSummary {
    pub pulses: usize,
    /// Discrete-return instruments.
    #[serde(flatten)]
    pub points: Option<PointsSummary>,
    /// Photon-counting instruments.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photons: Option<PhotonCounts>,
    /// Sums over the waveforms, for report.md (so it need not read every part again).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub waveform_totals: Option<WaveformTotals>,
    /// waveforms_l2a.h5 against its truth (waveform instruments).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub l2a: Option<L2aSummary>,
    /// Height differences between overlapping strips (several flight lines or stations).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub strips: Option<crate::products::points::strips::StripSummary>,
}

/// The L2A metrics against the truth under the footprints, over the shots of quality 1 with
/// a truth (none: null): RH98 above the lowest mode less the true canopy top above it, and
/// the lowest mode less the true ground.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct L2aSummary {
    pub shots: usize,
    pub quality_shots: usize,
    pub rh98_minus_top_mean_m: Option<f64>,
    pub rh98_minus_top_sd_m: Option<f64>,
    pub ground_minus_truth_mean_m: Option<f64>,
    pub ground_minus_truth_sd_m: Option<f64>,
}

/// Sums over a run's waveforms, in part and pulse order (so a report made from them or from
/// the parts themselves is the same to the last bit).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WaveformTotals {
    pub pulses: usize,
    pub rays: u64,
    /// Effective paths: paths per ray times rays, summed.
    pub paths: f64,
    pub received_energy_j: f64,
    /// Received energy beyond first order, J.
    pub multiple_energy_j: f64,
    pub solar_photons_per_bin: f64,
    /// Sum of `brf_fov_solar`; null without a sun.
    #[serde(default)]
    pub brf_fov_solar: Option<f64>,
    /// Sum of `brf_footprint_laser` over the `lit` pulses that have one.
    pub brf_footprint_laser: f64,
    pub lit: usize,
    /// Σ of the square of each pulse's `received_energy_se_j`, J²: with `received_energy_j`,
    /// how the simulation's noise compares with the photons' (report.md); null in a
    /// products.json written before it.
    #[serde(default)]
    pub received_energy_var_j2: Option<f64>,
    /// Σ of each pulse's solar photons over its gate (before the quantum efficiency), and Σ
    /// of the square of their standard error: the sun's side of the same comparison; null in
    /// a products.json written before them.
    #[serde(default)]
    pub solar_photons_in_gates: Option<f64>,
    #[serde(default)]
    pub solar_photons_var: Option<f64>,
}

impl WaveformTotals {
    pub fn add(&mut self, w: &crate::waveform::Waveform) {
        self.received_energy_j += w.received_energy_j;
        let se = w.received_energy_se_j;
        self.received_energy_var_j2 = Some(self.received_energy_var_j2.unwrap_or(0.0) + se * se);
        self.pulses += 1;
        self.multiple_energy_j +=
            w.received_energy_j - w.order_energy_j.first().copied().unwrap_or(0.0);
        self.rays += w.rays as u64;
        self.paths += w.paths_per_ray as f64 * w.rays as f64;
        self.solar_photons_per_bin += w.solar_photons_per_bin as f64;
        // the gate's solar photons, and their error by the solar power's relative error
        let in_gate = w.solar_photons_per_bin as f64 * w.laser_photons.len() as f64;
        let se = if w.solar_power_w > 0.0 {
            in_gate * w.solar_power_se_w / w.solar_power_w
        } else {
            0.0
        };
        self.solar_photons_in_gates = Some(self.solar_photons_in_gates.unwrap_or(0.0) + in_gate);
        self.solar_photons_var = Some(self.solar_photons_var.unwrap_or(0.0) + se * se);
        // null as soon as one pulse has none (no sun): a sum with a gap has no meaning
        let fov = Some(w.brf_fov_solar as f64).filter(|v| v.is_finite());
        self.brf_fov_solar = if self.pulses == 1 {
            fov
        } else {
            self.brf_fov_solar.zip(fov).map(|(a, b)| a + b)
        };
        if w.brf_footprint_laser.is_finite() {
            self.brf_footprint_laser += w.brf_footprint_laser as f64;
            self.lit += 1;
        }
    }
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointsSummary {
    pub points: usize,
    pub points_per_pulse: f64,
    /// Area of the box the first returns cover, m²; null when there is none.
    pub area_m2: Option<f64>,
    /// Pulses per m² of that box; null when the box is empty.
    pub pulse_density_per_m2: Option<f64>,
    /// Points by LAS class name (`SurfaceClass::las_name`).
    pub points_by_class: BTreeMap<String, usize>,
    /// How far the points lie from the scene's surfaces; null without points.
    #[serde(default)]
    pub surface_distance: Option<crate::products::points::accuracy::SurfaceDistance>,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhotonCounts {
    pub total: usize,
    pub laser: usize,
    pub solar: usize,
    pub dark: usize,
    pub laser_per_shot: f64,
}

impl ProductsSummary {
    /// The file's text: keys in sorted order (through a JSON value, whose maps sort), so the
    /// file does not depend on the order of the fields here.
    pub fn to_json(&self) -> String {
        serde_json::to_value(self)
            .and_then(|v| serde_json::to_string_pretty(&v))
            .unwrap_or_default()
    }

    /// `products.json` of a run folder; None when it is absent or not ours.
    pub fn read(path: &Path) -> Option<ProductsSummary> {
        serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_and_read_back_alike() {
        let s = ProductsSummary {
            pulses: 4,
            points: Some(PointsSummary {
                points: 6,
                points_per_pulse: 1.5,
                area_m2: Some(0.0),
                pulse_density_per_m2: None,
                points_by_class: [("ground".to_string(), 6)].into(),
                surface_distance: None,
            }),
            photons: None,
            strips: None,
            l2a: Some(L2aSummary {
                shots: 3,
                quality_shots: 2,
                rh98_minus_top_mean_m: Some(-1.5),
                rh98_minus_top_sd_m: None,
                ground_minus_truth_mean_m: Some(0.25),
                ground_minus_truth_sd_m: Some(0.125),
            }),
            waveform_totals: Some(WaveformTotals {
                pulses: 4,
                brf_fov_solar: None,
                ..Default::default()
            }),
        };
        let text = s.to_json();
        assert!(text.contains("\"brf_fov_solar\": null"), "{text}");
        assert!(text.contains("\"pulse_density_per_m2\": null"), "{text}");
        assert!(!text.contains("\"photons\""), "{text}");
        assert_eq!(serde_json::from_str::<ProductsSummary>(&text).unwrap(), s);
        let waveforms_only: ProductsSummary = serde_json::from_str("{\"pulses\": 1}").unwrap();
        assert_eq!(waveforms_only.points, None);
        assert_eq!(waveforms_only.photons, None);
        assert_eq!(waveforms_only.waveform_totals, None);
    }

    /// The fov BRF sum is null as soon as one pulse has none, and stays so.
    #[test]
    fn a_sum_with_a_gap_is_null() {
        let w = |fov: f32| crate::waveform::Waveform {
            pulse_id: 0,
            t0_ns: 0.0,
            bin_ns: 1.0,
            laser_photons: vec![],
            impulse_energy_j: vec![],
            impulse_energy_se_j: vec![],
            received_energy_j: 1.0,
            outside_gate_energy_j: 0.0,
            order_energy_j: vec![0.75],
            order_energy_se_j: vec![],
            received_energy_se_j: 0.0,
            solar_photons_per_bin: 0.5,
            solar_power_w: 0.0,
            solar_power_se_w: 0.0,
            brf_fov_solar: fov,
            brf_footprint_laser: f32::NAN,
            class_energy_j: Default::default(),
            span_first_bin: 0,
            rays: 2,
            paths_per_ray: 1.5,
            wavelength_nm: None,
            non_finite: 0,
            underflows: 0,
        };
        let mut t = WaveformTotals::default();
        t.add(&w(0.25));
        t.add(&w(0.5));
        assert_eq!(t.brf_fov_solar, Some(0.75));
        assert_eq!((t.pulses, t.rays, t.paths, t.lit), (2, 4, 6.0, 0));
        assert_eq!(t.multiple_energy_j, 0.5);
        t.add(&w(f32::NAN));
        t.add(&w(0.5));
        assert_eq!(t.brf_fov_solar, None);
    }
}
