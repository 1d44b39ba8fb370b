//! Waveforms: from a pulse's time-resolved energy to what the detector records.
//!
//! The paths are simulated for an impulse (Eq. 7 with p(τ) = δ(τ)); the pulse's Gaussian
//! time profile is applied here. Energy is kept on sub-bins of at most σ/4, and each sub-bin
//! is spread over the output bins through the pulse's CDF, so the convolved waveform does not
//! depend on where a path's time falls inside its bin.

pub mod file;
pub mod pulse;
pub mod record;

use crate::sensor::Gate;
use crate::transport::Tally;
use std::f64::consts::PI;

/// One pulse's waveform record (outputs.md, `waveforms/part-*.parquet`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Waveform {
    pub pulse_id: u64,
    pub t0_ns: f64,
    pub bin_ns: f32,
    /// Mean laser photons per bin at the detector, pulse-convolved (Eq. 19).
    pub laser_photons: Vec<f32>,
    /// Received laser energy per bin before pulse convolution, J.
    pub impulse_energy_j: Vec<f32>,
    /// Standard error of the impulse energy of the bins from [`Waveform::span_first_bin`]
    /// on, J (every other bin's is 0; [`Waveform::impulse_se`] reads any bin).
    pub impulse_energy_se_j: Vec<f32>,
    pub received_energy_j: f64,
    pub outside_gate_energy_j: f64,
    /// Index 0 = order 1.
    pub order_energy_j: Vec<f64>,
    /// Standard error of each order's energy, J.
    pub order_energy_se_j: Vec<f64>,
    pub received_energy_se_j: f64,
    pub solar_photons_per_bin: f32,
    /// Received solar power over the band, W, and its standard error.
    pub solar_power_w: f64,
    pub solar_power_se_w: f64,
    /// Scene BRF within the field of view from the solar signal (Eq. 20); NaN without sun.
    pub brf_fov_solar: f32,
    /// Scene BRF within the footprint from the laser signal, (π/ΔΩ)(Q_r/Q_e).
    pub brf_footprint_laser: f32,
    /// Impulse energy by class of the lit surface (ground, vegetation, building, other) of
    /// the bins from [`Waveform::span_first_bin`] on, J (every other bin's is 0); columns
    /// `ground_energy_j` … `other_energy_j` of the waveform files.
    pub class_energy_j: [Vec<f32>; 4],
    /// The gate bin at which `impulse_energy_se_j` and `class_energy_j` start: they hold the
    /// bins the pulse's light reached, as the files do (column `span_first_bin`). Dense,
    /// they would be mostly zeros on an airborne survey, and filling, scanning and reading
    /// those zeros back costs a few per cent of the simulate stage on long gates.
    pub span_first_bin: usize,
    pub rays: u32,
    /// Paths that carried energy, per ray.
    pub paths_per_ray: f32,
    /// The band of this row in a run of several bands (column `wavelength_nm`); `None` with
    /// one band, whose files have no such column.
    pub wavelength_nm: Option<f64>,
    /// Contributions left out for a weight that was not a finite number (not in the files:
    /// the run log reports them).
    pub non_finite: u64,
    /// Path weights of this band lost to underflow (see `Tally::underflows`; not in the files:
    /// the run log reports them).
    pub underflows: u64,
}

/// rRMSE of a waveform `w` against a reference over the bins `over`: the RMS of their
/// differences over the reference's mean there (the paper's measure of a waveform's error);
/// NaN over no bins.
pub fn rrmse<T: Copy + Into<f64>>(w: &[T], reference: &[T], over: &[usize]) -> f64 {
    if over.is_empty() {
        return f64::NAN;
    }
    let n = over.len() as f64;
    let (a, r) = (|i: usize| w[i].into(), |i: usize| reference[i].into());
    let mse = over.iter().map(|&i| (a(i) - r(i)).powi(2)).sum::<f64>() / n;
    let mean = over.iter().map(|&i| r(i)).sum::<f64>() / n;
    mse.sqrt() / mean
}

