//! Discrete returns from a waveform: peak detection or Gaussian decomposition (section 2.5).
//!
//! Bin i spans [i, i+1) in bin units, so a Gaussian centred in the middle of bin i has its
//! centre at i + 0.5. The Gaussian model integrates each component over the bin (an erf
//! difference) because the simulator's waveforms are bin integrals of the pulse-convolved
//! signal: sampling at bin centres would bias sigma by the bin width and, for narrow pulses,
//! the area too.
//!
//! The waveform is a photon count (or its mean), so the fit maximises the Poisson likelihood
//! (Levenberg-Marquardt on the Poisson deviance with Fisher scoring) rather than plain least
//! squares: on noisy counts this reaches the Cramér-Rao bound, and on a noise-free mean
//! waveform the optimum is still the exact parameters. Any background (solar, dark) must be
//! subtracted by the caller: the model has no baseline.

pub(crate) mod alarm;
mod detect;
mod fit;
mod solve;
mod surface;
#[cfg(test)]
mod tests;

use detect::{detect_peaks, parabola};
use fit::fit_all;

/// How a waveform becomes discrete returns.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Decomposition {
    /// Local maxima, centre refined by a parabola through ln of the three bins.
    PeakDetection,
    /// Peak detection seeds refined by a fit of bin-integrated Gaussians.
    #[default]
    Gaussian,
}

/// What shapes a return in the waveform given to [`decompose`], and the noise of each bin
/// besides the shot noise of its own photons.
#[derive(Clone, Copy, Debug)]
pub struct Receiver {
    /// The return's standard deviation in bins (the pulse's and the detector response's):
    /// it sizes the smoothing used for detection, seeds sigma, and bounds the fitted sigma
    /// from below (no return is narrower).
    pub sigma_bins: f64,
    /// Where the beam's footprint is cut, in sigmas of its Gaussian
    /// ([`crate::sensor::footprint_edge_sigmas`]): it shapes the waveform of one surface seen
    /// obliquely; None: unknown, no such test.
    pub footprint_edge_sigmas: Option<f64>,
    /// Variance of each bin's photons besides their shot noise, photons²: the configured
    /// electronic noise, the background's shot noise and the digitiser's rounding; 0 for the
    /// mean waveform.
    pub noise_floor: f64,
    /// For a record with noise: the probability that a gate of noise alone yields a return,
    /// which sets the level the matched-filtered record must reach ([`alarm`]); None: the
    /// threshold alone decides (a mean waveform, or a record without noise).
    pub false_alarm_rate: Option<f64>,
}

/// One return of a waveform, in bin units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Component {
    /// Fractional bin index of the centre (bin i spans [i, i+1)).
    pub centre_bin: f64,
    pub sigma_bins: f64,
    /// Total photons of the component.
    pub area_photons: f64,
    /// Peak of the component in photons per bin: area / (sigma √(2π)) for a Gaussian, the
    /// parabola's summit for peak detection.
    pub amplitude: f64,
    /// A return whose waveform is one surface's, the pulse smeared over its spread of ranges
    /// (a slope, see `surface`): placed at its centroid, the range of the beam's axis, never at
    /// a summit.
    pub one_surface: bool,
}

/// Components fitted jointly: 6 Gaussians = 18 parameters, still a trivial dense solve.
/// Components far enough apart are fitted in separate groups, so this bounds only pile-ups.
const MAX_JOINT: usize = 6;
/// Sigma below which a component is a one-bin spike, not a return (only reachable when the
/// caller gives no pulse width).
const COLLAPSED_SIGMA: f64 = 0.3;
const SIGMA_FLOOR: f64 = 0.1;
/// Deviance gain required to accept an extra component (likelihood-ratio test, 3 more
/// parameters): χ²₃ exceeds 16 with probability 0.1%, so noise rarely breeds components,
/// while two weak returns (~100 photons each) 3.3σ apart still separate.
const MIN_DEVIANCE_GAIN: f64 = 16.0;
/// Standard errors a return's area must exceed: below two, a "return" is as likely a draw
/// of the estimator (one rare multiple-scattering path among a pulse's few rays makes a
/// spike of its own) or of the photon noise as a surface.
const MIN_SIGNIFICANCE: f64 = 2.0;
/// Components less than this many sigmas (of the narrower) apart with no dip between them
/// are one return whose shape is no Gaussian, such as a mildly smeared surface: Gaussians
/// fitted to a flat top sit about 2σ apart, at Sparrow's limit, while returns 3σ apart are
/// resolved (the decomposition tests' cases), even a weak one on a strong one's flank with
/// no dip between them. The narrower's sigma, because a weak return's fitted width is the
/// least certain and must not merge it away.
const BLENDED_SIGMAS: f64 = 2.5;

/// Largest Monte Carlo error, relative to its area, of a wide return whose shape may show
/// it is one slope: with it, a survey of a few rays a pulse places more of its points within
/// 5 cm of a surface than with no limit, while planes at 200 rays and more are all placed at
/// their centroids.
const SHAPE_KNOWN: f64 = 0.2;

/// Bins kept on each side of a waveform's signal for its decomposition: this many pulse sigmas
/// plus [`SPAN_MARGIN_BINS`], beyond the fit's windows (6 sigmas and 3 bins of its widest
/// components) and the smoothing's reach.
const SPAN_MARGIN_SIGMAS: f64 = 16.0;
const SPAN_MARGIN_BINS: usize = 16;

/// Returns at least this many times as wide as the pulse are placed at their summit, not at
/// their fitted centre (see [`place_on_summits`]): 1.5 pulse sigmas hold a spread of ranges
/// of √(1.5² - 1) ≈ 1.1 sigma besides the pulse's own, several leaves or a slanted surface.
const WIDE_SIGMAS: f64 = 1.5;

