//! The campaign rows of `lidarsim bench`: the paper's sections 3.2-3.4 run as whole
//! campaigns through the pipeline (plan, simulate, products), each timed and with its peak
//! memory. The orchard rows need the RAMI files (README, "Scenes") and are skipped, with a
//! note in the table, when they are absent.

use crate::error::Result;
use crate::generate::{generate_with_summary, GenerateOptions, SceneKind};
use crate::pipeline::{self, RunOptions};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// One campaign of the bench.
#[derive(Clone, Debug)]
pub struct CampaignRow {
    pub name: String,
    pub what: String,
    pub pulses: usize,
    pub rays_per_pulse: u64,
    /// Wall time of the whole run (scene load, plan, simulate, products), s.
    pub run_s: f64,
    /// Wall time of the simulate stage, s, and pulses per second in it.
    pub simulate_s: f64,
    pub pulses_per_s: f64,
    /// Peak resident memory during the run, MB (None where the OS does not tell).
    pub peak_mb: Option<f64>,
    /// What the run measured: solar photons per bin, photons per shot, points per pulse.
    pub result: String,
}

/// A campaign the bench will run, or why it cannot.
pub enum Planned {
    Run {
        name: String,
        what: String,
        text: String,
    },
    Skipped {
        name: String,
        why: String,
    },
}

/// Peak resident memory since the last [`reset_peak_memory`], MB (Linux: VmHWM).
pub fn peak_memory_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// Resets the peak-memory mark, so that each row reports its own peak (Linux ≥ 4.0:
/// writing 5 to clear_refs resets VmHWM to the current resident size).
pub fn reset_peak_memory() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// MABEL at one wavelength (paper Table 1): 20 km, 6 µJ, 0.05 mrad footprint, 0.105 mrad
/// field of view, 0.083 ns bins, dead time 2.5 ns; QE 12.5 % / 1.5 % and bands 0.03 / 0.4 nm
/// at 532 / 1064 nm. Table 1 gives no telescope area: MABEL's 0.2 m telescope, 0.0314 m², is
/// assumed. The track runs from (3, 3) to (101, 101) in the paper's frame, which is (-51, -49)
/// to (47, 49) in RAMI's, at `step` m: 0.02 m gives the paper's 6929 pulses.
pub fn mabel_campaign(scene: &Path, wavelength_nm: u32, sun: bool, step: f64, rays: u64) -> String {
    let (qe, band, irradiance) = if wavelength_nm == 532 {
        (0.125, 0.03, 1850.0)
    } else {
        (0.015, 0.4, 640.0)
    };
    let mut s = format!(
        "name: mabel_{wavelength_nm}{}\nscene: {}\nseed: 11\nwavelength_nm: {wavelength_nm}\ninstrument:\n  kind: photon_counting\n  pulse_energy_j: 6.0e-6\n  pulse_fwhm_ns: 2.0\n  footprint_half_angle_mrad: 0.05\n  fov_half_angle_mrad: 0.105\n  receiver_area_m2: 0.0314\n  bin_ns: 0.083\n  bandwidth_nm: {band}\n  quantum_efficiency: {qe}\n  dead_time_ns: 2.5\n  dark_count_hz: 1000\nplatform:\n  kind: track\n  altitude_m: 20000\n  track: {{ start: [-51, -49], end: [47, 49] }}\n  along_track_step_m: {step}\nsimulation: {{ method: bdpt, rays_per_pulse: {rays}, max_order: 10 }}\n",
        if sun { "_sun" } else { "" },
        scene.display()
    );
    if sun {
        let _ = writeln!(
            s,
            "sun: {{ zenith_deg: 50, azimuth_deg: 180, irradiance_w_m2_um: {irradiance} }}"
        );
    }
    s
}

/// GEDI over the orchard with the sun at 50° zenith, 180° azimuth (paper section 3.3).
pub fn orchard_gedi_campaign(scene: &Path, rays: u64) -> String {
    format!(
        "name: orchard_gedi_sun\nscene: {}\nseed: 5\nwavelength_nm: 1064\ninstrument:\n  kind: waveform\n  pulse_energy_j: 0.0105\n  pulse_fwhm_ns: 14.0\n  footprint_half_angle_mrad: 0.03\n  fov_half_angle_mrad: 0.3\n  receiver_area_m2: 0.5\n  bin_ns: 1.0\n  bandwidth_nm: 0.8\nplatform:\n  kind: static\n  pulses:\n    - {{ position: [-4, -2, 419000], direction: [0, 0, -1] }}\nsun: {{ zenith_deg: 50, azimuth_deg: 180, irradiance_w_m2_um: 640 }}\nsimulation: {{ method: bdpt, rays_per_pulse: {rays}, max_order: 100 }}\n",
        scene.display()
    )
}

