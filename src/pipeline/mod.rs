//! The run: stages that turn a campaign into the files of a run folder (outputs.md).
//!
//! plan → simulate → products → report. Every file is written under a temporary name and
//! renamed when complete, so a crash or a kill never leaves a half-written file under its final
//! name. `manifest.json` records, per stage, its status, the fingerprint of its inputs (the
//! resolved campaign, the scene's files, the tool version), its outputs and wall time. With
//! `--resume` a stage whose fingerprint is unchanged is kept, and simulation keeps every part
//! file already written: a run killed at any moment and resumed gives the same files as an
//! uninterrupted one, since every random draw derives from (seed, pulse, chunk).

pub mod bench;
pub mod bench_campaigns;
pub mod compare;
pub mod parquet;
pub mod products;

use crate::campaign::{Campaign, Loaded};
use crate::error::{Error, Result};
use crate::fsutil::write_text_atomic;
use crate::plan::{self, Pulse};
use crate::scene::Scene;
use crate::sensor::{pulse_sigma_s, Gate, Laser, Receiver, SunSource};
use crate::transport::{simulate_pulse, PulseSetup};
use crate::waveform::{self, Radiometry, Waveform};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Pulses per waveform part file.
pub const PART_PULSES: usize = 1000;

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Stage {
    Plan,
    Simulate,
    Products,
    Report,
}

impl Stage {
    pub const ALL: [Stage; 4] = [Stage::Plan, Stage::Simulate, Stage::Products, Stage::Report];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Plan => "plan",
            Stage::Simulate => "simulate",
            Stage::Products => "products",
            Stage::Report => "report",
        }
    }

    pub fn parse(s: &str) -> Result<Stage> {
        Stage::ALL.into_iter().find(|st| st.name() == s).ok_or_else(|| {
            Error::msg(format!("--stages: unknown stage `{s}`; the stages are plan, simulate, products, report"))
        })
    }
}

#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    pub out: Option<PathBuf>,
    pub threads: Option<usize>,
    pub resume: bool,
    /// Stages to run (all when None).
    pub stages: Option<Vec<Stage>>,
    /// Simulate only the parts whose index ≡ K mod N.
    pub shard: Option<(usize, usize)>,
}

