//! Command line: one function per command, each turning its flags into a call to the stage
//! or tool that does the work.

mod check;

use crate::bench;
use crate::error::{Error, Result};
use crate::generate::{generate_with_summary, GenerateOptions, SceneKind};
use crate::pipeline::{self, RunOptions};
use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser, Debug)]
#[command(name = "lidarsim", version, about = "Physically based LiDAR simulator")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run a campaign into a run folder (default runs/<name>).
    Run(RunArgs),
    /// Validate a campaign and its scene; print pulses, facets, instances and memory.
    Check {
        /// The campaign file (YAML).
        campaign: PathBuf,
    },
    /// One table of products across runs (a sweep folder stands for its sub-runs).
    Compare(CompareArgs),
    /// Procedural scenes.
    Scene {
        #[command(subcommand)]
        command: SceneCommand,
    },
    /// The paper's experiments as a benchmark: rays and seconds each method needs for
    /// rRMSE ≤ 5% on a GEDI-like pulse (also by footprint, Table 2), the sun's cost, and whole
    /// campaigns (orchard GEDI with sun, MABEL tracks, ALS over a forest and over a town)
    /// with pulses/s, CPU use and peak memory. Quick by default; prints a markdown report and
    /// writes it to --report (docs/benchmarks.md).
    Bench(BenchArgs),
}

#[derive(Args, Debug)]
pub struct RunArgs {
    /// The campaign file (YAML).
    campaign: PathBuf,
    /// The run folder (default: runs/<name>, <name> the campaign's).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Worker threads (default: all cores). The output does not depend on it.
    #[arg(long, allow_negative_numbers = true)]
    threads: Option<usize>,
    /// Keep completed stages and simulation parts whose inputs are unchanged.
    #[arg(long)]
    resume: bool,
    /// Stages to run, comma-separated (default: all).
    #[arg(long, value_delimiter = ',', value_enum)]
    stages: Option<Vec<pipeline::Stage>>,
    /// Simulate only the parts whose index is K modulo N (for N machines sharing a run).
    #[arg(long, value_name = "K/N", allow_hyphen_values = true)]
    shard: Option<String>,
}

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// Run folders (a sweep's folder stands for its sub-runs).
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// Also write the table as CSV.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Write plots of the DSM's RMSE against altitude and pulse rate into this folder.
    #[arg(long)]
    plots: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Folder for the generated scenes and the campaign runs.
    #[arg(long, default_value = "runs/bench")]
    out: PathBuf,
    /// The markdown report, its first line naming the command, commit and machine.
    #[arg(long, default_value = "docs/benchmarks.md")]
    report: PathBuf,
    /// The paper's sizes: 10^7-ray reference, 5 seeds, 6929-pulse tracks, 1029-tree forest.
    #[arg(long)]
    full: bool,
    /// Rays of the reference waveform [quick 10^6, full 10^7].
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u64).range(1..))]
    reference_rays: Option<u64>,
    /// Seeds per ray count (median rRMSE) [quick 3, full 5].
    #[arg(long, allow_negative_numbers = true, value_parser = clap::value_parser!(u64).range(1..))]
    seeds: Option<u64>,
    /// Scene file of the RAMI orchard [default: scenes/rami_wco.yaml, whose rows are skipped
    /// when its data is absent; one named here must be there].
    #[arg(long)]
    rami: Option<PathBuf>,
    /// Leave out the campaign rows.
    #[arg(long)]
    no_campaigns: bool,
    /// Folder of the campaign rows' files (one YAML per row, quick.yaml for quick mode).
    #[arg(long, default_value = "pipelines/bench")]
    campaigns: PathBuf,
    /// Worker threads (default: all cores).
    #[arg(long, allow_negative_numbers = true)]
    threads: Option<usize>,
    /// Field-of-view half angle, mrad, 0 < x < 1500.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.3)]
    fov_mrad: f64,
    /// Crowns in the generated canopy (100 m × 100 m), at most 10^7 as `scene generate`
    /// allows (far more would exhaust memory).
    #[arg(long, allow_negative_numbers = true, default_value_t = 700, value_parser = clap::value_parser!(u64).range(1..=10_000_000))]
    trees: u64,
}

#[derive(Subcommand, Debug)]
pub enum SceneCommand {
    /// Write a deterministic procedural scene (OBJ templates, instance tables, scene YAML).
    Generate(GenerateArgs),
}

#[derive(Args, Debug)]
pub struct GenerateArgs {
    /// What to generate.
    #[arg(value_enum, ignore_case = true)]
    kind: SceneKind,
    /// Seed of every random draw: the same seed, the same files.
    #[arg(long, allow_negative_numbers = true, default_value_t = 1)]
    seed: u64,
    /// Output folder (the scene file is OUT/scene.yaml or similar, printed at the end).
    #[arg(long)]
    out: PathBuf,
    /// Trees (forest, orchard, town).
    #[arg(long, allow_negative_numbers = true)]
    trees: Option<usize>,
    /// Leaf area index to aim for (forest, orchard, town).
    #[arg(long, allow_negative_numbers = true)]
    lai: Option<f64>,
    /// Scene size in metres, `X` or `X,Y`.
    #[arg(long, allow_negative_numbers = true, value_delimiter = ',')]
    size: Option<Vec<f64>>,
    /// Distinct tree templates.
    #[arg(long, allow_negative_numbers = true)]
    templates: Option<usize>,
    /// Leaves per template.
    #[arg(long, allow_negative_numbers = true)]
    leaves: Option<usize>,
}

