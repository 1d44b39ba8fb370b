//! The products stage: discrete returns (points.las), photon counts (photons.parquet) and the
//! summary `products.json`, from the simulated waveforms.

use crate::campaign::{InstrumentKind, Loaded, PointsFormat};
use crate::error::{Error, Result};
use crate::fsutil::write_text_atomic;
use crate::parquet_io::Sink;
use crate::plan::Plan;
use crate::products::accuracy::DistanceHistogram;
use crate::products::dsm::Dsm;
use crate::products::figures::{self, TopPoint, WaveformFigure};
use crate::products::las::{write_las_chunks, Extent, Layout};
use crate::products::mission::{Atl03, L1b};
use crate::products::photons::{count_photons, photon_rows, photon_table, PhotonRow};
use crate::products::points::{points_on_axis, Point, PointConfig};
use crate::products::returns::{decompose, place_on_summits, Component, Decomposition, Receiver};
use crate::products::spill::Spill;
use crate::products::summary::{PhotonCounts, PointsSummary, ProductsSummary, WaveformTotals};
use crate::progress::{log, progress};
use crate::rng::SplitMix64;
use crate::scene::{Scene, SurfaceClass};
use crate::sensor::pulse_sigma_s;
use crate::waveform::file::{part_name, read_waveforms_but_impulse, Parts};
use crate::waveform::record::Recorder;
use crate::waveform::Waveform;
use glam::DVec3;
use rayon::prelude::*;
use std::borrow::Cow;
use std::path::Path;

/// The mission-shaped files (campaign.md, "Files of the next wave").
pub const L1B_FILE: &str = "waveforms_l1b.h5";
pub const ATL03_FILE: &str = "photons_atl03.h5";

/// Which products a campaign asks for: its `products:` section, or by instrument kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wanted {
    pub points: bool,
    pub photons: bool,
    pub dsm: Option<f64>,
    /// `waveforms_l1b.h5`: waveform instruments.
    pub l1b: bool,
}

pub fn wanted(loaded: &Loaded) -> Wanted {
    let c = &loaded.campaign;
    let kind = c.instrument.kind;
    match &c.products {
        Some(p) => Wanted {
            points: p.points,
            photons: p.photons,
            dsm: p.dsm.as_ref().map(|d| d.resolution_m),
            l1b: kind == InstrumentKind::Waveform,
        },
        None => Wanted {
            points: kind == InstrumentKind::DiscreteReturn,
            photons: kind == InstrumentKind::PhotonCounting,
            dsm: (kind == InstrumentKind::DiscreteReturn).then_some(2.0),
            l1b: kind == InstrumentKind::Waveform,
        },
    }
}

/// LAS class of a component: the surface class with the most impulse energy within two
/// sigmas of its centre.
fn class_of(w: &Waveform, centre: f64, sigma: f64) -> u8 {
    let lo = (centre - 2.0 * sigma).floor().max(0.0) as usize;
    let hi = ((centre + 2.0 * sigma).ceil() as usize).min(w.laser_photons.len());
    let mut best = (0.0f64, SurfaceClass::Other.las_code());
    for class in SurfaceClass::ALL {
        let code = class.las_code();
        let e = w.class_energy_sum(class.index(), lo, hi);
        if e > best.0 {
            best = (e, code);
        }
    }
    best.1
}

/// The decomposition of one waveform as the campaign asks for it: of the instrument's
/// record (noise, detector response, digitiser) when it has one, else of the mean photons.
/// The components as fitted (the figures draw them).
fn components(loaded: &Loaded, w: &Waveform) -> Vec<Component> {
    decomposed(loaded, w).0
}