#[derive(Clone, Debug)]
pub struct RunSummary {
    pub out: PathBuf,
    pub pulses: usize,
    pub rays: u64,
    pub seconds: f64,
    /// Parts simulated by this invocation.
    pub parts_done: usize,
    /// Whether every stage asked for is complete.
    pub complete: bool,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct StageRecord {
    pub status: String,
    pub fingerprint: String,
    pub outputs: Vec<String>,
    pub wall_time_s: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Manifest {
    pub tool_version: String,
    pub campaign: String,
    pub stages: BTreeMap<String, StageRecord>,
}

impl Manifest {
    fn read(path: &Path) -> Option<Manifest> {
        serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
    }

    fn done(&self, stage: Stage, fingerprint: &str) -> bool {
        self.stages
            .get(stage.name())
            .is_some_and(|r| r.status == "done" && r.fingerprint == fingerprint)
    }
}

/// FNV-1a, 64 bits: a fingerprint that is stable across platforms and tool builds.
fn fnv(h: &mut u64, bytes: &[u8]) {
    for b in bytes {
        *h ^= *b as u64;
        *h = h.wrapping_mul(0x100_0000_01b3);
    }
}

fn fingerprint(parts: &[&[u8]]) -> String {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for p in parts {
        fnv(&mut h, &(p.len() as u64).to_le_bytes());
        fnv(&mut h, p);
    }
    format!("{h:016x}")
}

/// Runs a campaign file into its run folder (each combination of a sweep into a sub-folder).
pub fn run(campaign_path: &Path, opts: &RunOptions) -> Result<RunSummary> {
    let loaded = plan::read_campaign(campaign_path)?;
    let out = opts
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(&loaded.campaign.name));
    with_threads(opts.threads, || match &loaded.campaign.sweep {
        Some(sweep) => run_sweep(&loaded, sweep, &out, opts),
        None => run_single(&loaded, &out, opts, &mut SceneCache::default()),
    })
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

/// Scenes already loaded, by (file, wavelength): sweep combinations share them.
#[derive(Default)]
struct SceneCache {
    scenes: Vec<(PathBuf, u64, Scene)>,
}

impl SceneCache {
    fn get(&mut self, path: &Path, wavelength_nm: f64) -> Result<&Scene> {
        let key = wavelength_nm.to_bits();
        if let Some(i) = self
            .scenes
            .iter()
            .position(|(p, w, _)| p == path && *w == key)
        {
            return Ok(&self.scenes[i].2);
        }
        let t = Instant::now();
        let scene = Scene::load(path, wavelength_nm)?;
        let s = scene.stats();
        log(&format!(
            "scene {}: {} instances, {} triangles ({} distinct), {:.1} MB, loaded in {:.2} s",
            scene.name,
            s.instances,
            s.instanced_triangles,
            s.distinct_triangles,
            s.memory_bytes as f64 / 1e6,
            t.elapsed().as_secs_f64()
        ));
        self.scenes.push((path.to_path_buf(), key, scene));
        Ok(&self.scenes.last().expect("just pushed").2)
    }
}

/// One sub-run per combination of the sweep's values, in sub-folders named after them.
fn run_sweep(
    loaded: &Loaded,
    sweep: &BTreeMap<String, Vec<serde_yaml::Value>>,
    out: &Path,
    opts: &RunOptions,
) -> Result<RunSummary> {
    // combinations vary the keys in the order the file gives them
    let mut keys: Vec<&String> = sweep.keys().collect();
    // (a dotted key is one YAML key here, so look for its text after `sweep:`)
    let sweep_at = loaded.doc.text.find("sweep:").unwrap_or(0);
    keys.sort_by_key(|k| {
        loaded.doc.text[sweep_at..]
            .find(k.as_str())
            .unwrap_or(usize::MAX)
    });
    for k in &keys {
        if sweep[*k].is_empty() {
            return Err(loaded
                .doc
                .error(&format!("sweep.{k}"), "the list of values is empty"));
        }
    }
    let mut combos: Vec<Vec<&serde_yaml::Value>> = vec![vec![]];
    for k in &keys {
        combos = combos
            .into_iter()
            .flat_map(|c| {
                sweep[*k].iter().map(move |v| {
                    let mut c = c.clone();
                    c.push(v);
                    c
                })
            })
            .collect();
    }
    let mut cache = SceneCache::default();
    let mut total = RunSummary {
        out: out.to_path_buf(),
        pulses: 0,
        rays: 0,
        seconds: 0.0,
        parts_done: 0,
        complete: true,
    };
    let mut runs = Vec::new();
    let mut rows: Vec<(Vec<serde_yaml::Value>, RunTotals)> = Vec::new();
    for combo in combos {
        let mut tree =
            serde_yaml::to_value(&loaded.campaign).map_err(|e| Error::msg(e.to_string()))?;
        let mut names = Vec::new();
        for (k, v) in keys.iter().zip(&combo) {
            set_path(&mut tree, k, (*v).clone())
                .map_err(|m| loaded.doc.error(&format!("sweep.{k}"), m))?;
            let value = serde_yaml::to_string(v)
                .unwrap_or_default()
                .trim()
                .to_string();
            names.push(format!("{}={}", k.rsplit('.').next().unwrap_or(k), value));
        }
        if let serde_yaml::Value::Mapping(m) = &mut tree {
            m.remove("sweep");
        }
        let campaign: Campaign = serde_yaml::from_value(tree).map_err(|e| {
            loaded.doc.error(
                "sweep",
                format!("a combination does not make a valid campaign: {e}"),
            )
        })?;
        plan::check_campaign(&loaded.doc, &campaign).map_err(|e| {
            Error::msg(format!(
                "{e} (in the sweep combination {})",
                names.join(", ")
            ))
        })?;
        let sub = Loaded {
            campaign,
            doc: loaded.doc.clone(),
            scene_path: loaded.scene_path.clone(),
        };
        let name = names.join("_").replace(['/', '\\', ' '], "-");
        log(&format!("sweep: {name}"));
        let s = run_single(&sub, &out.join(&name), opts, &mut cache)?;
        total.pulses += s.pulses;
        total.rays += s.rays;
        total.seconds += s.seconds;
        total.parts_done += s.parts_done;
        total.complete &= s.complete;
        if s.complete {
            rows.push((
                combo.iter().map(|v| (*v).clone()).collect(),
                RunTotals::read(&out.join(&name))?,
            ));
        }
        runs.push(name);
    }
    write_sweep_summary(out, &keys, &rows)?;
    let index = serde_json::json!({ "tool_version": env!("CARGO_PKG_VERSION"), "campaign": loaded.campaign.name, "sweep": runs });
    write_text_atomic(
        &out.join("sweep.json"),
        &serde_json::to_string_pretty(&index).unwrap_or_default(),
    )?;
    Ok(total)
}

/// The DSM error product: reference DSM from the scene's own surfaces, first-return DSM from
/// the points, on one grid; `dsm/report.json` and plots.
fn dsm_stage(
    loaded: &Loaded,
    out: &Path,
    points: &[crate::products::points::Point],
    pulses: &[Pulse],
    res: f64,
) -> Result<Vec<String>> {
    use crate::products::dsm::{
        aim_angles, compare, first_return_dsm_with_angle, write_report, DsmPoint,
    };
    use crate::scene::dsm::Grid;
    let firsts: Vec<DsmPoint> = points
        .iter()
        .map(|p| DsmPoint {
            x: p.x,
            y: p.y,
            z: p.z,
            scan_angle_deg: p.scan_angle_deg as f64,
            first: p.return_number == 1,
        })
        .collect();
    if !firsts.iter().any(|p| p.first) {
        log("dsm: no first returns, no DSM");
        return Ok(Vec::new());
    }
    // the grid covers the scanned area (the first returns) within the scene
    let scene = Scene::load(&loaded.scene_path, loaded.campaign.wavelength_nm)?;
    let (slo, shi) = scene.bounds();
    let (mut lo, mut hi) = (glam::DVec3::splat(f64::MAX), glam::DVec3::splat(f64::MIN));
    for p in firsts.iter().filter(|p| p.first) {
        lo = lo.min(glam::DVec3::new(p.x, p.y, p.z));
        hi = hi.max(glam::DVec3::new(p.x, p.y, p.z));
    }
    let (lo, hi) = (lo.max(slo), hi.min(shi));
    let grid = Grid::covering(
        glam::DVec3::new(lo.x, lo.y, slo.z),
        glam::DVec3::new(hi.x, hi.y, shi.z),
        res,
    );
    let reference = scene.top_surface_grid(&grid);
    let (measured, angles) = first_return_dsm_with_angle(&firsts, &grid);
    // pulses are aimed at the ground: the 5th percentile of the reference heights
    let mut heights: Vec<f64> = reference
        .iter()
        .copied()
        .filter(|z| z.is_finite())
        .collect();
    heights.sort_by(f64::total_cmp);
    let ground = heights.get(heights.len() / 20).copied().unwrap_or(slo.z);
    let aim = aim_angles(pulses, &grid, ground);
    let report = compare(&reference, &measured, &aim, &angles, &grid);
    write_report(&out.join("dsm"), &report, &reference, &measured, &grid)?;
    log(&format!(
        "dsm: bias {:+.3} m, RMSE {:.3} m, coverage {:.1}% over {} cells of {res} m",
        report.bias_m,
        report.rmse_m,
        100.0 * report.coverage,
        report.cells
    ));
    Ok(vec![
        "dsm/report.json".into(),
        "dsm/error_vs_scan_angle.png".into(),
        "dsm/error_map.png".into(),
    ])
}

/// Means over a run's pulses of what a sweep compares.
#[derive(Clone, Debug, Default)]
pub struct RunTotals {
    pub pulses: usize,
    pub received_energy_j: f64,
    pub solar_photons_per_bin: f64,
    pub brf_fov_solar: f64,
    pub brf_footprint_laser: f64,
}

impl RunTotals {
    pub fn read(run: &Path) -> Result<RunTotals> {
        let mut t = RunTotals::default();
        let dir = run.join("waveforms");
        let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
            .map_err(|e| Error::file(&dir, e))?
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e == "parquet"))
            .collect();
        files.sort();
        for f in files {
            for w in parquet::read_waveforms(&f)? {
                t.pulses += 1;
                t.received_energy_j += w.received_energy_j;
                t.solar_photons_per_bin += w.solar_photons_per_bin as f64;
                t.brf_fov_solar += w.brf_fov_solar as f64;
                t.brf_footprint_laser += w.brf_footprint_laser as f64;
            }
        }
        let n = t.pulses.max(1) as f64;
        t.received_energy_j /= n;
        t.solar_photons_per_bin /= n;
        t.brf_fov_solar /= n;
        t.brf_footprint_laser /= n;
        Ok(t)
    }
}

