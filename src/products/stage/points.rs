//! The points writer: discrete returns spilled to disk part by part with what their summary
//! needs, then read back a chunk at a time into points.las (or .laz), the top view and the
//! DSM, once their extent is known; the figures beside them.

use super::part::{components, Part, Writer};
use crate::campaign::{Loaded, PointsFormat};
use crate::error::{Error, Result};
use crate::plan::Plan;
use crate::products::figures::{self, TopPoint, WaveformFigure};
use crate::products::points::accuracy::DistanceHistogram;
use crate::products::points::las::{write_las_chunks, Extent, Layout};
use crate::products::points::spill::Spill;
use crate::products::points::strips::Strips;
use crate::products::points::Point;
use crate::products::raster::Dsm;
use crate::products::report::summary::{PointsSummary, ProductsSummary};
use crate::scene::{Scene, SurfaceClass};
use crate::waveform::file::Parts;
use crate::waveform::Waveform;
use glam::DVec3;
use std::path::{Path, PathBuf};

pub(super) struct PointsWriter<'a> {
    loaded: &'a Loaded,
    scene: &'a Scene,
    plan: &'a Plan,
    cut: Parts,
    out: &'a Path,
    las: PathBuf,
    /// The DSM's cell size, when the campaign asks for one.
    dsm: Option<f64>,
    spill: Spill,
    extent: Extent,
    tally: PointsTally,
    /// The box of the first returns, for the DSM grid.
    first: Option<(DVec3, DVec3)>,
    examples: Examples,
}

impl<'a> PointsWriter<'a> {
    pub fn new(
        loaded: &'a Loaded,
        scene: &'a Scene,
        plan: &'a Plan,
        cut: Parts,
        out: &'a Path,
        dsm: Option<f64>,
    ) -> Result<PointsWriter<'a>> {
        Ok(PointsWriter {
            loaded,
            scene,
            plan,
            cut,
            out,
            las: out.join(loaded.campaign.points_format().file_name()),
            dsm,
            spill: Spill::create(&out.join("points.spill"))?,
            extent: Extent::default(),
            tally: PointsTally::default(),
            first: None,
            examples: Examples::default(),
        })
    }
}

impl Writer for PointsWriter<'_> {
    fn add(&mut self, part: &Part) -> Result<()> {
        // the first band's points make the summary, the DSM grid and the figures; every
        // band's go into points.las
        let first = part.first_points();
        self.examples.offer(&part.first, first);
        self.tally.add(first);
        self.tally
            .distances
            .add(&crate::products::points::accuracy::distances(
                self.scene, first,
            ));
        for p in first.iter().filter(|p| p.return_number == 1) {
            let v = DVec3::new(p.x, p.y, p.z);
            let (lo, hi) = self.first.get_or_insert((v, v));
            (*lo, *hi) = (lo.min(v), hi.max(v));
        }
        self.extent.add(&self.las, part.points)?;
        self.spill.push(part.points)
    }

    fn finish(self: Box<Self>, summary: &mut ProductsSummary) -> Result<Vec<String>> {
        let PointsWriter {
            loaded,
            scene,
            plan,
            cut,
            out,
            las,
            dsm,
            mut spill,
            extent,
            tally,
            first,
            examples,
        } = *self;
        let c = &loaded.campaign;
        let several = c.wavelength_nm.several();
        let format = c.points_format();
        let mut dsm = dsm.and_then(|res| Dsm::new(scene, first, res));
        let mut top = TopView::new(spill.len());
        let mut strips = Strips::default();
        let (shift, wkt) = match &c.frame {
            Some(f) => (f.origin, Some(f.resolve().map_err(Error::msg)?.1)),
            None => ([0.0; 3], None),
        };
        let offset = extent.offset(&las, shift)?;
        let layout = Layout {
            offset,
            scale: extent.scale(offset, shift),
            shift,
            wkt,
            laz: format == PointsFormat::Laz,
            bands: several,
            gps_offset_s: extent.gps_offset_s(),
        };
        let first_nm = c.wavelength_nm.first() as f32;
        let mut pass = |dsm_points: &mut dyn FnMut(&[Point])| {
            write_las_chunks(&las, &layout, |write| {
                spill.read(|chunk| {
                    write(chunk)?;
                    let first: Vec<Point>;
                    let chunk = if several {
                        let band = chunk.iter().filter(|p| p.wavelength_nm == Some(first_nm));
                        first = band.cloned().collect();
                        &first
                    } else {
                        chunk
                    };
                    top.offer(chunk);
                    strips.add(chunk);
                    dsm_points(chunk);
                    Ok(())
                })
            })
        };
        // the pulses' aims over the DSM's grid are gathered beside the pass over the points
        match &mut dsm {
            Some(d) => d.add_points_and_aim(pass, cut.count(), |k| plan.pulses(cut.range(k))),
            None => pass(&mut |_| {}),
        }?;
        drop(spill);
        let mut outputs = vec![format.file_name().to_string()];
        // the figures and the DSM's files side by side: a few hundredths of a second of one
        // thread each, after the loop where nothing else runs
        let (figures, dsm) = rayon::join(
            || point_figures(loaded, out, examples, top, tally.points),
            || dsm.map_or(Ok(Vec::new()), |d| d.write(out, c.frame.as_ref())),
        );
        outputs.extend(figures?);
        outputs.extend(dsm?);
        summary.points = Some(tally.summary(plan.len()));
        summary.strips = strips.summary();
        Ok(outputs)
    }
}

/// Up to four waveforms worth looking at, kept while the parts stream by: the three with the
/// most returns (earliest first among equals) and the first with a single return.
#[derive(Default)]
struct Examples {
    most: Vec<(u8, u64, Waveform)>,
    single: Option<Waveform>,
}

