use super::*;
use crate::rng::SplitMix64;
use crate::waveform::normal_cdf;

/// A receiver of returns `sigma_bins` wide, with the default footprint (cut at 2 of its sigmas,
/// an edge energy fraction of e^-2) and no noise beyond shot noise.
fn rx(sigma_bins: f64) -> Receiver {
    Receiver {
        sigma_bins,
        footprint_edge_sigmas: Some(2.0),
        noise_floor: 0.0,
        false_alarm_rate: None,
    }
}

#[derive(Debug)]
struct Truth {
    centre: f64,
    sigma: f64,
    area: f64,
}

fn bin_mass(i: usize, t: &Truth) -> f64 {
    normal_cdf((i as f64 + 1.0 - t.centre) / t.sigma) - normal_cdf((i as f64 - t.centre) / t.sigma)
}

/// `count` Gaussians, sigmas in [1.5, 4] bins, areas log-uniform in [50, 5000] photons,
/// centres at least 3 × the larger sigma apart.
fn random_case(r: &mut SplitMix64, count: usize, min_area: f64, range: f64) -> (Vec<Truth>, usize) {
    let mut t: Vec<Truth> = Vec::new();
    let mut pos = 15.0 + 10.0 * r.uniform();
    for k in 0..count {
        let sigma = 1.5 + 2.5 * r.uniform();
        let area = min_area * range.powf(r.uniform());
        if k > 0 {
            let prev: &Truth = &t[k - 1];
            pos = prev.centre + 3.0 * prev.sigma.max(sigma) + 8.0 * r.uniform();
        }
        t.push(Truth {
            centre: pos,
            sigma,
            area,
        });
    }
    let len = (pos + 25.0).ceil() as usize;
    (t, len)
}

fn mean_waveform(t: &[Truth], len: usize) -> Vec<f64> {
    (0..len)
        .map(|i| t.iter().map(|g| g.area * bin_mass(i, g)).sum())
        .collect()
}

/// Noise-free sums of Gaussians come back exactly. Areas start at 5000 photons: below
/// that a weak return 3σ beside a strong one may not improve the Poisson deviance by the
/// 16 the decomposition asks of an extra component, and is then rightly kept merged.
#[test]
fn noise_free_gaussians_are_recovered_exactly() {
    let mut r = SplitMix64::new(1);
    let (mut worst_c, mut worst_a) = (0.0f64, 0.0f64);
    let mut missed: Vec<String> = Vec::new();
    for count in 1..=4 {
        for case in 0..200 {
            let (t, len) = random_case(&mut r, count, 5000.0, 100.0);
            let y: Vec<f32> = mean_waveform(&t, len).iter().map(|&v| v as f32).collect();
            let c = decompose(&y, &[], &[], 2.0, 4, Decomposition::Gaussian, &rx(1.5));
            if c.len() != count {
                missed.push(format!("count {count} case {case}: {c:?} truth {t:?}"));
                continue;
            }
            for (g, f) in t.iter().zip(&c) {
                worst_c = worst_c.max((f.centre_bin - g.centre).abs());
                worst_a = worst_a.max((f.area_photons / g.area - 1.0).abs());
            }
        }
    }
    println!(
        "noise-free: {} of 800 cases with a wrong count; max centre error {worst_c:.2e} bin, \
         max area error {worst_a:.2e}",
        missed.len()
    );
    assert!(missed.is_empty(), "{missed:#?}");
    assert!(worst_c < 0.01 && worst_a < 0.002);
}

/// The decomposition's criterion: 1 to 4 Gaussians (σ 1.5–4 bins, at least 3σ apart) with
/// Poisson noise, centres within 0.1 bin and areas within 2 %. Areas are 5·10⁴–5·10⁵ photons, a
/// mJ-class airborne return (the bundled ALS campaign over the plane gets ~2·10⁸), one
/// decade apart at most within a waveform: there the Cramér–Rao bounds of an isolated
/// return, σ/√A ≤ 0.018 bin and 1/√A ≤ 0.45 %, put the tolerances at 5.6 and 4.5 standard
/// errors; a neighbour 3σ away widens them (the test prints the worst errors). A return
/// beside one a hundred times stronger has bounds several times larger, and 2 % does not
/// hold there: the width of the weak one trades against the strong one's tail.
#[test]
fn noisy_gaussians_meet_a_tenth_of_a_bin_and_two_percent() {
    let mut r = SplitMix64::new(4);
    let (mut worst_c, mut worst_a, mut n) = (0.0f64, 0.0f64, 0);
    let mut missed: Vec<String> = Vec::new();
    for count in 1..=4 {
        for case in 0..200 {
            let (t, len) = random_case(&mut r, count, 5e4, 10.0);
            let y: Vec<f32> = mean_waveform(&t, len)
                .iter()
                .map(|&v| r.poisson(v) as f32)
                .collect();
            let c = decompose(&y, &[], &[], 5.0, 4, Decomposition::Gaussian, &rx(1.5));
            if c.len() != count {
                missed.push(format!("count {count} case {case}: {c:?} truth {t:?}"));
                continue;
            }
            for (g, f) in t.iter().zip(&c) {
                worst_c = worst_c.max((f.centre_bin - g.centre).abs());
                worst_a = worst_a.max((f.area_photons / g.area - 1.0).abs());
                n += 1;
            }
        }
    }
    println!(
        "poisson, 5e4-5e5 photons: {} of 800 cases with a wrong count; {n} returns, max \
         centre error {worst_c:.4} bin, max area error {:.3} %",
        missed.len(),
        worst_a * 100.0
    );
    assert!(missed.is_empty(), "{missed:#?}");
    assert!(worst_c < 0.1, "centre off by {worst_c} bin");
    assert!(worst_a < 0.02, "area off by {worst_a}");
}

