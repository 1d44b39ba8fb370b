//! Repeated scenes (`repeat: true`): the scene's x-y box is one period of an infinite
//! landscape, as DART's repeated scene.

mod common;
use common::*;

/// Closed form 1 over an infinite plane, from a 10 m patch repeated: a field of view 200 m
/// across and a footprint 100 m across at 10 km see twenty periods each way.
#[test]
fn a_repeated_patch_is_an_infinite_plane() {
    let inst = Inst {
        fp_mrad: 5.0,
        fov_mrad: 10.0,
        area: 0.1,
        energy: 0.001,
        ..Inst::default()
    };
    let (h, rho) = (10_000.0, 0.3);
    let expect = plane_energy(&inst, rho, h);
    for (repeat, method) in [(true, "forward"), (true, "bdpt"), (false, "forward")] {
        let dir = tmp(&format!("repeat_patch_{repeat}_{method}"));
        let scene = write(
            &dir,
            "patch.yaml",
            &format!(
                "name: patch\nrepeat: {repeat}\nmaterials:\n  soil: {{ reflectance: {rho} }}\nobjects:\n  - plane: {{ z: 0, extent: [[-5, -5], [5, 5]], material: soil }}\n"
            ),
        );
        let w = &run(
            &dir,
            &campaign(
                &scene,
                &inst,
                [1.3, -2.1, h],
                [0.0, 0.0, -1.0],
                method,
                200_000,
                3,
            ),
            None,
        )[0];
        let got = w.received_energy_j;
        let (rel, se) = (got / expect - 1.0, w.received_energy_se_j / expect);
        println!(
            "repeat {repeat} {method}: got {got:.5e} expect {expect:.5e} rel {rel:+.4} se {se:.4}"
        );
        if repeat {
            assert!(
                3.0 * se < 0.01,
                "standard error {se} too large for a 1% test"
            );
            assert!(rel.abs() < 0.01, "relative error {rel}");
            assert_eq!(w.outside_gate_energy_j, 0.0);
        } else {
            // one patch alone catches a few per cent of the light
            assert!(got < 0.1 * expect, "{got} against {expect}");
        }
    }
}

/// A 4 m x 4 m tile of soil under a slab of leaves reaching `half` m from its centre (1.85: its
/// x-y box within the ground's; more: overhanging it), as `repeated.yaml` (`repeat: true`, the
/// ground's extent its period) and `tiled.yaml` (a 5 x 5 tiled copy, the neighbours' leaves
/// overlapping where they overhang).
fn tile(dir: &std::path::Path, half: f64, seed: u64) {
    let obj = random_leaves(12_000, seed, [-half, -half, 1.0], [half, half, 2.0]);
    write(dir, "leaves.obj", &obj);
    let materials = "materials:\n  soil: { reflectance: 0.3 }\n  leaf: { reflectance: 0.45, transmittance: 0.45 }\n";
    write(
        dir,
        "repeated.yaml",
        &format!("name: slab\nrepeat: true\n{materials}objects:\n  - plane: {{ z: 0, extent: [[-2, -2], [2, 2]], material: soil }}\n  - mesh: {{ file: leaves.obj, material: leaf }}\n"),
    );
    let rows: String = [-8, -4, 0, 4, 8]
        .iter()
        .flat_map(|x| [-8, -4, 0, 4, 8].map(|y| format!("{x} {y}\n")))
        .collect();
    write(dir, "tiles.csv", &rows);
    write(
        dir,
        "tiled.yaml",
        &format!("name: tiled\n{materials}objects:\n  - plane: {{ z: 0, extent: [[-10, -10], [10, 10]], material: soil }}\n  - mesh: {{ file: leaves.obj, material: leaf, instances: tiles.csv }}\n"),
    );
}

/// The instrument over the slab: beam and field of view 4 and 5 m across at 100 m.
fn slab_inst() -> Inst {
    Inst {
        fp_mrad: 20.0,
        fov_mrad: 25.0,
        area: 0.1,
        energy: 0.001,
        fwhm_ns: 2.0,
        ..Inst::default()
    }
}

/// A repeated slab of leaves: forward, backward and bdpt agree per order and per bin within
/// 3 combined standard errors, and equal a 5 x 5 tiled copy of the slab (the beam and the
/// field of view, 4 and 5 m across, see two periods; the tiled copy's edges are 8 m away).
#[test]
fn a_repeated_slab_is_its_tiled_copy() {
    let dir = tmp("repeat_slab");
    tile(&dir, 1.85, 0x9E37_79B9_7F4A_7C15);
    let inst = slab_inst();
    let c = |scene: &str, m: &str, rays: u64| {
        campaign(
            &dir.join(scene),
            &inst,
            [0.3, -0.7, 100.0],
            [0.0, 0.0, -1.0],
            m,
            rays,
            100,
        )
    };
    let f = run(
        &tmp("repeat_slab_f"),
        &c("repeated.yaml", "forward", 1_000_000),
        None,
    )
    .remove(0);
    let b = run(
        &tmp("repeat_slab_b"),
        &c("repeated.yaml", "backward", 1_000_000),
        None,
    )
    .remove(0);
    let d = run(
        &tmp("repeat_slab_d"),
        &c("repeated.yaml", "bdpt", 400_000),
        None,
    )
    .remove(0);
    let t = run(
        &tmp("repeat_slab_t"),
        &c("tiled.yaml", "bdpt", 400_000),
        None,
    )
    .remove(0);
    assert!(
        f.order_energy_j[1] > 0.1 * f.order_energy_j[0],
        "{:?}",
        f.order_energy_j
    );
    compare_orders("repeated forward/backward", &f, &b, 4);
    compare_orders("repeated bdpt/forward", &d, &f, 4);
    compare_orders("repeated bdpt/backward", &d, &b, 4);
    compare_bins("repeated bdpt/forward", &d, &f);
    compare_orders("repeated/tiled bdpt", &d, &t, 4);
    compare_bins("repeated/tiled bdpt", &d, &t);
}

