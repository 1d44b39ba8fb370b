//! The run: stages that turn a campaign into the files of a run folder (outputs.md).
//!
//! plan → simulate → products → report. Every file is written under a temporary name and
//! renamed when complete, so a crash or a kill never leaves a half-written file under its final
//! name. `manifest.json` records, per stage, its status, the fingerprint of its inputs (the
//! resolved campaign, the scene's files, the tool version), its outputs and wall time. With
//! `--resume` a stage whose fingerprint is unchanged is kept, and simulation keeps every part
//! file already written: a run killed at any moment and resumed gives the same files as an
//! uninterrupted one, since every random draw derives from (seed, pulse, chunk).

pub mod check;
pub mod manifest;
pub mod memory;
pub mod open;
pub mod simulate;
pub mod sweep;

pub use manifest::StageRecord;
use manifest::{
    fingerprint, forget_damaged, invalidate_after, record, remove_products, save, Manifest,
};
use simulate::simulate_parts;
pub use simulate::{probe_rays_per_second, simulate, simulate_in_memory, with_method_chosen};
use sweep::run_sweep;
pub use sweep::RunTotals;

use crate::campaign::{Loaded, Method, ReceiverDepth};
use crate::error::{Error, Result};
use crate::fsutil::write_text_atomic;
use crate::plan::{self, Plan};
use crate::products;
use crate::progress::{log, StageClock};
use crate::scene::Scene;
use crate::waveform::file::{part_is_whole, part_name, Parts};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, clap::ValueEnum)]
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

    /// The stage of a name as [`Stage::name`] gives it, with the names there are when not.
    pub fn from_name(name: &str) -> Result<Stage> {
        Stage::ALL
            .into_iter()
            .find(|s| s.name() == name.trim())
            .ok_or_else(|| {
                let names: Vec<&str> = Stage::ALL.iter().map(|s| s.name()).collect();
                Error::msg(format!(
                    "stage {name:?}: expected one of {}",
                    names.join(", ")
                ))
            })
    }
}

/// `K/N` with 0 ≤ K < N, checked: the parts a shard simulates.
pub fn check_shard((k, n): (usize, usize)) -> Result<(usize, usize)> {
    if n == 0 || k >= n {
        return Err(Error::msg(format!(
            "shard {k}/{n}: expected K/N with 0 <= K < N, e.g. 0/4"
        )));
    }
    Ok((k, n))
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

/// Runs a campaign file into its run folder (each combination of a sweep into a sub-folder).
pub fn run(campaign_path: &Path, opts: &RunOptions) -> Result<RunSummary> {
    run_loaded(&plan::read_campaign(campaign_path)?, opts)
}

/// [`run`] for a campaign already read and checked (a host's mapping, overrides applied).
pub fn run_loaded(loaded: &Loaded, opts: &RunOptions) -> Result<RunSummary> {
    let out = opts
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(&loaded.campaign.name));
    with_threads(opts.threads, || match &loaded.campaign.sweep {
        Some(sweep) => run_sweep(loaded, sweep, &out, opts),
        None => run_single(loaded, &out, opts, &mut SceneCache::default()),
    })
    .map_err(Error::in_run)
}

/// Most threads a run may ask for: these still start, if slowly, while far more fail to
/// start (each needs its stack), which ends the process where no error can be returned.
pub const MAX_THREADS: usize = 4096;

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
        if n > MAX_THREADS {
            return Err(Error::msg(format!(
                "--threads {n}: at most {MAX_THREADS} (threads beyond the cores only wait their \
                 turn, and the system runs out of them)"
            )));
        }
        b = b.num_threads(n);
    }
    let pool = b
        .build()
        .map_err(|e| Error::msg(format!("cannot start threads: {e}")))?;
    pool.install(f)
}

/// Scenes already loaded, by (file, wavelengths): sweep combinations share them.
#[derive(Default)]
struct SceneCache {
    scenes: Vec<(PathBuf, Vec<u64>, Scene)>,
}

