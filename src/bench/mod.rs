//! `lidarsim bench`: speed against error, measured on this machine.
//!
//! A GEDI-like pulse (paper Table 1: 419 km, 0.5 m², 0.3 mrad field of view, 1 ns bins,
//! 14 ns pulse) over a generated canopy with a 25 m footprint. A reference waveform with
//! many rays, then, for each method, the fewest rays (on a 1-2-5 ladder) whose waveforms reach
//! rRMSE ≤ 5% against it (median over several seeds), with their wall time.

pub mod campaigns;
pub mod traversal;

use crate::campaign::{Campaign, Instrument, Method, Sampler, SunSelection};
use crate::error::{Error, Result};
use crate::generate::{canopy, Canopy};
use crate::plan::Pulse;
use crate::scene::Scene;
use crate::transport::Scratch;
use crate::waveform::pulse::PulseSimulator;
use crate::waveform::Waveform;
use glam::DVec3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Rays of the reference waveform.
    pub reference_rays: u64,
    /// Seeds per ray count (the median rRMSE is used).
    pub seeds: u64,
    /// Largest ray count tried per method.
    pub max_rays: u64,
    /// Folder for the generated scene and the report.
    pub dir: PathBuf,
    pub footprint_diameter_m: f64,
    /// Field-of-view half angle, mrad (GEDI: 0.3).
    pub fov_mrad: f64,
    pub canopy: Canopy,
    /// Footprint diameters (m) of the paper's Table 2: rays each method needs at each.
    pub table2_footprints: Vec<f64>,
    /// Largest ray count tried per method in the Table 2 rows.
    pub table2_max_rays: u64,
    /// Run the campaign rows (orchard GEDI and MABEL, ALS over a forest and over a town).
    pub campaigns: bool,
    /// The paper's sizes for the campaign rows (`--full`).
    pub full: bool,
    /// Scene file of the RAMI orchard for the campaign rows.
    pub rami_scene: PathBuf,
    /// Folder of the campaign rows' files (`pipelines/bench/`).
    pub campaigns_dir: PathBuf,
    /// The lidarsim executable that runs each campaign row in a process of its own, as a
    /// user runs a campaign; None: in this process (see `campaigns::run_row`).
    pub runner: Option<PathBuf>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        BenchOptions {
            reference_rays: 10_000_000,
            seeds: 5,
            max_rays: 2_000_000,
            dir: PathBuf::from("runs/bench"),
            footprint_diameter_m: 25.0,
            fov_mrad: 0.3,
            canopy: Canopy::default(),
            table2_footprints: vec![0.05, 1.0, 10.0, 25.0, 30.0],
            table2_max_rays: 2_000_000,
            campaigns: true,
            full: false,
            rami_scene: PathBuf::from("scenes/rami_wco.yaml"),
            campaigns_dir: PathBuf::from("pipelines/bench"),
            runner: None,
        }
    }
}

impl BenchOptions {
    /// The default, quick bench: a 10^6-ray reference, 3 seeds, ladders to 2·10^5 rays,
    /// campaign rows at a tenth of the paper's size.
    pub fn quick(dir: PathBuf) -> BenchOptions {
        BenchOptions {
            reference_rays: 1_000_000,
            seeds: 3,
            max_rays: 1_000_000,
            table2_max_rays: 200_000,
            dir,
            ..BenchOptions::default()
        }
    }

    /// `--full`: the paper's sizes, a 10^7-ray reference, 5 seeds; Table 2 ladders stop at
    /// 5·10^5 rays (backward tracing never reaches 5% at small footprints, and each of its
    /// rungs would cost minutes in the forest).
    pub fn full(dir: PathBuf) -> BenchOptions {
        BenchOptions {
            full: true,
            table2_max_rays: 500_000,
            dir,
            ..BenchOptions::default()
        }
    }
}