/// Weak returns (50–5000 photons) with Poisson noise cannot meet 0.1 bin and 2 % (the
/// Cramér–Rao bounds are σ/√A bins and 1/√A: 0.57 bin and 14 % at A = 50, σ = 4), and a
/// weak return beside a strong one is sometimes not worth an extra component to the
/// likelihood-ratio test. What must hold: the count is right in at least 99 % of cases,
/// and the pulls against the truth in units of those bounds have a median |z| near the
/// 0.67 of a unit normal (below 1: fits no worse than 1.5 × the bound on typical returns).
#[test]
fn poisson_gaussians_are_recovered_to_their_noise() {
    let mut r = SplitMix64::new(2);
    let mut worst = [0.0f64; 4]; // |Δc| real, |ΔA|/A real, |z_c|, |z_A| vs truth
    let (mut sum_zc2, mut sum_za2, mut n) = (0.0, 0.0, 0.0);
    let (mut pulls_c, mut pulls_a) = (Vec::new(), Vec::new());
    let (mut within_c, mut within_a, mut total) = (0, 0, 0);
    let mut missed: Vec<String> = Vec::new();
    for count in 1..=4 {
        for case in 0..200 {
            let (t, len) = random_case(&mut r, count, 50.0, 100.0);
            let mut y = vec![0.0f32; len];
            let mut real = Vec::new();
            for g in &t {
                let (mut a, mut c1) = (0.0, 0.0);
                for (i, yi) in y.iter_mut().enumerate() {
                    let k = r.poisson(g.area * bin_mass(i, g)) as f64;
                    *yi += k as f32;
                    a += k;
                    c1 += k * (i as f64 + 0.5);
                }
                real.push((c1 / a, a));
            }
            let c = decompose(&y, &[], &[], 2.0, 4, Decomposition::Gaussian, &rx(1.5));
            if c.len() != count {
                missed.push(format!("count {count} case {case}: {c:?} truth {t:?}"));
                continue;
            }
            for ((g, f), (rc, ra)) in t.iter().zip(&c).zip(&real) {
                let zc = (f.centre_bin - g.centre) / (g.sigma / g.area.sqrt());
                let za = (f.area_photons - g.area) / g.area.sqrt();
                worst[0] = worst[0].max((f.centre_bin - rc).abs());
                worst[1] = worst[1].max((f.area_photons / ra - 1.0).abs());
                worst[2] = worst[2].max(zc.abs());
                worst[3] = worst[3].max(za.abs());
                sum_zc2 += zc * zc;
                sum_za2 += za * za;
                pulls_c.push(zc.abs());
                pulls_a.push(za.abs());
                n += 1.0;
                total += 1;
                within_c += ((f.centre_bin - g.centre).abs() < 0.1) as usize;
                within_a += ((f.area_photons / g.area - 1.0).abs() < 0.02) as usize;
            }
        }
    }
    let (rms_c, rms_a) = ((sum_zc2 / n).sqrt(), (sum_za2 / n).sqrt());
    println!(
        "poisson: vs realised photons max |dc| {:.3} bin, max |dA|/A {:.4}; vs truth max \
         |z_c| {:.2}, max |z_A| {:.2}, rms z_c {rms_c:.3}, rms z_A {rms_a:.3}; within 0.1 \
         bin {within_c}/{total}, within 2% {within_a}/{total}",
        worst[0], worst[1], worst[2], worst[3]
    );
    println!("poisson: {} of 800 cases with a wrong count", missed.len());
    assert!(missed.len() <= 8, "{missed:#?}");
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (mc, ma) = (median(&mut pulls_c), median(&mut pulls_a));
    println!("poisson: median |z_c| {mc:.3}, median |z_A| {ma:.3}");
    assert!(mc < 1.0 && ma < 1.0);
}

