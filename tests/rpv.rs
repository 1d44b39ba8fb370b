//! The RPV glossy reflectance (docs/physics.md, "Glossy surfaces: RPV"): closed form 1 with RPV's hot
//! spot, the three estimators' agreement on a tilted RPV plane and on leaves over RPV soil, RPV
//! in several bands, and its bad parameters.

mod common;
use common::*;
use lidarsim::scene::Rpv;

/// RPV's reflectance factor at the hot spot (monostatic geometry) for incidence cosine μ:
/// ρ0 (2μ³)^(k−1) (1 − Θ²)/(1 + Θ)³ (2 − ρ_c), written out from Rahman et al. (1993).
fn hot_spot(rho0: f64, k: f64, theta: f64, rho_c: f64, mu: f64) -> f64 {
    rho0 * (2.0 * mu.powi(3)).powf(k - 1.0) * (1.0 - theta * theta) / (1.0 + theta).powi(3)
        * (2.0 - rho_c)
}

fn rpv_plane(dir: &std::path::Path, name: &str, material: &str) -> std::path::PathBuf {
    write(
        dir,
        name,
        &format!(
            "name: p\nmaterials:\n  soil: {material}\nobjects:\n  - plane: {{ z: 0, extent: [[-300, -300], [300, 300]], material: soil }}\n"
        ),
    )
}

const SOIL: &str = "{ reflectance: 0.25, rpv: { k: 0.75, theta: -0.2, rho_c: 0.4 } }";

/// Closed form 1 with RPV: at nadir a plane returns Q_1(ρ) with ρ the reflectance factor of
/// the hot spot at normal incidence, within 1 % (3 SE under 1 %); 30° off nadir, the ratio to
/// a Lambertian plane of reflectance ρ0 traced with the same draws is that of the hot spot at
/// 30° over ρ0, within 0.5 % (the footprint's spread of angles moves it by less than 0.1 %).
#[test]
fn plane_returns_the_hot_spot_reflectance() {
    let dir = tmp("rpv_plane");
    let inst = Inst::default();
    let h = 300.0;
    let rpv = rpv_plane(&dir, "rpv.yaml", SOIL);
    let lambert = rpv_plane(&dir, "lambert.yaml", "{ reflectance: 0.25 }");
    for sub in ["nadir", "rpv30", "lambert30"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
    }
    let nadir = run(
        &dir.join("nadir"),
        &campaign(
            &rpv,
            &inst,
            [0.0, 0.0, h],
            [0.0, 0.0, -1.0],
            "forward",
            400_000,
            1,
        ),
        None,
    )
    .remove(0);
    let rho = hot_spot(0.25, 0.75, -0.2, 0.4, 1.0);
    let expect = plane_energy(&inst, rho, h);
    let (got, se) = (nadir.received_energy_j, nadir.received_energy_se_j / expect);
    println!("nadir: ρ_hot {rho:.5}, got {got:.5e}, expect {expect:.5e}, se {se:.5}");
    assert!(
        3.0 * se < 0.01,
        "standard error {se} too large for a 1% test"
    );
    assert!((got / expect - 1.0).abs() < 0.01, "{}", got / expect);

    let t = 30f64.to_radians();
    let oblique = |scene: &std::path::Path| {
        campaign(
            scene,
            &inst,
            [-h * t.tan(), 0.0, h],
            [t.sin(), 0.0, -t.cos()],
            "forward",
            200_000,
            1,
        )
    };
    let a = run(&dir.join("rpv30"), &oblique(&rpv), None).remove(0);
    let b = run(&dir.join("lambert30"), &oblique(&lambert), None).remove(0);
    let want = hot_spot(0.25, 0.75, -0.2, 0.4, t.cos()) / 0.25;
    let ratio = a.received_energy_j / b.received_energy_j;
    println!("30°: ratio {ratio:.5}, hot spot over ρ0 {want:.5}");
    assert!((ratio / want - 1.0).abs() < 0.005, "{ratio} against {want}");
    // and RPV is not Lambert here: the test could tell them apart
    assert!((want - 1.0).abs() > 0.2);
}

