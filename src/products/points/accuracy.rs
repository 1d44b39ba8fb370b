//! How far the points lie from the scene's surfaces: the truth a simulation has and a survey
//! does not, so that a decomposition that invents returns shows up as points in mid-air or
//! under the ground.

use super::Point;
use crate::scene::Scene;
use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Farthest distance measured, m: a point farther from every surface counts as this far.
const REACH_M: f64 = 1.0;

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

/// Distance from each point to the nearest surface of `scene`, m, at most [`REACH_M`].
pub fn distances(scene: &Scene, points: &[Point]) -> Vec<f64> {
    points
        .par_iter()
        .map(|p| scene.nearest_surface(DVec3::new(p.x, p.y, p.z), REACH_M))
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

/// Bins of [`DistanceHistogram`] per metre (a multiplier, not a step: 0.05 m × 1e6 is exactly
/// 50 000, so the 5 and 25 cm limits fall on bin edges).
const BINS_PER_M: f64 = 1e6;

/// Distances counted by the micrometre, up to [`REACH_M`]: the summary of any number of
/// points in a fixed 4 MB, its quantiles rounded up to the next micrometre.
#[derive(Clone, Debug, Default)]
pub struct DistanceHistogram {
    /// Count of distances in ((k - 1) µm, k µm]; the first holds 0.
    counts: Vec<u32>,
    n: u64,
}

impl DistanceHistogram {
    fn bins() -> usize {
        (REACH_M * BINS_PER_M).round() as usize + 1
    }

    fn bin(d: f64) -> usize {
        ((d * BINS_PER_M).ceil().max(0.0) as usize).min(Self::bins() - 1)
    }

    pub fn add(&mut self, distances: &[f64]) {
        if self.counts.is_empty() && !distances.is_empty() {
            self.counts = vec![0; Self::bins()];
        }
        for &d in distances {
            let k = Self::bin(d);
            self.counts[k] = self.counts[k].saturating_add(1);
        }
        self.n += distances.len() as u64;
    }

    /// As [`summarize`] gives for the same distances, each quantile to the micrometre above.
    pub fn summary(&self) -> Option<SurfaceDistance> {
        if self.n == 0 {
            return None;
        }
        let n = self.n as f64;
        let within = |limit: f64| {
            let last = (limit * BINS_PER_M).round() as usize;
            self.counts[..=last].iter().map(|&c| c as u64).sum::<u64>() as f64 / n
        };
        // the value of rank r (0-based) in sorted order, as summarize picks it
        let quantile = |q: f64| {
            let rank = ((q * (n - 1.0)).round() as u64).min(self.n - 1);
            let mut below = 0u64;
            for (k, &c) in self.counts.iter().enumerate() {
                below += c as u64;
                if below > rank {
                    return k as f64 / BINS_PER_M;
                }
            }
            REACH_M
        };
        Some(SurfaceDistance {
            within_5cm: within(0.05),
            within_25cm: within(0.25),
            median_m: quantile(0.5),
            p99_m: quantile(0.99),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The histogram gives summarize's fractions exactly and its quantiles to the micrometre.
    #[test]
    fn histogram_agrees_with_the_sorted_summary() {
        let mut rng = crate::rng::SplitMix64::new(5);
        let d: Vec<f64> = (0..10_001)
            .map(|i| match i % 4 {
                0 => 0.0,
                1 => 0.05,
                2 => rng.uniform() * 0.3,
                _ => (rng.uniform() * 1.2).min(REACH_M),
            })
            .collect();
        let exact = summarize(&d).unwrap();
        let mut h = DistanceHistogram::default();
        h.add(&d[..17]);
        h.add(&d[17..]);
        let s = h.summary().unwrap();
        assert_eq!(s.within_5cm, exact.within_5cm);
        assert_eq!(s.within_25cm, exact.within_25cm);
        for (a, b) in [(s.median_m, exact.median_m), (s.p99_m, exact.p99_m)] {
            assert!(a >= b && a - b <= 1.0001 / BINS_PER_M, "{a} against {b}");
        }
        assert_eq!(DistanceHistogram::default().summary(), None);
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
