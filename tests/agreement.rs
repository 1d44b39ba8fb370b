//! Forward and backward estimators converge to the same waveform (physics.md, check 5):
//! per scattering order, within 3 combined standard errors.

mod common;
use common::*;
use lidarsim::waveform::Waveform;
use std::fmt::Write;

fn compare(name: &str, f: &Waveform, b: &Waveform, orders: usize) {
    for k in 0..orders {
        let (ef, eb) = (f.order_energy_j[k], b.order_energy_j[k]);
        let se = (f.order_energy_se_j[k].powi(2) + b.order_energy_se_j[k].powi(2)).sqrt();
        let z = (ef - eb) / se;
        println!("{name} order {}: forward {ef:.5e} backward {eb:.5e} z {z:+.2} rel se {:.4}", k + 1, se / ef);
        // the comparison must be able to see a 10% disagreement
        assert!(se / ef.max(eb) < 0.033, "{name} order {}: standard error too large", k + 1);
        assert!(z.abs() < 3.0, "{name} order {}: forward and backward differ by {z:.2} standard errors", k + 1);
    }
    let se = (f.received_energy_se_j.powi(2) + b.received_energy_se_j.powi(2)).sqrt();
    let z = (f.received_energy_j - b.received_energy_j) / se;
    println!("{name} total: z {z:+.2}");
    assert!(z.abs() < 3.0);
}

#[test]
fn forward_and_backward_agree_in_the_integrating_sphere() {
    let dir = tmp("agree_sphere");
    let scene = sphere_scene(&dir, 0.9);
    // a wide footprint inside a wide field of view, so both directions find every order
    let inst = Inst { fp_mrad: 250.0, fov_mrad: 300.0, area: 0.01, energy: 0.001, ..Inst::default() };
    let c = |m: &str| campaign(&scene, &inst, [0.0, 0.0, 0.0], [0.0, 0.0, -1.0], m, 400_000, 100);
    let f = run(&tmp("agree_sphere_f"), &c("forward"), None).remove(0);
    let b = run(&tmp("agree_sphere_b"), &c("backward"), None).remove(0);
    compare("sphere", &f, &b, 5);
}

/// A layer of small leaves (ρ = τ = 0.45) between 5 and 8 m over a soil plane.
fn leaf_layer(dir: &std::path::Path) -> std::path::PathBuf {
    let mut obj = String::new();
    let mut state: u64 = 0x2545F4914F6CDD1D;
    let mut rnd = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let leaves = 20_000;
    for i in 0..leaves {
        let c = [rnd() * 12.0 - 6.0, rnd() * 12.0 - 6.0, 5.0 + 3.0 * rnd()];
        // two random edge vectors of about 10 cm
        let mut e = [[0.0; 3]; 2];
        for v in &mut e {
            for x in v.iter_mut() {
                *x = (rnd() - 0.5) * 0.2;
            }
        }
        for p in [[0.0; 3], e[0], e[1]] {
            writeln!(obj, "v {} {} {}", c[0] + p[0], c[1] + p[1], c[2] + p[2]).unwrap();
        }
        writeln!(obj, "f {} {} {}", 3 * i + 1, 3 * i + 2, 3 * i + 3).unwrap();
    }
    write(dir, "leaves.obj", &obj);
    write(
        dir,
        "canopy.yaml",
        "name: canopy\nmaterials:\n  soil: { reflectance: { 1064: 0.3 } }\n  leaf: { reflectance: { 1064: 0.45 }, transmittance: { 1064: 0.45 } }\nobjects:\n  - plane: { z: 0, extent: [[-20, -20], [20, 20]], material: soil }\n  - mesh: { file: leaves.obj, material: leaf }\n",
    )
}

#[test]
fn forward_and_backward_agree_on_a_leaf_layer_over_ground() {
    let dir = tmp("agree_canopy");
    let scene = leaf_layer(&dir);
    let inst = Inst { fp_mrad: 20.0, fov_mrad: 25.0, area: 0.1, energy: 0.001, fwhm_ns: 2.0, ..Inst::default() };
    let c = |m: &str| campaign(&scene, &inst, [0.0, 0.0, 100.0], [0.0, 0.0, -1.0], m, 300_000, 100);
    let f = run(&tmp("agree_canopy_f"), &c("forward"), None).remove(0);
    let b = run(&tmp("agree_canopy_b"), &c("backward"), None).remove(0);
    compare("canopy", &f, &b, 4);
    // multiple scattering must matter in this scene for the comparison to mean anything
    assert!(f.order_energy_j[1] > 0.02 * f.order_energy_j[0]);
}
