//! The products stage: the waveforms read a part at a time and handed to a list of writers
//! (points, photons, the mission files), each adding what it makes of the part to its
//! files, then finishing them; `products.json` sums up.

mod mission;
mod part;
mod photons;
mod points;

use crate::campaign::{InstrumentKind, Loaded};
use crate::error::{Error, Result};
use crate::fsutil::write_text_atomic;
use crate::plan::Plan;
use crate::products::mission::{Atl03, L1b, L2a, Setup, SunAngles, ATL03_FILE, L1B_FILE};
use crate::products::report::summary::{ProductsSummary, WaveformTotals};
use crate::progress::{log, progress};
use crate::scene::Scene;
use crate::sensor::pulse_sigma_s;
use crate::waveform::file::{part_name, read_waveforms_but_impulse, Parts};
use crate::waveform::record::Recorder;
use crate::waveform::Waveform;
use part::{Made, Part, Writer};
use std::path::Path;

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
    let p = c.products();
    Wanted {
        points: p.points,
        photons: p.photons,
        dsm: p.dsm.as_ref().map(|d| d.resolution_m),
        l1b: c.instrument.kind == InstrumentKind::Waveform,
    }
}

/// The writers of the products `want` asks for, in the order the manifest lists their files.
fn writers<'a>(
    loaded: &'a Loaded,
    scene: &'a Scene,
    out: &'a Path,
    plan: &'a Plan,
    cut: Parts,
    want: Wanted,
) -> Result<Vec<Box<dyn Writer + Send + 'a>>> {
    let c = &loaded.campaign;
    let mut list: Vec<Box<dyn Writer + Send + 'a>> = Vec::new();
    if want.points {
        let w = points::PointsWriter::new(loaded, scene, plan, cut, out, want.dsm)?;
        list.push(Box::new(w));
    }
    if want.photons {
        let path = out.join(photons::PHOTONS_FILE);
        let bands = c.wavelength_nm.several();
        list.push(Box::new(photons::PhotonsWriter::new(
            path,
            bands,
            plan.len(),
        )));
        let sun = SunAngles::new(c.sun.as_ref());
        let file = Atl03::create(&out.join(ATL03_FILE), &c.name, c.frame.as_ref(), sun)?;
        list.push(Box::new(mission::Atl03Writer {
            file,
            plan,
            out,
            height0: c.frame.as_ref().map_or(0.0, |f| f.origin[2]),
            dots: Vec::new(),
            step: 1,
            seen: 0,
        }));
    }
    if want.l1b {
        let setup = Setup {
            campaign: &c.name,
            frame: c.frame.as_ref(),
            pulse_sigma_s: pulse_sigma_s(&c.instrument),
            counts: c.instrument.digitiser.is_some(),
            threshold_photons: c.instrument.detection_threshold_photons,
            sun: SunAngles::new(c.sun.as_ref()),
            first_gps_s: if !plan.is_empty() {
                plan.pulse(0).gps_time_s
            } else {
                0.0
            },
            // 32 hex digits for the uuid of /METADATA
            fingerprint: [b"uuid".as_slice(), b"file"]
                .iter()
                .map(|salt| {
                    crate::fsutil::fingerprint(&[salt, c.name.as_bytes(), &c.seed.to_le_bytes()])
                })
                .collect(),
        };
        let l1b = L1b::create(&out.join(L1B_FILE), &setup)?;
        let l2a = L2a::create(&out.join(crate::products::mission::L2A_FILE), &setup)?;
        let recorder = Recorder::new(&c.instrument, c.seed);
        let edge_tan = (c.instrument.footprint_half_angle_mrad * 1e-3).tan();
        list.push(Box::new(mission::WaveformFilesWriter {
            l1b,
            l2a,
            recorder,
            plan,
            scene,
            out,
            pulse_sigma_s: setup.pulse_sigma_s,
            threshold_photons: setup.threshold_photons,
            false_alarm_rate: c.instrument.false_alarm_rate(),
            edge_tan,
            sigma_tan: edge_tan / (-2.0 * c.instrument.edge_energy_fraction.ln()).sqrt(),
            height0: c.frame.as_ref().map_or(0.0, |f| f.origin[2]),
            figure_ids: mission::figure_ids(plan.len()),
            figures: Vec::new(),
            shots: 0,
            against_truth: Vec::new(),
        }));
    }
    Ok(list)
}

/// What `rows` make for every writer, once they are checked to be planned pulses'.
fn make(loaded: &Loaded, plan: &Plan, out: &Path, rows: &[Waveform], want: Wanted) -> Result<Made> {
    if rows.iter().any(|w| w.pulse_id as usize >= plan.len()) {
        return Err(Error::msg(format!(
            "{}: waveforms of pulses that were not planned: run again without --resume",
            out.display()
        )));
    }
    if want.photons {
        photons_fit(loaded, rows)?;
    }
    Ok(Made::new(loaded, plan, rows, want.points, want.photons))
}

/// Most photon events a part's pulses may be expected to record together: a part's events
/// are held in memory while its files are written (about 100 bytes each, twice over).
/// Photon-counting instruments record a few events a shot (ATLAS, MABEL); a million-photon
/// return asked for as photons is a mistake worth a message, not an exhausted memory.
pub const MAX_PHOTON_EVENTS_PER_PART: f64 = 5e6;

