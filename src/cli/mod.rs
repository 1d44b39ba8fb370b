//! Command line: `lidarsim run`, `lidarsim check`.

use crate::bench;
use crate::error::{Error, Result};
use crate::pipeline::{self, RunOptions};
use crate::plan;
use crate::scene::Scene;
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Parser, Debug)]
#[command(name = "lidarsim", version, about = "Physically based LiDAR simulator")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run a campaign into a run folder (default runs/<name>).
    Run {
        campaign: PathBuf,
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads (default: all cores). The output does not depend on it.
        #[arg(long)]
        threads: Option<usize>,
        /// Keep completed stages and simulation parts whose inputs are unchanged.
        #[arg(long)]
        resume: bool,
        /// Stages to run, comma-separated: plan,simulate,products,report (default: all).
        #[arg(long, value_delimiter = ',')]
        stages: Option<Vec<String>>,
        /// Simulate only the parts whose index is K modulo N (for N machines sharing a run).
        #[arg(long, value_name = "K/N")]
        shard: Option<String>,
    },
    /// Validate a campaign and its scene; print pulses, facets, instances and memory.
    Check { campaign: PathBuf },
    /// One table of products across runs (a sweep folder stands for its sub-runs).
    Compare {
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        /// Also write the table as CSV.
        #[arg(long)]
        csv: Option<PathBuf>,
        /// Write plots of DSM error against altitude and pulse rate into this folder.
        #[arg(long)]
        plots: Option<PathBuf>,
    },
    /// Procedural scenes.
    Scene {
        #[command(subcommand)]
        command: SceneCommand,
    },
    /// The paper's experiments as a benchmark: rays and seconds each method needs for
    /// rRMSE ≤ 5% on a GEDI-like pulse (also by footprint, Table 2), the sun's cost, and whole
    /// campaigns (orchard GEDI with sun, MABEL tracks, ALS over a forest) with pulses/s and
    /// peak memory. Quick by default; prints a markdown table and writes bench.md.
    Bench {
        /// Folder for the generated scenes, the campaign runs and bench.md.
        #[arg(long, default_value = "runs/bench")]
        out: PathBuf,
        /// The paper's sizes: 10^7-ray reference, 5 seeds, 6929-pulse tracks, 1029-tree forest.
        #[arg(long)]
        full: bool,
        /// Rays of the reference waveform [quick 10^6, full 10^7].
        #[arg(long)]
        reference_rays: Option<u64>,
        /// Seeds per ray count (median rRMSE) [quick 3, full 5].
        #[arg(long)]
        seeds: Option<u64>,
        /// Scene file of the RAMI orchard (skipped when its data is absent).
        #[arg(long, default_value = "scenes/rami_wco.yaml")]
        rami: PathBuf,
        /// Leave out the campaign rows.
        #[arg(long)]
        no_campaigns: bool,
        #[arg(long)]
        threads: Option<usize>,
        /// Field-of-view half angle, mrad.
        #[arg(long, default_value_t = 0.3)]
        fov_mrad: f64,
        /// Crowns in the generated canopy (100 m × 100 m).
        #[arg(long, default_value_t = 700)]
        trees: usize,
    },
}

#[derive(Subcommand, Debug)]
pub enum SceneCommand {
    /// Write a deterministic procedural scene (OBJ templates, instance tables, scene YAML).
    Generate {
        /// forest, orchard or flat
        kind: String,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Output folder (the scene file is OUT/scene.yaml or similar, printed at the end).
        #[arg(long)]
        out: PathBuf,
        /// Trees (forest, orchard).
        #[arg(long)]
        trees: Option<usize>,
        /// Leaf area index to aim for (forest, orchard).
        #[arg(long)]
        lai: Option<f64>,
        /// Scene size in metres, `X` or `X,Y`.
        #[arg(long, value_delimiter = ',')]
        size: Option<Vec<f64>>,
        /// Distinct tree templates.
        #[arg(long)]
        templates: Option<usize>,
        /// Leaves per template.
        #[arg(long)]
        leaves: Option<usize>,
    },
}

/// Parses the arguments and runs the command; returns the process exit code.
pub fn main() -> i32 {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { 1 } else { 0 };
            let _ = e.print();
            return code;
        }
    };
    match dispatch(cli) {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("error: {e}");
            1
        }
    }
}

