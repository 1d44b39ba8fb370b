use super::*;
use crate::campaign::Doc;
use crate::testdata::TempDir;
use std::path::PathBuf;

const HEAD: &str = "name: t
scene: plane.yaml
wavelength_nm: 1064
instrument: { pulse_energy_j: 0.001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.25,
              fov_half_angle_mrad: 0.375, receiver_area_m2: 0.1 }
";

/// A campaign text with `platform` appended to a fixed head (the platform starts on line 6).
fn text(platform: &str) -> String {
    format!("{HEAD}{platform}")
}

fn campaign(platform: &str) -> Campaign {
    serde_yaml::from_str::<Campaign>(&text(platform)).expect("test campaign parses")
}

fn pulses(platform: &str) -> Vec<Pulse> {
    let c = campaign(platform);
    validate(platform).expect("test campaign validates");
    plan(&c).unwrap()
}

fn validate(platform: &str) -> Result<()> {
    let doc = Doc {
        path: PathBuf::from("campaign.yaml"),
        text: text(platform),
    };
    // as a run reads it: parsed with located errors, then checked
    let campaign: Campaign = doc.parse()?;
    super::check_campaign(&doc, &campaign)
}

fn error(platform: &str) -> String {
    validate(platform)
        .expect_err("campaign must be rejected")
        .to_string()
}

fn close(a: DVec3, b: DVec3) -> bool {
    (a - b).length() < 1e-9
}

fn approx(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * (1.0 + b.abs())
}

fn assert_ids_and_times(p: &[Pulse]) {
    for (k, w) in p.windows(2).enumerate() {
        assert_eq!(w[0].id, k as u64);
        assert!(w[1].gps_time_s >= w[0].gps_time_s, "time goes back at {k}");
    }
    for q in p {
        assert!((q.direction.length() - 1.0).abs() < 1e-12);
    }
}

const PAPER_ALS: &str = "platform:
  kind: als
  altitude_m: 250
  speed_m_s: 4.444444444444445
  prf_hz: 100000
  lines: [ { start: [1, 50], end: [99, 50] } ]
  scanner: { pattern: line, scan_angle_deg: [-11.0894, 11.0894],
             look_angle_step_deg: 0.045, along_track_step_m: 0.3 }
";

#[test]
fn als_paper_count_is_160392() {
    // ⌊98 / 0.3⌋ = ⌊326.67⌋ = 326 scan lines; ⌊2·11.0894 / 0.045⌋ = ⌊492.86⌋ = 492 pulses per
    // line (11.0894° = atan(49/250): the 98 m swath seen from 250 m); 326 · 492 = 160,392.
    let start = std::time::Instant::now();
    let p = pulses(PAPER_ALS);
    assert!(start.elapsed().as_secs_f64() < 1.0);
    assert_eq!(p.len(), 160_392);
    assert_ids_and_times(&p);
    // The paper's rounded ±11.1° would give ⌊22.2/0.045⌋ = 493 per line, 160,718 pulses.
    let rounded = PAPER_ALS.replace("11.0894", "11.1");
    assert_eq!(count(&campaign(&rounded).platform).unwrap(), 326 * 493);
    // Ground swath: flying +x, positive angles look right = −y, so the sweep runs from
    // y = 50 + 250·tan(11.0894°) = 99.0 down towards y = 1.4.
    let q = p[0];
    let hit = q.origin + q.direction * (q.origin.z / -q.direction.z);
    assert!((hit.y - 99.0).abs() < 1e-3 && (hit.x - 1.0).abs() < 1e-12);
    // Every origin on the flight line: the last one is 326 − 1/492 lines in.
    let last = p[p.len() - 1];
    assert!(approx(last.origin.x, 1.0 + 0.3 * (326.0 - 1.0 / 492.0)));
    assert!(last.origin.x <= 99.0);
}

#[test]
fn als_line_pattern_hand_computed() {
    // d = 0.5 m given; δ derived = range · lines/s / prf = 20° · (10/0.5) / 100 = 4°,
    // so ⌊20/4⌋ = 5 angles per line: −10, −6, −2, 2, 6. Line 0 to (10, 0) along +x holds
    // ⌊10/0.5⌋ = 20 scan lines → 100 pulses; a scan line lasts 0.5/10 = 0.05 s, so pulses are
    // 0.01 s apart (effective rate 100 Hz = prf, since prf / lines-per-s = 5 is whole).
    let p = pulses(
        "platform: { kind: als, altitude_m: 100, speed_m_s: 10, prf_hz: 100, gps_start_s: 5,
  lines: [ { start: [0, 0], end: [10, 0] }, { start: [10, 20], end: [0, 20] } ],
  scanner: { pattern: line, scan_angle_deg: [-10, 10], along_track_step_m: 0.5 } }
",
    );
    assert_eq!(p.len(), 200);
    assert_ids_and_times(&p);
    let angles: Vec<f32> = p[..6].iter().map(|q| q.scan_angle_deg).collect();
    assert_eq!(angles, [-10.0, -6.0, -2.0, 2.0, 6.0, -10.0]);
    // First pulse: origin (0, 0, 100); right of +x is −y, θ = −10° looks left (+y):
    // direction (0, sin 10°, −cos 10°).
    let r = 10f64.to_radians();
    assert!(close(p[0].origin, DVec3::new(0.0, 0.0, 100.0)));
    assert!(close(p[0].direction, DVec3::new(0.0, r.sin(), -r.cos())));
    assert!(approx(p[0].gps_time_s, 5.0));
    // Pulse 3 (θ = 2°): 3/5 of a scan line flown, x = 0.3, t = 5 + 0.03.
    assert!(close(p[3].origin, DVec3::new(0.3, 0.0, 100.0)));
    assert!(approx(p[3].gps_time_s, 5.03));
    // Last pulse of line 0: scan line 19, i = 4: x = 0.5·(19 + 4/5) = 9.9, t = 5 + 0.99.
    assert!(close(p[99].origin, DVec3::new(9.9, 0.0, 100.0)));
    assert!(approx(p[99].gps_time_s, 5.99));
    // Line 1 flies −x: right is +y. The platform finishes line 0 at t = 5 + 1, transits 20 m
    // (2 s) and starts at t = 8, from (10, 20).
    assert_eq!(p[100].line, 1);
    assert!(approx(p[100].gps_time_s, 8.0));
    assert!(close(p[100].origin, DVec3::new(10.0, 20.0, 100.0)));
    assert!(close(p[100].direction, DVec3::new(0.0, -r.sin(), -r.cos())));
    // Last: θ = 6° to the right (+y), x = 10 − 9.9.
    let (s6, c6) = 6f64.to_radians().sin_cos();
    assert!(close(p[199].origin, DVec3::new(0.1, 20.0, 100.0)));
    assert!(close(p[199].direction, DVec3::new(0.0, s6, -c6)));
    assert!(approx(p[199].gps_time_s, 8.99));
    for q in &p {
        assert!((-10.0..=10.0).contains(&q.scan_angle_deg));
        assert!(approx(
            off_nadir_deg(q.direction),
            q.scan_angle_deg.abs() as f64
        ));
    }
}

#[test]
fn als_oscillating_goes_back_and_forth() {
    // scan_frequency 5 Hz → 10 scan lines/s, d = 20 / 10 = 2 m; δ = 30° · 10 / 100 = 3°,
    // ⌊30/3⌋ = 10 per line; line of 20 m → 10 scan lines → 100 pulses, t = k / 100.
    let p = pulses(
        "platform: { kind: als, altitude_m: 50, speed_m_s: 20, prf_hz: 100,
  lines: [ { start: [0, 0], end: [0, 20] } ],
  scanner: { pattern: oscillating, scan_angle_deg: [-15, 15], scan_frequency_hz: 5 } }
",
    );
    assert_eq!(p.len(), 100);
    assert_ids_and_times(&p);
    let a: Vec<f32> = p[8..12].iter().map(|q| q.scan_angle_deg).collect();
    // End of the forward sweep −15 + 9·3 = 12, then back from 15.
    assert_eq!(a, [9.0, 12.0, 15.0, 12.0]);
    for (k, q) in p.iter().enumerate() {
        assert!(approx(q.gps_time_s, k as f64 / 100.0));
        assert!((-15.0..=15.0).contains(&q.scan_angle_deg));
    }
    // Flying +y, right is +x: θ = −15° looks towards −x.
    let (s, c) = 15f64.to_radians().sin_cos();
    assert!(close(p[0].direction, DVec3::new(-s, 0.0, -c)));
    // Last pulse, backward sweep i = 9: 15 − 27 = −12°, y = 2·(9 + 9/10) = 19.8.
    assert_eq!(p[99].scan_angle_deg, -12.0);
    assert!(close(p[99].origin, DVec3::new(0.0, 19.8, 50.0)));
}