/// One method's row of the table.
#[derive(Clone, Debug)]
pub struct LadderRow {
    pub method: Method,
    pub sampler: Sampler,
    /// Fewest rays reaching the target, or None if `max_rays` did not.
    pub rays: Option<u64>,
    pub rrmse: f64,
    pub seconds: f64,
    pub rays_per_second: f64,
    pub paths_per_ray: f64,
    /// (rays, median rRMSE) along the ladder.
    pub curve: Vec<(u64, f64)>,
    /// (rays, median R² against the reference) along the ladder.
    pub r2: Vec<(u64, f64)>,
}

fn gedi(footprint_diameter_m: f64, fov_mrad: f64, altitude: f64) -> Instrument {
    let half_angle_mrad = (footprint_diameter_m / 2.0 / altitude).atan() * 1e3;
    serde_yaml::from_str(&format!(
        "pulse_energy_j: 0.0105\npulse_fwhm_ns: 14\nfootprint_half_angle_mrad: {half_angle_mrad}\nfov_half_angle_mrad: {fov_mrad}\nreceiver_area_m2: 0.5\nbin_ns: 1\nbandwidth_nm: 0.8"
    ))
    .expect("a fixed instrument parses")
}

/// The bins where a reference waveform carries signal (above 1e-3 of its peak): where the
/// bench compares waveforms with it.
fn signal_bins(reference: &[f32]) -> Vec<usize> {
    let peak = reference.iter().cloned().fold(0.0f32, f32::max) as f64;
    (0..reference.len())
        .filter(|&i| reference[i] as f64 > 1e-3 * peak)
        .collect()
}

/// rRMSE of a waveform against a reference over the bins where the reference carries signal
/// ([`crate::waveform::rrmse`] over [`signal_bins`]).
pub fn rrmse(w: &[f32], reference: &[f32]) -> f64 {
    crate::waveform::rrmse(w, reference, &signal_bins(reference))
}

/// Coefficient of determination of a waveform against the reference, over the same bins as
/// [`rrmse`]: 1 − Σ(w − r)² / Σ(r − r̄)².
pub fn r_squared(w: &[f32], reference: &[f32]) -> f64 {
    let bins = signal_bins(reference);
    if bins.len() < 2 {
        return f64::NAN;
    }
    let mean = bins.iter().map(|&i| reference[i] as f64).sum::<f64>() / bins.len() as f64;
    let ss_res: f64 = bins
        .iter()
        .map(|&i| (w[i] as f64 - reference[i] as f64).powi(2))
        .sum();
    let ss_tot: f64 = bins
        .iter()
        .map(|&i| (reference[i] as f64 - mean).powi(2))
        .sum();
    1.0 - ss_res / ss_tot
}

/// The bench's GEDI-like pulse: a one-pulse campaign (the one way a pulse is set up), whose
/// method, sampler, rays, seed and sun each measurement sets.
struct Bench<'a> {
    scene: &'a Scene,
    campaign: Campaign,
    pulse: Pulse,
}

impl<'a> Bench<'a> {
    fn new(scene: &'a Scene, scene_path: &Path, inst: &Instrument, origin: DVec3) -> Result<Self> {
        let simulation = "{ method: bdpt, max_order: 100, mis: power, receiver_depth: full }";
        let request = crate::plan::OnePulse {
            instrument: serde_yaml::to_value(inst).map_err(|e| Error::msg(e.to_string()))?,
            origin: origin.to_array(),
            direction: [0.0, 0.0, -1.0],
            wavelength_nm: 1064.0.into(),
            simulation: serde_yaml::from_str(simulation).map_err(|e| Error::msg(e.to_string()))?,
            seed: 1,
            sun: None,
            atmosphere: None,
        };
        let (loaded, pulse) = request.campaign(scene_path, "bench pulse")?;
        Ok(Bench {
            scene,
            campaign: loaded.campaign,
            pulse,
        })
    }

