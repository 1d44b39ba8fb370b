//! Surveys as they are flown: a recorded trajectory, and the navigation errors that move the
//! points of a real survey. Each run here is small (a plane or the small forest, a few
//! seconds), the statistics from 10^5 pulses.

mod common;
use common::*;
use glam::DVec3;
use lidarsim::products::points::las::read_las;
use lidarsim::products::points::Point;
use std::collections::HashMap;
use std::path::Path;

const INSTRUMENT: &str = "instrument: { kind: discrete_return, pulse_energy_j: 1.0e-4, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.1, fov_half_angle_mrad: 0.2, receiver_area_m2: 0.01, bin_ns: 0.25 }";
const SCANNER: &str =
    "scanner: { pattern: oscillating, scan_angle_deg: [-15, 15], scan_frequency_hz: 40 }";

fn survey(scene: &Path, platform: &str, rays: u32) -> String {
    format!(
        "name: s\nscene: {}\nseed: 11\nwavelength_nm: 1064\n{INSTRUMENT}\nplatform: {{ kind: als, prf_hz: 50000, {SCANNER}, {platform} }}\nsimulation: {{ method: forward, rays_per_pulse: {rays}, max_order: 1 }}\nproducts: {{ points: true }}\n",
        scene.display()
    )
}

fn points_by_return(run: &Path) -> HashMap<(u64, u8), Point> {
    read_las(&run.join("points.las"))
        .unwrap()
        .into_iter()
        .map(|p| ((p.pulse_id, p.return_number), p))
        .collect()
}

fn xyz(p: &Point) -> DVec3 {
    DVec3::new(p.x, p.y, p.z)
}

/// A trajectory of straight level flight (epochs every 1/8 s, GPS times near 1.3e9 s) over the
/// small forest gives the points of the same `lines:` campaign within 1 mm.
#[test]
fn a_straight_level_trajectory_gives_the_lines_points() {
    let dir = tmp("survey_straight");
    let forest = lidarsim::testdata::repo().join("scenes/small_forest/forest.yaml");
    let (t0, speed, h) = (1.3e9, 40.0, 150.0);
    let mut csv = String::from("time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n");
    for k in 0..=8 {
        let t = k as f64 * 0.125;
        csv += &format!("{},{},20,{h},0,0,90\n", t0 + t, t * speed);
    }
    write(&dir, "straight.csv", &csv);
    let lines = write(
        &dir,
        "lines.yaml",
        &survey(
            &forest,
            &format!("altitude_m: {h}, speed_m_s: {speed}, gps_start_s: {t0}, lines: [{{ start: [0, 20], end: [40, 20] }}]"),
            8,
        ),
    );
    let traj = write(
        &dir,
        "traj.yaml",
        &survey(&forest, "trajectory: { file: straight.csv }", 8),
    );
    run_cli(&lines, &dir.join("lines"), None);
    run_cli(&traj, &dir.join("traj"), None);
    let a = points_by_return(&dir.join("lines"));
    let b = points_by_return(&dir.join("traj"));
    assert!(a.len() > 20_000, "{} points", a.len());
    assert_eq!(a.len(), b.len());
    for (k, p) in &a {
        let q = &b[k];
        assert!(
            (xyz(p) - xyz(q)).length() < 1e-3,
            "{k:?}: {} m",
            (xyz(p) - xyz(q)).length()
        );
    }
    // the trajectory edited (flown 5 m further east): --resume plans and simulates again,
    // and the points move with it
    write(&dir, "straight.csv", &csv.replace(",20,", ",25,"));
    let out = dir.join("traj");
    let (code, _, log) = lidarsim(&[
        "run",
        traj.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--resume",
    ]);
    assert_eq!(code, 0, "{log}");
    assert!(!log.contains("plan: up to date"), "{log}");
    let c = points_by_return(&dir.join("traj"));
    // the same pulse fired 5 m further north: its first return lies elsewhere
    let moved = c
        .iter()
        .filter(|((_, n), _)| *n == 1)
        .filter(|(k, p)| b.get(k).is_some_and(|q| (xyz(p) - xyz(q)).length() > 1.0))
        .count();
    assert!(moved > c.len() / 4, "{moved} of {} points moved", c.len());
    let _ = std::fs::remove_dir_all(&dir);
}