/// A sample of a plan takes one pulse from each equal stratum, the same for the same seed,
/// and does not alias with the scan: here every stratum is 2 whole scan periods of 20 pulses,
/// so the first pulse of each would always be the scan's first angle.
#[test]
fn spread_takes_one_pulse_per_stratum_whatever_the_scan() {
    let c = campaign(
        "platform: { kind: als, altitude_m: 50, speed_m_s: 20, prf_hz: 100,
  lines: [ { start: [0, 0], end: [0, 20] } ],
  scanner: { pattern: oscillating, scan_angle_deg: [-15, 15], scan_frequency_hz: 5 } }
",
    );
    let plan = Plan::new(&c).unwrap();
    assert_eq!(plan.len(), 100);
    let sample = plan.spread(5, 7);
    let ids: Vec<u64> = sample.iter().map(|p| p.id).collect();
    for (k, &id) in ids.iter().enumerate() {
        assert!(
            (20 * k as u64..20 * (k as u64 + 1)).contains(&id),
            "{ids:?}"
        );
    }
    let angles: std::collections::BTreeSet<i32> =
        sample.iter().map(|p| p.scan_angle_deg as i32).collect();
    assert!(angles.len() > 1, "{ids:?}");
    assert_eq!(
        ids,
        plan.spread(5, 7).iter().map(|p| p.id).collect::<Vec<_>>()
    );
    assert_ne!(
        ids,
        plan.spread(5, 8).iter().map(|p| p.id).collect::<Vec<_>>()
    );
    assert_eq!(plan.spread(500, 7).len(), 100);
}

#[test]
fn als_conic_turns_on_the_cone() {
    // Cone 20° = max(|−5|, |20|). δ = 360° · 2 / 8 = 90° → 4 pulses per turn: ahead, right,
    // behind, left. d = 4 / 2 = 2 m; line of 4 m → 2 turns.
    let p = pulses(
        "platform: { kind: als, altitude_m: 10, speed_m_s: 4, prf_hz: 8,
  lines: [ { start: [0, 0], end: [4, 0] } ],
  scanner: { pattern: conic, scan_angle_deg: [-5, 20], scan_frequency_hz: 2 } }
",
    );
    assert_eq!(p.len(), 8);
    let (s, c) = 20f64.to_radians().sin_cos();
    assert!(close(p[0].direction, DVec3::new(s, 0.0, -c)));
    assert!(close(p[1].direction, DVec3::new(0.0, -s, -c)));
    assert!(close(p[2].direction, DVec3::new(-s, 0.0, -c)));
    assert!(close(p[3].direction, DVec3::new(0.0, s, -c)));
    assert!(close(p[7].origin, DVec3::new(3.5, 0.0, 10.0)));
    assert!(approx(p[7].gps_time_s, 7.0 / 8.0));
    assert!(p.iter().all(|q| q.scan_angle_deg == 20.0));
}

#[test]
fn spaceborne_hand_computed() {
    // Shot spacing 7200 / 240 = 30 m; track (50,0)→(50,100) holds shots at 0, 30, 60, 90 m
    // (inclusive rule, 100/30 = 3.3 → 4 shots), two beams → 8 pulses, shot-major.
    // Flying +y, right is +x. Tilt 0.01° right: origin moved left (−x) by H·tan(0.01°).
    let p = pulses(
        "platform: { kind: spaceborne, altitude_m: 400000, ground_speed_m_s: 7200, prf_hz: 240,
  track: { start: [50, 0], end: [50, 100] }, beams: [ { cross_track_m: 0 }, { cross_track_m: 10 } ],
  off_nadir_deg: 0.01, gps_start_s: 100 }
",
    );
    assert_eq!(p.len(), 8);
    assert_ids_and_times(&p);
    let (s, c) = 0.01f64.to_radians().sin_cos();
    let shift = 400000.0 * s / c; // 69.81 m
    assert!(close(p[0].origin, DVec3::new(50.0 - shift, 0.0, 400000.0)));
    assert!(close(p[1].origin, DVec3::new(60.0 - shift, 0.0, 400000.0)));
    assert!(close(p[7].origin, DVec3::new(60.0 - shift, 90.0, 400000.0)));
    assert!(close(p[0].direction, DVec3::new(s, 0.0, -c)));
    assert_eq!((p[0].line, p[1].line, p[6].line), (0, 1, 0));
    assert!(approx(p[1].gps_time_s, 100.0));
    assert!(approx(p[7].gps_time_s, 100.0 + 3.0 / 240.0));
    assert!(p.iter().all(|q| q.scan_angle_deg == 0.01));
    // Footprint centres stay on the offset tracks.
    let hit = p[7].origin + p[7].direction * (p[7].origin.z / -p[7].direction.z);
    assert!((hit - DVec3::new(60.0, 90.0, 0.0)).length() < 1e-6);
    // A whole number of spacings includes the end: 90 m / 30 m → 4 shots, one beam default.
    let q = pulses(
        "platform: { kind: spaceborne, altitude_m: 400000, ground_speed_m_s: 7200, prf_hz: 240,
  track: { start: [0, 0], end: [90, 0] } }
",
    );
    assert_eq!(q.len(), 4);
    assert!(close(q[3].origin, DVec3::new(90.0, 0.0, 400000.0)));
    assert!(close(q[3].direction, DVec3::NEG_Z));
}

#[test]
fn track_mabel_count_is_6929() {
    // 98√2 / 0.02 = 6929.65: one shot per whole step gives 6929 (both ends would give 6930).
    let p = pulses(
        "platform: { kind: track, altitude_m: 20000, track: { start: [3, 3], end: [101, 101] },
  along_track_step_m: 0.02 }
",
    );
    assert_eq!(p.len(), 6929);
    assert_ids_and_times(&p);
    assert!(close(p[0].origin, DVec3::new(3.0, 3.0, 20000.0)));
    // Shot 6928 is 138.56 m along the diagonal: 3 + 138.56/√2 on each axis.
    let e = 3.0 + 6928.0 * 0.02 / 2f64.sqrt();
    assert!(close(p[6928].origin, DVec3::new(e, e, 20000.0)));
    assert!(p
        .iter()
        .all(|q| q.direction == DVec3::NEG_Z && q.scan_angle_deg == 0.0));
    // Default 1 kHz for times.
    assert!(approx(p[6928].gps_time_s, 6.928));
}

#[test]
fn track_whole_steps_with_rounding() {
    // 1.0 / 0.1 = 9.999999999999998 in f64: still 10 whole steps, shots at 0 .. 0.9.
    let p = pulses(
        "platform: { kind: track, altitude_m: 100, track: { start: [0, 0], end: [0, 1] },
  along_track_step_m: 0.1, prf_hz: 10 }
",
    );
    assert_eq!(p.len(), 10);
    assert!(close(p[9].origin, DVec3::new(0.0, 0.9, 100.0)));
    assert!(approx(p[9].gps_time_s, 0.9));
}

#[test]
fn tls_hand_computed() {
    // Azimuth [0, 360] by 90: 0, 90, 180, 270 (360 not repeated); zenith [30, 130] by 50:
    // 30, 80, 130 → 12 pulses, azimuth outer.
    let p = pulses(
        "platform: { kind: tls, position: [50, 50, 1.5], azimuth_deg: [0, 360], azimuth_step_deg: 90,
  zenith_deg: [30, 130], zenith_step_deg: 50, prf_hz: 4 }
",
    );
    assert_eq!(p.len(), 12);
    assert_ids_and_times(&p);
    let (s, c) = 30f64.to_radians().sin_cos();
    assert!(close(p[0].direction, DVec3::new(s, 0.0, c)));
    assert_eq!(p[0].scan_angle_deg, 30.0);
    // Pulse 11: azimuth 270 (−y), zenith 130.
    let (s, c) = 130f64.to_radians().sin_cos();
    assert!(close(p[11].direction, DVec3::new(0.0, -s, c)));
    assert_eq!(p[11].scan_angle_deg, 130.0);
    // LAS counts from nadir: a beam 40° below the horizon (zenith 130°) is 50° from it
    let tls = Plan::new(&campaign(
        "platform: { kind: tls, position: [50, 50, 1.5], azimuth_deg: [0, 360], azimuth_step_deg: 90,
  zenith_deg: [30, 130], zenith_step_deg: 50, prf_hz: 4 }
",
    ))
    .unwrap();
    assert!((tls.las_scan_angle(&p[11]) - 50.0).abs() < 1e-4);
    assert!((tls.las_scan_angle(&p[0]) - 150.0).abs() < 1e-4);
    assert!(p.iter().all(|q| q.origin == DVec3::new(50.0, 50.0, 1.5)));
    assert!(approx(p[11].gps_time_s, 11.0 / 4.0));
    // Spec example: 3600 azimuths · 1001 zeniths (100/0.1 = 1000.0000000000001 steps).
    let spec = campaign(
        "platform: { kind: tls, position: [50, 50, 1.5], azimuth_deg: [0, 360], azimuth_step_deg: 0.1,
  zenith_deg: [30, 130], zenith_step_deg: 0.1 }