/// Sub-bins per bin so that a sub-bin is at most σ/4 wide (1 for an impulse pulse).
pub fn sub_bins_per_bin(bin_s: f64, pulse_sigma_s: f64) -> usize {
    if pulse_sigma_s <= 0.0 {
        1
    } else {
        ((bin_s / (pulse_sigma_s / 4.0)).ceil() as usize).clamp(1, 64)
    }
}

/// Standard normal CDF, Φ(x) = erfc(-x/√2)/2, with the C library's erfc (C99; accurate to a
/// few ulp over the whole line): bin integrals are differences of Φ at the bin's edges, and
/// with an approximate erfc (1e-7) those differences, and the fit's Jacobian built from them,
/// lose their digits wherever a bin is narrow against the pulse or far in its tail. The C
/// library's, not the `libm` crate's: the same algorithm (Sun's) over the system's exp, where
/// the crate's own exp is slower (it makes the products stage measurably slower in CPU), and
/// std's exp, which the transport uses, is the system's already.
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * c_erfc(-x / std::f64::consts::SQRT_2)
}

/// Standard normal density.
pub fn normal_pdf(z: f64) -> f64 {
    (-0.5 * z * z).exp() * (0.5 / std::f64::consts::PI).sqrt()
}

/// Gauss-Legendre nodes on [0, 1] and their weights, 4 points (exact to degree 7).
const GAUSS_LEGENDRE_4: [(f64, f64); 4] = [
    (0.069_431_844_202_973_71, 0.173_927_422_568_726_93),
    (0.330_009_478_207_571_87, 0.326_072_577_431_273_07),
    (0.669_990_521_792_428_1, 0.326_072_577_431_273_07),
    (0.930_568_155_797_026_3, 0.173_927_422_568_726_93),
];

/// Widest bin, in sigmas, whose integral is taken by quadrature: 4-point Gauss-Legendre on
/// half a sigma errs by under 1e-10 of the bin's value (its error term, h⁹ φ⁽⁸⁾ / 3.5e9).
const QUADRATURE_MAX_BIN_SIGMAS: f64 = 0.5;

/// The fraction of the unit Gaussian of `centre` and `sigma` (bins) in each bin
/// [offset + i, offset + i + 1) for i in [a, b), appended to `out`. Where bins are narrower
/// than [`QUADRATURE_MAX_BIN_SIGMAS`], by quadrature of φ, stepped from bin to bin as
/// φ(z + h) = φ(z) e^(-z h) e^(-h²/2) (e^(-z h) falling by e^(-h²) a bin): a few exponentials
/// per component instead of an erfc, itself an exponential and a rational function, per
/// edge (together a large share of a products stage); else as differences of Φ.
pub fn bin_masses_into(
    centre: f64,
    sigma: f64,
    offset: f64,
    (a, b): (usize, usize),
    out: &mut Vec<f64>,
) {
    let h = 1.0 / sigma;
    if h > QUADRATURE_MAX_BIN_SIGMAS || !h.is_finite() {
        let mut prev = normal_cdf((offset + a as f64 - centre) / sigma);
        for i in a..b {
            let next = normal_cdf((offset + (i + 1) as f64 - centre) / sigma);
            out.push(next - prev);
            prev = next;
        }
        return;
    }
    let (half, full) = ((-0.5 * h * h).exp(), (-h * h).exp());
    let z0 = (offset + a as f64 - centre) / sigma;
    // The four nodes' φ stepped side by side, each bin's mass summed node after node: the
    // same products and sums as one node's pass over the bins after another, four times as
    // many multiplications in flight (one pass at a time would wait on each step's product).
    let mut phi = [0.0; 4];
    let mut fall = [0.0; 4];
    let mut weight = [0.0; 4];
    for (k, (x, w)) in GAUSS_LEGENDRE_4.into_iter().enumerate() {
        // callers start at most 8 sigmas and 2 bins before the centre, so e^(-z h) stays
        // below e^5
        let z = z0 + x * h;
        (phi[k], fall[k], weight[k]) = (normal_pdf(z), (-z * h).exp(), w * h);
    }
    // written into a slice, not pushed: a push a bin keeps the vector's length in memory and
    // checks its capacity each time, more instructions than the quadrature's own
    let start = out.len();
    out.resize(start + (b - a), 0.0);
    for o in &mut out[start..] {
        let mut mass = 0.0;
        for k in 0..4 {
            mass += weight[k] * phi[k];
        }
        for k in 0..4 {
            phi[k] *= fall[k] * half;
            fall[k] *= full;
        }
        *o = mass;
    }
}