    fn run(&self, method: Method, sampler: Sampler, rays: u64, seed: u64) -> (Waveform, f64) {
        self.run_with_sun(method, sampler, rays, seed, None)
    }

    fn run_with_sun(
        &self,
        method: Method,
        sampler: Sampler,
        rays: u64,
        seed: u64,
        sun: Option<crate::campaign::Sun>,
    ) -> (Waveform, f64) {
        let mut c = self.campaign.clone();
        c.simulation.method = method;
        c.simulation.sampler = sampler;
        c.simulation.rays_per_pulse = rays;
        c.seed = seed;
        c.sun = sun;
        let sim = PulseSimulator::new(&c, self.scene);
        let t = Instant::now();
        let (w, _) = sim.simulate(&self.pulse, &mut Scratch::default());
        (w, t.elapsed().as_secs_f64())
    }
}

/// Runs the benchmark and returns the markdown report: the ladder on one GEDI-like pulse,
/// the sun's cost, the paper's Table 2, the campaign rows.
pub fn run(opts: &BenchOptions) -> Result<String> {
    crate::progress::reset_peak_rss();
    let (scene_path, size, what) = bench_scene(opts)?;
    let scene = Scene::load(&scene_path, 1064.0)?;
    let stats = scene.stats();
    let altitude = 419_000.0;
    let origin = DVec3::new(size / 2.0, size / 2.0, altitude);
    let bench_for = |footprint: f64| {
        let inst = gedi(footprint, opts.fov_mrad, altitude);
        Bench::new(&scene, &scene_path, &inst, origin)
    };
    let b = bench_for(opts.footprint_diameter_m)?;
    eprintln!(
        "lidarsim bench: reference waveform, bdpt, {} rays",
        opts.reference_rays
    );
    let (reference, ref_secs) = b.run(
        Method::Bdpt,
        Sampler::Independent,
        opts.reference_rays,
        1_000_003,
    );
    if reference.received_energy_j <= 0.0 {
        return Err(Error::msg("bench: the reference waveform is empty"));
    }
    let rows: Vec<LadderRow> = ladder_columns()
        .map(|(m, q)| ladder(&b, &reference, m, q, opts.seeds, opts.max_rays))
        .collect();
    let single_pulse_peak_mb = campaigns::peak_memory_mb();
    let mut text = provenance(opts);
    text += &report(opts, &what, &stats, &reference, ref_secs, &rows);
    if let Some(mb) = single_pulse_peak_mb {
        let _ = writeln!(
            text,
            "\nPeak memory of the single-pulse runs (scene and tracer): {mb:.0} MiB."
        );
    }
    text += &sun_section(opts, &b, &reference);

    // the paper's Table 2: rays for rRMSE ≤ 5% at other footprints
    if !opts.table2_footprints.is_empty() {
        let mut t2 = Vec::new();
        for &d in &opts.table2_footprints {
            let bd = bench_for(d)?;
            let reference = if d == opts.footprint_diameter_m {
                reference.clone()
            } else {
                eprintln!(
                    "lidarsim bench: footprint {d} m: reference, {} rays",
                    opts.reference_rays
                );
                bd.run(
                    Method::Bdpt,
                    Sampler::Independent,
                    opts.reference_rays,
                    1_000_003,
                )
                .0
            };
            let rows: Vec<LadderRow> = ladder_columns()
                .map(|(m, q)| ladder(&bd, &reference, m, q, opts.seeds, opts.table2_max_rays))
                .collect();
            t2.push((d, rows));
        }
        text += &table2(&t2, opts.table2_max_rays);
    }
    if opts.campaigns {
        text += &campaigns_section(opts)?;
    }
    text += &parquet_section(opts)?;
    Ok(text)
}