",
    );
    assert_eq!(count(&spec.platform).unwrap(), 3600 * 1001);
    // A part turn keeps both ends: [10, 40] by 10 → 10, 20, 30, 40.
    let q = pulses(
        "platform: { kind: tls, position: [0, 0, 0], azimuth_deg: [10, 40], azimuth_step_deg: 10,
  zenith_deg: [90, 90], zenith_step_deg: 1 }
",
    );
    assert_eq!(q.len(), 4);
    assert!(close(q[3].direction, direction_from_angles(90.0, 40.0)));
}

#[test]
fn validation_errors_are_located() {
    // Line 6 is `platform:`; in `platform: { ...` the value starts at column 11.
    let e = error("platform: { kind: als, speed_m_s: 4, prf_hz: 10, lines: [ { start: [0, 0], end: [1, 0] } ],
  scanner: { pattern: line, scan_angle_deg: [-1, 1], scan_frequency_hz: 1 } }
");
    assert_eq!(
        e,
        "campaign.yaml:6:11: platform: an als platform needs altitude_m"
    );

    let e = error(
        "platform:
  kind: als
  altitude_m: 100
  speed_m_s: 4
  prf_hz: 10
  lines:
    - { start: [0, 0], end: [10, 0] }
    - { start: [0, 5], end: [0, 5] }
  scanner: { pattern: line, scan_angle_deg: [-1, 1], scan_frequency_hz: 1 }
",
    );
    assert!(e.starts_with("campaign.yaml:13:"), "{e}");
    assert!(
        e.contains("platform.lines[1].end: must differ from start"),
        "{e}"
    );

    let e = error(
        "platform:
  kind: als
  altitude_m: 100
  speed_m_s: 4
  prf_hz: 10
  lines: [ { start: [0, 0], end: [10, 0] } ]
  scanner:
    pattern: zigzag
    scan_angle_deg: [-1, 1]
    scan_frequency_hz: 1
",
    );
    assert!(e.starts_with("campaign.yaml:13:"), "{e}");
    assert!(
        e.contains("platform.scanner.pattern: unknown variant `zigzag`, expected one of `oscillating`, `line`, `conic`"),
        "{e}"
    );

    let e = error(
        "platform:
  kind: als
  altitude_m: 100
  speed_m_s: 4
  prf_hz: 10
  lines: [ { start: [0, 0], end: [10, 0] } ]
  scanner:
    pattern: line
    scan_angle_deg: [5, -5]
    scan_frequency_hz: 1
",
    );
    assert!(e.starts_with("campaign.yaml:14:"), "{e}");
    assert!(
        e.contains("platform.scanner.scan_angle_deg: must be [min, max] with min < max"),
        "{e}"
    );

    let e = error(
        "platform:
  kind: track
  altitude_m: 100
  track: { start: [0, 0], end: [10, 0] }
  along_track_step_m: 1
  speed_m_s: 3
",
    );
    assert!(e.starts_with("campaign.yaml:11:"), "{e}");
    assert!(
        e.contains("platform.speed_m_s: not used by a track platform"),
        "{e}"
    );

    let e = error(
        "platform:
  kind: tls
  position: [0, 0, 1]
  azimuth_deg: [0, 360]
  azimuth_step_deg: 1
  zenith_deg: [30, 190]
  zenith_step_deg: 1
",
    );
    assert!(e.starts_with("campaign.yaml:11:"), "{e}");
    assert!(
        e.contains("platform.zenith_deg: zenith angles must lie within [0, 180]"),
        "{e}"
    );

    let e = error(
        "platform:
  kind: spaceborne
  altitude_m: -5
  ground_speed_m_s: 7000
  prf_hz: 242
  track: { start: [0, 0], end: [10, 0] }
",
    );
    assert!(e.starts_with("campaign.yaml:8:"), "{e}");
    assert!(
        e.contains("platform.altitude_m: must be positive, found -5"),
        "{e}"
    );

    // 1e6 m at 1e-3 m steps: 1e9 pulses.
    let e = error(
        "platform: { kind: track, altitude_m: 100, track: { start: [0, 0], end: [1000000, 0] },
  along_track_step_m: 0.001 }
",
    );
    assert!(
        e.contains(
            "platform: the platform plans 1000000000 pulses, more than the limit of 500000000"
        ),
        "{e}"
    );

    let e = error(
        "platform: { kind: track, altitude_m: 100, track: { start: [0, 0], end: [1, 0] },
  along_track_step_m: 2 }
",
    );
    assert!(
        e.contains("platform.along_track_step_m: 2 m is longer than the track"),
        "{e}"
    );

    let e = error("platform: { kind: als, altitude_m: 100, speed_m_s: 4, lines: [ { start: [0, 0], end: [1, 0] } ],
  scanner: { pattern: line, scan_angle_deg: [-1, 1], scan_frequency_hz: 1 } }
");
    assert!(
        e.contains("an als platform needs prf_hz unless scanner.look_angle_step_deg is given"),
        "{e}"
    );
}

#[test]
fn spec_examples_validate() {
    // The four platform examples of the contract (campaign.md) are accepted as written.
    for platform in [
        "platform: { kind: als, altitude_m: 250, speed_m_s: 4.44, prf_hz: 100000,
            lines: [ { start: [0, 1], end: [98, 1] } ],
            scanner: { pattern: oscillating, scan_angle_deg: [-11.1, 11.1], scan_frequency_hz: 75,
                       look_angle_step_deg: 0.045, along_track_step_m: 0.3 } }
",
        "platform: { kind: spaceborne, altitude_m: 419000, ground_speed_m_s: 7200, prf_hz: 242,
            track: { start: [50, 0], end: [50, 100] }, beams: [ { cross_track_m: 0 } ],
            off_nadir_deg: 0 }
",
        "platform: { kind: track, altitude_m: 20000, track: { start: [3, 3], end: [101, 101] },
            along_track_step_m: 0.02 }
",
        "platform: { kind: tls, position: [50, 50, 1.5],
            azimuth_deg: [0, 360], azimuth_step_deg: 0.1,
            zenith_deg: [30, 130], zenith_step_deg: 0.1 }
",
    ] {
        validate(platform).unwrap_or_else(|e| panic!("{e}\n{platform}"));
    }
}

#[test]
fn als_paper_campaign_file_plans_160392() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines/als_paper.yaml");
    let doc = Doc::read(&path).unwrap();
    let c: Campaign = doc.parse().unwrap();
    super::check_campaign(&doc, &c).unwrap();
    assert_eq!(plan(&c).unwrap().len(), 160_392);
}

/// The platform frame: x along track, y left, z up; a track flown towards +y has its left
/// towards -x, and every planner gives a unit horizontal direction of travel.
#[test]
fn platform_frame_points_along_track_and_left() {
    let mut p = Pulse {
        id: 0,
        gps_time_s: 0.0,
        origin: DVec3::ZERO,
        direction: DVec3::NEG_Z,
        scan_angle_deg: 0.0,
        line: 0,
        along: DVec3::X,
        up: DVec3::Z,
        recorded: None,
    };
    assert_eq!(
        p.platform_to_scene([1.0, 2.0, 3.0]),
        DVec3::new(1.0, 2.0, 3.0)
    );
    p.along = DVec3::Y;
    assert_eq!(
        p.platform_to_scene([1.0, 2.0, 3.0]),
        DVec3::new(-2.0, 1.0, 3.0)
    );
    let along = pulses(
        "platform: { kind: track, altitude_m: 500, track: { start: [0, 0], end: [-30, 40] }, along_track_step_m: 5 }\n",
    )[3]
    .along;
    assert!(
        (along - DVec3::new(-0.6, 0.8, 0.0)).length() < 1e-12,
        "{along}"
    );
}