/// [`components`], with the photons they were fitted to and the return's sigma in bins.
fn decomposed<'w>(loaded: &Loaded, w: &'w Waveform) -> (Vec<Component>, Cow<'w, [f32]>, f64) {
    let c = &loaded.campaign;
    let inst = &c.instrument;
    let hv = crate::photon_energy_j(band_of(loaded, w));
    // photons per bin of the gate from energies over the span of bins the light reached, as
    // the waveform holds them (zero outside)
    let photons_of = |energies: &[f32]| {
        let mut v = vec![0.0f32; w.laser_photons.len()];
        let span = w.span_first_bin.min(v.len())..v.len();
        for (m, &e) in v[span].iter_mut().zip(energies) {
            *m = (e as f64 / hv) as f32;
        }
        v
    };
    let mc_se = photons_of(&w.impulse_energy_se_j);
    let leaves = photons_of(&w.class_energy_j[SurfaceClass::Vegetation.index()]);
    let band = c.wavelength_nm.index_of(w.wavelength_nm);
    let recorder = Recorder::new(inst, SplitMix64::band_seed(c.seed, band));
    let (photons, sigma_s) = if recorder.changes_returns() {
        let recorded = recorder.laser_photons(&recorder.record(w));
        (
            Cow::Owned(recorded),
            recorder.return_sigma_s(pulse_sigma_s(inst)),
        )
    } else {
        (
            Cow::Borrowed(w.laser_photons.as_slice()),
            pulse_sigma_s(inst),
        )
    };
    let sigma_bins = sigma_s / (inst.bin_ns * 1e-9);
    let receiver = Receiver {
        sigma_bins,
        footprint_edge_sigmas: Some(crate::sensor::footprint_edge_sigmas(inst)),
        noise_floor: recorder.noise_floor_photons(w),
    };
    let comps = decompose(
        &photons,
        &mc_se,
        &leaves,
        inst.detection_threshold_photons,
        inst.max_returns as usize,
        Decomposition::Gaussian,
        &receiver,
    );
    (comps, photons, sigma_bins)
}

/// The wavelength of a waveform row, nm: its band's, or the campaign's.
fn band_of(loaded: &Loaded, w: &Waveform) -> f64 {
    w.wavelength_nm
        .unwrap_or(loaded.campaign.wavelength_nm.first())
}

/// Whether a waveform row is of the campaign's first band: the one the DSM, the mission files,
/// the figures and the summaries are made from.
fn first_band(loaded: &Loaded, w: &Waveform) -> bool {
    w.wavelength_nm
        .is_none_or(|nm| nm == loaded.campaign.wavelength_nm.first())
}

/// Discrete returns of every pulse, in pulse order then time (then band).
pub fn discrete_returns(loaded: &Loaded, plan: &Plan, waveforms: &[Waveform]) -> Vec<Point> {
    let c = &loaded.campaign;
    let inst = &c.instrument;
    let reference_range = if plan.is_empty() {
        1.0
    } else {
        plan.pulse(0).origin.z.abs().max(1.0)
    };
    let by_pulse: Vec<Vec<Point>> = waveforms
        .par_iter()
        .map(|w| {
            let config = PointConfig {
                emitted_energy_j: inst.pulse_energy_j,
                photon_energy_j: crate::photon_energy_j(band_of(loaded, w)),
                telescope_area_m2: inst.receiver_area_m2,
                reference_range_m: reference_range,
            };
            let pulse = &plan.pulse(w.pulse_id);
            // the points where a detector puts the returns: wide ones at their summits
            let (mut comps, photons, sigma_bins) = decomposed(loaded, w);
            place_on_summits(&mut comps, &photons, sigma_bins);
            let classes: Vec<u8> = comps
                .iter()
                .map(|k| class_of(w, k.centre_bin, k.sigma_bins))
                .collect();
            let mut points =
                points_on_axis(pulse, w.t0_ns, w.bin_ns as f64, &comps, &classes, &config);
            for p in &mut points {
                p.wavelength_nm = w.wavelength_nm.map(|nm| nm as f32);
            }
            points
        })
        .collect();
    by_pulse.into_iter().flatten().collect()
}

/// Up to four waveforms worth looking at, kept while the parts stream by: the three with the
/// most returns (earliest first among equals) and the first with a single return.
#[derive(Default)]
struct Examples {
    most: Vec<(u8, u64, Waveform)>,
    single: Option<Waveform>,
}