/// White navigation errors over 10^5 pulses over a plane 400 m below: against the error-free
/// run, the points' horizontal and vertical RMSE are the configured standard deviations
/// propagated to each point (position as it is; roll and pitch turn the beam about the track
/// and the wing, moving a point at range r by r δ across its beam) within 5 %. Errors given as
/// zeros leave every byte of the points and waveforms as they are without `errors`, and an
/// unknown boresight of 0.05° moves each point by its range × 0.05°.
#[test]
fn navigation_errors_move_the_points_as_configured() {
    let dir = tmp("survey_errors");
    let plane = plane_scene(&dir, 0.3, 400.0);
    let h = 400.0;
    let lines =
        format!("altitude_m: {h}, speed_m_s: 60, lines: [{{ start: [-70, 0], end: [70, 0] }}]");
    let (sd_pos, sd_att): ([f64; 3], [f64; 2]) = ([0.04, 0.06, 0.09], [0.004, 0.006]);
    let runs = [
        ("clean", String::new()),
        ("zero", ", errors: { position_sd_m: [0, 0, 0], attitude_sd_deg: [0, 0, 0], boresight_deg: [0, 0, 0] }".to_string()),
        ("white", format!(", errors: {{ position_sd_m: {sd_pos:?}, attitude_sd_deg: [{}, {}, 0] }}", sd_att[0], sd_att[1])),
        ("boresight", ", errors: { boresight_deg: [0.05, 0, 0] }".to_string()),
    ];
    for (name, errors) in &runs {
        let c = write(
            &dir,
            &format!("{name}.yaml"),
            &survey(&plane, &format!("{lines}{errors}"), 1),
        );
        run_cli(&c, &dir.join(name), None);
    }
    let same = |f: &str| {
        std::fs::read(dir.join("clean").join(f)).unwrap()
            == std::fs::read(dir.join("zero").join(f)).unwrap()
    };
    assert!(same("points.las"), "zero errors changed points.las");
    for part in std::fs::read_dir(dir.join("clean/waveforms")).unwrap() {
        let name = part.unwrap().file_name().into_string().unwrap();
        if name.ends_with(".parquet") {
            assert!(
                same(&format!("waveforms/{name}")),
                "zero errors changed {name}"
            );
        }
    }
    let clean = points_by_return(&dir.join("clean"));
    assert!(clean.len() >= 100_000, "{} points", clean.len());
    let plan = |name: &str| {
        let loaded = lidarsim::plan::read_campaign(&dir.join(format!("{name}.yaml"))).unwrap();
        lidarsim::plan::Plan::new(&loaded.campaign).unwrap()
    };

    let white = points_by_return(&dir.join("white"));
    let white_plan = plan("white");
    let (mut h2, mut v2, mut want_h2, mut want_v2) = (0.0, 0.0, 0.0, 0.0);
    for (k, p) in &clean {
        let q = &white[k];
        let d = xyz(q) - xyz(p);
        h2 += d.x * d.x + d.y * d.y;
        v2 += d.z * d.z;
        let pulse = white_plan.pulse(p.pulse_id);
        // every point lies where the recorded pose puts its range
        let r = (xyz(p) - pulse.origin).length();
        let at = pulse.rec_origin() + pulse.rec_direction() * r;
        assert!((at - xyz(q)).length() < 1e-3, "pulse {}", p.pulse_id);
        let dir_ = pulse.direction;
        let roll = DVec3::X.cross(dir_) * r * sd_att[0].to_radians();
        let pitch = DVec3::Y.cross(dir_) * r * sd_att[1].to_radians();
        want_h2 += sd_pos[0] * sd_pos[0]
            + sd_pos[1] * sd_pos[1]
            + roll.truncate().length_squared()
            + pitch.truncate().length_squared();
        want_v2 += sd_pos[2] * sd_pos[2] + roll.z * roll.z + pitch.z * pitch.z;
    }
    let n = clean.len() as f64;
    let (rh, rv) = ((h2 / n).sqrt(), (v2 / n).sqrt());
    let (wh, wv) = ((want_h2 / n).sqrt(), (want_v2 / n).sqrt());
    eprintln!(
        "white errors over {n} points: horizontal RMSE {rh:.4} m against {wh:.4} m, vertical {rv:.4} m against {wv:.4} m"
    );
    assert!(
        (rh / wh - 1.0).abs() < 0.05,
        "horizontal RMSE {rh} m against {wh} m"
    );
    assert!(
        (rv / wv - 1.0).abs() < 0.05,
        "vertical RMSE {rv} m against {wv} m"
    );

    // the unknown boresight: each point lies at its range along the recorded beam, r × 0.05°
    // (the chord, 2 r sin 0.025°) from where the flown beam met the plane
    let turned = points_by_return(&dir.join("boresight"));
    let turned_plan = plan("boresight");
    assert_eq!(turned.len(), clean.len());
    for q in turned.values() {
        let pulse = turned_plan.pulse(q.pulse_id);
        let r = (xyz(q) - pulse.rec_origin()).length();
        let hit = pulse.origin + pulse.direction * r;
        assert!(
            hit.z.abs() < 0.05,
            "pulse {}: the flown beam's point is {} m off the plane",
            q.pulse_id,
            hit.z
        );
        let shift = (xyz(q) - hit).length();
        let want = 2.0 * r * 0.025f64.to_radians().sin();
        assert!(
            (shift - want).abs() < 1e-3,
            "pulse {}: {shift} m against {want} m",
            q.pulse_id
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two strips flown in opposite directions 40 m apart over a plane 300 m below: without errors
/// their heights agree where they overlap (the range's own noise aside); with an unknown roll
/// boresight of 0.05° each strip's recorded plane tilts the other way, and report.md,
/// products.json and `compare` give the strips' height differences, whose RMS is the tilt's
/// (computed here from the geometry of every overlapping cell) with the noise added, within
/// 10 %.
#[test]
fn compare_reports_the_strips_height_differences() {
    let dir = tmp("survey_strips");
    let plane = plane_scene(&dir, 0.3, 400.0);
    let h = 300.0;
    let lines = format!(
        "altitude_m: {h}, speed_m_s: 60, lines: [{{ start: [-40, 0], end: [40, 0] }}, {{ start: [40, 40], end: [-40, 40] }}]"
    );
    for (name, errors) in [
        ("clean", ""),
        ("tilted", ", errors: { boresight_deg: [0.05, 0, 0] }"),
    ] {
        let c = write(
            &dir,
            &format!("{name}.yaml"),
            &survey(&plane, &format!("{lines}{errors}"), 1),
        );
        run_cli(&c, &dir.join(name), None);
    }
    let strips = |name: &str| {
        let text = std::fs::read_to_string(dir.join(name).join("products.json")).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        v["strips"].clone()
    };
    let (clean, tilted) = (strips("clean"), strips("tilted"));
    let pair = |s: &serde_json::Value| s["pairs"][0].clone();
    assert_eq!(
        (pair(&clean)["a"].as_u64(), pair(&clean)["b"].as_u64()),
        (Some(1), Some(2))
    );
    let cells = pair(&tilted)["cells"].as_u64().unwrap();
    assert!(cells > 1000, "{cells} cells");
    let noise = pair(&clean)["rms_dz_m"].as_f64().unwrap();
    assert!(noise < 0.02, "{clean}");
    assert!(
        pair(&clean)["mean_dz_m"].as_f64().unwrap().abs() < 0.005,
        "{clean}"
    );

    // the tilt: a beam flown at θ + δ meets the plane at its range H / cos(θ + δ), recorded
    // along θ: across H sin θ / cos(θ + δ) (right of the track), height H (1 − cos θ / cos(θ + δ))
    let delta = 0.05f64.to_radians();
    let height_at = |across: f64| {
        let (mut lo, mut hi) = (-0.5f64, 0.5f64);
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if h * mid.sin() / (mid + delta).cos() < across {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        h * (1.0 - lo.cos() / (lo + delta).cos())
    };
    // strip 1 flies +x along y = 0 (right is −y), strip 2 flies −x along y = 40 (right is +y);
    // the overlapping cells lie between the swaths' edges, 300 tan 15° = 80.4 m from each track
    let half = h * 15f64.to_radians().tan();
    let (mut sq, mut n) = (0.0, 0.0);
    for y in ((40.0 - half).ceil() as i64)..(half.floor() as i64) {
        let yc = y as f64 + 0.5;
        let dz = height_at(yc - 40.0) - height_at(-yc);
        sq += dz * dz;
        n += 1.0;
    }
    let tilt = (sq / n).sqrt();
    let want = (tilt * tilt + noise * noise).sqrt();
    let got = pair(&tilted)["rms_dz_m"].as_f64().unwrap();
    eprintln!("strips: RMS dz {got:.4} m with the boresight, {noise:.4} m without; the tilt alone {tilt:.4} m");
    assert!(
        (got / want - 1.0).abs() < 0.1,
        "RMS dz {got} m against {want} m"
    );

    let report = std::fs::read_to_string(dir.join("tilted/report.md")).unwrap();
    assert!(
        report.contains("## Strip-to-strip height differences"),
        "{report}"
    );
    let csv = dir.join("compare.csv");
    let (code, out, err) = lidarsim(&[
        "compare",
        dir.join("clean").to_str().unwrap(),
        dir.join("tilted").to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("strip RMS dz m"), "{out}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let row: Vec<&str> = text.lines().nth(2).unwrap().split(',').collect();
    let at = header.iter().position(|c| *c == "strip_rms_dz_m").unwrap();
    assert!(
        (row[at].parse::<f64>().unwrap() - got).abs() < 1e-9,
        "{text}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
