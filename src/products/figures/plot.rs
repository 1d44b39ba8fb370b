//! Line plots as SVG (a sweep's signal and BRFs, `compare --plots`), drawn with plotters
//! like every other figure: SVG because a browser or any image viewer shows it and its text
//! stays text.

use crate::error::{Error, Result};
use crate::products::figures::{register_font, short};
use plotters::prelude::*;
use std::path::Path;

pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

/// The range an axis shows: the values' span, widened when it is empty, padded by 8 %, and
/// starting at zero when the values are positive and zero is near.
fn axis(values: impl Iterator<Item = f64>, pad_to_zero: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for v in values {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return (0.0, 1.0);
    }
    if hi <= lo {
        let half = lo.abs().max(1.0) * 0.05;
        return (lo - half, hi + half);
    }
    let pad = (hi - lo) * 0.08;
    let lo = if pad_to_zero && lo >= 0.0 && lo - pad < 0.0 {
        0.0
    } else {
        lo - pad
    };
    (lo, hi + pad)
}

/// One plot: lines with markers, axes with ticks and labels, a legend. `path` is where the
/// SVG will go, for messages.
pub fn line_plot(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<String> {
    register_font();
    let fail = |e: &dyn std::fmt::Display| Error::data(path, format!("cannot draw: {e}"));
    let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
    let all = || series.iter().flat_map(|s| s.points.iter().filter(finite));
    let (x0, x1) = axis(all().map(|p| p.0), false);
    let (y0, y1) = axis(all().map(|p| p.1), true);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (640, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| fail(&e))?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .x_label_formatter(&short)
            .y_label_formatter(&short)
            .draw()
            .map_err(|e| fail(&e))?;
        for (k, s) in series.iter().enumerate() {
            let colour = Palette99::pick(k).to_rgba();
            let points: Vec<(f64, f64)> = s.points.iter().filter(finite).copied().collect();
            chart
                .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
                .map_err(|e| fail(&e))?
                .label(s.name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
            chart
                .draw_series(points.iter().map(|p| Circle::new(*p, 3, colour.filled())))
                .map_err(|e| fail(&e))?;
        }
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(|e| fail(&e))?;
        root.present().map_err(|e| fail(&e))?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plot_is_an_svg_with_its_points_and_escaped_text() {
        let s = line_plot(
            Path::new("t.svg"),
            "t <1>",
            "x",
            "y",
            &[Series {
                name: "a".into(),
                points: vec![(0.0, 1.0), (1.0, 3.0), (2.0, f64::NAN)],
            }],
        )
        .unwrap();
        assert!(
            s.starts_with("<svg") && s.trim_end().ends_with("</svg>"),
            "{s}"
        );
        assert!(s.contains("t &lt;1&gt;"), "{s}");
        // the two finite points as markers, the NaN left out
        assert_eq!(s.matches("<circle").count(), 2, "{s}");
        assert_eq!(axis([2.0, 2.0].into_iter(), true), (1.9, 2.1));
        assert_eq!(axis(std::iter::empty(), true), (0.0, 1.0));
    }
}
