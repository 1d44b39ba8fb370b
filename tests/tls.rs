//! Terrestrial scans from several stations, and the receiver's near-field overlap: what a
//! TLS user meets first (a scan from a tripod a metre or two over the ground).

mod common;
use common::*;
use lidarsim::products::points::las::read_las;

/// A TLS campaign over `plane.yaml`: a full turn in 4° steps, zenith 100°-150.5° in 0.5°
/// steps (90 x 102 = 9,180 pulses per station), discrete returns.
fn tls_campaign(stations: &str, fov_mrad: f64) -> String {
    format!(
        "name: tls\nscene: plane.yaml\nseed: 4\nwavelength_nm: 1064\ninstrument: {{ kind: discrete_return, pulse_energy_j: 1.0e-6, pulse_fwhm_ns: 2, footprint_half_angle_mrad: 0.2, fov_half_angle_mrad: {fov_mrad}, receiver_area_m2: 0.005, bin_ns: 0.25 }}\nplatform: {{ kind: tls, {stations}, azimuth_deg: [0, 360], azimuth_step_deg: 4, zenith_deg: [100, 150.5], zenith_step_deg: 0.5 }}\nsimulation: {{ method: forward, rays_per_pulse: 16, max_order: 1 }}\nproducts: {{ points: true }}\n"
    )
}

/// The scan from 1.5 m over a plane: with a 0.3 mrad field of view behind a 0.005 m²
/// aperture, less than 1 % of the aperture sees the spot at any range the scan meets (0.45 mm
/// of view against a 40 mm aperture radius at 1.5 m), and `check` and the run log say so;
/// with 20 mrad, no warning, and every pulse gives its point where its ray meets the plane.
#[test]
fn a_tripod_scan_warns_of_near_field_overlap() {
    let dir = tmp("tls_overlap");
    plane_scene(&dir, 0.3, 60.0);
    let narrow = write(
        &dir,
        "narrow.yaml",
        &tls_campaign("position: [0, 0, 1.5]", 0.3),
    );
    let (code, out, err) = lidarsim(&["check", narrow.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("near-field overlap"), "{out}");
    let log = run_cli(&narrow, &dir.join("narrow"), None);
    assert!(log.contains("near-field overlap"), "{log}");
    let few = read_las(&dir.join("narrow/points.las")).unwrap();
    assert!(few.len() < 9_180 / 10, "{} points", few.len());

    let wide = write(
        &dir,
        "wide.yaml",
        &tls_campaign("position: [0, 0, 1.5]", 20.0),
    );
    let (code, out, err) = lidarsim(&["check", wide.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(!out.contains("near-field overlap"), "{out}");
    let log = run_cli(&wide, &dir.join("wide"), None);
    assert!(!log.contains("near-field overlap"), "{log}");
    let points = read_las(&dir.join("wide/points.las")).unwrap();
    assert_eq!(points.len(), 9_180);
    let loaded = lidarsim::plan::read_campaign(&wide).unwrap();
    let plan = lidarsim::plan::Plan::new(&loaded.campaign).unwrap();
    for p in &points {
        let pulse = plan.pulse(p.pulse_id);
        let t = -pulse.origin.z / pulse.direction.z;
        let hit = pulse.origin + pulse.direction * t;
        let d = glam::DVec3::new(p.x, p.y, p.z) - hit;
        assert!(
            d.length() < 0.005,
            "pulse {}: {} m off",
            p.pulse_id,
            d.length()
        );
    }
}

/// Two stations over the small forest: both scanned, every point's source id its station's
/// index (0 and 1), and at least 99 % of the points within 5 cm of a surface.
#[test]
fn two_stations_scan_one_scene() {
    let dir = tmp("tls_two");
    let forest = lidarsim::testdata::repo().join("scenes/small_forest/forest.yaml");
    let camp = tls_campaign("positions: [[12, 12, 1.5], [28, 28, 1.5]]", 5.0)
        .replace("scene: plane.yaml", &format!("scene: {}", forest.display()))
        .replace(
            "zenith_deg: [100, 150.5], zenith_step_deg: 0.5",
            "zenith_deg: [40, 130], zenith_step_deg: 2",
        );
    let camp = write(&dir, "c.yaml", &camp);
    run_cli(&camp, &dir.join("run"), None);
    let points = read_las(&dir.join("run/points.las")).unwrap();
    let mut by_source = [0usize; 2];
    for p in &points {
        assert!(p.point_source_id < 2, "{}", p.point_source_id);
        by_source[p.point_source_id as usize] += 1;
        // the station's pulses come first, then the other's: 90 x 46 each
        assert_eq!(p.point_source_id as u64, p.pulse_id / (90 * 46));
    }
    assert!(by_source.iter().all(|&n| n > 1000), "{by_source:?}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run/products.json")).unwrap())
            .unwrap();
    let within = summary["surface_distance"]["within_5cm"].as_f64().unwrap();
    assert!(within >= 0.99, "{within}");
}

/// A station placed beside the scene (a position in other units or another frame): every
/// beam misses it, and `check` and the run log say so, naming where the beams leave from and
/// where the scene lies; a station over the scene is not warned of.
#[test]
fn a_scan_that_misses_the_scene_is_warned_of() {
    let dir = tmp("tls_miss");
    plane_scene(&dir, 0.3, 60.0);
    let away = write(
        &dir,
        "away.yaml",
        &tls_campaign("position: [5000, 0, 1.5]", 20.0),
    );
    let (code, out, err) = lidarsim(&["check", away.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("none of")
            && out.contains("x 5000.0 to 5000.0")
            && out.contains("meets the scene"),
        "{out}"
    );
    let log = run_cli(&away, &dir.join("away"), None);
    assert!(log.contains("none of"), "{log}");
    let over = write(
        &dir,
        "over.yaml",
        &tls_campaign("position: [0, 0, 1.5]", 20.0),
    );
    let (code, out, err) = lidarsim(&["check", over.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(!out.contains("none of"), "{out}");
    // 4,096 scan lines of 100 pulses: every 100th pulse is the -30° edge, which misses the
    // plane from 300 m; the sample must not see that edge alone (a third of the pulses hit)
    let edge = write(
        &dir,
        "edge.yaml",
        "name: edge
scene: plane.yaml
seed: 1
wavelength_nm: 1064
instrument: { kind: discrete_return, pulse_energy_j: 1.0e-4, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.25, fov_half_angle_mrad: 0.375, receiver_area_m2: 0.01, bin_ns: 0.5 }
platform: { kind: als, altitude_m: 300, speed_m_s: 1.46484375, prf_hz: 10000, lines: [ { start: [0, -30], end: [0, 30] } ], scanner: { pattern: line, scan_angle_deg: [-30, 30], scan_frequency_hz: 100 } }
simulation: { method: forward, rays_per_pulse: 1, max_order: 1 }
",
    );
    let (code, out, err) = lidarsim(&["check", edge.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("pulses: 409600"), "{out}");
    assert!(!out.contains("none of"), "{out}");
}