/// Where a detector places each return along its beam: at the fitted centre of a return as
/// narrow as the pulse (sub-bin precise), and at the summit of the waveform within one sigma
/// of the centre of a wider one ([`WIDE_SIGMAS`]). A wide return is several surfaces within
/// the pulse's length, leaves of a crown at a few ranges, whose centroid can lie between them
/// on no surface at all; its summit is the strongest of them, where a peak detector puts it.
/// A return merged as one smeared surface ([`Component::one_surface`]) keeps its centroid: the
/// summit of a flat top is wherever the noise peaks, up to half the spread off the beam's axis.
/// On the bench's campaigns this places more of the points within 25 cm of a surface, markedly
/// so over a forest.
pub fn place_on_summits(comps: &mut [Component], photons: &[f32], pulse_sigma_bins: f64) {
    if !(pulse_sigma_bins.is_finite() && pulse_sigma_bins > 0.0) {
        return;
    }
    let y = |k: usize| f64::from(photons[k]).max(0.0);
    for c in comps.iter_mut() {
        let wide = c.sigma_bins > WIDE_SIGMAS * pulse_sigma_bins;
        if !wide || c.one_surface || !c.centre_bin.is_finite() {
            continue;
        }
        let lo = (c.centre_bin - c.sigma_bins).floor().max(0.0) as usize;
        let hi = ((c.centre_bin + c.sigma_bins).ceil().max(0.0) as usize).min(photons.len());
        // the first of equal summits, so the placement is the same on any machine
        let Some(k) = (lo..hi).reduce(|m, k| if y(k) > y(m) { k } else { m }) else {
            continue;
        };
        if y(k) <= 0.0 {
            continue;
        }
        let around = [
            if k > 0 { y(k - 1) } else { 0.0 },
            y(k),
            if k + 1 < photons.len() { y(k + 1) } else { 0.0 },
        ];
        let (offset, _) = parabola(&around, 1);
        c.centre_bin = k as f64 + 0.5 + offset;
    }
}

/// Decomposes a waveform into at most `max_returns` returns, ordered by time.
///
/// What a detector could resolve decides what is one return (see [`resolve`]): a component
/// that does not stand out from the noise is part of the return it touches, or no return,
/// and two close ones with no dip between them are one return (a steep surface smears the
/// pulse over its range, which no number of Gaussians makes several surfaces).
/// `mc_se_photons` is the Monte Carlo standard error of each bin's photons before the pulse
/// convolution (empty: an exact waveform): the simulation's own noise, which a few-ray pulse
/// has plenty of, besides the photon noise a real detector has. `leaves_photons` are the
/// photons of each bin, likewise before the convolution, whose first surface was a leaf (the
/// vegetation class; empty: none known): a few rays' comb of spikes is one surface's
/// sampling where the light is a hard surface's, and leaves at many ranges where it is a
/// canopy's.
///
/// `threshold_photons` is both the minimum peak height (photons per bin) for detection and
/// the minimum area (photons) of a reported component; `receiver` the return's width, the
/// beam's shape and the detector's noise (its noise floor adds to every test of
/// significance). When more components than `max_returns` are found, the strongest (largest
/// area) are kept: the weakest are the least reliable, and a dense canopy must not hide the
/// ground.
///
/// Long because it is the decomposition's sequence in one place: the signal's span, peaks,
/// fit, resolution into returns, selection; each step is a function of its own.
pub fn decompose(
    photons: &[f32],
    mc_se_photons: &[f32],
    leaves_photons: &[f32],
    threshold_photons: f64,
    max_returns: usize,
    method: Decomposition,
    receiver: &Receiver,
) -> Vec<Component> {
    if max_returns == 0 || photons.is_empty() {
        return Vec::new();
    }
    let hint = if receiver.sigma_bins.is_finite() && receiver.sigma_bins > 0.0 {
        receiver.sigma_bins
    } else {
        0.0
    };
    let floor = if receiver.noise_floor.is_finite() {
        receiver.noise_floor.max(0.0)
    } else {
        0.0
    };
    let edge = receiver.footprint_edge_sigmas;
    let threshold = if threshold_photons.is_finite() {
        threshold_photons.max(0.0)
    } else {
        0.0
    };
    let f = coarsening(hint);
    let alarm_rate = receiver
        .false_alarm_rate
        .filter(|a| a.is_finite() && *a > 0.0 && floor > 0.0);
    // The bins around the signal only, on the coarse grid's boundaries: a gate of hundreds of
    // bins holds a return or two, and the zeros far from them change nothing (the smoothing,
    // the fit's windows and the residual search reach a few sigmas) but cost their passes.
    let Some((first, last)) = signal_span(photons) else {
        return Vec::new();
    };
    let margin = (SPAN_MARGIN_SIGMAS * hint).ceil() as usize + SPAN_MARGIN_BINS;
    let lo = first.saturating_sub(margin) / f * f;
    let hi = (last + 1 + margin).min(photons.len());
    // a record's noise below its background is kept, not rectified: set to zero, it would
    // lift every return's area and every noise bump's level
    let y: Vec<f64> = photons[lo..hi]
        .iter()
        .map(|&v| if v.is_finite() { v as f64 } else { 0.0 })
        .collect();
    let mc_se: Vec<f64> = mc_se_photons
        .get(lo.min(mc_se_photons.len())..hi.min(mc_se_photons.len()))
        .unwrap_or_default()
        .iter()
        .map(|&s| {
            if s.is_finite() {
                s.max(0.0) as f64
            } else {
                0.0
            }
        })
        .collect();
    // photons of one ray: Σ se² / Σ photons, the photon-weighted mean of the rays' shares
    // (a bin one ray lit has the error of its whole value)
    let light: f64 = y.iter().sum();
    let quantum = if light > 0.0 {
        mc_se.iter().map(|s| s * s).sum::<f64>() / light
    } else {
        0.0
    };
    let leaves: Vec<f64> = leaves_photons
        .get(lo.min(leaves_photons.len())..hi.min(leaves_photons.len()))
        .unwrap_or_default()
        .iter()
        .map(|&v| if signal(v) { v as f64 } else { 0.0 })
        .collect();
    let shifted = |c: Component| Component {
        centre_bin: c.centre_bin + lo as f64,
        ..c
    };
    if f == 1 {
        let threshold = Threshold {
            per_bin: threshold,
            area: threshold,
        };
        let noise = Noise {
            mc_se: &mc_se,
            pulse_sigma: hint,
            footprint_edge_sigmas: edge,
            floor,
            quantum,
            leaves: &leaves,
            alarm: alarm_rate
                .map(|a| alarm::alarm_level(y.len(), hint, floor, a, threshold.per_bin)),
        };
        return decompose_bins(&y, threshold, max_returns, method, &noise)
            .into_iter()
            .map(shifted)
            .collect();
    }
    // bin k of the coarse waveform is bins [f k, f k + f): its photons and (correlated, as
    // `Noise::mc_var` adds them) Monte Carlo errors are their sums
    let sum = |v: &[f64]| -> Vec<f64> { v.chunks(f).map(|c| c.iter().sum()).collect() };
    let (coarse, coarse_se, coarse_leaves) = (sum(&y), sum(&mc_se), sum(&leaves));
    let threshold = Threshold {
        per_bin: threshold * f as f64,
        area: threshold,
    };
    let k = f as f64;
    let noise = Noise {
        mc_se: &coarse_se,
        pulse_sigma: hint / k,
        footprint_edge_sigmas: edge,
        // a coarse bin's noise floor is that of f bins
        floor: floor * k,
        quantum,
        leaves: &coarse_leaves,
        alarm: alarm_rate
            .map(|a| alarm::alarm_level(coarse.len(), hint / k, floor * k, a, threshold.per_bin)),
    };
    decompose_bins(&coarse, threshold, max_returns, method, &noise)
        .into_iter()
        .map(|c| Component {
            centre_bin: c.centre_bin * k,
            sigma_bins: c.sigma_bins * k,
            area_photons: c.area_photons,
            amplitude: c.amplitude / k,
            one_surface: c.one_surface,
        })
        .map(shifted)
        .collect()
}

