//! Numerically hard cases: results must stay finite, non-negative and unbiased.

mod common;
use common::*;
use lidarsim::waveform::Waveform;

fn finite_non_negative(name: &str, w: &Waveform) {
    let all = w
        .laser_photons
        .iter()
        .chain(&w.impulse_energy_j)
        .map(|&x| x as f64)
        .chain(w.order_energy_j.iter().copied())
        .chain([
            w.received_energy_j,
            w.outside_gate_energy_j,
            w.received_energy_se_j,
        ]);
    for x in all {
        assert!(x.is_finite() && x >= 0.0, "{name}: value {x}");
    }
    assert!(w.received_energy_j > 0.0, "{name}: nothing received");
}

/// |got - expect| within 3 standard errors, and a standard error small enough (< `max_se`,
/// relative) that the check means something.
fn unbiased(name: &str, got: f64, se: f64, expect: f64, max_se: f64) {
    let z = (got - expect) / se;
    println!(
        "{name}: got {got:.6e} expect {expect:.6e} rel {:+.4} se {:.4} z {z:+.2}",
        got / expect - 1.0,
        se / expect
    );
    assert!(
        se / expect < max_se,
        "{name}: standard error {} too large",
        se / expect
    );
    assert!(
        z.abs() < 3.0,
        "{name}: {z:.2} standard errors from the expected value"
    );
}

#[test]
fn grazing_incidence_89_degrees_off_nadir() {
    // sensor 100 m above a plane, beam 89° off nadir: the footprint lands 5.7 km away,
    // stretched 57-fold along the beam
    let dir = tmp("hard_grazing");
    let scene = plane_scene(&dir, 0.5, 8000.0);
    let inst = Inst {
        fp_mrad: 0.1,
        fov_mrad: 0.2,
        area: 0.1,
        energy: 0.001,
        ..Inst::default()
    };
    let a = 89f64.to_radians();
    let d = [a.sin(), 0.0, -a.cos()];
    for method in ["bdpt", "forward", "backward"] {
        let w = run(
            &tmp(&format!("hard_grazing_{method}")),
            &campaign(&scene, &inst, [0.0, 0.0, 100.0], d, method, 400_000, 3),
            None,
        )
        .remove(0);
        finite_non_negative(method, &w);
        // small footprint: every ray meets the plane at the same angle and about the same range
        let r = 100.0 / a.cos();
        let expect = 0.5 / std::f64::consts::PI * inst.energy * inst.area * a.cos() / (r * r);
        unbiased(
            &format!("grazing {method}"),
            w.received_energy_j,
            w.received_energy_se_j.max(1e-3 * expect),
            expect,
            0.01,
        );
    }
}

