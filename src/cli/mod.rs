//! Command line: `lidarsim run`, `lidarsim check`.

use crate::campaign::Loaded;
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
    },
    /// Validate a campaign and its scene; print pulses, facets, instances and memory.
    Check { campaign: PathBuf },
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
        } => {
            require_file(&campaign)?;
            let s = pipeline::run(&campaign, &RunOptions { out, threads })?;
            println!(
                "wrote {} ({} pulses, {} rays, {:.2} s)",
                s.out.display(),
                s.pulses,
                s.rays,
                s.seconds
            );
            Ok(())
        }
        Command::Check { campaign } => check(&campaign),
    }
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
    let loaded = Loaded::read(path)?;
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
    println!("ok");
    Ok(())
}

/// Peak resident memory of this process (Linux), bytes.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
