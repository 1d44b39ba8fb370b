//! The campaign rows of `lidarsim bench`: the paper's sections 3.2-3.4 run as whole
//! campaigns through the pipeline (plan, simulate, products), each timed and with its peak
//! memory. The orchard rows need the RAMI files (docs/guide.md, "Scenes") and are skipped, with a
//! note in the table, when they are absent.

use crate::error::{Error, Result};
use crate::generate::{generate_with_summary, GenerateOptions, SceneKind};
use crate::pipeline::manifest::Manifest;
use crate::pipeline::{self, RunOptions};
use crate::products::raster::DsmReport;
use crate::products::report::summary::ProductsSummary;
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
    /// Wall time of the products stage, s (its share of the run is in the table).
    pub products_s: f64,
    /// Pulses per second over the whole run (plan to products).
    pub run_pulses_per_s: f64,
    /// Simulate stage: process CPU time over wall time and threads (1 = every core busy).
    pub cpu_utilisation: Option<f64>,
    /// Threads the run used.
    pub threads: usize,
    /// Peak resident memory during the run, MiB (None where the OS does not tell).
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

/// Peak resident memory since the last reset, MiB.
pub fn peak_memory_mb() -> Option<f64> {
    crate::progress::peak_rss_bytes().map(|b| b as f64 / (1024.0 * 1024.0))
}

/// The scene a bench campaign flies over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BenchScene {
    /// The RAMI orchard (skipped without its files).
    Orchard,
    /// The RAMI orchard as one period of an infinite orchard (`repeat: true`), as DART and
    /// the paper treat it.
    OrchardRepeated,
    /// The generated forest.
    Forest,
    /// The generated town of buildings and sparse trees.
    Town,
}

/// The bench's campaigns, in the order of its table: file stem under the campaigns folder
/// (`pipelines/bench/`), what it measures, and the scene it flies over.
pub const CAMPAIGNS: [(&str, &str, BenchScene); 12] = [
    (
        "orchard_gedi_sun",
        "orchard, GEDI-like waveform, sun 50°/180° (section 3.3)",
        BenchScene::Orchard,
    ),
    (
        "orchard_gedi_sun_repeated",
        "orchard repeated (repeat: true), GEDI-like waveform, sun 50°/180° (section 3.3)",
        BenchScene::OrchardRepeated,
    ),
    (
        "mabel_532",
        "orchard, MABEL-like photon counting, 532 nm, sun off (section 3.4)",
        BenchScene::Orchard,
    ),
    (
        "mabel_532_sun",
        "orchard, MABEL-like photon counting, 532 nm, sun on (section 3.4)",
        BenchScene::Orchard,
    ),
    (
        "mabel_1064",
        "orchard, MABEL-like photon counting, 1064 nm, sun off (section 3.4)",
        BenchScene::Orchard,
    ),
    (
        "mabel_1064_sun",
        "orchard, MABEL-like photon counting, 1064 nm, sun on (section 3.4)",
        BenchScene::Orchard,
    ),
    (
        "als_forest",
        "forest, Riegl VUX-1UAV-like discrete return (section 3.2)",
        BenchScene::Forest,
    ),
    (
        "als_town",
        "town, airborne discrete return at 19 rays per pulse, method auto",
        BenchScene::Town,
    ),
    (
        "als_town_auto",
        "the same town survey with max_order auto (the pilot keeps the orders that matter)",
        BenchScene::Town,
    ),
    (
        "als_forest_polygon",
        "forest, rotating polygon scanner (±30°, 80 % duty) from 100 m",
        BenchScene::Forest,
    ),
    (
        "als_forest_risley",
        "forest, Risley-prism rosette from a UAV at 60 m",
        BenchScene::Forest,
    ),
    (
        "als_forest_multibeam",
        "forest, 16-channel spinning head tilted 90° from a UAV at 30 m",
        BenchScene::Forest,
    ),
];

/// The keys `pipelines/bench/quick.yaml` replaces in campaign `name` for the quick bench
/// (dotted paths such as `simulation.rays_per_pulse`); none if it lists no such campaign.
pub fn quick_overrides(dir: &Path, name: &str) -> Result<serde_yaml::Mapping> {
    let path = dir.join("quick.yaml");
    let text = crate::error::read_text(&path)?;
    let all: serde_yaml::Value =
        serde_yaml::from_str(&text).map_err(|e| Error::file(&path, format!("not YAML: {e}")))?;
    match all.get(name) {
        None => Ok(serde_yaml::Mapping::new()),
        Some(serde_yaml::Value::Mapping(m)) => Ok(m.clone()),
        Some(_) => Err(Error::file(
            &path,
            format!("{name}: expected a mapping of dotted keys to values"),
        )),
    }
}