#[test]
fn two_leaves_one_micrometre_apart() {
    let dir = tmp("hard_leaves");
    let obj = "v -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\nv -1 -1 1.000001\nv 1 -1 1.000001\nv 1 1 1.000001\nv -1 1 1.000001\nf 1 2 3\nf 1 3 4\nf 5 6 7\nf 5 7 8\n";
    write(&dir, "leaves.obj", obj);
    let scene = write(
        &dir,
        "leaves.yaml",
        "name: leaves\nmaterials:\n  leaf: { reflectance: 0.45, transmittance: 0.45 }\n  soil: { reflectance: 0.3 }\nobjects:\n  - plane: { z: 0, extent: [[-3, -3], [3, 3]], material: soil }\n  - mesh: { file: leaves.obj, material: leaf }\n",
    );
    let inst = Inst {
        fp_mrad: 20.0,
        fov_mrad: 25.0,
        area: 0.01,
        energy: 0.001,
        ..Inst::default()
    };
    let mut results = Vec::new();
    for method in ["bdpt", "forward", "backward"] {
        let w = run(
            &tmp(&format!("hard_leaves_{method}")),
            &campaign(
                &scene,
                &inst,
                [0.0, 0.0, 20.0],
                [0.0, 0.0, -1.0],
                method,
                300_000,
                100,
            ),
            None,
        )
        .remove(0);
        finite_non_negative(method, &w);
        results.push(w);
    }
    // Orders inside the pair, which the soil 1 m below cannot reach before order 5: order 1
    // is the top leaf's reflection, order 2 does not exist (to leave upwards after entering
    // the gap, light must cross the top leaf again), order 3 is τ ρ τ through the top leaf
    // off the bottom one. A 1 µm gap mishandled shows up as order-2 energy or as a loss.
    let (rho, tau) = (0.45f64, 0.45f64);
    let h = 20.0 - 1.000001;
    let order1 = plane_energy(&inst, rho, h);
    let order3 = plane_energy(&inst, tau * rho * tau, h);
    for (w, method) in results.iter().zip(["bdpt", "forward", "backward"]) {
        let se = &w.order_energy_se_j;
        unbiased(
            &format!("stacked leaves {method} order 1"),
            w.order_energy_j[0],
            se[0].max(1e-4 * order1),
            order1,
            0.01,
        );
        // no even order exists: light leaves upwards after an odd number of reflections and
        // crosses each leaf an even number of times (bdpt's connections between two points of
        // one leaf run in its plane, where G rounds to ~1e-17: 1e-11 of order 1 at most seen)
        for k in (2..=8).step_by(2) {
            assert!(
                w.order_energy_j[k - 1] < 1e-6 * order1,
                "{method}: order {k} cannot exist: {:e}",
                w.order_energy_j[k - 1]
            );
        }
        unbiased(
            &format!("stacked leaves {method} order 3"),
            w.order_energy_j[2],
            se[2].max(1e-4 * order3),
            order3,
            0.01,
        );
    }
    // and the three methods agree on every order the soil makes too (the odd ones: the even
    // ones' rounding has no standard error to be judged by)
    for k in (0..8).step_by(2) {
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            let (x, y) = (&results[a], &results[b]);
            let se = x.order_energy_se_j[k].hypot(y.order_energy_se_j[k]);
            if se > 0.0 {
                let z = (x.order_energy_j[k] - y.order_energy_j[k]) / se;
                assert!(
                    z.abs() < 3.5,
                    "order {}: methods {a} and {b} differ by {z:.2} standard errors",
                    k + 1
                );
            }
        }
    }
}

#[test]
fn ray_leaving_a_facet_400_km_from_the_origin() {
    // the same plane and sensor, once at the origin and once 400 km away in x and y
    let inst = Inst {
        fp_mrad: 0.25,
        fov_mrad: 0.375,
        area: 0.1,
        energy: 0.001,
        ..Inst::default()
    };
    let mut got = Vec::new();
    for (name, off) in [("near", 0.0), ("far", 400_000.0)] {
        let dir = tmp(&format!("hard_far_{name}"));
        let scene = write(
            &dir,
            "plane.yaml",
            &format!(
                "name: p\nmaterials:\n  soil: {{ reflectance: 0.3 }}\nobjects:\n  - plane: {{ z: 0, extent: [[{}, {}], [{}, {}]], material: soil }}\n  - plane: {{ z: 3, extent: [[{}, {}], [{}, {}]], material: soil }}\n",
                off - 50.0, off - 50.0, off + 50.0, off + 50.0, off + 0.03, off - 1.0, off + 1.0, off + 1.0
            ),
        );
        // a second, small roof 3 m up half covers the footprint: multiple scattering and
        // occlusion both happen 400 km from the origin
        let w = run(
            &dir,
            &campaign(
                &scene,
                &inst,
                [off, off, 250.0],
                [0.0, 0.0, -1.0],
                "bdpt",
                400_000,
                10,
            ),
            None,
        )
        .remove(0);
        finite_non_negative(name, &w);
        got.push(w);
    }
    let (a, b) = (&got[0], &got[1]);
    let se = (a.received_energy_se_j.powi(2) + b.received_energy_se_j.powi(2)).sqrt();
    unbiased(
        "far from the origin",
        b.received_energy_j,
        se,
        a.received_energy_j,
        0.01,
    );
    // the roof and the ground are 3 m apart: two returns, 20 ns apart, in both
    let peaks = |w: &Waveform| {
        w.impulse_energy_j
            .iter()
            .filter(|&&e| e as f64 > 0.05 * w.received_energy_j)
            .count()
    };
    assert_eq!(peaks(a), 2);
    assert_eq!(peaks(b), 2);
}

