//! The detection threshold of a record with noise, set by a false-alarm probability.
//!
//! A detector reports a return where its record, filtered with the return's own shape (the
//! matched filter: a Gaussian of the return's σ), rises above a level u. In a gate of noise
//! alone (white, variance σ_n² per bin: electronic noise, the background's shot noise,
//! rounding) the filtered record s is a Gaussian sequence. The filter is cut at the gate's
//! ends (bins beyond count as zero, as [`matched`] has it), so s_i has variance
//! v_i = σ_n² Σ' w_j² / (Σ w_j)², the sum Σ' over the weights w that fall on the gate's bins,
//! and s_i, s_{i+1} the covariance c_i = σ_n² Σ' w_j w_{j+1} / (Σ w_j)²: a gate's first and
//! last few bins are quieter than its middle, where v and ρ = c / v are the stationary ones.
//! Each excursion above u starts with an up-crossing, so the expected number of false returns
//! in a gate of N bins is
//!
//!   E = P(s_0 ≥ u) + Σ_{i < N−1} P(s_i < u ≤ s_{i+1})
//!     = Q(a_0) + Σ_i ∫_{b_i}^∞ φ(t) Φ((a_i − ρ_i t) / √(1 − ρ_i²)) dt,
//!
//! with a_i = u / √v_i, b_i = u / √v_{i+1} and ρ_i = c_i / √(v_i v_{i+1}); the pairs in the
//! middle of the gate share one term. Excursions of a high level are rare and nearly
//! independent, so their count in a gate is Poisson and the probability of any false return
//! is 1 − e^(−E): u is the level at which E = −ln(1 − α), for the false-alarm rate α. The
//! integrals are numerical; the level depends on (N, σ, α) only, in units of √v of the middle.

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

/// Variance of the filtered noise per unit variance of a bin in the middle of a gate.
fn filter_gain(sigma: f64) -> f64 {
    let w = weights(sigma);
    let total: f64 = w.iter().sum();
    let squares: f64 = w.iter().map(|v| v * v).sum();
    squares / (total * total)
}

/// A gate's false-alarm terms, in units of the middle's variance: the first bin's standard
/// deviation, then each kind of neighbouring pair (i, i + 1) as (how many such pairs, sd of
/// s_i, sd of s_{i+1}, their correlation). The pairs the whole filter covers are one kind;
/// those within its reach of an end are each their own.
struct GateTerms {
    first_sd: f64,
    pairs: Vec<(f64, f64, f64, f64)>,
}

/// Most terms a gate's edges are summed in ([`GateTerms::grouped`]).
const EDGE_TERMS: usize = 256;

impl GateTerms {
    fn new(bins: usize, sigma: f64) -> GateTerms {
        GateTerms::grouped(bins, sigma, EDGE_TERMS)
    }

    /// The terms of a gate whose every bin were a middle one: the whole filter's variance and
    /// lag-one correlation everywhere.
    fn stationary(bins: usize, sigma: f64) -> GateTerms {
        let w = weights(sigma);
        let squares: f64 = w.iter().map(|v| v * v).sum();
        let lag: f64 = w.windows(2).map(|p| p[0] * p[1]).sum();
        let n_pairs = bins.saturating_sub(1);
        GateTerms {
            first_sd: 1.0,
            pairs: (n_pairs > 0)
                .then_some((n_pairs as f64, 1.0, 1.0, lag / squares))
                .into_iter()
                .collect(),
        }
    }

