//! Gaussian decomposition: peaks grouped, each group fitted with bin-integrated Gaussians,
//! extra components accepted only when they pay for their parameters in deviance.

use super::detect::{smooth, smoothing_sigma};
use super::{
    blend, Component, Noise, Threshold, COLLAPSED_SIGMA, MAX_JOINT, MIN_DEVIANCE_GAIN, SIGMA_FLOOR,
};
use crate::waveform::bin_masses_into;
use std::borrow::Cow;

/// A Gaussian's parameters during the fit: centre, sigma (bins), area (photons).
pub(super) type Params = [f64; 3];

/// Fits every return: seeds grouped where their windows overlap, each group fitted with the
/// other groups' components and the `fixed` ones (returns kept as they are) held as its
/// background, twice, so that neighbours settle together. One pass over the groups in time
/// order, which is why it stays one function.
pub(super) fn fit_all(
    y: &[f64],
    peaks: &[Component],
    fixed: &[Component],
    threshold: Threshold,
    hint: f64,
    noise: &Noise,
) -> Vec<Component> {
    let floor = hint.max(SIGMA_FLOOR);
    let mut seeds: Vec<Params> = peaks
        .iter()
        .map(|p| {
            [
                p.centre_bin,
                p.sigma_bins.max(floor),
                p.area_photons.max(1e-6),
            ]
        })
        .collect();
    seeds.sort_by(|a, b| a[0].total_cmp(&b[0]));
    // Seeds whose fitting windows (see `bounds`) overlap are fitted together: a window
    // holding photons of a return that is not in its model would drag the fit.
    let mut groups: Vec<Vec<Params>> = Vec::new();
    for s in seeds {
        match groups.last_mut() {
            Some(g)
                if {
                    let l = g.last().expect("groups are never empty");
                    l[0] + 6.0 * l[1].max(hint) + 3.0 > s[0] - 6.0 * s[1].max(hint) - 3.0
                } =>
            {
                g.push(s)
            }
            _ => groups.push(vec![s]),
        }
    }
    let groups: Vec<Vec<Params>> = groups
        .into_iter()
        .map(|mut g| {
            if g.len() > MAX_JOINT {
                g.sort_by(|a, b| b[2].total_cmp(&a[2]));
                g.truncate(MAX_JOINT);
            }
            g
        })
        .collect();
    // `fixed` components (a comb's light, see `resolve`) are background to every group
    let fixed: Vec<Params> = fixed
        .iter()
        .map(|c| [c.centre_bin, c.sigma_bins, c.area_photons])
        .collect();
    // A return found in a group's residual may reach into the next group's window, so each
    // group sees the components fitted so far as a fixed background; a second pass then
    // gives every group the background of all the others.
    let reaching = |fitted: &[Vec<Params>], k: usize, lo: usize, hi: usize| -> Vec<Params> {
        fitted
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != k)
            .flat_map(|(_, g)| g.iter().copied())
            .chain(fixed.iter().copied())
            .filter(|p| p[0] + 8.0 * p[1] > lo as f64 && p[0] - 8.0 * p[1] < hi as f64)
            .collect()
    };
    let earliest = groups.first().map_or(f64::INFINITY, |g| g[0][0]);
    let mut fitted: Vec<Vec<Params>> = vec![Vec::new(); groups.len()];
    for (k, g) in groups.iter().enumerate() {
        let others = match bounds(g, hint, y.len()) {
            Some((lo, hi)) => reaching(&fitted, k, lo, hi),
            None => Vec::new(),
        };
        let limits = Limits {
            threshold,
            hint,
            floor,
            earliest,
        };
        fitted[k] = fit_group(y, g.clone(), &limits, &others, noise);
    }
    {
        for k in 0..fitted.len() {
            let start = if fitted[k].is_empty() {
                groups[k].clone()
            } else {
                fitted[k].clone()
            };
            let Some((lo, hi)) = bounds(&start, hint, y.len()) else {
                continue;
            };
            let others = reaching(&fitted, k, lo, hi);
            // Alone, a group needs its second fit only if the first one's window cut into
            // what it found: its window moved, but bins more than 5 sigmas from every
            // component change nothing a fit can mean (on a survey, many fits would be such
            // refits).
            let first = bounds(&groups[k], hint, y.len());
            let inside = first.is_some_and(|(a, b)| {
                start.iter().all(|p| {
                    let reach = 5.0 * p[1].max(hint);
                    p[0] - reach >= a as f64 && p[0] + reach <= b as f64
                })
            });
            if others.is_empty() && (first == Some((lo, hi)) || inside) {
                continue;
            }
            let win = Window::new(y, lo, hi, Some(&others), noise.floor);
            if let Some((p, _)) = fit_clean(&win, start, floor)
                .filter(|(p, _)| p.iter().any(|q| q[2] > threshold.area))
            {
                fitted[k] = p;
            }
        }
    }
    let mut out = Vec::new();
    for g in fitted {
        out.extend(g.iter().map(component));
    }
    out
}