/// Whether a bin holds signal: photons, finite and above zero.
fn signal(v: f32) -> bool {
    v.is_finite() && v > 0.0
}

/// Bins scanned at once by [`signal_span`].
const SCAN_BLOCK: usize = 16;

/// The first and last bins holding [`signal`], None if none does. Blocks of bins are passed
/// over by a test of "any above zero" that vectorises, and only a block that passes is looked
/// into bin by bin: a scan bin by bin from either end would be most of `decompose`'s own
/// time on a forest's long gates.
fn signal_span(photons: &[f32]) -> Option<(usize, usize)> {
    // whole blocks as arrays, whose test the compiler unrolls and vectorises (measurably
    // faster than a slice of unknown length); the last, shorter block is looked into bin by
    // bin. Plain chunks from either end: a stepped range of block starts, reversed, cost as
    // much as the rest of `decompose`'s own time
    let any = |block: &[f32]| {
        <&[f32; SCAN_BLOCK]>::try_from(block)
            .is_ok_and(|block| block.iter().fold(false, |any, &v| any | (v > 0.0)))
    };
    let blocks = photons.chunks_exact(SCAN_BLOCK);
    let tail = blocks.remainder();
    let tail_at = photons.len() - tail.len();
    let first = blocks
        .clone()
        .enumerate()
        .filter(|(_, b)| any(b))
        .find_map(|(k, b)| {
            b.iter()
                .position(|&v| signal(v))
                .map(|i| k * SCAN_BLOCK + i)
        })
        .or_else(|| tail.iter().position(|&v| signal(v)).map(|i| tail_at + i))?;
    let last = tail
        .iter()
        .rposition(|&v| signal(v))
        .map(|i| tail_at + i)
        .or_else(|| {
            blocks
                .enumerate()
                .rev()
                .filter(|(_, b)| any(b))
                .find_map(|(k, b)| {
                    b.iter()
                        .rposition(|&v| signal(v))
                        .map(|i| k * SCAN_BLOCK + i)
                })
        });
    Some((first, last.unwrap_or(first)))
}

/// [`decompose`] on bins as given (see [`coarsening`]).
fn decompose_bins(
    y: &[f64],
    threshold: Threshold,
    max_returns: usize,
    method: Decomposition,
    noise: &Noise,
) -> Vec<Component> {
    let hint = noise.pulse_sigma;
    // a record with noise: a summit must reach the false-alarm level, which the filter's
    // weighted average of the bins around it reaches only if one of them does
    let mut peaks = detect_peaks(y, noise.alarm.unwrap_or(threshold.per_bin), hint);
    // what the matched filter does not see above the false-alarm level is noise: no seed
    let alarmed = noise.alarm.map(|u| (u, alarm::matched(y, hint)));
    let seen = |c: &Component| {
        alarmed
            .as_ref()
            .is_none_or(|(u, s)| above_alarm(c, *u, s, hint))
    };
    peaks.retain(|c| seen(c));
    // a seed's area summed between the noise's valleys may fall short of what the filter
    // measures (the least-squares area of a Gaussian of its σ there): the larger is kept, so
    // a seed that reaches the level stands out from the noise as its excursion does
    if let Some((_, s)) = &alarmed {
        for p in &mut peaks {
            let level = alarm::summit_near(s, p.centre_bin, 0.5);
            let area = level * 2.0 * std::f64::consts::PI.sqrt() * hint.max(COLLAPSED_SIGMA);
            if area > p.area_photons {
                p.area_photons = area;
                p.amplitude = area / (p.sigma_bins * (2.0 * std::f64::consts::PI).sqrt());
            }
        }
    }
    // every excursion of the filtered record above the level is a return's seed, where the
    // smoothed maxima missed it (a broad bump of noise has no raw summit that stands out)
    if let Some((u, s)) = &alarmed {
        for alarm::Excursion {
            first,
            last,
            at,
            level,
        } in alarm::excursions(s, *u)
        {
            let reach = hint.max(1.0);
            let (from, to) = (first as f64 - reach, (last + 1) as f64 + reach);
            if !peaks.iter().any(|p| (from..=to).contains(&p.centre_bin)) {
                let sigma = hint.max(COLLAPSED_SIGMA);
                // a Gaussian of the filter's σ whose filtered summit is `level`
                let area = level * 2.0 * std::f64::consts::PI.sqrt() * sigma;
                peaks.push(Component {
                    centre_bin: at,
                    sigma_bins: sigma,
                    area_photons: area,
                    amplitude: area / (sigma * (2.0 * std::f64::consts::PI).sqrt()),
                    one_surface: false,
                });
            }
        }
        peaks.sort_by(|a, b| a.centre_bin.total_cmp(&b.centre_bin));
    }
    // a comb's return is its rays' light, which no Gaussian's fit would describe better: it
    // is kept as gathered, the light the fit must leave to it
    let mut combs = Vec::new();
    let peaks = resolve(peaks, y, threshold.per_bin, noise, false, Some(&mut combs));
    let mut comps = match method {
        Decomposition::PeakDetection => peaks,
        Decomposition::Gaussian => fit_all(y, &peaks, &combs, threshold, hint, noise),
    };
    comps.extend(combs);
    let comps = resolve(
        comps,
        y,
        threshold.per_bin,
        noise,
        method == Decomposition::Gaussian,
        None,
    );
    let comps = match &alarmed {
        Some((u, s)) => alarm::standing_out(comps, y, s, *u, hint),
        None => comps,
    };
    select(comps, threshold.area, max_returns)
}

