//! How far the points lie from the scene's surfaces: the truth a simulation has and a survey
//! does not, so that a decomposition that invents returns shows up as points in mid-air or
//! under the ground.

use super::points::Point;
use crate::plan::Pulse;
use crate::scene::{FacetId, Scene};
use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Farthest distance measured, m: a point farther from every surface counts as this far.
const REACH_M: f64 = 1.0;
/// Directions tried around a point that is not on a surface along its beam: 64 spread over
/// the sphere leave no direction more than 19.2° from one of them (the test below), so a
/// distance to a plane is overestimated by at most 1/cos 19.2° - 1 ≈ 6 %.
const DIRECTIONS: usize = 64;

/// Distances from the points to the nearest surface, summarised.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SurfaceDistance {
    /// Fraction of the points within 5 cm of a surface.
    pub within_5cm: f64,
    /// Fraction of the points within 25 cm of a surface.
    pub within_25cm: f64,
    /// Median distance, m.
    pub median_m: f64,
    /// 99th percentile of the distance, m (1 m means "1 m or more").
    pub p99_m: f64,
}

/// Distance from each point to the nearest surface of `scene`, m, at most [`REACH_M`]: first
/// along the point's beam (both ways), where nearly every point lies, then, for a point more
/// than 5 cm from a surface that way, over [`DIRECTIONS`] directions.
pub fn distances(scene: &Scene, points: &[Point], pulses: &[Pulse]) -> Vec<f64> {
    let dirs = sphere_directions(DIRECTIONS);
    points
        .par_iter()
        .map(|p| {
            let at = DVec3::new(p.x, p.y, p.z);
            let reach = |d: DVec3| {
                scene
                    .intersect(at, d, REACH_M, FacetId::NONE)
                    .map_or(REACH_M, |h| h.t)
            };
            let axis = pulses
                .get(p.pulse_id as usize)
                .map_or(DVec3::Z, |q| q.direction);
            let along = reach(axis).min(reach(-axis));
            if along <= 0.05 {
                return along;
            }
            dirs.iter().fold(along, |best, &d| best.min(reach(d)))
        })
        .collect()
}

/// The summary of [`distances`]; None without points.
pub fn summarize(distances: &[f64]) -> Option<SurfaceDistance> {
    if distances.is_empty() {
        return None;
    }
    let mut d = distances.to_vec();
    d.sort_by(f64::total_cmp);
    let n = d.len() as f64;
    let within = |limit: f64| d.iter().filter(|&&x| x <= limit).count() as f64 / n;
    let quantile = |q: f64| d[((q * (n - 1.0)).round() as usize).min(d.len() - 1)];
    Some(SurfaceDistance {
        within_5cm: within(0.05),
        within_25cm: within(0.25),
        median_m: quantile(0.5),
        p99_m: quantile(0.99),
    })
}

/// `n` unit vectors spread evenly over the sphere (a Fibonacci lattice).
fn sphere_directions(n: usize) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            DVec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_cover_the_sphere() {
        let dirs = sphere_directions(DIRECTIONS);
        // the worst direction's nearest neighbour in the set, over a fine probe of the sphere
        let probe = sphere_directions(20_000);
        let worst = probe
            .iter()
            .map(|p| dirs.iter().map(|d| d.dot(*p)).fold(-1.0, f64::max))
            .fold(1.0, f64::min);
        let gap = worst.acos().to_degrees();
        assert!(gap < 19.5, "{gap}°");
    }

    #[test]
    fn summary_quantiles() {
        let d: Vec<f64> = (0..100).map(|i| i as f64 / 100.0).collect();
        let s = summarize(&d).unwrap();
        assert_eq!(s.within_5cm, 0.06);
        assert_eq!(s.within_25cm, 0.26);
        assert!((s.median_m - 0.5).abs() <= 0.01);
        assert_eq!(summarize(&[]), None);
    }
}