    /// The terms, the edges' pairs in at most about `most_terms` runs.
    fn grouped(bins: usize, sigma: f64, most_terms: usize) -> GateTerms {
        let w = weights(sigma);
        let len = w.len();
        let reach = len / 2;
        // prefix sums of the squares and of the lag-one products, for any cut of the filter
        let mut squares = vec![0.0; len + 1];
        let mut lags = vec![0.0; len + 1];
        for j in 0..len {
            squares[j + 1] = squares[j] + w[j] * w[j];
            lags[j + 1] = lags[j] + if j > 0 { w[j] * w[j - 1] } else { 0.0 };
        }
        let middle = squares[len];
        // the weights j of bin i that fall on the gate: i + j - reach in [0, bins)
        let cut = |i: usize| (reach.saturating_sub(i), (bins + reach - i).min(len));
        let var = |i: usize| {
            let (lo, hi) = cut(i);
            (squares[hi] - squares[lo]) / middle
        };
        let cov = |i: usize| {
            // s_i's weight m meets s_{i+1}'s weight m - 1 on bin i + m - reach
            let (lo, hi) = cut(i);
            let lo = lo.max(1);
            if hi > lo {
                (lags[hi] - lags[lo]) / middle
            } else {
                0.0
            }
        };
        let pair = |i: usize, count: f64| {
            let (va, vb) = (var(i), var(i + 1));
            (count, va.sqrt(), vb.sqrt(), cov(i) / (va * vb).sqrt())
        };
        let n_pairs = bins.saturating_sub(1);
        // pairs i in [reach, bins - 2 - reach] have both bins' filters whole
        let whole = (reach..n_pairs.saturating_sub(reach)).len();
        let mut pairs = Vec::new();
        if whole > 0 {
            pairs.push(pair(reach, whole as f64));
        }
        // a filter of thousands of bins (a pulse of microseconds, its σ not coarsened on the
        // L2A's path) has as many pairs within its reach of the ends: their moments change
        // smoothly from pair to pair, and runs of them stand for their middle one
        let edge: Vec<usize> = (0..n_pairs)
            .filter(|&i| i < reach || i + 1 + reach >= bins)
            .collect();
        let run = edge.len().div_ceil(most_terms.max(1)).max(1);
        for group in edge.chunks(run) {
            pairs.push(pair(group[group.len() / 2], group.len() as f64));
        }
        GateTerms {
            first_sd: var(0).sqrt(),
            pairs,
        }
    }

    /// Expected up-crossings of the level z (in sd of the middle) in the gate.
    fn expected_alarms(&self, z: f64) -> f64 {
        let mut e = normal_cdf(-z / self.first_sd);
        for &(count, sd_a, sd_b, rho) in &self.pairs {
            e += count * up_crossing(z / sd_a, z / sd_b, rho);
        }
        e
    }
}

/// P(X < a, Y ≥ b) for standard normals of correlation ρ:
/// ∫_0^∞ φ(b + x) Φ((a − ρb − ρx)/s) dx, s = √(1 − ρ²), by composite 4-point Gauss-Legendre
/// over the range where the integrand lives (the second factor falls from 1 to 0 over a few
/// s / ρ, which the panels resolve).
fn up_crossing(a: f64, b: f64, rho: f64) -> f64 {
    let rho = rho.clamp(-0.999_999, 0.999_999);
    let s = (1.0 - rho * rho).sqrt();
    let mut end: f64 = 10.0 + (-b).max(0.0);
    if rho > 0.0 {
        end = end.min(((a - rho * b).max(0.0) + 9.0 * s) / rho);
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
            sum += w * normal_pdf(b + x) * normal_cdf((a - rho * b - rho * x) / s);
        }
    }
    sum * h
}

thread_local! {
    /// z for (bins, σ, α): the same few gates recur over a survey's pulses.
    static LEVELS: RefCell<HashMap<(usize, u64, u64), f64>> = RefCell::new(HashMap::new());
}

/// The standardised level z (in sd of the gate's middle) at which a gate of `bins` bins of
/// noise alone, filtered with a Gaussian of `sigma` bins, gives a false return with
/// probability `alpha`: E(z) = −ln(1 − α) by bisection (E falls with z).
fn standard_level(bins: usize, sigma: f64, alpha: f64) -> f64 {
    let key = (bins, sigma.to_bits(), alpha.to_bits());
    if let Some(z) = LEVELS.with_borrow(|m| m.get(&key).copied()) {
        return z;
    }
    let terms = GateTerms::new(bins, sigma);
    let target = -(-alpha).ln_1p();
    // the level of a gate all middle, found with one term a step, brackets the root from
    // above (the quieter edges only lower E): the gate's own search starts beside it
    let middle = GateTerms::stationary(bins, sigma);
    let start = solve_falling(|z| middle.expected_alarms(z).ln() - target.ln(), 4.0);
    let z = solve_falling(|z| terms.expected_alarms(z).ln() - target.ln(), start);
    LEVELS.with_borrow_mut(|m| {
        if m.len() > 4096 {
            m.clear();
        }
        m.insert(key, z);
    });
    z
}