/// Whether the matched-filtered record `s` reaches the false-alarm level `u` near a seed: within
/// the filter's width and a bin (see [`alarm::standing_out`], which judges the returns).
fn above_alarm(c: &Component, u: f64, s: &[f64], sigma: f64) -> bool {
    alarm::summit_near(s, c.centre_bin, sigma.max(1.0) + 1.0) >= u
}

/// The detection threshold in its two uses: a level per bin (a peak's height, a run of
/// signal) and a least area (photons). They differ only where the waveform is decomposed
/// on coarsened bins, whose levels are the sums of `f` bins.
#[derive(Clone, Copy, Debug)]
pub(super) struct Threshold {
    pub(super) per_bin: f64,
    pub(super) area: f64,
}

/// Bins of a waveform summed into one for its decomposition, for a pulse of `sigma_bins`: 1
/// while the pulse spans fewer than 8 bins, else the most that leave it 2 bins or more. A
/// gate much finer than its pulse (0.067 ns bins against a 1.27 ns sigma: 19 bins) holds
/// little that bins of σ/2 lose: the model integrates each Gaussian over its bins exactly,
/// and Poisson counts summed are Poisson counts. On the paper's ALS campaign over the
/// generated forest, bins of σ/2 make the products stage several times faster than the
/// gate's own bins, the points and the DSM all but unchanged (the figures are in the commit
/// that made the choice).
pub fn coarsening(sigma_bins: f64) -> usize {
    if sigma_bins.is_finite() && sigma_bins >= 8.0 {
        (sigma_bins / 2.0).floor() as usize
    } else {
        1
    }
}

/// What a return must stand out from besides its own photon noise: the simulation's, and
/// the detector's beyond shot noise.
pub(super) struct Noise<'a> {
    /// Monte Carlo standard error of each bin's photons (impulse, before the pulse
    /// convolution).
    pub(super) mc_se: &'a [f64],
    /// The pulse's sigma, bins: the convolution that spreads each bin's error over its
    /// neighbours.
    pub(super) pulse_sigma: f64,
    /// Where the beam's footprint is cut, in sigmas of its Gaussian: the shape one surface
    /// smears the pulse into ([`surface`]); None: not known, no such test.
    pub(super) footprint_edge_sigmas: Option<f64>,
    /// Variance of each bin besides shot noise (see [`Receiver::noise_floor`]).
    pub(super) floor: f64,
    /// Photons one ray brings, on average over the waveform's light: a few-ray waveform is
    /// made of such quanta, and where it shows a gap, a smooth surface's light could have
    /// left one as well (see [`Noise::compound_var`]); 0 for an exact waveform.
    pub(super) quantum: f64,
    /// Photons of each bin whose first surface was a leaf (impulse, before the pulse
    /// convolution; empty: none known): a canopy's light, whose comb of few rays is leaves
    /// at many ranges rather than one surface's sampling.
    pub(super) leaves: &'a [f64],
    /// The level the matched-filtered record must reach for a return (see [`alarm`]); None:
    /// no false-alarm rule (a waveform without noise).
    pub(super) alarm: Option<f64>,
}