/// `sweep.csv`, one row per combination, and with a single numeric swept key, plots of the
/// signal and the BRFs against it.
fn write_sweep_summary(
    out: &Path,
    keys: &[&String],
    rows: &[(Vec<serde_yaml::Value>, RunTotals)],
) -> Result<()> {
    let mut csv = keys
        .iter()
        .map(|k| k.as_str())
        .collect::<Vec<_>>()
        .join(",");
    csv += ",pulses,received_energy_j,solar_photons_per_bin,brf_fov_solar,brf_footprint_laser\n";
    for (vals, t) in rows {
        let v: Vec<String> = vals
            .iter()
            .map(|v| {
                serde_yaml::to_string(v)
                    .unwrap_or_default()
                    .trim()
                    .to_string()
            })
            .collect();
        csv += &format!(
            "{},{},{:.6e},{:.6e},{:.6},{:.6}\n",
            v.join(","),
            t.pulses,
            t.received_energy_j,
            t.solar_photons_per_bin,
            t.brf_fov_solar,
            t.brf_footprint_laser
        );
    }
    write_text_atomic(&out.join("sweep.csv"), &csv)?;
    if keys.len() != 1 || rows.len() < 2 {
        return Ok(());
    }
    let xs: Option<Vec<f64>> = rows.iter().map(|(v, _)| v[0].as_f64()).collect();
    let Some(xs) = xs else { return Ok(()) };
    let key = keys[0].as_str();
    let series = |name: &str, f: &dyn Fn(&RunTotals) -> f64| crate::products::plot::Series {
        name: name.into(),
        points: xs.iter().zip(rows).map(|(x, (_, t))| (*x, f(t))).collect(),
    };
    let svg = crate::products::plot::line_plot(
        "Received laser energy",
        key,
        "J per pulse",
        &[series("laser", &|t| t.received_energy_j)],
    );
    write_text_atomic(&out.join("sweep_energy.svg"), &svg)?;
    if rows.iter().any(|(_, t)| t.solar_photons_per_bin > 0.0) {
        let svg = crate::products::plot::line_plot(
            "Solar background",
            key,
            "solar photons per bin",
            &[series("N_SN", &|t| t.solar_photons_per_bin)],
        );
        write_text_atomic(&out.join("sweep_solar.svg"), &svg)?;
        let svg = crate::products::plot::line_plot(
            "Scene BRF",
            key,
            "BRF",
            &[
                series("field of view, solar (Eq. 20)", &|t| t.brf_fov_solar),
                series("footprint, laser", &|t| t.brf_footprint_laser),
            ],
        );
        write_text_atomic(&out.join("sweep_brf.svg"), &svg)?;
    }
    Ok(())
}

