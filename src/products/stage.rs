//! The products stage: discrete returns (points.las), photon counts (photons.parquet) and the
//! summary `products.json`, from the simulated waveforms.

use crate::campaign::{InstrumentKind, Loaded};
use crate::error::{Error, Result};
use crate::fsutil::write_text_atomic;
use crate::plan::Pulse;
use crate::products::figures::{self, TopPoint, WaveformFigure};
use crate::products::las::write_las;
use crate::products::photons::{count_photons, photon_rows, write_photons, PhotonRow};
use crate::products::points::{points_on_axis, Point, PointConfig};
use crate::products::returns::{decompose, Component, Decomposition};
use crate::products::summary::{PhotonCounts, PointsSummary, ProductsSummary};
use crate::progress::{log, progress};
use crate::scene::{Scene, SurfaceClass};
use crate::sensor::pulse_sigma_s;
use crate::waveform::file::{part_name, read_waveforms};
use crate::waveform::Waveform;
use rayon::prelude::*;
use std::path::Path;

/// Which products a campaign asks for: its `products:` section, or by instrument kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wanted {
    pub points: bool,
    pub photons: bool,
    pub dsm: Option<f64>,
}

pub fn wanted(loaded: &Loaded) -> Wanted {
    let c = &loaded.campaign;
    let kind = c.instrument.kind;
    match &c.products {
        Some(p) => Wanted {
            points: p.points,
            photons: p.photons,
            dsm: p.dsm.as_ref().map(|d| d.resolution_m),
        },
        None => Wanted {
            points: kind == InstrumentKind::DiscreteReturn,
            photons: kind == InstrumentKind::PhotonCounting,
            dsm: (kind == InstrumentKind::DiscreteReturn).then_some(2.0),
        },
    }
}

/// LAS class of a component: the surface class with the most impulse energy within two
/// sigmas of its centre.
fn class_of(w: &Waveform, centre: f64, sigma: f64) -> u8 {
    let lo = (centre - 2.0 * sigma).floor().max(0.0) as usize;
    let hi = ((centre + 2.0 * sigma).ceil() as usize).min(w.impulse_energy_j.len());
    let mut best = (0.0f64, SurfaceClass::Other.las_code());
    for class in SurfaceClass::ALL {
        let code = class.las_code();
        let e: f64 = w.class_energy_j[class.index()]
            .get(lo..hi)
            .map_or(0.0, |s| s.iter().map(|&x| x as f64).sum());
        if e > best.0 {
            best = (e, code);
        }
    }
    best.1
}

/// The decomposition of one waveform as the campaign asks for it.
fn components(loaded: &Loaded, w: &Waveform) -> Vec<Component> {
    let inst = &loaded.campaign.instrument;
    let hv = crate::photon_energy_j(loaded.campaign.wavelength_nm);
    let mc_se: Vec<f32> = w
        .impulse_energy_se_j
        .iter()
        .map(|&s| (s as f64 / hv) as f32)
        .collect();
    decompose(
        &w.laser_photons,
        &mc_se,
        inst.detection_threshold_photons,
        inst.max_returns as usize,
        Decomposition::Gaussian,
        pulse_sigma_s(inst) / (inst.bin_ns * 1e-9),
    )
}

