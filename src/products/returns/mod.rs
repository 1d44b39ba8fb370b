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

mod detect;
mod fit;
mod solve;
#[cfg(test)]
mod tests;

use detect::detect_peaks;
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

/// Decomposes a waveform into at most `max_returns` returns, ordered by time.
///
/// `threshold_photons` is both the minimum peak height (photons per bin) for detection and
/// the minimum area (photons) of a reported component. `pulse_sigma_bins` is the emitted
/// pulse's standard deviation in bins: it sizes the smoothing used for detection, seeds
/// sigma, and bounds the fitted sigma from below (no return is narrower than the pulse).
/// When more components than `max_returns` are found, the strongest (largest area) are kept:
/// the weakest are the least reliable, and a dense canopy must not hide the ground.
pub fn decompose(
    photons: &[f32],
    threshold_photons: f64,
    max_returns: usize,
    method: Decomposition,
    pulse_sigma_bins: f64,
) -> Vec<Component> {
    if max_returns == 0 || photons.is_empty() {
        return Vec::new();
    }
    let y: Vec<f64> = photons
        .iter()
        .map(|&v| {
            if v.is_finite() && v > 0.0 {
                v as f64
            } else {
                0.0
            }
        })
        .collect();
    let hint = if pulse_sigma_bins.is_finite() && pulse_sigma_bins > 0.0 {
        pulse_sigma_bins
    } else {
        0.0
    };
    let threshold = if threshold_photons.is_finite() {
        threshold_photons.max(0.0)
    } else {
        0.0
    };
    let peaks = detect_peaks(&y, threshold, hint);
    let comps = match method {
        Decomposition::PeakDetection => peaks,
        Decomposition::Gaussian => fit_all(&y, &peaks, threshold, hint),
    };
    select(comps, threshold, max_returns)
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