/// The text of campaign `dir/name.yaml` with `overrides` applied (dotted key -> value) and its
/// scene set to `scene`, ready to be written anywhere (the scene path is absolute).
pub fn campaign_text(
    dir: &Path,
    name: &str,
    overrides: &serde_yaml::Mapping,
    scene: &Path,
) -> Result<String> {
    let path = dir.join(format!("{name}.yaml"));
    let text = crate::error::read_text(&path)?;
    let mut doc: serde_yaml::Value =
        serde_yaml::from_str(&text).map_err(|e| Error::file(&path, format!("not YAML: {e}")))?;
    let mut set = |key: &str, value: serde_yaml::Value| {
        crate::campaign::yaml::set_path(&mut doc, key, value)
            .map_err(|why| Error::file(&path, format!("{key}: {why}")))
    };
    for (k, v) in overrides {
        let k = k
            .as_str()
            .ok_or_else(|| Error::file(&path, "override keys must be dotted key names"))?;
        set(k, v.clone())?;
    }
    set("scene", scene.display().to_string().into())?;
    serde_yaml::to_string(&doc)
        .map_err(|e| Error::data(&path, format!("cannot write as YAML: {e}")))
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
            "RAMI geometry not found at {} (docs/guide.md, \"Scenes\")",
            probe.display()
        ));
    }
    Ok(scene.canonicalize().unwrap_or_else(|_| scene.to_path_buf()))
}

/// The bench's campaigns, read from `campaigns` (`pipelines/bench/`). `full` runs them as
/// written (the paper's sizes: 6929-pulse tracks, the generated 1029-tree forest); quick mode
/// applies `quick.yaml` there and flies the ALS line over a 40 m forest.
pub fn plan(dir: &Path, campaigns: &Path, rami: &Path, full: bool) -> Result<Vec<Planned>> {
    if !campaigns.join("quick.yaml").exists() {
        return Err(Error::file(
            campaigns,
            "the bench's campaign files are not there: run the bench from the repository's \
             folder or pass --campaigns pipelines/bench",
        ));
    }
    let rami = find_rami(rami);
    let mut out = Vec::new();
    for (name, what, source) in CAMPAIGNS {
        let (scene, what) = match (source, &rami) {
            (BenchScene::Orchard | BenchScene::OrchardRepeated, Err(why)) => {
                out.push(Planned::Skipped {
                    name: name.into(),
                    why: why.clone(),
                });
                continue;
            }
            (BenchScene::Orchard, Ok(scene)) => (scene.clone(), what.to_string()),
            (BenchScene::OrchardRepeated, Ok(scene)) => {
                (repeated_orchard(scene)?, what.to_string())
            }
            (BenchScene::Forest, _) => {
                let (scene, size) = forest_scene(dir, full)?;
                (scene, format!("{what}, {size} m stand"))
            }
            (BenchScene::Town, _) => (town_scene(dir)?, what.to_string()),
        };
        let overrides = if full {
            serde_yaml::Mapping::new()
        } else {
            quick_overrides(campaigns, name)?
        };
        out.push(Planned::Run {
            name: name.into(),
            what,
            text: campaign_text(campaigns, name, &overrides, &scene)?,
        });
    }
    Ok(out)
}

