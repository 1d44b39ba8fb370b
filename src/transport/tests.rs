use super::*;
use crate::campaign::Instrument;

fn setup_scene(name: &str) -> Scene {
    let dir = crate::testdata::TempDir::new(name);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("s.yaml");
    std::fs::write(
        &path,
        "name: s\nmaterials:\n  a: { reflectance: 0.4, back_reflectance: 0.2, transmittance: 0.3 }\n  b: { reflectance: 0.7 }\nobjects:\n  - plane: { z: 0, extent: [[0, 0], [1, 1]], material: a }\n  - plane: { z: 1, extent: [[0, 0], [1, 1]], material: b }\n",
    )
    .unwrap();
    Scene::load(&path, 1064.0).unwrap()
}

fn instrument() -> Instrument {
    serde_yaml::from_str(
        "pulse_energy_j: 1\npulse_fwhm_ns: 0\nfootprint_half_angle_mrad: 600\nfov_half_angle_mrad: 700\nreceiver_area_m2: 0.01",
    )
    .unwrap()
}

fn setup<'a>(scene: &'a Scene, method: Method, heuristic: MisHeuristic) -> PulseSetup<'a> {
    let inst = instrument();
    let pos = DVec3::new(0.0, 0.0, 10.0);
    PulseSetup {
        scene,
        laser: Laser::new(&inst, pos, -DVec3::Z),
        receiver: Receiver::new(&inst, pos, -DVec3::Z),
        gate: Gate {
            t0: 0.0,
            dt: 1e-9,
            bins: 10,
        },
        sub_bins: 1,
        edge_sub_bins: 0,
        method,
        heuristic,
        sampler: crate::campaign::Sampler::Independent,
        receiver_depth: ReceiverDepth::Full,
        sun: None,
        atmosphere: None,
        bands: None,
        max_order: 12,
        seed: 1,
        pulse_id: 0,
    }
}

/// A random full path: laser, `order` surface vertices, a point of the aperture. The first
/// and last surface vertices lie inside the footprint and the field of view.
fn random_path(st: &PulseSetup, rng: &mut Rng, order: usize) -> Vec<Vertex> {
    let mut v = vec![Vertex::endpoint(
        VertexKind::Laser,
        st.laser.position,
        -DVec3::Z,
        1.0,
    )];
    for i in 0..order {
        let near_axis = i == 0 || i == order - 1;
        let spread = if near_axis { 2.0 } else { 8.0 };
        let p = DVec3::new(
            (rng.uniform() - 0.5) * spread,
            (rng.uniform() - 0.5) * spread,
            rng.uniform() * 4.0,
        );
        let n = DVec3::new(
            rng.uniform() - 0.5,
            rng.uniform() - 0.5,
            rng.uniform() - 0.5,
        )
        .normalize();
        // material 0 reflects on both sides (differently) and transmits: every path is
        // possible, so every strategy has a density
        let mut s = Vertex::endpoint(VertexKind::Surface, p, n, 0.0);
        s.surface = 0;
        v.push(s);
    }
    let q = st.receiver.sample_point(rng.uniform(), rng.uniform());
    v.push(Vertex::endpoint(
        VertexKind::Aperture,
        q,
        -DVec3::Z,
        1.0 / st.receiver.area,
    ));
    v
}

fn sub_path(st: &PulseSetup, vs: impl Iterator<Item = Vertex>) -> Vec<Vertex> {
    let mut out = Vec::new();
    for v in vs {
        out.push(v);
        link(st, &mut out);
    }
    out
}

#[test]
fn mis_weights_of_a_path_sum_to_one() {
    let scene = setup_scene("mis-sum");
    let mut rng = Rng::new(5, 6, 7);
    let mut scratch = Vec::new();
    for (method, heuristic, depth) in [
        (Method::Bdpt, MisHeuristic::Power, ReceiverDepth::Full),
        (Method::Bdpt, MisHeuristic::Balance, ReceiverDepth::Full),
        (Method::Bdpt, MisHeuristic::Power, ReceiverDepth::First),
        (Method::Bdpt, MisHeuristic::Balance, ReceiverDepth::First),
        (Method::Forward, MisHeuristic::Power, ReceiverDepth::Full),
        (Method::Backward, MisHeuristic::Power, ReceiverDepth::Full),
        // forward and backward have one sub-path: `first` changes nothing for them
        (Method::Backward, MisHeuristic::Power, ReceiverDepth::First),
    ] {
        let st = PulseSetup {
            receiver_depth: depth,
            ..setup(&scene, method, heuristic)
        };
        // the paths here start at the laser
        let (s_cap, t_cap) = st.caps_for(VertexKind::Laser);
        for trial in 0..400 {
            let order = 1 + trial % 8;
            let mut x = random_path(&st, &mut rng, order);
            // half the paths belong to a light chosen for sub-paths with probability 0.3
            if trial % 2 == 1 {
                x[0].pdf_fwd = 0.3;
            }
            let nv = x.len();
            let mut sum = 0.0;
            let mut strategies = 0;
            for s in 1..=nv {
                let t = nv - s;
                if s > s_cap || t > t_cap {
                    continue;
                }
                let light = sub_path(&st, x[..s].iter().copied());
                let cam = sub_path(&st, x[s..].iter().rev().copied());
                let w = mis_weight(&st, &light, &cam, &mut scratch);
                assert!(
                    (0.0..=1.0 + 1e-12).contains(&w),
                    "{method:?} s={s} t={t}: weight {w}"
                );
                sum += w;
                strategies += 1;
            }
            assert!(strategies >= 1);
            if depth == ReceiverDepth::First && method == Method::Bdpt {
                // t = 0, 1 and 2 only: the test would not see a cap that does nothing
                assert!(strategies <= 3, "order {order}: {strategies} strategies");
            }
            assert!(
                (sum - 1.0).abs() < 1e-9,
                "{method:?} {heuristic:?} order {order}: weights sum to {sum}"
            );
        }
    }
}

