//! DSM error (paper section 3.2): the first-return DSM (highest first-return point per cell)
//! minus the reference DSM of the scene's own surfaces (`Scene::top_surface_grid`) on the same
//! grid, summarised as bias, RMSE, coverage and against scan angle.
//!
//! Scan-angle attribution: a cell belongs to the mean |scan angle| of the pulses aimed at it
//! (whose axis crosses the cell at the ground's height), whether or not a return came back
//! from it: so coverage per angle counts the blind spots behind buildings and crowns, which
//! grow with the angle. A cell no pulse was aimed at takes the |scan angle| of the point
//! that set its DSM value (its highest first return; among equal heights the smallest angle).

mod figures;
pub mod geotiff;

use crate::error::{Error, Result};
use crate::fsutil::write_text_atomic;
use crate::plan::Pulse;
use crate::products::points::Point;
pub use crate::scene::top_surface::Grid;
use crate::scene::Scene;
use glam::DVec3;
use serde::{Deserialize, Deserializer, Serialize};
use std::path::Path;

/// One point as the DSM needs it: world position, scan angle (degrees), and whether it is its
/// pulse's first return.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DsmPoint {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub scan_angle_deg: f64,
    pub first: bool,
}

/// Width of the scan-angle bins of `DsmReport::by_scan_angle`.
pub const ANGLE_BIN_DEG: f64 = 2.0;

/// The highest z of the first-return points in each cell (NaN where there is none).
pub fn first_return_dsm(points: &[DsmPoint], grid: &Grid) -> Vec<f64> {
    first_return_dsm_with_angle(points, grid).0
}

/// The first-return DSM and, per cell, the |scan angle| (degrees) of the point that set it
/// (NaN where there is none).
pub fn first_return_dsm_with_angle(points: &[DsmPoint], grid: &Grid) -> (Vec<f64>, Vec<f64>) {
    let n = grid.len();
    let (mut z, mut angle) = (vec![f64::NAN; n], vec![f64::NAN; n]);
    add_first_returns(&mut z, &mut angle, points, grid);
    (z, angle)
}

/// Raises the first-return DSM `z` (and its `angle`) by more points, in order: the same cells
/// whether the points come at once or a chunk at a time.
fn add_first_returns(z: &mut [f64], angle: &mut [f64], points: &[DsmPoint], grid: &Grid) {
    for p in points {
        if !p.first || !p.z.is_finite() {
            continue;
        }
        let Some(k) = grid.index(p.x, p.y) else {
            continue;
        };
        let a = p.scan_angle_deg.abs();
        let better = z[k].is_nan() || p.z > z[k] || (p.z == z[k] && a < angle[k]);
        if better {
            z[k] = p.z;
            angle[k] = a;
        }
    }
}

/// Per cell, the mean |scan angle| (degrees) of the pulses whose axis crosses the plane
/// z = `ground_z` in that cell (NaN where none does).
pub fn aim_angles(pulses: &[Pulse], grid: &Grid, ground_z: f64) -> Vec<f64> {
    let mut aims = Aims::new(grid.len());
    aims.add(pulses, grid, ground_z);
    aims.mean()
}

/// Sums behind [`aim_angles`], gathered a chunk of pulses at a time.
struct Aims {
    sum: Vec<f64>,
    count: Vec<u32>,
}

impl Aims {
    fn new(cells: usize) -> Aims {
        Aims {
            sum: vec![0.0; cells],
            count: vec![0; cells],
        }
    }

    fn add(&mut self, pulses: &[Pulse], grid: &Grid, ground_z: f64) {
        for p in pulses {
            let d = p.direction;
            if d.z.abs() < 1e-12 {
                continue; // horizontal: never reaches the ground plane
            }
            let t = (ground_z - p.origin.z) / d.z;
            if !(t > 0.0 && t.is_finite()) {
                continue;
            }
            let hit = p.origin + d * t;
            if let Some(k) = grid.index(hit.x, hit.y) {
                self.sum[k] += (p.scan_angle_deg as f64).abs();
                self.count[k] += 1;
            }
        }
    }

    fn mean(&self) -> Vec<f64> {
        self.sum
            .iter()
            .zip(&self.count)
            .map(|(s, &n)| if n > 0 { s / n as f64 } else { f64::NAN })
            .collect()
    }
}

