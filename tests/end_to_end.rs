//! End to end through the `lidarsim` binary, on scenes small enough to run in seconds: every
//! platform kind and scan pattern, heightfield and binary PLY scenes, photon counting,
//! `compare`, sweeps, generated scenes, staged runs, a fixed range gate, and resume over
//! damaged or foreign part files. Each test checks file contents, not only exit codes.

// indices are pulse ids here: a loop over them reads as the plan does
#![allow(clippy::needless_range_loop)]

mod common;
use common::*;

use arrow_array::cast::AsArray;
use arrow_array::types::{
    ArrowPrimitiveType, Float32Type, Float64Type, UInt32Type, UInt64Type, UInt8Type,
};
use arrow_array::RecordBatch;
use arrow_schema::{DataType, SchemaRef};
use lidarsim::waveform::file::read_waveforms;
use lidarsim::waveform::Waveform;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------------
// helpers

/// `lidarsim run CAMPAIGN --out OUT EXTRA...`, which must succeed; returns stdout then stderr.
fn run_ok(campaign: &Path, out: &Path, extra: &[&str]) -> String {
    let (c, o) = (campaign.to_str().unwrap(), out.to_str().unwrap());
    let mut args = vec!["run", c, "--out", o];
    args.extend_from_slice(extra);
    let (code, stdout, stderr) = lidarsim(&args);
    assert_eq!(code, 0, "lidarsim {args:?} failed:\n{stderr}");
    // a figure with no meaning for the run (a DSM group of no cells) is "–", never NaN
    assert!(!stderr.contains("NaN"), "{stderr}");
    format!("{stdout}{stderr}")
}

/// The pulse count of the run summary `wrote DIR (N pulses, ...)`.
fn summary_pulses(log: &str) -> usize {
    let line = log
        .lines()
        .find(|l| l.starts_with("wrote "))
        .unwrap_or_else(|| panic!("no run summary in:\n{log}"));
    let after = &line[line.rfind('(').expect("the summary has a parenthesis") + 1..];
    after
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap_or_else(|e| panic!("{line}: {e}"))
}

/// A Parquet file's schema and record batches.
fn read_table(path: &Path) -> (SchemaRef, Vec<RecordBatch>) {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let builder = ParquetRecordBatchReaderBuilder::try_new(file)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let schema = builder.schema().clone();
    let batches = builder
        .build()
        .unwrap()
        .map(|b| b.unwrap_or_else(|e| panic!("{}: {e}", path.display())))
        .collect();
    (schema, batches)
}

/// One primitive column over every batch.
fn column<T: ArrowPrimitiveType>(batches: &[RecordBatch], name: &str) -> Vec<T::Native> {
    batches
        .iter()
        .flat_map(|b| {
            b.column_by_name(name)
                .unwrap_or_else(|| panic!("no column {name}"))
                .as_primitive::<T>()
                .values()
                .to_vec()
        })
        .collect()
}

/// `pulses.parquet` of a run folder (outputs.md).
struct Pulses {
    id: Vec<u64>,
    gps: Vec<f64>,
    origin: Vec<[f64; 3]>,
    dir: Vec<[f64; 3]>,
    scan_angle: Vec<f32>,
    line: Vec<u32>,
}

fn read_pulses(out: &Path) -> Pulses {
    let (_, b) = read_table(&out.join("pulses.parquet"));
    let f = |n: &str| column::<Float64Type>(&b, n);
    let xyz = |x: Vec<f64>, y: Vec<f64>, z: Vec<f64>| -> Vec<[f64; 3]> {
        x.iter()
            .zip(&y)
            .zip(&z)
            .map(|((a, c), d)| [*a, *c, *d])
            .collect()
    };
    Pulses {
        id: column::<UInt64Type>(&b, "pulse_id"),
        gps: f("gps_time_s"),
        origin: xyz(f("origin_x"), f("origin_y"), f("origin_z")),
        dir: xyz(f("dir_x"), f("dir_y"), f("dir_z")),
        scan_angle: column::<Float32Type>(&b, "scan_angle_deg"),
        line: column::<UInt32Type>(&b, "line"),
    }
}

/// The waveforms of a run folder with a single part.
fn waveforms(out: &Path) -> Vec<Waveform> {
    read_waveforms(&out.join("waveforms/part-00000.parquet")).unwrap_or_else(|e| panic!("{e}"))
}

/// Energy-weighted mean time of the impulse waveform, ns after emission.
fn return_time_ns(w: &Waveform) -> f64 {
    let total: f64 = w.impulse_energy_j.iter().map(|&e| e as f64).sum();
    assert!(total > 0.0, "pulse {}: no energy in the gate", w.pulse_id);
    w.impulse_energy_j
        .iter()
        .enumerate()
        .map(|(i, &e)| e as f64 * (w.t0_ns + (i as f64 + 0.5) * w.bin_ns as f64))
        .sum::<f64>()
        / total
}

/// Round trip time of a range, ns.
fn two_way_ns(range_m: f64) -> f64 {
    2.0 * range_m / C * 1e9
}

fn class_sum(w: &Waveform, class: usize) -> f64 {
    w.class_energy_j[class].iter().map(|&e| e as f64).sum()
}

fn close3(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
    (0..3).all(|i| (a[i] - b[i]).abs() <= tol)
}

fn manifest(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap()
}

/// A discrete-return profiler over a plane: 10 nadir pulses from 100 m, one part.
fn small_track(dir: &Path) -> PathBuf {
    plane_scene(dir, 0.3, 30.0);
    write(
        dir,
        "campaign.yaml",
        "name: small\nscene: plane.yaml\nseed: 8\nwavelength_nm: 1064\ninstrument: { kind: discrete_return, pulse_energy_j: 0.00001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1 }\nplatform: { kind: track, altitude_m: 100, track: { start: [0, 0], end: [10, 0] }, along_track_step_m: 1 }\nsimulation: { method: forward, rays_per_pulse: 50, max_order: 1 }\nproducts: { points: true }\n",
    )
}