#[test]
fn albedo_099_with_max_order_100() {
    let dir = tmp("hard_albedo");
    let scene = sphere_scene(&dir, 0.99);
    let inst = Inst {
        fp_mrad: 20.0,
        fov_mrad: 300.0,
        area: 0.01,
        energy: 0.001,
        ..Inst::default()
    };
    let expect: f64 = (1..=100)
        .map(|k| sphere_order_energy(&inst, 0.99, 10.0, k))
        .sum();
    for (method, rays) in [("forward", 400_000), ("bdpt", 3_000)] {
        let w = run(
            &tmp(&format!("hard_albedo_{method}")),
            &campaign(
                &scene,
                &inst,
                [0.0, 0.0, 0.0],
                [0.0, 0.0, -1.0],
                method,
                rays,
                100,
            ),
            None,
        )
        .remove(0);
        finite_non_negative(method, &w);
        assert_eq!(w.order_energy_j.len(), 100);
        assert!(w.order_energy_j[99] > 0.0, "order 100 must be reached");
        // the bundled icosphere's facets exchange up to 0.4% more than a sphere in order 2
        // (measured against a finer tessellation): allow that beside 3 standard errors
        let se = w
            .received_energy_se_j
            .hypot(0.004 * sphere_order_energy(&inst, 0.99, 10.0, 2));
        unbiased(
            &format!("albedo 0.99 {method}"),
            w.received_energy_j,
            se,
            expect,
            0.02,
        );
    }
}

#[test]
fn five_centimetre_footprint_over_a_100_m_scene() {
    // spaceborne: 5 cm footprint from 419 km (θ = 6e-8 rad) over a 100 m plane
    let dir = tmp("hard_tiny");
    let scene = plane_scene(&dir, 0.3, 50.0);
    let h = 419_000.0;
    let fp = 0.025 / h * 1e3;
    let inst = Inst {
        fp_mrad: fp,
        fov_mrad: 0.3,
        area: 0.5,
        energy: 0.0105,
        ..Inst::default()
    };
    for method in ["bdpt", "forward"] {
        let w = run(
            &tmp(&format!("hard_tiny_{method}")),
            &campaign(
                &scene,
                &inst,
                [10.0, -7.0, h],
                [0.0, 0.0, -1.0],
                method,
                100_000,
                3,
            ),
            None,
        )
        .remove(0);
        finite_non_negative(method, &w);
        let expect = plane_energy(&inst, 0.3, h);
        unbiased(
            &format!("5 cm footprint {method}"),
            w.received_energy_j,
            w.received_energy_se_j.max(1e-4 * expect),
            expect,
            0.01,
        );
        let peak = w.impulse_energy_j.iter().cloned().fold(0.0f32, f32::max) as f64;
        assert!(
            peak / w.received_energy_j > 1.0 - 1e-6,
            "{method}: the return spreads over bins"
        );
    }
}