impl Noise<'_> {
    /// Monte Carlo variance of the photons in bins [lo, hi). The errors of bins within the
    /// pulse's sigma (at least one bin) of each other are added as if fully correlated, as
    /// they are where one ray's paths make a spike over a few bins: the one case the test must
    /// not miss. Bins farther apart hold different rays' light, whose errors are independent
    /// (or anticorrelated: a ray in one bin is in no other): added as fully correlated too, the
    /// error of a return spread over hundreds of bins by a steep surface would be their
    /// sum, as large as the return, and the return would not count.
    pub(super) fn mc_var(&self, lo: usize, hi: usize) -> f64 {
        let hi = hi.min(self.mc_se.len());
        let Some(se) = self.mc_se.get(lo..hi) else {
            return 0.0;
        };
        let reach = self.pulse_sigma.ceil().max(1.0) as usize;
        // Σ_j se_j Σ_{|k - j| ≤ reach} se_k, the neighbours' sum kept as a sliding window
        let mut near: f64 = se.iter().take(reach + 1).sum();
        let mut var = 0.0;
        for j in 0..se.len() {
            var += se[j] * near;
            if let Some(&next) = se.get(j + reach + 1) {
                near += next;
            }
            if j >= reach {
                near -= se[j - reach];
            }
        }
        var.max(0.0)
    }

    /// Rays whose light makes a component, area² / (its Monte Carlo variance), at least 1;
    /// infinite for an exact waveform.
    pub(super) fn rays(&self, c: &Component) -> f64 {
        let (lo, hi) = light_bins(c);
        let var = self.mc_var(lo, hi);
        if var > 0.0 {
            (c.area_photons.powi(2) / var).max(1.0)
        } else {
            f64::INFINITY
        }
    }

    /// Whether most of a component's light (within its sigma) came first off leaves.
    pub(super) fn leafy(&self, c: &Component) -> bool {
        let (lo, hi) = light_bins(c);
        let hi = hi.min(self.leaves.len());
        let leaves: f64 = self
            .leaves
            .get(lo.min(hi)..hi)
            .map_or(0.0, |l| l.iter().sum());
        leaves >= 0.5 * c.area_photons
    }

    /// Monte Carlo variance of a level of `level` photons per bin, the pulse-convolved
    /// waveform averaged by a Gaussian of `sigma` bins besides the pulse's, were the light
    /// smooth there: rays arrive as a Poisson process of quanta ([`Noise::quantum`]) of
    /// level / quantum per bin, each spread by the pulse and the average, so the level's
    /// variance is quantum · level · Σ k² for their kernel k (Σ k² = 1 / (2√π σ) for a
    /// Gaussian of σ bins). The error the bins' own estimates give is zero in a gap between
    /// rays, which is a gap of the sampling, not of the light, where rays are few.
    pub(super) fn compound_var(&self, level: f64, sigma: f64) -> f64 {
        let width = (self.pulse_sigma.powi(2) + sigma * sigma).sqrt().max(0.5);
        self.quantum * level.max(0.0) / (2.0 * std::f64::consts::PI.sqrt() * width)
    }

    /// Monte Carlo standard error of the pulse-convolved photons in bin `k`, at most: the
    /// convolution's weighted sum of the bins' errors (equal to it where one ray made them).
    pub(super) fn mc_se_convolved(&self, k: usize) -> f64 {
        let s = self.pulse_sigma.max(0.3);
        let reach = (4.0 * s).ceil() as usize;
        let (mut sum, mut weight) = (0.0, 0.0);
        for j in k.saturating_sub(reach)..(k + reach + 1).min(self.mc_se.len()) {
            let w = (-0.5 * ((j as f64 - k as f64) / s).powi(2)).exp();
            sum += w * self.mc_se[j];
            weight += w;
        }
        if weight > 0.0 {
            sum / weight
        } else {
            0.0
        }
    }

    /// Whether a component's area exceeds [`MIN_SIGNIFICANCE`] standard errors: Poisson noise
    /// of the area, the detector's noise floor and, with `mc`, the Monte Carlo noise of the bins within one sigma (at
    /// least one bin) of its centre, where its photons are.
    pub(super) fn significant(&self, c: &Component, mc: bool) -> bool {
        let half = c.sigma_bins.max(1.0);
        let lo = (c.centre_bin - half).floor().max(0.0) as usize;
        let hi = (c.centre_bin + half).ceil().max(0.0) as usize;
        // the detector's floor as a matched filter of the return's shape weighs it: over
        // 1 / Σ g² = 2√π σ bins
        let matched = 2.0 * std::f64::consts::PI.sqrt() * c.sigma_bins.max(0.5);
        let mut var = c.area_photons.max(0.0) + self.floor * matched;
        if mc {
            var += self.mc_var(lo, hi);
        }
        c.area_photons >= MIN_SIGNIFICANCE * var.sqrt()
    }
}

/// The returns a detector could tell apart, in time order, from fitted or detected
/// components:
/// 1. components joined by signal above the threshold make a run; in a run, a component
///    within its photon noise is dropped, and one that does not stand out from the
///    simulation's noise joins its nearest neighbour that does (all join into one if none
///    does): the rays of a few-ray pulse on a steep surface make a comb of spikes whose sum
///    is one return;
/// 2. runs with no significant component before the first return that has one are a comb
///    ([`flush_comb`]): together, where they are a hard surface's and stand out, one return
///    (a wide seed, before the fit); within [`JOIN_SIGMAS`] of the first significant
///    return, part of it; else only the first run is kept: the first return is
///    light scattered once by the nearest surface the rays met (any longer path arrives
///    later), a surface however few rays found it, as in any first-hit simulator, where a
///    later run may be one rare multiple-scattering path;
/// 3. with `by_shape` (fitted widths), neighbours less than [`BLENDED_SIGMAS`] apart are one
///    return unless the waveform dips between them by more than its noise (Sparrow's
///    criterion, the noise setting the depth a detector can see, and a few rays' comb
///    leaving gaps no surface has: [`Noise::compound_var`]).
///
/// Long because its three rules act on the same runs of components in one pass.
pub(super) fn resolve(
    mut comps: Vec<Component>,
    y: &[f64],
    threshold: f64,
    noise: &Noise,
    by_shape: bool,
    mut combs: Option<&mut Vec<Component>>,
) -> Vec<Component> {
    // a component the waveform cannot hold (a fit that wandered off) is no return
    let n = y.len() as f64;
    comps.retain(|c| {
        c.area_photons > 0.0
            && c.area_photons.is_finite()
            && (-1.0..=n + 1.0).contains(&c.centre_bin)
            && c.sigma_bins > 0.0
            && c.sigma_bins <= n
    });
    comps.sort_by(|a, b| a.centre_bin.total_cmp(&b.centre_bin));
    let close = comps;
    let joined = |a: &Component, b: &Component| {
        let lo = (a.centre_bin.max(0.0) as usize).min(y.len());
        let hi = (b.centre_bin.max(0.0) as usize).min(y.len());
        y[lo..hi].iter().all(|&v| v > threshold)
    };
    let mut out = Vec::new();
    let mut comb: Vec<Vec<Component>> = Vec::new();
    let mut start = 0;
    while start < close.len() {
        let mut end = start + 1;
        while end < close.len() && joined(&close[end - 1], &close[end]) {
            end += 1;
        }
        // photon noise is no part of any return; the simulation's noise is part of the
        // return it sits on
        let run: Vec<Component> = close[start..end]
            .iter()
            .filter(|c| noise.significant(c, false))
            .copied()
            .collect();
        let run = &run[..];
        let strong: Vec<usize> = (0..run.len())
            .filter(|&k| noise.significant(&run[k], true))
            .collect();
        if strong.is_empty() {
            // gathered as a comb (see `flush_comb`)
            if !run.is_empty() {
                comb.push(run.to_vec());
            }
        } else {
            // each weak component joins the significant one nearest in time, unless the rays
            // left the stretch between them empty (see `unsampled_gap`): then it is light of
            // a surface of its own, which few rays found, a return as its photons make it
            let mut parts: Vec<Vec<Component>> = strong.iter().map(|&k| vec![run[k]]).collect();
            for (k, c) in run.iter().enumerate() {
                if strong.contains(&k) {
                    continue;
                }
                let nearest = (0..strong.len())
                    .min_by(|&a, &b| {
                        (run[strong[a]].centre_bin - c.centre_bin)
                            .abs()
                            .total_cmp(&(run[strong[b]].centre_bin - c.centre_bin).abs())
                    })
                    .unwrap_or(0);
                let s = &run[strong[nearest]];
                let (first, second) = if s.centre_bin <= c.centre_bin {
                    (s, c)
                } else {
                    (c, s)
                };
                if noise.rays(c) >= SURFACE_RAYS && unsampled_gap(first, second, noise) {
                    parts.push(vec![*c]);
                } else {
                    parts[nearest].push(*c);
                }
            }
            parts.sort_by(|p, q| p[0].centre_bin.total_cmp(&q[0].centre_bin));
            // light of a hard surface before the first return, within its spread, is its
            // own (a leaf there is the canopy's first surface)
            if let Some(first) = parts.first_mut() {
                let claimed = claim(&merged(first), &mut comb, noise);
                first.extend(claimed);
            }
            flush_comb(&mut comb, &mut out, combs.as_deref_mut(), noise);
            out.extend(parts.iter().map(|p| merged(p)));
        }
        start = end;
    }
    flush_comb(&mut comb, &mut out, combs, noise);
    if !by_shape {
        return out;
    }
    let mut out = blend(out, y, noise, Some(threshold));
    // A wide return is placed at its summit, the strongest of several surfaces (see
    // `place_on_summits`), unless it is one slope's: its shape known to the simulation (Monte
    // Carlo error of its light within 2 sigmas under [`SHAPE_KNOWN`] of its area) and one
    // surface's waveform fitting it clearly better than its Gaussian does. A crown seen by a
    // few rays fits any shape to its noise, and its summit stays the better guess.
    for k in 0..out.len() {
        let c = out[k];
        if c.one_surface || c.sigma_bins <= WIDE_SIGMAS * noise.pulse_sigma {
            continue;
        }
        let lo = (c.centre_bin - 2.0 * c.sigma_bins).floor().max(0.0) as usize;
        let hi = (c.centre_bin + 2.0 * c.sigma_bins).ceil().max(0.0) as usize;
        if noise.mc_var(lo, hi) < (SHAPE_KNOWN * c.area_photons).powi(2) {
            let others: Vec<Component> = out[..k].iter().chain(&out[k + 1..]).copied().collect();
            out[k].one_surface = surface::slope(&c, &others, y, threshold, noise);
        }
    }
    out
}