/// The files two equal runs share byte for byte: the plan, products.json, the points (where
/// there are) and every waveform part (`part-*.parquet` only), by name.
fn run_files(out: &Path) -> Vec<(String, Vec<u8>)> {
    let mut names: Vec<String> = vec!["pulses.parquet".into(), "products.json".into()];
    // a waveform instrument makes no points
    if out.join("points.las").exists() {
        names.push("points.las".into());
    }
    let mut parts: Vec<String> = std::fs::read_dir(out.join("waveforms"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("part-") && n.ends_with(".parquet"))
        .collect();
    parts.sort();
    assert!(!parts.is_empty(), "{}: no waveform part", out.display());
    names.extend(parts.into_iter().map(|n| format!("waveforms/{n}")));
    names
        .into_iter()
        .map(|n| {
            let p = out.join(&n);
            let bytes = std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            (n, bytes)
        })
        .collect()
}

fn assert_same_files(a: &Path, b: &Path) {
    let (fa, fb) = (run_files(a), run_files(b));
    assert_eq!(
        fa.iter().map(|x| &x.0).collect::<Vec<_>>(),
        fb.iter().map(|x| &x.0).collect::<Vec<_>>()
    );
    for ((name, x), (_, y)) in fa.iter().zip(&fb) {
        assert!(
            x == y,
            "{name} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
}

// ---------------------------------------------------------------------------------------------
// platforms

/// A terrestrial scan from 1.5 m above a plane: a full turn of azimuth at 90° (360° is not
/// repeated: 4 azimuths) × zenith 120°..180° at 20° (both ends: 4) = 16 pulses, azimuth-major,
/// each aimed as `direction_from_angles` says, and each return at the slant range
/// 1.5 m / cos(180° − zenith).
#[test]
fn tls_scan_plans_its_grid_and_returns_at_the_slant_ranges() {
    let dir = tmp("e2e_tls");
    plane_scene(&dir, 0.5, 50.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: tls\nscene: plane.yaml\nseed: 1\nwavelength_nm: 1064\ninstrument: { pulse_energy_j: 0.001, pulse_fwhm_ns: 0, footprint_half_angle_mrad: 5, fov_half_angle_mrad: 30, receiver_area_m2: 0.001, bin_ns: 0.25 }\nplatform: { kind: tls, position: [0, 0, 1.5], azimuth_deg: [0, 360], azimuth_step_deg: 90, zenith_deg: [120, 180], zenith_step_deg: 20 }\nsimulation: { method: forward, rays_per_pulse: 200, max_order: 1 }\n",
    );
    let out = dir.join("run");
    let log = run_ok(&camp, &out, &[]);
    assert_eq!(summary_pulses(&log), 16, "{log}");
    let p = read_pulses(&out);
    assert_eq!(p.id, (0..16).collect::<Vec<u64>>());
    let w = waveforms(&out);
    assert_eq!(w.len(), 16);
    for k in 0..16 {
        let az = (k / 4) as f64 * 90.0;
        let ze = 120.0 + (k % 4) as f64 * 20.0;
        let (zr, ar) = (ze.to_radians(), az.to_radians());
        let want = [zr.sin() * ar.cos(), zr.sin() * ar.sin(), zr.cos()];
        assert!(
            close3(p.dir[k], want, 1e-9),
            "pulse {k}: {:?} vs {want:?}",
            p.dir[k]
        );
        assert_eq!(p.origin[k], [0.0, 0.0, 1.5]);
        assert!(
            (p.scan_angle[k] as f64 - ze).abs() < 1e-4,
            "scan angle = zenith"
        );
        assert_eq!(p.line[k], 0);
        // no prf_hz: the default 1000 Hz orders the pulses in time
        assert!((p.gps[k] - k as f64 / 1000.0).abs() < 1e-12);
        assert_eq!(w[k].pulse_id, k as u64);
        let range = 1.5 / -want[2];
        let t = return_time_ns(&w[k]);
        assert!(
            (t - two_way_ns(range)).abs() < 0.5,
            "pulse {k} (zenith {ze}°): return at {t} ns, slant range {range} m gives {} ns",
            two_way_ns(range)
        );
    }
}

/// ALS over a plane from 100 m with both non-line patterns.
/// Oscillating: 4 look angles of 5° from −10° (⌊20/5⌋) × 5 scan lines (⌊10 m / 2 m⌋) = 20
/// pulses, sweeping −10→5 on even scan lines and 10→−5 on odd ones, beams across track only
/// (flying +x, right is −y), each return at 100 m / cos θ.
/// Conic: 8 azimuths of 45° (⌊360/45⌋) × 2 scan lines = 16 pulses, all on the 10° cone
/// (same off-nadir angle, so the same range over the plane), turning from straight ahead to
/// the right.
#[test]
fn als_oscillating_and_conic_patterns_plan_and_return_as_specified() {
    let dir = tmp("e2e_als_patterns");
    plane_scene(&dir, 0.3, 60.0);
    let camp = |name: &str, scanner: &str| {
        write(
            &dir,
            &format!("{name}.yaml"),
            &format!(
                "name: {name}\nscene: plane.yaml\nseed: 2\nwavelength_nm: 1064\ninstrument: {{ pulse_energy_j: 0.001, pulse_fwhm_ns: 0, footprint_half_angle_mrad: 0.5, fov_half_angle_mrad: 1.5, receiver_area_m2: 0.01, bin_ns: 0.5 }}\nplatform: {{ kind: als, altitude_m: 100, speed_m_s: 50, lines: [ {{ start: [0, 0], end: [10, 0] }} ], scanner: {scanner} }}\nsimulation: {{ method: forward, rays_per_pulse: 100, max_order: 1 }}\n"
            ),
        )
    };

    // oscillating
    let osc = camp(
        "osc",
        "{ pattern: oscillating, scan_angle_deg: [-10, 10], look_angle_step_deg: 5, along_track_step_m: 2 }",
    );
    let out = dir.join("osc");
    let log = run_ok(&osc, &out, &[]);
    assert_eq!(summary_pulses(&log), 20, "{log}");
    let p = read_pulses(&out);
    let w = waveforms(&out);
    assert_eq!((p.id.len(), w.len()), (20, 20));
    for k in 0..20 {
        let (j, i) = (k / 4, k % 4);
        let theta: f64 = if j % 2 == 0 {
            -10.0 + 5.0 * i as f64
        } else {
            10.0 - 5.0 * i as f64
        };
        let (s, c) = theta.to_radians().sin_cos();
        assert!(
            (p.scan_angle[k] as f64 - theta).abs() < 1e-4,
            "pulse {k}: scan angle {} instead of {theta}",
            p.scan_angle[k]
        );
        assert!(
            close3(p.dir[k], [0.0, -s, -c], 1e-9),
            "pulse {k}: {:?}",
            p.dir[k]
        );
        // the platform moves on: scan line j, pulse i of 4 is at (j + i/4) · 2 m
        let x = (j as f64 + i as f64 / 4.0) * 2.0;
        assert!(
            close3(p.origin[k], [x, 0.0, 100.0], 1e-9),
            "{:?}",
            p.origin[k]
        );
        let t = return_time_ns(&w[k]);
        let want = two_way_ns(100.0 / c);
        assert!(
            (t - want).abs() < 0.5,
            "oscillating pulse {k} at {theta}°: {t} ns vs {want} ns"
        );
    }

    // conic
    let conic = camp(
        "conic",
        "{ pattern: conic, scan_angle_deg: [-10, 10], look_angle_step_deg: 45, along_track_step_m: 5 }",
    );
    let out = dir.join("conic");
    let log = run_ok(&conic, &out, &[]);
    assert_eq!(summary_pulses(&log), 16, "{log}");
    let p = read_pulses(&out);
    let w = waveforms(&out);
    assert_eq!((p.id.len(), w.len()), (16, 16));
    let (sc, cc) = 10f64.to_radians().sin_cos();
    let want_t = two_way_ns(100.0 / cc);
    let mut times = Vec::new();
    for k in 0..16 {
        let a = (45.0 * (k % 8) as f64).to_radians();
        assert!(
            (p.scan_angle[k] - 10.0).abs() < 1e-5,
            "conic: cone half-angle"
        );
        let off_nadir = (-p.dir[k][2]).acos().to_degrees();
        assert!((off_nadir - 10.0).abs() < 1e-9, "pulse {k}: {off_nadir}°");
        assert!(
            close3(p.dir[k], [a.cos() * sc, -a.sin() * sc, -cc], 1e-9),
            "pulse {k}: {:?}",
            p.dir[k]
        );
        let t = return_time_ns(&w[k]);
        assert!(
            (t - want_t).abs() < 0.5,
            "conic pulse {k}: {t} vs {want_t} ns"
        );
        times.push(t);
    }
    let spread = times.iter().cloned().fold(f64::MIN, f64::max)
        - times.iter().cloned().fold(f64::MAX, f64::min);
    assert!(
        spread < 0.5,
        "same off-nadir angle, same range: spread {spread} ns"
    );
}

/// A three-beam spaceborne track from 500 m: shots every 7000/700 = 10 m on 40 m, both ends
/// (5 shots), × 3 beams = 15 pulses, shot-major; beam b is `line` b, offset cross_track_m to
/// the right (−y when flying +x), all shots of a beam 1/700 s apart, every return at 500 m.
#[test]
fn spaceborne_multibeam_fires_every_beam_at_every_shot() {
    let dir = tmp("e2e_spaceborne_beams");
    plane_scene(&dir, 0.3, 60.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: beams\nscene: plane.yaml\nseed: 3\nwavelength_nm: 1064\ninstrument: { pulse_energy_j: 0.001, pulse_fwhm_ns: 0, footprint_half_angle_mrad: 0.05, fov_half_angle_mrad: 0.3, receiver_area_m2: 0.01, bin_ns: 0.5 }\nplatform: { kind: spaceborne, altitude_m: 500, ground_speed_m_s: 7000, prf_hz: 700, track: { start: [0, 0], end: [40, 0] }, beams: [ { cross_track_m: -20 }, { cross_track_m: 0 }, { cross_track_m: 20 } ] }\nsimulation: { method: forward, rays_per_pulse: 100, max_order: 1 }\n",
    );
    let out = dir.join("run");
    let log = run_ok(&camp, &out, &[]);
    let (beams, shots) = (3usize, 5usize);
    assert_eq!(summary_pulses(&log), beams * shots, "{log}");
    let p = read_pulses(&out);
    let w = waveforms(&out);
    assert_eq!((p.id.len(), w.len()), (15, 15));
    let cross = [-20.0, 0.0, 20.0];
    for k in 0..15 {
        let (shot, b) = (k / beams, k % beams);
        assert_eq!(p.line[k], b as u32, "pulse {k}: beam index");
        assert!(
            close3(p.origin[k], [10.0 * shot as f64, -cross[b], 500.0], 1e-9),
            "pulse {k}: {:?}",
            p.origin[k]
        );
        assert!(close3(p.dir[k], [0.0, 0.0, -1.0], 1e-12));
        assert!((p.gps[k] - shot as f64 / 700.0).abs() < 1e-12);
        let t = return_time_ns(&w[k]);
        assert!((t - two_way_ns(500.0)).abs() < 0.5, "pulse {k}: {t} ns");
    }
    // all three beams are distinct pulses with their own waveforms
    for b in 0..beams {
        assert_eq!(p.line.iter().filter(|&&l| l == b as u32).count(), shots);
    }
}

/// A beam's `relative_energy` scales its pulse: over a plane, the weak beam of a pair
/// (0.25) returns a quarter of the strong beam's photons, shot by shot, within 3 standard
/// errors of the shots' ratios (the Monte Carlo noise of each pulse's own rays).
#[test]
fn a_weak_beam_returns_a_quarter_of_the_strong_beams_light() {
    let dir = tmp("e2e_weak_beam");
    plane_scene(&dir, 0.3, 200.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: pair\nscene: plane.yaml\nseed: 3\nwavelength_nm: 532\ninstrument: { pulse_energy_j: 0.001, pulse_fwhm_ns: 1, footprint_half_angle_mrad: 0.05, fov_half_angle_mrad: 0.3, receiver_area_m2: 0.01, bin_ns: 0.5 }\nplatform: { kind: spaceborne, altitude_m: 500, ground_speed_m_s: 7000, prf_hz: 700, track: { start: [0, 0], end: [190, 0] }, beams: [ { cross_track_m: -45 }, { cross_track_m: 45, relative_energy: 0.25 } ] }\nsimulation: { method: forward, rays_per_pulse: 100, max_order: 1 }\n",
    );
    let out = dir.join("run");
    run_ok(&camp, &out, &[]);
    let w = waveforms(&out);
    let total = |k: usize| -> f64 { w[k].laser_photons.iter().map(|&v| v as f64).sum() };
    let ratios: Vec<f64> = (0..w.len() / 2)
        .map(|s| total(2 * s + 1) / total(2 * s))
        .collect();
    let n = ratios.len() as f64;
    assert_eq!(n, 20.0);
    let mean = ratios.iter().sum::<f64>() / n;
    let sd = (ratios.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let se = sd / n.sqrt();
    assert!(
        (mean - 0.25).abs() <= 3.0 * se + 1e-9,
        "weak over strong {mean} (SE {se:e})"
    );
}

// ---------------------------------------------------------------------------------------------
// scenes

/// A heightfield grid file (5 × 5 heights, 5 m cells from (−10, −10), z = 2 + 0.1 (x + 10)):
/// nadir pulses from 103 m at x = −5 and x = 5 return from z = 2.5 and 3.5, 6.67 ns apart,
/// and all the energy is labelled ground (a heightfield's default class).
#[test]
fn heightfield_scene_returns_at_its_heights() {
    let dir = tmp("e2e_heightfield");
    let row = "2, 2.5, 3, 3.5, 4\n";
    write(
        &dir,
        "dem.csv",
        &format!("# z by column\n{}", row.repeat(5)),
    );
    write(
        &dir,
        "scene.yaml",
        "name: hf\nmaterials:\n  soil: { reflectance: 0.3 }\nobjects:\n  - heightfield: { file: dem.csv, cell_m: 5, origin: [-10, -10], material: soil }\n",
    );
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: hf\nscene: scene.yaml\nseed: 4\nwavelength_nm: 1064\ninstrument: { pulse_energy_j: 0.001, pulse_fwhm_ns: 0, footprint_half_angle_mrad: 1, fov_half_angle_mrad: 2, receiver_area_m2: 0.01, bin_ns: 0.5 }\nplatform:\n  kind: static\n  pulses:\n    - { position: [-5, 0, 103], direction: [0, 0, -1] }\n    - { position: [5, 0, 103], direction: [0, 0, -1] }\nsimulation: { method: forward, rays_per_pulse: 200, max_order: 1 }\n",
    );
    let out = dir.join("run");
    run_ok(&camp, &out, &[]);
    let w = waveforms(&out);
    assert_eq!(w.len(), 2);
    let t: Vec<f64> = w.iter().map(return_time_ns).collect();
    for (k, z) in [(0, 2.5), (1, 3.5)] {
        let want = two_way_ns(103.0 - z);
        assert!(
            (t[k] - want).abs() < 0.5,
            "pulse {k}: {} ns, the heightfield at z = {z} gives {want} ns",
            t[k]
        );
        let total: f64 = w[k].impulse_energy_j.iter().map(|&e| e as f64).sum();
        assert!(
            class_sum(&w[k], 0) > 0.99 * total,
            "heightfields are ground"
        );
    }
    assert!(
        (t[0] - t[1] - two_way_ns(1.0)).abs() < 0.5,
        "1 m of height between the pulses: {} ns",
        t[0] - t[1]
    );
}

/// A binary little-endian PLY square (20 m × 20 m at z = 5, float vertices, uchar/int face
/// lists) over a plane at z = 0: a pulse from 105 m over the square returns at 100 m from the
/// mesh (class other), one beside it at 105 m from the plane (class ground).
#[test]
fn binary_ply_mesh_returns_at_its_height() {
    let dir = tmp("e2e_ply");
    let mut ply = b"ply\nformat binary_little_endian 1.0\ncomment lidarsim test\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for [x, y] in [[-10f32, -10.0], [10.0, -10.0], [10.0, 10.0], [-10.0, 10.0]] {
        for v in [x, y, 5.0f32] {
            ply.extend_from_slice(&v.to_le_bytes());
        }
    }
    for face in [[0i32, 1, 2], [0, 2, 3]] {
        ply.push(3u8);
        for i in face {
            ply.extend_from_slice(&i.to_le_bytes());
        }
    }
    std::fs::write(dir.join("roof.ply"), &ply).unwrap();
    write(
        &dir,
        "scene.yaml",
        "name: ply\nmaterials:\n  soil: { reflectance: 0.3 }\n  roof: { reflectance: 0.5 }\nobjects:\n  - plane: { z: 0, extent: [[-30, -30], [30, 30]], material: soil }\n  - mesh: { file: roof.ply, material: roof }\n",
    );
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: ply\nscene: scene.yaml\nseed: 5\nwavelength_nm: 1064\ninstrument: { pulse_energy_j: 0.001, pulse_fwhm_ns: 0, footprint_half_angle_mrad: 1, fov_half_angle_mrad: 2, receiver_area_m2: 0.01, bin_ns: 0.5 }\nplatform:\n  kind: static\n  pulses:\n    - { position: [0, 0, 105], direction: [0, 0, -1] }\n    - { position: [15, 0, 105], direction: [0, 0, -1] }\nsimulation: { method: forward, rays_per_pulse: 200, max_order: 1 }\n",
    );
    let out = dir.join("run");
    run_ok(&camp, &out, &[]);
    let w = waveforms(&out);
    assert_eq!(w.len(), 2);
    let (t0, t1) = (return_time_ns(&w[0]), return_time_ns(&w[1]));
    assert!(
        (t0 - two_way_ns(100.0)).abs() < 0.5,
        "over the PLY square: {t0} ns"
    );
    assert!(
        (t1 - two_way_ns(105.0)).abs() < 0.5,
        "beside it, the plane: {t1} ns"
    );
    // class index: 0 ground, 1 vegetation, 2 building, 3 other
    assert!(class_sum(&w[0], 3) > 0.0 && class_sum(&w[0], 0) == 0.0);
    assert!(class_sum(&w[1], 0) > 0.0 && class_sum(&w[1], 3) == 0.0);
}

/// `scene generate forest` (3 trees, 1 template, 50 leaves, 20 m): `check` accepts a
/// campaign over it (2 pulses, the terrain and 3 tree instances), and a run gives energy from
/// the terrain and, over the first tree of the instance table, from vegetation.
#[test]
fn generated_forest_passes_check_and_runs() {
    let dir = tmp("e2e_generated");
    let scene_dir = dir.join("scene");
    let (code, stdout, err) = lidarsim(&[
        "scene",
        "generate",
        "forest",
        "--seed",
        "3",
        "--trees",
        "3",
        "--size",
        "20",
        "--templates",
        "1",
        "--leaves",
        "50",
        "--out",
        scene_dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("(3 trees, 1 templates"), "{stdout}");
    assert!(scene_dir.join("forest.yaml").is_file() && scene_dir.join("terrain.csv").is_file());
    // the first tree of the template's instance table (x y z rotation_deg scale)
    let table = std::fs::read_dir(&scene_dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| {
            p.extension().is_some_and(|e| e == "csv")
                && p.file_name().and_then(|n| n.to_str()) != Some("terrain.csv")
        })
        .expect("an instance table beside the scene");
    let text = std::fs::read_to_string(&table).unwrap();
    let row: Vec<f64> = text
        .lines()
        .find(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .expect("a tree")
        .split(|c: char| c == ',' || c.is_whitespace())
        .filter(|f| !f.is_empty())
        .map(|f| f.parse().unwrap())
        .collect();
    let (tx, ty) = (row[0], row[1]);
    let camp = write(
        &dir,
        "campaign.yaml",
        &format!(
            "name: forest\nscene: scene/forest.yaml\nseed: 4\nwavelength_nm: 1064\ninstrument: {{ pulse_energy_j: 0.001, pulse_fwhm_ns: 2, footprint_half_angle_mrad: 30, fov_half_angle_mrad: 40, receiver_area_m2: 0.01, bin_ns: 1 }}\nplatform:\n  kind: static\n  pulses:\n    - {{ position: [{tx}, {ty}, 100], direction: [0, 0, -1] }}\n    - {{ position: [10, 10, 100], direction: [0, 0, -1] }}\nsimulation: {{ method: forward, rays_per_pulse: 200, max_order: 2 }}\n"
        ),
    );
    let (code, stdout, err) = lidarsim(&["check", camp.to_str().unwrap()]);
    assert_eq!(code, 0, "check refused the generated scene: {err}");
    assert!(stdout.lines().any(|l| l == "pulses: 2"), "{stdout}");
    assert!(
        stdout.lines().any(|l| l == "instances: 4"),
        "terrain + 3 trees: {stdout}"
    );
    assert!(stdout.lines().any(|l| l == "ok"), "{stdout}");

    let out = dir.join("run");
    let log = run_ok(&camp, &out, &[]);
    assert_eq!(summary_pulses(&log), 2);
    let w = waveforms(&out);
    assert_eq!(w.len(), 2);
    for x in &w {
        assert!(
            x.received_energy_j > 0.0,
            "pulse {}: nothing hit",
            x.pulse_id
        );
    }
    assert!(
        class_sum(&w[0], 1) > 0.0,
        "the pulse over the tree at ({tx}, {ty}) saw no vegetation"
    );
}

// ---------------------------------------------------------------------------------------------
// products

/// A photon-counting profiler (10 shots from 200 m, ~6 detectable laser photons a shot,
/// 2·10⁸ Hz dark counts, no sun): photons.parquet has the contract's columns, laser photons
/// on the ground at the shot's x and along-track distance, dark photons, no solar ones, and
/// products.json counts the same.
/// Photon events asked of pulses that return millions of photons each (an airborne discrete
/// return instrument) end the products stage with one message at `products.photons`, not an
/// exhausted memory; the waveforms are kept.
#[test]
fn photons_of_bright_returns_are_refused_at_their_key() {
    let dir = tmp("e2e_photon_flood");
    plane_scene(&dir, 0.3, 30.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: flood\nscene: plane.yaml\nseed: 5\nwavelength_nm: 1064\ninstrument: { kind: discrete_return, pulse_energy_j: 0.0001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.25, fov_half_angle_mrad: 0.4, receiver_area_m2: 0.01, bin_ns: 0.5 }\nplatform: { kind: track, altitude_m: 250, track: { start: [0, 0], end: [1, 0] }, along_track_step_m: 1 }\nsimulation: { method: forward, rays_per_pulse: 4, max_order: 1 }\nproducts: { points: true, photons: true }\n",
    );
    let out = dir.join("run");
    let (code, _, err) = lidarsim(&[
        "run",
        camp.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{err}");
    let last = err.trim().lines().last().unwrap_or_default();
    assert!(
        last.contains("campaign.yaml:8:")
            && last.contains("products.photons: ")
            && last.contains("photon events"),
        "{err}"
    );
    assert!(!out.join("photons.parquet").exists() && out.join("waveforms").is_dir());
}

#[test]
fn photon_counting_writes_labelled_photons() {
    let dir = tmp("e2e_photons");
    plane_scene(&dir, 0.3, 30.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: pc\nscene: plane.yaml\nseed: 5\nwavelength_nm: 1064\ninstrument:\n  kind: photon_counting\n  pulse_energy_j: 1.0e-10\n  pulse_fwhm_ns: 1.0\n  footprint_half_angle_mrad: 0.1\n  fov_half_angle_mrad: 0.5\n  receiver_area_m2: 0.01\n  bin_ns: 1.0\n  quantum_efficiency: 0.5\n  dead_time_ns: 1.0\n  dark_count_hz: 2.0e8\nplatform: { kind: track, altitude_m: 200, track: { start: [0, 0], end: [10, 0] }, along_track_step_m: 1 }\nsimulation: { method: forward, rays_per_pulse: 100, max_order: 1 }\n",
    );
    let out = dir.join("run");
    let log = run_ok(&camp, &out, &[]);
    assert_eq!(summary_pulses(&log), 10);
    let (schema, b) = read_table(&out.join("photons.parquet"));
    let got: Vec<(String, DataType)> = schema
        .fields()
        .iter()
        .map(|f| (f.name().clone(), f.data_type().clone()))
        .collect();
    for (name, ty) in [
        ("pulse_id", DataType::UInt64),
        ("time_ns", DataType::Float64),
        ("x", DataType::Float64),
        ("y", DataType::Float64),
        ("z", DataType::Float64),
        ("along_track_m", DataType::Float64),
        ("source", DataType::UInt8),
    ] {
        assert!(
            got.contains(&(name.to_string(), ty.clone())),
            "column {name} ({ty}) missing: {got:?}"
        );
    }
    let id = column::<UInt64Type>(&b, "pulse_id");
    let time = column::<Float64Type>(&b, "time_ns");
    let (x, y, z) = (
        column::<Float64Type>(&b, "x"),
        column::<Float64Type>(&b, "y"),
        column::<Float64Type>(&b, "z"),
    );
    let along = column::<Float64Type>(&b, "along_track_m");
    let source = column::<UInt8Type>(&b, "source");
    assert!(!id.is_empty(), "no photons");
    let count = |s: u8| source.iter().filter(|&&v| v == s).count();
    let (laser, solar, dark) = (count(0), count(1), count(2));
    println!("photons: {laser} laser, {solar} solar, {dark} dark");
    assert!(laser >= 5, "{laser} laser photons over 10 shots");
    assert!(dark >= 1, "dark_count_hz > 0 but no dark photon");
    assert_eq!(solar, 0, "no sun, no solar photon");
    assert_eq!(
        laser + solar + dark,
        id.len(),
        "every photon has a known source"
    );
    for i in 0..id.len() {
        assert!(id[i] < 10);
        // nadir shots 1 m apart from x = 0: every event is on the shot's axis
        assert!((x[i] - id[i] as f64).abs() < 1e-9 && y[i].abs() < 1e-9);
        assert!((along[i] - id[i] as f64).abs() < 1e-9);
        // the position is at range c t / 2 along the axis
        assert!((z[i] - (200.0 - C * time[i] * 1e-9 / 2.0)).abs() < 1e-6);
        if source[i] == 0 {
            assert!(
                (time[i] - two_way_ns(200.0)).abs() < 5.0 && z[i].abs() < 1.0,
                "laser photon at {} ns, z {}",
                time[i],
                z[i]
            );
        }
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("products.json")).unwrap()).unwrap();
    let ph = &summary["photons"];
    assert_eq!(ph["total"].as_u64(), Some(id.len() as u64), "{summary}");
    assert_eq!(ph["laser"].as_u64(), Some(laser as u64));
    assert_eq!(ph["dark"].as_u64(), Some(dark as u64));
}

/// `campaign.resolved.yaml` writes out the defaults the run applied (the products, the GPS
/// start, the receiver's offset, the false-alarm rate, a polygon's duty), and is itself a
/// campaign: run again, it makes the same pulses and points, byte for byte.
#[test]
fn the_resolved_campaign_holds_its_defaults_and_runs_the_same() {
    let dir = tmp("e2e_resolved");
    plane_scene(&dir, 0.3, 30.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: defaults\nscene: plane.yaml\nseed: 6\nwavelength_nm: 1064\ninstrument: { kind: discrete_return, pulse_energy_j: 0.00001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1 }\nplatform: { kind: als, altitude_m: 100, speed_m_s: 10, prf_hz: 20000, lines: [ { start: [-5, 0], end: [5, 0] } ], scanner: { pattern: rotating_polygon, facets: 4, scan_angle_deg: [-10, 10], scan_frequency_hz: 50 } }\nsimulation: { method: forward, rays_per_pulse: 8, max_order: 1 }\n",
    );
    let out = dir.join("run");
    run_ok(&camp, &out, &[]);
    let resolved_path = out.join("campaign.resolved.yaml");
    let text = std::fs::read_to_string(&resolved_path).unwrap();
    let r: serde_yaml::Value = serde_yaml::from_str(&text).unwrap();
    assert_eq!(r["products"]["points"].as_bool(), Some(true), "{text}");
    assert_eq!(r["products"]["dsm"]["resolution_m"].as_f64(), Some(2.0));
    assert_eq!(r["products"]["points_format"].as_str(), Some("las"));
    assert_eq!(r["platform"]["gps_start_s"].as_f64(), Some(0.0));
    assert_eq!(r["platform"]["scanner"]["duty"].as_f64(), Some(1.0));
    assert_eq!(r["instrument"]["false_alarm_rate"].as_f64(), Some(0.001));
    assert_eq!(
        r["instrument"]["receiver_offset_m"],
        serde_yaml::from_str::<serde_yaml::Value>("[0.0, 0.0, 0.0]").unwrap()
    );
    // its files are named absolutely: a run started from the campaign's folder with a
    // relative path leaves a resolved campaign that checks where it lies
    let rel = std::process::Command::new(env!("CARGO_BIN_EXE_lidarsim"))
        .args(["run", "campaign.yaml", "--out", "rel", "--stages", "plan"])
        .current_dir(&dir)
        .output()
        .unwrap();
    assert!(
        rel.status.success(),
        "{}",
        String::from_utf8_lossy(&rel.stderr)
    );
    let resolved_rel = dir.join("rel/campaign.resolved.yaml");
    let (code, _, err) = lidarsim(&["check", resolved_rel.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let again = dir.join("again");
    let copy = write(&dir, "resolved.yaml", &text);
    run_ok(&copy, &again, &[]);
    for file in ["pulses.parquet", "points.las", "dsm/dsm.tif"] {
        assert!(
            std::fs::read(out.join(file)).unwrap() == std::fs::read(again.join(file)).unwrap(),
            "{file} differs"
        );
    }

    // a track's pulse rate, the sun's share and fixed probability, a digitiser's saturation
    let camp = write(
        &dir,
        "track.yaml",
        "name: track_defaults\nscene: plane.yaml\nseed: 6\nwavelength_nm: 1064\ninstrument: { pulse_energy_j: 0.00001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1, bandwidth_nm: 1, digitiser: { gain: 10, offset: 5, bits: 10 } }\nplatform: { kind: track, altitude_m: 100, track: { start: [0, 0], end: [3, 0] }, along_track_step_m: 1 }\nsun: { zenith_deg: 30, azimuth_deg: 0, irradiance_w_m2_um: 1000, selection: fixed }\nsimulation: { method: bdpt, rays_per_pulse: 8, max_order: 2 }\n",
    );
    let out = dir.join("track");
    run_ok(&camp, &out, &[]);
    let text = std::fs::read_to_string(out.join("campaign.resolved.yaml")).unwrap();
    let r: serde_yaml::Value = serde_yaml::from_str(&text).unwrap();
    assert_eq!(r["platform"]["prf_hz"].as_f64(), Some(1000.0), "{text}");
    assert_eq!(r["sun"]["share"].as_f64(), Some(1.0), "{text}");
    assert_eq!(
        r["sun"]["selection_probability"].as_f64(),
        Some(0.5),
        "{text}"
    );
    assert_eq!(
        r["instrument"]["digitiser"]["saturation"].as_f64(),
        Some(1023.0),
        "{text}"
    );
    for (key, value) in [("quantum_efficiency", 1.0), ("dark_count_hz", 0.0)] {
        assert_eq!(r["instrument"][key].as_f64(), Some(value), "{key}: {text}");
    }
    let again = dir.join("track_again");
    run_ok(&write(&dir, "track_resolved.yaml", &text), &again, &[]);
    for file in [
        "pulses.parquet",
        "waveforms/part-00000.parquet",
        "waveforms_l1b.h5",
    ] {
        assert!(
            std::fs::read(out.join(file)).unwrap() == std::fs::read(again.join(file)).unwrap(),
            "{file} differs"
        );
    }
}

/// One pulse's DSM has one cell and no swath edge: the log's figures of the edge's no cells
/// are "–", not NaN (`run_ok` refuses a log with NaN).
#[test]
fn a_dsm_group_of_no_cells_reads_as_a_dash() {
    let dir = tmp("e2e_dsm_dash");
    plane_scene(&dir, 0.3, 30.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: one\nscene: plane.yaml\nseed: 1\nwavelength_nm: 1064\ninstrument: { kind: discrete_return, pulse_energy_j: 0.00001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1 }\nplatform: { kind: static, pulses: [ { position: [0, 0, 100], direction: [0, 0, -1] } ] }\nsimulation: { method: forward, rays_per_pulse: 8, max_order: 1 }\nproducts: { points: true, dsm: { resolution_m: 2 } }\n",
    );
    let log = run_ok(&camp, &dir.join("run"), &[]);
    assert!(
        log.contains("the swath's edge: RMSE – m, coverage –% over 0 cells"),
        "{log}"
    );
}

/// A fixed `instrument.range_gate: { start_ns, bins }`: every waveform starts at start_ns
/// with that many bins whatever its range; a return inside the gate lands at its time, one
/// beyond it leaves the gate empty and all its energy in `outside_gate_energy_j`.
#[test]
fn fixed_range_gate_sets_t0_and_bins() {
    let dir = tmp("e2e_range_gate");
    plane_scene(&dir, 0.3, 30.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: gate\nscene: plane.yaml\nseed: 6\nwavelength_nm: 1064\ninstrument:\n  pulse_energy_j: 0.001\n  pulse_fwhm_ns: 0\n  footprint_half_angle_mrad: 0.5\n  fov_half_angle_mrad: 1.5\n  receiver_area_m2: 0.01\n  bin_ns: 1\n  range_gate: { start_ns: 900, bins: 300 }\nplatform:\n  kind: static\n  pulses:\n    - { position: [0, 0, 150], direction: [0, 0, -1] }\n    - { position: [5, 5, 300], direction: [0, 0, -1] }\nsimulation: { method: forward, rays_per_pulse: 100, max_order: 1 }\n",
    );
    let out = dir.join("run");
    run_ok(&camp, &out, &[]);
    let resolved = std::fs::read_to_string(out.join("campaign.resolved.yaml")).unwrap();
    assert!(resolved.contains("range_gate"), "{resolved}");
    let w = waveforms(&out);
    assert_eq!(w.len(), 2);
    for x in &w {
        assert!(
            (x.t0_ns - 900.0).abs() < 1e-6,
            "pulse {}: t0 {}",
            x.pulse_id,
            x.t0_ns
        );
        assert_eq!(x.bin_ns, 1.0);
        assert_eq!(x.laser_photons.len(), 300);
        assert_eq!(x.impulse_energy_j.len(), 300);
        assert!(x.received_energy_j > 0.0);
    }
    // 150 m: 1000.7 ns, inside [900, 1200) ns
    let t = return_time_ns(&w[0]);
    assert!((t - two_way_ns(150.0)).abs() < 0.6, "{t} ns");
    assert!(w[0].outside_gate_energy_j <= 1e-9 * w[0].received_energy_j);
    // 300 m: 2001 ns, beyond the gate
    let inside: f64 = w[1].impulse_energy_j.iter().map(|&e| e as f64).sum();
    assert_eq!(inside, 0.0, "a return beyond the gate must not be binned");
    assert!(
        (w[1].outside_gate_energy_j - w[1].received_energy_j).abs()
            <= 1e-9 * w[1].received_energy_j,
        "{} of {} J outside",
        w[1].outside_gate_energy_j,
        w[1].received_energy_j
    );
}

// ---------------------------------------------------------------------------------------------
// compare and sweeps

/// `compare RUN RUN --csv F --plots DIR` over two ALS discrete-return runs at 100 and 150 m
/// whose folder names hold a comma: the markdown table has both, the CSV has its header and
/// two rows with the run names quoted (RFC 4180), altitude, pulses and a DSM RMSE, and the
/// plots folder has the DSM error against altitude as SVG.
#[test]
fn compare_writes_csv_and_plots() {
    let dir = tmp("e2e_compare");
    plane_scene(&dir, 0.3, 60.0);
    let mut runs = Vec::new();
    for (h, name) in [(100, "h100,a"), (150, "h150,b")] {
        let camp = write(
            &dir,
            &format!("als{h}.yaml"),
            &format!(
                "name: als{h}\nscene: plane.yaml\nseed: 7\nwavelength_nm: 1064\ninstrument:\n  kind: discrete_return\n  pulse_energy_j: 0.00001\n  pulse_fwhm_ns: 4\n  footprint_half_angle_mrad: 0.3\n  fov_half_angle_mrad: 0.5\n  receiver_area_m2: 0.01\n  bin_ns: 1\nplatform: {{ kind: als, altitude_m: {h}, speed_m_s: 50, lines: [ {{ start: [0, 0], end: [20, 0] }} ], scanner: {{ pattern: line, scan_angle_deg: [-10, 10], look_angle_step_deg: 1, along_track_step_m: 1 }} }}\nsimulation: {{ method: forward, rays_per_pulse: 8, max_order: 1 }}\nproducts: {{ points: true, dsm: {{ resolution_m: 4 }} }}\n"
            ),
        );
        let out = dir.join(name);
        let log = run_ok(&camp, &out, &[]);
        assert_eq!(summary_pulses(&log), 400, "20 scan lines × 20 look angles");
        assert!(out.join("dsm/report.json").is_file());
        runs.push(out);
    }
    let csv_path = dir.join("cmp/table.csv");
    let plots = dir.join("cmp/plots");
    let (code, stdout, err) = lidarsim(&[
        "compare",
        runs[0].to_str().unwrap(),
        runs[1].to_str().unwrap(),
        "--csv",
        csv_path.to_str().unwrap(),
        "--plots",
        plots.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("| h100,a | 100 |"), "{stdout}");
    assert!(stdout.contains("| h150,b | 150 |"), "{stdout}");
    // the markdown is the CSV's table: its columns, in its order
    let md_header: Vec<&str> = stdout.lines().next().unwrap().split('|').collect();
    assert_eq!(
        md_header.len() - 2,
        lidarsim::compare::CSV_COLUMNS.len(),
        "{stdout}"
    );
    assert!(md_header[5].contains("points") && md_header[19].contains("strip max mean"));
    // two runs whose folders share a name are told apart by their paths
    let twin = dir.join("elsewhere").join("h100,a");
    copy_tree(&runs[0], &twin);
    let (code, stdout, err) =
        lidarsim(&["compare", runs[0].to_str().unwrap(), twin.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    for path in [&runs[0], &twin] {
        assert!(
            stdout.contains(&format!("| {} | 100 |", path.display())),
            "{stdout}"
        );
    }
    // a run's own file is no place for the table: refused, the run left whole
    let manifest = runs[0].join("manifest.json");
    let before = std::fs::read(&manifest).unwrap();
    let (code, _, err) = lidarsim(&[
        "compare",
        runs[0].to_str().unwrap(),
        "--csv",
        manifest.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("--csv") && err.contains("elsewhere"), "{err}");
    assert_eq!(std::fs::read(&manifest).unwrap(), before);

    let text = std::fs::read_to_string(&csv_path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 3, "header and two rows:\n{text}");
    assert!(
        lines[0].starts_with("run,altitude_m,prf_hz,pulses,"),
        "{text}"
    );
    // the name holds a comma, so it is quoted; no prf_hz: an empty cell
    assert!(lines[1].starts_with("\"h100,a\",100,,400,"), "{text}");
    assert!(lines[2].starts_with("\"h150,b\",150,,400,"), "{text}");
    let mut reader = csv::Reader::from_path(&csv_path).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    let rmse = header
        .iter()
        .position(|h| h == "dsm_rmse_m")
        .expect("dsm_rmse_m column");
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    assert_eq!(rows.len(), 2);
    assert_eq!(&rows[0][0], "h100,a");
    for r in &rows {
        assert_eq!(r.len(), header.len());
        let v: f64 = r[rmse]
            .parse()
            .unwrap_or_else(|_| panic!("RMSE cell: {r:?}"));
        assert!(
            v.is_finite() && (0.0..0.1).contains(&v),
            "DSM RMSE of a plane: {v}"
        );
    }

    let svg =
        std::fs::read_to_string(plots.join("dsm_error_vs_altitude.svg")).unwrap_or_else(|e| {
            panic!(
                "{e}; in the plots folder: {:?}",
                std::fs::read_dir(&plots)
                    .map(|d| d.flatten().map(|e| e.file_name()).collect::<Vec<_>>())
            )
        });
    assert!(svg.contains("<svg"), "not an SVG");

    // a products.json or DSM report cut short, or a resolved campaign that is not one, is
    // named, not shown as an empty row
    for file in ["products.json", "dsm/report.json", "campaign.resolved.yaml"] {
        let path = runs[1].join(file);
        let whole = std::fs::read(&path).unwrap();
        if file.ends_with(".yaml") {
            // YAML cut short mostly still parses: garbage instead
            std::fs::write(&path, b"- [not a campaign").unwrap();
        } else {
            std::fs::write(&path, &whole[..whole.len() / 2]).unwrap();
        }
        let (code, stdout, err) = lidarsim(&[
            "compare",
            runs[0].to_str().unwrap(),
            runs[1].to_str().unwrap(),
        ]);
        assert_eq!(code, 1, "{stdout}{err}");
        assert!(err.contains(file) && err.contains("--resume"), "{err}");
        assert!(!err.contains("panicked"), "{err}");
        std::fs::write(&path, whole).unwrap();
    }
    // a run without its products yet: its planned pulses, the products' cells empty
    std::fs::remove_file(runs[1].join("products.json")).unwrap();
    std::fs::remove_dir_all(runs[1].join("dsm")).unwrap();
    let (code, stdout, err) = lidarsim(&["compare", runs[1].to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(
        stdout.contains("| h150,b | 150 | – | 400 | – |"),
        "{stdout}"
    );
}

/// A sweep of `platform.altitude_m: [100, 200]` over a 10-shot profiler: one sub-folder per
/// value with its report and waveforms, sweep.csv with a header and 2 rows (10 pulses each,
/// the energy at 200 m a quarter of that at 100 m), sweep.json listing both runs in order,
/// and sweep_energy.svg.
#[test]
fn sweep_writes_subruns_and_summaries() {
    let dir = tmp("e2e_sweep");
    plane_scene(&dir, 0.3, 30.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: swept\nscene: plane.yaml\nseed: 6\nwavelength_nm: 1064\ninstrument: { pulse_energy_j: 0.001, pulse_fwhm_ns: 2, footprint_half_angle_mrad: 0.5, fov_half_angle_mrad: 1.5, receiver_area_m2: 0.01, bin_ns: 1 }\nplatform: { kind: track, altitude_m: 100, track: { start: [25.5, 0], end: [35.5, 0] }, along_track_step_m: 1 }\nsimulation: { method: forward, rays_per_pulse: 100, max_order: 1 }\nsweep:\n  platform.altitude_m: [100, 200]\n",
    );
    let out = dir.join("runs");
    let log = run_ok(&camp, &out, &[]);
    assert_eq!(summary_pulses(&log), 20, "{log}");
    let names = ["altitude_m=100", "altitude_m=200"];
    for n in names {
        let sub = out.join(n);
        assert!(sub.join("report.md").is_file(), "{}", sub.display());
        assert_eq!(waveforms(&sub).len(), 10);
    }

    let mut reader = csv::Reader::from_path(out.join("sweep.csv")).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(header[0], "platform.altitude_m");
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (pulses, energy) = (col("pulses"), col("received_energy_j"));
    let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
    assert_eq!(rows.len(), 2);
    assert_eq!((&rows[0][0], &rows[1][0]), ("100", "200"));
    assert_eq!((&rows[0][pulses], &rows[1][pulses]), ("10", "10"));
    let e: Vec<f64> = rows.iter().map(|r| r[energy].parse().unwrap()).collect();
    let ratio = e[0] / e[1];
    assert!((3.6..4.4).contains(&ratio), "energy ∝ 1/H²: ratio {ratio}");
    // half the pulses miss the plane (it ends at x = 30): the footprint's BRF is the mean
    // over the lit ones, the plane's ρ = 0.3 (a Lambertian plane's BRF is its albedo), not
    // spoilt by the dark ones' nulls; without a sun the solar BRF has no value at all
    let brf = col("brf_footprint_laser");
    for r in &rows {
        let b: f64 = r[brf].parse().unwrap();
        assert!((0.28..0.32).contains(&b), "BRF {b}");
        assert_eq!(&r[col("brf_fov_solar")], "");
    }

    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sweep.json")).unwrap()).unwrap();
    assert_eq!(index["campaign"], "swept");
    assert_eq!(index["sweep"], serde_json::json!(names));

    let svg = std::fs::read_to_string(out.join("sweep_energy.svg")).unwrap();
    assert!(svg.contains("<svg"));

    // runs planned but not simulated: their planned pulses and empty cells, not zeros
    let planned = dir.join("planned");
    run_ok(&camp, &planned, &["--stages", "plan"]);
    let text = std::fs::read_to_string(planned.join("sweep.csv")).unwrap();
    let rows: Vec<&str> = text.lines().skip(1).collect();
    assert_eq!(rows, ["100,10,,,,", "200,10,,,,"], "{text}");

    // a sweep stopped before its last run: compared as far as it went, that run's row empty
    std::fs::remove_dir_all(out.join(names[1])).unwrap();
    let (code, stdout, err) = lidarsim(&["compare", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(
        stdout.contains("| altitude_m=100 | 100 | 1000 | 10 |"),
        "{stdout}"
    );
    assert!(
        stdout.contains("| altitude_m=200 | – | – | – | – |"),
        "{stdout}"
    );
    assert!(stdout
        .lines()
        .last()
        .unwrap()
        .ends_with("| – | – | – | – | – | – |"));
    // an index naming folders outside the sweep's is no sweep's: said, not followed
    let index = out.join("sweep.json");
    let text = std::fs::read_to_string(&index).unwrap();
    std::fs::write(&index, text.replace("altitude_m=100", "../altitude_m=100")).unwrap();
    let (code, _, err) = lidarsim(&["compare", out.to_str().unwrap()]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("sweep.json") && err.contains("--resume"),
        "{err}"
    );
}

// ---------------------------------------------------------------------------------------------
// stages and resume

/// `--stages plan`, then `--stages simulate` (no `--resume`: a stage list keeps the folder),
/// then a plain `--resume`: the folder
/// holds the plan only, then the waveforms too, then the products and report, and the files
/// equal a one-shot run byte for byte.
#[test]
fn staged_run_equals_one_shot_run() {
    let dir = tmp("e2e_stages");
    let camp = small_track(&dir);
    let staged = dir.join("staged");

    let log = run_ok(&camp, &staged, &["--stages", "plan"]);
    assert_eq!(summary_pulses(&log), 10);
    assert!(log.contains("0 parts simulated"), "{log}");
    assert!(staged.join("pulses.parquet").is_file());
    assert_eq!(read_pulses(&staged).id.len(), 10);
    for absent in ["waveforms", "products.json", "points.las", "report.md"] {
        assert!(
            !staged.join(absent).exists(),
            "{absent} after --stages plan"
        );
    }
    let m = manifest(&staged);
    assert_eq!(m["stages"]["plan"]["status"], "done");
    assert!(m["stages"]["simulate"].is_null(), "{m}");

    // a later stage alone picks up the plan, with or without --resume
    let log = run_ok(&camp, &staged, &["--stages", "simulate"]);
    assert!(log.contains("plan: up to date"), "{log}");
    assert!(log.contains("1 parts simulated"), "{log}");
    assert_eq!(waveforms(&staged).len(), 10);
    for absent in ["products.json", "points.las", "report.md"] {
        assert!(
            !staged.join(absent).exists(),
            "{absent} after --stages simulate"
        );
    }
    let m = manifest(&staged);
    assert_eq!(m["stages"]["simulate"]["status"], "done");
    assert!(m["stages"]["products"].is_null(), "{m}");

    let log = run_ok(&camp, &staged, &["--resume"]);
    assert!(log.contains("simulate: up to date"), "{log}");
    assert!(log.contains("0 parts simulated"), "{log}");
    for present in ["products.json", "points.las", "report.md"] {
        assert!(staged.join(present).is_file(), "{present} after --resume");
    }
    let m = manifest(&staged);
    for stage in ["plan", "simulate", "products", "report"] {
        assert_eq!(m["stages"][stage]["status"], "done", "{stage}: {m}");
        assert_eq!(
            m["stages"][stage]["tool_version"],
            env!("CARGO_PKG_VERSION"),
            "{stage}: {m}"
        );
    }

    let oneshot = dir.join("oneshot");
    run_ok(&camp, &oneshot, &[]);
    assert_same_files(&staged, &oneshot);

    // a later stage alone over an earlier stage's damaged file (the products' summary, then
    // a waveform part): the message names the stage to run again and the file
    let part = staged.join("waveforms/part-00000.parquet");
    let mut bytes = std::fs::read(&part).unwrap();
    bytes.push(b'x');
    for (damage, stage, says) in [
        (
            (staged.join("products.json"), b"{}".to_vec()),
            "report",
            "stage products must run again (products.json is not what it wrote)",
        ),
        (
            (part, bytes),
            "products",
            "stage simulate must run again (waveforms/part-00000.parquet",
        ),
    ] {
        std::fs::write(&damage.0, &damage.1).unwrap();
        let (c, o) = (camp.to_str().unwrap(), staged.to_str().unwrap());
        let (code, _, err) = lidarsim(&["run", c, "--out", o, "--stages", stage]);
        assert_eq!(code, 1, "{err}");
        assert!(err.contains(says), "{err}");
    }
}

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let target = to.join(e.file_name());
        if e.path().is_dir() {
            copy_tree(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

fn truncate_half(part: &Path) {
    let bytes = std::fs::read(part).unwrap();
    std::fs::write(part, &bytes[..bytes.len() / 2]).unwrap();
}

/// `run --resume` after damage: exit 0, the damaged part simulated again (said in the log),
/// and every file equal to a clean run's.
fn resume_redoes(camp: &Path, out: &Path, clean: &Path) -> String {
    let log = run_ok(camp, out, &["--resume"]);
    assert!(out.join("report.md").is_file(), "{log}");
    assert_same_files(out, clean);
    log
}

/// Resume never trusts a damaged part: a part cut in half, whether the manifest says the
/// simulate stage is done or not, is simulated again, and a foreign `*.parquet` beside the
/// parts is neither read nor removed.
#[test]
fn resume_over_damaged_or_foreign_part_files() {
    let dir = tmp("e2e_damaged_parts");
    let camp = small_track(&dir);
    let clean = dir.join("clean");
    run_ok(&camp, &clean, &[]);

    // simulated, then the part truncated: the simulate stage redoes it
    let damaged = dir.join("damaged");
    run_ok(&camp, &damaged, &["--stages", "plan,simulate"]);
    truncate_half(&damaged.join("waveforms/part-00000.parquet"));
    let log = resume_redoes(&camp, &damaged, &clean);
    assert!(log.contains("1 parts simulated"), "{log}");

    // simulated, then a part's timings cut in half: the part is made again with them
    let timings = dir.join("timings");
    run_ok(&camp, &timings, &["--stages", "plan,simulate"]);
    truncate_half(&timings.join("waveforms/part-00000.stats.csv"));
    let log = resume_redoes(&camp, &timings, &clean);
    assert!(log.contains("1 parts simulated"), "{log}");

    // simulated, then a foreign Parquet file beside the parts: only part-NNNNN files are read
    let foreign = dir.join("foreign");
    run_ok(&camp, &foreign, &["--stages", "plan,simulate"]);
    let stray = foreign.join("waveforms/foreign.parquet");
    std::fs::write(&stray, b"PAR1 this is not a waveform part PAR1").unwrap();
    let log = resume_redoes(&camp, &foreign, &clean);
    assert!(log.contains("0 parts simulated"), "{log}");
    assert!(
        stray.is_file(),
        "a file lidarsim did not write is left alone"
    );

    // a complete folder whose part is then truncated: the manifest says done, the file
    // disagrees, and the file wins
    let complete = dir.join("complete");
    run_ok(&camp, &complete, &[]);
    truncate_half(&complete.join("waveforms/part-00000.parquet"));
    let log = resume_redoes(&camp, &complete, &clean);
    assert!(log.contains("a part file is missing or damaged"), "{log}");
    assert!(log.contains("1 parts simulated"), "{log}");

    // the plan's and the products' files damaged under their final names: the manifest's
    // checksums catch them and their stages are redone
    truncate_half(&complete.join("pulses.parquet"));
    std::fs::write(complete.join("points.las"), b"not a LAS file").unwrap();
    let log = resume_redoes(&camp, &complete, &clean);
    assert!(
        log.contains("pulses.parquet is not what the plan stage wrote"),
        "{log}"
    );
    assert!(log.contains("0 parts simulated"), "{log}");
}

/// One run per folder: a second run started while the first works exits 1 naming the first's
/// PID; once the first is killed (SIGKILL leaves its lock behind), a resume takes the stale
/// lock over, finishes, leaves no lock, and the folder equals an undisturbed run's.
#[test]
fn a_busy_folder_is_refused_and_a_stale_lock_taken_over() {
    let dir = tmp("e2e_lock");
    plane_scene(&dir, 0.3, 30.0);
    // long enough (thousands of pulses at 2000 rays) that the second run starts before it ends
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: busy\nscene: plane.yaml\nseed: 8\nwavelength_nm: 1064\ninstrument: { kind: waveform, pulse_energy_j: 0.00001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1 }\nplatform: { kind: track, altitude_m: 100, track: { start: [-20, 0], end: [20, 0] }, along_track_step_m: 0.005 }\nsimulation: { method: forward, rays_per_pulse: 2000, max_order: 1 }\n",
    );
    let out = dir.join("run");
    let (c, o) = (camp.to_str().unwrap(), out.to_str().unwrap());
    let mut first = std::process::Command::new(env!("CARGO_BIN_EXE_lidarsim"))
        .args(["run", c, "--out", o])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let lock = out.join("run.lock");
    let t = std::time::Instant::now();
    while !lock.exists() && t.elapsed().as_secs() < 30 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    assert!(lock.exists(), "the first run never took the folder");
    let (code, _, err) = lidarsim(&["run", c, "--out", o, "--resume"]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains(&format!(
            "another lidarsim run (PID {}) is working in this folder",
            first.id()
        )),
        "{err}"
    );
    first.kill().unwrap();
    // killed but not yet waited for (a zombie): its lock is stale already
    let t = std::time::Instant::now();
    while !std::fs::read_to_string(format!("/proc/{}/stat", first.id()))
        .is_ok_and(|s| s.contains(") Z"))
        && t.elapsed().as_secs() < 30
    {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    assert!(lock.exists(), "SIGKILL leaves the lock behind");
    let (code, _, err) = lidarsim(&["run", c, "--out", o, "--resume", "--stages", "plan"]);
    assert_eq!(code, 0, "a zombie's lock is taken over: {err}");
    first.wait().unwrap();
    std::fs::write(&lock, format!("{}", first.id())).unwrap();
    // a lock whose process id a later process took (here a `sleep`, started after the lock's
    // time) is stale, and taken over; the lock of the process that runs is not
    let mut other = std::process::Command::new("sleep")
        .arg("30")
        .spawn()
        .unwrap();
    let stat = std::fs::read_to_string(format!("/proc/{}/stat", other.id())).unwrap();
    let started: u64 = stat[stat.rfind(')').unwrap() + 1..]
        .split_whitespace()
        .nth(19)
        .unwrap()
        .parse()
        .unwrap();
    std::fs::write(&lock, format!("{} {started}", other.id())).unwrap();
    let (code, _, err) = lidarsim(&["run", c, "--out", o, "--resume"]);
    assert_eq!(code, 1, "the sleep's own lock is held: {err}");
    // a shard takes no lock (shards share the folder) but does not work beside a whole run
    let (code, _, err) = lidarsim(&["run", c, "--out", o, "--shard", "1/2"]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains(&format!("(PID {}) is working in this folder", other.id())),
        "{err}"
    );
    std::fs::write(
        &lock,
        format!("{} {}", other.id(), started.saturating_sub(1)),
    )
    .unwrap();
    let log = run_ok(&camp, &out, &["--resume"]);
    other.kill().unwrap();
    other.wait().unwrap();
    assert!(log.contains("complete"), "{log}");
    assert!(!lock.exists(), "the lock goes when the run ends");
    // and the refused second run changed nothing: the folder equals a run never disturbed
    let clean = dir.join("clean");
    run_ok(&camp, &clean, &[]);
    assert_same_files(&out, &clean);
}

/// A discrete-return track of 2500 pulses over the plane, with the given seed: three parts, as
/// its 100 rays per pulse keep parts at their fewest pulses (`waveform::file::Parts`).
fn parts_track(dir: &Path, seed: u64) -> PathBuf {
    plane_scene(dir, 0.3, 30.0);
    write(
        dir,
        &format!("campaign_{seed}.yaml"),
        &format!("name: parts\nscene: plane.yaml\nseed: {seed}\nwavelength_nm: 1064\ninstrument: {{ kind: discrete_return, pulse_energy_j: 0.00001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1 }}\nplatform: {{ kind: track, altitude_m: 100, track: {{ start: [-10, 0], end: [15, 0] }}, along_track_step_m: 0.01 }}\nsimulation: {{ method: forward, rays_per_pulse: 100, max_order: 1 }}\n"),
    )
}

/// The files of a run folder, every one, by name (the lock, wall times and logs aside): what
/// "nothing lost, nothing changed" compares.
fn folder_bytes(out: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut files = Vec::new();
    let mut todo = vec![out.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                todo.push(p);
            } else {
                files.push((p.clone(), std::fs::read(&p).unwrap()));
            }
        }
    }
    files.sort();
    files
}

/// A manifest cut in half is not trusted: `--resume` says it cannot be read and redoes the
/// stages from what the files themselves prove (each part by its checksum), and the run ends
/// equal to a clean one.
#[test]
fn a_damaged_manifest_is_not_trusted() {
    let dir = tmp("e2e_damaged_manifest");
    let camp = parts_track(&dir, 4);
    let clean = dir.join("clean");
    run_ok(&camp, &clean, &[]);
    let out = dir.join("run");
    run_ok(&camp, &out, &[]);
    truncate_half(&out.join("manifest.json"));
    let log = resume_redoes(&camp, &out, &clean);
    assert!(log.contains("manifest.json cannot be read"), "{log}");
    assert!(log.contains("0 parts simulated"), "{log}");
    // and a manifest that is valid JSON but another run's: its fingerprints do not match
    std::fs::copy(dir.join("clean/manifest.json"), out.join("manifest.json")).unwrap();
    let other = parts_track(&dir, 5);
    let log = run_ok(&other, &out, &["--resume"]);
    assert!(log.contains("3 parts simulated"), "{log}");
}

/// Parts simulated for another campaign (here another seed) in the same folder are redone,
/// never mixed with the new campaign's: by a resume, and by shards, which keep the folder's
/// files because other shards may be writing beside them.
#[test]
fn parts_of_another_campaign_are_redone_never_mixed() {
    let dir = tmp("e2e_other_parts");
    let (a, b) = (parts_track(&dir, 4), parts_track(&dir, 5));
    let clean = dir.join("clean");
    run_ok(&b, &clean, &[]);
    for how in [&["--resume"][..], &["--shard", "0/1"][..]] {
        let out = dir.join(format!("mixed{}", how.len()));
        run_ok(&a, &out, &["--stages", "plan,simulate"]);
        let log = run_ok(&b, &out, how);
        assert!(log.contains("3 parts simulated"), "{how:?}: {log}");
        run_ok(&b, &out, &["--resume"]);
        assert_same_files(&out, &clean);
    }
}

/// The command that runs `lidarsim` as a user who may not write `folder` (root-owned): as
/// root, the binary copied where anyone can run it and started as `nobody` with setpriv;
/// otherwise the folder is made read-only for its owner. None, saying why, where neither works.
fn unprivileged(dir: &Path, folder: &Path) -> Option<std::process::Command> {
    let root = std::process::Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
    if !root {
        let mut perms = std::fs::metadata(folder).unwrap().permissions();
        std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o555);
        std::fs::set_permissions(folder, perms).unwrap();
        return Some(std::process::Command::new(env!("CARGO_BIN_EXE_lidarsim")));
    }
    let has_setpriv = std::process::Command::new("setpriv")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_setpriv {
        lidarsim::testdata::skip_tool("unwritable folder test: running as root without setpriv (util-linux), no user to lack the permission");
        return None;
    }
    let bin = dir.join("lidarsim-copy");
    std::fs::copy(env!("CARGO_BIN_EXE_lidarsim"), &bin).unwrap();
    let mut c = std::process::Command::new("setpriv");
    c.args(["--reuid=65534", "--regid=65534", "--clear-groups"])
        .arg(bin);
    Some(c)
}

/// A run that failed as a fault should end it: exit 1 and one `error:` line, naming a file in
/// the run folder `out` and saying how to go on (`--resume`); returns that line.
fn one_error(o: &std::process::Output, out: &Path) -> String {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "{err}");
    assert!(
        errors[0].contains(out.to_str().unwrap()) && errors[0].contains("--resume"),
        "{err}"
    );
    errors[0].to_string()
}

/// An output folder the run cannot write: exit 1, one message naming a file in it and what to
/// do, and nothing in it changed; once it can be written, `--resume` finishes the run equal to
/// a clean one.
#[test]
fn an_unwritable_folder_ends_with_a_message_and_resume_finishes_it() {
    // under the system's temporary folder, which every user may cross (the target folder may
    // lie under a home that `nobody` cannot enter)
    let dir = std::env::temp_dir().join(format!("lidarsim-e2e-unwritable-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let camp = parts_track(&dir, 4);
    let clean = dir.join("clean");
    run_ok(&camp, &clean, &[]);
    let out = dir.join("run");
    run_ok(&camp, &out, &["--stages", "plan,simulate"]);
    let before = folder_bytes(&out);
    let Some(mut cmd) = unprivileged(&dir, &out) else {
        return;
    };
    let o = cmd
        .args([
            "run",
            camp.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--resume",
        ])
        .output()
        .unwrap();
    let error = one_error(&o, &out);
    assert!(
        error.contains("Permission denied") && error.contains("permissions of that folder"),
        "{error}"
    );
    let mut perms = std::fs::metadata(&out).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o755);
    std::fs::set_permissions(&out, perms).unwrap();
    assert!(
        folder_bytes(&out) == before,
        "the refused run changed the folder"
    );
    let log = run_ok(&camp, &out, &["--resume"]);
    assert!(log.contains("0 parts simulated"), "{log}");
    assert_same_files(&out, &clean);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The disk filling in the products stage (a file-size limit under the points' size): exit 1
/// naming the file, no file half-written under its final name, and `--resume` finishes the
/// run equal to a clean one. Before the points streamed through the las crate's writer, whose
/// drop after a failed write panics, this was a panic.
#[test]
fn a_full_disk_in_the_products_stage_ends_with_a_message_and_resume_finishes_it() {
    let dir = tmp("e2e_products_fsize");
    let camp = parts_track(&dir, 4);
    let clean = dir.join("clean");
    run_ok(&camp, &clean, &[]);
    let las = std::fs::metadata(clean.join("points.las")).unwrap().len();
    let out = dir.join("run");
    run_ok(&camp, &out, &["--stages", "plan,simulate"]);
    // a limit in 512-byte blocks (as dash counts them; bash counts KiB, which only doubles it)
    // at a third of points.las, which the parts already written do not need
    let blocks = las / 3 / 1024;
    assert!(blocks >= 8, "points.las is {las} bytes");
    let o = std::process::Command::new("sh")
        .args([
            "-c",
            &format!(
                "ulimit -f {blocks} && exec '{}' run '{}' --out '{}' --resume",
                env!("CARGO_BIN_EXE_lidarsim"),
                camp.display(),
                out.display()
            ),
        ])
        .output()
        .unwrap();
    let error = one_error(&o, &out);
    assert!(!out.join("points.las").exists(), "{error}");
    let log = run_ok(&camp, &out, &["--resume"]);
    assert!(log.contains("0 parts simulated"), "{log}");
    assert_same_files(&out, &clean);
}

/// The number before `unit` after `label` in `text`.
fn figure_after(text: &str, label: &str) -> f64 {
    let rest = &text[text
        .find(label)
        .unwrap_or_else(|| panic!("no {label:?} in {text}"))
        + label.len()..];
    rest.split_whitespace()
        .next()
        .and_then(|w| w.trim_end_matches(',').parse().ok())
        .unwrap_or_else(|| panic!("no number after {label:?} in {text}"))
}

/// `lidarsim check` bounds a run's peak memory: a discrete-return survey (points, DSM) of
/// 25,000 pulses peaks below the estimate, and the estimate is not so loose as to be useless.
#[test]
fn check_bounds_the_peak_memory_of_a_run() {
    let dir = tmp("e2e_memory_bound");
    plane_scene(&dir, 0.3, 60.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: bound\nscene: plane.yaml\nseed: 2\nwavelength_nm: 1064\ninstrument: { kind: discrete_return, pulse_energy_j: 0.001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.25, fov_half_angle_mrad: 0.375, receiver_area_m2: 0.1, bin_ns: 0.067 }\nplatform: { kind: als, altitude_m: 250, speed_m_s: 5, prf_hz: 100000, lines: [ { start: [-40, 0], end: [40, 0] } ], scanner: { pattern: line, scan_angle_deg: [-10, 10], look_angle_step_deg: 0.04, along_track_step_m: 1.6 } }\nsimulation: { method: bdpt, rays_per_pulse: 1 }\n",
    );
    let (code, check, err) = lidarsim(&["check", camp.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let bound = figure_after(&check, "estimated peak memory:");
    let log = run_ok(&camp, &dir.join("run"), &[]);
    assert_eq!(summary_pulses(&log), 25_000, "{log}");
    let peak = figure_after(&log, "peak memory");
    assert!(
        peak <= bound,
        "peak {peak} MB over the bound {bound} MB\n{check}"
    );
    assert!(
        bound <= 4.0 * peak,
        "bound {bound} MB for a peak of {peak} MB\n{check}"
    );
}

/// A campaign of one pulse holds one pulse's waveform, not a survey part's thousand: a gate of
/// 200,000 bins of 1 ps was refused as needing 28 GB (a part of 1,000 such pulses) where the
/// run peaks at about 35 MB.
#[test]
fn check_bounds_a_one_pulse_campaign_by_its_one_pulse() {
    let dir = tmp("e2e_memory_one_pulse");
    plane_scene(&dir, 0.3, 10.0);
    let camp = write(
        &dir,
        "campaign.yaml",
        "name: one\nscene: plane.yaml\nseed: 3\nwavelength_nm: 1064\ninstrument: { kind: discrete_return, pulse_energy_j: 0.001, pulse_fwhm_ns: 0.01, footprint_half_angle_mrad: 0.01, fov_half_angle_mrad: 1, receiver_area_m2: 0.0001, bin_ns: 0.001, range_gate: { start_ns: 600, bins: 200000 } }\nplatform: { kind: static, pulses: [ { position: [0, 0, 100], direction: [0, 0, -1] } ] }\nsimulation: { method: forward, rays_per_pulse: 200, max_order: 1 }\n",
    );
    let (code, check, err) = lidarsim(&["check", camp.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let bound = figure_after(&check, "estimated peak memory:");
    let log = run_ok(&camp, &dir.join("run"), &[]);
    let peak = figure_after(&log, "peak memory");
    assert!(
        peak <= bound,
        "peak {peak} MB over the bound {bound} MB\n{check}"
    );
    assert!(bound < 1000.0, "bound {bound} MB for one pulse\n{check}");
}

/// Every bundled campaign in pipelines/ (the bench's aside) reads and plans as `lidarsim run`
/// reads and plans it: keys, values and the platform's pulses. Its scene is not loaded (some
/// are made by `lidarsim scene generate` first, as their comments say, or need ../shared).
#[test]
fn every_bundled_campaign_plans() {
    let dir = lidarsim::testdata::repo().join("pipelines");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "yaml"))
        .collect();
    names.sort();
    assert!(names.len() >= 10, "{names:?}");
    for path in names {
        let name = path.display();
        let doc = lidarsim::campaign::Doc::read(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut campaign: lidarsim::campaign::Campaign =
            doc.parse().unwrap_or_else(|e| panic!("{name}: {e}"));
        campaign.resolve_files(&doc);
        lidarsim::plan::check_campaign(&doc, &campaign).unwrap_or_else(|e| panic!("{name}: {e}"));
        let plan = lidarsim::plan::Plan::new(&campaign).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(!plan.is_empty(), "{}: no pulses", path.display());
    }
}