impl SceneCache {
    fn get(&mut self, path: &Path, wavelengths_nm: &[f64]) -> Result<&Scene> {
        let key: Vec<u64> = wavelengths_nm.iter().map(|w| w.to_bits()).collect();
        if let Some(i) = self
            .scenes
            .iter()
            .position(|(p, w, _)| p == path && *w == key)
        {
            return Ok(&self.scenes[i].2);
        }
        let t = Instant::now();
        let scene = Scene::load_bands(path, wavelengths_nm)?;
        let s = scene.stats();
        log(&format!(
            "scene {}: {} instances (traced as {}), {} triangles ({} distinct), {:.1} MB, loaded in {:.2} s",
            scene.name,
            s.instances,
            s.traced_instances,
            s.instanced_triangles,
            s.distinct_triangles,
            s.memory_bytes as f64 / 1e6,
            t.elapsed().as_secs_f64()
        ));
        for w in scene.warnings() {
            log(&format!("warning: {w}"));
        }
        self.scenes.push((path.to_path_buf(), key, scene));
        Ok(&self.scenes.last().expect("just pushed").2)
    }
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

/// A run folder while its stages run: its manifest and what the command asked for.
struct RunFolder<'a> {
    out: &'a Path,
    opts: &'a RunOptions,
    manifest_path: PathBuf,
    manifest: Manifest,
    /// The stages whose files were found damaged on opening, each with the file: forgotten,
    /// with every later stage.
    damaged: Vec<(Stage, String)>,
    /// Held while the run works in the folder (none for a shard: shards share it).
    _lock: Option<FolderLock>,
}

/// An exclusive claim on a run folder: `run.lock` holds the owner's process id and start
/// time, and goes when the run ends. A lock whose process is gone (killed) is stale and taken
/// over, as is one whose id a later process took (a container reuses ids at once).
struct FolderLock {
    path: PathBuf,
}

/// What a run says when another holds the folder.
fn busy(out: &Path, pid: u32) -> Error {
    Error::file(
        out,
        format!("another lidarsim run (PID {pid}) is working in this folder"),
    )
    .advise("wait for it to end or stop it, then run again with --resume")
}

impl FolderLock {
    /// For a shard, which shares the folder with other shards and so takes no lock: refuses
    /// when a whole run holds it (on this host: a lock of another host's run looks stale).
    fn check_free(out: &Path) -> Result<()> {
        let held = std::fs::read_to_string(out.join("run.lock")).ok();
        match held.as_deref().and_then(lock_holder) {
            Some(pid) => Err(busy(out, pid)),
            None => Ok(()),
        }
    }

    fn take(out: &Path) -> Result<FolderLock> {
        let path = out.join("run.lock");
        // the lock appears with its content or not at all: written aside, then hard-linked
        // into place, which fails when a lock is there
        let mine = crate::fsutil::temp_name(&path);
        std::fs::write(&mine, lock_text()).map_err(|e| {
            Error::io(&mine, "cannot write the folder's lock", e)
                .advise(crate::fsutil::RUN_WRITE_ADVICE)
        })?;
        let taken = (|| {
            for _ in 0..3 {
                match std::fs::hard_link(&mine, &path) {
                    Ok(()) => return Ok(FolderLock { path: path.clone() }),
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                        let holder = std::fs::read_to_string(&path).ok();
                        if let Some(pid) = holder.as_deref().and_then(lock_holder) {
                            return Err(busy(out, pid));
                        }
                        // stale: left by a run that was killed
                        let _ = std::fs::remove_file(&path);
                    }
                    // a file system without hard links: create it in place instead
                    Err(_) => {
                        use std::io::Write as _;
                        let mut f = std::fs::OpenOptions::new()
                            .write(true)
                            .create_new(true)
                            .open(&path)
                            .map_err(|e| {
                                Error::io(&path, "cannot take the folder's lock", e)
                                    .advise(crate::fsutil::RUN_WRITE_ADVICE)
                            })?;
                        let _ = write!(f, "{}", lock_text());
                        return Ok(FolderLock { path: path.clone() });
                    }
                }
            }
            Err(Error::file(&path, "cannot take the folder's lock")
                .advise("remove it and run again"))
        })();
        let _ = std::fs::remove_file(&mine);
        taken
    }
}