/// Error figures of the cells whose |scan angle| falls in [bin_deg_lo, bin_deg_hi).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AngleBin {
    pub bin_deg_lo: f64,
    pub bin_deg_hi: f64,
    /// Cells with a reference surface in this bin, and those of them with a first return.
    pub cells_surfaced: usize,
    pub cells: usize,
    /// `cells / cells_surfaced`; 1 − coverage is the bin's coverage gap.
    #[serde(deserialize_with = "nan_if_null")]
    pub coverage: f64,
    /// NaN (null in JSON) for an empty bin.
    #[serde(deserialize_with = "nan_if_null")]
    pub bias_m: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub rmse_m: f64,
}

/// DSM error figures. Error = measured − reference over the cells where both exist; the
/// figures are NaN (null in JSON) when there is no such cell.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DsmReport {
    #[serde(deserialize_with = "nan_if_null")]
    pub bias_m: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub rmse_m: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub mae_m: f64,
    /// `cells_with_points / cells`.
    #[serde(deserialize_with = "nan_if_null")]
    pub coverage: f64,
    /// Cells with a reference surface.
    pub cells: usize,
    /// Cells with a reference surface and a first-return value: the cells compared.
    pub cells_with_points: usize,
    /// 2° bins of |scan angle| from 0 up to the largest angle seen, empty bins included.
    pub by_scan_angle: Vec<AngleBin>,
    pub resolution_m: f64,
}

/// JSON writes a NaN as null; reading it back gives the NaN again.
fn nan_if_null<'de, D: Deserializer<'de>>(d: D) -> std::result::Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

impl DsmReport {
    /// `dsm/report.json` of a run folder; None when it is absent or not ours.
    pub fn read(path: &Path) -> Option<DsmReport> {
        serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
    }
}

#[derive(Default)]
struct Sums {
    n: usize,
    sum: f64,
    sum_sq: f64,
    sum_abs: f64,
}

impl Sums {
    fn add(&mut self, e: f64) {
        self.n += 1;
        self.sum += e;
        self.sum_sq += e * e;
        self.sum_abs += e.abs();
    }

    fn mean(&self, s: f64) -> f64 {
        if self.n == 0 {
            f64::NAN
        } else {
            s / self.n as f64
        }
    }
}

/// Compares a measured DSM with the reference on `grid`. `aim_angle` is the |scan angle| of
/// the pulses aimed at each cell ([`aim_angles`]), `point_angle` that of the point that set
/// the cell ([`first_return_dsm_with_angle`]), used where no pulse was aimed; NaN where
/// unknown.
pub fn compare(
    reference: &[f64],
    measured: &[f64],
    aim_angle: &[f64],
    point_angle: &[f64],
    grid: &Grid,
) -> DsmReport {
    let mut all = Sums::default();
    let mut bins: Vec<(usize, Sums)> = Vec::new();
    let mut cells = 0;
    for (k, &r) in reference.iter().enumerate() {
        if !r.is_finite() {
            continue;
        }
        cells += 1;
        let m = measured.get(k).copied().unwrap_or(f64::NAN);
        let aim = aim_angle.get(k).copied().unwrap_or(f64::NAN).abs();
        let a = if aim.is_finite() {
            aim
        } else {
            point_angle.get(k).copied().unwrap_or(f64::NAN).abs()
        };
        let bin = a.is_finite().then(|| (a / ANGLE_BIN_DEG).floor() as usize);
        if let Some(b) = bin {
            if bins.len() <= b {
                bins.resize_with(b + 1, || (0, Sums::default()));
            }
            bins[b].0 += 1;
        }
        if !m.is_finite() {
            continue;
        }
        let e = m - r;
        all.add(e);
        if let Some(b) = bin {
            bins[b].1.add(e);
        }
    }
    DsmReport {
        bias_m: all.mean(all.sum),
        rmse_m: all.mean(all.sum_sq).sqrt(),
        mae_m: all.mean(all.sum_abs),
        coverage: if cells == 0 {
            f64::NAN
        } else {
            all.n as f64 / cells as f64
        },
        cells,
        cells_with_points: all.n,
        by_scan_angle: bins
            .iter()
            .enumerate()
            .map(|(b, (surfaced, s))| AngleBin {
                bin_deg_lo: b as f64 * ANGLE_BIN_DEG,
                bin_deg_hi: (b + 1) as f64 * ANGLE_BIN_DEG,
                cells_surfaced: *surfaced,
                cells: s.n,
                coverage: if *surfaced == 0 {
                    f64::NAN
                } else {
                    s.n as f64 / *surfaced as f64
                },
                bias_m: s.mean(s.sum),
                rmse_m: s.mean(s.sum_sq).sqrt(),
            })
            .collect(),
        resolution_m: grid.cell,
    }
}

