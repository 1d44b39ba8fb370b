//! The closed-form cases of ../shared/spec/physics.md.

mod common;
use common::*;
use lidarsim::waveform::Waveform;

/// Closed form 1: received energy within 1% and all of it in the bin of 2H/c.
fn plane_case(name: &str, h: f64, inst: Inst, method: &str, rays: u64) {
    plane_case_sampled(name, h, inst, method, rays, "independent");
}

/// [`plane_case`] with the given `simulation.sampler`.
fn plane_case_sampled(name: &str, h: f64, inst: Inst, method: &str, rays: u64, sampler: &str) {
    let dir = tmp(name);
    let rho = 0.3;
    let scene = plane_scene(&dir, rho, 200.0);
    let text = campaign(
        &scene,
        &inst,
        [0.0, 0.0, h],
        [0.0, 0.0, -1.0],
        method,
        rays,
        5,
    );
    let w = &run(&dir, &with_sampler(&text, sampler), None)[0];
    let expect = plane_energy(&inst, rho, h);
    let got = w.received_energy_j;
    let rel = (got - expect) / expect;
    let se = w.received_energy_se_j / expect;
    println!("{name}: H={h} got {got:.6e} expect {expect:.6e} rel {rel:+.4} se {se:.4}");
    // the test must be able to tell a 1% error from noise
    assert!(
        3.0 * se < 0.01,
        "standard error {se} too large for a 1% test"
    );
    assert!(rel.abs() < 0.01, "{name}: relative error {rel}");
    // single scattering only, and every path in the bin of τ = 2H/c
    assert!(w.order_energy_j[1..].iter().all(|&e| e == 0.0));
    assert_eq!(w.outside_gate_energy_j, 0.0);
    let bin = ((2.0 * h / C - w.t0_ns * 1e-9) / (w.bin_ns as f64 * 1e-9)).floor() as usize;
    let total: f64 = w.impulse_energy_j.iter().map(|&e| e as f64).sum();
    let in_bin = w.impulse_energy_j[bin] as f64;
    assert!(
        in_bin / total > 1.0 - 1e-6,
        "{name}: only {} of the energy in bin {bin}",
        in_bin / total
    );
    assert!((total - got).abs() / got < 1e-5);
}

// Each case runs the three methods with the rays it needs for a standard error well under
// 1/3 %: light tracing is weak when the field of view is the narrower cone, receiver tracing
// when the footprint is; BDPT weighs both.
#[test]
fn plane_airborne_fov_wider_than_footprint() {
    // Riegl-like at 250 m: a 17.8 cm lens beside a 9.4 cm field of view on the ground.
    let inst = Inst {
        fp_mrad: 0.25,
        fov_mrad: 0.375,
        area: 0.1,
        energy: 0.001,
        ..Inst::default()
    };
    plane_case("plane_250_wide", 250.0, inst.clone(), "forward", 1_000_000);
    plane_case(
        "plane_250_wide_bdpt",
        250.0,
        inst.clone(),
        "bdpt",
        1_000_000,
    );
    plane_case("plane_250_wide_bwd", 250.0, inst, "backward", 2_000_000);
}

#[test]
fn plane_airborne_fov_narrower_than_footprint() {
    let inst = Inst {
        fp_mrad: 0.25,
        fov_mrad: 0.15,
        area: 0.1,
        energy: 0.001,
        ..Inst::default()
    };
    plane_case(
        "plane_250_narrow",
        250.0,
        inst.clone(),
        "forward",
        4_000_000,
    );
    plane_case(
        "plane_250_narrow_bdpt",
        250.0,
        inst.clone(),
        "bdpt",
        1_000_000,
    );
    plane_case("plane_250_narrow_bwd", 250.0, inst, "backward", 1_000_000);
}

#[test]
fn plane_spaceborne_fov_wider_than_footprint() {
    let inst = Inst {
        fp_mrad: 0.03,
        fov_mrad: 0.3,
        area: 0.5,
        energy: 0.0105,
        ..Inst::default()
    };
    plane_case(
        "plane_419k_wide",
        419_000.0,
        inst.clone(),
        "forward",
        1_000_000,
    );
    plane_case("plane_419k_wide_bdpt", 419_000.0, inst, "bdpt", 1_000_000);
}