/// The paper's section 3.2 scanner (Riegl VUX-1UAV, Table 1) over a forest of `size` m:
/// 250 m, scan ±atan(49/250), 0.045° look step, 0.3 m along track, one line through the
/// middle of `length` m.
pub fn als_forest_campaign(scene: &Path, size: f64, length: f64, rays: u64) -> String {
    let y = size / 2.0;
    let x0 = (size - length).max(0.0) / 2.0;
    format!(
        "name: als_forest\nscene: {}\nseed: 3\nwavelength_nm: 1064\ninstrument:\n  kind: discrete_return\n  pulse_energy_j: 0.001\n  pulse_fwhm_ns: 3.0\n  footprint_half_angle_mrad: 0.25\n  fov_half_angle_mrad: 0.375\n  receiver_area_m2: 0.1\n  bin_ns: 0.067\n  max_returns: 4\nplatform:\n  kind: als\n  altitude_m: 250\n  speed_m_s: 4.444444444444445\n  prf_hz: 100000\n  lines: [ {{ start: [{x0}, {y}], end: [{}, {y}] }} ]\n  scanner: {{ pattern: line, scan_angle_deg: [-11.0894, 11.0894], look_angle_step_deg: 0.045, along_track_step_m: 0.3 }}\nsimulation: {{ method: forward, rays_per_pulse: {rays}, max_order: 5 }}\nproducts: {{ points: true, dsm: {{ resolution_m: 2.0 }} }}\n",
        scene.display(),
        x0 + length
    )
}

/// Where the bench finds the RAMI orchard scene: `scenes/rami_wco.yaml` under the working
/// folder, if its geometry is there.
pub fn find_rami(scene: &Path) -> std::result::Result<PathBuf, String> {
    if !scene.exists() {
        return Err(format!("{} not found", scene.display()));
    }
    let probe = scene
        .parent()
        .unwrap_or(Path::new("."))
        .join("../../shared/data/rami-wco/CISI1/foliage.ply");
    if !probe.exists() {
        return Err(format!(
            "RAMI geometry not found at {} (README, \"Scenes\")",
            probe.display()
        ));
    }
    Ok(scene.canonicalize().unwrap_or_else(|_| scene.to_path_buf()))
}

/// The bench's campaigns. `full` runs the paper's sizes (6929-pulse tracks, the generated
/// 1029-tree forest); quick mode a tenth of the track and a 40 m forest.
pub fn plan(dir: &Path, rami: &Path, full: bool) -> Result<Vec<Planned>> {
    let mut out = Vec::new();
    match find_rami(rami) {
        Ok(scene) => {
            let (step, rays) = if full { (0.02, 1000) } else { (0.2, 200) };
            out.push(Planned::Run {
                name: "orchard_gedi_sun".into(),
                what: "orchard, GEDI-like waveform, sun 50°/180° (section 3.3)".into(),
                text: orchard_gedi_campaign(&scene, if full { 100_000 } else { 20_000 }),
            });
            for wl in [532, 1064] {
                for sun in [false, true] {
                    out.push(Planned::Run {
                        name: format!("mabel_{wl}{}", if sun { "_sun" } else { "" }),
                        what: format!(
                            "orchard, MABEL-like photon counting, {wl} nm, sun {} (section 3.4)",
                            if sun { "on" } else { "off" }
                        ),
                        text: mabel_campaign(&scene, wl, sun, step, rays),
                    });
                }
            }
        }
        Err(why) => {
            for name in ["orchard_gedi_sun", "mabel_532", "mabel_1064"] {
                out.push(Planned::Skipped {
                    name: name.into(),
                    why: why.clone(),
                });
            }
        }
    }
    let (scene, size) = forest_scene(dir, full)?;
    out.push(Planned::Run {
        name: "als_forest".into(),
        what: format!(
            "forest {size} m, Riegl VUX-1UAV-like discrete return (section 3.2){}",
            if full { "" } else { ", 10 m of line" }
        ),
        text: als_forest_campaign(
            &scene,
            size,
            if full { 98.0 } else { 10.0 },
            if full { 32 } else { 16 },
        ),
    });
    Ok(out)
}