#[test]
fn weak_return_below_threshold_is_not_reported() {
    let t = [
        Truth {
            centre: 30.5,
            sigma: 2.0,
            area: 2000.0,
        },
        Truth {
            centre: 60.5,
            sigma: 2.0,
            area: 8.0,
        },
    ];
    let y: Vec<f32> = mean_waveform(&t, 90).iter().map(|&v| v as f32).collect();
    for method in [Decomposition::Gaussian, Decomposition::PeakDetection] {
        let c = decompose(&y, &[], &[], 3.0, 4, method, &rx(2.0));
        assert_eq!(c.len(), 1, "{method:?}: {c:?}");
        assert!((c[0].centre_bin - 30.5).abs() < 0.05);
        // Lower the threshold and it is there.
        assert_eq!(
            decompose(&y, &[], &[], 0.5, 4, method, &rx(2.0)).len(),
            2,
            "{method:?}"
        );
    }
}

#[test]
fn max_returns_keeps_the_strongest_in_time_order() {
    let t = [
        Truth {
            centre: 20.5,
            sigma: 2.0,
            area: 300.0,
        },
        Truth {
            centre: 40.5,
            sigma: 2.0,
            area: 900.0,
        },
        Truth {
            centre: 60.5,
            sigma: 2.0,
            area: 100.0,
        },
        Truth {
            centre: 80.5,
            sigma: 2.0,
            area: 600.0,
        },
    ];
    let y: Vec<f32> = mean_waveform(&t, 100).iter().map(|&v| v as f32).collect();
    let c = decompose(&y, &[], &[], 2.0, 2, Decomposition::Gaussian, &rx(2.0));
    assert_eq!(c.len(), 2);
    assert!((c[0].centre_bin - 40.5).abs() < 0.01 && (c[1].centre_bin - 80.5).abs() < 0.01);
    assert!(decompose(&y, &[], &[], 2.0, 0, Decomposition::Gaussian, &rx(2.0)).is_empty());
}

#[test]
fn peak_detection_finds_centres_and_areas() {
    let t = [
        Truth {
            centre: 20.3,
            sigma: 2.0,
            area: 500.0,
        },
        Truth {
            centre: 50.8,
            sigma: 3.0,
            area: 1500.0,
        },
    ];
    let y: Vec<f32> = mean_waveform(&t, 80).iter().map(|&v| v as f32).collect();
    let c = decompose(&y, &[], &[], 2.0, 4, Decomposition::PeakDetection, &rx(2.0));
    assert_eq!(c.len(), 2);
    for (g, f) in t.iter().zip(&c) {
        assert!((f.centre_bin - g.centre).abs() < 0.05, "{f:?}");
        assert!((f.area_photons / g.area - 1.0).abs() < 0.01, "{f:?}");
    }
}

#[test]
fn shoulder_on_a_strong_return_is_found() {
    let t = [
        Truth {
            centre: 40.0,
            sigma: 4.0,
            area: 5000.0,
        },
        Truth {
            centre: 52.0,
            sigma: 1.5,
            area: 50.0,
        },
    ];
    let y: Vec<f32> = mean_waveform(&t, 90).iter().map(|&v| v as f32).collect();
    let c = decompose(&y, &[], &[], 2.0, 4, Decomposition::Gaussian, &rx(1.5));
    assert_eq!(c.len(), 2, "{c:?}");
    assert!((c[1].centre_bin - 52.0).abs() < 0.01 && (c[1].area_photons / 50.0 - 1.0).abs() < 0.01);
}

#[test]
fn bad_input_gives_no_returns_and_no_panic() {
    assert!(decompose(&[], &[], &[], 1.0, 4, Decomposition::Gaussian, &rx(1.0)).is_empty());
    let y = [f32::NAN, f32::INFINITY, -3.0, 0.0, 5.0, 0.0];
    for m in [Decomposition::Gaussian, Decomposition::PeakDetection] {
        for c in decompose(&y, &[], &[], 1.0, 4, m, &rx(f64::NAN)) {
            assert!(c.centre_bin.is_finite() && c.area_photons.is_finite());
        }
        assert!(decompose(&[0.0; 50], &[], &[], 1.0, 4, m, &rx(2.0)).is_empty());
        for floor in [f64::NAN, f64::INFINITY, -1.0] {
            let odd = Receiver {
                noise_floor: floor,
                footprint_edge_sigmas: Some(f64::NAN),
                ..rx(1.5)
            };
            for c in decompose(&y, &[], &[], 1.0, 4, m, &odd) {
                assert!(c.centre_bin.is_finite() && c.area_photons.is_finite());
            }
        }
    }
}