#[test]
fn plane_spaceborne_fov_narrower_than_footprint() {
    let inst = Inst {
        fp_mrad: 0.03,
        fov_mrad: 0.02,
        area: 0.5,
        energy: 0.0105,
        ..Inst::default()
    };
    plane_case(
        "plane_419k_narrow",
        419_000.0,
        inst.clone(),
        "forward",
        1_000_000,
    );
    plane_case(
        "plane_419k_narrow_bdpt",
        419_000.0,
        inst.clone(),
        "bdpt",
        1_000_000,
    );
    plane_case(
        "plane_419k_narrow_bwd",
        419_000.0,
        inst,
        "backward",
        1_000_000,
    );
}

/// Closed form 3: orders 1..5 and the total within 2%.
fn sphere_case(name: &str, albedo: f64, method: &str, fov_mrad: f64, rays: u64) {
    let dir = tmp(name);
    // a narrow field of view sees the lit spot's neighbourhood, where the bundled mesh's
    // flat facets exchange noticeably more than a sphere does: tessellate finer there
    let scene = if fov_mrad < 200.0 {
        fine_sphere_scene(&dir, albedo, 7)
    } else {
        sphere_scene(&dir, albedo)
    };
    let inst = Inst {
        fp_mrad: 20.0,
        fov_mrad,
        area: 0.01,
        energy: 0.001,
        ..Inst::default()
    };
    let w = &run(
        &dir,
        &campaign(
            &scene,
            &inst,
            [0.0, 0.0, 0.0],
            [0.3, -0.2, -1.0],
            method,
            rays,
            100,
        ),
        None,
    )[0];
    let mut total_expect = 0.0;
    for k in 1..=100u32 {
        total_expect += sphere_order_energy(&inst, albedo, 10.0, k);
    }
    for k in 1..=5u32 {
        let expect = sphere_order_energy(&inst, albedo, 10.0, k);
        let got = w.order_energy_j[k as usize - 1];
        let se = w.order_energy_se_j[k as usize - 1] / expect;
        let rel = (got - expect) / expect;
        println!("{name} order {k}: got {got:.5e} expect {expect:.5e} rel {rel:+.4} se {se:.4}");
        assert!(
            3.0 * se < 0.02,
            "order {k}: standard error {se} too large for a 2% test"
        );
        assert!(rel.abs() < 0.02, "{name} order {k}: relative error {rel}");
    }
    let rel = (w.received_energy_j - total_expect) / total_expect;
    println!(
        "{name} total: rel {rel:+.4} se {:.4}",
        w.received_energy_se_j / total_expect
    );
    assert!(rel.abs() < 0.02, "{name} total: relative error {rel}");
}

// Unidirectional estimators need a wide field of view here: only (1 - cos θ_fov)/2 of the
// wall is in view (physics.md, closed form 3).
/// Closed form 1 with the low-discrepancy first dimensions (`sampler: sobol`), each method
/// where the other is weak: the field of view narrower than the footprint.
#[test]
fn plane_with_sobol_samples() {
    let inst = Inst {
        fp_mrad: 0.03,
        fov_mrad: 0.02,
        area: 0.5,
        energy: 0.0105,
        ..Inst::default()
    };
    for method in ["forward", "bdpt", "backward"] {
        let name = format!("plane_419k_narrow_sobol_{method}");
        plane_case_sampled(&name, 419_000.0, inst.clone(), method, 1_000_000, "sobol");
    }
}