/// The generated forest of the bench (made once, then reused): the paper's stand size in full
/// mode (100 m, 1029 trees of 7 species, > 10^8 facets), a 40 m stand of 120 trees otherwise.
/// Returns the scene file and the stand's size, m.
pub fn forest_scene(dir: &Path, full: bool) -> Result<(PathBuf, f64)> {
    let forest_dir = dir.join(if full { "forest" } else { "forest_small" });
    let opts = if full {
        GenerateOptions::default()
    } else {
        GenerateOptions {
            size_m: Some([40.0, 40.0]),
            trees: Some(120),
            templates: Some(5),
            leaves: Some(1500),
            ..Default::default()
        }
    };
    let scene = match std::fs::metadata(forest_dir.join("forest.yaml")) {
        Ok(_) => forest_dir.join("forest.yaml"),
        Err(_) => generate_with_summary(SceneKind::Forest, 2, &forest_dir, &opts)?.scene,
    };
    let scene = scene.canonicalize().unwrap_or(scene);
    Ok((scene, opts.size_m.map_or(100.0, |s| s[0])))
}

/// Runs one planned campaign in `dir/name` and measures it.
pub fn run_row(dir: &Path, name: &str, what: &str, text: &str) -> Result<CampaignRow> {
    let folder = dir.join(name);
    let _ = std::fs::remove_dir_all(&folder);
    std::fs::create_dir_all(&folder)
        .map_err(|e| crate::error::Error::file(&folder, format!("cannot create folder: {e}")))?;
    let path = folder.join("campaign.yaml");
    crate::fsutil::write_text_atomic(&path, text)?;
    reset_peak_memory();
    let t = Instant::now();
    let summary = pipeline::run(
        &path,
        &RunOptions {
            out: Some(folder.join("run")),
            ..Default::default()
        },
    )?;
    let run_s = t.elapsed().as_secs_f64();
    let peak_mb = peak_memory_mb();
    let read = |p: PathBuf| -> Option<serde_json::Value> {
        serde_json::from_str(&std::fs::read_to_string(p).ok()?).ok()
    };
    let run = folder.join("run");
    let manifest = read(run.join("manifest.json"));
    let simulate_s = manifest
        .as_ref()
        .and_then(|m| m["stages"]["simulate"]["wall_time_s"].as_f64())
        .unwrap_or(f64::NAN);
    let products = read(run.join("products.json"));
    let mut result = String::new();
    if let Some(p) = &products {
        if let Some(ph) = p.get("photons") {
            let shots = summary.pulses.max(1) as f64;
            let _ = write!(
                result,
                "{:.3} laser, {:.3} solar, {:.4} dark photons per shot",
                ph["laser"].as_f64().unwrap_or(0.0) / shots,
                ph["solar"].as_f64().unwrap_or(0.0) / shots,
                ph["dark"].as_f64().unwrap_or(0.0) / shots
            );
        }
        if let Some(pp) = p.get("points_per_pulse").and_then(|v| v.as_f64()) {
            let _ = write!(result, "{pp:.2} points per pulse");
            if let Some(d) = read(run.join("dsm/report.json")) {
                let _ = write!(
                    result,
                    ", DSM bias {:+.3} m, RMSE {:.3} m, coverage {:.1}%",
                    d["bias_m"].as_f64().unwrap_or(f64::NAN),
                    d["rmse_m"].as_f64().unwrap_or(f64::NAN),
                    100.0 * d["coverage"].as_f64().unwrap_or(f64::NAN)
                );
            }
        }
    }
    if result.is_empty() {
        let waves =
            crate::waveform::file::read_waveforms(&run.join(crate::waveform::file::part_name(0)))?;
        if let Some(w) = waves.first() {
            let _ = write!(
                result,
                "{:.3} solar photons per bin, BRF {:.3} (field of view, sun) / {:.3} (footprint, laser)",
                w.solar_photons_per_bin, w.brf_fov_solar, w.brf_footprint_laser
            );
        }
    }
    Ok(CampaignRow {
        name: name.to_string(),
        what: what.to_string(),
        pulses: summary.pulses,
        rays_per_pulse: summary.rays / summary.pulses.max(1) as u64,
        run_s,
        simulate_s,
        pulses_per_s: summary.pulses as f64 / simulate_s,
        peak_mb,
        result,
    })
}

/// The markdown table of the campaign rows and the skipped ones.
pub fn table(rows: &[CampaignRow], skipped: &[(String, String)]) -> String {
    let mut s = String::from(
        "\n### Campaigns (paper sections 3.2-3.4), whole runs through the pipeline\n\n| campaign | what | pulses | rays/pulse | run s | simulate s | pulses/s | peak memory MB | result |\n| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.1} | {:.1} | {:.0} | {} | {} |",
            r.name,
            r.what,
            r.pulses,
            r.rays_per_pulse,
            r.run_s,
            r.simulate_s,
            r.pulses_per_s,
            r.peak_mb.map_or("–".to_string(), |m| format!("{m:.0}")),
            r.result
        );
    }
    for (name, why) in skipped {
        let _ = writeln!(s, "| {name} | skipped: {why} | | | | | | | |");
    }
    s
}