/// Sets the value at a dotted key path (`platform.altitude_m`) in a YAML tree.
fn set_path(
    tree: &mut serde_yaml::Value,
    key: &str,
    value: serde_yaml::Value,
) -> std::result::Result<(), String> {
    let mut node = tree;
    let parts: Vec<&str> = key.split('.').collect();
    for (i, p) in parts.iter().enumerate() {
        let map = node
            .as_mapping_mut()
            .ok_or_else(|| format!("`{}` is not a section", parts[..i].join(".")))?;
        let k = serde_yaml::Value::String(p.to_string());
        if i + 1 == parts.len() {
            map.insert(k, value);
            return Ok(());
        }
        node = map
            .entry(k)
            .or_insert_with(|| serde_yaml::Value::Mapping(Default::default()));
    }
    Err("empty key".into())
}

/// Removes files left under temporary names by a crash or a kill.
fn clean_temp_files(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            clean_temp_files(&p);
        } else if p
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.contains(".tmp-"))
        {
            let _ = std::fs::remove_file(&p);
        }
    }
}

pub fn part_name(k: usize) -> String {
    format!("waveforms/part-{k:05}.parquet")
}

fn run_single(
    loaded: &Loaded,
    out: &Path,
    opts: &RunOptions,
    cache: &mut SceneCache,
) -> Result<RunSummary> {
    let start = Instant::now();
    let c = &loaded.campaign;
    std::fs::create_dir_all(out)
        .map_err(|e| Error::file(out, format!("cannot create run folder: {e}")))?;
    let manifest_path = out.join("manifest.json");
    // shards share the folder with each other: they keep what is there, like a resume
    let keep = opts.resume || opts.shard.is_some();
    let mut manifest = if keep {
        Manifest::read(&manifest_path).unwrap_or_default()
    } else {
        Manifest::default()
    };
    if keep {
        // another shard may be writing beside a shard: only a plain resume, alone on the
        // folder, removes temporary files (left by a crash or a kill)
        if opts.shard.is_none() {
            clean_temp_files(out);
        }
    } else {
        for name in ["waveforms", "pulses.parquet", "manifest.json", "report.md"] {
            let p = out.join(name);
            let _ = if p.is_dir() {
                std::fs::remove_dir_all(&p)
            } else {
                std::fs::remove_file(&p)
            };
        }
    }
    manifest.tool_version = env!("CARGO_PKG_VERSION").to_string();
    manifest.campaign = c.name.clone();
    let before = manifest.clone();
    let wanted = |s: Stage| opts.stages.as_ref().is_none_or(|v| v.contains(&s));

    let resolved = loaded.resolved_yaml();
    write_text_atomic(&out.join("campaign.resolved.yaml"), &resolved)?;
    let fp_plan = fingerprint(&[resolved.as_bytes(), env!("CARGO_PKG_VERSION").as_bytes()]);

    // plan: cheap and deterministic, so the pulses are always planned in memory; the file is
    // written only when the stage is not already done
    let t = Instant::now();
    let pulses = plan_with_progress(c)?;
    if wanted(Stage::Plan) && !manifest.done(Stage::Plan, &fp_plan) {
        parquet::write_pulses(&out.join("pulses.parquet"), &pulses)?;
        record(
            &mut manifest,
            Stage::Plan,
            &fp_plan,
            vec!["pulses.parquet".into()],
            t,
            None,
        );
        save(&manifest_path, &manifest)?;
        log(&format!(
            "plan: {} pulses in {:.2} s",
            pulses.len(),
            t.elapsed().as_secs_f64()
        ));
    } else if !manifest.done(Stage::Plan, &fp_plan) {
        return Err(Error::msg(format!(
            "{}: stage plan has not run: include it in --stages",
            out.display()
        )));
    } else {
        log("plan: up to date");
    }

    let mut summary = RunSummary {
        out: out.to_path_buf(),
        pulses: pulses.len(),
        rays: 0,
        seconds: 0.0,
        parts_done: 0,
        complete: true,
    };
    let later = [Stage::Simulate, Stage::Products, Stage::Report];
    if !later.iter().any(|s| wanted(*s)) {
        summary.seconds = start.elapsed().as_secs_f64();
        return Ok(summary);
    }

    let scene = cache.get(&loaded.scene_path, c.wavelength_nm)?;
    let mut scene_bytes = Vec::new();
    for f in &scene.files {
        let bytes = std::fs::read(f).map_err(|e| Error::file(f, format!("cannot read: {e}")))?;
        scene_bytes.push(bytes);
    }
    let mut inputs: Vec<&[u8]> = vec![fp_plan.as_bytes()];
    inputs.extend(scene_bytes.iter().map(|b| b.as_slice()));
    let fp_sim = fingerprint(&inputs);

    // simulate
    let parts = pulses.len().div_ceil(PART_PULSES);
    let part_files: Vec<String> = (0..parts).map(part_name).collect();
    if wanted(Stage::Simulate) && !manifest.done(Stage::Simulate, &fp_sim) {
        let t = Instant::now();
        let wf_dir = out.join("waveforms");
        let marker = wf_dir.join("fingerprint");
        let stale = std::fs::read_to_string(&marker)
            .map(|s| s.trim() != fp_sim)
            .unwrap_or(true);
        if stale && opts.shard.is_none() && wf_dir.exists() {
            let _ = std::fs::remove_dir_all(&wf_dir);
        }
        write_text_atomic(&marker, &fp_sim)?;
        let todo: Vec<usize> = (0..parts)
            .filter(|k| opts.shard.is_none_or(|(i, n)| k % n == i))
            .filter(|&k| !out.join(part_name(k)).is_file())
            .collect();
        let (rays, done) = simulate_parts(loaded, scene, &pulses, &todo, out)?;
        summary.rays = rays;
        summary.parts_done = done;
        let missing = (0..parts)
            .filter(|&k| !out.join(part_name(k)).is_file())
            .count();
        if missing == 0 {
            record(
                &mut manifest,
                Stage::Simulate,
                &fp_sim,
                part_files.clone(),
                t,
                None,
            );
        } else {
            let note =
                format!("{missing} of {parts} parts missing: run again with --resume to finish");
            record(
                &mut manifest,
                Stage::Simulate,
                &fp_sim,
                part_files.clone(),
                t,
                Some(note.clone()),
            );
            manifest
                .stages
                .get_mut("simulate")
                .expect("recorded")
                .status = "partial".into();
            log(&format!("simulate: {note}"));
        }
        invalidate_after(&mut manifest, Stage::Simulate);
        save(&manifest_path, &manifest)?;
    } else if manifest.done(Stage::Simulate, &fp_sim) {
        log("simulate: up to date");
    }
    if !manifest.done(Stage::Simulate, &fp_sim) {
        summary.complete = false;
        summary.seconds = start.elapsed().as_secs_f64();
        return Ok(summary);
    }

    // products: discrete returns, photon counts and the DSM error, from the waveforms
    let fp_products = fingerprint(&[fp_sim.as_bytes(), b"products"]);
    if wanted(Stage::Products) && !manifest.done(Stage::Products, &fp_products) {
        let t = Instant::now();
        let (outputs, note) = products::run(loaded, out, &pulses, parts)?;
        log(&format!(
            "products: {} in {:.2} s",
            outputs.join(", "),
            t.elapsed().as_secs_f64()
        ));
        record(
            &mut manifest,
            Stage::Products,
            &fp_products,
            outputs,
            t,
            (!note.is_empty()).then_some(note),
        );
        invalidate_after(&mut manifest, Stage::Products);
        save(&manifest_path, &manifest)?;
    }

    // report
    let fp_report = fingerprint(&[fp_products.as_bytes(), b"report"]);
    if wanted(Stage::Report)
        && manifest.done(Stage::Products, &fp_products)
        && !manifest.done(Stage::Report, &fp_report)
    {
        let t = Instant::now();
        let text = report(loaded, scene, &pulses, out, &manifest)?;
        write_text_atomic(&out.join("report.md"), &text)?;
        record(
            &mut manifest,
            Stage::Report,
            &fp_report,
            vec!["report.md".into()],
            t,
            None,
        );
        save(&manifest_path, &manifest)?;
    }
    if manifest == before {
        log("nothing to do: every stage is up to date");
    }
    summary.complete = opts.stages.is_some() || manifest.done(Stage::Report, &fp_report);
    summary.seconds = start.elapsed().as_secs_f64();
    Ok(summary)
}

