//! The waveform one surface makes: the pulse smeared by the spread of ranges a plane presents
//! across the beam's footprint, whatever the angle it is seen at.
//!
//! Within the beam's few milliradians a plane's range is affine in the footprint coordinate
//! along its slope, so its impulse response is the beam's profile along one axis (the
//! marginal of the footprint's truncated Gaussian) stretched by a factor set by the
//! incidence; its waveform is that convolved with the pulse. Seen at 0° it is the pulse; at
//! 45° over a wide footprint it is a flat top with soft shoulders that a sum of Gaussians
//! fits only as two or three of them, each "significant" at 10^5 photons. Comparing the
//! components against this shape, not against one Gaussian, is what keeps a slanted roof or
//! a slope one return while a second surface on the flank of the first (asymmetric) still
//! counts as two.

use super::fit::{add_gaussians, Params};
use super::{Component, Noise};
use crate::waveform::bin_masses_into;

/// Beam profile samples for its variance: the profile is smooth, so this is exact to 1e-6.
const PROFILE_NODES: usize = 256;
/// Spread of the trial smears around the moment-matched one: relative widths tried.
const STRETCH_TRIALS: [f64; 9] = [0.7, 0.8, 0.875, 0.95, 1.0, 1.05, 1.125, 1.2, 1.35];
/// Parabolic steps refining the best trial.
const PARABOLA_STEPS: usize = 3;

/// The beam's power along one axis of its footprint at x ∈ [-1, 1] (units of the footprint's
/// edge), for a Gaussian truncated at `edge` of its sigmas: the 2-D profile integrated
/// across the other axis, exp(-x² e²/2) erf(e √(1 - x²) / √2), up to a constant.
fn profile(x: f64, edge: f64) -> f64 {
    let across = (1.0 - x * x).max(0.0).sqrt();
    (-0.5 * x * x * edge * edge).exp() * erf(edge * across / std::f64::consts::SQRT_2)
}

/// erf from the normal CDF the waveform code already has: erf(z) = 2 Φ(z √2) - 1.
fn erf(z: f64) -> f64 {
    2.0 * crate::waveform::normal_cdf(z * std::f64::consts::SQRT_2) - 1.0
}

/// Variance of the profile on [-1, 1] (x in edge units).
fn profile_variance(edge: f64) -> f64 {
    let (mut m0, mut m2) = (0.0, 0.0);
    for q in 0..PROFILE_NODES {
        let x = -1.0 + (q as f64 + 0.5) * 2.0 / PROFILE_NODES as f64;
        let f = profile(x, edge);
        m0 += f;
        m2 += f * x * x;
    }
    m2 / m0
}

/// Adds `area` photons of one surface's waveform (centre `centre`, half-spread `half` bins,
/// pulse sigma `sigma` bins) to `m`, whose first bin is bin `offset`: the stretched profile
/// as nodes at most one pulse sigma apart, each a pulse-shaped Gaussian (the Riemann sum of a
/// Gaussian-smoothed function at that spacing is exact to e^-20).
fn add_smear(
    m: &mut [f64],
    offset: f64,
    (centre, half, area): (f64, f64, f64),
    sigma: f64,
    edge: f64,
) {
    let nodes = ((2.0 * half / sigma).ceil() as usize + 1).clamp(1, 512);
    let n = m.len() as f64;
    let weights: Vec<(f64, f64)> = (0..nodes)
        .map(|q| {
            let x = -1.0 + (q as f64 + 0.5) * 2.0 / nodes as f64;
            (centre + half * x, profile(x, edge))
        })
        .collect();
    let total: f64 = weights.iter().map(|w| w.1).sum();
    if total <= 0.0 {
        return;
    }
    let mut masses = Vec::new();
    for (at, w) in weights {
        let a = (at - offset - 8.0 * sigma - 1.0).floor().clamp(0.0, n) as usize;
        let b = ((at - offset + 8.0 * sigma + 1.0).ceil().clamp(0.0, n) as usize).max(a);
        masses.clear();
        bin_masses_into(at, sigma, offset, (a, b), &mut masses);
        for (mi, mass) in m[a..b].iter_mut().zip(&masses) {
            *mi += area * w / total * mass;
        }
    }
}