/// Few rays per pulse: over 256 pulses of 16 rays on closed form 1, with the field of view
/// narrower than the footprint and a small lens (only the rays that land inside the field of
/// view count, an indicator that independent draws sample unevenly), the low-discrepancy
/// first dimensions give a root-mean-square error under 0.8 of independent draws', for each
/// method, and neither has a bias beyond its standard error.
#[test]
fn sobol_samples_cut_the_error_at_few_rays() {
    let inst = Inst {
        fp_mrad: 0.3,
        fov_mrad: 0.2,
        area: 0.001,
        energy: 0.001,
        ..Inst::default()
    };
    let (h, rho) = (250.0, 0.3);
    let expect = plane_energy(&inst, rho, h);
    for method in ["forward", "backward", "bdpt"] {
        let rms = |sampler: &str| {
            let dir = tmp(&format!("few_rays_{method}_{sampler}"));
            let scene = plane_scene(&dir, rho, 200.0);
            let one = campaign(
                &scene,
                &inst,
                [0.0, 0.0, h],
                [0.0, 0.0, -1.0],
                method,
                16,
                5,
            );
            // the one pulse of the campaign text, 256 times (256 pulse ids, 256 streams)
            let (head, rest) = one.split_once("    - ").unwrap();
            let (pulse, tail) = rest.split_once('\n').unwrap();
            let text = format!("{head}{}{tail}", format!("    - {pulse}\n").repeat(256));
            let w = run(&dir, &with_sampler(&text, sampler), None);
            assert_eq!(w.len(), 256);
            let rel: Vec<f64> = w
                .iter()
                .map(|w| w.received_energy_j / expect - 1.0)
                .collect();
            let mean = rel.iter().sum::<f64>() / 256.0;
            let rms = (rel.iter().map(|r| r * r).sum::<f64>() / 256.0).sqrt();
            println!("{method} {sampler}: mean {mean:+.4} rms {rms:.4}");
            (mean, rms)
        };
        let (iid_mean, iid) = rms("independent");
        let (sobol_mean, sobol) = rms("sobol");
        assert!(
            iid > 0.03,
            "{method}: independent draws too good ({iid}) to tell"
        );
        // the rms of 256 pulses is known to about 4.4 %, a ratio of two to about 6 %
        assert!(
            sobol < 0.8 * iid,
            "{method}: sobol rms {sobol} against {iid}"
        );
        for (mean, rms) in [(iid_mean, iid), (sobol_mean, sobol)] {
            assert!(
                mean.abs() < 4.0 * rms / 16.0,
                "{method}: bias {mean} (rms {rms})"
            );
        }
    }
}

// 5·10^6 rays: at 4·10^6 the 5th order's standard error is 0.66-0.67 % depending on the
// random streams, on the edge of the 3σ < 2 % this test needs to mean anything
#[test]
fn integrating_sphere_albedo_05_forward() {
    sphere_case("sphere_05", 0.5, "forward", 300.0, 5_000_000);
}

#[test]
fn integrating_sphere_albedo_09_forward() {
    sphere_case("sphere_09", 0.9, "forward", 300.0, 2_500_000);
}

#[test]
fn integrating_sphere_albedo_09_bdpt() {
    sphere_case("sphere_09_bdpt", 0.9, "bdpt", 300.0, 20_000);
}

/// BDPT joins the lit spot to wall points in view directly, so it converges with a narrow
/// field of view too.
#[test]
fn integrating_sphere_albedo_09_bdpt_narrow_fov() {
    sphere_case("sphere_09_bdpt_narrow", 0.9, "bdpt", 100.0, 20_000);
}

/// Closed form 2: a plane of slope α spreads the impulse waveform; its shape is the
/// footprint-weighted histogram of 2·range/c, computed here by quadrature over the footprint.
#[test]
fn tilted_plane_waveform_matches_quadrature() {
    tilted_plane("tilted_forward", "forward");
    tilted_plane("tilted_bdpt", "bdpt");
}

/// Closed form 2 in each of three bands traced at once: the waveform's shape and level per
/// band, with that band's reflectance.
#[test]
fn tilted_plane_waveform_holds_in_every_band() {
    tilted_plane_in(
        "tilted_bands",
        "bdpt",
        &[(532.0, 0.12), (1064.0, 0.4), (1550.0, 0.33)],
    );
}

fn tilted_plane(name: &str, method: &str) {
    tilted_plane_in(name, method, &[(1064.0, 0.4)]);
}

/// The tilted plane of closed form 2 with reflectance `bands[k].1` at `bands[k].0` nm: one
/// band as the campaign's `wavelength_nm`, several as a list traced in one pass.
fn tilted_plane_in(name: &str, method: &str, bands: &[(f64, f64)]) {
    let dir = tmp(name);
    let alpha: f64 = 30f64.to_radians();
    let h = 500.0;
    // a 60 m square through the origin, tilted by α about the x axis (normal (0, -sin α, cos α))
    write(&dir, "tilted.obj", &tilted_square_obj(30.0, alpha));
    let (reflectance, wavelengths) = match bands {
        [(_, rho)] => (rho.to_string(), None),
        _ => {
            let table: Vec<String> = bands.iter().map(|(nm, r)| format!("{nm}: {r}")).collect();
            let list: Vec<String> = bands.iter().map(|(nm, _)| nm.to_string()).collect();
            (
                format!("{{ {} }}", table.join(", ")),
                Some(format!("wavelength_nm: [{}]\n", list.join(", "))),
            )
        }
    };
    let scene = write(
        &dir,
        "tilted.yaml",
        &format!("name: tilted\nmaterials:\n  soil: {{ reflectance: {reflectance} }}\nobjects:\n  - mesh: {{ file: tilted.obj, material: soil }}\n"),
    );
    let inst = Inst {
        fp_mrad: 5.0,
        fov_mrad: 6.0,
        area: 0.1,
        energy: 0.001,
        bin_ns: 1.0,
        ..Inst::default()
    };
    let mut text = campaign(
        &scene,
        &inst,
        [0.0, 0.0, h],
        [0.0, 0.0, -1.0],
        method,
        300_000,
        1,
    );
    if let Some(list) = wavelengths {
        text = text.replace("wavelength_nm: 1064\n", &list);
    }
    let rows = run(&dir, &text, None);
    assert_eq!(rows.len(), bands.len());
    for (w, &(nm, rho)) in rows.iter().zip(bands) {
        if bands.len() > 1 {
            assert_eq!(w.wavelength_nm, Some(nm));
        }
        check_tilted_plane(&format!("{name} {nm} nm"), w, &inst, h, alpha, rho);
    }
}

