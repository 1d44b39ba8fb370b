//! `check`: a campaign validated, its scene loaded and measured, and the run's memory and
//! time estimated before any ray is traced. The CLI prints the report; the Python package
//! hands it over as a dict.

use crate::error::Result;
use crate::plan::{self, Plan};
use crate::progress::{peak_rss_bytes, reset_peak_rss};
use crate::scene::Scene;
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// What `check` finds. Sizes in MB are 10^6 bytes, as the CLI prints them; the memory
/// bound is also given in MiB.
#[derive(Clone, Debug, Serialize)]
pub struct CheckReport {
    pub campaign: String,
    pub campaign_file: String,
    pub scene: String,
    pub scene_file: String,
    /// Pulses the run fires: over all of its runs for a sweep.
    pub pulses: u64,
    /// The recorded trajectory a platform flies, as one line, when it flies one.
    pub trajectory: Option<String>,
    pub wavelengths_nm: Vec<f64>,
    /// The water surface, as one line, when the scene has one.
    pub water: Option<String>,
    pub rays_per_pulse: u64,
    pub instances: u64,
    pub distinct_meshes: u64,
    pub traced_meshes: u64,
    pub traced_instances: u64,
    pub distinct_triangles: u64,
    /// Instanced triangles: every instance's counted.
    pub triangles: u64,
    pub scene_memory_mb: f64,
    pub peak_process_memory_mb: Option<f64>,
    pub bounds: [[f64; 3]; 2],
    pub repeated: bool,
    pub scene_load_s: f64,
    /// What the pilots of `auto` keys chose, when there were any.
    pub pilot: Option<String>,
    /// A sweep's sub-runs, by name.
    pub sweep: Vec<String>,
    /// This process with the scene loaded, and the run's bound on top: bytes.
    pub process_bytes: f64,
    pub run_bytes: f64,
    pub memory_bound_mib: f64,
    pub total_rays: f64,
    pub rays_per_second: f64,
    pub threads: usize,
    pub estimated_time_s: f64,
    pub warnings: Vec<String>,
}

/// Long because it gathers every figure of the report in the order `check` prints them.
pub fn check(path: &Path) -> Result<CheckReport> {
    // the process as it is now, with the scene about to be loaded: not what a host process
    // (Python) held and gave back before the call
    reset_peak_rss();
    let loaded = plan::read_campaign(path)?;
    let c = &loaded.campaign;
    let plan = Plan::new(c)?;
    let t = Instant::now();
    let scene = Scene::load_bands(&loaded.scene_path, c.wavelength_nm.all())?;
    let scene_load_s = t.elapsed().as_secs_f64();
    // before the probes below, which trace pulses in gates of the campaign's size
    super::memory::fits(&loaded, &scene, &plan)?;
    mission_fits(&loaded, &scene, &plan)?;
    let s = scene.stats();
    let (lo, hi) = scene.bounds();
    let water = scene.water.as_ref().map(|w| {
        format!(
            "surface at z = {} m over [{}, {}] .. [{}, {}], n = {}, {}",
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
        )
    });
    let peak_process_memory_mb = peak_rss_bytes().map(|b| b as f64 / 1e6);
    // the estimates are of the method the run will use
    let chosen = super::with_method_chosen(&loaded, &scene, &plan);
    let pilot = chosen
        .as_ref()
        .map(|c| c.method_note.clone().unwrap_or_default());
    let run = chosen.as_ref().unwrap_or(&loaded);
    let rate = super::probe_rays_per_second(run, &scene, &plan);
    let mut total_rays = plan.len() as f64 * c.simulation.rays_per_pulse as f64;
    let mut sweep = Vec::new();
    let mut pulses = plan.len() as u64;
    // a sweep: every combination checked as the run would check it, its rays counted at the
    // rate measured on the campaign as written
    if let Some(spec) = &c.sweep {
        let runs = super::sweep::sweep_runs(run, spec, &scene)?;
        (total_rays, pulses) = (0.0, 0);
        for (sub, name) in runs {
            let n = Plan::new(&sub.campaign)?.len();
            total_rays += n as f64 * sub.campaign.simulation.rays_per_pulse as f64;
            pulses += n as u64;
            sweep.push(name);
        }
    }
    let run_bytes = super::memory::bound(run, &scene, &plan).total();
    // what this process holds now: the program, its threads and the scene
    let process_bytes = peak_rss_bytes().map_or(s.memory_bytes as f64, |b| b as f64);
    Ok(CheckReport {
        campaign: c.name.clone(),
        campaign_file: path.display().to_string(),
        scene: scene.name.clone(),
        scene_file: loaded.scene_path.display().to_string(),
        pulses,
        trajectory: plan.trajectory_note(),
        wavelengths_nm: c.wavelength_nm.all().to_vec(),
        water,
        rays_per_pulse: c.simulation.rays_per_pulse,
        instances: s.instances as u64,
        distinct_meshes: s.distinct_meshes as u64,
        traced_meshes: s.traced_meshes as u64,
        traced_instances: s.traced_instances as u64,
        distinct_triangles: s.distinct_triangles as u64,
        triangles: s.instanced_triangles as u64,
        scene_memory_mb: s.memory_bytes as f64 / 1e6,
        peak_process_memory_mb,
        bounds: [lo.to_array(), hi.to_array()],
        repeated: scene.is_repeated(),
        scene_load_s,
        pilot,
        sweep,
        process_bytes,
        run_bytes,
        memory_bound_mib: (process_bytes + run_bytes) / (1024.0 * 1024.0),
        total_rays,
        rays_per_second: rate,
        threads: rayon::current_num_threads(),
        estimated_time_s: total_rays / rate,
        warnings: c
            .warnings()
            .into_iter()
            .chain(scene_warnings(c, &scene, &plan))
            .collect(),
    })
}