/// Adds the components' bin-integrated Gaussians to `m` (first bin `offset`).
fn add_components(m: &mut [f64], offset: f64, comps: &[Component]) {
    let params: Vec<Params> = comps
        .iter()
        .map(|c| [c.centre_bin, c.sigma_bins, c.area_photons])
        .collect();
    add_gaussians(m, offset, &params);
}

/// The least χ² gain for `k` components to be several surfaces rather than one: the 0.1 %
/// tail of χ² with the 3 (k - 1) parameters they have beyond the surface's three (16.3, 22.5,
/// 27.9, 32.9 and 37.7 for 2 to 6), as the decomposition asks of each extra component.
fn gain_needed(k: usize) -> f64 {
    const TAIL: [f64; 5] = [16.27, 22.46, 27.88, 32.91, 37.70];
    TAIL[(k.max(2) - 2).min(TAIL.len() - 1)]
}

/// Whether `chain`, neighbouring components with no dip between them, is one surface: the
/// waveform over them is fitted no worse by one smeared pulse (see the module) than by the
/// components, by less than [`gain_needed`] in χ² under the photon, detector and simulation
/// noise (`others`, the waveform's other components, held fixed under both). The return it
/// makes, if so.
pub(super) fn one_surface(
    chain: &[Component],
    others: &[Component],
    y: &[f64],
    level: f64,
    noise: &Noise,
) -> Option<Component> {
    let one = |f: &SmearFit| f.smear - f.components < gain_needed(chain.len());
    // the search goes on until the return's placement (`SmearFit::fits`) is settled too
    smear_fit(chain, others, y, level, noise, &|f| one(f) && f.fits())
        .filter(one)
        .map(|f| f.component())
}

/// Whether one surface's waveform fits the light of `c` to its noise, and better than `c`
/// itself: a wide Gaussian fitted to a slope's flat top.
pub(super) fn slope(
    c: &Component,
    others: &[Component],
    y: &[f64],
    level: f64,
    noise: &Noise,
) -> bool {
    let slope = |f: &SmearFit| f.fits() && f.smear < f.components;
    smear_fit(std::slice::from_ref(c), others, y, level, noise, &slope).is_some_and(|f| slope(&f))
}

/// One surface's waveform fitted to the light of some components.
pub(super) struct SmearFit {
    /// χ² of the surface's waveform and of the components.
    smear: f64,
    components: f64,
    /// Bins fitted.
    bins: usize,
    /// The light's centroid (bin units), variance (bins²) and area (photons).
    centre: f64,
    variance: f64,
    area: f64,
}

impl SmearFit {
    fn fits(&self) -> bool {
        let n = self.bins as f64;
        self.smear <= n + 3.0 * (2.0 * n).sqrt()
    }

    /// The return: the light's centroid, spread and area, placed at the centroid if the
    /// surface's waveform fits it ([`Component::one_surface`]).
    fn component(&self) -> Component {
        let sigma = self.variance.sqrt();
        Component {
            centre_bin: self.centre,
            sigma_bins: sigma,
            area_photons: self.area,
            amplitude: self.area / (sigma * (2.0 * std::f64::consts::PI).sqrt()),
            one_surface: self.fits(),
        }
    }
}