fn c_erfc(x: f64) -> f64 {
    extern "C" {
        fn erfc(x: f64) -> f64;
    }
    // SAFETY: erfc is a pure C99 function of one double, defined for every input (NaN and
    // infinities included), in the C library std already links.
    unsafe { erfc(x) }
}

/// Impulse energy per bin: the sub-bins summed back to bins.
pub fn impulse_bins(sub: &[f64], sub_bins: usize) -> Vec<f64> {
    sub.chunks(sub_bins).map(|c| c.iter().sum()).collect()
}

/// Spreads each sub-bin's energy (at its energy-weighted mean time) over the bins with a Gaussian
/// of standard deviation `sigma` (s), integrated exactly over each bin.
///
/// `sub_moment[i] / sub[i]` is the mean position (0..1) of sub-bin i's energy within it.
/// Only the sub-bins of the bins `lit` are read: a pulse's energy lies within a few dozen of
/// its gate's hundreds of bins, and the others are zero. `edges` are the sub-bins and moments
/// kept before the gate and after it ([`Tally::edge_sub`]): energy outside the gate whose
/// tails reach into it, as a digitiser records them.
pub fn convolve(
    sub: &[f64],
    sub_moment: &[f64],
    sub_bins: usize,
    gate: &Gate,
    sigma: f64,
    lit: (usize, usize),
    edges: [(&[f64], &[f64]); 2],
) -> Vec<f64> {
    if sigma <= 0.0 {
        return impulse_bins(sub, sub_bins);
    }
    let mut out = vec![0.0; gate.bins];
    let sub_dt = gate.dt / sub_bins as f64;
    let sigma_bins = sigma / gate.dt;
    let reach = convolution_reach(sigma_bins);
    let first = lit.0.saturating_mul(sub_bins).min(sub.len());
    let last = lit.1.saturating_mul(sub_bins).min(sub.len()).max(first);
    // the bin integrals by the stepped quadrature of `bin_masses_into` where bins are at most
    // half a sigma: a few exponentials per sub-bin instead of an erfc per edge, whose 2 × 96
    // per sub-bin on a forest's gates (0.067 ns bins, 1.27 ns sigma) would be most of
    // building a waveform
    // a sub-bin's masses cover its reach within the gate: no more than the gate's bins, whatever
    // the pulse (one of 10^9 ns would ask 68 GB here)
    let mut masses = Vec::with_capacity((2 * reach as usize + 1).min(gate.bins));
    // sub-bin energy `e` with moment `moment`, the sub-bin starting `at` sub-bins from t0
    let mut spread = |e: f64, moment: Option<&f64>, at: f64| {
        let pos = match moment {
            Some(m) if (0.0..=e).contains(m) => m / e,
            _ => 0.5,
        };
        let t = (at + pos) * sub_dt; // relative to t0
        let centre = (t / gate.dt).floor() as i64;
        let lo = (centre - reach).max(0);
        let hi = (centre + reach).min(gate.bins as i64 - 1);
        if lo > hi {
            return;
        }
        masses.clear();
        bin_masses_into(
            t / gate.dt,
            sigma_bins,
            0.0,
            (lo as usize, hi as usize + 1),
            &mut masses,
        );
        for (o, m) in out[lo as usize..=hi as usize].iter_mut().zip(&masses) {
            *o += e * m;
        }
    };
    for (i, &e) in sub.iter().enumerate().take(last).skip(first) {
        if e != 0.0 {
            spread(e, sub_moment.get(i), i as f64);
        }
    }
    let [(before, before_moment), (after, after_moment)] = edges;
    for (j, &e) in before.iter().enumerate() {
        if e != 0.0 {
            spread(e, before_moment.get(j), j as f64 - before.len() as f64);
        }
    }
    for (j, &e) in after.iter().enumerate() {
        if e != 0.0 {
            spread(e, after_moment.get(j), (sub.len() + j) as f64);
        }
    }
    out
}

