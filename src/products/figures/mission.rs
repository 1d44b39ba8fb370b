//! Figures of the mission files: waveforms against elevation with the L2A ground and RH98
//! beside the truth (`l2a_waveforms.png`), and the ATL03 photons as height against
//! along-track distance, coloured by their truth (`atl03_photons.png`).

use super::{fail, legend, png, short};
use crate::error::Result;
use plotters::prelude::*;
use std::path::Path;

/// One shot of [`l2a_waveforms`]: its record and mean waveform (photoelectrons per sample,
/// noise mean removed) against each sample's elevation, and the heights to mark.
#[derive(Clone, Debug)]
pub struct ShotFigure {
    pub pulse_id: u64,
    pub elevation: Vec<f64>,
    pub record: Vec<f64>,
    pub mean: Vec<f64>,
    /// L2A's ground and RH98 (elevations), none without a signal.
    pub ground: Option<f64>,
    pub rh98: Option<f64>,
    pub truth_ground: Option<f64>,
    pub truth_top: Option<f64>,
}

/// `l2a_waveforms.png`: one panel per shot, elevation up, signal across.
pub fn l2a_waveforms(path: &Path, shots: &[ShotFigure]) -> Result<()> {
    let n = shots.len().max(1);
    png(path, (420 * n as u32, 620), |root| {
        let panels = root.split_evenly((1, n));
        for (area, s) in panels.iter().zip(shots) {
            let finite = |v: &&f64| v.is_finite();
            let marks = [s.ground, s.rh98, s.truth_ground, s.truth_top];
            // the stretch with signal (the mean above 1 % of its peak) and the marks, padded
            let peak = s.mean.iter().cloned().fold(0.0f64, f64::max);
            let signal = s
                .elevation
                .iter()
                .zip(&s.mean)
                .filter(|(_, &m)| peak > 0.0 && m >= 0.01 * peak)
                .map(|(z, _)| z);
            let heights = signal.chain(marks.iter().flatten()).filter(finite);
            let (lo, hi) = heights.fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
            let pad = (0.15 * (hi - lo)).max(3.0);
            let (lo, hi) = (lo - pad, hi + pad);
            let (lo, hi) = if lo < hi { (lo, hi) } else { (0.0, 1.0) };
            let xs = s.record.iter().chain(&s.mean).filter(finite);
            let (x0, x1) = xs.fold((0.0f64, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
            let x1 = if x1 > x0 { x1 * 1.05 } else { x0 + 1.0 };
            let mut chart = ChartBuilder::on(area)
                .caption(format!("pulse {}", s.pulse_id), ("sans-serif", 15))
                .margin(8)
                .x_label_area_size(35)
                .y_label_area_size(70)
                .build_cartesian_2d(x0..x1, lo..hi)
                .map_err(|e| fail(path, e))?;
            chart
                .configure_mesh()
                .x_desc("photoelectrons per sample")
                .y_desc("elevation (m)")
                .x_label_formatter(&short)
                .y_label_formatter(&short)
                .draw()
                .map_err(|e| fail(path, e))?;
            let line = |v: &[f64]| -> Vec<(f64, f64)> {
                v.iter()
                    .zip(&s.elevation)
                    .map(|(&x, &z)| (x, z))
                    .filter(|p| p.0.is_finite() && p.1.is_finite())
                    .collect()
            };
            chart
                .draw_series(LineSeries::new(line(&s.record), BLACK.stroke_width(1)))
                .map_err(|e| fail(path, e))?
                .label("record")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
            let blue = RGBColor(40, 90, 200);
            chart
                .draw_series(LineSeries::new(line(&s.mean), blue.stroke_width(2)))
                .map_err(|e| fail(path, e))?
                .label("noise-free mean")
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], blue));
            let marks = [
                (
                    s.ground,
                    RGBColor(150, 90, 30),
                    "L2A ground (lowest mode)",
                    false,
                ),
                (s.rh98, RGBColor(20, 140, 40), "L2A RH98", false),
                (s.truth_ground, RGBColor(150, 90, 30), "truth ground", true),
                (s.truth_top, RGBColor(20, 140, 40), "truth canopy top", true),
            ];
            for (z, colour, name, dashed) in marks {
                let Some(z) = z.filter(|z| z.is_finite()) else {
                    continue;
                };
                let style = colour.stroke_width(if dashed { 2 } else { 3 });
                let pts: Vec<(f64, f64)> = if dashed {
                    // dashes: every other tenth of the width
                    (0..10)
                        .map(|k| x0 + (x1 - x0) * k as f64 / 10.0)
                        .map(|x| (x, z))
                        .collect()
                } else {
                    vec![(x0, z), (x1, z)]
                };
                if dashed {
                    chart
                        .draw_series(pts.chunks(2).map(|c| PathElement::new(c.to_vec(), style)))
                        .map_err(|e| fail(path, e))?
                        .label(name)
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 8, y)], style));
                } else {
                    chart
                        .draw_series(LineSeries::new(pts, style))
                        .map_err(|e| fail(path, e))?
                        .label(name)
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
                }
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .border_style(BLACK)
                .background_style(WHITE.mix(0.8))
                .draw()
                .map_err(|e| fail(path, e))?;
        }
        Ok(())
    })
}

/// One photon of [`atl03_photons`]: along-track distance, height and truth (0 laser, 1
/// solar, 2 dark).
#[derive(Clone, Copy, Debug)]
pub struct PhotonDot {
    pub along: f64,
    pub height: f64,
    pub source: u8,
}

/// `atl03_photons.png`: a ground track's photons, height against along-track distance, in
/// the truth's colours.
pub fn atl03_photons(path: &Path, track: &str, dots: &[PhotonDot]) -> Result<()> {
    let finite: Vec<&PhotonDot> = dots
        .iter()
        .filter(|d| d.along.is_finite() && d.height.is_finite())
        .collect();
    let span = |f: fn(&PhotonDot) -> f64| {
        let (a, b) = finite
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), d| (a.min(f(d)), b.max(f(d))));
        if a < b {
            let pad = 0.03 * (b - a);
            (a - pad)..(b + pad)
        } else {
            0.0..1.0
        }
    };
    let (x, y) = (span(|d| d.along), span(|d| d.height));
    png(path, (900, 520), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!("{track}: {} photon events by their truth", finite.len()),
                ("sans-serif", 16),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x, y)
            .map_err(|e| fail(path, e))?;
        chart
            .configure_mesh()
            .x_desc("along-track distance (m)")
            .y_desc("height (m)")
            .x_label_formatter(&short)
            .y_label_formatter(&short)
            .draw()
            .map_err(|e| fail(path, e))?;
        // noise first, so the laser photons are drawn over it
        for (source, colour, name) in [
            (2u8, RGBColor(120, 120, 120), "dark counts"),
            (1, RGBColor(240, 150, 20), "solar background"),
            (0, RGBColor(20, 140, 40), "laser"),
        ] {
            chart
                .draw_series(
                    finite
                        .iter()
                        .filter(|d| d.source == source)
                        .map(|d| Circle::new((d.along, d.height), 1, colour.filled())),
                )
                .map_err(|e| fail(path, e))?
                .label(name)
                .legend(move |(x, y)| Circle::new((x + 10, y), 4, colour.filled()));
        }
        legend(&mut chart, path)
    })
}