impl Examples {
    fn offer(&mut self, waveforms: &[&Waveform], points: &[Point]) {
        // each pulse's count of returns, as its last point gives it (a map of them, one
        // insertion a point, was a hundredth of the town survey's products stage)
        let mut returns: Vec<(u64, u8)> = points
            .iter()
            .map(|p| (p.pulse_id, p.number_of_returns))
            .collect();
        returns.reverse();
        returns.sort_by_key(|r| r.0);
        returns.dedup_by_key(|r| r.0);
        for &w in waveforms {
            let Ok(k) = returns.binary_search_by_key(&w.pulse_id, |r| r.0) else {
                continue;
            };
            let n = returns[k].1;
            if n == 1 && self.single.is_none() {
                self.single = Some(w.clone());
            }
            let better = self.most.len() < 3
                || self.most.last().is_some_and(|l| {
                    (n, std::cmp::Reverse(w.pulse_id)) > (l.0, std::cmp::Reverse(l.1))
                });
            if better {
                self.most.push((n, w.pulse_id, w.clone()));
                self.most.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
                self.most.truncate(3);
            }
        }
    }

    fn figures(self, loaded: &Loaded) -> Vec<WaveformFigure> {
        let mut list: Vec<Waveform> = self.most.into_iter().map(|m| m.2).collect();
        if let Some(s) = self.single {
            if !list.iter().any(|w| w.pulse_id == s.pulse_id) {
                list.push(s);
            }
        }
        list.iter()
            .map(|w| WaveformFigure {
                pulse_id: w.pulse_id,
                t0_ns: w.t0_ns,
                bin_ns: w.bin_ns as f64,
                photons: w.laser_photons.clone(),
                components: components(loaded, w),
            })
            .collect()
    }
}

/// `points_top.png` and `waveforms.png` beside points.las; `top` holds the points the top
/// view shows ([`TopView`]), `points` is how many there are in all.
fn point_figures(
    loaded: &Loaded,
    out: &Path,
    examples: Examples,
    top: TopView,
    points: usize,
) -> Result<Vec<String>> {
    figures::points_top_view(
        &out.join("points_top.png"),
        &top.lowest_first(),
        &format!(
            "{}: {} points from above, by apparent reflectance",
            loaded.campaign.name, points
        ),
        &figures::MapAxes::of(loaded.campaign.frame.as_ref()),
    )?;
    let examples = examples.figures(loaded);
    let mut written = vec!["points_top.png".to_string()];
    if !examples.is_empty() {
        figures::waveforms(&out.join("waveforms.png"), &examples)?;
        written.push("waveforms.png".to_string());
    }
    Ok(written)
}

/// The points the top view draws: every `step`-th point, `step` chosen from the number of
/// points so that at most [`figures::TOP_VIEW_MAX_POINTS`] are kept.
struct TopView {
    step: usize,
    seen: usize,
    kept: Vec<(f64, TopPoint)>,
}

impl TopView {
    fn new(points: usize) -> TopView {
        let step = points.div_ceil(figures::TOP_VIEW_MAX_POINTS).max(1);
        TopView {
            step,
            seen: 0,
            kept: Vec::with_capacity(points.div_ceil(step)),
        }
    }

    fn offer(&mut self, points: &[Point]) {
        for p in points {
            if self.seen.is_multiple_of(self.step) {
                let top = TopPoint {
                    x: p.x,
                    y: p.y,
                    reflectance: p.apparent_reflectance as f64,
                };
                self.kept.push((p.z, top));
            }
            self.seen += 1;
        }
    }

    /// Lowest first, so the top of the canopy is what one sees from above.
    fn lowest_first(mut self) -> Vec<TopPoint> {
        self.kept.sort_by(|a, b| a.0.total_cmp(&b.0));
        self.kept.into_iter().map(|t| t.1).collect()
    }
}

/// The points' part of `products.json`, summed as the points stream by: counts, the pulse
/// density over the box the first returns cover, and the distances to the surfaces.
struct PointsTally {
    points: usize,
    by_class: [usize; SurfaceClass::ALL.len()],
    /// The box of the first returns in x and y.
    lo: [f64; 2],
    hi: [f64; 2],
    distances: DistanceHistogram,
}

impl Default for PointsTally {
    fn default() -> PointsTally {
        PointsTally {
            points: 0,
            by_class: [0; SurfaceClass::ALL.len()],
            lo: [f64::MAX; 2],
            hi: [f64::MIN; 2],
            distances: DistanceHistogram::default(),
        }
    }
}

impl PointsTally {
    fn add(&mut self, points: &[Point]) {
        self.points += points.len();
        for p in points {
            if let Some(i) = SurfaceClass::ALL
                .iter()
                .position(|c| c.las_code() == p.classification)
            {
                self.by_class[i] += 1;
            }
            if p.return_number == 1 {
                self.lo = [self.lo[0].min(p.x), self.lo[1].min(p.y)];
                self.hi = [self.hi[0].max(p.x), self.hi[1].max(p.y)];
            }
        }
    }

    fn summary(&self, pulses: usize) -> PointsSummary {
        let (lo, hi) = (self.lo, self.hi);
        let area = ((hi[0] - lo[0]) * (hi[1] - lo[1])).max(0.0);
        let points_by_class = SurfaceClass::ALL
            .iter()
            .zip(self.by_class)
            .map(|(class, n)| (class.las_name().to_string(), n))
            .collect();
        PointsSummary {
            points: self.points,
            points_per_pulse: self.points as f64 / pulses.max(1) as f64,
            area_m2: Some(area).filter(|a| a.is_finite()),
            pulse_density_per_m2: (area > 0.0).then(|| pulses as f64 / area),
            points_by_class,
            surface_distance: self.distances.summary(),
        }
    }
}
