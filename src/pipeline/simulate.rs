//! The simulate stage: pulses in parts of [`PART_PULSES`], each part written when complete,
//! with per-pulse timing beside it.

use super::PART_PULSES;
use crate::campaign::Loaded;
use crate::error::{Error, Result};
use crate::plan::{Plan, Pulse};
use crate::progress::{log, progress};
use crate::scene::Scene;
use crate::sensor::{pulse_sigma_s, Gate, Laser, Receiver, SunSource};
use crate::transport::atmosphere::Atmosphere;
use crate::transport::{simulate_pulse_in, PulseSetup, Scratch};
use crate::waveform::file::{part_name, write_waveforms};
use crate::waveform::{self, Radiometry, Waveform};
use glam::DVec3;
use indicatif::ProgressBar;
use rayon::prelude::*;
use std::io::IsTerminal;
use std::path::Path;
use std::time::Instant;

/// Simulates the given parts, each written when complete. Pulses within a part and each
/// pulse's ray chunks run in parallel, and a finished part is encoded and written on a thread
/// of its own while the workers go on with the next one: the queue holds one finished part
/// at most, so memory stays at about two parts. A signal (see [`crate::interrupt`]) stops it
/// before the next part, the parts in flight written. Returns (rays traced, parts written,
/// the signal that stopped it).
pub(super) fn simulate_parts(
    loaded: &Loaded,
    scene: &Scene,
    plan: &Plan,
    todo: &[usize],
    out: &Path,
    fingerprint: &str,
) -> Result<(u64, usize, Option<i32>)> {
    let total: usize = todo.iter().map(|&k| part_range(k, plan.len()).len()).sum();
    let bar = progress(total as u64, "simulating");
    let t = Instant::now();
    let mut rays = 0u64;
    let mut done_pulses = 0usize;
    let terminal = std::io::stderr().is_terminal();
    let mut last_log = 0.0;
    let mut written = 0usize;
    let mut stopped = None;
    std::thread::scope(|scope| -> Result<()> {
        let (queue, finished) =
            std::sync::mpsc::sync_channel::<(usize, Vec<Waveform>, Vec<f64>)>(1);
        let writer = scope.spawn(move || -> Result<()> {
            for (n, (k, waveforms, secs)) in finished.into_iter().enumerate() {
                write_waveforms(&out.join(part_name(k)), &waveforms, fingerprint)?;
                write_pulse_stats(
                    &out.join(format!("waveforms/part-{k:05}.stats.csv")),
                    &waveforms,
                    &secs,
                )?;
                drop(waveforms);
                crate::progress::release_after_part(n);
            }
            Ok(())
        });
        for (i, &k) in todo.iter().enumerate() {
            if let Some(signal) = crate::interrupt::requested() {
                stopped = Some(signal);
                break;
            }
            let pulses = plan.pulses(part_range(k, plan.len()));
            let (waveforms, secs) = simulate(loaded, scene, &pulses, &bar);
            rays += waveforms.iter().map(|w| w.rays as u64).sum::<u64>();
            done_pulses += waveforms.len();
            let elapsed = t.elapsed().as_secs_f64();
            let rate = done_pulses as f64 / elapsed;
            // a log, not a terminal: a line per tenth of the work, or per minute if slower
            let tenth = (i + 1) % todo.len().div_ceil(10).max(1) == 0;
            if !terminal && (tenth || elapsed - last_log >= 60.0) && i + 1 < todo.len() {
                last_log = elapsed;
                log(&format!(
                    "simulate: part {} ({}/{} parts) simulated, {:.0} pulses/s, {:.0} s left",
                    k,
                    i + 1,
                    todo.len(),
                    rate,
                    (total - done_pulses) as f64 / rate
                ));
            }
            if queue.send((k, waveforms, secs)).is_err() {
                break; // the writer stopped on an error, which join returns below
            }
            written += 1;
        }
        drop(queue);
        writer
            .join()
            .unwrap_or_else(|_| Err(Error::msg("internal error: the part writer stopped")))
    })?;
    bar.finish_and_clear();
    let secs = t.elapsed().as_secs_f64();
    if done_pulses > 0 {
        log(&format!(
            "simulated {done_pulses} pulses, {rays} rays in {secs:.2} s ({:.1} pulses/s, {:.3e} rays/s)",
            done_pulses as f64 / secs,
            rays as f64 / secs
        ));
    }
    Ok((rays, written, stopped))
}

pub(super) fn part_range(k: usize, n: usize) -> std::ops::Range<usize> {
    k * PART_PULSES..((k + 1) * PART_PULSES).min(n)
}

