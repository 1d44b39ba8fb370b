//! The detection threshold of a record with noise, set by a false-alarm probability.
//!
//! A detector reports a return where its record, filtered with the return's own shape (the
//! matched filter: a Gaussian of the return's σ), rises above a level u. In a gate of noise
//! alone (white, variance σ_n² per bin: electronic noise, the background's shot noise,
//! rounding) the filtered record s is a stationary Gaussian sequence of variance
//! v = σ_n² Σ w_j² / (Σ w_j)² and lag-one correlation ρ = Σ w_j w_{j+1} / Σ w_j², for the
//! filter's weights w. Each excursion above u starts with an up-crossing, so the expected
//! number of false returns in a gate of N bins is
//!
//!   E = P(s_0 ≥ u) + (N − 1) P(s_k < u ≤ s_{k+1})
//!     = Q(z) + (N − 1) ∫_z^∞ φ(t) Φ((z − ρ t) / √(1 − ρ²)) dt,      z = u / √v,
//!
//! and u is the level at which E equals the false-alarm rate α (for small α, E is the
//! probability of any false return: two excursions in one gate have probability O(α²)).
//! The bivariate normal's up-crossing probability is integrated numerically; z depends on
//! (N, σ, α) only, and u = z √v.

use super::fit::{add_gaussians, Params};
use super::Component;
use crate::waveform::{normal_cdf, normal_pdf};
use std::cell::RefCell;
use std::collections::HashMap;

/// The filter's weights: a Gaussian of `sigma` bins to ±3σ (at least the bin itself).
fn weights(sigma: f64) -> Vec<f64> {
    let s = sigma.max(1e-3);
    let reach = (3.0 * s).ceil() as usize;
    (0..=2 * reach)
        .map(|j| {
            let d = j as f64 - reach as f64;
            (-0.5 * (d / s).powi(2)).exp()
        })
        .collect()
}

/// The record filtered with the return's shape, s_i = Σ_j w_j y_{i+j-reach} / Σ w: bins
/// beyond the gate count as zero, so s has the same variance everywhere but at the gate's
/// ends, where it is lower (and false alarms rarer).
pub(crate) fn matched(y: &[f64], sigma: f64) -> Vec<f64> {
    let w = weights(sigma);
    let reach = w.len() / 2;
    let total: f64 = w.iter().sum();
    (0..y.len())
        .map(|i| {
            let mut acc = 0.0;
            for (j, &wj) in w.iter().enumerate() {
                if let Some(&v) = (i + j).checked_sub(reach).and_then(|k| y.get(k)) {
                    acc += wj * v;
                }
            }
            acc / total
        })
        .collect()
}

/// An excursion of the filtered record above the level: bins [first, last] and its summit.
pub(super) struct Excursion {
    pub(super) first: usize,
    pub(super) last: usize,
    /// Centre of the highest bin (bin i spans [i, i+1)).
    pub(super) at: f64,
    pub(super) level: f64,
}

/// The excursions of the filtered record `s` at or above `u`, in time order.
pub(super) fn excursions(s: &[f64], u: f64) -> Vec<Excursion> {
    let mut out = Vec::new();
    let mut open: Option<Excursion> = None;
    for (i, &v) in s.iter().enumerate() {
        if v >= u {
            let e = open.get_or_insert(Excursion {
                first: i,
                last: i,
                at: i as f64 + 0.5,
                level: v,
            });
            e.last = i;
            if v > e.level {
                e.at = i as f64 + 0.5;
                e.level = v;
            }
        } else if let Some(e) = open.take() {
            out.push(e);
        }
    }
    out.extend(open);
    out
}

/// The highest level of the filtered record `s` within `reach` bins of `centre` (bin i spans
/// [i, i+1)); −∞ if none of its bins is there.
pub(super) fn summit_near(s: &[f64], centre: f64, reach: f64) -> f64 {
    let lo = (centre - reach).floor().max(0.0) as usize;
    let hi = ((centre + reach).ceil().max(0.0) as usize).min(s.len());
    s.get(lo..hi)
        .unwrap_or_default()
        .iter()
        .fold(f64::NEG_INFINITY, |m, &v| m.max(v))
}