/// The checks of closed form 2 on one waveform of the tilted plane of reflectance `rho`.
fn check_tilted_plane(name: &str, w: &Waveform, inst: &Inst, h: f64, alpha: f64, rho: f64) {
    let (s, c) = (alpha.sin(), alpha.cos());

    // Quadrature in tan-space: each emission direction u lands on the plane at range r(u);
    // it returns energy ∝ p(u) ρ/π cos θ_surface · A / r² (the receiver sees it along the
    // same line, within the field of view), at time 2r/c.
    let t0 = w.t0_ns * 1e-9;
    let dt = w.bin_ns as f64 * 1e-9;
    let mut reference = vec![0.0; w.impulse_energy_j.len()];
    let n_plane = (0.0f64, -s, c);
    let u_max = (inst.fp_mrad * 1e-3).tan();
    let n = 1200;
    let du = 2.0 * u_max / n as f64;
    for i in 0..n {
        for j in 0..n {
            let ux = -u_max + (i as f64 + 0.5) * du;
            let uy = -u_max + (j as f64 + 0.5) * du;
            let u = (ux * ux + uy * uy).sqrt();
            let p = p_tan(u, inst.fp_mrad, inst.eta);
            if p == 0.0 {
                continue;
            }
            let len = (1.0 + u * u).sqrt();
            let d = (ux / len, uy / len, -1.0 / len);
            // plane through the origin: n·(P + r d) = 0
            let denom = n_plane.0 * d.0 + n_plane.1 * d.1 + n_plane.2 * d.2;
            let r = -(n_plane.2 * h) / denom;
            let cos_surface = denom.abs();
            let e = p * du * du * cos_surface / (r * r);
            let bin = ((2.0 * r / C - t0) / dt).floor();
            if bin >= 0.0 && (bin as usize) < reference.len() {
                reference[bin as usize] += e;
            }
        }
    }
    let sim: Vec<f64> = w.impulse_energy_j.iter().map(|&e| e as f64).collect();
    let norm = |v: &[f64]| {
        let s: f64 = v.iter().sum();
        v.iter().map(|x| x / s).collect::<Vec<_>>()
    };
    let (a, b) = (norm(&sim), norm(&reference));
    let support: Vec<usize> = (0..a.len()).filter(|&i| a[i] > 0.0 || b[i] > 0.0).collect();
    assert!(
        support.len() >= 10,
        "the slope should spread the return over many bins: {}",
        support.len()
    );
    let e = lidarsim::waveform::rrmse(&a, &b, &support);
    println!("{name}: {} bins, rRMSE {e:.4}", support.len());
    assert!(e < 0.03, "rRMSE {e}");
    // and the absolute level: ρ/π · A · Σ p cos/r² du² (same quadrature) within 1%
    let expect =
        rho / std::f64::consts::PI * inst.area * inst.energy * reference.iter().sum::<f64>();
    let rel = (w.received_energy_j - expect) / expect;
    println!("{name}: energy rel {rel:+.4}");
    assert!(rel.abs() < 0.01);
}

