//! Near-field overlap: how much of the receiver's aperture sees the laser spot at a range.
//!
//! Each point of the aperture (a disk of radius a = √(A/π)) accepts light within θ_fov of the
//! axis, so at range R it sees a disk of radius R tan θ_fov about its own position. The laser
//! spot's centre lies b off the aperture's centre across the beam (the receiver's offset), so
//! the aperture points that see it fill the lens where the aperture overlaps the disk of radius
//! R tan θ_fov about the spot: the overlap factor O(R) = lens(a, R tan θ_fov, b) / (π a²), the
//! spot taken as a point (it is millimetres near the sensor, where O matters). O = 1 from
//! R_full = (a + b) / tan θ_fov on; nearer, the record keeps only O of the light, and a small
//! field of view behind a wide aperture sees almost nothing of a spot a metre or two away.

use crate::campaign::Instrument;
use std::f64::consts::PI;

/// Below this overlap the receiver cannot see the spot: less than 1 % of its aperture does
/// (a 0.3 mrad field of view behind a 0.08 m aperture at 1.5 m: 1.3e-4). Between it and 1 the
/// signal is only cut, as a real receiver focused at infinity cuts it (its blur circle, a / R,
/// outgrows the field stop): the bundled airborne campaigns keep 0.07 to 0.4 of theirs.
pub const POOR_OVERLAP: f64 = 0.01;

/// Area of the intersection of two disks of radii `r1`, `r2` whose centres are `d` apart.
fn lens(r1: f64, r2: f64, d: f64) -> f64 {
    if d >= r1 + r2 {
        return 0.0;
    }
    if d <= (r1 - r2).abs() {
        return PI * r1.min(r2).powi(2);
    }
    let a1 = ((d * d + r1 * r1 - r2 * r2) / (2.0 * d * r1))
        .clamp(-1.0, 1.0)
        .acos();
    let a2 = ((d * d + r2 * r2 - r1 * r1) / (2.0 * d * r2))
        .clamp(-1.0, 1.0)
        .acos();
    let k = ((-d + r1 + r2) * (d + r1 - r2) * (d - r1 + r2) * (d + r1 + r2)).max(0.0);
    r1 * r1 * a1 + r2 * r2 * a2 - 0.5 * k.sqrt()
}

/// The aperture's radius and the receiver's offset across the beam, m.
fn aperture(inst: &Instrument) -> (f64, f64) {
    let a = (inst.receiver_area_m2 / PI).sqrt();
    let b = inst
        .receiver_offset_m
        .map_or(0.0, |o| o[1].hypot(o[2]).max(0.0));
    (a, b)
}

/// O(R): the fraction of the aperture that sees the spot's centre at range `r`.
pub fn overlap(inst: &Instrument, r: f64) -> f64 {
    let (a, b) = aperture(inst);
    let seen = r * (inst.fov_half_angle_mrad * 1e-3).tan();
    (lens(a, seen, b) / (PI * a * a)).clamp(0.0, 1.0)
}

/// R_full, from which the whole aperture sees the spot.
pub fn full_overlap_range_m(inst: &Instrument) -> f64 {
    let (a, b) = aperture(inst);
    (a + b) / (inst.fov_half_angle_mrad * 1e-3).tan()
}

/// A warning when part of the scene lies where less than [`POOR_OVERLAP`] of the aperture
/// sees the spot: `ranges` are where pulses of the campaign first meet the scene.
pub fn warning(inst: &Instrument, ranges: &[f64]) -> Option<String> {
    let poor: Vec<f64> = ranges
        .iter()
        .copied()
        .filter(|&r| overlap(inst, r) < POOR_OVERLAP)
        .collect();
    if poor.is_empty() {
        return None;
    }
    let nearest = poor.iter().cloned().fold(f64::INFINITY, f64::min);
    let (a, b) = aperture(inst);
    let wanted_mrad = ((a + b) / nearest).atan() * 1e3;
    Some(format!(
        "near-field overlap: the receiver's field of view ({} mrad behind a {:.3} m aperture{}) sees the laser spot with its whole aperture only beyond {:.2} m; {} of {} sampled pulses meet the scene where less than 1 % of it does (at {:.2} m, {:.1e} of it): their signal is cut by as much, and few or no returns come back. A field of view of {:.1} mrad sees the spot from the whole aperture at {:.2} m (instrument.fov_half_angle_mrad)",
        inst.fov_half_angle_mrad,
        2.0 * a,
        if b > 0.0 { format!(", {b:.3} m off the laser") } else { String::new() },
        full_overlap_range_m(inst),
        poor.len(),
        ranges.len(),
        nearest,
        overlap(inst, nearest),
        wanted_mrad,
        nearest,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lens against its limits: apart, nested, and two equal disks half overlapping.
    #[test]
    fn lens_areas() {
        assert_eq!(lens(1.0, 1.0, 2.5), 0.0);
        assert!((lens(1.0, 0.5, 0.2) - PI * 0.25).abs() < 1e-12);
        // two unit disks one radius apart: 2π/3 − √3/2
        let want = 2.0 * PI / 3.0 - 3f64.sqrt() / 2.0;
        assert!((lens(1.0, 1.0, 1.0) - want).abs() < 1e-12);
    }
}