impl Drop for FolderLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// What `run.lock` holds: this process's id and, where the system says, its start time.
fn lock_text() -> String {
    let pid = std::process::id();
    match process_start(pid) {
        Some(start) => format!("{pid} {start}"),
        None => pid.to_string(),
    }
}

/// The process holding a lock of text `text` when it still runs: its id, and its start time
/// when the lock gives one (a lock of an id alone, or on a system without /proc, is held while
/// a process of that id runs).
fn lock_holder(text: &str) -> Option<u32> {
    let mut words = text.split_whitespace();
    let pid: u32 = words.next()?.parse().ok()?;
    let start: Option<u64> = words.next().and_then(|w| w.parse().ok());
    let alive = Path::new(&format!("/proc/{pid}")).exists() && !process_ended(pid);
    match start {
        // this very process (another of its threads: a host running two runs) holds it too
        Some(s) => (alive && process_start(pid).is_none_or(|now| now == s)).then_some(pid),
        // an id alone: this process's own id is a killed process's that it now reuses
        None => (alive && pid != std::process::id()).then_some(pid),
    }
}

/// Whether process `pid` has ended and only waits for its parent to collect it (a zombie,
/// state Z, or X): a run killed a moment ago whose parent has not waited yet holds nothing.
fn process_ended(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|stat| {
            let after_name = stat[stat.rfind(')')? + 1..].trim_start().chars().next()?;
            Some(matches!(after_name, 'Z' | 'X'))
        })
        .unwrap_or(false)
}

/// When process `pid` started, in clock ticks since boot (Linux: field 22 of
/// /proc/PID/stat, counted after the command's name, which may hold spaces).
fn process_start(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let after_name = &stat[stat.rfind(')')? + 1..];
    after_name.split_whitespace().nth(19)?.parse().ok()
}