#[test]
fn a_wrong_density_breaks_the_sum() {
    // the check above can fail: perturb one stored density and the sum leaves 1
    let scene = setup_scene("mis-wrong");
    let st = setup(&scene, Method::Bdpt, MisHeuristic::Power);
    let mut rng = Rng::new(1, 2, 3);
    let mut scratch = Vec::new();
    let x = random_path(&st, &mut rng, 4);
    let nv = x.len();
    let mut sum = 0.0;
    for s in 1..=nv {
        let mut light = sub_path(&st, x[..s].iter().copied());
        let cam = sub_path(&st, x[s..].iter().rev().copied());
        if s >= 4 {
            light[1].pdf_rev *= 100.0;
        }
        sum += mis_weight(&st, &light, &cam, &mut scratch);
    }
    assert!((sum - 1.0).abs() > 1e-6, "{sum}");
}

/// White furnace of the RPV facet: the mean of [`bsdf::sample_bsdf`]'s throughput factors from
/// an incidence equals the albedo integral ∫ f cos dω (by quadrature) within 3 standard errors
/// (the quadrature's own error, its change from half the cells, added in quadrature),
/// for bowl- and bell-shaped, forward and backward parameter sets, from nadir to 80°, on both
/// sides; and the factor is f cos / pdf of the direction drawn, with the density that
/// [`bsdf_pdf`] gives.
#[test]
fn rpv_sampling_weights_integrate_to_the_albedo() {
    use crate::scene::{Rpv, Surface, SurfaceClass};
    let cases = [
        (0.3, 0.7, -0.2, None),
        (0.5, 1.3, 0.15, Some(0.2)),
        (0.12, 0.95, -0.05, Some(0.9)),
    ];
    let mut rng = Rng::new(5, 0, 0);
    for (rho0, k, theta, rho_c) in cases {
        let shape = Rpv {
            k,
            theta,
            rho_c,
            limit: None,
        };
        let s = Surface {
            name: "rpv".into(),
            reflectance: rho0,
            back_reflectance: rho0,
            transmittance: 0.0,
            bands: vec![[rho0, rho0, 0.0]],
            rpv: Some(shape),
            band_rpv: vec![shape],
            water: None,
            class: SurfaceClass::Ground,
        };
        for deg in [0.0f64, 35.0, 60.0, 80.0] {
            let mu = deg.to_radians().cos();
            let want = shape.albedo(rho0, mu, 800, 240);
            let quadrature_error = (want - shape.albedo(rho0, mu, 400, 120)).abs();
            for side in [1.0, -1.0] {
                let n = DVec3::Z * side;
                // w_prev on the side the normal points to, or on the other for the back
                let w_prev = DVec3::new((1.0 - mu * mu).sqrt(), 0.0, mu * side);
                let (mut sum, mut sq, count) = (0.0, 0.0, 400_000);
                for i in 0..count {
                    let (d, w, _) = bsdf::sample_bsdf(&s, n, w_prev, true, &mut rng).unwrap();
                    sum += w;
                    sq += w * w;
                    if i < 100 {
                        let f = bsdf(&s, n, w_prev, d) * n.dot(d).abs();
                        let p = bsdf_pdf(&s, n, w_prev, d);
                        assert!((f / p - w).abs() <= 1e-12 * w.max(1.0), "{f} / {p} != {w}");
                    }
                }
                let mean = sum / count as f64;
                let se = ((sq / count as f64 - mean * mean) / (count - 1) as f64).sqrt();
                println!(
                    "rpv ρ0 {rho0} k {k} Θ {theta} at {deg}° side {side}: {mean:.5} ± {se:.5}, quadrature {want:.5}"
                );
                let tolerance = 3.0 * se.hypot(quadrature_error);
                assert!(
                    (mean - want).abs() < tolerance,
                    "{mean} vs {want} (se {se})"
                );
                assert!(se < 0.01 * want, "standard error too large to tell 1 %");
            }
        }
    }
}

