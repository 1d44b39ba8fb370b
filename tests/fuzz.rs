//! Mutation fuzzing of every loader through `lidarsim check`, bounded so the suite stays quick
//! (`LIDARSIM_FUZZ_CASES` sets the count; `tools/fuzz_loaders.sh` runs a longer one).
//!
//! Each case mutates one file of a valid campaign (campaign YAML with a sweep, scene YAML, a
//! heightfield, an OBJ, an instance table, an ASCII and a binary PLY, a second campaign flying a
//! trajectory CSV with a mount and navigation errors) by byte flips, cuts,
//! copies and hostile tokens, deterministically from a seed. What must hold: exit code 0 or 1,
//! never a panic ("internal error"), and a rejection is exactly one `error:` line.

mod common;
use common::*;
use lidarsim::rng::SplitMix64;
use std::path::Path;
use std::process::Command;

const CAMPAIGN: &str = "name: f
scene: scene.yaml
seed: 1
wavelength_nm: 1064
instrument:
  kind: discrete_return
  pulse_energy_j: 0.001
  pulse_fwhm_ns: 3
  footprint_half_angle_mrad: 0.25
  fov_half_angle_mrad: 0.375
  receiver_area_m2: 0.1
  bin_ns: 0.5
  bandwidth_nm: 1.0
  range_gate: { start_ns: 0, bins: 2000 }
  noise: { electronic_sd_photons: 0.5 }
  detector_response_fwhm_ns: 1.5
  digitiser: { gain: 4, offset: 10, bits: 12, saturation: 4000 }
  receiver_offset_m: [0.0, 0.3, 0.0]
platform:
  kind: als
  altitude_m: 100
  speed_m_s: 50
  prf_hz: 1000
  lines: [ { start: [0, 5], end: [10, 5] } ]
  scanner: { pattern: oscillating, scan_angle_deg: [-10, 10], scan_frequency_hz: 20 }
simulation: { method: bdpt, rays_per_pulse: 10, max_order: 3 }
sun: { zenith_deg: 30, azimuth_deg: 0, irradiance_w_m2_um: 600 }
atmosphere:
  layers:
    - { scale_height_m: 8000, optical_depth: { 532: 0.12, 1064: 0.008 } }
    - { scale_height_m: 1500, optical_depth: 0.1 }
frame: { crs: EPSG:32631, origin: [500000.0, 4800000.0, 120.0] }
products: { points: true, points_format: laz, dsm: { resolution_m: 2 } }
sweep:
  platform.altitude_m: [100, 200]
";

const SCENE: &str = "name: s
repeat: true
materials:
  soil: { reflectance: { 1064: 0.3, 532: 0.1 } }
  leaf: { reflectance: 0.4, transmittance: 0.4 }
objects:
  - plane: { z: 0, extent: [[0, 0], [10, 10]], material: soil }
  - heightfield: { file: dem.csv, cell_m: 2, origin: [0, 0], material: soil }
  - mesh: { file: tree.obj, materials: { leaves: leaf }, instances: trees.csv }
  - mesh: { file: roof.ply, material: soil, class: building }
  - mesh: { file: bin.ply, material: soil }
";

/// A second campaign flying a recorded trajectory with a mount and navigation errors: its
/// file and the trajectory's CSV are mutated and checked through it.
const TRAJECTORY_CAMPAIGN: &str = "name: t
scene: scene.yaml
seed: 1
wavelength_nm: 1064
instrument: { kind: discrete_return, pulse_energy_j: 0.001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.25, fov_half_angle_mrad: 0.375, receiver_area_m2: 0.1, bin_ns: 0.5 }
platform:
  kind: als
  prf_hz: 1000
  trajectory: { file: trajectory.csv, scan: [[1000.0, 1000.2], [1000.3, 1000.4]] }
  mount: { offset_m: [0.1, 0, -0.2], boresight_deg: [0.1, 0, 0] }
  errors: { position_sd_m: [0.03, 0.03, 0.05], position_correlation_s: 1, attitude_sd_deg: [0.003, 0.003, 0.008], boresight_deg: [0.01, 0, 0] }
  scanner: { pattern: oscillating, scan_angle_deg: [-10, 10], scan_frequency_hz: 20 }
simulation: { method: forward, rays_per_pulse: 10, max_order: auto }
";