impl<'a> RunFolder<'a> {
    /// Creates the folder, or takes it over with its manifest when resuming or sharding.
    fn open(loaded: &Loaded, out: &'a Path, opts: &'a RunOptions) -> Result<RunFolder<'a>> {
        std::fs::create_dir_all(out).map_err(|e| {
            Error::io(out, "cannot create run folder", e).advise(crate::fsutil::RUN_WRITE_ADVICE)
        })?;
        let lock = match opts.shard {
            None => Some(FolderLock::take(out)?),
            Some(_) => {
                FolderLock::check_free(out)?;
                None
            }
        };
        let manifest_path = out.join("manifest.json");
        // shards share the folder with each other, and `--stages` picks up where earlier
        // stages left off: both keep what is there, like a resume (the fingerprints still
        // decide what is trusted)
        let keep = opts.resume || opts.shard.is_some() || opts.stages.is_some();
        let mut manifest = if keep {
            Manifest::read(&manifest_path).unwrap_or_else(|| {
                if manifest_path.exists() {
                    // a damaged record is never trusted: nothing it says is kept
                    log(&format!(
                        "{} cannot be read: every stage is redone",
                        manifest_path.display()
                    ));
                }
                Manifest::default()
            })
        } else {
            Manifest::default()
        };
        // a resume into another campaign's folder keeps none of it (the fingerprints differ):
        // said, so that its files going is no surprise
        if keep && !manifest.campaign.is_empty() && manifest.campaign != loaded.campaign.name {
            log(&format!(
                "warning: {} holds the run of campaign `{}`: this campaign's stages replace it",
                out.display(),
                manifest.campaign
            ));
        }
        let mut damaged = Vec::new();
        if keep {
            damaged = forget_damaged(&mut manifest, out);
            for (stage, file) in &damaged {
                log(&format!(
                    "{}: {file} is not what the {} stage wrote: that stage is redone",
                    out.display(),
                    stage.name()
                ));
            }
            // another shard may be writing beside a shard: only a plain resume, alone on the
            // folder, removes temporary files (left by a crash or a kill)
            if opts.shard.is_none() {
                clean_temp_files(out);
            }
        } else {
            // a new run in a used folder: what the last run's products wrote goes too, or a
            // reader would take its points and DSM for this run's until products are redone
            if let Some(old) = Manifest::read(&manifest_path) {
                for (name, r) in &old.stages {
                    if let Some(stage) = Stage::ALL.into_iter().find(|s| s.name() == name) {
                        remove_products(out, stage, r);
                    }
                }
            }
            for name in [
                "waveforms",
                "pulses.parquet",
                "manifest.json",
                "report.md",
                "sweep.json",
                "sweep.csv",
            ] {
                let p = out.join(name);
                let _ = if p.is_dir() {
                    std::fs::remove_dir_all(&p)
                } else {
                    std::fs::remove_file(&p)
                };
            }
        }
        manifest.tool_version = env!("CARGO_PKG_VERSION").to_string();
        manifest.campaign = loaded.campaign.name.clone();
        Ok(RunFolder {
            out,
            opts,
            manifest_path,
            manifest,
            damaged,
            _lock: lock,
        })
    }

    /// The error of a stage left out of `--stages` whose output a later stage asked for is
    /// missing or stale.
    fn missing(&self, stage: Stage) -> Error {
        let damaged = self.damaged.iter().find(|(s, _)| *s <= stage);
        let why = match damaged {
            Some((s, file)) if *s == stage => {
                format!("must run again ({file} is not what it wrote)")
            }
            Some((s, file)) => format!(
                "must run again (the {} stage's {file} is not what it wrote)",
                s.name()
            ),
            None if self
                .manifest
                .stages
                .get(stage.name())
                .is_some_and(|r| r.status == "partial") =>
            {
                // a shard's parts, or a run stopped midway: the rest are to be simulated
                "has not finished (parts of it are still to run: the other shards, or \
                 --resume)"
                    .into()
            }
            None if self.manifest.stages.contains_key(stage.name()) => {
                "is out of date (the campaign, its scene or lidarsim changed since it ran)".into()
            }
            None => "has not run".into(),
        };
        Error::msg(format!(
            "{}: stage {} {why}: include it in --stages",
            self.out.display(),
            stage.name()
        ))
    }

    fn wanted(&self, stage: Stage) -> bool {
        self.opts.stages.as_ref().is_none_or(|v| v.contains(&stage))
    }

    /// Whether `stage` ran to the end on inputs with this fingerprint.
    fn done(&self, stage: Stage, fp: &str) -> bool {
        self.manifest.done(stage, fp)
    }

    /// Records a stage that ran (`note`: what is left to do, if anything), makes every later
    /// stage stale and saves the manifest.
    fn finish(
        &mut self,
        stage: Stage,
        fp: &str,
        outputs: Vec<String>,
        clock: StageClock,
        note: Option<String>,
        status: &str,
    ) -> Result<()> {
        // what the stage freed goes back to the system before the next stage allocates
        crate::progress::release_free_memory();
        record(
            &mut self.manifest,
            self.out,
            stage,
            fp,
            outputs,
            clock,
            note,
        );
        if let Some(r) = self.manifest.stages.get_mut(stage.name()) {
            r.status = status.into();
        }
        invalidate_after(&mut self.manifest, self.out, stage);
        save(&self.manifest_path, &self.manifest)
    }
}

