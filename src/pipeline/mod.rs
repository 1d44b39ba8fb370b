//! The run: stages that turn a campaign into the files of a run folder (outputs.md).
//!
//! Every file is written under a temporary name and renamed when complete, so a crash never
//! leaves a half-written file under its final name.

pub mod parquet;

use crate::campaign::Loaded;
use crate::error::{Error, Result};
use crate::fsutil::write_text_atomic;
use crate::plan::{self, Pulse};
use crate::scene::Scene;
use crate::sensor::{pulse_sigma_s, Gate, Laser, Receiver};
use crate::transport::{simulate_pulse, PulseSetup};
use crate::waveform::{self, Waveform};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Pulses per waveform part file.
pub const PART_PULSES: usize = 1000;

#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    pub out: Option<PathBuf>,
    pub threads: Option<usize>,
}

#[derive(Clone, Debug)]
pub struct RunSummary {
    pub out: PathBuf,
    pub pulses: usize,
    pub rays: u64,
    pub seconds: f64,
}

/// Runs a campaign file into its run folder.
pub fn run(campaign_path: &Path, opts: &RunOptions) -> Result<RunSummary> {
    let loaded = Loaded::read(campaign_path)?;
    let out = opts
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(&loaded.campaign.name));
    std::fs::create_dir_all(&out)
        .map_err(|e| Error::file(&out, format!("cannot create run folder: {e}")))?;
    with_threads(opts.threads, || run_in(&loaded, &out))
}

/// Runs `f` on a pool of `threads` threads (all cores when None).
pub fn with_threads<T: Send>(
    threads: Option<usize>,
    f: impl FnOnce() -> Result<T> + Send,
) -> Result<T> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            return Err(Error::msg("--threads must be at least 1"));
        }
        b = b.num_threads(n);
    }
    let pool = b
        .build()
        .map_err(|e| Error::msg(format!("cannot start threads: {e}")))?;
    pool.install(f)
}

fn run_in(loaded: &Loaded, out: &Path) -> Result<RunSummary> {
    let start = Instant::now();
    let c = &loaded.campaign;
    write_text_atomic(&out.join("campaign.resolved.yaml"), &loaded.resolved_yaml())?;

    let pulses = plan::plan(c)?;
    parquet::write_pulses(&out.join("pulses.parquet"), &pulses)?;
    log(&format!("planned {} pulses", pulses.len()));

    let t_scene = Instant::now();
    let scene = Scene::load(&loaded.scene_path, c.wavelength_nm)?;
    let stats = scene.stats();
    log(&format!(
        "scene {}: {} instances, {} triangles ({} distinct), {:.1} MB, loaded in {:.2} s",
        scene.name,
        stats.instances,
        stats.instanced_triangles,
        stats.distinct_triangles,
        stats.memory_bytes as f64 / 1e6,
        t_scene.elapsed().as_secs_f64()
    ));

    let t_sim = Instant::now();
    let waveforms = simulate(loaded, &scene, &pulses);
    let rays: u64 = waveforms.iter().map(|w| w.rays as u64).sum();
    let secs = t_sim.elapsed().as_secs_f64();
    for (k, part) in waveforms.chunks(PART_PULSES).enumerate() {
        parquet::write_waveforms(
            &out.join("waveforms").join(format!("part-{k:05}.parquet")),
            part,
        )?;
    }
    log(&format!(
        "simulated {} pulses, {} rays in {:.2} s ({:.0} pulses/s, {:.3e} rays/s)",
        pulses.len(),
        rays,
        secs,
        pulses.len() as f64 / secs,
        rays as f64 / secs
    ));
    let manifest = serde_json::json!({
        "tool_version": env!("CARGO_PKG_VERSION"),
        "campaign": c.name,
        "stages": {
            "plan": { "status": "done", "outputs": ["pulses.parquet"] },
            "simulate": { "status": "done", "wall_time_s": secs, "pulses": pulses.len(), "rays": rays,
                          "outputs": (0..waveforms.len().div_ceil(PART_PULSES)).map(|k| format!("waveforms/part-{k:05}.parquet")).collect::<Vec<_>>() },
        },
    });
    write_text_atomic(
        &out.join("manifest.json"),
        &serde_json::to_string_pretty(&manifest).unwrap_or_default(),
    )?;
    Ok(RunSummary {
        out: out.to_path_buf(),
        pulses: pulses.len(),
        rays,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Simulates every pulse: pulses and each pulse's ray chunks run in parallel.
pub fn simulate(loaded: &Loaded, scene: &Scene, pulses: &[Pulse]) -> Vec<Waveform> {
    let c = &loaded.campaign;
    let inst = &c.instrument;
    let sigma = pulse_sigma_s(inst);
    let hv = crate::photon_energy_j(c.wavelength_nm);
    let bounds = scene.bounds();
    let bar = progress(pulses.len() as u64, "simulating");
    let out = pulses
        .par_iter()
        .map(|p| {
            let gate = Gate::for_pulse(inst, p.origin, bounds);
            let sub_bins = waveform::sub_bins_per_bin(gate.dt, sigma);
            let setup = PulseSetup {
                scene,
                laser: Laser::new(inst, p.origin, p.direction),
                receiver: Receiver::new(inst, p.origin, p.direction),
                gate,
                sub_bins,
                method: c.simulation.method,
                heuristic: c.simulation.mis,
                max_order: c.simulation.max_order,
                seed: c.seed,
                pulse_id: p.id,
            };
            let tally = simulate_pulse(&setup, c.simulation.rays_per_pulse);
            bar.inc(1);
            waveform::waveform(p.id, &tally, &gate, sub_bins, sigma, hv)
        })
        .collect();
    bar.finish_and_clear();
    out
}

/// A progress bar on a terminal; nothing otherwise (the stage logs its own summary line).
pub fn progress(len: u64, what: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} pulses {per_sec} eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar
}

pub fn log(line: &str) {
    eprintln!("lidarsim: {line}");
}