/// The angle between two unit vectors, radians (acos loses digits near 0: atan2 of the cross
/// and dot products keeps them).
fn angle_between(a: DVec3, b: DVec3) -> f64 {
    a.cross(b).length().atan2(a.dot(b))
}

/// A rotating polygon: a sawtooth of the look angle against time, min + (max − min) frac(f t),
/// firing only in the first `duty` of each line (here 0.75 of P = 40 pulses: 30 a line).
#[test]
fn rotating_polygon_is_a_sawtooth_with_its_duty() {
    let p = pulses(
        "platform: { kind: als, altitude_m: 100, speed_m_s: 10, prf_hz: 4000, lines: [ { start: [0, 0], end: [10, 0] } ],
            scanner: { pattern: rotating_polygon, facets: 4, scan_angle_deg: [-30, 30], scan_frequency_hz: 100, duty: 0.75 } }",
    );
    assert_ids_and_times(&p);
    // 10 m at 10 m/s: 100 lines of 30 pulses
    assert_eq!(p.len(), 100 * 30);
    for q in &p {
        let u = (q.gps_time_s * 100.0).fract();
        let u = if u > 1.0 - 1e-9 { 0.0 } else { u };
        assert!(u < 0.75 + 1e-9, "pulse {} at phase {u}", q.id);
        let want = -30.0 + 60.0 * u;
        assert!(
            (q.scan_angle_deg as f64 - want).abs() < 1e-4,
            "pulse {}",
            q.id
        );
        // the beam across track at that angle, flying +x: right is −y
        let t = want.to_radians();
        let d = DVec3::new(0.0, -t.sin(), -t.cos());
        assert!(angle_between(q.direction, d) < 1e-9, "pulse {}", q.id);
    }
}

/// Risley prisms, paraxial: the off-nadir angle |d1 + d2| towards the body azimuth of
/// d1 + d2, d_i = dev_i (cos p_i, sin p_i), p_i = 360 rate_i t + phase_i, to 1e-9 rad.
#[test]
fn risley_prisms_add_their_deflections() {
    let p = pulses(
        "platform: { kind: als, altitude_m: 60, speed_m_s: 5, prf_hz: 2000, lines: [ { start: [0, 0], end: [0, 2] } ],
            scanner: { pattern: risley, prism_rates_hz: [120.0, -87.0], deviation_deg: [19.0, 19.0], phase_deg: [0, 30] } }",
    );
    assert_ids_and_times(&p);
    assert_eq!(p.len(), 800);
    // flying +y: body x = +y, body left = −x
    let (along, left) = (DVec3::Y, DVec3::NEG_X);
    for q in &p {
        let t = q.gps_time_s;
        assert!((t - q.id as f64 / 2000.0).abs() < 1e-12);
        let d = |rate: f64, phase: f64| {
            let a = (360.0 * rate * t + phase).to_radians();
            (19.0 * a.cos(), 19.0 * a.sin())
        };
        let (a, b) = (d(120.0, 0.0), d(-87.0, 30.0));
        let (x, y) = (a.0 + b.0, a.1 + b.1);
        let off = x.hypot(y).to_radians();
        let az = y.atan2(x);
        let want = (along * az.cos() + left * az.sin()) * off.sin() - DVec3::Z * off.cos();
        assert!(angle_between(q.direction, want) < 1e-9, "pulse {}", q.id);
        assert!((q.scan_angle_deg as f64 - x.hypot(y)).abs() < 1e-4);
    }
    // the rosette reaches both its centre and its rim
    let offs: Vec<f32> = p.iter().map(|q| q.scan_angle_deg).collect();
    assert!(offs.iter().cloned().fold(f32::MAX, f32::min) < 5.0);
    assert!(offs.iter().cloned().fold(0.0, f32::max) > 37.0);
}

/// LAS's scan angle of a rosette's and a cone's beams is signed across track, as LAS defines
/// it (from nadir, positive to the right of the direction of travel), not their unsigned
/// look angle off nadir: a beam ahead is 0°, one to the left negative.
#[test]
fn las_scan_angles_of_cones_and_rosettes_are_across_track() {
    for sc in [
        "scanner: { pattern: risley, prism_rates_hz: [120.0, -87.0], deviation_deg: [19.0, 19.0], phase_deg: [0, 30] }",
        "scanner: { pattern: conic, scan_angle_deg: [-12, 12], scan_frequency_hz: 20 }",
    ] {
        // flying +y: the right is +x
        let text = format!(
            "platform: {{ kind: als, altitude_m: 60, speed_m_s: 5, prf_hz: 2000, lines: [ {{ start: [0, 0], end: [0, 2] }} ], {sc} }}"
        );
        let plan = Plan::new(&campaign(&text)).unwrap();
        let p = plan.pulses(0..plan.len());
        let (mut left, mut right) = (0, 0);
        for q in &p {
            let las = plan.las_scan_angle(q) as f64;
            let want = q.direction.x.atan2(-q.direction.z).to_degrees();
            assert!((las - want).abs() < 1e-4, "{sc}: pulse {}: {las} against {want}", q.id);
            left += (want < -1.0) as usize;
            right += (want > 1.0) as usize;
        }
        assert!(left > p.len() / 5 && right > p.len() / 5, "{sc}: {left} left, {right} right");
    }
}

/// A multi-beam head: every firing gives one pulse per channel at once, each at its
/// elevation above the head's plane, the azimuth stepping 360 rotation / prf per firing
/// (counter-clockwise from body x); a head tilt rolls it about body x, right side down.
#[test]
fn multibeam_head_fires_its_channels_around() {
    for tilt in [0.0f64, 20.0] {
        let text = format!(
            "platform: {{ kind: als, altitude_m: 2, speed_m_s: 10, prf_hz: 1800, lines: [ {{ start: [0, 0], end: [1, 0] }} ],
                scanner: {{ pattern: multibeam, channels_deg: [-15, -5, 5, 15], rotation_hz: 10, head_tilt_deg: {tilt} }} }}"
        );
        let p = pulses(&text);
        let plan = Plan::new(&campaign(&text)).unwrap();
        assert_ids_and_times(&p);
        // 1 m at 10 m/s: 180 firings of 4 channels
        assert_eq!(p.len(), 180 * 4);
        let (sr, cr) = tilt.to_radians().sin_cos();
        // the head's axis and its zero azimuth, in the world (flying +x: left = +y)
        let axis = DVec3::new(0.0, -sr, cr);
        for q in &p {
            let (k, c) = (q.id / 4, (q.id % 4) as usize);
            assert_eq!(
                q.gps_time_s,
                p[4 * k as usize].gps_time_s,
                "channels fire at once"
            );
            let e = [-15.0f64, -5.0, 5.0, 15.0][c];
            assert_eq!(q.scan_angle_deg as f64, e);
            // elevation above the head's plane
            let elev = std::f64::consts::FRAC_PI_2 - angle_between(q.direction, axis);
            assert!((elev - e.to_radians()).abs() < 1e-9, "pulse {}", q.id);
            let phi = (360.0 * 10.0 * k as f64 / 1800.0).to_radians();
            let h = DVec3::new(
                e.to_radians().cos() * phi.cos(),
                e.to_radians().cos() * phi.sin(),
                e.to_radians().sin(),
            );
            let want = DVec3::new(h.x, h.y * cr - h.z * sr, h.y * sr + h.z * cr);
            assert!(angle_between(q.direction, want) < 1e-9, "pulse {}", q.id);
            // LAS's scan angle: from nadir across track (flying +x: right is -y), ±180° up;
            // a channel at the horizon looking right is 90°, not the elevation's 0
            let las = plan.las_scan_angle(q) as f64;
            let want = (-q.direction.y).atan2(-q.direction.z).to_degrees();
            // (+180° and −180° are both straight up)
            let off = (las - want + 180.0).rem_euclid(360.0) - 180.0;
            assert!(off.abs() < 1e-4, "pulse {}: {las} against {want}", q.id);
            if tilt == 0.0 && k == 135 && c == 2 {
                // azimuth 270°: to the right, 5° above the horizon
                assert!((las - 95.0).abs() < 1e-3, "{las}");
            }
        }
        // the azimuth step: 2 degrees between firings, about the head's axis
        let flat = |d: DVec3| d - axis * d.dot(axis);
        let step = angle_between(flat(p[0].direction), flat(p[4].direction));
        assert!((step - 2f64.to_radians()).abs() < 1e-9, "{step}");
    }
}