/// Sub-bins kept on each side of a gate of bins of `dt` (s) for a pulse of `sigma` (s), whose
/// energy's tails reach into the gate ([`crate::transport::PulseSetup::edge_sub_bins`]): the
/// convolution's reach, but no more bins than the gate holds sub-bins (memory a tally already
/// has); none without a convolution.
pub fn edge_sub_bins(dt: f64, sigma: f64, gate_bins: usize) -> usize {
    if !(sigma > 0.0 && dt > 0.0) {
        return 0;
    }
    let reach = usize::try_from(convolution_reach(sigma / dt)).unwrap_or(usize::MAX);
    let sub_bins = sub_bins_per_bin(dt, sigma);
    reach
        .saturating_mul(sub_bins)
        .min(gate_bins.saturating_mul(sub_bins))
}

/// Bins on either side of a sub-bin's own that [`convolve`] spreads it over, for a pulse of
/// `sigma_bins`.
fn convolution_reach(sigma_bins: f64) -> i64 {
    (5.0 * sigma_bins).ceil() as i64 + 1
}

/// Builds a pulse's waveform record from its tally.
/// What turns received energy and power into reflectance factors.
#[derive(Clone, Copy, Debug)]
pub struct Radiometry {
    pub pulse_energy_j: f64,
    pub receiver_area_m2: f64,
    /// Field-of-view half angle, rad.
    pub fov_half_angle: f64,
    /// With a sun: its irradiance over the band (W m⁻²) and the cosine of its zenith angle.
    pub sun: Option<(f64, f64)>,
}

impl Radiometry {
    /// BRF of the scene within the field of view from the solar power (Eq. 20), with the
    /// receiver's étendue A_tel · π sin²θ_fov for A_fov ΔΩ.
    pub fn brf_fov(&self, solar_power_w: f64) -> f64 {
        match self.sun {
            Some((e, cos)) => {
                let etendue = self.receiver_area_m2 * PI * self.fov_half_angle.sin().powi(2);
                PI * solar_power_w / (e * cos * etendue)
            }
            None => f64::NAN,
        }
    }

    /// BRF within the footprint from the laser energy: ρ = (π/ΔΩ)(Q_r/Q_e), ΔΩ = A_tel/R².
    pub fn brf_footprint(&self, received_j: f64, range_m: f64) -> f64 {
        PI * range_m * range_m / self.receiver_area_m2 * received_j / self.pulse_energy_j
    }
}

impl Waveform {
    /// Standard error of bin `b`'s impulse energy, J (0 outside the span).
    pub fn impulse_se(&self, b: usize) -> f32 {
        at_bin(&self.impulse_energy_se_j, self.span_first_bin, b)
    }

    /// Class `k`'s impulse energy summed over the gate bins [lo, hi), J.
    pub fn class_energy_sum(&self, k: usize, lo: usize, hi: usize) -> f64 {
        let first = self.span_first_bin;
        let v = &self.class_energy_j[k];
        let (a, b) = (lo.max(first) - first, hi.max(first) - first);
        v.get(a.min(v.len())..b.min(v.len()))
            .map_or(0.0, |s| s.iter().map(|&x| x as f64).sum())
    }
}

/// Bin `b` of a gate of which `v` holds the bins from `first` on (0 elsewhere).
fn at_bin(v: &[f32], first: usize, b: usize) -> f32 {
    b.checked_sub(first)
        .and_then(|i| v.get(i))
        .copied()
        .unwrap_or(0.0)
}