/// A weak return (150 photons, 23 a bin at its peak) 5 sigmas after a strong one: two returns
/// to a detector with shot noise alone, one to a detector whose electronic noise (σ_e = 40
/// photons a bin, a floor of 1600 photons²: over the return's matched width of 2√π σ = 9 bins
/// an error of 121 photons, under the 2 standard errors a return must exceed) buries it, the search for a return in the fit's
/// residual weighing the excess against that noise too. The strong return's fit then holds
/// the weak one's light, its centre pulled by a tenth of a sigma at most.
#[test]
fn the_configured_noise_decides_what_is_resolved() {
    let sigma = 2.55;
    let t = [
        Truth {
            centre: 40.3,
            sigma,
            area: 2e4,
        },
        Truth {
            centre: 53.1,
            sigma,
            area: 150.0,
        },
    ];
    let y: Vec<f32> = mean_waveform(&t, 90).iter().map(|&v| v as f32).collect();
    let quiet = decompose(&y, &[], &[], 5.0, 4, Decomposition::Gaussian, &rx(sigma));
    assert_eq!(quiet.len(), 2, "{quiet:?}");
    let noisy = Receiver {
        noise_floor: 1600.0,
        ..rx(sigma)
    };
    let c = decompose(&y, &[], &[], 5.0, 4, Decomposition::Gaussian, &noisy);
    assert_eq!(c.len(), 1, "{c:?}");
    assert!((c[0].centre_bin - 40.3).abs() < 0.1 * sigma, "{c:?}");
}

/// A strong return and, 17 bins later, a weak one of 230 photons: a surface when the
/// simulation's error of its bins is small, an estimator spike when that error is as large
/// as the bump itself (one path among few rays), as in a ground return followed by one
/// third-order path.
#[test]
fn a_later_return_must_stand_out_from_the_simulations_noise() {
    let sigma = 2.55;
    let strong = Truth {
        centre: 40.3,
        sigma,
        area: 7.8e6,
    };
    let weak = Truth {
        centre: 57.7,
        sigma,
        area: 230.0,
    };
    let y: Vec<f32> = mean_waveform(&[strong, weak], 80)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let mut se = vec![0.0f32; 80];
    // binning noise of the strong return: ~10 % of its bins, well below its area
    for (i, s) in se.iter_mut().enumerate().take(44).skip(37) {
        *s = 0.1 * y[i];
    }
    se[57] = 1.0; // a well-sampled weak surface
    let c = decompose(&y, &se, &[], 5.0, 4, Decomposition::Gaussian, &rx(sigma));
    assert_eq!(c.len(), 2, "{c:?}");
    se[57] = 230.0; // one path of one ray made it
    let c = decompose(&y, &se, &[], 5.0, 4, Decomposition::Gaussian, &rx(sigma));
    assert_eq!(c.len(), 1, "{c:?}");
    assert!((c[0].centre_bin - 40.3).abs() < 0.01, "{c:?}");
    let c = decompose(
        &y,
        &se,
        &[],
        5.0,
        4,
        Decomposition::PeakDetection,
        &rx(sigma),
    );
    assert_eq!(c.len(), 1, "{c:?}");
}

/// The earliest return is light scattered once by the nearest surface: kept however noisy
/// the simulation's estimate of it, where a later one of the same size and error is not.
#[test]
fn the_first_return_is_judged_by_its_photon_noise_only() {
    let sigma = 2.55;
    let early = Truth {
        centre: 20.0,
        sigma,
        area: 300.0,
    };
    let late = Truth {
        centre: 45.0,
        sigma,
        area: 5e5,
    };
    let y: Vec<f32> = mean_waveform(&[early, late], 70)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let mut se = vec![0.0f32; 70];
    se[20] = 300.0;
    let c = decompose(&y, &se, &[], 5.0, 4, Decomposition::Gaussian, &rx(sigma));
    assert_eq!(c.len(), 2, "{c:?}");
    assert!((c[0].centre_bin - 20.0).abs() < 0.05, "{c:?}");
}

/// Rays of 5000 photons each at the given ranges (bins), each ray's light the pulse's shape
/// (sigma 1.7 bins), with the Monte Carlo error of one ray's light in its bin: a comb as a
/// few rays leave it over a steep surface.
struct Comb {
    y: Vec<f32>,
    se: Vec<f32>,
    centres: Vec<f64>,
}

impl Comb {
    const QUANTUM: f64 = 5000.0;