/// Writing waveform parts: every candidate encoding on one part of the ALS campaign row,
/// timed (median of 5 writes to memory) and sized, each read back and compared with the
/// waveforms it was given.
fn parquet_section(opts: &BenchOptions) -> Result<String> {
    use crate::parquet_io::{CANDIDATES, ENCODING};
    use crate::waveform::file::{part_name, read_waveforms, waveform_table};
    let mut s = String::from("\n### Writing waveform parts: encoding against size\n\n");
    let part = opts.dir.join("als_forest/run").join(part_name(0));
    if !part.is_file() {
        s += "Skipped: no waveform part of the als_forest row (the campaign rows did not run).\n";
        return Ok(s);
    }
    let waves = read_waveforms(&part)?;
    let table = waveform_table(&waves);
    let bins: usize = waves.iter().map(|w| w.laser_photons.len()).sum();
    let _ = writeln!(
        s,
        "Part 0 of the als_forest row: {} waveforms, {:.0} bins each on average; median of 5 writes to memory; every encoding reads back equal to what it was given. Arrow's writer takes a record batch (built inside the timing); lidarsim writes the columns straight from the waveforms, to the same bytes as Arrow's writer at its encoding.\n\n| encoding | writer | write ms | size MB |\n| --- | --- | ---: | ---: |",
        waves.len(),
        bins as f64 / waves.len().max(1) as f64
    );
    let check = opts.dir.join("encoding_check.parquet");
    let direct = |e: &crate::parquet_io::Encoding| table.encode(Vec::new(), e.props());
    let arrow = |e: &crate::parquet_io::Encoding| table.encode_with_arrow(e.props());
    let mut rows: Vec<(crate::parquet_io::Encoding, &str)> =
        CANDIDATES.iter().map(|&e| (e, "Arrow")).collect();
    rows.push((ENCODING, "columns (lidarsim's)"));
    for (e, writer) in rows {
        let mut times = Vec::new();
        let mut bytes = Vec::new();
        for _ in 0..5 {
            let t = Instant::now();
            bytes = if writer == "Arrow" {
                arrow(&e)
            } else {
                direct(&e)
            }
            .map_err(|err| Error::data(&part, format!("{}: {err}", e.name)))?;
            times.push(t.elapsed().as_secs_f64());
        }
        std::fs::write(&check, &bytes).map_err(|err| Error::io(&check, "cannot write", err))?;
        // compared as text: a NaN (a figure with no meaning for the run) equals itself there
        if format!("{:?}", read_waveforms(&check)?) != format!("{waves:?}") {
            return Err(Error::data(
                &check,
                format!("{}: read back differs", e.name),
            ));
        }
        let _ = writeln!(
            s,
            "| {} | {writer} | {:.1} | {:.3} |",
            e.name,
            1e3 * median(&mut times),
            bytes.len() as f64 / 1e6
        );
    }
    let _ = std::fs::remove_file(&check);
    Ok(s)
}

/// Where the figures come from: the command, the commit and the machine, so that a table
/// quoted elsewhere says what produced it.
fn provenance(opts: &BenchOptions) -> String {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let commit = match git(&["rev-parse", "--short", "HEAD"]) {
        Some(c)
            if git(&["status", "--porcelain", "--untracked-files=no"])
                .is_some_and(|s| !s.is_empty()) =>
        {
            format!("{c} with uncommitted changes")
        }
        Some(c) => c,
        None => "unknown (not run from a git checkout)".into(),
    };
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!(
        "Measured by `lidarsim bench{}` (reference {} rays, {} seeds) at commit {commit}, lidarsim {}, on {cpu} ({cores} cores available, {} threads used).\n\n",
        if opts.full { " --full" } else { "" },
        opts.reference_rays,
        opts.seeds,
        env!("CARGO_PKG_VERSION"),
        rayon::current_num_threads()
    )
}