/// Bins [lo, hi) of `chain`'s light: those its components reach (4 sigmas, at least the
/// pulse's `sigma`) and the run of bins above `level` around them, short of the others'
/// centres. A fit that left some of a smeared surface's light to no component (its search
/// adds none that would merge) still finds all of it here.
fn extent(
    chain: &[Component],
    others: &[Component],
    y: &[f64],
    level: f64,
    sigma: f64,
) -> Option<(usize, usize)> {
    let reach = |c: &Component| 4.0 * c.sigma_bins.max(sigma) + 2.0;
    let mut lo = chain
        .iter()
        .map(|c| c.centre_bin - reach(c))
        .fold(f64::INFINITY, f64::min)
        .floor()
        .max(0.0) as usize;
    let mut hi = (chain
        .iter()
        .map(|c| c.centre_bin + reach(c))
        .fold(f64::NEG_INFINITY, f64::max)
        .ceil()
        .max(0.0) as usize)
        .min(y.len());
    let first = chain.first()?.centre_bin;
    let last = chain.last()?.centre_bin;
    let before = others
        .iter()
        .map(|o| o.centre_bin)
        .filter(|&c| c < first)
        .fold(f64::NEG_INFINITY, f64::max);
    let after = others
        .iter()
        .map(|o| o.centre_bin)
        .filter(|&c| c > last)
        .fold(f64::INFINITY, f64::min);
    while lo > 0 && y[lo - 1] > level && (lo - 1) as f64 > before {
        lo -= 1;
    }
    while hi < y.len() && y[hi] > level && (hi as f64) < after {
        hi += 1;
    }
    (lo < hi).then_some((lo, hi))
}

/// Components holding under half the light of their run of signal (the others' taken out:
/// a fit that settled on one bump or two of a flat top's noise) as the return of one surface,
/// where that shape fits all the light to its noise.
pub(super) fn unclaimed(
    chain: &[Component],
    others: &[Component],
    y: &[f64],
    level: f64,
    noise: &Noise,
) -> Option<Component> {
    let (lo, hi) = extent(chain, others, y, level, noise.pulse_sigma.max(0.3))?;
    let held: f64 = chain.iter().map(|c| c.area_photons).sum();
    // most components hold their run's light: the raw sum, an upper bound, settles them
    if y[lo..hi].iter().sum::<f64>() <= 2.0 * held {
        return None;
    }
    let mut background = vec![0.0; hi - lo];
    add_components(&mut background, lo as f64, others);
    let light: f64 = y[lo..hi]
        .iter()
        .zip(&background)
        .map(|(&v, &b)| (v - b).max(0.0))
        .sum();
    if light <= 2.0 * held {
        return None;
    }
    smear_fit(chain, others, y, level, noise, &SmearFit::fits)
        .filter(SmearFit::fits)
        .map(|f| f.component())
}