/// Closed form 1 with an offset telescope (`instrument.receiver_offset_m`): a static sensor's
/// platform frame is the scene's, so an offset of 0.12 m along y moves the aperture and its
/// field of view (0.1 m on the ground) off the footprint (0.1 m): the energy is the quadrature
/// of the two geometries' overlap within 1 %, here about a third of the mono-static one.
#[test]
fn plane_with_an_offset_telescope() {
    let inst = Inst {
        fp_mrad: 1.0,
        fov_mrad: 1.0,
        area: 0.001,
        energy: 0.001,
        ..Inst::default()
    };
    let (h, rho) = (100.0, 0.3);
    for (name, offset, method, rays) in [
        ("bistatic_y_bdpt", [0.0, 0.12], "bdpt", 400_000),
        ("bistatic_xy_fwd", [-0.05, 0.08], "forward", 400_000),
    ] {
        let dir = tmp(name);
        let scene = plane_scene(&dir, rho, 50.0);
        let text = campaign(
            &scene,
            &inst,
            [3.0, -2.0, h],
            [0.0, 0.0, -1.0],
            method,
            rays,
            2,
        )
        .replace(
            "  bin_ns: 1\n",
            &format!(
                "  bin_ns: 1\n  receiver_offset_m: [{}, {}, 0]\n",
                offset[0], offset[1]
            ),
        );
        assert!(text.contains("receiver_offset_m"));
        let w = &run(&dir, &text, None)[0];
        let expect = plane_energy_offset(&inst, rho, h, offset);
        let mono = plane_energy(&inst, rho, h);
        let got = w.received_energy_j;
        let (rel, se) = (got / expect - 1.0, w.received_energy_se_j / expect);
        println!("{name}: got {got:.5e} expect {expect:.5e} (mono-static {mono:.5e}) rel {rel:+.4} se {se:.4}");
        assert!(
            expect < 0.8 * mono,
            "the offset must matter: {expect} against {mono}"
        );
        assert!(
            3.0 * se < 0.01,
            "standard error {se} too large for a 1% test"
        );
        assert!(rel.abs() < 0.01, "{name}: relative error {rel}");
        assert_eq!(w.outside_gate_energy_j, 0.0);
    }
}

/// A return just outside a set range gate: its energy is counted outside the gate, yet its
/// pulse's tail reaches into the gate's first (or last) bins, where a digitiser records it.
/// Over a plane, every path arrives at τ = 2H/c, so the photons in the gate are the received
/// photons times the pulse's Gaussian mass over the gate, whichever side of it τ lies.
#[test]
fn a_return_beside_a_set_gate_leaves_its_tail_in_it() {
    let dir = tmp("gate_edge");
    let scene = plane_scene(&dir, 0.5, 200.0);
    let (h, fwhm_ns, bins) = (1000.0, 3.0, 20usize);
    let inst = Inst {
        energy: 0.001,
        fwhm_ns,
        fp_mrad: 0.5,
        fov_mrad: 1.0,
        ..Inst::default()
    };
    let tau_ns = 2.0 * h / C * 1e9;
    let sigma_ns = fwhm_ns / (8.0 * 2f64.ln()).sqrt();
    let hv = lidarsim::photon_energy_j(1064.0);
    // the gate's start from τ: after it (the return before the gate), just before it (the
    // return inside), and a gate ending before τ (the return after it)
    for start in [0.3, 1.0, -0.3, -20.7] {
        let text = campaign(
            &scene,
            &inst,
            [0.0, 0.0, h],
            [0.0, 0.0, -1.0],
            "bdpt",
            2000,
            1,
        )
        .replace(
            "\nplatform:",
            &format!(
                "\n  range_gate: {{ start_ns: {}, bins: {bins} }}\nplatform:",
                tau_ns + start
            ),
        );
        let sub = dir.join(format!("start{start}"));
        std::fs::create_dir_all(&sub).unwrap();
        let w = &run(&sub, &text, None)[0];
        let recorded: f64 = w.laser_photons.iter().map(|&p| p as f64).sum();
        let (a, b) = (start, start + bins as f64 * inst.bin_ns);
        let mass = lidarsim::waveform::normal_cdf(b / sigma_ns)
            - lidarsim::waveform::normal_cdf(a / sigma_ns);
        let expect = w.received_energy_j / hv * mass;
        println!("gate from τ{start:+} ns: {recorded:.5e} photons, expected {expect:.5e}");
        // the convolution's stepped quadrature of the bins' Gaussian masses is good to ~1e-4
        // of the pulse's photons (the same in a gate that holds the whole return)
        assert!(
            (recorded - expect).abs() <= 3e-4 * w.received_energy_j / hv,
            "gate from τ{start:+} ns: {recorded:.5e} photons, expected {expect:.5e}"
        );
        assert!(recorded > 0.0);
    }
}
