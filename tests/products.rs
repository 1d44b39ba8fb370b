//! Products through the whole pipeline: points on a plane against closed form 1, the DSM of a
//! plane and of a scene of boxes under an airborne scanner, photon counting, `compare`.

mod common;

use common::*;
use lidarsim::products::points::las::read_las;
use std::path::Path;

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Static nadir discrete-return pulses over a Lambertian plane: every pulse gives one point on
/// the plane, and its apparent reflectance (π/ΔΩ)(Q_i/Q_e) is what closed form 1 predicts,
/// ρ · Q_r(ρ=1)·πH²/(A Q_e): the plane's ρ when the field of view takes the whole footprint
/// through the whole aperture, less when the aperture is wide for the field of view (the
/// paper's VUX-1UAV at 250 m, where only ~28 % of the aperture sees each lit point).
#[test]
fn plane_points_have_the_plane_height_and_the_closed_form_reflectance() {
    struct Case {
        h: f64,
        fp: f64,
        fov: f64,
        area: f64,
        bin: f64,
        fwhm: f64,
        rho: f64,
    }
    let cases = [
        Case {
            h: 250.0,
            fp: 0.25,
            fov: 1.0,
            area: 0.01,
            bin: 0.5,
            fwhm: 4.0,
            rho: 0.3,
        },
        Case {
            h: 250.0,
            fp: 0.25,
            fov: 0.375,
            area: 0.1,
            bin: 0.067,
            fwhm: 3.0,
            rho: 0.3,
        },
        Case {
            h: 731.3,
            fp: 0.1,
            fov: 0.3,
            area: 0.05,
            bin: 1.0,
            fwhm: 5.0,
            rho: 0.55,
        },
    ];
    for (k, c) in cases.iter().enumerate() {
        let dir = tmp(&format!("products-plane-{k}"));
        let scene = plane_scene(&dir, c.rho, 200.0);
        let inst = Inst {
            energy: 1e-6,
            fwhm_ns: c.fwhm,
            fp_mrad: c.fp,
            fov_mrad: c.fov,
            area: c.area,
            bin_ns: c.bin,
            ..Default::default()
        };
        let text = format!(
            "name: t\nscene: {}\nseed: 5\nwavelength_nm: 1064\ninstrument:\n  kind: discrete_return\n  pulse_energy_j: {}\n  pulse_fwhm_ns: {}\n  footprint_half_angle_mrad: {}\n  fov_half_angle_mrad: {}\n  receiver_area_m2: {}\n  bin_ns: {}\n  max_returns: 4\n  detection_threshold_photons: 5\nplatform:\n  kind: static\n  pulses:\n    - {{ position: [0, 0, {h}], direction: [0, 0, -1] }}\n    - {{ position: [13.7, -40.2, {h}], direction: [0, 0, -1] }}\n    - {{ position: [-81.1, 5.5, {h}], direction: [0, 0, -1] }}\nsimulation: {{ method: forward, rays_per_pulse: 20000, max_order: 1 }}\n",
            scene.display(),
            inst.energy,
            c.fwhm,
            c.fp,
            c.fov,
            c.area,
            c.bin,
            h = c.h
        );
        let out = run_campaign(&dir, &text, None);
        let points = read_las(&out.join("points.las")).unwrap();
        let waveforms =
            lidarsim::waveform::file::read_waveforms(&out.join("waveforms/part-00000.parquet"))
                .unwrap();
        assert_eq!(points.len(), 3, "case {k}: one return per pulse");
        let expected = plane_energy(&inst, c.rho, c.h) * PI_ * c.h * c.h / (c.area * inst.energy);
        for (p, w) in points.iter().zip(&waveforms) {
            let se_rel = w.received_energy_se_j / w.received_energy_j;
            let tol = 4.0 * se_rel + 1e-4;
            let got = p.apparent_reflectance as f64;
            println!(
                "case {k}: z {:+.4} m, apparent reflectance {got:.5} vs closed form {expected:.5} \
                 (SE {:.2e})",
                p.z,
                se_rel * expected
            );
            assert!(p.z.abs() < 0.005, "case {k}: z = {}", p.z);
            assert!(
                (got / expected - 1.0).abs() < tol,
                "case {k}: {got} vs {expected} (tolerance {tol})"
            );
            assert_eq!((p.return_number, p.number_of_returns), (1, 1));
            assert_eq!(p.classification, 2, "the plane is ground");
        }
    }
}

const PI_: f64 = std::f64::consts::PI;

/// An OBJ of axis-aligned boxes (closed, outward normals) standing on z = 0.
fn boxes_obj(boxes: &[[f64; 5]]) -> String {
    let mut s = String::new();
    let mut v = 0;
    for &[x0, y0, w, d, h] in boxes {
        for (x, y, z) in [
            (x0, y0, 0.0),
            (x0 + w, y0, 0.0),
            (x0 + w, y0 + d, 0.0),
            (x0, y0 + d, 0.0),
            (x0, y0, h),
            (x0 + w, y0, h),
            (x0 + w, y0 + d, h),
            (x0, y0 + d, h),
        ] {
            s += &format!("v {x} {y} {z}\n");
        }
        for f in [
            [5, 6, 7],
            [5, 7, 8],
            [1, 2, 6],
            [1, 6, 5],
            [2, 3, 7],
            [2, 7, 6],
            [3, 4, 8],
            [3, 8, 7],
            [4, 1, 5],
            [4, 5, 8],
        ] {
            s += &format!("f {} {} {}\n", v + f[0], v + f[1], v + f[2]);
        }
        v += 8;
    }
    s
}