fn dispatch(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Run {
            campaign,
            out,
            threads,
            resume,
            stages,
            shard,
        } => {
            require_file(&campaign)?;
            let stages = stages
                .map(|v| {
                    v.iter()
                        .map(|s| pipeline::Stage::parse(s.trim()))
                        .collect::<Result<Vec<_>>>()
                })
                .transpose()?;
            let shard = shard.map(|s| parse_shard(&s)).transpose()?;
            let opts = RunOptions {
                out,
                threads,
                resume,
                stages,
                shard,
            };
            let s = pipeline::run(&campaign, &opts)?;
            let state = if s.complete {
                "complete"
            } else {
                "incomplete: run again with --resume"
            };
            println!(
                "wrote {} ({} pulses, {} rays, {} parts simulated, {:.2} s, {state})",
                s.out.display(),
                s.pulses,
                s.rays,
                s.parts_done,
                s.seconds
            );
            Ok(())
        }
        Command::Check { campaign } => check(&campaign),
        Command::Compare { runs, csv, plots } => {
            use crate::compare;
            let mut rows = Vec::new();
            for r in &runs {
                for dir in compare::expand(r)? {
                    rows.push(compare::read_row(&dir)?);
                }
            }
            print!("{}", compare::markdown(&rows));
            if let Some(path) = csv {
                crate::fsutil::write_text_atomic(&path, &compare::csv(&rows))?;
            }
            if let Some(dir) = plots {
                for p in compare::plots(&rows, &dir)? {
                    eprintln!("wrote {}", p.display());
                }
            }
            Ok(())
        }
        Command::Scene {
            command:
                SceneCommand::Generate {
                    kind,
                    seed,
                    out,
                    trees,
                    lai,
                    size,
                    templates,
                    leaves,
                },
        } => {
            use crate::generate::{generate_with_summary, GenerateOptions, SceneKind};
            let kind: SceneKind = kind.parse()?;
            let size_m = match size.as_deref() {
                None => None,
                Some([x]) => Some([*x, *x]),
                Some([x, y]) => Some([*x, *y]),
                Some(_) => return Err(Error::msg("--size: give X or X,Y in metres")),
            };
            let opts = GenerateOptions {
                trees,
                lai,
                size_m,
                templates,
                leaves,
                ..GenerateOptions::default()
            };
            let s = generate_with_summary(kind, seed, &out, &opts)?;
            println!(
                "wrote {} ({} trees, {} templates, {} facets instanced, {} distinct, LAI {:.2}, {:.1} MB)",
                s.scene.display(),
                s.trees,
                s.templates.len(),
                s.facets,
                s.distinct_facets,
                s.lai,
                s.bytes as f64 / 1e6
            );
            Ok(())
        }
        Command::Bench {
            out,
            full,
            reference_rays,
            seeds,
            rami,
            no_campaigns,
            threads,
            fov_mrad,
            trees,
        } => {
            let mut opts = if full {
                bench::BenchOptions::full(out)
            } else {
                bench::BenchOptions::quick(out)
            };
            if let Some(r) = reference_rays {
                opts.reference_rays = r;
            }
            if let Some(s) = seeds {
                opts.seeds = s;
            }
            opts.rami_scene = rami;
            opts.campaigns = !no_campaigns;
            opts.fov_mrad = fov_mrad;
            opts.canopy.trees = trees;
            let text = pipeline::with_threads(threads, || bench::run(&opts))?;
            let path = bench::write_report(&opts, &text)?;
            println!("{text}\n(written to {})", path.display());
            Ok(())
        }
    }
}

/// `K/N` with 0 ≤ K < N.
fn parse_shard(s: &str) -> Result<(usize, usize)> {
    let bad = || {
        Error::msg(format!(
            "--shard {s}: expected K/N with 0 <= K < N, e.g. 0/4"
        ))
    };
    let (k, n) = s.split_once('/').ok_or_else(bad)?;
    let (k, n): (usize, usize) = (
        k.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if n == 0 || k >= n {
        return Err(bad());
    }
    Ok((k, n))
}

fn require_file(path: &std::path::Path) -> Result<()> {
    if path.is_file() {
        Ok(())
    } else {
        Err(Error::file(path, "campaign file does not exist"))
    }
}

fn check(path: &std::path::Path) -> Result<()> {
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

/// Peak resident memory of this process (Linux), bytes.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