fn record(
    m: &mut Manifest,
    stage: Stage,
    fp: &str,
    outputs: Vec<String>,
    t: Instant,
    note: Option<String>,
) {
    m.stages.insert(
        stage.name().into(),
        StageRecord {
            status: "done".into(),
            fingerprint: fp.into(),
            outputs,
            wall_time_s: (t.elapsed().as_secs_f64() * 1000.0).round() / 1000.0,
            note,
        },
    );
}

/// A stage redone makes every later stage stale.
fn invalidate_after(m: &mut Manifest, stage: Stage) {
    for s in Stage::ALL.into_iter().filter(|s| *s > stage) {
        m.stages.remove(s.name());
    }
}

fn save(path: &Path, m: &Manifest) -> Result<()> {
    write_text_atomic(path, &serde_json::to_string_pretty(m).unwrap_or_default())
}

fn plan_with_progress(c: &Campaign) -> Result<Vec<Pulse>> {
    let pulses = plan::plan(c)?;
    if pulses.is_empty() {
        return Err(Error::msg("the platform plans no pulses"));
    }
    Ok(pulses)
}

/// Simulates the given parts, each written when complete. Pulses within a part and each
/// pulse's ray chunks run in parallel. Returns (rays traced, parts written).
fn simulate_parts(
    loaded: &Loaded,
    scene: &Scene,
    pulses: &[Pulse],
    todo: &[usize],
    out: &Path,
) -> Result<(u64, usize)> {
    let total: usize = todo
        .iter()
        .map(|&k| part_range(k, pulses.len()).len())
        .sum();
    let bar = progress(total as u64, "simulating");
    let t = Instant::now();
    let mut rays = 0u64;
    let mut done_pulses = 0usize;
    let terminal = std::io::stderr().is_terminal();
    for (i, &k) in todo.iter().enumerate() {
        let range = part_range(k, pulses.len());
        let (waveforms, secs) = simulate(loaded, scene, &pulses[range], &bar);
        parquet::write_waveforms(&out.join(part_name(k)), &waveforms)?;
        write_pulse_stats(
            &out.join(format!("waveforms/part-{k:05}.stats.csv")),
            &waveforms,
            &secs,
        )?;
        rays += waveforms.iter().map(|w| w.rays as u64).sum::<u64>();
        done_pulses += waveforms.len();
        let elapsed = t.elapsed().as_secs_f64();
        let rate = done_pulses as f64 / elapsed;
        if !terminal {
            log(&format!(
                "simulate: part {} ({}/{} parts) done, {:.0} pulses/s, {:.0} s left",
                k,
                i + 1,
                todo.len(),
                rate,
                (total - done_pulses) as f64 / rate
            ));
        }
    }
    bar.finish_and_clear();
    let secs = t.elapsed().as_secs_f64();
    if done_pulses > 0 {
        log(&format!(
            "simulated {done_pulses} pulses, {rays} rays in {secs:.2} s ({:.1} pulses/s, {:.3e} rays/s)",
            done_pulses as f64 / secs,
            rays as f64 / secs
        ));
    }
    Ok((rays, todo.len()))
}