/// Buildings under an airborne line scanner: the ground behind each box (seen from the
/// scanner) gets no first return, and that blind strip is h·tan θ wide, so the DSM coverage
/// gap is positive off nadir and grows with the scan angle. The plane around them gives a
/// DSM bias under 1 cm.
#[test]
fn boxes_leave_a_coverage_gap_that_grows_with_scan_angle() {
    let dir = tmp("products-boxes");
    // 6 m x 6 m boxes, 8 m tall, on a 15 m grid over the whole swath (±53 m)
    let mut boxes = Vec::new();
    for i in 0..4 {
        for j in 0..7 {
            boxes.push([
                8.0 + 15.0 * i as f64,
                -51.0 + 15.0 * j as f64,
                6.0,
                6.0,
                8.0,
            ]);
        }
    }
    write(&dir, "boxes.obj", &boxes_obj(&boxes));
    write(
        &dir,
        "scene.yaml",
        "name: boxes\nmaterials:\n  soil: { reflectance: 0.3 }\n  roof: { reflectance: 0.4 }\nobjects:\n  - plane: { z: 0, extent: [[-10, -60], [80, 60]], material: soil, class: ground }\n  - mesh: { file: boxes.obj, material: roof, class: building }\n",
    );
    let text = "name: boxes\nscene: scene.yaml\nseed: 9\nwavelength_nm: 1064\ninstrument:\n  kind: discrete_return\n  pulse_energy_j: 0.0001\n  pulse_fwhm_ns: 3.0\n  footprint_half_angle_mrad: 0.25\n  fov_half_angle_mrad: 0.5\n  receiver_area_m2: 0.01\n  bin_ns: 0.5\n  max_returns: 4\n  detection_threshold_photons: 5\nplatform:\n  kind: als\n  altitude_m: 120\n  speed_m_s: 30\n  prf_hz: 100000\n  lines: [ { start: [5, 0], end: [70, 0] } ]\n  scanner: { pattern: line, scan_angle_deg: [-24, 24], look_angle_step_deg: 0.2, along_track_step_m: 0.4 }\nsimulation: { method: forward, rays_per_pulse: 8, max_order: 1 }\nproducts: { points: true, dsm: { resolution_m: 1.0 } }\n";
    let out = run_campaign(&dir, text, None);
    let report = json(&out.join("dsm/report.json"));
    let bins = report["by_scan_angle"].as_array().unwrap();
    let gap = |lo: f64, hi: f64| {
        let (mut surfaced, mut covered) = (0.0, 0.0);
        for b in bins {
            let c = b["bin_deg_lo"].as_f64().unwrap() + 1.0;
            if c >= lo && c < hi {
                surfaced += b["cells_surfaced"].as_f64().unwrap();
                covered += b["cells"].as_f64().unwrap();
            }
        }
        assert!(surfaced > 100.0, "{lo}-{hi}°: only {surfaced} cells");
        1.0 - covered / surfaced
    };
    let (g0, g1, g2) = (gap(0.0, 8.0), gap(8.0, 16.0), gap(16.0, 24.0));
    println!("coverage gap: 0-8° {g0:.4}, 8-16° {g1:.4}, 16-24° {g2:.4}");
    assert!(g1 > 0.0 && g2 > g1 && g1 > g0, "{g0} {g1} {g2}");
    // the blind strips are 8 m · tan θ deep behind 6 m-wide boxes: between 12° and 20°
    // about twice as much ground is hidden
    assert!(g2 > 1.5 * g1);
    // the points on roofs are buildings, the others ground
    let points = read_las(&out.join("points.las")).unwrap();
    let roof = points.iter().filter(|p| p.z > 7.9 && p.z < 8.1).count();
    let roof_buildings = points
        .iter()
        .filter(|p| p.z > 7.9 && p.z < 8.1 && p.classification == 6)
        .count();
    assert!(
        roof > 1000 && roof_buildings == roof,
        "{roof_buildings}/{roof}"
    );
    let ground = points.iter().filter(|p| p.z.abs() < 0.05).count();
    let ground_class = points
        .iter()
        .filter(|p| p.z.abs() < 0.05 && p.classification == 2)
        .count();
    assert_eq!(ground_class, ground);
    for f in [
        "dsm/error_map.png",
        "dsm/error_vs_scan_angle.png",
        "points_top.png",
        "waveforms.png",
    ] {
        let b = std::fs::read(out.join(f)).unwrap();
        assert_eq!(&b[..4], b"\x89PNG", "{f}");
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        md.contains("error_map.png") && md.contains("points_top.png"),
        "{md}"
    );
}