/// Keys of another pattern are refused by name, and a pattern's own missing keys too.
#[test]
fn scanner_keys_belong_to_their_pattern() {
    let e = error(
        "platform: { kind: als, altitude_m: 60, speed_m_s: 5, prf_hz: 2000, lines: [ { start: [0, 0], end: [0, 2] } ],
            scanner: { pattern: risley, prism_rates_hz: [1, 2], deviation_deg: [1, 1], scan_angle_deg: [-1, 1] } }",
    );
    assert!(
        e.contains("scan_angle_deg") && e.contains("not used by the risley pattern"),
        "{e}"
    );
    let e = error(
        "platform: { kind: als, altitude_m: 60, speed_m_s: 5, prf_hz: 2000, lines: [ { start: [0, 0], end: [0, 2] } ],
            scanner: { pattern: multibeam, channels_deg: [0] } }",
    );
    assert!(e.contains("needs rotation_hz"), "{e}");
    let e = error(
        "platform: { kind: als, altitude_m: 60, speed_m_s: 5, prf_hz: 2000, lines: [ { start: [0, 0], end: [0, 2] } ],
            scanner: { pattern: rotating_polygon, scan_angle_deg: [-30, 30], scan_frequency_hz: 100, duty: 1.5 } }",
    );
    assert!(e.contains("duty"), "{e}");
}

/// LAS's scan flags: an oscillating scan's lines alternate their direction (left to right on
/// even lines, growing angles) and its edge is the pulse at each turn (the first of every
/// line but the first, at the swath's edge); a line scan's all grow, the last pulse of every
/// line its edge; a conic scan has neither flag.
#[test]
fn scan_flags_follow_the_sweep() {
    let platform = |pattern: &str| {
        format!(
            "platform: {{ kind: als, altitude_m: 100, speed_m_s: 10, prf_hz: 2000, lines: [ {{ start: [0, 0], end: [2, 0] }} ],
                scanner: {{ pattern: {pattern}, scan_angle_deg: [-10, 10], scan_frequency_hz: 50 }} }}"
        )
    };
    for pattern in ["oscillating", "line", "conic"] {
        let c = campaign(&platform(pattern));
        let plan = Plan::new(&c).unwrap();
        let Source::Als(a) = &plan.platform else {
            panic!("an als plan")
        };
        let n = a.per_line;
        assert!(n > 2);
        let pulses = plan.pulses(0..plan.len());
        for q in &pulses {
            let (dir, edge) = plan.scan_flags(q.id);
            let (j, i) = (q.id / n, q.id % n);
            match pattern {
                "conic" => assert_eq!((dir, edge), (false, false)),
                _ => {
                    if pattern == "line" {
                        assert_eq!(edge, i + 1 == n, "pulse {}", q.id);
                    } else {
                        assert_eq!(edge, i == 0 && j > 0, "pulse {}", q.id);
                        if edge {
                            assert_eq!(q.scan_angle_deg.abs(), 10.0, "pulse {}", q.id);
                        }
                    }
                    let growing = pattern == "line" || j % 2 == 0;
                    assert_eq!(dir, growing, "pulse {}", q.id);
                    // the flag says which way the angle goes to the line's next pulse
                    if i + 1 < n {
                        let next = pulses[q.id as usize + 1].scan_angle_deg;
                        assert_eq!(next > q.scan_angle_deg, dir, "pulse {}", q.id);
                    }
                }
            }
        }
    }
}

/// A trajectory CSV flying from `from` to `to` (x, y) at height `z` with a constant attitude,
/// one epoch every `dt` seconds from GPS time `t0` to `t1`.
#[allow(clippy::too_many_arguments)]
fn trajectory_csv(
    dir: &TempDir,
    name: &str,
    (t0, t1, dt): (f64, f64, f64),
    from: [f64; 2],
    to: [f64; 2],
    z: f64,
    rph: [f64; 3],
) -> PathBuf {
    let mut s = String::from("time_s,x,y,z,roll_deg,pitch_deg,heading_deg,extra\n");
    let n = ((t1 - t0) / dt).round() as usize;
    for k in 0..=n {
        let u = k as f64 / n as f64;
        let x = from[0] + (to[0] - from[0]) * u;
        let y = from[1] + (to[1] - from[1]) * u;
        s += &format!(
            "{},{x},{y},{z},{},{},{},7\n",
            t0 + k as f64 * dt,
            rph[0],
            rph[1],
            rph[2]
        );
    }
    let p = dir.join(name);
    std::fs::write(&p, s).unwrap();
    p
}

/// A campaign in `dir`, loaded as a run loads it (its files resolved there), and its plan.
fn plan_in(dir: &TempDir, platform: &str) -> Result<Plan> {
    let doc = Doc {
        path: dir.join("campaign.yaml"),
        text: text(platform),
    };
    let mut campaign: Campaign = doc.parse()?;
    campaign.resolve_files(&doc);
    super::check_campaign(&doc, &campaign)?;
    Plan::new(&campaign)
}

const OSC: &str =
    "scanner: { pattern: oscillating, scan_angle_deg: [-20, 20], scan_frequency_hz: 25 }";

/// Straight level flight from a trajectory (at GPS times near 1.3e9 s, one epoch every 1/8 s,
/// times a GPS double holds exactly)
/// plans the `lines:` campaign's pulses: origins within 1e-6 m, directions within 1e-9 rad,
/// the same times and angles, for every scanner; along +x and along a diagonal.
#[test]
fn a_straight_level_trajectory_flies_the_lines_campaign() {
    let dir = TempDir::new("plan-straight");
    let scanners = [
        OSC.to_string(),
        "scanner: { pattern: line, scan_angle_deg: [-15, 15], scan_frequency_hz: 40 }".into(),
        "scanner: { pattern: rotating_polygon, scan_angle_deg: [-30, 30], scan_frequency_hz: 60, duty: 0.8 }".into(),
        "scanner: { pattern: conic, scan_angle_deg: [-10, 10], scan_frequency_hz: 20 }".into(),
        "scanner: { pattern: risley, prism_rates_hz: [120, -87], deviation_deg: [10, 10] }".into(),
        "scanner: { pattern: multibeam, channels_deg: [-15, 0, 15], rotation_hz: 10 }".into(),
    ];
    let t0 = 1.3e9;
    for (from, to) in [([0.0, 0.0], [200.0, 0.0]), ([10.0, -5.0], [130.0, 155.0])] {
        let length = DVec2::from_array(to).distance(DVec2::from_array(from));
        let (speed, z) = (50.0, 120.0);
        let heading = 90.0 - (to[1] - from[1]).atan2(to[0] - from[0]).to_degrees();
        let csv = trajectory_csv(
            &dir,
            "t.csv",
            (t0, t0 + length / speed, 0.125),
            from,
            to,
            z,
            [0.0, 0.0, heading],
        );
        for sc in &scanners {
            let lines = pulses(&format!(
                "platform: {{ kind: als, altitude_m: {z}, speed_m_s: {speed}, prf_hz: 9000, gps_start_s: {t0},
                    lines: [ {{ start: {from:?}, end: {to:?} }} ], {sc} }}"
            ));
            let plan = plan_in(
                &dir,
                &format!(
                    "platform: {{ kind: als, prf_hz: 9000, trajectory: {{ file: {} }}, {sc} }}",
                    csv.file_name().unwrap().to_str().unwrap()
                ),
            )
            .unwrap();
            let level = Plan::new(&campaign(&format!(
                "platform: {{ kind: als, altitude_m: {z}, speed_m_s: {speed}, prf_hz: 9000,
                    lines: [ {{ start: {from:?}, end: {to:?} }} ], {sc} }}"
            )))
            .unwrap();
            assert_eq!(plan.len(), lines.len(), "{sc}");
            assert!(lines.len() > 1000, "{sc}: {}", lines.len());
            for a in &lines {
                let b = plan.pulse(a.id);
                assert!((a.origin - b.origin).length() < 1e-6, "{sc} pulse {}", a.id);
                assert!(
                    angle_between(a.direction, b.direction) < 1e-9,
                    "{sc} pulse {}",
                    a.id
                );
                assert!((a.gps_time_s - b.gps_time_s).abs() < 1e-6, "{sc}");
                assert!((a.scan_angle_deg - b.scan_angle_deg).abs() < 1e-4, "{sc}");
                assert_eq!(a.line, b.line);
                assert_eq!(plan.scan_flags(a.id), level.scan_flags(a.id));
            }
        }
    }
}