/// The wind-roughened water surface: its BSDF is reciprocal as a dielectric's must be
/// (f(l→v)/n_v² = f(v→l)/n_l²), its density integrates over the sphere (quadrature) to the
/// share of draws that leave a valid direction, and the weight of every draw is f |cos| / pdf;
/// from the air at 60° the flux it passes on (reflected plus transmitted) is 1 less what the
/// facets shadow: at most 1 within 3 SE, and above 0.97.
#[test]
fn rough_water_is_reciprocal_and_its_densities_are_its_draws() {
    use crate::scene::{Surface, SurfaceClass, WaterInterface};
    let water = WaterInterface {
        n: 1.33,
        mss: 0.003 + 0.00512 * 6.0,
    };
    let s = Surface {
        name: "water".into(),
        reflectance: 0.0,
        back_reflectance: 0.0,
        transmittance: 0.0,
        bands: vec![[0.0; 3]],
        rpv: None,
        band_rpv: Vec::new(),
        water: Some(water),
        class: SurfaceClass::Other,
    };
    let n = DVec3::Z;
    let mut rng = Rng::new(9, 0, 0);
    let uniform = |rng: &mut Rng| {
        let z = 2.0 * rng.uniform() - 1.0;
        let phi = std::f64::consts::TAU * rng.uniform();
        let r = (1.0 - z * z).max(0.0).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    };
    // reciprocity, both sides, reflection and transmission
    let mut checked = 0;
    for _ in 0..20_000 {
        let (l, v) = (uniform(&mut rng), uniform(&mut rng));
        let index = |d: DVec3| if d.z > 0.0 { 1.0 } else { water.n };
        let (a, b) = (
            bsdf(&s, n, l, v) / index(v).powi(2),
            bsdf(&s, n, v, l) / index(l).powi(2),
        );
        assert!(
            (a - b).abs() <= 1e-6 * a.abs().max(b.abs()) + 1e-290,
            "{l} {v}: {a} {b}"
        );
        checked += usize::from(a > 0.0);
    }
    assert!(checked > 1000, "{checked}");
    for (w_prev, name) in [
        (DVec3::new(0.3, 0.1, 0.9).normalize(), "from the air"),
        (DVec3::new(-0.2, 0.25, -0.8).normalize(), "from the water"),
    ] {
        // share of valid draws, and each draw's weight against f |cos| / pdf
        let count = 400_000;
        let mut valid = 0usize;
        for _ in 0..count {
            if let Some((d, w, delta)) = bsdf::sample_bsdf(&s, n, w_prev, true, &mut rng) {
                assert!(!delta);
                let f = bsdf(&s, n, w_prev, d) * n.dot(d).abs();
                let p = bsdf_pdf(&s, n, w_prev, d);
                assert!((f / p - w).abs() <= 1e-9 * w.max(1.0));
                valid += 1;
            }
        }
        let share = valid as f64 / count as f64;
        // ∫ pdf dω over the sphere by the midpoint rule (the lobes are 0.05-0.4 rad wide;
        // the cells 0.0016 by 0.003 rad)
        let (nt, np) = (2000, 2000);
        let mut integral = 0.0;
        for i in 0..nt {
            let theta = std::f64::consts::PI * (i as f64 + 0.5) / nt as f64;
            let (st, ct) = theta.sin_cos();
            for j in 0..np {
                let phi = std::f64::consts::TAU * (j as f64 + 0.5) / np as f64;
                let d = DVec3::new(st * phi.cos(), st * phi.sin(), ct);
                integral += bsdf_pdf(&s, n, w_prev, d) * st;
            }
        }
        integral *= std::f64::consts::PI / nt as f64 * std::f64::consts::TAU / np as f64;
        let share_se = (share * (1.0 - share) / count as f64).sqrt();
        println!("rough water {name}: ∫ pdf = {integral:.5}, valid draws {share:.5}");
        assert!(
            (integral - share).abs() < 2e-3 + 3.0 * share_se,
            "{integral} vs {share}"
        );
        assert!(share > 0.95);
    }
    // 60° from the air: reflected + transmitted flux, 1 less what the facets shadow
    let (mut sum, mut sq, count) = (0.0, 0.0, 400_000);
    let w_prev = DVec3::new(0.75f64.sqrt(), 0.0, 0.5);
    for _ in 0..count {
        let w = bsdf::sample_bsdf(&s, n, w_prev, true, &mut rng).map_or(0.0, |x| x.1);
        sum += w;
        sq += w * w;
    }
    let mean = sum / count as f64;
    let se = ((sq / count as f64 - mean * mean) / (count - 1) as f64).sqrt();
    println!("rough water at 60°: flux passed on {mean:.5} ± {se:.5}");
    assert!(mean <= 1.0 + 3.0 * se && mean > 0.97, "{mean}");
}