/// [`SmearFit`] of `chain` over the bins its components reach (4 sigmas) and the run of bins
/// above `level` around them, the light of the others taken out; None where that holds no
/// light or the beam's shape is unknown. The search for the best stretch stops as soon as
/// the fit is `enough` for the caller's question (most chains settle at the first trial).
///
/// Long because the search is one loop over trial stretches of one surface's waveform, each
/// fitted against the same window and judged by the caller's `enough`.
fn smear_fit(
    chain: &[Component],
    others: &[Component],
    y: &[f64],
    level: f64,
    noise: &Noise,
    enough: &dyn Fn(&SmearFit) -> bool,
) -> Option<SmearFit> {
    let sigma = noise.pulse_sigma.max(0.3);
    let edge = noise
        .footprint_edge_sigmas
        .filter(|e| e.is_finite() && *e > 0.0)?;
    let (lo, hi) = extent(chain, others, y, level, sigma)?;
    if hi < lo + 3 {
        return None;
    }
    let offset = lo as f64;
    let data = &y[lo..hi];
    let mut background = vec![0.0; data.len()];
    add_components(&mut background, offset, others);
    let mut several = background.clone();
    add_components(&mut several, offset, chain);
    // the moments of the light the chain holds
    let (mut m0, mut m1) = (0.0, 0.0);
    for (k, (&d, &b)) in data.iter().zip(&background).enumerate() {
        let v = (d - b).max(0.0);
        m0 += v;
        m1 += v * (offset + k as f64 + 0.5);
    }
    if m0 <= 0.0 {
        return None;
    }
    let centre = m1 / m0;
    let m2 = data
        .iter()
        .zip(&background)
        .enumerate()
        .map(|(k, (&d, &b))| (d - b).max(0.0) * (offset + k as f64 + 0.5 - centre).powi(2))
        .sum::<f64>()
        / m0;
    let stretch = ((m2 - sigma * sigma - 1.0 / 12.0).max(0.0) / profile_variance(edge)).sqrt();
    // photon noise, the detector's floor, and the simulation's as it is after the pulse's
    // convolution
    let var: Vec<f64> = data
        .iter()
        .enumerate()
        .map(|(k, &d)| d.max(1.0) + noise.floor + noise.mc_se_convolved(lo + k).powi(2))
        .collect();
    let chi2 = |m: &[f64]| -> f64 {
        data.iter()
            .zip(m)
            .zip(&var)
            .map(|((&d, &m), &v)| (d - m).powi(2) / v)
            .sum()
    };
    let several_chi2 = chi2(&several);
    // χ² of the surface stretched by `f` times the moments' stretch, its area by weighted
    // least squares over the light left to it
    let misfit = |f: f64| -> f64 {
        let mut shape = vec![0.0; data.len()];
        add_smear(&mut shape, offset, (centre, f * stretch, 1.0), sigma, edge);
        let (mut num, mut den) = (0.0, 0.0);
        for k in 0..data.len() {
            num += (data[k] - background[k]) * shape[k] / var[k];
            den += shape[k] * shape[k] / var[k];
        }
        if den <= 0.0 {
            return f64::INFINITY;
        }
        let area = (num / den).max(0.0);
        let model: Vec<f64> = background
            .iter()
            .zip(&shape)
            .map(|(b, s)| b + area * s)
            .collect();
        chi2(&model)
    };
    let mut fit = SmearFit {
        smear: f64::INFINITY,
        components: several_chi2,
        bins: data.len(),
        centre,
        variance: m2,
        area: m0,
    };
    // the trials from the moments' stretch outwards (on 10^5 photons their steps alone leave
    // a χ² of tens)
    let mut tried = [f64::INFINITY; STRETCH_TRIALS.len()];
    let mut order: Vec<usize> = (0..STRETCH_TRIALS.len()).collect();
    order.sort_by(|&a, &b| {
        (STRETCH_TRIALS[a] - 1.0)
            .abs()
            .total_cmp(&(STRETCH_TRIALS[b] - 1.0).abs())
    });
    for k in order {
        tried[k] = misfit(STRETCH_TRIALS[k]);
        fit.smear = fit.smear.min(tried[k]);
        if enough(&fit) {
            return Some(fit);
        }
    }
    // then parabolas through the best point and its neighbours, each vertex tried in turn:
    // χ² is close to quadratic in the stretch about its least value
    let at = (0..tried.len())
        .min_by(|&a, &b| tried[a].total_cmp(&tried[b]))
        .unwrap_or(0);
    if at == 0 || at + 1 == tried.len() {
        return Some(fit);
    }
    let mut points = [
        (STRETCH_TRIALS[at - 1], tried[at - 1]),
        (STRETCH_TRIALS[at], tried[at]),
        (STRETCH_TRIALS[at + 1], tried[at + 1]),
    ];
    for _ in 0..PARABOLA_STEPS {
        let [(a, fa), (b, fb), (c, fc)] = points;
        let den = (b - a) * (fb - fc) - (b - c) * (fb - fa);
        if den.abs() < 1e-300 {
            break;
        }
        let v = b - 0.5 * ((b - a).powi(2) * (fb - fc) - (b - c).powi(2) * (fb - fa)) / den;
        if !(v > a && v < c) || (v - b).abs() < 1e-4 * b.abs() {
            break;
        }
        let fv = misfit(v);
        fit.smear = fit.smear.min(fv);
        if enough(&fit) {
            break;
        }
        // the three best of the four, in order, still bracketing the least
        points = if v < b {
            if fv < fb {
                [(a, fa), (v, fv), (b, fb)]
            } else {
                [(v, fv), (b, fb), (c, fc)]
            }
        } else if fv < fb {
            [(b, fb), (v, fv), (c, fc)]
        } else {
            [(a, fa), (b, fb), (v, fv)]
        };
    }
    Some(fit)
}