/// The single pulse's scene: the generated forest (the paper's stand size) with `--full`, a
/// lighter canopy otherwise. Returns its file, its size (m) and a line describing it.
fn bench_scene(opts: &BenchOptions) -> Result<(PathBuf, f64, String)> {
    if opts.full {
        let (path, size) = campaigns::forest_scene(&opts.dir, true)?;
        return Ok((
            path,
            size,
            format!("generated forest (`lidarsim scene generate forest --seed 2`) on {size} m × {size} m"),
        ));
    }
    let spec = &opts.canopy;
    let path = canopy(&opts.dir.join("canopy"), spec)?;
    Ok((
        path,
        spec.size,
        format!(
            "{} crowns ({} templates × {} leaves) on {} m × {} m",
            spec.trees, spec.templates, spec.leaves, spec.size, spec.size
        ),
    ))
}

/// The sun in the same paths: wall time at the same rays per pulse with the sun at 50° zenith
/// and without, then fixed against by-power light selection.
fn sun_section(opts: &BenchOptions, b: &Bench, reference: &Waveform) -> String {
    let sun_spec = |selection| crate::campaign::Sun {
        zenith_deg: 50.0,
        azimuth_deg: 180.0,
        irradiance_w_m2_um: 640.0,
        selection: Some(selection),
        selection_probability: (selection == SunSelection::Fixed).then_some(0.5),
        share: None,
    };
    let sun_rays = opts.reference_rays / 50;
    let fixed = sun_spec(SunSelection::Fixed);
    let (mut off, mut on) = (Vec::new(), Vec::new());
    let mut photons = 0.0;
    for seed in 0..opts.seeds {
        off.push(
            b.run_with_sun(
                Method::Bdpt,
                Sampler::Independent,
                sun_rays,
                40 + seed,
                None,
            )
            .1,
        );
        let (w, t) = b.run_with_sun(
            Method::Bdpt,
            Sampler::Independent,
            sun_rays,
            40 + seed,
            Some(fixed.clone()),
        );
        on.push(t);
        photons = w.solar_photons_per_bin as f64;
    }
    let (t_off, t_on) = (median(&mut off), median(&mut on));
    let mut text = String::new();
    let _ = writeln!(
        text,
        "\n### Sun on and off (bdpt, {sun_rays} rays, sun at 50° zenith, 0.8 nm band)\n\n| sun | wall s (median) |\n| --- | ---: |\n| off | {t_off:.3} |\n| on | {t_on:.3} |\n\nRatio {:.2}; {photons:.3} solar photons per bin.",
        t_on / t_off
    );
    let selections: Vec<SelectionRow> = [SunSelection::Fixed, SunSelection::Power]
        .into_iter()
        .map(|sel| selection_row(b, reference, sun_spec(sel), sel, sun_rays, opts.seeds))
        .collect();
    text += &selection_table(&selections, sun_rays);
    text
}

/// The campaign rows: each planned campaign run through the pipeline and measured, or the
/// reason it was skipped.
fn campaigns_section(opts: &BenchOptions) -> Result<String> {
    let planned = campaigns::plan(&opts.dir, &opts.campaigns_dir, &opts.rami_scene, opts.full)?;
    let (mut rows, mut skipped, mut traversals) = (Vec::new(), Vec::new(), Vec::new());
    let (mut scaling, mut bands) = (Vec::new(), Vec::new());
    for p in planned {
        match p {
            campaigns::Planned::Run { name, what, text } => {
                eprintln!("lidarsim bench: campaign {name}");
                let runner = opts.runner.as_deref();
                let row = campaigns::run_row_settled(&opts.dir, runner, &name, &what, &text)?;
                if name == "mabel_1064" {
                    eprintln!("lidarsim bench: campaign {name} in one band and in three");
                    bands.push(campaigns::bands_row(&opts.dir, &name, &text, 3)?);
                }
                // each bench scene's traversals: the forest and the town by their ALS rows
                // (2000 pulses spread over the campaign, with its rays per pulse), the orchard
                // by 100 shots of the MABEL track with the sun (hundreds of rays each)
                let path = opts.dir.join(&name).join("campaign.yaml");
                if name == "mabel_1064_sun" {
                    traversals.push(traversal::measure(&name, &path, 100)?);
                }
                if name.starts_with("als_") {
                    traversals.push(traversal::measure(&name, &path, 2000)?);
                    eprintln!("lidarsim bench: campaign {name} on one thread and on all, 3 pairs");
                    scaling.push(campaigns::scaling(&opts.dir, runner, &row, &text)?);
                }
                rows.push(row);
            }
            campaigns::Planned::Skipped { name, why } => {
                eprintln!("lidarsim bench: campaign {name} skipped: {why}");
                skipped.push((name, why));
            }
        }
    }
    Ok(campaigns::table(&rows, &skipped)
        + &campaigns::scaling_table(&scaling)
        + &traversal::table(&traversals)
        + &campaigns::bands_table(&bands))
}