/// Most samples GEDI's `rx_sample_count` (16 bits) gives a shot of `waveforms_l1b.h5`.
const L1B_MAX_SAMPLES: usize = u16::MAX as usize;

/// A waveform instrument's gates against what `waveforms_l1b.h5` holds a shot, before any
/// pulse is traced: the gates of up to 64 pulses spread over the plan, as the scene's ranges
/// size them (a `range_gate` is checked with the campaign).
pub fn mission_fits(loaded: &crate::campaign::Loaded, scene: &Scene, plan: &Plan) -> Result<()> {
    let inst = &loaded.campaign.instrument;
    if inst.kind != crate::campaign::InstrumentKind::Waveform || inst.range_gate.is_some() {
        return Ok(());
    }
    let most = plan
        .spread(64, loaded.campaign.seed)
        .iter()
        .map(|p| {
            let near = scene.bounds_near(p.origin, p.direction);
            crate::sensor::Gate::for_pulse(inst, p.origin, p.direction, near).bins
        })
        .max()
        .unwrap_or(0);
    if most <= L1B_MAX_SAMPLES {
        return Ok(());
    }
    Err(loaded.doc.error(
        "instrument.bin_ns",
        format!(
            "the scene's ranges make gates of {most} bins of {} ns, more than the 65535 samples \
             waveforms_l1b.h5 gives a shot (GEDI's rx_sample_count is 16 bits): use wider bins \
             or a range_gate",
            inst.bin_ns
        ),
    ))
}

/// What `check` and the run log warn of a campaign over its scene: where its pulses aim
/// ([`aim_warnings`]) and what a smooth water surface hides ([`water_warnings`]).
pub fn scene_warnings(c: &crate::campaign::Campaign, scene: &Scene, plan: &Plan) -> Vec<String> {
    let mut out = aim_warnings(c, scene, plan);
    out.extend(water_warnings(c, scene));
    out
}

/// A smooth water surface is a mirror: no strategy connects through it (docs/physics.md,
/// "Specular vertices"). `backward` then finds nothing of it or under it; forward and bdpt
/// find the light under it only along paths that happen to cross the aperture, which a
/// narrow field of view makes rare. Wind (even 0 m/s: Cox and Munk's calm sea) makes it rough.
pub fn water_warnings(c: &crate::campaign::Campaign, scene: &Scene) -> Vec<String> {
    if !scene.water.as_ref().is_some_and(|w| w.mss <= 0.0) {
        return Vec::new();
    }
    let calm = "give the water wind_speed_m_s (0 is Cox and Munk's calm sea, a rough surface \
                every strategy connects through)";
    if c.simulation.method == crate::campaign::Method::Backward {
        vec![format!(
            "simulation.method backward over smooth water: no receiver path joins the laser's \
             light through a mirror-flat surface, so its reflection and everything under it are \
             missing; use forward, bdpt or auto, or {calm}"
        )]
    } else {
        vec![format!(
            "the scene's water surface is smooth: light from under it reaches the telescope only \
             along paths that happen to cross the aperture, which a narrow field of view makes \
             rare, so the bottom's return may be missing or noisy; {calm}"
        )]
    }
}

/// Pulses traced for the ranges at which the scene lies before the sensor.
const OVERLAP_PULSES: u64 = 4096;