/// Steps a trial of the residual search may take before it is judged against the others.
/// Most of those that converge do so in fewer; the rest crawl along a valley (a shape no
/// sum of Gaussians describes), and on a survey much of the multi-component fits' work comes
/// after the tenth step, in trials of which one a round at most is kept. The trial kept is
/// fitted on to convergence. Against trials of up to 100 steps, this saves a measurable share
/// of the products stage, the points and the DSM all but unchanged (the figures are in the
/// commit that made the choice).
const TRIAL_ITERATIONS: usize = 10;

/// Steps a fit may take: far more than a fit that converges needs (one or two from a
/// window's moments, ten to twenty for several components).
const MAX_ITERATIONS: usize = 100;

/// The return a fitted Gaussian makes.
fn component(p: &Params) -> Component {
    Component {
        centre_bin: p[0],
        sigma_bins: p[1],
        area_photons: p[2],
        amplitude: p[2] / (p[1] * (2.0 * std::f64::consts::PI).sqrt()),
        one_surface: false,
    }
}

/// What a group's fit is held to.
#[derive(Clone, Copy)]
struct Limits {
    /// Least level of signal per bin and least area of a component.
    threshold: Threshold,
    /// The pulse's sigma, bins.
    hint: f64,
    /// Least sigma of a component, bins.
    floor: f64,
    /// Centre of the waveform's earliest seed: an excess before it may be the first return,
    /// which the simulation's noise cannot have made (see `decompose`).
    earliest: f64,
}

