//! Forward, backward and bidirectional estimators converge to the same waveform (physics.md,
//! check 5): per scattering order and per bin, within 3 combined standard errors.

mod common;
use common::*;

#[test]
fn three_methods_agree_in_the_integrating_sphere() {
    let dir = tmp("agree_sphere");
    let scene = sphere_scene(&dir, 0.9);
    // a wide footprint inside a wide field of view, so both directions find every order
    let inst = Inst {
        fp_mrad: 250.0,
        fov_mrad: 300.0,
        area: 0.01,
        energy: 0.001,
        ..Inst::default()
    };
    let c = |m: &str, rays: u64| {
        campaign(
            &scene,
            &inst,
            [0.0, 0.0, 0.0],
            [0.0, 0.0, -1.0],
            m,
            rays,
            100,
        )
    };
    let f = run(&tmp("agree_sphere_f"), &c("forward", 400_000), None).remove(0);
    let b = run(&tmp("agree_sphere_b"), &c("backward", 400_000), None).remove(0);
    let d = run(&tmp("agree_sphere_d"), &c("bdpt", 20_000), None).remove(0);
    compare_orders("sphere forward/backward", &f, &b, 5);
    compare_orders("sphere bdpt/forward", &d, &f, 5);
    compare_orders("sphere bdpt/backward", &d, &b, 5);
}

#[test]
fn three_methods_agree_on_a_leaf_layer_over_ground() {
    let dir = tmp("agree_canopy");
    let scene = leaf_layer(&dir);
    let inst = Inst {
        fp_mrad: 20.0,
        fov_mrad: 25.0,
        area: 0.1,
        energy: 0.001,
        fwhm_ns: 2.0,
        ..Inst::default()
    };
    let c = |m: &str| {
        campaign(
            &scene,
            &inst,
            [0.0, 0.0, 100.0],
            [0.0, 0.0, -1.0],
            m,
            1_000_000,
            100,
        )
    };
    let f = run(&tmp("agree_canopy_f"), &c("forward"), None).remove(0);
    let b = run(&tmp("agree_canopy_b"), &c("backward"), None).remove(0);
    let d = run(&tmp("agree_canopy_d"), &c("bdpt"), None).remove(0);
    // multiple scattering must matter in this scene for the comparison to mean anything
    assert!(f.order_energy_j[1] > 0.1 * f.order_energy_j[0]);
    compare_orders("canopy forward/backward", &f, &b, 4);
    compare_orders("canopy bdpt/forward", &d, &f, 4);
    compare_orders("canopy bdpt/backward", &d, &b, 4);
    compare_bins("canopy forward/backward", &f, &b);
    compare_bins("canopy bdpt/forward", &d, &f);
    compare_bins("canopy bdpt/backward", &d, &b);
}
