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
    let plan = plan::Plan::new(c)?;
    let t = Instant::now();
    let scene = Scene::load_bands(&loaded.scene_path, c.wavelength_nm.all())?;
    let load_s = t.elapsed().as_secs_f64();
    // before the probes below, which trace pulses in gates of the campaign's size
    pipeline::memory::fits(&loaded, &scene, &plan)?;
    let s = scene.stats();
    let (lo, hi) = scene.bounds();
    println!("campaign: {} ({})", c.name, path.display());
    println!("scene: {} ({})", scene.name, loaded.scene_path.display());
    println!("pulses: {}", plan.len());
    if c.wavelength_nm.several() {
        println!("bands: {} nm, traced in one pass", c.wavelength_nm);
    }
    if let Some(w) = &scene.water {
        println!(
            "water: surface at z = {} m over [{}, {}] .. [{}, {}], n = {}, {}",
            w.z,
            w.lo[0],
            w.lo[1],
            w.hi[0],
            w.hi[1],
            w.n,
            if w.mss > 0.0 {
                format!("rough (mean square slope {:.4})", w.mss)
            } else {
                "smooth".to_string()
            }
        );
    }
    println!("rays per pulse: {}", c.simulation.rays_per_pulse);
    println!("instances: {}", s.instances);
    println!("distinct meshes: {}", s.distinct_meshes);
    println!(
        "traced as: {} meshes, {} instances (objects with equal instance tables are one mesh)",
        s.traced_meshes, s.traced_instances
    );
    println!("triangles (distinct): {}", s.distinct_triangles);
    println!("triangles (instanced): {}", s.instanced_triangles);
    println!("scene memory: {:.1} MB", s.memory_bytes as f64 / 1e6);
    if let Some(peak) = peak_rss_bytes() {
        println!("peak process memory: {:.1} MB", peak as f64 / 1e6);
    }
    println!(
        "bounds: [{:.3}, {:.3}, {:.3}] .. [{:.3}, {:.3}, {:.3}] m{}",
        lo.x,
        lo.y,
        lo.z,
        hi.x,
        hi.y,
        hi.z,
        if scene.is_repeated() {
            " (repeat: one period of an infinite landscape in x and y)"
        } else {
            ""
        }
    );
    println!("scene load: {load_s:.2} s");
    // the estimates are of the method the run will use
    let chosen = pipeline::with_method_chosen(&loaded, &scene, &plan);
    let loaded = match &chosen {
        Some(c) => {
            // the method's, the sun's selection's and bdpt's receiver depth's choices
            println!("pilot: {}", c.method_note.as_deref().unwrap_or_default());
            c
        }
        None => &loaded,
    };
    let rate = pipeline::probe_rays_per_second(loaded, &scene, &plan);
    let mut total_rays = plan.len() as f64 * c.simulation.rays_per_pulse as f64;
    // a sweep: every combination checked as the run would check it, its rays counted at the
    // rate measured on the campaign as written
    if let Some(sweep) = &c.sweep {
        let runs = pipeline::sweep::sweep_runs(loaded, sweep)?;
        total_rays = 0.0;
        for (sub, _) in &runs {
            let pulses = plan::Plan::new(&sub.campaign)?.len();
            total_rays += pulses as f64 * sub.campaign.simulation.rays_per_pulse as f64;
        }
        let names: Vec<&str> = runs.iter().map(|(_, n)| n.as_str()).collect();
        println!("sweep: {} runs ({})", runs.len(), names.join(", "));
    }
    let run_bytes = pipeline::memory::bound(loaded, &scene, &plan).total();
    // what this process holds now: the program, its threads and the scene
    let base = peak_rss_bytes().map_or(s.memory_bytes as f64, |b| b as f64);
    println!(
        "estimated peak memory: {:.0} MB (this process with the scene loaded {:.0} MB + run {:.0} MB; a bound that does not grow with the number of pulses)",
        (base + run_bytes) / 1e6,
        base / 1e6,
        run_bytes / 1e6
    );
    println!(
        "estimated time: {} ({:.3e} rays at {:.3e} rays/s measured here on {} threads)",
        human_seconds(total_rays / rate),
        total_rays,
        rate,
        rayon::current_num_threads()
    );
    for w in c.warnings() {
        println!("warning: {w}");
    }
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
