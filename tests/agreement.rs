//! Forward, backward and bidirectional estimators converge to the same waveform (physics.md,
//! check 5): per scattering order and per bin, within 3 combined standard errors.

mod common;
use common::*;
use lidarsim::waveform::Waveform;
use std::fmt::Write;

/// Per-order agreement: |a - b| < 3 combined standard errors, with standard errors small
/// enough that a 10% disagreement could not hide.
fn compare_orders(name: &str, a: &Waveform, b: &Waveform, orders: usize) {
    for k in 0..orders {
        let (ea, eb) = (a.order_energy_j[k], b.order_energy_j[k]);
        let se = (a.order_energy_se_j[k].powi(2) + b.order_energy_se_j[k].powi(2)).sqrt();
        let z = (ea - eb) / se;
        println!(
            "{name} order {}: {ea:.5e} vs {eb:.5e} z {z:+.2} rel se {:.4}",
            k + 1,
            se / ea
        );
        assert!(
            se / ea.max(eb) < 0.033,
            "{name} order {}: standard error too large",
            k + 1
        );
        assert!(
            z.abs() < 3.0,
            "{name} order {}: the methods differ by {z:.2} standard errors",
            k + 1
        );
    }
    let se = (a.received_energy_se_j.powi(2) + b.received_energy_se_j.powi(2)).sqrt();
    let z = (a.received_energy_j - b.received_energy_j) / se;
    println!("{name} total: z {z:+.2}");
    assert!(z.abs() < 3.0);
}

/// Per-bin agreement of the impulse waveforms over the bins that hold 99.9% of the energy.
/// Each bin's z-score must stay within 3 (a bin beyond is reported; with many bins one in a
/// few hundred may be, so at most 1% of them), and Σz² must stay under the 99.9% quantile of
/// its χ² distribution (Wilson-Hilferty), which a systematic shift of the shape would break.
fn compare_bins(name: &str, a: &Waveform, b: &Waveform) {
    let total: f64 = a.impulse_energy_j.iter().map(|&e| e as f64).sum();
    let mut bins: Vec<usize> = (0..a.impulse_energy_j.len()).collect();
    bins.sort_by(|&i, &j| a.impulse_energy_j[j].total_cmp(&a.impulse_energy_j[i]));
    let mut acc = 0.0;
    let mut kept = Vec::new();
    for i in bins {
        if acc >= 0.999 * total {
            break;
        }
        acc += a.impulse_energy_j[i] as f64;
        kept.push(i);
    }
    let mut chi2 = 0.0;
    let mut beyond = 0;
    for &i in &kept {
        let se = ((a.impulse_energy_se_j[i] as f64).powi(2)
            + (b.impulse_energy_se_j[i] as f64).powi(2))
        .sqrt();
        let z = (a.impulse_energy_j[i] as f64 - b.impulse_energy_j[i] as f64) / se;
        chi2 += z * z;
        if z.abs() >= 3.0 {
            beyond += 1;
        }
    }
    let k = kept.len() as f64;
    let q999 = k * (1.0 - 2.0 / (9.0 * k) + 3.09 * (2.0 / (9.0 * k)).sqrt()).powi(3);
    println!(
        "{name}: {} bins, {beyond} beyond 3 SE, chi2 {chi2:.1} (99.9% quantile {q999:.1})",
        kept.len()
    );
    assert!(kept.len() >= 5);
    assert!(
        beyond as f64 <= (0.01 * k).max(1.0),
        "{name}: {beyond} of {} bins beyond 3 SE",
        kept.len()
    );
    assert!(chi2 < q999, "{name}: chi2 {chi2} over {k} bins");
}

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

/// A layer of small leaves (ρ = τ = 0.45 at 1064 nm, LAI about 1.7) between 5 and 8 m over a
/// soil plane: multiple scattering carries a fifth of the signal.
pub fn leaf_layer(dir: &std::path::Path) -> std::path::PathBuf {
    let mut obj = String::new();
    let mut state: u64 = 0x2545F4914F6CDD1D;
    let mut rnd = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let leaves = 100_000;
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