impl Examples {
    fn offer(&mut self, waveforms: &[Waveform], points: &[Point]) {
        // each pulse's count of returns, as its last point gives it (a map of them, one
        // insertion a point, was a hundredth of the town survey's products stage)
        let mut returns: Vec<(u64, u8)> = points
            .iter()
            .map(|p| (p.pulse_id, p.number_of_returns))
            .collect();
        returns.reverse();
        returns.sort_by_key(|r| r.0);
        returns.dedup_by_key(|r| r.0);
        for w in waveforms {
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

/// Photon events of every pulse (photon counting), deterministic per (seed, pulse).
pub fn photon_events(loaded: &Loaded, plan: &Plan, waveforms: &[Waveform]) -> Vec<PhotonRow> {
    let c = &loaded.campaign;
    let inst = &c.instrument;
    let first = if plan.is_empty() {
        DVec3::ZERO
    } else {
        plan.pulse(0).origin
    };
    let by_pulse: Vec<Vec<PhotonRow>> = waveforms
        .par_iter()
        .map(|w| {
            let pulse = &plan.pulse(w.pulse_id);
            let events = count_photons(
                &w.laser_photons,
                w.solar_photons_per_bin as f64,
                w.bin_ns as f64 * 1e-9,
                inst.quantum_efficiency.unwrap_or(1.0),
                inst.dark_count_hz.unwrap_or(0.0),
                inst.dead_time_ns.unwrap_or(0.0) * 1e-9,
                SplitMix64::band_seed(c.seed, c.wavelength_nm.index_of(w.wavelength_nm)),
                w.pulse_id,
            );
            let along = (pulse.origin - first).truncate().length();
            let mut rows = photon_rows(pulse, w.t0_ns, &events, along);
            for r in &mut rows {
                r.wavelength_nm = w.wavelength_nm;
            }
            rows
        })
        .collect();
    by_pulse.into_iter().flatten().collect()
}

/// Runs the products stage; returns the files written (relative to `out`) and a note.
///
/// Memory is bounded by a part and the scene, not by the campaign's length: the first pass
/// reads the waveforms a part at a time, writes photons as they come and spills the points to
/// disk with what their summary needs; the second reads the points back a chunk at a time
/// into points.las, the top view and the DSM, once their extent is known.
pub fn run(
    loaded: &Loaded,
    scene: &Scene,
    out: &Path,
    plan: &Plan,
    cut: Parts,
) -> Result<(Vec<String>, String)> {
    let parts = cut.count();
    let want = wanted(loaded);
    let c = &loaded.campaign;
    let several = c.wavelength_nm.several();
    let format = c.points_format();
    let las_path = out.join(format.file_name());
    let mut points = if want.points {
        Some(PointsPass::new(&out.join("points.spill"))?)
    } else {
        None
    };
    let mut photons = PhotonsPass::default();
    let photons_path = out.join("photons.parquet");
    let recorder = Recorder::new(&c.instrument, c.seed);
    let mut l1b = if want.l1b {
        Some(L1b::create(
            &out.join(L1B_FILE),
            &c.name,
            c.frame.as_ref(),
            pulse_sigma_s(&c.instrument),
            c.instrument.digitiser.is_some(),
            c.instrument.detection_threshold_photons,
        )?)
    } else {
        None
    };
    let mut atl03 = if want.photons {
        Some(Atl03::create(
            &out.join(ATL03_FILE),
            &c.name,
            c.frame.as_ref(),
        )?)
    } else {
        None
    };
    let (mut examples, mut seen) = (Examples::default(), 0usize);
    let mut totals = WaveformTotals::default();
    let bar = progress(plan.len() as u64, "products");
    let start = std::time::Instant::now();
    let every = parts.div_ceil(10).max(1);
    // Part k + 1 is read and decoded while part k is decomposed, as two halves of one rayon
    // join, as the simulate stage writes: the same threads do both, so no core waits for a
    // reader (a reader thread beside the workers made the loop wait for it a tenth of its
    // time on the town survey, whenever it lost its share of the cores to them)
    let read = |k: usize, spare| read_waveforms_but_impulse(&out.join(part_name(k)), spare);
    let mut next = (parts > 0).then(|| read(0, Vec::new()));
    // The part before lends its buffers to the reading of the next.
    let mut previous: Option<Vec<Waveform>> = None;
    for k in 0..parts {
        if let Some(signal) = crate::interrupt::requested() {
            return Err(Error::interrupted(
                signal,
                "the products stage stopped before writing anything; the waveforms are kept",
            ));
        }
        crate::progress::release_after_part(k);
        let Some(part) = next.take() else {
            break;
        };
        let part = part?;
        let finished = previous.take();
        let (ahead, done) = rayon::join(
            || (k + 1 < parts).then(|| read(k + 1, finished.unwrap_or_default())),
            || -> Result<()> {
                if part.iter().any(|w| w.pulse_id as usize >= plan.len()) {
                    return Err(Error::msg(format!(
                        "{}: waveforms of pulses that were not planned: run again without --resume",
                        out.display()
                    )));
                }
                // with several bands, the rows of the first band (all rows with one) make the
                // products of one band; points and photons are made in every band
                let first: Vec<&Waveform> = part.iter().filter(|w| first_band(loaded, w)).collect();
                let pulses_in_part = first.len();
                seen += pulses_in_part;
                for w in &first {
                    totals.add(w);
                }
                if let Some(pass) = &mut points {
                    let p = discrete_returns(loaded, plan, &part);
                    let of_first = |p: &Point| {
                        p.wavelength_nm
                            .is_none_or(|nm| nm == c.wavelength_nm.first() as f32)
                    };
                    if several {
                        let first_points: Vec<Point> =
                            p.iter().filter(|p| of_first(p)).cloned().collect();
                        let first_rows: Vec<Waveform> =
                            first.iter().map(|w| (*w).clone()).collect();
                        examples.offer(&first_rows, &first_points);
                        pass.tally_first_band(scene, &first_points);
                    } else {
                        examples.offer(&part, &p);
                        pass.tally_first_band(scene, &p);
                    }
                    pass.add(&las_path, &p)?;
                }
                if want.photons {
                    let events = photon_events(loaded, plan, &part);
                    if let Some(a) = &mut atl03 {
                        let first_events = events.iter().filter(|r| {
                            r.wavelength_nm
                                .is_none_or(|nm| nm == c.wavelength_nm.first())
                        });
                        let first_events: Vec<PhotonRow> = first_events.copied().collect();
                        for rows in first_events.chunk_by(|a, b| a.pulse_id == b.pulse_id) {
                            a.add(&plan.pulse(rows[0].pulse_id), rows)?;
                        }
                    }
                    photons.add(&photons_path, &events, several)?;
                }
                if let Some(l) = &mut l1b {
                    let records: Vec<_> = first.par_iter().map(|w| recorder.record(w)).collect();
                    for (w, r) in first.iter().zip(&records) {
                        l.add(&plan.pulse(w.pulse_id), w, r)?;
                    }
                }
                bar.inc(pulses_in_part as u64);
                if bar.is_hidden() && (k + 1) % every == 0 && k + 1 < parts {
                    let rate = seen as f64 / start.elapsed().as_secs_f64().max(1e-9);
                    log(&format!(
                        "products: {}/{} parts, {rate:.0} pulses/s, {:.0} s left",
                        k + 1,
                        parts,
                        (plan.len() - seen.min(plan.len())) as f64 / rate
                    ));
                }
                Ok(())
            },
        );
        done?;
        next = ahead;
        previous = Some(part);
    }
    bar.finish_and_clear();
    if seen != plan.len() {
        return Err(Error::msg(format!(
            "{}: {seen} waveforms for {} planned pulses: run again with --resume",
            out.display(),
            plan.len()
        )));
    }
    let mut outputs = Vec::new();
    let mut summary = ProductsSummary {
        pulses: plan.len(),
        waveform_totals: Some(totals),
        ..Default::default()
    };
    if let Some(pass) = points {
        let mut dsm = want.dsm.and_then(|res| Dsm::new(scene, pass.first, res));
        let mut top = TopView::new(pass.spill.len());
        let (shift, wkt) = match &c.frame {
            Some(f) => (f.origin, Some(f.resolve().map_err(Error::msg)?.1)),
            None => ([0.0; 3], None),
        };
        let layout = Layout {
            offset: pass.extent.offset(&las_path, shift)?,
            shift,
            wkt,
            laz: format == PointsFormat::Laz,
            bands: several,
        };
        let PointsPass {
            mut spill, tally, ..
        } = pass;
        let first_nm = c.wavelength_nm.first() as f32;
        write_las_chunks(&las_path, &layout, |write| {
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
                if let Some(d) = &mut dsm {
                    d.add_points(chunk);
                }
                Ok(())
            })
        })?;
        drop(spill);
        outputs.push(format.file_name().to_string());
        // the figures and the DSM side by side: a few hundredths of a second of one thread
        // each, after the loop where nothing else runs
        let (figures, dsm) = rayon::join(
            || point_figures(loaded, out, examples, top, tally.points),
            || -> Result<Vec<String>> {
                let Some(mut d) = dsm else {
                    return Ok(Vec::new());
                };
                for k in 0..parts {
                    d.aim(&plan.pulses(cut.range(k)));
                }
                d.write(out, c.frame.as_ref())
            },
        );
        outputs.extend(figures?);
        outputs.extend(dsm?);
        summary.points = Some(tally.summary(plan.len()));
    }
    if want.photons {
        let counts = photons.finish(&photons_path, plan.len(), several)?;
        outputs.push("photons.parquet".to_string());
        summary.photons = Some(counts);
    }
    if let Some(a) = atl03 {
        a.finish()?;
        outputs.push(ATL03_FILE.to_string());
    }
    if let Some(l) = l1b {
        l.finish()?;
        outputs.push(L1B_FILE.to_string());
    }
    write_text_atomic(&out.join("products.json"), &summary.to_json())?;
    outputs.push("products.json".to_string());
    let note = if !want.points && !want.photons {
        "the waveforms are the product"
    } else {
        ""
    };
    Ok((outputs, note.to_string()))
}

/// The first pass's work on the points: spilled to disk, with what points.las, the DSM and
/// `products.json` need of them gathered on the way.
struct PointsPass {
    spill: Spill,
    extent: Extent,
    tally: PointsTally,
    /// The box of the first returns, for the DSM grid.
    first: Option<(DVec3, DVec3)>,
}

impl PointsPass {
    fn new(spill: &Path) -> Result<PointsPass> {
        Ok(PointsPass {
            spill: Spill::create(spill)?,
            extent: Extent::default(),
            tally: PointsTally::default(),
            first: None,
        })
    }