/// Refuses a part whose pulses would record more than [`MAX_PHOTON_EVENTS_PER_PART`] photon
/// events on average: the mean of each pulse's events (laser, solar and dark), no more than
/// its gate holds dead times.
fn photons_fit(loaded: &Loaded, rows: &[Waveform]) -> Result<()> {
    let inst = &loaded.campaign.instrument;
    let qe = inst.quantum_efficiency.unwrap_or(1.0);
    let dark_hz = inst.dark_count_hz.unwrap_or(0.0);
    let dead_s = inst.dead_time_ns.unwrap_or(0.0) * 1e-9;
    let mut total = 0.0;
    let mut most: f64 = 0.0;
    for w in rows {
        let bins = w.laser_photons.len() as f64;
        let gate_s = bins * w.bin_ns as f64 * 1e-9;
        let laser: f64 = w.laser_photons.iter().map(|&v| v.max(0.0) as f64).sum();
        let mut mean =
            qe * (laser + w.solar_photons_per_bin.max(0.0) as f64 * bins) + dark_hz * gate_s;
        if dead_s > 0.0 {
            mean = mean.min(gate_s / dead_s + 1.0);
        }
        total += mean;
        most = most.max(mean);
    }
    if total <= MAX_PHOTON_EVENTS_PER_PART {
        return Ok(());
    }
    Err(loaded.doc.error(
        "products.photons",
        format!(
            "the pulses would record about {:.1e} photon events a pulse (up to {:.1e}), {:.1e} in a part of {} pulses, more than the {:.0e} a part may hold: a photon-counting detector records a few a shot (ATLAS, MABEL); lower instrument.pulse_energy_j or receiver_area_m2, set instrument.dead_time_ns, or leave photons out",
            total / rows.len().max(1) as f64,
            most,
            total,
            rows.len(),
            MAX_PHOTON_EVENTS_PER_PART
        ),
    ))
}

/// Runs the products stage; returns the files written (relative to `out`) and a note.
///
/// Memory is bounded by a part and the scene, not by the campaign's length: the writers take
/// the waveforms a part at a time and write or spill what they make of them as they go.
///
/// Long because the loop reads part k + 1, makes part k's returns and has the writers take
/// part k - 1 side by side, checks the parts and logs progress; the products themselves are
/// the writers'.
pub fn run(
    loaded: &Loaded,
    scene: &Scene,
    out: &Path,
    plan: &Plan,
    cut: Parts,
) -> Result<(Vec<String>, String)> {
    let parts = cut.count();
    let want = wanted(loaded);
    let mut writers = writers(loaded, scene, out, plan, cut, want)?;
    let mut seen = 0usize;
    let mut totals = WaveformTotals::default();
    let bar = progress(plan.len() as u64, "products");
    let start = std::time::Instant::now();
    let every = parts.div_ceil(10).max(1);
    // Three parts are in hand at once, in two nested rayon joins on the same threads:
    // part k + 1 is read and decoded, part k's returns are made, and the writers take part
    // k - 1. The writers' share is serial (each file is written in order), and with only
    // the reading beside it, it left a core idle at the end of every part.
    let read = |k: usize, spare| read_waveforms_but_impulse(&out.join(part_name(k)), spare);
    let mut next = (parts > 0).then(|| read(0, Vec::new()));
    // part k - 1's rows and what was made of them, for the writers
    let mut behind: Option<(Vec<Waveform>, Made)> = None;
    // the rows the writers are done with lend their buffers to the reading of a later part
    let mut spare: Vec<Waveform> = Vec::new();
    for k in 0..=parts {
        if let Some(signal) = crate::interrupt::requested() {
            return Err(Error::interrupted(
                signal,
                "the products stage stopped before writing anything; the waveforms are kept",
            ));
        }
        crate::progress::release_after_part(k);
        let rows = next.take().transpose()?;
        if k < parts && rows.is_none() {
            break;
        }
        let written = behind.take();
        let lend = std::mem::take(&mut spare);
        let (ahead, (made, added)) = rayon::join(
            || (k + 1 < parts).then(|| read(k + 1, lend)),
            || {
                rayon::join(
                    || {
                        rows.as_deref()
                            .map(|rows| make(loaded, plan, out, rows, want))
                    },
                    || -> Result<()> {
                        let Some((rows, made)) = &written else {
                            return Ok(());
                        };
                        let part = Part::new(loaded, rows, made);
                        seen += part.first.len();
                        part.first.iter().for_each(|w| totals.add(w));
                        for w in &mut writers {
                            w.add(&part)?;
                        }
                        bar.inc(part.first.len() as u64);
                        if bar.is_hidden() && k % every == 0 && k < parts {
                            let rate = seen as f64 / start.elapsed().as_secs_f64().max(1e-9);
                            log(&format!(
                                "products: {k}/{parts} parts, {rate:.0} pulses/s, {:.0} s left",
                                (plan.len() - seen.min(plan.len())) as f64 / rate
                            ));
                        }
                        Ok(())
                    },
                )
            },
        );
        added?;
        next = ahead;
        if let Some((rows, _)) = written {
            spare = rows;
        }
        if let (Some(rows), Some(made)) = (rows, made) {
            behind = Some((rows, made?));
        }
    }
    bar.finish_and_clear();
    if seen != plan.len() {
        return Err(Error::msg(format!(
            "{}: {seen} waveforms for {} planned pulses: run again with --resume",
            out.display(),
            plan.len()
        )));
    }
    let mut summary = ProductsSummary {
        pulses: plan.len(),
        waveform_totals: Some(totals),
        ..Default::default()
    };
    let mut outputs = Vec::new();
    for w in writers {
        outputs.extend(w.finish(&mut summary)?);
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