/// Why this build cannot run on this CPU, if it cannot: `.cargo/config.toml` builds for
/// x86-64-v3, and a CPU without its instructions would otherwise stop on the first one it
/// meets, with no message.
pub fn unsupported_cpu() -> Option<String> {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        let lacks = |f: bool, name: &str| (!f).then(|| name.to_string());
        let missing: Vec<String> = [
            lacks(std::arch::is_x86_feature_detected!("avx2"), "avx2"),
            lacks(std::arch::is_x86_feature_detected!("bmi2"), "bmi2"),
            lacks(std::arch::is_x86_feature_detected!("fma"), "fma"),
            lacks(std::arch::is_x86_feature_detected!("lzcnt"), "lzcnt"),
        ]
        .into_iter()
        .flatten()
        .collect();
        if !missing.is_empty() {
            return Some(format!(
                "this lidarsim was built for x86-64-v3 CPUs and this CPU lacks {}: rebuild it with RUSTFLAGS=\"-C target-cpu=native\" cargo build --release",
                missing.join(", ")
            ));
        }
    }
    None
}

/// Parses the arguments and runs the command; returns the process exit code.
pub fn main() -> i32 {
    main_with(std::env::args_os())
}

/// [`main`] with the arguments given (the first is the program's name): the Python
/// package's `lidarsim` command calls it with its own.
pub fn main_with<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    if let Some(why) = unsupported_cpu() {
        crate::progress::tell(&format!("error: {why}"));
        return 1;
    }
    crate::progress::tune_allocator();
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) if e.use_stderr() => {
            crate::progress::tell(&one_line(&e.render().to_string()));
            return 1;
        }
        Err(e) => {
            // --help and --version
            let _ = e.print();
            return 0;
        }
    };
    let done = match cli.command {
        Command::Run(args) => run(args),
        Command::Check { campaign } => check::check(&campaign),
        Command::Compare(args) => compare(args),
        Command::Scene {
            command: SceneCommand::Generate(args),
        } => generate(args),
        Command::Bench(args) => bench(args),
    };
    match done {
        Ok(()) => 0,
        Err(e) => {
            crate::progress::tell(&format!("error: {e}"));
            1
        }
    }
}

/// clap's message about a bad flag as one line: its paragraph up to the first blank line
/// (the usage and tips after it are what `--help` prints).
fn one_line(rendered: &str) -> String {
    let head: Vec<&str> = rendered
        .lines()
        .take_while(|l| !l.trim().is_empty())
        .map(str::trim)
        .collect();
    format!("{} (see --help)", head.join(" "))
}

fn run(args: RunArgs) -> Result<()> {
    require_file(&args.campaign)?;
    crate::interrupt::install();
    let shard = args.shard.map(|s| parse_shard(&s)).transpose()?;
    let opts = RunOptions {
        out: args.out,
        threads: args.threads,
        resume: args.resume,
        stages: args.stages,
        shard,
    };
    let s = pipeline::run(&args.campaign, &opts)?;
    let state = if s.complete {
        "complete"
    } else {
        "incomplete: run again with --resume"
    };
    let peak = crate::progress::peak_rss_bytes()
        .map(|b| format!(", peak memory {:.0} MB", b as f64 / 1e6))
        .unwrap_or_default();
    // the files are the run's result: a summary that cannot be shown fails nothing
    let _ = crate::progress::say(&format!(
        "wrote {} ({} pulses, {} rays, {} parts simulated, {:.2} s{peak}, {state})\n",
        s.out.display(),
        s.pulses,
        s.rays,
        s.parts_done,
        s.seconds
    ));
    Ok(())
}

fn compare(args: CompareArgs) -> Result<()> {
    use crate::compare;
    // a file a run compared wrote (its manifest) is no place for the table
    const RUN_FILES: [&str; 10] = [
        "manifest.json",
        "sweep.json",
        "sweep.csv",
        "report.md",
        "products.json",
        "campaign.resolved.yaml",
        "pulses.parquet",
        "points.las",
        "points.laz",
        "photons.parquet",
    ];
    let inside_runs = |flag: &str, out: &std::path::Path| -> Result<()> {
        let name = out.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let listed = RUN_FILES.contains(&name)
            || out
                .components()
                .any(|c| c.as_os_str() == "waveforms" || c.as_os_str() == "dsm");
        if !out.exists() || !listed {
            return Ok(());
        }
        let parent = out.parent().filter(|p| !p.as_os_str().is_empty());
        let dir = std::fs::canonicalize(parent.unwrap_or(std::path::Path::new(".")));
        let Ok(dir) = dir else { return Ok(()) };
        let whole = dir.join(out.file_name().unwrap_or_default());
        for run in &args.runs {
            if let Ok(run) = std::fs::canonicalize(run) {
                if whole.starts_with(&run) {
                    return Err(Error::msg(format!(
                        "{flag} {}: is a file of the run folder {} compared: write the table elsewhere",
                        out.display(),
                        run.display()
                    )));
                }
            }
        }
        Ok(())
    };
    if let Some(path) = &args.csv {
        inside_runs("--csv", path)?;
    }
    let rows = compare::rows(&args.runs)?;
    crate::progress::say(&compare::markdown(&rows))?;
    if let Some(path) = args.csv {
        compare::write_csv(&path, &rows)?;
    }
    if let Some(dir) = args.plots {
        let written = compare::plots(&rows, &dir)?;
        for p in &written {
            crate::progress::tell(&format!("wrote {}", p.display()));
        }
        if written.is_empty() {
            crate::progress::tell(&format!(
                "no plot written to {}: a plot needs two runs or more with a DSM error and their altitudes or pulse rates",
                dir.display()
            ));
        }
    }
    Ok(())
}