/// What the ranges at which up to 4,096 of the plan's pulses, spread over it, first meet the
/// scene say: the near-field overlap warning ([`crate::sensor::overlap`]), and a warning when
/// none of them meets it (a trajectory in local metres under a `frame`, lines beside the
/// scene), which would otherwise end in a run without a return.
pub fn aim_warnings(c: &crate::campaign::Campaign, scene: &Scene, plan: &Plan) -> Vec<String> {
    // one pulse drawn from each of 4,096 even strata of the ids, not every k-th: a stride
    // that is a multiple of the pulses a scan line or the beams would see one look angle or
    // one beam alone
    let pulses = plan.spread(OVERLAP_PULSES as usize, c.seed);
    let (mut lo, mut hi) = (
        glam::DVec3::splat(f64::INFINITY),
        glam::DVec3::splat(f64::NEG_INFINITY),
    );
    for p in &pulses {
        (lo, hi) = (lo.min(p.origin), hi.max(p.origin));
    }
    let tried = pulses.len();
    let none = crate::scene::FacetId::NONE;
    let ranges: Vec<f64> = pulses
        .iter()
        .filter_map(|p| {
            scene
                .intersect(p.origin, p.direction, f64::INFINITY, none)
                .map(|h| h.t)
        })
        .collect();
    let mut out: Vec<String> = crate::sensor::overlap::warning(&c.instrument, &ranges)
        .into_iter()
        .collect();
    if tried > 0 && ranges.is_empty() {
        let (slo, shi) = scene.bounds();
        out.push(format!(
            "none of {tried} pulses sampled over the plan meets the scene along its beam's axis: they leave from x {:.1} to {:.1}, y {:.1} to {:.1}, z {:.1} to {:.1} m and the scene spans x {:.1} to {:.1}, y {:.1} to {:.1}, z {:.1} to {:.1} m{}; check the platform's positions and aim",
            lo.x, hi.x, lo.y, hi.y, lo.z, hi.z, slo.x, shi.x, slo.y, shi.y, slo.z, shi.z,
            if c.frame.is_some() { " (both less the frame's origin)" } else { "" }
        ));
    }
    out
}

impl CheckReport {
    /// The report as `lidarsim check` prints it, a line each.
    pub fn lines(&self) -> Vec<String> {
        let mut out = vec![
            format!("campaign: {} ({})", self.campaign, self.campaign_file),
            format!("scene: {} ({})", self.scene, self.scene_file),
            format!("pulses: {}", self.pulses),
        ];
        if let Some(t) = &self.trajectory {
            out.push(format!("trajectory: {t}"));
        }
        if self.wavelengths_nm.len() > 1 {
            let nm: Vec<String> = self.wavelengths_nm.iter().map(|w| w.to_string()).collect();
            out.push(format!("bands: {} nm, traced in one pass", nm.join(", ")));
        }
        if let Some(w) = &self.water {
            out.push(format!("water: {w}"));
        }
        out.push(format!("rays per pulse: {}", self.rays_per_pulse));
        out.push(format!("instances: {}", self.instances));
        out.push(format!("distinct meshes: {}", self.distinct_meshes));
        out.push(format!(
            "traced as: {} meshes, {} instances (objects with equal instance tables are one mesh)",
            self.traced_meshes, self.traced_instances
        ));
        out.push(format!("triangles (distinct): {}", self.distinct_triangles));
        out.push(format!("triangles (instanced): {}", self.triangles));
        out.push(format!("scene memory: {:.1} MB", self.scene_memory_mb));
        if let Some(peak) = self.peak_process_memory_mb {
            out.push(format!("peak process memory: {peak:.1} MB"));
        }
        let [lo, hi] = self.bounds;
        out.push(format!(
            "bounds: [{:.3}, {:.3}, {:.3}] .. [{:.3}, {:.3}, {:.3}] m{}",
            lo[0],
            lo[1],
            lo[2],
            hi[0],
            hi[1],
            hi[2],
            if self.repeated {
                " (repeat: one period of an infinite landscape in x and y)"
            } else {
                ""
            }
        ));
        out.push(format!("scene load: {:.2} s", self.scene_load_s));
        if let Some(p) = &self.pilot {
            // the method's, the sun's selection's and bdpt's receiver depth's choices
            out.push(format!("pilot: {p}"));
        }
        if !self.sweep.is_empty() {
            out.push(format!(
                "sweep: {} runs ({})",
                self.sweep.len(),
                self.sweep.join(", ")
            ));
        }
        out.push(format!(
            "estimated peak memory: {:.0} MB (this process with the scene loaded {:.0} MB + run {:.0} MB; a bound that does not grow with the number of pulses)",
            (self.process_bytes + self.run_bytes) / 1e6,
            self.process_bytes / 1e6,
            self.run_bytes / 1e6
        ));
        out.push(format!(
            "estimated time: {} ({:.3e} rays at {:.3e} rays/s measured here on {} threads)",
            human_seconds(self.estimated_time_s),
            self.total_rays,
            self.rays_per_second,
            self.threads
        ));
        out.extend(self.warnings.iter().map(|w| format!("warning: {w}")));
        out.push("ok".into());
        out
    }
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