/// Writes `dir/report.json`, `dir/error_vs_scan_angle.png` (bias, RMSE and coverage per angle
/// bin) and `dir/error_map.png`.
pub fn write_report(
    dir: &Path,
    report: &DsmReport,
    reference: &[f64],
    measured: &[f64],
    grid: &Grid,
) -> Result<()> {
    let json = serde_json::to_string_pretty(report)
        .map_err(|e| Error::msg(format!("cannot encode the DSM report: {e}")))?;
    write_text_atomic(&dir.join("report.json"), &(json + "\n"))?;
    figures::dsm_error_vs_angle(&dir.join("error_vs_scan_angle.png"), report)?;
    figures::dsm_error_map(
        &dir.join("error_map.png"),
        reference,
        measured,
        grid,
        &format!(
            "first-return DSM − reference, {} m cells: bias {:+.3} m, RMSE {:.3} m",
            report.resolution_m, report.bias_m, report.rmse_m
        ),
    )
}

/// The DSM error product of a run: reference DSM from the scene's own surfaces, first-return
/// DSM from the points, on one grid over the scanned area; `dsm/report.json` and plots.
/// Built while the points and pulses stream by, so its memory is the grid's: [`Dsm::new`]
/// once the first returns' extent is known, [`Dsm::add_points`] and [`Dsm::aim`] a chunk at
/// a time (in point and pulse order), then [`Dsm::write`].
pub struct Dsm {
    grid: Grid,
    res: f64,
    reference: Vec<f64>,
    /// Height the pulses are aimed at, for the scan-angle attribution.
    ground: f64,
    measured: Vec<f64>,
    angles: Vec<f64>,
    aims: Aims,
}

impl Dsm {
    /// The grid over `first_returns` (the box of the first-return points) within the scene;
    /// None, and a log line, without first returns.
    pub fn new(scene: &Scene, first_returns: Option<(DVec3, DVec3)>, res: f64) -> Option<Dsm> {
        let Some((lo, hi)) = first_returns else {
            crate::progress::log("dsm: no first returns, no DSM");
            return None;
        };
        let (slo, shi) = scene.bounds();
        // a repeated scene has surfaces under every point
        let (lo, hi) = if scene.is_repeated() {
            (lo, hi)
        } else {
            (lo.max(slo), hi.min(shi))
        };
        let grid = Grid::covering(
            DVec3::new(lo.x, lo.y, slo.z),
            DVec3::new(hi.x, hi.y, shi.z),
            res,
        );
        let reference = scene.top_surface_grid(&grid);
        // pulses are aimed at the ground: the 5th percentile of the reference heights
        let mut heights: Vec<f64> = reference
            .iter()
            .copied()
            .filter(|z| z.is_finite())
            .collect();
        heights.sort_by(f64::total_cmp);
        let ground = heights.get(heights.len() / 20).copied().unwrap_or(slo.z);
        let n = grid.len();
        Some(Dsm {
            grid,
            res,
            reference,
            ground,
            measured: vec![f64::NAN; n],
            angles: vec![f64::NAN; n],
            aims: Aims::new(n),
        })
    }

    pub fn add_points(&mut self, points: &[Point]) {
        let firsts: Vec<DsmPoint> = points.iter().map(DsmPoint::from).collect();
        add_first_returns(&mut self.measured, &mut self.angles, &firsts, &self.grid);
    }

    pub fn aim(&mut self, pulses: &[Pulse]) {
        self.aims.add(pulses, &self.grid, self.ground);
    }