/// The root of `f`, a function that falls with z, in [−10, 40] (at the nearer end when none
/// is there): a bracket of unit steps from [start − 1, start], then regula falsi with the
/// Illinois rule.
/// Each step of `f` is a gate's sum of integrals, and this takes about a dozen where
/// bisection to the same 1e-9 takes forty.
fn solve_falling(f: impl Fn(f64) -> f64, start: f64) -> f64 {
    let (min, max) = (-10.0f64, 40.0f64);
    let hi = start.clamp(min + 1.0, max);
    let (mut lo, mut hi) = (hi - 1.0, hi);
    let (mut f_lo, mut f_hi) = (f(lo), f(hi));
    while f_lo < 0.0 {
        if lo <= min {
            return min;
        }
        (hi, f_hi) = (lo, f_lo);
        lo = (lo - 1.0).max(min);
        f_lo = f(lo);
    }
    while f_hi > 0.0 {
        if hi >= max {
            return max;
        }
        (lo, f_lo) = (hi, f_hi);
        hi = (hi + 1.0).min(max);
        f_hi = f(hi);
    }
    // f(lo) ≥ 0 ≥ f(hi); where f is infinite (E underflows far out) the step is a halving
    let mut side = 0i8;
    for _ in 0..100 {
        if hi - lo < 1e-10 {
            break;
        }
        let mut z = hi - f_hi * (hi - lo) / (f_hi - f_lo);
        if !(z > lo && z < hi) {
            z = 0.5 * (lo + hi);
        }
        let fz = f(z);
        if fz == 0.0 {
            return z;
        }
        if fz > 0.0 {
            (lo, f_lo) = (z, fz);
            if side == -1 {
                f_hi *= 0.5;
            }
            side = -1;
        } else {
            (hi, f_hi) = (z, fz);
            if side == 1 {
                f_lo *= 0.5;
            }
            side = 1;
        }
    }
    0.5 * (lo + hi)
}

