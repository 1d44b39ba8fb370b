//! The DSM error figures: the error map and the error and coverage against scan angle.

use super::{AngleBin, DsmReport, Grid};
use crate::error::Result;
use crate::products::figures::{
    cell_colour, colour_bar, diverging, error_scale, fail, legend, map_chart, png, short, MapAxes,
    GREY_EMPTY, GREY_MISSED,
};
use plotters::prelude::*;
use std::path::Path;

/// `error_map.png`: first-return DSM minus reference per cell, north up, with a colour bar of
/// ± twice the headline RMSE ([`error_scale`]) and the two greys named below it.
pub fn dsm_error_map(
    path: &Path,
    reference: &[f64],
    measured: &[f64],
    grid: &Grid,
    title: &str,
    rmse_m: f64,
    axes: &MapAxes,
) -> Result<()> {
    let aspect = (grid.ny.max(1) as f64 / grid.nx.max(1) as f64).clamp(0.25, 4.0);
    let (w, h) = (800u32, (80.0 + 640.0 * aspect).round().max(420.0) as u32);
    let sat = error_scale(rmse_m);
    png(path, (w, h), |root| {
        let (left, right) = root.split_horizontally(w - 150);
        let (x0, y0) = (grid.x0, grid.y0);
        let (x1, y1) = (
            x0 + grid.cell * grid.nx as f64,
            y0 + grid.cell * grid.ny as f64,
        );
        let mut chart = map_chart(&left, path, title, x0..x1, y0..y1, axes)?;
        chart
            .draw_series((0..grid.ny).flat_map(|j| {
                (0..grid.nx).map(move |i| {
                    let k = grid.nx * j + i;
                    let c = cell_colour(
                        reference.get(k).copied().unwrap_or(f64::NAN),
                        measured.get(k).copied().unwrap_or(f64::NAN),
                        sat,
                    );
                    let (a, b) = (x0 + grid.cell * i as f64, y0 + grid.cell * j as f64);
                    Rectangle::new([(a, b), (a + grid.cell, b + grid.cell)], c.filled())
                })
            }))
            .map_err(|e| fail(path, e))?;
        let (bar, key) = right.split_vertically(right.dim_in_pixel().1.saturating_sub(110));
        colour_bar(&bar, path, -sat, sat, "error (m)", |v| diverging(v / sat))?;
        // the greys, which the bar has not
        for (k, (colour, name)) in [
            (GREY_MISSED, "no first return"),
            (GREY_EMPTY, "no reference"),
        ]
        .into_iter()
        .enumerate()
        {
            let y = 10 + 28 * k as i32;
            key.draw(&Rectangle::new([(8, y), (26, y + 18)], colour.filled()))
                .map_err(|e| fail(path, e))?;
            key.draw(&Text::new(name, (32, y + 2), ("sans-serif", 13)))
                .map_err(|e| fail(path, e))?;
        }
        Ok(())
    })
}

/// `error_vs_scan_angle.png`: bias and RMSE (top) and coverage (bottom) per |scan angle| bin.
pub fn dsm_error_vs_angle(path: &Path, report: &DsmReport) -> Result<()> {
    png(path, (800, 640), |root| {
        let (top, bottom) = root.split_vertically(380);
        let bins = &report.by_scan_angle;
        let centre = |b: &AngleBin| 0.5 * (b.bin_deg_lo + b.bin_deg_hi);
        let xmax = bins.last().map_or(1.0, |b| b.bin_deg_hi).max(1.0);
        let finite = |v: f64| v.is_finite().then_some(v);
        let vals: Vec<f64> = bins
            .iter()
            .flat_map(|b| [finite(b.bias_m), finite(b.rmse_m)])
            .flatten()
            .collect();
        let (lo, hi) = vals
            .iter()
            .fold((0.0f64, 0.0f64), |(a, b), &v| (a.min(v), b.max(v)));
        let pad = 0.1 * (hi - lo).max(1e-3);
        let mut chart = ChartBuilder::on(&top)
            .caption(
                format!(
                    "DSM error against scan angle ({} m cells)",
                    report.resolution_m
                ),
                ("sans-serif", 18),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(65)
            .build_cartesian_2d(0.0..xmax, (lo - pad)..(hi + pad))
            .map_err(|e| fail(path, e))?;
        chart
            .configure_mesh()
            .x_desc("|scan angle| (deg)")
            .y_desc("DSM − reference (m)")
            .x_label_formatter(&short)
            .y_label_formatter(&short)
            .draw()
            .map_err(|e| fail(path, e))?;
        for (name, colour, get) in [
            ("bias", BLUE, (|b: &AngleBin| b.bias_m) as fn(&_) -> f64),
            ("RMSE", RED, |b| b.rmse_m),
        ] {
            let pts: Vec<(f64, f64)> = bins
                .iter()
                .filter_map(|b| finite(get(b)).map(|v| (centre(b), v)))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(|e| fail(path, e))?
                .label(name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                .map_err(|e| fail(path, e))?;
        }
        legend(&mut chart, path)?;

        let mut cov = ChartBuilder::on(&bottom)
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(65)
            .build_cartesian_2d(0.0..xmax, 0.0..105.0)
            .map_err(|e| fail(path, e))?;
        cov.configure_mesh()
            .x_desc("|scan angle| of the pulses aimed at the cell (deg)")
            .y_desc("coverage (%)")
            .draw()
            .map_err(|e| fail(path, e))?;
        let pts: Vec<(f64, f64)> = bins
            .iter()
            .filter_map(|b| finite(b.coverage).map(|v| (centre(b), 100.0 * v)))
            .collect();
        cov.draw_series(LineSeries::new(pts.clone(), GREEN.stroke_width(2)))
            .map_err(|e| fail(path, e))?;
        cov.draw_series(pts.iter().map(|&p| Circle::new(p, 3, GREEN.filled())))
            .map_err(|e| fail(path, e))?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_map_is_a_png_file() {
        let d = crate::testdata::TempDir::new("dsmfig");
        let grid = Grid {
            x0: 0.0,
            y0: 0.0,
            cell: 2.0,
            nx: 5,
            ny: 3,
        };
        let reference = vec![0.0; 15];
        let measured: Vec<f64> = (0..15)
            .map(|k| {
                if k == 4 {
                    f64::NAN
                } else {
                    k as f64 * 0.1 - 0.5
                }
            })
            .collect();
        dsm_error_map(
            &d.join("map.png"),
            &reference,
            &measured,
            &grid,
            "t",
            1.0,
            &MapAxes::default(),
        )
        .unwrap();
        let bytes = std::fs::read(d.join("map.png")).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        let _ = std::fs::remove_dir_all(&d);
    }
}