pub fn waveform(
    pulse_id: u64,
    tally: &Tally,
    gate: &Gate,
    sub_bins: usize,
    pulse_sigma_s: f64,
    photon_energy_j: f64,
    radiometry: &Radiometry,
) -> Waveform {
    // every per-bin sum is zero outside the lit span: those bins are zero without a sum
    let (lo, hi) = (tally.lit.0.min(gate.bins), tally.lit.1.min(gate.bins));
    let lit = |f: &dyn Fn(usize) -> f64| -> Vec<f64> { spanned(gate.bins, lo, hi, f) };
    let impulse = lit(&|b| tally.sub[b * sub_bins..(b + 1) * sub_bins].iter().sum());
    let convolved = convolve(
        &tally.sub,
        &tally.sub_moment,
        sub_bins,
        gate,
        pulse_sigma_s,
        (lo, hi),
        [0, 1].map(|k| (&tally.edge_sub[k][..], &tally.edge_moment[k][..])),
    );
    // the bins the convolution may have reached (a bin more each side than its reach): zero
    // beyond, so the photons are made only here, as the impulse only over the lit span
    let reach = if pulse_sigma_s > 0.0 {
        usize::try_from(convolution_reach(pulse_sigma_s / gate.dt))
            .unwrap_or(usize::MAX)
            .saturating_add(1)
    } else {
        0
    };
    let (c_lo, c_hi) = if tally.edge_lit {
        // energy just outside the gate reached its first or last bins
        (0, gate.bins)
    } else {
        (
            lo.saturating_sub(reach),
            hi.saturating_add(reach).min(gate.bins),
        )
    };
    let n = tally.rays.max(1) as f64;
    let (solar_w, solar_se) = tally.solar_power();
    // range of the return's energy centroid, for the footprint's solid angle; the sums over
    // the lit span are those over the gate, bit for bit (adding zeros changes no sum)
    let in_gate: f64 = impulse[lo..hi.max(lo)].iter().sum();
    let t_mean = (lo..hi)
        .map(|i| impulse[i] * (gate.t0 + (i as f64 + 0.5) * gate.dt))
        .sum::<f64>()
        / in_gate.max(f64::MIN_POSITIVE);
    let range = crate::C * t_mean / 2.0;
    let received = tally.total_energy();
    Waveform {
        pulse_id,
        t0_ns: gate.t0 * 1e9,
        bin_ns: (gate.dt * 1e9) as f32,
        laser_photons: spanned(gate.bins, c_lo, c_hi.max(c_lo), &|b| {
            (convolved[b] / n / photon_energy_j) as f32
        }),
        impulse_energy_j: spanned(gate.bins, lo, hi.max(lo), &|b| (impulse[b] / n) as f32),
        impulse_energy_se_j: (lo..hi).map(|b| tally.bin_se(b, sub_bins) as f32).collect(),
        received_energy_j: tally.total_energy(),
        outside_gate_energy_j: tally.outside / n,
        order_energy_j: tally.order_energy(),
        order_energy_se_j: tally.order_se(),
        received_energy_se_j: tally.total_se(),
        solar_photons_per_bin: (solar_w * gate.dt / photon_energy_j) as f32,
        solar_power_w: solar_w,
        solar_power_se_w: solar_se,
        brf_fov_solar: radiometry.brf_fov(solar_w) as f32,
        brf_footprint_laser: if in_gate > 0.0 {
            radiometry.brf_footprint(received, range) as f32
        } else {
            f32::NAN
        },
        class_energy_j: std::array::from_fn(|k| {
            (lo..hi)
                .map(|b| (tally.class_bins[k][b] / n) as f32)
                .collect()
        }),
        span_first_bin: lo.min(hi),
        rays: tally.rays as u32,
        paths_per_ray: (tally.paths as f64 / n) as f32,
        wavelength_nm: None,
        non_finite: tally.non_finite,
        underflows: tally.underflows,
    }
}

/// `len` values, `f(b)` for b in [lo, hi) and zero elsewhere. The zeros are written, not
/// asked of the allocator (`vec![0.0; n]` is calloc, whose fresh pages a part's thousand
/// waveforms then fault in one by one: more system time than the sums saved).
fn spanned<T: Copy + Default>(len: usize, lo: usize, hi: usize, f: &dyn Fn(usize) -> T) -> Vec<T> {
    let mut v = Vec::with_capacity(len);
    v.resize(lo, T::default());
    v.extend((lo..hi).map(f));
    v.resize(len, T::default());
    v
}