/// Sigmas of a return within which light beside it is its own.
const JOIN_SIGMAS: f64 = 3.0;

/// The components of the `runs` that are a hard surface's light (see [`Noise::leafy`])
/// within [`JOIN_SIGMAS`] of `ret`'s centre, taken out of `runs` in their order.
fn claim(ret: &Component, runs: &mut Vec<Vec<Component>>, noise: &Noise) -> Vec<Component> {
    let within = |r: &[Component]| {
        let c = merged(r);
        (c.centre_bin - ret.centre_bin).abs() <= JOIN_SIGMAS * ret.sigma_bins && !noise.leafy(&c)
    };
    let (claimed, kept): (Vec<_>, Vec<_>) =
        std::mem::take(runs).into_iter().partition(|r| within(r));
    *runs = kept;
    claimed.into_iter().flatten().collect()
}

/// Rays a component's light must hold to be a surface of its own beyond a stretch the rays
/// left empty (see [`resolve`]): one ray's light may be one rare multiple-scattering path,
/// whose range is a path's length, not a surface's; several rays at one range found a surface.
const SURFACE_RAYS: f64 = 2.0;

/// Tail probability below which a gap in a comb parts it (see [`flush_comb`]).
const COMB_GAP_TAIL: f64 = 1e-3;

/// Bins [lo, hi) holding a component's light, as [`Noise::significant`] counts them.
fn light_bins(c: &Component) -> (usize, usize) {
    let half = c.sigma_bins.max(1.0);
    (
        (c.centre_bin - half).floor().max(0.0) as usize,
        (c.centre_bin + half).ceil().max(0.0) as usize,
    )
}

/// Runs of light none of which stands out from the simulation's noise, in time order, as
/// the returns they make together. A few rays over a steep surface leave a comb of spikes,
/// each one ray's light: alone none is a return, together they are the surface's. The comb
/// is parted at any gap longer than its rays' spacing makes likely (a homogeneous Poisson
/// process of the comb's rays leaves a gap of g bins with probability e^{-λg}, below
/// [`COMB_GAP_TAIL`] over all its gaps), and a run mostly of leaves' light stands alone:
/// leaves at many ranges are many surfaces, whose first is the first return. A part whose
/// sum stands out is one return, wide, so placed like any wide return of unknown shape (at
/// its summit, [`place_on_summits`]) unless its shape shows one surface; before the fit it is
/// one wide seed, which the fit widens to all the comb's light. Of the parts that do not
/// stand out, only a first one is kept, as for a lone run.
fn flush_comb(
    runs: &mut Vec<Vec<Component>>,
    out: &mut Vec<Component>,
    mut combs: Option<&mut Vec<Component>>,
    noise: &Noise,
) {
    // a hard surface's light just after a return, within its spread, is its own
    if let Some(prev) = out.last_mut() {
        let all: Vec<Component> = std::iter::once(*prev)
            .chain(claim(prev, runs, noise))
            .collect();
        *prev = merged(&all);
    }
    if runs.is_empty() {
        return;
    }
    let comb: Vec<Component> = runs.iter().map(|r| merged(r)).collect();
    // rays of each run: its area over its Monte Carlo standard error, squared
    let rays: Vec<f64> = comb
        .iter()
        .map(|c| {
            let (lo, hi) = light_bins(c);
            let var = noise.mc_var(lo, hi);
            if var > 0.0 {
                (c.area_photons.powi(2) / var).max(1.0)
            } else {
                1.0
            }
        })
        .collect();
    // a run mostly of leaves' light stands alone: leaves at many ranges are many surfaces
    let mut parts: Vec<std::ops::Range<usize>> = Vec::new();
    let mut todo = Vec::new();
    let mut from = 0;
    for (k, c) in comb.iter().enumerate() {
        if noise.leafy(c) {
            todo.extend([from..k, k..k + 1]);
            from = k + 1;
        }
    }
    todo.push(from..comb.len());
    todo.retain(|r| !r.is_empty());
    while let Some(r) = todo.pop() {
        if r.len() < 2 {
            parts.push(r);
            continue;
        }
        let n: f64 = rays[r.clone()].iter().sum();
        // a run's light reaches from its first component to its last
        let first = |k: usize| runs[k].first().map_or(comb[k].centre_bin, |c| c.centre_bin);
        let last = |k: usize| runs[k].last().map_or(comb[k].centre_bin, |c| c.centre_bin);
        let span = last(r.end - 1) - first(r.start);
        let (at, gap) = (r.start..r.end - 1)
            .map(|k| (k, first(k + 1) - last(k)))
            .fold(
                (r.start, f64::NEG_INFINITY),
                |m, g| if g.1 > m.1 { g } else { m },
            );
        let rate = (n - 1.0).max(1.0) / span.max(1e-9);
        if (r.len() - 1) as f64 * (-rate * gap).exp() < COMB_GAP_TAIL {
            todo.push(at + 1..r.end);
            todo.push(r.start..at + 1);
        } else {
            parts.push(r);
        }
    }
    parts.sort_by_key(|r| r.start);
    for r in parts {
        let part = &comb[r.clone()];
        let sum = merged(part);
        let lo = part.iter().map(|c| light_bins(c).0).min().unwrap_or(0);
        let hi = part.iter().map(|c| light_bins(c).1).max().unwrap_or(0);
        let matched = 2.0 * std::f64::consts::PI.sqrt() * sum.sigma_bins.max(0.5);
        let var = sum.area_photons + noise.floor * matched + noise.mc_var(lo, hi);
        if sum.area_photons >= MIN_SIGNIFICANCE * var.sqrt() {
            match combs.as_deref_mut() {
                Some(combs) => combs.push(sum),
                None => out.push(sum),
            }
        } else if out.is_empty() {
            out.push(part[0]);
        }
    }
    runs.clear();
}

