//! Strip-to-strip height differences where flight lines overlap: the check a survey's strips
//! get before and after strip adjustment, and what navigation errors and an unknown boresight
//! show up in first.
//!
//! The points of each strip (LAS point source id) are binned in square cells of [`CELL_M`]. A
//! cell counts when at least two strips each have [`MIN_POINTS`] first-band last returns in
//! it spread over at most [`FLAT_M`] in height: a smooth, solid surface (ground, a roof), where
//! the strips' mean heights should agree; canopy and edges, where they need not, are left out.
//! For every pair of strips, the differences of their mean heights over the cells both cover.

use super::Point;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};

/// Cell side, metres.
pub const CELL_M: f64 = 1.0;
/// Points a strip needs in a cell.
pub const MIN_POINTS: u32 = 3;
/// Largest spread of a strip's heights in a cell for it to count as one surface, metres.
pub const FLAT_M: f64 = 0.15;

#[derive(Clone, Copy, Debug)]
struct Cell {
    n: u32,
    sum: f64,
    lo: f64,
    hi: f64,
}

/// Per strip and cell, the last returns' heights, gathered as the points stream by.
#[derive(Default)]
pub struct Strips {
    cells: HashMap<(i64, i64), BTreeMap<u16, Cell>>,
}

/// One pair of strips over the cells both cover: b's mean height less a's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StripPair {
    pub a: u16,
    pub b: u16,
    pub cells: usize,
    pub mean_dz_m: f64,
    pub rms_dz_m: f64,
    pub max_abs_dz_m: f64,
}

/// `products.json`'s `strips`: the rule and every overlapping pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StripSummary {
    pub cell_m: f64,
    pub flat_m: f64,
    pub min_points: u32,
    pub pairs: Vec<StripPair>,
    /// Over every pair's cells.
    pub cells: usize,
    pub rms_dz_m: Option<f64>,
}

impl Strips {
    pub fn add(&mut self, points: &[Point]) {
        for p in points
            .iter()
            .filter(|p| p.return_number == p.number_of_returns)
        {
            let key = ((p.x / CELL_M).floor() as i64, (p.y / CELL_M).floor() as i64);
            let c = self
                .cells
                .entry(key)
                .or_default()
                .entry(p.point_source_id)
                .or_insert(Cell {
                    n: 0,
                    sum: 0.0,
                    lo: p.z,
                    hi: p.z,
                });
            c.n += 1;
            c.sum += p.z;
            c.lo = c.lo.min(p.z);
            c.hi = c.hi.max(p.z);
        }
    }

    /// The pairs of strips that overlap on smooth cells; `None` with fewer than two strips.
    pub fn summary(&self) -> Option<StripSummary> {
        let mut diffs: BTreeMap<(u16, u16), Vec<f64>> = BTreeMap::new();
        let mut strips = std::collections::BTreeSet::new();
        // cells in a fixed order, so the sums are the same whatever the hash map's order
        let mut keys: Vec<&(i64, i64)> = self.cells.keys().collect();
        keys.sort();
        for key in keys {
            let by_strip = &self.cells[key];
            strips.extend(by_strip.keys().copied());
            let flat: Vec<(u16, f64)> = by_strip
                .iter()
                .filter(|(_, c)| c.n >= MIN_POINTS && c.hi - c.lo <= FLAT_M)
                .map(|(s, c)| (*s, c.sum / c.n as f64))
                .collect();
            for (i, (a, za)) in flat.iter().enumerate() {
                for (b, zb) in &flat[i + 1..] {
                    diffs.entry((*a, *b)).or_default().push(zb - za);
                }
            }
        }
        if strips.len() < 2 {
            return None;
        }
        let pairs: Vec<StripPair> = diffs
            .iter()
            .map(|(&(a, b), d)| {
                let n = d.len() as f64;
                StripPair {
                    a,
                    b,
                    cells: d.len(),
                    mean_dz_m: d.iter().sum::<f64>() / n,
                    rms_dz_m: (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt(),
                    max_abs_dz_m: d.iter().fold(0.0, |m, x| m.max(x.abs())),
                }
            })
            .collect();
        let cells: usize = pairs.iter().map(|p| p.cells).sum();
        let rms = (cells > 0).then(|| {
            let sq: f64 = pairs
                .iter()
                .map(|p| p.rms_dz_m * p.rms_dz_m * p.cells as f64)
                .sum();
            (sq / cells as f64).sqrt()
        });
        Some(StripSummary {
            cell_m: CELL_M,
            flat_m: FLAT_M,
            min_points: MIN_POINTS,
            pairs,
            cells,
            rms_dz_m: rms,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(x: f64, y: f64, z: f64, source: u16) -> Point {
        Point {
            x,
            y,
            z,
            gps_time: 0.0,
            intensity: 0,
            return_number: 1,
            number_of_returns: 1,
            scan_angle_deg: 0.0,
            point_source_id: source,
            classification: 2,
            apparent_reflectance: 0.0,
            pulse_id: 0,
            wavelength_nm: None,
            left_to_right: false,
            edge_of_line: false,
        }
    }

    /// Two strips over a flat 10 × 10 m patch, the second 4 cm higher, with a canopy cell
    /// (1 m of spread) left out and a third strip that overlaps neither.
    #[test]
    fn overlapping_strips_differ_by_their_offset() {
        let mut s = Strips::default();
        let mut pts = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let (x, y) = (i as f64 * 0.25 + 0.1, j as f64 * 0.25 + 0.1);
                pts.push(point(x, y, 0.0, 1));
                pts.push(point(x, y, 0.04, 2));
            }
        }
        for k in 0..4 {
            pts.push(point(20.5, 20.5, k as f64 * 0.3, 1));
            pts.push(point(20.5, 20.5, 0.0, 2));
            pts.push(point(50.5, 50.5, 0.0, 3));
        }
        s.add(&pts);
        let sum = s.summary().unwrap();
        assert_eq!(sum.pairs.len(), 1);
        let p = &sum.pairs[0];
        assert_eq!((p.a, p.b, p.cells), (1, 2, 100));
        assert!((p.mean_dz_m - 0.04).abs() < 1e-12 && (p.rms_dz_m - 0.04).abs() < 1e-12);
        let mut one = Strips::default();
        let first: Vec<Point> = pts
            .iter()
            .filter(|p| p.point_source_id == 1)
            .cloned()
            .collect();
        one.add(&first);
        assert_eq!(one.summary(), None);
    }
}