fn generate(args: GenerateArgs) -> Result<()> {
    let size_m = match args.size.as_deref() {
        None => None,
        Some([x]) => Some([*x, *x]),
        Some([x, y]) => Some([*x, *y]),
        Some(_) => return Err(Error::msg("--size: give X or X,Y in metres")),
    };
    let opts = GenerateOptions {
        trees: args.trees,
        lai: args.lai,
        size_m,
        templates: args.templates,
        leaves: args.leaves,
        ..GenerateOptions::default()
    };
    let s = generate_with_summary(args.kind, args.seed, &args.out, &opts)?;
    crate::progress::say(&format!(
        "wrote {} ({} trees, {} templates, {} facets instanced, {} distinct, LAI {:.2}, {:.1} MB)\n",
        s.scene.display(),
        s.trees,
        s.templates.len(),
        s.facets,
        s.distinct_facets,
        // a scene without leaves: 0, not -0
        s.lai + 0.0,
        s.bytes as f64 / 1e6
    ))
}

fn bench(args: BenchArgs) -> Result<()> {
    let mut opts = if args.full {
        bench::BenchOptions::full(args.out)
    } else {
        bench::BenchOptions::quick(args.out)
    };
    if let Some(r) = args.reference_rays {
        opts.reference_rays = r;
    }
    if let Some(s) = args.seeds {
        opts.seeds = s;
    }
    // the field of view is a half angle: it must open and stay below a hemisphere
    let fov = args.fov_mrad;
    if !(fov.is_finite() && fov > 0.0 && fov < 1500.0) {
        return Err(Error::msg(format!(
            "--fov-mrad {fov}: expected a half angle in mrad with 0 < x < 1500, e.g. 0.3"
        )));
    }
    // what would fail only at the bench's end, minutes later, fails now
    if !args.no_campaigns && !args.campaigns.join("quick.yaml").is_file() {
        return Err(Error::msg(format!(
            "--campaigns {}: not the bench's campaign folder (it holds quick.yaml and a file per \
             campaign row: pipelines/bench in the repository; run the bench from its root, or \
             name the folder)",
            args.campaigns.display()
        )));
    }
    // a RAMI scene named on the command line is meant to be there: only the default's
    // absence (a checkout without ../shared/) skips its rows
    if let Some(rami) = &args.rami {
        if let Err(why) = bench::campaigns::find_rami(rami) {
            return Err(Error::msg(format!("--rami {}: {why}", rami.display())));
        }
    }
    if args.report.is_dir() {
        return Err(Error::msg(format!(
            "--report {}: is a folder; name the report's file, e.g. docs/benchmarks.md",
            args.report.display()
        )));
    }
    let parent = args
        .report
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    if !parent.is_dir() {
        return Err(Error::msg(format!(
            "--report {}: its folder {} does not exist",
            args.report.display(),
            parent.display()
        )));
    }
    // a folder the report cannot be written to: its temporary file made and removed now
    drop(crate::fsutil::Pending::create(&args.report)?);
    opts.rami_scene = args
        .rami
        .unwrap_or_else(|| PathBuf::from("scenes/rami_wco.yaml"));
    opts.campaigns = !args.no_campaigns;
    // each campaign row in a process of its own, as a user runs it (in this one where the
    // executable cannot be found)
    opts.runner = std::env::current_exe().ok();
    opts.campaigns_dir = args.campaigns;
    opts.fov_mrad = fov;
    opts.canopy.trees = usize::try_from(args.trees)
        .map_err(|_| Error::msg(format!("--trees {}: too many", args.trees)))?;
    let text = pipeline::with_threads(args.threads, || bench::run(&opts))?;
    let path = bench::write_report(&args.report, &text)?;
    crate::progress::say(&format!("{text}\n(written to {})\n", path.display()))?;
    Ok(())
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
    pipeline::check_shard((k, n)).map_err(|_| bad())
}

pub(crate) fn require_file(path: &std::path::Path) -> Result<()> {
    if path.is_file() {
        Ok(())
    } else {
        Err(crate::campaign::missing_campaign(path))
    }
}