/// One campaign's stages in order, each kept or run by its fingerprint. Long because it is the
/// run's whole sequence (plan, scene, pilot, simulate, products, report) read top to bottom;
/// each stage is a function of its own.
fn run_single(
    loaded: &Loaded,
    out: &Path,
    opts: &RunOptions,
    cache: &mut SceneCache,
) -> Result<RunSummary> {
    let start = Instant::now();
    let mut run = RunFolder::open(loaded, out, opts)?;
    let before = run.manifest.clone();
    let resolved = loaded.resolved_yaml();
    write_text_atomic(&out.join("campaign.resolved.yaml"), &resolved)?;
    // the campaign with its scene as the file names it, not as found from the working folder:
    // the same campaign run from elsewhere is the same run (the scene's bytes are in the
    // simulate stage's fingerprint)
    let as_written = loaded.campaign_yaml_but_products();
    // a recorded trajectory's epochs are the plan's input as much as the campaign's keys
    let trajectory = match loaded.campaign.platform.trajectory.as_ref() {
        Some(t) => {
            let path = t.resolved.clone().unwrap_or_else(|| PathBuf::from(&t.file));
            std::fs::read(&path).map_err(|e| Error::io(&path, "cannot read", e))?
        }
        None => Vec::new(),
    };
    let fp_plan = fingerprint(&[
        as_written.as_bytes(),
        &trajectory,
        env!("CARGO_PKG_VERSION").as_bytes(),
    ]);
    let plan = plan_stage(&mut run, loaded, &fp_plan)?;
    // after the plan, which a `--stages` without it refuses first: an error then is the one
    // message on stderr
    for w in loaded.campaign.warnings() {
        log(&format!("warning: {w}"));
    }

    let mut summary = RunSummary {
        out: out.to_path_buf(),
        pulses: plan.len(),
        rays: 0,
        seconds: 0.0,
        parts_done: 0,
        complete: true,
    };
    let later = [Stage::Simulate, Stage::Products, Stage::Report];
    if !later.iter().any(|s| run.wanted(*s)) {
        summary.seconds = start.elapsed().as_secs_f64();
        return Ok(summary);
    }

    let scene = cache.get(&loaded.scene_path, loaded.campaign.wavelength_nm.all())?;
    memory::fits(loaded, scene, &plan)?;
    check::mission_fits(loaded, scene, &plan)?;
    for w in check::scene_warnings(&loaded.campaign, scene, &plan) {
        log(&format!("warning: {w}"));
    }
    let sim = &loaded.campaign.simulation;
    let bdpt = matches!(sim.method, Method::Bdpt | Method::Auto);
    if scene.water.is_some() && bdpt && sim.receiver_depth == ReceiverDepth::First {
        log(&format!(
            "warning: simulation.receiver_depth first {}; full (or auto) keeps every strategy",
            simulate::WATER_DEPTH
        ));
    }
    // `auto` resolved here, once the scene is known. The pilot is deterministic, but another
    // version of the program may pick otherwise: the method picked is part of the simulate
    // fingerprint (and the sun's selection), so a resume never mixes parts of two methods
    let t = Instant::now();
    let chosen = simulate::with_method_chosen(loaded, scene, &plan);
    let original = loaded;
    let loaded = match &chosen {
        Some(c) => {
            let note = c.method_note.as_deref().unwrap_or_default();
            log(&format!(
                "{note} (pilot {:.2} s)",
                t.elapsed().as_secs_f64()
            ));
            write_text_atomic(&out.join("campaign.resolved.yaml"), &c.resolved_yaml())?;
            c
        }
        None => loaded,
    };
    let picked = chosen.as_ref().map(|c| simulate::choices_made(c, original));
    // what loading the scene and the pilots freed (a BVH build's scratch) goes back before
    // the simulate stage allocates, and is not counted as its time: returned at the stage's
    // end, it would keep one thread busy after the others, a visible part of a short run's
    // CPU share
    crate::progress::release_free_memory();
    let parts = Parts::of_run(loaded, scene, &plan);
    let fp_sim = simulate_fingerprint(&fp_plan, scene, picked, parts)?;
    if run.done(Stage::Simulate, &fp_sim) {
        if let Some(bad) = first_broken_part(out, parts, bands_of(loaded), &fp_sim) {
            // the manifest says done, the files disagree: the files win
            log(&format!(
                "simulate: a part file is missing or damaged ({bad}): it is simulated again"
            ));
            run.manifest.stages.remove(Stage::Simulate.name());
            invalidate_after(&mut run.manifest, out, Stage::Simulate);
            run.damaged.push((Stage::Simulate, bad));
        }
    }
    if run.wanted(Stage::Simulate) && !run.done(Stage::Simulate, &fp_sim) {
        let (rays, parts_done) = simulate_stage(&mut run, loaded, scene, &plan, parts, &fp_sim)?;
        summary.rays = rays;
        summary.parts_done = parts_done;
    } else if run.done(Stage::Simulate, &fp_sim) {
        // the parts are whole and this simulation's: a marker lost or damaged since is put
        // back, or the next change would take the parts for another campaign's
        let marker = fingerprint_marker(out);
        if std::fs::read_to_string(&marker).map_or(true, |t| t.trim() != fp_sim) {
            write_text_atomic(&marker, &fp_sim)?;
        }
        log("simulate: up to date");
    }
    if !run.done(Stage::Simulate, &fp_sim) {
        if !run.wanted(Stage::Simulate) {
            return Err(run.missing(Stage::Simulate));
        }
        summary.complete = false;
        summary.seconds = start.elapsed().as_secs_f64();
        return Ok(summary);
    }

    let fp_products = fingerprint(&[
        fp_sim.as_bytes(),
        b"products",
        loaded.products_yaml().as_bytes(),
    ]);
    if run.wanted(Stage::Report)
        && !run.wanted(Stage::Products)
        && !run.done(Stage::Products, &fp_products)
    {
        return Err(run.missing(Stage::Products));
    }
    if run.wanted(Stage::Products) && !run.done(Stage::Products, &fp_products) {
        // products of other `products:` (a DSM no longer asked for, LAS for LAZ) go with
        // their record, before this stage writes its own
        invalidate_after(&mut run.manifest, out, Stage::Simulate);
        products_stage(&mut run, loaded, scene, &plan, parts, &fp_products)?;
    }
    let fp_report = fingerprint(&[fp_products.as_bytes(), b"report"]);
    if run.wanted(Stage::Report)
        && run.done(Stage::Products, &fp_products)
        && !run.done(Stage::Report, &fp_report)
    {
        report_stage(&mut run, loaded, scene, parts, &fp_report)?;
    }
    if run.manifest == before {
        log("nothing to do: every stage is up to date");
    }
    // with --stages, complete when the stages asked for are
    summary.complete = match &opts.stages {
        Some(_) => {
            (!run.wanted(Stage::Products) || run.done(Stage::Products, &fp_products))
                && (!run.wanted(Stage::Report) || run.done(Stage::Report, &fp_report))
        }
        None => run.done(Stage::Report, &fp_report),
    };
    summary.seconds = start.elapsed().as_secs_f64();
    Ok(summary)
}

