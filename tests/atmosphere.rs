//! The atmosphere (campaign.md, "Keys of the next wave"): a plane-parallel exponential
//! atmosphere weights every path segment by its transmittance.

mod common;
use common::*;

/// The spec's example layers at 1064 nm: τ = 0.008 (H = 8 km) and 0.10 (H = 1.5 km).
const ATMOSPHERE: &str = "atmosphere:\n  layers:\n    - { scale_height_m: 8000, optical_depth: { 532: 0.12, 1064: 0.008 } }\n    - { scale_height_m: 1500, optical_depth: { 532: 0.20, 1064: 0.10 } }\n";
const LAYERS: [(f64, f64); 2] = [(8000.0, 0.008), (1500.0, 0.10)];

/// Vertical optical depth between heights z1 < z2.
fn column(z1: f64, z2: f64) -> f64 {
    LAYERS
        .iter()
        .map(|&(h, tau)| tau * ((-z1 / h).exp() - (-z2 / h).exp()))
        .sum()
}

fn gedi() -> Inst {
    Inst {
        fp_mrad: 0.03,
        fov_mrad: 0.3,
        area: 0.5,
        energy: 0.0105,
        ..Inst::default()
    }
}

/// A pulse from 419 km at `zenith_deg` off nadir onto a plane of reflectance 0.3, with and
/// without the atmosphere: (energy with, energy without, its standard error).
fn pulse_pair(name: &str, zenith_deg: f64, method: &str, rays: u64) -> (f64, f64, f64) {
    let dir = tmp(name);
    for sub in ["vacuum", "air"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
    }
    let scene = plane_scene(&dir, 0.3, 400.0);
    let h = 419_000.0;
    let t = zenith_deg.to_radians();
    let text = campaign(
        &scene,
        &gedi(),
        [-h * t.tan(), 0.0, h],
        [t.sin(), 0.0, -t.cos()],
        method,
        rays,
        3,
    );
    let vacuum = run(&dir.join("vacuum"), &text, None).remove(0);
    let air = run(&dir.join("air"), &format!("{text}{ATMOSPHERE}"), None).remove(0);
    (
        air.received_energy_j,
        vacuum.received_energy_j,
        vacuum.received_energy_se_j,
    )
}

/// Closed form 1 times e^(-2τ) at nadir, and e^(-2τ / cos 30°) at 30° off nadir, within 1 %;
/// the atmosphere changes no random draw, so with the same seed the ratio to vacuum is the
/// two-way transmittance itself.
#[test]
fn laser_signal_loses_the_two_way_transmittance() {
    for (zenith, method, rays) in [(0.0, "forward", 1_000_000), (30.0, "bdpt", 300_000)] {
        let name = format!("atm_{zenith}_{method}");
        let (air, vacuum, se) = pulse_pair(&name, zenith, method, rays);
        let mu = f64::cos(zenith.to_radians());
        let t2 = (-2.0 * column(0.0, 419_000.0) / mu).exp();
        println!(
            "{zenith}°: ratio {:.6}, e^(-2τ/μ) {t2:.6}, vacuum rel. SE {:.4}",
            air / vacuum,
            se / vacuum
        );
        assert!((air / vacuum / t2 - 1.0).abs() < 1e-3, "{}", air / vacuum);
        if zenith == 0.0 {
            let expect = plane_energy(&gedi(), 0.3, 419_000.0) * t2;
            assert!(
                3.0 * se / vacuum < 0.01,
                "standard error too large for a 1% test"
            );
            assert!((air / expect - 1.0).abs() < 0.01, "{air} against {expect}");
        }
    }
}

/// Closed form 4 with the atmosphere: the sun's light crosses the whole column at its zenith
/// angle, then the layer between the plane and the sensor (1 km) on the way up.
#[test]
fn solar_signal_gets_its_own_transmittance() {
    let rho = 0.3;
    let inst = sun_inst(5.0);
    let zenith: f64 = 50.0;
    let dir = tmp("atm_sun");
    let scene = plane_scene(&dir, rho, 600.0);
    let text = with_sun_selected(
        &campaign(
            &scene,
            &inst,
            [10.0, -20.0, 1000.0],
            [0.0, 0.0, -1.0],
            "bdpt",
            100_000,
            3,
        ),
        zenith,
        180.0,
        "fixed",
    );
    std::fs::create_dir_all(dir.join("vacuum")).unwrap();
    std::fs::create_dir_all(dir.join("air")).unwrap();
    let vacuum = run(&dir.join("vacuum"), &text, None).remove(0);
    let air = run(&dir.join("air"), &format!("{text}{ATMOSPHERE}"), None).remove(0);
    let t_sun = (-column(0.0, 1e7) / zenith.to_radians().cos()).exp();
    let t_view = (-column(0.0, 1000.0)).exp();
    let (p_sun, vacuum_expect) = solar_closed_form(&inst, rho, zenith);
    let expect = vacuum_expect * t_sun * t_view;
    let (got, got_vacuum) = (
        air.solar_photons_per_bin as f64,
        vacuum.solar_photons_per_bin as f64,
    );
    let se = vacuum.solar_power_se_w / p_sun;
    println!(
        "sun: {got:.5} photons/bin, expect {expect:.5} (T_sun {t_sun:.5}, T_view {t_view:.5}), ratio to vacuum {:.6}, se {se:.5}",
        got / got_vacuum
    );
    assert!((got / got_vacuum / (t_sun * t_view) - 1.0).abs() < 1e-4);
    assert!(
        3.0 * se < 0.01,
        "standard error {se} too large for a 1% test"
    );
    assert!((got / expect - 1.0).abs() < 0.01);
    // and the laser, 1 km up, crosses the lowest layer twice
    let t_laser = (-2.0 * column(0.0, 1000.0)).exp();
    let ratio = air.received_energy_j / vacuum.received_energy_j;
    assert!(
        (ratio / t_laser - 1.0).abs() < 1e-3,
        "{ratio} against {t_laser}"
    );
}