/// Time-ordered components merged into the returns a detector makes of them. Neighbours with
/// no dip between them ([`dips`]) form a chain; with `surfaces` (the level of signal per bin),
/// a chain joined by light ([`lit`]) that one surface explains as well
/// ([`surface::one_surface`]: a slope, a roof seen obliquely) is one return,
/// and in any other chain each neighbour a detector cannot tell apart ([`apart`]) is merged
/// into the one before it. The fit's search asks without `surfaces`: its components on the
/// way to the last are no better than one surface, yet lead to it.
pub(super) fn blend(
    comps: Vec<Component>,
    y: &[f64],
    noise: &Noise,
    surfaces: Option<f64>,
) -> Vec<Component> {
    let mut one: Vec<Component> = Vec::with_capacity(comps.len());
    let mut start = 0;
    while start < comps.len() {
        let mut end = start + 1;
        while end < comps.len()
            && !dips(&comps[end - 1], &comps[end], y, noise)
            && lit(&comps[end - 1], &comps[end], y, noise)
        {
            end += 1;
        }
        let chain = &comps[start..end];
        let others = || {
            comps[..start]
                .iter()
                .chain(&comps[end..])
                .copied()
                .collect::<Vec<_>>()
        };
        // neighbours a detector cannot tell apart by their distance or a dip merge first;
        // only a chain that stays several returns is asked whether one surface made it
        let mut pairs: Vec<Component> = Vec::with_capacity(chain.len());
        for &c in chain {
            match pairs.last_mut() {
                Some(l) if !apart(l, &c, y, noise) => *l = merged(&[*l, c]),
                _ => pairs.push(c),
            }
        }
        let surface = match surfaces {
            Some(level) if pairs.len() > 1 && lit(&chain[0], &chain[chain.len() - 1], y, noise) => {
                surface::one_surface(chain, &others(), y, level, noise)
            }
            _ => None,
        };
        match surface {
            Some(s) => one.push(s),
            None => one.extend(pairs),
        }
        start = end;
    }
    let Some(level) = surfaces else {
        return one;
    };
    // Returns joined by light that together hold under half of it: a fit that settled on
    // bumps of a flat top's noise, which one surface's return replaces where it fits
    let mut out: Vec<Component> = Vec::with_capacity(one.len());
    let mut start = 0;
    while start < one.len() {
        let mut end = start + 1;
        while end < one.len() && lit(&one[end - 1], &one[end], y, noise) {
            end += 1;
        }
        let others: Vec<Component> = one[..start].iter().chain(&one[end..]).copied().collect();
        match surface::unclaimed(&one[start..end], &others, y, level, noise) {
            Some(s) => out.push(s),
            None => out.extend_from_slice(&one[start..end]),
        }
        start = end;
    }
    out
}

/// Whether light joins `a` and `b` (a first) as it joins the parts of one surface: a
/// surface's light is continuous over its spread, sampled by rays whose ranges leave gaps
/// shorter than the pulse (8 sigmas) where they are dense enough to show its shape; a longer
/// gap without any light (a crown above the ground) parts them. Any light, not light above
/// the threshold: a faint slope's bins hover about it.
fn lit(a: &Component, b: &Component, y: &[f64], noise: &Noise) -> bool {
    let at = |c: &Component| (c.centre_bin.max(0.0) as usize).min(y.len());
    // rays per bin of the weaker end's light (its level over the photons of a ray): a gap
    // without rays longer than e^{-λ g} = [`COMB_GAP_TAIL`] allows is a gap of the light
    let rate = if noise.quantum > 0.0 {
        a.amplitude.min(b.amplitude).max(0.0) / noise.quantum
    } else {
        f64::INFINITY
    };
    let sampled = if rate > 0.0 {
        (1.0 / COMB_GAP_TAIL).ln() / rate
    } else {
        f64::INFINITY
    };
    let longest = (8.0 * noise.pulse_sigma)
        .max(sampled.min(y.len() as f64))
        .max(1.0) as usize;
    let mut gap = 0;
    y[at(a)..at(b).max(at(a))].iter().all(|&v| {
        gap = if v > 0.0 { 0 } else { gap + 1 };
        gap <= longest
    })
}