/// Per-pulse counters beside the waveforms: effective paths per ray and time per ray. Kept
/// out of the waveform files, which must not depend on timing.
pub(super) fn write_pulse_stats(path: &Path, waveforms: &[Waveform], secs: &[f64]) -> Result<()> {
    let rows = waveforms.iter().zip(secs).map(|(w, s)| {
        vec![
            w.pulse_id.to_string(),
            w.rays.to_string(),
            w.paths_per_ray.to_string(),
            format!("{s:.6}"),
            format!("{:.4e}", s / w.rays.max(1) as f64),
        ]
    });
    let header = [
        "pulse_id",
        "rays",
        "paths_per_ray",
        "seconds",
        "seconds_per_ray",
    ];
    crate::fsutil::write_csv_atomic(path, &header, rows)
}

/// In a repeated scene, the box of the landscape a pulse sees: the copy of the scene's box
/// under its beam grown sideways by the wider of its cones at the bottom of the scene (at
/// most ten periods), which the sun's disk must cover for its light sub-paths to reach every
/// point in view.
fn viewed_box(
    inst: &crate::campaign::Instrument,
    p: &Pulse,
    (lo, hi): (DVec3, DVec3),
) -> (DVec3, DVec3) {
    let half = inst.fov_half_angle_mrad.max(inst.footprint_half_angle_mrad) * 1e-3;
    let down = (p.origin.z - lo.z).max(0.0) / p.direction.z.abs().max(1e-9);
    let grow = (down * half.tan()).min(10.0 * (hi - lo).truncate().max_element());
    let g = DVec3::new(grow, grow, 0.0);
    (lo - g, hi + g)
}

/// Simulates pulses: pulses and each pulse's ray chunks run in parallel. Returns the
/// waveforms and each pulse's wall time (with the threads it shared).
pub fn simulate(
    loaded: &Loaded,
    scene: &Scene,
    pulses: &[Pulse],
    bar: &ProgressBar,
) -> (Vec<Waveform>, Vec<f64>) {
    let c = &loaded.campaign;
    let inst = &c.instrument;
    let sigma = pulse_sigma_s(inst);
    let hv = crate::photon_energy_j(c.wavelength_nm);
    let bounds = scene.bounds();
    let sun = c
        .sun
        .as_ref()
        .map(|s| SunSource::new(s, inst.bandwidth_nm.unwrap_or(0.0), bounds));
    // every layer has an optical depth at the wavelength: the campaign's validation says so
    let atmosphere = c
        .atmosphere
        .as_ref()
        .and_then(|a| Atmosphere::new(a, c.wavelength_nm).ok());
    let radiometry = Radiometry {
        pulse_energy_j: inst.pulse_energy_j,
        receiver_area_m2: inst.receiver_area_m2,
        fov_half_angle: inst.fov_half_angle_mrad * 1e-3,
        sun: sun.map(|s| (s.band_irradiance, s.cos_zenith)),
    };
    pulses
        .par_iter()
        .map_init(Scratch::default, |scratch, p| {
            let near = scene.bounds_near(p.origin, p.direction);
            let gate = Gate::for_pulse(inst, p.origin, p.direction, near);
            let sub_bins = waveform::sub_bins_per_bin(gate.dt, sigma);
            let sun = sun.map(|s| {
                let s = if scene.is_repeated() {
                    let (lo, hi) = viewed_box(inst, p, near);
                    s.covering(lo, hi)
                } else {
                    s
                };
                s.for_gate(inst.pulse_energy_j, gate.dt * gate.bins as f64)
            });
            let setup = PulseSetup {
                scene,
                laser: Laser::new(inst, p.origin, p.direction),
                receiver: Receiver::new(
                    inst,
                    p.origin + p.platform_to_scene(inst.receiver_offset_m.unwrap_or_default()),
                    p.direction,
                ),
                gate,
                sub_bins,
                method: c.simulation.method,
                heuristic: c.simulation.mis,
                sun,
                atmosphere: atmosphere.as_ref(),
                max_order: c.simulation.max_order,
                seed: c.seed,
                pulse_id: p.id,
            };
            let t = Instant::now();
            let tally = simulate_pulse_in(&setup, c.simulation.rays_per_pulse, scratch);
            let secs = t.elapsed().as_secs_f64();
            bar.inc(1);
            (
                waveform::waveform(p.id, tally, &gate, sub_bins, sigma, hv, &radiometry),
                secs,
            )
        })
        .unzip()
}

/// Rays per second on this machine for this campaign, measured on up to 8 pulses spread
/// over the plan with at most 1000 rays each: the basis of `lidarsim check`'s time estimate.
pub fn probe_rays_per_second(loaded: &Loaded, scene: &Scene, plan: &Plan) -> f64 {
    let n = plan.len().min(8);
    let sample: Vec<Pulse> = (0..n)
        .map(|i| plan.pulse((i * plan.len() / n) as u64))
        .collect();
    let mut probe = loaded.clone();
    probe.campaign.simulation.rays_per_pulse = probe.campaign.simulation.rays_per_pulse.min(1000);
    let t = Instant::now();
    let (w, _) = simulate(&probe, scene, &sample, &ProgressBar::hidden());
    let rays: u64 = w.iter().map(|w| w.rays as u64).sum();
    rays as f64 / t.elapsed().as_secs_f64().max(1e-9)
}
