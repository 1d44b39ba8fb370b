//! `lidarsim check`: a campaign validated, its scene loaded and measured, and the run's
//! memory and time estimated before any ray is traced.

use super::require_file;
use crate::error::Result;
use crate::pipeline;
use crate::plan;
use crate::progress::peak_rss_bytes;
use crate::scene::Scene;
use std::time::Instant;

pub(super) fn check(path: &std::path::Path) -> Result<()> {
    require_file(path)?;
    let loaded = crate::plan::read_campaign(path)?;
    let c = &loaded.campaign;
    let pulses = plan::plan(c)?;
    let t = Instant::now();
    let scene = Scene::load(&loaded.scene_path, c.wavelength_nm)?;
    let load_s = t.elapsed().as_secs_f64();
    let s = scene.stats();
    let (lo, hi) = scene.bounds();
    println!("campaign: {} ({})", c.name, path.display());
    println!("scene: {} ({})", scene.name, loaded.scene_path.display());
    println!("pulses: {}", pulses.len());
    println!("rays per pulse: {}", c.simulation.rays_per_pulse);
    println!("instances: {}", s.instances);
    println!("distinct meshes: {}", s.distinct_meshes);
    println!("triangles (distinct): {}", s.distinct_triangles);
    println!("triangles (instanced): {}", s.instanced_triangles);
    println!("scene memory: {:.1} MB", s.memory_bytes as f64 / 1e6);
    if let Some(peak) = peak_rss_bytes() {
        println!("peak process memory: {:.1} MB", peak as f64 / 1e6);
    }
    println!(
        "bounds: [{:.3}, {:.3}, {:.3}] .. [{:.3}, {:.3}, {:.3}] m",
        lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
    );
    println!("scene load: {load_s:.2} s");
    let rate = pipeline::probe_rays_per_second(&loaded, &scene, &pulses);
    let total_rays = pulses.len() as f64 * c.simulation.rays_per_pulse as f64;
    // what a run holds beyond the scene: the pulses, one part of waveforms, per-thread tallies
    let bins = pulses
        .iter()
        .take(1)
        .map(|p| {
            crate::sensor::Gate::for_pulse(&c.instrument, p.origin, p.direction, scene.bounds())
                .bins
        })
        .next()
        .unwrap_or(0) as f64;
    let run_bytes = pulses.len() as f64 * 80.0
        + pipeline::PART_PULSES as f64 * (bins * 12.0 + c.simulation.max_order as f64 * 16.0)
        + rayon::current_num_threads() as f64 * bins * 64.0 * 8.0;
    println!(
        "estimated memory: {:.0} MB (scene {:.0} MB + run {:.0} MB)",
        (s.memory_bytes as f64 + run_bytes) / 1e6,
        s.memory_bytes as f64 / 1e6,
        run_bytes / 1e6
    );
    println!(
        "estimated time: {} ({:.3e} rays at {:.3e} rays/s measured here on {} threads)",
        human_seconds(total_rays / rate),
        total_rays,
        rate,
        rayon::current_num_threads()
    );
    println!("ok");
    Ok(())
}

fn human_seconds(s: f64) -> String {
    if s < 120.0 {
        format!("{s:.1} s")
    } else if s < 7200.0 {
        format!("{:.1} min", s / 60.0)
    } else {
        format!("{:.1} h", s / 3600.0)
    }
}
