//! Pulse planning: a platform expands into the list of pulses to simulate.
//!
//! The frame is flat and local: x, y in metres across the scene, z up, no Earth curvature.

use crate::campaign::{Campaign, PlatformKind};
use crate::error::{Error, Result};
use glam::DVec3;

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

pub fn plan(campaign: &Campaign) -> Result<Vec<Pulse>> {
    let p = &campaign.platform;
    match p.kind {
        PlatformKind::Static => {
            let specs = p.pulses.as_deref().unwrap_or(&[]);
            let t0 = p.gps_start_s.unwrap_or(0.0);
            Ok(specs
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
                    }
                })
                .collect())
        }
        other => Err(Error::msg(format!(
            "platform kind {other:?} is not available yet"
        ))),
    }
}