fn binary_ply() -> Vec<u8> {
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for v in [[0f32, 0.0, 6.0], [1.0, 0.0, 6.0], [1.0, 1.0, 6.0]] {
        for c in v {
            b.extend_from_slice(&c.to_le_bytes());
        }
    }
    b.push(3);
    for i in [0i32, 1, 2] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

fn files() -> Vec<(&'static str, Vec<u8>)> {
    vec![
        ("campaign.yaml", CAMPAIGN.into()),
        ("scene.yaml", SCENE.into()),
        ("dem.csv", b"# z\n1,2,3\n2,3,4\n3,4,5\n".to_vec()),
        ("tree.obj", b"g leaves\nv 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 2\nf 1 2 3\nf 2 4 3\n".to_vec()),
        ("trees.csv", b"# x y z rotation scale\n1 2 0 0 1\n3, 4, 0, 90, 1.5\n".to_vec()),
        ("roof.ply", b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 5\n1 0 5\n1 1 5\n0 1 5\n3 0 1 2\n3 0 2 3\n".to_vec()),
        ("bin.ply", binary_ply()),
        ("traj.yaml", TRAJECTORY_CAMPAIGN.into()),
        ("trajectory.csv", b"time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n1000.0,0,5,100,0,0,90\n1000.25,5,5,100,1.5,0.5,91\n1000.5,10,5,101,0,0,92\n".to_vec()),
    ]
}

const TOKENS: &[&[u8]] = &[
    b"-1",
    b"0",
    b"1e308",
    b"nan",
    b"inf",
    b"-inf",
    b"",
    b"[",
    b"]",
    b"{",
    b"}",
    b":",
    b",",
    b"\n",
    b"  ",
    b"\t",
    b"\"",
    b"'",
    b"#",
    b"99999999999999999999",
    b"4294967296",
    b"-0",
    b"1e-320",
    b"null",
    b"~",
    b"[[]]",
    b"{a: b}",
    b"\x00",
    b"\xff\xfe",
    b"f 1 2 99",
    b"v 1 2",
    b"3 0 1 9",
    b"element vertex 100000000000\n",
];

fn below(r: &mut SplitMix64, n: usize) -> usize {
    (r.uniform() * n as f64) as usize % n.max(1)
}

/// One to four edits: a byte replaced, a run cut, a token put in, a run copied elsewhere, or a
/// number replaced by a token.
fn mutate(r: &mut SplitMix64, data: &[u8]) -> Vec<u8> {
    let mut d = data.to_vec();
    for _ in 0..1 + below(r, 4) {
        if d.is_empty() {
            d.push(b' ');
        }
        let i = below(r, d.len());
        match below(r, 5) {
            0 => d[i] = below(r, 256) as u8,
            1 => {
                let end = (i + 1 + below(r, 8)).min(d.len());
                d.drain(i..end);
            }
            2 => {
                let t = TOKENS[below(r, TOKENS.len())];
                d.splice(i..i, t.iter().copied());
            }
            3 => {
                let j = below(r, d.len());
                let run: Vec<u8> = d[j..(j + 1 + below(r, 20)).min(d.len())].to_vec();
                d.splice(i..i, run);
            }
            _ => {
                let mut j = i;
                while j < d.len() && b"0123456789.-e".contains(&d[j]) {
                    j += 1;
                }
                let t = TOKENS[below(r, TOKENS.len())];
                d.splice(i..j, t.iter().copied());
            }
        }
    }
    d
}

#[test]
fn mutated_inputs_never_panic_and_fail_with_one_line() {
    let env = |name: &str| -> Option<u64> { std::env::var(name).ok()?.parse().ok() };
    // LIDARSIM_FUZZ_SECONDS runs for that long instead of a number of cases
    let seconds = env("LIDARSIM_FUZZ_SECONDS");
    let cases = match seconds {
        Some(_) => usize::MAX,
        None => env("LIDARSIM_FUZZ_CASES").unwrap_or(400) as usize,
    };
    let start = std::time::Instant::now();
    let dir = tmp("fuzz_loaders");
    let base = files();
    // the unmutated files are a valid campaign: every rejection below is the mutation's
    let whole = dir.join("base");
    std::fs::create_dir_all(&whole).unwrap();
    for (name, bytes) in &base {
        std::fs::write(whole.join(name), bytes).unwrap();
    }
    for campaign in ["campaign.yaml", "traj.yaml"] {
        let o = Command::new(env!("CARGO_BIN_EXE_lidarsim"))
            .args(["check", whole.join(campaign).to_str().unwrap()])
            .output()
            .unwrap();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{campaign}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let mut r = SplitMix64::new(2026);
    let mut rejected = 0;
    let mut tried = vec![0usize; base.len()];
    let mut findings: Vec<String> = Vec::new();
    let mut cases_run = 0;
    for case in 0..cases {
        if seconds.is_some_and(|s| start.elapsed().as_secs() >= s) {
            break;
        }
        cases_run += 1;
        let d = dir.join(format!("case{}", case % 4));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let target = below(&mut r, base.len());
        tried[target] += 1;
        for (k, (name, bytes)) in base.iter().enumerate() {
            let data = if k == target {
                mutate(&mut r, bytes)
            } else {
                bytes.clone()
            };
            std::fs::write(d.join(name), data).unwrap();
        }
        // the trajectory's files are read through their own campaign
        let checked = match base[target].0 {
            "traj.yaml" | "trajectory.csv" => "traj.yaml",
            _ => "campaign.yaml",
        };
        let o = Command::new(env!("CARGO_BIN_EXE_lidarsim"))
            .args(["check", d.join(checked).to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        let errors = err.lines().filter(|l| l.starts_with("error:")).count();
        let code = o.status.code();
        let bad = !matches!(code, Some(0) | Some(1))
            || err.contains("internal error")
            || (code == Some(1) && errors != 1);
        if code == Some(1) {
            rejected += 1;
        }
        if bad {
            let keep = dir.join(format!("finding{}", findings.len()));
            let _ = std::fs::remove_dir_all(&keep);
            copy_dir(&d, &keep);
            findings.push(format!(
                "case {case} ({}): exit {code:?}: {} (kept in {})",
                base[target].0,
                err.trim(),
                keep.display()
            ));
        }
    }
    let per_file: Vec<String> = base
        .iter()
        .zip(&tried)
        .map(|((name, _), n)| format!("{name} {n}"))
        .collect();
    eprintln!(
        "fuzz: {cases_run} cases in {:.0} s ({}), {rejected} rejected, {} findings",
        start.elapsed().as_secs_f64(),
        per_file.join(", "),
        findings.len()
    );
    // the mutations must reach the loaders' error paths, not only pass through
    assert!(
        rejected * 4 >= cases_run,
        "only {rejected} of {cases_run} cases rejected"
    );
    if !findings.is_empty() {
        // the findings are for a person to look at: their folder outlives the test
        std::mem::forget(dir);
        panic!("{findings:#?}");
    }
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}