/// The products stage: discrete returns, photon counts and the DSM error, from the waveforms.
fn products_stage(
    run: &mut RunFolder,
    loaded: &Loaded,
    scene: &Scene,
    plan: &Plan,
    parts: Parts,
    fp: &str,
) -> Result<()> {
    let clock = StageClock::start();
    let (outputs, note) = products::stage::run(loaded, scene, run.out, plan, parts)?;
    let secs = clock.wall_s();
    // the share of the cores kept busy, as the simulate stage reports it
    let busy = clock.busy(secs);
    log(&format!(
        "products: {} in {secs:.2} s{busy}",
        outputs.join(", "),
    ));
    let note = (!note.is_empty()).then_some(note);
    run.finish(Stage::Products, fp, outputs, clock, note, "done")
}

/// The report stage: report.md, quoting the simulate stage's wall time.
fn report_stage(
    run: &mut RunFolder,
    loaded: &Loaded,
    scene: &Scene,
    parts: Parts,
    fp: &str,
) -> Result<()> {
    let clock = StageClock::start();
    let simulated = run.manifest.stages.get("simulate");
    let simulate_s = simulated.map(|r| r.wall_time_s).unwrap_or(0.0);
    let pulses_now = simulated.and_then(|r| r.pulses_simulated);
    let text = products::report::report(loaded, scene, parts, run.out, (simulate_s, pulses_now))?;
    write_text_atomic(&run.out.join("report.md"), &text)?;
    run.finish(
        Stage::Report,
        fp,
        vec!["report.md".into()],
        clock,
        None,
        "done",
    )
}