/// Where a pulse's beam meets z = 0.
fn ground(p: &Pulse) -> DVec3 {
    p.origin + p.direction * (-p.origin.z / p.direction.z)
}

/// A constant roll of 5° (right wing down) moves the nadir beam's spot H tan 5° to the left,
/// and LAS's scan angle counts it; a heading of 30° flies the swath turned by 30°.
#[test]
fn roll_shifts_and_heading_turns_the_swath() {
    let dir = TempDir::new("plan-roll");
    let h = 300.0;
    let nadir = |p: &Plan| -> Vec<Pulse> {
        (0..p.len() as u64)
            .map(|i| p.pulse(i))
            .filter(|q| {
                let level = q.direction - q.up * q.direction.dot(q.up);
                level.dot(q.up.cross(q.along)).abs() < 1e-12 && level.dot(q.along).abs() < 1e-12
            })
            .collect()
    };
    let plat = |file: &str| {
        format!("platform: {{ kind: als, prf_hz: 10000, trajectory: {{ file: {file} }}, {OSC} }}")
    };
    trajectory_csv(
        &dir,
        "roll.csv",
        (0.0, 2.0, 0.5),
        [0.0, 0.0],
        [100.0, 0.0],
        h,
        [5.0, 0.0, 90.0],
    );
    let roll_plan = plan_in(&dir, &plat("roll.csv")).unwrap();
    let rolled = nadir(&roll_plan);
    assert!(rolled.len() > 10);
    for q in &rolled {
        // flying +x, left is +y
        let spot = ground(q);
        assert!(
            (spot.y - h * 5f64.to_radians().tan()).abs() < 1e-6,
            "{spot}"
        );
        // the look angle is the scanner's; LAS's counts from the scene's vertical
        assert!(q.scan_angle_deg.abs() < 1e-4, "{}", q.scan_angle_deg);
        let las = roll_plan.las_scan_angle(q);
        assert!((las + 5.0).abs() < 1e-4, "{las}");
    }
    // heading 30°: flying towards azimuth 30° from north, the swath across it
    let (s, c) = 30f64.to_radians().sin_cos();
    trajectory_csv(
        &dir,
        "turn.csv",
        (0.0, 2.0, 0.5),
        [0.0, 0.0],
        [100.0 * s, 100.0 * c],
        h,
        [0.0, 0.0, 30.0],
    );
    let plan = plan_in(&dir, &plat("turn.csv")).unwrap();
    let across = DVec3::new(c, -s, 0.0); // the right of the track
    for id in 0..plan.len() as u64 {
        let q = plan.pulse(id);
        let off = ground(&q) - q.origin.with_z(0.0);
        // every spot lies across the track, at its scan angle
        assert!(off.dot(DVec3::new(s, c, 0.0)).abs() < 1e-6, "pulse {id}");
        let theta = (q.scan_angle_deg as f64).to_radians();
        assert!(
            (off.dot(across) - h * theta.tan()).abs() < 1e-3,
            "pulse {id}"
        );
    }
}

/// A scan interval of whole scan lines keeps its last line at GPS times near 1.3e9 s, where
/// its ends' rounding makes its length a little short (1300000001.1 - 1300000001.0 is
/// 0.0999999 in f64): the same pulses as the same interval near 0 s, for every pattern.
#[test]
fn scan_intervals_near_gps_times_keep_their_last_line() {
    let dir = TempDir::new("plan-interval");
    let scanners = [
        "scanner: { pattern: oscillating, scan_angle_deg: [-20, 20], scan_frequency_hz: 20 }",
        "scanner: { pattern: rotating_polygon, scan_angle_deg: [-20, 20], scan_frequency_hz: 40 }",
        "scanner: { pattern: risley, prism_rates_hz: [120, -87], deviation_deg: [10, 10] }",
        "scanner: { pattern: multibeam, channels_deg: [-5, 5], rotation_hz: 10 }",
    ];
    for (t0, name) in [(1.3e9, "late.csv"), (0.0, "early.csv")] {
        trajectory_csv(
            &dir,
            name,
            (t0, t0 + 4.0, 0.125),
            [0.0, 50.0],
            [200.0, 50.0],
            300.0,
            [0.0; 3],
        );
    }
    for sc in scanners {
        let count = |file: &str, a: f64, b: f64| {
            let plat = format!(
                "platform: {{ kind: als, prf_hz: 2000, trajectory: {{ file: {file}, scan: [[{a}, {b}]] }}, {sc} }}"
            );
            plan_in(&dir, &plat).unwrap().len()
        };
        let early = count("early.csv", 1.0, 1.1);
        assert_eq!(count("late.csv", 1300000001.0, 1300000001.1), early, "{sc}");
        let lines = if sc.contains("multibeam") { 2 } else { 1 };
        assert_eq!(early, 200 * lines, "{sc}");
    }
}

/// A polygon's sweep may end past the horizon where its duty leaves that part unfired: ±30° at
/// duty 0.5 is [-30, 90]; a fired angle at 90° or beyond is refused, naming the key.
#[test]
fn a_polygon_fires_a_symmetric_swath_at_any_duty() {
    let plan = |sc: &str| {
        Plan::new(&campaign(&format!(
            "platform: {{ kind: als, altitude_m: 100, speed_m_s: 10, prf_hz: 4000, lines: [{{ start: [0, 0], end: [10, 0] }}], {sc} }}"
        )))
    };
    let p = plan("scanner: { pattern: rotating_polygon, scan_angle_deg: [-30, 90], scan_frequency_hz: 100, duty: 0.5 }").unwrap();
    let angles: Vec<f32> = p
        .pulses(0..p.len())
        .iter()
        .map(|q| q.scan_angle_deg)
        .collect();
    let (lo, hi) = angles
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    // 40 pulses a period, 20 fired, 3° apart: -30° to one step short of 30°
    assert!(lo == -30.0 && (hi - 27.0).abs() < 1e-4, "{lo} .. {hi}");
    assert_eq!(angles.len() % 20, 0);
    let doc = Doc {
        path: "campaign.yaml".into(),
        text: text("platform: { kind: als, altitude_m: 100, speed_m_s: 10, prf_hz: 4000, lines: [{ start: [0, 0], end: [10, 0] }], scanner: { pattern: rotating_polygon, scan_angle_deg: [-30, 150], scan_frequency_hz: 100, duty: 0.75 } }"),
    };
    let c: Campaign = doc.parse().unwrap();
    let e = super::check_campaign(&doc, &c).unwrap_err().to_string();
    assert!(
        e.contains("platform.scanner.scan_angle_deg") && e.contains("105"),
        "{e}"
    );
}