    /// Writes `dsm/` under `out`: the report, its figures and the three rasters, in the
    /// frame's CRS when there is one; returns the files written, relative to `out`.
    pub fn write(self, out: &Path, frame: Option<&crate::campaign::Frame>) -> Result<Vec<String>> {
        let aim = self.aims.mean();
        let report = compare(
            &self.reference,
            &self.measured,
            &aim,
            &self.angles,
            &self.grid,
        );
        let dir = out.join("dsm");
        write_report(&dir, &report, &self.reference, &self.measured, &self.grid)?;
        let difference: Vec<f64> = self
            .measured
            .iter()
            .zip(&self.reference)
            .map(|(m, r)| m - r)
            .collect();
        geotiff::write(
            &dir.join("dsm.tif"),
            &self.grid,
            &self.measured,
            frame,
            true,
        )?;
        geotiff::write(
            &dir.join("reference.tif"),
            &self.grid,
            &self.reference,
            frame,
            true,
        )?;
        geotiff::write(
            &dir.join("difference.tif"),
            &self.grid,
            &difference,
            frame,
            false,
        )?;
        crate::progress::log(&format!(
            "dsm: bias {:+.3} m, RMSE {:.3} m, coverage {:.1}% over {} cells of {} m",
            report.bias_m,
            report.rmse_m,
            100.0 * report.coverage,
            report.cells,
            self.res
        ));
        Ok(vec![
            "dsm/report.json".into(),
            "dsm/error_vs_scan_angle.png".into(),
            "dsm/error_map.png".into(),
            "dsm/dsm.tif".into(),
            "dsm/reference.tif".into(),
            "dsm/difference.tif".into(),
        ])
    }
}