/// The plan stage. Planning is cheap and deterministic, so every stage makes the pulses it
/// needs from the [`Plan`], a part at a time; `pulses.parquet` is written only when the stage
/// is not already done.
fn plan_stage(run: &mut RunFolder, loaded: &Loaded, fp: &str) -> Result<Plan> {
    let clock = StageClock::start();
    let pulses = Plan::new(&loaded.campaign)?;
    if pulses.is_empty() {
        return Err(loaded.doc.error("platform", "plans no pulses").advise(
            "give it at least one: static pulses, or lines, tracks and angle ranges longer \
             than their steps",
        ));
    }
    if run.wanted(Stage::Plan) && !run.done(Stage::Plan, fp) {
        plan::write_pulses(&run.out.join("pulses.parquet"), &pulses)?;
        run.finish(
            Stage::Plan,
            fp,
            vec!["pulses.parquet".into()],
            clock,
            None,
            "done",
        )?;
        log(&format!(
            "plan: {} pulses in {:.2} s",
            pulses.len(),
            clock.wall_s()
        ));
    } else if !run.done(Stage::Plan, fp) {
        return Err(run.missing(Stage::Plan));
    } else {
        log("plan: up to date");
    }
    Ok(pulses)
}

/// The simulate stage's fingerprint: the plan's and every scene file's bytes.
fn simulate_fingerprint(
    fp_plan: &str,
    scene: &Scene,
    picked: Option<String>,
    parts: Parts,
) -> Result<String> {
    let mut scene_bytes = Vec::new();
    for f in &scene.files {
        let bytes = std::fs::read(f).map_err(|e| Error::io(f, "cannot read", e))?;
        scene_bytes.push(bytes);
    }
    let mut inputs: Vec<&[u8]> = vec![fp_plan.as_bytes()];
    inputs.extend(scene_bytes.iter().map(|b| b.as_slice()));
    inputs.extend(picked.as_deref().map(str::as_bytes));
    // parts cut otherwise (another version's rule) are not this run's parts
    let size = format!("parts of {}", parts.size());
    inputs.push(size.as_bytes());
    Ok(fingerprint(&inputs))
}

/// The file that says which simulation made the parts in a run folder's `waveforms/`.
fn fingerprint_marker(out: &Path) -> PathBuf {
    out.join("waveforms").join("fingerprint")
}