/// A trajectory longer than a block, read on demand in any order, gives the same pulses as in
/// order; and its errors name the CSV file, line and column.
#[test]
fn trajectory_files_stream_and_their_errors_are_located() {
    let dir = TempDir::new("plan-stream");
    // 2,001 epochs of a turning, climbing flight
    let mut s = String::from("heading_deg,time_s,x,y,z,roll_deg,pitch_deg\n");
    for k in 0..=2000 {
        let t = k as f64 * 0.01;
        let a = t * 0.5;
        s += &format!(
            "{},{t},{},{},{},{},{}\n",
            90.0 - a.to_degrees(),
            100.0 * a.sin(),
            100.0 * (1.0 - a.cos()),
            200.0 + t,
            10.0 * a.sin(),
            2.0
        );
    }
    std::fs::write(dir.join("turn.csv"), &s).unwrap();
    let plat = format!("platform: {{ kind: als, prf_hz: 2000, trajectory: {{ file: turn.csv, scan: [[1, 9], [11, 19.5]] }}, {OSC} }}");
    let plan = plan_in(&dir, &plat).unwrap();
    let all = plan.pulses(0..plan.len());
    assert_eq!(
        all.len(),
        (8.0 * 50.0) as usize * 40 + (8.5 * 50.0) as usize * 40
    );
    assert!(all
        .iter()
        .all(|p| (1.0..=19.5).contains(&(p.gps_time_s)) && !(9.0..11.0).contains(&p.gps_time_s)));
    assert_eq!(all.last().unwrap().line, 1);
    let fresh = plan_in(&dir, &plat).unwrap();
    for id in (0..all.len() as u64).rev().step_by(97) {
        assert_eq!(fresh.pulse(id), all[id as usize]);
    }
    // an epoch between two holds the interpolated attitude: roll 10 sin(t/2)
    let q = &all[1234];
    let t = q.gps_time_s;
    let up = q.up;
    let left = up.cross(q.along);
    let roll = left.z.atan2(up.z).to_degrees();
    assert!((roll - 10.0 * (t * 0.5).sin()).abs() < 1e-3, "{roll}");

    let bad = |name: &str, csv: &str| -> String {
        std::fs::write(dir.join(name), csv).unwrap();
        plan_in(
            &dir,
            &format!(
                "platform: {{ kind: als, prf_hz: 2000, trajectory: {{ file: {name} }}, {OSC} }}"
            ),
        )
        .err()
        .expect("refused")
        .to_string()
    };
    let e = bad("a.csv", "time_s,x,y,z,roll_deg,pitch_deg\n0,0,0,0,0,0\n");
    assert!(e.contains("a.csv") && e.contains("heading_deg"), "{e}");
    let e = bad(
        "b.csv",
        "time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n0,0,0,100,0,0,90\n1,5,0,1e,0,0,90\n",
    );
    assert!(e.contains("b.csv:3:7: z:"), "{e}");
    let e = bad(
        "c.csv",
        "time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n0,0,0,100,0,0,90\n0,5,0,100,0,0,90\n",
    );
    assert!(
        e.contains("c.csv:3") && e.contains("time_s") && e.contains("increase"),
        "{e}"
    );
    let e = bad(
        "d.csv",
        "time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n0,0,0,100,0,0,90\n",
    );
    assert!(e.contains("d.csv") && e.contains("two epochs"), "{e}");
    let e = bad(
        "e.csv",
        "time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n0,0,0,100,0,0,90\n1,5,0,100,0\n",
    );
    assert!(e.contains("e.csv:3") && e.contains("fields"), "{e}");
    // a time or a place beyond any flight, named where it stands
    let e = bad(
        "f.csv",
        "time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n0,0,0,100,0,0,90\n1e300,5,0,100,0,0,90\n",
    );
    assert!(e.contains("f.csv:3:1: time_s:"), "{e}");
    let e = bad(
        "g.csv",
        "time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n0,0,0,100,0,0,90\n1,1e300,0,100,0,0,90\n",
    );
    assert!(e.contains("g.csv:3:3: x:"), "{e}");
    let e = bad(
        "h.csv",
        "time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n0,0,0,100,0,0,90\n1,5,0,100,0,0,1e308\n",
    );
    assert!(
        e.contains("h.csv:3:15: heading_deg: must be an angle in degrees"),
        "{e}"
    );
    // a classic Mac OS export ends its lines in CR alone: said so, in one short line
    let rows: String = (0..2000).map(|k| format!("{k},0,0,100,0,0,90\r")).collect();
    let e = bad(
        "cr.csv",
        &format!("time_s,x,y,z,roll_deg,pitch_deg,heading_deg\r{rows}"),
    );
    assert!(
        e.contains("cr.csv:1:44") && e.contains("carriage return") && e.len() < 300,
        "{e}"
    );
    // a stray CR inside a field of a file whose lines end in LF is blank space
    let ok = "time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n0,0,0,100,0,0,90\n1,5,0\r,100,0,0,90\n";
    std::fs::write(dir.join("stray.csv"), ok).unwrap();
    plan_in(
        &dir,
        &format!(
            "platform: {{ kind: als, prf_hz: 2000, trajectory: {{ file: stray.csv }}, {OSC} }}"
        ),
    )
    .unwrap();
    // a header that names no needed column lists a dozen of its names, not all
    let many: Vec<String> = (0..500).map(|k| format!("c{k}")).collect();
    let e = bad("w.csv", &format!("{}\n1,2\n", many.join(",")));
    assert!(e.contains("and 488 more") && e.len() < 400, "{e}");
    // a scanner stepped along track has no speed to step by under a trajectory
    let e = plan_in(
        &dir,
        "platform: { kind: als, prf_hz: 2000, trajectory: { file: turn.csv }, scanner: { pattern: line, scan_angle_deg: [-10, 10], look_angle_step_deg: 1, along_track_step_m: 1 } }",
    )
    .err()
    .expect("refused")
    .to_string();
    assert!(e.contains("platform.scanner.along_track_step_m"), "{e}");
    // a byte that is no UTF-8 names its line
    std::fs::write(
        dir.join("h.csv"),
        b"time_s,x,y,z,roll_deg,pitch_deg,heading_deg\n0,0,0,100,0,0,90\n1,5,0,1\xff0,0,0,90\n",
    )
    .unwrap();
    let e = plan_in(
        &dir,
        &format!("platform: {{ kind: als, prf_hz: 2000, trajectory: {{ file: h.csv }}, {OSC} }}"),
    )
    .err()
    .expect("refused")
    .to_string();
    assert!(e.contains("h.csv:3:") && e.contains("UTF-8"), "{e}");
    let e = plan_in(
        &dir,
        &format!(
            "platform: {{ kind: als, prf_hz: 2000, trajectory: {{ file: none.csv }}, {OSC} }}"
        ),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(
        e.contains("platform.trajectory.file") && e.contains("does not exist"),
        "{e}"
    );
    let e = plan_in(&dir, &format!("platform: {{ kind: als, prf_hz: 2000, altitude_m: 100, trajectory: {{ file: turn.csv }}, {OSC} }}")).err().unwrap().to_string();
    assert!(
        e.contains("platform.altitude_m") && e.contains("trajectory"),
        "{e}"
    );
    let e = plan_in(&dir, &format!("platform: {{ kind: als, prf_hz: 2000, trajectory: {{ file: turn.csv, scan: [[5, 30]] }}, {OSC} }}")).err().unwrap().to_string();
    assert!(
        e.contains("platform.trajectory.scan[0]") && e.contains("within"),
        "{e}"
    );
}

/// A known mount (offset and boresight) is flown and recorded alike; an unknown boresight of
/// 0.05° turns the flown beam from the recorded one by 0.05°, so a point at range r moves by
/// r × 0.05° (in radians); errors off (absent, or all zero) leave every pulse as it was.
#[test]
fn mount_and_boresight() {
    let base = format!(
        "platform: {{ kind: als, altitude_m: 500, speed_m_s: 60, prf_hz: 20000, lines: [ {{ start: [0, 0], end: [60, 0] }} ], {OSC}"
    );
    let plain = pulses(&format!("{base} }}"));
    let mounted = pulses(&format!(
        "{base}, mount: {{ offset_m: [1.0, 0.5, -0.3], boresight_deg: [0.4, -0.2, 1.0] }}, errors: {{}} }}"
    ));
    for (a, b) in plain.iter().zip(&mounted) {
        assert!((b.origin - a.origin - DVec3::new(1.0, 0.5, -0.3)).length() < 1e-9);
        assert_eq!(b.rec_origin(), b.origin);
        assert_eq!(b.rec_direction(), b.direction);
        // the boresight turns the beam by at most the sum of its angles
        let turn = angle_between(a.direction, b.direction).to_degrees();
        assert!(turn > 0.1 && turn < 1.6, "{turn}");
    }
    let unknown = pulses(&format!(
        "{base}, errors: {{ boresight_deg: [0.05, 0, 0] }} }}"
    ));
    for (a, b) in plain.iter().zip(&unknown) {
        assert_eq!(a.direction, b.rec_direction());
        assert_eq!(a.origin, b.rec_origin());
        let turn = angle_between(b.direction, b.rec_direction()).to_degrees();
        assert!((turn - 0.05).abs() < 1e-9, "{turn}");
    }
    let zero = pulses(&format!(
        "{base}, errors: {{ position_sd_m: [0, 0, 0], attitude_sd_deg: [0, 0, 0], boresight_deg: [0, 0, 0] }} }}"
    ));
    for (a, b) in plain.iter().zip(&zero) {
        assert_eq!((a.origin, a.direction), (b.origin, b.direction));
        assert_eq!((a.origin, a.direction), (b.rec_origin(), b.rec_direction()));
        assert_eq!(a.recorded, None);
    }
}

/// The channels of a multibeam head fire together: with white errors (correlation 0) as with
/// correlated ones, they share one recorded pose's error, and successive firings do not.
#[test]
fn channels_that_fire_together_share_one_error() {
    for tau in [
        "",
        ", position_correlation_s: 0.1, attitude_correlation_s: 0.1",
    ] {
        let p = pulses(&format!(
            "platform: {{ kind: als, altitude_m: 30, speed_m_s: 11, prf_hz: 3000, lines: [ {{ start: [0, 0], end: [10, 0] }} ],
                scanner: {{ pattern: multibeam, channels_deg: [-25, -10.5, 0, 7, 22], rotation_hz: 7 }},
                errors: {{ position_sd_m: [0.05, 0.05, 0.05], attitude_sd_deg: [0.1, 0.1, 0.1]{tau} }} }}"
        ));
        assert!(p.len() >= 500 && p.len().is_multiple_of(5), "{}", p.len());
        let mut differ = 0;
        for firing in p.chunks_exact(5) {
            let d0 = firing[0].rec_origin() - firing[0].origin;
            for q in firing {
                assert_eq!(q.gps_time_s, firing[0].gps_time_s, "one firing, one time");
                let d = q.rec_origin() - q.origin;
                assert!((d - d0).length() < 1e-12, "{tau}: {d} against {d0}");
            }
            differ += usize::from(
                firing[0].gps_time_s != p[0].gps_time_s
                    && (d0 - (p[0].rec_origin() - p[0].origin)).length() > 1e-9,
            );
        }
        assert!(
            differ > p.len() / 5 - 2,
            "{tau}: firings share errors: {differ}"
        );
    }
}