/// The orchard's scene file with `repeat: true` (`scenes/rami_wco_repeated.yaml`, beside the
/// orchard's), by an absolute path: the campaign that names it lies in another folder.
fn repeated_orchard(scene: &Path) -> Result<PathBuf> {
    let repeated = scene.with_file_name("rami_wco_repeated.yaml");
    crate::error::read_text(&repeated)?;
    Ok(repeated.canonicalize().unwrap_or(repeated))
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

/// The generated town of the bench (made once, then reused): 100 m, 5 buildings, 60 trees.
pub fn town_scene(dir: &Path) -> Result<PathBuf> {
    let town_dir = dir.join("town");
    let scene = match std::fs::metadata(town_dir.join("town.yaml")) {
        Ok(_) => town_dir.join("town.yaml"),
        Err(_) => {
            generate_with_summary(SceneKind::Town, 1, &town_dir, &GenerateOptions::default())?.scene
        }
    };
    Ok(scene.canonicalize().unwrap_or(scene))
}

/// Runs one planned campaign in `dir/name` and measures it: in a process of its own when
/// `runner` (the lidarsim executable) is given, else in this one.
pub fn run_row(
    dir: &Path,
    runner: Option<&Path>,
    name: &str,
    what: &str,
    text: &str,
) -> Result<CampaignRow> {
    run_row_on(dir, runner, name, what, text, None)
}

/// Whole runs shorter than this, s, are run [`SHORT_RUNS`] times ([`run_row_settled`]).
const SHORT_RUN_S: f64 = 2.0;

/// Runs of a short campaign, odd so that one is the median.
const SHORT_RUNS: usize = 5;

/// [`run_row`], run [`SHORT_RUNS`] times in all when it takes under [`SHORT_RUN_S`]: the row
/// of the run of median wall time. A run of a few tenths of a second, and the CPU share
/// measured over it, are at the mercy of the shared machine: runs one after another can
/// differ by tens of per cent in CPU share, and a median of three is still swayed by them.
pub fn run_row_settled(
    dir: &Path,
    runner: Option<&Path>,
    name: &str,
    what: &str,
    text: &str,
) -> Result<CampaignRow> {
    let first = run_row(dir, runner, name, what, text)?;
    if first.run_s >= SHORT_RUN_S {
        return Ok(first);
    }
    let mut rows = vec![first];
    for _ in 1..SHORT_RUNS {
        rows.push(run_row(dir, runner, name, what, text)?);
    }
    rows.sort_by(|a, b| a.run_s.total_cmp(&b.run_s));
    Ok(rows.swap_remove(SHORT_RUNS / 2))
}

/// [`run_row`] on `threads` threads (as many as this process has when None), in a folder of
/// its own. A run in this process inherits what the rows before it left (the allocator's
/// heap, the peak memory, a cache's warmth), which can make it slower, its serial share
/// larger and its peak memory several times its own. In a process of its own each row
/// measures what a user's run does.
fn run_row_on(
    dir: &Path,
    runner: Option<&Path>,
    name: &str,
    what: &str,
    text: &str,
    threads: Option<usize>,
) -> Result<CampaignRow> {
    let folder = match threads {
        Some(n) => dir.join(format!("{name}_{n}thread")),
        None => dir.join(name),
    };
    let _ = std::fs::remove_dir_all(&folder);
    std::fs::create_dir_all(&folder)
        .map_err(|e| crate::error::Error::io(&folder, "cannot create folder", e))?;
    let path = folder.join("campaign.yaml");
    crate::fsutil::write_text_atomic(&path, text)?;
    let run = folder.join("run");
    let threads = threads.unwrap_or(rayon::current_num_threads());
    let (run_s, peak_mb) = match runner {
        Some(exe) => {
            let secs = run_child(exe, &path, &run, threads, &folder.join("run.log"))?;
            let peak = Manifest::read(&run.join("manifest.json")).and_then(|m| {
                m.stages
                    .values()
                    .filter_map(|s| s.peak_memory_mib)
                    .reduce(f64::max)
            });
            (secs, peak)
        }
        None => {
            crate::progress::reset_peak_rss();
            let t = Instant::now();
            pipeline::run(
                &path,
                &RunOptions {
                    out: Some(run.clone()),
                    threads: Some(threads),
                    ..Default::default()
                },
            )?;
            (t.elapsed().as_secs_f64(), peak_memory_mb())
        }
    };
    let manifest = Manifest::read(&run.join("manifest.json"));
    let simulate = manifest.as_ref().and_then(|m| m.stages.get("simulate"));
    let simulate_s = simulate.map_or(f64::NAN, |s| s.wall_time_s);
    let cpu_utilisation = simulate
        .and_then(|s| s.cpu_time_s)
        .map(|cpu| cpu / simulate_s / threads as f64);
    let products_s = manifest
        .as_ref()
        .and_then(|m| m.stages.get("products"))
        .map_or(f64::NAN, |s| s.wall_time_s);
    let products = ProductsSummary::read(&run.join("products.json"));
    let (pulses, rays) = products
        .as_ref()
        .and_then(|p| p.waveform_totals.as_ref())
        .map_or((0, 0), |t| (t.pulses, t.rays));
    let result = row_result(&run, products.as_ref(), pulses)?;
    Ok(CampaignRow {
        name: name.to_string(),
        what: what.to_string(),
        pulses,
        rays_per_pulse: rays / pulses.max(1) as u64,
        run_s,
        simulate_s,
        pulses_per_s: pulses as f64 / simulate_s,
        products_s,
        run_pulses_per_s: pulses as f64 / run_s,
        cpu_utilisation,
        threads,
        peak_mb,
        result,
    })
}

/// What a campaign row's run came back with, in a few words: photons per shot, points per
/// pulse with their distance to the surfaces and the DSM's error, or (for a waveform run) the
/// first pulse's solar photons and BRFs.
fn row_result(run: &Path, products: Option<&ProductsSummary>, pulses: usize) -> Result<String> {
    let mut result = String::new();
    if let Some(p) = products {
        if let Some(ph) = &p.photons {
            let shots = pulses.max(1) as f64;
            let _ = write!(
                result,
                "{:.3} laser, {:.3} solar, {:.4} dark photons per shot",
                ph.laser as f64 / shots,
                ph.solar as f64 / shots,
                ph.dark as f64 / shots
            );
        }
        if let Some(pts) = &p.points {
            let _ = write!(result, "{:.2} points per pulse", pts.points_per_pulse);
            if let Some(d) = &pts.surface_distance {
                let _ = write!(
                    result,
                    ", {:.2}% / {:.3}% within 5 / 25 cm of a surface",
                    100.0 * d.within_5cm,
                    100.0 * d.within_25cm
                );
            }
            if let Some(d) = DsmReport::read(&run.join("dsm/report.json")) {
                let _ = write!(
                    result,
                    ", DSM bias {:+.3} m, RMSE {:.3} m, coverage {:.1}%",
                    d.bias_m,
                    d.rmse_m,
                    100.0 * d.coverage
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
    Ok(result)
}

/// Runs `campaign` into `out` on `threads` threads with the lidarsim executable `exe`, its
/// messages into `log`: the run's wall time, s. Its peak memory is in its manifest: the
/// kernel's account of a child (wait4's ru_maxrss) starts from this process's own peak, as
/// the child began as a copy of it.
fn run_child(exe: &Path, campaign: &Path, out: &Path, threads: usize, log: &Path) -> Result<f64> {
    let messages =
        std::fs::File::create(log).map_err(|e| Error::io(log, "cannot create the run's log", e))?;
    let t = Instant::now();
    let mut child = std::process::Command::new(exe)
        .arg("run")
        .arg(campaign)
        .arg("--out")
        .arg(out)
        .arg("--threads")
        .arg(threads.to_string())
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(messages)
        .spawn()
        .map_err(|e| Error::io(exe, "cannot start lidarsim for a bench row", e))?;
    let status = child
        .wait()
        .map_err(|e| Error::io(exe, "lost a bench row's run", e))?;
    let secs = t.elapsed().as_secs_f64();
    if !status.success() {
        let said = std::fs::read_to_string(log).unwrap_or_default();
        let last = said.lines().last().unwrap_or("(nothing)");
        return Err(Error::msg(format!(
            "{}: the bench row's run failed ({last}); its messages are in {}",
            campaign.display(),
            log.display()
        )));
    }
    Ok(secs)
}

/// The bands of the bench's multispectral comparison: those of Optech Titan-like instruments,
/// all in the orchard's material table.
pub const THREE_BANDS: [f64; 3] = [532.0, 1064.0, 1550.0];

/// One campaign traced in its own band and in [`THREE_BANDS`] in one pass, each run `pairs`
/// times in alternation (the machines are shared and noisy): the medians of the simulate
/// stage's wall time and their ratio.
#[derive(Clone, Debug)]
pub struct BandsRow {
    pub name: String,
    pub pulses: usize,
    pub one_band_s: f64,
    pub three_bands_s: f64,
    pub pairs: usize,
    /// Mean received laser energy per pulse in each of the three bands, J.
    pub energy_j: Vec<f64>,
}

/// Runs [`BandsRow`] for the campaign `text` (of one band).
pub fn bands_row(dir: &Path, name: &str, text: &str, pairs: usize) -> Result<BandsRow> {
    let mut doc: serde_yaml::Value = serde_yaml::from_str(text)
        .map_err(|e| Error::msg(format!("bench campaign {name}: not YAML: {e}")))?;
    let bands: Vec<serde_yaml::Value> = THREE_BANDS.iter().map(|&w| w.into()).collect();
    crate::campaign::yaml::set_path(&mut doc, "wavelength_nm", bands.into()).map_err(Error::msg)?;
    let three = serde_yaml::to_string(&doc)
        .map_err(|e| Error::msg(format!("bench campaign {name}: {e}")))?;
    let (mut one_s, mut three_s) = (Vec::new(), Vec::new());
    let mut last = None;
    for _ in 0..pairs {
        one_s.push(run_row(dir, None, &format!("{name}_1band"), name, text)?.simulate_s);
        let row = run_row(dir, None, &format!("{name}_3bands"), name, &three)?;
        three_s.push(row.simulate_s);
        last = Some(row);
    }
    let pulses = last.map_or(0, |r| r.pulses);
    let run = dir.join(format!("{name}_3bands")).join("run");
    let mut sums = vec![0.0; THREE_BANDS.len()];
    // the run's parts, by index, up to the first that is not there
    let parts = (0..).map(|k| run.join(crate::waveform::file::part_name(k)));
    for path in parts.take_while(|p| p.is_file()) {
        let part = crate::waveform::file::read_waveforms(&path)?;
        for w in part {
            let b = THREE_BANDS.iter().position(|&x| Some(x) == w.wavelength_nm);
            if let Some(b) = b {
                sums[b] += w.received_energy_j;
            }
        }
    }
    Ok(BandsRow {
        name: name.to_string(),
        pulses,
        one_band_s: super::median(&mut one_s),
        three_bands_s: super::median(&mut three_s),
        pairs,
        energy_j: sums.iter().map(|s| s / pulses.max(1) as f64).collect(),
    })
}

pub fn bands_table(rows: &[BandsRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut s = String::from(
        "
### Several bands in one pass (532, 1064 and 1550 nm)

The campaign in its own band and in three bands at once: every path traced once, with one throughput per band (docs/physics.md, \"Several bands in one pass\"). Simulate stage wall time, median of alternating runs.

| campaign | pulses | runs each | 1 band s | 3 bands s | 3 bands / 1 band | mean received energy per pulse, J (532 / 1064 / 1550 nm) |
| --- | ---: | ---: | ---: | ---: | ---: | --- |
",
    );
    for r in rows {
        let energy: Vec<String> = r.energy_j.iter().map(|e| format!("{e:.3e}")).collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.2} | {:.2} | {:.2} | {} |",
            r.name,
            r.pulses,
            r.pairs,
            r.one_band_s,
            r.three_bands_s,
            r.three_bands_s / r.one_band_s,
            energy.join(" / ")
        );
    }
    s
}

/// A campaign run on one thread and on all, for Amdahl's law: with a serial fraction f, n
/// threads take T1 (f + (1 - f) / n), so f = (n Tn / T1 - 1) / (n - 1), and N threads would
/// run N / (1 + f (N - 1)) times faster than one.
#[derive(Clone, Debug)]
pub struct Scaling {
    pub name: String,
    pub threads: usize,
    /// (whole run, simulate stage) wall times on one thread and on `threads`, s.
    pub one: (f64, f64),
    pub all: (f64, f64),
}

/// Pairs of runs (one thread, then all) behind a [`Scaling`], odd so that one is the median.
const SCALING_PAIRS: usize = 3;

/// Runs the campaign of `row` on one thread and then on all, [`SCALING_PAIRS`] times, and
/// keeps the pair of median serial fraction (of the whole run). One run on one thread set
/// against a run on all made at another time gives serial fractions that vary several-fold
/// between benches of the same code: a pair run back to back shares the machine's mood.
pub fn scaling(
    dir: &Path,
    runner: Option<&Path>,
    row: &CampaignRow,
    text: &str,
) -> Result<Scaling> {
    let threads = rayon::current_num_threads();
    let mut pairs = Vec::with_capacity(SCALING_PAIRS);
    for _ in 0..SCALING_PAIRS {
        let one = run_row_on(dir, runner, &row.name, &row.what, text, Some(1))?;
        let all = run_row_on(dir, runner, &row.name, &row.what, text, None)?;
        pairs.push(Scaling {
            name: row.name.clone(),
            threads,
            one: (one.run_s, one.simulate_s),
            all: (all.run_s, all.simulate_s),
        });
    }
    let f = |s: &Scaling| serial_fraction(s.one.0, s.all.0, threads).unwrap_or(0.0);
    pairs.sort_by(|a, b| f(a).total_cmp(&f(b)));
    Ok(pairs.swap_remove(SCALING_PAIRS / 2))
}

/// Amdahl's serial fraction from the wall times on one and on `n` threads (None below 2).
pub fn serial_fraction(t1: f64, tn: f64, n: usize) -> Option<f64> {
    (n >= 2 && t1 > 0.0).then(|| ((n as f64 * tn / t1 - 1.0) / (n as f64 - 1.0)).clamp(0.0, 1.0))
}

/// Speed-up on `threads` threads of a run with serial fraction `f`.
pub fn amdahl_speedup(f: f64, threads: f64) -> f64 {
    threads / (1.0 + f * (threads - 1.0))
}

/// The markdown table of [`Scaling`]s.
pub fn scaling_table(rows: &[Scaling]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    let mut s = String::from(
        "\n### Serial share of a campaign run (Amdahl), from one thread against all\n\nSerial fraction f = (n T_n / T_1 - 1) / (n - 1) of the whole run (plan to products) and of the simulate stage; projected speed-up on N threads N / (1 + f (N - 1)). Each row is the median of three pairs of runs (one thread, then n), by the whole run's serial fraction.\n\n| campaign | threads n | run s, 1 thread | run s, n threads | serial fraction, run | speed-up at 20 / 64 threads, run | serial fraction, simulate | speed-up at 20 / 64 threads, simulate |\n| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n",
    );
    for r in rows {
        let cell = |t1: f64, tn: f64| match serial_fraction(t1, tn, r.threads) {
            Some(f) => (
                format!("{f:.3}"),
                format!(
                    "{:.1} / {:.1}",
                    amdahl_speedup(f, 20.0),
                    amdahl_speedup(f, 64.0)
                ),
            ),
            None => ("– (needs 2 threads)".to_string(), "–".to_string()),
        };
        let (run_f, run_x) = cell(r.one.0, r.all.0);
        let (sim_f, sim_x) = cell(r.one.1, r.all.1);
        let _ = writeln!(
            s,
            "| {} | {} | {:.1} | {:.1} | {run_f} | {run_x} | {sim_f} | {sim_x} |",
            r.name, r.threads, r.one.0, r.all.0
        );
    }
    s
}

/// The markdown table of the campaign rows and the skipped ones.
pub fn table(rows: &[CampaignRow], skipped: &[(String, String)]) -> String {
    let mut s = String::from(
        "\n### Campaigns (paper sections 3.2-3.4 and an airborne survey), whole runs through the pipeline\n\nEach campaign runs in a `lidarsim run` process of its own, as a user runs it: run s is that process's wall time, products s the products stage's (with its share of the run), peak memory its peak resident memory (MiB). CPU is the simulate stage's process CPU time over its wall time, out of 100 % per thread. A campaign whose run takes under 2 s is run five times: its row is the run of median wall time.\n\n| campaign | what | pulses | rays/pulse | run s | simulate s | products s | pulses/s simulate | pulses/s run | CPU | peak memory MiB | result |\n| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.1} | {:.1} | {} | {:.0} | {:.0} | {} | {} | {} |",
            r.name,
            r.what,
            r.pulses,
            r.rays_per_pulse,
            r.run_s,
            r.simulate_s,
            if r.products_s.is_finite() {
                format!(
                    "{:.2} ({:.1} %)",
                    r.products_s,
                    100.0 * r.products_s / r.run_s
                )
            } else {
                "–".to_string()
            },
            r.pulses_per_s,
            r.run_pulses_per_s,
            r.cpu_utilisation.map_or("–".to_string(), |u| format!(
                "{:.0} % of {} %",
                100.0 * u * r.threads as f64,
                100 * r.threads
            )),
            r.peak_mb.map_or("–".to_string(), |m| format!("{m:.0}")),
            r.result
        );
    }
    for (name, why) in skipped {
        let _ = writeln!(s, "| {name} | skipped: {why} | | | | | | | | | | |");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Amdahl's law both ways: times made from a known serial fraction give it back, and the
    /// projection is 1 on one thread and 1/f on many.
    #[test]
    fn the_serial_fraction_comes_back_from_the_times_it_makes() {
        for f in [0.0, 0.05, 0.3, 1.0] {
            let (t1, n) = (100.0, 2);
            let tn = t1 * (f + (1.0 - f) / n as f64);
            assert!(
                (serial_fraction(t1, tn, n).unwrap() - f).abs() < 1e-12,
                "{f}"
            );
            assert!((amdahl_speedup(f, 1.0) - 1.0).abs() < 1e-12);
        }
        assert!((amdahl_speedup(0.05, 1e9) - 20.0).abs() < 1e-6);
        assert_eq!(serial_fraction(10.0, 10.0, 1), None);
        // faster than linear (noise) is clamped to no serial part
        assert_eq!(serial_fraction(10.0, 4.0, 2), Some(0.0));
    }
}