/// Removes the files of parts `first` and later (`part-NNNNN.*`) from the waveforms folder.
fn remove_parts_from(wf_dir: &Path, first: usize) {
    let Ok(entries) = std::fs::read_dir(wf_dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let index = name
            .to_str()
            .and_then(|n| n.strip_prefix("part-"))
            .and_then(|n| n.split('.').next())
            .and_then(|k| k.parse::<usize>().ok());
        if index.is_some_and(|k| k >= first) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

/// The first of a run's parts (in `bands` bands) that is missing or not whole, by its name.
fn first_broken_part(out: &Path, parts: Parts, bands: usize, fp: &str) -> Option<String> {
    (0..parts.count())
        .find(|&k| !part_done(out, parts, k, bands, fp))
        .map(part_name)
}

/// Whether part `k` is whole: its waveforms (checksum, rows, the simulation that made them)
/// and its per-pulse timings beside them, which are made again with it when damaged.
fn part_done(out: &Path, parts: Parts, k: usize, bands: usize, fp: &str) -> bool {
    let range = parts.range(k);
    let pulses = range.len();
    part_is_whole(&out.join(part_name(k)), range, pulses * bands, fp)
        && simulate::stats_are_whole(&out.join(simulate::stats_name(k)), pulses)
}

/// Bands the campaign traces: rows per pulse in its waveform parts.
fn bands_of(loaded: &Loaded) -> usize {
    loaded.campaign.wavelength_nm.all().len()
}

/// The simulate stage: the parts this invocation owns (all, or its shard's) that are not
/// written yet. Returns (rays traced, parts written).
fn simulate_stage(
    run: &mut RunFolder,
    loaded: &Loaded,
    scene: &Scene,
    plan: &Plan,
    cut: Parts,
    fp: &str,
) -> Result<(u64, usize)> {
    let (out, shard) = (run.out, run.opts.shard);
    let clock = StageClock::start();
    let parts = cut.count();
    let part_files: Vec<String> = (0..parts).map(part_name).collect();
    let wf_dir = out.join("waveforms");
    let marker = fingerprint_marker(out);
    let stale = std::fs::read_to_string(&marker)
        .map(|s| s.trim() != fp)
        .unwrap_or(true);
    if stale && shard.is_none() && wf_dir.exists() {
        let _ = std::fs::remove_dir_all(&wf_dir);
    }
    // a shard leaves the folder to the others, but no part past this run's last is any
    // shard's: those are another campaign's (one of more parts), whose rows a reader of
    // `part-*.parquet` would take for this run's
    remove_parts_from(&wf_dir, parts);
    write_text_atomic(&marker, fp)?;
    let whole = |k: usize| part_done(out, cut, k, bands_of(loaded), fp);
    let todo: Vec<usize> = (0..parts)
        .filter(|k| shard.is_none_or(|(i, n)| k % n == i))
        .filter(|&k| !whole(k))
        .collect();
    let (rays, done, stopped) = simulate_parts(loaded, scene, plan, cut, &todo, out, fp)?;
    // the parts written just now are whole; the others are read again, as another shard may
    // have written some meanwhile
    let mut written_now = vec![false; parts];
    todo[..done].iter().for_each(|&k| written_now[k] = true);
    let missing = (0..parts).filter(|&k| !written_now[k] && !whole(k)).count();
    let pulses_now: usize = todo[..done].iter().map(|&k| cut.range(k).len()).sum();
    if missing == 0 {
        run.finish(Stage::Simulate, fp, part_files, clock, None, "done")?;
    } else {
        let note = format!("{missing} of {parts} parts missing: run again with --resume to finish");
        log(&format!("simulate: {note}"));
        run.finish(
            Stage::Simulate,
            fp,
            part_files,
            clock,
            Some(note),
            "partial",
        )?;
    }
    // its wall time is of these pulses alone: the report's rate is over them
    if let Some(r) = run.manifest.stages.get_mut(Stage::Simulate.name()) {
        r.pulses_simulated = Some(pulses_now as u64);
        save(&run.manifest_path, &run.manifest)?;
    }
    if let Some(signal) = stopped {
        return Err(Error::interrupted(
            signal,
            format!(
                "{} of {parts} parts of waveforms are written in {}",
                parts - missing,
                out.display()
            ),
        ));
    }
    Ok((rays, done))
}

#[cfg(test)]
mod tests {
    use super::{lock_holder, lock_text, process_start};

    /// A lock of this process's id and start time is held (another thread's run); one of its
    /// id and another start time, or of its id alone (left by a killed process whose id it
    /// now has), is stale; so is one of a process that is gone, or of no process at all.
    #[test]
    fn a_lock_is_held_by_its_process_as_it_started() {
        let me = std::process::id();
        assert_eq!(lock_holder(&lock_text()), Some(me));
        let start = process_start(me).expect("Linux: /proc/self/stat");
        assert_eq!(lock_holder(&format!("{me} {}", start + 1)), None);
        assert_eq!(lock_holder(&me.to_string()), None);
        assert_eq!(lock_holder(&format!("{} 1", u32::MAX)), None);
        assert_eq!(lock_holder("garbage"), None);
    }
}