fn part_range(k: usize, n: usize) -> std::ops::Range<usize> {
    k * PART_PULSES..((k + 1) * PART_PULSES).min(n)
}

/// Per-pulse counters beside the waveforms: effective paths per ray and time per ray. Kept
/// out of the waveform files, which must not depend on timing.
fn write_pulse_stats(path: &Path, waveforms: &[Waveform], secs: &[f64]) -> Result<()> {
    let mut text = String::from("pulse_id,rays,paths_per_ray,seconds,seconds_per_ray\n");
    for (w, s) in waveforms.iter().zip(secs) {
        text.push_str(&format!(
            "{},{},{},{:.6},{:.4e}\n",
            w.pulse_id,
            w.rays,
            w.paths_per_ray,
            s,
            s / w.rays.max(1) as f64
        ));
    }
    write_text_atomic(path, &text)
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
    let radiometry = Radiometry {
        pulse_energy_j: inst.pulse_energy_j,
        receiver_area_m2: inst.receiver_area_m2,
        fov_half_angle: inst.fov_half_angle_mrad * 1e-3,
        sun: sun.map(|s| (s.band_irradiance, s.cos_zenith)),
    };
    pulses
        .par_iter()
        .map(|p| {
            let gate = Gate::for_pulse(inst, p.origin, p.direction, bounds);
            let sub_bins = waveform::sub_bins_per_bin(gate.dt, sigma);
            let sun = sun.map(|s| s.for_gate(inst.pulse_energy_j, gate.dt * gate.bins as f64));
            let setup = PulseSetup {
                scene,
                laser: Laser::new(inst, p.origin, p.direction),
                receiver: Receiver::new(inst, p.origin, p.direction),
                gate,
                sub_bins,
                method: c.simulation.method,
                heuristic: c.simulation.mis,
                sun,
                max_order: c.simulation.max_order,
                seed: c.seed,
                pulse_id: p.id,
            };
            let t = Instant::now();
            let tally = simulate_pulse(&setup, c.simulation.rays_per_pulse);
            let secs = t.elapsed().as_secs_f64();
            bar.inc(1);
            (
                waveform::waveform(p.id, &tally, &gate, sub_bins, sigma, hv, &radiometry),
                secs,
            )
        })
        .unzip()
}