/// Table 2 of the paper: rays (and wall seconds) each method needs for rRMSE ≤ 5% by
/// footprint diameter.
fn table2(rows: &[(f64, Vec<LadderRow>)], max_rays: u64) -> String {
    let names: Vec<String> = rows
        .first()
        .map(|(_, r)| r.iter().map(LadderRow::name).collect())
        .unwrap_or_default();
    let mut s = format!(
        "\n### Rays for rRMSE ≤ 5% by footprint diameter (paper Table 2)\n\n| footprint m | {} |\n| ---: |{}\n",
        names.join(" | "),
        " ---: |".repeat(names.len())
    );
    for (d, r) in rows {
        let cells: Vec<String> = r
            .iter()
            .map(|row| match row.rays {
                Some(n) => format!("{n} ({:.3} s)", row.seconds),
                None => format!("> {max_rays}"),
            })
            .collect();
        let _ = writeln!(s, "| {d} | {} |", cells.join(" | "));
    }
    s
}

/// How one way of choosing between the sun and the laser converges.
#[derive(Clone, Debug)]
pub struct SelectionRow {
    pub selection: SunSelection,
    /// Probability of the sun.
    pub q: f64,
    /// Medians over seeds at the same rays: laser rRMSE against the reference, relative
    /// standard error of the solar power, wall seconds.
    pub laser_rrmse: f64,
    pub solar_rel_se: f64,
    pub seconds: f64,
}

impl SelectionRow {
    /// Wall time to reach both laser rRMSE ≤ 5 % and solar relative SE ≤ 1 %, from the
    /// 1/√N law of Monte Carlo errors: t · max((rRMSE/5 %)², (SE/1 %)²).
    pub fn seconds_to_target(&self) -> f64 {
        self.seconds
            * (self.laser_rrmse / 0.05)
                .powi(2)
                .max((self.solar_rel_se / 0.01).powi(2))
    }
}

fn selection_row(
    b: &Bench,
    reference: &Waveform,
    sun: crate::campaign::Sun,
    selection: SunSelection,
    rays: u64,
    seeds: u64,
) -> SelectionRow {
    // the probability of tracing the sun that the pulse's setup gives it
    let q = {
        let mut c = b.campaign.clone();
        c.sun = Some(sun.clone());
        let sim = PulseSimulator::new(&c, b.scene);
        let setup = sim.setup(&b.pulse, Method::Bdpt);
        setup.sun.map_or(0.0, |s| s.probability)
    };
    let (mut e, mut se, mut t) = (Vec::new(), Vec::new(), Vec::new());
    for seed in 0..seeds {
        let (w, secs) = b.run_with_sun(
            Method::Bdpt,
            Sampler::Independent,
            rays,
            60 + seed,
            Some(sun.clone()),
        );
        e.push(rrmse(&w.laser_photons, &reference.laser_photons));
        se.push(w.solar_power_se_w / w.solar_power_w);
        t.push(secs);
    }
    SelectionRow {
        selection,
        q,
        laser_rrmse: median(&mut e),
        solar_rel_se: median(&mut se),
        seconds: median(&mut t),
    }
}