/// Discrete returns of every pulse, in pulse order then time.
pub fn discrete_returns(loaded: &Loaded, pulses: &[Pulse], waveforms: &[Waveform]) -> Vec<Point> {
    let c = &loaded.campaign;
    let inst = &c.instrument;
    let reference_range = pulses.first().map_or(1.0, |p| p.origin.z.abs().max(1.0));
    let config = PointConfig {
        emitted_energy_j: inst.pulse_energy_j,
        photon_energy_j: crate::photon_energy_j(c.wavelength_nm),
        telescope_area_m2: inst.receiver_area_m2,
        reference_range_m: reference_range,
    };
    let by_pulse: Vec<Vec<Point>> = waveforms
        .par_iter()
        .map(|w| {
            let pulse = &pulses[w.pulse_id as usize];
            let comps = components(loaded, w);
            let classes: Vec<u8> = comps
                .iter()
                .map(|k| class_of(w, k.centre_bin, k.sigma_bins))
                .collect();
            points_on_axis(pulse, w.t0_ns, w.bin_ns as f64, &comps, &classes, &config)
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
        let mut returns: std::collections::BTreeMap<u64, u8> = std::collections::BTreeMap::new();
        for p in points {
            returns.insert(p.pulse_id, p.number_of_returns);
        }
        for w in waveforms {
            let Some(&n) = returns.get(&w.pulse_id) else {
                continue;
            };
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

/// `points_top.png` and `waveforms.png` beside points.las.
fn point_figures(
    loaded: &Loaded,
    out: &Path,
    examples: Examples,
    points: &[Point],
) -> Result<Vec<String>> {
    // lowest first, so the top of the canopy is what one sees from above
    let mut top: Vec<(f64, TopPoint)> = points
        .iter()
        .map(|p| {
            (
                p.z,
                TopPoint {
                    x: p.x,
                    y: p.y,
                    reflectance: p.apparent_reflectance as f64,
                },
            )
        })
        .collect();
    top.sort_by(|a, b| a.0.total_cmp(&b.0));
    let top: Vec<TopPoint> = top.into_iter().map(|t| t.1).collect();
    figures::points_top_view(
        &out.join("points_top.png"),
        &top,
        &format!(
            "{}: {} points from above, by apparent reflectance",
            loaded.campaign.name,
            points.len()
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

/// Photon events of every pulse (photon counting), deterministic per (seed, pulse).
pub fn photon_events(loaded: &Loaded, pulses: &[Pulse], waveforms: &[Waveform]) -> Vec<PhotonRow> {
    let c = &loaded.campaign;
    let inst = &c.instrument;
    let first = pulses.first().map(|p| p.origin).unwrap_or_default();
    let by_pulse: Vec<Vec<PhotonRow>> = waveforms
        .par_iter()
        .map(|w| {
            let pulse = &pulses[w.pulse_id as usize];
            let events = count_photons(
                &w.laser_photons,
                w.solar_photons_per_bin as f64,
                w.bin_ns as f64 * 1e-9,
                inst.quantum_efficiency.unwrap_or(1.0),
                inst.dark_count_hz.unwrap_or(0.0),
                inst.dead_time_ns.unwrap_or(0.0) * 1e-9,
                c.seed,
                w.pulse_id,
            );
            let along = (pulse.origin - first).truncate().length();
            photon_rows(pulse, w.t0_ns, &events, along)
        })
        .collect();
    by_pulse.into_iter().flatten().collect()
}

/// Runs the products stage; returns the files written (relative to `out`) and a note.
pub fn run(
    loaded: &Loaded,
    scene: &Scene,
    out: &Path,
    pulses: &[Pulse],
    parts: usize,
) -> Result<(Vec<String>, String)> {
    let want = wanted(loaded);
    // one part of waveforms in memory at a time: a long gate of fine bins makes a waveform
    // tens of kilobytes, and a campaign millions of them
    let (mut points, mut rows, mut examples, mut seen) =
        (Vec::new(), Vec::new(), Examples::default(), 0usize);
    let bar = progress(pulses.len() as u64, "products");
    let start = std::time::Instant::now();
    let every = parts.div_ceil(10).max(1);
    for k in 0..parts {
        if let Some(signal) = crate::interrupt::requested() {
            return Err(Error::interrupted(
                signal,
                "the products stage stopped before writing anything; the waveforms are kept",
            ));
        }
        let part = read_waveforms(&out.join(part_name(k)))?;
        if part.iter().any(|w| w.pulse_id as usize >= pulses.len()) {
            return Err(Error::msg(format!(
                "{}: waveforms of pulses that were not planned: run again without --resume",
                out.display()
            )));
        }
        seen += part.len();
        if want.points {
            let p = discrete_returns(loaded, pulses, &part);
            examples.offer(&part, &p);
            points.extend(p);
        }
        if want.photons {
            rows.extend(photon_events(loaded, pulses, &part));
        }
        bar.inc(part.len() as u64);
        if bar.is_hidden() && (k + 1) % every == 0 && k + 1 < parts {
            let rate = seen as f64 / start.elapsed().as_secs_f64().max(1e-9);
            log(&format!(
                "products: {}/{} parts, {rate:.0} pulses/s, {:.0} s left",
                k + 1,
                parts,
                (pulses.len() - seen.min(pulses.len())) as f64 / rate
            ));
        }
    }
    bar.finish_and_clear();
    if seen != pulses.len() {
        return Err(Error::msg(format!(
            "{}: {seen} waveforms for {} planned pulses: run again with --resume",
            out.display(),
            pulses.len()
        )));
    }
    let mut outputs = Vec::new();
    let mut summary = ProductsSummary {
        pulses: pulses.len(),
        ..Default::default()
    };
    if want.points {
        write_las(&out.join("points.las"), &points)?;
        outputs.push("points.las".to_string());
        outputs.extend(point_figures(loaded, out, examples, &points)?);
        let mut points_summary = points_summary(&points, pulses.len());
        let distances = crate::products::accuracy::distances(scene, &points, pulses);
        points_summary.surface_distance = crate::products::accuracy::summarize(&distances);
        summary.points = Some(points_summary);
        if let Some(res) = want.dsm {
            let dsm_outputs = crate::products::dsm::write_dsm(scene, out, &points, pulses, res)?;
            outputs.extend(dsm_outputs);
        }
    }
    if want.photons {
        write_photons(&out.join("photons.parquet"), &rows)?;
        outputs.push("photons.parquet".to_string());
        let count = |s: u8| rows.iter().filter(|r| r.source == s).count();
        summary.photons = Some(PhotonCounts {
            total: rows.len(),
            laser: count(0),
            solar: count(1),
            dark: count(2),
            laser_per_shot: count(0) as f64 / pulses.len().max(1) as f64,
        });
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

/// The points' part of `products.json`: counts, and the pulse density over the box the first
/// returns cover.
fn points_summary(points: &[Point], pulses: usize) -> PointsSummary {
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for p in points.iter().filter(|p| p.return_number == 1) {
        lo = [lo[0].min(p.x), lo[1].min(p.y)];
        hi = [hi[0].max(p.x), hi[1].max(p.y)];
    }
    let area = ((hi[0] - lo[0]) * (hi[1] - lo[1])).max(0.0);
    let points_by_class = SurfaceClass::ALL
        .iter()
        .map(|class| {
            let n = points
                .iter()
                .filter(|p| p.classification == class.las_code())
                .count();
            (class.las_name().to_string(), n)
        })
        .collect();
    PointsSummary {
        points: points.len(),
        points_per_pulse: points.len() as f64 / pulses.max(1) as f64,
        area_m2: Some(area).filter(|a| a.is_finite()),
        pulse_density_per_m2: (area > 0.0).then(|| pulses as f64 / area),
        points_by_class,
        surface_distance: None,
    }
}