/// Rays per second on this machine for this campaign, measured on up to 8 pulses spread
/// over the plan with at most 1000 rays each: the basis of `lidarsim check`'s time estimate.
pub fn probe_rays_per_second(loaded: &Loaded, scene: &Scene, pulses: &[Pulse]) -> f64 {
    let n = pulses.len().min(8);
    let sample: Vec<Pulse> = (0..n).map(|i| pulses[i * pulses.len() / n]).collect();
    let mut probe = loaded.clone();
    probe.campaign.simulation.rays_per_pulse = probe.campaign.simulation.rays_per_pulse.min(1000);
    let t = Instant::now();
    let (w, _) = simulate(&probe, scene, &sample, &ProgressBar::hidden());
    let rays: u64 = w.iter().map(|w| w.rays as u64).sum();
    rays as f64 / t.elapsed().as_secs_f64().max(1e-9)
}

/// `report.md`: what ran, on what, how fast, and what came back.
fn report(
    loaded: &Loaded,
    scene: &Scene,
    pulses: &[Pulse],
    out: &Path,
    manifest: &Manifest,
) -> Result<String> {
    let c = &loaded.campaign;
    let mut received = Vec::new();
    let mut multiple = 0.0;
    let mut rays = 0u64;
    let mut paths = 0.0;
    let (mut solar, mut brf_fov, mut brf_fp) = (0.0, 0.0, 0.0);
    for f in std::fs::read_dir(out.join("waveforms"))
        .map_err(|e| Error::file(out, e))?
        .flatten()
    {
        let p = f.path();
        if p.extension().is_some_and(|e| e == "parquet") {
            for w in parquet::read_waveforms(&p)? {
                received.push(w.received_energy_j);
                multiple += w.received_energy_j - w.order_energy_j.first().copied().unwrap_or(0.0);
                rays += w.rays as u64;
                paths += w.paths_per_ray as f64 * w.rays as f64;
                solar += w.solar_photons_per_bin as f64;
                brf_fov += w.brf_fov_solar as f64;
                brf_fp += w.brf_footprint_laser as f64;
            }
        }
    }
    let total: f64 = received.iter().sum();
    let sim = manifest
        .stages
        .get("simulate")
        .map(|r| r.wall_time_s)
        .unwrap_or(0.0);
    let s = scene.stats();
    let mut text = format!("# Run report: {}\n\n", c.name);
    text += &format!(
        "| | |\n| --- | --- |\n| scene | {} ({} instances, {} triangles) |\n| instrument | {:?}, {} nm, {} J, footprint {} mrad, field of view {} mrad |\n| method | {:?}, {} rays per pulse, max order {} |\n| pulses | {} |\n| rays | {} |\n| simulation wall time | {:.2} s ({:.1} pulses/s) |\n| effective paths per ray | {:.2} |\n| mean received energy per pulse | {:.4e} J |\n| multiple scattering share | {:.1}% |\n",
        scene.name,
        s.instances,
        s.instanced_triangles,
        c.instrument.kind,
        c.wavelength_nm,
        c.instrument.pulse_energy_j,
        c.instrument.footprint_half_angle_mrad,
        c.instrument.fov_half_angle_mrad,
        c.simulation.method,
        c.simulation.rays_per_pulse,
        c.simulation.max_order,
        pulses.len(),
        rays,
        sim,
        if sim > 0.0 { pulses.len() as f64 / sim } else { 0.0 },
        paths / rays.max(1) as f64,
        total / received.len().max(1) as f64,
        if total > 0.0 { 100.0 * multiple / total } else { 0.0 },
    );
    let n = received.len().max(1) as f64;
    text += &format!(
        "| scene BRF in the footprint, from the laser (π/ΔΩ)(Q_r/Q_e) | {:.4} |\n",
        brf_fp / n
    );
    if let Some(sun) = &c.sun {
        text += &format!(
            "| sun | zenith {}°, azimuth {}° |\n| solar photons per bin | {:.4} |\n| scene BRF in the field of view, from the sun (Eq. 20) | {:.4} |\n",
            sun.zenith_deg, sun.azimuth_deg, solar / n, brf_fov / n
        );
    }
    text += &products_section(out);
    Ok(text)
}