/// Fits one group, then looks in the residual for returns that peak detection missed
/// (a weak return on the flank of a strong one makes a shoulder, not a maximum).
///
/// Long because the search is one loop: fit, look at the residual, try one more component,
/// keep it only if it pays for its three parameters in deviance.
fn fit_group(
    y: &[f64],
    seeds: Vec<Params>,
    limits: &Limits,
    others: &[Params],
    noise: &Noise,
) -> Vec<Params> {
    let Limits {
        threshold,
        hint,
        floor,
        earliest,
    } = *limits;
    let Some((lo, hi)) = bounds(&seeds, hint, y.len()) else {
        return Vec::new();
    };
    let win = Window::new(y, lo, hi, Some(others), noise.floor);
    // One return alone in its window starts from the window's moments, which are a
    // bin-integrated Gaussian's parameters (to e^(-2π²σ²), σ in bins) when it is one: the
    // solver's first step then shows it converged.
    // A record's noise has moments of its own across the window, so it starts from the seed.
    let start = match (&seeds[..], others.is_empty() && win.shift == 0.0) {
        ([_], true) => moments(&win, floor).map_or_else(|| seeds.clone(), |m| vec![m]),
        _ => seeds.clone(),
    };
    // a fit that fails (diverges, leaves its window, or shrinks every component below the
    // threshold) keeps the detector's seeds: it must not erase a return
    let Some((mut params, mut dev)) =
        fit_clean(&win, start, floor).filter(|(p, _)| p.iter().any(|q| q[2] > threshold.area))
    else {
        return seeds;
    };
    let sk = smoothing_sigma(hint);
    for _ in 0..3 {
        // No extra component could gain enough: the common case of a clean fit.
        if params.len() >= MAX_JOINT || dev < MIN_DEVIANCE_GAIN {
            break;
        }
        let mut trials: Vec<Vec<Params>> = Vec::new();
        // A return on the flank of a stronger one: the most significant excess in the
        // residual, not the largest, so a strong return's small shape mismatch does not
        // hide a weak one beside it.
        let m = win.model(&params);
        let r: Vec<f64> = win.y.iter().zip(&m).map(|(y, m)| y - m).collect();
        let rs = smooth(&r, sk);
        let ms = smooth(&m, sk);
        let z: Vec<f64> = rs
            .iter()
            .zip(&ms)
            .map(|(r, m)| r / (m + 1.0).sqrt())
            .collect();
        // The few most significant local excesses each make a trial: the single largest
        // may sit under a strong return whose shape the current model misses.
        let mut excess: Vec<usize> = (0..z.len())
            .filter(|&j| {
                rs[j] > threshold.per_bin
                    && (j == 0 || z[j - 1] < z[j])
                    && (j + 1 == z.len() || z[j + 1] <= z[j])
            })
            .collect();
        excess.sort_by(|&a, &b| z[b].total_cmp(&z[a]));
        excess.truncate(3);
        // A pulse sampled coarsely (σ under a bin) keeps its own width here, down to half a
        // bin: a trial as wide as a bin would blend two returns 2 bins apart into one.
        for j in excess {
            let half = (2.0 * hint.max(0.5)).ceil() as usize;
            let (a, b) = (j.saturating_sub(half), (j + half + 1).min(r.len()));
            let area: f64 = r[a..b].iter().sum();
            let lo = win.offset as usize;
            // the model holds the noise's variance (the window's shift) in every bin
            let mut var = m[a..b].iter().sum::<f64>() + 1.0;
            if win.offset + j as f64 + 0.5 > earliest {
                var += noise.mc_var(lo + a, lo + b);
            }
            let sd = var.sqrt();
            // Only a loose screen: the deviance test below decides.
            if area > threshold.area && area > 2.0 * sd {
                let mut t = params.clone();
                t.push([win.offset + j as f64 + 0.5, hint.max(0.5), area]);
                trials.push(t);
            }
        }
        // Two returns closer than their widths blend into one wide component: try it split.
        let widest = (0..params.len())
            .max_by(|&a, &b| params[a][1].total_cmp(&params[b][1]))
            .filter(|&w| params[w][1] > 1.3 * floor.max(hint.clamp(0.5, 1.0)));
        if let Some(w) = widest {
            let p = params[w];
            let s2 = (0.6 * p[1]).max(floor);
            let mut t: Vec<Params> = params
                .iter()
                .enumerate()
                .filter(|(k, _)| *k != w)
                .map(|(_, q)| *q)
                .collect();
            t.push([p[0] - 0.8 * p[1], s2, 0.5 * p[2]]);
            t.push([p[0] + 0.8 * p[1], s2, 0.5 * p[2]]);
            trials.push(t);
        }
        // A component only pays if a detector could tell it from its neighbours: on a mean
        // waveform of 10^5 photons any shape that is no Gaussian (a smeared surface, a comb
        // of few rays) gains deviance from a split that `resolve` merges back, and each
        // such round fits up to four more models.
        let returns = returns_made(&params, y, noise);
        let mut best: Option<(Vec<Params>, f64, bool)> = None;
        for t in trials {
            if let Some((p, d, capped)) = fit_clean_within(&win, t, floor, TRIAL_ITERATIONS) {
                if d < dev - MIN_DEVIANCE_GAIN
                    && p.len() > params.len()
                    && best.as_ref().is_none_or(|b| d < b.1)
                    && returns_made(&p, y, noise) > returns
                {
                    best = Some((p, d, capped));
                }
            }
        }
        let Some((p, d, capped)) = best else {
            break;
        };
        // the trial kept, if it was cut short, is fitted on to convergence, as long as it
        // keeps the component it was tried for
        (params, dev) = match capped.then(|| fit_clean(&win, p.clone(), floor)).flatten() {
            Some((q, e)) if e <= d && q.len() == p.len() => (q, e),
            _ => (p, d),
        };
    }
    params
}

/// The window's photons as one Gaussian: centroid, standard deviation (less a bin's own
/// variance, 1/12, at least `floor`) and sum; None without photons.
fn moments(win: &Window, floor: f64) -> Option<Params> {
    let (mut sum, mut first, mut second) = (0.0, 0.0, 0.0);
    for (i, &v) in win.y.iter().enumerate() {
        let x = i as f64 + 0.5;
        sum += v;
        first += v * x;
        second += v * x * x;
    }
    if sum.is_nan() || sum <= 0.0 {
        return None;
    }
    let mean = first / sum;
    let var = second / sum - mean * mean - 1.0 / 12.0;
    Some([win.offset + mean, var.max(0.0).sqrt().max(floor), sum])
}

/// The returns a detector would make of these components ([`blend`]).
fn returns_made(params: &[Params], y: &[f64], noise: &Noise) -> usize {
    let mut comps: Vec<Component> = params.iter().map(component).collect();
    comps.sort_by(|a, b| a.centre_bin.total_cmp(&b.centre_bin));
    blend(comps, y, noise, None).len()
}