fn selection_table(rows: &[SelectionRow], rays: u64) -> String {
    let mut s = format!(
        "\n### Choosing the light: fixed 0.5 against by power (bdpt, {rays} rays)\n\nTime to target: wall time scaled by 1/√N to reach laser rRMSE ≤ 5% and solar relative SE ≤ 1%.\n\n| selection | sun probability | laser rRMSE | solar rel. SE | wall s | time to target s |\n| --- | ---: | ---: | ---: | ---: | ---: |\n"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {:.3} | {:.2}% | {:.2}% | {:.3} | {:.3} |",
            format!("{:?}", r.selection).to_lowercase(),
            r.q,
            100.0 * r.laser_rrmse,
            100.0 * r.solar_rel_se,
            r.seconds,
            r.seconds_to_target()
        );
    }
    s
}

impl LadderRow {
    /// The method, and the sampler when it is not independent draws: "bdpt", "bdpt, sobol".
    pub fn name(&self) -> String {
        let method = format!("{:?}", self.method).to_lowercase();
        match self.sampler {
            Sampler::Independent => method,
            Sampler::Sobol => format!("{method}, sobol"),
        }
    }
}

/// The ladders' columns: each method with independent draws, then with low-discrepancy first
/// dimensions.
fn ladder_columns() -> impl Iterator<Item = (Method, Sampler)> {
    [Sampler::Independent, Sampler::Sobol]
        .into_iter()
        .flat_map(|q| [Method::Forward, Method::Backward, Method::Bdpt].map(|m| (m, q)))
}