    fn new(mut centres: Vec<f64>, len: usize) -> Comb {
        centres.sort_by(f64::total_cmp);
        let truths: Vec<Truth> = centres
            .iter()
            .map(|&centre| Truth {
                centre,
                sigma: 1.7,
                area: Self::QUANTUM,
            })
            .collect();
        let y = mean_waveform(&truths, len)
            .iter()
            .map(|&v| v as f32)
            .collect();
        let mut se = vec![0.0f32; len];
        for &c in &centres {
            se[c as usize] += Self::QUANTUM as f32;
        }
        Comb { y, se, centres }
    }

    /// `rays` ranges drawn (seeded) from one surface's spread about `centre`, `half` bins to
    /// either side: the footprint's profile along the slope, a Gaussian cut at 2 of its
    /// sigmas, integrated across.
    fn surface(r: &mut SplitMix64, rays: usize, centre: f64, half: f64, len: usize) -> Comb {
        let edge: f64 = 2.0;
        let erf = |z: f64| 2.0 * normal_cdf(z * std::f64::consts::SQRT_2) - 1.0;
        let profile = |x: f64| {
            let across = (1.0 - x * x).max(0.0).sqrt();
            (-0.5 * x * x * edge * edge).exp() * erf(edge * across / std::f64::consts::SQRT_2)
        };
        let mut centres = Vec::new();
        while centres.len() < rays {
            let x = 2.0 * r.uniform() - 1.0;
            if r.uniform() * profile(0.0) < profile(x) {
                centres.push(centre + half * x);
            }
        }
        Comb::new(centres, len)
    }

    /// Asserts that return `k` of `got` lies within a standard error of the rays' mean
    /// range.
    fn assert_at_centroid(&self, seed: u64, got: &[Component], k: usize) {
        let n = self.centres.len() as f64;
        let mean = self.centres.iter().sum::<f64>() / n;
        let var = self.centres.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let se = (var / n).sqrt();
        assert!(
            (got[k].centre_bin - mean).abs() < se,
            "seed {seed}, return {k}: {got:?}, rays at {mean} ± {se}"
        );
    }
}

/// Twenty rays over a steep hard surface, one spike each, none significant against the
/// simulation's noise alone: together one return, placed within a standard error of their
/// mean range, not at the first spike (where the first-hit rule alone would put the return,
/// up to 2 m above a plane seen at 75°). Two such surfaces with a gap far longer than their
/// rays' spacing between them are two returns. Eight leaves hit one ray each give the first
/// leaf as the first return, as a first-hit simulator has it, where the same light off a hard
/// surface is one return.
#[test]
fn a_few_rays_comb_is_one_surface_unless_leaves_or_a_gap_part_it() {
    let rx = rx(1.7);
    let gaussian = Decomposition::Gaussian;
    for seed in 1..=20 {
        let mut r = SplitMix64::new(seed);
        let c = Comb::surface(&mut r, 20, 240.0, 200.0, 480);
        let got = decompose(&c.y, &c.se, &[], 5.0, 4, gaussian, &rx);
        assert_eq!(got.len(), 1, "seed {seed}: {got:?}");
        c.assert_at_centroid(seed, &got, 0);

        let a = Comb::surface(&mut r, 20, 200.0, 200.0, 1300);
        let b = Comb::surface(&mut r, 20, 1000.0, 200.0, 1300);
        let y: Vec<f32> = a.y.iter().zip(&b.y).map(|(p, q)| p + q).collect();
        let se: Vec<f32> = a.se.iter().zip(&b.se).map(|(p, q)| p + q).collect();
        let got = decompose(&y, &se, &[], 5.0, 4, gaussian, &rx);
        assert_eq!(got.len(), 2, "seed {seed}: {got:?}");
        a.assert_at_centroid(seed, &got, 0);
        b.assert_at_centroid(seed, &got, 1);

        // leaves every 40 bins, give or take 5: no two rays' light overlaps
        let leaves: Vec<f64> = (0..8)
            .map(|k| 60.0 + 40.0 * k as f64 + 10.0 * r.uniform() - 5.0)
            .collect();
        let c = Comb::new(leaves, 480);
        let got = decompose(&c.y, &c.se, &c.se, 5.0, 4, gaussian, &rx);
        assert_eq!(got.len(), 1, "seed {seed}: {got:?}");
        assert!(
            (got[0].centre_bin - c.centres[0]).abs() < 0.5,
            "seed {seed}: {got:?}"
        );
        let got = decompose(&c.y, &c.se, &[], 5.0, 4, gaussian, &rx);
        assert_eq!(got.len(), 1, "seed {seed}: {got:?}");
        c.assert_at_centroid(seed, &got, 0);
    }
}

