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

/// Sums behind [`aim_angles`], gathered a chunk of pulses at a time, and the swath: the
/// cells whose top surface (the reference) a pulse's axis crosses.
struct Aims {
    sum: Vec<f64>,
    count: Vec<u32>,
    swath: Vec<bool>,
}

impl Aims {
    fn new(cells: usize) -> Aims {
        Aims {
            sum: vec![0.0; cells],
            count: vec![0; cells],
            swath: vec![false; cells],
        }
    }

    /// Marks the cells whose top (the reference height) the axes of `pulses` cross from above,
    /// between the heights `lo` and `hi` (the reference's lowest and highest): a slanted pulse
    /// reaches a crown nearer the nadir than the ground it is aimed at, so at the swath's edge
    /// the tops of tall surfaces lie outside it. The axis is followed in steps of a quarter
    /// cell, from a little above `hi` to a little below `lo`.
    fn cross_tops(&mut self, pulses: &[Pulse], grid: &Grid, reference: &[f64], lo: f64, hi: f64) {
        for p in pulses {
            let (o, d) = (p.origin, p.direction);
            if d.z >= -1e-12 {
                continue; // level or upwards: reaches no top from above
            }
            let margin = 0.01 * (hi - lo).max(1.0);
            let (t_hi, t_lo) = ((hi + margin - o.z) / d.z, (lo - margin - o.z) / d.z);
            if !(t_lo > 0.0 && t_lo.is_finite()) {
                continue;
            }
            let t_hi = t_hi.max(0.0);
            let horizontal = d.truncate().length() * (t_lo - t_hi);
            let steps = (4.0 * horizontal / grid.cell).ceil().max(1.0) as usize;
            let mut last: Option<(usize, f64)> = None;
            for s in 0..=steps {
                let t = t_hi + (t_lo - t_hi) * s as f64 / steps as f64;
                let q = o + d * t;
                let Some(k) = grid.index(q.x, q.y) else {
                    last = None;
                    continue;
                };
                let above = q.z - reference[k];
                // a crossing from above, within the cell: an axis that enters a cell below its
                // top meets the surface's side, and the top stays unseen
                let crossed =
                    matches!(last, Some((j, was)) if j == k && was >= 0.0 && above <= 0.0);
                if crossed && reference[k].is_finite() {
                    self.swath[k] = true;
                }
                last = Some((k, above));
            }
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

/// The error figures of a set of cells: those with a reference surface, those of them with a
/// first return, and over the latter bias, RMSE and MAE (NaN, null in JSON, without any).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CellStats {
    pub cells: usize,
    pub cells_with_points: usize,
    #[serde(deserialize_with = "nan_if_null")]
    pub coverage: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub bias_m: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub rmse_m: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub mae_m: f64,
}

/// Which cells the headline figures are over: the inner swath, the cells whose top surface a
/// pulse's axis crosses, as it does each of their eight neighbours'; or every cell with a
/// reference surface where no cell is inner (a swath of a cell or two, a scan with no pulse
/// towards the ground).
pub const INNER_SWATH: &str = "inner swath: cells whose top surface a pulse's axis crosses from above, as it does each of their eight neighbours' (the swath's edge in `edge`; cells whose top no pulse reaches, beyond the swath or tall surfaces at its edge seen only from the side, in `outside`)";
pub const ALL_CELLS: &str =
    "all cells with a reference surface (no cell of the swath has all eight neighbours in it)";

/// DSM error figures. Error = measured − reference over the cells where both exist; the
/// figures are NaN (null in JSON) when there is no such cell. The headline figures (bias, RMSE,
/// MAE, coverage, cells) are over the cells `headline` names; `edge` holds the swath's edge
/// (cells of the swath, not inner), `outside` the cells whose top no pulse reaches (beyond
/// the swath, or tall surfaces at its edge seen only from the side), `all` every cell with a
/// reference surface.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DsmReport {
    #[serde(default)]
    pub headline: String,
    #[serde(default)]
    pub edge: CellStats,
    /// Cells with a reference surface whose top no pulse's axis reaches from above.
    #[serde(default)]
    pub outside: CellStats,
    #[serde(default)]
    pub all: CellStats,
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
    swath: &[bool],
    grid: &Grid,
) -> DsmReport {
    // the swath: cells whose top a pulse's axis crosses; inner: with all eight neighbours in it
    let in_swath = |i: i64, j: i64| {
        i >= 0
            && j >= 0
            && (i as usize) < grid.nx
            && (j as usize) < grid.ny
            && swath
                .get(j as usize * grid.nx + i as usize)
                .copied()
                .unwrap_or(false)
    };
    let inner = |k: usize| {
        let (i, j) = ((k % grid.nx.max(1)) as i64, (k / grid.nx.max(1)) as i64);
        (-1..=1).all(|di| (-1..=1).all(|dj| in_swath(i + di, j + dj)))
    };
    let any_inner = (0..reference.len()).any(|k| reference[k].is_finite() && inner(k));
    let (mut all, mut head) = (Group::default(), Group::default());
    let (mut edge, mut outside) = (Group::default(), Group::default());
    let mut bins: Vec<(usize, Sums)> = Vec::new();
    for (k, &r) in reference.iter().enumerate() {
        if !r.is_finite() {
            continue;
        }
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
        let e = m.is_finite().then_some(m - r);
        all.add(e);
        let is_inner = any_inner && inner(k);
        if is_inner || !any_inner {
            head.add(e);
        } else if swath.get(k).copied().unwrap_or(false) {
            edge.add(e);
        } else {
            outside.add(e);
        }
        if let (Some(b), Some(e)) = (bin, e) {
            bins[b].1.add(e);
        }
    }
    let headline = head.stats();
    DsmReport {
        headline: if any_inner { INNER_SWATH } else { ALL_CELLS }.to_string(),
        edge: edge.stats(),
        outside: outside.stats(),
        all: all.stats(),
        bias_m: headline.bias_m,
        rmse_m: headline.rmse_m,
        mae_m: headline.mae_m,
        coverage: headline.coverage,
        cells: headline.cells,
        cells_with_points: headline.cells_with_points,
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

/// Cells with a reference surface and the errors of those with a first return.
#[derive(Default)]
struct Group {
    cells: usize,
    errors: Sums,
}

impl Group {
    fn add(&mut self, error: Option<f64>) {
        self.cells += 1;
        if let Some(e) = error {
            self.errors.add(e);
        }
    }

    fn stats(&self) -> CellStats {
        let s = &self.errors;
        CellStats {
            cells: self.cells,
            cells_with_points: s.n,
            coverage: if self.cells == 0 {
                f64::NAN
            } else {
                s.n as f64 / self.cells as f64
            },
            bias_m: s.mean(s.sum),
            rmse_m: s.mean(s.sum_sq).sqrt(),
            mae_m: s.mean(s.sum_abs),
        }
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
    axes: &crate::products::figures::MapAxes,
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
            "first-return DSM − reference, {} m cells: bias {:+.3} m, RMSE {:.3} m ({})",
            report.resolution_m,
            report.bias_m,
            report.rmse_m,
            report.headline.split(':').next().unwrap_or_default()
        ),
        report.rmse_m,
        axes,
    )
}

/// The DSM error product of a run: reference DSM from the scene's own surfaces, first-return
/// DSM from the points, on one grid over the scanned area; `dsm/report.json` and plots.
/// Built while the points and pulses stream by, so its memory is the grid's: [`Dsm::new`]
/// once the first returns' extent is known, [`Dsm::add_points_and_aim`] over the points and
/// pulses a chunk at a time (in point and pulse order), then [`Dsm::write`].
pub struct Dsm {
    grid: Grid,
    res: f64,
    reference: Vec<f64>,
    /// Height the pulses are aimed at, for the scan-angle attribution.
    ground: f64,
    measured: Vec<f64>,
    angles: Vec<f64>,
    aims: Aims,
    /// The reference's lowest and highest heights.
    heights: (f64, f64),
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
        let span = (
            heights.first().copied().unwrap_or(slo.z),
            heights.last().copied().unwrap_or(shi.z),
        );
        let n = grid.len();
        Some(Dsm {
            grid,
            res,
            reference,
            ground,
            measured: vec![f64::NAN; n],
            angles: vec![f64::NAN; n],
            aims: Aims::new(n),
            heights: span,
        })
    }

    /// The first returns among every chunk of points a pass over them hands it (in point
    /// order), beside the aims of `parts` parts of pulses (`pulses(k)`, in order): two
    /// threads' work, each on fields of its own, where one after the other left a core idle.
    /// Returns what the pass returns.
    pub fn add_points_and_aim<R: Send>(
        &mut self,
        pass: impl FnOnce(&mut dyn FnMut(&[Point])) -> R + Send,
        parts: usize,
        pulses: impl Fn(usize) -> Vec<Pulse> + Sync,
    ) -> R {
        let Dsm {
            grid,
            reference,
            ground,
            measured,
            angles,
            aims,
            heights: (lo, hi),
            ..
        } = self;
        let grid = &*grid;
        let (out, ()) = rayon::join(
            || {
                pass(&mut |points: &[Point]| {
                    let firsts: Vec<DsmPoint> = points.iter().map(DsmPoint::from).collect();
                    add_first_returns(measured, angles, &firsts, grid);
                })
            },
            || {
                for k in 0..parts {
                    let p = pulses(k);
                    aims.add(&p, grid, *ground);
                    aims.cross_tops(&p, grid, reference, *lo, *hi);
                }
            },
        );
        out
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
            &self.aims.swath,
            &self.grid,
        );
        let dir = out.join("dsm");
        let axes = crate::products::figures::MapAxes::of(frame);
        write_report(
            &dir,
            &report,
            &self.reference,
            &self.measured,
            &self.grid,
            &axes,
        )?;
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
        // a figure of no cells (no value, null in the report) reads as "–", not "NaN"
        let fixed = |v: f64, digits: usize, scale: f64| {
            if v.is_finite() {
                format!("{:.digits$}", v * scale)
            } else {
                "–".to_string()
            }
        };
        crate::progress::log(&format!(
            "dsm: bias {} m, RMSE {} m, coverage {}% over {} cells of {} m ({}); the swath's edge: RMSE {} m, coverage {}% over {} cells{}",
            if report.bias_m.is_finite() {
                format!("{:+.3}", report.bias_m)
            } else {
                "–".to_string()
            },
            fixed(report.rmse_m, 3, 1.0),
            fixed(report.coverage, 1, 100.0),
            report.cells,
            self.res,
            report.headline.split(':').next().unwrap_or_default(),
            fixed(report.edge.rmse_m, 3, 1.0),
            fixed(report.edge.coverage, 1, 100.0),
            report.edge.cells,
            match report.outside.cells {
                0 => String::new(),
                n => format!(
                    "; tops no pulse reaches: RMSE {} m over {n} cells",
                    fixed(report.outside.rmse_m, 3, 1.0)
                ),
            },
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
        let r = compare(&reference, &measured, &[], &angle, &[], &grid);
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
        write_report(
            &out,
            &r,
            &reference,
            &measured,
            &grid,
            &crate::products::figures::MapAxes::default(),
        )
        .unwrap();
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
        let r = compare(&reference, &measured, &[], &angle, &[], &grid);
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
        let r = compare(
            &reference,
            &[f64::NAN; 12],
            &[],
            &[f64::NAN; 12],
            &[],
            &grid,
        );
        assert_eq!((r.cells_with_points, r.coverage), (0, 0.0));
        assert!(r.bias_m.is_nan() && r.by_scan_angle.is_empty());
        let json = serde_json::to_string(&r).unwrap();
        assert!(json.contains("\"bias_m\":null"), "{json}");
    }

    /// The headline is over the inner swath: on a 6 x 4 grid whose swath is columns 0-4, the
    /// cells with all eight neighbours in it are (1..=3, 1..=2); the swath's
    /// edge, badly covered and off by 3 m, stays in `edge`, and `all` keeps every cell.
    #[test]
    fn the_headline_is_the_inner_swath() {
        let grid = Grid {
            x0: 0.0,
            y0: 0.0,
            cell: 1.0,
            nx: 6,
            ny: 4,
        };
        let reference = vec![0.0; 24];
        let mut measured = vec![f64::NAN; 24];
        let mut swath = vec![false; 24];
        for j in 0..4 {
            for i in 0..5 {
                swath[j * 6 + i] = true;
                let inner = (1..=3).contains(&i) && (1..=2).contains(&j);
                // inner cells 0.1 m off; the edge off by 3 m where it has a return at all
                measured[j * 6 + i] = if inner {
                    0.1
                } else if (i + j) % 2 == 0 {
                    3.0
                } else {
                    f64::NAN
                };
            }
        }
        let r = compare(&reference, &measured, &[], &[f64::NAN; 24], &swath, &grid);
        assert_eq!(r.headline, INNER_SWATH);
        assert_eq!((r.cells, r.cells_with_points), (6, 6));
        assert!((r.rmse_m - 0.1).abs() < 1e-12 && (r.bias_m - 0.1).abs() < 1e-12);
        // the edge: 20 swath cells less the 6 inner, 7 of them with a return
        assert_eq!((r.edge.cells, r.edge.cells_with_points), (14, 7));
        assert!((r.edge.rmse_m - 3.0).abs() < 1e-12);
        assert_eq!((r.outside.cells, r.outside.cells_with_points), (4, 0));
        assert_eq!((r.all.cells, r.all.cells_with_points), (24, 13));
        // no swath: the headline is every cell
        let r = compare(&reference, &measured, &[], &[f64::NAN; 24], &[], &grid);
        assert_eq!(r.headline, ALL_CELLS);
        assert_eq!((r.cells, r.cells_with_points), (24, 13));
        assert_eq!(r.edge.cells, 0);
    }
}