/// The fewest rays on a 1-2-5 ladder from 100 whose median rRMSE over `seeds` reaches 5%.
fn ladder(
    b: &Bench,
    reference: &Waveform,
    method: Method,
    sampler: Sampler,
    seeds: u64,
    max_rays: u64,
) -> LadderRow {
    let mut row = LadderRow {
        method,
        sampler,
        rays: None,
        rrmse: f64::NAN,
        seconds: f64::NAN,
        rays_per_second: f64::NAN,
        paths_per_ray: f64::NAN,
        curve: Vec::new(),
        r2: Vec::new(),
    };
    let mut rays = 100u64;
    let mut step = 0;
    while rays <= max_rays {
        let mut errs = Vec::new();
        let mut secs = Vec::new();
        let mut paths = Vec::new();
        let mut r2 = Vec::new();
        for s in 0..seeds {
            let (w, t) = b.run(method, sampler, rays, 17 + s);
            errs.push(rrmse(&w.laser_photons, &reference.laser_photons));
            r2.push(r_squared(&w.laser_photons, &reference.laser_photons));
            secs.push(t);
            paths.push(w.paths_per_ray as f64);
        }
        let e = median(&mut errs);
        eprintln!(
            "lidarsim bench: {} {rays} rays: rRMSE {:.2}%",
            row.name(),
            100.0 * e
        );
        row.curve.push((rays, e));
        row.r2.push((rays, median(&mut r2)));
        if e <= 0.05 {
            let t = median(&mut secs);
            row.rays = Some(rays);
            row.rrmse = e;
            row.seconds = t;
            row.rays_per_second = rays as f64 / t;
            row.paths_per_ray = median(&mut paths);
            break;
        }
        // the 1-2-5 ladder
        rays = rays * if step % 3 == 1 { 5 } else { 2 } / if step % 3 == 1 { 2 } else { 1 };
        step += 1;
    }
    row
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn report(
    opts: &BenchOptions,
    what: &str,
    stats: &crate::scene::SceneStats,
    reference: &Waveform,
    ref_secs: f64,
    rows: &[LadderRow],
) -> String {
    let mut s = String::new();
    let threads = rayon::current_num_threads();
    let _ = writeln!(
        s,
        "### Rays to reach rRMSE ≤ 5%: GEDI-like pulse, {} m footprint, at the scene's centre\n",
        opts.footprint_diameter_m
    );
    let _ = writeln!(
        s,
        "Scene: {what}, {} instanced triangles. Reference: bdpt, {} rays, {:.1} s; {:.1}% of its energy beyond first order. {} seeds per ray count, median; {} threads.\n",
        stats.instanced_triangles,
        opts.reference_rays,
        ref_secs,
        100.0 * (1.0 - reference.order_energy_j[0] / reference.received_energy_j),
        opts.seeds,
        threads
    );
    let _ = writeln!(
        s,
        "| method | rays for rRMSE ≤ 5% | rRMSE | wall s | rays/s | threads busy | effective paths/ray |"
    );
    let _ = writeln!(s, "| --- | ---: | ---: | ---: | ---: | ---: | ---: |");
    for r in rows {
        let name = r.name();
        match r.rays {
            Some(n) => {
                // a pulse's chunks are its parallel tasks: under two chunks, one thread works
                let chunks = n.div_ceil(crate::transport::CHUNK_RAYS);
                let busy = chunks.min(threads as u64);
                let _ = writeln!(
                    s,
                    "| {name} | {n} | {:.2}% | {:.3} | {:.3e} | {busy} | {:.2} |",
                    100.0 * r.rrmse,
                    r.seconds,
                    r.rays_per_second,
                    r.paths_per_ray
                );
            }
            None => {
                let _ = writeln!(s, "| {name} | > {} | | | | | |", opts.max_rays);
            }
        }
    }
    s += &ladder_table(
        "median rRMSE by rays",
        rows,
        |r| &r.curve,
        |v| format!("{:.2}%", 100.0 * v),
    );
    s += &ladder_table("median R² by rays", rows, |r| &r.r2, |v| format!("{v:.4}"));
    s
}

/// One column per method of a figure along the ray ladder.
fn ladder_table(
    title: &str,
    rows: &[LadderRow],
    column: impl Fn(&LadderRow) -> &[(u64, f64)],
    cell: impl Fn(f64) -> String,
) -> String {
    let mut s = format!("\n{title}:\n\n");
    let names: Vec<String> = rows.iter().map(LadderRow::name).collect();
    let _ = writeln!(s, "| rays | {} |", names.join(" | "));
    let _ = writeln!(s, "| ---: |{}", " ---: |".repeat(rows.len()));
    let mut all: Vec<u64> = rows
        .iter()
        .flat_map(|r| column(r).iter().map(|c| c.0))
        .collect();
    all.sort();
    all.dedup();
    for n in all {
        let cells: Vec<String> = rows
            .iter()
            .map(|r| {
                column(r)
                    .iter()
                    .find(|c| c.0 == n)
                    .map(|c| cell(c.1))
                    .unwrap_or_default()
            })
            .collect();
        let _ = writeln!(s, "| {n} | {} |", cells.join(" | "));
    }
    s
}

/// Writes the report beside the generated scene and returns its path.
/// Writes the report to `path` (its folder made when missing).
pub fn write_report(path: &Path, text: &str) -> Result<PathBuf> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| {
            Error::io(dir, "cannot create the report's folder", e)
                .advise(crate::fsutil::WRITE_ADVICE)
        })?;
    }
    crate::fsutil::write_text_atomic(path, text)?;
    Ok(path.to_path_buf())
}

/// Used by tests: the ladder and the report on a small scene, quickly.
pub fn quick_options(dir: &Path) -> BenchOptions {
    BenchOptions {
        reference_rays: 200_000,
        seeds: 3,
        max_rays: 50_000,
        table2_footprints: vec![1.0],
        table2_max_rays: 50_000,
        campaigns: false,
        dir: dir.to_path_buf(),
        footprint_diameter_m: 25.0,
        // few but large leaves: a dense canopy that is quick to build
        canopy: Canopy {
            trees: 700,
            leaves: 2000,
            leaf_m: 0.25,
            ..Canopy::default()
        },
        ..BenchOptions::default()
    }
}