/// A forest ALS waveform (als_sweep, pulse 71648 at 250 m and 150 kHz, 32 rays: four returns
/// with deep dips between them) on which a fit can wander to a centre and a width of billions
/// of bins, a point thousands of kilometres away that the LAS writer cannot take: every
/// component stays within its waveform, and a fit that fails keeps the detector's return.
/// (The four merge into one here: each is as large as one ray's share of the Monte Carlo
/// error, and with no leaves' share of the light given they are read as one surface's comb.)
#[test]
fn no_component_leaves_its_waveform() {
    let v: serde_json::Value = serde_json::from_str(include_str!(
        "../../../tests/data/diverging_fit_waveform.json"
    ))
    .unwrap();
    let list = |k: &str| -> Vec<f32> {
        v[k].as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap() as f32)
            .collect()
    };
    let (y, se) = (list("photons"), list("mc_se_photons"));
    let sigma = 3.0 / 2.354_820_045 / 0.5;
    for method in [Decomposition::Gaussian, Decomposition::PeakDetection] {
        let c = decompose(&y, &se, &[], 5.0, 4, method, &rx(sigma));
        assert!(!c.is_empty(), "{method:?}: the fit lost every return");
        for k in &c {
            assert!(
                (-1.0..=y.len() as f64 + 1.0).contains(&k.centre_bin)
                    && k.sigma_bins > 0.0
                    && k.sigma_bins <= y.len() as f64,
                "{method:?}: {k:?}"
            );
        }
    }
}

/// Skipping empty windows and keeping the kernel change no bit: the smoothing equals the dense
/// sum everywhere, on waveforms with empty stretches, lone spikes at the ends and negative
/// residuals, made anew or with the kernel a thread kept.
#[test]
fn smoothing_skips_empty_windows_to_the_same_bits() {
    fn dense(y: &[f64], sigma: f64) -> Vec<f64> {
        let reach = (3.0 * sigma).ceil() as usize;
        let n = y.len();
        (0..n)
            .map(|i| {
                let (lo, hi) = (i.saturating_sub(reach), (i + reach).min(n - 1));
                let (mut acc, mut w) = (0.0, 0.0);
                for (j, &v) in y.iter().enumerate().take(hi + 1).skip(lo) {
                    let k = (-0.5 * (i.abs_diff(j) as f64 / sigma).powi(2)).exp();
                    acc += k * v;
                    w += k;
                }
                acc / w
            })
            .collect()
    }
    let mut r = SplitMix64::new(7);
    for case in 0..200 {
        let n = 1 + (r.uniform() * 400.0) as usize;
        let mut y = vec![0.0; n];
        for _ in 0..(r.uniform() * 6.0) as usize {
            let at = (r.uniform() * n as f64) as usize % n;
            let len = 1 + (r.uniform() * 30.0) as usize;
            for v in y.iter_mut().skip(at).take(len) {
                *v = (r.uniform() - 0.3) * 1e3;
            }
        }
        if case % 3 == 0 {
            y[n - 1] = -0.0;
            y[0] = 5.0;
        }
        let sigma = 0.7 + 12.0 * r.uniform();
        let (got, want) = (detect::smooth(&y, sigma), dense(&y, sigma));
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!(g.to_bits(), w.to_bits(), "case {case}, bin {i}: {g} != {w}");
        }
        // again with the kernel the thread kept for this sigma
        let again = detect::smooth(&y, sigma);
        assert!(
            again
                .iter()
                .zip(&want)
                .all(|(g, w)| g.to_bits() == w.to_bits()),
            "case {case}: the kept kernel"
        );
    }
}

