//! PNG figures of a run's products (plotters): the DSM error map, DSM error and coverage
//! against scan angle, the point cloud from above coloured by apparent reflectance, and a few
//! waveforms with their fitted components. Text needs a font: DejaVu Sans ships in `assets/`
//! and is compiled in, so no system font library is needed.

pub mod mission;
pub mod plot;

use crate::error::{Error, Result};
use crate::products::returns::Component;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

const FONT: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

pub(crate) fn register_font() {
    REGISTER.call_once(|| {
        // The font is compiled in and known to parse; a failure would only lose the text.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

pub(crate) type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// Draws a PNG under a temporary name (ending in .png, which the backend needs) and moves it
/// into place, so a crash never leaves half a figure under the final name.
pub(crate) fn png(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&Area) -> Result<()>,
) -> Result<()> {
    register_font();
    crate::fsutil::write_atomic_at(path, ".png", |tmp| {
        let root = BitMapBackend::new(tmp, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(path, e))?;
        draw(&root)?;
        root.present().map_err(|e| fail(path, e))
    })
}

/// Axis labels: short, with an exponent when the values are large or small.
pub(crate) fn short(v: &f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-2..1e5).contains(&a) {
        format!("{v:.1e}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

pub(crate) fn fail(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::file(path, format!("cannot draw the figure: {e}"))
}

/// The error map's smallest scale, ± m (see [`error_scale`]).
pub const MAP_SATURATION_M: f64 = 1.0;
/// No first return where the reference has a surface: a blind spot.
pub const GREY_MISSED: RGBColor = RGBColor(128, 128, 128);
/// No reference surface.
pub const GREY_EMPTY: RGBColor = RGBColor(64, 64, 64);

/// Blue (−1) through white (0) to red (+1).
pub fn diverging(t: f64) -> RGBColor {
    let t = if t.is_nan() { 0.0 } else { t.clamp(-1.0, 1.0) };
    let fade = |a: f64| (255.0 * (1.0 - a)).round() as u8;
    if t < 0.0 {
        RGBColor(fade(-t), fade(-t), 255)
    } else {
        RGBColor(255, fade(t), fade(t))
    }
}

/// Colour of one DSM cell: the error on the diverging scale of ± `saturation` m, or a grey
/// for a blind spot (a reference surface with no first return) or for no reference at all.
pub fn cell_colour(reference: f64, measured: f64, saturation: f64) -> RGBColor {
    if !reference.is_finite() {
        GREY_EMPTY
    } else if !measured.is_finite() {
        GREY_MISSED
    } else {
        diverging((measured - reference) / saturation)
    }
}

/// The error map's scale, ± m: twice the RMSE, at least [`MAP_SATURATION_M`], rounded up to
/// 1, 2 or 5 times a power of ten, so the RMSE sits halfway up the colour bar.
pub fn error_scale(rmse_m: f64) -> f64 {
    let want = if rmse_m.is_finite() {
        (2.0 * rmse_m).max(MAP_SATURATION_M)
    } else {
        MAP_SATURATION_M
    };
    let p = 10f64.powf(want.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * p)
        .find(|&v| v >= want * (1.0 - 1e-12))
        .unwrap_or(want)
}

/// A perceptual ramp for reflectance (dark blue → green → yellow), t in [0, 1].
pub fn ramp(t: f64) -> RGBColor {
    const STOPS: [(f64, [f64; 3]); 5] = [
        (0.0, [68.0, 1.0, 84.0]),
        (0.25, [59.0, 82.0, 139.0]),
        (0.5, [33.0, 145.0, 140.0]),
        (0.75, [94.0, 201.0, 98.0]),
        (1.0, [253.0, 231.0, 37.0]),
    ];
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let k = STOPS.iter().position(|s| s.0 >= t).unwrap_or(4).max(1);
    let (a, b) = (STOPS[k - 1], STOPS[k]);
    let f = (t - a.0) / (b.0 - a.0);
    let c = |i: usize| (a.1[i] + f * (b.1[i] - a.1[i])).round() as u8;
    RGBColor(c(0), c(1), c(2))
}

/// A vertical colour bar from `lo` to `hi` with its label.
pub(crate) fn colour_bar(
    area: &Area,
    path: &Path,
    lo: f64,
    hi: f64,
    label: &str,
    colour: impl Fn(f64) -> RGBColor,
) -> Result<()> {
    // Tick labels drawn as text beside the bar: the mesh's own labels come out tiny on an
    // axis this narrow.
    let mut chart = ChartBuilder::on(area)
        .caption(label, ("sans-serif", 13))
        .margin_top(10)
        .margin_bottom(50)
        .margin_right(5)
        .build_cartesian_2d(0.0..2.6, lo..hi)
        .map_err(|e| fail(path, e))?;
    chart
        .draw_series((0..=4).map(|k| {
            let v = lo + (hi - lo) * k as f64 / 4.0;
            Text::new(short(&v), (1.1, v), ("sans-serif", 13))
        }))
        .map_err(|e| fail(path, e))?;
    let steps = 100;
    chart
        .draw_series((0..steps).map(|k| {
            let (a, b) = (
                lo + (hi - lo) * k as f64 / steps as f64,
                lo + (hi - lo) * (k + 1) as f64 / steps as f64,
            );
            Rectangle::new([(0.0, a), (1.0, b)], colour(0.5 * (a + b)).filled())
        }))
        .map_err(|e| fail(path, e))?;
    Ok(())
}

pub(crate) type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The series' legend, boxed, in the chart's corner.
pub(crate) fn legend<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>, path: &Path) -> Result<()> {
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()
        .map_err(|e| fail(path, e))
}

/// How a map's axes are labelled: in the frame's easting and northing (the scene's x and y
/// plus the frame's origin) when the campaign has a frame, else in scene metres.
#[derive(Clone, Debug, Default)]
pub struct MapAxes {
    pub east0: f64,
    pub north0: f64,
    pub crs: Option<String>,
}

impl MapAxes {
    pub fn of(frame: Option<&crate::campaign::Frame>) -> MapAxes {
        frame.map_or_else(MapAxes::default, |f| MapAxes {
            east0: f.origin[0],
            north0: f.origin[1],
            crs: Some(f.crs.clone()),
        })
    }
}

/// A map in scene coordinates (x, y in metres), its axes labelled as `axes` says.
pub(crate) fn map_chart<'a, 'b>(
    area: &'a Area<'b>,
    path: &Path,
    title: &str,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
    axes: &MapAxes,
) -> Result<Chart<'a, 'b>> {
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(75)
        .build_cartesian_2d(x, y)
        .map_err(|e| fail(path, e))?;
    let (x_desc, y_desc) = match &axes.crs {
        Some(c) => (format!("easting (m, {c})"), format!("northing (m, {c})")),
        None => ("x (m)".to_string(), "y (m)".to_string()),
    };
    // whole metres of a projected CRS, in full: 6459925, not 6.5e6
    let label = |v: f64| {
        if axes.crs.is_some() {
            format!("{v:.0}")
        } else {
            short(&v)
        }
    };
    let (e0, n0) = (axes.east0, axes.north0);
    chart
        .configure_mesh()
        .disable_x_mesh()
        .disable_y_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&|v: &f64| label(v + e0))
        .y_label_formatter(&|v: &f64| label(v + n0))
        .draw()
        .map_err(|e| fail(path, e))?;
    Ok(chart)
}

/// A point of the top view: position and apparent reflectance.
#[derive(Clone, Copy, Debug)]
pub struct TopPoint {
    pub x: f64,
    pub y: f64,
    pub reflectance: f64,
}

/// Most points drawn in the top view: beyond, every k-th point. 100,000 dots of at least
/// 3 x 3 pixels fill the plot's 650 x 640 pixels, so more would not change the picture, only
/// the memory the products stage needs (a fixed few MB, whatever the campaign's length).
pub const TOP_VIEW_MAX_POINTS: usize = 100_000;

/// `points_top.png`: every first return seen from above, coloured by apparent reflectance
/// (the colour scale runs to the 99th percentile, so a few specular outliers do not wash
/// the rest out).
pub fn points_top_view(
    path: &Path,
    points: &[TopPoint],
    title: &str,
    axes: &MapAxes,
) -> Result<()> {
    let step = points.len().div_ceil(TOP_VIEW_MAX_POINTS).max(1);
    let shown: Vec<TopPoint> = points
        .iter()
        .step_by(step)
        .copied()
        .filter(|p| p.x.is_finite() && p.y.is_finite())
        .collect();
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for p in &shown {
        lo = [lo[0].min(p.x), lo[1].min(p.y)];
        hi = [hi[0].max(p.x), hi[1].max(p.y)];
    }
    if shown.is_empty() {
        (lo, hi) = ([0.0; 2], [1.0; 2]);
    }
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-3);
    let mut refl: Vec<f64> = shown
        .iter()
        .map(|p| p.reflectance)
        .filter(|r| r.is_finite())
        .collect();
    refl.sort_by(f64::total_cmp);
    let top = refl
        .get((refl.len() * 99) / 100)
        .copied()
        .unwrap_or(1.0)
        .max(1e-6);
    let aspect = ((hi[1] - lo[1]) / (hi[0] - lo[0]).max(1e-3)).clamp(0.25, 4.0);
    let (w, h) = (760u32, (80.0 + 640.0 * aspect).round() as u32);
    let radius = if shown.len() > 50_000 { 1 } else { 2 };
    png(path, (w, h), |root| {
        let (left, right) = root.split_horizontally(w - 110);
        let pad = 0.02 * span;
        let mut chart = map_chart(
            &left,
            path,
            title,
            (lo[0] - pad)..(hi[0] + pad),
            (lo[1] - pad)..(hi[1] + pad),
            axes,
        )?;
        chart
            .draw_series(
                shown
                    .iter()
                    .map(|p| Circle::new((p.x, p.y), radius, ramp(p.reflectance / top).filled())),
            )
            .map_err(|e| fail(path, e))?;
        colour_bar(&right, path, 0.0, top, "apparent reflectance", |v| {
            ramp(v / top)
        })
    })
}

/// One waveform for [`waveforms`]: its time axis, photons per bin and fitted components.
#[derive(Clone, Debug)]
pub struct WaveformFigure {
    pub pulse_id: u64,
    pub t0_ns: f64,
    pub bin_ns: f64,
    pub photons: Vec<f32>,
    pub components: Vec<Component>,
}

/// `waveforms.png`: a few waveforms (photons per bin against range) with each fitted
/// Gaussian component and their sum, one panel each.
pub fn waveforms(path: &Path, list: &[WaveformFigure]) -> Result<()> {
    let n = list.len().max(1);
    png(path, (800, 60 + 240 * n as u32), |root| {
        let panels = root.split_evenly((n, 1));
        for (area, w) in panels.iter().zip(list) {
            let range = |bin: f64| crate::C * (w.t0_ns + bin * w.bin_ns) * 1e-9 / 2.0;
            // only the part of the gate with signal, and a margin
            let nz: Vec<usize> = (0..w.photons.len())
                .filter(|&i| w.photons[i] > 1e-3 * w.photons.iter().cloned().fold(0.0, f32::max))
                .collect();
            let (a, b) = match (nz.first(), nz.last()) {
                (Some(&a), Some(&b)) => (a.saturating_sub(5), (b + 6).min(w.photons.len())),
                _ => (0, w.photons.len()),
            };
            let ymax = w.photons[a..b].iter().cloned().fold(0.0f32, f32::max) as f64 * 1.1;
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!("pulse {}: {} component(s)", w.pulse_id, w.components.len()),
                    ("sans-serif", 15),
                )
                .margin(8)
                .x_label_area_size(35)
                .y_label_area_size(70)
                .build_cartesian_2d(range(a as f64)..range(b as f64), 0.0..ymax.max(1e-9))
                .map_err(|e| fail(path, e))?;
            chart
                .configure_mesh()
                .x_desc("range (m)")
                .y_desc("photons per bin")
                .x_label_formatter(&short)
                .y_label_formatter(&short)
                .draw()
                .map_err(|e| fail(path, e))?;
            let data: Vec<(f64, f64)> = (a..b)
                .map(|i| (range(i as f64 + 0.5), w.photons[i] as f64))
                .collect();
            chart
                .draw_series(LineSeries::new(data, BLACK.stroke_width(2)))
                .map_err(|e| fail(path, e))?
                .label("waveform")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
            let gauss = |c: &Component, x: f64| {
                let z = (x - c.centre_bin) / c.sigma_bins;
                c.amplitude * (-0.5 * z * z).exp()
            };
            let fine: Vec<f64> = (0..=(b - a) * 8)
                .map(|k| a as f64 + k as f64 / 8.0)
                .collect();
            // the sum first, so every component shows above it
            if w.components.len() > 1 {
                chart
                    .draw_series(LineSeries::new(
                        fine.iter()
                            .map(|&x| (range(x), w.components.iter().map(|c| gauss(c, x)).sum())),
                        RED.stroke_width(1),
                    ))
                    .map_err(|e| fail(path, e))?
                    .label("sum of fits")
                    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
            }
            for (k, c) in w.components.iter().enumerate() {
                let colour = Palette99::pick(k + 1).to_rgba();
                chart
                    .draw_series(LineSeries::new(
                        fine.iter().map(|&x| (range(x), gauss(c, x))),
                        colour.stroke_width(2),
                    ))
                    .map_err(|e| fail(path, e))?
                    .label(format!("return {}", k + 1))
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
            }
            legend(&mut chart, path)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours() {
        assert_eq!(cell_colour(0.0, -2.0, 1.0), RGBColor(0, 0, 255));
        assert_eq!(cell_colour(0.0, 0.0, 1.0), RGBColor(255, 255, 255));
        assert_eq!(cell_colour(0.0, 0.5, 1.0), RGBColor(255, 128, 128));
        assert_eq!(cell_colour(0.0, 1.0, 2.0), RGBColor(255, 128, 128));
        assert_eq!(cell_colour(f64::NAN, 1.0, 1.0), GREY_EMPTY);
        assert_eq!(cell_colour(0.0, f64::NAN, 1.0), GREY_MISSED);
        // the error map's scale: twice the RMSE, at least 1 m, to 1, 2 or 5 x 10^k
        assert_eq!(error_scale(0.2), 1.0);
        assert_eq!(error_scale(0.75), 2.0);
        assert_eq!(error_scale(1.0), 2.0);
        assert_eq!(error_scale(4.5), 10.0);
        assert_eq!(error_scale(f64::NAN), 1.0);
        assert_eq!(ramp(0.0), RGBColor(68, 1, 84));
        assert_eq!(ramp(1.0), RGBColor(253, 231, 37));
        assert_eq!(ramp(0.5), RGBColor(33, 145, 140));
    }

    #[test]
    fn figures_are_png_files() {
        let d = crate::testdata::TempDir::new("fig");
        let pts: Vec<TopPoint> = (0..100)
            .map(|k| TopPoint {
                x: k as f64,
                y: (k % 7) as f64,
                reflectance: k as f64 / 100.0,
            })
            .collect();
        points_top_view(&d.join("top.png"), &pts, "t", &MapAxes::default()).unwrap();
        let c = Component {
            centre_bin: 20.0,
            sigma_bins: 2.0,
            area_photons: 100.0,
            amplitude: 100.0 / (2.0 * (2.0 * std::f64::consts::PI).sqrt()),
            one_surface: false,
        };
        let photons: Vec<f32> = (0..40)
            .map(|i| (c.amplitude * (-0.5 * ((i as f64 + 0.5 - 20.0) / 2.0).powi(2)).exp()) as f32)
            .collect();
        waveforms(
            &d.join("wf.png"),
            &[WaveformFigure {
                pulse_id: 3,
                t0_ns: 1000.0,
                bin_ns: 1.0,
                photons,
                components: vec![c],
            }],
        )
        .unwrap();
        for f in ["top.png", "wf.png"] {
            let b = std::fs::read(d.join(f)).unwrap();
            assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{f}");
            assert!(b.len() > 2000, "{f}: {} bytes", b.len());
        }
        // nothing left under a temporary name
        let left: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().contains(".tmp-"))
            .collect();
        assert!(left.is_empty());
        let _ = std::fs::remove_dir_all(&d);
    }
}
