//! Same seed, same output, whatever the number of threads.

mod common;
use common::*;

#[test]
fn output_files_do_not_depend_on_thread_count() {
    let dir = tmp("determinism");
    let scene = sphere_scene(&dir, 0.7);
    let inst = Inst {
        fp_mrad: 100.0,
        fov_mrad: 300.0,
        area: 0.01,
        fwhm_ns: 3.0,
        ..Inst::default()
    };
    let text = campaign(
        &scene,
        &inst,
        [0.0, 0.0, 0.0],
        [0.0, 0.0, -1.0],
        "forward",
        50_000,
        30,
    );
    // a noisy, digitised record in waveforms_l1b.h5: its draws too are per (seed, pulse)
    let text = text.replace(
        "  bin_ns: 1\n",
        "  bin_ns: 1\n  noise: { electronic_sd_photons: 1 }\n  digitiser: { gain: 3, offset: 10, bits: 12 }\n",
    );
    assert!(text.contains("noise:"), "{text}");
    let camp = write(&dir, "campaign.yaml", &text);
    let (mut parts, mut l1b) = (Vec::new(), Vec::new());
    for threads in ["1", "2"] {
        let out = dir.join(format!("run{threads}"));
        let (code, _, err) = lidarsim(&[
            "run",
            camp.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--threads",
            threads,
        ]);
        assert_eq!(code, 0, "{err}");
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
    let other = text.replace("seed: 3", "seed: 4");
    let camp = write(&dir, "campaign.yaml", &other);
    let out = dir.join("run_seed4");
    let (code, _, err) = lidarsim(&[
        "run",
        camp.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_ne!(
        std::fs::read(out.join("waveforms/part-00000.parquet")).unwrap(),
        parts[0]
    );
}