/// Closed form 4 over a repeated 10 m patch seen through a field of view 40 m across: the
/// sun's disk covers what the pulse sees, and the light sub-paths' density is 0 where it
/// does not reach, so bdpt's solar estimate is the infinite plane's; both BRFs equal ρ.
#[test]
fn the_sun_lights_every_period_in_view() {
    let rho = 0.3;
    let inst = sun_inst(20.0);
    let dir = tmp("repeat_sun");
    let scene = write(
        &dir,
        "patch.yaml",
        &format!("name: patch\nrepeat: true\nmaterials:\n  soil: {{ reflectance: {rho} }}\nobjects:\n  - plane: {{ z: 0, extent: [[-5, -5], [5, 5]], material: soil }}\n"),
    );
    for zenith in [0.0f64, 50.0] {
        let text = with_sun_selected(
            &campaign(
                &scene,
                &inst,
                [2.0, 1.0, 1000.0],
                [0.0, 0.0, -1.0],
                "bdpt",
                100_000,
                3,
            ),
            zenith,
            180.0,
            "fixed",
        );
        let sub = dir.join(format!("z{zenith}"));
        std::fs::create_dir_all(&sub).unwrap();
        let w = run(&sub, &text, None).remove(0);
        let (p_sun, expect) = solar_closed_form(&inst, rho, zenith);
        let got = w.solar_photons_per_bin as f64;
        let se = w.solar_power_se_w / p_sun;
        println!("sun {zenith}°: {got:.5} photons/bin, expect {expect:.5}, rel {:+.5}, se {se:.5}, BRF fov {}", got / expect - 1.0, w.brf_fov_solar);
        assert!(
            3.0 * se < 0.01,
            "standard error {se} too large for a 1% test"
        );
        assert!((got / expect - 1.0).abs() < 0.01);
        assert!(
            (w.brf_fov_solar as f64 / rho - 1.0).abs() < 0.01,
            "{}",
            w.brf_fov_solar
        );
    }
}

/// The DSM of a survey over a repeated 10 m patch of a plane with a box on it: the survey
/// runs 60 m across six periods, and its reference is the repeated scene's (coverage of the
/// whole strip, the plane and the roofs at their heights), not the one patch's.
#[test]
fn a_repeated_scene_has_a_reference_dsm_everywhere() {
    let dir = tmp("repeat_dsm");
    write(
        &dir,
        "box.obj",
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nv -1 -1 3\nv 1 -1 3\nv 1 1 3\nv -1 1 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n",
    );
    let scene = write(
        &dir,
        "scene.yaml",
        "name: blocks\nrepeat: true\nmaterials:\n  soil: { reflectance: 0.3 }\n  roof: { reflectance: 0.3 }\nobjects:\n  - plane: { z: 0, extent: [[-5, -5], [5, 5]], material: soil }\n  - mesh: { file: box.obj, material: roof, class: building }\n",
    );
    let text = format!(
        "name: blocks\nscene: {}\nseed: 2\nwavelength_nm: 1064\ninstrument: {{ kind: discrete_return, pulse_energy_j: 0.00001, pulse_fwhm_ns: 4.0, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1.0 }}\nplatform: {{ kind: als, altitude_m: 300, speed_m_s: 30, prf_hz: 100000, lines: [ {{ start: [-30, 0.5], end: [30, 0.5] }} ], scanner: {{ pattern: line, scan_angle_deg: [-2, 2], look_angle_step_deg: 0.2, along_track_step_m: 0.5 }} }}\nsimulation: {{ method: forward, rays_per_pulse: 16, max_order: 1 }}\nproducts: {{ points: true, dsm: {{ resolution_m: 1.0 }} }}\n",
        scene.display()
    );
    let out = run_campaign(&dir, &text, None);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("dsm/report.json")).unwrap())
            .unwrap();
    println!("repeated DSM: {r}");
    assert!(r["cells"].as_u64().unwrap() >= 55 * 8, "{r}");
    assert!(r["coverage"].as_f64().unwrap() > 0.95, "{r}");
    assert!(r["bias_m"].as_f64().unwrap().abs() < 0.05, "{r}");
    let points = lidarsim::products::points::las::read_las(&out.join("points.las")).unwrap();
    let roofs = points.iter().filter(|p| p.classification == 6).count();
    // a 2 m x 2 m box in every 10 m x 10 m period: 4 % of the strip, in every period it crosses
    let share = roofs as f64 / points.len() as f64;
    assert!(
        (0.02..0.08).contains(&share),
        "{roofs} of {} points on roofs",
        points.len()
    );
    let mut periods: Vec<i64> = points
        .iter()
        .filter(|p| p.classification == 6)
        .map(|p| ((p.x + 5.0) / 10.0).floor() as i64)
        .collect();
    periods.dedup();
    assert!(periods.len() >= 6, "roofs in periods {periods:?}");
    assert!(points
        .iter()
        .all(|p| (p.z.abs() < 0.05) || ((p.z - 3.0).abs() < 0.05)));
}