/// Whether a detector tells `a` and `b` (a first) apart: they are [`BLENDED_SIGMAS`] apart,
/// or the waveform dips between them ([`dips`]).
fn apart(a: &Component, b: &Component, y: &[f64], noise: &Noise) -> bool {
    b.centre_bin - a.centre_bin >= BLENDED_SIGMAS * a.sigma_bins.min(b.sigma_bins)
        || dips(a, b, y, noise)
}

/// Whether the waveform between the centres of `a` and `b` (a first) dips below the lower of
/// its values at them by more than [`MIN_SIGNIFICANCE`] standard errors of the trough (photon,
/// detector and simulation noise): Sparrow's criterion, the noise setting the depth a detector
/// sees. Where the simulation's noise alone hides the dip, the rays decide: a stretch between
/// them that no ray reached, far longer than their spacing makes likely ([`unsampled_gap`]),
/// is a gap of the light, so a dip deeper than the photon and detector noise is a dip (two
/// clusters of leaves a metre apart, each hit by a few rays, are two returns however large
/// each one's Monte Carlo error).
fn dips(a: &Component, b: &Component, y: &[f64], noise: &Noise) -> bool {
    let at = |c: &Component| (c.centre_bin.max(0.0) as usize).min(y.len().saturating_sub(1));
    let (i, j) = (at(a), at(b));
    if j <= i + 1 {
        return false;
    }
    // the waveform and its shot noise's variance at bin k, averaged over half the pulse's
    // width: no feature of a pulse-convolved waveform is narrower, so a one-bin trough of
    // counts is noise, which the average's smaller variance no longer mistakes for a dip
    let s = 0.5 * noise.pulse_sigma;
    let reach = if s >= 0.5 {
        (3.0 * s).ceil() as usize
    } else {
        0
    };
    let level = |k: usize| -> (f64, f64) {
        let (mut sum, mut weights, mut squares) = (0.0, 0.0, 0.0);
        let from = k.saturating_sub(reach);
        for (m, &v) in y.iter().enumerate().take(k + reach + 1).skip(from) {
            let w = if reach == 0 {
                1.0
            } else {
                (-0.5 * ((m as f64 - k as f64) / s).powi(2)).exp()
            };
            sum += w * v;
            weights += w;
            squares += w * w;
        }
        let v = sum / weights;
        (
            v,
            (v.max(0.0) + noise.floor) * squares / (weights * weights),
        )
    };
    let (yi, yj) = (level(i), level(j));
    let (s_bin, (ys, vs)) = if yi.0 <= yj.0 { (i, yi) } else { (j, yj) };
    // the trough where the counts are lowest: the average there, not the least average, which
    // would cost an average at every bin between the two
    let k = (i + 1..j)
        .min_by(|&p, &q| y[p].total_cmp(&y[q]))
        .unwrap_or(i);
    let (trough, vt) = level(k);
    // the depth's error: photon and detector noise of both ends and the simulation's at each
    // were there no dip the trough would hold the lower end's level, made of as few rays
    let var = vs
        + vt
        + noise.mc_se_convolved(s_bin).powi(2)
        + noise
            .mc_se_convolved(k)
            .powi(2)
            .max(noise.compound_var(ys, s));
    let depth = ys - trough;
    depth > MIN_SIGNIFICANCE * var.sqrt()
        || (depth > MIN_SIGNIFICANCE * (vs + vt).sqrt() && unsampled_gap(a, b, noise))
}

/// Whether the rays left a stretch between the centres of `a` and `b` empty (no Monte Carlo
/// error in any of its bins: no ray's light) for longer than their spacing makes likely: the
/// rays of both, n = Σ area² / (Monte Carlo variance of the area), spread as a homogeneous
/// Poisson process over the bins from one centre to the other would leave a gap of g bins
/// with probability about (n − 1) e^{−λ g}, λ = (n − 1) / span, which must fall below
/// [`COMB_GAP_TAIL`], as for the gaps that part a comb ([`flush_comb`]).
fn unsampled_gap(a: &Component, b: &Component, noise: &Noise) -> bool {
    let se = noise.mc_se;
    let at = |c: &Component| (c.centre_bin.max(0.0) as usize).min(se.len());
    let (i, j) = (at(a), at(b));
    if se.is_empty() || j <= i + 1 {
        return false;
    }
    let (mut gap, mut run) = (0usize, 0usize);
    for &v in &se[i + 1..j] {
        run = if v > 0.0 { 0 } else { run + 1 };
        gap = gap.max(run);
    }
    let n = noise.rays(a) + noise.rays(b);
    if gap == 0 || !n.is_finite() {
        return false;
    }
    let rate = (n - 1.0).max(1.0) / (j - i) as f64;
    (n - 1.0).max(1.0) * (-rate * gap as f64).exp() < COMB_GAP_TAIL
}

/// One component with the area, centroid and spread (second moment) of several.
fn merged(parts: &[Component]) -> Component {
    if let [one] = parts {
        return *one;
    }
    let area: f64 = parts.iter().map(|c| c.area_photons).sum();
    let centre = parts
        .iter()
        .map(|c| c.area_photons * c.centre_bin)
        .sum::<f64>()
        / area;
    let var = parts
        .iter()
        .map(|c| c.area_photons * (c.sigma_bins.powi(2) + (c.centre_bin - centre).powi(2)))
        .sum::<f64>()
        / area;
    let sigma = var.sqrt();
    Component {
        centre_bin: centre,
        sigma_bins: sigma,
        area_photons: area,
        amplitude: area / (sigma * (2.0 * std::f64::consts::PI).sqrt()),
        one_surface: false,
    }
}

fn select(mut comps: Vec<Component>, threshold: f64, max_returns: usize) -> Vec<Component> {
    comps.retain(|c| {
        c.area_photons > threshold
            && c.centre_bin.is_finite()
            && c.sigma_bins.is_finite()
            && c.area_photons.is_finite()
    });
    if comps.len() > max_returns {
        comps.sort_by(|a, b| b.area_photons.total_cmp(&a.area_photons));
        comps.truncate(max_returns);
    }
    comps.sort_by(|a, b| a.centre_bin.total_cmp(&b.centre_bin));
    comps
}