/// The level of the [`matched`] record above which a return is reported: the larger of the
/// level a gate of `bins` bins of noise alone (variance `noise_var` per bin) crosses with
/// probability `alpha` and the filtered summit of a return whose own summit is `threshold` per
/// bin (a return of σ equal to the filter's: √½ of its summit).
pub(crate) fn alarm_level(
    bins: usize,
    sigma: f64,
    noise_var: f64,
    alpha: f64,
    threshold: f64,
) -> f64 {
    let gain = filter_gain(sigma);
    let noise = standard_level(bins.max(1), sigma, alpha) * (noise_var.max(0.0) * gain).sqrt();
    noise.max(threshold * std::f64::consts::FRAC_1_SQRT_2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The up-crossing probability against its closed forms: independent samples (ρ = 0),
    /// P(X < a) P(Y ≥ b); ρ → 1 at one level, Rice's rate exp(−z²/2) / (2π) · √(2(1 − ρ)).
    #[test]
    fn up_crossings_meet_their_closed_forms() {
        for z in [0.5, 2.0, 3.5, 5.0] {
            for b in [z, 0.7 * z, 1.6 * z] {
                let want = normal_cdf(z) * normal_cdf(-b);
                let got = up_crossing(z, b, 0.0);
                assert!(
                    (got / want - 1.0).abs() < 1e-6,
                    "a {z}, b {b}: {got:e} against {want:e}"
                );
            }
            let rho: f64 = 0.9995;
            let rice =
                (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI) * (2.0 * (1.0 - rho)).sqrt();
            let got = up_crossing(z, z, rho);
            assert!(
                (got / rice - 1.0).abs() < 0.01,
                "z {z}: {got:e} against {rice:e}"
            );
        }
    }

    /// The gate's terms, grouped, against every bin's variance and every pair's covariance
    /// summed from the filter's matrix itself ([`matched`] of each unit impulse): the expected
    /// up-crossings agree, for gates shorter than the filter, about as long, and much longer.
    #[test]
    fn the_gate_terms_are_the_filtered_noise_moments() {
        for (bins, sigma) in [
            (1, 2.0),
            (5, 2.0),
            (13, 2.0),
            (40, 1.7),
            (300, 5.1),
            (64, 0.3),
        ] {
            // column k of the matrix: the filtered record of a unit impulse at bin k
            let columns: Vec<Vec<f64>> = (0..bins)
                .map(|k| {
                    let mut y = vec![0.0; bins];
                    y[k] = 1.0;
                    matched(&y, sigma)
                })
                .collect();
            let middle = filter_gain(sigma);
            let moment = |i: usize, j: usize| -> f64 {
                columns.iter().map(|c| c[i] * c[j]).sum::<f64>() / middle
            };
            let terms = GateTerms::new(bins, sigma);
            for z in [1.0, 2.5, 4.0] {
                let mut want = normal_cdf(-z / moment(0, 0).sqrt());
                for i in 0..bins.saturating_sub(1) {
                    let (va, vb) = (moment(i, i), moment(i + 1, i + 1));
                    let rho = moment(i, i + 1) / (va * vb).sqrt();
                    want += up_crossing(z / va.sqrt(), z / vb.sqrt(), rho);
                }
                let got = terms.expected_alarms(z);
                assert!(
                    (got / want - 1.0).abs() < 1e-9,
                    "{bins} bins, σ {sigma}, z {z}: {got:e} against {want:e}"
                );
            }
        }
    }

    /// Gaussian noise filtered and thresholded at the level: the share of gates with at least
    /// one excursion is the configured rate within 3 standard errors (binomial), for filters
    /// of 0.8 to 5 bins and gates of 40 to 400 bins, where the filter's cut at the gate's ends
    /// is a large part of a short gate.
    #[test]
    fn noise_alone_crosses_the_level_at_the_configured_rate() {
        let mut rng = SplitMix64::new(7);
        let normal = |rng: &mut SplitMix64| {
            let (u, v) = (rng.uniform_pos(), rng.uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        };
        let cases = [
            (400, 0.8, 0.02),
            (400, 1.7, 0.01),
            (400, 2.0, 0.05),
            (200, 5.1, 0.05),
            (100, 4.0, 0.05),
            (40, 5.1, 0.05),
            (40, 1.0, 0.2),
        ];
        for (bins, sigma, alpha) in cases {
            let (gates, var) = (20_000, 9.0);
            let u = alarm_level(bins, sigma, var, alpha, 0.0);
            let mut alarmed = 0usize;
            for _ in 0..gates {
                let y: Vec<f64> = (0..bins).map(|_| 3.0 * normal(&mut rng)).collect();
                if matched(&y, sigma).iter().any(|&v| v >= u) {
                    alarmed += 1;
                }
            }
            let want = alpha * gates as f64;
            let se = (want * (1.0 - alpha)).sqrt();
            println!("{bins} bins, σ {sigma}: {alarmed} gates alarmed against {want} ± {se:.1}");
            assert!(
                (alarmed as f64 - want).abs() < 3.0 * se,
                "{bins} bins, σ {sigma}: {alarmed} gates alarmed against {want} ± {se:.1}"
            );
        }
    }

    /// The level solves E = −ln(1 − α) to the bracket's precision from α = 1e-300 to 0.999
    /// (E counts excursions, so it rises as z falls only down to about 0, then falls to one
    /// excursion as the level drops below the whole gate: the root is the upper one), and
    /// where no level can (one bin cannot alarm 6.9 times) it is the lowest, not a hang.
    #[test]
    fn the_level_solves_its_equation_at_extreme_rates() {
        for (bins, sigma) in [(1, 1.0), (2, 0.5), (400, 1.7), (200, 40.0)] {
            let terms = GateTerms::new(bins, sigma);
            for alpha in [1e-300, 1e-12, 1e-3, 0.5, 0.999] {
                let z = standard_level(bins, sigma, alpha);
                let target = -(-alpha).ln_1p();
                if z == -10.0 {
                    for k in 0..=140 {
                        let z = -10.0 + 0.1 * k as f64;
                        let e = terms.expected_alarms(z);
                        assert!(e < target, "{bins} bins, α {alpha}: E({z}) {e} missed");
                    }
                } else {
                    let e = terms.expected_alarms(z);
                    assert!(
                        (e / target - 1.0).abs() < 1e-6,
                        "{bins} bins, σ {sigma}, α {alpha}: z {z}, E {e:e} against {target:e}"
                    );
                }
            }
        }
    }

    /// A filter of thousands of bins, its edges' pairs summed in runs, gives the expected
    /// up-crossings of every pair summed one by one to 1e-3, and its level in milliseconds
    /// rather than seconds.
    #[test]
    fn a_wide_filter_sums_its_edges_in_runs() {
        for (bins, sigma) in [(12_000, 1274.0), (3_000, 900.0), (400, 40.0)] {
            let grouped = GateTerms::new(bins, sigma);
            let exact = GateTerms::grouped(bins, sigma, usize::MAX);
            assert!(
                grouped.pairs.len() <= EDGE_TERMS + 2,
                "{}",
                grouped.pairs.len()
            );
            for z in [2.0, 3.5, 5.0, 8.0] {
                let (g, e) = (grouped.expected_alarms(z), exact.expected_alarms(z));
                assert!(
                    (g / e - 1.0).abs() < 1e-3,
                    "{bins} bins, σ {sigma}, z {z}: {g:e} against {e:e}"
                );
            }
        }
    }
}