/// A plane tilted by 30° of RPV soil: forward, backward and bdpt agree on its energy and its
/// waveform bin by bin within 3 combined standard errors.
#[test]
fn three_methods_agree_on_a_tilted_rpv_plane() {
    let dir = tmp("rpv_tilted");
    write(
        &dir,
        "tilted.obj",
        &tilted_square_obj(30.0, 30f64.to_radians()),
    );
    let scene = write(
        &dir,
        "tilted.yaml",
        &format!("name: tilted\nmaterials:\n  soil: {SOIL}\nobjects:\n  - mesh: {{ file: tilted.obj, material: soil }}\n"),
    );
    let inst = Inst {
        fp_mrad: 5.0,
        fov_mrad: 6.0,
        area: 0.1,
        energy: 0.001,
        bin_ns: 1.0,
        ..Inst::default()
    };
    let go = |m: &str, rays: u64| {
        let sub = dir.join(m);
        std::fs::create_dir_all(&sub).unwrap();
        let text = campaign(
            &scene,
            &inst,
            [0.0, 0.0, 500.0],
            [0.0, 0.0, -1.0],
            m,
            rays,
            1,
        );
        run(&sub, &text, None).remove(0)
    };
    let (f, b, d) = (
        go("forward", 300_000),
        go("backward", 300_000),
        go("bdpt", 150_000),
    );
    compare_orders("tilted rpv forward/backward", &f, &b, 1);
    compare_orders("tilted rpv bdpt/forward", &d, &f, 1);
    compare_orders("tilted rpv bdpt/backward", &d, &b, 1);
    compare_bins("tilted rpv forward/backward", &f, &b);
    compare_bins("tilted rpv bdpt/forward", &d, &f);
}

/// Leaves over RPV soil (multiple scattering through the soil's glossy lobe and hot spot):
/// forward, backward and bdpt agree per order (4 orders) and per bin within 3 combined
/// standard errors.
#[test]
fn three_methods_agree_on_leaves_over_rpv_soil() {
    let dir = tmp("rpv_canopy");
    let scene = leaf_layer_of(
        &dir,
        "{ reflectance: 0.3, rpv: { k: 0.7, theta: -0.25 } }",
        "{ reflectance: 0.45, transmittance: 0.45 }",
    );
    let inst = Inst {
        fp_mrad: 20.0,
        fov_mrad: 25.0,
        area: 0.1,
        energy: 0.001,
        fwhm_ns: 2.0,
        ..Inst::default()
    };
    let go = |m: &str| {
        let sub = dir.join(m);
        std::fs::create_dir_all(&sub).unwrap();
        let text = campaign(
            &scene,
            &inst,
            [0.0, 0.0, 100.0],
            [0.0, 0.0, -1.0],
            m,
            1_000_000,
            100,
        );
        run(&sub, &text, None).remove(0)
    };
    let (f, b, d) = (go("forward"), go("backward"), go("bdpt"));
    assert!(f.order_energy_j[1] > 0.1 * f.order_energy_j[0]);
    compare_orders("rpv canopy forward/backward", &f, &b, 4);
    compare_orders("rpv canopy bdpt/forward", &d, &f, 4);
    compare_orders("rpv canopy bdpt/backward", &d, &b, 4);
    compare_bins("rpv canopy forward/backward", &f, &b);
    compare_bins("rpv canopy bdpt/forward", &d, &f);
}