#[cfg(test)]
mod tests {
    /// No energy kept outside the gate.
    const NO_EDGES: [(&[f64], &[f64]); 2] = [(&[], &[]), (&[], &[])];

    use super::*;

    #[test]
    fn convolution_puts_a_return_at_its_exact_time() {
        let gate = Gate {
            t0: 0.0,
            dt: 0.5e-9,
            bins: 80,
        };
        let sigma = 4e-9 / 2.354_820_045;
        let m = sub_bins_per_bin(gate.dt, sigma);
        for frac in [0.0, 0.13, 0.5, 0.77, 0.999] {
            // one return at 20.3 bins + frac of a sub-bin
            let x = 40.0 * m as f64 + frac;
            let mut sub = vec![0.0; 80 * m];
            let mut moment = vec![0.0; 80 * m];
            sub[x as usize] = 2.0;
            moment[x as usize] = 2.0 * (x - x.floor());
            let c = convolve(&sub, &moment, m, &gate, sigma, (0, gate.bins), NO_EDGES);
            let centroid: f64 = c
                .iter()
                .enumerate()
                .map(|(i, v)| (i as f64 + 0.5) * v)
                .sum::<f64>()
                / 2.0;
            assert!((centroid - x / m as f64).abs() < 1e-4, "{frac}: {centroid}");
        }
    }

    #[test]
    fn convolution_keeps_energy_and_is_independent_of_position_in_bin() {
        let gate = Gate {
            t0: 0.0,
            dt: 1e-9,
            bins: 100,
        };
        let sigma = 2e-9;
        let m = sub_bins_per_bin(gate.dt, sigma);
        assert!(gate.dt / m as f64 <= sigma / 4.0 + 1e-18);
        let mut a = vec![0.0; 100 * m];
        a[50 * m] = 1.0; // early in bin 50
        let mut b = vec![0.0; 100 * m];
        b[50 * m + m - 1] = 1.0; // late in bin 50
        let half = |v: &[f64]| v.iter().map(|e| e * 0.5).collect::<Vec<f64>>();
        let ca = convolve(&a, &half(&a), m, &gate, sigma, (0, gate.bins), NO_EDGES);
        let cb = convolve(&b, &half(&b), m, &gate, sigma, (0, gate.bins), NO_EDGES);
        assert!((ca.iter().sum::<f64>() - 1.0).abs() < 1e-6);
        // centroids follow the sub-bin times, not the bin centre
        let centroid = |c: &[f64]| {
            c.iter()
                .enumerate()
                .map(|(i, v)| (i as f64 + 0.5) * v)
                .sum::<f64>()
        };
        let ta = (50.0 * m as f64 + 0.5) / m as f64;
        let tb = (50.0 * m as f64 + m as f64 - 0.5) / m as f64;
        assert!(
            (centroid(&ca) - ta).abs() < 1e-3,
            "{} {}",
            centroid(&ca),
            ta
        );
        assert!((centroid(&cb) - tb).abs() < 1e-3);
    }

    #[test]
    fn normal_cdf_values() {
        // Φ to 16 digits (Abramowitz & Stegun 26.2; mpmath): relative error 1e-14 holds in
        // the tails too, where an erfc good to 1e-7 fails it
        for (x, want) in [
            (0.0, 0.5),
            (1.0, 0.841_344_746_068_542_9),
            (-2.0, 0.022_750_131_948_179_21),
            (-6.0, 9.865_876_450_376_98e-10),
            (-10.0, 7.619_853_024_160_527e-24),
            (3.0, 0.998_650_101_968_369_9),
        ] {
            let got = normal_cdf(x);
            assert!(
                ((got - want) / want).abs() < 1e-14,
                "Φ({x}) = {got:e}, not {want:e}"
            );
        }
    }
}