/// A 10 cm cube written in UTM-like coordinates (its centre at 654,321.987 m): seen from its
/// centre, its wall is 5 cm away, and an OBJ file says so as a PLY file of doubles does. As
/// f32 the OBJ's vertices were rounded to 6 cm before the scene was re-centred: the wall lay at
/// 75.6 mm and the energy came out 56 % low.
#[test]
fn a_mesh_in_utm_coordinates_keeps_its_millimetres() {
    let dir = tmp("utm_mesh");
    let c = [654_321.987, 654_321.987, 1_234.567_8];
    let corners: Vec<[f64; 3]> = (0..8)
        .map(|k| {
            let s = |bit: usize| if k >> bit & 1 == 1 { 0.05 } else { -0.05 };
            [c[0] + s(0), c[1] + s(1), c[2] + s(2)]
        })
        .collect();
    // the cube's twelve facets, by corner (bit 0: +x, bit 1: +y, bit 2: +z)
    let faces = [
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ];
    let obj: String = corners
        .iter()
        .map(|v| format!("v {:.10} {:.10} {:.10}\n", v[0], v[1], v[2]))
        .chain(
            faces
                .iter()
                .map(|f| format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1)),
        )
        .collect();
    let ply = format!(
        "ply\nformat ascii 1.0\nelement vertex 8\nproperty double x\nproperty double y\nproperty double z\nelement face 12\nproperty list uchar int vertex_indices\nend_header\n{}{}",
        corners
            .iter()
            .map(|v| format!("{:.10} {:.10} {:.10}\n", v[0], v[1], v[2]))
            .collect::<String>(),
        faces
            .iter()
            .map(|f| format!("3 {} {} {}\n", f[0], f[1], f[2]))
            .collect::<String>()
    );
    write(&dir, "cube.obj", &obj);
    write(&dir, "cube.ply", &ply);
    let (energy, rho, area, d) = (0.001, 0.5, 1e-8, 0.05);
    let expect = energy * rho * area / (std::f64::consts::PI * d * d);
    let mut got = Vec::new();
    for file in ["cube.obj", "cube.ply"] {
        let scene = write(
            &dir,
            &format!("{file}.yaml"),
            &format!("name: s\nmaterials:\n  w: {{ reflectance: {rho} }}\nobjects:\n  - mesh: {{ file: {file}, material: w }}\n"),
        );
        let text = format!(
            "name: t\nscene: {}\nseed: 3\nwavelength_nm: 1064\ninstrument: {{ pulse_energy_j: {energy}, pulse_fwhm_ns: 0, footprint_half_angle_mrad: 0.0001, fov_half_angle_mrad: 20, receiver_area_m2: {area}, bin_ns: 0.001 }}\nplatform:\n  kind: static\n  pulses:\n    - {{ position: [{}, {}, {}], direction: [1, 0, 0] }}\nsimulation: {{ method: forward, rays_per_pulse: 2000, max_order: 1 }}\n",
            scene.display(),
            c[0],
            c[1],
            c[2]
        );
        let sub = dir.join(file.replace('.', "_"));
        std::fs::create_dir_all(&sub).unwrap();
        let w = run(&sub, &text, None).remove(0);
        finite_non_negative(file, &w);
        // the wall's range from the start of the bin holding the energy (the impulse spans
        // the whole gate): bins of 0.15 mm
        let (b, _) = w
            .impulse_energy_j
            .iter()
            .enumerate()
            .fold((0, 0.0f32), |m, (i, &e)| if e > m.1 { (i, e) } else { m });
        let t_ns = w.t0_ns + b as f64 * w.bin_ns as f64;
        let range = C * t_ns * 1e-9 / 2.0;
        println!(
            "{file}: wall at {:.3} mm, {:.6e} J",
            range * 1e3,
            w.received_energy_j
        );
        assert!(
            (range - d).abs() < 3e-4,
            "{file}: wall at {range} m, not {d} m"
        );
        unbiased(
            file,
            w.received_energy_j,
            w.received_energy_se_j.max(1e-6 * expect),
            expect,
            0.01,
        );
        got.push(w.received_energy_j);
    }
    assert_eq!(
        got[0], got[1],
        "the OBJ and the PLY of the same cube differ"
    );
}