/// The components that stand out from the noise on their own: the record less every other
/// component (as fitted: bin-integrated Gaussians), filtered, reaches the level `u` within
/// the component's width or the filter's `sigma` (a bin at least), and a bin more, of its
/// centre, the excursion that makes it, from whose summit the fit of a bump of noise may
/// wander that far. Without the others taken out, a bump of noise on a strong return's flank
/// would ride on the return's own filtered light.
/// `filtered` is [`matched`] of `y` itself, which a lone component is judged on.
pub(super) fn standing_out(
    comps: Vec<Component>,
    y: &[f64],
    filtered: &[f64],
    u: f64,
    sigma: f64,
) -> Vec<Component> {
    if comps.len() < 2 {
        return comps
            .into_iter()
            .filter(|c| summit_near(filtered, c.centre_bin, reach(c, sigma)) >= u)
            .collect();
    }
    let params: Vec<Params> = comps
        .iter()
        .map(|c| [c.centre_bin, c.sigma_bins, c.area_photons])
        .collect();
    (0..comps.len())
        .filter(|&k| {
            let mut model = vec![0.0; y.len()];
            let others: Vec<Params> = params
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != k)
                .map(|(_, p)| *p)
                .collect();
            add_gaussians(&mut model, 0.0, &others);
            let rest: Vec<f64> = y.iter().zip(&model).map(|(y, m)| y - m).collect();
            let s = matched(&rest, sigma);
            summit_near(&s, comps[k].centre_bin, reach(&comps[k], sigma)) >= u
        })
        .map(|k| comps[k])
        .collect()
}

/// Bins from a component's centre within which its excursion is looked for.
fn reach(c: &Component, sigma: f64) -> f64 {
    c.sigma_bins.max(sigma).max(1.0) + 1.0
}

/// Variance of the filtered noise per unit variance of a bin, and its lag-one correlation.
fn filter_moments(sigma: f64) -> (f64, f64) {
    let w = weights(sigma);
    let total: f64 = w.iter().sum();
    let squares: f64 = w.iter().map(|v| v * v).sum();
    let lag: f64 = w.windows(2).map(|p| p[0] * p[1]).sum();
    (squares / (total * total), lag / squares)
}

/// P(X < z ≤ Y) for standard normals of correlation ρ: ∫_0^∞ φ(z + x) Φ((z(1−ρ) − ρx)/s) dx,
/// s = √(1 − ρ²), by composite 4-point Gauss-Legendre over the range where the integrand
/// lives (the second factor falls from 1 to 0 over a few s / ρ, which the panels resolve).
fn up_crossing(z: f64, rho: f64) -> f64 {
    let rho = rho.clamp(-0.999_999, 0.999_999);
    let s = (1.0 - rho * rho).sqrt();
    let mut end: f64 = 10.0;
    if rho > 0.0 {
        end = end.min(((z * (1.0 - rho)).max(0.0) + 9.0 * s) / rho);
    }
    const PANELS: usize = 32;
    const NODES: [(f64, f64); 4] = [
        (0.069_431_844_202_973_71, 0.173_927_422_568_726_93),
        (0.330_009_478_207_571_87, 0.326_072_577_431_273_07),
        (0.669_990_521_792_428_1, 0.326_072_577_431_273_07),
        (0.930_568_155_797_026_3, 0.173_927_422_568_726_93),
    ];
    let h = end / PANELS as f64;
    let mut sum = 0.0;
    for p in 0..PANELS {
        for (x0, w) in NODES {
            let x = (p as f64 + x0) * h;
            sum += w * normal_pdf(z + x) * normal_cdf((z * (1.0 - rho) - rho * x) / s);
        }
    }
    sum * h
}

/// Expected false returns in a gate of `bins` bins at standardised level z.
fn expected_alarms(z: f64, bins: usize, rho: f64) -> f64 {
    normal_cdf(-z) + bins.saturating_sub(1) as f64 * up_crossing(z, rho)
}