/// The DSM of a plane scanned off nadir: bias under 1 cm at every scan angle.
#[test]
fn plane_dsm_bias_is_under_a_centimetre() {
    let dir = tmp("products-plane-dsm");
    let scene = plane_scene(&dir, 0.3, 100.0);
    let text = format!(
        "name: plane\nscene: {}\nseed: 2\nwavelength_nm: 1064\ninstrument:\n  kind: discrete_return\n  pulse_energy_j: 0.00001\n  pulse_fwhm_ns: 4.0\n  footprint_half_angle_mrad: 0.3\n  fov_half_angle_mrad: 0.5\n  receiver_area_m2: 0.01\n  bin_ns: 1.0\n  max_returns: 4\n  detection_threshold_photons: 5\nplatform:\n  kind: als\n  altitude_m: 300\n  speed_m_s: 30\n  prf_hz: 100000\n  lines: [ {{ start: [-40, 0], end: [40, 0] }} ]\n  scanner: {{ pattern: line, scan_angle_deg: [-15, 15], look_angle_step_deg: 0.3, along_track_step_m: 1.0 }}\nsimulation: {{ method: forward, rays_per_pulse: 16, max_order: 1 }}\nproducts: {{ points: true, dsm: {{ resolution_m: 2.0 }} }}\n",
        scene.display()
    );
    let out = run_campaign(&dir, &text, None);
    let r = json(&out.join("dsm/report.json"));
    println!("plane DSM: {}", r);
    assert!(r["bias_m"].as_f64().unwrap().abs() < 0.01);
    assert!(r["rmse_m"].as_f64().unwrap() < 0.01);
    assert!(r["coverage"].as_f64().unwrap() > 0.99);
    for b in r["by_scan_angle"].as_array().unwrap() {
        if b["cells"].as_u64().unwrap() > 0 {
            assert!(b["bias_m"].as_f64().unwrap().abs() < 0.01, "{b}");
        }
    }
}

/// One plane, seen from 250 m at incidences from 0° to 75° with a wide beam (2.5 mrad, a
/// 1.25 m footprint) and a short pulse (1 ns): the waveform of a steep view is the pulse
/// smeared over metres of range, and with few rays a comb of one spike per ray, yet one
/// surface gives one return, on the plane within 5 cm plus 4 standard errors of the rays'
/// mean range (the footprint's spread in range over √rays). The hard cases: steep views at
/// few rays, where the decomposition must weigh the simulation's noise, compare its
/// components with one surface's waveform, and read a comb of a few rays' spikes as one
/// surface's sampling rather than as several returns.
#[test]
fn a_plane_gives_one_return_at_any_incidence_at_few_rays() {
    let dir = tmp("products-incidence");
    let degrees = [0.0f64, 15.0, 30.0, 45.0, 60.0, 75.0];
    struct View {
        h: f64,
        rho: f64,
        fwhm_ns: f64,
        footprint_mrad: f64,
        method: &'static str,
        threshold: f64,
    }
    let view = |h, rho, fwhm_ns, footprint_mrad, method, threshold| View {
        h,
        rho,
        fwhm_ns,
        footprint_mrad,
        method,
        threshold,
    };
    // (view, rays, seeds): 19 rays is the bench's airborne town survey
    let cases: [(View, usize, &[u64]); 8] = [
        (
            view(250.0, 0.3, 1.0, 2.5, "bdpt", 5.0),
            19,
            &[1, 2, 3, 4, 5, 6, 7, 8, 9],
        ),
        (view(250.0, 0.3, 1.0, 2.5, "bdpt", 5.0), 200, &[1, 2, 3]),
        (view(250.0, 0.3, 1.0, 2.5, "bdpt", 5.0), 2000, &[1, 2, 3]),
        (view(100.0, 0.05, 1.0, 2.5, "bdpt", 5.0), 19, &[1, 2, 3]),
        (view(600.0, 0.9, 1.0, 2.5, "bdpt", 5.0), 19, &[1, 2, 3]),
        (view(250.0, 0.3, 3.0, 2.5, "bdpt", 5.0), 19, &[1, 2, 3]),
        (view(400.0, 0.5, 2.0, 2.0, "forward", 20.0), 19, &[1, 2, 3]),
        (view(250.0, 0.1, 1.0, 2.5, "backward", 5.0), 19, &[1, 2, 3]),
    ];
    for (v, rays, seeds) in cases {
        let name = format!("{}-{}-{}-{}-{}", v.h, v.rho, v.fwhm_ns, v.method, rays);
        let sub = dir.join(&name);
        std::fs::create_dir_all(&sub).unwrap();
        let scene = plane_scene(&sub, v.rho, 5000.0);
        let h = v.h;
        let mut pulses = String::new();
        for (k, deg) in degrees.iter().enumerate() {
            let t = deg.to_radians();
            let _ = std::fmt::Write::write_fmt(
                &mut pulses,
                format_args!(
                    "    - {{ position: [{}, 0, {h}], direction: [{}, 0, {}] }}\n",
                    -h * t.tan() + 20.0 * k as f64,
                    t.sin(),
                    -t.cos()
                ),
            );
        }
        for &seed in seeds {
            let text = format!(
                "name: t\nscene: {}\nseed: {seed}\nwavelength_nm: 1064\ninstrument:\n  kind: discrete_return\n  pulse_energy_j: 0.0001\n  pulse_fwhm_ns: {}\n  footprint_half_angle_mrad: {}\n  fov_half_angle_mrad: {}\n  receiver_area_m2: 0.01\n  bin_ns: 0.25\n  max_returns: 4\n  detection_threshold_photons: {}\nplatform:\n  kind: static\n  pulses:\n{pulses}simulation: {{ method: {}, rays_per_pulse: {rays}, max_order: 3 }}\n",
                scene.display(),
                v.fwhm_ns,
                v.footprint_mrad,
                1.2 * v.footprint_mrad,
                v.threshold,
                v.method,
            );
            let run = sub.join(format!("s{seed}"));
            std::fs::create_dir_all(&run).unwrap();
            let out = run_campaign(&run, &text, None);
            let points = read_las(&out.join("points.las")).unwrap();
            for (k, deg) in degrees.iter().enumerate() {
                let on: Vec<f64> = points
                    .iter()
                    .filter(|p| p.pulse_id == k as u64)
                    .map(|p| p.z)
                    .collect();
                let t = deg.to_radians();
                // footprint radius along the slope, and the spread of the rays' ranges over it
                // (the footprint's σ is about half its edge radius)
                let along = h / t.cos() * v.footprint_mrad * 1e-3 / t.cos();
                let se = 0.5 * along * t.sin() / (rays as f64).sqrt();
                let tol = 0.05 + 4.0 * se * t.cos();
                assert!(
                    on.len() == 1 && on[0].abs() < tol,
                    "{name}, seed {seed}, {deg}°: z {on:?} (one return within {tol:.3})"
                );
            }
        }
    }
}