/// The products part of report.md: figures from products.json and dsm/report.json, and the
/// plots beside them.
fn products_section(out: &Path) -> String {
    let read = |p: &Path| -> Option<serde_json::Value> {
        serde_json::from_str(&std::fs::read_to_string(p).ok()?).ok()
    };
    let mut text = String::new();
    let Some(p) = read(&out.join("products.json")) else {
        return text;
    };
    let num = |v: &serde_json::Value| v.as_f64().map_or("–".to_string(), |x| format!("{x:.3}"));
    if p.get("points").is_some() {
        let by = &p["points_by_class"];
        text += &format!(
            "\n## Discrete returns (points.las)\n\n| | |\n| --- | --- |\n| points | {} |\n| points per pulse | {} |\n| pulse density | {} per m² |\n| ground / vegetation / building / unclassified | {} / {} / {} / {} |\n",
            p["points"], num(&p["points_per_pulse"]), num(&p["pulse_density_per_m2"]),
            by["ground"], by["vegetation"], by["building"], by["unclassified"]
        );
        for (f, what) in [
            (
                "points_top.png",
                "Points from above, coloured by apparent reflectance",
            ),
            ("waveforms.png", "Waveforms with their fitted components"),
        ] {
            if out.join(f).exists() {
                text += &format!("\n{what}:\n\n![{what}]({f})\n");
            }
        }
    }
    if let Some(d) = read(&out.join("dsm/report.json")) {
        text += &format!(
            "\n## DSM error ({} m cells)\n\n| bias | RMSE | MAE | coverage | cells |\n| --- | --- | --- | --- | --- |\n| {} m | {} m | {} m | {} | {} |\n\n| \\|scan angle\\| (°) | cells | coverage | bias (m) | RMSE (m) |\n| --- | --- | --- | --- | --- |\n",
            d["resolution_m"], num(&d["bias_m"]), num(&d["rmse_m"]), num(&d["mae_m"]),
            num(&d["coverage"]), d["cells"]
        );
        for b in d["by_scan_angle"].as_array().into_iter().flatten() {
            text += &format!(
                "| {}–{} | {} | {} | {} | {} |\n",
                b["bin_deg_lo"],
                b["bin_deg_hi"],
                b["cells_surfaced"],
                num(&b["coverage"]),
                num(&b["bias_m"]),
                num(&b["rmse_m"])
            );
        }
        text += "\n![DSM error map](dsm/error_map.png)\n\n![DSM error and coverage against scan angle](dsm/error_vs_scan_angle.png)\n";
    }
    if let Some(ph) = p.get("photons") {
        text += &format!(
            "\n## Photon counting (photons.parquet)\n\n| total | laser | solar | dark | laser per shot |\n| --- | --- | --- | --- | --- |\n| {} | {} | {} | {} | {} |\n",
            ph["total"], ph["laser"], ph["solar"], ph["dark"], num(&ph["laser_per_shot"])
        );
    }
    text
}

/// A progress bar on a terminal; hidden otherwise (stages then log plain lines).
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
