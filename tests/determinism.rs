//! Same seed, same output, whatever the number of threads.

mod common;
use common::*;
use std::path::{Path, PathBuf};

/// A campaign of one pulse from inside the diffuse sphere (albedo 0.7), wide beam and view.
fn sphere_campaign(dir: &Path, method: &str, rays: u64, max_order: u32) -> String {
    let scene = sphere_scene(dir, 0.7);
    let inst = Inst {
        fp_mrad: 100.0,
        fov_mrad: 300.0,
        area: 0.01,
        fwhm_ns: 3.0,
        ..Inst::default()
    };
    campaign(
        &scene,
        &inst,
        [0.0, 0.0, 0.0],
        [0.0, 0.0, -1.0],
        method,
        rays,
        max_order,
    )
}

/// Runs the campaign text through the binary into `dir/run<label>`, with `--threads` when
/// given; returns that folder.
fn run_with(dir: &Path, text: &str, label: &str, threads: Option<&str>) -> PathBuf {
    let camp = write(dir, "campaign.yaml", text);
    let out = dir.join(format!("run{label}"));
    let mut args = vec![
        "run",
        camp.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    if let Some(t) = threads {
        args.extend(["--threads", t]);
    }
    let (code, _, err) = lidarsim(&args);
    assert_eq!(code, 0, "{err}");
    out
}

#[test]
fn output_files_do_not_depend_on_thread_count() {
    let dir = tmp("determinism");
    let text = sphere_campaign(&dir, "forward", 50_000, 30);
    // a noisy, digitised record in waveforms_l1b.h5: its draws too are per (seed, pulse)
    let text = text.replace(
        "  bin_ns: 1\n",
        "  bin_ns: 1\n  noise: { electronic_sd_photons: 1 }\n  digitiser: { gain: 3, offset: 10, bits: 12 }\n",
    );
    assert!(text.contains("noise:"), "{text}");
    let (mut parts, mut l1b) = (Vec::new(), Vec::new());
    for threads in ["1", "2"] {
        let out = run_with(&dir, &text, threads, Some(threads));
        parts.push(std::fs::read(out.join("waveforms/part-00000.parquet")).unwrap());
        l1b.push(std::fs::read(out.join("waveforms_l1b.h5")).unwrap());
        assert!(
            out.join("pulses.parquet").is_file() && out.join("campaign.resolved.yaml").is_file()
        );
    }
    assert_eq!(
        parts[0], parts[1],
        "waveform files differ between 1 and 2 threads"
    );
    assert!(
        l1b[0] == l1b[1],
        "waveforms_l1b.h5 differs between 1 and 2 threads"
    );
    // a different seed gives a different estimate
    let out = run_with(&dir, &text.replace("seed: 3", "seed: 4"), "_seed4", None);
    assert_ne!(
        std::fs::read(out.join("waveforms/part-00000.parquet")).unwrap(),
        parts[0]
    );
}

/// The same with `sampler: sobol`, whose pulses are split into chunks of 256 rays: a bdpt
/// pulse of 5000 rays (20 chunks) on 1 and 2 threads.
#[test]
fn sobol_files_do_not_depend_on_thread_count() {
    let dir = tmp("determinism_sobol");
    let one = sphere_campaign(&dir, "bdpt", 5000, 10);
    let text = with_sampler(&one, "sobol");
    let part = |out: PathBuf| std::fs::read(out.join("waveforms/part-00000.parquet")).unwrap();
    let parts: Vec<Vec<u8>> = ["1", "2"]
        .map(|t| part(run_with(&dir, &text, t, Some(t))))
        .into();
    assert_eq!(
        parts[0], parts[1],
        "sobol waveforms differ between 1 and 2 threads"
    );
    // and they are not independent draws' waveforms
    assert_ne!(part(run_with(&dir, &one, "_independent", None)), parts[0]);
}