impl From<&Point> for DsmPoint {
    fn from(p: &Point) -> DsmPoint {
        DsmPoint {
            x: p.x,
            y: p.y,
            z: p.z,
            scan_angle_deg: p.scan_angle_deg as f64,
            first: p.return_number == 1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    fn tmp(name: &str) -> crate::testdata::TempDir {
        let d = crate::testdata::TempDir::new(&format!("dsmprod-{name}"));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn flat_plane_dense_points_have_no_bias() {
        let d = tmp("plane");
        let p = d.join("scene.yaml");
        std::fs::write(
            &p,
            "name: plane\nmaterials:\n  soil: { reflectance: 0.3 }\nobjects:\n  - plane: { z: 0, extent: [[0, 0], [20, 20]], material: soil }\n",
        )
        .unwrap();
        let scene = Scene::load(&p, 1064.0).unwrap();
        let grid = Grid {
            x0: 0.0,
            y0: 0.0,
            cell: 2.0,
            nx: 10,
            ny: 10,
        };
        let reference = scene.top_surface_grid(&grid);
        assert!(reference.iter().all(|z| z.abs() < 1e-9));
        // 5 cm spacing, a scan line every row, angles across the swath
        let mut points = Vec::new();
        for a in 0..400 {
            for b in 0..400 {
                let (x, y) = (0.025 + 0.05 * a as f64, 0.025 + 0.05 * b as f64);
                points.push(DsmPoint {
                    x,
                    y,
                    z: 0.0,
                    scan_angle_deg: (x - 10.0) * 1.1,
                    first: true,
                });
                // a later return below must not lower or raise anything
                points.push(DsmPoint {
                    x,
                    y,
                    z: 5.0,
                    scan_angle_deg: 0.0,
                    first: false,
                });
            }
        }
        let (measured, angle) = first_return_dsm_with_angle(&points, &grid);
        assert_eq!(measured, first_return_dsm(&points, &grid));
        let r = compare(&reference, &measured, &[], &angle, &grid);
        assert!(r.bias_m.abs() < 0.01 && r.rmse_m < 0.01, "{r:?}");
        assert_eq!((r.cells, r.cells_with_points, r.coverage), (100, 100, 1.0));
        assert_eq!(r.resolution_m, 2.0);
        // every point of a cell is equally high, so the cell takes its smallest |angle|: up to
        // 8.8° in the outermost cells, so 5 bins, every cell binned
        assert!(
            (angle[0] - (10.0 - 1.975) * 1.1).abs() < 1e-9,
            "{}",
            angle[0]
        );
        assert_eq!(r.by_scan_angle.len(), 5);
        assert_eq!(r.by_scan_angle.iter().map(|b| b.cells).sum::<usize>(), 100);
        assert_eq!(r.by_scan_angle[4].bin_deg_lo, 8.0);

        let out = d.join("dsm");
        write_report(&out, &r, &reference, &measured, &grid).unwrap();
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                .unwrap();
        assert_eq!(json["cells"], 100);
        assert!(json["by_scan_angle"][0]["rmse_m"].is_number());
        for f in ["error_vs_scan_angle.png", "error_map.png"] {
            let png = std::fs::read(out.join(f)).unwrap();
            assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        }
    }

    #[test]
    fn missed_cells_lower_coverage() {
        let grid = Grid {
            x0: 0.0,
            y0: 0.0,
            cell: 1.0,
            nx: 4,
            ny: 3,
        };
        // the reference has no surface in the last column
        let mut reference = vec![1.0; 12];
        for j in 0..3 {
            reference[j * 4 + 3] = f64::NAN;
        }
        // points in 6 of the 9 surfaced cells, one in the unsurfaced column, one outside
        let at = |x: f64, y: f64, z: f64, a: f64| DsmPoint {
            x,
            y,
            z,
            scan_angle_deg: a,
            first: true,
        };
        let points = [
            at(0.5, 0.5, 1.2, 1.0),
            at(0.6, 0.6, 0.9, -7.0), // lower: does not set the cell
            at(1.5, 0.5, 1.2, -3.0),
            at(2.5, 0.5, 0.8, 3.5),
            at(0.5, 1.5, 0.8, 0.5),
            at(1.5, 1.5, 1.0, 2.5),
            at(2.0, 2.0, 1.0, 5.0), // on a shared corner: cell (2, 2)
            at(3.5, 1.5, 9.0, 0.0), // no reference there
            at(-0.5, 1.5, 9.0, 0.0),
            DsmPoint {
                first: false,
                ..at(0.5, 2.5, 2.0, 0.0)
            },
        ];
        let (measured, angle) = first_return_dsm_with_angle(&points, &grid);
        assert_eq!(measured[0], 1.2);
        assert_eq!(angle[0], 1.0);
        assert_eq!(measured[2 * 4 + 2], 1.0);
        assert!(measured[2 * 4].is_nan());
        let r = compare(&reference, &measured, &[], &angle, &grid);
        assert_eq!((r.cells, r.cells_with_points), (9, 6));
        assert!((r.coverage - 6.0 / 9.0).abs() < 1e-12);
        let errors = [0.2, 0.2, -0.2, -0.2, 0.0, 0.0];
        let bias = errors.iter().sum::<f64>() / 6.0;
        let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / 6.0).sqrt();
        assert!((r.bias_m - bias).abs() < 1e-12 && (r.rmse_m - rmse).abs() < 1e-12);
        assert!((r.mae_m - 0.8 / 6.0).abs() < 1e-12);
        // bins: [0,2): 1.0→+0.2, 0.5→−0.2; [2,4): 3.0→+0.2, 3.5→−0.2, 2.5→0; [4,6): 5.0→0
        let b: Vec<(usize, f64)> = r
            .by_scan_angle
            .iter()
            .map(|b| (b.cells, b.bias_m))
            .collect();
        assert_eq!(b.len(), 3);
        assert_eq!((b[0].0, b[1].0, b[2].0), (2, 3, 1));
        assert!(b[0].1.abs() < 1e-12 && b[1].1.abs() < 1e-12 && b[2].1 == 0.0);
        assert!((r.by_scan_angle[0].rmse_m - 0.2).abs() < 1e-12);

        // no points at all: nothing covered, figures undefined, written as null
        let r = compare(&reference, &[f64::NAN; 12], &[], &[f64::NAN; 12], &grid);
        assert_eq!((r.cells_with_points, r.coverage), (0, 0.0));
        assert!(r.bias_m.is_nan() && r.by_scan_angle.is_empty());
        let json = serde_json::to_string(&r).unwrap();
        assert!(json.contains("\"bias_m\":null"), "{json}");
    }
}