/// On a gate much finer than the pulse the decomposition works on coarsened bins (see
/// [`coarsening`]). Noise-free sums of 1-3 Gaussians of 8-40 bins, at least 3σ apart, areas
/// within a decade: where the count is right, centres, widths and areas come back in the
/// gate's own bins as the model is exact; the count itself is found as on the gate's bins
/// but for a weak return between two strong ones, which the residual search (a heuristic
/// whose path depends on the bins) finds on the gate's own bins and may miss on coarse ones
/// (a few of these 600 cases, which the test prints; at most 1 % is allowed).
#[test]
fn fine_gates_are_decomposed_on_coarser_bins_without_loss() {
    let mut r = SplitMix64::new(11);
    let (mut worst_c, mut worst_a, mut worst_s) = (0.0f64, 0.0f64, 0.0f64);
    let (mut cases, mut missed_coarse, mut missed_fine) = (0, 0, 0);
    for count in 1..=3 {
        for _ in 0..200 {
            let sigma = 8.0 + 32.0 * r.uniform();
            assert!(coarsening(sigma) > 1);
            let mut t: Vec<Truth> = Vec::new();
            let mut pos = 6.0 * sigma + 20.0 * r.uniform();
            for _ in 0..count {
                t.push(Truth {
                    centre: pos,
                    sigma,
                    area: 5000.0 * 10f64.powf(r.uniform()),
                });
                pos += (3.0 + 2.0 * r.uniform()) * sigma;
            }
            let len = (pos + 5.0 * sigma) as usize;
            let y: Vec<f32> = mean_waveform(&t, len).iter().map(|&v| v as f32).collect();
            cases += 1;
            // the same waveform decomposed on its own bins
            let fine: Vec<f64> = y.iter().map(|&v| v as f64).collect();
            let th = Threshold {
                per_bin: 0.5,
                area: 0.5,
            };
            let noise = Noise {
                mc_se: &[],
                pulse_sigma: sigma,
                footprint_edge_sigmas: Some(2.0),
                floor: 0.0,
                quantum: 0.0,
                leaves: &[],
                alarm: None,
            };
            let on_fine = decompose_bins(&fine, th, 4, Decomposition::Gaussian, &noise);
            missed_fine += usize::from(on_fine.len() != count);
            let c = decompose(&y, &[], &[], 0.5, 4, Decomposition::Gaussian, &rx(sigma));
            if c.len() != count {
                missed_coarse += 1;
                continue;
            }
            for (g, f) in t.iter().zip(&c) {
                worst_c = worst_c.max((f.centre_bin - g.centre).abs() / g.sigma);
                worst_a = worst_a.max((f.area_photons / g.area - 1.0).abs());
                worst_s = worst_s.max((f.sigma_bins / g.sigma - 1.0).abs());
            }
        }
    }
    println!(
        "coarsened: {missed_coarse} of {cases} cases with a wrong count ({missed_fine} on the \
         gate's own bins); max centre error {worst_c:.2e} sigma, width {worst_s:.2e}, area \
         {worst_a:.2e}"
    );
    assert!(missed_coarse * 100 <= cases, "{missed_coarse} of {cases}");
    assert!(worst_c < 1e-3 && worst_s < 1e-3 && worst_a < 2e-3);
}

/// Four leaves 4 bins apart (1.6 pulse sigmas, 2.55 bins) with no dip between them, the second
/// three times the weakest: fitted as one return over 1.5 times as wide as the pulse, whose
/// centre lies between the leaves. The detector's point goes to the summit, next to the
/// strongest leaf; a return as wide as the pulse keeps its fitted centre to the bit.
#[test]
fn a_wide_return_is_placed_at_its_summit_a_narrow_one_at_its_fit() {
    let sigma = 2.55;
    let leaves: Vec<Truth> = [(37.0, 1e5), (41.0, 3e5), (45.0, 2e5), (49.0, 1.5e5)]
        .iter()
        .map(|&(centre, area)| Truth {
            centre,
            sigma,
            area,
        })
        .collect();
    let y: Vec<f32> = mean_waveform(&leaves, 90)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let mut c = decompose(&y, &[], &[], 5.0, 4, Decomposition::Gaussian, &rx(sigma));
    assert_eq!(c.len(), 1, "{c:?}");
    assert!(c[0].sigma_bins > WIDE_SIGMAS * sigma, "{c:?}");
    let fit = c[0].centre_bin;
    place_on_summits(&mut c, &y, sigma);
    let summit = (0..y.len()).fold(0, |m, k| if y[k] > y[m] { k } else { m });
    assert!(
        (c[0].centre_bin - (summit as f64 + 0.5)).abs() <= 0.5,
        "{c:?}, summit bin {summit}"
    );
    assert!(
        (c[0].centre_bin - 41.0).abs() < 1.0 && (fit - 41.0).abs() > 1.5,
        "fit {fit}, placed {c:?}"
    );

    let one = Truth {
        centre: 40.3,
        sigma,
        area: 3e5,
    };
    let y: Vec<f32> = mean_waveform(&[one], 90)
        .iter()
        .map(|&v| v as f32)
        .collect();
    let fitted = decompose(&y, &[], &[], 5.0, 4, Decomposition::Gaussian, &rx(sigma));
    let mut placed = fitted.clone();
    place_on_summits(&mut placed, &y, sigma);
    assert_eq!(placed, fitted);
}