/// A GeoTIFF raster's float32 cells (north row first) and its tiepoint, pixel scale and
/// GeoKey directory.
fn read_geotiff(path: &Path) -> (Vec<f32>, Vec<f64>, Vec<f64>, Vec<u16>) {
    use tiff::decoder::{Decoder, DecodingResult};
    use tiff::tags::Tag;
    let mut d = Decoder::new(std::fs::File::open(path).unwrap()).unwrap();
    let DecodingResult::F32(v) = d.read_image().unwrap() else {
        panic!("{}: not float32", path.display());
    };
    (
        v,
        d.get_tag_f64_vec(Tag::ModelTiepointTag).unwrap(),
        d.get_tag_f64_vec(Tag::ModelPixelScaleTag).unwrap(),
        d.get_tag_u16_vec(Tag::GeoKeyDirectoryTag).unwrap(),
    )
}

/// A survey placed in UTM zone 31N (`frame`) with LAZ points is the local survey shifted by
/// the frame's origin: the same points at local + origin (to the millimetre both files keep),
/// the CRS as an OGC WKT VLR, the DSM rasters' cells and corner shifted alike with the EPSG
/// code in their GeoKeys (the difference raster unshifted); laspy and rasterio, readers we did
/// not write, read the files the same way when they are installed.
#[test]
fn a_georeferenced_survey_is_the_local_one_shifted_into_its_crs() {
    let dir = tmp("products_frame");
    plane_scene(&dir, 0.3, 40.0);
    let base = "scene: plane.yaml\nseed: 3\nwavelength_nm: 1064\ninstrument: { kind: discrete_return, pulse_energy_j: 0.001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.25, fov_half_angle_mrad: 0.375, receiver_area_m2: 0.1, bin_ns: 0.5 }\nplatform: { kind: als, altitude_m: 250, speed_m_s: 5, prf_hz: 100000, lines: [ { start: [-30, 0], end: [30, 0] } ], scanner: { pattern: line, scan_angle_deg: [-6, 6], look_angle_step_deg: 0.3, along_track_step_m: 1.5 } }\nsimulation: { method: bdpt, rays_per_pulse: 4 }\n";
    let origin = [500_000.25, 4_800_000.5, 120.0];
    let local = write(
        &dir,
        "local.yaml",
        &format!("name: local\n{base}products: {{ points: true, dsm: {{ resolution_m: 4 }} }}\n"),
    );
    // the georeferenced survey as LAZ, and as LAS for laspy to read beside it, flown on a
    // real date (GPS time past week 0: adjusted standard GPS time in the files)
    let dated = base.replace("kind: als,", "kind: als, gps_start_s: 1300000000.5,");
    let georeferenced = |name: &str, format: &str| {
        write(
            &dir,
            &format!("{name}.yaml"),
            &format!(
                "name: {name}\n{dated}products: {{ points: true, dsm: {{ resolution_m: 4 }}, points_format: {format} }}\nframe: {{ crs: EPSG:32631, origin: [{}, {}, {}] }}\n",
                origin[0], origin[1], origin[2]
            ),
        )
    };
    let (geo, geo_las) = (georeferenced("geo", "laz"), georeferenced("geo_las", "las"));
    let (a, b, c) = (dir.join("local"), dir.join("geo"), dir.join("geo_las"));
    for (camp, out) in [(&local, &a), (&geo, &b), (&geo_las, &c)] {
        let (code, _, err) = lidarsim(&[
            "run",
            camp.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{err}");
    }
    assert!(!b.join("points.las").exists() && !a.join("points.laz").exists());
    let (pa, pb) = (
        read_las(&a.join("points.las")).unwrap(),
        read_las(&b.join("points.laz")).unwrap(),
    );
    assert!(pa.len() > 1000, "{} points", pa.len());
    assert_eq!(pa.len(), pb.len());
    for (p, q) in pa.iter().zip(&pb) {
        assert_eq!(p.pulse_id, q.pulse_id);
        // week time as it is, standard time read back as the GPS seconds
        let dt = q.gps_time - p.gps_time - 1_300_000_000.5;
        assert!(dt.abs() < 1e-6, "{} against {}", q.gps_time, p.gps_time);
        for (u, v, o) in [
            (p.x, q.x, origin[0]),
            (p.y, q.y, origin[1]),
            (p.z, q.z, origin[2]),
        ] {
            assert!((u + o - v).abs() <= 0.0011, "{u} + {o} against {v}");
        }
    }
    let header = las::Reader::from_path(b.join("points.laz"))
        .unwrap()
        .header()
        .clone();
    assert!(header.point_format().is_compressed && header.has_wkt_crs());
    let wkt = String::from_utf8_lossy(header.get_wkt_crs_bytes().unwrap()).into_owned();
    assert!(wkt.starts_with("PROJCS[\"WGS 84 / UTM zone 31N\""), "{wkt}");
    assert!(
        wkt.ends_with("]\0"),
        "not one null-terminated string: {wkt}"
    );
    assert_eq!(wkt.matches('\0').count(), 1, "{wkt}");
    let local_header = las::Reader::from_path(a.join("points.las"))
        .unwrap()
        .header()
        .clone();
    assert!(local_header.get_wkt_crs_bytes().is_none());

    for (name, dz) in [
        ("dsm", origin[2]),
        ("reference", origin[2]),
        ("difference", 0.0),
    ] {
        let (va, ta, sa, ka) = read_geotiff(&a.join(format!("dsm/{name}.tif")));
        let (vb, tb, sb, kb) = read_geotiff(&b.join(format!("dsm/{name}.tif")));
        assert_eq!(va.len(), vb.len(), "{name}");
        assert!(va.iter().any(|&v| v != -9999.0), "{name}: no data at all");
        for (u, v) in va.iter().zip(&vb) {
            if *u == -9999.0 {
                assert_eq!(*v, -9999.0, "{name}");
            } else {
                assert!(
                    (*u as f64 + dz - *v as f64).abs() < 1e-4,
                    "{name}: {u} + {dz} against {v}"
                );
            }
        }
        assert_eq!(sa, sb);
        assert_eq!(sa, vec![4.0, 4.0, 0.0]);
        assert_eq!(
            (tb[3] - ta[3], tb[4] - ta[4]),
            (origin[0], origin[1]),
            "{name}"
        );
        assert!(ka.chunks(4).any(|k| k == [3072, 0, 1, 32767]), "{ka:?}");
        assert!(kb.chunks(4).any(|k| k == [3072, 0, 1, 32631]), "{kb:?}");
    }

    if !python_with("laspy, lazrs, rasterio", "'laspy[lazrs]' rasterio") {
        return;
    }
    let script = format!(
        r#"
import sys, laspy, rasterio, numpy as np
f = laspy.read(sys.argv[1] + "/points.laz")
assert len(f.points) == {n}, len(f.points)
wkt = [v for v in f.header.vlrs if v.record_id == 2112][0].string
assert "UTM zone 31N" in wkt, wkt
# GPS times of 2021: adjusted standard GPS time, as the header says
assert f.header.global_encoding.gps_time_type == laspy.header.GpsTimeType.STANDARD
assert 300_000_000.5 <= float(f.gps_time.min()) < 300_000_100, f.gps_time.min()
assert abs(float(f.x.min()) - {xmin}) < 0.0011, f.x.min()
# the LAS of the same survey: the same points, fields and CRS
g = laspy.read(sys.argv[1] + "/../geo_las/points.las")
assert not g.header.are_points_compressed and f.header.are_points_compressed
assert [v for v in g.header.vlrs if v.record_id == 2112][0].string == wkt
for d in ["X", "Y", "Z", "gps_time", "return_number", "number_of_returns", "classification",
          "intensity", "pulse_id", "scan_direction_flag", "edge_of_flight_line"]:
    assert np.array_equal(np.asarray(f[d]), np.asarray(g[d])), d
# the scan flags as LAS defines them: a line scanner sweeps left to right (1) in lines of
# 12 / 0.3 = 40 pulses, the last of each at the edge of the flight line
pid = np.asarray(g["pulse_id"]).astype(np.int64)
assert np.all(np.asarray(g["scan_direction_flag"]) == 1)
assert np.array_equal(np.asarray(g["edge_of_flight_line"]) == 1, pid % 40 == 39)
assert (pid % 40 == 39).sum() > 0
with rasterio.open(sys.argv[1] + "/dsm/dsm.tif") as r:
    assert r.crs.to_epsg() == 32631, r.crs
    assert r.nodata == -9999.0, r.nodata
    t = r.transform
    assert (t.a, t.e) == (4.0, -4.0), t
    a = r.read(1)
    h = a[a != r.nodata]
    assert abs(float(np.median(h)) - {z0}) < 0.05, np.median(h)
# the difference raster is what dsm/report.json reports over all cells: its cells with a
# value, their mean, root mean square and mean absolute value (the headline is over the inner
# swath, a part of them)
import json
rep = json.load(open(sys.argv[1] + "/dsm/report.json"))
assert rep["cells"] <= rep["all"]["cells"], rep
rep = rep["all"]
with rasterio.open(sys.argv[1] + "/dsm/difference.tif") as r:
    assert r.crs.to_epsg() == 32631 and r.nodata == -9999.0
    a = r.read(1)
    d = a[a != r.nodata].astype(np.float64)
    assert len(d) == rep["cells_with_points"], (len(d), rep)
    assert abs(d.mean() - rep["bias_m"]) < 1e-5, (d.mean(), rep["bias_m"])
    assert abs(np.sqrt((d * d).mean()) - rep["rmse_m"]) < 1e-5, (np.sqrt((d * d).mean()), rep["rmse_m"])
    assert abs(np.abs(d).mean() - rep["mae_m"]) < 1e-5, (np.abs(d).mean(), rep["mae_m"])
print("laspy and rasterio ok")
"#,
        n = pb.len(),
        xmin = pb.iter().map(|p| p.x).fold(f64::MAX, f64::min),
        z0 = origin[2],
    );
    run_python(&script, &b);
}

/// report.md's simulation noise against photon noise is the waveforms' own figure,
/// Σ (qe SE / hν)² over Σ qe E / hν, and it falls as 1 / rays: each pulse's variance over
/// its rays times the rays (the variance of one ray's energy) is the same at 40 and at 160
/// rays, within four standard errors of the mean over the pulses.
#[test]
fn simulation_noise_against_photon_noise_falls_as_one_over_rays() {
    let dir = tmp("products-mc-noise");
    let scene = plane_scene(&dir, 0.4, 200.0);
    let qe = 0.3;
    let mut per_ray = Vec::new();
    for rays in [40u64, 160] {
        let text = format!(
            "name: pc\nscene: {}\nseed: 3\nwavelength_nm: 1064\ninstrument:\n  kind: photon_counting\n  pulse_energy_j: 1.0e-9\n  pulse_fwhm_ns: 1.0\n  footprint_half_angle_mrad: 0.2\n  fov_half_angle_mrad: 0.3\n  receiver_area_m2: 0.01\n  bin_ns: 0.5\n  quantum_efficiency: {qe}\n  dead_time_ns: 0\n  dark_count_hz: 0\nplatform: {{ kind: track, altitude_m: 300, track: {{ start: [-20, 0], end: [20, 0] }}, along_track_step_m: 0.5 }}\nsimulation: {{ method: bdpt, rays_per_pulse: {rays}, max_order: 2 }}\n",
            scene.display()
        );
        let sub = dir.join(format!("r{rays}"));
        std::fs::create_dir_all(&sub).unwrap();
        let out = run_campaign(&sub, &text, None);
        let rows = all_waveforms(&out);
        assert!(rows.len() > 50, "{} pulses", rows.len());
        let hv = lidarsim::photon_energy_j(1064.0);
        let var: f64 = rows
            .iter()
            .map(|w| (qe * w.received_energy_se_j / hv).powi(2))
            .sum();
        let photons: f64 = rows.iter().map(|w| qe * w.received_energy_j / hv).sum();
        let (line, printed) = report_figure(&out, "simulation noise against photon noise");
        let expected = var / photons;
        println!("{rays} rays: {line}");
        assert!(
            (printed - expected).abs() <= 5e-4 * expected,
            "{rays} rays: report {printed}, waveforms {expected}"
        );
        // one ray's variance of the received energy, per pulse
        let v: Vec<f64> = rows
            .iter()
            .map(|w| (w.received_energy_se_j / w.received_energy_j).powi(2) * rays as f64)
            .collect();
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        per_ray.push((mean, sd / n.sqrt()));
    }
    let ((a, sa), (b, sb)) = (per_ray[0], per_ray[1]);
    println!("relative variance of one ray: {a:.5} ± {sa:.5} at 40 rays, {b:.5} ± {sb:.5} at 160");
    assert!(
        (a - b).abs() <= 4.0 * (sa * sa + sb * sb).sqrt(),
        "{a} ± {sa} against {b} ± {sb}"
    );
}

/// Two returns that the waveform separates are never merged: noise-free waveforms of two
/// Gaussians (analytic, bin-integrated), the weaker 5-50 % of the stronger, 1.5 to 5 pulse
/// FWHMs apart, decompose into two returns, each centre within 1 cm of its Gaussian's
/// (1 ns bins: 15 cm of range); with the pulse sampled finely (σ of 3 bins) and coarsely (a
/// 1.5 ns pulse in 1 ns bins: σ of 0.64 bins, where the two are 2.2 bins apart at 1.5 FWHM).
#[test]
fn two_gaussians_give_two_returns_at_their_centres() {
    use lidarsim::products::returns::{decompose, Decomposition, Receiver};
    use lidarsim::waveform::normal_cdf;
    for sigma in [3.0f64, 1.5 / (2.0 * (2.0 * 2f64.ln()).sqrt())] {
        let fwhm = 2.0 * (2.0 * 2f64.ln()).sqrt() * sigma;
        let bin_m = 1e-9 * C / 2.0;
        let receiver = Receiver {
            sigma_bins: sigma,
            footprint_edge_sigmas: None,
            noise_floor: 0.0,
            false_alarm_rate: None,
        };
        for ratio in [0.05, 0.1, 0.2, 0.3, 0.5] {
            for separation in [1.5, 2.0, 2.5, 3.0, 4.0, 5.0] {
                let (c1, c2) = (100.3, 100.3 + separation * fwhm);
                let bin = |c: f64, a: f64, i: usize| {
                    let (x0, x1) = ((i as f64 - c) / sigma, (i as f64 + 1.0 - c) / sigma);
                    a * (normal_cdf(x1) - normal_cdf(x0))
                };
                let n = 260;
                let y: Vec<f32> = (0..n)
                    .map(|i| (bin(c1, 1e5, i) + bin(c2, ratio * 1e5, i)) as f32)
                    .collect();
                let zero = vec![0.0f32; n];
                let comps = decompose(&y, &zero, &zero, 5.0, 4, Decomposition::Gaussian, &receiver);
                let centres: Vec<f64> = comps.iter().map(|c| c.centre_bin).collect();
                assert_eq!(
                    comps.len(),
                    2,
                    "σ {sigma} bins, ratio {ratio}, {separation} FWHM: {centres:?}"
                );
                for (got, want) in centres.iter().zip([c1, c2]) {
                    assert!(
                        (got - want).abs() * bin_m < 0.01,
                        "σ {sigma} bins, ratio {ratio}, {separation} FWHM: {got} against {want}"
                    );
                }
            }
        }
    }
}

/// A discrete-return survey over `plane.yaml` whose records carry detector noise (electronic
/// noise `sd` photoelectrons, quantum efficiency `q`; None: the mean waveform), a 40 m line
/// scanned to ±`scan` degrees in steps of `look_step` degrees, lines `along_step` m apart,
/// 16 rays a pulse; `gate` and `extra` are more instrument keys.
fn noisy_survey(
    q: f64,
    sd: Option<f64>,
    seed: u64,
    gate: &str,
    extra: &str,
    sweep: (f64, f64, f64),
) -> String {
    let (scan, look_step, along_step) = sweep;
    let noise = sd.map_or(String::new(), |sd| {
        format!("  quantum_efficiency: {q}\n  noise: {{ electronic_sd_photons: {sd} }}\n")
    });
    format!(
        "name: noisy\nscene: plane.yaml\nseed: {seed}\nwavelength_nm: 1064\ninstrument:\n  kind: discrete_return\n  pulse_energy_j: 0.00001\n  pulse_fwhm_ns: 4.0\n  footprint_half_angle_mrad: 0.3\n  fov_half_angle_mrad: 0.5\n  receiver_area_m2: 0.01\n  bin_ns: 1.0\n  max_returns: 4\n{noise}{gate}{extra}platform:\n  kind: als\n  altitude_m: 300\n  speed_m_s: 30\n  prf_hz: 100000\n  lines: [ {{ start: [-20, 0], end: [20, 0] }} ]\n  scanner: {{ pattern: line, scan_angle_deg: [-{scan}, {scan}], look_angle_step_deg: {look_step}, along_track_step_m: {along_step} }}\nsimulation: {{ method: forward, rays_per_pulse: 16, max_order: 1 }}\nproducts: {{ points: true }}\n"
    )
}

/// Records of noise alone (range gates that hold no surface: they end over 200 m short of the
/// plane) at quantum efficiencies 0.3, 0.5 and 1 and electronic noise of 3 and 8
/// photoelectrons: the share of pulses with a false return is the configured false-alarm rate
/// within 3 standard errors (binomial), at 0.01 over 10,000 pulses each in gates of 400 ns,
/// at the default 1e-3 over 40,000, and at 0.05 over 40,000 in gates of 100 and of 30 ns,
/// where the matched filter's cut at the gate's ends (6 bins each side) is 40 % of the gate.
/// The detection threshold of 5 photons stays below the false-alarm level in every case (at
/// q = 1 and σ_e = 3 its filtered summit, 3.5 photoelectrons, against 5.3).
#[test]
fn noise_alone_gives_false_returns_at_the_configured_rate() {
    let dir = tmp("products-false-alarms");
    write(
        &dir,
        "plane.yaml",
        "name: p\nmaterials:\n  soil: { reflectance: 0.3 }\nobjects:\n  - plane: { z: 0, extent: [[-2000, -2000], [2000, 2000]], material: soil }\n",
    );
    // (q, σ_e, rate, along-track step: 100 looks every step over 40 m, gate bins)
    let mut cases: Vec<(f64, f64, f64, f64, usize)> = Vec::new();
    for q in [0.3, 0.5, 1.0] {
        for sd in [3.0, 8.0] {
            cases.push((q, sd, 0.01, 0.4, 400));
        }
    }
    cases.push((0.3, 3.0, 0.001, 0.1, 400));
    cases.push((0.5, 3.0, 0.05, 0.1, 100));
    cases.push((1.0, 8.0, 0.05, 0.1, 30));
    for (k, (q, sd, rate, along, bins)) in cases.into_iter().enumerate() {
        let gate = format!("  range_gate: {{ start_ns: 200, bins: {bins} }}\n");
        let extra = format!("  false_alarm_rate: {rate}\n");
        let text = noisy_survey(
            q,
            Some(sd),
            10 + k as u64,
            &gate,
            &extra,
            (15.0, 0.3, along),
        );
        let run = dir.join(format!("q{q}-sd{sd}-a{rate}-b{bins}"));
        std::fs::create_dir_all(&run).unwrap();
        std::fs::copy(dir.join("plane.yaml"), run.join("plane.yaml")).unwrap();
        let out = run_campaign(&run, &text, None);
        let pulses = (40.0 / along).round() * 100.0;
        let points = read_las(&out.join("points.las")).unwrap();
        let alarmed = points.iter().filter(|p| p.return_number == 1).count();
        let want = rate * pulses;
        let se = (want * (1.0 - rate)).sqrt();
        println!(
            "q {q}, σ_e {sd}, {bins} bins: {alarmed} pulses with a false return ({} returns) in {pulses}, expected {want} ± {se:.1}",
            points.len()
        );
        assert!(
            (alarmed as f64 - want).abs() < 3.0 * se,
            "q {q}, σ_e {sd}, rate {rate}, {bins} bins: {alarmed} pulses with a false return in {pulses}, expected {want} ± {se:.1}"
        );
    }
}

/// A plane seen at 0° to 75° of incidence through the same noisy detectors (q 0.3, 0.5, 1;
/// σ_e 3 and 8 photoelectrons; the default false-alarm rate), at a reflectance of 0.01 whose
/// returns hold a few hundred photons: of the pulses with a return, at least 99.5 % have one
/// and only one, and in each 15° band the mean height of the single returns differs from the
/// noise-free survey's (the same simulation, no detector noise) by less than 3 standard
/// errors of the noise's share of its scatter, √(s_noisy² − s_free²) / √n: the noise does
/// not bias the range.
#[test]
fn a_plane_gives_one_unbiased_return_per_pulse_through_a_noisy_detector() {
    let dir = tmp("products-noisy-plane");
    write(
        &dir,
        "plane.yaml",
        "name: p\nmaterials:\n  soil: { reflectance: 0.01 }\nobjects:\n  - plane: { z: 0, extent: [[-2000, -2000], [2000, 2000]], material: soil }\n",
    );
    let sweep = (75.0, 0.5, 1.0);
    let bands = |points: &[lidarsim::products::points::Point]| -> Vec<(usize, f64, f64)> {
        (0..5)
            .map(|b| {
                let z: Vec<f64> = points
                    .iter()
                    .filter(|p| p.number_of_returns == 1)
                    .filter(|p| {
                        let a = p.scan_angle_deg.abs() as f64;
                        a >= 15.0 * b as f64 - 0.25 && a < 15.0 * (b + 1) as f64 - 0.25
                    })
                    .map(|p| p.z)
                    .collect();
                let n = z.len() as f64;
                let mean = z.iter().sum::<f64>() / n;
                let var = z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
                (z.len(), mean, var)
            })
            .collect()
    };
    let free_dir = dir.join("free");
    std::fs::create_dir_all(&free_dir).unwrap();
    std::fs::copy(dir.join("plane.yaml"), free_dir.join("plane.yaml")).unwrap();
    let free = run_campaign(&free_dir, &noisy_survey(1.0, None, 3, "", "", sweep), None);
    let free = bands(&read_las(&free.join("points.las")).unwrap());
    for q in [0.3, 0.5, 1.0] {
        for sd in [3.0, 8.0] {
            let run = dir.join(format!("q{q}-sd{sd}"));
            std::fs::create_dir_all(&run).unwrap();
            std::fs::copy(dir.join("plane.yaml"), run.join("plane.yaml")).unwrap();
            let out = run_campaign(&run, &noisy_survey(q, Some(sd), 3, "", "", sweep), None);
            let points = read_las(&out.join("points.las")).unwrap();
            let with_return = points.iter().filter(|p| p.return_number == 1).count();
            let single = points.iter().filter(|p| p.number_of_returns == 1).count();
            let share = single as f64 / with_return as f64;
            println!("q {q}, σ_e {sd}: {single} of {with_return} pulses with a return have one ({share:.5})");
            assert!(share >= 0.995, "q {q}, σ_e {sd}: {share}");
            for (b, (noisy, clean)) in bands(&points).iter().zip(&free).enumerate() {
                let se = ((noisy.2 - clean.2).max(0.0) / noisy.0 as f64).sqrt();
                let d = noisy.1 - clean.1;
                println!(
                    "  {}-{}°: {} returns, mean height {:+.5} m against {:+.5} m noise-free, SE {:.5}",
                    15 * b,
                    15 * (b + 1),
                    noisy.0,
                    noisy.1,
                    clean.1,
                    se
                );
                assert!(
                    d.abs() < 3.0 * se,
                    "q {q}, σ_e {sd}, band {b}: {d} against SE {se}"
                );
            }
        }
    }
}

/// The bundled first run's pulse 1 (16 rays over the small forest), as a user runs it: its
/// waveform has a peak of 4.0e6 photons from about ten rays on leaves and, a metre later past
/// a stretch no ray reached, one of 6e5 photons from three rays at one range. Each peak's
/// Monte Carlo error is of its own size, yet the gap between them says they are two surfaces:
/// two returns, as far apart in height as the summits are in range (to one bin's range) along
/// the pulse's direction.
#[test]
fn the_first_runs_second_surface_is_a_return_of_its_own() {
    let dir = tmp("products-first-run");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("pipelines/first_run.yaml"))
        .unwrap()
        .replace(
            "../scenes/small_forest/forest.yaml",
            &root
                .join("scenes/small_forest/forest.yaml")
                .display()
                .to_string(),
        );
    let out = run_campaign(&dir, &text, None);
    let w = all_waveforms(&out)
        .into_iter()
        .find(|w| w.pulse_id == 1)
        .unwrap();
    let y = &w.laser_photons;
    let top = y.iter().cloned().fold(0.0f32, f32::max);
    // the summits: local maxima above a tenth of the highest, refined by a parabola
    let summits: Vec<f64> = (1..y.len() - 1)
        .filter(|&k| y[k] > 0.1 * top && y[k] > y[k - 1] && y[k] >= y[k + 1])
        .map(|k| {
            let (a, b, c) = (y[k - 1] as f64, y[k] as f64, y[k + 1] as f64);
            k as f64 + 0.5 + 0.5 * (a - c) / (a - 2.0 * b + c)
        })
        .collect();
    let points: Vec<_> = read_las(&out.join("points.laz"))
        .unwrap()
        .into_iter()
        .filter(|p| p.pulse_id == 1)
        .collect();
    let zs: Vec<f64> = points.iter().map(|p| p.z).collect();
    println!("summits at bins {summits:?}, returns at heights {zs:?}");
    assert_eq!(summits.len(), 2, "the waveform's peaks: {summits:?}");
    assert_eq!(points.len(), 2, "returns at heights {zs:?}");
    let bin_m = w.bin_ns as f64 * 1e-9 * lidarsim::C / 2.0;
    let cos = (points[0].scan_angle_deg as f64).to_radians().cos();
    let want = (summits[1] - summits[0]) * bin_m * cos;
    let got = zs[0] - zs[1];
    assert!(
        (got - want).abs() < bin_m,
        "returns {got} m apart in height, the summits {want} m"
    );
}