/// A tile whose leaves overhang its ground by 0.85 m on every side (a crown wider than its
/// plot), repeated with the ground's extent as its period (the default), equals the 5 x 5
/// tiled copy in which the neighbours' leaves overlap: bdpt and forward over the repeated
/// scene against bdpt over the tiled one, per order and per bin within 3 combined standard
/// errors. Its DSM reference over three periods has no gap and is the tiled copy's.
#[test]
fn overhanging_leaves_wrap_into_the_period() {
    let dir = tmp("repeat_overhang");
    tile(&dir, 2.85, 0x5851_F42D_4C95_7F2D);
    let inst = slab_inst();
    // the beam's axis 0.3 m inside the period's edge, where its light meets the wrapped
    // leaves of the next period as much as the tile's own
    let c = |scene: &str, method: &str| {
        campaign(
            &dir.join(scene),
            &inst,
            [1.7, -0.7, 100.0],
            [0.0, 0.0, -1.0],
            method,
            400_000,
            100,
        )
    };
    let t = run(&tmp("repeat_overhang_t"), &c("tiled.yaml", "bdpt"), None).remove(0);
    for method in ["bdpt", "forward"] {
        let r = run(&tmp("repeat_overhang_r"), &c("repeated.yaml", method), None).remove(0);
        compare_orders(
            &format!("overhanging repeated {method}/tiled bdpt"),
            &r,
            &t,
            4,
        );
        compare_bins(&format!("overhanging repeated {method}/tiled bdpt"), &r, &t);
    }

    use lidarsim::scene::top_surface::Grid;
    use lidarsim::scene::Scene;
    let repeated = Scene::load(&dir.join("repeated.yaml"), 1064.0).unwrap();
    let tiled = Scene::load(&dir.join("tiled.yaml"), 1064.0).unwrap();
    let (lo, hi) = repeated.period().unwrap();
    assert_eq!((lo.x, lo.y, hi.x, hi.y), (-2.0, -2.0, 2.0, 2.0));
    // 12 m x 12 m of 0.25 m cells centred on the tiled copy's middle
    let grid = Grid {
        x0: -6.0,
        y0: -6.0,
        cell: 0.25,
        nx: 48,
        ny: 48,
    };
    let (a, b) = (
        repeated.top_surface_grid(&grid),
        tiled.top_surface_grid(&grid),
    );
    assert!(
        a.iter().all(|z| z.is_finite()),
        "the repeated reference has gaps"
    );
    for (k, (za, zb)) in a.iter().zip(&b).enumerate() {
        assert!(
            (za - zb).abs() < 1e-5,
            "cell {k}: {za} against the tiled {zb}"
        );
    }
}

/// The period as the scene file gives it: a repeated plane of 10 m with `period` 5 m wide is
/// the same infinite plane, its period the one given; a period on a scene that does not
/// repeat, or an empty one, is refused at its key.
#[test]
fn a_given_period_is_the_period() {
    use lidarsim::scene::Scene;
    let dir = tmp("repeat_period");
    let scene = |name: &str, extra: &str| {
        write(
            &dir,
            name,
            &format!("name: p\n{extra}materials:\n  soil: {{ reflectance: 0.3 }}\nobjects:\n  - plane: {{ z: 0, extent: [[-5, -5], [5, 5]], material: soil }}\n"),
        )
    };
    let given = scene("given.yaml", "repeat: true\nperiod: [[0, 0], [5, 2.5]]\n");
    let s = Scene::load(&given, 1064.0).unwrap();
    let (lo, hi) = s.period().unwrap();
    assert_eq!((lo.x, lo.y, hi.x, hi.y), (0.0, 0.0, 5.0, 2.5));
    for (name, extra, says) in [
        (
            "lonely.yaml",
            "period: [[0, 0], [5, 5]]\n",
            "add repeat: true",
        ),
        (
            "empty.yaml",
            "repeat: true\nperiod: [[0, 0], [0, 5]]\n",
            "x1 > x0",
        ),
    ] {
        let path = scene(name, extra);
        let Err(e) = Scene::load(&path, 1064.0) else {
            panic!("{name}: loaded")
        };
        let e = e.to_string();
        println!("{e}");
        assert!(
            e.contains(name) && e.contains("period") && e.contains(says),
            "{e}"
        );
        assert!(e.contains(":2:") || e.contains(":3:"), "no line in {e}");
    }
}