/// Fits, then drops diverged, collapsed or duplicated components and refits the rest, at most
/// twice; what it returns lies within the window.
fn fit_clean(win: &Window, seeds: Vec<Params>, floor: f64) -> Option<(Vec<Params>, f64)> {
    fit_clean_within(win, seeds, floor, MAX_ITERATIONS).map(|(p, dev, _)| (p, dev))
}

/// [`fit_clean`] with each fit held to `iterations` steps; also says whether one of them
/// stopped at that limit.
fn fit_clean_within(
    win: &Window,
    seeds: Vec<Params>,
    floor: f64,
    iterations: usize,
) -> Option<(Vec<Params>, f64, bool)> {
    let mut params = seeds;
    let mut capped = false;
    for round in 0..3 {
        let (p, dev, cut) = win.fit(std::mem::take(&mut params), floor, iterations)?;
        capped |= cut;
        let len = win.y.len() as f64;
        let mut kept: Vec<Params> = p
            .iter()
            .copied()
            .filter(|q| {
                q.iter().all(|v| v.is_finite())
                    && q[0] > win.offset - 1.0
                    && q[0] < win.offset + len + 1.0
                    && q[1] >= COLLAPSED_SIGMA
                    && q[1] < len
                    && q[2] > 0.0
            })
            .collect();
        // Two components on top of each other are one return split in two.
        kept.sort_by(|a, b| a[0].total_cmp(&b[0]));
        let mut merged: Vec<Params> = Vec::new();
        for q in kept {
            match merged.last_mut() {
                Some(l) if (q[0] - l[0]).abs() < 0.5 * l[1].min(q[1]) => {
                    let a = l[2] + q[2];
                    *l = [(l[0] * l[2] + q[0] * q[2]) / a, l[1].max(q[1]), a];
                }
                _ => merged.push(q),
            }
        }
        if merged.len() == p.len() {
            return Some((p, dev, capped));
        }
        if merged.is_empty() {
            return None;
        }
        if round == 2 {
            // a further refit may wander off again: the components that stayed in place
            let dev = win.deviance(&win.model(&merged));
            return Some((merged, dev, capped));
        }
        params = merged;
    }
    None
}

/// Bins [lo, hi) a group is fitted on: ±6σ of each component and 3 bins of margin.
fn bounds(params: &[Params], hint: f64, n: usize) -> Option<(usize, usize)> {
    let lo = params
        .iter()
        .map(|p| p[0] - 6.0 * p[1].max(hint) - 3.0)
        .fold(f64::INFINITY, f64::min)
        .floor()
        .max(0.0) as usize;
    let hi = (params
        .iter()
        .map(|p| p[0] + 6.0 * p[1].max(hint) + 3.0)
        .fold(f64::NEG_INFINITY, f64::max)
        .ceil()
        .max(0.0) as usize)
        .min(n);
    (lo < hi).then_some((lo, hi))
}

/// Adds bin-integrated Gaussians to `m`, whose first bin has index `offset`.
pub(super) fn add_gaussians(m: &mut [f64], offset: f64, params: &[Params]) {
    add_gaussians_keeping(m, offset, params, &mut Vec::new());
}

/// [`add_gaussians`], keeping in `masses` each component's bin integrals (the fraction of it
/// in each bin it touches), component after component: the solver's Jacobian at these
/// parameters needs the same values, which are most of its cost to compute again.
fn add_gaussians_keeping(m: &mut [f64], offset: f64, params: &[Params], masses: &mut Vec<f64>) {
    masses.clear();
    let n = m.len() as f64;
    for p in params {
        let (a, b) = span(p, offset, n);
        let start = masses.len();
        bin_masses(p, offset, (a, b), masses);
        for (mi, mass) in m[a..b].iter_mut().zip(&masses[start..]) {
            *mi += p[2] * mass;
        }
    }
}

/// [`bin_masses_into`] of the unit Gaussian of centre p[0] and sigma p[1] (bins).
fn bin_masses(p: &Params, offset: f64, (a, b): (usize, usize), out: &mut Vec<f64>) {
    bin_masses_into(p[0], p[1], offset, (a, b), out);
}

/// Bins [a, b) of a window of `n` bins starting at bin `offset` that a component touches:
/// ±8σ holds all but 1e-15 of it.
fn span(p: &Params, offset: f64, n: f64) -> (usize, usize) {
    let a = (p[0] - offset - 8.0 * p[1] - 1.0).floor().clamp(0.0, n) as usize;
    let b = (p[0] - offset + 8.0 * p[1] + 1.0).ceil().clamp(0.0, n) as usize;
    (a, b.max(a))
}

