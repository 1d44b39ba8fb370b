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
    pub surface_distance: Option<crate::products::accuracy::SurfaceDistance>,
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
        };
        let text = s.to_json();
        assert!(text.contains("\"pulse_density_per_m2\": null"), "{text}");
        assert!(!text.contains("photons"), "{text}");
        assert_eq!(serde_json::from_str::<ProductsSummary>(&text).unwrap(), s);
        let waveforms_only: ProductsSummary = serde_json::from_str("{\"pulses\": 1}").unwrap();
        assert_eq!(waveforms_only.points, None);
        assert_eq!(waveforms_only.photons, None);
    }
}