/// RPV in several bands: soil whose amplitude and shape differ by band, under leaves, traced
/// in two bands at once, equals single-band runs of each wavelength per order and per bin
/// within 3 combined standard errors (the band factor of an RPV vertex depends on its
/// directions, so it is evaluated, not tabulated).
#[test]
fn rpv_in_several_bands_equals_single_band_runs() {
    let dir = tmp("rpv_bands");
    let obj = random_leaves(50_000, 7, [-6.0, -6.0, 5.0], [6.0, 6.0, 8.0]);
    write(&dir, "leaves.obj", &obj);
    let scene = write(
        &dir,
        "canopy.yaml",
        "name: canopy\nmaterials:\n  soil: { reflectance: { 532: 0.1, 1064: 0.35 }, rpv: { k: { 532: 1.2, 1064: 0.7 }, theta: { 532: 0.1, 1064: -0.25 }, rho_c: 0.3 } }\n  leaf: { reflectance: { 532: 0.1, 1064: 0.45 }, transmittance: { 532: 0.05, 1064: 0.45 } }\nobjects:\n  - plane: { z: 0, extent: [[-20, -20], [20, 20]], material: soil }\n  - mesh: { file: leaves.obj, material: leaf }\n",
    );
    let inst = Inst {
        fp_mrad: 5.0,
        fov_mrad: 7.5,
        area: 0.1,
        bin_ns: 0.5,
        ..Inst::default()
    };
    let text = campaign(
        &scene,
        &inst,
        [0.0, 0.0, 500.0],
        [0.0, 0.0, -1.0],
        "bdpt",
        60_000,
        3,
    );
    compare_bands_with_single_runs("rpv", &dir, &text, &[532.0, 1064.0], 3);
}

/// Bad RPV parameters end with exit code 1 and one message naming the file, line and key.
#[test]
fn bad_rpv_parameters_are_located_errors() {
    let dir = tmp("rpv_bad");
    let text = "name: bad\nscene: plane.yaml\nwavelength_nm: 1064\ninstrument: { pulse_energy_j: 0.00001, pulse_fwhm_ns: 3, footprint_half_angle_mrad: 0.3, fov_half_angle_mrad: 0.5, receiver_area_m2: 0.01, bin_ns: 1 }\nplatform: { kind: track, altitude_m: 100, track: { start: [0, 0], end: [2, 0] }, along_track_step_m: 1 }\n";
    let path = write(&dir, "bad.yaml", text);
    for (material, says) in [
        (
            "{ reflectance: 0.3, transmittance: 0.2, rpv: { k: 0.8, theta: 0 } }",
            "soil.transmittance",
        ),
        (
            "{ reflectance: 0.3, rpv: { k: 0, theta: 0 } }",
            "soil.rpv.k",
        ),
        (
            "{ reflectance: 0.3, rpv: { k: 0.8, theta: 1.5 } }",
            "soil.rpv.theta",
        ),
        (
            "{ reflectance: 0.3, rpv: { k: 0.8, theta: 0, rho_c: 2 } }",
            "soil.rpv.rho_c",
        ),
        ("{ reflectance: 0.3, rpv: { k: 0.8 } }", "theta"),
        (
            "{ reflectance: 0.3, rpv: { k: 0.8, theta: 0, hotspot: 1 } }",
            "hotspot",
        ),
        (
            "{ reflectance: 0.95, rpv: { k: 0.4, theta: -0.6 } }",
            "more than it receives",
        ),
        (
            "{ reflectance: 0.6, rpv: { k: 0.6, theta: -0.3 } }",
            "more than it receives",
        ),
        (
            "{ reflectance: 0.3, rpv: { k: { 532: 0.8 }, theta: 0 } }",
            "1064",
        ),
    ] {
        rpv_plane(&dir, "plane.yaml", material);
        assert_bad_input(&path, "plane.yaml", says);
    }
    // the check is RPV's own: sound parameters pass
    let ok = Rpv {
        k: 0.75,
        theta: -0.2,
        rho_c: Some(0.4),
        limit: None,
    };
    assert!(ok.max_albedo(0.25, 0.0, 80.0).0 < 1.0);
}