    /// Points of every band, into points.las.
    fn add(&mut self, las: &Path, points: &[Point]) -> Result<()> {
        self.extent.add(las, points)?;
        self.spill.push(points)
    }

    /// The first band's points, into the summary and the DSM grid.
    fn tally_first_band(&mut self, scene: &Scene, points: &[Point]) {
        self.tally.add(points);
        self.tally
            .distances
            .add(&crate::products::accuracy::distances(scene, points));
        for p in points.iter().filter(|p| p.return_number == 1) {
            let v = DVec3::new(p.x, p.y, p.z);
            let (lo, hi) = self.first.get_or_insert((v, v));
            (*lo, *hi) = (lo.min(v), hi.max(v));
        }
    }
}

/// The photons, written a part at a time, and their counts by source.
#[derive(Default)]
struct PhotonsPass {
    sink: Option<Sink>,
    /// Rows by source: laser, solar, dark.
    by_source: [usize; 3],
    total: usize,
}

impl PhotonsPass {
    fn add(&mut self, path: &Path, rows: &[PhotonRow], bands: bool) -> Result<()> {
        let table = photon_table(rows, bands);
        let sink = match &mut self.sink {
            Some(s) => s,
            None => self.sink.insert(Sink::create(path, table.schema())?),
        };
        sink.write(&table)?;
        for r in rows {
            if let Some(n) = self.by_source.get_mut(r.source as usize) {
                *n += 1;
            }
        }
        self.total += rows.len();
        Ok(())
    }

    fn finish(mut self, path: &Path, pulses: usize, bands: bool) -> Result<PhotonCounts> {
        if self.sink.is_none() {
            self.add(path, &[], bands)?;
        }
        if let Some(s) = self.sink {
            s.finish()?;
        }
        let [laser, solar, dark] = self.by_source;
        Ok(PhotonCounts {
            total: self.total,
            laser,
            solar,
            dark,
            laser_per_shot: laser as f64 / pulses.max(1) as f64,
        })
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