/// The blockwise scan finds the same first and last bins of signal as a scan bin by bin, with
/// zeros, negative values, NaN and infinities anywhere, on every length around the block's.
#[test]
fn signal_span_equals_the_scan_bin_by_bin() {
    let mut rng = SplitMix64::new(11);
    let naive = |v: &[f32]| {
        let first = v.iter().position(|&x| signal(x))?;
        Some((first, v.iter().rposition(|&x| signal(x)).unwrap_or(first)))
    };
    let odd = [
        0.0,
        -1.0,
        -0.0,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        1e-30,
        3.0,
    ];
    for len in 0..80 {
        for _ in 0..200 {
            let dense = rng.uniform();
            let v: Vec<f32> = (0..len)
                .map(|_| {
                    if rng.uniform() < dense * 0.3 {
                        odd[(rng.uniform() * odd.len() as f64) as usize % odd.len()]
                    } else {
                        0.0
                    }
                })
                .collect();
            assert_eq!(signal_span(&v), naive(&v), "{v:?}");
        }
    }
}

/// One plane seen at any incidence through a footprint cut at 2 of its sigmas: the pulse
/// (σ 1.7 bins) smeared over a spread of ranges from none to 60 pulse sigmas, built here
/// from the 2-D footprint itself (a grid over the disk, each cell's range affine in its
/// coordinate), noise-free and with Poisson noise at 10^4 to 10^6 photons. One return each
/// time, placed at the light's centroid within a tenth of a pulse sigma plus 3 standard
/// errors of the centroid (the spread's over √photons). Without comparing its components
/// with one surface's waveform, the decomposition would make 2-4 returns of spreads of 8
/// sigmas and more, and place a wide one at the summit of its flat top.
#[test]
fn a_smeared_surface_is_one_return_at_any_spread() {
    let sigma = 1.7;
    let mut r = SplitMix64::new(11);
    let mut failures = Vec::new();
    for half in [0.0, 2.0, 5.0, 8.0, 12.0, 20.0, 35.0, 60.0, 100.0] {
        for area in [1e4, 1e5, 1e6] {
            for noisy in [false, true] {
                let len = (2.0 * half + 60.0) as usize;
                let centre = len as f64 / 2.0 + 0.3;
                let mut y = vec![0.0f64; len];
                let cells = 81;
                let mut weights = 0.0;
                let mut spots = Vec::new();
                for i in 0..cells {
                    for j in 0..cells {
                        let x = -1.0 + (i as f64 + 0.5) * 2.0 / cells as f64;
                        let v = -1.0 + (j as f64 + 0.5) * 2.0 / cells as f64;
                        if x * x + v * v > 1.0 {
                            continue;
                        }
                        let w = (-2.0 * (x * x + v * v)).exp();
                        weights += w;
                        spots.push((centre + half * x, w));
                    }
                }
                for (at, w) in spots {
                    let t = Truth {
                        centre: at,
                        sigma,
                        area: area * w / weights,
                    };
                    for (i, yi) in y.iter_mut().enumerate() {
                        *yi += t.area * bin_mass(i, &t);
                    }
                }
                let y: Vec<f32> = y
                    .iter()
                    .map(|&v| if noisy { r.poisson(v) as f32 } else { v as f32 })
                    .collect();
                let mut c = decompose(&y, &[], &[], 5.0, 4, Decomposition::Gaussian, &rx(sigma));
                // where the point goes: a slope's return at its centroid, not its summit
                place_on_summits(&mut c, &y, sigma);
                // the footprint's spread of ranges: half × the profile's sd (≈ 0.4)
                let se = (sigma * sigma + (0.4 * half).powi(2)).sqrt() / area.sqrt();
                let ok = c.len() == 1 && (c[0].centre_bin - centre).abs() < 0.1 * sigma + 3.0 * se;
                if !ok {
                    failures.push(format!("half {half} area {area} noisy {noisy}: {c:?}"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Two surfaces each smeared (two slopes 12 pulse sigmas apart in range, one half as bright),
/// with the waveform dipping between them: two returns, not one surface.
#[test]
fn two_smeared_surfaces_stay_two_returns() {
    let sigma = 1.7;
    let len = 160;
    let mut y = vec![0.0f64; len];
    for (centre, area) in [(60.0, 2e5), (80.0, 1e5)] {
        for k in 0..21 {
            let t = Truth {
                centre: centre - 4.0 + 0.4 * k as f64,
                sigma,
                area: area / 21.0,
            };
            for (i, yi) in y.iter_mut().enumerate() {
                *yi += t.area * bin_mass(i, &t);
            }
        }
    }
    let y: Vec<f32> = y.iter().map(|&v| v as f32).collect();
    let c = decompose(&y, &[], &[], 5.0, 4, Decomposition::Gaussian, &rx(sigma));
    assert_eq!(c.len(), 2, "{c:?}");
    assert!(
        (c[0].centre_bin - 60.0).abs() < 0.5 && (c[1].centre_bin - 80.0).abs() < 0.5,
        "{c:?}"
    );
}