thread_local! {
    /// z for (bins, σ, α): the same few gates recur over a survey's pulses.
    static LEVELS: RefCell<HashMap<(usize, u64, u64), f64>> = RefCell::new(HashMap::new());
}

/// The standardised level z at which a gate of `bins` bins of noise alone, filtered with a
/// Gaussian of `sigma` bins, gives `alpha` false returns on average (bisection: E falls with z).
fn standard_level(bins: usize, sigma: f64, alpha: f64) -> f64 {
    let key = (bins, sigma.to_bits(), alpha.to_bits());
    if let Some(z) = LEVELS.with_borrow(|m| m.get(&key).copied()) {
        return z;
    }
    let (_, rho) = filter_moments(sigma);
    let (mut lo, mut hi) = (-10.0f64, 40.0f64);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if expected_alarms(mid, bins, rho) > alpha {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let z = hi;
    LEVELS.with_borrow_mut(|m| {
        if m.len() > 4096 {
            m.clear();
        }
        m.insert(key, z);
    });
    z
}

/// The level of the [`matched`] record above which a return is reported: the larger of the
/// level a gate of `bins` bins of noise alone (variance `noise_var` per bin) crosses `alpha`
/// times on average and the filtered summit of a return whose own summit is `threshold` per
/// bin (a return of σ equal to the filter's: √½ of its summit).
pub(crate) fn alarm_level(
    bins: usize,
    sigma: f64,
    noise_var: f64,
    alpha: f64,
    threshold: f64,
) -> f64 {
    let (gain, _) = filter_moments(sigma);
    let noise = standard_level(bins.max(1), sigma, alpha) * (noise_var.max(0.0) * gain).sqrt();
    noise.max(threshold * std::f64::consts::FRAC_1_SQRT_2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The up-crossing probability against its closed forms: independent samples (ρ = 0),
    /// P(X < z) P(Y ≥ z); ρ → 1, Rice's rate exp(−z²/2) / (2π) · √(2(1 − ρ)).
    #[test]
    fn up_crossings_meet_their_closed_forms() {
        for z in [0.5, 2.0, 3.5, 5.0] {
            let want = normal_cdf(z) * normal_cdf(-z);
            let got = up_crossing(z, 0.0);
            assert!(
                (got / want - 1.0).abs() < 1e-6,
                "z {z}: {got:e} against {want:e}"
            );
            let rho: f64 = 0.9995;
            let rice =
                (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI) * (2.0 * (1.0 - rho)).sqrt();
            let got = up_crossing(z, rho);
            assert!(
                (got / rice - 1.0).abs() < 0.01,
                "z {z}: {got:e} against {rice:e}"
            );
        }
    }

    /// Gaussian noise filtered and thresholded at the level: the excursions per gate are the
    /// configured rate within 3 standard errors (Poisson counts), for filters of 0.8 to 4 bins.
    #[test]
    fn noise_alone_crosses_the_level_at_the_configured_rate() {
        let mut rng = SplitMix64::new(7);
        let normal = |rng: &mut SplitMix64| {
            let (u, v) = (rng.uniform_pos(), rng.uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        for (sigma, alpha) in [(0.8, 0.02), (1.7, 0.01), (2.0, 0.02), (4.0, 0.05)] {
            let (bins, gates, var) = (400, 20_000, 9.0);
            let u = alarm_level(bins, sigma, var, alpha, 0.0);
            let mut alarms = 0usize;
            for _ in 0..gates {
                let y: Vec<f64> = (0..bins).map(|_| 3.0 * normal(&mut rng)).collect();
                let s = matched(&y, sigma);
                let mut above = false;
                for &v in &s {
                    if v >= u && !above {
                        alarms += 1;
                    }
                    above = v >= u;
                }
            }
            let want = alpha * gates as f64;
            let se = want.sqrt();
            println!("σ {sigma}: {alarms} excursions against {want} ± {se:.1}");
            assert!(
                (alarms as f64 - want).abs() < 3.0 * se,
                "σ {sigma}: {alarms} excursions against {want} ± {se:.1}"
            );
        }
    }
}