/// White navigation errors (correlation 0) over 10^5 pulses: the recorded positions scatter
/// about the flown ones with the configured standard deviations (within 5 %: the estimate's
/// relative SE is 1/sqrt(2N) = 0.22 %), attitude errors turn the recorded beam by as much.
#[test]
fn white_errors_have_their_standard_deviations() {
    let p = pulses(&format!(
        "platform: {{ kind: als, altitude_m: 500, speed_m_s: 60, prf_hz: 40000, lines: [ {{ start: [0, 0], end: [150, 0] }} ], {OSC},
            errors: {{ position_sd_m: [0.03, 0.05, 0.08], attitude_sd_deg: [0.003, 0.004, 0.0] }} }}"
    ));
    assert!(p.len() >= 100_000, "{}", p.len());
    let n = p.len() as f64;
    let mut sq = [0.0f64; 3];
    let mut mean = [0.0f64; 3];
    let (mut across, mut along) = (0.0f64, 0.0f64);
    for q in &p {
        let d = q.rec_origin() - q.origin;
        for k in 0..3 {
            sq[k] += d[k] * d[k];
            mean[k] += d[k] / n;
        }
        // roll turns the beam about the track (x), pitch about the wing (y)
        let (a, b) = (q.direction, q.rec_direction());
        let flat = |v: DVec3, axis: DVec3| (v - axis * v.dot(axis)).normalize();
        across += angle_between(flat(a, DVec3::X), flat(b, DVec3::X)).powi(2);
        along += angle_between(flat(a, DVec3::Y), flat(b, DVec3::Y)).powi(2);
    }
    for (k, want) in [0.03, 0.05, 0.08].iter().enumerate() {
        let sd = (sq[k] / n).sqrt();
        assert!(
            (sd / want - 1.0).abs() < 0.05,
            "axis {k}: {sd} against {want}"
        );
        assert!(
            mean[k].abs() < 4.0 * want / n.sqrt(),
            "axis {k}: mean {}",
            mean[k]
        );
    }
    let across = (across / n).sqrt().to_degrees();
    let along = (along / n).sqrt().to_degrees();
    assert!((across / 0.003 - 1.0).abs() < 0.05, "{across}");
    assert!((along / 0.004 - 1.0).abs() < 0.05, "{along}");
}

/// Correlated position errors (τ = 0.2 s) are a first-order Gauss-Markov process: over 24
/// seeds, the mean of (x_t x_{t+lag}) / σ² at lags of 0.5, 1 and 2 τ is exp(−lag/τ) within 3
/// SE (the SE from the 24 seeds' spread), and the variance is σ² within 3 SE.
#[test]
fn correlated_errors_decay_as_exp_minus_lag_over_tau() {
    let (tau, sd, prf): (f64, f64, f64) = (0.2, 0.05, 2000.0);
    let lags = [0.0, 0.5, 1.0, 2.0];
    let mut runs: Vec<[f64; 4]> = Vec::new();
    for seed in 0..24u64 {
        let c = campaign(&format!(
            "seed: {seed}\nplatform: {{ kind: als, altitude_m: 500, speed_m_s: 50, prf_hz: {prf}, lines: [ {{ start: [0, 0], end: [200, 0] }} ],
                scanner: {{ pattern: risley, prism_rates_hz: [10, -7], deviation_deg: [5, 5] }},
                errors: {{ position_sd_m: [{sd}, 0, 0], position_correlation_s: {tau} }} }}"
        ));
        let p = plan(&c).unwrap();
        let x: Vec<f64> = p.iter().map(|q| q.rec_origin().x - q.origin.x).collect();
        runs.push(lags.map(|l| {
            let k = (l * tau * prf).round() as usize;
            let m = x.len() - k;
            (0..m).map(|i| x[i] * x[i + k]).sum::<f64>() / m as f64 / (sd * sd)
        }));
    }
    let n = runs.len() as f64;
    for (j, l) in lags.iter().enumerate() {
        let mean = runs.iter().map(|r| r[j]).sum::<f64>() / n;
        let var = runs.iter().map(|r| (r[j] - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let se = (var / n).sqrt();
        let want = (-l).exp();
        assert!(
            (mean - want).abs() < 3.0 * se,
            "lag {l} tau: {mean} against {want}, SE {se}"
        );
        assert!(se < 0.1, "lag {l}: SE {se}");
    }
}

/// With a `frame`, the trajectory's x, y, z are the CRS's easting, northing and ellipsoidal
/// height: the pulses fly them less the frame's origin.
#[test]
fn a_trajectory_in_a_frame_is_moved_into_the_scene() {
    let dir = TempDir::new("plan-frame");
    let origin = [500_000.0, 4_800_000.0, 120.0];
    trajectory_csv(
        &dir,
        "utm.csv",
        (0.0, 2.0, 0.5),
        [origin[0] + 10.0, origin[1] + 20.0],
        [origin[0] + 110.0, origin[1] + 20.0],
        origin[2] + 300.0,
        [0.0, 0.0, 90.0],
    );
    let plan = plan_in(
        &dir,
        &format!(
            "frame: {{ crs: EPSG:32631, origin: {origin:?} }}\nplatform: {{ kind: als, prf_hz: 2000, trajectory: {{ file: utm.csv }}, {OSC} }}"
        ),
    )
    .unwrap();
    assert!(!plan.is_empty());
    for id in [0, plan.len() as u64 / 2, plan.len() as u64 - 1] {
        let p = plan.pulse(id);
        assert!(
            (p.origin.y - 20.0).abs() < 1e-6 && (p.origin.z - 300.0).abs() < 1e-6,
            "{}",
            p.origin
        );
        assert!(
            (p.origin.x - (10.0 + 50.0 * p.gps_time_s)).abs() < 1e-6,
            "{}",
            p.origin
        );
    }
}

/// LAS numbers a point's flight line or station in 16 bits: a campaign of more lines
/// (counted from 1) or stations (from 0) than that holds is refused at its key, not written
/// with ids that saturate and repeat.
#[test]
fn more_sources_than_las_numbers_are_refused() {
    let refused = |platform: String, key: &str| {
        let doc = Doc {
            path: "campaign.yaml".into(),
            text: text(&platform),
        };
        let c: Campaign = doc.parse().unwrap();
        let e = super::check_campaign(&doc, &c).unwrap_err().to_string();
        assert!(e.contains(key) && e.contains("16 bits"), "{e}");
    };
    let stations = |n: usize| {
        let list: Vec<String> = (0..n).map(|i| format!("[{i}, 0, 1.5]")).collect();
        format!(
            "platform: {{ kind: tls, positions: [{}], azimuth_deg: [0, 360], azimuth_step_deg: 90, zenith_deg: [100, 110], zenith_step_deg: 10 }}",
            list.join(", ")
        )
    };
    refused(stations(65_537), "platform.positions");
    let lines = (0..65_536)
        .map(|i| format!("{{ start: [0, {i}], end: [10, {i}] }}"))
        .collect::<Vec<_>>()
        .join(", ");
    refused(
        format!("platform: {{ kind: als, altitude_m: 100, speed_m_s: 10, prf_hz: 1000, lines: [{lines}], {OSC} }}"),
        "platform.lines",
    );
}