/// The bins a group is fitted on.
///
/// A record with noise besides its photons' own (electronic noise, the background's shot
/// noise, rounding: variance `shift` per bin) is fitted as a shifted Poisson count: y + shift
/// against m + shift. Its variance, m + shift, is the record's, so the deviance weighs each
/// bin by its real noise and the likelihood-ratio test of an extra component keeps its χ²
/// calibration; a plain Poisson deviance would take the noise for signal and breed
/// components. Negative samples (noise below the background) are kept, not rectified, down
/// to -shift, below which a shifted count cannot go.
pub(super) struct Window<'a> {
    /// The shifted samples, y + shift (the samples themselves for a noise-free waveform).
    pub(super) y: Cow<'a, [f64]>,
    /// Bin index of y[0].
    pub(super) offset: f64,
    /// Fixed part of the model: the other groups' components that reach into this window,
    /// plus the shift and a floor that keeps the model positive so the likelihood stays
    /// finite.
    pub(super) base: Vec<f64>,
    /// The noise variance per bin added to the samples and the model.
    pub(super) shift: f64,
}

impl<'a> Window<'a> {
    fn new(y: &'a [f64], lo: usize, hi: usize, others: Option<&[Params]>, shift: f64) -> Self {
        let y = &y[lo..hi];
        let eps = 1e-9 * (1.0 + y.iter().cloned().fold(0.0, f64::max));
        let y: Cow<'a, [f64]> = if shift > 0.0 {
            Cow::Owned(y.iter().map(|&v| (v + shift).max(0.0)).collect())
        } else {
            Cow::Borrowed(y)
        };
        let mut base = vec![eps + shift; y.len()];
        if let Some(o) = others {
            add_gaussians(&mut base, lo as f64, o);
        }
        Window {
            y,
            offset: lo as f64,
            base,
            shift,
        }
    }
}

pub(super) use crate::waveform::normal_pdf as pdf;

impl Window<'_> {
    /// Bins a component touches (see [`span`]).
    pub(super) fn reach(&self, p: &Params) -> (usize, usize) {
        span(p, self.offset, self.y.len() as f64)
    }

    pub(super) fn model(&self, params: &[Params]) -> Vec<f64> {
        let mut m = self.base.clone();
        add_gaussians(&mut m, self.offset, params);
        m
    }

    /// [`Window::model`] into `m`, with each component's bin integrals kept in `masses` (see
    /// [`add_gaussians_keeping`]).
    pub(super) fn model_keeping(&self, params: &[Params], masses: &mut Vec<f64>, m: &mut Vec<f64>) {
        m.clear();
        m.extend_from_slice(&self.base);
        add_gaussians_keeping(m, self.offset, params, masses);
    }

    /// Poisson deviance, 2 Σ [m - y + y ln(y/m)].
    pub(super) fn deviance(&self, m: &[f64]) -> f64 {
        2.0 * self
            .y
            .iter()
            .zip(m)
            .map(
                |(&y, &m)| {
                    if y > 0.0 {
                        m - y + y * (y / m).ln()
                    } else {
                        m
                    }
                },
            )
            .sum::<f64>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::waveform::normal_cdf;

    /// Bin integrals by quadrature equal the differences of Φ to 1e-10 of the component
    /// wherever the quadrature is used (bins up to half a sigma), centred anywhere in a bin
    /// and reaching both ends of the window.
    #[test]
    fn quadrature_bins_equal_differences_of_phi() {
        for sigma in [2.0, 2.55, 4.0, 7.3, 19.0] {
            for centre in [0.0, 0.37, 31.5, 40.99, 79.2] {
                let p = [centre, sigma, 1.0];
                let (a, b) = span(&p, 0.0, 80.0);
                let mut quad = Vec::new();
                bin_masses(&p, 0.0, (a, b), &mut quad);
                for (i, q) in (a..b).zip(&quad) {
                    let exact = normal_cdf((i as f64 + 1.0 - centre) / sigma)
                        - normal_cdf((i as f64 - centre) / sigma);
                    assert!(
                        (q - exact).abs() < 1e-10,
                        "sigma {sigma}, centre {centre}, bin {i}: {q:e} against {exact:e}"
                    );
                }
            }
        }
    }
}
